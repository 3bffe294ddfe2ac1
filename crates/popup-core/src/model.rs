//! The compiled, immutable `Model`: validated arm data in the form the step needs.
//!
//! `Model::compile(&ArmSpec, Options)` is the only way to get one. It is `Send + Sync` and
//! shared by every rollout; per-rollout numbers (payload, pressures) live in
//! [`crate::params::Params`].

use crate::error::{Error, Result};
use crate::beam::BeamLink;
use crate::math::{rot_x, rot_zx, skew, Mat3, Vec3, VecN, NBMAX, NELEM_MAX, NM, NMAX, NPMAX, NSEG_MAX, NV_SPEC};
use crate::spec::arm::{ArmSpec, JointKind, PartShape};

/// Switches that turn force terms off (MuJoCo-style disable flags). Effects of the
/// diagnosis layer are switched the same way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Disable {
    /// Gravity off.
    pub gravity: bool,
    /// Springs of the passive joints (bending and torsion) off.
    pub spring: bool,
    /// Dampers of the passive joints (bending and torsion) off.
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

/// Which joints the compiled chain has, beyond the arm file's 7 (physical effects
/// `higher_bending_modes` and `torsion` of `effects.md`). Chosen at compile time: it sets
/// the model's `nv`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Structure {
    /// Segments per link, 0, 1, 2 or 3 (`higher_bending_modes`): the link's outer part (the
    /// body after its universal joint) is split into this many equal pieces, each starting
    /// with its own universal joint (two bending joints). Default 1 (the arm file's chain).
    /// 0 = a rigid link: its universal joint stays in the chain, locked at δ = 0 (q̈ = 0, no
    /// spring); its `m*` channels are the constraint moments (see [`Model::locked`]).
    pub segments: [usize; 2],
    /// A torsion joint per link (`torsion`): a revolute joint about the link's own long axis
    /// at the link root, just before its (first) universal joint. Default off.
    pub torsion: [bool; 2],
    /// Euler–Bernoulli elements per link (`higher_bending_modes.elements`), 0 = PRBM (the
    /// default). A beam link of n elements has 2n universal joints (see [`crate::beam`]'s
    /// `BeamLink`); `segments` must then be 1.
    pub elements: [usize; 2],
}

impl Default for Structure {
    fn default() -> Self {
        Structure { segments: [1, 1], torsion: [false, false], elements: [0, 0] }
    }
}

impl Structure {
    /// True for the arm file's own chain (one segment per link, no torsion).
    pub fn is_nominal(&self) -> bool {
        *self == Structure::default()
    }
    /// Universal joints of link `l` in the chain: S_l for a PRBM link, 2 n_l for a beam link,
    /// 1 (locked) for a rigid link.
    pub fn chain_segments(&self, l: usize) -> usize {
        if self.elements[l] > 0 {
            2 * self.elements[l]
        } else {
            self.segments[l].max(1)
        }
    }
    /// True when link `l` is rigid (`segments[l] == 0`).
    pub fn is_rigid(&self, l: usize) -> bool {
        self.segments[l] == 0 && self.elements[l] == 0
    }
    /// Number of joints of the compiled chain: 3 motors + Σ_l (2 S_l + torsion_l) (S_l = 2 n_l
    /// for a beam link).
    pub fn nv(&self) -> usize {
        NM + (0..2).map(|l| 2 * self.chain_segments(l) + usize::from(self.torsion[l])).sum::<usize>()
    }
    /// The link model of link `l` as users write it: `"rigid"`, `"prbm"`, `"prbm(S)"` or
    /// `"beam(n)"`.
    pub fn link_name(&self, l: usize) -> String {
        match (self.elements[l], self.segments[l]) {
            (0, 0) => "rigid".into(),
            (0, 1) => "prbm".into(),
            (0, s) => format!("prbm({s})"),
            (n, _) => format!("beam({n})"),
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
    /// Extra joints (segments, torsion). Default: the arm file's 7-joint chain.
    pub structure: Structure,
}

impl Default for Options {
    fn default() -> Self {
        Options { dt: 1e-3, integrator: Integrator::Rk4, gravity: None, disable: Disable::default(), structure: Structure::default() }
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

/// How a joint's rotation depends on its coordinate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointLaw {
    /// Standard DH row: `R_{i-1,i} = Rot_z(θ + offset) Rot_x(α)`, axis z_{i-1}.
    Dh,
    /// Revolute joint about the x axis of frame i−1: `R_{i-1,i} = Rot_x(θ)`, frames i−1 and
    /// i coincide at θ = 0 (the torsion joints, about the link's long axis).
    AboutX,
}

/// Compiled joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointModel {
    /// Name (`q1`, `d11`, `d11_2` (segment 2), `t1` (torsion of link 1), ...).
    pub name: String,
    /// Motor, bending or torsion.
    pub kind: JointKind,
    /// Rotation law (DH row, or about x for torsion joints).
    pub law: JointLaw,
    /// Joint axis in body-i axes: (0, sin α, cos α) for DH rows, (1, 0, 0) for `AboutX`.
    pub u: Vec3,
    /// Vector from origin i-1 to origin i in body-i axes: (a, d sin α, d cos α) [m].
    pub r: Vec3,
    /// cos α.
    pub ca: f64,
    /// sin α.
    pub sa: f64,
    /// DH α [rad].
    pub alpha: f64,
    /// DH a [m].
    pub a: f64,
    /// DH d [m].
    pub d: f64,
    /// θ offset [rad].
    pub theta_offset: f64,
    /// Link index (0 or 1) for bending and torsion joints.
    pub link: usize,
    /// Segment of the link (1-based) for bending joints, 0 otherwise.
    pub segment: usize,
    /// For bending joints: 0 for the first axis of the universal joint (d·1), 1 for the
    /// second (d·2).
    pub axis: usize,
}

impl JointModel {
    /// A DH row.
    #[allow(clippy::too_many_arguments)]
    fn dh(name: String, kind: JointKind, d: f64, a: f64, alpha: f64, theta_offset: f64, link: usize) -> JointModel {
        let (sa, ca) = alpha.sin_cos();
        JointModel {
            name,
            kind,
            law: JointLaw::Dh,
            u: Vec3::new(0.0, sa, ca),
            r: Vec3::new(a, d * sa, d * ca),
            ca,
            sa,
            alpha,
            a,
            d,
            theta_offset,
            link,
            segment: 0,
            axis: 0,
        }
    }

    /// Rotation from body-i axes to body-(i-1) axes at joint coordinate `q` [rad].
    #[inline]
    pub fn rot(&self, q: f64) -> Mat3 {
        let (st, ct) = (q + self.theta_offset).sin_cos();
        match self.law {
            JointLaw::Dh => rot_zx(ct, st, self.ca, self.sa),
            JointLaw::AboutX => rot_x(ct, st),
        }
    }
}

/// The compiled arm. Immutable, `Send + Sync`.
///
/// The chain has `nv` joints (7 for the arm file's chain; up to [`NMAX`] with segments and
/// torsion joints, see [`Structure`]). Per-joint arrays have capacity [`NMAX`]; entries
/// `>= nv` are zero (index lists are padded with `usize::MAX`).
#[derive(Debug, Clone)]
pub struct Model {
    /// The spec it was compiled from (for saving and reports).
    pub spec: ArmSpec,
    /// Options.
    pub options: Options,
    /// Number of joints of the chain.
    pub nv: usize,
    /// Joints, base to tip (length `nv`).
    pub joints: Vec<JointModel>,
    /// Body inertias about their frame origins without payload (body i is rigid with
    /// frame i+1, moved by joint i).
    pub body: [Rbi; NMAX],
    /// Indices of the motor joints in the chain.
    pub motor_idx: [usize; NM],
    /// Indices of all bending joints in chain order (the first `nbend` entries).
    pub bend_idx: [usize; NBMAX],
    /// Number of bending joints, 2 Σ_l S_l.
    pub nbend: usize,
    /// Torsion joint of each link, if any.
    pub torsion_idx: [Option<usize>; 2],
    /// Indices of all passive joints (bending and torsion: the joints with a spring and a
    /// damper) in chain order (the first `npassive` entries).
    pub passive_idx: [usize; NPMAX],
    /// Number of passive joints.
    pub npassive: usize,
    /// Locked joints (the universal joints of rigid links, chain order; the first `nlocked`
    /// entries): not integrated (q = q̇ = q̈ = 0), no spring; the generalised constraint force
    /// that holds them is the link's root bending moment.
    pub locked_idx: [usize; 4],
    /// Number of locked joints (2 per rigid link).
    pub nlocked: usize,
    /// The universal joint at the root of each link (first segment): `[d11, d12, d21, d22]`.
    /// Their moments are the `m11..m22` channels (where wrinkling starts).
    pub root_bend_idx: [usize; 4],
    /// Per channel `d11, d12, d21, d22` (link l, axis a at index 2l + a): the bending joint
    /// of that axis in each segment, root first (the first `segments[l]` entries).
    pub segment_bend_idx: [[usize; NSEG_MAX]; 4],
    /// Universal joints per link in the chain: PRBM segments, or 2 per element of a beam link.
    pub segments: [usize; 2],
    /// Stiffness factor of each segment joint relative to the one-joint PRBM,
    /// `Σ_{i=0}^{S-1} (1 − i/S)²` (1 for S = 1): with it the static tip deflection under a
    /// tip force equals that of the one-joint link.
    pub seg_factor: [f64; 2],
    /// The structure the chain was compiled with (segments, torsion joints, beam elements).
    pub structure: Structure,
    /// Beam links (`higher_bending_modes.elements > 0`), see [`crate::beam::BeamLink`].
    pub beam: [Option<BeamLink>; 2],
    /// Model body (0-based) of each body of the arm file (0-based). A link's outer body maps
    /// to its last segment, whose frame is the original one.
    pub spec_body: [usize; NV_SPEC],
    /// Armature per chain joint (zero on passive joints) [kg·m²].
    pub armature: [f64; NMAX],
    /// Payload body (0-based) and centre of mass in that body's frame [m].
    pub payload_body: usize,
    /// Payload centre in the payload body's frame [m].
    pub payload_com: Vec3,
    /// Link radii [m].
    pub link_radius: [f64; 2],
    /// Stiffness scale per link (k and c).
    pub link_scale: [f64; 2],
    /// Extra damping factor per link (c only) [1].
    pub link_damping: [f64; 2],
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

/// A validated mass part in its body's frame.
#[derive(Debug, Clone, Copy)]
struct Part {
    m: f64,
    c: Vec3,
    /// Extra central inertia given in the arm file.
    extra: Mat3,
    /// (length, radius) of a thin-walled tube along local x.
    tube: Option<(f64, f64)>,
}

/// Central inertia of a thin-walled tube of mass `m`, radius `r`, length `l` along x.
#[inline]
fn tube_inertia(m: f64, r: f64, l: f64) -> Mat3 {
    Mat3::from_diagonal(&Vec3::new(m * r * r, m * (r * r / 2.0 + l * l / 12.0), m * (r * r / 2.0 + l * l / 12.0)))
}

impl Part {
    /// Inertia about the body origin.
    fn rbi(&self) -> Rbi {
        let mut ic = self.extra;
        if let Some((l, r)) = self.tube {
            ic += tube_inertia(self.m, r, l);
        }
        Rbi::from_com(self.m, self.c, ic)
    }
}

/// Split the parts of a link's outer body (frame O at the link tip, the universal joint at
/// x = −len on O's x axis) into segments ending at `ends[k]` from the joint (increasing, the
/// last = len; equal pieces for a multi-segment PRBM link, chord bars and zero-length node
/// segments for a beam link). Segment k (0-based) covers x ∈ [−len + ends[k−1], −len +
/// ends[k]] (the first open to −∞, the last to +∞); a tube part contributes to each segment
/// the piece of it inside (mass and extra inertia in proportion to length, tube inertia of
/// the piece's own length); points and zero-length tubes stay on the last segment. Segment
/// k < s−1 has its frame at its outer end with the axes of the link-root frame P (`r_po`
/// maps O axes to P axes); the last segment's frame is O itself.
///
/// With `beam` (a beam link: segments alternate chord bars and zero-length node frames) a
/// bar keeps the rod inertia of its chord (m h²/12 across, m r² about x) and the section's
/// rotary inertia m r²/2 across goes half to each end node's frame (the first half to the
/// link-root frame P, returned second), so that every node rotation carries inertia.
fn split_outer(parts: &[Part], ends: &[f64], len: f64, r_po: &Mat3, beam: bool) -> ([Rbi; NSEG_MAX], Rbi) {
    let s = ends.len();
    let mut out = [Rbi::ZERO; NSEG_MAX];
    let mut root = Rbi::ZERO;
    for p in parts {
        let (l, r) = match p.tube {
            Some((l, r)) if l > 0.0 => (l, r),
            _ => {
                out[s - 1] = out[s - 1].add(&p.rbi());
                continue;
            }
        };
        let (x0, x1) = (p.c.x - l / 2.0, p.c.x + l / 2.0);
        #[allow(clippy::needless_range_loop)]
        for k in 0..s {
            let lo = if k == 0 { f64::NEG_INFINITY } else { -len + ends[k - 1] };
            let hi = if k + 1 == s { f64::INFINITY } else { -len + ends[k] };
            let (a, b) = (x0.max(lo), x1.min(hi));
            if b <= a {
                continue;
            }
            let lk = b - a;
            let mk = p.m * lk / l;
            let ck = Vec3::new(0.5 * (a + b), p.c.y, p.c.z);
            let mut ick = p.extra * (lk / l) + tube_inertia(mk, r, lk);
            if beam {
                // section rotary inertia to the end nodes (node frames: x along the link)
                let half = mk * r * r / 4.0;
                ick -= Mat3::from_diagonal(&Vec3::new(0.0, 2.0 * half, 2.0 * half));
                let node = Rbi { m: 0.0, h: Vec3::zeros(), j: Mat3::from_diagonal(&Vec3::new(0.0, half, half)) };
                if k == 0 {
                    root = root.add(&Rbi { m: 0.0, h: Vec3::zeros(), j: r_po * node.j * r_po.transpose() });
                } else {
                    let prev = if k - 1 + 1 == s { node } else { Rbi { m: 0.0, h: Vec3::zeros(), j: r_po * node.j * r_po.transpose() } };
                    out[k - 1] = out[k - 1].add(&prev);
                }
                if k + 1 < s {
                    let next = if k + 2 == s { node } else { Rbi { m: 0.0, h: Vec3::zeros(), j: r_po * node.j * r_po.transpose() } };
                    out[k + 1] = out[k + 1].add(&next);
                }
            }
            let piece = if k + 1 == s {
                Rbi::from_com(mk, ck, ick)
            } else {
                // O axes → P axes, origin moved from the link tip to the segment's outer end
                let c_p = r_po * ck + Vec3::new(len - ends[k], 0.0, 0.0);
                Rbi::from_com(mk, c_p, r_po * ick * r_po.transpose())
            };
            out[k] = out[k].add(&piece);
        }
    }
    (out, root)
}

impl Model {
    /// Validate `spec` and precompute everything the step needs; expand the chain as
    /// `options.structure` asks (segments, torsion joints).
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] naming the first offending key (non-finite or negative
    /// masses, radii, stiffness, a chain that is not 3 motors + 2 bending joints per link,
    /// a non-increasing pressure table, a bad time step, a segment count outside 1..=3, a
    /// universal joint that cannot be split into segments or given a torsion joint, ...).
    pub fn compile(spec: &ArmSpec, options: Options) -> Result<Model> {
        positive("options.dt", options.dt)?;
        // the joint structure: `options.structure` or, when that is the default, the arm
        // file's structural effects (multi-segment links, torsion joints)
        let from_effects = Structure {
            segments: spec.effects.higher_bending_modes.segments.map(|s| if s.is_finite() && s >= 0.0 && s.fract() == 0.0 && s <= 3.0 { s as usize } else { usize::MAX }),
            torsion: spec.effects.torsion.k_t.map(|k| k.is_finite()),
            elements: spec.effects.higher_bending_modes.elements.map(|s| if s.is_finite() && s >= 0.0 && s.fract() == 0.0 { s as usize } else { usize::MAX }),
        };
        let structure = if options.structure == Structure::default() { from_effects } else { options.structure };
        if options.structure != Structure::default() && from_effects != Structure::default() && options.structure != from_effects {
            return Err(Error::param(
                "options.structure",
                format!("{:?}", options.structure),
                format!("contradicts the arm file's structural effects ({from_effects:?}); give the structure in one place"),
            ));
        }
        for l in 0..2 {
            let s = structure.segments[l];
            if !(0..=3).contains(&s) {
                let v = if options.structure == Structure::default() { spec.effects.higher_bending_modes.segments[l] } else { s as f64 };
                let key = if options.structure == Structure::default() { "higher_bending_modes.segments" } else { "options.structure.segments" };
                return Err(Error::param(format!("{key}[{l}] (link {})", l + 1), v, "must be 0 (rigid link), 1, 2 or 3"));
            }
            let n = structure.elements[l];
            if n > NELEM_MAX {
                return Err(Error::param(format!("higher_bending_modes.elements[{l}] (link {})", l + 1), n as f64, format!("must be a whole number 0..={NELEM_MAX} (0 = PRBM)")));
            }
            if s == 0 && structure.torsion[l] {
                return Err(Error::param(
                    format!("torsion.k_t[{l}] (link {})", l + 1),
                    spec.effects.torsion.k_t[l],
                    "a rigid link (higher_bending_modes.segments = 0) has no torsion joint: leave k_t unset",
                ));
            }
            if n > 0 && s != 1 {
                return Err(Error::param(
                    format!("higher_bending_modes.segments[{l}] (link {})", l + 1),
                    s,
                    format!("a beam link ({n} elements) has no PRBM segments: leave segments at 1"),
                ));
            }
        }
        if structure.nv() > NMAX {
            return Err(Error::param(
                "higher_bending_modes.elements",
                format!("{:?}", structure.elements),
                format!("the chain would have {} joints, more than the {NMAX} the engine holds (4 per element, 2 per PRBM segment, 1 per torsion joint, 3 motors)", structure.nv()),
            ));
        }
        if spec.joints.len() != NV_SPEC {
            return Err(Error::param("joints", spec.joints.len(), "the PRBM chain must have exactly 7 joints"));
        }
        if spec.bodies.len() != NV_SPEC {
            return Err(Error::param("bodies", spec.bodies.len(), "there must be exactly 7 bodies (one per joint)"));
        }
        if spec.links.len() != 2 {
            return Err(Error::param("links", spec.links.len(), "there must be exactly 2 links"));
        }
        let mut link_radius = [0.0; 2];
        let mut link_scale = [0.0; 2];
        let mut link_damping = [1.0; 2];
        let rref = positive("stiffness.reference_radius_m", spec.stiffness.reference_radius_m)?;
        for (l, ls) in spec.links.iter().enumerate() {
            link_radius[l] = positive(&format!("links[{l}].radius_m"), ls.radius_m)?;
            positive(&format!("links[{l}].length_m"), ls.length_m)?;
            nonneg(&format!("links[{l}].pressure_pa"), ls.pressure_pa)?;
            link_scale[l] = match ls.stiffness_scale {
                Some(s) => positive(&format!("links[{l}].stiffness_scale"), s)?,
                None => (ls.radius_m / rref).powi(3),
            };
            if let Some(s) = ls.damping_scale {
                link_damping[l] = nonneg(&format!("links[{l}].damping_scale"), s)?;
            }
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
        positive("wrinkling.collapse_factor", spec.wrinkling.collapse_factor)?;

        // the arm file's 7 rows
        let mut motor_spec = Vec::new();
        let mut bend_spec = Vec::new();
        let mut base = Vec::with_capacity(NV_SPEC);
        let mut base_armature = [0.0; NV_SPEC];
        for (i, js) in spec.joints.iter().enumerate() {
            let p = |k: &str| format!("joints[{i}].{k}");
            let d = finite(&p("d"), js.d)?;
            let a = finite(&p("a"), js.a)?;
            let alpha = finite(&p("alpha"), js.alpha)?;
            finite(&p("theta_offset"), js.theta_offset)?;
            let mut link = 0;
            match js.kind {
                JointKind::Motor => {
                    let m = motor_spec.len();
                    if m < NM {
                        base_armature[i] = nonneg(&format!("motors.armature_kgm2[{m}]"), spec.motors.armature_kgm2[m])?;
                        positive(&format!("motors.tau_max_nm[{m}]"), spec.motors.tau_max_nm[m])?;
                    }
                    motor_spec.push(i)
                }
                JointKind::Bending => {
                    if js.link != 1 && js.link != 2 {
                        return Err(Error::param(p("link"), js.link, "a bending joint must name link 1 or 2"));
                    }
                    link = js.link - 1;
                    bend_spec.push(i)
                }
                JointKind::Torsion => {
                    return Err(Error::param(
                        p("kind"),
                        "\"torsion\"",
                        "torsion joints are not written in the arm file: the torsion effect inserts them (Options.structure.torsion)",
                    ))
                }
            }
            base.push(JointModel::dh(js.name.clone(), js.kind, d, a, alpha, js.theta_offset, link));
        }
        if motor_spec.len() != NM || bend_spec.len() != 4 {
            return Err(Error::param(
                "joints",
                format!("{} motor and {} bending joints", motor_spec.len(), bend_spec.len()),
                "the PRBM chain needs 3 motor and 4 bending joints",
            ));
        }
        // the universal joint of each link: (first row, second row) in chain order
        let mut uj = [(0usize, 0usize); 2];
        for (l, u) in uj.iter_mut().enumerate() {
            let rows: Vec<usize> = bend_spec.iter().copied().filter(|&b| base[b].link == l).collect();
            if rows.len() != 2 {
                return Err(Error::param(format!("joints (link {})", l + 1), rows.len(), "each link needs exactly 2 bending joints (a universal joint)"));
            }
            *u = (rows[0], rows[1]);
        }

        let mut parts: Vec<Vec<Part>> = Vec::with_capacity(NV_SPEC);
        let mut base_body = [Rbi::ZERO; NV_SPEC];
        for (i, bs) in spec.bodies.iter().enumerate() {
            if bs.link > 2 {
                return Err(Error::param(format!("bodies[{i}].link"), bs.link, "must be 0, 1 or 2"));
            }
            let mut list = Vec::with_capacity(bs.parts.len());
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
                let extra = Mat3::new(iv[0], iv[3], iv[4], iv[3], iv[1], iv[5], iv[4], iv[5], iv[2]);
                if iv[0] < 0.0 || iv[1] < 0.0 || iv[2] < 0.0 {
                    return Err(Error::param(p("inertia_kgm2"), format!("{iv:?}"), "principal moments must be >= 0"));
                }
                let mut tube = None;
                if ps.shape == PartShape::Tube {
                    let l = nonneg(&p("length_m"), ps.length_m)?;
                    let r = match ps.radius_m {
                        Some(r) => positive(&p("radius_m"), r)?,
                        None if bs.link > 0 => link_radius[bs.link - 1],
                        None => return Err(Error::param(p("radius_m"), "absent", "a tube on a body without a link needs radius_m")),
                    };
                    tube = Some((l, r));
                }
                let part = Part { m, c, extra, tube };
                base_body[i] = base_body[i].add(&part.rbi());
                list.push(part);
            }
            parts.push(list);
        }
        let sensor = |what: &str, b: usize, pos: [f64; 3]| -> Result<(usize, Vec3)> {
            if !(1..=NV_SPEC).contains(&b) {
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

        // expansion: segments and torsion joints
        for (l, &(f, s)) in uj.iter().enumerate() {
            if structure.chain_segments(l) == 1 && !structure.torsion[l] {
                continue;
            }
            let why = format!(
                "link {} has {} universal joint(s){}: its universal joint must be two consecutive rows (d = 0, a = 0) and (d = 0, a = L > 0) without θ offsets, the outer part along x",
                l + 1,
                structure.chain_segments(l),
                if structure.torsion[l] { " and a torsion joint" } else { "" }
            );
            let bad = |k: &str, i: usize, v: f64| Err(Error::param(format!("joints[{i}].{k}"), v, why.clone()));
            if s != f + 1 {
                return Err(Error::param(format!("joints[{s}]"), &base[s].name, why.clone()));
            }
            if base[f].d != 0.0 {
                return bad("d", f, base[f].d);
            }
            if base[f].a != 0.0 {
                return bad("a", f, base[f].a);
            }
            if base[f].theta_offset != 0.0 {
                return bad("theta_offset", f, base[f].theta_offset);
            }
            if base[s].d != 0.0 {
                return bad("d", s, base[s].d);
            }
            if base[s].theta_offset != 0.0 {
                return bad("theta_offset", s, base[s].theta_offset);
            }
            if base[s].a <= 0.0 {
                return bad("a", s, base[s].a);
            }
        }
        let nv = structure.nv();
        let mut joints: Vec<JointModel> = Vec::with_capacity(nv);
        let mut body = [Rbi::ZERO; NMAX];
        let mut armature = [0.0; NMAX];
        let mut spec_body = [0usize; NV_SPEC];
        let mut i = 0;
        while i < NV_SPEC {
            let link_here = (0..2).find(|&l| uj[l].0 == i);
            match link_here {
                Some(l) if structure.chain_segments(l) > 1 || structure.torsion[l] => {
                    let (ja, jb) = (&base[i], &base[i + 1]);
                    if structure.torsion[l] {
                        joints.push(JointModel {
                            name: format!("t{}", l + 1),
                            kind: JointKind::Torsion,
                            law: JointLaw::AboutX,
                            u: Vec3::new(1.0, 0.0, 0.0),
                            r: Vec3::zeros(),
                            ca: 1.0,
                            sa: 0.0,
                            alpha: 0.0,
                            a: 0.0,
                            d: 0.0,
                            theta_offset: 0.0,
                            link: l,
                            segment: 0,
                            axis: 0,
                        });
                    }
                    let ns = structure.chain_segments(l);
                    let len = jb.a;
                    // segment lengths: S equal pieces (PRBM) or, per element, a chord bar of
                    // L/n and a zero-length node joint (beam)
                    let nel = structure.elements[l];
                    let seg_len = |k: usize| if nel == 0 { len / ns as f64 } else if k % 2 == 1 { len / nel as f64 } else { 0.0 };
                    let (pieces, root_extra) = if ns == 1 {
                        let mut p = [Rbi::ZERO; NSEG_MAX];
                        p[0] = base_body[i + 1];
                        (p, Rbi::ZERO)
                    } else {
                        let ends: Vec<f64> = if nel == 0 {
                            let seg = len / ns as f64;
                            (0..ns).map(|k| (k + 1) as f64 * seg).collect()
                        } else {
                            let h = len / nel as f64;
                            (0..ns).map(|k| (k / 2 + 1) as f64 * h).collect()
                        };
                        split_outer(&parts[i + 1], &ends, len, &(ja.rot(0.0) * jb.rot(0.0)), nel > 0)
                    };
                    if nel > 0 {
                        // the clamped root section turns with the body before the beam (frame P)
                        let prev = joints.len() - 1;
                        body[prev] = body[prev].add(&root_extra);
                    }
                    for k in 1..=ns {
                        let suffix = if k == 1 { String::new() } else { format!("_{k}") };
                        let mut a = JointModel::dh(format!("{}{suffix}", ja.name), ja.kind, 0.0, 0.0, ja.alpha, 0.0, l);
                        a.segment = k;
                        a.axis = 0;
                        if k == 1 {
                            body[joints.len()] = base_body[i];
                            spec_body[i] = joints.len();
                        }
                        joints.push(a);
                        // intermediate segments end in the link-root axes (α = −α_first), the
                        // last one in the original outer frame
                        let (seg_a, seg_alpha) = if ns == 1 { (jb.a, jb.alpha) } else if k == ns { (seg_len(k), jb.alpha) } else { (seg_len(k), -ja.alpha) };
                        let mut b = JointModel::dh(format!("{}{suffix}", jb.name), jb.kind, 0.0, seg_a, seg_alpha, 0.0, l);
                        b.segment = k;
                        b.axis = 1;
                        body[joints.len()] = pieces[k - 1];
                        if k == ns {
                            spec_body[i + 1] = joints.len();
                        }
                        joints.push(b);
                    }
                    i += 2;
                }
                _ => {
                    let mut j = base[i].clone();
                    if j.kind == JointKind::Bending {
                        j.segment = 1;
                        j.axis = usize::from(uj[j.link].1 == i);
                    }
                    body[joints.len()] = base_body[i];
                    armature[joints.len()] = base_armature[i];
                    spec_body[i] = joints.len();
                    joints.push(j);
                    i += 1;
                }
            }
        }
        debug_assert_eq!(joints.len(), nv);

        let mut motor_idx = [usize::MAX; NM];
        let mut bend_idx = [usize::MAX; NBMAX];
        let mut passive_idx = [usize::MAX; NPMAX];
        let mut torsion_idx = [None; 2];
        let mut root_bend_idx = [usize::MAX; 4];
        let mut segment_bend_idx = [[usize::MAX; NSEG_MAX]; 4];
        let mut locked_idx = [usize::MAX; 4];
        let (mut nm, mut nbend, mut npassive, mut nlocked) = (0, 0, 0, 0);
        for (i, j) in joints.iter().enumerate() {
            match j.kind {
                JointKind::Motor => {
                    motor_idx[nm] = i;
                    nm += 1;
                }
                JointKind::Bending => {
                    if structure.is_rigid(j.link) {
                        locked_idx[nlocked] = i;
                        nlocked += 1;
                    } else {
                        bend_idx[nbend] = i;
                        nbend += 1;
                        passive_idx[npassive] = i;
                        npassive += 1;
                    }
                    let ch = 2 * j.link + j.axis;
                    segment_bend_idx[ch][j.segment - 1] = i;
                    if j.segment == 1 {
                        root_bend_idx[ch] = i;
                    }
                }
                JointKind::Torsion => {
                    torsion_idx[j.link] = Some(i);
                    passive_idx[npassive] = i;
                    npassive += 1;
                }
            }
        }
        let seg_factor = structure.segments.map(|s| (0..s).map(|i| (1.0 - i as f64 / s as f64).powi(2)).sum());
        let mut model = Model {
            spec: spec.clone(),
            options,
            nv,
            joints,
            body,
            motor_idx,
            bend_idx,
            nbend,
            torsion_idx,
            passive_idx,
            npassive,
            locked_idx,
            nlocked,
            root_bend_idx,
            segment_bend_idx,
            segments: [structure.chain_segments(0), structure.chain_segments(1)],
            seg_factor,
            structure,
            beam: [None, None],
            spec_body,
            armature,
            payload_body: spec_body[payload_body],
            payload_com,
            link_radius,
            link_scale,
            link_damping,
            wrinkle_coef,
            imu: [(spec_body[imu[0].0], imu[0].1), (spec_body[imu[1].0], imu[1].1)],
            ee: (spec_body[ee.0], ee.1),
            gravity,
        };
        for l in 0..2 {
            if structure.elements[l] > 0 {
                model.attach_beam(l)?;
            }
        }
        Ok(model)
    }

    /// Compile link `l`'s chain joints into a [`BeamLink`]: the map T from the chain's
    /// geometry at q = 0 (link frame B = the tip frame's axes).
    fn attach_beam(&mut self, l: usize) -> Result<()> {
        let n = self.structure.elements[l];
        let start = self.channel_joints(2 * l)[0];
        let nb = 4 * n;
        let f = crate::kinematics::prbm::frames(self, &VecN::zeros());
        let r_b = f.r_wb[start + nb];
        let len = (f.p_wb[start + nb] - f.p_wb[start]).norm();
        let mut t_map = nalgebra::DMatrix::zeros(nb, nb);
        for e in 1..=n {
            let x_e = f.p_wb[start + 4 * e];
            for jj in 0..4 * e {
                let j = start + jj;
                let w = f.r_wb[j + 1] * self.joints[j].u;
                let dp = r_b.transpose() * w.cross(&(x_e - f.p_wb[j]));
                let dth = r_b.transpose() * w;
                let row = 4 * (e - 1);
                t_map[(row, jj)] = dp.y;
                t_map[(row + 1, jj)] = dp.z;
                t_map[(row + 2, jj)] = dth.y;
                t_map[(row + 3, jj)] = dth.z;
            }
        }
        let bar_mass: f64 = (0..n).map(|e| self.body[start + 4 * e + 1].m).sum();
        self.beam[l] = Some(BeamLink::new(l, n, start, len, self.link_radius[l], bar_mass / len, t_map)?);
        Ok(())
    }

    /// True when a link is an Euler–Bernoulli beam.
    #[inline]
    pub fn has_beam(&self) -> bool {
        self.beam[0].is_some() || self.beam[1].is_some()
    }

    /// Name of chain joint `i` (0-based, `i < nv`).
    pub fn joint_name(&self, i: usize) -> &str {
        &self.joints[i].name
    }

    /// Names of all chain joints, base to tip (`nv` names).
    pub fn joint_names(&self) -> Vec<&str> {
        self.joints.iter().map(|j| j.name.as_str()).collect()
    }

    /// All bending joints, chain order.
    #[inline]
    pub fn bend(&self) -> &[usize] {
        &self.bend_idx[..self.nbend]
    }

    /// All passive joints (bending and torsion), chain order.
    #[inline]
    pub fn passive(&self) -> &[usize] {
        &self.passive_idx[..self.npassive]
    }

    /// Locked joints (the universal joints of rigid links), chain order.
    #[inline]
    pub fn locked(&self) -> &[usize] {
        &self.locked_idx[..self.nlocked]
    }

    /// True when joint `i` is locked (a rigid link's universal joint).
    #[inline]
    pub fn is_locked(&self, i: usize) -> bool {
        self.locked().contains(&i)
    }

    /// The joints the integrator moves: all but the locked ones (torque drive) or the
    /// passive ones (replay, where the motors follow the encoders), chain order.
    pub fn free_joints(&self, replay: bool) -> Vec<usize> {
        if replay {
            self.passive().to_vec()
        } else {
            (0..self.nv).filter(|&i| !self.is_locked(i)).collect()
        }
    }

    /// The bending joints of channel `ch` (0..4: d11, d12, d21, d22) in each segment of
    /// its link, root first.
    #[inline]
    pub fn channel_joints(&self, ch: usize) -> &[usize] {
        &self.segment_bend_idx[ch][..self.segments[ch / 2]]
    }

    /// Rotation from body-i to body-(i-1) axes for every joint at `q` (identity beyond `nv`).
    #[inline]
    pub fn rotations(&self, q: &VecN) -> [Mat3; NMAX] {
        let mut r = [Mat3::identity(); NMAX];
        for (i, j) in self.joints.iter().enumerate() {
            r[i] = j.rot(q[i]);
        }
        r
    }
}
