//! The effect library: optional physical terms that the nominal model leaves out
//! (`effects.md`). Each effect has named parameters with units, bounds and a neutral value;
//! at its neutral value an effect is skipped entirely, so the model is bit-identical to
//! the nominal one.
//!
//! Effects are per-rollout numbers ([`crate::params::Params::effects`]), so a fit can vary
//! them across a batch. Two effects change the joint structure (`higher_bending_modes`,
//! `torsion`); the structure is taken from the arm file's `[effects]` table when the model
//! is compiled, and the rollout may then vary their continuous parameters.
//!
//! Physical definitions (SI units; `docs/effects.md` has the derivations):
//! - `joint_friction`: motor-side torque `τ_f = (τ_c + τ_s e^{−(q̇/v_s)²}) tanh(q̇/v_ε) + b q̇`
//!   with the sign's width `v_ε` (`v_eps`, default [`FRICTION_V_EPS`]: how sharply the
//!   friction reverses with the velocity, the presliding regime of a real gear); it opposes
//!   the motor in torque drive and adds to the torque the motor must deliver in replay (the
//!   `tau*` channels).
//! - `backlash`: a dead zone of full width `gap` between the motor side (encoder, prescribed
//!   in replay) and the link side of each motor joint, which becomes a degree of freedom of
//!   its own: free inside the gap (with the gear's link-side `inertia`), in rigid unilateral
//!   contact on a flank while the gear pushes, plastic impact when it reaches a flank
//!   (`crate::backlash`). With `contact_k > 0` the flanks are compliant instead (a
//!   unilateral spring-damper `τ_g = −k_c(x ∓ gap/2) − c_c ẋ` past a flank, never pulling:
//!   the elasto-backlash law of Modelica and Simscape). With `held = 1` the link side is held inside the gap instead and
//!   follows the play operator `q_l ← clamp(q_l, q_m − gap/2, q_m + gap/2)` of the encoder
//!   angle (started centred), prescribed like a rigid gear.
//! - `pressure_leak`: `p(t) = p₀ e^{−rate·t}` per link (t on the run's clock); k(p), c(p)
//!   follow the table and `M_w = coef·p·r³` follows p.
//! - `wrinkling`: bilinear spring per universal joint: with `s = k|δ|` (both axes) and
//!   `M'_w = mw_scale·M_w`, the spring moment is `kδ` for `s ≤ M'_w` and
//!   `(M'_w + ratio·(s − M'_w)) δ/|δ|` above.
//! - `payload_mass`: payload `m + delta_kg` at `com + com_offset_m`.
//! - `sensor_delay`: a sensor group reads the physics `delay` seconds late:
//!   `y(t) = y_true(t − delay)` (cubic interpolation between samples, first sample held).
//! - `actuator_saturation`: motor torque clamped to ±`tau_max` (the command in torque
//!   drive; the measured torque in replay).
//! - `air_drag`: quadratic drag `dF = −½ ρ c_d (2r) |v⊥| v⊥ dl` along every link tube
//!   (3-point Gauss per tube piece, ρ = [`AIR_DENSITY`]).
//! - `higher_bending_modes`, `torsion`: extra joints (see `docs/effects.md`).

use crate::error::{Error, Result};
use crate::math::{Mat3, Vec3, VecN, NMAX};
use crate::model::Model;
use serde::{Deserialize, Serialize};

/// Air density used by `air_drag` [kg/m³] (sea level, 20 °C).
pub const AIR_DENSITY: f64 = 1.204;
/// Default velocity scale of the smoothed sign in `joint_friction` (`v_eps`) [rad/s].
pub const FRICTION_V_EPS: f64 = 1e-2;

/// Coulomb + viscous (+ Stribeck) friction in each motoreducer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JointFriction {
    /// Coulomb torque per motor joint [N·m].
    pub tau_c: [f64; 3],
    /// Viscous coefficient per motor joint [N·m·s/rad].
    pub b: [f64; 3],
    /// Stribeck excess static torque [N·m].
    pub tau_s: [f64; 3],
    /// Stribeck velocity [rad/s].
    pub v_s: [f64; 3],
    /// Velocity scale of the smoothed sign, `tanh(q̇/v_eps)` [rad/s].
    pub v_eps: [f64; 3],
}
impl JointFriction {
    /// True when any friction torque is non-zero.
    #[inline]
    pub fn on(&self) -> bool {
        self.tau_c != [0.0; 3] || self.b != [0.0; 3] || self.tau_s != [0.0; 3]
    }
}
impl Default for JointFriction {
    fn default() -> Self {
        JointFriction { tau_c: [0.0; 3], b: [0.0; 3], tau_s: [0.0; 3], v_s: [0.05; 3], v_eps: [FRICTION_V_EPS; 3] }
    }
}

/// Dead zone between encoder and link side of each motor joint.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Backlash {
    /// Full width of the dead zone per motor joint [rad].
    pub gap: [f64; 3],
    /// Inertia on the link side of the dead zone about the motor axis (gear output flange
    /// and link clamp), felt only while the link side moves inside the gap [kg·m²].
    pub inertia: [f64; 3],
    /// Coefficient of restitution of the gear's flanks [1] (0 = plastic impact).
    pub restitution: [f64; 3],
    /// 1 = the link side is held inside the gap (its bearing's friction beats every load)
    /// and only moves when a flank pushes it: a play operator on the encoder angle, started
    /// in the middle of the gap; 0 = free inside the gap (the gear with play) [1].
    pub held: [f64; 3],
    /// Stiffness of the gear's flanks [N·m/rad]: 0 = rigid flanks (contact as a constraint,
    /// impacts with `restitution`); > 0 = a compliant contact past the flank.
    pub contact_k: [f64; 3],
    /// Damping of a compliant flank contact [N·m·s/rad] (with `contact_k > 0`).
    pub contact_c: [f64; 3],
}
impl Default for Backlash {
    fn default() -> Self {
        Backlash { gap: [0.0; 3], inertia: [BACKLASH_INERTIA; 3], restitution: [0.0; 3], held: [0.0; 3], contact_k: [0.0; 3], contact_c: [0.0; 3] }
    }
}
impl Backlash {
    /// True when any joint has play.
    #[inline]
    pub fn on(&self) -> bool {
        self.gap != [0.0; 3]
    }

    /// Gaps whose link side is free inside them (the gear with play, `crate::backlash`) [rad].
    #[inline]
    pub fn free_gap(&self) -> [f64; 3] {
        std::array::from_fn(|k| if self.held[k] == 0.0 { self.gap[k] } else { 0.0 })
    }

    /// Whether motor joint `k`'s link side is free in its gap with compliant flanks.
    #[inline]
    pub fn compliant(&self, k: usize) -> bool {
        self.gap[k] != 0.0 && self.held[k] == 0.0 && self.contact_k[k] > 0.0
    }

    /// Gaps whose link side is held inside them (a play operator on the encoder) [rad].
    #[inline]
    pub fn held_gap(&self) -> [f64; 3] {
        std::array::from_fn(|k| if self.held[k] != 0.0 { self.gap[k] } else { 0.0 })
    }
}

/// Default link-side inertia of a gear with play [kg·m²]: a harmonic-drive output flange
/// with the clamp ring of a 17 cm tube (~0.5 kg at 8.5 cm gives 3.6e-3) is of this order.
pub const BACKLASH_INERTIA: f64 = 0.01;

/// Multi-segment PRBM links.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HigherBendingModes {
    /// Number of PRBM segments per link (1, 2 or 3; 0 = a rigid link; structural).
    pub segments: [f64; 2],
    /// Scale of the segment springs per link (1 = same static tip deflection as one joint).
    pub k_scale: [f64; 2],
    /// Stiffness of a multi-segment link's root joint relative to its other joints, the
    /// springs rescaled so that the static tip deflection under a tip force is unchanged
    /// (1 = equal springs; 4 with 2 segments also gives a uniform cantilever's tip rotation).
    pub root_ratio: [f64; 2],
    /// Euler–Bernoulli beam elements per link (structural): 0 = PRBM link, n = 1..=6 a beam
    /// link of n elements (`crate::beam::BeamLink`) whose material is the parameters below.
    pub elements: [f64; 2],
    /// Young's modulus of a beam link's wall E [Pa].
    pub e_pa: [f64; 2],
    /// Wall thickness of a beam link t [m] (I = π r³ t).
    pub wall_m: [f64; 2],
    /// Poisson's ratio of a beam link's wall ν [1] (with `shear`).
    pub nu: [f64; 2],
    /// Stiffness-proportional Rayleigh damping of a beam link λ [s].
    pub lambda_s: [f64; 2],
    /// Mass-proportional Rayleigh damping of a beam link μ [1/s].
    pub mu_per_s: [f64; 2],
    /// Timoshenko shear deformation with Fichter's pressure term, per beam link (0 or 1).
    pub shear: [f64; 2],
}
impl Default for HigherBendingModes {
    fn default() -> Self {
        let m = crate::beam::PRESETS[0].1;
        HigherBendingModes {
            segments: [1.0; 2],
            k_scale: [1.0; 2],
            root_ratio: [1.0; 2],
            elements: [0.0; 2],
            e_pa: [m.e; 2],
            wall_m: [m.t; 2],
            nu: [m.nu; 2],
            lambda_s: [m.lambda; 2],
            mu_per_s: [m.mu; 2],
            shear: [0.0; 2],
        }
    }
}

impl HigherBendingModes {
    /// The beam material of link `l`.
    pub fn material(&self, l: usize) -> crate::beam::BeamMaterial {
        crate::beam::BeamMaterial { e: self.e_pa[l], t: self.wall_m[l], nu: self.nu[l], lambda: self.lambda_s[l], mu: self.mu_per_s[l], shear: self.shear[l] != 0.0 }
    }
}

/// Inflation pressure decaying during the run.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PressureLeak {
    /// Leak rate 1/τ per link [1/s]: p(t) = p₀ exp(−rate·t).
    pub rate: [f64; 2],
}

/// Stiffness loss past the wrinkling moment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Wrinkling {
    /// Stiffness after wrinkling over stiffness before [1].
    pub ratio: f64,
    /// Scale of the wrinkling moment M_w [1].
    pub mw_scale: f64,
}
impl Default for Wrinkling {
    fn default() -> Self {
        Wrinkling { ratio: 1.0, mw_scale: 1.0 }
    }
}

/// The true payload differs from the declared one.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PayloadMass {
    /// Mass error [kg] (true = declared + delta).
    pub delta_kg: f64,
    /// Centre offset in the payload body's frame [m].
    pub com_offset_m: [f64; 3],
}

/// Sensor groups reading the physics late.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorDelay {
    /// IMU channels delay [s].
    pub imu: f64,
    /// Encoder channels (q, dq) delay [s].
    pub encoder: f64,
    /// Motor-torque channels delay [s].
    pub torque: f64,
    /// Motion-capture (end-effector) channels delay [s].
    pub mocap: f64,
}

/// Motor torque limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActuatorSaturation {
    /// Torque limit per motor joint [N·m] (∞ = none).
    pub tau_max: [f64; 3],
}
impl Default for ActuatorSaturation {
    fn default() -> Self {
        ActuatorSaturation { tau_max: [f64::INFINITY; 3] }
    }
}

/// Quadratic aerodynamic drag on the links.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AirDrag {
    /// Drag coefficient on the projected area 2·r·l [1].
    pub cd: f64,
}

/// Torsional compliance of each link about its own axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Torsion {
    /// Torsional stiffness per link [N·m/rad] (∞ = rigid, no torsion joint).
    pub k_t: [f64; 2],
    /// Torsional damping per link [N·m·s/rad].
    pub c_t: [f64; 2],
}
impl Default for Torsion {
    fn default() -> Self {
        Torsion { k_t: [f64::INFINITY; 2], c_t: [0.0; 2] }
    }
}

/// Parameters of every effect; [`Effects::default`] is the nominal model (all neutral).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    /// `joint_friction`.
    pub joint_friction: JointFriction,
    /// `backlash`.
    pub backlash: Backlash,
    /// `higher_bending_modes`.
    pub higher_bending_modes: HigherBendingModes,
    /// `pressure_leak`.
    pub pressure_leak: PressureLeak,
    /// `wrinkling`.
    pub wrinkling: Wrinkling,
    /// `payload_mass`.
    pub payload_mass: PayloadMass,
    /// `sensor_delay`.
    pub sensor_delay: SensorDelay,
    /// `actuator_saturation`.
    pub actuator_saturation: ActuatorSaturation,
    /// `air_drag`.
    pub air_drag: AirDrag,
    /// `torsion`.
    pub torsion: Torsion,
}

/// One parameter of the registry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Effect name (`effects.md`).
    pub effect: &'static str,
    /// Parameter name.
    pub name: &'static str,
    /// Unit.
    pub unit: &'static str,
    /// Number of values (per joint: 3, per link: 2, scalar: 1).
    pub len: usize,
    /// Neutral value.
    pub neutral: f64,
    /// Lower bound (inclusive).
    pub lo: f64,
    /// Upper bound (inclusive).
    pub hi: f64,
    /// Fitted by default when the effect is diagnosed.
    pub fit: bool,
    /// Integer-valued (structural).
    pub integer: bool,
    /// What it is.
    pub doc: &'static str,
}

const fn p(effect: &'static str, name: &'static str, unit: &'static str, len: usize, neutral: f64, lo: f64, hi: f64, fit: bool, doc: &'static str) -> ParamSpec {
    ParamSpec { effect, name, unit, len, neutral, lo, hi, fit, integer: false, doc }
}

/// Effect names in library order.
pub const EFFECT_NAMES: [&str; 10] = [
    "joint_friction",
    "backlash",
    "higher_bending_modes",
    "pressure_leak",
    "wrinkling",
    "payload_mass",
    "sensor_delay",
    "actuator_saturation",
    "air_drag",
    "torsion",
];

const INF: f64 = f64::INFINITY;

/// The parameter registry, in flat-vector order (see [`Effects::to_flat`]).
pub const PARAMS: [ParamSpec; NPARAM] = [
    p("joint_friction", "tau_c", "N·m", 3, 0.0, 0.0, 100.0, true, "Coulomb friction torque per motor joint"),
    p("joint_friction", "b", "N·m·s/rad", 3, 0.0, 0.0, 100.0, true, "viscous friction per motor joint"),
    p("joint_friction", "tau_s", "N·m", 3, 0.0, 0.0, 100.0, false, "Stribeck excess static torque per motor joint"),
    p("joint_friction", "v_s", "rad/s", 3, 0.05, 1e-4, 10.0, false, "Stribeck velocity per motor joint"),
    p("joint_friction", "v_eps", "rad/s", 3, FRICTION_V_EPS, 1e-4, 1.0, false, "velocity scale of the smoothed sign tanh(v/v_eps) per motor joint (how sharply friction reverses)"),
    p("backlash", "gap", "rad", 3, 0.0, 0.0, 0.2, true, "full width of the dead zone per motor joint"),
    p("backlash", "inertia", "kg·m²", 3, BACKLASH_INERTIA, 1e-4, 10.0, false, "link-side inertia of the gear about the motor axis, felt inside the gap"),
    p("backlash", "restitution", "1", 3, 0.0, 0.0, 0.95, false, "coefficient of restitution of the gear's flanks (0 = plastic impact)"),
    ParamSpec {
        effect: "backlash",
        name: "held",
        unit: "1",
        len: 3,
        neutral: 0.0,
        lo: 0.0,
        hi: 1.0,
        fit: false,
        integer: true,
        doc: "1 = the link side is held inside the gap and only moves when a flank pushes it (play operator on the encoder, started centred); 0 = free inside the gap",
    },
    p("backlash", "contact_k", "N·m/rad", 3, 0.0, 0.0, 1e9, false, "stiffness of the gear's flanks: 0 = rigid (impacts with restitution), > 0 = a compliant unilateral contact past a flank"),
    p("backlash", "contact_c", "N·m·s/rad", 3, 0.0, 0.0, 1e6, false, "damping of a compliant flank contact (with contact_k > 0)"),
    ParamSpec {
        effect: "higher_bending_modes",
        name: "segments",
        unit: "1",
        len: 2,
        neutral: 1.0,
        lo: 0.0,
        hi: 3.0,
        fit: false,
        integer: true,
        doc: "PRBM segments per link, 0 = a rigid link (structural)",
    },
    p("higher_bending_modes", "k_scale", "1", 2, 1.0, 0.05, 20.0, true, "scale of the segment springs per link"),
    p("higher_bending_modes", "root_ratio", "1", 2, 1.0, 0.05, 20.0, false, "stiffness of a multi-segment link's root joint relative to its other joints, at the same static tip deflection (4 with 2 segments: a uniform cantilever's tip rotation too)"),
    ParamSpec {
        effect: "higher_bending_modes",
        name: "elements",
        unit: "1",
        len: 2,
        neutral: 0.0,
        lo: 0.0,
        hi: crate::math::NELEM_MAX as f64,
        fit: false,
        integer: true,
        doc: "Euler–Bernoulli beam elements per link, 0 = PRBM link (structural)",
    },
    p("higher_bending_modes", "e_pa", "Pa", 2, 0.557e9, 1e5, 1e12, false, "Young's modulus of a beam link's wall"),
    p("higher_bending_modes", "wall_m", "m", 2, 1.2e-3, 1e-6, 0.05, false, "wall thickness of a beam link"),
    p("higher_bending_modes", "nu", "1", 2, 0.3, 0.0, 0.499, false, "Poisson's ratio of a beam link's wall (with shear)"),
    p("higher_bending_modes", "lambda_s", "s", 2, 3.896e-4, 0.0, 1.0, false, "stiffness-proportional Rayleigh damping of a beam link"),
    p("higher_bending_modes", "mu_per_s", "1/s", 2, 0.0, 0.0, 1e3, false, "mass-proportional Rayleigh damping of a beam link"),
    ParamSpec {
        effect: "higher_bending_modes",
        name: "shear",
        unit: "1",
        len: 2,
        neutral: 0.0,
        lo: 0.0,
        hi: 1.0,
        fit: false,
        integer: true,
        doc: "Timoshenko shear deformation of a beam link with Fichter's pressure term (0 or 1)",
    },
    p("pressure_leak", "rate", "1/s", 2, 0.0, 0.0, 1.0, true, "leak rate 1/τ per link: p(t) = p0·exp(−rate·t)"),
    p("wrinkling", "ratio", "1", 1, 1.0, 0.01, 1.0, true, "bending stiffness after wrinkling / before"),
    p("wrinkling", "mw_scale", "1", 1, 1.0, 0.1, 10.0, true, "scale of the wrinkling moment M_w"),
    p("payload_mass", "delta_kg", "kg", 1, 0.0, -50.0, 50.0, true, "true payload minus declared payload"),
    p("payload_mass", "com_offset_m", "m", 3, 0.0, -1.0, 1.0, false, "payload centre offset in the payload body frame"),
    p("sensor_delay", "imu", "s", 1, 0.0, 0.0, 0.5, true, "IMU delay"),
    p("sensor_delay", "encoder", "s", 1, 0.0, 0.0, 0.5, false, "encoder delay (in replay indistinguishable from equal delays of every other group, so not fitted by default)"),
    p("sensor_delay", "torque", "s", 1, 0.0, 0.0, 0.5, true, "motor-torque delay"),
    p("sensor_delay", "mocap", "s", 1, 0.0, 0.0, 0.5, true, "motion-capture (end-effector) delay"),
    p("actuator_saturation", "tau_max", "N·m", 3, INF, 0.0, INF, true, "torque limit per motor joint"),
    p("air_drag", "cd", "1", 1, 0.0, 0.0, 100.0, true, "drag coefficient on the projected area 2·r·l"),
    p("torsion", "k_t", "N·m/rad", 2, INF, 1e-3, INF, true, "torsional stiffness per link (∞ = rigid)"),
    p("torsion", "c_t", "N·m·s/rad", 2, 0.0, 0.0, 1e4, true, "torsional damping per link"),
];

/// Number of registered parameters.
pub const NPARAM: usize = 34;

/// Length of the flat effect vector.
pub const NE: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < NPARAM {
        n += PARAMS[i].len;
        i += 1;
    }
    n
};

/// Offset of parameter `i` in the flat vector.
pub const fn offset(i: usize) -> usize {
    let mut n = 0;
    let mut k = 0;
    while k < i {
        n += PARAMS[k].len;
        k += 1;
    }
    n
}

impl Effects {
    fn slots(&self) -> [&[f64]; NPARAM] {
        let e = self;
        [
            &e.joint_friction.tau_c,
            &e.joint_friction.b,
            &e.joint_friction.tau_s,
            &e.joint_friction.v_s,
            &e.joint_friction.v_eps,
            &e.backlash.gap,
            &e.backlash.inertia,
            &e.backlash.restitution,
            &e.backlash.held,
            &e.backlash.contact_k,
            &e.backlash.contact_c,
            &e.higher_bending_modes.segments,
            &e.higher_bending_modes.k_scale,
            &e.higher_bending_modes.root_ratio,
            &e.higher_bending_modes.elements,
            &e.higher_bending_modes.e_pa,
            &e.higher_bending_modes.wall_m,
            &e.higher_bending_modes.nu,
            &e.higher_bending_modes.lambda_s,
            &e.higher_bending_modes.mu_per_s,
            &e.higher_bending_modes.shear,
            &e.pressure_leak.rate,
            std::slice::from_ref(&e.wrinkling.ratio),
            std::slice::from_ref(&e.wrinkling.mw_scale),
            std::slice::from_ref(&e.payload_mass.delta_kg),
            &e.payload_mass.com_offset_m,
            std::slice::from_ref(&e.sensor_delay.imu),
            std::slice::from_ref(&e.sensor_delay.encoder),
            std::slice::from_ref(&e.sensor_delay.torque),
            std::slice::from_ref(&e.sensor_delay.mocap),
            &e.actuator_saturation.tau_max,
            std::slice::from_ref(&e.air_drag.cd),
            &e.torsion.k_t,
            &e.torsion.c_t,
        ]
    }

    fn slots_mut(&mut self) -> [&mut [f64]; NPARAM] {
        let e = self;
        [
            &mut e.joint_friction.tau_c,
            &mut e.joint_friction.b,
            &mut e.joint_friction.tau_s,
            &mut e.joint_friction.v_s,
            &mut e.joint_friction.v_eps,
            &mut e.backlash.gap,
            &mut e.backlash.inertia,
            &mut e.backlash.restitution,
            &mut e.backlash.held,
            &mut e.backlash.contact_k,
            &mut e.backlash.contact_c,
            &mut e.higher_bending_modes.segments,
            &mut e.higher_bending_modes.k_scale,
            &mut e.higher_bending_modes.root_ratio,
            &mut e.higher_bending_modes.elements,
            &mut e.higher_bending_modes.e_pa,
            &mut e.higher_bending_modes.wall_m,
            &mut e.higher_bending_modes.nu,
            &mut e.higher_bending_modes.lambda_s,
            &mut e.higher_bending_modes.mu_per_s,
            &mut e.higher_bending_modes.shear,
            &mut e.pressure_leak.rate,
            std::slice::from_mut(&mut e.wrinkling.ratio),
            std::slice::from_mut(&mut e.wrinkling.mw_scale),
            std::slice::from_mut(&mut e.payload_mass.delta_kg),
            &mut e.payload_mass.com_offset_m,
            std::slice::from_mut(&mut e.sensor_delay.imu),
            std::slice::from_mut(&mut e.sensor_delay.encoder),
            std::slice::from_mut(&mut e.sensor_delay.torque),
            std::slice::from_mut(&mut e.sensor_delay.mocap),
            &mut e.actuator_saturation.tau_max,
            std::slice::from_mut(&mut e.air_drag.cd),
            &mut e.torsion.k_t,
            &mut e.torsion.c_t,
        ]
    }

    /// The flat parameter vector (registry order, [`NE`] values).
    pub fn to_flat(&self) -> [f64; NE] {
        let mut out = [0.0; NE];
        let mut k = 0;
        for s in self.slots() {
            out[k..k + s.len()].copy_from_slice(s);
            k += s.len();
        }
        out
    }

    /// Build from a flat vector and validate it.
    ///
    /// # Errors
    /// As [`Effects::validate`], or a wrong length.
    pub fn from_flat(v: &[f64]) -> Result<Effects> {
        if v.len() != NE {
            return Err(Error::param("effects", v.len(), format!("the flat effect vector has {NE} values")));
        }
        let mut e = Effects::default();
        let mut k = 0;
        for s in e.slots_mut() {
            let n = s.len();
            s.copy_from_slice(&v[k..k + n]);
            k += n;
        }
        e.validate()?;
        Ok(e)
    }

    /// Check every value against its bounds.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming `effects.<effect>.<param>[i]`.
    pub fn validate(&self) -> Result<()> {
        for (i, s) in self.slots().iter().enumerate() {
            let ps = &PARAMS[i];
            for (j, &x) in s.iter().enumerate() {
                let key = if ps.len > 1 { format!("effects.{}.{}[{j}]", ps.effect, ps.name) } else { format!("effects.{}.{}", ps.effect, ps.name) };
                if x.is_nan() || x < ps.lo || x > ps.hi {
                    return Err(Error::param(key, x, format!("must be within [{}, {}] {}", ps.lo, ps.hi, ps.unit)));
                }
                if ps.integer && x.fract() != 0.0 {
                    return Err(Error::param(key, x, "must be a whole number"));
                }
            }
        }
        Ok(())
    }

    /// True when the named effect is at its neutral value (changes nothing).
    pub fn is_neutral(&self, effect: &str) -> bool {
        let slots = self.slots();
        PARAMS[..NPARAM].iter().zip(slots.iter()).filter(|(ps, _)| ps.effect == effect).all(|(ps, s)| {
            // parameters that only shape an effect whose strength is neutral do not count
            is_shaping(ps.effect, ps.name) || s.iter().all(|&x| x.to_bits() == ps.neutral.to_bits())
        })
    }

    /// Names of the effects that are not neutral.
    pub fn active(&self) -> Vec<&'static str> {
        EFFECT_NAMES.iter().copied().filter(|n| !self.is_neutral(n)).collect()
    }

    /// Structural parameters are the compiled model's (segments, beam elements, whether a
    /// torsion joint exists); a rollout's `segments` and `elements` are ignored, its beam
    /// material acts only on beam links and its `k_t` only where the model has a torsion
    /// joint.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for an infinite `k_t` on a link with a torsion joint.
    pub fn check_structure(&self, model: &Model) -> Result<()> {
        for l in 0..2 {
            if model.torsion_idx[l].is_some() && !self.torsion.k_t[l].is_finite() {
                return Err(Error::param(
                    format!("effects.torsion.k_t[{l}]"),
                    self.torsion.k_t[l],
                    format!("must be finite: the model has a torsion joint for link {} (structural); give its torsional stiffness", l + 1),
                ));
            }
        }
        Ok(())
    }
}

/// The parameters that only shape an effect: they change nothing while the effect's
/// strength parameters are neutral (so [`Effects::is_neutral`] ignores them).
pub const SHAPING: [(&str, &str); 16] = [
    ("joint_friction", "v_s"),
    ("joint_friction", "v_eps"),
    ("backlash", "inertia"),
    ("backlash", "restitution"),
    ("backlash", "held"),
    ("backlash", "contact_k"),
    ("backlash", "contact_c"),
    ("torsion", "c_t"),
    ("higher_bending_modes", "k_scale"),
    ("higher_bending_modes", "root_ratio"),
    ("higher_bending_modes", "e_pa"),
    ("higher_bending_modes", "wall_m"),
    ("higher_bending_modes", "nu"),
    ("higher_bending_modes", "lambda_s"),
    ("higher_bending_modes", "mu_per_s"),
    ("higher_bending_modes", "shear"),
];

/// Whether `effect.name` is a shaping parameter ([`SHAPING`]).
pub fn is_shaping(effect: &str, name: &str) -> bool {
    SHAPING.iter().any(|&(e, n)| e == effect && n == name)
}

/// Effect parameters that, in encoder replay (the motor side prescribed), act on the sensor
/// rows only, never on the motion, as `(effect, parameter or "*" for all of the effect's,
/// the prefix of the channels they act on)`: the motor torque read (`tau*`: friction at the
/// motor's rate, its clamp; with or without a gear's play, whose link side is behind the
/// motor side) and the delays of the sensor groups read from the physics (the encoder's
/// delay moves the drive, so it is not one). A rollout batch whose jobs differ only in them
/// needs one run of physics ([`crate::rollout`]), and the diagnosis
/// measures such an effect's share of the error on those channels.
pub const OUTPUT_ONLY_IN_REPLAY: &[(&str, &str, &str)] = &[
    ("joint_friction", "*", "tau"),
    ("actuator_saturation", "*", "tau"),
    ("sensor_delay", "imu", "imu"),
    ("sensor_delay", "torque", "tau"),
    ("sensor_delay", "mocap", "ee_"),
];

/// Whether `a` and `b` differ at most in the parameters of [`OUTPUT_ONLY_IN_REPLAY`].
pub fn same_motion(a: &Effects, b: &Effects) -> bool {
    let mut c = *b;
    c.joint_friction = a.joint_friction;
    c.actuator_saturation = a.actuator_saturation;
    c.sensor_delay = SensorDelay { encoder: b.sensor_delay.encoder, ..a.sensor_delay };
    c == *a
}

/// Motor-side friction torque at motor rate `v` [N·m] (joint `k` of 3).
#[inline]
pub fn friction_torque(f: &JointFriction, k: usize, v: f64) -> f64 {
    let mut s = f.tau_c[k];
    if f.tau_s[k] != 0.0 {
        let r = v / f.v_s[k];
        s += f.tau_s[k] * (-r * r).exp();
    }
    s * (v / f.v_eps[k]).tanh() + f.b[k] * v
}

/// Leak factor p(t)/p₀ for link `l`.
#[inline]
pub fn leak_factor(e: &Effects, l: usize, t: f64) -> f64 {
    (-e.pressure_leak.rate[l] * t).exp()
}

/// A point of the drag quadrature: body (0-based), position in body axes [m], link axis
/// in body axes, and weight `2 r Δl` [m²].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DragPoint {
    /// Body index (0-based).
    pub body: usize,
    /// Position in the body frame [m].
    pub p_b: Vec3,
    /// Projected area of the tube piece it stands for [m²].
    pub area: f64,
}

/// Maximum number of drag points.
pub const MAX_DRAG: usize = 3 * 2 * NMAX;

/// Drag quadrature points of the link tubes: 3-point Gauss–Legendre along each tube piece
/// of the arm file (tubes lie along their body's local x axis). With a multi-segment link
/// the points stay on the segment that carries the piece's frame (an approximation: the
/// drag of the outer segments is applied as if they moved with the first).
pub fn drag_points(model: &Model) -> ([DragPoint; MAX_DRAG], usize) {
    let mut out = [DragPoint { body: 0, p_b: Vec3::zeros(), area: 0.0 }; MAX_DRAG];
    let mut n = 0;
    let xi = [-(0.6f64).sqrt(), 0.0, (0.6f64).sqrt()];
    let w = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0];
    for (i, bs) in model.spec.bodies.iter().enumerate() {
        if bs.link == 0 {
            continue;
        }
        for ps in &bs.parts {
            if ps.shape != crate::spec::arm::PartShape::Tube || ps.length_m <= 0.0 {
                continue;
            }
            let r = ps.radius_m.unwrap_or(model.link_radius[bs.link - 1]);
            let c = Vec3::from(ps.com_m);
            for g in 0..3 {
                if n < MAX_DRAG {
                    out[n] = DragPoint { body: model.spec_body[i], p_b: c + Vec3::x() * (0.5 * ps.length_m * xi[g]), area: 2.0 * r * ps.length_m * w[g] };
                    n += 1;
                }
            }
        }
    }
    (out, n)
}

/// Generalised air-drag forces [N·m] at (q, q̇) for drag coefficient `cd`.
pub fn drag_forces(model: &Model, pts: &[DragPoint], cd: f64, rot: &[Mat3; NMAX], v: &VecN) -> VecN {
    let f = crate::kinematics::prbm::frames_with(model, rot);
    let mut axis = [Vec3::zeros(); NMAX];
    for j in 0..model.nv {
        axis[j] = f.r_wb[j + 1] * model.joints[j].u;
    }
    let mut tau = VecN::zeros();
    for d in pts {
        let p = f.point(d.body + 1, &d.p_b);
        let mut vel = Vec3::zeros();
        for j in 0..=d.body {
            vel += axis[j].cross(&(p - f.p_wb[j])) * v[j];
        }
        let e = f.r_wb[d.body + 1] * Vec3::x();
        let vp = vel - e * vel.dot(&e);
        let force = vp * (-0.5 * AIR_DENSITY * cd * d.area * vp.norm());
        for j in 0..=d.body {
            tau[j] += axis[j].cross(&(p - f.p_wb[j])).dot(&force);
        }
    }
    tau
}

/// Bilinear wrinkled spring: the spring moments of one universal joint for deflections
/// (δ₁, δ₂) with stiffness `k`, onset moment `mw` and post-wrinkling ratio `ratio` [N·m].
#[inline]
pub fn wrinkled_spring(k: f64, d1: f64, d2: f64, mw: f64, ratio: f64) -> (f64, f64) {
    let (m1, m2) = (k * d1, k * d2);
    let s = (m1 * m1 + m2 * m2).sqrt();
    if s <= mw {
        return (m1, m2);
    }
    let g = (mw + ratio * (s - mw)) / s;
    (m1 * g, m2 * g)
}

/// Potential energy of the wrinkled spring [J].
#[inline]
pub fn wrinkled_energy(k: f64, d1: f64, d2: f64, mw: f64, ratio: f64) -> f64 {
    let d = (d1 * d1 + d2 * d2).sqrt();
    let dw = mw / k;
    if d <= dw {
        0.5 * k * d * d
    } else {
        0.5 * k * dw * dw + mw * (d - dw) + 0.5 * ratio * k * (d - dw) * (d - dw)
    }
}
