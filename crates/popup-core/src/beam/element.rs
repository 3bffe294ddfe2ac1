//! The 3D Euler–Bernoulli element: section properties of a thin-walled tube, 12×12
//! stiffness and consistent mass matrices in local axes.

use crate::error::{Error, Result};
use nalgebra::DMatrix;

/// DOFs per node: u, v, w, θx, θy, θz.
pub const NDOF_NODE: usize = 6;

/// Material and section of a thin-walled circular tube.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// Young's modulus E [Pa].
    pub e: f64,
    /// Poisson's ratio ν [-] (shear modulus G = E / (2 (1 + ν))).
    pub nu: f64,
    /// Density of the wall ρ [kg/m³].
    pub rho: f64,
    /// Mean radius of the wall r [m].
    pub r: f64,
    /// Wall thickness t [m] (thin wall: t ≪ r).
    pub t: f64,
    /// Shear deformation (Timoshenko): `false` = Euler–Bernoulli.
    pub shear: bool,
    /// Inflation pressure p [Pa] (relative); with `shear`, it stiffens the shear term as
    /// in Fichter's inflated-beam theory: κGA → κGA + p π r².
    pub pressure_pa: f64,
}

/// Shear coefficient κ of a thin-walled circular tube.
pub const KAPPA_TUBE: f64 = 0.5;

impl Section {
    /// Check every value is finite and in range (E, ρ, r, t > 0; −1 < ν < 0.5; t < r).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first bad value.
    pub fn validate(&self) -> Result<()> {
        let pos = [("beam.E", self.e, "Pa"), ("beam.rho", self.rho, "kg/m³"), ("beam.r", self.r, "m"), ("beam.t", self.t, "m")];
        for (n, v, u) in pos {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::param(n, v, format!("must be finite and > 0 {u}")));
            }
        }
        if !(self.nu.is_finite() && self.nu > -1.0 && self.nu < 0.5) {
            return Err(Error::param("beam.nu", self.nu, "Poisson's ratio must be in (-1, 0.5)"));
        }
        if self.t >= self.r {
            return Err(Error::param("beam.t", self.t, format!("a thin-walled tube needs t < r = {} m", self.r)));
        }
        if !(self.pressure_pa.is_finite() && self.pressure_pa >= 0.0) {
            return Err(Error::param("beam.pressure_pa", self.pressure_pa, "must be finite and >= 0 Pa"));
        }
        Ok(())
    }

    /// A tube of `e`, `nu`, `rho`, `r`, `t` without shear or pressure terms
    /// (Euler–Bernoulli).
    pub fn tube(e: f64, nu: f64, rho: f64, r: f64, t: f64) -> Section {
        Section { e, nu, rho, r, t, shear: false, pressure_pa: 0.0 }
    }

    /// Effective shear stiffness κGA + p π r² [N] (Fichter), +inf without shear.
    pub fn shear_stiffness(&self) -> f64 {
        if self.shear {
            KAPPA_TUBE * self.g() * self.area() + self.pressure_pa * std::f64::consts::PI * self.r * self.r
        } else {
            f64::INFINITY
        }
    }

    /// Wall area A = 2π r t [m²].
    pub fn area(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.r * self.t
    }

    /// Second moment of area about a diameter I = π r³ t [m⁴].
    pub fn i(&self) -> f64 {
        std::f64::consts::PI * self.r.powi(3) * self.t
    }

    /// Torsion constant (= polar moment for a thin circular tube) J = 2π r³ t [m⁴].
    pub fn j(&self) -> f64 {
        2.0 * self.i()
    }

    /// Shear modulus G = E / (2 (1 + ν)) [Pa].
    pub fn g(&self) -> f64 {
        self.e / (2.0 * (1.0 + self.nu))
    }

    /// Mass per length ρA [kg/m].
    pub fn mass_per_length(&self) -> f64 {
        self.rho * self.area()
    }
}

/// Write a 4×4 bending block into `k` at DOFs `idx` (v₁/w₁, θ₁, v₂/w₂, θ₂); `s` = +1 for
/// the x–y plane (v, θz), −1 for x–z (w, θy), where θy = −dw/dx.
fn bending_block(k: &mut DMatrix<f64>, idx: [usize; 4], a: [[f64; 4]; 4], s: f64) {
    // the rotation DOFs (1, 3) flip sign in the x–z plane
    let sg = [1.0, s, 1.0, s];
    for i in 0..4 {
        for j in 0..4 {
            k[(idx[i], idx[j])] += a[i][j] * sg[i] * sg[j];
        }
    }
}

/// Element stiffness (12×12, local axes) of length `l` [m].
pub fn element_stiffness(s: &Section, l: f64) -> DMatrix<f64> {
    let mut k = DMatrix::zeros(12, 12);
    let ea = s.e * s.area() / l;
    let gj = s.g() * s.j() / l;
    for (a, c) in [(0, ea), (3, gj)] {
        k[(a, a)] += c;
        k[(a + 6, a + 6)] += c;
        k[(a, a + 6)] -= c;
        k[(a + 6, a)] -= c;
    }
    // shear parameter Φ = 12 EI / (κGA L²) (0: Euler–Bernoulli); Przemieniecki's element
    let ei = s.e * s.i();
    let phi = 12.0 * ei / (s.shear_stiffness() * l * l);
    let c = ei / ((1.0 + phi) * l.powi(3));
    let l2 = l * l;
    let b = [
        [12.0 * c, 6.0 * l * c, -12.0 * c, 6.0 * l * c],
        [6.0 * l * c, (4.0 + phi) * l2 * c, -6.0 * l * c, (2.0 - phi) * l2 * c],
        [-12.0 * c, -6.0 * l * c, 12.0 * c, -6.0 * l * c],
        [6.0 * l * c, (2.0 - phi) * l2 * c, -6.0 * l * c, (4.0 + phi) * l2 * c],
    ];
    bending_block(&mut k, [1, 5, 7, 11], b, 1.0);
    bending_block(&mut k, [2, 4, 8, 10], b, -1.0);
    k
}

/// Consistent element mass (12×12, local axes) of length `l` [m]: the Euler–Bernoulli
/// (cubic Hermite) mass also with `shear` (rotary inertia neglected, as in the stiffness).
pub fn element_mass(s: &Section, l: f64) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(12, 12);
    let ml = s.mass_per_length() * l;
    // axial: ρAL/6 [2 1; 1 2]; twist: ρ J L/6 [2 1; 1 2] (polar inertia per length ρ J)
    for (a, c) in [(0, ml / 6.0), (3, s.rho * s.j() * l / 6.0)] {
        m[(a, a)] += 2.0 * c;
        m[(a + 6, a + 6)] += 2.0 * c;
        m[(a, a + 6)] += c;
        m[(a + 6, a)] += c;
    }
    let c = ml / 420.0;
    let l2 = l * l;
    let b = [
        [156.0 * c, 22.0 * l * c, 54.0 * c, -13.0 * l * c],
        [22.0 * l * c, 4.0 * l2 * c, 13.0 * l * c, -3.0 * l2 * c],
        [54.0 * c, 13.0 * l * c, 156.0 * c, -22.0 * l * c],
        [-13.0 * l * c, -3.0 * l2 * c, -22.0 * l * c, 4.0 * l2 * c],
    ];
    bending_block(&mut m, [1, 5, 7, 11], b, 1.0);
    bending_block(&mut m, [2, 4, 8, 10], b, -1.0);
    m
}

/// Consistent rotary-inertia mass of the bending rotations (12×12, local axes) of length
/// `l` [m] with rotary inertia per length `rho_i` [kg·m] (ρI of the section about a
/// diameter; for a thin tube ρA r²/2): `ρI/(30 l) [36, 3l, −36, 3l; 3l, 4l², −3l, −l²; …]`
/// per plane (Rayleigh beam). Added to [`element_mass`] it makes the element's kinetic
/// energy exact for rigid rotations of a thick-ish tube (r/L of the POP-UP links is 0.1–0.15).
pub fn element_rotary_mass(rho_i: f64, l: f64) -> DMatrix<f64> {
    let mut m = DMatrix::zeros(12, 12);
    let c = rho_i / (30.0 * l);
    let l2 = l * l;
    let b = [
        [36.0 * c, 3.0 * l * c, -36.0 * c, 3.0 * l * c],
        [3.0 * l * c, 4.0 * l2 * c, -3.0 * l * c, -l2 * c],
        [-36.0 * c, -3.0 * l * c, 36.0 * c, -3.0 * l * c],
        [3.0 * l * c, -l2 * c, -3.0 * l * c, 4.0 * l2 * c],
    ];
    bending_block(&mut m, [1, 5, 7, 11], b, 1.0);
    bending_block(&mut m, [2, 4, 8, 10], b, -1.0);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tube() -> Section {
        Section::tube(0.557e9, 0.3, 1000.0, 0.05, 1.2e-3)
    }

    /// Symmetric, rigid-body modes (translations, rotations about the axes) cost no energy,
    /// and the mass matrix gives back the element's mass for a translation.
    #[test]
    fn rigid_body_modes_are_free_and_mass_is_right() {
        let s = tube();
        let l = 0.3;
        let k = element_stiffness(&s, l);
        let m = element_mass(&s, l);
        assert!((&k - k.transpose()).amax() < 1e-9 * k.amax());
        assert!((&m - m.transpose()).amax() < 1e-15 * m.amax());
        // translations along x, y, z; rotation about y: w = −θ x (θy = −dw/dx = θ); about z: v = θ x
        let mut modes = Vec::new();
        for d in 0..3 {
            let mut u = nalgebra::DVector::zeros(12);
            u[d] = 1.0;
            u[6 + d] = 1.0;
            modes.push(u);
        }
        let mut ry = nalgebra::DVector::zeros(12);
        ry[4] = 1.0;
        ry[10] = 1.0;
        ry[8] = -l;
        let mut rz = nalgebra::DVector::zeros(12);
        rz[5] = 1.0;
        rz[11] = 1.0;
        rz[7] = l;
        let mut rx = nalgebra::DVector::zeros(12);
        rx[3] = 1.0;
        rx[9] = 1.0;
        modes.extend([rx, ry, rz]);
        for u in &modes {
            assert!((&k * u).amax() < 1e-9 * k.amax(), "{u}");
        }
        let mass = (modes[1].transpose() * &m * &modes[1])[(0, 0)];
        assert!((mass - s.mass_per_length() * l).abs() < 1e-12 * mass);
    }

    #[test]
    fn bad_sections_are_refused_by_name() {
        let mut s = tube();
        s.t = 0.06;
        assert!(s.validate().unwrap_err().to_string().contains("beam.t"));
        s = tube();
        s.nu = 0.5;
        assert!(s.validate().unwrap_err().to_string().contains("beam.nu"));
        s = tube();
        s.e = f64::NAN;
        assert!(s.validate().unwrap_err().to_string().contains("beam.E"));
    }
}
