//! Kinematics: the 7-DOF PRBM chain and the rigid 3-DOF equivalents.

pub mod prbm;
pub mod rigid;
