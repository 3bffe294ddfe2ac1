//! `Arm` (wraps `ArmSpec`) and `RigidArm` (rigid 3-DOF kinematics).

use crate::errors::{make, IntoPy};
use numpy::{PyArray1, PyArray2};
use popup_core::kinematics::rigid::{Elbow, RigidArm, Shoulder};
use popup_core::math::Vec3;
use popup_core::spec::ArmSpec;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};

/// One row of `Arm.channel_limits()`.
type ArmLimitRow = (Vec<String>, String, f64, f64, f64, String);

/// An arm description (the content of an arm file). Immutable; `with_overrides` returns
/// a modified copy.
#[pyclass(name = "Arm", module = "popup._core", frozen)]
#[derive(Clone)]
pub struct PyArm {
    pub spec: ArmSpec,
}

fn to_toml_value(path: &str, obj: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    let py = obj.py();
    if obj.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(obj.extract()?));
    }
    if obj.is_instance_of::<PyInt>() {
        return Ok(toml::Value::Float(obj.extract::<i64>()? as f64));
    }
    if obj.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(obj.extract()?));
    }
    if obj.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(obj.extract()?));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, v) in d.iter() {
            let k: String = k.extract()?;
            let p = format!("{path}.{k}");
            t.insert(k, to_toml_value(&p, &v)?);
        }
        return Ok(toml::Value::Table(t));
    }
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() || obj.hasattr("tolist")? {
        let seq = if obj.hasattr("tolist")? { obj.call_method0("tolist")? } else { obj.clone() };
        let mut a = Vec::new();
        for (i, v) in seq.try_iter()?.enumerate() {
            a.push(to_toml_value(&format!("{path}[{i}]"), &v?)?);
        }
        return Ok(toml::Value::Array(a));
    }
    Err(make(py, "ArmFileError", &format!("override {path}: cannot use a value of type {}", obj.get_type().name()?)))
}

/// Integer-valued keys of the arm schema (TOML integers, not floats).
const INT_KEYS: &[&str] = &["link", "body"];

fn fix_ints(v: &mut toml::Value) {
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t.iter_mut() {
                if INT_KEYS.contains(&k.as_str()) {
                    if let toml::Value::Float(f) = x {
                        *x = toml::Value::Integer(*f as i64);
                    }
                }
                fix_ints(x);
            }
        }
        toml::Value::Array(a) => a.iter_mut().for_each(fix_ints),
        _ => {}
    }
}

#[pymethods]
impl PyArm {
    /// A built-in arm by name (`"popup-lab"`).
    #[staticmethod]
    fn builtin(name: &str) -> PyResult<Self> {
        Ok(PyArm { spec: ArmSpec::builtin(name).py()? })
    }

    /// Names of the built-in arms (`popup-lab` and the packaged arm files, e.g.
    /// `popup-lab-thesis`): the one list every front end resolves names against.
    #[staticmethod]
    fn builtin_names() -> Vec<String> {
        ArmSpec::BUILTIN.iter().map(|s| s.to_string()).collect()
    }

    /// The text (with its comments) of the packaged arm file `name`; `None` for an arm that
    /// is not a packaged file (`popup-lab` is built in code).
    #[staticmethod]
    fn packaged_source(name: &str) -> Option<&'static str> {
        ArmSpec::packaged_source(name)
    }

    /// Parse an arm file's text; `source` names it in error messages.
    #[staticmethod]
    #[pyo3(signature = (text, source = "<string>"))]
    fn from_toml(text: &str, source: &str) -> PyResult<Self> {
        Ok(PyArm { spec: ArmSpec::from_toml(text, source).py()? })
    }

    /// Load an arm file (TOML) from `path`.
    #[staticmethod]
    fn load(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Self> {
        let text = std::fs::read_to_string(&path)
            .map_err(|e| make(py, "ArmFileError", &format!("arm file {}: cannot read: {e}", path.display())))?;
        Ok(PyArm { spec: ArmSpec::from_toml(&text, &path.display().to_string()).py()? })
    }

    /// Write the complete arm file (TOML) to `path`.
    fn save(&self, py: Python<'_>, path: std::path::PathBuf) -> PyResult<()> {
        std::fs::write(&path, self.spec.to_toml())
            .map_err(|e| make(py, "ArmFileError", &format!("arm file {}: cannot write: {e}", path.display())))
    }

    /// The complete arm file (TOML).
    fn to_toml(&self) -> String {
        self.spec.to_toml()
    }

    /// A copy with nested overrides merged in (dicts merge by key, lists of dicts by index).
    fn with_overrides(&self, overrides: &Bound<'_, PyDict>) -> PyResult<Self> {
        let mut v = to_toml_value("", overrides.as_any())?;
        fix_ints(&mut v);
        let t = match v {
            toml::Value::Table(t) => t,
            _ => unreachable!(),
        };
        Ok(PyArm { spec: self.spec.with_overrides(t, "<overrides>").py()? })
    }

    /// Arm name.
    #[getter]
    fn name(&self) -> String {
        self.spec.name.clone()
    }

    /// The plausibility limits of measured runs for this arm, in numbers: a list of
    /// `(columns, unit, min, warn_abs, error_abs, advice)`; torque limits from the drives
    /// (`motors.tau_max_nm`), acceleration limits from `reach()` (`popup_core::limits::for_arm`).
    fn channel_limits(&self, py: Python<'_>) -> PyResult<Vec<ArmLimitRow>> {
        let spec = self.spec.clone();
        let lims = py.detach(move || popup_core::limits::for_arm(&spec)).py()?;
        Ok(lims.into_iter().map(|l| (l.columns.iter().map(|c| c.to_string()).collect(), l.unit.to_string(), l.min, l.warn_abs, l.error_abs, l.advice)).collect())
    }

    /// What the arm can produce (`popup_core::limits::arm::reach`): a dict with
    /// `tau_max_nm` (3) [N·m], `collapse_nm` (2) [N·m], `joint_accel` (nv) [rad/s²],
    /// `motor_accel` (3) [rad/s²], `imu_accel` (2) [m/s²].
    fn reach<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let spec = self.spec.clone();
        let r = py.detach(move || popup_core::limits::arm::reach(&spec)).py()?;
        let d = PyDict::new(py);
        d.set_item("tau_max_nm", r.tau_max_nm.to_vec())?;
        d.set_item("collapse_nm", r.collapse_nm.to_vec())?;
        d.set_item("joint_accel", r.joint_accel)?;
        d.set_item("motor_accel", r.motor_accel.to_vec())?;
        d.set_item("imu_accel", r.imu_accel.to_vec())?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        format!("Arm({:?})", self.spec.name)
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other.cast::<PyArm>().map(|o| o.get().spec == self.spec).unwrap_or(false)
    }
}

/// Rigid 3-DOF kinematics (thesis Tables 1 and 2).
#[pyclass(name = "RigidArm", module = "popup._core", frozen)]
pub struct PyRigidArm {
    pub arm: RigidArm,
}

fn vec3(p: [f64; 3]) -> Vec3 {
    Vec3::new(p[0], p[1], p[2])
}

/// Three values of argument `what` (`meaning` says which), or an `InputError` naming it.
pub(crate) fn three(what: &str, v: &[f64], meaning: &str) -> PyResult<[f64; 3]> {
    match v {
        [a, b, c] => Ok([*a, *b, *c]),
        _ => Err(Python::attach(|py| crate::errors::make(py, "InputError", &format!("input {what}: expected 3 values ({meaning}), got {}", v.len())))),
    }
}

const Q3: &str = "joint angles q1, q2, q3 [rad]";
const P3: &str = "position x, y, z in the base frame [m]";

#[pymethods]
impl PyRigidArm {
    /// The rigid table `table` (`"as_built"` = Table 1, `"ik"` = Table 2) of `arm`.
    #[new]
    #[pyo3(signature = (arm, table = "as_built"))]
    fn new(arm: PyRef<'_, PyArm>, table: &str) -> PyResult<Self> {
        Ok(PyRigidArm { arm: arm.spec.rigid_arm(table).py()? })
    }

    /// Name of the table.
    #[getter]
    fn name(&self) -> String {
        self.arm.name.clone()
    }

    /// End-effector position p_WE [m] for joint angles q [rad].
    fn fk<'py>(&self, py: Python<'py>, q: Vec<f64>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let q = three("q", &q, Q3)?;
        Ok(PyArray1::from_slice(py, self.arm.fk(&q).as_slice()))
    }

    /// Geometric Jacobian (6 × 3): rows linear then angular velocity, base frame.
    fn jacobian<'py>(&self, py: Python<'py>, q: Vec<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let q = three("q", &q, Q3)?;
        let j = self.arm.jacobian(&q);
        let rows: Vec<Vec<f64>> = (0..6).map(|r| (0..3).map(|c| j[(r, c)]).collect()).collect();
        Ok(PyArray2::from_vec2(py, &rows)?)
    }

    /// The four closed-form IK solutions as (q, shoulder, elbow) tuples.
    fn ik(&self, p: Vec<f64>) -> PyResult<Vec<([f64; 3], &'static str, &'static str)>> {
        let p = three("p", &p, P3)?;
        let sols = self.arm.ik(&vec3(p)).py()?;
        Ok(sols
            .iter()
            .map(|s| {
                let sh = match s.shoulder {
                    Shoulder::Front => "front",
                    Shoulder::Back => "back",
                };
                let el = match s.elbow {
                    Elbow::Up => "up",
                    Elbow::Down => "down",
                };
                (s.q, sh, el)
            })
            .collect())
    }

    /// Singularity report: dict(elbow, shoulder, elbow_measure, shoulder_measure).
    #[pyo3(signature = (q, tol = 1e-6))]
    fn singularity<'py>(&self, py: Python<'py>, q: Vec<f64>, tol: f64) -> PyResult<Bound<'py, PyDict>> {
        let q = three("q", &q, Q3)?;
        let s = self.arm.singularity(&q, tol);
        let d = PyDict::new(py);
        d.set_item("elbow", s.elbow)?;
        d.set_item("shoulder", s.shoulder)?;
        d.set_item("elbow_measure", s.elbow_measure)?;
        d.set_item("shoulder_measure", s.shoulder_measure)?;
        Ok(d)
    }

    /// |det J_v| [m³].
    fn manipulability(&self, q: Vec<f64>) -> PyResult<f64> {
        Ok(self.arm.manipulability(&three("q", &q, Q3)?))
    }

    /// Raise `UnreachableError` if p [m] is outside the workspace.
    fn check_reachable(&self, p: Vec<f64>) -> PyResult<()> {
        self.arm.in_workspace(&vec3(three("p", &p, P3)?)).py()
    }

    /// Frames 0..3 as a (4, 4, 4) array of homogeneous transforms T_W_i.
    fn frames<'py>(&self, py: Python<'py>, q: Vec<f64>) -> PyResult<Bound<'py, numpy::PyArray3<f64>>> {
        let f = self.arm.frames(&three("q", &q, Q3)?);
        let mut out = numpy::ndarray::Array3::<f64>::zeros((4, 4, 4));
        for (i, (r, p)) in f.iter().enumerate() {
            for a in 0..3 {
                for b in 0..3 {
                    out[[i, a, b]] = r[(a, b)];
                }
                out[[i, a, 3]] = p[a];
            }
            out[[i, 3, 3]] = 1.0;
        }
        Ok(numpy::PyArray3::from_owned_array(py, out))
    }
}
