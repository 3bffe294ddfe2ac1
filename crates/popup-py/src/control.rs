//! Closed-loop rollouts: a control file (TOML, the `popup.control` format) plus per-job
//! parameters, gains and initial motor angles, run in parallel with the GIL released.

use crate::errors::{describe, make, IntoPy};
use crate::model::PyModel;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray3, PyReadonlyArray1, PyReadonlyArray2};
use popup_core::control::config::{parse_control, ControlFile};
use popup_core::control::{gain_names, rollout_closed_until, ClosedLoop, Gains, CTRL_CHANNELS, NCTRL, NG};
use popup_core::params::Params;
use popup_core::sensor::NCH;
use pyo3::prelude::*;

/// One log entry: (t, kind, from, to, detail).
type EventRow = (f64, String, String, String, String);

/// (data (B, S, NCH), control (B, S, NCTRL), errors, events, status, alarms, warnings).
type ClosedOut<'py> = (
    Bound<'py, PyArray3<f64>>,
    Bound<'py, PyArray3<f64>>,
    Vec<Option<(String, String)>>,
    Vec<Vec<EventRow>>,
    Vec<String>,
    Vec<Vec<(usize, f64, f64, f64)>>,
    Vec<Vec<String>>,
);

/// Controller channel names.
#[pyfunction]
pub fn control_channels() -> Vec<&'static str> {
    CTRL_CHANNELS.to_vec()
}

/// Flat gain names (the columns of `gains` in `closed_loop_rollout`).
#[pyfunction(name = "gain_names")]
pub fn py_gain_names() -> Vec<String> {
    gain_names()
}

/// Parse and validate a control file for `model`; returns the flat default gains of the
/// file and the number of phases. Raises the core's error (file, line, key) otherwise.
#[pyfunction]
#[pyo3(signature = (model, text, source = "<control>"))]
pub fn check_control(model: &PyModel, text: &str, source: &str) -> PyResult<(Vec<f64>, usize)> {
    let cf = parse_control(&model.m, text, source).py()?;
    Ok((cf.controller.gains.to_flat().to_vec(), cf.sequence.phases.len()))
}

/// Batched closed-loop runs. `payload_kg` (B,), `pressure_pa` (B, 2), `q0` (B, 3) initial
/// motor angles [rad] (at rest, bending in equilibrium), `gains` (B, NG) or None (the file's),
/// `effects` (B, NE) or None (the arm's). Results are bit-identical for any `threads`.
#[pyfunction]
#[pyo3(signature = (model, text, payload_kg, pressure_pa, q0, duration, sample_period, gains = None, effects = None, threads = 0, check_step = true, source = "<control>"))]
#[allow(clippy::too_many_arguments)]
pub fn closed_loop_rollout<'py>(
    py: Python<'py>,
    model: &PyModel,
    text: &str,
    payload_kg: PyReadonlyArray1<'py, f64>,
    pressure_pa: PyReadonlyArray2<'py, f64>,
    q0: PyReadonlyArray2<'py, f64>,
    duration: f64,
    sample_period: f64,
    gains: Option<PyReadonlyArray2<'py, f64>>,
    effects: Option<PyReadonlyArray2<'py, f64>>,
    threads: i64,
    check_step: bool,
    source: &str,
) -> PyResult<ClosedOut<'py>> {
    let cf = parse_control(&model.m, text, source).py()?;
    closed_rollout(py, model, vec![cf], payload_kg, pressure_pa, q0, duration, sample_period, gains, effects, threads, check_step, source)
}

/// [`closed_loop_rollout`] with one control file per job (`texts`, length B): the task, its
/// reference signals and the controller may differ between the runs of one batch (a
/// stepped sine is one call, one frequency per job). `gains` (B, NG) overrides each file's
/// gains when given.
#[pyfunction]
#[pyo3(signature = (model, texts, payload_kg, pressure_pa, q0, duration, sample_period, gains = None, effects = None, threads = 0, check_step = true, source = "<control>"))]
#[allow(clippy::too_many_arguments)]
pub fn closed_loop_rollout_multi<'py>(
    py: Python<'py>,
    model: &PyModel,
    texts: Vec<String>,
    payload_kg: PyReadonlyArray1<'py, f64>,
    pressure_pa: PyReadonlyArray2<'py, f64>,
    q0: PyReadonlyArray2<'py, f64>,
    duration: f64,
    sample_period: f64,
    gains: Option<PyReadonlyArray2<'py, f64>>,
    effects: Option<PyReadonlyArray2<'py, f64>>,
    threads: i64,
    check_step: bool,
    source: &str,
) -> PyResult<ClosedOut<'py>> {
    let nb = payload_kg.as_array().len();
    if texts.len() != nb {
        return Err(make(py, "InputError", &format!("input texts: expected {nb} control files (one per job), got {}", texts.len())));
    }
    let cfs = texts.iter().enumerate().map(|(b, t)| parse_control(&model.m, t, &format!("{source}[{b}]")).py()).collect::<PyResult<Vec<_>>>()?;
    closed_rollout(py, model, cfs, payload_kg, pressure_pa, q0, duration, sample_period, gains, effects, threads, check_step, source)
}

/// The batch of closed-loop runs: `cfs` holds one control file shared by every job or one
/// per job.
#[allow(clippy::too_many_arguments)]
fn closed_rollout<'py>(
    py: Python<'py>,
    model: &PyModel,
    cfs: Vec<ControlFile>,
    payload_kg: PyReadonlyArray1<'py, f64>,
    pressure_pa: PyReadonlyArray2<'py, f64>,
    q0: PyReadonlyArray2<'py, f64>,
    duration: f64,
    sample_period: f64,
    gains: Option<PyReadonlyArray2<'py, f64>>,
    effects: Option<PyReadonlyArray2<'py, f64>>,
    threads: i64,
    check_step: bool,
    source: &str,
) -> PyResult<ClosedOut<'py>> {
    let bad = |m: String| make(py, "InputError", &m);
    for (b, cf) in cfs.iter().enumerate() {
        if cf.sequence.phases.is_empty() {
            let which = if cfs.len() == 1 { source.to_string() } else { format!("{source}[{b}]") };
            return Err(bad(format!("input {which}: the control file has no [[phases]]")));
        }
    }
    let pay = payload_kg.as_array().to_owned();
    let nb = pay.len();
    let pres = pressure_pa.as_array().to_owned();
    let q0 = q0.as_array().to_owned();
    for (n, s, want) in [("pressure_pa", pres.shape().to_vec(), 2), ("q0", q0.shape().to_vec(), 3)] {
        if s != [nb, want] {
            return Err(bad(format!("input {n}: expected shape ({nb}, {want}), got {s:?}")));
        }
    }
    let g = gains.map(|a| a.as_array().to_owned());
    if let Some(g) = &g {
        if g.shape() != [nb, NG] {
            return Err(bad(format!("input gains: expected shape ({nb}, {NG}), got {:?}", g.shape())));
        }
    }
    let fx = crate::model::effects_rows(py, effects, nb, model.m.spec.effects)?;
    let mut jobs = Vec::with_capacity(nb);
    for b in 0..nb {
        let cf = &cfs[if cfs.len() == 1 { 0 } else { b }];
        let mut c = cf.controller;
        if let Some(g) = &g {
            let row: [f64; NG] = std::array::from_fn(|i| g[[b, i]]);
            c.gains = Gains::from_flat(&row);
        }
        let effects = fx[b];
        let params = Params { payload_kg: pay[b], pressure_pa: [pres[[b, 0]], pres[[b, 1]]], effects };
        let run = ClosedLoop {
            controller: c,
            sequence: cf.sequence.clone(),
            obstacles: cf.obstacles.clone(),
            payload_radius: cf.payload_radius,
            q0: [q0[[b, 0]], q0[[b, 1]], q0[[b, 2]]],
            initial: None,
            duration,
            sample_period,
            check_step,
        };
        jobs.push((params, run));
    }
    let threads = crate::errors::threads("threads", threads)?;
    // bounded work: steps and collected samples are checked before anything runs
    let dt = model.m.options.dt;
    let nstep = popup_core::limits::check_steps("duration", duration, dt).py()?;
    let every = popup_core::sim::check_sample_period(sample_period, dt).py()?;
    popup_core::limits::check_collected(nb, (nstep / every + 1) as f64, NCH + NCTRL).py()?;
    let m = model.m.clone();
    let results = crate::errors::interruptible(py, move |stop| rollout_closed_until(&m, &jobs, threads, stop))?;
    let ns = crate::errors::batch_nsample(&results, |t| t.traj.nsample)?;
    let mut data = Array3::<f64>::from_elem((nb, ns, NCH), f64::NAN);
    let mut ctrl = Array3::<f64>::from_elem((nb, ns, NCTRL), f64::NAN);
    let (mut errors, mut events, mut status, mut alarms, mut warnings) = (vec![], vec![], vec![], vec![], vec![]);
    for (b, r) in results.into_iter().enumerate() {
        match r {
            Ok(ct) => {
                let a = Array2::from_shape_vec((ns, NCH), ct.traj.data).expect("shape");
                data.index_axis_mut(numpy::ndarray::Axis(0), b).assign(&a);
                let a = Array2::from_shape_vec((ns, NCTRL), ct.control).expect("shape");
                ctrl.index_axis_mut(numpy::ndarray::Axis(0), b).assign(&a);
                errors.push(None);
                events.push(ct.events.into_iter().map(|e| (e.t, e.kind.to_string(), e.from, e.to, e.detail)).collect());
                status.push(ct.status.name().to_string());
                alarms.push(ct.traj.alarms.iter().map(|a| (a.link, a.t_start, a.t_end, a.peak_ratio)).collect());
                warnings.push(ct.traj.warnings);
            }
            Err(e) => {
                errors.push(Some(describe(&e)));
                events.push(Vec::new());
                status.push("error".to_string());
                alarms.push(Vec::new());
                warnings.push(Vec::new());
            }
        }
    }
    Ok((data.into_pyarray(py), ctrl.into_pyarray(py), errors, events, status, alarms, warnings))
}
