//! Euler–Bernoulli beam elements for thin-walled inflated tubes (issue 6, first part):
//! the 3D two-node element (axial, torsion, bending in two planes; consistent mass), a
//! clamped cantilever of `n` elements with a tip mass (static deflection, modes), and
//! Rayleigh damping from two modal damping ratios.
//!
//! Local axes: x along the beam, y and z across it. Node DOFs, in this order:
//! `u` (axial [m]), `v` (y [m]), `w` (z [m]), `θx` (twist [rad]), `θy`, `θz` (bending
//! rotations [rad]). SI units throughout. Matrices are nalgebra `DMatrix` (analysis, not
//! the per-step path).

mod cantilever;
mod element;
mod link;

pub use cantilever::{Cantilever, ModeKind, Modes, Rayleigh};
pub use element::{element_mass, element_rotary_mass, element_stiffness, Section, NDOF_NODE};
pub use link::{BeamLink, BeamMaterial, PRESETS};
