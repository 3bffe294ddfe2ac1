//! # popup-core
//!
//! Deterministic simulation core for inflatable robot arms: the 7-DOF pseudo-rigid-body
//! (PRBM) chain of the POP-UP arm (expandable at compile time to up to 17 joints: several
//! segments per link, torsion joints), its rigid 3-DOF kinematics, sensors and batched
//! rollouts. Pure Rust, no Python, no I/O.
//!
//! Structure: [`spec::ArmSpec`] (editable, TOML) → [`model::Model`] (compiled, immutable)
//! + [`params::Params`] (per rollout) → [`sim::run`] / [`rollout::rollout`].
//! Units are SI; frames follow standard Denavit–Hartenberg (see `reference-arm.md`).
#![warn(missing_docs)]

pub mod drive;
pub mod dynamics;
pub mod effects;
pub mod error;
pub mod forward;
pub mod integrate;
pub mod kinematics;
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
