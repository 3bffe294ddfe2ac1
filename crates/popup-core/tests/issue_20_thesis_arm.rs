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

/// Regression: an arm with both links rigid and no payload, in torque drive, has a double
/// zero eigenvalue (q1 turns freely about the vertical axis: no stiffness, no damping). The
/// QR iteration leaves it as a 2×2 block `[[0, 1], [ε, 0]]` with ε at rounding level, and
/// nalgebra's `complex_eigenvalues` read that block as a complex pair, `√(−ε)` = NaN: the
/// step check then named "the mode at |λ| = NaN rad/s dominated by joint q1" and refused
/// every closed-loop run of such an arm (docs/thesis.md's rigid 0 kg rows needed 1 g).
/// With `math::eigenvalues` every eigenvalue is finite, the free rotation's pair is ≈ 0,
/// the step check passes, and the poles equal the rigid arm's closed form: q1's pair at 0
/// and the elbow/shoulder gravity pair ±√(−k/m) of the 2-joint (q2, q3) subsystem.
#[test]
fn all_rigid_arm_without_payload_has_finite_modes() {
    use popup_core::linear::{linearize, LinearInput};
    use popup_core::model::Structure;
    use popup_core::sim::{check_step, rest_state};
    use popup_core::statics::{linear_eigs, mass_matrix, stiffness};

    let half = std::f64::consts::FRAC_PI_2;
    // popup-lab-thesis's armature and link-2 tube (0.35618 kg·m², 0.10402 kg) gave the NaN
    // at the one-link pose; the spec's and popup-lab's numbers are checked too, and the home
    // pose and a turned one
    for (armature, tube) in [(0.35618, 0.10402), (0.05, 0.38), (0.8, 0.38), (0.35618, 0.38)] {
        let text = format!("base = \"popup-lab\"\nbodies = [{{}}, {{}}, {{}}, {{}}, {{}}, {{}}, {{ parts = [{{ mass_kg = {tube} }}] }}]\n[motors]\narmature_kgm2 = [{armature}, {armature}, {armature}]\n");
        let spec = ArmSpec::from_toml(&text, "rigid.toml").unwrap();
        let opts = Options { dt: 1e-4, structure: Structure { segments: [0, 0], ..Structure::default() }, ..Options::default() };
        let model = Model::compile(&spec, opts).unwrap();
        for payload in [0.0, 1e-3, 2.0] {
            let mut p = Params::defaults(&model);
            p.payload_kg = payload;
            let pd = ParamData::new(&model, &p).unwrap();
            for qm in [[0.0, half, -half], [0.0, 0.0, 0.0], [0.3, half, 0.0]] {
                let st = rest_state(&model, &pd, 0.0, qm).unwrap();
                let free = model.free_joints(false);
                assert_eq!(free.len(), 3, "only the motors are free with both links rigid");
                let eig = linear_eigs(&model, &pd, &st.q, &free, true);
                assert!(eig.iter().all(|(l, _)| l.re.is_finite() && l.im.is_finite()), "J_m {armature}, tube {tube} kg, {payload} kg, q {qm:?}: {eig:?}");
                check_step(&model, &pd, &st.q, false).unwrap_or_else(|e| panic!("J_m {armature}, tube {tube} kg, {payload} kg, q {qm:?}: {e}"));
                // closed form of the undamped motors-only arm: det(K − λ² M) = 0 on (q1, q2, q3);
                // q1 decouples (M's cross terms vanish up to rounding, K's q1 row is 0)
                let (m, k) = (mass_matrix(&model, &pd, &st.q), stiffness(&model, &pd, &st.q));
                let sub = |x: &popup_core::math::MatN| nalgebra::DMatrix::from_fn(3, 3, |i, j| x[(free[i], free[j])]);
                let (m3, k3) = (sub(&m), sub(&k));
                let gen = m3.clone().try_inverse().unwrap() * &k3;
                let mut want: Vec<f64> = popup_core::math::eigenvalues(gen.clone()).iter().map(|z| z.re).collect();
                want.sort_by(f64::total_cmp);
                // λ² = −eig(M⁻¹K): two of the three are |λ|² ≈ 0 (q1 and, at most poses, one more)
                let mut got: Vec<f64> = eig.iter().map(|(l, _)| -(l * l).re).collect();
                got.sort_by(f64::total_cmp);
                for w in &want {
                    assert!(got.iter().any(|g| (g - w).abs() <= 1e-6 * (1.0 + w.abs())), "J_m {armature}, {payload} kg, q {qm:?}: λ² {got:?}, closed form {want:?}");
                }
                let lin = linearize(&model, &pd, &st.q, LinearInput::Torque, &[], 0.0).unwrap();
                assert!(lin.poles().iter().all(|z| z.re.is_finite() && z.im.is_finite()), "poles J_m {armature}, {payload} kg, q {qm:?}");
            }
        }
    }
}

/// The packaged arm files are built-in arms: the one list of names ([`ArmSpec::BUILTIN`])
/// is `popup-lab` and the packaged files, each loads under its own name, and
/// [`ArmSpec::resolve`] gives the same arm by name as from the file's path; an unknown name
/// is refused with every known name.
#[test]
fn packaged_arms_resolve_by_name_like_the_builtin() {
    use popup_core::error::Error;
    let packaged: Vec<&str> = ArmSpec::PACKAGED.iter().map(|(n, _)| *n).collect();
    assert_eq!(ArmSpec::BUILTIN[0], "popup-lab");
    assert_eq!(&ArmSpec::BUILTIN[1..], packaged.as_slice(), "BUILTIN must list exactly popup-lab and the packaged files");
    assert!(packaged.contains(&"popup-lab-thesis"));
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("arms");
    for name in ArmSpec::BUILTIN {
        let (spec, file) = ArmSpec::resolve(name, std::path::Path::new("/nonexistent")).unwrap();
        assert_eq!(spec.name, *name);
        assert!(file.is_none());
        assert_eq!(spec, ArmSpec::builtin(name).unwrap());
        Model::compile(&spec, Options::default()).unwrap();
        if let Some(text) = ArmSpec::packaged_source(name) {
            // the compiled-in text is the file in the repository, and loads the same by path
            assert_eq!(text, std::fs::read_to_string(dir.join(format!("{name}.toml"))).unwrap(), "{name}: rebuild after editing the file");
            let (by_path, file) = ArmSpec::resolve(&format!("{name}.toml"), &dir).unwrap();
            assert_eq!(by_path, spec);
            assert_eq!(file, Some(dir.join(format!("{name}.toml"))));
        }
    }
    assert!(ArmSpec::packaged_source("popup-lab").is_none());
    match ArmSpec::resolve("no-such-arm", std::path::Path::new(".")).unwrap_err() {
        e @ Error::UnknownArm { .. } => {
            let m = e.to_string();
            assert!(ArmSpec::BUILTIN.iter().all(|n| m.contains(n)) && m.contains("no-such-arm"), "{m}");
        }
        e => panic!("expected UnknownArm, got {e}"),
    }
}
