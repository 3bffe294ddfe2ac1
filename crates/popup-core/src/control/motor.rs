//! Motoreducer: the drive between the velocity controller and the joint.
//!
//! The velocity PI outputs a command `u` in the thesis's drive units; the motoreducer turns
//! it into a torque reference at the joint output `τ* = c_u · u`, limits it to `±τ_max`
//! (the current limit times the torque constant and the gear ratio), and its current loop
//! makes the applied torque follow the limited reference as a first-order lag of bandwidth
//! `ω_i`, discretised exactly for the held reference:
//! `τ_k = τ_{k−1} + α (sat(τ*_k) − τ_{k−1})`, `α = 1 − exp(−ω_i T)`.
//! The reflected rotor inertia `J_r N²` is the arm file's `[motors] armature_kgm2` (it is
//! part of the multibody, not of this struct). The encoder sits on the motor side: with
//! `encoder_counts` per motor revolution and gear ratio `N`, the joint angle the
//! controller sees is quantised to `2π / (counts · N)` rad.

use crate::error::{Error, Result};

/// One motoreducer (values at the joint output unless stated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motoreducer {
    /// Gear ratio N (motor turns per joint turn) [-].
    pub gear_ratio: f64,
    /// Joint torque per drive unit of velocity-PI output, c_u [N·m].
    pub torque_per_unit: f64,
    /// Torque limit at the joint output, τ_max [N·m] (`∞` = none).
    pub tau_max: f64,
    /// Current-loop bandwidth ω_i [rad/s] (`∞` = ideal torque source).
    pub current_bandwidth: f64,
    /// Encoder counts per motor revolution (0 = ideal, unquantised angle).
    pub encoder_counts: u32,
}

impl Motoreducer {
    /// The defaults fitted to the thesis's Tables 5–9 (see `docs/control.md`,
    /// "Motoreducer fit"): a shared motoreducer on all three joints.
    pub const DEFAULT: Motoreducer =
        Motoreducer { gear_ratio: 100.0, torque_per_unit: 0.1014, tau_max: 66.83, current_bandwidth: 6283.0, encoder_counts: 4096 };

    /// Joint-side encoder resolution [rad] (0 for an ideal encoder).
    pub fn resolution(&self) -> f64 {
        if self.encoder_counts == 0 {
            0.0
        } else {
            2.0 * std::f64::consts::PI / (self.encoder_counts as f64 * self.gear_ratio)
        }
    }

    /// The joint angle the encoder reports for the true angle `q` [rad].
    #[inline]
    pub fn encode(&self, q: f64) -> f64 {
        let r = self.resolution();
        if r > 0.0 {
            (q / r).round() * r
        } else {
            q
        }
    }

    /// Check every field; `what` prefixes the error path (e.g. `controller.motors[1]`).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a non-positive or non-finite gear ratio or torque per
    /// unit, a NaN or non-positive torque limit or current bandwidth.
    pub fn validate(&self, what: &str) -> Result<()> {
        let pos_finite = [("gear_ratio", self.gear_ratio), ("torque_per_unit", self.torque_per_unit)];
        for (n, v) in pos_finite {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::param(format!("{what}.{n}"), v, "must be finite and > 0"));
            }
        }
        for (n, v) in [("tau_max", self.tau_max), ("current_bandwidth", self.current_bandwidth)] {
            if v.is_nan() || v <= 0.0 {
                return Err(Error::param(format!("{what}.{n}"), v, "must be > 0 (inf = no limit)"));
            }
        }
        Ok(())
    }
}

impl Default for Motoreducer {
    fn default() -> Self {
        Motoreducer::DEFAULT
    }
}
