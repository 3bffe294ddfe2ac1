//! The dynamic `backlash` gear (`popup_core::backlash`) tested against physics: a loaded link
//! rests on one flank (the run equals a rigid run with the encoder shifted by half the gap),
//! a free link side keeps its generalised momentum about a cyclic axis while it crosses the
//! gap, an impact has the stated restitution (0: plastic) and its impulse acts on its row
//! only, and a vanishing gap converges to the rigid gear.

mod common;

use common::{col, lab_pd, max_abs_diff, ramp, replay_2ms};
use popup_core::backlash::{self, Gears};
use popup_core::drive::{Drive, Spline3};
use popup_core::effects::Effects;
use popup_core::integrate::{step_with, Workspace};
use popup_core::math::VecN;
use popup_core::model::{Model, Options};
use popup_core::params::ParamData;
use popup_core::sim::{run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::{gravity_torque, mass_matrix};
use std::f64::consts::{FRAC_PI_2, PI};

fn model() -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap()
}


#[test]
fn a_link_held_by_gravity_rests_on_one_flank_and_equals_the_shifted_rigid_gear() {
    // joint 2 moves slowly about a pose where gravity always pulls the same way: the gear
    // pushes one way throughout, so the link side stays on one flank and the run is the
    // rigid run with the encoder shifted by −sign(G)·gap/2 (the same dynamics, exactly)
    let m = model();
    let gap = 0.02;
    let t: Vec<f64> = (0..=1000).map(|k| k as f64 * 2e-3).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.0, -FRAC_PI_2 + 1.2 + 0.2 * ramp(t / 2.0), 0.3]).collect();
    let mut fx = Effects::default();
    fx.backlash.gap = [0.0, gap, 0.0];
    let a = replay_2ms(&m, fx, &t, &y);
    let p0 = lab_pd(&m, Effects::default());
    let st = popup_core::sim::rest_state(&m, &p0, 0.0, y[0]).unwrap();
    let g = gravity_torque(&m, &p0, &st.q)[m.motor_idx[1]];
    assert!(g.abs() > 1.0, "the pose must load joint 2 ({g} N·m)");
    let shift = -g.signum() * gap / 2.0;
    let ys: Vec<[f64; 3]> = y.iter().map(|r| [r[0], r[1] + shift, r[2]]).collect();
    let b = replay_2ms(&m, Effects::default(), &t, &ys);
    // the encoder channel reads the motor side; the physics is the shifted one
    assert_eq!(col(&a, "q2"), y.iter().map(|r| r[1]).collect::<Vec<_>>());
    for ch in ["ee_x", "ee_z", "imu2_ax", "imu2_az", "tau2", "tau3", "d11", "d21"] {
        let d = max_abs_diff(&a, &b, ch);
        if d > 0.0 {
            let (ca, cb) = (col(&a, ch), col(&b, ch));
            let i = (0..ca.len()).max_by(|&i, &j| (ca[i] - cb[i]).abs().total_cmp(&(ca[j] - cb[j]).abs())).unwrap();
            eprintln!("{ch}: worst at sample {i}: {} vs {}", ca[i], cb[i]);
        }
        let scale = col(&b, ch).iter().map(|x| x.abs()).fold(0.0, f64::max).max(1e-3);
        assert!(d < 1e-9 * scale, "{ch}: {d:e} (scale {scale})");
    }
    // and it differs from the rigid gear by the shift
    let c = replay_2ms(&m, Effects::default(), &t, &y);
    assert!(max_abs_diff(&a, &c, "ee_z") > 0.5 * gap / 2.0 * 0.5, "the flank must show in the end effector");
}

/// The generalised momentum of joint 1 (the vertical axis: cyclic, no gravity moment) with
/// the link side's own inertia on its row.
fn momentum_1(m: &Model, p: &ParamData, q: &VecN, v: &VecN) -> f64 {
    let mm = mass_matrix(m, p, q);
    let r = m.motor_idx[0];
    let mut s = 0.0;
    for j in 0..m.nv {
        s += mm[(r, j)] * v[j];
    }
    s + (p.params.effects.backlash.inertia[0] - m.armature[r]) * v[r]
}

#[test]
fn a_free_link_side_keeps_its_momentum_across_the_gap_and_stops_on_the_far_flank() {
    // motor 1 spins up, cruises and stops; motors 2, 3 hold. While the motor brakes the gear
    // would have to pull: the link side leaves the flank, coasts across the gap with
    // constant generalised momentum (joint 1 is cyclic), and hits the far flank plastically
    let m = model();
    let gap = 0.05;
    let mut fx = Effects::default();
    fx.backlash.gap = [gap, 0.0, 0.0];
    let p = lab_pd(&m, fx);
    let dt = m.options.dt;
    let t: Vec<f64> = (0..=3000).map(|k| k as f64 * 1e-3).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.4 * ramp(t / 0.8) + 0.3 * ramp((t - 1.2) / 0.6), -FRAC_PI_2 + 0.6, 0.4]).collect();
    let drive = Drive::Replay(Spline3::new(&t, &y).unwrap());
    let Drive::Replay(sp) = &drive else { unreachable!() };
    let mut st = backlash::rest(&m, &p, 0.0, y[0]).unwrap();
    let mut ws = Workspace::new();
    let r = m.motor_idx[0];
    let (mut free_steps, mut worst_drift, mut hit_far) = (0, 0.0f64, false);
    let n = (2.5 / dt) as usize;
    for k in 0..n {
        let tk = k as f64 * dt;
        let g: Gears = backlash::modes(&m, &p, &drive, tk, &st.q, &st.v, ws.matrix());
        let h0 = momentum_1(&m, &p, &st.q, &st.v);
        let (q0, v0) = (st.q, st.v);
        step_with(&m, &p, &drive, tk, dt, &mut st.q, &mut st.v, &mut ws);
        let (qm, _, _) = sp.eval(tk + dt);
        let x = st.q[r] - qm[0];
        assert!(x.abs() <= gap / 2.0 * (1.0 + 1e-9), "t = {tk}: the link side left the gap (x = {x:e})");
        // a whole step clear of the flanks (no contact inside it, plastic impacts stop the
        // link side on a flank): momentum conserved to the integrator's accuracy
        let (qm0, _, _) = sp.eval(tk);
        let inside = |x: f64| x.abs() < gap / 2.0 * (1.0 - 1e-3);
        if g.free[0] && inside(q0[r] - qm0[0]) && inside(x) {
            free_steps += 1;
            let h1 = momentum_1(&m, &p, &st.q, &st.v);
            worst_drift = worst_drift.max((h1 - h0).abs() / h0.abs().max(1e-3));
        }
        if x > gap / 2.0 * (1.0 - 1e-9) && tk > 1.2 {
            hit_far = true;
        }
        let _ = v0;
    }
    assert!(free_steps > 5, "the link side must cross the gap over several steps ({free_steps})");
    assert!(worst_drift < 1e-6, "momentum drift {worst_drift:e} while free");
    assert!(hit_far, "braking must throw the link side onto the far flank");
}

#[test]
fn an_impact_has_its_restitution_and_its_impulse_acts_on_its_row_only() {
    let m = model();
    for e in [0.0, 0.3, 0.8] {
        let mut fx = Effects::default();
        fx.backlash.gap = [0.0, 0.02, 0.0];
        fx.backlash.restitution = [0.0, e, 0.0];
        let p = lab_pd(&m, fx);
        let mut st = popup_core::sim::rest_state(&m, &p, 0.0, [0.1, -FRAC_PI_2 + 0.8, 0.5]).unwrap();
        for i in 0..m.nv {
            st.v[i] = 0.05 * (i as f64 + 1.0) * if i % 2 == 0 { 1.0 } else { -1.0 };
        }
        let r = m.motor_idx[1];
        let (qm, vm) = (st.q[r] - 0.01, st.v[r] - 0.4); // the link side runs onto the upper flank at 0.4 rad/s
        let g = Gears { off: [0.0; 3], free: [false, true, false] };
        let (q0, v0) = (st.q, st.v);
        backlash::hit(&m, &p, &g, 1, 1.0, (qm, vm), false, &mut st.q, &mut st.v);
        assert!((st.q[r] - (qm + 0.01)).abs() < 1e-15);
        let rel = st.v[r] - vm;
        assert!((rel + e * 0.4).abs() < 1e-12, "e = {e}: relative speed after {rel}");
        // A Δv has no component on the free rows but the struck one (the prescribed motors
        // 1 and 3 are held: their velocity does not jump)
        let mm = mass_matrix(&m, &p, &q0);
        let dv = st.v - v0;
        for (k, &pk) in m.motor_idx.iter().enumerate() {
            if k != 1 {
                assert_eq!(dv[pk], 0.0, "held motor {k} moved");
            }
        }
        for i in 0..m.nv {
            if m.motor_idx.contains(&i) {
                continue;
            }
            let mut f = 0.0;
            for j in 0..m.nv {
                f += mm[(i, j)] * dv[j];
            }
            assert!(f.abs() < 1e-9, "e = {e}: impulse leaked onto joint {i}: {f:e}");
        }
    }
}

#[test]
fn a_vanishing_gap_converges_to_the_rigid_gear() {
    // reversals on every joint; the outputs approach the rigid gear's as the gap shrinks
    let m = model();
    let t: Vec<f64> = (0..=1500).map(|k| k as f64 * 2e-3).collect();
    let y: Vec<[f64; 3]> = t
        .iter()
        .map(|&t| {
            let w = ramp(t);
            [0.3 * w * (2.0 * PI * 0.6 * t).sin(), -FRAC_PI_2 + 0.9 + 0.2 * w * (2.0 * PI * 0.5 * t).sin(), 0.4 + 0.3 * w * (2.0 * PI * 0.7 * t).sin()]
        })
        .collect();
    let rigid = replay_2ms(&m, Effects::default(), &t, &y);
    let err = |gap: f64| {
        let mut fx = Effects::default();
        fx.backlash.gap = [gap; 3];
        let a = replay_2ms(&m, fx, &t, &y);
        max_abs_diff(&a, &rigid, "ee_x").max(max_abs_diff(&a, &rigid, "ee_y")).max(max_abs_diff(&a, &rigid, "ee_z"))
    };
    let e: Vec<f64> = [1e-3, 1e-5, 1e-7, 1e-9].iter().map(|&g| err(g)).collect();
    for w in e.windows(2) {
        assert!(w[1] < 0.5 * w[0], "no convergence: {e:?}");
    }
    assert!(e[3] < 1e-5, "{e:?}");
}

#[test]
fn backlash_runs_are_deterministic_and_torque_drive_and_beam_links_are_refused() {
    let m = model();
    let t: Vec<f64> = (0..=500).map(|k| k as f64 * 2e-3).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.3 * (2.0 * PI * t).sin() * ramp(t), -FRAC_PI_2 + 0.5, 0.3]).collect();
    let mut fx = Effects::default();
    fx.backlash.gap = [0.01, 0.02, 0.015];
    let a = replay_2ms(&m, fx, &t, &y);
    let b = replay_2ms(&m, fx, &t, &y);
    assert!(a.data.iter().zip(&b.data).all(|(x, y)| x.to_bits() == y.to_bits()));
    let drive = Drive::Torque(popup_core::drive::Linear3::new(&[0.0], &[[0.0; 3]]).unwrap());
    let e = run(&m, &lab_pd(&m, fx), &RunConfig { drive, initial: None, duration: Some(0.1), sample_period: 2e-3, check_step: true }).unwrap_err();
    assert!(e.to_string().contains("effects.backlash.gap"), "{e}");
    let mut spec = ArmSpec::popup_lab();
    spec.effects.higher_bending_modes.elements = [2.0, 0.0];
    let mb = Model::compile(&spec, Options::default()).unwrap();
    let cfg = RunConfig { drive: Drive::Replay(Spline3::new(&t, &y).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true };
    let e = run(&mb, &lab_pd(&mb, fx), &cfg).unwrap_err();
    assert!(e.to_string().contains("beam links"), "{e}");
}

/// The play operator's output at time t for a motor angle qm(t) that rises from 0 to its
/// peak 0.3 at t = 0.5 and falls after (`0.3 sin(π t)` on [0, 1.5]) and a gap `2h`, link
/// side started centred, written out piecewise: taken up when the motor passes h, dragged
/// on the lower flank to the peak, held there while the motor comes back 2h, then dragged
/// on the upper flank.
fn played(t: f64, qm: f64, h: f64) -> f64 {
    if t <= 0.5 {
        (qm - h).max(0.0)
    } else if qm >= 0.3 - 2.0 * h {
        0.3 - h
    } else {
        qm + h
    }
}

#[test]
fn a_held_link_side_follows_the_play_operator() {
    // joint 1 (no gravity moment) swings up and back with a held gap: the run is the rigid
    // run driven by the play operator's output at the encoder samples, while q1 reads the
    // encoder
    let m = model();
    let h = 0.025;
    let t: Vec<f64> = (0..=750).map(|k| k as f64 * 2e-3).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.3 * (PI * t).sin(), -FRAC_PI_2 + 0.6, 0.4]).collect();
    let mut fx = Effects::default();
    fx.backlash.gap = [2.0 * h, 0.0, 0.0];
    fx.backlash.held = [1.0, 0.0, 0.0];
    let a = replay_2ms(&m, fx, &t, &y);
    let yl: Vec<[f64; 3]> = t.iter().zip(&y).map(|(&t, r)| [played(t, r[0], h), r[1], r[2]]).collect();
    let b = replay_2ms(&m, Effects::default(), &t, &yl);
    assert_eq!(col(&a, "q1"), y.iter().map(|r| r[0]).collect::<Vec<_>>());
    for ch in ["ee_x", "ee_y", "ee_z", "imu2_ay", "tau1", "d11"] {
        let d = max_abs_diff(&a, &b, ch);
        let scale = col(&b, ch).iter().map(|x| x.abs()).fold(0.0, f64::max).max(1e-3);
        assert!(d < 1e-9 * scale, "{ch}: {d:e} (scale {scale})");
    }
    // a free link side does something else: it coasts ahead while the motor brakes
    fx.backlash.held = [0.0; 3];
    let c = replay_2ms(&m, fx, &t, &y);
    assert!(max_abs_diff(&a, &c, "ee_y") > 0.1 * h, "held and free gears must differ");
    // and a held gap needs no free row, so beam links take it
    fx.backlash.held = [1.0, 0.0, 0.0];
    let mut spec = ArmSpec::popup_lab();
    spec.effects.higher_bending_modes.elements = [2.0, 0.0];
    let mb = Model::compile(&spec, Options { dt: 2e-4, ..Options::default() }).unwrap();
    let ab = replay_2ms(&mb, fx, &t, &y);
    let bb = replay_2ms(&mb, Effects::default(), &t, &yl);
    assert!(max_abs_diff(&ab, &bb, "ee_y") < 1e-9, "beam links with a held gap");
}

#[test]
fn held_is_a_whole_number_and_neutral_without_a_gap() {
    let mut fx = Effects::default();
    fx.backlash.held = [0.5, 0.0, 0.0];
    let e = fx.validate().unwrap_err();
    assert!(e.to_string().contains("held"), "{e}");
    fx.backlash.held = [1.0; 3];
    assert!(fx.is_neutral("backlash"));
}
