//! Independent rigid-arm checks against hand-derived mechanics.
//!
//! 1. Double pendulum: with the bending angles and rates zero and q̇1 = q̈1 = 0, the arm is
//!    a planar two-link pendulum (joints q2, q3) whose link masses and inertias follow
//!    from the spec's numbers by hand (tubes, elbow motoreducer, payload). The 2×2 block of
//!    CRBA's M and the q2/q3 rows of RNEA must equal the textbook closed form
//!      M11 = I1 + I2 + m2 L1² + 2 m2 L1 c2 cos θ2,  M12 = I2 + m2 L1 c2 cos θ2,  M22 = I2,
//!      h1 = −m2 L1 c2 sin θ2 (2 θ̇1 θ̇2 + θ̇2²),     h2 = m2 L1 c2 sin θ2 θ̇1²,
//!      G1 = g ((m1 c1 + m2 L1) cos θ1 + m2 c2 cos θ12), G2 = g m2 c2 cos θ12,
//!    with I1, I2 about the joint axes and c1, c2 the centre-of-mass distances along the links.
//! 2. Simple pendulum: a point payload moved onto body 2 (rigid with q2) at distance L from
//!    the q2 axis, every other body a massless rotor (inertia only), springs and dampers
//!    off, q2 without armature, zero torques: the simulated period of q2 must be the exact
//!    pendulum period 2π √(L/g) / AGM(1, cos(θ0/2)) (→ 2π √(L/g) for small θ0).

mod common;

use common::{col, constant_torque, Rng};
use popup_core::dynamics::{crba, rnea};
use popup_core::math::VecN;
use popup_core::model::{Disable, Model, Options};
use popup_core::params::{Flex, ParamData, Params};
use popup_core::sim::{run, RunConfig, State};
use popup_core::spec::arm::{PartShape, PartSpec};
use popup_core::spec::ArmSpec;
use std::f64::consts::{FRAC_PI_2, PI};

/// Hand-derived link data: (mass, com distance from the joint axis, inertia about the axis).
fn link(parts: &[(f64, f64, f64)]) -> (f64, f64, f64) {
    // parts: (mass, distance of its centre from the joint axis, central inertia about an axis ∥ joint)
    let m: f64 = parts.iter().map(|p| p.0).sum();
    let c = parts.iter().map(|p| p.0 * p.1).sum::<f64>() / m;
    let i = parts.iter().map(|p| p.2 + p.0 * p.1 * p.1).sum();
    (m, c, i)
}

fn tube_perp(m: f64, r: f64, l: f64) -> f64 {
    m * (r * r / 2.0 + l * l / 12.0)
}

#[test]
fn double_pendulum_block_matches_closed_form() {
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let g = 9.81;
    let (r1, r2, l1) = (0.085, 0.055, 0.6);
    let mut rng = Rng(77);
    let mut worst: f64 = 0.0;
    for n in 0..40 {
        let payload = rng.uniform(0.0, 4.0);
        let pd = ParamData::new(&model, &Params { payload_kg: payload, pressure_pa: [30e3, 30e3], flex: Flex::default() }).unwrap();
        // numbers from reference-arm.md, combined by hand
        let (m1, c1, i1) = link(&[
            (0.03, 0.015, tube_perp(0.03, r1, 0.03)),
            (0.57, 0.03 + 0.285, tube_perp(0.57, r1, 0.57)),
            (1.5, 0.6, 0.003),
        ]);
        let (m2, c2, i2) = link(&[(0.02, 0.015, tube_perp(0.02, r2, 0.03)), (0.38, 0.03 + 0.285, tube_perp(0.38, r2, 0.57)), (payload, 0.6, 0.0)]);
        let (t1, t2) = (rng.uniform(-PI, PI), rng.uniform(-PI, PI));
        let (w1, w2) = (rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0));
        let (a1, a2) = (rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0));
        let q1 = rng.uniform(-PI, PI); // base yaw: turns the vertical plane, changes nothing
        let mut q = VecN::zeros();
        let mut v = VecN::zeros();
        let mut qdd = VecN::zeros();
        let [i_q1, i_q2, i_q3] = model.motor_idx;
        q[i_q1] = q1;
        q[i_q2] = t1;
        q[i_q3] = t2;
        v[i_q2] = w1;
        v[i_q3] = w2;
        qdd[i_q2] = a1;
        qdd[i_q3] = a2;
        let rot = model.rotations(&q);
        let m = crba(&model, &pd.body, &rot);
        let (c2t, s2t) = (t2.cos(), t2.sin());
        let m11 = i1 + i2 + m2 * l1 * l1 + 2.0 * m2 * l1 * c2 * c2t;
        let m12 = i2 + m2 * l1 * c2 * c2t;
        let m22 = i2;
        let scale = m11.abs();
        for (got, want, what) in [(m[(i_q2, i_q2)], m11, "M11"), (m[(i_q2, i_q3)], m12, "M12"), (m[(i_q3, i_q2)], m12, "M21"), (m[(i_q3, i_q3)], m22, "M22")] {
            let d = (got - want).abs() / scale;
            worst = worst.max(d);
            assert!(d < 1e-12, "case {n}: {what} = {got} vs closed form {want}");
        }
        let h1 = -m2 * l1 * c2 * s2t * (2.0 * w1 * w2 + w2 * w2);
        let h2 = m2 * l1 * c2 * s2t * w1 * w1;
        let g1 = g * ((m1 * c1 + m2 * l1) * t1.cos() + m2 * c2 * (t1 + t2).cos());
        let g2 = g * m2 * c2 * (t1 + t2).cos();
        let tau1 = m11 * a1 + m12 * a2 + h1 + g1;
        let tau2 = m12 * a1 + m22 * a2 + h2 + g2;
        let tau = rnea(&model, &pd.body, &rot, &v, &qdd, &model.gravity);
        let ts = tau1.abs().max(tau2.abs());
        for (got, want, what) in [(tau[i_q2], tau1, "tau(q2)"), (tau[i_q3], tau2, "tau(q3)")] {
            let d = (got - want).abs() / ts;
            worst = worst.max(d);
            assert!(d < 1e-12, "case {n}: RNEA {what} = {got} vs closed form {want}");
        }
        // planar motion in a vertical plane through the yaw axis: no yaw torque
        assert!(tau[i_q1].abs() < 1e-12 * ts, "case {n}: yaw torque {} for a planar motion", tau[i_q1]);
    }
    println!("double pendulum: worst relative difference to the closed form {worst:.2e}");
}

/// Complete elliptic integral route: T = 2π √(L/g) / AGM(1, cos(θ0/2)).
fn exact_period(l: f64, g: f64, theta0: f64) -> f64 {
    let (mut a, mut b) = (1.0f64, (theta0 / 2.0).cos());
    for _ in 0..40 {
        let (an, bn) = ((a + b) / 2.0, (a * b).sqrt());
        a = an;
        b = bn;
    }
    2.0 * PI * (l / g).sqrt() / a
}

fn pendulum_spec(l: f64) -> ArmSpec {
    let mut spec = ArmSpec::popup_lab();
    let rotor = |name: &str| PartSpec {
        name: name.into(),
        shape: PartShape::Point,
        mass_kg: 0.0,
        com_m: [0.0; 3],
        length_m: 0.0,
        radius_m: None,
        inertia_kgm2: [1e-3, 1e-3, 1e-3, 0.0, 0.0, 0.0],
    };
    // body 1 (on the yaw axis) keeps the shoulder housing; body 2 carries only the payload
    spec.bodies[1].parts.clear();
    spec.bodies[2].parts.clear();
    spec.bodies[3].parts = vec![rotor("rotor 4")];
    spec.bodies[4].parts = vec![rotor("rotor 5")];
    spec.bodies[5].parts.clear();
    spec.bodies[6].parts = vec![rotor("rotor 7")];
    spec.payload.body = 2;
    spec.payload.com_m = [l - spec.joints[1].a, 0.0, 0.0];
    spec.motors.armature_kgm2 = [0.05, 0.0, 0.05];
    spec
}

/// Times where `x` crosses zero (linear interpolation between samples).
fn zero_crossings(t: &[f64], x: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for i in 1..x.len() {
        if x[i - 1] != 0.0 && x[i - 1].signum() != x[i].signum() {
            out.push(t[i - 1] + (t[i] - t[i - 1]) * x[i - 1] / (x[i - 1] - x[i]));
        }
    }
    out
}

#[test]
fn simple_pendulum_period() {
    let (l, g) = (1.0, 9.81);
    let spec = pendulum_spec(l);
    let opts = Options { dt: 1e-3, disable: Disable { spring: true, damper: true, gravity: false }, ..Options::default() };
    let model = Model::compile(&spec, opts).unwrap();
    let pd = ParamData::new(&model, &Params { payload_kg: 3.7, pressure_pa: [30e3, 30e3], flex: Flex::default() }).unwrap();
    let iq2 = model.motor_idx[1];
    for theta0 in [0.01, 0.5, 1.5] {
        let mut q = VecN::zeros();
        q[iq2] = -FRAC_PI_2 + theta0;
        let cfg = RunConfig {
            drive: constant_torque([0.0; 3]),
            initial: Some(State { t: 0.0, q, v: VecN::zeros() }),
            duration: Some(7.0),
            sample_period: 1e-3,
            check_step: true,
        };
        let tr = run(&model, &pd, &cfg).unwrap();
        let t = col(&tr, "t");
        let th: Vec<f64> = col(&tr, "q2").iter().map(|x| x + FRAC_PI_2).collect();
        let zc = zero_crossings(&t, &th);
        assert!(zc.len() >= 5, "θ0 = {theta0}: only {} zero crossings", zc.len());
        let period = 2.0 * (zc[zc.len() - 1] - zc[0]) / (zc.len() - 1) as f64;
        let small = 2.0 * PI * (l / g).sqrt();
        let exact = exact_period(l, g, theta0);
        let rel = (period - exact).abs() / exact;
        println!("θ0 = {theta0}: period {period:.9} s, exact {exact:.9} s (small-angle {small:.9} s), rel error {rel:.2e}");
        assert!(rel < 1e-8, "θ0 = {theta0}: simulated period {period} vs exact {exact} (rel {rel:e})");
        if theta0 < 0.02 {
            assert!((period - small).abs() / small < 2e-5, "small-amplitude period {period} vs 2π√(L/g) = {small}");
        }
        // amplitude kept (no damping, RK4) and the rest of the chain stays planar (the
        // out-of-plane rotors are neutrally stable: round-off grows to ~4e-8 rad at θ0 = 1.5)
        let amp = th.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        assert!((amp - theta0).abs() < 1e-6 * theta0.max(0.1), "amplitude {amp} vs {theta0}");
        let q1max = col(&tr, "q1").iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let d11max = col(&tr, "d11").iter().chain(col(&tr, "d21").iter()).fold(0.0f64, |a, x| a.max(x.abs()));
        assert!(q1max < 1e-6 && d11max < 1e-6, "out-of-plane motion: q1 {q1max}, d11/d21 {d11max}");
    }
}
