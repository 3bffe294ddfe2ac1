//! `popup._core`: thin PyO3 bindings of `popup-core`. The public Python API lives in the
//! `popup` package; this module mirrors the core's types (`PyArm` → `Arm`, `PyModel` →
//! `Model`, `PyRigidArm` → `RigidArm`).

mod arm;
mod cli;
mod control;
mod errors;
mod frequency;
mod model;
mod scenario;

use pyo3::prelude::*;

/// Raise an exception of the given `popup.exceptions` class from a core error description.
#[pyfunction]
fn _raise(py: Python<'_>, cls: &str, msg: &str) -> PyResult<()> {
    Err(errors::make(py, cls, msg))
}

/// One row of `_core.CHANNEL_LIMITS`: (columns, unit, min, warn, error, scale, advice).
type LimitRow = (Vec<&'static str>, &'static str, f64, f64, f64, &'static str, &'static str);

#[pymodule(gil_used = false)]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<arm::PyArm>()?;
    m.add_class::<arm::PyRigidArm>()?;
    m.add_class::<model::PyModel>()?;
    m.add_function(wrap_pyfunction!(_raise, m)?)?;
    m.add_function(wrap_pyfunction!(model::effect_registry, m)?)?;
    m.add_function(wrap_pyfunction!(model::effect_shaping, m)?)?;
    m.add_function(wrap_pyfunction!(model::effect_output_only, m)?)?;
    m.add("EFFECT_NAMES", popup_core::effects::EFFECT_NAMES.to_vec())?;
    let presets = pyo3::types::PyDict::new(m.py());
    for (name, mat) in popup_core::beam::PRESETS {
        let d = pyo3::types::PyDict::new(m.py());
        d.set_item("e_pa", mat.e)?;
        d.set_item("wall_m", mat.t)?;
        d.set_item("nu", mat.nu)?;
        d.set_item("lambda_s", mat.lambda)?;
        d.set_item("mu_per_s", mat.mu)?;
        presets.set_item(name, d)?;
    }
    m.add("BEAM_PRESETS", presets)?;
    // the one registry of bounds and measured-data plausibility limits (popup_core::limits)
    // (columns, unit, min, warn, error, scale, advice): warn/error in the unit when scale
    // is "", else factors of the arm's number (`Arm.channel_limits()` gives the numbers)
    let lim: Vec<LimitRow> =
        popup_core::limits::CHANNEL_LIMITS.iter().map(|l| (l.columns.to_vec(), l.unit, l.min, l.warn, l.error, l.scale.name(), l.advice)).collect();
    m.add("CHANNEL_LIMITS", lim)?;
    m.add("GAP_WARN_STEPS", popup_core::limits::GAP_WARN_STEPS)?;
    m.add("GAP_ERROR_STEPS", popup_core::limits::GAP_ERROR_STEPS)?;
    m.add("MAX_STEPS", popup_core::limits::MAX_STEPS)?;
    m.add_function(wrap_pyfunction!(cli::run_cli, m)?)?;
    m.add_function(wrap_pyfunction!(control::closed_loop_rollout, m)?)?;
    m.add_function(wrap_pyfunction!(control::closed_loop_rollout_multi, m)?)?;
    m.add_function(wrap_pyfunction!(frequency::linearize, m)?)?;
    m.add_function(wrap_pyfunction!(frequency::controller_params, m)?)?;
    m.add_function(wrap_pyfunction!(scenario::check_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(scenario::scenario_set_key, m)?)?;
    m.add_function(wrap_pyfunction!(scenario::run_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(control::check_control, m)?)?;
    m.add_function(wrap_pyfunction!(control::control_channels, m)?)?;
    m.add_function(wrap_pyfunction!(control::py_gain_names, m)?)?;
    m.add("__version__", popup_core::VERSION)?;
    m.add("BUILD_PROFILE", if cfg!(debug_assertions) { "debug" } else { "release" })?;
    m.add("BUILD_FEATURES", popup_core::BUILD_FEATURES.to_vec())?;
    Ok(())
}
