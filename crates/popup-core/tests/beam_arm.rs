//! Beam links in the arm (`higher_bending_modes.elements`): Euler–Bernoulli elements coupled
//! to the joint chain in the floating frame of the link's root body (docs/beams.md).
//!
//! - static tip deflection and rotation of a beam link under its payload equal
//!   P L³/(3EI), P L²/(2EI) (and + P L/(κGA + pπr²) with shear) in the arm, gravity on;
//! - the arm's locked-motor modes of a beam link converge to the Euler–Bernoulli tip-mass
//!   cantilever (classical frequency equation), first and second mode per plane;
//! - energy is conserved with damping off (RK4), and Rayleigh damping dissipates;
//! - channels: d21/d22 are the tip rotations, m21/m22 the root moments (static: P g L);
//! - mixed arms (PRBM + beam, beam + beam, beam + torsion), replay and torque drive run;
//!   batched = one by one, 1 vs 2 threads bit for bit;
//! - bad element counts, segments with elements, too many joints, bad sections are refused
//!   by name.

use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::kinematics::prbm::frames;
use popup_core::math::{Vec3, VecN};
use popup_core::model::{Disable, Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::rollout::{rollout, Job};
use popup_core::sensor::{channel_index, NCH};
use popup_core::sim::{rest_state, run, RunConfig, State};
use popup_core::spec::ArmSpec;
use popup_core::statics::locked_modes;

mod common;

fn structure(elements: [usize; 2]) -> Structure {
    Structure { elements, ..Structure::default() }
}

fn compile(spec: &ArmSpec, elements: [usize; 2], opts: Options) -> Model {
    Model::compile(spec, Options { structure: structure(elements), ..opts }).unwrap()
}

/// popup-lab with link 1 made (nearly) rigid, so link 2 is clamped at its motor.
fn stiff_link1() -> ArmSpec {
    let mut s = ArmSpec::popup_lab();
    s.links[0].stiffness_scale = Some(1e7);
    s
}

fn params(model: &Model, payload: f64) -> Params {
    let mut p = Params::defaults(model);
    p.payload_kg = payload;
    p.pressure_pa = [30e3, 30e3];
    p
}

/// EI of link l's beam with the model's material [N·m²].
fn ei(model: &Model, p: &Params, l: usize) -> f64 {
    let m = p.effects.higher_bending_modes.material(l);
    m.e * std::f64::consts::PI * model.link_radius[l].powi(3) * m.t
}

/// Nodal (v, w, θy, θz) of link l's tip node in its link frame at q.
fn tip_nodal(model: &Model, l: usize, q: &VecN) -> [f64; 4] {
    let bl = model.beam[l].as_ref().unwrap();
    let phi = nalgebra::DVector::from_fn(bl.dof(), |i, _| q[bl.start + i]);
    let eta = &bl.t_map * phi;
    let o = bl.dof() - 4;
    [eta[o], eta[o + 1], eta[o + 2], eta[o + 3]]
}

/// Gravity in link l's frame B at q = 0 (B = the tip frame's axes).
fn gravity_in_b(model: &Model, l: usize) -> Vec3 {
    let bl = model.beam[l].as_ref().unwrap();
    let f = frames(model, &VecN::zeros());
    f.r_wb[bl.start + bl.dof()].transpose() * model.gravity
}

#[test]
fn static_tip_deflection_is_pl3_over_3ei() {
    for shear in [false, true] {
        let mut spec = stiff_link1();
        // a massless tube: the payload is the only load on link 2
        spec.bodies[6].parts[0].mass_kg = 1e-9;
        for n in [1, 2, 4] {
            let model = compile(&spec, [0, n], Options::default());
            let mut p = params(&model, 2.0);
            p.effects.higher_bending_modes.shear[1] = if shear { 1.0 } else { 0.0 };
            let pd = ParamData::new(&model, &p).unwrap();
            let q = rest_state(&model, &pd, 0.0, [0.0; 3]).unwrap().q;
            let [v, w, thy, thz] = tip_nodal(&model, 1, &q);
            let g = gravity_in_b(&model, 1);
            let (fy, fz) = (2.0 * g.y, 2.0 * g.z);
            let ei = ei(&model, &p, 1);
            let l = model.beam[1].as_ref().unwrap().length;
            let sec = model.beam[1].as_ref().unwrap().section(&p.effects.higher_bending_modes.material(1), 30e3);
            let shear_c = if shear { l / sec.shear_stiffness() } else { 0.0 };
            let c = l.powi(3) / (3.0 * ei) + shear_c;
            let r = l * l / (2.0 * ei);
            let (ev, ew) = (fy * c, fz * c);
            let (ethz, ethy) = (fy * r, -fz * r);
            let scale = ev.abs().max(ew.abs());
            assert!(scale > 1e-4, "the payload must bend link 2 ({scale} m)");
            for (got, want, what) in [(v, ev, "v"), (w, ew, "w")] {
                assert!((got - want).abs() < 2e-3 * scale, "n = {n}, shear {shear}: tip {what} = {got:e} m, expected {want:e} m");
            }
            let rs = ethz.abs().max(ethy.abs());
            for (got, want, what) in [(thy, ethy, "θy"), (thz, ethz, "θz")] {
                assert!((got - want).abs() < 2e-3 * rs, "n = {n}, shear {shear}: tip {what} = {got:e} rad, expected {want:e} rad");
            }
        }
    }
}

/// The locked-motor modes of a beam link clamped at its motor (link 1 made rigid, gravity
/// off) converge to the Euler–Bernoulli tip-mass cantilever's first two frequencies as the
/// element count grows, at second order (the chord-bar mass; docs/beams.md), one per plane.
#[test]
fn locked_modes_of_a_beam_link_converge_to_the_tip_mass_cantilever() {
    let spec = stiff_link1();
    let mut errs = Vec::new();
    for n in [1, 2, 4, 6] {
        let model = compile(&spec, [0, n], Options { gravity: Some([0.0; 3]), ..Options::default() });
        let p = params(&model, 2.0);
        let pd = ParamData::new(&model, &p).unwrap();
        let modes = locked_modes(&model, &pd, &VecN::zeros());
        assert_eq!(modes.len(), 4 * n + 2, "one mode per beam joint plus link 1's two");
        let bl = model.beam[1].as_ref().unwrap();
        let (l, rho_a) = (bl.length, bl.mass_per_length);
        let roots = common::tip_mass_roots(2.0 / (rho_a * l), 2);
        let c = (ei(&model, &p, 1) / rho_a).sqrt() / (l * l);
        let exact: Vec<f64> = roots.iter().map(|b| b * b * c).collect();
        // both planes: modes come in pairs
        let e1 = ((modes[0] - exact[0]) / exact[0]).abs().max(((modes[1] - exact[0]) / exact[0]).abs());
        let e2 = if n > 1 { ((modes[2] - exact[1]) / exact[1]).abs().max(((modes[3] - exact[1]) / exact[1]).abs()) } else { f64::NAN };
        eprintln!("n = {n}: ω1 {:.3} {:.3} (EB {:.3}), ω2 {:.3} (EB {:.3}); errors {e1:.2e} {e2:.2e}", modes[0], modes[1], exact[0], modes[2], exact[1]);
        errs.push((n, e1, e2));
    }
    // the first mode is within 1 % from 2 elements on; the second within 3 % at 6
    let at = |n: usize| errs.iter().find(|e| e.0 == n).unwrap();
    assert!(at(2).1 < 1e-2 && at(6).1 < 2e-3, "{errs:?}");
    assert!(at(6).2 < 3e-2, "{errs:?}");
    // and the second-mode error falls with n (roughly second order: 4 → 6 elements)
    assert!(at(6).2 < at(4).2 && at(4).2 < at(2).2, "{errs:?}");
}

fn zero_torque(duration: f64) -> Drive {
    Drive::Torque(Linear3::new(&[0.0, duration], &[[0.0; 3], [0.0; 3]]).unwrap())
}

#[test]
fn energy_is_conserved_without_damping_and_falls_with_rayleigh_damping() {
    let spec = ArmSpec::popup_lab();
    let dt = 2e-5;
    let model = compile(&spec, [0, 2], Options { dt, disable: Disable { damper: true, ..Disable::default() }, ..Options::default() });
    let mut p = params(&model, 1.0);
    p.effects.higher_bending_modes.lambda_s = [0.0; 2];
    let pd = ParamData::new(&model, &p).unwrap();
    // released from rest with the beam undeflected: the arm falls and the beam rings
    let cfg = RunConfig { drive: zero_torque(0.3), initial: Some(State { t: 0.0, q: VecN::zeros(), v: VecN::zeros() }), duration: Some(0.3), sample_period: 1e-3, check_step: true };
    let tr = run(&model, &pd, &cfg).unwrap();
    let e = channel_index("energy").unwrap();
    let e0 = tr.data[e];
    let mut worst: f64 = 0.0;
    for r in 0..tr.nsample {
        worst = worst.max((tr.data[r * NCH + e] - e0).abs());
    }
    // the motion is large (the arm falls ~0.5 rad): kinetic energy of several joules
    let ke_scale = 10.0;
    assert!(worst < 1e-7 * ke_scale, "energy drift {worst} J");
    // with Rayleigh damping (and dampers on) energy only falls
    let model = compile(&spec, [0, 2], Options { dt, ..Options::default() });
    let pd = ParamData::new(&model, &params(&model, 1.0)).unwrap();
    let tr = run(&model, &pd, &cfg).unwrap();
    let mut prev = tr.data[e];
    for r in 1..tr.nsample {
        let x = tr.data[r * NCH + e];
        assert!(x <= prev + 1e-9, "energy rose at sample {r}: {prev} → {x}");
        prev = x;
    }
}

#[test]
fn channels_are_tip_rotations_and_root_moments() {
    let mut spec = ArmSpec::popup_lab();
    spec.links[0].stiffness_scale = Some(1e3);
    let model = compile(&spec, [0, 3], Options { dt: 1e-5, ..Options::default() });
    let p = params(&model, 2.0);
    let pd = ParamData::new(&model, &p).unwrap();
    let rest = rest_state(&model, &pd, 0.0, [0.0; 3]).unwrap();
    let cfg = RunConfig { drive: hold_drive(&model, &pd), initial: Some(rest), duration: Some(1e-3), sample_period: 1e-3, check_step: true };
    let tr = run(&model, &pd, &cfg).unwrap();
    let row = &tr.data[..NCH];
    let [_, _, thy, thz] = tip_nodal(&model, 1, &rest.q);
    let (d21, d22) = (row[channel_index("d21").unwrap()], row[channel_index("d22").unwrap()]);
    let mut got = [d21.abs(), d22.abs()];
    let mut want = [thy.abs(), thz.abs()];
    got.sort_by(|a, b| a.partial_cmp(b).unwrap());
    want.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert!((got[1] - want[1]).abs() < 1e-9 * want[1], "tip rotation {got:?} vs {want:?}");
    // root moment = moment of the payload's and the tube's weight about the root (gravity
    // across the link at rest)
    let g = gravity_in_b(&model, 1);
    let bl = model.beam[1].as_ref().unwrap();
    let (l, mt) = (bl.length, bl.mass_per_length * bl.length);
    let m_expect = (g.y * g.y + g.z * g.z).sqrt() * (2.0 * l + mt * l / 2.0);
    let m = row[channel_index("m21").unwrap()].hypot(row[channel_index("m22").unwrap()]);
    assert!((m - m_expect).abs() < 2e-3 * m_expect, "root moment {m} N·m, expected {m_expect} N·m");
    let ratio = row[channel_index("m2_ratio").unwrap()];
    assert!((ratio - m / pd.mw[1]).abs() < 1e-12 * ratio);
}

/// A torque drive holding the arm at rest (the holding torques of the motors).
fn hold_drive(model: &Model, pd: &ParamData) -> Drive {
    let q = rest_state(model, pd, 0.0, [0.0; 3]).unwrap().q;
    let g = popup_core::statics::gravity_torque(model, pd, &q);
    let tau: [f64; 3] = std::array::from_fn(|k| g[model.motor_idx[k]]);
    Drive::Hold(tau)
}

fn replay(duration: f64) -> Drive {
    let n = 201;
    let t: Vec<f64> = (0..n).map(|i| duration * i as f64 / (n - 1) as f64).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [0.3 * (2.0 * t).sin(), 0.2 * (3.0 * t).sin(), -0.3 * (2.5 * t).sin()]).collect();
    Drive::Replay(Spline3::new(&t, &y).unwrap())
}

#[test]
fn mixed_arms_run_in_replay_and_torque_drive() {
    let spec = ArmSpec::popup_lab();
    for (elements, torsion) in [([2, 0], [false, false]), ([0, 3], [false, false]), ([2, 2], [false, false]), ([1, 2], [true, true])] {
        let model = Model::compile(&spec, Options { dt: 5e-5, structure: Structure { elements, torsion, ..Structure::default() }, ..Options::default() }).unwrap();
        let mut p = params(&model, 1.0);
        for l in 0..2 {
            if torsion[l] {
                p.effects.torsion.k_t[l] = 2000.0;
                p.effects.torsion.c_t[l] = 0.5;
            }
        }
        let pd = ParamData::new(&model, &p).unwrap();
        for drive in [replay(0.2), hold_drive(&model, &pd)] {
            let cfg = RunConfig { drive, initial: None, duration: Some(0.2), sample_period: 1e-3, check_step: true };
            let tr = run(&model, &pd, &cfg).unwrap_or_else(|e| panic!("{elements:?} {torsion:?}: {e}"));
            assert!(tr.data.iter().all(|x| x.is_finite()), "{elements:?}: non-finite channel");
            // bending channels of a beam link move
            let d = channel_index("dd21").unwrap();
            assert!(tr.data.chunks(NCH).any(|r| r[d] != 0.0));
        }
    }
}

#[test]
fn beam_rollouts_are_deterministic_batched_and_threaded() {
    let spec = ArmSpec::popup_lab();
    let model = compile(&spec, [1, 2], Options { dt: 5e-5, ..Options::default() });
    let jobs: Vec<Job> = (0..4)
        .map(|i| {
            let mut p = params(&model, 0.5 * i as f64);
            p.effects.higher_bending_modes.e_pa[1] = 0.4e9 + 0.1e9 * i as f64;
            Job { params: p, run: RunConfig { drive: replay(0.1), initial: None, duration: Some(0.1), sample_period: 1e-3, check_step: true } }
        })
        .collect();
    let a = rollout(&model, &jobs, 1);
    let b = rollout(&model, &jobs, 2);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        let (x, y) = (x.as_ref().unwrap(), y.as_ref().unwrap());
        assert!(x.data.iter().zip(&y.data).all(|(p, q)| p.to_bits() == q.to_bits()), "job {i}: 1 vs 2 threads differ");
        let single = rollout(&model, &jobs[i..=i], 1);
        let s = single[0].as_ref().unwrap();
        assert!(s.data.iter().zip(&x.data).all(|(p, q)| p.to_bits() == q.to_bits()), "job {i}: batched vs alone differ");
    }
    // E matters
    assert!(a[0].as_ref().unwrap().data != a[1].as_ref().unwrap().data);
}

#[test]
fn bad_beam_settings_are_refused_by_name() {
    let spec = ArmSpec::popup_lab();
    let err = |s: Structure| Model::compile(&spec, Options { structure: s, ..Options::default() }).unwrap_err().to_string();
    let e = err(structure([0, 7]));
    assert!(e.contains("elements[1]") && e.contains("0..=6"), "{e}");
    let e = err(Structure { segments: [2, 1], elements: [1, 0], ..Structure::default() });
    assert!(e.contains("segments[0]") && e.contains("beam link"), "{e}");
    let e = err(structure([6, 6]));
    assert!(e.contains("more than the 31"), "{e}");
    let model = compile(&spec, [0, 2], Options::default());
    let mut p = params(&model, 1.0);
    p.effects.higher_bending_modes.wall_m[1] = 0.06;
    let e = ParamData::new(&model, &p).unwrap_err().to_string();
    assert!(e.contains("effects.higher_bending_modes.wall_m[1]"), "{e}");
    p.effects.higher_bending_modes.wall_m[1] = 1.2e-3;
    p.effects.higher_bending_modes.e_pa[1] = f64::NAN;
    let e = ParamData::new(&model, &p).unwrap_err().to_string();
    assert!(e.contains("e_pa[1]"), "{e}");
}
