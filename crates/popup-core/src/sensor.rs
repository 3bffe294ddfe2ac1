//! Sensor outputs: the channels a measured run may contain, computed from (q, q̇, q̈).
//!
//! Channel names match the measured-run format (`measured-run.md`) where one exists.
//! IMUs read specific force `a − g` at their mount in the mount body's axes; the bending
//! moment of joint j is `k δ_j + c δ̇_j`; `m*_ratio` is |M| of the link's universal joint
//! (both axes combined) over the wrinkling-onset moment M_w = coef · p · r³.
//!
//! With several segments per link (`higher_bending_modes`) the channels keep their meaning
//! for the link as a whole: `d11` (`d12`) is the sum of the first- (second-) axis angles of
//! all the link's universal joints (the small-angle tip rotation relative to the root),
//! `dd*` the sum of their rates, and `m11..m22`, `m*_ratio` are the moments at the link's
//! ROOT universal joint (first segment), where the bending moment is largest and wrinkling
//! starts. The torsion joints have no channel of their own; `energy` includes their springs.
//!
//! A rigid link's universal joint is locked: `d*`, `dd*` are 0 and `m*` is the moment the
//! link's root carries, the constraint force of the lock (sign as `k δ`).

use crate::drive::Drive;
use crate::dynamics::{crba, forward_pass, rnea};
use crate::forward::{locked_moments, solve_accel, spring_moments, FreeMotors, ALL_PRESCRIBED};
use crate::kinematics::prbm::{frames_with, Frames};
use crate::math::{dot_n, mat_vec_row, MatN, Vec3, VecN};
use crate::model::Model;
use crate::params::ParamData;

/// Number of output channels.
pub const NCH: usize = 36;

/// Output channel names, in column order. Units: s, rad, rad/s, N·m, m, m/s², Pa, rad,
/// rad/s, N·m, 1 (ratio), J.
pub const CHANNELS: [&str; NCH] = [
    "t", "q1", "q2", "q3", "dq1", "dq2", "dq3", "tau1", "tau2", "tau3", "ee_x", "ee_y", "ee_z", "imu1_ax", "imu1_ay", "imu1_az", "imu2_ax",
    "imu2_ay", "imu2_az", "p1", "p2", "d11", "d12", "d21", "d22", "dd11", "dd12", "dd21", "dd22", "m11", "m12", "m21", "m22", "m1_ratio",
    "m2_ratio", "energy",
];

/// Units of [`CHANNELS`], same order.
pub const UNITS: [&str; NCH] = [
    "s", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "N·m", "N·m", "N·m", "m", "m", "m", "m/s²", "m/s²", "m/s²", "m/s²", "m/s²", "m/s²",
    "Pa", "Pa", "rad", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "rad/s", "N·m", "N·m", "N·m", "N·m", "1", "1", "J",
];

/// The kind of sensor that records each channel of [`CHANNELS`], same order: `clock`,
/// `encoder`, `drive` (the motor torque read), `mocap`, `imu`, `pressure`, or `model` for a
/// quantity no lab measures (bending angles and moments, energy). Channels of one kind share
/// its signal chain: a lab sets every IMU (every drive) alike, so the colour of their noise
/// (the sensor's own low-pass, as a ratio to white noise) is one property of the kind.
pub const SENSORS: [&str; NCH] = [
    "clock", "encoder", "encoder", "encoder", "encoder", "encoder", "encoder", "drive", "drive", "drive", "mocap", "mocap", "mocap", "imu", "imu",
    "imu", "imu", "imu", "imu", "pressure", "pressure", "model", "model", "model", "model", "model", "model", "model", "model", "model", "model",
    "model", "model", "model", "model", "model",
];

/// Column index of a channel name.
pub fn channel_index(name: &str) -> Option<usize> {
    CHANNELS.iter().position(|c| *c == name)
}

/// Bending moments `k δ + c δ̇` of the root universal joints `[d11, d12, d21, d22]` [N·m]
/// and |M|/M_w per link. For a beam link the moments at its clamped root: the first two
/// rows of `K_φ φ + C_φ φ̇` (the generalised force of a joint that turns the whole beam
/// about the root is the root moment about that axis). For a rigid link the constraint
/// moments of its locked joint, `locked` (from [`crate::forward::locked_moments`]; zeros
/// when the model has no rigid link).
#[inline]
pub fn bending_moments(model: &Model, pd: &ParamData, t: f64, q: &VecN, v: &VecN, locked: &VecN) -> ([f64; 4], [f64; 2]) {
    let d = &model.options.disable;
    let fx = &pd.params.effects;
    let mut m = [0.0; 4];
    let mut sq = [0.0; 2];
    let plain = fx.pressure_leak.rate == [0.0; 2] && (fx.wrinkling.ratio == 1.0 || d.spring);
    if plain {
        for (a, &b) in model.root_bend_idx.iter().enumerate() {
            let ks = if d.spring { 0.0 } else { pd.k[b] };
            let cs = if d.damper { 0.0 } else { pd.c[b] };
            m[a] = ks * q[b] + cs * v[b];
        }
    } else {
        let s = spring_moments(model, pd, t, q);
        for (a, &b) in model.root_bend_idx.iter().enumerate() {
            let cs = if d.damper { 0.0 } else { pd.kc_at(model, b, t).1 };
            m[a] = s[b] + cs * v[b];
        }
    }
    for bl in model.beam.iter().flatten() {
        for ax in 0..2 {
            let i = bl.start + ax;
            let mut x = 0.0;
            for j in bl.start..bl.start + bl.dof() {
                if !d.spring {
                    x += pd.beam_k[(i, j)] * q[j];
                }
                if !d.damper {
                    x += pd.beam_c[(i, j)] * v[j];
                }
            }
            m[2 * bl.link + ax] = x;
        }
    }
    for (a, &b) in model.root_bend_idx.iter().enumerate() {
        if model.nlocked > 0 && model.is_locked(b) {
            m[a] = locked[b];
        }
        sq[model.joints[b].link] += m[a] * m[a];
    }
    let ratio = std::array::from_fn(|l| {
        let mw = if plain { pd.mw[l] } else { pd.mw_at(l, t) };
        if mw > 0.0 {
            sq[l].sqrt() / mw
        } else {
            f64::INFINITY
        }
    });
    (m, ratio)
}

/// Total mechanical energy: kinetic (armature included) + gravity + springs (every bending
/// segment and torsion joint) [J].
pub fn energy(model: &Model, pd: &ParamData, t: f64, q: &VecN, v: &VecN) -> f64 {
    let rot = model.rotations(q);
    let m = crba(model, &pd.body, &rot);
    energy_with(model, pd, t, q, v, &m, &frames_with(model, &rot))
}

fn energy_with(model: &Model, pd: &ParamData, t: f64, q: &VecN, v: &VecN, m: &MatN, f: &Frames) -> f64 {
    let n = model.nv;
    let mut mv = VecN::zeros();
    for i in 0..n {
        mv[i] = mat_vec_row(m, v, i, n);
    }
    let mut kin = 0.5 * dot_n(v, &mv, n);
    for i in 0..n {
        kin += 0.5 * model.armature[i] * v[i] * v[i];
    }
    let mut pot = 0.0;
    for i in 0..n {
        let b = &pd.body[i];
        let mc_w = f.p_wb[i + 1] * b.m + f.r_wb[i + 1] * b.h;
        pot -= model.gravity.dot(&mc_w);
    }
    let fx = &pd.params.effects;
    if model.has_beam() {
        let bs = crate::forward::beam_spring(model, pd, q);
        pot += 0.5 * dot_n(q, &bs, n);
    }
    if model.options.disable.spring {
    } else if fx.pressure_leak.rate == [0.0; 2] && fx.wrinkling.ratio == 1.0 {
        for &b in model.passive() {
            pot += 0.5 * pd.k[b] * q[b] * q[b];
        }
    } else {
        for pair in model.bend().chunks(2) {
            let (b1, b2) = (pair[0], pair[1]);
            let (k1, k2) = (pd.kc_at(model, b1, t).0, pd.kc_at(model, b2, t).0);
            if fx.wrinkling.ratio != 1.0 && k1 == k2 {
                pot += crate::effects::wrinkled_energy(k1, q[b1], q[b2], pd.mw_at(model.joints[b1].link, t), fx.wrinkling.ratio);
            } else {
                pot += 0.5 * (k1 * q[b1] * q[b1] + k2 * q[b2] * q[b2]);
            }
        }
        for &b in model.passive() {
            if !model.bend().contains(&b) {
                pot += 0.5 * pd.k[b] * q[b] * q[b];
            }
        }
    }

    kin + pot
}

/// The `tau{k+1}` channel from the motor torque `tau` (friction included) [N·m]: clamped to
/// `actuator_saturation` where it has a limit.
#[inline]
pub fn torque_read(fx: &crate::effects::Effects, k: usize, tau: f64) -> f64 {
    let lim = fx.actuator_saturation.tau_max[k];
    if lim.is_finite() {
        tau.clamp(-lim, lim)
    } else {
        tau
    }
}

/// The `tau*` channels of a row computed without `joint_friction` and `actuator_saturation`
/// (`bare`, whose `dq*` hold the physics' motor rates) with the friction and clamp of `fx`:
/// the same bits as [`sample`] with them (it adds the friction to the same torque).
pub fn with_torque_effects(fx: &crate::effects::Effects, bare: &[f64; NCH], row: &mut [f64; NCH]) {
    *row = *bare;
    for k in 0..3 {
        let mut tau = bare[7 + k];
        if fx.joint_friction.on() {
            tau += crate::effects::friction_torque(&fx.joint_friction, k, bare[4 + k]);
        }
        row[7 + k] = torque_read(fx, k, tau);
    }
}

/// Fill one output row at time `t` for state (q, q̇) (already prescribed in replay, with
/// the motor accelerations `am`). One mass matrix, one bias and one kinematics pass serve
/// every channel.
#[allow(clippy::too_many_arguments)]
pub fn sample(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, row: &mut [f64]) {
    sample_free(model, pd, drive, t, q, v, am, &ALL_PRESCRIBED, row)
}

/// [`sample`] with the motor rows in `free` inside their `backlash` gap (not prescribed;
/// [`crate::backlash`]). Under backlash in replay the `q*`, `dq*` channels and the motors'
/// friction read the motor side (the encoder), not the link side.
#[allow(clippy::too_many_arguments)]
pub fn sample_free(model: &Model, pd: &ParamData, drive: &Drive, t: f64, q: &VecN, v: &VecN, am: Option<[f64; 3]>, free: &FreeMotors, row: &mut [f64]) {
    let rot = model.rotations(q);
    let m = crba(model, &pd.body, &rot);
    let b = rnea(model, &pd.body, &rot, v, &VecN::zeros(), &model.gravity);
    let qdd = solve_accel(model, pd, drive, t, q, v, am, 0.0, &m, &b, free);
    let bm = forward_pass(model, &rot, v, &qdd, &(-model.gravity));
    let fr = frames_with(model, &rot);
    let fx = &pd.params.effects;
    let drag = if fx.air_drag.cd > 0.0 { Some(crate::effects::drag_forces(model, &pd.drag.0[..pd.drag.1], fx.air_drag.cd, &rot, v)) } else { None };
    row[0] = t;
    let motor = match drive {
        Drive::Replay(s) if crate::backlash::active(pd, drive) => {
            let (qm, vm, _) = s.eval(t);
            Some((qm, vm))
        }
        _ => None,
    };
    for k in 0..3 {
        let i = model.motor_idx[k];
        let (qk, vk) = motor.map_or((q[i], v[i]), |(qm, vm)| (qm[k], vm[k]));
        row[1 + k] = qk;
        row[4 + k] = vk;
        // row i of M q̈ + b (minus external loads), plus the motoreducer's own friction; a
        // compliant flank's: the gear's torque less the output inertia's own J_out·q̈, so that
        // both flank laws read the torque between the gear's output and the link
        let mut tau = if fx.backlash.compliant(k) && free[k] {
            crate::backlash::contact_torque(&fx.backlash, k, q[i] - qk, v[i] - vk) - fx.backlash.inertia[k] * qdd[i]
        } else {
            let mut t_row = mat_vec_row(&m, &qdd, i, model.nv) + b[i];
            if let Some(dr) = &drag {
                t_row -= dr[i];
            }
            t_row
        };
        if fx.joint_friction.on() {
            tau += crate::effects::friction_torque(&fx.joint_friction, k, vk);
        }
        row[7 + k] = torque_read(fx, k, tau);
    }
    let ee = fr.point(model.ee.0 + 1, &model.ee.1);
    row[10..13].copy_from_slice(ee.as_slice());
    for s in 0..2 {
        let (b, p) = &model.imu[s];
        let (w, wd, a) = (bm.w[*b], bm.wd[*b], bm.a[*b]);
        let f: Vec3 = a + wd.cross(p) + w.cross(&w.cross(p));
        row[13 + 3 * s..16 + 3 * s].copy_from_slice(f.as_slice());
    }
    row[19] = pd.pressure_at(0, t);
    row[20] = pd.pressure_at(1, t);
    let (mom, ratio) = bending_moments(model, pd, t, q, v, &locked_moments(model, pd, &rot, v, &qdd));
    for a in 0..4 {
        // sum over the link's segments, root first (exactly q[root] for one segment)
        let js = model.channel_joints(a);
        let (mut d, mut dd) = (q[js[0]], v[js[0]]);
        for &j in &js[1..] {
            d += q[j];
            dd += v[j];
        }
        row[21 + a] = d;
        row[25 + a] = dd;
        row[29 + a] = mom[a];
    }
    row[33] = ratio[0];
    row[34] = ratio[1];
    row[35] = energy_with(model, pd, t, q, v, &m, &fr);
}
