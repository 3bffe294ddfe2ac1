//! Forward dynamics of the arm with its drive: q̈ = f(t, q, q̇).
//!
//! `(M(q) + diag(armature) + h·C_free) q̈ = τ_drive + τ_passive − b(q, q̇)`, where `b` is the
//! RNEA bias (Coriolis, centrifugal, gravity), `τ_passive = −k δ − c δ̇` on the passive
//! (bending and torsion) joints and `h` is the implicit-damping step of the semi-implicit
//! integrator (0 for RK4). In replay the motor rows are replaced by the prescribed
//! accelerations, so the same Cholesky solve gives the passive-joint accelerations with the
//! motors following the encoders. The locked joints of rigid links get q̈ = 0 the same way
//! (their constraint moments: [`locked_moments`]). Everything works on the leading `nv`
//! block.

use crate::drive::Drive;
use crate::dynamics::{crba_into, rnea};
use crate::math::{cholesky_solve, Mat3, MatN, VecN};
use crate::model::Model;
use crate::params::ParamData;

/// Which motor rows are free in replay (the link side of a `backlash` gap), per motor.
pub type FreeMotors = [bool; 3];
/// Every motor row prescribed (no joint inside its gap).
pub const ALL_PRESCRIBED: FreeMotors = [false; 3];

/// Passive joint forces `−k δ − c δ̇` on the bending and torsion joints at time `t` [N·m]
/// (respecting `disable`; with `pressure_leak` the bending k, c follow p(t); with
/// `wrinkling` the bending springs are bilinear, see [`crate::effects`]).
#[inline]
pub fn passive(model: &Model, pd: &ParamData, t: f64, q: &VecN, v: &VecN) -> VecN {
    let d = &model.options.disable;
    let fx = &pd.params.effects;
    let leak = fx.pressure_leak.rate != [0.0; 2];
    let wrinkle = fx.wrinkling.ratio != 1.0 && !d.spring;
    let mut t_out = VecN::zeros();
    for &b in model.passive() {
        let mut f = 0.0;
        if !d.spring {
            f -= pd.k[b] * q[b];
        }
        if !d.damper {
            f -= pd.c[b] * v[b];
        }
        t_out[b] = f;
    }
    if !leak && !wrinkle {
        if model.has_beam() {
            add_beam_forces(model, pd, q, v, &mut t_out);
        }
        return t_out;
    }
    let s = spring_moments(model, pd, t, q);
    for &b in model.bend() {
        let mut f = -s[b];
        if !d.damper {
            f -= pd.kc_at(model, b, t).1 * v[b];
        }
        t_out[b] = f;
    }
    if model.has_beam() {
        add_beam_forces(model, pd, q, v, &mut t_out);
    }
    t_out
}

/// Add the beam links' elastic and Rayleigh forces `−K_φ φ − C_φ φ̇` (respecting `disable`)
/// [N·m]. Beam links are not touched by `pressure_leak` and `wrinkling` (docs/beams.md).
#[inline]
fn add_beam_forces(model: &Model, pd: &ParamData, q: &VecN, v: &VecN, out: &mut VecN) {
    let d = &model.options.disable;
    for bl in model.beam.iter().flatten() {
        let r = bl.start..bl.start + bl.dof();
        for i in r.clone() {
            let mut f = 0.0;
            for j in r.clone() {
                if !d.spring {
                    f -= pd.beam_k[(i, j)] * q[j];
                }
                if !d.damper {
                    f -= pd.beam_c[(i, j)] * v[j];
                }
            }
            out[i] += f;
        }
    }
}

/// Elastic forces of the beam links `K_φ φ` (generalised, chain coordinates; zero outside
/// the beam blocks and with springs disabled) [N·m]. The entries of a link's first two
/// joints are the bending moments at its clamped root.
pub fn beam_spring(model: &Model, pd: &ParamData, q: &VecN) -> VecN {
    let mut s = VecN::zeros();
    if model.options.disable.spring {
        return s;
    }
    for bl in model.beam.iter().flatten() {
        let r = bl.start..bl.start + bl.dof();
        for i in r.clone() {
            for j in r.clone() {
                s[i] += pd.beam_k[(i, j)] * q[j];
            }
        }
    }
    s
}

/// Full damping matrix of the passive joints: diag(c) plus the beam links' Rayleigh blocks
/// (zero with dampers disabled) [N·m·s/rad].
pub fn damping_matrix(model: &Model, pd: &ParamData) -> MatN {
    let mut m = MatN::zeros();
    let c = damping_diag(model, pd);
    for i in 0..model.nv {
        m[(i, i)] = c[i];
    }
    if !model.options.disable.damper {
        for bl in model.beam.iter().flatten() {
            let r = bl.start..bl.start + bl.dof();
            for i in r.clone() {
                for j in r.clone() {
                    m[(i, j)] += pd.beam_c[(i, j)];
                }
            }
        }
    }
    m
}

/// Spring moments of the bending joints at time `t` (with `pressure_leak` and `wrinkling`,
/// per universal joint) [N·m]; zero with springs disabled.
#[inline]
pub fn spring_moments(model: &Model, pd: &ParamData, t: f64, q: &VecN) -> VecN {
    let mut s = VecN::zeros();
    if model.options.disable.spring {
        return s;
    }
    let w = &pd.params.effects.wrinkling;
    for pair in model.bend().chunks(2) {
        let (b1, b2) = (pair[0], pair[1]);
        let (k1, _) = pd.kc_at(model, b1, t);
        let (k2, _) = pd.kc_at(model, b2, t);
        if w.ratio != 1.0 && k1 == k2 {
            let mw = pd.mw_at(model.joints[b1].link, t);
            let (m1, m2) = crate::effects::wrinkled_spring(k1, q[b1], q[b2], mw, w.ratio);
            s[b1] = m1;
            s[b2] = m2;
        } else {
            s[b1] = k1 * q[b1];
            s[b2] = k2 * q[b2];
        }
    }
    s
}

/// Damping coefficients on the passive (bending and torsion) joints, for implicit damping.
#[inline]
pub fn damping_diag(model: &Model, pd: &ParamData) -> VecN {
    let mut c = VecN::zeros();
    if !model.options.disable.damper {
        for &b in model.passive() {
            c[b] = pd.c[b];
        }
    }
    c
}

/// In replay, overwrite the motor coordinates of `q`, `v` with the encoder spline at `t`
/// and return the prescribed motor accelerations; in torque drive return `None`.
#[inline]
pub fn prescribe(model: &Model, drive: &Drive, t: f64, q: &mut VecN, v: &mut VecN) -> Option<[f64; 3]> {
    match drive {
        Drive::Replay(s) => {
            let (qm, vm, am) = s.eval(t);
            for (k, &i) in model.motor_idx.iter().enumerate() {
                q[i] = qm[k];
                v[i] = vm[k];
            }
            Some(am)
        }
        Drive::Torque(_) | Drive::Hold(_) => None,
    }
}

/// Add a torque drive's motor torques at `t` to the generalised forces `out` [N·m]: the
/// drive's torque clamped to `actuator_saturation`, then minus `joint_friction` at the motor
/// rates `v`.
#[inline]
pub fn add_drive_torques(model: &Model, pd: &ParamData, drive: &Drive, t: f64, v: &VecN, out: &mut VecN) {
    let fx = &pd.params.effects;
    let tau = drive.torque(t).unwrap_or([0.0; 3]);
    let fr = fx.joint_friction.on();
    for (k, &i) in model.motor_idx.iter().enumerate() {
        let lim = fx.actuator_saturation.tau_max[k];
        out[i] += if lim.is_finite() { tau[k].clamp(-lim, lim) } else { tau[k] };
        if fr {
            out[i] -= crate::effects::friction_torque(&fx.joint_friction, k, v[i]);
        }
    }
}

/// Joint accelerations at time `t` [rad/s²]. `q`, `v` must already be prescribed for
/// replay (see [`prescribe`]); `h_implicit` is 0 for explicit evaluation.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn accel(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, h_implicit: f64) -> VecN {
    accel_with(model, pd, drive, t, q, v, am, h_implicit, &mut MatN::zeros())
}

/// [`accel`] with a scratch matrix `m` that is zero outside the leading nv × nv block (and
/// is left so): the integrators keep one per run instead of clearing a 17 × 17 matrix at
/// every evaluation.
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn accel_with(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, h_implicit: f64, m: &mut MatN) -> VecN {
    accel_free(model, pd, drive, t, q, v, am, h_implicit, m, &ALL_PRESCRIBED)
}

/// [`accel_with`] where the motor rows marked in `free` are not prescribed in replay: they
/// are the link side of a `backlash` gap, a free joint whose own inertia is the gear's
/// link-side `inertia` instead of the motor's armature ([`crate::backlash`]).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn accel_free(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, h_implicit: f64, m: &mut MatN, free: &FreeMotors) -> VecN {
    let rot = model.rotations(q);
    crba_into(model, &pd.body, &rot, m);
    let b = rnea(model, &pd.body, &rot, v, &VecN::zeros(), &model.gravity);
    solve_accel_in_place(model, pd, drive, t, q, v, am, h_implicit, m, &b, free)
}

/// [`accel`] given the bare-chain mass matrix `m` and bias `b` at (q, v).
#[inline]
#[allow(clippy::too_many_arguments)]
pub fn solve_accel(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, h_implicit: f64, m: &MatN, b: &VecN, free: &FreeMotors) -> VecN {
    let mut m: MatN = *m;
    solve_accel_in_place(model, pd, drive, t, q, v, am, h_implicit, &mut m, b, free)
}

/// [`solve_accel`] that overwrites the leading block of `m` (with the Cholesky factor of the
/// system matrix).
#[inline]
#[allow(clippy::too_many_arguments)]
fn solve_accel_in_place(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, h_implicit: f64, m: &mut MatN, b: &VecN, free: &FreeMotors) -> VecN {
    let n = model.nv;
    let mut rhs = passive(model, pd, t, q, v) - b;
    let fx = &pd.params.effects;
    if fx.air_drag.cd > 0.0 {
        let rot = model.rotations(q);
        rhs += crate::effects::drag_forces(model, &pd.drag.0[..pd.drag.1], fx.air_drag.cd, &rot, v);
    }
    add_armature(model, pd, m, free);
    if *free != ALL_PRESCRIBED {
        if let Some(tg) = crate::backlash::contact_torques(model, pd, drive, t, q, v) {
            for (k, &p) in model.motor_idx.iter().enumerate() {
                if free[k] {
                    rhs[p] += tg[k];
                }
            }
        }
    }
    if h_implicit > 0.0 {
        let c = damping_diag(model, pd);
        for i in 0..n {
            m[(i, i)] += h_implicit * c[i];
        }
        if model.has_beam() && !model.options.disable.damper {
            for bl in model.beam.iter().flatten() {
                let r = bl.start..bl.start + bl.dof();
                for i in r.clone() {
                    for j in r.clone() {
                        m[(i, j)] += h_implicit * pd.beam_c[(i, j)];
                    }
                }
            }
        }
    }
    match (drive, am) {
        (Drive::Torque(_) | Drive::Hold(_), _) => add_drive_torques(model, pd, drive, t, v, &mut rhs),
        (Drive::Replay(_), Some(am)) => {
            for (k, &p) in model.motor_idx.iter().enumerate() {
                if free[k] {
                    continue;
                }
                for f in 0..n {
                    rhs[f] -= m[(f, p)] * am[k];
                }
            }
            for (k, &p) in model.motor_idx.iter().enumerate() {
                if free[k] {
                    continue;
                }
                hold(m, p, n);
                rhs[p] = am[k];
            }
        }
        (Drive::Replay(_), None) => unreachable!("replay accelerations must be prescribed"),
    }
    for &p in model.locked() {
        hold(m, p, n);
        rhs[p] = 0.0;
    }
    if !cholesky_solve(m, &mut rhs, n) {
        for i in 0..n {
            rhs[i] = f64::NAN;
        }
    }
    rhs
}

/// Add the motors' armature to the diagonal of `m`; a row in `free` (the link side of a
/// backlash gap) gets the gear's link-side inertia instead.
#[inline]
fn add_armature(model: &Model, pd: &ParamData, m: &mut MatN, free: &FreeMotors) {
    for i in 0..model.nv {
        m[(i, i)] += model.armature[i];
    }
    if *free != ALL_PRESCRIBED {
        for (k, &p) in model.motor_idx.iter().enumerate() {
            if free[k] {
                m[(p, p)] += pd.params.effects.backlash.inertia[k] - model.armature[p];
            }
        }
    }
}

/// Replace row and column `p` of the leading `n` block of `m` by the identity (a joint whose
/// acceleration is given).
#[inline]
fn hold(m: &mut MatN, p: usize, n: usize) {
    for f in 0..n {
        m[(f, p)] = 0.0;
        m[(p, f)] = 0.0;
    }
    m[(p, p)] = 1.0;
}

/// Velocity change of every joint per unit generalised impulse on joint `row` at `q`, with
/// the motor rows not in `free` and the locked joints held (their velocity does not jump):
/// `A⁻¹ e_row` [rad/s per N·m·s]. A plastic impact that sets joint `row`'s velocity jump to
/// Δ applies `Δ / r[row]` times this response `r`.
pub fn impulse_response(model: &Model, pd: &ParamData, q: &VecN, free: &FreeMotors, row: usize) -> VecN {
    let n = model.nv;
    let rot = model.rotations(q);
    let mut m = MatN::zeros();
    crba_into(model, &pd.body, &rot, &mut m);
    add_armature(model, pd, &mut m, free);
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if !free[k] {
            hold(&mut m, p, n);
        }
    }
    for &p in model.locked() {
        hold(&mut m, p, n);
    }
    let mut r = VecN::zeros();
    r[row] = 1.0;
    if !cholesky_solve(&mut m, &mut r, n) {
        r.fill(f64::NAN);
    }
    r
}

/// Root bending moments carried by the locked joints of rigid links at (q, q̇) with the
/// joint accelerations `qdd` from the forward dynamics [N·m]: on each locked joint p,
/// `−(M q̈ + b − τ_drag)_p`, i.e. minus the generalised constraint force, which has the sign
/// of a spring moment `k δ` (so a rigid link's `m*` channels read like a stiff PRBM link's).
/// Zero on every other joint and without rigid links. `rot` = `model.rotations(q)`.
pub fn locked_moments(model: &Model, pd: &ParamData, rot: &[Mat3; crate::math::NMAX], v: &VecN, qdd: &VecN) -> VecN {
    let mut out = VecN::zeros();
    if model.nlocked == 0 {
        return out;
    }
    let tau = rnea(model, &pd.body, rot, v, qdd, &model.gravity);
    let fx = &pd.params.effects;
    let drag = if fx.air_drag.cd > 0.0 { Some(crate::effects::drag_forces(model, &pd.drag.0[..pd.drag.1], fx.air_drag.cd, rot, v)) } else { None };
    for &p in model.locked() {
        out[p] = -(tau[p] - drag.map_or(0.0, |d| d[p]));
    }
    out
}

/// [`locked_moments`] at time `t` for the state (q, q̇) under `drive` (prescribed here for
/// replay, with the gears' modes under `backlash`): one forward-dynamics evaluation, only
/// when the model has rigid links.
pub fn locked_moments_at(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN) -> VecN {
    if model.nlocked == 0 {
        return VecN::zeros();
    }
    let (mut q, mut v) = (*q, *v);
    let mut m = MatN::zeros();
    let g = if crate::backlash::active(pd, drive) { crate::backlash::modes(model, pd, drive, t, &q, &v, &mut m) } else { crate::backlash::RIGID };
    let am = crate::backlash::prescribe(model, drive, &g, t, &mut q, &mut v);
    let qdd = accel_free(model, pd, drive, t, &q, &v, am, 0.0, &mut m, &g.free);
    locked_moments(model, pd, &model.rotations(&q), &v, &qdd)
}
