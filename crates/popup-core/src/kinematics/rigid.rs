//! Rigid 3-DOF kinematics of the POP-UP arm (thesis Tables 1 and 2).
//!
//! Conventions: base frame W (= frame 0) with z up; standard Denavit–Hartenberg,
//! `A_i = Rot_z(θ_i) · Trans_z(d_i) · Trans_x(a_i) · Rot_x(α_i)` with
//! `θ_i = q_i + theta_offset_i`; joint i turns about the z axis of frame i−1; the end
//! effector E is the origin of frame 3.
//!
//! For the POP-UP structure (α = (π/2, 0, 0), a1 = 0) the forward kinematics is, with
//! `r = a2 c2 + a3 c23`, `z = a2 s2 + a3 s23` and the lateral offset `D = d2 + d3`
//! (angles are the DH angles θ_i):
//!
//! ```text
//! p_WE = (c1 r + s1 D,  s1 r − c1 D,  d1 + z)
//! ```
//!
//! so `x² + y² = r² + D²`; this is what the closed-form [`RigidArm::ik`] inverts. With
//! d = 0 it reduces to thesis eqs. 2.30–2.41.
//!
//! The linear part of the geometric Jacobian has
//! `det J_v = −a2 a3 sin θ3 (a2 cos θ2 + a3 cos(θ2 + θ3))`, independent of d1 and D:
//! the arm is singular when the elbow is straight or folded (`sin θ3 = 0`) or when the
//! end effector lies on the shoulder singular surface `r = 0` (on the base z axis for
//! D = 0, on the cylinder of radius |D| around it otherwise).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{Matrix3, SMatrix, Vector3};

use crate::error::{Error, Result};

/// Tolerance on α and a1 when checking that a table has the structure the closed-form
/// IK needs (α = (π/2, 0, 0), a1 = 0) [rad] / [m].
pub const STRUCTURE_TOL: f64 = 1e-12;

/// Distance `|a2 c2 + a3 c23|` of the end effector from the shoulder singular surface
/// below which [`RigidArm::ik`] reports [`Error::Singular`] [m].
///
/// With a lateral offset D ≠ 0, r = sqrt(x² + y² − D²) is only resolved to about
/// sqrt(2 |D| δ) for a target known to δ (≈ 1e-8 m for |D| = 0.07 m and δ ≈ 1e-15 m), so
/// the tolerance sits well above that.
pub const SHOULDER_SINGULAR_TOL: f64 = 1e-6;

/// Round-off accepted on the elbow cosine at the workspace boundary before a target is
/// called unreachable (|c3| ≤ 1 + this is clamped to ±1).
const C3_ROUNDOFF: f64 = 1e-12;

/// DH table of a rigid 3-DOF revolute arm (lengths [m], angles [rad]).
#[derive(Debug, Clone, PartialEq)]
pub struct RigidArm {
    /// Name of the table, used in error messages.
    pub name: String,
    /// DH offsets d_i along z_{i−1} [m].
    pub d: [f64; 3],
    /// DH lengths a_i along x_i [m].
    pub a: [f64; 3],
    /// DH twists α_i about x_i [rad].
    pub alpha: [f64; 3],
    /// Constant offsets added to the joint angles, θ_i = q_i + theta_offset_i [rad].
    pub theta_offset: [f64; 3],
}

/// Shoulder branch of an IK solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shoulder {
    /// The end effector is in front of the shoulder: `a2 c2 + a3 c23 > 0` (reaching
    /// towards the target along x_1).
    Front,
    /// The end effector is behind the shoulder: `a2 c2 + a3 c23 < 0` (q1 turned by about
    /// π, reaching over the top).
    Back,
}

/// Elbow branch of an IK solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Elbow {
    /// The elbow (origin of frame 2) is above the straight line from the shoulder
    /// (origin of frame 1) to the end effector.
    Up,
    /// The elbow is below that line.
    Down,
}

/// One closed-form inverse-kinematics solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolution {
    /// Joint angles q, each wrapped to (−π, π] [rad].
    pub q: [f64; 3],
    /// Shoulder branch.
    pub shoulder: Shoulder,
    /// Elbow branch.
    pub elbow: Elbow,
}

/// Singularity report of a configuration (see [`RigidArm::singularity`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Singularity {
    /// Elbow singularity: the elbow is straight or folded (|sin θ3| ≤ tol).
    pub elbow: bool,
    /// Shoulder singularity: the end effector lies on the shoulder singular surface
    /// (|a2 c2 + a3 c23| ≤ tol · (|a2| + |a3|)).
    pub shoulder: bool,
    /// sin θ3 [-]; zero at the elbow singularity.
    pub elbow_measure: f64,
    /// a2 cos θ2 + a3 cos(θ2 + θ3) [m]; zero at the shoulder singularity.
    pub shoulder_measure: f64,
}

/// Geometry of a target that passed the workspace check.
struct Reach {
    /// |r| = sqrt(x² + y² − D²) [m].
    r_abs: f64,
    /// Height above the shoulder, z − d1 [m].
    z_rel: f64,
    /// Elbow cosine, clamped to [−1, 1].
    c3: f64,
}

impl RigidArm {
    /// Builds a DH table; every number must be finite.
    ///
    /// `d`, `a` [m]; `alpha`, `theta_offset` [rad].
    pub fn new(
        name: impl Into<String>,
        d: [f64; 3],
        a: [f64; 3],
        alpha: [f64; 3],
        theta_offset: [f64; 3],
    ) -> Result<Self> {
        let columns: [(&str, &[f64; 3]); 4] = [
            ("d", &d),
            ("a", &a),
            ("alpha", &alpha),
            ("theta_offset", &theta_offset),
        ];
        for (col, values) in columns {
            for (i, v) in values.iter().enumerate() {
                if !v.is_finite() {
                    return Err(Error::param(
                        format!("rigid DH table {col}[{i}]"),
                        v,
                        "must be finite",
                    ));
                }
            }
        }
        Ok(Self {
            name: name.into(),
            d,
            a,
            alpha,
            theta_offset,
        })
    }

    /// Thesis Table 1, the arm as built: d = (0.15, 0.05, −0.12) m,
    /// a = (0, 0.745, 0.685) m, α = (π/2, 0, 0), no angle offsets.
    pub fn table1() -> Self {
        Self {
            name: "popup-lab table 1 (as built)".to_string(),
            d: [0.15, 0.05, -0.12],
            a: [0.0, 0.745, 0.685],
            alpha: [FRAC_PI_2, 0.0, 0.0],
            theta_offset: [0.0; 3],
        }
    }

    /// Thesis Table 2, the idealised arm without offsets: d = 0,
    /// a = (0, 0.745, 0.685) m, α = (π/2, 0, 0).
    pub fn table2() -> Self {
        Self {
            name: "popup-lab table 2 (no offsets)".to_string(),
            d: [0.0; 3],
            a: [0.0, 0.745, 0.685],
            alpha: [FRAC_PI_2, 0.0, 0.0],
            theta_offset: [0.0; 3],
        }
    }

    /// Lateral offset D = d2 + d3 of the arm plane from the base z axis [m].
    pub fn lateral_offset(&self) -> f64 {
        self.d[1] + self.d[2]
    }

    /// Reach of the two links in the arm plane, `(||a2| − |a3||, |a2| + |a3|)` [m]:
    /// the distance from the shoulder axis to the end effector, measured in the arm plane,
    /// lies in this closed interval.
    pub fn planar_reach(&self) -> (f64, f64) {
        let (a2, a3) = (self.a[1].abs(), self.a[2].abs());
        ((a2 - a3).abs(), a2 + a3)
    }

    /// DH joint angles θ = q + theta_offset [rad].
    fn theta(&self, q: &[f64; 3]) -> [f64; 3] {
        [
            q[0] + self.theta_offset[0],
            q[1] + self.theta_offset[1],
            q[2] + self.theta_offset[2],
        ]
    }

    /// Poses of frames 0..3 in the base frame: element i is `(R_Wi, p_Wi)` with R_Wi the
    /// rotation of frame i and p_Wi its origin [m]; element 0 is the base (identity, 0)
    /// and element 3 the end-effector frame. `q` [rad].
    pub fn frames(&self, q: &[f64; 3]) -> [(Matrix3<f64>, Vector3<f64>); 4] {
        let theta = self.theta(q);
        let mut out = [(Matrix3::identity(), Vector3::zeros()); 4];
        for i in 0..3 {
            let (st, ct) = theta[i].sin_cos();
            let (sa, ca) = self.alpha[i].sin_cos();
            // Rot_z(θ) · Rot_x(α) and the translation of Trans_z(d) · Trans_x(a).
            #[rustfmt::skip]
            let r_local = Matrix3::new(
                ct, -st * ca,  st * sa,
                st,  ct * ca, -ct * sa,
                0.0,      sa,       ca,
            );
            let p_local = Vector3::new(self.a[i] * ct, self.a[i] * st, self.d[i]);
            let (r_prev, p_prev) = out[i];
            out[i + 1] = (r_prev * r_local, p_prev + r_prev * p_local);
        }
        out
    }

    /// Forward kinematics: end-effector position p_WE in the base frame [m] for joint
    /// angles `q` [rad].
    pub fn fk(&self, q: &[f64; 3]) -> Vector3<f64> {
        self.frames(q)[3].1
    }

    /// Geometric Jacobian at `q` [rad]: rows 0..3 map q̇ [rad/s] to the end-effector linear
    /// velocity v_WE [m/s], rows 3..6 to the angular velocity ω_W3 [rad/s], both in the
    /// base frame. Column i is `[z_{i−1} × (p_WE − p_W(i−1)); z_{i−1}]`.
    pub fn jacobian(&self, q: &[f64; 3]) -> SMatrix<f64, 6, 3> {
        let frames = self.frames(q);
        let p_e = frames[3].1;
        let mut j = SMatrix::<f64, 6, 3>::zeros();
        for (i, (r_prev, p_prev)) in frames.iter().take(3).enumerate() {
            let z: Vector3<f64> = r_prev.column(2).into_owned();
            let v = z.cross(&(p_e - p_prev));
            j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
            j.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
        }
        j
    }

    /// Manipulability |det J_v| [m³/rad³] of the 3×3 linear part of [`Self::jacobian`].
    ///
    /// For the POP-UP structure `det J_v = −a2 a3 sin θ3 (a2 cos θ2 + a3 cos(θ2 + θ3))`
    /// exactly (negative sign in this DH convention, no dependence on d1, d2, d3), so this
    /// is zero at the elbow and shoulder singularities.
    pub fn manipulability(&self, q: &[f64; 3]) -> f64 {
        let j = self.jacobian(q);
        j.fixed_view::<3, 3>(0, 0).determinant().abs()
    }

    /// Singularity report at `q` [rad] for the POP-UP structure (α = (π/2, 0, 0), a1 = 0;
    /// for other tables the measures are computed the same way but do not characterise the
    /// singularities, use [`Self::manipulability`]).
    ///
    /// `tol` [-] is applied to the elbow measure sin θ3 directly and to the shoulder
    /// measure a2 c2 + a3 c23 [m] relative to the full reach |a2| + |a3|.
    pub fn singularity(&self, q: &[f64; 3], tol: f64) -> Singularity {
        let theta = self.theta(q);
        let elbow_measure = theta[2].sin();
        let shoulder_measure = self.a[1] * theta[1].cos() + self.a[2] * (theta[1] + theta[2]).cos();
        let reach = self.a[1].abs() + self.a[2].abs();
        Singularity {
            elbow: elbow_measure.abs() <= tol,
            shoulder: shoulder_measure.abs() <= tol * reach,
            elbow_measure,
            shoulder_measure,
        }
    }

    /// Checks that the target p_WE [m] is inside the workspace of the closed-form IK.
    ///
    /// Errors: [`Error::InvalidParameter`] if the table does not have the POP-UP structure;
    /// [`Error::Unreachable`] for a non-finite target, a target closer to the base z axis
    /// than the lateral offset |d2 + d3|, or a target whose distance from the shoulder
    /// axis in the arm plane is outside [`Self::planar_reach`] (the reason states that
    /// distance and the reachable range in metres). Targets on the shoulder singular
    /// surface are reachable and pass.
    pub fn in_workspace(&self, p: &Vector3<f64>) -> Result<()> {
        self.reach(p).map(|_| ())
    }

    /// Closed-form inverse kinematics: all four joint solutions reaching the target p_WE [m],
    /// in the order (Front, Up), (Front, Down), (Back, Up), (Back, Down). Angles are wrapped
    /// to (−π, π] [rad]. At the workspace boundary (elbow straight or folded) the Up and
    /// Down solutions coincide.
    ///
    /// Needs the POP-UP structure α = (π/2, 0, 0), a1 = 0, a2 ≠ 0, a3 ≠ 0 (any d and
    /// theta offsets), else [`Error::InvalidParameter`]. Unreachable targets give
    /// [`Error::Unreachable`] (see [`Self::in_workspace`]); nothing is clamped except
    /// round-off at the boundary. A target on the shoulder singular surface
    /// (|a2 c2 + a3 c23| < [`SHOULDER_SINGULAR_TOL`]) gives [`Error::Singular`].
    pub fn ik(&self, p: &Vector3<f64>) -> Result<[IkSolution; 4]> {
        let Reach { r_abs, z_rel, c3 } = self.reach(p)?;
        let d_lat = self.lateral_offset();
        if r_abs < SHOULDER_SINGULAR_TOL {
            let where_ = if d_lat == 0.0 {
                "lies on the base z axis (the q1 axis), so every q1 reaches it".to_string()
            } else {
                format!(
                    "lies on the cylinder of radius |d2 + d3| = {:.6} m around the base z axis, \
                     where the front and back solutions merge and the Jacobian loses rank",
                    d_lat.abs()
                )
            };
            return Err(Error::Singular(format!(
                "shoulder singularity for {}: target p = [{:.6}, {:.6}, {:.6}] m {where_} \
                 (a2 c2 + a3 c23 = {r_abs:.3e} m); move the target off it or choose q1 from \
                 the current configuration",
                self.name, p[0], p[1], p[2]
            )));
        }
        let (a2, a3) = (self.a[1], self.a[2]);
        let s3_abs = (1.0 - c3 * c3).max(0.0).sqrt();
        let phi = p[1].atan2(p[0]);
        let mut out = [IkSolution {
            q: [0.0; 3],
            shoulder: Shoulder::Front,
            elbow: Elbow::Up,
        }; 4];
        let mut k = 0;
        for (shoulder, r) in [(Shoulder::Front, r_abs), (Shoulder::Back, -r_abs)] {
            let th1 = phi - (-d_lat).atan2(r);
            for elbow in [Elbow::Up, Elbow::Down] {
                // The elbow is above the shoulder→end-effector line iff r a2 a3 s3 < 0.
                let up_sign = -(r * a2 * a3).signum();
                let s3 = if elbow == Elbow::Up {
                    up_sign * s3_abs
                } else {
                    -up_sign * s3_abs
                };
                let th3 = s3.atan2(c3);
                let th2 = z_rel.atan2(r) - (a3 * s3).atan2(a2 + a3 * c3);
                let theta = [th1, th2, th3];
                let mut q = [0.0; 3];
                for i in 0..3 {
                    q[i] = wrap_pi(theta[i] - self.theta_offset[i]);
                }
                out[k] = IkSolution { q, shoulder, elbow };
                k += 1;
            }
        }
        Ok(out)
    }

    /// Structure check for the closed-form IK.
    fn check_ik_structure(&self) -> Result<()> {
        const NEED: &str =
            "closed-form IK needs the POP-UP structure alpha = (pi/2, 0, 0), a1 = 0, \
                            a2 != 0, a3 != 0";
        let expected_alpha = [FRAC_PI_2, 0.0, 0.0];
        for (i, (&alpha, &expected)) in self.alpha.iter().zip(&expected_alpha).enumerate() {
            if (alpha - expected).abs() > STRUCTURE_TOL {
                return Err(Error::param(
                    format!("{}: alpha[{i}]", self.name),
                    alpha,
                    NEED,
                ));
            }
        }
        if self.a[0].abs() > STRUCTURE_TOL {
            return Err(Error::param(
                format!("{}: a[0]", self.name),
                self.a[0],
                NEED,
            ));
        }
        for i in 1..3 {
            if self.a[i] == 0.0 {
                return Err(Error::param(
                    format!("{}: a[{i}]", self.name),
                    self.a[i],
                    NEED,
                ));
            }
        }
        Ok(())
    }

    /// Workspace check shared by [`Self::ik`] and [`Self::in_workspace`].
    fn reach(&self, p: &Vector3<f64>) -> Result<Reach> {
        self.check_ik_structure()?;
        let unreachable = |reason: String| Error::Unreachable {
            target: [p[0], p[1], p[2]],
            arm: self.name.clone(),
            reason,
        };
        if !p.iter().all(|v| v.is_finite()) {
            return Err(unreachable(
                "the target has a non-finite coordinate (NaN or inf)".into(),
            ));
        }
        let d_lat = self.lateral_offset();
        let rho2 = p[0] * p[0] + p[1] * p[1];
        let r2 = rho2 - d_lat * d_lat;
        // Round-off of rho² − D² near the offset cylinder; below it the target is on the
        // singular surface, not outside the workspace.
        let slack = SHOULDER_SINGULAR_TOL * SHOULDER_SINGULAR_TOL
            + 4.0 * f64::EPSILON * (rho2 + d_lat * d_lat);
        if r2 < -slack {
            return Err(unreachable(format!(
                "its distance from the base z axis rho = {:.6} m is less than the lateral offset \
                 |d2 + d3| = {:.6} m; reachable: rho >= {:.6} m",
                rho2.sqrt(),
                d_lat.abs(),
                d_lat.abs()
            )));
        }
        let r_abs = r2.max(0.0).sqrt();
        let z_rel = p[2] - self.d[0];
        let (a2, a3) = (self.a[1], self.a[2]);
        let ell2 = r_abs * r_abs + z_rel * z_rel;
        let c3 = (ell2 - a2 * a2 - a3 * a3) / (2.0 * a2 * a3);
        // Signed a's are allowed, so the range test is on c3·sign(a2 a3): +1 is full
        // stretch, −1 full fold.
        let c3_abs_dir = c3 * (a2 * a3).signum();
        if c3_abs_dir.abs() > 1.0 + C3_ROUNDOFF {
            let (lo, hi) = self.planar_reach();
            let ell = ell2.sqrt();
            let dist = (ell2 + d_lat * d_lat).sqrt();
            let side = if c3_abs_dir > 0.0 {
                format!("beyond the reach |a2| + |a3| = {hi:.6} m")
            } else {
                format!("inside the inner limit ||a2| - |a3|| = {lo:.6} m")
            };
            return Err(unreachable(format!(
                "its distance from the shoulder axis in the arm plane l = {ell:.6} m is {side}; \
                 reachable: {lo:.6} m <= l <= {hi:.6} m (distance from the shoulder centre \
                 (0, 0, d1) = {dist:.6} m, reachable {:.6} m to {:.6} m)",
                (lo * lo + d_lat * d_lat).sqrt(),
                (hi * hi + d_lat * d_lat).sqrt()
            )));
        }
        Ok(Reach {
            r_abs,
            z_rel,
            c3: c3.clamp(-1.0, 1.0),
        })
    }
}

/// Wraps an angle [rad] to (−π, π].
fn wrap_pi(a: f64) -> f64 {
    if a > -PI && a <= PI {
        return a;
    }
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI {
        w + TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_range() {
        for a in [-7.0, -PI, -3.0, 0.0, 3.0, PI, 4.0, 10.0 * PI, -10.0 * PI] {
            let w = wrap_pi(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(((a - w) / TAU - ((a - w) / TAU).round()).abs() < 1e-12);
        }
        assert_eq!(wrap_pi(-PI), PI);
    }

    #[test]
    fn zero_pose_and_ik_roundtrip() {
        let arm = RigidArm::table1();
        let p = arm.fk(&[0.0; 3]);
        assert!((p - Vector3::new(1.43, 0.07, 0.15)).norm() < 1e-12);
        let q = [0.3, -0.4, 1.1];
        let p = arm.fk(&q);
        for s in arm.ik(&p).unwrap() {
            assert!((arm.fk(&s.q) - p).norm() < 1e-10);
        }
    }

    #[test]
    fn det_jv_sign() {
        let arm = RigidArm::table1();
        let q = [0.2, 0.5, 0.9];
        let j = arm.jacobian(&q);
        let det = j.fixed_view::<3, 3>(0, 0).determinant();
        let (a2, a3) = (arm.a[1], arm.a[2]);
        let r = a2 * q[1].cos() + a3 * (q[1] + q[2]).cos();
        assert!((det + a2 * a3 * q[2].sin() * r).abs() < 1e-12);
    }
}
