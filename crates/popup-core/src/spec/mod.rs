//! Editable, serialisable descriptions (what a user writes in files).

pub mod arm;

pub use arm::ArmSpec;
