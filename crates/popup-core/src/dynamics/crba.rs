//! Composite-rigid-body algorithm: the joint-space mass matrix M(q) of the bare chain.
//!
//! Composite inertias are accumulated tip → base about each frame origin; the motion
//! subspace of joint i in body-i axes at origin i is the constant `S_i = [u_i; u_i × r_i]`,
//! so `M_ii = S_iᵀ Ic_i S_i` and the off-diagonal terms follow by transforming the force
//! `Ic_i S_i` down the chain.

use crate::math::{Mat3, MatN, NMAX};
use crate::model::{Model, Rbi};

/// Mass matrix M(q) (leading nv × nv block; the rest 0) [kg·m²] without armature.
#[inline]
pub fn crba(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX]) -> MatN {
    let nv = model.nv;
    let mut m = MatN::zeros();
    let mut ic = *body;
    for i in (1..nv).rev() {
        let c = ic[i].to_parent(&rot[i], &model.joints[i].r);
        ic[i - 1] = ic[i - 1].add(&c);
    }
    for i in 0..nv {
        let ji = &model.joints[i];
        let (sw, sv) = (ji.u, ji.u.cross(&ji.r));
        let c = &ic[i];
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
    m
}
