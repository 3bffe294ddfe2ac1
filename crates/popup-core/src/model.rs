//! The compiled, immutable `Model`: validated arm data in the form the step needs.
//!
//! `Model::compile(&ArmSpec, Options)` is the only way to get one. It is `Send + Sync` and
//! shared by every rollout; per-rollout numbers (payload, pressures) live in
//! [`crate::params::Params`].

use crate::error::{Error, Result};
use crate::math::{rot_zx, skew, Mat3, Vec3, NB, NM, NV};
use crate::spec::arm::{ArmSpec, JointKind, PartShape};

/// Switches that turn force terms off (MuJoCo-style disable flags). Effects of the
/// diagnosis layer are switched the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Disable {
    /// Gravity off.
    pub gravity: bool,
    /// Bending springs off.
    pub spring: bool,
    /// Bending dampers off.
    pub damper: bool,
}

/// Fixed-step integrators.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Integrator {
    /// Classical 4th-order Runge–Kutta: 4 dynamics evaluations per step, global error
    /// O(dt⁴), no numerical damping of the lightly damped bending modes. Explicit: its
    /// stability region (|R(hλ)| ≤ 1) is checked against the linearised arm before a run.
    Rk4,
    /// Semi-implicit Euler with the bending dampers implicit — the scheme of MuJoCo's
    /// `implicitfast`: 1 evaluation per step, global error O(dt), stable for dt·ω < 2 on
    /// the undamped modes. Energy stays bounded for small oscillations; in large nonlinear
    /// motion (configuration-dependent M) it drifts at first order.
    SemiImplicit,
}

impl Integrator {
    /// Parse `"rk4"` or `"semi_implicit"`.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for other names.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "rk4" => Ok(Integrator::Rk4),
            "semi_implicit" | "semi-implicit" => Ok(Integrator::SemiImplicit),
            _ => Err(Error::param("integrator", format!("{s:?}"), "must be \"rk4\" or \"semi_implicit\"")),
        }
    }
    /// Name as accepted by [`Integrator::parse`].
    pub fn name(self) -> &'static str {
        match self {
            Integrator::Rk4 => "rk4",
            Integrator::SemiImplicit => "semi_implicit",
        }
    }
    /// Global order of accuracy.
    pub fn order(self) -> u32 {
        match self {
            Integrator::Rk4 => 4,
            Integrator::SemiImplicit => 1,
        }
    }
}

/// Simulation options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Physics time step [s]. Default 1e-3 s; RK4 is stable on `popup-lab` well beyond it.
    pub dt: f64,
    /// Integrator. Default [`Integrator::Rk4`].
    pub integrator: Integrator,
    /// Gravity in the base frame [m/s²]; `None` takes the arm file's value.
    pub gravity: Option<[f64; 3]>,
    /// Disabled force terms.
    pub disable: Disable,
}

impl Default for Options {
    fn default() -> Self {
        Options { dt: 1e-3, integrator: Integrator::Rk4, gravity: None, disable: Disable::default() }
    }
}

/// Rigid-body inertia about a frame origin, in that frame's axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rbi {
    /// Mass [kg].
    pub m: f64,
    /// First moment m·c [kg·m] (c: centre of mass).
    pub h: Vec3,
    /// Rotational inertia about the frame origin [kg·m²].
    pub j: Mat3,
}

impl Rbi {
    /// Zero inertia.
    pub const ZERO: Rbi = Rbi { m: 0.0, h: Vec3::new(0.0, 0.0, 0.0), j: Mat3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) };

    /// Inertia of mass `m` with centre `c` and central inertia `ic`, about the origin.
    pub fn from_com(m: f64, c: Vec3, ic: Mat3) -> Rbi {
        Rbi { m, h: c * m, j: ic - skew(&c) * skew(&c) * m }
    }
    /// Sum of two inertias about the same origin.
    pub fn add(&self, o: &Rbi) -> Rbi {
        Rbi { m: self.m + o.m, h: self.h + o.h, j: self.j + o.j }
    }
    /// Express about the parent origin in parent axes: the child origin sits at `r` (child
    /// axes) from the parent origin, and `rot` maps child axes to parent axes.
    #[inline]
    pub fn to_parent(&self, rot: &Mat3, r: &Vec3) -> Rbi {
        let rs = skew(r);
        let hs = skew(&self.h);
        let j = self.j - (hs * rs + rs * hs) - rs * rs * self.m;
        Rbi { m: self.m, h: rot * (self.h + r * self.m), j: rot * j * rot.transpose() }
    }
}

/// Compiled joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointModel {
    /// Name (`q1`, `d11`, ...).
    pub name: String,
    /// Motor or bending.
    pub kind: JointKind,
    /// Joint axis in body-i axes: (0, sin α, cos α).
    pub u: Vec3,
    /// Vector from origin i-1 to origin i in body-i axes: (a, d sin α, d cos α) [m].
    pub r: Vec3,
    /// cos α.
    pub ca: f64,
    /// sin α.
    pub sa: f64,
    /// DH a [m].
    pub a: f64,
    /// DH d [m].
    pub d: f64,
    /// θ offset [rad].
    pub theta_offset: f64,
    /// Link index (0 or 1) for bending joints.
    pub link: usize,
}

impl JointModel {
    /// Rotation from body-i axes to body-(i-1) axes at joint coordinate `q` [rad].
    #[inline]
    pub fn rot(&self, q: f64) -> Mat3 {
        let (st, ct) = (q + self.theta_offset).sin_cos();
        rot_zx(ct, st, self.ca, self.sa)
    }
}

/// The compiled arm. Immutable, `Send + Sync`.
#[derive(Debug, Clone)]
pub struct Model {
    /// The spec it was compiled from (for saving and reports).
    pub spec: ArmSpec,
    /// Options.
    pub options: Options,
    /// Joints, base to tip.
    pub joints: [JointModel; NV],
    /// Body inertias about their frame origins without payload.
    pub body: [Rbi; NV],
    /// Indices of the motor joints in the chain.
    pub motor_idx: [usize; NM],
    /// Indices of the bending joints in the chain.
    pub bend_idx: [usize; NB],
    /// Armature per chain joint (zero on bending joints) [kg·m²].
    pub armature: [f64; NV],
    /// Payload body (0-based) and centre of mass in that body's frame [m].
    pub payload_body: usize,
    /// Payload centre in the payload body's frame [m].
    pub payload_com: Vec3,
    /// Link radii [m].
    pub link_radius: [f64; 2],
    /// Stiffness scale per link.
    pub link_scale: [f64; 2],
    /// Wrinkling coefficient (M_w = coef · p · r³).
    pub wrinkle_coef: f64,
    /// IMU mounts: (body 0-based, position in body frame).
    pub imu: [(usize, Vec3); 2],
    /// End-effector mount.
    pub ee: (usize, Vec3),
    /// Gravity in the base frame [m/s²] (zero when disabled).
    pub gravity: Vec3,
}

fn finite(what: &str, v: f64) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::param(what, v, "must be finite"))
    }
}

fn nonneg(what: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(Error::param(what, v, "must be finite and >= 0"))
    }
}

fn positive(what: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(Error::param(what, v, "must be finite and > 0"))
    }
}

impl Model {
    /// Validate `spec` and precompute everything the step needs.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first offending key (non-finite or negative
    /// masses, radii, stiffness, a chain that is not 3 motors + 2 bending joints per link,
    /// a non-increasing pressure table, a bad time step, ...).
    pub fn compile(spec: &ArmSpec, options: Options) -> Result<Model> {
        positive("options.dt", options.dt)?;
        if spec.joints.len() != NV {
            return Err(Error::param("joints", spec.joints.len(), "the PRBM chain must have exactly 7 joints"));
        }
        if spec.bodies.len() != NV {
            return Err(Error::param("bodies", spec.bodies.len(), "there must be exactly 7 bodies (one per joint)"));
        }
        if spec.links.len() != 2 {
            return Err(Error::param("links", spec.links.len(), "there must be exactly 2 links"));
        }
        let mut link_radius = [0.0; 2];
        let mut link_scale = [0.0; 2];
        let rref = positive("stiffness.reference_radius_m", spec.stiffness.reference_radius_m)?;
        for (l, ls) in spec.links.iter().enumerate() {
            link_radius[l] = positive(&format!("links[{l}].radius_m"), ls.radius_m)?;
            positive(&format!("links[{l}].length_m"), ls.length_m)?;
            nonneg(&format!("links[{l}].pressure_pa"), ls.pressure_pa)?;
            link_scale[l] = match ls.stiffness_scale {
                Some(s) => positive(&format!("links[{l}].stiffness_scale"), s)?,
                None => (ls.radius_m / rref).powi(3),
            };
        }
        let t = &spec.stiffness;
        if t.pressure_pa.is_empty() || t.pressure_pa.len() != t.k_nm_per_rad.len() || t.pressure_pa.len() != t.c_nms_per_rad.len() {
            return Err(Error::param(
                "stiffness",
                format!("{} pressures, {} k, {} c", t.pressure_pa.len(), t.k_nm_per_rad.len(), t.c_nms_per_rad.len()),
                "pressure_pa, k_nm_per_rad and c_nms_per_rad must be non-empty and of equal length",
            ));
        }
        for i in 0..t.pressure_pa.len() {
            nonneg(&format!("stiffness.pressure_pa[{i}]"), t.pressure_pa[i])?;
            positive(&format!("stiffness.k_nm_per_rad[{i}]"), t.k_nm_per_rad[i])?;
            nonneg(&format!("stiffness.c_nms_per_rad[{i}]"), t.c_nms_per_rad[i])?;
            if i > 0 && t.pressure_pa[i] <= t.pressure_pa[i - 1] {
                return Err(Error::param(format!("stiffness.pressure_pa[{i}]"), t.pressure_pa[i], "must be strictly increasing"));
            }
        }
        let wrinkle_coef = spec.wrinkling_coefficient()?;
        spec.effects.validate()?;
        for l in 0..2 {
            if spec.effects.higher_bending_modes.segments[l] != 1.0 || spec.effects.torsion.k_t[l].is_finite() {
                return Err(Error::param(
                    format!("effects (link {})", l + 1),
                    "higher_bending_modes.segments / torsion.k_t",
                    "extra joints (multi-segment links, torsion) are not available in this build yet",
                ));
            }
        }
        positive("wrinkling.collapse_factor", spec.wrinkling.collapse_factor)?;

        let mut motor_idx = Vec::new();
        let mut bend_idx = Vec::new();
        let mut joints = Vec::with_capacity(NV);
        let mut armature = [0.0; NV];
        for (i, js) in spec.joints.iter().enumerate() {
            let p = |k: &str| format!("joints[{i}].{k}");
            let d = finite(&p("d"), js.d)?;
            let a = finite(&p("a"), js.a)?;
            let alpha = finite(&p("alpha"), js.alpha)?;
            finite(&p("theta_offset"), js.theta_offset)?;
            let (sa, ca) = alpha.sin_cos();
            let mut link = 0;
            match js.kind {
                JointKind::Motor => {
                    let m = motor_idx.len();
                    if m < NM {
                        armature[i] = nonneg(&format!("motors.armature_kgm2[{m}]"), spec.motors.armature_kgm2[m])?;
                    }
                    motor_idx.push(i)
                }
                JointKind::Bending => {
                    if js.link != 1 && js.link != 2 {
                        return Err(Error::param(p("link"), js.link, "a bending joint must name link 1 or 2"));
                    }
                    link = js.link - 1;
                    bend_idx.push(i)
                }
            }
            joints.push(JointModel {
                name: js.name.clone(),
                kind: js.kind,
                u: Vec3::new(0.0, sa, ca),
                r: Vec3::new(a, d * sa, d * ca),
                ca,
                sa,
                a,
                d,
                theta_offset: js.theta_offset,
                link,
            });
        }
        if motor_idx.len() != NM || bend_idx.len() != NB {
            return Err(Error::param(
                "joints",
                format!("{} motor and {} bending joints", motor_idx.len(), bend_idx.len()),
                "the PRBM chain needs 3 motor and 4 bending joints",
            ));
        }
        for l in 0..2 {
            let n = bend_idx.iter().filter(|&&b| joints[b].link == l).count();
            if n != 2 {
                return Err(Error::param(format!("joints (link {})", l + 1), n, "each link needs exactly 2 bending joints (a universal joint)"));
            }
        }

        let mut body = [Rbi::ZERO; NV];
        for (i, bs) in spec.bodies.iter().enumerate() {
            if bs.link > 2 {
                return Err(Error::param(format!("bodies[{i}].link"), bs.link, "must be 0, 1 or 2"));
            }
            for (k, ps) in bs.parts.iter().enumerate() {
                let p = |s: &str| format!("bodies[{i}].parts[{k}].{s}");
                let m = nonneg(&p("mass_kg"), ps.mass_kg)?;
                let mut c = Vec3::zeros();
                for a in 0..3 {
                    c[a] = finite(&p("com_m"), ps.com_m[a])?;
                }
                let iv = ps.inertia_kgm2;
                for (a, v) in iv.iter().enumerate() {
                    finite(&format!("{}[{a}]", p("inertia_kgm2")), *v)?;
                }
                let mut ic = Mat3::new(iv[0], iv[3], iv[4], iv[3], iv[1], iv[5], iv[4], iv[5], iv[2]);
                if iv[0] < 0.0 || iv[1] < 0.0 || iv[2] < 0.0 {
                    return Err(Error::param(p("inertia_kgm2"), format!("{iv:?}"), "principal moments must be >= 0"));
                }
                if ps.shape == PartShape::Tube {
                    let l = nonneg(&p("length_m"), ps.length_m)?;
                    let r = match ps.radius_m {
                        Some(r) => positive(&p("radius_m"), r)?,
                        None if bs.link > 0 => link_radius[bs.link - 1],
                        None => return Err(Error::param(p("radius_m"), "absent", "a tube on a body without a link needs radius_m")),
                    };
                    ic += Mat3::from_diagonal(&Vec3::new(m * r * r, m * (r * r / 2.0 + l * l / 12.0), m * (r * r / 2.0 + l * l / 12.0)));
                }
                body[i] = body[i].add(&Rbi::from_com(m, c, ic));
            }
        }
        let sensor = |what: &str, b: usize, pos: [f64; 3]| -> Result<(usize, Vec3)> {
            if b < 1 || b > NV {
                return Err(Error::param(format!("{what}.body"), b, "must be a body number 1..7"));
            }
            for v in pos {
                finite(&format!("{what}.position_m"), v)?;
            }
            Ok((b - 1, Vec3::from(pos)))
        };
        if spec.sensors.imu.len() != 2 {
            return Err(Error::param("sensors.imu", spec.sensors.imu.len(), "there must be 2 IMUs (tip of link 1, tip of link 2)"));
        }
        let imu = [
            sensor("sensors.imu[0]", spec.sensors.imu[0].body, spec.sensors.imu[0].position_m)?,
            sensor("sensors.imu[1]", spec.sensors.imu[1].body, spec.sensors.imu[1].position_m)?,
        ];
        let ee = sensor("sensors.end_effector", spec.sensors.end_effector.body, spec.sensors.end_effector.position_m)?;
        let (payload_body, payload_com) = sensor("payload", spec.payload.body, spec.payload.com_m)?;
        nonneg("payload.default_kg", spec.payload.default_kg)?;
        let g = options.gravity.unwrap_or(spec.gravity_mps2);
        for v in g {
            finite("gravity", v)?;
        }
        let gravity = if options.disable.gravity { Vec3::zeros() } else { Vec3::from(g) };
        Ok(Model {
            spec: spec.clone(),
            options,
            joints: joints.try_into().expect("7 joints"),
            body,
            motor_idx: motor_idx.try_into().expect("3 motors"),
            bend_idx: bend_idx.try_into().expect("4 bending joints"),
            armature,
            payload_body,
            payload_com,
            link_radius,
            link_scale,
            wrinkle_coef,
            imu,
            ee,
            gravity,
        })
    }

    /// Name of chain joint `i` (0-based).
    pub fn joint_name(&self, i: usize) -> &str {
        &self.joints[i].name
    }

    /// Rotation from body-i to body-(i-1) axes for every joint at `q`.
    #[inline]
    pub fn rotations(&self, q: &crate::math::VecN) -> [Mat3; NV] {
        std::array::from_fn(|i| self.joints[i].rot(q[i]))
    }
}
