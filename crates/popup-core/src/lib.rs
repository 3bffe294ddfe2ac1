//! # popup-core
//!
//! Deterministic simulation core for inflatable robot arms: the 7-DOF pseudo-rigid-body
//! (PRBM) chain of the POP-UP arm (expandable at compile time to up to 31 joints: several
//! segments per link, Euler–Bernoulli beam links of up to 6 elements ([`beam`]), torsion
//! joints), its rigid 3-DOF kinematics, sensors and batched rollouts, the controllers and
//! scenario files ([`scenario`]).
//! Pure Rust, no Python; the only I/O is the MCAP log writer ([`log`], feature `mcap`).
//!
//! Structure: [`spec::ArmSpec`] (editable, TOML) → [`model::Model`] (compiled, immutable)
//! + [`params::Params`] (per rollout) → [`sim::run`] / [`rollout::rollout`]; streamed
//! runs hand their samples to a [`stream::Sink`] ([`sim::run_into`],
//! [`control::closed_loop::run_closed_loop_into`]).
//! Units are SI; frames follow standard Denavit–Hartenberg (see `reference-arm.md`).
#![warn(missing_docs)]

pub mod drive;
pub mod dynamics;
pub mod effects;
pub mod error;
pub mod forward;
pub mod integrate;
pub mod kinematics;
pub mod limits;
pub mod linear;
pub mod math;
pub mod model;
pub mod params;
pub mod rollout;
pub mod scenario;
pub mod sensor;
pub mod sim;
pub mod control;
pub mod spec;
pub mod statics;
pub mod backlash;
pub mod beam;
pub mod stream;
#[cfg(feature = "mcap")]
pub mod log;

pub use error::{Error, Result};

/// Crate version.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// Cargo features this build was compiled with.
pub const BUILD_FEATURES: &[&str] = &[
    #[cfg(feature = "parallel")]
    "parallel",
    #[cfg(feature = "mcap")]
    "mcap",
];
