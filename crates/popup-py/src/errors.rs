//! Maps `popup_core::Error` variants onto the Python exception hierarchy of
//! `popup.exceptions` (all derive from `PopupError` and the matching built-in).

use popup_core::Error;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

fn class_name(e: &Error) -> &'static str {
    match e {
        Error::InvalidParameter { .. } => "ParameterError",
        Error::ArmFile { .. } => "ArmFileError",
        Error::UnknownArm { .. } => "UnknownArmError",
        Error::Unreachable { .. } => "UnreachableError",
        Error::Singular(_) => "SingularityError",
        Error::Input { .. } => "InputError",
        Error::StepTooLarge { .. } => "StepTooLargeError",
        Error::Diverged { .. } => "DivergenceError",
        Error::NoConvergence { .. } => "ConvergenceError",
        Error::Log { .. } => "LogWriteError",
    }
}

/// The exception class name and message of a core error.
pub fn describe(e: &Error) -> (String, String) {
    (class_name(e).to_string(), e.to_string())
}

/// Convert a core error to a Python exception of the matching `popup.exceptions` class.
pub fn to_py(e: Error) -> PyErr {
    let (cls, msg) = describe(&e);
    Python::attach(|py| {
        let err = make(py, &cls, &msg);
        if let Error::StepTooLarge { dt, dt_max, .. } = e {
            // the numbers, so that callers need not parse the message
            let v = err.value(py);
            let _ = v.setattr("dt", dt).and_then(|_| v.setattr("dt_max", dt_max));
        }
        err
    })
}

/// Build an exception of class `cls` from `popup.exceptions` (falls back to a built-in
/// when that module is not importable).
pub fn make(py: Python<'_>, cls: &str, msg: &str) -> PyErr {
    let built = py
        .import("popup.exceptions")
        .and_then(|m| m.getattr(cls))
        .and_then(|c| c.call1((msg.to_string(),)));
    match built {
        Ok(obj) => PyErr::from_value(obj),
        Err(_) if matches!(cls, "DivergenceError" | "ConvergenceError") => PyRuntimeError::new_err(msg.to_string()),
        Err(_) if cls == "LogWriteError" => pyo3::exceptions::PyOSError::new_err(msg.to_string()),
        Err(_) => PyValueError::new_err(msg.to_string()),
    }
}

/// Extension trait: `result.py()?`.
pub trait IntoPy<T> {
    /// Map the core error into a Python exception.
    fn py(self) -> PyResult<T>;
}

impl<T> IntoPy<T> for Result<T, Error> {
    fn py(self) -> PyResult<T> {
        self.map_err(to_py)
    }
}

/// Sample count of a batch: that of its first successful job; when every job failed, the
/// first job's error is raised (0 for an empty batch).
pub fn batch_nsample<T>(results: &[popup_core::Result<T>], nsample: impl Fn(&T) -> usize) -> PyResult<usize> {
    match results.iter().find_map(|r| r.as_ref().ok().map(&nsample)) {
        Some(n) => Ok(n),
        None => match results.first() {
            Some(Err(e)) => Err(to_py(e.clone())),
            _ => Ok(0),
        },
    }
}


/// A requested thread count, validated by the core's [`popup_core::limits::threads`]
/// (negative or absurd counts refused naming `what` and the machine's cores).
pub fn threads(what: &str, requested: i64) -> PyResult<usize> {
    popup_core::limits::threads(what, requested).py()
}

/// Run `work` without the GIL on a helper thread while this thread checks Python's signal
/// handlers every 100 ms: on Ctrl-C (KeyboardInterrupt, or any error a handler raises) the
/// stop flag handed to `work` is raised, the work is awaited (it ends within
/// [`popup_core::limits::POLL_EVERY_STEPS`] steps) and the handler's error is returned.
pub fn interruptible<R: Send>(py: Python<'_>, work: impl FnOnce(&AtomicBool) -> R + Send) -> PyResult<R> {
    let flag = AtomicBool::new(false);
    let me = std::thread::current();
    let mut pending: Option<PyErr> = None;
    let out = std::thread::scope(|s| {
        let flag = &flag;
        let h = s.spawn(move || {
            let r = work(flag);
            me.unpark();
            r
        });
        while !h.is_finished() {
            py.detach(|| std::thread::park_timeout(Duration::from_millis(100)));
            if pending.is_none() && !h.is_finished() {
                if let Err(e) = py.check_signals() {
                    pending = Some(e);
                    flag.store(true, Ordering::SeqCst);
                }
            }
        }
        py.detach(|| h.join())
    });
    let out = match out {
        Ok(r) => r,
        Err(panic) => std::panic::resume_unwind(panic),
    };
    match pending {
        Some(e) => Err(e),
        None => Ok(out),
    }
}
