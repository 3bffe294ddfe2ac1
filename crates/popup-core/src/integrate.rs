//! Fixed-step integrators (see [`crate::model::Integrator`] for the choice).
//!
//! Both advance `(q, q̇)` by one step `h` and leave the motor coordinates on the encoder
//! spline in replay. Neither allocates.

use crate::drive::Drive;
use crate::dynamics::articulated::accel_articulated;
use crate::forward::{accel_free, accel_with, prescribe};
use crate::math::{MatN, VecN};
use crate::model::{Integrator, Model};
use crate::params::ParamData;

/// Scratch space of the step (the joint-space matrix, zero outside the model's leading
/// nv × nv block). One per run; it carries no state between steps.
#[derive(Debug, Clone)]
pub struct Workspace {
    m: MatN,
}

impl Workspace {
    /// A fresh (zeroed) workspace.
    pub fn new() -> Workspace {
        Workspace { m: MatN::zeros() }
    }

    /// The scratch matrix (zero outside the model's leading block between uses).
    pub fn matrix(&mut self) -> &mut MatN {
        &mut self.m
    }
}

impl Default for Workspace {
    fn default() -> Self {
        Workspace::new()
    }
}

/// Advance `(q, v)` from `t` to `t + h`.
#[inline]
pub fn step(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN) {
    step_with(model, pd, drive, t, h, q, v, &mut Workspace::new())
}

/// [`step`] with a reusable workspace.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn step_with(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) {
    if crate::backlash::active(pd, drive) {
        return step_play(model, pd, drive, t, h, q, v, ws);
    }
    match model.options.integrator {
        Integrator::Rk4 => rk4(model, pd, drive, t, h, q, v, ws),
        Integrator::SemiImplicit => semi_implicit(model, pd, drive, t, h, q, v, ws),
    }
}

/// One explicit evaluation. Arms with beam links (nv ≥ 9) use the O(nv) articulated-body
/// algorithm (cheaper from nv = 8 on, 2× at nv = 29); the 7-joint arm and PRBM chains keep
/// CRBA + Cholesky (their bits are fixed by the bit-identity tests).
#[inline]
fn stage(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) -> VecN {
    let am = prescribe(model, drive, t, q, v);
    if model.has_beam() {
        accel_articulated(model, pd, drive, t, q, v, am)
    } else {
        accel_with(model, pd, drive, t, q, v, am, 0.0, &mut ws.m)
    }
}

/// Classical RK4.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn rk4(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) {
    rk4_stages(t, h, q, v, |t, q, v| stage(model, pd, drive, t, q, v, ws));
    prescribe(model, drive, t + h, q, v);
}

/// The RK4 update with `stage(t, q, v)` = q̈ at (t, q, v) (it may overwrite the prescribed
/// coordinates of q, v first).
#[inline]
fn rk4_stages<F: FnMut(f64, &mut VecN, &mut VecN) -> VecN>(t: f64, h: f64, q: &mut VecN, v: &mut VecN, mut stage: F) {
    let (q0, mut v1) = (*q, *v);
    let mut q1 = q0;
    let a1 = stage(t, &mut q1, &mut v1);
    let (mut q2, mut v2) = (q1 + v1 * (0.5 * h), v1 + a1 * (0.5 * h));
    let a2 = stage(t + 0.5 * h, &mut q2, &mut v2);
    let (mut q3, mut v3) = (q1 + v2 * (0.5 * h), v1 + a2 * (0.5 * h));
    let a3 = stage(t + 0.5 * h, &mut q3, &mut v3);
    let (mut q4, mut v4) = (q1 + v3 * h, v1 + a3 * h);
    let a4 = stage(t + h, &mut q4, &mut v4);
    *q = q1 + (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
    *v = v1 + (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
}

/// One step with `backlash` in replay: the gears' modes are chosen from the state and held
/// over a segment; when a free link side reaches a flank inside the segment, the segment is
/// cut at the contact (located on the cubic Hermite of the play between the segment's
/// ends), the link side hits the flank there and the rest of the step goes on with the new
/// modes ([`crate::backlash`]). At most [`crate::backlash::MAX_CONTACTS_PER_STEP`] contacts
/// are located per step; beyond that the link side is put on the flank at the step's end.
#[allow(clippy::too_many_arguments)]
fn step_play(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) {
    use crate::backlash;
    let (mut t0, mut left) = (t, h);
    for event in 0..=backlash::MAX_CONTACTS_PER_STEP {
        let g = backlash::modes(model, pd, drive, t0, q, v, &mut ws.m);
        let (q0, v0) = (*q, *v);
        segment(model, pd, drive, &g, t0, left, q, v, ws);
        let cut = if event < backlash::MAX_CONTACTS_PER_STEP { backlash::first_contact(model, pd, drive, &g, t0, left, (&q0, &v0), (q, v)) } else { None };
        match cut {
            Some((s, k, side)) if s < left => {
                (*q, *v) = (q0, v0);
                segment(model, pd, drive, &g, t0, s, q, v, ws);
                if let Drive::Replay(sp) = drive {
                    let (qm, vm, _) = sp.eval(t0 + s);
                    backlash::hit(model, pd, &g, k, side, (qm[k], vm[k]), true, q, v);
                }
                backlash::impacts(model, pd, drive, &g, t0 + s, q, v);
                t0 += s;
                left -= s;
            }
            _ => {
                backlash::impacts(model, pd, drive, &g, t0 + left, q, v);
                backlash::prescribe(model, drive, &g, t0 + left, q, v);
                return;
            }
        }
    }
}

/// Advance (q, q̇) from `t` by `h` with the gears' modes `g` held.
#[allow(clippy::too_many_arguments)]
fn segment(model: &Model, pd: &ParamData, drive: &Drive, g: &crate::backlash::Gears, t: f64, h: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) {
    use crate::backlash;
    match model.options.integrator {
        Integrator::Rk4 => rk4_stages(t, h, q, v, |t, q, v| {
            let am = backlash::prescribe(model, drive, g, t, q, v);
            accel_free(model, pd, drive, t, q, v, am, 0.0, &mut ws.m, &g.free)
        }),
        Integrator::SemiImplicit => {
            let am = backlash::prescribe(model, drive, g, t, q, v);
            let a = accel_free(model, pd, drive, t, q, v, am, h, &mut ws.m, &g.free);
            *v += a * h;
            *q += *v * h;
        }
    }
    backlash::prescribe(model, drive, g, t + h, q, v);
}

/// Semi-implicit Euler with implicit damping: `(M + hC) Δq̇ = h (τ − b − C q̇)`,
/// `q̇⁺ = q̇ + Δq̇`, `q⁺ = q + h q̇⁺`.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn semi_implicit(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN, ws: &mut Workspace) {
    let am = prescribe(model, drive, t, q, v);
    let a = accel_with(model, pd, drive, t, q, v, am, h, &mut ws.m);
    *v += a * h;
    *q += *v * h;
    prescribe(model, drive, t + h, q, v);
}
