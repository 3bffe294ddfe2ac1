//! Issue 20 (the thesis reproduced): a link's own damping scale, and the Cartesian law's
//! choice of rigid kinematics (`[controller] cartesian_arm`).

use popup_core::control::config::parse_control;
use popup_core::control::CartesianArm;
use popup_core::model::{Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::spec::ArmSpec;

#[test]
fn damping_scale_multiplies_only_that_links_damping() {
    let text = "base = \"popup-lab\"\nlinks = [{}, { stiffness_scale = 0.5, damping_scale = 3.0 }]\n";
    let spec = ArmSpec::from_toml(text, "thesis.toml").unwrap();
    assert_eq!(spec.links[1].damping_scale, Some(3.0));
    assert_eq!(ArmSpec::from_toml(&spec.to_toml(), "round-trip").unwrap(), spec);
    let lab = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let new = Model::compile(&spec, Options::default()).unwrap();
    let p = Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects: Default::default() };
    let (pd0, pd1) = (ParamData::new(&lab, &p).unwrap(), ParamData::new(&new, &p).unwrap());
    for (i, &b) in lab.bend_idx[..4].iter().enumerate() {
        let (kr, cr) = (pd1.k[b] / pd0.k[b], pd1.c[b] / pd0.c[b]);
        if i < 2 {
            assert_eq!((kr, cr), (1.0, 1.0), "link 1 joint {i}");
        } else {
            // link 2: its own stiffness scale (0.5) replaces (r2/r_ref)³ = 1; c gets × 3 on top
            assert!((kr - 0.5).abs() < 1e-12 && (cr - 1.5).abs() < 1e-12, "link 2 joint {i}: k × {kr}, c × {cr}");
        }
    }
    let bad = ArmSpec::from_toml("base = \"popup-lab\"\nlinks = [{}, { damping_scale = -1.0 }]\n", "bad.toml").unwrap();
    let e = Model::compile(&bad, Options::default()).expect_err("a negative damping scale must be refused");
    assert!(e.to_string().contains("damping_scale"), "{e}");
}

#[test]
fn cartesian_arm_is_parsed_and_checked() {
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let default = parse_control(&model, "[controller]\n", "c.toml").unwrap();
    assert_eq!(default.controller.cartesian_arm, CartesianArm::Prbm);
    for (name, want) in [("prbm", CartesianArm::Prbm), ("as_built", CartesianArm::AsBuilt), ("ik", CartesianArm::Ik)] {
        let cf = parse_control(&model, &format!("[controller]\ncartesian_arm = \"{name}\"\n"), "c.toml").unwrap();
        assert_eq!(cf.controller.cartesian_arm, want);
    }
    assert!(parse_control(&model, "[controller]\ncartesian_arm = \"table9\"\n", "c.toml").is_err());
}
