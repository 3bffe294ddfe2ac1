//! Per-rollout parameters (`Params`: what a sweep or fit varies) and the numbers derived
//! from them for one model (`ParamData`: joint stiffness, damping, wrinkling moments and
//! body inertias with the payload).

use crate::error::{Error, Result};
use crate::math::{Mat3, NV};
use crate::model::{Model, Rbi};

/// Parameters of one rollout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Payload at the payload mount [kg], >= 0. Default: the arm's `payload.default_kg`.
    pub payload_kg: f64,
    /// Relative inflation pressure of link 1 and link 2 [Pa], >= 0. k(p), c(p) are
    /// interpolated linearly in the arm's table and clamped (with a warning) outside it.
    pub pressure_pa: [f64; 2],
}

impl Params {
    /// The arm's defaults.
    pub fn defaults(model: &Model) -> Params {
        Params {
            payload_kg: model.spec.payload.default_kg,
            pressure_pa: [model.spec.links[0].pressure_pa, model.spec.links[1].pressure_pa],
        }
    }
}

/// Numbers derived from `Params` for one model.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamData {
    /// The parameters.
    pub params: Params,
    /// Spring stiffness per chain joint (0 on motors) [N·m/rad].
    pub k: [f64; NV],
    /// Damping per chain joint (0 on motors) [N·m·s/rad].
    pub c: [f64; NV],
    /// Wrinkling-onset moment per link M_w = coef · p · r³ [N·m].
    pub mw: [f64; 2],
    /// Body inertias about their frame origins, payload included.
    pub body: [Rbi; NV],
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
    /// [`Error::InvalidParameter`] for a NaN/negative payload or pressure.
    pub fn new(model: &Model, params: &Params) -> Result<ParamData> {
        if !(params.payload_kg.is_finite() && params.payload_kg >= 0.0) {
            return Err(Error::param("payload_kg", params.payload_kg, "must be finite and >= 0 kg"));
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
        let mut k = [0.0; NV];
        let mut c = [0.0; NV];
        for &b in &model.bend_idx {
            k[b] = kl[model.joints[b].link];
            c[b] = cl[model.joints[b].link];
        }
        let mut body = model.body;
        let pb = model.payload_body;
        body[pb] = body[pb].add(&Rbi::from_com(params.payload_kg, model.payload_com, Mat3::zeros()));
        Ok(ParamData { params: *params, k, c, mw, body, warnings })
    }
}
