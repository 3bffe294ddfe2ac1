//! Cross-checks of the rigid-body dynamics of the PRBM chain against each other and
//! against plain kinematics, at random states, payloads, pressures and gravity vectors:
//!
//! (a) ABA forward dynamics == CRBA + RNEA forward dynamics (and == `forward::accel`);
//! (b) CRBA's M == columns of RNEA(q, 0, e_j, g = 0) == M from the kinetic energy built
//!     out of finite-difference Jacobians of `kinematics::prbm::frames`; M symmetric PD;
//! (c) the RNEA bias is Lagrange's: c(q, v) = Ṁ v − ½ ∂(vᵀ M v)/∂q, and Ṁ − 2C is
//!     skew-symmetric with C the Christoffel matrix obtained by polarising RNEA;
//! (d) the gravity torque RNEA(q, 0, 0, g) == ∂V/∂q by central differences of the
//!     potential energy computed from the frames (and == `sensor::energy` at v = 0).
//!
//! The 50 cases of the arm file's 7-joint chain are followed by 20 cases of expanded chains
//! (2 or 3 segments per link, torsion joints about the link axes: up to 17 joints).

mod common;

use common::Rng;
use nalgebra::DMatrix;
use popup_core::drive::{Drive, Linear3};
use popup_core::dynamics::{aba, crba, rnea};
use popup_core::forward::{accel, passive};
use popup_core::kinematics::prbm::frames;
use popup_core::math::{Mat3, MatN, Vec3, VecN, NMAX};
use popup_core::model::{Disable, Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::spec::ArmSpec;

const NSTATE: usize = 50;

struct Case {
    model: Model,
    pd: ParamData,
    q: VecN,
    v: VecN,
    g: Vec3,
}

const NSTRUCT: usize = 20;

fn cases() -> Vec<Case> {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let spec = ArmSpec::popup_lab();
    let mut out: Vec<Case> = (0..NSTATE)
        .map(|n| {
            // every third case with the arm file's gravity, the others with a random one
            let g = if n % 3 == 0 { [0.0, 0.0, -9.81] } else { [rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)] };
            let model = Model::compile(&spec, Options { gravity: Some(g), ..Options::default() }).unwrap();
            let params = Params { payload_kg: rng.uniform(0.0, 5.0), pressure_pa: [rng.uniform(5e3, 95e3), rng.uniform(5e3, 95e3)], effects: Default::default() };
            let pd = ParamData::new(&model, &params).unwrap();
            let mut q = VecN::zeros();
            let mut v = VecN::zeros();
            for i in 0..model.nv {
                let bending = model.bend().contains(&i);
                q[i] = if bending { rng.uniform(-0.3, 0.3) } else { rng.uniform(-3.2, 3.2) };
                v[i] = if bending { rng.uniform(-2.0, 2.0) } else { rng.uniform(-3.0, 3.0) };
            }
            Case { g: Vec3::from(g), model, pd, q, v }
        })
        .collect();
    // expanded chains: segments and torsion joints
    let mut rng = Rng(0x51ED_2701_A5A5_0F0F);
    for n in 0..NSTRUCT {
        let structure = Structure { segments: [1 + n % 3, 1 + (n / 3) % 3], torsion: [n % 2 == 0, n % 4 < 2], elements: [0, 0] };
        let g = [rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)];
        let model = Model::compile(&spec, Options { gravity: Some(g), structure, ..Options::default() }).unwrap();
        let mut effects = popup_core::effects::Effects::default();
        effects.higher_bending_modes.k_scale = [rng.uniform(0.5, 2.0), rng.uniform(0.5, 2.0)];
        effects.torsion.k_t = [rng.uniform(100.0, 2000.0), rng.uniform(100.0, 2000.0)];
        effects.torsion.c_t = [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)];
        let params = Params { payload_kg: rng.uniform(0.0, 5.0), pressure_pa: [rng.uniform(5e3, 95e3), rng.uniform(5e3, 95e3)], effects };
        let pd = ParamData::new(&model, &params).unwrap();
        let mut q = VecN::zeros();
        let mut v = VecN::zeros();
        for i in 0..model.nv {
            let passive = model.passive().contains(&i);
            q[i] = if passive { rng.uniform(-0.3, 0.3) } else { rng.uniform(-3.2, 3.2) };
            v[i] = if passive { rng.uniform(-2.0, 2.0) } else { rng.uniform(-3.0, 3.0) };
        }
        out.push(Case { g: Vec3::from(g), model, pd, q, v });
    }
    out
}

/// The leading nv × nv block of a joint-space matrix.
fn block(m: &MatN, nv: usize) -> DMatrix<f64> {
    DMatrix::from_fn(nv, nv, |i, j| m[(i, j)])
}

/// Solve with the leading nv × nv block (nalgebra's Cholesky on the block).
fn solve_block(m: &MatN, b: &VecN, nv: usize) -> VecN {
    let x = block(m, nv).cholesky().expect("M + armature is SPD").solve(&nalgebra::DVector::from_fn(nv, |i, _| b[i]));
    VecN::from_fn(|i, _| if i < nv { x[i] } else { 0.0 })
}

fn amax(v: &VecN) -> f64 {
    v.amax()
}

fn mass(c: &Case, q: &VecN) -> MatN {
    crba(&c.model, &c.pd.body, &c.model.rotations(q))
}

fn bias(c: &Case, q: &VecN, v: &VecN, g: &Vec3) -> VecN {
    rnea(&c.model, &c.pd.body, &c.model.rotations(q), v, &VecN::zeros(), g)
}

/// Mass matrix from the kinetic energy T = Σ_i ½ m|v_o|² + v_o·(ω × R h) + ½ ω_bᵀ J ω_b,
/// with the origin-velocity and angular-velocity Jacobians of every body taken by central
/// differences of the forward kinematics. Uses neither RNEA nor CRBA.
fn mass_from_kinematics(c: &Case, q: &VecN) -> MatN {
    let h = 1e-6;
    let f0 = frames(&c.model, q);
    // jp[j][i], jw[j][i]: world velocity of origin i+1 and world angular velocity of body i
    // per unit q̇_j
    let nv = c.model.nv;
    let mut jp = [[Vec3::zeros(); NMAX]; NMAX];
    let mut jw = [[Vec3::zeros(); NMAX]; NMAX];
    for j in 0..nv {
        let (mut qp, mut qm) = (*q, *q);
        qp[j] += h;
        qm[j] -= h;
        let (fp, fm) = (frames(&c.model, &qp), frames(&c.model, &qm));
        for i in 0..nv {
            jp[j][i] = (fp.p_wb[i + 1] - fm.p_wb[i + 1]) / (2.0 * h);
            let rd: Mat3 = (fp.r_wb[i + 1] - fm.r_wb[i + 1]) / (2.0 * h);
            let w = rd * f0.r_wb[i + 1].transpose(); // = skew(ω)
            jw[j][i] = Vec3::new(0.5 * (w[(2, 1)] - w[(1, 2)]), 0.5 * (w[(0, 2)] - w[(2, 0)]), 0.5 * (w[(1, 0)] - w[(0, 1)]));
        }
    }
    let mut m = MatN::zeros();
    for i in 0..nv {
        let b = &c.pd.body[i];
        let r = f0.r_wb[i + 1];
        let hw = r * b.h;
        for j in 0..nv {
            for k in 0..nv {
                let (pj, pk, wj, wk) = (jp[j][i], jp[k][i], jw[j][i], jw[k][i]);
                m[(j, k)] += b.m * pj.dot(&pk)
                    + pj.dot(&wk.cross(&hw))
                    + pk.dot(&wj.cross(&hw))
                    + (r.transpose() * wj).dot(&(b.j * (r.transpose() * wk)));
            }
        }
    }
    m
}

/// Potential energy of gravity from the frames: V = −Σ g · (m p_i + R_i h_i).
fn potential(c: &Case, q: &VecN) -> f64 {
    let f = frames(&c.model, q);
    (0..c.model.nv).map(|i| -c.g.dot(&(f.p_wb[i + 1] * c.pd.body[i].m + f.r_wb[i + 1] * c.pd.body[i].h))).sum()
}

#[test]
fn aba_matches_crba_rnea_forward_dynamics() {
    let mut rng = Rng(12345);
    let mut worst: f64 = 0.0;
    let mut worst_accel: f64 = 0.0;
    for (n, c) in cases().iter().enumerate() {
        let rot = c.model.rotations(&c.q);
        let nv = c.model.nv;
        let tau = rng.vec_n(-20.0, 20.0, nv);
        // with the arm's armature and with a random one (zero on every other case)
        let arm: [f64; NMAX] =
            if n % 2 == 0 { c.model.armature } else { std::array::from_fn(|i| if n % 4 == 1 || i >= nv { 0.0 } else { rng.uniform(0.0, 0.2) * (i % 2) as f64 }) };
        let mut m = crba(&c.model, &c.pd.body, &rot);
        for i in 0..nv {
            m[(i, i)] += arm[i];
        }
        let rhs = tau - rnea(&c.model, &c.pd.body, &rot, &c.v, &VecN::zeros(), &c.g);
        let qdd_crba = solve_block(&m, &rhs, nv);
        let qdd_aba = aba(&c.model, &c.pd.body, &rot, &c.v, &tau, &arm, &c.g);
        let rel = amax(&(qdd_aba - qdd_crba)) / amax(&qdd_crba);
        worst = worst.max(rel);
        assert!(rel < 1e-9, "case {n}: ABA {qdd_aba:?} vs CRBA+RNEA {qdd_crba:?} (rel {rel:e})");
        // the integrator's right-hand side (torque drive): springs, dampers, armature, motor torques
        let tm = [rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0), rng.uniform(-10.0, 10.0)];
        let drive = Drive::Torque(Linear3::new(&[0.0], &[tm]).unwrap());
        let a = accel(&c.model, &c.pd, &drive, 0.3, &c.q, &c.v, None, 0.0);
        let mut tau_full = passive(&c.model, &c.pd, 0.0, &c.q, &c.v);
        for k in 0..3 {
            tau_full[c.model.motor_idx[k]] += tm[k];
        }
        let a_ref = aba(&c.model, &c.pd.body, &rot, &c.v, &tau_full, &c.model.armature, &c.model.gravity);
        let rel = amax(&(a - a_ref)) / amax(&a_ref);
        worst_accel = worst_accel.max(rel);
        assert!(rel < 1e-9, "case {n}: forward::accel {a:?} vs ABA {a_ref:?} (rel {rel:e})");
    }
    println!("ABA vs CRBA+RNEA: worst relative difference {worst:.2e}; forward::accel vs ABA: {worst_accel:.2e}");
}

#[test]
fn mass_matrix_is_rnea_columns_and_kinetic_energy() {
    let mut worst_cols: f64 = 0.0;
    let mut worst_kin: f64 = 0.0;
    let mut worst_sym: f64 = 0.0;
    let mut min_ratio = f64::INFINITY;
    for (n, c) in cases().iter().enumerate() {
        let rot = c.model.rotations(&c.q);
        let m = crba(&c.model, &c.pd.body, &rot);
        let scale = m.amax();
        let nv = c.model.nv;
        let mut cols = MatN::zeros();
        for j in 0..nv {
            let mut e = VecN::zeros();
            e[j] = 1.0;
            cols.set_column(j, &rnea(&c.model, &c.pd.body, &rot, &VecN::zeros(), &e, &Vec3::zeros()));
        }
        let d = (m - cols).amax() / scale;
        worst_cols = worst_cols.max(d);
        assert!(d < 1e-12, "case {n}: CRBA vs RNEA columns differ by {d:e} (relative)\n{m}\n{cols}");
        let sym = (cols - cols.transpose()).amax() / scale;
        worst_sym = worst_sym.max(sym);
        assert!(sym < 1e-12, "case {n}: RNEA columns not symmetric ({sym:e})");
        let mk = mass_from_kinematics(c, &c.q);
        let d = (m - mk).amax() / scale;
        worst_kin = worst_kin.max(d);
        assert!(d < 1e-7, "case {n}: CRBA vs kinetic-energy M differ by {d:e} (relative)\n{m}\n{mk}");
        let eig = block(&m, nv).symmetric_eigen().eigenvalues;
        let (lo, hi) = (eig.min(), eig.max());
        min_ratio = min_ratio.min(lo / hi);
        assert!(lo > 0.0 && block(&m, nv).cholesky().is_some(), "case {n}: M not positive definite, eigenvalues {eig:?}");
    }
    println!(
        "M: CRBA vs RNEA columns {worst_cols:.2e}, symmetry of RNEA columns {worst_sym:.2e}, CRBA vs kinetic energy (FD Jacobians) {worst_kin:.2e}, min λ_min/λ_max {min_ratio:.2e}"
    );
}

#[test]
fn coriolis_is_lagrangian_and_mdot_minus_2c_skew() {
    let eps = 1e-5;
    let zero = Vec3::zeros();
    let (mut worst_lag, mut worst_skew, mut worst_quad): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for (n, c) in cases().iter().enumerate() {
        let (q, v) = (c.q, c.v);
        let mdot = (mass(c, &(q + v * eps)) - mass(c, &(q - v * eps))) / (2.0 * eps);
        let nv = c.model.nv;
        let mut grad = VecN::zeros();
        for k in 0..nv {
            let (mut qp, mut qm) = (q, q);
            qp[k] += eps;
            qm[k] -= eps;
            grad[k] = 0.5 * (v.dot(&(mass(c, &qp) * v)) - v.dot(&(mass(c, &qm) * v))) / (2.0 * eps);
        }
        let lag = mdot * v - grad;
        let cv = bias(c, &q, &v, &zero);
        let scale = amax(&(mdot * v)).max(amax(&grad));
        let d = amax(&(cv - lag)) / scale;
        worst_lag = worst_lag.max(d);
        assert!(d < 1e-7, "case {n}: RNEA bias {cv:?} vs Lagrange Ṁv − ∂T/∂q {lag:?} (rel {d:e})");
        // Christoffel C(q, v) by polarising the quadratic form c(q, ·): C w = (c(v+w) − c(v−w))/4
        let mut cm = MatN::zeros();
        for j in 0..nv {
            let mut e = VecN::zeros();
            e[j] = 1.0;
            cm.set_column(j, &((bias(c, &q, &(v + e), &zero) - bias(c, &q, &(v - e), &zero)) / 4.0));
        }
        // c is a quadratic form: C(q, v) v == c(q, v)
        let dq = amax(&(cm * v - cv)) / amax(&cv);
        worst_quad = worst_quad.max(dq);
        assert!(dq < 1e-10, "case {n}: C(q, v) v != c(q, v) (rel {dq:e})");
        let n_ = mdot - cm * 2.0;
        let s = (n_ + n_.transpose()).amax() / n_.amax();
        worst_skew = worst_skew.max(s);
        assert!(s < 1e-7, "case {n}: Ṁ − 2C is not skew-symmetric (|N + Nᵀ|/|N| = {s:e})\n{n_}");
        // scalar form: vᵀ (Ṁ − 2C) v = 0, i.e. d/dt T = vᵀ (τ − g)
        let e = (v.dot(&(mdot * v)) - 2.0 * v.dot(&cv)).abs() / v.dot(&(mdot * v)).abs().max(1.0);
        assert!(e < 1e-7, "case {n}: vᵀ(Ṁ − 2C)v = {e:e}");
    }
    println!("Coriolis: RNEA vs Lagrange {worst_lag:.2e}, C v vs c {worst_quad:.2e}, skew(Ṁ − 2C) {worst_skew:.2e} (relative)");
}

#[test]
fn gravity_torque_is_gradient_of_potential() {
    let h = 1e-5;
    let mut worst: f64 = 0.0;
    let mut worst_energy: f64 = 0.0;
    for (n, c) in cases().iter().enumerate() {
        let g = bias(c, &c.q, &VecN::zeros(), &c.g);
        let mut dv = VecN::zeros();
        for k in 0..c.model.nv {
            let (mut qp, mut qm) = (c.q, c.q);
            qp[k] += h;
            qm[k] -= h;
            dv[k] = (potential(c, &qp) - potential(c, &qm)) / (2.0 * h);
        }
        let d = amax(&(g - dv)) / amax(&g).max(1e-3);
        worst = worst.max(d);
        assert!(d < 1e-7, "case {n}: RNEA gravity {g:?} vs ∂V/∂q {dv:?} (rel {d:e})");
        // sensor::energy at v = 0 with springs off is the same potential
        let opts = Options { gravity: Some(c.g.into()), disable: Disable { spring: true, ..Disable::default() }, structure: c.model.options.structure, ..Options::default() };
        let m2 = Model::compile(&ArmSpec::popup_lab(), opts).unwrap();
        let pd2 = ParamData::new(&m2, &c.pd.params).unwrap();
        let e = popup_core::sensor::energy(&m2, &pd2, 0.0, &c.q, &VecN::zeros());
        let v0 = potential(c, &c.q);
        let de = (e - v0).abs() / v0.abs().max(1.0);
        worst_energy = worst_energy.max(de);
        assert!(de < 1e-12, "case {n}: sensor::energy {e} vs V {v0}");
        // and the spring term is ½ Σ k δ² when springs are on
        let es = popup_core::sensor::energy(&c.model, &c.pd, 0.0, &c.q, &VecN::zeros());
        let spring: f64 = c.model.passive().iter().map(|&b| 0.5 * c.pd.k[b] * c.q[b] * c.q[b]).sum();
        assert!((es - v0 - spring).abs() < 1e-9 * (es.abs() + 1.0), "case {n}: energy with springs {es} vs {}", v0 + spring);
    }
    println!("gravity torque vs ∂V/∂q (FD): worst relative {worst:.2e}; sensor::energy vs V: {worst_energy:.2e}");
}
