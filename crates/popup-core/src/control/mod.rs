//! Closed-loop control of the arm: motoreducers, the decentralized cascade (position PI →
//! velocity PI → current loop) with the vibration-damping PIDs, Cartesian control, reference
//! generators, the task state machine and collision awareness, all stepped at a controller
//! rate of their own on top of the physics step. The discrete-time laws are written out in
//! `docs/control.md`.
//!
//! Structure: [`ControllerSpec`] (gains, motoreducers, rate) + [`machine::Sequence`]
//! (phases, guards, fault policy) + obstacles → [`ClosedLoop`] (one run) →
//! [`closed_loop::run_closed_loop`] → [`closed_loop::ClosedTrajectory`].

pub mod closed_loop;
pub mod collision;
pub mod config;
pub mod law;
pub mod machine;
pub mod motor;
pub mod reference;

use crate::error::{Error, Result};
use crate::sim::State;
pub use closed_loop::{rollout_closed, rollout_closed_until, run_closed_loop, run_closed_loop_until, ClosedTrajectory, Status, CTRL_CHANNELS, NCTRL};
pub use machine::{Command, Event, FaultPolicy, Guard, Phase, Sequence};
pub use motor::Motoreducer;
pub use reference::Signal;

/// Controller gains per motor joint (index 0..3 = q1..q3). These are what gain studies sweep
/// (see [`Gains::to_flat`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Gains {
    /// Position-loop proportional gain Kp_q [1/s] (rad/s of velocity reference per rad).
    pub pos_kp: [f64; 3],
    /// Position-loop integral gain Ki_q [1/s²].
    pub pos_ki: [f64; 3],
    /// Velocity-loop proportional gain Kp_v [drive units per rad/s] (the thesis's units; the
    /// motoreducer's `torque_per_unit` converts to N·m).
    pub vel_kp: [f64; 3],
    /// Velocity-loop integral gain Ki_v [drive units per rad].
    pub vel_ki: [f64; 3],
    /// Damping-PID proportional gain [(rad/s)/(m/s²)].
    pub damp_kp: [f64; 3],
    /// Damping-PID integral gain [(rad/s)/(m/s)].
    pub damp_ki: [f64; 3],
    /// Damping-PID derivative gain [(rad/s)/(m/s³)].
    pub damp_kd: [f64; 3],
    /// Cartesian (Jacobian-transpose) gain K_c: q̇* = K_c J_vᵀ (p* − p) [rad²/(m²·s)].
    pub cart_k: f64,
}

impl Default for Gains {
    /// Thesis chapter 7: position Kp = 20, Ki = 0.25; velocity Kp = 5000, Ki = 100; damping
    /// proportional gains 0.01 (joint 1) and 0.04 (joints 2, 3) as tuned in
    /// `docs/control.md`; Cartesian gain 4.
    fn default() -> Self {
        Gains {
            pos_kp: [20.0; 3],
            pos_ki: [0.25; 3],
            vel_kp: [5000.0; 3],
            vel_ki: [100.0; 3],
            damp_kp: [0.01, 0.04, 0.04],
            damp_ki: [0.0; 3],
            damp_kd: [0.0; 3],
            cart_k: 4.0,
        }
    }
}

/// Number of gains in the flat layout of [`Gains::to_flat`].
pub const NG: usize = 22;

/// Names of the flat gains, in order (`pos_kp[0]`, ...).
pub fn gain_names() -> Vec<String> {
    let mut v = Vec::with_capacity(NG);
    for n in ["pos_kp", "pos_ki", "vel_kp", "vel_ki", "damp_kp", "damp_ki", "damp_kd"] {
        for j in 0..3 {
            v.push(format!("{n}[{j}]"));
        }
    }
    v.push("cart_k".into());
    v
}

impl Gains {
    /// Flat layout: pos_kp[3], pos_ki[3], vel_kp[3], vel_ki[3], damp_kp[3], damp_ki[3],
    /// damp_kd[3], cart_k.
    pub fn to_flat(&self) -> [f64; NG] {
        let mut f = [0.0; NG];
        for (g, a) in [self.pos_kp, self.pos_ki, self.vel_kp, self.vel_ki, self.damp_kp, self.damp_ki, self.damp_kd].iter().enumerate() {
            f[3 * g..3 * g + 3].copy_from_slice(a);
        }
        f[21] = self.cart_k;
        f
    }

    /// Inverse of [`Gains::to_flat`].
    pub fn from_flat(f: &[f64; NG]) -> Gains {
        let a = |g: usize| [f[3 * g], f[3 * g + 1], f[3 * g + 2]];
        Gains { pos_kp: a(0), pos_ki: a(1), vel_kp: a(2), vel_ki: a(3), damp_kp: a(4), damp_ki: a(5), damp_kd: a(6), cart_k: f[21] }
    }

    /// Every gain must be finite and >= 0 (damping gains may be negative: their sign picks
    /// the sense of the feedback).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `controller.gains.<name>[j]`.
    pub fn validate(&self) -> Result<()> {
        let names = gain_names();
        for (i, v) in self.to_flat().iter().enumerate() {
            let signed = (12..21).contains(&i);
            if !v.is_finite() || (!signed && *v < 0.0) {
                return Err(Error::param(format!("controller.gains.{}", names[i]), v, if signed { "must be finite" } else { "must be finite and >= 0" }));
            }
        }
        Ok(())
    }
}

/// Which rigid 3-DOF kinematics the Cartesian law (`q̇* = K_c J_vᵀ (p* − p)`) and its
/// workspace check use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CartesianArm {
    /// The model's own chain with every bending joint at zero (default: controller and
    /// plant agree on the geometry).
    #[default]
    Prbm,
    /// The arm file's as-built rigid table (thesis Table 1), as the thesis's chapter 8 did
    /// with its PRBM plant.
    AsBuilt,
    /// The arm file's offset-free rigid table (thesis Table 2).
    Ik,
}

/// The controller: rate, motoreducers, gains and switches (immutable during a run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ControllerSpec {
    /// Controller rate 1/T [Hz]; T must be a whole multiple of the physics step dt.
    pub rate_hz: f64,
    /// Motoreducers of q1..q3.
    pub motors: [Motoreducer; 3],
    /// Gains.
    pub gains: Gains,
    /// Damping PIDs on per joint (phases may override).
    pub damping: [bool; 3],
    /// Corner of the damping PIDs' input low-pass ω_f [rad/s] (thesis: 13.5).
    pub damping_lpf: f64,
    /// Limit of the velocity reference [rad/s] (`∞` = none).
    pub v_max: f64,
    /// Conditional-integration anti-windup on (default true; off only to show what it does).
    pub anti_windup: bool,
    /// Kinematics of the Cartesian law (default: the chain's own).
    pub cartesian_arm: CartesianArm,
}

impl Default for ControllerSpec {
    fn default() -> Self {
        ControllerSpec {
            rate_hz: 10_000.0,
            motors: [Motoreducer::DEFAULT; 3],
            gains: Gains::default(),
            damping: [false; 3],
            damping_lpf: 13.5,
            v_max: f64::INFINITY,
            anti_windup: true,
            cartesian_arm: CartesianArm::Prbm,
        }
    }
}

impl ControllerSpec {
    /// Controller period T [s].
    pub fn period(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// Check everything.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the field.
    pub fn validate(&self) -> Result<()> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(Error::param("controller.rate_hz", self.rate_hz, "must be finite and > 0 Hz"));
        }
        for (j, m) in self.motors.iter().enumerate() {
            m.validate(&format!("controller.motors[{j}]"))?;
        }
        self.gains.validate()?;
        if !(self.damping_lpf > 0.0) {
            return Err(Error::param("controller.damping_lpf_rad_s", self.damping_lpf, "must be > 0 rad/s (inf = no filter)"));
        }
        if !(self.v_max > 0.0) {
            return Err(Error::param("controller.v_max", self.v_max, "must be > 0 rad/s (inf = no limit)"));
        }
        Ok(())
    }
}

/// One closed-loop run.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedLoop {
    /// The controller.
    pub controller: ControllerSpec,
    /// The task: phases and fault policy.
    pub sequence: Sequence,
    /// Obstacles for collision awareness (empty = none).
    pub obstacles: Vec<collision::Obstacle>,
    /// Radius of the payload's collision sphere [m] (used while a payload is attached).
    pub payload_radius: f64,
    /// Initial motor angles [rad] (the arm starts at rest there, bending joints in static
    /// equilibrium, drives holding it); ignored when `initial` is given.
    pub q0: [f64; 3],
    /// Initial state (optional).
    pub initial: Option<State>,
    /// Duration [s].
    pub duration: f64,
    /// Sensor sample period [s] (a whole multiple of dt).
    pub sample_period: f64,
    /// Check the physics step against the linearised arm first.
    pub check_step: bool,
}

impl ClosedLoop {
    /// A run of `duration` with one phase doing `command`, default controller.
    pub fn single(command: Command, q0: [f64; 3], duration: f64, sample_period: f64) -> ClosedLoop {
        ClosedLoop {
            controller: ControllerSpec::default(),
            sequence: Sequence::single(command),
            obstacles: Vec::new(),
            payload_radius: 0.05,
            q0,
            initial: None,
            duration,
            sample_period,
            check_step: true,
        }
    }
}
