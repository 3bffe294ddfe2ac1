//! Statics and linearisation: static equilibrium of the passive (bending and torsion)
//! joints, gravity stiffness, locked-motor modes and the eigenvalues used by the step-size
//! check. None of this is on the hot path; matrices over joint subsets are `DMatrix`.

use crate::dynamics::{crba, rnea};
use crate::error::{Error, Result};
use crate::forward::{beam_spring, damping_matrix};
use crate::math::{MatN, VecN};
use crate::model::Model;
use crate::params::ParamData;
use nalgebra::{Complex, DMatrix, DVector};

/// Generalised gravity forces G(q) = ∂V/∂q [N·m].
pub fn gravity_torque(model: &Model, pd: &ParamData, q: &VecN) -> VecN {
    let rot = model.rotations(q);
    rnea(model, &pd.body, &rot, &VecN::zeros(), &VecN::zeros(), &model.gravity)
}

/// Joint-space stiffness K = diag(k) + ∂G/∂q at `q` (central differences of G, symmetrised)
/// [N·m/rad], leading nv × nv block.
pub fn stiffness(model: &Model, pd: &ParamData, q: &VecN) -> MatN {
    let h = 1e-6;
    let mut k = MatN::zeros();
    for j in 0..model.nv {
        let mut qp = *q;
        let mut qm = *q;
        qp[j] += h;
        qm[j] -= h;
        let col = (gravity_torque(model, pd, &qp) - gravity_torque(model, pd, &qm)) / (2.0 * h);
        k.set_column(j, &col);
    }
    k = (k + k.transpose()) * 0.5;
    if !model.options.disable.spring {
        for &b in model.passive() {
            k[(b, b)] += pd.k[b];
        }
        for bl in model.beam.iter().flatten() {
            for i in bl.start..bl.start + bl.dof() {
                for j in bl.start..bl.start + bl.dof() {
                    k[(i, j)] += pd.beam_k[(i, j)];
                }
            }
        }
    }
    k
}

/// Mass matrix with armature [kg·m²], leading nv × nv block.
pub fn mass_matrix(model: &Model, pd: &ParamData, q: &VecN) -> MatN {
    let rot = model.rotations(q);
    let mut m = crba(model, &pd.body, &rot);
    for i in 0..model.nv {
        m[(i, i)] += model.armature[i];
    }
    m
}

fn sub(m: &MatN, idx: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(idx.len(), idx.len(), |i, j| m[(idx[i], idx[j])])
}

/// Static equilibrium of the passive (bending and torsion) joints with the motor joints held
/// at the motor coordinates of `q`: solves `G_p(q) + k δ = 0` by Newton's method. Returns q
/// with the passive coordinates at equilibrium (starting from those of `q`).
///
/// # Errors
/// [`Error::NoConvergence`] if Newton fails (e.g. springs too weak to hold the arm).
pub fn static_equilibrium(model: &Model, pd: &ParamData, q: &VecN) -> Result<VecN> {
    let mut x = *q;
    let bi = model.passive();
    if bi.is_empty() {
        return Ok(x);
    }
    for it in 0..50 {
        let g = gravity_torque(model, pd, &x);
        let mut r = DVector::<f64>::zeros(bi.len());
        let fx = &pd.params.effects;
        let sm = if fx.wrinkling.ratio != 1.0 || fx.pressure_leak.rate != [0.0; 2] { Some(crate::forward::spring_moments(model, pd, 0.0, &x)) } else { None };
        let bs = if model.has_beam() { Some(beam_spring(model, pd, &x)) } else { None };
        for (a, &b) in bi.iter().enumerate() {
            let spring = if model.options.disable.spring {
                0.0
            } else if let (Some(s), true) = (&sm, model.bend().contains(&b)) {
                s[b]
            } else {
                pd.k[b] * x[b]
            };
            r[a] = g[b] + spring;
            if let Some(bs) = &bs {
                r[a] += bs[b];
            }
        }
        let mut kfull = stiffness(model, pd, &x);
        if sm.is_some() && !model.options.disable.spring {
            // tangent of the effect-modified springs (bilinear, leaking) instead of diag(k)
            let h = 1e-7;
            for &j in model.bend() {
                kfull[(j, j)] -= pd.k[j];
                let (mut xp, mut xm) = (x, x);
                xp[j] += h;
                xm[j] -= h;
                let d = (crate::forward::spring_moments(model, pd, 0.0, &xp) - crate::forward::spring_moments(model, pd, 0.0, &xm)) / (2.0 * h);
                for &i in model.bend() {
                    kfull[(i, j)] += d[i];
                }
            }
        }
        let kk = sub(&kfull, bi);
        let dx = kk.lu().solve(&r).ok_or_else(|| Error::NoConvergence {
            what: "static equilibrium".into(),
            message: "the passive-joint stiffness matrix is singular (springs disabled or zero?)".into(),
        })?;
        for (a, &b) in bi.iter().enumerate() {
            x[b] -= dx[a];
        }
        if dx.amax() < if sm.is_some() { 1e-12 } else { 1e-14 } && it > 0 {
            return Ok(x);
        }
        if !dx.amax().is_finite() || dx.amax() > 10.0 {
            break;
        }
    }
    Err(Error::NoConvergence {
        what: "static equilibrium".into(),
        message: format!(
            "Newton iteration on the passive joints did not converge (payload_kg = {} kg, pressure_pa = {:?} Pa): the springs may be too weak for the load",
            pd.params.payload_kg, pd.params.pressure_pa
        ),
    })
}

/// Undamped natural frequencies of the passive (bending and torsion) joints with the motors
/// locked, about `q` (spring plus gravity stiffness), ascending [rad/s], one per passive
/// joint. A negative entry means a statically unstable direction (−√|λ|).
pub fn locked_modes(model: &Model, pd: &ParamData, q: &VecN) -> Vec<f64> {
    let bi = model.passive();
    if bi.is_empty() {
        return Vec::new();
    }
    let m = sub(&mass_matrix(model, pd, q), bi);
    let k = sub(&stiffness(model, pd, q), bi);
    let l = m.cholesky().expect("passive-joint mass matrix is positive definite").l();
    let li = l.try_inverse().expect("invertible");
    let a = &li * k * li.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let mut ev: Vec<f64> = a.symmetric_eigen().eigenvalues.iter().map(|&l| if l >= 0.0 { l.sqrt() } else { -(-l).sqrt() }).collect();
    ev.sort_by(|x, y| x.partial_cmp(y).unwrap());
    ev
}

/// Eigenvalues of the linearised first-order system about `(q, 0)` over the free joints
/// (`free`: joints that are integrated), with the integrator's view of damping [1/s].
/// Returns (eigenvalue, index of the joint whose diagonal k/m is nearest |λ|², an estimate
/// of where the mode lives).
/// With `with_damping = false` the dampers are left out (the semi-implicit integrator
/// treats them implicitly, so only the undamped frequencies limit its step).
pub fn linear_eigs(model: &Model, pd: &ParamData, q: &VecN, free: &[usize], with_damping: bool) -> Vec<(Complex<f64>, usize)> {
    let n = free.len();
    if n == 0 {
        return Vec::new();
    }
    let mut mm = mass_matrix(model, pd, q);
    // a free motor row with play is the link side of its gear: the gear's link-side inertia
    // replaces the motor's armature (crate::backlash)
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if pd.params.effects.backlash.free_gap()[k] != 0.0 && free.contains(&p) {
            mm[(p, p)] += pd.params.effects.backlash.inertia[k] - model.armature[p];
        }
    }
    let mut kk = stiffness(model, pd, q);
    let mut cc = if with_damping { damping_matrix(model, pd) } else { MatN::zeros() };
    // a compliant flank in contact ties its link side to the prescribed motor side
    let bl = &pd.params.effects.backlash;
    for (k, &p) in model.motor_idx.iter().enumerate() {
        if bl.compliant(k) && free.contains(&p) {
            kk[(p, p)] += bl.contact_k[k];
            if with_damping {
                cc[(p, p)] += bl.contact_c[k];
            }
        }
    }
    let m = DMatrix::from_fn(n, n, |i, j| mm[(free[i], free[j])]);
    let k = DMatrix::from_fn(n, n, |i, j| kk[(free[i], free[j])]);
    let c = DMatrix::from_fn(n, n, |i, j| cc[(free[i], free[j])]);
    let mi = m.clone().try_inverse().expect("mass matrix invertible");
    let mut a = DMatrix::zeros(2 * n, 2 * n);
    for i in 0..n {
        a[(i, n + i)] = 1.0;
    }
    a.view_mut((n, 0), (n, n)).copy_from(&(-&mi * &k));
    a.view_mut((n, n), (n, n)).copy_from(&(-&mi * &c));
    let eig = crate::math::eigenvalues(a.clone());
    let mut out = Vec::with_capacity(2 * n);
    for lam in eig.iter() {
        // name the joint whose own k_ii/m_ii is nearest |λ|²: a cheap estimate of where the
        // mode lives, good enough for an error message (not an eigenvector)
        let w2 = lam.norm_sqr();
        let mut best = (0usize, f64::NEG_INFINITY);
        for i in 0..n {
            let s = (k[(i, i)] - w2 * m[(i, i)]).abs();
            let score = -s / (k[(i, i)].abs() + w2 * m[(i, i)] + 1e-300);
            if score > best.1 {
                best = (i, score);
            }
        }
        out.push((*lam, free[best.0]));
    }
    out
}
