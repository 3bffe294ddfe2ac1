//! The task state machine: a user sequence of phases, each with a motor command and a
//! guarded exit, plus fault states entered from any phase. Every transition is logged.
//!
//! Phase semantics: on entry a phase may set the payload (a grasp is a step change of tip
//! mass), the link pressures and the damping switches; while active its [`Command`] makes the
//! references; it is left for the next phase when its [`Guard`] holds. The last phase stays
//! active until the end of the run. Faults (`WrinkleAlarm`, `Saturated`, `Contact`,
//! `Unstable`) interrupt the active phase; the resumable ones hold the motors and give the
//! phase back (its clock paused) when cleared.

use crate::control::reference::Signal;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// What the motors do during a phase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Command {
    /// Hold the motor angles measured when the phase began.
    Hold,
    /// Follow a position reference per joint (time since the phase began).
    Track([Signal; 3]),
    /// Velocity references per joint [rad/s] straight into the velocity loops (the position
    /// loops are bypassed; frequency-response experiments of the motoreducers).
    Velocity([Signal; 3]),
    /// Minimum-jerk move from the angles at phase start to `q` [rad] in `duration` [s].
    MoveTo {
        /// Target motor angles [rad].
        q: [f64; 3],
        /// Duration [s].
        duration: f64,
    },
    /// Cartesian target p_WE* [m] for the end effector (Jacobian-transpose law of the rigid
    /// arm). Must be inside the model's rigid workspace.
    Cartesian {
        /// Target in the base frame [m].
        target: [f64; 3],
    },
}

/// Exit condition of a phase: left when `elapsed ≥ min_time` and every condition given
/// holds, or when `elapsed ≥ max_time` (logged as a timeout).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Guard {
    /// Minimum time in the phase [s].
    pub min_time: f64,
    /// Maximum time in the phase [s] (`∞` = none).
    pub max_time: f64,
    /// Settled: every |reference − encoder angle| below this [rad] and every encoder speed
    /// below 10× this per second [rad/s].
    pub settled: Option<f64>,
    /// Still: every filtered relative tip acceleration (the damping PIDs' inputs) below this
    /// [m/s²].
    pub still: Option<f64>,
    /// At target (Cartesian): |p* − p_rigid| below this [m].
    pub at_target: Option<f64>,
}

impl Default for Guard {
    fn default() -> Self {
        Guard { min_time: 0.0, max_time: f64::INFINITY, settled: None, still: None, at_target: None }
    }
}

/// One phase of a task.
#[derive(Debug, Clone, PartialEq)]
pub struct Phase {
    /// Name in the log (e.g. `Moving`).
    pub name: String,
    /// Motor command.
    pub command: Command,
    /// Payload set on entry [kg] (grasp: the object; release: 0).
    pub payload_kg: Option<f64>,
    /// Link pressures set on entry [Pa].
    pub pressure_pa: Option<[f64; 2]>,
    /// Damping PIDs on/off during the phase (`None` = the controller's setting).
    pub damping: Option<[bool; 3]>,
    /// Exit condition.
    pub until: Guard,
}

/// What a fault does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultAction {
    /// Log only; the phase goes on.
    Continue,
    /// Hold the motors where they are until the fault clears, then resume the phase.
    Hold,
    /// Hold the motors where they are for the rest of the run.
    Stop,
    /// Move back (minimum jerk, 1 s) to the angles at the start of the interrupted phase,
    /// then hold for the rest of the run.
    Retreat,
}

/// How faults are detected and handled.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FaultPolicy {
    /// On a wrinkling alarm (|M|/M_w > 1 on a link).
    pub wrinkle: FaultAction,
    /// The alarm clears when |M|/M_w < this on both links [-].
    pub wrinkle_clear_ratio: f64,
    /// On a saturated drive (velocity-loop output at its limit) lasting `saturation_time`.
    pub saturation: FaultAction,
    /// How long a drive must stay saturated to raise the fault [s].
    pub saturation_time: f64,
    /// On contact: a part of the arm closer than `contact_margin` to an obstacle.
    pub contact: FaultAction,
    /// Clearance that raises the contact guard [m].
    pub contact_margin: f64,
    /// Time a cleared fault must stay cleared before the phase resumes [s].
    pub clear_time: f64,
}

impl Default for FaultPolicy {
    fn default() -> Self {
        FaultPolicy {
            wrinkle: FaultAction::Hold,
            wrinkle_clear_ratio: 0.9,
            saturation: FaultAction::Continue,
            saturation_time: 0.1,
            contact: FaultAction::Stop,
            contact_margin: 0.02,
            clear_time: 0.2,
        }
    }
}

/// A task: phases in order and the fault policy.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// Phases (at least one).
    pub phases: Vec<Phase>,
    /// Faults.
    pub faults: FaultPolicy,
}

impl Sequence {
    /// One `Moving` phase with `command` for the whole run.
    pub fn single(command: Command) -> Sequence {
        Sequence {
            phases: vec![Phase { name: "Moving".into(), command, payload_kg: None, pressure_pa: None, damping: None, until: Guard::default() }],
            faults: FaultPolicy::default(),
        }
    }

    /// Check the sequence.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] / [`Error::Input`] naming `phases[i] (name).<field>`.
    pub fn validate(&self) -> Result<()> {
        if self.phases.is_empty() {
            return Err(Error::input("sequence", "needs at least one phase"));
        }
        for (i, p) in self.phases.iter().enumerate() {
            let w = format!("phases[{i}] ({})", p.name);
            match &p.command {
                Command::Hold => {}
                Command::Track(s) | Command::Velocity(s) => {
                    for (j, sig) in s.iter().enumerate() {
                        sig.validate(&format!("{w}.{}[{j}]", if matches!(p.command, Command::Track(_)) { "track" } else { "velocity" }))?;
                    }
                }
                Command::MoveTo { q, duration } => {
                    if q.iter().any(|v| !v.is_finite()) {
                        return Err(Error::param(format!("{w}.move_to.q"), format!("{q:?}"), "must be finite [rad]"));
                    }
                    if !(duration.is_finite() && *duration > 0.0) {
                        return Err(Error::param(format!("{w}.move_to.duration"), duration, "must be finite and > 0 s"));
                    }
                }
                Command::Cartesian { target } => {
                    if target.iter().any(|v| !v.is_finite()) {
                        return Err(Error::param(format!("{w}.cartesian.target"), format!("{target:?}"), "must be finite [m]"));
                    }
                }
            }
            if let Some(m) = p.payload_kg {
                if !(m.is_finite() && m >= 0.0) {
                    return Err(Error::param(format!("{w}.payload_kg"), m, "must be finite and >= 0 kg"));
                }
            }
            if let Some(pp) = p.pressure_pa {
                if pp.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
                    return Err(Error::param(format!("{w}.pressure_pa"), format!("{pp:?}"), "must be finite and >= 0 Pa"));
                }
            }
            let g = &p.until;
            if !(g.min_time.is_finite() && g.min_time >= 0.0) || g.max_time.is_nan() || g.max_time < 0.0 {
                return Err(Error::param(format!("{w}.until"), format!("min_time = {}, max_time = {}", g.min_time, g.max_time), "need 0 <= min_time < inf, max_time >= 0"));
            }
            for (n, v) in [("settled", g.settled), ("still", g.still), ("at_target", g.at_target)] {
                if let Some(v) = v {
                    if !(v.is_finite() && v > 0.0) {
                        return Err(Error::param(format!("{w}.until.{n}"), v, "must be finite and > 0"));
                    }
                }
            }
            if g.at_target.is_some() && !matches!(p.command, Command::Cartesian { .. }) {
                return Err(Error::input(format!("{w}.until.at_target"), "only a Cartesian phase has a target"));
            }
        }
        let f = &self.faults;
        for (n, v) in [("wrinkle_clear_ratio", f.wrinkle_clear_ratio), ("saturation_time", f.saturation_time), ("contact_margin", f.contact_margin), ("clear_time", f.clear_time)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::param(format!("faults.{n}"), v, "must be finite and >= 0"));
            }
        }
        Ok(())
    }
}

/// One entry of the run log.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Time [s].
    pub t: f64,
    /// `transition`, `fault`, `contact`, `timeout`, `payload`, `pressure`.
    pub kind: &'static str,
    /// Phase before.
    pub from: String,
    /// Phase after.
    pub to: String,
    /// What happened (guard that fired, where a contact was, ...).
    pub detail: String,
}
