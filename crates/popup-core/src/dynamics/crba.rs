//! Composite-rigid-body algorithm: the joint-space mass matrix M(q) of the bare chain.
//!
//! Composite inertias are accumulated tip → base about each frame origin; the motion
//! subspace of joint i in body-i axes at origin i is the constant `S_i = [u_i; u_i × r_i]`,
//! so `M_ii = S_iᵀ Ic_i S_i` and the off-diagonal terms follow by transforming the force
//! `Ic_i S_i` down the chain.

use crate::math::{Mat3, MatN, NMAX};
use crate::model::{Model, Rbi};

/// Mass matrix M(q) (leading nv × nv block; the rest 0) [kg·m²] without armature.
///
/// One tip → base sweep: the composite inertia of body i (`body[i]` plus its child's
/// composite moved to frame i) is formed and at once used for row/column i.
#[inline]
pub fn crba(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX]) -> MatN {
    let mut m = MatN::zeros();
    crba_into(model, body, rot, &mut m);
    m
}

/// [`crba`] into `m`: writes every entry of the leading nv × nv block and nothing else (a
/// scratch matrix that is zero outside that block stays so; no 17 × 17 clearing per call).
#[inline]
pub fn crba_into(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX], m: &mut MatN) {
    let nv = model.nv;
    let mut c = body[nv - 1];
    for i in (0..nv).rev() {
        if i + 1 < nv {
            c = body[i].add(&c.to_parent(&rot[i + 1], &model.joints[i + 1].r));
        }
        let ji = &model.joints[i];
        let (sw, sv) = (ji.u, ji.u.cross(&ji.r));
        // force (n, f) = Ic S about origin i
        let mut n = c.j * sw + c.h.cross(&sv);
        let mut f = sv * c.m + sw.cross(&c.h);
        m[(i, i)] = sw.dot(&n) + sv.dot(&f);
        for k in (0..i).rev() {
            let jk1 = &model.joints[k + 1];
            let rr = &rot[k + 1];
            let n2 = rr * (n + jk1.r.cross(&f));
            f = rr * f;
            n = n2;
            let jk = &model.joints[k];
            let v = jk.u.dot(&n) + jk.u.cross(&jk.r).dot(&f);
            m[(i, k)] = v;
            m[(k, i)] = v;
        }
    }
}
