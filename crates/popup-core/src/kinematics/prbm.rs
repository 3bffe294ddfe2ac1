//! Forward kinematics of the PRBM chain (7 joints, or up to `NMAX` with segments and
//! torsion joints): the pose of every body frame in the base (world) frame W.

use crate::math::{Mat3, Vec3, VecN, NMAX};
use crate::model::Model;

/// Poses of the frames 0..=nv in the base frame: `R_WB[i]`, `p_WB[i]` (frame 0 = base;
/// entries beyond nv are identity / zero).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frames {
    /// Orientation of frame i in W.
    pub r_wb: [Mat3; NMAX + 1],
    /// Origin of frame i in W [m].
    pub p_wb: [Vec3; NMAX + 1],
}

impl Frames {
    /// A point given in body frame `b` (1-based frame number) expressed in W [m].
    pub fn point(&self, b: usize, p_b: &Vec3) -> Vec3 {
        self.p_wb[b] + self.r_wb[b] * p_b
    }
}

/// Forward kinematics at joint coordinates `q` [rad].
pub fn frames(model: &Model, q: &VecN) -> Frames {
    frames_with(model, &model.rotations(q))
}

/// Forward kinematics from the joint rotations `R_{i-1,i}` (see [`Model::rotations`]).
pub fn frames_with(model: &Model, rot: &[Mat3; NMAX]) -> Frames {
    let mut r_wb = [Mat3::identity(); NMAX + 1];
    let mut p_wb = [Vec3::zeros(); NMAX + 1];
    for i in 0..model.nv {
        r_wb[i + 1] = r_wb[i] * rot[i];
        p_wb[i + 1] = p_wb[i] + r_wb[i + 1] * model.joints[i].r;
    }
    Frames { r_wb, p_wb }
}

/// End-effector position p_WE [m] (the arm's end-effector mount).
pub fn end_effector(model: &Model, q: &VecN) -> Vec3 {
    let f = frames(model, q);
    f.point(model.ee.0 + 1, &model.ee.1)
}
