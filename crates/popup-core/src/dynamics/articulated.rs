//! O(nv) forward dynamics: an articulated-body algorithm specialised to the revolute chain,
//! hybrid (free joints with given forces, prescribed joints with given accelerations).
//!
//! Same frames as [`crate::dynamics::rnea`]: body i (moved by joint i) about origin i in
//! body-i axes; joint i turns about `u_i` through origin i−1, which sits at `−r_i` from
//! origin i; `R_i = R_{i−1,i}` (`model.rotations(q)`) maps body-i axes to body-(i−1) axes,
//! `E_i = R_iᵀ`. Spatial quantities are split into 3-vectors `[angular; linear]`, and the
//! accelerations are the classical ones of RNEA (`ω̇_i`, `a_i` the acceleration of origin i),
//! the base accelerating with −g, so gravity needs no separate term.
//!
//! Articulated inertias are symmetric 6×6 matrices kept as three 3×3 blocks
//! `[[A, B], [Bᵀ, C]]`. Each joint is handled at its own axis point: the tip-side inertia
//! is shifted from origin i to origin i−1 (body-i axes), where the motion subspace is
//! `s = [u; 0]`, so that `U = I s = [A u; Bᵀ u]`, `D = uᵀ A u + armature` and the
//! rank-1 update `I − U Uᵀ / D` are a few 3×3 operations; the result is rotated into the
//! parent's axes (block rotations `R X Rᵀ`) and added to the parent's inertia. Per joint:
//! one shift (cross products), one rank-1 update, three block rotations, nothing of size
//! nv: the cost is linear in nv with a constant of roughly 400 multiplications (about
//! 115 ns per joint on the development machine; `examples/step_cost.rs` measures it).
//!
//! Everything lives in fixed arrays of [`NMAX`]; nothing is allocated.

use crate::drive::Drive;
use crate::forward::{add_drive_torques, passive};
use crate::math::{Mat3, Vec3, VecN, NMAX};
use crate::model::{Model, Rbi};
use crate::params::ParamData;

/// How a joint enters the hybrid problem.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// q̈ unknown, generalised force given.
    Free,
    /// q̈ given [rad/s²] (replayed motor, or 0 for a locked joint).
    Prescribed(f64),
}

/// Symmetric 6×6 inertia `[[a, b], [bᵀ, c]]` about a point [kg·m², kg·m, kg].
#[derive(Debug, Clone, Copy)]
struct Inertia6 {
    a: Mat3,
    b: Mat3,
    c: Mat3,
}

impl Inertia6 {
    /// Rigid body: `[[J, ĥ], [ĥᵀ, m 1]]`.
    #[inline(always)]
    fn rigid(b: &Rbi) -> Inertia6 {
        let h = b.h;
        Inertia6 {
            a: b.j,
            b: Mat3::new(0.0, -h.z, h.y, h.z, 0.0, -h.x, -h.y, h.x, 0.0),
            c: Mat3::from_diagonal_element(b.m),
        }
    }

    /// Move the reference point by `−r` (from origin i to origin i−1, same axes):
    /// `Tᵀ I T` with `T = [[1, 0], [−r̂, 1]]`, i.e. `B' = B + r̂ C`,
    /// `A' = A + r̂ Bᵀ − B' r̂`, `C' = C`.
    #[inline(always)]
    fn shift(&self, r: &Vec3) -> Inertia6 {
        let b = self.b + cross_cols(r, &self.c);
        let rbt = cross_cols(r, &self.b.transpose());
        let bpr = cols_cross(&b, r);
        let mut a = self.a;
        // symmetric: upper triangle, mirrored
        for j in 0..3 {
            for i in 0..=j {
                let x = a[(i, j)] + rbt[(i, j)] - bpr[(i, j)];
                a[(i, j)] = x;
                a[(j, i)] = x;
            }
        }
        Inertia6 { a, b, c: self.c }
    }

    /// `I x` for x = (xw, xv).
    #[inline(always)]
    fn mul(&self, xw: &Vec3, xv: &Vec3) -> (Vec3, Vec3) {
        (self.a * xw + self.b * xv, self.b.tr_mul(xw) + self.c * xv)
    }

    /// `I − U Uᵀ / d` for U = (uw, uv).
    #[inline(always)]
    fn rank1_sub(&mut self, uw: &Vec3, uv: &Vec3, dinv: f64) {
        let (sw, sv) = (uw * dinv, uv * dinv);
        for j in 0..3 {
            for i in 0..=j {
                let x = self.a[(i, j)] - sw[i] * uw[j];
                self.a[(i, j)] = x;
                self.a[(j, i)] = x;
                let y = self.c[(i, j)] - sv[i] * uv[j];
                self.c[(i, j)] = y;
                self.c[(j, i)] = y;
            }
            for i in 0..3 {
                self.b[(i, j)] -= sw[i] * uv[j];
            }
        }
    }

    /// `self += R X Rᵀ` blockwise (X expressed in the child axes, `rot` child → parent).
    #[inline(always)]
    fn add_rotated(&mut self, x: &Inertia6, rot: &Mat3) {
        add_sym_rotated(&mut self.a, &x.a, rot);
        add_sym_rotated(&mut self.c, &x.c, rot);
        self.b += rot * x.b * rot.transpose();
    }
}

/// `r̂ M` (r × each column of M).
#[inline(always)]
fn cross_cols(r: &Vec3, m: &Mat3) -> Mat3 {
    let mut o = Mat3::zeros();
    for j in 0..3 {
        let c = m.column(j);
        o[(0, j)] = r.y * c[2] - r.z * c[1];
        o[(1, j)] = r.z * c[0] - r.x * c[2];
        o[(2, j)] = r.x * c[1] - r.y * c[0];
    }
    o
}

/// `M r̂` (row k of the result is `m_k × r`, m_k row k of M).
#[inline(always)]
fn cols_cross(m: &Mat3, r: &Vec3) -> Mat3 {
    let mut o = Mat3::zeros();
    for k in 0..3 {
        let (x, y, z) = (m[(k, 0)], m[(k, 1)], m[(k, 2)]);
        o[(k, 0)] = y * r.z - z * r.y;
        o[(k, 1)] = z * r.x - x * r.z;
        o[(k, 2)] = x * r.y - y * r.x;
    }
    o
}

/// `dst += R S Rᵀ` for symmetric S (upper triangle computed, mirrored).
#[inline(always)]
fn add_sym_rotated(dst: &mut Mat3, s: &Mat3, rot: &Mat3) {
    let rs = rot * s;
    for j in 0..3 {
        for i in 0..=j {
            let x = dst[(i, j)] + (rs[(i, 0)] * rot[(j, 0)] + rs[(i, 1)] * rot[(j, 1)] + rs[(i, 2)] * rot[(j, 2)]);
            dst[(i, j)] = x;
            dst[(j, i)] = x;
        }
    }
}

/// Hybrid forward dynamics of the bare chain (no springs or drive; those are in `tau`):
/// joint accelerations q̈ [rad/s²] at the configuration whose rotations are `rot`, with
/// joint rates `v` [rad/s], generalised forces `tau` on the free joints [N·m], `armature`
/// added on the joint diagonal [kg·m²] and gravity `g` in the base frame [m/s²].
///
/// The joints in `prescribed` (index, q̈ [rad/s²]) follow their given acceleration and the
/// joints in `locked` have q̈ = 0 (a joint in both is locked); their `tau` and `armature`
/// entries are ignored and their returned entries are the prescribed values. Equivalent
/// to solving `(M + diag(armature)) q̈ = tau − b(q, q̇)` on the free rows with the
/// prescribed q̈ moved to the right-hand side, in O(nv) and without allocation.
/// Returns NaN everywhere when an articulated pivot `uᵀ A u + armature` is not positive
/// (as `forward::accel` does when its Cholesky factorisation fails).
#[allow(clippy::too_many_arguments)]
pub fn articulated(
    model: &Model,
    body: &[Rbi; NMAX],
    rot: &[Mat3; NMAX],
    v: &VecN,
    tau: &VecN,
    armature: &[f64; NMAX],
    g: &Vec3,
    prescribed: &[(usize, f64)],
    locked: &[usize],
) -> VecN {
    let nv = model.nv;
    let mut mode = [Mode::Free; NMAX];
    for &(i, a) in prescribed {
        mode[i] = Mode::Prescribed(a);
    }
    for &i in locked {
        mode[i] = Mode::Prescribed(0.0);
    }

    // pass 1 (base → tip): angular velocities, bias accelerations at the joint point,
    // velocity-product forces, rigid inertias
    // c'_i = (ε_i, ω_i × (ω_i × r_i)): bias of (ω̇_i, a_i + r_i × ω̇_i) given the parent's motion
    let mut cw = [Vec3::zeros(); NMAX];
    let mut cv = [Vec3::zeros(); NMAX];
    let mut ia = [Inertia6 { a: Mat3::zeros(), b: Mat3::zeros(), c: Mat3::zeros() }; NMAX];
    let mut pn = [Vec3::zeros(); NMAX];
    let mut pf = [Vec3::zeros(); NMAX];
    let mut wp = Vec3::zeros();
    for i in 0..nv {
        let j = &model.joints[i];
        let we = rot[i].tr_mul(&wp);
        let uq = j.u * v[i];
        let wi = we + uq;
        cw[i] = we.cross(&uq);
        cv[i] = wi.cross(&wi.cross(&j.r));
        let b = &body[i];
        ia[i] = Inertia6::rigid(b);
        pn[i] = wi.cross(&(b.j * wi));
        pf[i] = wi.cross(&wi.cross(&b.h));
        wp = wi;
    }

    // pass 2 (tip → base): articulated inertias and bias forces, projected at each joint
    let mut uw = [Vec3::zeros(); NMAX];
    let mut uv = [Vec3::zeros(); NMAX];
    let mut dinv = [0.0; NMAX];
    let mut ut = [0.0; NMAX];
    for i in (0..nv).rev() {
        let j = &model.joints[i];
        let r = &j.r;
        let mut is = ia[i].shift(r);
        let mut fn_ = pn[i] + r.cross(&pf[i]);
        let mut ff = pf[i];
        match mode[i] {
            Mode::Free => {
                let a_u = is.a * j.u;
                let b_u = is.b.tr_mul(&j.u);
                let d = j.u.dot(&a_u) + armature[i];
                if d.is_nan() || d <= 0.0 {
                    return VecN::from_element(f64::NAN);
                }
                let di = 1.0 / d;
                let u_tau = tau[i] - j.u.dot(&fn_);
                uw[i] = a_u;
                uv[i] = b_u;
                dinv[i] = di;
                ut[i] = u_tau;
                is.rank1_sub(&a_u, &b_u, di);
                let (xw, xv) = is.mul(&cw[i], &cv[i]);
                let s = u_tau * di;
                fn_ += xw + a_u * s;
                ff += xv + b_u * s;
            }
            Mode::Prescribed(qdd) => {
                let (xw, xv) = is.mul(&(cw[i] + j.u * qdd), &cv[i]);
                fn_ += xw;
                ff += xv;
            }
        }
        if i > 0 {
            let ro = &rot[i];
            ia[i - 1].add_rotated(&is, ro);
            pn[i - 1] += ro * fn_;
            pf[i - 1] += ro * ff;
        }
    }

    // pass 3 (base → tip): accelerations
    let mut qdd = VecN::zeros();
    let (mut wdp, mut ap) = (Vec3::zeros(), -g);
    for i in 0..nv {
        let j = &model.joints[i];
        let bw = rot[i].tr_mul(&wdp) + cw[i];
        let bv = rot[i].tr_mul(&ap) + cv[i];
        let a = match mode[i] {
            Mode::Free => (ut[i] - uw[i].dot(&bw) - uv[i].dot(&bv)) * dinv[i],
            Mode::Prescribed(x) => x,
        };
        qdd[i] = a;
        let wd = bw + j.u * a;
        ap = bv + wd.cross(&j.r);
        wdp = wd;
    }
    qdd
}

/// Joint accelerations at time `t` [rad/s²] by the articulated-body algorithm: the same
/// model as [`crate::forward::accel`] with `h_implicit = 0` (passive springs and dampers,
/// beam-link elastic and Rayleigh forces, air drag, motor torques with saturation and
/// friction in torque drive; in replay the motors follow `am`; the locked joints of rigid
/// links at q̈ = 0). `q`, `v` must already be prescribed for replay
/// ([`crate::forward::prescribe`]). O(nv) apart from the dense beam blocks of the passive
/// forces (O(dof²) per beam link). The RK4 integrator uses it for arms with beam links.
#[inline]
pub fn accel_articulated(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>) -> VecN {
    accel_articulated_locked(model, pd, drive, t, q, v, am, &[])
}

/// [`accel_articulated`] with the joints in `locked` also held at q̈ = 0, besides the
/// model's own locked joints (rows replaced by q̈ = 0, as for a motor in replay; the
/// returned entries are 0).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn accel_articulated_locked(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, locked: &[usize]) -> VecN {
    let rot = model.rotations(q);
    let mut tau = passive(model, pd, t, q, v);
    let fx = &pd.params.effects;
    if fx.air_drag.cd > 0.0 {
        tau += crate::effects::drag_forces(model, &pd.drag.0[..pd.drag.1], fx.air_drag.cd, &rot, v);
    }
    let mut pres = [(usize::MAX, 0.0); 3];
    let np = match (drive, am) {
        (Drive::Torque(_) | Drive::Hold(_), _) => {
            add_drive_torques(model, pd, drive, t, v, &mut tau);
            0
        }
        (Drive::Replay(_), Some(am)) => {
            for (k, &i) in model.motor_idx.iter().enumerate() {
                pres[k] = (i, am[k]);
            }
            3
        }
        (Drive::Replay(_), None) => unreachable!("replay accelerations must be prescribed"),
    };
    let mut all = [usize::MAX; NMAX];
    let mut nl = 0;
    for &j in model.locked().iter().chain(locked) {
        if !all[..nl].contains(&j) {
            all[nl] = j;
            nl += 1;
        }
    }
    articulated(model, &pd.body, &rot, v, &tau, &model.armature, &model.gravity, &pres[..np], &all[..nl])
}
