//! Fixed-size linear-algebra aliases (no heap allocation, deterministic kernels).

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Number of joints of the PRBM chain (3 motors + 4 bending joints).
pub const NV: usize = 7;
/// Number of motor joints.
pub const NM: usize = 3;
/// Number of bending joints.
pub const NB: usize = 4;

/// 3-vector.
pub type Vec3 = Vector3<f64>;
/// 3×3 matrix.
pub type Mat3 = Matrix3<f64>;
/// Joint-space vector (nv).
pub type VecN = SVector<f64, NV>;
/// Joint-space matrix (nv × nv).
pub type MatN = SMatrix<f64, NV, NV>;

/// Skew-symmetric matrix with `skew(a) * b = a × b`.
#[inline]
pub fn skew(a: &Vec3) -> Mat3 {
    Mat3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// Rotation `Rot_z(θ) Rot_x(α)` from `(cos θ, sin θ, cos α, sin α)`.
#[inline]
pub fn rot_zx(ct: f64, st: f64, ca: f64, sa: f64) -> Mat3 {
    Mat3::new(ct, -st * ca, st * sa, st, ct * ca, -ct * sa, 0.0, sa, ca)
}
