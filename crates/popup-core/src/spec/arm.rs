//! The arm description (`ArmSpec`): everything a user may override in an arm file, in SI
//! units. The built-in `popup-lab` arm reproduces `shared/spec/reference-arm.md`.
//!
//! Frames follow standard Denavit–Hartenberg: `A_i = Rot_z(θ_i) Trans_z(d_i) Trans_x(a_i)
//! Rot_x(α_i)`, joint i turns about z of frame i-1, body i is rigid with frame i. All
//! positions of parts, sensors and payload are given in the frame of their body.

use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// Kind of a joint of the PRBM chain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    /// A motorised joint (encoder, motor torque).
    Motor,
    /// A passive bending joint of an inflatable link (torsional spring and damper).
    Bending,
    /// A passive torsion joint about a link's own long axis (spring k_t, damper c_t). Not
    /// written in arm files: `Model::compile` inserts it when `Options::structure` asks for
    /// the `torsion` effect.
    Torsion,
}

/// One DH row of the PRBM chain.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Name used in outputs and error messages (e.g. `q2`, `d12`).
    pub name: String,
    /// Motor or bending joint.
    pub kind: JointKind,
    /// DH offset along z_{i-1} [m].
    pub d: f64,
    /// DH length along x_i [m].
    pub a: f64,
    /// DH twist about x_i [rad].
    pub alpha: f64,
    /// Constant added to the joint coordinate: θ_i = q_i + theta_offset [rad].
    #[serde(default)]
    pub theta_offset: f64,
    /// For bending joints: the link (1 or 2) whose stiffness table and pressure apply.
    #[serde(default)]
    pub link: usize,
}

/// Shape of a mass part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PartShape {
    /// Point mass (plus the extra inertia given).
    Point,
    /// Thin-walled tube along the local x axis: I_xx = m r², I_yy = I_zz = m (r²/2 + l²/12)
    /// about its centre.
    Tube,
}

/// A mass part rigidly attached to a body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartSpec {
    /// Free-text name.
    pub name: String,
    /// Point or thin-walled tube.
    pub shape: PartShape,
    /// Mass [kg], >= 0.
    pub mass_kg: f64,
    /// Centre of mass in the body frame [m].
    pub com_m: [f64; 3],
    /// Tube length [m] (tubes only).
    #[serde(default)]
    pub length_m: f64,
    /// Tube radius [m]; when absent the radius of the body's link is used (tubes only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    /// Extra inertia about the centre of mass, body axes, `[Ixx, Iyy, Izz, Ixy, Ixz, Iyz]` [kg·m²].
    #[serde(default)]
    pub inertia_kgm2: [f64; 6],
}

/// A body of the chain (body i is rigid with DH frame i).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySpec {
    /// Free-text name.
    pub name: String,
    /// The inflatable link this body belongs to (1 or 2), 0 for none; used for tube radii.
    #[serde(default)]
    pub link: usize,
    /// Mass parts (may be empty: a massless body).
    #[serde(default)]
    pub parts: Vec<PartSpec>,
}

/// An inflatable link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    /// Tube radius r [m].
    pub radius_m: f64,
    /// Link length L [m] (documentation and drag/geometry; the DH rows set the kinematics).
    pub length_m: f64,
    /// Factor applied to the k(p), c(p) table for this link. When absent it is
    /// (r / reference_radius_m)³: bending stiffness of an inflated tube grows with r³.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_scale: Option<f64>,
    /// Extra factor on this link's damping c(p) only, on top of the stiffness scale [1];
    /// absent = 1. It lets a fitted link keep its own damping ratio when its stiffness is
    /// rescaled (e.g. `popup-lab-thesis`, docs/thesis.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub damping_scale: Option<f64>,
    /// Default inflation pressure (relative) [Pa].
    pub pressure_pa: f64,
}

/// Stiffness and damping of each bending joint vs pressure (thesis Table 3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StiffnessTable {
    /// Radius of the link on which the table was measured [m].
    pub reference_radius_m: f64,
    /// Relative pressures, strictly increasing [Pa].
    pub pressure_pa: Vec<f64>,
    /// Torsional stiffness per bending joint [N·m/rad].
    pub k_nm_per_rad: Vec<f64>,
    /// Torsional damping per bending joint [N·m·s/rad].
    pub c_nms_per_rad: Vec<f64>,
}

/// Wrinkling-moment coefficient: M_w = coefficient · p · r³.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WrinklingSpec {
    /// `"classical"` (π/2, Comer & Levy 1963), `"thesis"` (π²/4) or a number as a string.
    pub coefficient: String,
    /// Collapse moment as a multiple of M_w (2 for both named coefficients).
    pub collapse_factor: f64,
}

/// Where a point sensor sits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorMount {
    /// Body index (1-based, DH frame number).
    pub body: usize,
    /// Position in the body frame [m]; the sensor axes are the body frame's axes.
    pub position_m: [f64; 3],
}

/// Sensor placement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorSpec {
    /// The two tip IMUs (link 1, link 2).
    pub imu: Vec<SensorMount>,
    /// The end-effector point (motion capture).
    pub end_effector: SensorMount,
}

/// Payload mount.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadSpec {
    /// Body carrying the payload (1-based).
    pub body: usize,
    /// Payload centre of mass in that body's frame [m].
    pub com_m: [f64; 3],
    /// Default payload mass [kg].
    pub default_kg: f64,
}

/// Motoreducer constants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorSpec {
    /// Reflected rotor inertia (armature) at each motor joint output [kg·m²].
    pub armature_kgm2: [f64; 3],
    /// Torque limit of each motor joint's drive at the joint output [N·m] (> 0). The
    /// plausibility limits of measured torques and accelerations scale with it
    /// (`limits::arm`); absent from a complete arm file: the lab motoreducer's
    /// `Motoreducer::DEFAULT.tau_max` on every joint.
    #[serde(default = "default_tau_max")]
    pub tau_max_nm: [f64; 3],
}

fn default_tau_max() -> [f64; 3] {
    [crate::control::motor::Motoreducer::DEFAULT.tau_max; 3]
}

/// One row of a rigid 3-DOF DH table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidTable {
    /// d_i [m].
    pub d: [f64; 3],
    /// a_i [m].
    pub a: [f64; 3],
    /// α_i [rad].
    pub alpha: [f64; 3],
    /// Joint offsets [rad].
    #[serde(default)]
    pub theta_offset: [f64; 3],
}

/// Rigid 3-DOF equivalents of the arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigidSpec {
    /// As built, with offsets (thesis Table 1).
    pub as_built: RigidTable,
    /// Offsets removed, for closed-form IK (thesis Table 2).
    pub ik: RigidTable,
}

/// The complete arm description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmSpec {
    /// Arm name.
    pub name: String,
    /// The seven DH rows of the PRBM chain, base to tip.
    pub joints: Vec<JointSpec>,
    /// The seven bodies (body i rigid with frame i).
    pub bodies: Vec<BodySpec>,
    /// The two inflatable links.
    pub links: Vec<LinkSpec>,
    /// k(p), c(p) of the bending joints.
    pub stiffness: StiffnessTable,
    /// Wrinkling coefficient.
    pub wrinkling: WrinklingSpec,
    /// Payload mount and default mass.
    pub payload: PayloadSpec,
    /// Sensor placement.
    pub sensors: SensorSpec,
    /// Motoreducers.
    pub motors: MotorSpec,
    /// Rigid 3-DOF tables.
    pub rigid: RigidSpec,
    /// Gravity in the base frame [m/s²].
    pub gravity_mps2: [f64; 3],
    /// Effects switched on in this arm (`[effects.<name>]` tables; absent = nominal).
    #[serde(default, skip_serializing_if = "is_nominal")]
    pub effects: crate::effects::Effects,
}

fn is_nominal(e: &crate::effects::Effects) -> bool {
    *e == crate::effects::Effects::default()
}

fn joint(name: &str, kind: JointKind, a: f64, alpha: f64, link: usize) -> JointSpec {
    JointSpec { name: name.into(), kind, d: 0.0, a, alpha, theta_offset: 0.0, link }
}

fn tube(name: &str, mass: f64, length: f64) -> PartSpec {
    PartSpec {
        name: name.into(),
        shape: PartShape::Tube,
        mass_kg: mass,
        com_m: [-length / 2.0, 0.0, 0.0],
        length_m: length,
        radius_m: None,
        inertia_kgm2: [0.0; 6],
    }
}

fn point(name: &str, mass: f64, inertia: f64) -> PartSpec {
    PartSpec {
        name: name.into(),
        shape: PartShape::Point,
        mass_kg: mass,
        com_m: [0.0; 3],
        length_m: 0.0,
        radius_m: None,
        inertia_kgm2: [inertia, inertia, inertia, 0.0, 0.0, 0.0],
    }
}

fn body(name: &str, link: usize, parts: Vec<PartSpec>) -> BodySpec {
    BodySpec { name: name.into(), link, parts }
}

impl ArmSpec {
    /// Names of the built-in arms: `popup-lab` (built in code, [`ArmSpec::popup_lab`]) and
    /// the packaged arm files of [`ArmSpec::PACKAGED`], in that order. Every front end
    /// (the CLI's `--arm` and scenario `arm` keys, `popup.Model(name)`, measured-run and
    /// sweep files) resolves a name through [`ArmSpec::builtin`], so this is the one list.
    pub const BUILTIN: &'static [&'static str] = &["popup-lab", "popup-lab-thesis"];

    /// Arm files packaged with the core (`crates/popup-core/arms/<name>.toml`, compiled in):
    /// name → the file's text, each `base = "popup-lab"` plus its overrides, with comments
    /// giving the reason for every number that differs. `popup-lab-thesis`: the numbers the
    /// thesis's Simscape model must have had (docs/thesis.md, written by
    /// `examples/thesis_report.py`).
    pub const PACKAGED: &'static [(&'static str, &'static str)] = &[("popup-lab-thesis", include_str!("../../arms/popup-lab-thesis.toml"))];

    /// A built-in arm by name: `popup-lab` or a packaged arm file ([`ArmSpec::PACKAGED`]).
    ///
    /// # Errors
    /// [`crate::Error::UnknownArm`] for a name not in [`ArmSpec::BUILTIN`], listing them.
    pub fn builtin(name: &str) -> crate::Result<Self> {
        if name == "popup-lab" {
            return Ok(Self::popup_lab());
        }
        match Self::packaged_source(name) {
            Some(text) => Self::from_toml(text, &format!("packaged arm file {name}.toml")),
            None => Err(crate::Error::UnknownArm { name: name.into(), known: Self::BUILTIN.join(", ") }),
        }
    }

    /// The arm `name` as every front end resolves it: a built-in arm ([`ArmSpec::BUILTIN`],
    /// packaged arm files included) by its name, else the arm file at `name`, relative to
    /// `base_dir` (the CLI's working directory, a scenario's folder). Returns the arm and
    /// the file's path (`None` for a built-in arm).
    ///
    /// # Errors
    /// [`crate::Error::UnknownArm`] (listing the built-in names) when `name` is neither a
    /// built-in arm nor an existing file; [`crate::Error::ArmFile`] for a file that cannot be
    /// read or parsed.
    pub fn resolve(name: &str, base_dir: &std::path::Path) -> crate::Result<(Self, Option<std::path::PathBuf>)> {
        if Self::BUILTIN.contains(&name) {
            return Ok((Self::builtin(name)?, None));
        }
        let path = base_dir.join(name);
        match std::fs::read_to_string(&path) {
            Ok(text) => Self::from_toml(&text, &path.display().to_string()).map(|a| (a, Some(path))),
            Err(e) if path.exists() => Err(crate::Error::ArmFile { source_name: path.display().to_string(), message: format!("cannot read: {e}") }),
            Err(_) => Err(crate::Error::UnknownArm { name: name.into(), known: format!("{} (and no arm file {})", Self::BUILTIN.join(", "), path.display()) }),
        }
    }

    /// The text of the packaged arm file `name` (with its comments), `None` for an arm that
    /// is not a packaged file (`popup-lab` is built in code; `popup arm popup-lab` prints it).
    pub fn packaged_source(name: &str) -> Option<&'static str> {
        Self::PACKAGED.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
    }

    /// The POP-UP laboratory prototype exactly as `reference-arm.md` gives it.
    pub fn popup_lab() -> Self {
        use JointKind::{Bending, Motor};
        ArmSpec {
            name: "popup-lab".into(),
            joints: vec![
                joint("q1", Motor, 0.0, FRAC_PI_2, 0),
                joint("q2", Motor, 0.03, -FRAC_PI_2, 0),
                joint("d11", Bending, 0.0, FRAC_PI_2, 1),
                joint("d12", Bending, 0.57, 0.0, 1),
                joint("q3", Motor, 0.03, -FRAC_PI_2, 0),
                joint("d21", Bending, 0.0, FRAC_PI_2, 2),
                joint("d22", Bending, 0.57, 0.0, 2),
            ],
            bodies: vec![
                body("shoulder housing", 0, vec![point("shoulder housing", 2.0, 0.004)]),
                body("link 1 root", 1, vec![tube("link 1 root piece", 0.03, 0.03)]),
                body("link 1 gimbal", 1, vec![]),
                body("link 1 outer", 1, vec![tube("link 1 outer piece", 0.57, 0.57), point("elbow motoreducer", 1.5, 0.003)]),
                body("link 2 root", 2, vec![tube("link 2 root piece", 0.02, 0.03)]),
                body("link 2 gimbal", 2, vec![]),
                body("link 2 outer", 2, vec![tube("link 2 outer piece", 0.38, 0.57)]),
            ],
            links: vec![
                LinkSpec { radius_m: 0.085, length_m: 0.6, stiffness_scale: None, damping_scale: None, pressure_pa: 30e3 },
                LinkSpec { radius_m: 0.055, length_m: 0.6, stiffness_scale: None, damping_scale: None, pressure_pa: 30e3 },
            ],
            stiffness: StiffnessTable {
                reference_radius_m: 0.055,
                pressure_pa: (1..=9).map(|i| i as f64 * 10e3).collect(),
                k_nm_per_rad: vec![321.0, 347.0, 360.0, 370.0, 382.0, 388.0, 392.0, 401.0, 405.0],
                c_nms_per_rad: vec![0.557, 0.547, 0.463, 0.450, 0.433, 0.429, 0.412, 0.407, 0.406],
            },
            wrinkling: WrinklingSpec { coefficient: "classical".into(), collapse_factor: 2.0 },
            payload: PayloadSpec { body: 7, com_m: [0.0; 3], default_kg: 2.0 },
            sensors: SensorSpec {
                imu: vec![SensorMount { body: 4, position_m: [0.0; 3] }, SensorMount { body: 7, position_m: [0.0; 3] }],
                end_effector: SensorMount { body: 7, position_m: [0.0; 3] },
            },
            motors: MotorSpec { armature_kgm2: [0.8; 3], tau_max_nm: default_tau_max() },
            rigid: RigidSpec {
                as_built: RigidTable { d: [0.15, 0.05, -0.12], a: [0.0, 0.745, 0.685], alpha: [FRAC_PI_2, 0.0, 0.0], theta_offset: [0.0; 3] },
                ik: RigidTable { d: [0.0; 3], a: [0.0, 0.745, 0.685], alpha: [FRAC_PI_2, 0.0, 0.0], theta_offset: [0.0; 3] },
            },
            gravity_mps2: [0.0, 0.0, -9.81],
            effects: Default::default(),
        }
    }

    /// The wrinkling coefficient as a number: `classical` = π/2, `thesis` = π²/4.
    ///
    /// # Errors
    /// [`crate::Error::InvalidParameter`] for an unknown name or a non-positive number.
    pub fn wrinkling_coefficient(&self) -> crate::Result<f64> {
        let s = self.wrinkling.coefficient.trim();
        let v = match s {
            "classical" => FRAC_PI_2,
            "thesis" => PI * PI / 4.0,
            _ => s.parse::<f64>().map_err(|_| {
                crate::Error::param("wrinkling.coefficient", format!("{s:?}"), "must be \"classical\", \"thesis\" or a positive number")
            })?,
        };
        if !(v.is_finite() && v > 0.0) {
            return Err(crate::Error::param("wrinkling.coefficient", v, "must be finite and > 0"));
        }
        Ok(v)
    }

    /// Serialise to a complete TOML arm file.
    pub fn to_toml(&self) -> String {
        let mut s = String::from("# popup arm file: SI units (m, kg, s, rad, Pa). `base` may name a built-in arm to\n# start from; every key given here overrides it (arrays of tables merge by index).\n");
        s.push_str(&toml::to_string(self).expect("ArmSpec serialises"));
        s
    }

    /// Parse an arm file. If it has `base = "<builtin>"`, its keys override that arm
    /// (tables merge key by key, arrays of tables merge element by element, other arrays
    /// are replaced); without `base` the file must be complete.
    ///
    /// # Errors
    /// [`crate::Error::ArmFile`] with the parser's line/column or the unknown key;
    /// [`crate::Error::UnknownArm`] for an unknown base.
    pub fn from_toml(text: &str, source_name: &str) -> crate::Result<Self> {
        let err = |m: String| crate::Error::ArmFile { source_name: source_name.into(), message: m };
        let mut user: toml::Table = toml::from_str(text).map_err(|e| err(e.to_string()))?;
        let merged = match user.remove("base") {
            Some(toml::Value::String(base)) => {
                let base = Self::builtin(&base)?;
                let mut value = toml::Table::try_from(&base).map_err(|e| err(e.to_string()))?;
                merge(&mut value, user, "");
                value
            }
            Some(other) => return Err(err(format!("`base` must be a string naming a built-in arm, got {other}"))),
            None => user,
        };
        let spec: ArmSpec = merged.try_into().map_err(|e: toml::de::Error| err(e.to_string()))?;
        Ok(spec)
    }

    /// A copy of this arm with `overrides` merged in (same merge rules as `base` files).
    ///
    /// # Errors
    /// [`crate::Error::ArmFile`] when the result is not a valid arm description.
    pub fn with_overrides(&self, overrides: toml::Table, source_name: &str) -> crate::Result<Self> {
        let err = |m: String| crate::Error::ArmFile { source_name: source_name.into(), message: m };
        let mut value = toml::Table::try_from(self).map_err(|e| err(e.to_string()))?;
        merge(&mut value, overrides, "");
        value.try_into().map_err(|e: toml::de::Error| err(e.to_string()))
    }

    /// The rigid 3-DOF arm of table `which`: `"as_built"` (thesis Table 1), `"ik"`
    /// (Table 2), or `"prbm"`: the PRBM chain itself with every bending joint at zero,
    /// reduced to three DH rows (for `popup-lab`: a = (0, 0.6, 0.6) m, reach 1.2 m).
    ///
    /// # Errors
    /// [`crate::Error::InvalidParameter`] for another name, non-finite numbers, or a chain
    /// whose straight pose cannot be written as three DH rows.
    pub fn rigid_arm(&self, which: &str) -> crate::Result<crate::kinematics::rigid::RigidArm> {
        let t = match which {
            "as_built" => self.rigid.as_built.clone(),
            "ik" => self.rigid.ik.clone(),
            "prbm" => self.straight_chain_table()?,
            _ => {
                return Err(crate::Error::param(
                    "rigid table",
                    format!("{which:?}"),
                    "must be \"as_built\" (thesis Table 1), \"ik\" (Table 2) or \"prbm\" (the PRBM chain, bending at zero)",
                ))
            }
        };
        crate::kinematics::rigid::RigidArm::new(format!("{} rigid {which}", self.name), t.d, t.a, t.alpha, t.theta_offset)
    }

    /// Three DH rows equivalent to the PRBM chain with the bending joints at zero.
    fn straight_chain_table(&self) -> crate::Result<RigidTable> {
        use nalgebra::{Matrix4, Vector3};
        let bad = |m: String| crate::Error::param("joints", "the PRBM chain", m);
        let motors: Vec<usize> = self.joints.iter().enumerate().filter(|(_, j)| j.kind == JointKind::Motor).map(|(i, _)| i).collect();
        if motors.len() != 3 || motors[0] != 0 {
            return Err(bad("needs 3 motor joints, the first at the base".into()));
        }
        let mut out = RigidTable { d: [0.0; 3], a: [0.0; 3], alpha: [0.0; 3], theta_offset: [0.0; 3] };
        for k in 0..3 {
            let end = if k < 2 { motors[k + 1] } else { self.joints.len() };
            let mut t = Matrix4::<f64>::identity();
            for (n, j) in self.joints[motors[k]..end].iter().enumerate() {
                let th = if n == 0 { 0.0 } else { j.theta_offset };
                let (st, ct) = th.sin_cos();
                let (sa, ca) = j.alpha.sin_cos();
                #[rustfmt::skip]
                let a = Matrix4::new(
                    ct, -st * ca, st * sa, j.a * ct,
                    st, ct * ca, -ct * sa, j.a * st,
                    0.0, sa, ca, j.d,
                    0.0, 0.0, 0.0, 1.0,
                );
                t *= a;
            }
            let p = Vector3::new(t[(0, 3)], t[(1, 3)], t[(2, 3)]);
            let x_ok = (t[(0, 0)] - 1.0).abs() < 1e-12 && t[(1, 0)].abs() < 1e-12 && t[(2, 0)].abs() < 1e-12;
            if !x_ok || p.y.abs() > 1e-12 {
                return Err(bad(format!("the straight segment after motor {} is not a DH row (Tz(d) Tx(a) Rx(α))", k + 1)));
            }
            out.d[k] = p.z;
            out.a[k] = p.x;
            out.alpha[k] = t[(2, 1)].atan2(t[(1, 1)]);
            out.theta_offset[k] = self.joints[motors[k]].theta_offset;
        }
        Ok(out)
    }
}

fn merge(base: &mut toml::Table, over: toml::Table, _path: &str) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o, &k),
            (Some(toml::Value::Array(b)), toml::Value::Array(o)) if o.iter().all(|x| x.is_table()) && b.iter().all(|x| x.is_table()) && !o.is_empty() => {
                for (i, item) in o.into_iter().enumerate() {
                    match (b.get_mut(i), item) {
                        (Some(toml::Value::Table(bt)), toml::Value::Table(ot)) => merge(bt, ot, &k),
                        (_, item) => {
                            if i < b.len() {
                                b[i] = item;
                            } else {
                                b.push(item);
                            }
                        }
                    }
                }
            }
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}
