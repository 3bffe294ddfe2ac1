//! Recursive Newton–Euler inverse dynamics in body frames.
//!
//! Forward pass (base → tip), classical accelerations of the frame origins, base
//! accelerating with −g so that gravity needs no separate term:
//! `ω_i = Eᵢ ω_{i-1} + u_i q̇_i`, `ω̇_i = Eᵢ ω̇_{i-1} + u_i q̈_i + (Eᵢ ω_{i-1}) × u_i q̇_i`,
//! `a_i = Eᵢ a_{i-1} + ω̇_i × r_i + ω_i × (ω_i × r_i)` with `Eᵢ = R_{i-1,i}ᵀ`.
//! The origin acceleration `a_i` is then the specific force of a point at origin i.
//! Backward pass: `f_i = m a_i + ω̇ × h + ω × (ω × h) + R_{i+1} f_{i+1}`,
//! `n_i = J ω̇ + ω × J ω + h × a_i + R_{i+1}(n_{i+1} + r_{i+1} × f_{i+1})`,
//! `τ_i = u_i · (n_i + r_i × f_i)` (moment about the joint axis through origin i-1).

use crate::math::{Mat3, Vec3, VecN, NMAX};
use crate::model::{Model, Rbi};

/// Body velocities and accelerations from the forward pass, in body axes (entries `>= nv`
/// are 0).
#[derive(Debug, Clone, Copy)]
pub struct BodyMotion {
    /// Angular velocity ω_i [rad/s].
    pub w: [Vec3; NMAX],
    /// Angular acceleration ω̇_i [rad/s²].
    pub wd: [Vec3; NMAX],
    /// Classical acceleration of origin i minus gravity (specific force) [m/s²].
    pub a: [Vec3; NMAX],
}

/// Forward pass: body motion for joint rates `v` and accelerations `qdd`, with the base
/// accelerating at `a0 = −g` (base axes).
#[inline]
pub fn forward_pass(model: &Model, rot: &[Mat3; NMAX], v: &VecN, qdd: &VecN, a0: &Vec3) -> BodyMotion {
    let mut w = [Vec3::zeros(); NMAX];
    let mut wd = [Vec3::zeros(); NMAX];
    let mut a = [Vec3::zeros(); NMAX];
    let (mut wp, mut wdp, mut ap) = (Vec3::zeros(), Vec3::zeros(), *a0);
    for i in 0..model.nv {
        let j = &model.joints[i];
        let e = rot[i].transpose();
        let we = e * wp;
        let wi = we + j.u * v[i];
        let wdi = e * wdp + j.u * qdd[i] + we.cross(&(j.u * v[i]));
        let ai = e * ap + wdi.cross(&j.r) + wi.cross(&wi.cross(&j.r));
        w[i] = wi;
        wd[i] = wdi;
        a[i] = ai;
        wp = wi;
        wdp = wdi;
        ap = ai;
    }
    BodyMotion { w, wd, a }
}

/// Joint forces τ = M(q) q̈ + C(q, q̇) q̇ + G(q) of the bare chain (no springs, dampers or
/// armature) [N·m]. `g` is gravity in the base frame [m/s²].
#[inline]
pub fn rnea(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX], v: &VecN, qdd: &VecN, g: &Vec3) -> VecN {
    let bm = forward_pass(model, rot, v, qdd, &(-g));
    backward_pass(model, body, rot, &bm)
}

/// Backward pass of RNEA given the body motion.
#[inline]
pub fn backward_pass(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX], bm: &BodyMotion) -> VecN {
    let mut tau = VecN::zeros();
    let mut fc = Vec3::zeros();
    let mut nc = Vec3::zeros();
    let nv = model.nv;
    for i in (0..nv).rev() {
        let b = &body[i];
        let (w, wd, a) = (bm.w[i], bm.wd[i], bm.a[i]);
        let mut f = a * b.m + wd.cross(&b.h) + w.cross(&w.cross(&b.h));
        let mut n = b.j * wd + w.cross(&(b.j * w)) + b.h.cross(&a);
        if i + 1 < nv {
            let rc = &rot[i + 1];
            let rn = &model.joints[i + 1].r;
            f += rc * fc;
            n += rc * (nc + rn.cross(&fc));
        }
        let j = &model.joints[i];
        tau[i] = j.u.dot(&(n + j.r.cross(&f)));
        fc = f;
        nc = n;
    }
    tau
}
