//! Kinematics: the PRBM chain (7 joints, more with segments and torsion joints) and the rigid
//! 3-DOF equivalents.

pub mod prbm;
pub mod rigid;
