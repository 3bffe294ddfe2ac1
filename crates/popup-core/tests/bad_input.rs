//! Bad inputs are refused with the right error variant and a message that names the
//! offending key, value or joint and what is required.

mod common;

use common::constant_torque;
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::error::Error;
use popup_core::math::VecN;
use popup_core::model::{Integrator, Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::rollout::{run_job, Job};
use popup_core::sim::{run, RunConfig, State};
use popup_core::spec::ArmSpec;

const JOINTS: [&str; 7] = ["q1", "q2", "d11", "d12", "q3", "d21", "d22"];

fn lab(dt: f64, integ: Integrator) -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options { dt, integrator: integ, ..Options::default() }).unwrap()
}

fn defaults() -> Params {
    Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects: Default::default() }
}

fn expect_param(r: popup_core::Result<impl std::fmt::Debug>, what: &str, facts: &[&str]) -> String {
    let e = r.expect_err("must be refused");
    let msg = e.to_string();
    match &e {
        Error::InvalidParameter { what: w, .. } => assert_eq!(w, what, "{msg}"),
        other => panic!("expected InvalidParameter for {what}, got {other:?}"),
    }
    for f in facts {
        assert!(msg.contains(f), "message {msg:?} does not contain {f:?}");
    }
    msg
}

fn expect_input(r: popup_core::Result<impl std::fmt::Debug>, what: &str, facts: &[&str]) -> String {
    let e = r.expect_err("must be refused");
    let msg = e.to_string();
    match &e {
        Error::Input { what: w, .. } => assert_eq!(w, what, "{msg}"),
        other => panic!("expected Input for {what}, got {other:?}"),
    }
    for f in facts {
        assert!(msg.contains(f), "message {msg:?} does not contain {f:?}");
    }
    msg
}

fn torque_cfg(duration: Option<f64>, sp: f64) -> RunConfig {
    RunConfig { drive: constant_torque([0.0, 18.0, 4.0]), initial: None, duration, sample_period: sp, check_step: true }
}

#[test]
fn bad_params() {
    let m = lab(1e-3, Integrator::Rk4);
    expect_param(ParamData::new(&m, &Params { payload_kg: f64::NAN, ..defaults() }), "payload_kg", &["payload_kg", "NaN", ">= 0"]);
    expect_param(ParamData::new(&m, &Params { payload_kg: -0.5, ..defaults() }), "payload_kg", &["-0.5", ">= 0"]);
    expect_param(ParamData::new(&m, &Params { pressure_pa: [-100.0, 30e3], ..defaults() }), "pressure_pa[0] (link 1)", &["-100", "link 1", ">= 0"]);
    expect_param(ParamData::new(&m, &Params { pressure_pa: [30e3, f64::NAN], ..defaults() }), "pressure_pa[1] (link 2)", &["NaN", "link 2"]);
    // the rollout path reports the same error
    let job = Job { params: Params { payload_kg: -1.0, ..defaults() }, run: torque_cfg(Some(0.1), 1e-3) };
    expect_param(run_job(&m, &job), "payload_kg", &["-1"]);
    // a pressure outside the table is accepted with a warning, not refused
    let pd = ParamData::new(&m, &Params { pressure_pa: [120e3, 30e3], ..defaults() }).unwrap();
    assert!(pd.warnings.iter().any(|w| w.contains("link 1") && w.contains("120000")), "{:?}", pd.warnings);
}

#[test]
fn bad_arm_spec_and_options() {
    let mut spec = ArmSpec::popup_lab();
    spec.bodies[3].parts[1].mass_kg = -1.5;
    expect_param(Model::compile(&spec, Options::default()), "bodies[3].parts[1].mass_kg", &["bodies[3].parts[1].mass_kg", "-1.5", ">= 0"]);
    let mut spec = ArmSpec::popup_lab();
    spec.links[1].radius_m = 0.0;
    expect_param(Model::compile(&spec, Options::default()), "links[1].radius_m", &["links[1].radius_m", "> 0"]);
    let mut spec = ArmSpec::popup_lab();
    spec.stiffness.pressure_pa[4] = spec.stiffness.pressure_pa[3];
    expect_param(Model::compile(&spec, Options::default()), "stiffness.pressure_pa[4]", &["strictly increasing"]);
    expect_param(Model::compile(&ArmSpec::popup_lab(), Options { dt: -1e-3, ..Options::default() }), "options.dt", &["options.dt"]);
    expect_param(Integrator::parse("euler"), "integrator", &["euler", "rk4", "semi_implicit"]);

    let e = ArmSpec::builtin("nope").unwrap_err();
    assert!(matches!(e, Error::UnknownArm { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("\"nope\"") && msg.contains("popup-lab"), "{msg}");
}

fn step_too_large(r: popup_core::Result<impl std::fmt::Debug>, dt: f64, integ: &str) -> f64 {
    let e = r.expect_err("dt must be refused");
    let msg = e.to_string();
    match e {
        Error::StepTooLarge { dt: d, dt_max, integrator, detail } => {
            assert_eq!(d, dt);
            assert_eq!(integrator, integ);
            assert!(dt_max > 0.0 && dt_max < dt, "dt_max {dt_max}");
            assert!(JOINTS.iter().any(|j| detail.contains(&format!("joint {j} "))), "detail names no joint: {detail}");
            assert!(msg.contains(integ) && msg.contains(&format!("{dt_max:e}")) && msg.contains("rad/s"), "{msg}");
            println!("{msg}");
            dt_max
        }
        other => panic!("expected StepTooLarge, got {other:?}"),
    }
}

#[test]
fn step_too_large_and_the_suggested_step_works() {
    for integ in [Integrator::Rk4, Integrator::SemiImplicit] {
        // torque drive: every joint free
        let m = lab(0.05, integ);
        let pd = ParamData::new(&m, &defaults()).unwrap();
        let dt_max = step_too_large(run(&m, &pd, &torque_cfg(Some(1.0), 0.05)), 0.05, integ.name());
        let m2 = lab(dt_max, integ);
        let tr = run(&m2, &pd, &torque_cfg(Some(200.0 * dt_max), dt_max)).expect("the suggested dt_max is accepted");
        assert!(tr.data.iter().all(|x| x.is_finite()));

        // replay with the motors held: only the bending joints are integrated
        let hold = Drive::Replay(Spline3::new(&[0.0, 3.0], &[[0.0, 0.3, -0.2]; 2]).unwrap());
        let cfg = |sp: f64, check: bool| RunConfig { drive: hold.clone(), initial: None, duration: None, sample_period: sp, check_step: check };
        let dt_max = step_too_large(run(&m, &pd, &cfg(0.05, true)), 0.05, integ.name());
        let e = run(&m, &pd, &cfg(0.05, true)).unwrap_err();
        assert!(["d11", "d12", "d21", "d22"].iter().any(|j| e.to_string().contains(&format!("joint {j} "))), "replay limit must name a bending joint: {e}");
        // at dt_max: accepted, and a perturbed bending state stays bounded
        let m2 = lab(dt_max, integ);
        let mut s = popup_core::sim::rest_state(&m2, &pd, 0.0, [0.0, 0.3, -0.2]).unwrap();
        let b0 = s.q;
        s.q[m2.bend_idx[1]] += 0.02;
        s.q[m2.bend_idx[3]] += 0.02;
        let run_from = |model: &Model, check: bool| {
            let c = RunConfig { initial: Some(s), ..cfg(model.options.dt, check) };
            run(model, &pd, &c)
        };
        let tr = run_from(&m2, true).expect("replay at the suggested dt_max is accepted");
        let end = tr.final_state.q - b0;
        assert!(end.amax() < 0.02, "{integ:?}: bending deflection grew at dt_max: {end:?}");
        // 30 % beyond the true limit (dt_max is 0.95 of it), unchecked: the ringing grows
        let m3 = lab(dt_max / 0.95 * 1.3, integ);
        match run_from(&m3, false) {
            Err(Error::Diverged { .. }) => {}
            Ok(tr) => {
                let end = tr.final_state.q - b0;
                assert!(end.amax() > 0.02, "{integ:?}: no growth beyond the stability limit: {end:?}");
            }
            Err(other) => panic!("{other:?}"),
        }
    }
}

#[test]
fn divergence_is_reported_with_step_and_joint() {
    let m = lab(0.01, Integrator::Rk4);
    let pd = ParamData::new(&m, &defaults()).unwrap();
    let drive = Drive::Torque(Linear3::new(&[0.0, 0.1, 0.11], &[[0.0; 3], [0.0; 3], [0.0, 1e6, -1e6]]).unwrap());
    let cfg = RunConfig { drive, initial: None, duration: Some(2.0), sample_period: 0.01, check_step: false };
    let e = run(&m, &pd, &cfg).unwrap_err();
    let msg = e.to_string();
    println!("{msg}");
    match e {
        Error::Diverged { step, time, joint, quantity, advice } => {
            assert!((10..200).contains(&step), "step {step}");
            assert!((time - step as f64 * 0.01).abs() < 1e-9);
            assert!(JOINTS.contains(&joint.as_str()), "{joint}");
            assert!(quantity.contains("rad/s"), "{quantity}");
            assert!(advice.contains("dt") && advice.contains("rk4"), "{advice}");
            assert!(msg.contains(&format!("step {step}")) && msg.contains(&format!("joint {joint}")), "{msg}");
        }
        other => panic!("expected Diverged, got {other:?}"),
    }
}

#[test]
fn bad_drive_and_run_config() {
    // replay samples
    expect_input(Spline3::new(&[0.0, 0.1, 0.1, 0.2], &[[0.0; 3]; 4]), "encoder replay", &["strictly increasing", "t[2]"]);
    expect_input(Spline3::new(&[0.0, 0.2, 0.1], &[[0.0; 3]; 3]), "encoder replay", &["strictly increasing", "t[2]"]);
    expect_input(Spline3::new(&[0.0, 0.1, 0.2], &[[0.0; 3], [0.0, 0.0, f64::NAN], [0.0; 3]]), "encoder replay angles", &["row 1", "column 2", "NaN"]);
    expect_input(Spline3::new(&[0.0, 0.1, 0.2], &[[0.0; 3]; 2]), "encoder replay", &["3 time stamps", "2 value rows"]);
    expect_input(Spline3::new(&[0.0], &[[0.0; 3]]), "encoder replay", &["at least 2"]);
    expect_input(Linear3::new(&[0.0, 0.1], &[[0.0; 3], [f64::INFINITY, 0.0, 0.0]]), "motor torques", &["row 1", "column 0", "inf"]);

    let m = lab(1e-3, Integrator::Rk4);
    let pd = ParamData::new(&m, &defaults()).unwrap();
    expect_input(run(&m, &pd, &torque_cfg(Some(0.1), 1.5e-3)), "sample_period (1/sample_rate)", &["0.0015", "whole multiple", "dt = 0.001", "sample rate 666.6666666666666 Hz must divide the physics rate 1000.0 Hz"]);
    expect_input(run(&m, &pd, &torque_cfg(Some(0.1), 0.0)), "sample_period (1/sample_rate)", &["> 0"]);
    expect_input(run(&m, &pd, &torque_cfg(None, 1e-3)), "duration", &["torque-driven run needs a duration"]);
    expect_input(run(&m, &pd, &torque_cfg(Some(f64::NAN), 1e-3)), "duration", &["NaN"]);
    let mut q = VecN::zeros();
    q[3] = f64::NAN;
    let cfg = RunConfig { initial: Some(State { t: 0.0, q, v: VecN::zeros() }), ..torque_cfg(Some(0.1), 1e-3) };
    expect_input(run(&m, &pd, &cfg), "initial state", &["d12", "NaN"]);
}
