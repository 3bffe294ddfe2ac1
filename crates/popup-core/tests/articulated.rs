//! The O(nv) articulated-body path (`dynamics::articulated`) against the CRBA + Cholesky
//! path at random states:
//!
//! - `accel_articulated` == `forward::accel` (h_implicit = 0) for the nominal 7-joint PRBM
//!   arm, a beam(4) link 2 and both links beam(3) (and PRBM segments / beam links with
//!   torsion joints), torque drive and replay, with the arm
//!   file's gravity and random gravity vectors, and with friction, saturation and air drag;
//! - with locked joints, == a CRBA reference whose locked rows and columns are replaced by
//!   q̈ = 0 (built here), in torque drive and in replay (motors prescribed as well).

mod common;

use common::Rng;
use nalgebra::DMatrix;
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::dynamics::articulated::{accel_articulated, accel_articulated_locked, articulated};
use popup_core::dynamics::{crba, rnea};
use popup_core::forward::{accel, passive, prescribe};
use popup_core::math::{Vec3, VecN};
use popup_core::model::{Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::spec::ArmSpec;

const TOL: f64 = 1e-10;

fn model(elements: [usize; 2], g: Option<[f64; 3]>) -> Model {
    model_of(Structure { elements, ..Structure::default() }, g)
}

fn model_of(structure: Structure, g: Option<[f64; 3]>) -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options { structure, gravity: g, ..Options::default() }).unwrap()
}

fn param_data(model: &Model, rng: &mut Rng, extra_effects: bool) -> ParamData {
    let mut p = Params::defaults(model);
    p.payload_kg = 2.0;
    p.pressure_pa = [rng.uniform(10e3, 90e3), rng.uniform(10e3, 90e3)];
    p.effects.torsion.k_t = [500.0, 200.0];
    p.effects.torsion.c_t = [0.1, 0.01];
    if extra_effects {
        let fx = &mut p.effects;
        fx.joint_friction.tau_c = [0.3, 0.5, 0.2];
        fx.joint_friction.b = [0.05, 0.1, 0.02];
        fx.joint_friction.tau_s = [0.2, 0.2, 0.1];
        fx.actuator_saturation.tau_max = [4.0, 6.0, 3.0];
        fx.air_drag.cd = 1.1;
    }
    ParamData::new(model, &p).unwrap()
}

/// Random joint state: motors over a full turn, link joints within ±0.3 rad.
fn state(model: &Model, rng: &mut Rng) -> (VecN, VecN) {
    let mut q = VecN::zeros();
    let mut v = VecN::zeros();
    for i in 0..model.nv {
        let motor = model.motor_idx.contains(&i);
        q[i] = if motor { rng.uniform(-3.2, 3.2) } else { rng.uniform(-0.3, 0.3) };
        v[i] = if motor { rng.uniform(-3.0, 3.0) } else { rng.uniform(-2.0, 2.0) };
    }
    (q, v)
}

fn torque_drive(rng: &mut Rng) -> Drive {
    let tm = [rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)];
    Drive::Torque(Linear3::new(&[0.0], &[tm]).unwrap())
}

fn replay_drive(rng: &mut Rng) -> Drive {
    let t: Vec<f64> = (0..8).map(|k| k as f64 * 0.1).collect();
    let y: Vec<[f64; 3]> = t.iter().map(|_| [rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0)]).collect();
    Drive::Replay(Spline3::new(&t, &y).unwrap())
}

fn amax(x: &VecN, n: usize) -> f64 {
    (0..n).map(|i| x[i].abs()).fold(0.0, f64::max)
}

fn rel(a: &VecN, b: &VecN, n: usize) -> f64 {
    amax(&(a - b), n) / amax(b, n).max(1e-300)
}

#[test]
fn articulated_equals_crba_cholesky() {
    let mut rng = Rng(0x5EED_0AB4_1234_5678);
    let mut worst: f64 = 0.0;
    let mut count = 0;
    // the three structures of the brief, then PRBM segments with torsion joints (rotations
    // about x) and a beam link with a torsion joint
    let structures = [
        Structure { elements: [0, 0], ..Structure::default() },
        Structure { elements: [0, 4], ..Structure::default() },
        Structure { elements: [3, 3], ..Structure::default() },
        Structure { segments: [3, 2], torsion: [true, true], elements: [0, 0] },
        Structure { segments: [1, 1], torsion: [false, true], elements: [2, 4] },
        // rigid links (their universal joints locked by the model itself)
        Structure { segments: [0, 1], torsion: [false, false], elements: [0, 4] },
        Structure { segments: [0, 0], torsion: [false, false], elements: [0, 0] },
    ];
    for st in structures {
        let elements = st.elements;
        for case in 0..24 {
            let g = if case % 3 == 0 { None } else { Some([rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)]) };
            let m = model_of(st, g);
            let pd = param_data(&m, &mut rng, case % 4 == 1);
            assert_eq!(m.structure, st);
            let drive = if case % 2 == 0 { torque_drive(&mut rng) } else { replay_drive(&mut rng) };
            let t = rng.uniform(0.0, 0.7);
            let (mut q, mut v) = state(&m, &mut rng);
            let am = prescribe(&m, &drive, t, &mut q, &mut v);
            let a_ref = accel(&m, &pd, &drive, t, &q, &v, am, 0.0);
            let a = accel_articulated(&m, &pd, &drive, t, &q, &v, am);
            let e = rel(&a, &a_ref, m.nv);
            worst = worst.max(e);
            count += 1;
            assert!(e < TOL, "elements {elements:?} case {case} (nv {}): articulated {a:?} vs CRBA {a_ref:?} (rel {e:e})", m.nv);
            for i in m.nv..a.len() {
                assert_eq!(a[i], 0.0);
            }
            for &i in m.locked() {
                assert_eq!(a[i], 0.0, "locked joint {i}");
            }
            if let Some(am) = am {
                for (k, &i) in m.motor_idx.iter().enumerate() {
                    assert_eq!(a[i], am[k], "replayed motor {k} must follow its acceleration exactly");
                }
            }
        }
    }
    println!("articulated vs forward::accel: worst relative difference {worst:.2e} over {count} cases");
}

/// Reference: `(M + diag(armature)) q̈ = τ − b` with the rows and columns of the fixed
/// joints (locked: q̈ = 0; prescribed: given) replaced, dense LU.
fn reference(m: &Model, pd: &ParamData, q: &VecN, v: &VecN, tau: &VecN, fixed: &[(usize, f64)]) -> VecN {
    let n = m.nv;
    let rot = m.rotations(q);
    let mm = crba(m, &pd.body, &rot);
    let b = rnea(m, &pd.body, &rot, v, &VecN::zeros(), &m.gravity);
    let mut a = DMatrix::from_fn(n, n, |i, j| mm[(i, j)] + if i == j { m.armature[i] } else { 0.0 });
    let mut rhs = nalgebra::DVector::from_fn(n, |i, _| tau[i] - b[i]);
    for &(p, x) in fixed {
        for f in 0..n {
            rhs[f] -= a[(f, p)] * x;
        }
    }
    for &(p, x) in fixed {
        for f in 0..n {
            a[(f, p)] = 0.0;
            a[(p, f)] = 0.0;
        }
        a[(p, p)] = 1.0;
        rhs[p] = x;
    }
    let x = a.lu().solve(&rhs).unwrap();
    VecN::from_fn(|i, _| if i < n { x[i] } else { 0.0 })
}

#[test]
fn locked_joints_match_reduced_crba() {
    let mut rng = Rng(0xC0FF_EE00_D15E_A5E5);
    let mut worst: f64 = 0.0;
    for elements in [[0, 0], [0, 4], [3, 3]] {
        for case in 0..16 {
            let m = model(elements, if case % 2 == 0 { None } else { Some([rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)]) });
            let n = m.nv;
            let pd = param_data(&m, &mut rng, false);
            let (mut q, mut v) = state(&m, &mut rng);
            // a random set of locked joints (about a third), sometimes a whole beam link
            let mut locked: Vec<usize> = (0..n).filter(|_| rng.uniform(0.0, 1.0) < 0.33).collect();
            if case % 4 == 3 {
                if let Some(bl) = m.beam.iter().flatten().next() {
                    locked = (bl.start..bl.start + bl.dof()).collect();
                }
            }
            // the bare core with random forces and random prescribed joints
            let rot = m.rotations(&q);
            let tau = rng.vec_n(-20.0, 20.0, n);
            let mut pres: Vec<(usize, f64)> = Vec::new();
            for i in 0..n {
                let x = rng.uniform(-5.0, 5.0);
                if !locked.contains(&i) && rng.uniform(0.0, 1.0) < 0.2 {
                    pres.push((i, x));
                }
            }
            let a = articulated(&m, &pd.body, &rot, &v, &tau, &m.armature, &m.gravity, &pres, &locked);
            let mut fixed: Vec<(usize, f64)> = locked.iter().map(|&i| (i, 0.0)).collect();
            fixed.extend_from_slice(&pres);
            let a_ref = reference(&m, &pd, &q, &v, &tau, &fixed);
            let e = rel(&a, &a_ref, n);
            worst = worst.max(e);
            assert!(e < TOL, "core: elements {elements:?} case {case}, locked {locked:?}: rel {e:e}");
            for &i in &locked {
                assert_eq!(a[i], 0.0);
            }
            // the full right-hand side, torque drive or replay
            let drive = if case % 2 == 0 { torque_drive(&mut rng) } else { replay_drive(&mut rng) };
            let t = rng.uniform(0.0, 0.7);
            let am = prescribe(&m, &drive, t, &mut q, &mut v);
            locked.retain(|i| !m.motor_idx.contains(i) || am.is_none());
            let a = accel_articulated_locked(&m, &pd, &drive, t, &q, &v, am, &locked);
            let mut tau = passive(&m, &pd, t, &q, &v);
            let mut fixed: Vec<(usize, f64)> = locked.iter().map(|&i| (i, 0.0)).collect();
            match am {
                Some(am) => fixed.extend(m.motor_idx.iter().zip(am).map(|(&i, x)| (i, x))),
                None => {
                    let tm = drive.torque(t).unwrap();
                    for k in 0..3 {
                        tau[m.motor_idx[k]] += tm[k];
                    }
                }
            }
            let a_ref = reference(&m, &pd, &q, &v, &tau, &fixed);
            let e = rel(&a, &a_ref, n);
            worst = worst.max(e);
            assert!(e < TOL, "accel: elements {elements:?} case {case}, locked {locked:?}: rel {e:e}");
        }
    }
    println!("articulated with locked joints vs reduced CRBA: worst relative difference {worst:.2e}");
}

#[test]
fn everything_locked_or_prescribed_gives_the_given_accelerations() {
    let m = model([0, 2], None);
    let pd = ParamData::new(&m, &Params::defaults(&m)).unwrap();
    let mut rng = Rng(7);
    let (q, v) = state(&m, &mut rng);
    let rot = m.rotations(&q);
    let all: Vec<usize> = (0..m.nv).collect();
    let a = articulated(&m, &pd.body, &rot, &v, &VecN::zeros(), &m.armature, &Vec3::new(0.0, 0.0, -9.81), &[(0, 1.5)], &all[1..]);
    assert_eq!(a[0], 1.5);
    for i in 1..m.nv {
        assert_eq!(a[i], 0.0);
    }
}
