//! Fixed-step integrators (see [`crate::model::Integrator`] for the choice).
//!
//! Both advance `(q, q̇)` by one step `h` and leave the motor coordinates on the encoder
//! spline in replay. Neither allocates.

use crate::drive::Drive;
use crate::forward::{accel, prescribe};
use crate::math::VecN;
use crate::model::{Integrator, Model};
use crate::params::ParamData;

/// Advance `(q, v)` from `t` to `t + h`.
#[inline]
pub fn step(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN) {
    match model.options.integrator {
        Integrator::Rk4 => rk4(model, pd, drive, t, h, q, v),
        Integrator::SemiImplicit => semi_implicit(model, pd, drive, t, h, q, v),
    }
}

#[inline]
fn stage(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &mut VecN, v: &mut VecN) -> VecN {
    let am = prescribe(model, drive, t, q, v);
    accel(model, pd, drive, t, q, v, am, 0.0)
}

/// Classical RK4.
#[inline]
pub fn rk4(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN) {
    let (q0, mut v1) = (*q, *v);
    let mut q1 = q0;
    let a1 = stage(model, pd, drive, t, &mut q1, &mut v1);
    let (mut q2, mut v2) = (q1 + v1 * (0.5 * h), v1 + a1 * (0.5 * h));
    let a2 = stage(model, pd, drive, t + 0.5 * h, &mut q2, &mut v2);
    let (mut q3, mut v3) = (q1 + v2 * (0.5 * h), v1 + a2 * (0.5 * h));
    let a3 = stage(model, pd, drive, t + 0.5 * h, &mut q3, &mut v3);
    let (mut q4, mut v4) = (q1 + v3 * h, v1 + a3 * h);
    let a4 = stage(model, pd, drive, t + h, &mut q4, &mut v4);
    *q = q1 + (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
    *v = v1 + (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
    prescribe(model, drive, t + h, q, v);
}

/// Semi-implicit Euler with implicit damping: `(M + hC) Δq̇ = h (τ − b − C q̇)`,
/// `q̇⁺ = q̇ + Δq̇`, `q⁺ = q + h q̇⁺`.
#[inline]
pub fn semi_implicit(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN) {
    let am = prescribe(model, drive, t, q, v);
    let a = accel(model, pd, drive, t, q, v, am, h);
    *v += a * h;
    *q += *v * h;
    prescribe(model, drive, t + h, q, v);
}
