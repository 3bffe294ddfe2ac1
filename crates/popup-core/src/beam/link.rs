//! A beam link of the arm (`higher_bending_modes.elements = n`): the link's outer part as a
//! clamped Euler–Bernoulli beam of `n` elements in the floating frame of its root body.
//!
//! The chain carries the beam as `2n` universal joints, two per element: one at the element's
//! start turning a rigid chord bar of length h = L/n (which carries the element's mass), one
//! at its end (zero length) setting the node's rotation. Their 4n angles φ map linearly
//! (to first order) onto the FE nodal coordinates η = (v, w, θy, θz) of nodes 1..n in the
//! link frame B (x along the link): η = T φ, T from the chain's geometry at φ = 0, square
//! and invertible. The elastic forces are those of the FE model, `K_φ = Tᵀ K T`,
//! `C_φ = Tᵀ (μ M + λ K) T`. The mass is the chain's own: the chord bars carry the tube's
//! mass and the section rotary inertia is lumped at the nodes (a rigid-finite-element mass;
//! the consistent-mass correction `Tᵀ M T − M_bars` made the arm's mass matrix indefinite
//! and was dropped, docs/beams.md; [`BeamLink::joint_mass`] is kept for comparisons).
//! Downstream bodies (next motor, next link, payload) ride on the tip node's frame, so the
//! tip masses are the chain's own bodies.

use super::cantilever::assemble_free;
use super::element::{element_mass, element_rotary_mass, element_stiffness, Section, NDOF_NODE};
use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// Bending DOFs of a node among its 6 (v, w, θy, θz).
const BEND: [usize; 4] = [1, 2, 4, 5];

/// Material and damping of a beam link (the `higher_bending_modes` parameters of one link).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamMaterial {
    /// Young's modulus E [Pa].
    pub e: f64,
    /// Wall thickness t [m] (I = π r³ t with the link's radius).
    pub t: f64,
    /// Poisson's ratio ν [1] (shear modulus, with `shear`).
    pub nu: f64,
    /// Stiffness-proportional Rayleigh coefficient λ [s] (C = μ M + λ K).
    pub lambda: f64,
    /// Mass-proportional Rayleigh coefficient μ [1/s].
    pub mu: f64,
    /// Timoshenko shear deformation with Fichter's pressure term (κGA + p π r²).
    pub shear: bool,
}

/// The thesis's fitted FEM-link values (its section 2.3) as named presets: E with the wall
/// thickness it was fitted for and its stiffness-proportional damping coefficient. The
/// thesis prints λ as 3.896 × 10⁴ s and 3.4919 × 10⁴ s, which would make every mode
/// overdamped (ζ₁ = λω₁/2 ≈ 10⁶); the values here are × 10⁻⁴ s, which give the lightly
/// damped responses it shows (docs/beams.md).
pub const PRESETS: [(&str, BeamMaterial); 2] = [
    ("thesis-1.2mm", BeamMaterial { e: 0.557e9, t: 1.2e-3, nu: 0.3, lambda: 3.896e-4, mu: 0.0, shear: false }),
    ("thesis-0.8mm", BeamMaterial { e: 794.9e6, t: 0.8e-3, nu: 0.3, lambda: 3.4919e-4, mu: 0.0, shear: false }),
];

impl BeamMaterial {
    /// A preset by name ([`PRESETS`]).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an unknown name (the message lists the known ones).
    pub fn preset(name: &str) -> Result<BeamMaterial> {
        PRESETS.iter().find(|(n, _)| *n == name).map(|(_, m)| *m).ok_or_else(|| {
            let names: Vec<&str> = PRESETS.iter().map(|(n, _)| *n).collect();
            Error::param("beam preset", format!("{name:?}"), format!("unknown; known presets: {}", names.join(", ")))
        })
    }
}

/// A beam link compiled into the chain.
#[derive(Debug, Clone, PartialEq)]
pub struct BeamLink {
    /// Link (0 or 1).
    pub link: usize,
    /// Elements n.
    pub n: usize,
    /// First chain joint of the link's 4n beam joints (contiguous).
    pub start: usize,
    /// Beam length L (root universal joint → link tip) [m].
    pub length: f64,
    /// Tube radius r [m].
    pub radius: f64,
    /// Mass per length ρA of the beam (the link's outer tube) [kg/m].
    pub mass_per_length: f64,
    /// η = T φ: nodal (v, w, θy, θz of nodes 1..n, link-frame axes) from the chain's beam
    /// joint angles (4n × 4n) [m/rad, 1].
    pub t_map: DMatrix<f64>,
    /// Consistent nodal mass of the free nodes, bending DOFs, rotary inertia included (4n × 4n).
    pub m_nodal: DMatrix<f64>,
}

/// The free nodes' bending DOFs (v, w, θy, θz of nodes 1..n) of `n` assembled elements.
fn assemble_bending(n: usize, ke: &DMatrix<f64>) -> DMatrix<f64> {
    let free = assemble_free(n, ke);
    let idx: Vec<usize> = (0..n).flat_map(|node| BEND.iter().map(move |&d| NDOF_NODE * node + d)).collect();
    DMatrix::from_fn(4 * n, 4 * n, |i, j| free[(idx[i], idx[j])])
}

impl BeamLink {
    /// A beam link of `n` elements starting at chain joint `start`, with its geometry map
    /// `t_map` (4n × 4n) and mass per length [kg/m].
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a singular map (the chain does not span the nodal
    /// coordinates) or non-positive dimensions.
    pub fn new(link: usize, n: usize, start: usize, length: f64, radius: f64, mass_per_length: f64, t_map: DMatrix<f64>) -> Result<BeamLink> {
        let what = format!("higher_bending_modes.elements[{link}] (link {})", link + 1);
        if !(length > 0.0 && radius > 0.0 && mass_per_length.is_finite() && mass_per_length >= 0.0) {
            return Err(Error::param(what, n, format!("needs a tube of positive length and radius (L = {length} m, r = {radius} m, ρA = {mass_per_length} kg/m)")));
        }
        let sv = t_map.clone().svd(false, false).singular_values;
        if t_map.nrows() != 4 * n || t_map.ncols() != 4 * n || !(sv.min() > 1e-10 * sv.max()) {
            return Err(Error::param(what, n, "the chain's beam joints do not span the nodal coordinates (singular map)"));
        }
        let h = length / n as f64;
        // mass only: the section's E and t do not enter the mass, ρA and ρI come from the arm file
        let area = 2.0 * std::f64::consts::PI * radius * 1e-3;
        let s = Section::tube(1.0, 0.3, mass_per_length / area, radius, 1e-3);
        let me = element_mass(&s, h) + element_rotary_mass(mass_per_length * radius * radius / 2.0, h);
        let m_nodal = assemble_bending(n, &me);
        Ok(BeamLink { link, n, start, length, radius, mass_per_length, t_map, m_nodal })
    }

    /// Number of chain joints of the beam (4n).
    pub fn dof(&self) -> usize {
        4 * self.n
    }

    /// The section for a material at inflation pressure `p` [Pa].
    pub fn section(&self, mat: &BeamMaterial, p: f64) -> Section {
        let area = 2.0 * std::f64::consts::PI * self.radius * mat.t;
        Section { e: mat.e, nu: mat.nu, rho: self.mass_per_length / area, r: self.radius, t: mat.t, shear: mat.shear, pressure_pa: p }
    }

    /// Nodal bending stiffness of the free nodes (4n × 4n) [N/m, N, N·m/rad].
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a bad section (names the value).
    pub fn nodal_stiffness(&self, mat: &BeamMaterial, p: f64) -> Result<DMatrix<f64>> {
        let s = self.section(mat, p);
        s.validate()?;
        Ok(assemble_bending(self.n, &element_stiffness(&s, self.length / self.n as f64)))
    }

    /// Elastic stiffness and Rayleigh damping in the chain's beam-joint coordinates:
    /// `(Tᵀ K T, Tᵀ (μ M + λ K) T)` (4n × 4n) [N·m/rad, N·m·s/rad].
    ///
    /// # Errors
    /// As [`BeamLink::nodal_stiffness`].
    pub fn joint_matrices(&self, mat: &BeamMaterial, p: f64) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
        let k = self.nodal_stiffness(mat, p)?;
        let t = &self.t_map;
        let kj = t.transpose() * &k * t;
        let cj = t.transpose() * (&self.m_nodal * mat.mu + &k * mat.lambda) * t;
        Ok(((&kj + kj.transpose()) * 0.5, (&cj + cj.transpose()) * 0.5))
    }

    /// The consistent mass in chain coordinates, `Tᵀ M T` (4n × 4n) [kg·m²]; not used by the
    /// arm's dynamics (see the module docs).
    pub fn joint_mass(&self) -> DMatrix<f64> {
        let m = self.t_map.transpose() * &self.m_nodal * &self.t_map;
        (&m + m.transpose()) * 0.5
    }
}
