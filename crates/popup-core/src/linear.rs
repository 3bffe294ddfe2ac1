//! Linearised arm: the continuous-time state-space model `ẋ = A x + B u`, `y = C x + D u`
//! about a static equilibrium, obtained by differentiating the engine's own forward
//! dynamics ([`crate::forward::accel`]) and sensor model ([`crate::sensor::sample`]).
//!
//! Operating point: the motors at given angles, the passive (bending and torsion) joints in
//! static equilibrium ([`crate::statics::static_equilibrium`]), every rate zero, at time `t`
//! (0 by default; only `pressure_leak` makes the model depend on it). `x`, `u`, `y` are
//! deviations from that point.
//!
//! Three ways to drive the motor joints ([`LinearInput`]):
//!
//! * `Torque`: the motor torques are the inputs (`tau1..3` [N·m] at the joint outputs, on
//!   top of the gravity holding torques `u0`); state = every joint `(q, q̇)`, `2 nv` (less
//!   the locked joints of rigid links, which never move).
//! * `Acceleration`: the motor joints follow prescribed accelerations (`ddq1..3`
//!   [rad/s²], the encoder-replay drive); state = every unlocked joint, the motor rows are
//!   double integrators. A prescribed joint *velocity* or *angle* input is this model
//!   times `s` or `s²` in the frequency domain (`popup.frequency` does that).
//! * `Locked`: motors held at their angles; state = the passive joints only, no input. Its
//!   eigenvalues are the locked-motor modes ([`crate::statics::locked_modes`] for the
//!   undamped frequencies, [`crate::statics::linear_eigs`] for the damped eigenvalues).
//!
//! Derivatives are fourth-order central differences (`[f(−2h) − 8 f(−h) + 8 f(h) − f(2h)] /
//! 12h`) with `h = 1e-4` (angles [rad], rates [rad/s]) and `h = 1e-4 · max(1, |u0|)`
//! (torques): truncation O(h⁴) ≈ 1e-16 relative, rounding ≈ 1e-12 relative to the largest
//! term. Velocity terms are exact (the Coriolis terms are quadratic and cancel in a central
//! difference at q̇ = 0). Non-smooth effects (`joint_friction`'s tanh at q̇ = 0, `backlash`,
//! `wrinkling` exactly at its threshold) are linearised as the secant over ±2h, i.e. their
//! local slope; that is the engine's model, not an approximation added here.

use crate::drive::{Drive, Spline3};
use crate::error::{Error, Result};
use crate::forward::accel;
use crate::math::VecN;
use crate::model::Model;
use crate::params::ParamData;
use crate::sensor::{sample, CHANNELS, NCH};
use crate::statics::{gravity_torque, static_equilibrium};
use nalgebra::{Complex, DMatrix};

/// How the motor joints enter the linear model (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinearInput {
    /// Motor torques in [N·m]; state = all joints.
    Torque,
    /// Prescribed motor accelerations in [rad/s²]; state = all joints.
    Acceleration,
    /// Motors locked; state = passive joints, no input.
    Locked,
}

impl LinearInput {
    /// Parse `"torque"`, `"acceleration"` or `"locked"`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for anything else.
    pub fn parse(s: &str) -> Result<LinearInput> {
        match s {
            "torque" => Ok(LinearInput::Torque),
            "acceleration" => Ok(LinearInput::Acceleration),
            "locked" => Ok(LinearInput::Locked),
            other => Err(Error::param("input", format!("{other:?}"), "must be \"torque\", \"acceleration\" or \"locked\"")),
        }
    }

    /// The name [`LinearInput::parse`] reads.
    pub fn name(&self) -> &'static str {
        match self {
            LinearInput::Torque => "torque",
            LinearInput::Acceleration => "acceleration",
            LinearInput::Locked => "locked",
        }
    }
}

/// A linear state-space model about an operating point (deviation variables).
#[derive(Debug, Clone, PartialEq)]
pub struct LinearModel {
    /// How the motors enter.
    pub input: LinearInput,
    /// Chain indices of the joints in the state: positions are `x[..n]`, rates `x[n..2n]`.
    pub free: Vec<usize>,
    /// State names: the joint names, then `<joint>_dot`.
    pub states: Vec<String>,
    /// Input names (`tau1..3`, `ddq1..3`, or none).
    pub inputs: Vec<String>,
    /// Output channel names ([`CHANNELS`]).
    pub outputs: Vec<String>,
    /// Operating point: joint coordinates (leading `nv` entries used) [rad].
    pub q0: VecN,
    /// Inputs at the operating point (gravity holding torques for `Torque`, zeros else).
    pub u0: Vec<f64>,
    /// Outputs at the operating point.
    pub y0: Vec<f64>,
    /// `∂ẋ/∂x` (2n × 2n).
    pub a: DMatrix<f64>,
    /// `∂ẋ/∂u` (2n × m).
    pub b: DMatrix<f64>,
    /// `∂y/∂x` (p × 2n).
    pub c: DMatrix<f64>,
    /// `∂y/∂u` (p × m).
    pub d: DMatrix<f64>,
}

impl LinearModel {
    /// Eigenvalues of A (the poles) [1/s], sorted by |λ| then imaginary part.
    pub fn poles(&self) -> Vec<Complex<f64>> {
        let mut ev: Vec<Complex<f64>> = crate::math::eigenvalues(self.a.clone());
        ev.sort_by(|x, y| x.norm().partial_cmp(&y.norm()).unwrap_or(std::cmp::Ordering::Equal).then(x.im.partial_cmp(&y.im).unwrap_or(std::cmp::Ordering::Equal)));
        ev
    }

    /// Frequency response `C (iω − A)⁻¹ B + D` at `omega` [rad/s] (p × m).
    pub fn frf(&self, omega: f64) -> DMatrix<Complex<f64>> {
        let n = self.a.nrows();
        let m = self.b.ncols();
        let mut s = self.a.map(|v| Complex::new(-v, 0.0));
        for i in 0..n {
            s[(i, i)] += Complex::new(0.0, omega);
        }
        let b = self.b.map(|v| Complex::new(v, 0.0));
        let x = s.lu().solve(&b).unwrap_or_else(|| DMatrix::from_element(n, m, Complex::new(f64::NAN, f64::NAN)));
        self.c.map(|v| Complex::new(v, 0.0)) * x + self.d.map(|v| Complex::new(v, 0.0))
    }
}

/// Fourth-order central-difference step for angles and rates.
const H_STATE: f64 = 1e-4;

fn stencil<F: FnMut(f64) -> Vec<f64>>(h: f64, mut f: F) -> Vec<f64> {
    let (m2, m1, p1, p2) = (f(-2.0 * h), f(-h), f(h), f(2.0 * h));
    (0..p1.len()).map(|i| (m2[i] - 8.0 * m1[i] + 8.0 * p1[i] - p2[i]) / (12.0 * h)).collect()
}

/// Linearise about the static equilibrium with the motors at `q_motor` [rad] (the passive
/// joints are solved for). `outputs` are channel indices into [`CHANNELS`].
///
/// # Errors
/// As [`static_equilibrium`]; [`Error::Input`] for an output index out of range.
pub fn linearize_at_rest(model: &Model, pd: &ParamData, q_motor: [f64; 3], input: LinearInput, outputs: &[usize], t: f64) -> Result<LinearModel> {
    let mut q = VecN::zeros();
    for (k, &i) in model.motor_idx.iter().enumerate() {
        q[i] = q_motor[k];
    }
    let q = static_equilibrium(model, pd, &q)?;
    linearize(model, pd, &q, input, outputs, t)
}

/// Linearise about `(q0, q̇ = 0)`. `q0` should be a static equilibrium of the passive joints
/// (see [`linearize_at_rest`]); it is not checked, the model is simply the tangent there.
/// For [`LinearInput::Torque`] the operating inputs are the motor rows of the gravity
/// torque G(q0) (the holding torques).
///
/// # Errors
/// [`Error::Input`] for an output index out of range.
pub fn linearize(model: &Model, pd: &ParamData, q0: &VecN, input: LinearInput, outputs: &[usize], t: f64) -> Result<LinearModel> {
    if let Some(&bad) = outputs.iter().find(|&&o| o >= NCH) {
        return Err(Error::input("linearize outputs", format!("channel index {bad} out of range (0..{NCH})")));
    }
    let free: Vec<usize> = match input {
        LinearInput::Locked => model.free_joints(true),
        _ => model.free_joints(false),
    };
    let n = free.len();
    let m = if input == LinearInput::Locked { 0 } else { 3 };
    let g0 = gravity_torque(model, pd, q0);
    let u0: Vec<f64> = match input {
        LinearInput::Torque => model.motor_idx.iter().map(|&i| g0[i]).collect(),
        _ => vec![0.0; m],
    };
    // a replay drive whose spline is never evaluated: `accel` and `sample` only look at the
    // variant and take the motor accelerations from `am`
    let dummy = Drive::Replay(Spline3::new(&[0.0, 1.0], &[[0.0; 3], [0.0; 3]])?);
    // ẋ and y at (q0 + dq, dv) with inputs u0 + du (dq, dv over `free`)
    let eval = |dq: &[f64], dv: &[f64], du: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let mut q = *q0;
        let mut v = VecN::zeros();
        for (a, &j) in free.iter().enumerate() {
            q[j] += dq[a];
            v[j] = dv[a];
        }
        let (drive, am) = match input {
            LinearInput::Torque => (Drive::Hold([u0[0] + du[0], u0[1] + du[1], u0[2] + du[2]]), None),
            LinearInput::Acceleration => (dummy.clone(), Some([du[0], du[1], du[2]])),
            LinearInput::Locked => (dummy.clone(), Some([0.0; 3])),
        };
        let acc = accel(model, pd, &drive, t, &q, &v, am, 0.0);
        let mut xd = Vec::with_capacity(2 * n);
        xd.extend(free.iter().map(|&j| v[j]));
        xd.extend(free.iter().map(|&j| acc[j]));
        let mut row = [0.0; NCH];
        sample(model, pd, &drive, t, &q, &v, am, &mut row);
        (xd, outputs.iter().map(|&o| row[o]).collect())
    };
    let zn = vec![0.0; n];
    let zm = vec![0.0; m];
    let (_, y0) = eval(&zn, &zn, &zm);
    let p = outputs.len();
    let mut a = DMatrix::zeros(2 * n, 2 * n);
    let mut b = DMatrix::zeros(2 * n, m);
    let mut c = DMatrix::zeros(p, 2 * n);
    let mut d = DMatrix::zeros(p, m);
    for col in 0..2 * n {
        let mut ys = Vec::new();
        let dx = stencil(H_STATE, |h| {
            let (mut dq, mut dv) = (zn.clone(), zn.clone());
            if col < n {
                dq[col] = h;
            } else {
                dv[col - n] = h;
            }
            let (xd, y) = eval(&dq, &dv, &zm);
            ys.push(y);
            xd
        });
        a.set_column(col, &nalgebra::DVector::from_vec(dx));
        let dy = combine(&ys, H_STATE);
        c.set_column(col, &nalgebra::DVector::from_vec(dy));
    }
    for col in 0..m {
        let h = H_STATE * u0[col].abs().max(1.0);
        let mut ys = Vec::new();
        let dx = stencil(h, |h| {
            let mut du = zm.clone();
            du[col] = h;
            let (xd, y) = eval(&zn, &zn, &du);
            ys.push(y);
            xd
        });
        b.set_column(col, &nalgebra::DVector::from_vec(dx));
        d.set_column(col, &nalgebra::DVector::from_vec(combine(&ys, h)));
    }
    let names = model.joint_names();
    let mut states: Vec<String> = free.iter().map(|&j| names[j].to_string()).collect();
    states.extend(free.iter().map(|&j| format!("{}_dot", names[j])));
    let inputs = match input {
        LinearInput::Torque => vec!["tau1".into(), "tau2".into(), "tau3".into()],
        LinearInput::Acceleration => vec!["ddq1".into(), "ddq2".into(), "ddq3".into()],
        LinearInput::Locked => vec![],
    };
    Ok(LinearModel {
        input,
        free,
        states,
        inputs,
        outputs: outputs.iter().map(|&o| CHANNELS[o].to_string()).collect(),
        q0: *q0,
        u0,
        y0,
        a,
        b,
        c,
        d,
    })
}

/// The stencil over values collected in the order −2h, −h, h, 2h.
fn combine(ys: &[Vec<f64>], h: f64) -> Vec<f64> {
    (0..ys[0].len()).map(|i| (ys[0][i] - 8.0 * ys[1][i] + 8.0 * ys[2][i] - ys[3][i]) / (12.0 * h)).collect()
}
