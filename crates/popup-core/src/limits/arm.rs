//! What an arm can physically produce, derived from its description: the torque limit of
//! each drive (the arm file's `motors.tau_max_nm`) and a bound on the accelerations its
//! joints and IMU mounts can reach. [`super::for_arm`] scales the plausibility limits of
//! measured torques and accelerations by these numbers, so a different arm gets different
//! limits.
//!
//! The bound, at each configuration of a grid (q2, q3 over whole turns in π/4 steps,
//! bending at zero, no payload: the least inertia):
//!
//! - generalised force bound `f_i`: a motor joint's drive torque `tau_max` plus its
//!   gravity torque `|G_i(q)|`; a bending joint carries at most its link's collapse moment
//!   (`collapse_factor × coef · p · r³` at the stiffness table's highest pressure: beyond
//!   it the tube kinks) plus `|G_i(q)|`;
//! - joint acceleration `|q̈_j| ≤ Σ_i |M⁻¹(q)_ji| f_i` [rad/s²] (M with armature);
//! - IMU mount: `|a − g| ≤ Σ_i |(J M⁻¹)_{:,i}| f_i + |g|` [m/s²], J the mount's
//!   translational Jacobian (central differences): what each joint's force bound does
//!   there, added up.
//!
//! The maximum over the grid is taken. Velocity terms (centripetal, Coriolis) are left
//! out: at the drives' speeds (a few rad/s) they are smaller than the torque-driven terms,
//! and the plausibility factors ([`super::ARM_ACCEL_WARN`], [`super::ARM_ACCEL_ERROR`])
//! leave room for them.

use crate::error::{Error, Result};
use crate::kinematics::prbm::frames;
use crate::math::{VecN, NM};
use crate::model::{Model, Options};
use crate::params::{ParamData, Params};
use crate::spec::ArmSpec;
use crate::statics::{gravity_torque, mass_matrix};
use nalgebra::DMatrix;

/// What an arm's drives and links can produce (see the module docs for the derivation).
#[derive(Debug, Clone, PartialEq)]
pub struct ArmReach {
    /// Arm name.
    pub arm: String,
    /// Drive torque limit of q1, q2, q3 [N·m] (`motors.tau_max_nm`).
    pub tau_max_nm: [f64; NM],
    /// Collapse moment of link 1 and link 2 at the stiffness table's highest pressure
    /// [N·m]: the most a bending joint carries.
    pub collapse_nm: [f64; 2],
    /// Bound on the angular acceleration of each chain joint (7 for the nominal chain)
    /// [rad/s²].
    pub joint_accel: Vec<f64>,
    /// Bound on the motor joints' angular accelerations q̈1..q̈3 [rad/s²].
    pub motor_accel: [f64; NM],
    /// Bound on the specific force `|a − g|` at IMU 1 (tip of link 1) and IMU 2 (tip of
    /// link 2) [m/s²].
    pub imu_accel: [f64; 2],
}

/// Steps of the configuration grid per joint (q2 and q3 over a whole turn).
const GRID: usize = 8;

/// The reach of arm `spec` (module docs).
///
/// # Errors
/// The arm's compile errors ([`Error::InvalidParameter`] naming the arm-file key); an
/// [`Error::Singular`] when the mass matrix cannot be inverted (a body without inertia).
pub fn reach(spec: &ArmSpec) -> Result<ArmReach> {
    let model = Model::compile(spec, Options::default())?;
    let table = &spec.stiffness.pressure_pa;
    let p_max = table.iter().copied().fold(0.0_f64, f64::max);
    let params = Params { payload_kg: 0.0, pressure_pa: [p_max; 2], effects: Default::default() };
    let pd = ParamData::new(&model, &params)?;
    let collapse_nm: [f64; 2] =
        std::array::from_fn(|l| spec.wrinkling.collapse_factor * model.wrinkle_coef * p_max * model.link_radius[l].powi(3));
    let tau_max_nm = spec.motors.tau_max_nm;
    let nv = model.nv;
    let g = model.gravity.norm();
    let mut joint_accel = vec![0.0_f64; nv];
    let mut imu_accel = [0.0_f64; 2];
    let step = 2.0 * std::f64::consts::PI / GRID as f64;
    for a in 0..GRID {
        for b in 0..GRID {
            let mut q = VecN::zeros();
            q[model.motor_idx[1]] = -std::f64::consts::PI + step * a as f64;
            q[model.motor_idx[2]] = -std::f64::consts::PI + step * b as f64;
            let m = mass_matrix(&model, &pd, &q);
            let minv = DMatrix::from_fn(nv, nv, |i, j| m[(i, j)])
                .try_inverse()
                .ok_or_else(|| Error::Singular(format!("arm {}: the mass matrix at q = {:?} is singular", spec.name, &q.as_slice()[..nv])))?;
            let grav = gravity_torque(&model, &pd, &q);
            let f: Vec<f64> = (0..nv)
                .map(|i| {
                    let drive = match model.motor_idx.iter().position(|&k| k == i) {
                        Some(k) => tau_max_nm[k],
                        None => collapse_nm[model.joints[i].link.clamp(1, 2) - 1],
                    };
                    drive + grav[i].abs()
                })
                .collect();
            let qdd: Vec<f64> = (0..nv).map(|j| (0..nv).map(|i| minv[(j, i)].abs() * f[i]).sum()).collect();
            for j in 0..nv {
                joint_accel[j] = joint_accel[j].max(qdd[j]);
            }
            for (s, acc) in imu_accel.iter_mut().enumerate() {
                // the mount's linear acceleration J_s q̈ = (J_s M⁻¹) f: column i of J_s M⁻¹
                // is what a unit force at joint i does there
                let (body, p) = model.imu[s];
                let at = |q: &VecN| frames(&model, q).point(body + 1, &p);
                let h = 1e-6;
                let js = DMatrix::from_fn(3, nv, |r, j| {
                    let (mut qp, mut qm) = (q, q);
                    qp[j] += h;
                    qm[j] -= h;
                    (at(&qp)[r] - at(&qm)[r]) / (2.0 * h)
                });
                let a = js * &minv;
                let lin: f64 = (0..nv).map(|i| a.column(i).norm() * f[i]).sum();
                *acc = acc.max(lin + g);
            }
        }
    }
    let motor_accel = std::array::from_fn(|k| joint_accel[model.motor_idx[k]]);
    Ok(ArmReach { arm: spec.name.clone(), tau_max_nm, collapse_nm, joint_accel, motor_accel, imu_accel })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_follows_the_arm() {
        let lab = ArmSpec::popup_lab();
        let r = reach(&lab).unwrap();
        // a drive torque turns its armature at least: q̈ ≤ tau_max / armature, and more
        // than tau_max / (armature + the whole arm about the axis, under 5 kg·m²)
        let arm0 = lab.motors.armature_kgm2[0];
        assert!(r.motor_accel[0] >= r.tau_max_nm[0] / (arm0 + 5.0) && r.motor_accel[0] < 10.0 * r.tau_max_nm[0] / arm0, "{r:?}");
        // an IMU reads at least gravity, and the tip of link 2 moves more than that of link 1
        assert!(r.imu_accel[0] > 9.81 && r.imu_accel[1] > r.imu_accel[0], "{r:?}");
        // stronger drives: larger motor accelerations (the links follow through their
        // springs, which carry at most the collapse moment)
        let mut strong = lab.clone();
        strong.motors.tau_max_nm = [10.0 * lab.motors.tau_max_nm[0]; 3];
        let rs = reach(&strong).unwrap();
        assert!(rs.motor_accel[0] > 2.0 * r.motor_accel[0], "{rs:?} vs {r:?}");
        assert_eq!(rs.tau_max_nm, strong.motors.tau_max_nm);
        // lighter armature: larger motor accelerations
        let mut light = lab.clone();
        light.motors.armature_kgm2 = [0.05; 3];
        assert!(reach(&light).unwrap().motor_accel[0] > 1.5 * r.motor_accel[0]);
        // links that carry more before they collapse: larger tip accelerations
        let mut stiff = lab.clone();
        stiff.wrinkling.collapse_factor *= 4.0;
        let rk = reach(&stiff).unwrap();
        assert!(rk.collapse_nm[1] == 4.0 * r.collapse_nm[1] && rk.imu_accel[1] > 2.0 * r.imu_accel[1], "{rk:?} vs {r:?}");
        // a lighter tip link (the thesis arm's 0.104 kg outer piece): larger tip accelerations
        let thesis = ArmSpec::from_toml("base = \"popup-lab\"\nbodies = [{}, {}, {}, {}, {}, {}, { parts = [{ mass_kg = 0.10402 }] }]\n", "t").unwrap();
        assert!(reach(&thesis).unwrap().imu_accel[1] > 1.5 * r.imu_accel[1]);
    }

    #[test]
    fn a_bad_drive_limit_is_named() {
        let mut s = ArmSpec::popup_lab();
        s.motors.tau_max_nm[1] = 0.0;
        let e = reach(&s).unwrap_err().to_string();
        assert!(e.contains("motors.tau_max_nm[1]"), "{e}");
    }
}
