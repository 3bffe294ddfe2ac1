//! The `backlash` effect in replay: a dead zone of full width `gap` between the motor side
//! of a motor joint (the encoder angle q_m, prescribed) and its link side (the chain's joint
//! angle q_l, a degree of freedom of its own while it is inside the gap).
//!
//! With the play x = q_l − q_m and h = gap/2, each gear is in one of three modes:
//! - on the lower flank (x = −h) while the gear pushes the link forwards (τ_g ≥ 0),
//! - on the upper flank (x = +h) while it pushes backwards (τ_g ≤ 0),
//! - free inside the gap (|x| < h, τ_g = 0): the link side moves under its own dynamics with
//!   the gear's link-side `inertia` instead of the motor's armature.
//!
//! τ_g is the torque the gear applies to the link side: on a flank, the constraint torque
//! of the prescribed row, `(M q̈ + b − τ_drag)_p + J_out q̈_p`. A flank whose τ_g would have
//! to pull is released. A free link side that reaches a flank is put on it and hits it with
//! the restitution e (`restitution`, 0 = plastic): the impulse on its row that leaves the
//! relative speed −e times what it was, with the prescribed rows held
//! ([`crate::forward::impulse_response`]). The modes are chosen from the state alone (no
//! hidden state) and held through a segment's stages. A contact that closes inside a step
//! is located on the cubic Hermite of x between the segment's ends; the step is cut there
//! and finishes with the new modes (at most [`MAX_CONTACTS_PER_STEP`] cuts). A contact that
//! opens inside a step is seen at the next one (first order in dt at the release).
//!
//! **Compliant flanks** (`contact_k` k_c > 0 on a joint): the link side is always free, and
//! past a flank the gear pushes it with the unilateral spring-damper
//! `τ_g = −k_c (x − h) − c_c ẋ` (x > h, never positive) or `−k_c (x + h) − c_c ẋ` (x < −h,
//! never negative), 0 inside the gap ([`contact_torque`]): the elasto-backlash law of
//! Modelica's `ElastoBacklash` and of Simscape's hard stops. No impacts and no modes: the
//! contact is a force, integrated like the springs (its stiffness enters the step check).
//! As k_c → ∞ with the damping ratio growing (c_c ∝ k_c) it converges to the rigid law's
//! plastic impact (the clamped dashpot's rebound is ~1/(4ζ²)); with c_c = 0 a strike is
//! elastic.
//!
//! At rest (no initial state given) each link side lies on the flank its static load
//! pushes it to; an unloaded one (e.g. a vertical axis) sits in the middle of its gap.
//!
//! The torque channel (`tau*`) reads the torque between the gear's output and the link, as
//! without play: `(M q̈ + b − τ_drag)_p` plus the motor's friction at the motor's speed, so
//! it is 0 (up to friction) while a rigid gear's link side is free. Compliant flanks read
//! the same place: `τ_g − J_out q̈_l` (the gear's torque less its output inertia's own), so
//! as k_c → ∞ they read what the rigid flanks read (until session 67 they read τ_g, and
//! did not).

use crate::drive::Drive;
use crate::dynamics::rnea;
use crate::error::Result;
use crate::forward::{accel_free, impulse_response, FreeMotors, ALL_PRESCRIBED};
use crate::math::{MatN, VecN};
use crate::model::Model;
use crate::params::ParamData;
use crate::sim::{rest_state, State};
use crate::statics::gravity_torque;

/// Relative tolerance of "on the flank" (a fraction of the half gap).
const ON_FLANK: f64 = 1e-9;

/// How far inside its flank a play x may read and still be on it: [`ON_FLANK`] of the half
/// gap `h`, plus the rounding of x = q_l − q_m at the motor angle `qm` (a link side put
/// exactly on a flank reads back a few ulps of q_m off it).
#[inline]
fn flank_tol(h: f64, qm: f64) -> f64 {
    ON_FLANK * h + 8.0 * f64::EPSILON * (qm.abs() + h)
}

/// Separation speed below which a link side on a flank counts as resting on it [rad/s].
const SEPARATING: f64 = 1e-9;

/// Contacts located inside one step (bounded work): a link side that rattles faster than
/// this is put on its flank at the end of the step instead.
pub const MAX_CONTACTS_PER_STEP: usize = 4;

/// The gears' modes at one instant: the play `off[k]` = q_l − q_m of a row in contact
/// (0 without play, ±gap/2 on a flank) and which rows are free inside their gap.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gears {
    /// Play of each motor row in contact [rad] (unused for a free row).
    pub off: [f64; 3],
    /// Rows free inside their gap.
    pub free: FreeMotors,
}

/// Every gear rigid (no play).
pub const RIGID: Gears = Gears { off: [0.0; 3], free: ALL_PRESCRIBED };

/// True when the run's physics needs the dynamic gear model: play on some joint in replay.
#[inline]
pub fn active(pd: &ParamData, drive: &Drive) -> bool {
    drive.is_replay() && pd.params.effects.backlash.free_gap() != [0.0; 3]
}

/// Play operator over samples `y` of the motor angles [rad]: the link-side angles of gears
/// whose link side is held inside full gaps `gap` [rad] (0 = no play), started in the middle
/// of the gap.
pub fn play(y: &[[f64; 3]], gap: &[f64; 3]) -> Vec<[f64; 3]> {
    let mut ql = y.first().copied().unwrap_or([0.0; 3]);
    y.iter()
        .map(|row| {
            for c in 0..3 {
                let h = 0.5 * gap[c];
                ql[c] = ql[c].clamp(row[c] - h, row[c] + h);
            }
            ql
        })
        .collect()
}

/// In replay, set the motor rows in contact to the motor side plus their play (`q_m + off`,
/// `q̇_m`) and leave the free rows; return the motor accelerations (the prescribed ones are
/// used, the free ones ignored). `None` in torque drive.
#[inline]
pub fn prescribe(model: &Model, drive: &Drive, g: &Gears, t: f64, q: &mut VecN, v: &mut VecN) -> Option<[f64; 3]> {
    match drive {
        Drive::Replay(s) => {
            let (qm, vm, am) = s.eval(t);
            for (k, &i) in model.motor_idx.iter().enumerate() {
                if !g.free[k] {
                    q[i] = qm[k] + g.off[k];
                    v[i] = vm[k];
                }
            }
            Some(am)
        }
        Drive::Torque(_) | Drive::Hold(_) => None,
    }
}

/// The gears' modes at (t, q, q̇) in replay, q holding the link-side angles: a row on a flank
/// and not moving into the gap stays in contact unless the gear would have to pull there
/// (checked jointly, releasing the wrong-signed contacts until none is left).
pub fn modes(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, m: &mut MatN) -> Gears {
    let gap = pd.params.effects.backlash.free_gap();
    let Drive::Replay(s) = drive else {
        return RIGID;
    };
    let (qm, vm, _) = s.eval(t);
    let mut g = RIGID;
    let mut side = [0.0f64; 3];
    let fx = &pd.params.effects.backlash;
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if gap[k] == 0.0 {
            continue;
        }
        if fx.compliant(k) {
            g.free[k] = true;
            continue;
        }
        let h = 0.5 * gap[k];
        let (x, xd) = (q[p] - qm[k], v[p] - vm[k]);
        let tol = flank_tol(h, qm[k]);
        // a link side that separates slower than this is still on its flank (the step's end
        // t + dt and the next step's start differ by rounding, and so do q̇_m there)
        let vtol = SEPARATING + 8.0 * f64::EPSILON * vm[k].abs();
        if x >= h - tol && xd >= -vtol {
            side[k] = 1.0;
        } else if x <= -h + tol && xd <= vtol {
            side[k] = -1.0;
        }
        g.free[k] = side[k] == 0.0;
        g.off[k] = side[k] * h;
    }
    // at most one release per gear: three passes settle every combination
    for _ in 0..3 {
        if (0..3).all(|k| side[k] == 0.0) {
            break;
        }
        let tg = gear_torques(model, pd, drive, &g, t, q, v, m);
        let mut changed = false;
        for k in 0..3 {
            if side[k] != 0.0 && side[k] * tg[k] > 0.0 {
                side[k] = 0.0;
                g.free[k] = true;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    g
}

/// The torque each gear in contact applies to its link side at (t, q, q̇) with the modes `g`
/// [N·m] (0 for free and rigid-free rows).
#[allow(clippy::too_many_arguments)]
pub fn gear_torques(model: &Model, pd: &ParamData, drive: &Drive, g: &Gears, t: f64, q: &VecN, v: &VecN, m: &mut MatN) -> [f64; 3] {
    let (mut q, mut v) = (*q, *v);
    let am = prescribe(model, drive, g, t, &mut q, &mut v);
    let qdd = accel_free(model, pd, drive, t, &q, &v, am, 0.0, m, &g.free);
    let rot = model.rotations(&q);
    let tau = rnea(model, &pd.body, &rot, &v, &qdd, &model.gravity);
    let fx = &pd.params.effects;
    let drag = if fx.air_drag.cd > 0.0 { Some(crate::effects::drag_forces(model, &pd.drag.0[..pd.drag.1], fx.air_drag.cd, &rot, &v)) } else { None };
    std::array::from_fn(|k| {
        let p = model.motor_idx[k];
        if g.free[k] {
            return 0.0;
        }
        tau[p] + fx.backlash.inertia[k] * qdd[p] - drag.map_or(0.0, |d| d[p])
    })
}

/// The first time in (0, h] at which a free link side reaches a flank over a segment from
/// `t` with the modes `g`, located on the cubic Hermite of the play x(s) through its values
/// and rates at the segment's ends (`start`, `end` = (q, q̇) there); `None` when every free
/// link side ends inside its gap. Also returns the gear and the flank (±1) it reaches.
pub fn first_contact(model: &Model, pd: &ParamData, drive: &Drive, g: &Gears, t: f64, h: f64, start: (&VecN, &VecN), end: (&VecN, &VecN)) -> Option<(f64, usize, f64)> {
    let Drive::Replay(s) = drive else {
        return None;
    };
    let gap = pd.params.effects.backlash.free_gap();
    let (qa, va, _) = s.eval(t);
    let (qb, vb, _) = s.eval(t + h);
    let mut first: Option<(f64, usize, f64)> = None;
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if !g.free[k] || gap[k] == 0.0 || pd.params.effects.backlash.compliant(k) {
            continue;
        }
        let half = 0.5 * gap[k];
        let (x0, d0) = (start.0[p] - qa[k], start.1[p] - va[k]);
        let (x1, d1) = (end.0[p] - qb[k], end.1[p] - vb[k]);
        if x1.abs() < half - flank_tol(half, qb[k]) {
            continue;
        }
        let x = |u: f64| {
            let (u2, u3) = (u * u, u * u * u);
            (2.0 * u3 - 3.0 * u2 + 1.0) * x0 + (u3 - 2.0 * u2 + u) * h * d0 + (-2.0 * u3 + 3.0 * u2) * x1 + (u3 - u2) * h * d1
        };
        // bisection for |x| = half between u = 0 (inside) and u = 1 (on or past a flank)
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if x(mid).abs() < half {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let at = hi * h;
        if first.map_or(true, |f| at < f.0) {
            first = Some((at, k, x(hi).signum()));
        }
    }
    first
}

/// At `t`, after a segment with the modes `g`: a free link side on or past a flank is put on
/// it, and if it still moves outwards it hits the flank plastically (its velocity becomes the
/// motor's through an impulse on its row; the other free rows and the passive joints respond
/// through the mass matrix, the prescribed rows are held). The rows in contact are left to
/// [`prescribe`].
pub fn impacts(model: &Model, pd: &ParamData, drive: &Drive, g: &Gears, t: f64, q: &mut VecN, v: &mut VecN) {
    let Drive::Replay(s) = drive else {
        return;
    };
    let gap = pd.params.effects.backlash.free_gap();
    let (qm, vm, _) = s.eval(t);
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if !g.free[k] || gap[k] == 0.0 || pd.params.effects.backlash.compliant(k) {
            continue;
        }
        let h = 0.5 * gap[k];
        let x = q[p] - qm[k];
        if x.abs() < h - flank_tol(h, qm[k]) {
            continue;
        }
        hit(model, pd, g, k, x.signum(), (qm[k], vm[k]), false, q, v);
    }
}

/// Put free link side `k` on its flank `side` (±1) with the motor side at (q_m, q̇_m). If it
/// moves outwards it hits the flank (an impulse on its row leaves the relative speed −e
/// times what it was; see [`impacts`]). `located`: the contact was located inside the
/// segment, so a link side that reads as separating only skims the flank while its
/// acceleration takes it back: it is put at rest on the flank (relative speed 0) so that
/// the next segment's modes decide by the gear torque instead of cutting again at once.
#[allow(clippy::too_many_arguments)]
pub fn hit(model: &Model, pd: &ParamData, g: &Gears, k: usize, side: f64, (qm, vm): (f64, f64), located: bool, q: &mut VecN, v: &mut VecN) {
    let p = model.motor_idx[k];
    q[p] = qm + side * 0.5 * pd.params.effects.backlash.free_gap()[k];
    let closing = vm - v[p];
    let after = if side * closing < 0.0 {
        pd.params.effects.backlash.restitution[k] * closing
    } else if located {
        0.0
    } else {
        return;
    };
    let dv = closing + after;
    let r = impulse_response(model, pd, q, &g.free, p);
    let scale = dv / r[p];
    if scale.is_finite() {
        for i in 0..model.nv {
            v[i] += scale * r[i];
        }
    }
    v[p] = vm + after;
}

/// The state at rest with the motors at `qm` and each link side on the flank its static
/// load pushes it to (centred in the gap when unloaded), the passive joints in static
/// equilibrium.
///
/// # Errors
/// As [`rest_state`].
pub fn rest(model: &Model, pd: &ParamData, t: f64, qm: [f64; 3]) -> Result<State> {
    let st = rest_state(model, pd, t, qm)?;
    let gap = pd.params.effects.backlash.free_gap();
    if gap == [0.0; 3] {
        return Ok(st);
    }
    let g = gravity_torque(model, pd, &st.q);
    let scale = model.motor_idx.iter().map(|&p| g[p].abs()).fold(0.0, f64::max);
    let fx = &pd.params.effects.backlash;
    let mut ql = qm;
    for (k, &p) in model.motor_idx.iter().enumerate() {
        // the gear holds the link with τ_g = G_p: pushing forwards puts the link side behind
        if g[p].abs() > 1e-9 * scale.max(1e-12) {
            ql[k] -= g[p].signum() * 0.5 * gap[k];
        }
    }
    if !(0..3).any(|k| fx.compliant(k)) {
        return rest_state(model, pd, t, ql);
    }
    // a compliant flank is pressed in by G_p/k_c more, with G_p the load at the pressed-in
    // pose (a fixed point: G_p/k_c is a small correction)
    let flank = ql;
    let mut st = rest_state(model, pd, t, ql)?;
    for _ in 0..8 {
        let g = gravity_torque(model, pd, &st.q);
        let mut moved = 0.0f64;
        for (k, &p) in model.motor_idx.iter().enumerate() {
            if fx.compliant(k) && g[p].abs() > 1e-9 * scale.max(1e-12) {
                let want = flank[k] - g[p] / fx.contact_k[k];
                moved = moved.max((want - ql[k]).abs());
                ql[k] = want;
            }
        }
        st = rest_state(model, pd, t, ql)?;
        if moved < 1e-15 {
            break;
        }
    }
    Ok(st)
}

/// The torque a compliant flank contact of gear `k` applies to its link side [N·m] at the
/// play x = q_l − q_m [rad] and its rate ẋ [rad/s] (module docs); 0 inside the gap and for
/// a gear with rigid flanks.
#[inline]
pub fn contact_torque(b: &crate::effects::Backlash, k: usize, x: f64, xd: f64) -> f64 {
    if !b.compliant(k) {
        return 0.0;
    }
    let h = 0.5 * b.gap[k];
    if x > h {
        (-b.contact_k[k] * (x - h) - b.contact_c[k] * xd).min(0.0)
    } else if x < -h {
        (-b.contact_k[k] * (x + h) - b.contact_c[k] * xd).max(0.0)
    } else {
        0.0
    }
}

/// The compliant contacts' torques on the link-side rows at (t, q, q̇) in replay (0 on
/// every other row and joint; `None` when no gear has compliant flanks).
#[inline]
pub fn contact_torques(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN) -> Option<[f64; 3]> {
    let b = &pd.params.effects.backlash;
    if !(0..3).any(|k| b.compliant(k)) {
        return None;
    }
    let Drive::Replay(s) = drive else {
        return None;
    };
    let (qm, vm, _) = s.eval(t);
    Some(std::array::from_fn(|k| {
        let p = model.motor_idx[k];
        contact_torque(b, k, q[p] - qm[k], v[p] - vm[k])
    }))
}
