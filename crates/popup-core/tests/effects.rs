//! The effect library: neutral values are bit-identical to the nominal model, every
//! parameter moves the outputs, and each term obeys its physical definition.

mod common;

use common::col;
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::effects::{friction_torque, Effects, NE, NPARAM, PARAMS};
use popup_core::model::{Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sim::{run, RunConfig, Trajectory};
use popup_core::spec::ArmSpec;
use std::f64::consts::{FRAC_PI_2, PI};

fn model() -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap()
}

/// 2 s of encoder samples at 500 Hz: a move of every joint with a velocity reversal.
fn encoder() -> (Vec<f64>, Vec<[f64; 3]>) {
    let t: Vec<f64> = (0..=1000).map(|k| k as f64 * 2e-3).collect();
    let y = t
        .iter()
        .map(|&t| {
            let s = (2.0 * PI * 0.5 * t).sin();
            [0.4 * s, -FRAC_PI_2 + 0.5 + 0.3 * s, 0.3 - 0.4 * s]
        })
        .collect();
    (t, y)
}

fn replay(fx: Effects) -> Trajectory {
    let m = model();
    let pd = ParamData::new(&m, &Params { payload_kg: 1.0, pressure_pa: [30e3, 30e3], effects: fx }).unwrap();
    let (t, y) = encoder();
    let cfg = RunConfig { drive: Drive::Replay(Spline3::new(&t, &y).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true };
    run(&m, &pd, &cfg).unwrap()
}

fn torque_run(fx: Effects, tau: [f64; 3], duration: f64) -> Trajectory {
    let m = model();
    let pd = ParamData::new(&m, &Params { payload_kg: 1.0, pressure_pa: [30e3, 30e3], effects: fx }).unwrap();
    let drive = Drive::Torque(Linear3::new(&[0.0], &[tau]).unwrap());
    let cfg = RunConfig { drive, initial: None, duration: Some(duration), sample_period: 2e-3, check_step: true };
    run(&m, &pd, &cfg).unwrap()
}

fn bits(tr: &Trajectory) -> Vec<u64> {
    tr.data.iter().map(|x| x.to_bits()).collect()
}

fn maxdiff(a: &Trajectory, b: &Trajectory) -> f64 {
    a.data.iter().zip(&b.data).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn flat_vector_round_trips_and_bounds_are_enforced() {
    let mut v = Effects::default().to_flat();
    assert_eq!(v.len(), NE);
    v[0] = 0.7;
    let e = Effects::from_flat(&v).unwrap();
    assert_eq!(e.joint_friction.tau_c[0], 0.7);
    assert_eq!(e.to_flat().map(f64::to_bits), v.map(f64::to_bits));
    // every out-of-bounds or NaN value names its key
    let mut off = 0;
    for ps in PARAMS.iter().take(NPARAM) {
        let mut w = Effects::default().to_flat();
        w[off] = f64::NAN;
        let msg = Effects::from_flat(&w).unwrap_err().to_string();
        assert!(msg.contains(&format!("effects.{}.{}", ps.effect, ps.name)), "{msg}");
        off += ps.len;
    }
    let mut w = Effects::default().to_flat();
    let seg = PARAMS.iter().position(|p| (p.effect, p.name) == ("higher_bending_modes", "segments")).unwrap();
    w[popup_core::effects::offset(seg)] = 1.5; // higher_bending_modes.segments[0]
    assert!(Effects::from_flat(&w).unwrap_err().to_string().contains("whole number"));
}

#[test]
fn neutral_values_are_bit_identical_to_nominal() {
    let nominal_r = bits(&replay(Effects::default()));
    let nominal_t = bits(&torque_run(Effects::default(), [0.0, 30.0, 5.0], 0.5));
    // every effect at its neutral values, set explicitly, plus shaping parameters that
    // must not matter while the effect's strength is neutral
    let mut fx = Effects::from_flat(&Effects::default().to_flat()).unwrap();
    fx.joint_friction.v_s = [0.3, 0.2, 0.1];
    fx.torsion.c_t = [0.0, 0.0];
    fx.higher_bending_modes.k_scale = [1.0, 1.0];
    fx.backlash.inertia = [0.5, 0.2, 0.1];
    fx.backlash.restitution = [0.3; 3];
    for name in popup_core::effects::EFFECT_NAMES {
        assert!(fx.is_neutral(name), "{name}");
    }
    assert_eq!(bits(&replay(fx)), nominal_r);
    assert_eq!(bits(&torque_run(fx, [0.0, 30.0, 5.0], 0.5)), nominal_t);
}

/// Each continuous parameter, moved off neutral (with the others of its effect set so that
/// it matters), changes the outputs of a replay or a torque run.
#[test]
fn every_parameter_moves_the_outputs() {
    let nominal_r = replay(Effects::default());
    let nominal_t = torque_run(Effects::default(), [0.0, 30.0, 5.0], 0.5);
    let mut checked = 0;
    let mut off = 0;
    for ps in PARAMS.iter().take(NPARAM) {
        for j in 0..ps.len {
            let mut base = Effects::default();
            // make the shaping parameters matter
            match (ps.effect, ps.name) {
                ("joint_friction", "v_s") => base.joint_friction.tau_s = [1.0; 3],
                ("joint_friction", "v_eps") => base.joint_friction.tau_c = [1.0; 3],
                ("wrinkling", "mw_scale") => base.wrinkling.ratio = 0.3,
                ("backlash", "inertia" | "restitution" | "contact_k") => base.backlash.gap = [0.02; 3],
                ("backlash", "contact_c") => {
                    base.backlash.gap = [0.02; 3];
                    base.backlash.contact_k = [1e4; 3];
                }
                _ => {}
            }
            let mut v = base.to_flat();
            let x = match (ps.effect, ps.name) {
                ("actuator_saturation", "tau_max") => 2.0,
                ("wrinkling", "ratio") => 0.3,
                ("wrinkling", "mw_scale") => 0.5,
                ("joint_friction", "v_s") => 0.5,
                ("payload_mass", "delta_kg") => 0.5,
                ("payload_mass", "com_offset_m") => 0.05,
                ("backlash", "gap") => 0.02,
                ("backlash", "contact_k") => 1e4,
                ("pressure_leak", "rate") => 0.2,
                ("sensor_delay", _) => 0.013,
                ("air_drag", "cd") => 5.0,
                (_, _) => 0.5,
            };
            if ps.integer || ps.effect == "torsion" || ps.effect == "higher_bending_modes" {
                continue; // structural: tested with the variable-DOF chain
            }
            v[off + j] = x;
            let fx = Effects::from_flat(&v).unwrap();
            let base_r = if base == Effects::default() { nominal_r.clone() } else { replay(base) };
            let d = maxdiff(&replay(fx), &base_r);
            let moved_torque = if ps.effect == "backlash" {
                0.0
            } else {
                let base_t = if base == Effects::default() { nominal_t.clone() } else { torque_run(base, [0.0, 30.0, 5.0], 0.5) };
                maxdiff(&torque_run(fx, [0.0, 30.0, 5.0], 0.5), &base_t)
            };
            assert!(d > 1e-6 || moved_torque > 1e-6, "{}.{}[{j}] = {x} moves nothing (replay {d:e}, torque {moved_torque:e})", ps.effect, ps.name);
            checked += 1;
        }
        off += ps.len;
    }
    assert!(checked >= 30, "{checked}");
}

#[test]
fn friction_in_replay_adds_exactly_the_friction_torque() {
    let mut fx = Effects::default();
    fx.joint_friction.tau_c = [1.5, 2.0, 0.7];
    fx.joint_friction.b = [0.3, 0.2, 0.1];
    let a = replay(Effects::default());
    let b = replay(fx);
    for k in 0..3 {
        let dq = col(&a, &format!("dq{}", k + 1));
        let ta = col(&a, &format!("tau{}", k + 1));
        let tb = col(&b, &format!("tau{}", k + 1));
        for r in 0..a.nsample {
            let want = friction_torque(&fx.joint_friction, k, dq[r]);
            assert!((tb[r] - ta[r] - want).abs() < 1e-9, "joint {k} row {r}");
        }
    }
    // the physics of the free joints is untouched in replay
    for c in ["d11", "d22", "ee_z", "imu2_ax"] {
        assert_eq!(col(&a, c), col(&b, c), "{c}");
    }
}

#[test]
fn shaping_parameters_are_registered_and_neutral_while_their_effect_is() {
    use popup_core::effects::SHAPING;
    let a = replay(Effects::default());
    for (e, n) in SHAPING {
        let (i, ps) = PARAMS.iter().enumerate().find(|(_, p)| p.effect == e && p.name == n).unwrap_or_else(|| panic!("{e}.{n} not in the registry"));
        let off = popup_core::effects::offset(i);
        let mut v = Effects::default().to_flat();
        // a value inside the bounds, away from neutral
        v[off] = if ps.integer { ps.hi } else if ps.neutral != ps.lo { 0.5 * (ps.neutral + ps.lo.max(ps.neutral * 0.1)) } else { ps.lo + 0.1 * (ps.hi - ps.lo).min(1.0) };
        let fx = Effects::from_flat(&v).unwrap();
        assert!(fx.is_neutral(e), "{e}.{n} = {} makes {e} active", v[off]);
        if e != "higher_bending_modes" && e != "torsion" {
            assert_eq!(bits(&replay(fx)), bits(&a), "{e}.{n} = {} changed a nominal replay", v[off]);
        }
    }
}

#[test]
fn friction_sign_width_is_the_tanh_scale_and_neutral_without_friction() {
    // the law written out: (tau_c + tau_s e^{-(v/v_s)^2}) tanh(v/v_eps) + b v
    let mut fx = Effects::default();
    fx.joint_friction.tau_c = [1.5, 2.0, 0.7];
    fx.joint_friction.b = [0.3, 0.2, 0.1];
    fx.joint_friction.tau_s = [0.4, 0.0, 0.2];
    fx.joint_friction.v_s = [0.05, 0.05, 0.02];
    fx.joint_friction.v_eps = [0.003, 0.03, 0.1];
    let a = replay(Effects::default());
    let b = replay(fx);
    let f = fx.joint_friction;
    for k in 0..3 {
        let dq = col(&a, &format!("dq{}", k + 1));
        let ta = col(&a, &format!("tau{}", k + 1));
        let tb = col(&b, &format!("tau{}", k + 1));
        for r in 0..a.nsample {
            let v = dq[r];
            let want = (f.tau_c[k] + f.tau_s[k] * (-(v / f.v_s[k]).powi(2)).exp()) * (v / f.v_eps[k]).tanh() + f.b[k] * v;
            assert!((tb[r] - ta[r] - want).abs() < 1e-9, "joint {k} row {r}");
        }
    }
    // a sharper sign is closer to sign(v): at v = v_eps/2 of the default, the default gives
    // tanh(0.5) of the Coulomb torque, a 10 × sharper one almost all of it
    let mut sharp = Effects::default().joint_friction;
    sharp.tau_c = [1.0; 3];
    let mut soft = sharp;
    sharp.v_eps = [1e-3; 3];
    let v = 0.5 * popup_core::effects::FRICTION_V_EPS;
    assert!((friction_torque(&soft, 0, v) - 0.5f64.tanh()).abs() < 1e-12);
    assert!(friction_torque(&sharp, 0, v) > 0.9999);
    soft.v_eps = [popup_core::effects::FRICTION_V_EPS; 3];
    assert_eq!(soft, { let mut d = Effects::default().joint_friction; d.tau_c = [1.0; 3]; d });
    // without a friction torque the width changes nothing: neutral, bit for bit
    let mut w = Effects::default();
    w.joint_friction.v_eps = [0.002, 0.5, 0.05];
    assert!(w.is_neutral("joint_friction"));
    assert_eq!(bits(&replay(w)), bits(&a));
}

#[test]
fn friction_in_torque_drive_opposes_motion_and_dissipates() {
    // gravity off, a constant torque on q1: the steady speed is set by b (Coulomb + viscous)
    let m = Model::compile(&ArmSpec::popup_lab(), Options { gravity: Some([0.0; 3]), ..Options::default() }).unwrap();
    let mut fx = Effects::default();
    fx.joint_friction.tau_c = [1.0, 0.0, 0.0];
    fx.joint_friction.b = [2.0, 0.0, 0.0];
    let pd = ParamData::new(&m, &Params { payload_kg: 0.0, pressure_pa: [30e3, 30e3], effects: fx }).unwrap();
    let drive = Drive::Torque(Linear3::new(&[0.0], &[[5.0, 0.0, 0.0]]).unwrap());
    let cfg = RunConfig { drive, initial: None, duration: Some(20.0), sample_period: 1e-2, check_step: true };
    let tr = run(&m, &pd, &cfg).unwrap();
    let v = col(&tr, "dq1");
    let v_end = v[v.len() - 1];
    // steady state: 5 = 1·tanh(v/eps) + 2 v  →  v = 2 rad/s
    assert!((v_end - 2.0).abs() < 1e-3, "{v_end}");
}

#[test]
fn pressure_leak_follows_exponential_and_drops_stiffness() {
    let mut fx = Effects::default();
    fx.pressure_leak.rate = [0.1, 0.3];
    let tr = replay(fx);
    let t = col(&tr, "t");
    let p1 = col(&tr, "p1");
    let p2 = col(&tr, "p2");
    for r in 0..tr.nsample {
        assert!((p1[r] - 30e3 * (-0.1 * t[r]).exp()).abs() < 1e-9 * 30e3);
        assert!((p2[r] - 30e3 * (-0.3 * t[r]).exp()).abs() < 1e-9 * 30e3);
    }
    // lower pressure → softer link → the sag at the end is larger than nominal
    let nominal = replay(Effects::default());
    let sag = |tr: &Trajectory| col(tr, "d12").iter().rev().take(50).map(|x| x.abs()).sum::<f64>();
    assert!(sag(&tr) > sag(&nominal) * 1.01, "{} vs {}", sag(&tr), sag(&nominal));
}

#[test]
fn wrinkled_spring_is_bilinear_and_continuous() {
    use popup_core::effects::{wrinkled_energy, wrinkled_spring};
    let (k, mw, r) = (400.0, 20.0, 0.25);
    // below onset: linear
    let (m1, m2) = wrinkled_spring(k, 0.03, 0.02, mw, r);
    assert_eq!((m1, m2), (k * 0.03, k * 0.02));
    // above: |M| = mw + r (k|δ| − mw), along δ
    let (d1, d2) = (0.09, -0.05);
    let (m1, m2) = wrinkled_spring(k, d1, d2, mw, r);
    let s = k * (d1 * d1 + d2 * d2).sqrt();
    let want = mw + r * (s - mw);
    assert!(((m1 * m1 + m2 * m2).sqrt() - want).abs() < 1e-12);
    assert!((m1 / m2 - d1 / d2).abs() < 1e-12);
    // energy is the integral of the moment: dE/dδ = M (finite differences)
    let h = 1e-7;
    let de1 = (wrinkled_energy(k, d1 + h, d2, mw, r) - wrinkled_energy(k, d1 - h, d2, mw, r)) / (2.0 * h);
    assert!((de1 - m1).abs() < 1e-5, "{de1} vs {m1}");
    // continuity at onset
    let dw = mw / k;
    let (a, _) = wrinkled_spring(k, dw * (1.0 + 1e-12), 0.0, mw, r);
    assert!((a - mw).abs() < 1e-8);
}

#[test]
fn wrinkling_softens_only_above_the_onset_moment() {
    // with the onset far above the loads nothing changes; with it below, the sag grows
    let mut high = Effects::default();
    high.wrinkling.ratio = 0.3;
    high.wrinkling.mw_scale = 10.0;
    let mut base_high = Effects::default();
    base_high.wrinkling.mw_scale = 10.0;
    assert!(maxdiff(&replay(high), &replay(base_high)) < 1e-12);
    let mut low = Effects::default();
    low.wrinkling.ratio = 0.3;
    low.wrinkling.mw_scale = 0.2;
    let mut base_low = Effects::default();
    base_low.wrinkling.mw_scale = 0.2;
    let a = replay(low);
    let b = replay(base_low);
    let mx = |tr: &Trajectory| col(tr, "d12").iter().map(|x| x.abs()).fold(0.0, f64::max);
    assert!(mx(&a) > 1.2 * mx(&b), "{} vs {}", mx(&a), mx(&b));
}

#[test]
fn payload_delta_equals_a_heavier_payload() {
    let m = model();
    let mut fx = Effects::default();
    fx.payload_mass.delta_kg = 0.75;
    let (t, y) = encoder();
    let cfg = RunConfig { drive: Drive::Replay(Spline3::new(&t, &y).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true };
    let a = run(&m, &ParamData::new(&m, &Params { payload_kg: 1.0, pressure_pa: [30e3; 2], effects: fx }).unwrap(), &cfg).unwrap();
    let b = run(&m, &ParamData::new(&m, &Params { payload_kg: 1.75, pressure_pa: [30e3; 2], effects: Effects::default() }).unwrap(), &cfg).unwrap();
    assert_eq!(bits(&a), bits(&b));
    fx.payload_mass.delta_kg = -1.5;
    let err = ParamData::new(&m, &Params { payload_kg: 1.0, pressure_pa: [30e3; 2], effects: fx }).unwrap_err().to_string();
    assert!(err.contains("effects.payload_mass.delta_kg") && err.contains("negative payload"), "{err}");
}

#[test]
fn sensor_delay_shifts_exactly_by_whole_samples() {
    let nominal = replay(Effects::default());
    let mut fx = Effects::default();
    fx.sensor_delay.imu = 0.010; // 5 samples at 500 Hz
    fx.sensor_delay.torque = 0.004;
    let d = replay(fx);
    for (c, s) in [("imu2_az", 5usize), ("imu1_ax", 5), ("tau2", 2)] {
        let a = col(&nominal, c);
        let b = col(&d, c);
        for r in s + 2..a.len() {
            assert!((b[r] - a[r - s]).abs() <= 1e-12 * a[r - s].abs().max(1.0), "{c} row {r}");
        }
        assert_eq!(b[0], a[0]);
    }
    assert_eq!(col(&nominal, "ee_x"), col(&d, "ee_x"));
    // encoder delay: the physics leads the encoder; the q channels stay the encoder's
    let mut fe = Effects::default();
    fe.sensor_delay.encoder = 0.02;
    let e = replay(fe);
    assert_eq!(col(&nominal, "q2"), col(&e, "q2"));
    let (a, b) = (col(&nominal, "ee_z"), col(&e, "ee_z"));
    // ee_z of the delayed-encoder run at t equals nominal at t + 0.02 (10 samples), up to
    // the bending transient
    let err = (200..900).map(|r| (b[r] - a[r + 10]).abs()).fold(0.0, f64::max);
    let shift = (200..900).map(|r| (b[r] - a[r]).abs()).fold(0.0, f64::max);
    assert!(err < 0.2 * shift, "{err} vs {shift}");
}

#[test]
fn saturation_clips_the_measured_torque_in_replay_and_the_command_in_torque_drive() {
    let mut fx = Effects::default();
    fx.actuator_saturation.tau_max = [f64::INFINITY, 5.0, f64::INFINITY];
    let a = replay(Effects::default());
    let b = replay(fx);
    let (ta, tb) = (col(&a, "tau2"), col(&b, "tau2"));
    assert!(ta.iter().any(|x| x.abs() > 5.0));
    for (x, y) in ta.iter().zip(&tb) {
        assert_eq!(*y, x.clamp(-5.0, 5.0));
    }
    // torque drive: 30 N·m commanded, limited to 5: q2 falls as if 5 were commanded
    let c = torque_run(fx, [0.0, 30.0, 0.0], 0.3);
    let d = torque_run(Effects::default(), [0.0, 5.0, 0.0], 0.3);
    assert_eq!(col(&c, "q2"), col(&d, "q2"));
}

#[test]
fn air_drag_dissipates_and_scales_with_speed_squared() {
    use popup_core::effects::{drag_forces, drag_points};
    let m = model();
    let (pts, n) = drag_points(&m);
    assert_eq!(n, 12, "3 Gauss points on each of the 4 tube pieces");
    // total projected area = Σ 2 r l over the tubes
    let area: f64 = pts[..n].iter().map(|p| p.area).sum();
    let want = 2.0 * 0.085 * (0.03 + 0.57) + 2.0 * 0.055 * (0.03 + 0.57);
    assert!((area - want).abs() < 1e-12, "{area} vs {want}");
    let q = popup_core::math::VecN::from_fn(|i, _| 0.1 * i as f64);
    let v = popup_core::math::VecN::from_fn(|i, _| 0.5 - 0.13 * i as f64);
    let rot = m.rotations(&q);
    let f1 = drag_forces(&m, &pts[..n], 1.0, &rot, &v);
    let f2 = drag_forces(&m, &pts[..n], 1.0, &rot, &(v * 2.0));
    assert!((f2 - f1 * 4.0).norm() < 1e-12 * f1.norm().max(1e-300));
    assert!(f1.dot(&v) < 0.0, "drag power must be negative");
    assert!((drag_forces(&m, &pts[..n], 2.0, &rot, &v) - f1 * 2.0).norm() < 1e-12);
}

#[test]
fn structural_effects_in_the_arm_file_compile_the_extra_joints() {
    // torsion and segments in the arm file's [effects] give the model its extra joints
    let mut spec = ArmSpec::popup_lab();
    spec.effects.torsion.k_t = [50.0, f64::INFINITY];
    spec.effects.higher_bending_modes.segments = [1.0, 2.0];
    let m = Model::compile(&spec, Options::default()).unwrap();
    assert_eq!(m.nv, 7 + 1 + 2);
    assert!(m.torsion_idx[0].is_some() && m.torsion_idx[1].is_none());
    // the rollout's k_t must be finite where the joint exists
    let mut fx = spec.effects;
    fx.torsion.k_t[0] = f64::INFINITY;
    let e = ParamData::new(&m, &Params { payload_kg: 1.0, pressure_pa: [30e3; 2], effects: fx }).unwrap_err().to_string();
    assert!(e.contains("effects.torsion.k_t[0]") && e.contains("torsion joint"), "{e}");
    // and a contradictory Options.structure is refused
    let opts = Options { structure: popup_core::model::Structure { segments: [3, 1], torsion: [false; 2], elements: [0, 0] }, ..Options::default() };
    let e = Model::compile(&spec, opts).unwrap_err().to_string();
    assert!(e.contains("options.structure"), "{e}");
}
