//! Frequency analysis: the linearised arm (`popup_core::linear`) over a batch of operating
//! points, and the controller numbers the Python side needs to close the loop around it.

use crate::errors::{describe, make, IntoPy};
use crate::model::PyModel;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyReadonlyArray1, PyReadonlyArray2};
use popup_core::control::config::parse_control;
use popup_core::linear::{linearize_at_rest, LinearInput};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::channel_index;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Linearise the arm about the static equilibrium at each operating point of a batch.
///
/// `payload_kg` (B,), `pressure_pa` (B, 2), `q_motor` (B, 3) [rad]; `input` one of
/// "torque", "acceleration", "locked"; `outputs` channel names; `effects` (B, NE) or None
/// (the arm's). Returns a dict: `a` (B, 2n, 2n), `b` (B, 2n, m), `c` (B, p, 2n), `d`
/// (B, p, m), `q0` (B, nv) operating-point coordinates, `u0` (B, m), `y0` (B, p), `states`,
/// `inputs`, `outputs` (names), `free` (chain indices of the state's joints), `warnings`
/// (per row).
#[pyfunction]
#[pyo3(signature = (model, payload_kg, pressure_pa, q_motor, input, outputs, t = 0.0, effects = None))]
#[allow(clippy::too_many_arguments)]
pub fn linearize<'py>(
    py: Python<'py>,
    model: &PyModel,
    payload_kg: PyReadonlyArray1<'py, f64>,
    pressure_pa: PyReadonlyArray2<'py, f64>,
    q_motor: PyReadonlyArray2<'py, f64>,
    input: &str,
    outputs: Vec<String>,
    t: f64,
    effects: Option<PyReadonlyArray2<'py, f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let bad = |m: String| make(py, "InputError", &m);
    let kind = LinearInput::parse(input).py()?;
    let pay = payload_kg.as_array().to_owned();
    let nb = pay.len();
    let pres = pressure_pa.as_array().to_owned();
    let qm = q_motor.as_array().to_owned();
    if pres.shape() != [nb, 2] {
        return Err(bad(format!("input pressure_pa: expected shape ({nb}, 2), got {:?}", pres.shape())));
    }
    if qm.shape() != [nb, 3] {
        return Err(bad(format!("input q_motor: expected shape ({nb}, 3), got {:?}", qm.shape())));
    }
    let mut out_idx = Vec::with_capacity(outputs.len());
    for o in &outputs {
        match channel_index(o) {
            Some(i) => out_idx.push(i),
            None => return Err(bad(format!("input outputs: unknown channel {o:?}; channels are {:?}", popup_core::sensor::CHANNELS))),
        }
    }
    let fx = crate::model::effects_rows(py, effects, nb, model.m.spec.effects)?;
    let m = model.m.clone();
    // Ctrl-C: the helper thread stops between operating points (each takes milliseconds)
    let res = crate::errors::interruptible(py, move |stop| -> Vec<popup_core::Result<(popup_core::linear::LinearModel, Vec<String>)>> {
        (0..nb)
            .take_while(|_| !stop.load(std::sync::atomic::Ordering::Relaxed))
            .map(|b| {
                let pd = ParamData::new(&m, &Params { payload_kg: pay[b], pressure_pa: [pres[[b, 0]], pres[[b, 1]]], effects: fx[b] })?;
                let lin = linearize_at_rest(&m, &pd, [qm[[b, 0]], qm[[b, 1]], qm[[b, 2]]], kind, &out_idx, t)?;
                Ok((lin, pd.warnings.clone()))
            })
            .collect()
    })?;
    let mut lins = Vec::with_capacity(nb);
    for (b, r) in res.into_iter().enumerate() {
        match r {
            Ok(x) => lins.push(x),
            Err(e) => {
                let (cls, msg) = describe(&e);
                return Err(make(py, &cls, &format!("{msg} (operating point {b})")));
            }
        }
    }
    let nv = model.m.nv;
    let (n2, mu, p) = if let Some((l, _)) = lins.first() { (l.a.nrows(), l.b.ncols(), l.c.nrows()) } else { (0, 0, outputs.len()) };
    let mut a = Array3::<f64>::zeros((nb, n2, n2));
    let mut bm = Array3::<f64>::zeros((nb, n2, mu));
    let mut c = Array3::<f64>::zeros((nb, p, n2));
    let mut d = Array3::<f64>::zeros((nb, p, mu));
    let mut q0 = Array2::<f64>::zeros((nb, nv));
    let mut u0 = Array2::<f64>::zeros((nb, mu));
    let mut y0 = Array2::<f64>::zeros((nb, p));
    let mut warnings = Vec::with_capacity(nb);
    for (k, (l, w)) in lins.iter().enumerate() {
        for i in 0..n2 {
            for j in 0..n2 {
                a[[k, i, j]] = l.a[(i, j)];
            }
            for j in 0..mu {
                bm[[k, i, j]] = l.b[(i, j)];
            }
        }
        for i in 0..p {
            for j in 0..n2 {
                c[[k, i, j]] = l.c[(i, j)];
            }
            for j in 0..mu {
                d[[k, i, j]] = l.d[(i, j)];
            }
            y0[[k, i]] = l.y0[i];
        }
        for j in 0..nv {
            q0[[k, j]] = l.q0[j];
        }
        for j in 0..mu {
            u0[[k, j]] = l.u0[j];
        }
        warnings.push(w.clone());
    }
    let out = PyDict::new(py);
    out.set_item("a", a.into_pyarray(py))?;
    out.set_item("b", bm.into_pyarray(py))?;
    out.set_item("c", c.into_pyarray(py))?;
    out.set_item("d", d.into_pyarray(py))?;
    out.set_item("q0", q0.into_pyarray(py))?;
    out.set_item("u0", u0.into_pyarray(py))?;
    out.set_item("y0", y0.into_pyarray(py))?;
    let first = lins.first().map(|(l, _)| l);
    out.set_item("states", first.map(|l| l.states.clone()).unwrap_or_default())?;
    out.set_item("inputs", first.map(|l| l.inputs.clone()).unwrap_or_default())?;
    out.set_item("outputs", outputs)?;
    out.set_item("free", first.map(|l| l.free.clone()).unwrap_or_default())?;
    out.set_item("warnings", warnings)?;
    Ok(out)
}

/// The controller of a control file as numbers: `rate_hz`, `gains` (flat, `gain_names()`
/// order), `motors` (three dicts: `gear_ratio`, `torque_per_unit`, `tau_max`,
/// `current_bandwidth`, `encoder_counts`), `damping` (three bools), `damping_lpf_rad_s`,
/// `v_max`, `anti_windup`, `cartesian_arm`. Raises the parser's error otherwise.
#[pyfunction]
#[pyo3(signature = (model, text, source = "<control>"))]
pub fn controller_params<'py>(py: Python<'py>, model: &PyModel, text: &str, source: &str) -> PyResult<Bound<'py, PyDict>> {
    let cf = parse_control(&model.m, text, source).py()?;
    let c = cf.controller;
    let out = PyDict::new(py);
    out.set_item("rate_hz", c.rate_hz)?;
    out.set_item("gains", c.gains.to_flat().to_vec())?;
    let mut motors = Vec::with_capacity(3);
    for m in c.motors.iter() {
        let d = PyDict::new(py);
        d.set_item("gear_ratio", m.gear_ratio)?;
        d.set_item("torque_per_unit", m.torque_per_unit)?;
        d.set_item("tau_max", m.tau_max)?;
        d.set_item("current_bandwidth", m.current_bandwidth)?;
        d.set_item("encoder_counts", m.encoder_counts)?;
        motors.push(d);
    }
    out.set_item("motors", motors)?;
    out.set_item("damping", c.damping.to_vec())?;
    out.set_item("damping_lpf_rad_s", c.damping_lpf)?;
    out.set_item("v_max", c.v_max)?;
    out.set_item("anti_windup", c.anti_windup)?;
    out.set_item(
        "cartesian_arm",
        match c.cartesian_arm {
            popup_core::control::CartesianArm::Prbm => "prbm",
            popup_core::control::CartesianArm::AsBuilt => "as_built",
            popup_core::control::CartesianArm::Ik => "ik",
        },
    )?;
    Ok(out)
}
