//! `torsion`: a revolute joint about each link's own long axis at the link root, before the
//! universal joint (`Options.structure.torsion`, spring `effects.torsion.k_t`, damper `effects.torsion.c_t`).
//!
//! - the joint turns the outer link about the link axis: with the elbow straight a twist of
//!   link 1 moves no point of the arm's axis; with the forearm hanging down it swings the
//!   forearm sideways by L sin θ;
//! - k_t = 1e9: the motion equals the model without torsion joints (joint angles and end
//!   effector within 1e-7) — a stiff torsion spring is a rigid link;
//! - k_t = 300 N·m/rad: yawing (q1) the arm with the forearm hanging below link 1 twists
//!   link 1 (the forearm's lateral inertia acts below its axis) and shows in the lateral
//!   end-effector channel, while a pitch move (q2) in the vertical plane leaves the torsion
//!   coordinate at zero (no lateral load);
//! - k_t and c_t both move the outputs; bad values are refused by name.

use popup_core::drive::{Drive, Spline3};
use popup_core::kinematics::prbm::{end_effector, frames};
use popup_core::math::VecN;
use popup_core::model::{Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::{channel_index, NCH};
use popup_core::sim::{run, RunConfig, Trajectory};
use popup_core::spec::ArmSpec;
use popup_core::Error;
use std::f64::consts::FRAC_PI_2;

fn model(torsion: [bool; 2], dt: f64) -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options { dt, structure: Structure { segments: [1, 1], torsion, elements: [0, 0] }, ..Options::default() }).unwrap()
}

fn params(m: &Model, k_t: f64, c_t: f64) -> Params {
    let mut p = Params::defaults(m);
    p.payload_kg = 2.0;
    p.pressure_pa = [30e3, 30e3];
    for l in 0..2 {
        if m.torsion_idx[l].is_some() {
            p.effects.torsion.k_t[l] = k_t;
            p.effects.torsion.c_t[l] = c_t;
        }
    }
    p
}

/// Smooth step 0 → 1 over [0, 1] (zero velocity and acceleration at both ends).
fn smooth(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
}

/// Encoder replay from `q0` by `dq` over `t_move`, held until `t_end` [s].
fn replay_over(q0: [f64; 3], dq: [f64; 3], t_move: f64, t_end: f64) -> Drive {
    let n = (t_end / 0.005).round() as usize;
    let tk: Vec<f64> = (0..=n).map(|k| k as f64 * 0.005).collect();
    let yk: Vec<[f64; 3]> = tk.iter().map(|&t| std::array::from_fn(|i| q0[i] + dq[i] * smooth(t / t_move))).collect();
    Drive::Replay(Spline3::new(&tk, &yk).unwrap())
}

/// Encoder replay from `q0` by `dq` over 0.4 s, held until 0.6 s.
fn replay(q0: [f64; 3], dq: [f64; 3]) -> Drive {
    replay_over(q0, dq, 0.4, 0.6)
}

fn go(m: &Model, p: &Params, drive: Drive) -> Trajectory {
    let pd = ParamData::new(m, p).unwrap();
    run(m, &pd, &RunConfig { drive, initial: None, duration: None, sample_period: m.options.dt * 10.0, check_step: true }).unwrap()
}

fn col(tr: &Trajectory, name: &str) -> Vec<f64> {
    let c = channel_index(name).unwrap();
    (0..tr.nsample).map(|r| tr.data[r * NCH + c]).collect()
}

fn maxdiff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

const ELBOW_DOWN: [f64; 3] = [0.0, 0.0, -FRAC_PI_2];

#[test]
fn torsion_joint_turns_the_link_about_its_axis() {
    let m = model([true, true], 1e-3);
    let (t1, t2) = (m.torsion_idx[0].unwrap(), m.torsion_idx[1].unwrap());
    assert_eq!((m.joint_name(t1), m.joint_name(t2)), ("t1", "t2"));
    // right after the link's motor, before its universal joint
    assert_eq!(t1, m.motor_idx[1] + 1);
    assert_eq!(m.root_bend_idx[0], t1 + 1);
    assert_eq!(t2, m.motor_idx[2] + 1);
    for th in [0.3, -1.0] {
        // straight arm: the twist moves no point of the axis
        let mut q = VecN::zeros();
        q[m.motor_idx[1]] = 0.4;
        q[t1] = th;
        let e = end_effector(&m, &q);
        q[t1] = 0.0;
        assert!((e - end_effector(&m, &q)).amax() < 1e-12);
        // forearm hanging down: the twist of link 1 swings it sideways, 0.6 sin θ
        let mut q = VecN::zeros();
        for k in 0..3 {
            q[m.motor_idx[k]] = ELBOW_DOWN[k];
        }
        let e0 = end_effector(&m, &q);
        q[t1] = th;
        let e = end_effector(&m, &q);
        let want = [e0.x, e0.y + 0.6 * th.sin(), -0.6 * th.cos()];
        assert!((e.x - want[0]).abs() < 1e-12 && (e.y - want[1]).abs() < 1e-12 && (e.z - want[2]).abs() < 1e-12, "twist {th}: {e:?} vs {want:?}");
        // the twist turns the link-1 IMU about the link axis (x of frame 4)
        let f = frames(&m, &q);
        let r = f.r_wb[m.imu[0].0 + 1];
        assert!((r[(0, 0)] - 1.0).abs() < 1e-12, "IMU x axis stays on the link axis");
    }
}

#[test]
fn stiff_torsion_is_a_rigid_link() {
    // k_t = 1e9 puts the torsion modes near 1e6 rad/s: RK4 needs dt of a few µs
    let dt = 2e-6;
    let nominal = model([false, false], dt);
    let stiff = model([true, true], dt);
    let drive = replay_over(ELBOW_DOWN, [0.6, 0.3, 0.4], 0.25, 0.3);
    let a = go(&nominal, &params(&nominal, 0.0, 0.0), drive.clone());
    let b = go(&stiff, &params(&stiff, 1e9, 1.0), drive.clone());
    // a 100× softer spring: 100× the difference (the twist is τ/k_t)
    let c = go(&stiff, &params(&stiff, 1e7, 1.0), drive);
    assert_eq!(a.nsample, b.nsample);
    for ch in ["d11", "d12", "d21", "d22", "ee_x", "ee_y", "ee_z", "tau1", "tau2", "tau3"] {
        let scale = col(&a, ch).iter().fold(0.0f64, |s, x| s.max(x.abs()));
        let d = maxdiff(&col(&a, ch), &col(&b, ch)) / scale;
        let d7 = maxdiff(&col(&a, ch), &col(&c, ch)) / scale;
        println!("{ch}: max difference / range: k_t = 1e9 {d:.2e}, 1e7 {d7:.2e} (range {scale:.2e})");
        assert!(d < 2e-6, "{ch}: stiff torsion differs from no torsion by {d:e} of its range");
        assert!(d7 > 20.0 * d, "{ch}: the difference must shrink with k_t ({d7:e} at 1e7, {d:e} at 1e9)");
    }
    let tw = b.final_state.q[stiff.torsion_idx[0].unwrap()].abs().max(b.final_state.q[stiff.torsion_idx[1].unwrap()].abs());
    assert!(tw < 1e-6, "twist {tw:e} rad at k_t = 1e9");
}

/// Peak |twist of link 1| over a run, from the final states of runs over 0.05, 0.1, ...,
/// 0.6 s (the torsion joint has no output channel), and the longest run.
fn peak_twist(m: &Model, p: &Params, drive: &Drive) -> (f64, Trajectory) {
    let pd = ParamData::new(m, p).unwrap();
    let t1 = m.torsion_idx[0].unwrap();
    let mut peak: f64 = 0.0;
    let mut last = None;
    for k in 1..=12 {
        let cfg = RunConfig { drive: drive.clone(), initial: None, duration: Some(0.05 * k as f64), sample_period: m.options.dt * 10.0, check_step: true };
        let tr = run(m, &pd, &cfg).unwrap();
        peak = peak.max(tr.final_state.q[t1].abs());
        last = Some(tr);
    }
    (peak, last.unwrap())
}

#[test]
fn out_of_plane_move_twists_the_link_in_plane_move_does_not() {
    let m = model([true, false], 1e-3);
    let nominal = model([false, false], 1e-3);
    let p = params(&m, 300.0, 0.2);
    let yaw = replay(ELBOW_DOWN, [0.5, 0.0, 0.0]);
    let pitch = replay(ELBOW_DOWN, [0.0, 0.4, 0.0]);
    let (tw_yaw, tr_yaw) = peak_twist(&m, &p, &yaw);
    let (tw_pitch, tr_pitch) = peak_twist(&m, &p, &pitch);
    println!("peak twist of link 1: yaw move {tw_yaw:.3e} rad, pitch move {tw_pitch:.3e} rad");
    assert!(tw_yaw > 1e-3, "a yaw with the forearm below link 1 must twist it ({tw_yaw:e} rad)");
    assert!(tw_pitch < 1e-9, "a move in the vertical plane must not twist link 1 ({tw_pitch:e} rad)");
    // where it shows: the lateral end-effector channel
    let n_yaw = go(&nominal, &params(&nominal, 0.0, 0.0), yaw);
    let n_pitch = go(&nominal, &params(&nominal, 0.0, 0.0), pitch);
    let dy_yaw = maxdiff(&col(&tr_yaw, "ee_y"), &col(&n_yaw, "ee_y")[..tr_yaw.nsample]);
    let dy_pitch = maxdiff(&col(&tr_pitch, "ee_y"), &col(&n_pitch, "ee_y")[..tr_pitch.nsample]);
    println!("ee_y torsion vs none: yaw {dy_yaw:.3e} m, pitch {dy_pitch:.3e} m");
    assert!(dy_yaw > 5e-4, "lateral residual of the yaw move {dy_yaw:e} m");
    assert!(dy_pitch < 1e-9, "lateral residual of the pitch move {dy_pitch:e} m");
}

#[test]
fn k_t_and_c_t_move_the_outputs() {
    let m = model([true, true], 1e-3);
    let drive = replay(ELBOW_DOWN, [0.5, 0.2, 0.0]);
    let base = go(&m, &params(&m, 300.0, 0.2), drive.clone());
    let stiffer = go(&m, &params(&m, 600.0, 0.2), drive.clone());
    let damped = go(&m, &params(&m, 300.0, 2.0), drive);
    for (name, other) in [("k_t", &stiffer), ("c_t", &damped)] {
        let d = maxdiff(&col(&base, "ee_y"), &col(other, "ee_y")).max(maxdiff(&col(&base, "imu1_ay"), &col(other, "imu1_ay")) * 1e-3);
        println!("{name}: ee_y / imu1_ay change {d:.3e}");
        assert!(d > 1e-5, "{name} does not move the outputs");
    }
}

#[test]
fn bad_torsion_parameters_are_refused_by_name() {
    let m = model([true, false], 1e-3);
    let expect = |p: Params, what: &str, part: &str| match ParamData::new(&m, &p) {
        Err(Error::InvalidParameter { what: w, requirement, .. }) => {
            assert_eq!(w, what);
            assert!(requirement.contains(part), "{requirement}");
        }
        other => panic!("{what}: {other:?}"),
    };
    let ok = params(&m, 300.0, 0.2);
    // default k_t = ∞ is refused when the joint exists ...
    let mut p = ok;
    p.effects.torsion.k_t[0] = f64::INFINITY;
    expect(p, "effects.torsion.k_t[0]", "torsion joint");
    // ... and accepted for a link without one
    let mut p = ok;
    p.effects.torsion.k_t[1] = f64::INFINITY;
    assert!(ParamData::new(&m, &p).is_ok());
    for bad in [0.0, -5.0, f64::NAN] {
        let mut p = ok;
        p.effects.torsion.k_t[0] = bad;
        expect(p, "effects.torsion.k_t[0]", "within");
        let mut p = ok;
        p.effects.torsion.k_t[1] = bad;
        expect(p, "effects.torsion.k_t[1]", "within");
    }
    for bad in [-0.1, f64::NAN, f64::INFINITY] {
        let mut p = ok;
        p.effects.torsion.c_t[0] = bad;
        expect(p, "effects.torsion.c_t[0]", "within");
    }
    // the torsion numbers land on the joint
    let pd = ParamData::new(&m, &ok).unwrap();
    let t1 = m.torsion_idx[0].unwrap();
    assert_eq!((pd.k[t1], pd.c[t1]), (300.0, 0.2));
    assert_eq!(popup_core::effects::Effects::default().torsion.k_t, [f64::INFINITY; 2]);
    // no torsion joints in arm files
    let mut spec = ArmSpec::popup_lab();
    spec.joints[2].kind = popup_core::spec::arm::JointKind::Torsion;
    match Model::compile(&spec, Options::default()) {
        Err(Error::InvalidParameter { what, .. }) => assert_eq!(what, "joints[2].kind"),
        other => panic!("{other:?}"),
    }
}
