//! Per-rollout parameters (`Params`: what a sweep or fit varies) and the numbers derived
//! from them for one model (`ParamData`: joint stiffness, damping, wrinkling moments and
//! body inertias with the payload).

use crate::error::{Error, Result};
use crate::math::{Mat3, NMAX};
use crate::model::{Model, Rbi};

/// Per-rollout numbers of the extra joints (effects `higher_bending_modes` and `torsion`).
/// Neutral values: `seg_k_scale = 1`, and the torsion entries are ignored for a link
/// without a torsion joint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flex {
    /// Factor on the stiffness and damping of every bending joint of link l (all its
    /// segments), finite and > 0. Neutral 1.0.
    pub seg_k_scale: [f64; 2],
    /// Torsional stiffness of link l's torsion joint [N·m/rad], > 0; must be finite when
    /// the model has that joint. Default +∞ (no torsion joint: rigid in torsion).
    pub k_t: [f64; 2],
    /// Torsional damping of link l's torsion joint [N·m·s/rad], finite and >= 0. Default 0.
    pub c_t: [f64; 2],
}

impl Default for Flex {
    fn default() -> Self {
        Flex { seg_k_scale: [1.0, 1.0], k_t: [f64::INFINITY; 2], c_t: [0.0, 0.0] }
    }
}

/// Parameters of one rollout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Payload at the payload mount [kg], >= 0. Default: the arm's `payload.default_kg`.
    pub payload_kg: f64,
    /// Relative inflation pressure of link 1 and link 2 [Pa], >= 0. k(p), c(p) are
    /// interpolated linearly in the arm's table and clamped (with a warning) outside it.
    pub pressure_pa: [f64; 2],
    /// Segment stiffness scale and torsion spring/damper.
    pub flex: Flex,
}

impl Params {
    /// The arm's defaults.
    pub fn defaults(model: &Model) -> Params {
        Params {
            payload_kg: model.spec.payload.default_kg,
            pressure_pa: [model.spec.links[0].pressure_pa, model.spec.links[1].pressure_pa],
            flex: Flex::default(),
        }
    }
}

/// Numbers derived from `Params` for one model.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamData {
    /// The parameters.
    pub params: Params,
    /// Spring stiffness per chain joint (0 on motors and beyond `nv`) [N·m/rad]. Bending
    /// joints of link l: k(p) · link scale · segment factor · `seg_k_scale[l]`; torsion:
    /// `k_t[l]`.
    pub k: [f64; NMAX],
    /// Damping per chain joint (0 on motors and beyond `nv`) [N·m·s/rad], as `k` with c(p)
    /// and `c_t`.
    pub c: [f64; NMAX],
    /// Wrinkling-onset moment per link M_w = coef · p · r³ [N·m].
    pub mw: [f64; 2],
    /// Body inertias about their frame origins, payload included.
    pub body: [Rbi; NMAX],
    /// Warnings raised while deriving (pressure outside the table, ...).
    pub warnings: Vec<String>,
}

/// Linear interpolation in a table, clamped to its ends. Returns (value, clamped).
pub fn interp_clamped(xs: &[f64], ys: &[f64], x: f64) -> (f64, bool) {
    let n = xs.len();
    if x <= xs[0] {
        return (ys[0], x < xs[0]);
    }
    if x >= xs[n - 1] {
        return (ys[n - 1], x > xs[n - 1]);
    }
    let i = xs.partition_point(|&v| v <= x) - 1;
    let w = (x - xs[i]) / (xs[i + 1] - xs[i]);
    (ys[i] + w * (ys[i + 1] - ys[i]), false)
}

impl ParamData {
    /// Derive the per-rollout numbers.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for a NaN/negative payload or pressure, a non-finite or
    /// non-positive `flex.seg_k_scale`, a NaN or non-positive `flex.k_t`, a non-finite or
    /// negative `flex.c_t`, or an infinite `flex.k_t` for a link that has a torsion joint.
    pub fn new(model: &Model, params: &Params) -> Result<ParamData> {
        if !(params.payload_kg.is_finite() && params.payload_kg >= 0.0) {
            return Err(Error::param("payload_kg", params.payload_kg, "must be finite and >= 0 kg"));
        }
        let f = &params.flex;
        for l in 0..2 {
            let s = f.seg_k_scale[l];
            if !(s.is_finite() && s > 0.0) {
                return Err(Error::param(format!("flex.seg_k_scale[{l}] (link {})", l + 1), s, "must be finite and > 0 (neutral 1)"));
            }
            let kt = f.k_t[l];
            if kt.is_nan() || kt <= 0.0 {
                return Err(Error::param(format!("flex.k_t[{l}] (link {})", l + 1), kt, "must be > 0 N·m/rad"));
            }
            if model.torsion_idx[l].is_some() && kt.is_infinite() {
                return Err(Error::param(
                    format!("flex.k_t[{l}] (link {})", l + 1),
                    kt,
                    "must be finite: the model has a torsion joint for this link (Options.structure.torsion); give its torsional stiffness",
                ));
            }
            let ct = f.c_t[l];
            if !(ct.is_finite() && ct >= 0.0) {
                return Err(Error::param(format!("flex.c_t[{l}] (link {})", l + 1), ct, "must be finite and >= 0 N·m·s/rad"));
            }
        }
        let mut warnings = Vec::new();
        let t = &model.spec.stiffness;
        let mut kl = [0.0; 2];
        let mut cl = [0.0; 2];
        let mut mw = [0.0; 2];
        for l in 0..2 {
            let p = params.pressure_pa[l];
            if !(p.is_finite() && p >= 0.0) {
                return Err(Error::param(format!("pressure_pa[{l}] (link {})", l + 1), p, "must be finite and >= 0 Pa (relative pressure)"));
            }
            let (k, clamped) = interp_clamped(&t.pressure_pa, &t.k_nm_per_rad, p);
            let (c, _) = interp_clamped(&t.pressure_pa, &t.c_nms_per_rad, p);
            if clamped {
                warnings.push(format!(
                    "link {} pressure {p} Pa is outside the stiffness table [{}, {}] Pa: k and c clamped to the end row",
                    l + 1,
                    t.pressure_pa[0],
                    t.pressure_pa[t.pressure_pa.len() - 1]
                ));
            }
            kl[l] = k * model.link_scale[l];
            cl[l] = c * model.link_scale[l];
            mw[l] = model.wrinkle_coef * p * model.link_radius[l].powi(3);
        }
        let mut k = [0.0; NMAX];
        let mut c = [0.0; NMAX];
        for &b in model.bend() {
            let l = model.joints[b].link;
            k[b] = kl[l] * model.seg_factor[l] * f.seg_k_scale[l];
            c[b] = cl[l] * model.seg_factor[l] * f.seg_k_scale[l];
        }
        for l in 0..2 {
            if let Some(t) = model.torsion_idx[l] {
                k[t] = f.k_t[l];
                c[t] = f.c_t[l];
            }
        }
        let mut body = model.body;
        let pb = model.payload_body;
        body[pb] = body[pb].add(&Rbi::from_com(params.payload_kg, model.payload_com, Mat3::zeros()));
        Ok(ParamData { params: *params, k, c, mw, body, warnings })
    }
}
