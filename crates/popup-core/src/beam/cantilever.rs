//! A cantilever of `n` equal elements clamped at x = 0, with a point mass at the tip:
//! static tip response, undamped modes (K φ = ω² M φ), Rayleigh damping.

use super::element::{element_mass, element_stiffness, Section, NDOF_NODE};
use crate::error::{Error, Result};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// A clamped beam: the free DOFs (nodes 1..=n, 6 each) and their matrices.
#[derive(Debug, Clone, PartialEq)]
pub struct Cantilever {
    /// Material and section.
    pub section: Section,
    /// Length L [m].
    pub length: f64,
    /// Number of elements.
    pub n: usize,
    /// Point mass at the tip [kg] (translational DOFs of the last node).
    pub tip_mass: f64,
    /// Stiffness of the free DOFs (6n × 6n) [N/m, N, N·m/rad].
    pub k: DMatrix<f64>,
    /// Consistent mass of the free DOFs (6n × 6n), tip mass included [kg, kg·m, kg·m²].
    pub m: DMatrix<f64>,
}

/// What a mode mostly moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModeKind {
    /// u.
    Axial,
    /// v, θz (bending in the x–y plane).
    BendingY,
    /// w, θy (bending in the x–z plane).
    BendingZ,
    /// θx.
    Torsion,
}

/// Undamped modes, ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct Modes {
    /// Angular frequencies ω [rad/s].
    pub omega: Vec<f64>,
    /// Mass-normalised shapes (columns, φᵀ M φ = 1).
    pub shapes: DMatrix<f64>,
    /// What each mode mostly moves (largest share of its kinetic energy).
    pub kind: Vec<ModeKind>,
}

impl Modes {
    /// The first `count` frequencies of one kind [rad/s].
    pub fn of(&self, kind: ModeKind, count: usize) -> Vec<f64> {
        self.omega.iter().zip(&self.kind).filter(|(_, k)| **k == kind).map(|(w, _)| *w).take(count).collect()
    }
}

/// Assemble `n` equal 12×12 element matrices end to end and keep the DOFs of the free
/// nodes 1..=n (node 0 clamped): a 6n × 6n matrix.
pub(crate) fn assemble_free(n: usize, ke: &DMatrix<f64>) -> DMatrix<f64> {
    let nd = NDOF_NODE * (n + 1);
    let mut full = DMatrix::zeros(nd, nd);
    for e in 0..n {
        let o = NDOF_NODE * e;
        for i in 0..12 {
            for j in 0..12 {
                full[(o + i, o + j)] += ke[(i, j)];
            }
        }
    }
    let free = nd - NDOF_NODE;
    full.view((NDOF_NODE, NDOF_NODE), (free, free)).into_owned()
}

impl Cantilever {
    /// Assemble `n` elements over `length` [m] with `tip_mass` [kg].
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a bad section, length, element count or tip mass.
    pub fn new(section: Section, length: f64, n: usize, tip_mass: f64) -> Result<Cantilever> {
        section.validate()?;
        if !(length.is_finite() && length > 0.0) {
            return Err(Error::param("beam.length", length, "must be finite and > 0 m"));
        }
        if n == 0 {
            return Err(Error::param("beam.elements", n, "a beam needs at least one element"));
        }
        if !(tip_mass.is_finite() && tip_mass >= 0.0) {
            return Err(Error::param("beam.tip_mass", tip_mass, "must be finite and >= 0 kg"));
        }
        let l = length / n as f64;
        let k = assemble_free(n, &element_stiffness(&section, l));
        let mut m = assemble_free(n, &element_mass(&section, l));
        let tip = NDOF_NODE * (n - 1);
        for d in 0..3 {
            m[(tip + d, tip + d)] += tip_mass;
        }
        Ok(Cantilever { section, length, n, tip_mass, k, m })
    }

    /// Static displacement of the tip node [u, v, w, θx, θy, θz] under a tip load
    /// [Fx, Fy, Fz, Mx, My, Mz] [N, N·m].
    ///
    /// # Errors
    /// [`Error::Singular`] if the stiffness cannot be factorised (cannot happen when clamped).
    pub fn static_tip(&self, load: [f64; 6]) -> Result<[f64; 6]> {
        let nf = self.k.nrows();
        let mut f = DVector::zeros(nf);
        for (i, v) in load.iter().enumerate() {
            f[nf - NDOF_NODE + i] = *v;
        }
        let ch = self.k.clone().cholesky().ok_or_else(|| Error::Singular("beam stiffness is not positive definite".into()))?;
        let u = ch.solve(&f);
        Ok(std::array::from_fn(|i| u[nf - NDOF_NODE + i]))
    }

    /// Undamped modes: K φ = ω² M φ through the Cholesky factor of M.
    ///
    /// # Errors
    /// [`Error::Singular`] if M is not positive definite.
    pub fn modes(&self) -> Result<Modes> {
        let ch = self.m.clone().cholesky().ok_or_else(|| Error::Singular("beam mass is not positive definite".into()))?;
        let lo = ch.l();
        let linv = lo.clone().try_inverse().ok_or_else(|| Error::Singular("beam mass factor".into()))?;
        let a = &linv * &self.k * linv.transpose();
        let a = (&a + a.transpose()) * 0.5;
        let eig = SymmetricEigen::new(a);
        let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
        order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
        let nf = self.k.nrows();
        let mut shapes = DMatrix::zeros(nf, nf);
        let mut omega = Vec::with_capacity(nf);
        let mut kind = Vec::with_capacity(nf);
        for (c, &i) in order.iter().enumerate() {
            omega.push(eig.eigenvalues[i].max(0.0).sqrt());
            let phi = linv.transpose() * eig.eigenvectors.column(i);
            let mphi = &self.m * &phi;
            let mut share = [0.0; 4];
            for r in 0..nf {
                let e = phi[r] * mphi[r];
                let k = match r % NDOF_NODE {
                    0 => 0,
                    1 | 5 => 1,
                    2 | 4 => 2,
                    _ => 3,
                };
                share[k] += e;
            }
            let best = (0..4).max_by(|&a, &b| share[a].total_cmp(&share[b])).unwrap_or(0);
            kind.push([ModeKind::Axial, ModeKind::BendingY, ModeKind::BendingZ, ModeKind::Torsion][best]);
            shapes.set_column(c, &phi);
        }
        Ok(Modes { omega, shapes, kind })
    }
}

/// Rayleigh damping C = μ M + λ K: modal damping ratio ζ(ω) = μ/(2ω) + λω/2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rayleigh {
    /// Mass-proportional coefficient μ [1/s].
    pub mu: f64,
    /// Stiffness-proportional coefficient λ [s].
    pub lambda: f64,
}

impl Rayleigh {
    /// μ, λ giving ratio `z1` at `w1` and `z2` at `w2` [rad/s], w1 ≠ w2.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for non-positive or equal frequencies, negative ratios,
    /// or ratios that need a negative coefficient (C would not be dissipative).
    pub fn from_ratios(w1: f64, z1: f64, w2: f64, z2: f64) -> Result<Rayleigh> {
        for (n, w) in [("w1", w1), ("w2", w2)] {
            if !(w.is_finite() && w > 0.0) {
                return Err(Error::param(format!("rayleigh.{n}"), w, "must be finite and > 0 rad/s"));
            }
        }
        if (w1 - w2).abs() <= 1e-12 * w1.max(w2) {
            return Err(Error::param("rayleigh.w2", w2, "must differ from w1"));
        }
        for (n, z) in [("z1", z1), ("z2", z2)] {
            if !(z.is_finite() && z >= 0.0) {
                return Err(Error::param(format!("rayleigh.{n}"), z, "must be finite and >= 0"));
            }
        }
        // [1/(2 w1)  w1/2; 1/(2 w2)  w2/2] [μ; λ] = [z1; z2]
        let det = w2 / (4.0 * w1) - w1 / (4.0 * w2);
        let mu = (z1 * w2 / 2.0 - z2 * w1 / 2.0) / det;
        let lambda = (z2 / (2.0 * w1) - z1 / (2.0 * w2)) / det;
        if mu < 0.0 || lambda < 0.0 {
            return Err(Error::param(
                "rayleigh",
                format!("z1 = {z1} at {w1} rad/s, z2 = {z2} at {w2} rad/s"),
                format!("needs mu = {mu:.4e} 1/s, lambda = {lambda:.4e} s: a negative coefficient (not dissipative); pick ratios with z2/z1 between w1/w2 and w2/w1"),
            ));
        }
        Ok(Rayleigh { mu, lambda })
    }

    /// μ, λ from the computed `modes`: ratio `z1` on the `k1`-th and `z2` on the `k2`-th
    /// mode of `kind` (0-based). Returns warnings when a request lands on another mode
    /// than the same index of the whole spectrum would (another kind of mode lies below:
    /// asking "mode 2" by index would have damped the wrong one), and for every mode the
    /// result overdamps (ζ ≥ 1).
    ///
    /// # Errors
    /// A missing mode, and as [`Rayleigh::from_ratios`].
    pub fn for_modes(modes: &Modes, kind: ModeKind, (k1, z1): (usize, f64), (k2, z2): (usize, f64)) -> Result<(Rayleigh, Vec<String>)> {
        let idx: Vec<usize> = (0..modes.omega.len()).filter(|&i| modes.kind[i] == kind).collect();
        let pick = |k: usize| {
            idx.get(k).copied().ok_or_else(|| Error::param("rayleigh.mode", k, format!("the beam has {} {kind:?} modes", idx.len())))
        };
        let (i1, i2) = (pick(k1)?, pick(k2)?);
        let r = Rayleigh::from_ratios(modes.omega[i1], z1, modes.omega[i2], z2)?;
        let mut warn = Vec::new();
        for (k, i) in [(k1, i1), (k2, i2)] {
            if i != k {
                warn.push(format!(
                    "{kind:?} mode {k} is mode {i} of the spectrum ({:.2} rad/s); mode {k} of the spectrum is {:?} at {:.2} rad/s: a ratio given by spectrum index would land on the wrong mode",
                    modes.omega[i], modes.kind[k], modes.omega[k]
                ));
            }
        }
        for (i, w) in modes.omega.iter().enumerate() {
            if r.ratio(*w) >= 1.0 {
                warn.push(format!("mode {i} ({:?}, {w:.2} rad/s) is overdamped: zeta = {:.3}", modes.kind[i], r.ratio(*w)));
                break;
            }
        }
        Ok((r, warn))
    }

    /// Modal damping ratio at ω [rad/s].
    pub fn ratio(&self, w: f64) -> f64 {
        self.mu / (2.0 * w) + self.lambda * w / 2.0
    }
}
