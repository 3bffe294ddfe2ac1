//! Scenario files (`popup.Scenario`): validation, key setting for sweeps, and logged runs.

use crate::errors::{make, IntoPy};
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use popup_cli::execute::{check_duration, execute};
use popup_cli::progress::{Progress, StopFlags};
use popup_core::control::closed_loop::NCTRL;
use popup_core::scenario::{set_key, Scenario};
use popup_core::sensor::NCH;
use popup_core::stream::Collect;
use pyo3::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// One problem: (file, line (1-based, 0 unknown), key, message).
type ProblemRow = (String, usize, String, String);

/// (status, data (S, NCH), control (S, NCTRL), events, alarms, warnings, nonfinite_dropped).
type RunOut<'py> = (
    String,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
    Vec<(f64, String, String, String, String)>,
    Vec<(usize, f64, f64, f64)>,
    Vec<String>,
    usize,
);

fn problems(ps: Vec<popup_core::scenario::Problem>) -> Vec<ProblemRow> {
    ps.into_iter().map(|p| (p.file, p.line, p.key, p.message)).collect()
}

/// Every problem of a scenario text (empty when valid). Arm files are relative to
/// `base_dir`.
#[pyfunction]
#[pyo3(signature = (text, source = "<scenario>", base_dir = "."))]
pub fn check_scenario(text: &str, source: &str, base_dir: &str) -> Vec<ProblemRow> {
    match Scenario::parse(text, source, Path::new(base_dir)) {
        Ok(_) => Vec::new(),
        Err(ps) => problems(ps),
    }
}

/// The scenario text with the numeric key `path` (`payload_kg`, `pressure_pa[1]`,
/// `controller.gains.vel_kp`, ...) set to `value`.
#[pyfunction]
pub fn scenario_set_key(py: Python<'_>, text: &str, path: &str, value: f64) -> PyResult<String> {
    set_key(text, path, value).map_err(|p| make(py, "InputError", &format!("input {p}")))
}

/// Run a scenario (its duration and seed unless given), logging it to the MCAP file `out`
/// when set, with the GIL released; returns the arrays the run produced (the samples the
/// log holds, noise included).
#[pyfunction]
#[pyo3(signature = (text, source = "<scenario>", base_dir = ".", out = None, duration = None, seed = None))]
#[allow(clippy::too_many_arguments)]
pub fn run_scenario<'py>(
    py: Python<'py>,
    text: &str,
    source: &str,
    base_dir: &str,
    out: Option<String>,
    duration: Option<f64>,
    seed: Option<u64>,
) -> PyResult<RunOut<'py>> {
    let mut sc = Scenario::parse(text, source, Path::new(base_dir)).map_err(|ps| {
        let msg: Vec<String> = ps.iter().map(|p| p.to_string()).collect();
        make(py, "ScenarioError", &msg.join("\n"))
    })?;
    if let Some(d) = duration {
        sc.closed.duration = check_duration("duration", d).py()?;
    }
    if let Some(s) = seed {
        sc.seed = s;
    }
    // Ctrl-C stops the run and finishes the log; then Python's KeyboardInterrupt is raised
    let (stop, armed) = StopFlags::register();
    let res = py.detach(move || {
        let mut col = Collect::default();
        let mut extra = BTreeMap::new();
        extra.insert("command".to_string(), "popup.Scenario.run (Python)".to_string());
        let o = execute(&sc, out.as_deref().map(Path::new), &mut Progress::silent(stop), extra, Some(&mut col));
        o.map(|o| (o, col))
    });
    drop(armed);
    py.check_signals()?;
    let (o, col) = res.py()?;
    let ns = col.data.len() / NCH;
    let data = Array2::from_shape_vec((ns, NCH), col.data).expect("rows of NCH");
    let ctrl = Array2::from_shape_vec((col.ctrl.len() / NCTRL, NCTRL), col.ctrl).expect("rows of NCTRL");
    let events = col.events.into_iter().map(|e| (e.t, e.kind.to_string(), e.from, e.to, e.detail)).collect();
    let alarms = o.alarms.iter().map(|a| (a.link, a.t_start, a.t_end, a.peak_ratio)).collect();
    Ok((o.status.name().to_string(), data.into_pyarray(py), ctrl.into_pyarray(py), events, alarms, o.warnings, o.nonfinite))
}
