//! The one error type of the core. Every variant names what was wrong, where, and what
//! is required, so that the Python layer can raise a precise exception.

use thiserror::Error;

/// Everything that can go wrong in `popup-core`.
#[derive(Debug, Clone, Error, PartialEq)]
pub enum Error {
    /// A parameter (arm file, options, params) is outside its valid range.
    /// `what` names the parameter with its path (e.g. `bodies[3].parts[0].mass_kg`).
    #[error("invalid parameter {what} = {value}: {requirement}")]
    InvalidParameter {
        /// Path of the offending parameter.
        what: String,
        /// The offending value, printed.
        value: String,
        /// What the value must satisfy.
        requirement: String,
    },
    /// The arm file could not be parsed or has the wrong structure.
    #[error("arm file {source_name}: {message}")]
    ArmFile {
        /// File name or `<string>`.
        source_name: String,
        /// What is wrong, with line/key where known.
        message: String,
    },
    /// A built-in arm name that does not exist.
    #[error("unknown arm {name:?}; built-in arms are: {known}")]
    UnknownArm {
        /// The requested name.
        name: String,
        /// Comma-separated list of known names.
        known: String,
    },
    /// A Cartesian target outside the workspace of the chosen arm.
    #[error("target p = [{:.4}, {:.4}, {:.4}] m is unreachable for {arm}: {reason}", .target[0], .target[1], .target[2])]
    Unreachable {
        /// Target position in the base frame [m].
        target: [f64; 3],
        /// Which kinematic table was used.
        arm: String,
        /// Why (distance vs reach, etc.).
        reason: String,
    },
    /// The configuration is singular for the requested operation.
    #[error("singular configuration: {0}")]
    Singular(String),
    /// An input array has the wrong shape or content.
    #[error("input {what}: {message}")]
    Input {
        /// Which input.
        what: String,
        /// What is wrong.
        message: String,
    },
    /// The time step is outside the integrator's stability region (checked before a run).
    #[error("time step dt = {dt:e} s is too large for the {integrator} integrator: {detail}; use dt <= {dt_max:e} s")]
    StepTooLarge {
        /// Requested time step [s].
        dt: f64,
        /// Largest stable step found [s].
        dt_max: f64,
        /// Integrator name.
        integrator: String,
        /// Which mode/joint limits it.
        detail: String,
    },
    /// The state became non-finite or unbounded during a run.
    #[error("simulation diverged at step {step} (t = {time:.6} s): joint {joint} has {quantity}; {advice}")]
    Diverged {
        /// Index of the step that failed (0-based).
        step: usize,
        /// Time at the start of the failing step [s].
        time: f64,
        /// Name of the joint where it was detected.
        joint: String,
        /// What was observed (e.g. `v = NaN rad/s`).
        quantity: String,
        /// What to change.
        advice: String,
    },
    /// A solver (static equilibrium, etc.) did not converge.
    #[error("{what} did not converge: {message}")]
    NoConvergence {
        /// Which solver.
        what: String,
        /// Details.
        message: String,
    },
    /// Writing a log file failed (I/O or encoding).
    #[error("log {path}: {message}")]
    Log {
        /// The file.
        path: String,
        /// What failed.
        message: String,
    },
}

/// Result alias of the core.
pub type Result<T> = std::result::Result<T, Error>;

impl Error {
    /// Shorthand for [`Error::InvalidParameter`].
    pub fn param(what: impl Into<String>, value: impl std::fmt::Display, requirement: impl Into<String>) -> Self {
        Error::InvalidParameter { what: what.into(), value: value.to_string(), requirement: requirement.into() }
    }
    /// Shorthand for [`Error::Input`].
    pub fn input(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Input { what: what.into(), message: message.into() }
    }
}
