//! Rigid links (`higher_bending_modes.segments = 0`): the link's universal joint stays in the
//! chain, locked at δ = 0; its `m*` channels are the constraint moments.
//!
//! - static: a rigid link's root moments equal the gravity moment of everything outboard of
//!   its root (computed here from the frames and body inertias, not from the dynamics);
//! - dynamic: a rigid link is the limit of a stiff PRBM link (k, c × 10⁴): same motor
//!   motion and the same root moments, in torque drive and in replay;
//! - energy is conserved with dampers off; locked joints never move (bit-exact zeros);
//! - mixed arms (rigid + PRBM, rigid + beam) run in both drives; batched = alone, 1 vs 2
//!   threads bit for bit; the step check and linearisation leave the locked joints out
//!   (torque-input B = the inverse of the motors' mass matrix);
//! - a rigid link with a torsion joint, a segment count of 4 and an initial state that moves
//!   a locked joint are refused by name.

use popup_core::drive::{Drive, Spline3};
use popup_core::error::Error;
use popup_core::kinematics::prbm::frames;
use popup_core::linear::{linearize, LinearInput};
use popup_core::math::{Vec3, VecN};
use popup_core::model::{Disable, Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::rollout::{rollout, Job};
use popup_core::sensor::channel_index;
use popup_core::sim::{rest_state, run, RunConfig, State, Trajectory};
use popup_core::spec::ArmSpec;
use popup_core::statics::{gravity_torque, mass_matrix};

mod common;
use common::col;

fn compile(spec: &ArmSpec, segments: [usize; 2], elements: [usize; 2], opts: Options) -> Model {
    Model::compile(spec, Options { structure: Structure { segments, elements, ..Structure::default() }, ..opts }).unwrap()
}

fn params(model: &Model, payload: f64) -> Params {
    let mut p = Params::defaults(model);
    p.payload_kg = payload;
    p.pressure_pa = [30e3, 30e3];
    p
}

fn hold(model: &Model, pd: &ParamData, qm: [f64; 3], extra: [f64; 3]) -> (State, Drive) {
    let st = rest_state(model, pd, 0.0, qm).unwrap();
    let g = gravity_torque(model, pd, &st.q);
    (st, Drive::Hold(std::array::from_fn(|k| g[model.motor_idx[k]] + extra[k])))
}

fn replay(duration: f64) -> Drive {
    let n = 201;
    let t: Vec<f64> = (0..n).map(|i| duration * i as f64 / (n - 1) as f64).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.3 * (4.0 * t).sin(), 0.4 + 0.3 * (5.0 * t).sin(), -0.3 * (6.0 * t).sin()]).collect();
    Drive::Replay(Spline3::new(&t, &y).unwrap())
}

fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |a, b| a.max(b.abs()))
}

fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
}

/// Moment about joint p's axis of the weights of bodies p.. (everything it carries), from
/// the frames at q [N·m]; sign of a spring moment k δ (= −∂V/∂q_p).
fn gravity_moment(model: &Model, pd: &ParamData, q: &VecN, p: usize) -> f64 {
    let f = frames(model, q);
    let w = f.r_wb[p + 1] * model.joints[p].u;
    let o = f.p_wb[p];
    let mut m = Vec3::zeros();
    for j in p..model.nv {
        let b = &pd.body[j];
        if b.m == 0.0 {
            continue;
        }
        let c = f.p_wb[j + 1] + f.r_wb[j + 1] * b.h / b.m;
        m += (c - o).cross(&(model.gravity * b.m));
    }
    w.dot(&m)
}

#[test]
fn rigid_link_root_moment_is_the_outboard_gravity_moment() {
    let spec = ArmSpec::popup_lab();
    for (segments, qm) in [([0, 0], [0.0, 0.5, -0.3]), ([1, 0], [0.2, 0.9, 0.4]), ([0, 1], [-0.3, 0.3, -0.6])] {
        let model = compile(&spec, segments, [0, 0], Options::default());
        assert_eq!(model.nlocked, 2 * segments.iter().filter(|&&s| s == 0).count());
        let pd = ParamData::new(&model, &params(&model, 2.0)).unwrap();
        let (st, drive) = hold(&model, &pd, qm, [0.0; 3]);
        let tr = run(&model, &pd, &RunConfig { drive, initial: Some(st), duration: Some(0.2), sample_period: 0.01, check_step: true }).unwrap();
        for l in 0..2 {
            if segments[l] != 0 {
                continue;
            }
            for a in 0..2 {
                let ch = 2 * l + a;
                let p = model.root_bend_idx[ch];
                let want = gravity_moment(&model, &pd, &st.q, p);
                let name = format!("m{}{}", l + 1, a + 1);
                let got = col(&tr, &name);
                let scale = want.abs().max(1e-3 * pd.params.payload_kg * 9.81);
                // at rest under the holding torques the arm does not move: the moment stays
                assert!(max_diff(&got, &vec![want; got.len()]) < 1e-8 * scale, "{segments:?} {name}: {got:?} vs {want}");
                // locked joints are exactly at rest
                assert!(col(&tr, &format!("d{}{}", l + 1, a + 1)).iter().chain(&col(&tr, &format!("dd{}{}", l + 1, a + 1))).all(|&x| x == 0.0));
            }
            // the moment of the in-plane axis is the big one (the link is loaded by its payload)
            let m = [col(&tr, &format!("m{}1", l + 1))[0], col(&tr, &format!("m{}2", l + 1))[0]];
            let ratio = col(&tr, &format!("m{}_ratio", l + 1))[0];
            assert!((ratio - m[0].hypot(m[1]) / pd.mw[l]).abs() < 1e-12 * ratio, "{segments:?}: ratio {ratio}");
            assert!(m[0].hypot(m[1]) > 1.0, "{segments:?} link {}: root moment {m:?} N·m is implausibly small for 2 kg", l + 1);
        }
    }
}

/// popup-lab with link 2's PRBM joint stiffened (k and c × `s`).
fn stiff_link2(s: f64) -> ArmSpec {
    let mut spec = ArmSpec::popup_lab();
    spec.links[1].stiffness_scale = Some(s);
    spec
}

#[test]
fn rigid_link_is_the_limit_of_a_stiff_prbm_link() {
    let dt = 2e-5;
    let rigid = compile(&ArmSpec::popup_lab(), [1, 0], [0, 0], Options { dt, ..Options::default() });
    let stiff_spec = stiff_link2(1e4);
    let stiff = compile(&stiff_spec, [1, 1], [0, 0], Options { dt, integrator: popup_core::model::Integrator::SemiImplicit, ..Options::default() });
    let prd = ParamData::new(&rigid, &params(&rigid, 1.0)).unwrap();
    let psd = ParamData::new(&stiff, &params(&stiff, 1.0)).unwrap();
    let rigid_rk4 = |drive: Drive| run(&rigid, &prd, &RunConfig { drive, initial: None, duration: Some(0.4), sample_period: 1e-3, check_step: true }).unwrap();
    let stiff_run = |drive: Drive| run(&stiff, &psd, &RunConfig { drive, initial: None, duration: Some(0.4), sample_period: 1e-3, check_step: true }).unwrap();
    let (_, dr) = hold(&rigid, &prd, [0.0, 0.4, -0.2], [0.3, -0.8, 0.5]);
    let (_, ds) = hold(&stiff, &psd, [0.0, 0.4, -0.2], [0.3, -0.8, 0.5]);
    // both start at their own rest state; the torque step is the same
    for (what, a, b) in [("torque step", rigid_rk4(dr), stiff_run(ds)), ("replay", rigid_rk4(replay(0.4)), stiff_run(replay(0.4)))] {
        check_close(what, &a, &b);
    }
}

fn check_close(what: &str, a: &Trajectory, b: &Trajectory) {
    for q in ["q1", "q2", "q3"] {
        let (x, y) = (col(a, q), col(b, q));
        assert!(max_diff(&x, &y) < 2e-3, "{what} {q}: {} rad apart", max_diff(&x, &y));
    }
    // from 10 ms on: at t = 0 the stiff link starts from static equilibrium while the rigid
    // one carries the replay's initial acceleration at once (a transient of the stiff link)
    for m in ["m21", "m22", "tau2", "tau3"] {
        let (x, y) = (&col(a, m)[10..], &col(b, m)[10..]);
        let d = max_diff(x, y);
        assert!(d < 0.005 * max_abs(x), "{what} {m}: {d} N·m apart (max |m| {})", max_abs(x));
    }
    // the stiff PRBM link does bend a little; the rigid one not at all
    assert!(max_abs(&col(b, "d21")) > 0.0 && col(a, "d21").iter().all(|&x| x == 0.0));
}

#[test]
fn rigid_arm_conserves_energy_without_damping() {
    let model = compile(&ArmSpec::popup_lab(), [0, 0], [0, 0], Options { dt: 5e-4, disable: Disable { damper: true, ..Disable::default() }, ..Options::default() });
    let pd = ParamData::new(&model, &params(&model, 1.0)).unwrap();
    let mut q = VecN::zeros();
    q[model.motor_idx[1]] = 0.6;
    q[model.motor_idx[2]] = -0.4;
    let mut v = VecN::zeros();
    v[model.motor_idx[0]] = 1.0;
    let cfg = RunConfig { drive: common::constant_torque([0.0; 3]), initial: Some(State { t: 0.0, q, v }), duration: Some(2.0), sample_period: 0.01, check_step: true };
    let tr = run(&model, &pd, &cfg).unwrap();
    let e = col(&tr, "energy");
    let swing = max_abs(&col(&tr, "dq2"));
    assert!(swing > 1.0, "the arm falls and swings ({swing} rad/s)");
    let drift = max_diff(&e, &vec![e[0]; e.len()]);
    assert!(drift < 1e-7 * e[0].abs().max(1.0), "energy drift {drift} J of {}", e[0]);
    // the locked joints never moved
    for a in 0..4 {
        assert!(tr.final_state.q[model.root_bend_idx[a]] == 0.0 && tr.final_state.v[model.root_bend_idx[a]] == 0.0);
    }
}

#[test]
fn mixed_rigid_arms_run_and_are_bit_identical_batched_and_threaded() {
    let spec = ArmSpec::popup_lab();
    for (segments, elements) in [([0, 1], [0, 0]), ([1, 0], [0, 0]), ([0, 1], [0, 2]), ([1, 0], [1, 0]), ([2, 0], [0, 0])] {
        let model = compile(&spec, segments, elements, Options { dt: 5e-5, ..Options::default() });
        assert_eq!(model.structure.link_name(0) == "rigid", segments[0] == 0 && elements[0] == 0);
        let pd = ParamData::new(&model, &params(&model, 1.0)).unwrap();
        let (_, h) = hold(&model, &pd, [0.0; 3], [0.2, 0.2, -0.2]);
        for drive in [replay(0.2), h] {
            let tr = run(&model, &pd, &RunConfig { drive, initial: None, duration: Some(0.2), sample_period: 1e-3, check_step: true }).unwrap_or_else(|e| panic!("{segments:?} {elements:?}: {e}"));
            assert!(tr.data.iter().all(|x| x.is_finite()));
            let rl = segments.iter().zip(&elements).position(|(&s, &e)| s == 0 && e == 0).unwrap();
            let fl = 1 - rl;
            assert!(col(&tr, &format!("dd{}1", rl + 1)).iter().all(|&x| x == 0.0));
            assert!(col(&tr, &format!("dd{}1", fl + 1)).iter().any(|&x| x != 0.0), "{segments:?}: the flexible link bends");
            let root = max_abs(&col(&tr, &format!("m{}1", rl + 1))).hypot(max_abs(&col(&tr, &format!("m{}2", rl + 1))));
            assert!(root > 0.1, "{segments:?}: the rigid link's root moment {root} N·m");
        }
    }
    let model = compile(&spec, [0, 1], [0, 1], Options { dt: 5e-5, ..Options::default() });
    let jobs: Vec<Job> = (0..4).map(|i| Job { params: params(&model, 0.5 * i as f64), run: RunConfig { drive: replay(0.1), initial: None, duration: Some(0.1), sample_period: 1e-3, check_step: true } }).collect();
    let a = rollout(&model, &jobs, 1);
    let b = rollout(&model, &jobs, 2);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        let (x, y) = (x.as_ref().unwrap(), y.as_ref().unwrap());
        assert!(x.data.iter().zip(&y.data).all(|(p, q)| p.to_bits() == q.to_bits()), "job {i}: 1 vs 2 threads differ");
        let alone = rollout(&model, &jobs[i..=i], 1);
        assert!(alone[0].as_ref().unwrap().data.iter().zip(&x.data).all(|(p, q)| p.to_bits() == q.to_bits()), "job {i}: batched vs alone differ");
    }
    let m11 = channel_index("m11").unwrap();
    assert!(a[0].as_ref().unwrap().data[m11] != a[3].as_ref().unwrap().data[m11], "the payload loads the rigid link's root");
}

#[test]
fn rigid_effects_key_compiles_the_same_chain() {
    let mut spec = ArmSpec::popup_lab();
    spec.effects.higher_bending_modes.segments = [0.0, 1.0];
    let from_fx = Model::compile(&spec, Options::default()).unwrap();
    let from_opts = compile(&ArmSpec::popup_lab(), [0, 1], [0, 0], Options::default());
    assert_eq!(from_fx.structure, from_opts.structure);
    assert_eq!(from_fx.locked(), from_opts.locked());
    assert_eq!(from_fx.structure.link_name(0), "rigid");
    assert_eq!(from_fx.nv, 7);
    assert_eq!(from_fx.passive().len(), 2);
}

#[test]
fn linearised_rigid_arm_is_the_motors_mass_matrix() {
    let model = compile(&ArmSpec::popup_lab(), [0, 0], [0, 0], Options { disable: Disable { gravity: true, ..Disable::default() }, ..Options::default() });
    let pd = ParamData::new(&model, &params(&model, 1.5)).unwrap();
    let mut q0 = VecN::zeros();
    q0[model.motor_idx[1]] = 0.5;
    q0[model.motor_idx[2]] = -0.7;
    let lin = linearize(&model, &pd, &q0, LinearInput::Torque, &[], 0.0).unwrap();
    assert_eq!(lin.free, model.motor_idx.to_vec(), "state = the motors only");
    assert_eq!(lin.a.nrows(), 6);
    let m = mass_matrix(&model, &pd, &q0);
    let mm = nalgebra::Matrix3::from_fn(|i, j| m[(model.motor_idx[i], model.motor_idx[j])]);
    let inv = mm.try_inverse().unwrap();
    for i in 0..3 {
        for j in 0..3 {
            assert!((lin.b[(3 + i, j)] - inv[(i, j)]).abs() < 1e-8 * inv.norm(), "B[{i},{j}] {} vs {}", lin.b[(3 + i, j)], inv[(i, j)]);
            assert!(lin.a[(3 + i, j)].abs() < 1e-8, "no stiffness without gravity and springs");
        }
    }
    // in replay with both links rigid nothing is free: the step check has nothing to limit
    let tr = run(&model, &pd, &RunConfig { drive: replay(0.05), initial: None, duration: Some(0.05), sample_period: 1e-3, check_step: true }).unwrap();
    assert_eq!(tr.nsample, 51);
}

#[test]
fn bad_rigid_settings_are_refused_by_name() {
    let mut spec = ArmSpec::popup_lab();
    spec.effects.higher_bending_modes.segments = [0.0, 1.0];
    spec.effects.torsion.k_t = [500.0, f64::NAN];
    let e = Model::compile(&spec, Options::default()).unwrap_err().to_string();
    assert!(e.contains("torsion.k_t[0]") && e.contains("rigid"), "{e}");

    let mut spec = ArmSpec::popup_lab();
    spec.effects.higher_bending_modes.segments = [1.0, 4.0];
    let e = Model::compile(&spec, Options::default()).unwrap_err().to_string();
    assert!(e.contains("higher_bending_modes.segments[1]") && e.contains("0 (rigid link)"), "{e}");

    let model = compile(&ArmSpec::popup_lab(), [1, 0], [0, 0], Options::default());
    let pd = ParamData::new(&model, &params(&model, 1.0)).unwrap();
    let (mut st, drive) = hold(&model, &pd, [0.0; 3], [0.0; 3]);
    st.v[model.root_bend_idx[3]] = 0.1;
    match run(&model, &pd, &RunConfig { drive, initial: Some(st), duration: Some(0.01), sample_period: 1e-3, check_step: true }) {
        Err(Error::Input { what, message }) => {
            assert_eq!(what, "initial state");
            assert!(message.contains(model.joint_name(model.root_bend_idx[3])) && message.contains("rigid"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}


