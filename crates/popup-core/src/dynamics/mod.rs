//! Rigid multibody dynamics of the PRBM chain in reduced (joint) coordinates.

pub mod aba;
pub mod articulated;
pub mod crba;
pub mod rnea;

pub use aba::aba;
pub use crba::{crba, crba_into};
pub use rnea::{forward_pass, rnea, BodyMotion};
