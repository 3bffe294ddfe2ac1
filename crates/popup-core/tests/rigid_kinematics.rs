//! Rigid 3-DOF kinematics of the POP-UP arm: FK, Jacobian, closed-form IK, singularities,
//! workspace errors (thesis Tables 1 and 2).

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix3, Vector3};
use popup_core::error::Error;
use popup_core::kinematics::rigid::*;

/// xorshift64* — deterministic, no external crate.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
}

fn tables() -> [RigidArm; 4] {
    let with_offsets = RigidArm::new(
        "table 1 with theta offsets",
        [0.15, 0.05, -0.12],
        [0.0, 0.745, 0.685],
        [FRAC_PI_2, 0.0, 0.0],
        [0.4, -1.2, 0.3],
    )
    .unwrap();
    // A negative DH length is legal (it flips the link); the IK handles signed a2, a3.
    let signed = RigidArm::new(
        "table 1 with a3 < 0",
        [0.15, 0.05, -0.12],
        [0.0, 0.745, -0.685],
        [FRAC_PI_2, 0.0, 0.0],
        [0.0, 0.2, -0.1],
    )
    .unwrap();
    [RigidArm::table1(), RigidArm::table2(), with_offsets, signed]
}

fn ang_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * PI);
    d.min(2.0 * PI - d)
}

fn q_dist(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|i| ang_diff(a[i], b[i])).fold(0.0, f64::max)
}

fn assert_close(a: &Vector3<f64>, b: &Vector3<f64>, tol: f64, what: &str) {
    assert!(
        (a - b).norm() <= tol,
        "{what}: {a:?} vs {b:?} (|diff| = {:e})",
        (a - b).norm()
    );
}

/// Planar distance of p from the shoulder axis, as the error message reports it.
fn planar_distance(arm: &RigidArm, p: &Vector3<f64>) -> f64 {
    let d = arm.lateral_offset();
    let r2 = p[0] * p[0] + p[1] * p[1] - d * d;
    (r2 + (p[2] - arm.d[0]).powi(2)).sqrt()
}

#[test]
fn fk_known_poses() {
    let t2 = RigidArm::table2();
    assert_close(
        &t2.fk(&[0.0; 3]),
        &Vector3::new(1.43, 0.0, 0.0),
        1e-12,
        "table 2 zero",
    );
    assert_close(
        &t2.fk(&[0.0, FRAC_PI_2, 0.0]),
        &Vector3::new(0.0, 0.0, 1.43),
        1e-12,
        "table 2 up",
    );
    assert_close(
        &t2.fk(&[FRAC_PI_2, 0.0, 0.0]),
        &Vector3::new(0.0, 1.43, 0.0),
        1e-12,
        "table 2 q1",
    );
    // Elbow bent 90° down: upper arm along x, forearm along −z.
    assert_close(
        &t2.fk(&[0.0, 0.0, -FRAC_PI_2]),
        &Vector3::new(0.745, 0.0, -0.685),
        1e-12,
        "bent",
    );

    // Table 1 at zero, by hand: A1 = Rot_x(π/2) lifted by d1 = 0.15, so x_1 = x_0, z_1 = −y_0;
    // A2, A3 move a2 + a3 = 1.43 along x_1 and d2 + d3 = −0.07 along z_1, i.e. +0.07 along y_0.
    let t1 = RigidArm::table1();
    assert_close(
        &t1.fk(&[0.0; 3]),
        &Vector3::new(1.43, 0.07, 0.15),
        1e-12,
        "table 1 zero",
    );
    // q1 = π/2 turns that about z_0: (x, y) → (−y, x).
    assert_close(
        &t1.fk(&[FRAC_PI_2, 0.0, 0.0]),
        &Vector3::new(-0.07, 1.43, 0.15),
        1e-12,
        "t1 q1",
    );
    assert_close(
        &t1.fk(&[0.0, FRAC_PI_2, 0.0]),
        &Vector3::new(0.0, 0.07, 1.58),
        1e-12,
        "t1 up",
    );

    let f = t1.frames(&[0.0; 3]);
    assert_eq!(f[0].0, Matrix3::identity());
    assert_eq!(f[0].1, Vector3::zeros());
    let r_w1 = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0);
    assert!((f[1].0 - r_w1).norm() < 1e-15);
    assert_close(&f[1].1, &Vector3::new(0.0, 0.0, 0.15), 1e-15, "p_W1");
    assert_close(&f[2].1, &Vector3::new(0.745, -0.05, 0.15), 1e-15, "p_W2");
    assert_close(&f[3].1, &t1.fk(&[0.0; 3]), 0.0, "p_W3 = p_WE");
    for (r, _) in &f {
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
    }
}

#[test]
fn fk_matches_closed_form() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for arm in tables() {
        let big_d = arm.lateral_offset();
        for _ in 0..200 {
            let q = [
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
            ];
            let th: Vec<f64> = (0..3).map(|i| q[i] + arm.theta_offset[i]).collect();
            let r = arm.a[1] * th[1].cos() + arm.a[2] * (th[1] + th[2]).cos();
            let z = arm.a[1] * th[1].sin() + arm.a[2] * (th[1] + th[2]).sin();
            let (s1, c1) = th[0].sin_cos();
            let p = Vector3::new(c1 * r + s1 * big_d, s1 * r - c1 * big_d, arm.d[0] + z);
            assert_close(&arm.fk(&q), &p, 1e-14, &arm.name);
        }
    }
}

#[test]
fn ik_roundtrip_random_joint_space() {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for arm in tables() {
        let mut n = 0;
        while n < 1000 {
            let q = [
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
            ];
            let sing = arm.singularity(&q, 1e-3);
            if sing.elbow || sing.shoulder {
                continue;
            }
            n += 1;
            let p = arm.fk(&q);
            let sols = arm
                .ik(&p)
                .unwrap_or_else(|e| panic!("{}: q = {q:?}: {e}", arm.name));
            let mut found = false;
            for (k, s) in sols.iter().enumerate() {
                assert_close(&arm.fk(&s.q), &p, 1e-10, &format!("{} sol {k}", arm.name));
                for v in s.q {
                    assert!(v > -PI && v <= PI, "not wrapped: {:?}", s.q);
                }
                found |= q_dist(&s.q, &q) < 1e-8;
                for t in &sols[k + 1..] {
                    assert!(
                        q_dist(&s.q, &t.q) > 1e-6,
                        "solutions not distinct: {sols:?}"
                    );
                }
                // Branch labels agree with the geometry.
                let sg = arm.singularity(&s.q, 0.0);
                let front = sg.shoulder_measure > 0.0;
                assert_eq!(s.shoulder == Shoulder::Front, front, "{s:?}");
                let f = arm.frames(&s.q);
                let (e, w) = (f[2].1 - f[1].1, p - f[1].1);
                // Above the shoulder→wrist line, in the vertical arm plane.
                let horiz = |v: Vector3<f64>| v.x * f[1].0[(0, 0)] + v.y * f[1].0[(1, 0)];
                let above = (horiz(w) * e.z - w.z * horiz(e)) * horiz(w).signum() > 0.0;
                assert_eq!(s.elbow == Elbow::Up, above, "{s:?}");
            }
            let labels: Vec<_> = sols.iter().map(|s| (s.shoulder, s.elbow)).collect();
            assert_eq!(
                labels,
                [
                    (Shoulder::Front, Elbow::Up),
                    (Shoulder::Front, Elbow::Down),
                    (Shoulder::Back, Elbow::Up),
                    (Shoulder::Back, Elbow::Down)
                ]
            );
            assert!(found, "{}: original q = {q:?} not among {sols:?}", arm.name);
        }
    }
}

#[test]
fn ik_random_cartesian_points_agree_with_workspace() {
    let mut rng = Rng(0xdead_beef_cafe_f00d);
    for arm in tables() {
        let (mut ok, mut bad) = (0, 0);
        while ok < 1000 {
            let p = Vector3::new(
                rng.uniform(-1.6, 1.6),
                rng.uniform(-1.6, 1.6),
                rng.uniform(-1.5, 1.8),
            );
            match (arm.in_workspace(&p), arm.ik(&p)) {
                (Ok(()), Ok(sols)) => {
                    ok += 1;
                    for s in &sols {
                        assert_close(&arm.fk(&s.q), &p, 1e-10, &arm.name);
                    }
                    for i in 0..4 {
                        for j in i + 1..4 {
                            assert!(q_dist(&sols[i].q, &sols[j].q) > 1e-9, "{sols:?}");
                        }
                    }
                }
                (Err(e1), Err(e2)) => {
                    assert_eq!(e1, e2);
                    assert!(matches!(e1, Error::Unreachable { .. }), "{e1}");
                    let rho = p.x.hypot(p.y);
                    let l = planar_distance(&arm, &p);
                    let (lo, hi) = arm.planar_reach();
                    assert!(rho < arm.lateral_offset().abs() || l > hi || l < lo, "{e1}");
                    bad += 1;
                }
                (a, b) => panic!("in_workspace {a:?} but ik {b:?} for p = {p:?}"),
            }
        }
        assert!(bad > 100, "sampling box too small: {bad}");
    }
}

#[test]
fn ik_at_boundary_tolerates_roundoff() {
    for arm in tables() {
        // Fully stretched and fully folded: |c3| = 1 up to round-off, Up = Down.
        for q3 in [0.0, PI] {
            let q = [0.7, 0.3, q3 - arm.theta_offset[2]];
            let p = arm.fk(&q);
            let sols = arm.ik(&p).unwrap_or_else(|e| panic!("{}: {e}", arm.name));
            for s in &sols {
                assert_close(&arm.fk(&s.q), &p, 1e-10, &arm.name);
            }
            assert!(q_dist(&sols[0].q, &sols[1].q) < 1e-6);
        }
    }
}

#[test]
fn jacobian_matches_finite_differences() {
    let mut rng = Rng(42);
    let h = 1e-6;
    for arm in tables() {
        for _ in 0..50 {
            let q = [
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
            ];
            let j = arm.jacobian(&q);
            let r0 = arm.frames(&q)[3].0;
            for i in 0..3 {
                let (mut qp, mut qm) = (q, q);
                qp[i] += h;
                qm[i] -= h;
                let v = (arm.fk(&qp) - arm.fk(&qm)) / (2.0 * h);
                let jv = Vector3::new(j[(0, i)], j[(1, i)], j[(2, i)]);
                assert!(
                    (v - jv).norm() < 1e-7,
                    "{}: col {i}: {v:?} vs {jv:?}",
                    arm.name
                );
                // Ṙ Rᵀ = [ω]×.
                let rd = (arm.frames(&qp)[3].0 - arm.frames(&qm)[3].0) / (2.0 * h);
                let w = rd * r0.transpose();
                let w = Vector3::new(w[(2, 1)], w[(0, 2)], w[(1, 0)]);
                let jw = Vector3::new(j[(3, i)], j[(4, i)], j[(5, i)]);
                assert!(
                    (w - jw).norm() < 1e-7,
                    "{}: ω col {i}: {w:?} vs {jw:?}",
                    arm.name
                );
            }
        }
    }
}

/// det J_v = −a2 a3 sin θ3 (a2 cos θ2 + a3 cos(θ2 + θ3)), independent of d1, d2, d3.
fn det_formula(arm: &RigidArm, q: &[f64; 3]) -> f64 {
    let (t2, t3) = (q[1] + arm.theta_offset[1], q[2] + arm.theta_offset[2]);
    let (a2, a3) = (arm.a[1], arm.a[2]);
    -a2 * a3 * t3.sin() * (a2 * t2.cos() + a3 * (t2 + t3).cos())
}

#[test]
fn det_jv_formula_and_sign() {
    let mut rng = Rng(7);
    for arm in tables() {
        for _ in 0..200 {
            let q = [
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
                rng.uniform(-PI, PI),
            ];
            let j = arm.jacobian(&q);
            let det = j.fixed_view::<3, 3>(0, 0).determinant();
            assert!(
                (det - det_formula(&arm, &q)).abs() < 1e-12,
                "{}: {det} vs formula",
                arm.name
            );
            assert!((arm.manipulability(&q) - det.abs()).abs() < 1e-15);
        }
    }
}

#[test]
fn singularities_flagged() {
    for arm in tables() {
        let off = arm.theta_offset;
        for t3 in [0.0, PI] {
            let q = [0.4, 0.2, t3 - off[2]];
            let s = arm.singularity(&q, 1e-9);
            assert!(s.elbow, "{}: {s:?}", arm.name);
            assert!(s.elbow_measure.abs() < 1e-12);
            assert!(arm.manipulability(&q) < 1e-12);
        }
        // Shoulder: θ2 = atan2(a2 + a3 c3, a3 s3) makes a2 c2 + a3 c23 = 0.
        let (a2, a3) = (arm.a[1], arm.a[2]);
        for t3 in [1.0, -0.6, 2.5] {
            let t2 = (a2 + a3 * f64::cos(t3)).atan2(a3 * f64::sin(t3));
            let q = [-1.1, t2 - off[1], t3 - off[2]];
            let s = arm.singularity(&q, 1e-9);
            assert!(s.shoulder && !s.elbow, "{}: {s:?}", arm.name);
            assert!(s.shoulder_measure.abs() < 1e-12);
            assert!(arm.manipulability(&q) < 1e-12);
            assert!((arm.manipulability(&q) - det_formula(&arm, &q).abs()).abs() < 1e-15);
        }
        let q = [0.3 - off[0], 0.4 - off[1], 1.2 - off[2]];
        let s = arm.singularity(&q, 1e-6);
        assert!(!s.elbow && !s.shoulder);
        assert!(arm.manipulability(&q) > 0.1);
    }
}

#[test]
fn unreachable_targets_are_reported_with_distance() {
    for arm in tables() {
        let (lo, hi) = arm.planar_reach();
        assert!((hi - 1.43).abs() < 1e-12 && (lo - 0.06).abs() < 1e-12);
        let d1 = arm.d[0];
        let big_d = arm.lateral_offset();
        let beyond = Vector3::new(1.3, 0.6, d1 + 0.6);
        // r = 0.03 m, z − d1 = 0.02 m: 0.036 m from the shoulder axis in the arm plane.
        let inside = Vector3::new((big_d * big_d + 0.03 * 0.03).sqrt(), 0.0, d1 + 0.02);
        for p in [beyond, inside] {
            let e = arm.ik(&p).unwrap_err();
            assert_eq!(arm.in_workspace(&p).unwrap_err(), e);
            let msg = e.to_string();
            let dist = format!("{:.6}", planar_distance(&arm, &p));
            assert!(msg.contains(&dist), "{msg} should contain {dist}");
            assert!(
                msg.contains("1.430000") && msg.contains("0.060000"),
                "{msg}"
            );
            match e {
                Error::Unreachable {
                    target, arm: name, ..
                } => {
                    assert_eq!(target, [p[0], p[1], p[2]]);
                    assert_eq!(name, arm.name);
                }
                other => panic!("expected Unreachable, got {other}"),
            }
        }
        for p in [
            Vector3::new(f64::NAN, 0.0, 0.5),
            Vector3::new(0.5, f64::INFINITY, 0.5),
            Vector3::new(0.5, 0.5, f64::NEG_INFINITY),
        ] {
            assert!(matches!(arm.ik(&p), Err(Error::Unreachable { .. })));
            assert!(matches!(
                arm.in_workspace(&p),
                Err(Error::Unreachable { .. })
            ));
        }
    }
    // Table 1: closer to the base axis than the lateral offset |d2 + d3| = 0.07 m.
    let t1 = RigidArm::table1();
    let e = t1.ik(&Vector3::new(0.03, 0.04, 0.6)).unwrap_err();
    assert!(matches!(e, Error::Unreachable { .. }), "{e}");
    assert!(
        e.to_string().contains("0.050000") && e.to_string().contains("0.070000"),
        "{e}"
    );
}

#[test]
fn chapter8_target_reachable_with_table1() {
    let arm = RigidArm::table1();
    let p = Vector3::new(-0.8, -0.8, 0.9);
    arm.in_workspace(&p).unwrap();
    let sols = arm.ik(&p).unwrap();
    for s in &sols {
        assert_close(&arm.fk(&s.q), &p, 1e-10, "chapter 8");
    }
}

#[test]
fn target_on_shoulder_axis_is_singular() {
    let t2 = RigidArm::table2();
    for p in [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.0, 0.0, -0.5),
        Vector3::new(1e-12, 0.0, 0.3),
    ] {
        let e = t2.ik(&p).unwrap_err();
        assert!(matches!(e, Error::Singular(_)), "{e}");
        assert!(e.to_string().contains("shoulder singularity"), "{e}");
        t2.in_workspace(&p).unwrap();
    }
    // Beyond reach on the axis is unreachable, not singular.
    assert!(matches!(
        t2.ik(&Vector3::new(0.0, 0.0, 1.5)),
        Err(Error::Unreachable { .. })
    ));
    // Table 1: the singular surface is the cylinder rho = |d2 + d3| (e.g. arm straight up).
    let t1 = RigidArm::table1();
    for q1 in [0.0, 1.0, -2.5] {
        let p = t1.fk(&[q1, FRAC_PI_2, 0.0]);
        let e = t1.ik(&p).unwrap_err();
        assert!(matches!(e, Error::Singular(_)), "{e}");
        assert!(e.to_string().contains("shoulder singularity"), "{e}");
    }
    // The base axis itself is inside the offset cylinder.
    assert!(matches!(
        t1.ik(&Vector3::new(0.0, 0.0, 1.0)),
        Err(Error::Unreachable { .. })
    ));
}

#[test]
fn invalid_tables_rejected() {
    let e = RigidArm::new("bad", [0.0, f64::NAN, 0.0], [0.0; 3], [0.0; 3], [0.0; 3]).unwrap_err();
    assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
    assert!(e.to_string().contains("d[1]"), "{e}");
    let e = RigidArm::new(
        "bad",
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [f64::INFINITY, 0.0, 0.0],
    )
    .unwrap_err();
    assert!(e.to_string().contains("theta_offset[0]"), "{e}");

    // FK works for any table, closed-form IK only for the POP-UP structure.
    let planar = RigidArm::new("planar", [0.0; 3], [0.5, 0.4, 0.3], [0.0; 3], [0.0; 3]).unwrap();
    assert_close(
        &planar.fk(&[0.0; 3]),
        &Vector3::new(1.2, 0.0, 0.0),
        1e-15,
        "planar",
    );
    let e = planar.ik(&Vector3::new(0.5, 0.5, 0.0)).unwrap_err();
    assert!(matches!(e, Error::InvalidParameter { .. }), "{e}");
    assert!(e.to_string().contains("closed-form IK"), "{e}");
    let mut a1 = RigidArm::table2();
    a1.a[0] = 0.1;
    assert!(matches!(
        a1.in_workspace(&Vector3::new(0.5, 0.5, 0.0)),
        Err(Error::InvalidParameter { .. })
    ));
}
