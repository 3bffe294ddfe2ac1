//! The linearised arm (`popup_core::linear`): its eigenvalues are the locked-motor modes and
//! the step-check eigenvalues, its input matrix is the inverse mass matrix, its output
//! matrices are the kinematics' derivatives, and a small-amplitude simulation follows it.

mod common;

use nalgebra::Complex;
use popup_core::drive::{Drive, Linear3};
use popup_core::kinematics::prbm::end_effector;
use popup_core::linear::{linearize_at_rest, LinearInput};
use popup_core::math::VecN;
use popup_core::model::{Disable, Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::channel_index;
use popup_core::sim::{run, RunConfig, State};
use popup_core::spec::ArmSpec;
use popup_core::statics::{linear_eigs, locked_modes, mass_matrix};

fn model(opts: Options) -> Model {
    Model::compile(&ArmSpec::popup_lab(), opts).unwrap()
}

fn pd(m: &Model, payload: f64) -> ParamData {
    ParamData::new(m, &Params { payload_kg: payload, pressure_pa: [30e3, 30e3], effects: Default::default() }).unwrap()
}

fn sorted(mut v: Vec<Complex<f64>>) -> Vec<Complex<f64>> {
    v.sort_by(|a, b| a.im.partial_cmp(&b.im).unwrap().then(a.re.partial_cmp(&b.re).unwrap()));
    v
}

fn assert_same(a: &[Complex<f64>], b: &[Complex<f64>], rel: f64) {
    assert_eq!(a.len(), b.len());
    for (x, y) in sorted(a.to_vec()).iter().zip(sorted(b.to_vec()).iter()) {
        assert!((x - y).norm() <= rel * y.norm().max(1.0), "{x} vs {y}");
    }
}

const POSES: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [0.0, 0.6, -0.3], [0.0, std::f64::consts::FRAC_PI_2, 0.0]];

#[test]
fn locked_eigenvalues_are_the_locked_modes() {
    // undamped: ±iω for every locked-motor frequency of statics::locked_modes
    let m = model(Options { disable: Disable { damper: true, ..Disable::default() }, ..Options::default() });
    for payload in [0.0, 1.0, 2.0] {
        let p = pd(&m, payload);
        for qm in POSES {
            let lin = linearize_at_rest(&m, &p, qm, LinearInput::Locked, &[], 0.0).unwrap();
            assert_eq!(lin.a.nrows(), 2 * m.passive().len());
            let mut w: Vec<f64> = lin.poles().iter().filter(|l| l.im > 0.0).map(|l| l.im).collect();
            w.sort_by(|a, b| a.partial_cmp(b).unwrap());
            let st = popup_core::sim::rest_state(&m, &p, 0.0, qm).unwrap();
            let want = locked_modes(&m, &p, &st.q);
            assert_eq!(w.len(), want.len(), "{w:?} vs {want:?}");
            for (a, b) in w.iter().zip(&want) {
                assert!((a - b).abs() < 1e-6 * b, "payload {payload} pose {qm:?}: {a} vs {b}");
            }
            for l in lin.poles() {
                assert!(l.re.abs() < 1e-6 * l.norm(), "undamped pole {l} has a real part");
            }
        }
    }
}

#[test]
fn damped_eigenvalues_match_the_step_check() {
    // with damping: the same eigenvalues as statics::linear_eigs (passive joints = locked,
    // every joint = torque-driven)
    let m = model(Options::default());
    for payload in [0.0, 2.0] {
        let p = pd(&m, payload);
        for qm in POSES {
            let st = popup_core::sim::rest_state(&m, &p, 0.0, qm).unwrap();
            let lk = linearize_at_rest(&m, &p, qm, LinearInput::Locked, &[], 0.0).unwrap();
            let want: Vec<Complex<f64>> = linear_eigs(&m, &p, &st.q, m.passive(), true).into_iter().map(|e| e.0).collect();
            assert_same(&lk.poles(), &want, 1e-6);
            let tq = linearize_at_rest(&m, &p, qm, LinearInput::Torque, &[], 0.0).unwrap();
            let all: Vec<usize> = (0..m.nv).collect();
            let want: Vec<Complex<f64>> = linear_eigs(&m, &p, &st.q, &all, true).into_iter().map(|e| e.0).collect();
            // the torque-driven arm has zero and near-zero poles (free yaw, gravity on the
            // motors): compare with an absolute floor
            assert_same(&tq.poles(), &want, 1e-6);
        }
    }
}

#[test]
fn torque_input_matrix_is_the_inverse_mass_matrix_and_holds_the_arm() {
    let m = model(Options::default());
    let p = pd(&m, 2.0);
    let qm = [0.3, 0.6, -0.3];
    let lin = linearize_at_rest(&m, &p, qm, LinearInput::Torque, &[], 0.0).unwrap();
    let n = m.nv;
    let mm = mass_matrix(&m, &p, &lin.q0);
    let mi = nalgebra::DMatrix::from_fn(n, n, |i, j| mm[(i, j)]).try_inverse().unwrap();
    for (k, &i) in m.motor_idx.iter().enumerate() {
        for r in 0..n {
            assert!((lin.b[(n + r, k)] - mi[(r, i)]).abs() < 1e-8 * mi.amax(), "B[{r},{k}]");
            assert_eq!(lin.b[(r, k)], 0.0);
        }
    }
    // u0 holds the arm: a run from the operating point with u0 stays there
    let run_cfg = RunConfig {
        drive: Drive::Torque(Linear3::new(&[0.0], &[[lin.u0[0], lin.u0[1], lin.u0[2]]]).unwrap()),
        initial: Some(State { t: 0.0, q: lin.q0, v: VecN::zeros() }),
        duration: Some(0.5),
        sample_period: 0.5,
        check_step: true,
    };
    let tr = run(&m, &p, &run_cfg).unwrap();
    assert!((tr.final_state.q - lin.q0).amax() < 1e-9, "drift {}", (tr.final_state.q - lin.q0).amax());
}

#[test]
fn acceleration_input_has_double_integrator_motors_and_exact_output_jacobians() {
    let m = model(Options::default());
    let p = pd(&m, 1.0);
    let outs: Vec<usize> = ["q2", "ee_x", "ee_z", "d22", "dq3", "dd12"].iter().map(|c| channel_index(c).unwrap()).collect();
    let lin = linearize_at_rest(&m, &p, [0.2, 0.5, -0.4], LinearInput::Acceleration, &outs, 0.0).unwrap();
    let n = m.nv;
    for (k, &i) in m.motor_idx.iter().enumerate() {
        for c in 0..2 * n {
            assert!(lin.a[(n + i, c)].abs() < 1e-9, "motor row {i} of A must be zero");
        }
        for kk in 0..3 {
            let want = if kk == k { 1.0 } else { 0.0 };
            assert!((lin.b[(n + i, kk)] - want).abs() < 1e-9);
        }
    }
    // C rows of ee_x / ee_z: derivatives of the forward kinematics (independent FD, h = 1e-6)
    for j in 0..n {
        let (mut qp, mut qm) = (lin.q0, lin.q0);
        qp[j] += 1e-6;
        qm[j] -= 1e-6;
        let g = (end_effector(&m, &qp) - end_effector(&m, &qm)) / 2e-6;
        assert!((lin.c[(1, j)] - g.x).abs() < 1e-7, "dee_x/dq{j}: {} vs {}", lin.c[(1, j)], g.x);
        assert!((lin.c[(2, j)] - g.z).abs() < 1e-7);
        assert!((lin.c[(0, j)] - if j == m.motor_idx[1] { 1.0 } else { 0.0 }).abs() < 1e-12);
    }
    // velocity channels read the rate states
    assert!((lin.c[(4, n + m.motor_idx[2])] - 1.0).abs() < 1e-12);
    assert!((lin.c[(5, n + 3)] - 1.0).abs() < 1e-12);
    assert!(lin.d.amax() < 1e-9, "angle and rate outputs have no feedthrough");
}

#[test]
fn small_torque_step_follows_the_linear_model() {
    // gravity off, a 0.05 N·m step on q3 for 0.3 s: simulated tip position vs the linear
    // model integrated exactly (matrix exponential of the augmented system)
    let m = model(Options { dt: 5e-4, gravity: Some([0.0; 3]), ..Options::default() });
    let p = pd(&m, 2.0);
    let ee = channel_index("ee_z").unwrap();
    let d22 = channel_index("d22").unwrap();
    let lin = linearize_at_rest(&m, &p, [0.0, 0.3, 0.5], LinearInput::Torque, &[ee, d22], 0.0).unwrap();
    let du = [0.0, 0.0, 0.05];
    let t_end = 0.3;
    let cfg = RunConfig {
        drive: Drive::Torque(Linear3::new(&[0.0], &[[lin.u0[0] + du[0], lin.u0[1] + du[1], lin.u0[2] + du[2]]]).unwrap()),
        initial: Some(State { t: 0.0, q: lin.q0, v: VecN::zeros() }),
        duration: Some(t_end),
        sample_period: t_end,
        check_step: true,
    };
    let tr = run(&m, &p, &cfg).unwrap();
    let y_sim = [common::col(&tr, "ee_z"), common::col(&tr, "d22")];
    // x(T) = ∫0^T e^{A s} ds B du: exp of [[A, B du], [0, 0]]
    let n2 = lin.a.nrows();
    let mut aug = nalgebra::DMatrix::zeros(n2 + 1, n2 + 1);
    aug.view_mut((0, 0), (n2, n2)).copy_from(&(&lin.a * t_end));
    let bu = &lin.b * nalgebra::DVector::from_row_slice(&du);
    for i in 0..n2 {
        aug[(i, n2)] = bu[i] * t_end;
    }
    let e = aug.exp();
    let x = e.view((0, n2), (n2, 1)).into_owned();
    let y = &lin.c * x + &lin.d * nalgebra::DVector::from_row_slice(&du);
    for k in 0..2 {
        let sim = y_sim[k][y_sim[k].len() - 1] - lin.y0[k];
        println!("output {k}: simulated {sim:.6e}, linear {:.6e}", y[k]);
        assert!((sim - y[k]).abs() < 0.01 * y[k].abs(), "output {k}: {sim} vs {}", y[k]);
    }
}

#[test]
fn segmented_links_linearise_too() {
    let m = model(Options { structure: Structure { segments: [2, 1], torsion: [false, false], elements: [0, 0] }, disable: Disable { damper: true, ..Disable::default() }, ..Options::default() });
    let p = pd(&m, 2.0);
    let lin = linearize_at_rest(&m, &p, [0.0, 0.4, 0.0], LinearInput::Locked, &[], 0.0).unwrap();
    let st = popup_core::sim::rest_state(&m, &p, 0.0, [0.0, 0.4, 0.0]).unwrap();
    let want = locked_modes(&m, &p, &st.q);
    let mut w: Vec<f64> = lin.poles().iter().filter(|l| l.im > 0.0).map(|l| l.im).collect();
    w.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(w.len(), want.len());
    for (a, b) in w.iter().zip(&want) {
        assert!((a - b).abs() < 1e-6 * b, "{a} vs {b}");
    }
}
