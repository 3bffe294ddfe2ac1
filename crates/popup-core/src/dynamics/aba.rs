//! Articulated-body algorithm (Featherstone) with 6×6 spatial matrices.
//!
//! An independent forward-dynamics path used to cross-check CRBA + RNEA; it is not on the
//! hot path. Spatial vectors are `[angular; linear]` in body axes at the frame origin.

use crate::math::{skew, Mat3, Vec3, VecN, NMAX};
use crate::model::{Model, Rbi};
use nalgebra::{Matrix6, Vector6};

fn xform(rot: &Mat3, r: &Vec3) -> Matrix6<f64> {
    let e = rot.transpose();
    let mut x = Matrix6::zeros();
    x.fixed_view_mut::<3, 3>(0, 0).copy_from(&e);
    x.fixed_view_mut::<3, 3>(3, 3).copy_from(&e);
    x.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-skew(r) * e));
    x
}

fn inertia(b: &Rbi) -> Matrix6<f64> {
    let mut i = Matrix6::zeros();
    let hs = skew(&b.h);
    i.fixed_view_mut::<3, 3>(0, 0).copy_from(&b.j);
    i.fixed_view_mut::<3, 3>(0, 3).copy_from(&hs);
    i.fixed_view_mut::<3, 3>(3, 0).copy_from(&hs.transpose());
    i.fixed_view_mut::<3, 3>(3, 3).copy_from(&(Mat3::identity() * b.m));
    i
}

fn crm(v: &Vector6<f64>) -> Matrix6<f64> {
    let w = Vec3::new(v[0], v[1], v[2]);
    let l = Vec3::new(v[3], v[4], v[5]);
    let mut x = Matrix6::zeros();
    x.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew(&w));
    x.fixed_view_mut::<3, 3>(3, 3).copy_from(&skew(&w));
    x.fixed_view_mut::<3, 3>(3, 0).copy_from(&skew(&l));
    x
}

fn crf(v: &Vector6<f64>) -> Matrix6<f64> {
    -crm(v).transpose()
}

/// Forward dynamics q̈ = ABA(q, q̇, τ) of the bare chain with `armature` added on the joint
/// diagonal; `g` gravity in the base frame [m/s²].
pub fn aba(model: &Model, body: &[Rbi; NMAX], rot: &[Mat3; NMAX], v: &VecN, tau: &VecN, armature: &[f64; NMAX], g: &Vec3) -> VecN {
    let nv = model.nv;
    let mut x = [Matrix6::zeros(); NMAX];
    let mut s = [Vector6::zeros(); NMAX];
    let mut vel = [Vector6::zeros(); NMAX];
    let mut c = [Vector6::zeros(); NMAX];
    let mut ia = [Matrix6::zeros(); NMAX];
    let mut pa = [Vector6::zeros(); NMAX];
    let mut vp = Vector6::zeros();
    for i in 0..nv {
        let j = &model.joints[i];
        x[i] = xform(&rot[i], &j.r);
        let uxr = j.u.cross(&j.r);
        s[i] = Vector6::new(j.u.x, j.u.y, j.u.z, uxr.x, uxr.y, uxr.z);
        vel[i] = x[i] * vp + s[i] * v[i];
        c[i] = crm(&vel[i]) * s[i] * v[i];
        ia[i] = inertia(&body[i]);
        pa[i] = crf(&vel[i]) * ia[i] * vel[i];
        vp = vel[i];
    }
    let mut uu = [Vector6::zeros(); NMAX];
    let mut d = [0.0; NMAX];
    let mut u = [0.0; NMAX];
    for i in (0..nv).rev() {
        uu[i] = ia[i] * s[i];
        d[i] = s[i].dot(&uu[i]) + armature[i];
        u[i] = tau[i] - s[i].dot(&pa[i]);
        if i > 0 {
            let iam = ia[i] - uu[i] * uu[i].transpose() / d[i];
            let pam = pa[i] + iam * c[i] + uu[i] * (u[i] / d[i]);
            ia[i - 1] += x[i].transpose() * iam * x[i];
            pa[i - 1] += x[i].transpose() * pam;
        }
    }
    let mut qdd = VecN::zeros();
    let mut ap = Vector6::new(0.0, 0.0, 0.0, -g.x, -g.y, -g.z);
    for i in 0..nv {
        let ai = x[i] * ap + c[i];
        qdd[i] = (u[i] - uu[i].dot(&ai)) / d[i];
        ap = ai + s[i] * qdd[i];
    }
    qdd
}
