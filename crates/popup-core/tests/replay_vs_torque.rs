//! Encoder replay reproduces a torque-driven run.
//!
//! A torque-driven run (gravity-holding torques of a pose near hanging, plus sinusoids of
//! 1–2 N·m; |τ| up to ~19 N·m) is sampled at every physics step; its motor angles are then
//! replayed (natural cubic spline through the samples) from the same initial state. Checks:
//! - the `tau` channel of the torque run is the link-side torque: applied torque minus
//!   armature · q̈ (q̈ from `forward::accel` at the sampled state) — an identity, 1e-10 N·m;
//! - the replay's `tau` plus armature · q̈_spline equals the applied torque. The only error
//!   source is the spline's acceleration error, O(Δ²) for sample spacing Δ
//!   (≈ Δ²/12 · q⁗ at the knots), so the observed order must be ≈ 2 ([1.7, 2.5]); at
//!   Δ = 0.25 ms it is 1.2e-5 N·m, asserted < 1e-4 N·m (5e-6 of the torque range);
//! - the replay's bending angles match the torque run's. They respond to the same
//!   acceleration error, filtered by the bending dynamics; observed order ≈ 3.1–3.2 (the
//!   knot-scale part of the spline error averages out), asserted ≥ 1.7; at Δ = 0.25 ms the
//!   error is 3.5e-10 rad, asserted < 2e-9 rad.
//! The torque run goes on 0.1 s past the compared span so that the natural spline end
//! condition (q̈ = 0 at the last sample) does not enter the comparison.

mod common;

use common::{col, orders, state_of_row};
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::forward::accel;
use popup_core::model::{Model, Options};
use popup_core::params::{Flex, ParamData, Params};
use popup_core::sim::{rest_state, run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::gravity_torque;
use std::f64::consts::{FRAC_PI_2, PI};

const T: f64 = 1.5;
const TAIL: f64 = 0.1; // the torque run goes on past T so that the spline's natural end is not compared

struct Result {
    bend_err: f64,
    tau_err: f64,
    tau_scale: f64,
    identity_err: f64,
}

fn compare(dt: f64) -> Result {
    let model = Model::compile(&ArmSpec::popup_lab(), Options { dt, ..Options::default() }).unwrap();
    let pd = ParamData::new(&model, &Params { payload_kg: 1.5, pressure_pa: [25e3, 40e3], flex: Flex::default() }).unwrap();
    let q0 = [0.2, -FRAC_PI_2 + 0.5, 0.3];
    let s0 = rest_state(&model, &pd, 0.0, q0).unwrap();
    let g = gravity_torque(&model, &pd, &s0.q);
    let hold: [f64; 3] = std::array::from_fn(|k| g[model.motor_idx[k]]);
    let amp = [1.0, 2.0, 1.0];
    let freq = [0.8, 1.3, 1.7];
    let applied = |t: f64| -> [f64; 3] { std::array::from_fn(|k| hold[k] + amp[k] * (2.0 * PI * freq[k] * t).sin()) };
    let n = ((T + TAIL) / dt).round() as usize;
    let tt: Vec<f64> = (0..=n).map(|k| k as f64 * dt).collect();
    let tau_samples: Vec<[f64; 3]> = tt.iter().map(|&t| applied(t)).collect();
    let drive = Drive::Torque(Linear3::new(&tt, &tau_samples).unwrap());
    let cfg = RunConfig { drive: drive.clone(), initial: Some(s0), duration: Some(T + TAIL), sample_period: dt, check_step: true };
    let tr = run(&model, &pd, &cfg).unwrap();

    // identity: tau channel = applied − armature · q̈
    let tau_ch: Vec<Vec<f64>> = ["tau1", "tau2", "tau3"].iter().map(|c| col(&tr, c)).collect();
    let mut identity_err: f64 = 0.0;
    for r in (0..tr.nsample).step_by(7) {
        let st = state_of_row(&model, &tr, r);
        let qdd = accel(&model, &pd, &drive, st.t, &st.q, &st.v, None, 0.0);
        let ta = applied(st.t);
        for k in 0..3 {
            let i = model.motor_idx[k];
            identity_err = identity_err.max((tau_ch[k][r] + model.armature[i] * qdd[i] - ta[k]).abs());
        }
    }

    // replay the encoder angles
    let t_s = col(&tr, "t");
    let qs: Vec<Vec<f64>> = ["q1", "q2", "q3"].iter().map(|c| col(&tr, c)).collect();
    let y: Vec<[f64; 3]> = (0..tr.nsample).map(|r| [qs[0][r], qs[1][r], qs[2][r]]).collect();
    let spline = Spline3::new(&t_s, &y).unwrap();
    let rcfg = RunConfig { drive: Drive::Replay(spline.clone()), initial: Some(s0), duration: Some(T), sample_period: dt, check_step: true };
    let rp = run(&model, &pd, &rcfg).unwrap();
    assert!(rp.nsample > 100 && rp.nsample < tr.nsample);
    let mut bend_err: f64 = 0.0;
    for c in ["d11", "d12", "d21", "d22"] {
        let (a, b) = (col(&tr, c), col(&rp, c));
        for r in 0..rp.nsample {
            bend_err = bend_err.max((a[r] - b[r]).abs());
        }
    }
    let rtau: Vec<Vec<f64>> = ["tau1", "tau2", "tau3"].iter().map(|c| col(&rp, c)).collect();
    let rt = col(&rp, "t");
    let mut tau_err: f64 = 0.0;
    let mut tau_scale: f64 = 0.0;
    for r in 0..rp.nsample {
        assert_eq!(rt[r].to_bits(), t_s[r].to_bits());
        let (_, _, am) = spline.eval(rt[r]);
        let ta = applied(rt[r]);
        for k in 0..3 {
            let i = model.motor_idx[k];
            tau_err = tau_err.max((rtau[k][r] + model.armature[i] * am[k] - ta[k]).abs());
            tau_scale = tau_scale.max(ta[k].abs());
        }
    }
    Result { bend_err, tau_err, tau_scale, identity_err }
}

#[test]
fn replay_of_encoder_angles_reproduces_the_torque_run() {
    let dts = [1e-3, 5e-4, 2.5e-4];
    let res: Vec<Result> = dts.iter().map(|&dt| compare(dt)).collect();
    println!("torque run vs encoder replay (sample spacing = dt), {T} s:");
    for (dt, r) in dts.iter().zip(&res) {
        println!(
            "  dt {dt:.2e}: max |Δδ| {:.3e} rad, max |tau + A q̈ − τ_applied| {:.3e} N·m (|τ| up to {:.2} N·m), tau identity in the torque run {:.1e} N·m",
            r.bend_err, r.tau_err, r.tau_scale, r.identity_err
        );
    }
    let ob = orders(&res.iter().map(|r| r.bend_err).collect::<Vec<_>>());
    let ot = orders(&res.iter().map(|r| r.tau_err).collect::<Vec<_>>());
    println!("  observed orders: bending {ob:.3?}, torque {ot:.3?}");
    for r in &res {
        assert!(r.identity_err < 1e-10, "tau channel is not applied − armature·q̈ ({:e} N·m)", r.identity_err);
    }
    for p in &ot {
        assert!((1.7..=2.5).contains(p), "replay torque error order {p}, expected 2 (spline acceleration error)");
    }
    for p in &ob {
        assert!((1.7..=4.5).contains(p), "replay bending error order {p}, expected >= 2");
    }
    let last = res.last().unwrap();
    assert!(last.bend_err < 2e-9, "bending angles differ by {} rad at Δ = 0.25 ms", last.bend_err);
    assert!(last.tau_err < 1e-4, "motor torques differ by {} N·m at Δ = 0.25 ms", last.tau_err);
}
