//! `Model` (wraps an `Arc<popup_core::model::Model>`) and its batched rollout.
//!
//! Array inputs are copied into Rust-owned buffers before the GIL is released, so another
//! Python thread cannot mutate them during a run.

use crate::arm::PyArm;
use crate::errors::{describe, interruptible, make, IntoPy};
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::effects::{Effects, NE};
use popup_core::kinematics::prbm::frames;
use popup_core::math::VecN;
use popup_core::model::{Disable, Integrator, Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::limits::{check_collected, check_steps};
use popup_core::rollout::{rollout_cached, Job, MotionCache};
use popup_core::sensor::{CHANNELS, NCH, UNITS};
use popup_core::sim::{check_sample_period, check_step, rest_state, RunConfig, State};
use popup_core::statics;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// A compiled arm with its simulation options. Immutable and thread-safe; payload and
/// pressures are per-call parameters.
#[pyclass(name = "Model", module = "popup._core", frozen)]
pub struct PyModel {
    pub m: Arc<Model>,
    /// Motions of recent rollouts that jobs shared (`popup_core::rollout::MotionCache`).
    pub motion: Arc<MotionCache>,
}

/// A joint vector of the model (`nv` values; the capacity beyond stays 0).
fn vecn(py: Python<'_>, m: &Model, what: &str, q: &[f64]) -> PyResult<VecN> {
    if q.len() != m.nv {
        return Err(make(py, "InputError", &format!("input {what}: expected {} joint values, got {}", m.nv, q.len())));
    }
    Ok(VecN::from_fn(|i, _| if i < q.len() { q[i] } else { 0.0 }))
}

impl PyModel {
    /// ParamData at the arm's default pressures (M and G do not depend on pressure).
    fn pd_default_pressure(&self, payload_kg: f64) -> PyResult<ParamData> {
        let l = &self.m.spec.links;
        self.pd(payload_kg, [l[0].pressure_pa, l[1].pressure_pa])
    }

    fn pd(&self, payload_kg: f64, pressure_pa: [f64; 2]) -> PyResult<ParamData> {
        ParamData::new(&self.m, &Params { payload_kg, pressure_pa, effects: self.m.spec.effects }).py()
    }
}

/// Result of a batched rollout: (data (B, S, NCH), errors, alarms, warnings).
type RolloutOut<'py> = (
    Bound<'py, PyArray3<f64>>,
    Vec<Option<(String, String)>>,
    Vec<Vec<(usize, f64, f64, f64)>>,
    Vec<Vec<String>>,
);

#[pymethods]
impl PyModel {
    /// Compile `arm` with the given options. `disable` lists force terms to switch off:
    /// any of "gravity", "spring", "damper".
    #[new]
    #[pyo3(signature = (arm, dt = 1e-3, integrator = "rk4", gravity = None, disable = Vec::new()))]
    fn new(py: Python<'_>, arm: PyRef<'_, PyArm>, dt: f64, integrator: &str, gravity: Option<[f64; 3]>, disable: Vec<String>) -> PyResult<Self> {
        let mut d = Disable::default();
        for s in &disable {
            match s.as_str() {
                "gravity" => d.gravity = true,
                "spring" => d.spring = true,
                "damper" => d.damper = true,
                other => return Err(make(py, "ParameterError", &format!("invalid parameter disable = {other:?}: must be one of \"gravity\", \"spring\", \"damper\""))),
            }
        }
        let options = Options { dt, integrator: Integrator::parse(integrator).py()?, gravity, disable: d, ..Options::default() };
        Ok(PyModel { m: Arc::new(Model::compile(&arm.spec, options).py()?), motion: Arc::default() })
    }

    /// The arm this model was compiled from.
    #[getter]
    fn arm(&self) -> PyArm {
        PyArm { spec: self.m.spec.clone() }
    }
    /// Physics time step [s].
    #[getter]
    fn dt(&self) -> f64 {
        self.m.options.dt
    }

    /// Rollout jobs computed from the kept motion of an earlier batch (no physics run) so
    /// far: jobs that differ from it only in friction, saturation or a sensor group's delay.
    #[getter]
    fn motion_hits(&self) -> usize {
        self.motion.hits()
    }
    /// Integrator name.
    #[getter]
    fn integrator(&self) -> &'static str {
        self.m.options.integrator.name()
    }
    /// Global order of the integrator.
    #[getter]
    fn integrator_order(&self) -> u32 {
        self.m.options.integrator.order()
    }
    /// Disabled force terms.
    #[getter]
    fn disabled(&self) -> Vec<&'static str> {
        let d = self.m.options.disable;
        let mut v = Vec::new();
        if d.gravity {
            v.push("gravity");
        }
        if d.spring {
            v.push("spring");
        }
        if d.damper {
            v.push("damper");
        }
        v
    }
    /// Gravity in the base frame [m/s²] (zero when disabled).
    #[getter]
    fn gravity(&self) -> [f64; 3] {
        [self.m.gravity.x, self.m.gravity.y, self.m.gravity.z]
    }
    /// Joint names in chain order.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.m.joints.iter().map(|j| j.name.clone()).collect()
    }
    /// Link models, link 1 and 2: `"rigid"`, `"prbm"`, `"prbm(S)"` (S segments) or `"beam(n)"`.
    #[getter]
    fn link_models(&self) -> Vec<String> {
        (0..2).map(|l| self.m.structure.link_name(l)).collect()
    }
    /// Chain indices of the motor joints.
    #[getter]
    fn motor_index(&self) -> Vec<usize> {
        self.m.motor_idx.to_vec()
    }
    /// Chain indices of the bending joints.
    #[getter]
    fn bend_index(&self) -> Vec<usize> {
        self.m.bend().to_vec()
    }
    /// Chain indices of the locked joints (the universal joints of rigid links).
    #[getter]
    fn locked_index(&self) -> Vec<usize> {
        self.m.locked().to_vec()
    }
    /// Wrinkling coefficient c in M_w = c · p · r³.
    #[getter]
    fn wrinkle_coefficient(&self) -> f64 {
        self.m.wrinkle_coef
    }
    /// Output channel names (columns of rollout data).
    #[staticmethod]
    fn channels() -> Vec<&'static str> {
        CHANNELS.to_vec()
    }
    /// Units of the output channels.
    #[staticmethod]
    fn units() -> Vec<&'static str> {
        UNITS.to_vec()
    }
    /// The kind of sensor that records each output channel (`popup_core::sensor::SENSORS`).
    #[staticmethod]
    fn sensors() -> Vec<&'static str> {
        popup_core::sensor::SENSORS.to_vec()
    }

    /// Derived per-rollout numbers: dict(k, c, mw, warnings).
    fn param_data<'py>(&self, py: Python<'py>, payload_kg: f64, pressure_pa: [f64; 2]) -> PyResult<Bound<'py, PyDict>> {
        let pd = self.pd(payload_kg, pressure_pa)?;
        let d = PyDict::new(py);
        d.set_item("k", pd.k[..self.m.nv].to_vec())?;
        d.set_item("c", pd.c[..self.m.nv].to_vec())?;
        d.set_item("mw", pd.mw.to_vec())?;
        d.set_item("warnings", pd.warnings.clone())?;
        Ok(d)
    }

    /// Joint coordinates (nv,) (7 for the arm file's chain) at rest: motors at `q_motor`, bending joints in static
    /// equilibrium.
    fn rest_state<'py>(&self, py: Python<'py>, payload_kg: f64, pressure_pa: [f64; 2], q_motor: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let q_motor = crate::arm::three("q_motor", &q_motor, "motor angles q1, q2, q3 [rad]")?;
        let pd = self.pd(payload_kg, pressure_pa)?;
        let st = rest_state(&self.m, &pd, 0.0, q_motor).py()?;
        Ok(PyArray1::from_slice(py, &st.q.as_slice()[..self.m.nv]))
    }

    /// Locked-motor natural frequencies of the passive joints about q (nv,) [rad/s].
    fn locked_modes<'py>(&self, py: Python<'py>, payload_kg: f64, pressure_pa: [f64; 2], q: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let pd = self.pd(payload_kg, pressure_pa)?;
        let q = vecn(py, &self.m, "q", &q)?;
        Ok(PyArray1::from_slice(py, &statics::locked_modes(&self.m, &pd, &q)))
    }

    /// Mass matrix (nv, nv) with armature [kg·m²].
    fn mass_matrix<'py>(&self, py: Python<'py>, payload_kg: f64, q: Vec<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let pd = self.pd_default_pressure(payload_kg)?;
        let m = statics::mass_matrix(&self.m, &pd, &vecn(py, &self.m, "q", &q)?);
        let nv = self.m.nv;
        Ok(Array2::from_shape_fn((nv, nv), |(i, j)| m[(i, j)]).into_pyarray(py))
    }

    /// Generalised gravity forces G(q) (nv,) [N·m].
    fn gravity_torque<'py>(&self, py: Python<'py>, payload_kg: f64, q: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let pd = self.pd_default_pressure(payload_kg)?;
        let g = statics::gravity_torque(&self.m, &pd, &vecn(py, &self.m, "q", &q)?);
        Ok(PyArray1::from_slice(py, &g.as_slice()[..self.m.nv]))
    }

    /// Homogeneous transforms T_W_i of frames 0..nv, shape (nv + 1, 4, 4).
    fn frames<'py>(&self, py: Python<'py>, q: Vec<f64>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let f = frames(&self.m, &vecn(py, &self.m, "q", &q)?);
        let nv = self.m.nv;
        let mut out = Array3::<f64>::zeros((nv + 1, 4, 4));
        for i in 0..=nv {
            for a in 0..3 {
                for b in 0..3 {
                    out[[i, a, b]] = f.r_wb[i][(a, b)];
                }
                out[[i, a, 3]] = f.p_wb[i][a];
            }
            out[[i, 3, 3]] = 1.0;
        }
        Ok(out.into_pyarray(py))
    }

    /// End-effector position p_WE (3,) [m].
    fn end_effector<'py>(&self, py: Python<'py>, q: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let p = popup_core::kinematics::prbm::end_effector(&self.m, &vecn(py, &self.m, "q", &q)?);
        Ok(PyArray1::from_slice(py, p.as_slice()))
    }

    /// Raise `StepTooLargeError` if dt is outside the integrator's stability region for
    /// the arm linearised about q (free joints: bending only when `replay`).
    fn check_step(&self, py: Python<'_>, payload_kg: f64, pressure_pa: [f64; 2], q: Vec<f64>, replay: bool) -> PyResult<()> {
        let pd = self.pd(payload_kg, pressure_pa)?;
        check_step(&self.m, &pd, &vecn(py, &self.m, "q", &q)?, replay).py()
    }

    /// Batched rollout (GIL released, `threads` rayon threads, 0 = all cores).
    ///
    /// payload_kg (B,), pressure_pa (B, 2); drive "torque" or "replay"; times (N,) shared
    /// by all jobs; values (B, N, 3): torques [N·m] or encoder angles [rad];
    /// initial_q/initial_v (B, nv) or None (rest state); t0 start time for torque runs;
    /// duration [s] (None for replay = span of `times`); sample_period [s].
    /// Returns (data (B, S, NCH), errors [None | (class, message)], alarms
    /// [[(link, t_start, t_end, peak_ratio)]], warnings [[str]]). Failed rows are NaN.
    /// effects (B, NE) or None: flat effect parameters per job (registry order, see
    /// `effect_registry()`); None = the arm's `[effects]`.
    /// log: MCAP path to stream the run into (B must be 1), with `log_experiment` the
    /// measured-run experiment TOML of its `experiment` metadata record.
    #[pyo3(signature = (payload_kg, pressure_pa, drive, times, values, initial_q = None, initial_v = None, duration = None, sample_period = 1e-3, threads = 0, check_step = true, effects = None, log = None, log_experiment = None))]
    #[allow(clippy::too_many_arguments)]
    fn rollout<'py>(
        &self,
        py: Python<'py>,
        payload_kg: PyReadonlyArray1<'py, f64>,
        pressure_pa: PyReadonlyArray2<'py, f64>,
        drive: &str,
        times: PyReadonlyArray1<'py, f64>,
        values: PyReadonlyArray3<'py, f64>,
        initial_q: Option<PyReadonlyArray2<'py, f64>>,
        initial_v: Option<PyReadonlyArray2<'py, f64>>,
        duration: Option<f64>,
        sample_period: f64,
        threads: i64,
        check_step: bool,
        effects: Option<PyReadonlyArray2<'py, f64>>,
        log: Option<String>,
        log_experiment: Option<String>,
    ) -> PyResult<RolloutOut<'py>> {
        let bad = |m: String| make(py, "InputError", &m);
        let payload = payload_kg.as_array().to_owned();
        let pressure = pressure_pa.as_array().to_owned();
        let t = times.as_array().to_vec();
        let vals = values.as_array().to_owned();
        let nb = payload.len();
        if pressure.shape() != [nb, 2] {
            return Err(bad(format!("input pressure_pa: expected shape ({nb}, 2), got {:?}", pressure.shape())));
        }
        if vals.shape()[0] != nb || vals.shape()[2] != 3 || vals.shape()[1] != t.len() {
            return Err(bad(format!("input values: expected shape ({nb}, {}, 3), got {:?}", t.len(), vals.shape())));
        }
        let fx = effects_rows(py, effects, nb, self.m.spec.effects)?;
        let iq = initial_q.map(|a| a.as_array().to_owned());
        let iv = initial_v.map(|a| a.as_array().to_owned());
        for (name, a) in [("initial_q", &iq), ("initial_v", &iv)] {
            if let Some(a) = a {
                if a.shape() != [nb, self.m.nv] {
                    return Err(bad(format!("input {name}: expected shape ({nb}, {}), got {:?}", self.m.nv, a.shape())));
                }
            }
        }
        if iq.is_none() && iv.is_some() {
            return Err(bad("input initial_v: given without initial_q".into()));
        }
        let is_replay = match drive {
            "torque" => false,
            "replay" => true,
            other => return Err(bad(format!("input drive: {other:?} must be \"torque\" or \"replay\""))),
        };
        let nv = self.m.nv;
        let mut jobs = Vec::with_capacity(nb);
        for b in 0..nb {
            let rows: Vec<[f64; 3]> = (0..t.len()).map(|k| [vals[[b, k, 0]], vals[[b, k, 1]], vals[[b, k, 2]]]).collect();
            let drv = if is_replay { Drive::Replay(Spline3::new(&t, &rows).py()?) } else { Drive::Torque(Linear3::new(&t, &rows).py()?) };
            let initial = iq.as_ref().map(|q| State {
                t: t[0],
                q: VecN::from_fn(|i, _| if i < nv { q[[b, i]] } else { 0.0 }),
                v: VecN::from_fn(|i, _| if i < nv { iv.as_ref().map_or(0.0, |v| v[[b, i]]) } else { 0.0 }),
            });
            jobs.push(Job {
                params: Params { payload_kg: payload[b], pressure_pa: [pressure[[b, 0]], pressure[[b, 1]]], effects: fx[b] },
                run: RunConfig { drive: drv, initial, duration, sample_period, check_step },
            });
        }
        let threads = crate::errors::threads("threads", threads)?;
        // bounded work: steps and collected samples are checked before anything runs
        let dt = self.m.options.dt;
        let (what, span) = match (is_replay, duration) {
            (true, None) => ("replay span (last encoder time - first)", t.last().copied().unwrap_or(0.0) - t.first().copied().unwrap_or(0.0)),
            (_, d) => ("duration", d.unwrap_or(0.0)),
        };
        let nstep = check_steps(what, span, dt).py()?;
        let every = check_sample_period(sample_period, dt).py()?;
        check_collected(nb, (nstep / every + 1) as f64, NCH).py()?;
        let model = self.m.clone();
        let motion = self.motion.clone();
        let results = match log {
            None => interruptible(py, move |stop| rollout_cached(&model, &jobs, threads, stop, Some(&motion)))?,
            Some(path) if nb == 1 => vec![interruptible(py, move |stop| logged(&model, &jobs[0], &path, log_experiment.unwrap_or_default(), stop))?],
            Some(_) => return Err(bad(format!("input log: one MCAP file logs one run; got a batch of {nb}"))),
        };
        let ns = crate::errors::batch_nsample(&results, |t| t.nsample)?;
        let mut data = Array3::<f64>::from_elem((nb, ns, NCH), f64::NAN);
        let mut errors = Vec::with_capacity(nb);
        let mut alarms = Vec::with_capacity(nb);
        let mut warnings = Vec::with_capacity(nb);
        for (b, r) in results.into_iter().enumerate() {
            match r {
                Ok(tr) => {
                    if tr.nsample != ns {
                        return Err(bad(format!("rollout: job {b} produced {} samples, job 0 {ns}; give every job the same duration", tr.nsample)));
                    }
                    let a = Array2::from_shape_vec((ns, NCH), tr.data).expect("shape");
                    data.index_axis_mut(numpy::ndarray::Axis(0), b).assign(&a);
                    errors.push(None);
                    alarms.push(tr.alarms.iter().map(|a| (a.link, a.t_start, a.t_end, a.peak_ratio)).collect());
                    warnings.push(tr.warnings);
                }
                Err(e) => {
                    errors.push(Some(describe(&e)));
                    alarms.push(Vec::new());
                    warnings.push(Vec::new());
                }
            }
        }
        Ok((data.into_pyarray(py), errors, alarms, warnings))
    }

    fn __repr__(&self) -> String {
        format!("Model(arm={:?}, dt={}, integrator={:?})", self.m.spec.name, self.m.options.dt, self.m.options.integrator.name())
    }
}

/// The effect-parameter registry, in flat-vector order: one tuple per parameter
/// (effect, name, unit, length, neutral, lower, upper, fitted by default, integer, doc).
#[pyfunction]
#[allow(clippy::type_complexity)]
pub fn effect_registry() -> Vec<(&'static str, &'static str, &'static str, usize, f64, f64, f64, bool, bool, &'static str)> {
    popup_core::effects::PARAMS.iter().map(|p| (p.effect, p.name, p.unit, p.len, p.neutral, p.lo, p.hi, p.fit, p.integer, p.doc)).collect()
}

/// The shaping parameters (effect, name): they change nothing while their effect's
/// strength is neutral (`popup_core::effects::SHAPING`).
#[pyfunction]
pub fn effect_shaping() -> Vec<(&'static str, &'static str)> {
    popup_core::effects::SHAPING.to_vec()
}

/// The effect parameters that act on the sensor rows only in encoder replay, with the
/// prefix of the channels they act on: (effect, name or "*", channel prefix)
/// (`popup_core::effects::OUTPUT_ONLY_IN_REPLAY`).
#[pyfunction]
pub fn effect_output_only() -> Vec<(&'static str, &'static str, &'static str)> {
    popup_core::effects::OUTPUT_ONLY_IN_REPLAY.to_vec()
}

/// One open-loop run streamed into an MCAP log and collected.
fn logged(model: &Model, job: &Job, path: &str, experiment: String, stop: &std::sync::atomic::AtomicBool) -> popup_core::Result<popup_core::sim::Trajectory> {
    use popup_core::log::{LogOptions, McapLogger, RunMeta};
    use popup_core::stream::{Collect, Stoppable, Tee};
    let pd = ParamData::new(model, &job.params)?;
    let meta = RunMeta { experiment_toml: experiment, ..RunMeta::default() };
    let mut lg = McapLogger::create(std::path::Path::new(path), model, &LogOptions::default(), &meta, job.run.sample_period, 0.05)?;
    let mut col = Collect::default();
    let res = popup_core::sim::run_into(model, &pd, &job.run, &mut Stoppable { inner: &mut Tee { a: &mut col, b: &mut lg }, flag: stop });
    match res {
        Ok(end) => {
            lg.finish(if stop.load(std::sync::atomic::Ordering::SeqCst) { "interrupted" } else { "completed" })?;
            Ok(popup_core::sim::Trajectory { data: col.data, nsample: end.nsample, alarms: end.alarms, final_state: end.final_state, warnings: pd.warnings.clone() })
        }
        Err(e) => {
            let _ = lg.finish("failed");
            Err(e)
        }
    }
}

/// Effects of each of `nb` jobs from a flat `(nb, NE)` array (registry order), or `default`
/// for every job. Errors name the bad row (and, through the core, the parameter).
pub(crate) fn effects_rows(py: Python<'_>, effects: Option<PyReadonlyArray2<'_, f64>>, nb: usize, default: Effects) -> PyResult<Vec<Effects>> {
    let Some(a) = effects else {
        return Ok(vec![default; nb]);
    };
    let a = a.as_array();
    if a.shape() != [nb, NE] {
        return Err(make(py, "InputError", &format!("input effects: expected shape ({nb}, {NE}), got {:?}", a.shape())));
    }
    (0..nb)
        .map(|b| {
            Effects::from_flat(&a.row(b).to_vec()).map_err(|e| {
                let (cls, msg) = describe(&e);
                make(py, &cls, &format!("{msg} (effects row {b})"))
            })
        })
        .collect()
}
