//! Arm files: TOML round trip, partial files on a built-in `base`, precise refusals, and a
//! complete non-lab arm (`tests/data/canadarm3.toml`) that compiles and runs.

mod common;

use common::{col, constant_torque};
use popup_core::error::Error;
use popup_core::kinematics::prbm::end_effector;
use popup_core::math::VecN;
use popup_core::model::{Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sim::{rest_state, run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::gravity_torque;

const CANADARM3: &str = include_str!("data/canadarm3.toml");

fn arm_file_err(text: &str, facts: &[&str]) -> String {
    let e = ArmSpec::from_toml(text, "test.toml").expect_err("must be refused");
    let msg = e.to_string();
    assert!(matches!(e, Error::ArmFile { .. }), "expected ArmFile, got {e:?}");
    for f in ["test.toml"].iter().chain(facts) {
        assert!(msg.contains(f), "message {msg:?} does not contain {f:?}");
    }
    msg
}

#[test]
fn round_trip() {
    let mut odd = ArmSpec::popup_lab();
    odd.name = "odd \"quoted\" arm".into();
    odd.joints[4].theta_offset = -0.1234567890123;
    odd.links[1].stiffness_scale = Some(2.5);
    odd.bodies[3].parts[0].radius_m = Some(0.0912345);
    odd.bodies[6].parts[0].inertia_kgm2 = [1e-3, 2e-3, 3e-3, 1e-17, -4e-5, 0.1 + 0.2];
    odd.wrinkling.coefficient = "thesis".into();
    odd.gravity_mps2 = [0.1, -0.2, -9.80665];
    let canadarm = ArmSpec::from_toml(CANADARM3, "canadarm3.toml").unwrap();
    for spec in [ArmSpec::popup_lab(), odd, canadarm] {
        let text = spec.to_toml();
        let back = ArmSpec::from_toml(&text, "round-trip").unwrap();
        assert_eq!(back, spec, "round trip changed the spec:\n{text}");
        assert_eq!(back.to_toml(), text);
    }
}

#[test]
fn partial_file_on_base_overrides_and_changes_the_model() {
    let text = r#"
base = "popup-lab"

[[links]]
radius_m = 0.1          # link 1 fatter: stiffness scale (0.1/0.055)³

[[bodies]]
[[bodies]]
[[bodies]]
[[bodies]]
[[bodies.parts]]
[[bodies.parts]]
mass_kg = 3.0           # elbow motoreducer 1.5 → 3 kg
"#;
    let spec = ArmSpec::from_toml(text, "partial.toml").unwrap();
    let mut expected = ArmSpec::popup_lab();
    expected.links[0].radius_m = 0.1;
    expected.bodies[3].parts[1].mass_kg = 3.0;
    assert_eq!(spec, expected, "the partial file must change exactly the two keys");

    let lab = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let new = Model::compile(&spec, Options::default()).unwrap();
    let p = Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects: Default::default() };
    let (pd0, pd1) = (ParamData::new(&lab, &p).unwrap(), ParamData::new(&new, &p).unwrap());
    let b12 = lab.bend_idx[1];
    let b22 = lab.bend_idx[3];
    let k_ratio = pd1.k[b12] / pd0.k[b12];
    assert!((k_ratio - (0.1f64 / 0.085).powi(3)).abs() < 1e-12, "k ratio {k_ratio}");
    assert_eq!(pd1.k[b22], pd0.k[b22]);
    let s0 = rest_state(&lab, &pd0, 0.0, [0.0; 3]).unwrap();
    let s1 = rest_state(&new, &pd1, 0.0, [0.0; 3]).unwrap();
    // spring moment = gravity moment about d12: the old moment, plus 1.5 kg more at 0.57 m
    // from the d12 axis, over the new stiffness (small angles: cos δ ≈ 1 to ~1e-3)
    let m_old = -pd0.k[b12] * s0.q[b12];
    let d12_pred = -(m_old + 1.5 * 9.81 * 0.57) / pd1.k[b12];
    let rigid = VecN::zeros();
    let sag = |m: &Model, q: &VecN| end_effector(m, q).z - end_effector(m, &rigid).z;
    let (sag0, sag1) = (sag(&lab, &s0.q), sag(&new, &s1.q));
    println!(
        "δ12: lab {:.6}, partial file {:.6} (predicted {d12_pred:.6}); δ22 {:.6} → {:.6}; tip sag {sag0:.5} → {sag1:.5} m",
        s0.q[b12], s1.q[b12], s0.q[b22], s1.q[b22]
    );
    assert!((s1.q[b12] - d12_pred).abs() < 2e-3 * d12_pred.abs(), "δ12 {} vs predicted {d12_pred}", s1.q[b12]);
    assert!((s1.q[b22] - s0.q[b22]).abs() < 1e-4, "link 2 deflection changed: {} → {}", s0.q[b22], s1.q[b22]);
    // the tip follows: sag change ≈ change of δ12 times the 1.17 m from the d12 axis to the tip
    let dsag_pred = (s1.q[b12] - s0.q[b12]) * 1.17;
    assert!(((sag1 - sag0) - dsag_pred).abs() < 0.02 * dsag_pred.abs(), "sag change {} vs {dsag_pred}", sag1 - sag0);
}

#[test]
fn refusals_name_the_problem() {
    // unknown keys, top level and nested, with and without base
    arm_file_err("base = \"popup-lab\"\ncolour = \"red\"\n", &["colour"]);
    arm_file_err("base = \"popup-lab\"\n[[links]]\nradius_mm = 0.1\n", &["radius_mm"]);
    arm_file_err("base = \"popup-lab\"\n[payload]\nmass_kg = 1.0\n", &["mass_kg"]);
    let full = ArmSpec::popup_lab().to_toml();
    arm_file_err(&full.replace("[motors]\n", "[motors]\ngear_ratio = 100\n"), &["gear_ratio"]);
    // wrong type
    arm_file_err("base = \"popup-lab\"\n[[links]]\nradius_m = \"big\"\n", &["radius_m"]);
    // malformed TOML: the parser's line number
    let msg = arm_file_err("base = \"popup-lab\"\n\n[links\nradius_m = 0.1\n", &["line 3"]);
    println!("{msg}");
    // without base the file must be complete
    let cut = full.replace("[wrinkling]\ncoefficient = \"classical\"\ncollapse_factor = 2.0\n", "");
    assert_ne!(cut, full);
    arm_file_err(&cut, &["missing field", "wrinkling"]);
    arm_file_err("name = \"half an arm\"\ngravity_mps2 = [0.0, 0.0, -9.81]\n", &["missing field"]);
    // base must name a built-in arm
    let e = ArmSpec::from_toml("base = \"nope\"\n", "test.toml").unwrap_err();
    assert!(matches!(e, Error::UnknownArm { .. }) && e.to_string().contains("nope") && e.to_string().contains("popup-lab"), "{e}");
    arm_file_err("base = 3\n", &["base"]);
    // values parse but are invalid: the compile step names the key path
    let spec = ArmSpec::from_toml("base = \"popup-lab\"\n[[bodies]]\n[[bodies.parts]]\nmass_kg = -2.0\n", "test.toml").unwrap();
    let e = Model::compile(&spec, Options::default()).unwrap_err();
    assert!(matches!(e, Error::InvalidParameter { .. }) && e.to_string().contains("bodies[0].parts[0].mass_kg"), "{e}");
}

#[test]
fn canadarm3_file_compiles_and_runs() {
    let spec = ArmSpec::from_toml(CANADARM3, "canadarm3.toml").unwrap();
    assert_eq!(spec.name, "canadarm3-inflatable");
    let model = Model::compile(&spec, Options::default()).unwrap();
    let pd = ParamData::new(&model, &Params::defaults(&model)).unwrap();
    assert!(pd.warnings.is_empty(), "{:?}", pd.warnings);
    // straight out along +x at the shoulder height: 0.15 + 4.05 + 0.15 + 4.05 = 8.4 m reach
    let ee0 = end_effector(&model, &VecN::zeros());
    assert!((ee0 - nalgebra::Vector3::new(8.4, 0.0, 0.5)).norm() < 1e-12, "{ee0:?}");
    let q0 = [0.2, 0.3, -0.5];
    let s0 = rest_state(&model, &pd, 0.0, q0).unwrap();
    let mut rigid = VecN::zeros();
    for k in 0..3 {
        rigid[model.motor_idx[k]] = q0[k];
    }
    let sag = end_effector(&model, &s0.q).z - end_effector(&model, &rigid).z;
    let modes = popup_core::statics::locked_modes(&model, &pd, &s0.q);
    println!("canadarm3 at {q0:?}: bending {:?}, tip sag {sag:.4} m, locked modes {modes:.2?} rad/s", model.root_bend_idx.map(|b| s0.q[b]));
    assert!(sag < 0.0 && sag > -0.5, "tip sag {sag} m under lunar gravity");
    // hold against lunar gravity, then a 50 N·m step on the shoulder pitch
    let g = gravity_torque(&model, &pd, &s0.q);
    let hold: [f64; 3] = std::array::from_fn(|k| g[model.motor_idx[k]]);
    let tau = [hold[0], hold[1] + 50.0, hold[2]];
    let cfg = RunConfig { drive: constant_torque(tau), initial: Some(s0), duration: Some(2.0), sample_period: 0.01, check_step: true };
    let tr = run(&model, &pd, &cfg).unwrap();
    assert_eq!(tr.nsample, 201);
    assert!(tr.data.iter().all(|x| x.is_finite()));
    let q: Vec<Vec<f64>> = ["q1", "q2", "q3"].iter().map(|c| col(&tr, c)).collect();
    assert!(q[1][200] > q[1][0] + 1e-3, "the shoulder step did not move the arm: {} → {}", q[1][0], q[1][200]);
    // energy balance: constant torques do work Σ τ Δq; the dampers only take energy out
    let work: f64 = (0..3).map(|k| tau[k] * (q[k][200] - q[k][0])).sum();
    let e = col(&tr, "energy");
    println!("canadarm3 step: work {work:.4} J, energy change {:.4} J, q2 {:.4} → {:.4} rad", e[200] - e[0], q[1][0], q[1][200]);
    assert!(e[200] - e[0] <= work + 1e-6 && e[200] - e[0] > 0.5 * work, "energy change {} vs work {work}", e[200] - e[0]);
}
