//! Fixed-step integrators (see [`crate::model::Integrator`] for the choice).
//!
//! Both advance `(q, q̇)` by one step `h` and leave the motor coordinates on the encoder
//! spline in replay. Neither allocates.

use crate::drive::Drive;
use crate::dynamics::articulated::accel_articulated;
use crate::forward::{accel_with, prescribe};
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
    let (q0, mut v1) = (*q, *v);
    let mut q1 = q0;
    let a1 = stage(model, pd, drive, t, &mut q1, &mut v1, ws);
    let (mut q2, mut v2) = (q1 + v1 * (0.5 * h), v1 + a1 * (0.5 * h));
    let a2 = stage(model, pd, drive, t + 0.5 * h, &mut q2, &mut v2, ws);
    let (mut q3, mut v3) = (q1 + v2 * (0.5 * h), v1 + a2 * (0.5 * h));
    let a3 = stage(model, pd, drive, t + 0.5 * h, &mut q3, &mut v3, ws);
    let (mut q4, mut v4) = (q1 + v3 * h, v1 + a3 * h);
    let a4 = stage(model, pd, drive, t + h, &mut q4, &mut v4, ws);
    *q = q1 + (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
    *v = v1 + (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
    prescribe(model, drive, t + h, q, v);
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
