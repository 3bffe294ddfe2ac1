//! Per-rollout parameters (`Params`: what a sweep or fit varies) and the numbers derived
//! from them for one model (`ParamData`: joint stiffness, damping, wrinkling moments and
//! body inertias with the payload).

use crate::error::{Error, Result};
use crate::effects::{drag_points, DragPoint, Effects, MAX_DRAG};
use crate::math::{Mat3, MatN, Vec3, NMAX};
use crate::model::{Model, Rbi};

/// Parameters of one rollout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Payload at the payload mount [kg], >= 0. Default: the arm's `payload.default_kg`.
    pub payload_kg: f64,
    /// Relative inflation pressure of link 1 and link 2 [Pa], >= 0. k(p), c(p) are
    /// interpolated linearly in the arm's table and clamped (with a warning) outside it.
    pub pressure_pa: [f64; 2],
    /// Effect parameters (default: the arm file's `[effects]`, usually all neutral). The
    /// structural ones (segments, whether a torsion joint exists) are the compiled model's;
    /// `higher_bending_modes.k_scale` and `torsion.k_t`, `c_t` act on the extra joints.
    pub effects: Effects,
}

impl Params {
    /// The arm's defaults.
    pub fn defaults(model: &Model) -> Params {
        Params {
            payload_kg: model.spec.payload.default_kg,
            pressure_pa: [model.spec.links[0].pressure_pa, model.spec.links[1].pressure_pa],
            effects: model.spec.effects,
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
    /// Table values k(p₀), c(p₀) per link before the link scale (for `pressure_leak`).
    pub kc0: [[f64; 2]; 2],
    /// Beam links: elastic stiffness `Tᵀ K T` in chain coordinates (zero outside the beam
    /// blocks; their diagonal `k` entries are 0) [N·m/rad].
    pub beam_k: MatN,
    /// Beam links: Rayleigh damping `Tᵀ (μ M + λ K) T` in chain coordinates [N·m·s/rad].
    pub beam_c: MatN,
    /// Air-drag quadrature points and their count (filled only with `air_drag` on).
    pub drag: ([DragPoint; MAX_DRAG], usize),
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
    /// [`Error::InvalidParameter`] for a NaN/negative payload or pressure, an effect
    /// parameter out of its bounds (`effects.<effect>.<param>[i]`), an infinite
    /// `effects.torsion.k_t` for a link that has a torsion joint, or a negative total payload.
    pub fn new(model: &Model, params: &Params) -> Result<ParamData> {
        if !(params.payload_kg.is_finite() && params.payload_kg >= 0.0) {
            return Err(Error::param("payload_kg", params.payload_kg, "must be finite and >= 0 kg"));
        }
        let fx = &params.effects;
        fx.validate()?;
        fx.check_structure(model)?;
        let payload = params.payload_kg + fx.payload_mass.delta_kg;
        if payload < 0.0 {
            return Err(Error::param(
                "effects.payload_mass.delta_kg",
                fx.payload_mass.delta_kg,
                format!("gives a negative payload ({payload} kg with {} kg declared)", params.payload_kg),
            ));
        }
        let mut warnings = Vec::new();
        let t = &model.spec.stiffness;
        let mut kl = [0.0; 2];
        let mut cl = [0.0; 2];
        let mut mw = [0.0; 2];
        let mut kc0 = [[0.0; 2]; 2];
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
            kc0[l] = [k, c];
            kl[l] = k * model.link_scale[l];
            cl[l] = c * model.link_scale[l] * model.link_damping[l];
            mw[l] = model.wrinkle_coef * p * model.link_radius[l].powi(3);
            if fx.wrinkling.mw_scale != 1.0 {
                mw[l] *= fx.wrinkling.mw_scale;
            }
        }
        let mut k = [0.0; NMAX];
        let mut c = [0.0; NMAX];
        for &b in model.bend() {
            let l = model.joints[b].link;
            if model.beam[l].is_some() {
                continue;
            }
            // k_scale and root_ratio shape the segments of a multi-segment link only (neutral for one)
            let mut sc = if model.segments[l] > 1 { fx.higher_bending_modes.k_scale[l] } else { 1.0 };
            let r = fx.higher_bending_modes.root_ratio[l];
            if model.segments[l] > 1 && r != 1.0 {
                // root × r·α, the others × α, with α keeping Σ (1 − i/S)²/k_i (the static tip
                // deflection under a tip force)
                let f = model.seg_factor[l];
                let alpha = (1.0 / r + f - 1.0) / f;
                sc *= if model.joints[b].segment == 1 { r * alpha } else { alpha };
            }
            k[b] = kl[l] * model.seg_factor[l] * sc;
            c[b] = cl[l] * model.seg_factor[l] * sc;
        }
        for l in 0..2 {
            if let Some(t) = model.torsion_idx[l] {
                k[t] = fx.torsion.k_t[l];
                c[t] = fx.torsion.c_t[l];
            }
        }
        let mut body = model.body;
        let pb = model.payload_body;
        let com = if fx.payload_mass.com_offset_m == [0.0; 3] { model.payload_com } else { model.payload_com + Vec3::from(fx.payload_mass.com_offset_m) };
        let payload = if fx.payload_mass.delta_kg == 0.0 { params.payload_kg } else { payload };
        body[pb] = body[pb].add(&Rbi::from_com(payload, com, Mat3::zeros()));
        let mut beam_k = MatN::zeros();
        let mut beam_c = MatN::zeros();
        for bl in model.beam.iter().flatten() {
            let l = bl.link;
            // name the effect parameter behind a bad section value
            let (kj, cj) = bl.joint_matrices(&fx.higher_bending_modes.material(l), params.pressure_pa[l]).map_err(|e| match e {
                Error::InvalidParameter { what, value, requirement } => {
                    let key = match what.as_str() {
                        "beam.E" => format!("effects.higher_bending_modes.e_pa[{l}]"),
                        "beam.t" => format!("effects.higher_bending_modes.wall_m[{l}]"),
                        "beam.nu" => format!("effects.higher_bending_modes.nu[{l}]"),
                        other => format!("{other} (beam link {})", l + 1),
                    };
                    Error::InvalidParameter { what: key, value, requirement }
                }
                other => other,
            })?;
            for i in 0..bl.dof() {
                for j in 0..bl.dof() {
                    beam_k[(bl.start + i, bl.start + j)] = kj[(i, j)];
                    beam_c[(bl.start + i, bl.start + j)] = cj[(i, j)];
                }
            }
        }
        let drag = if fx.air_drag.cd > 0.0 { drag_points(model) } else { ([DragPoint { body: 0, p_b: Vec3::zeros(), area: 0.0 }; MAX_DRAG], 0) };
        Ok(ParamData { params: *params, k, c, mw, body, kc0, beam_k, beam_c, drag, warnings })
    }

    /// Spring and damper coefficients of chain joint `b` at time `t` (with `pressure_leak`,
    /// a bending joint's k and c follow the table at p(t)) [N·m/rad], [N·m·s/rad].
    #[inline]
    pub fn kc_at(&self, model: &Model, b: usize, t: f64) -> (f64, f64) {
        let l = model.joints[b].link;
        let rate = self.params.effects.pressure_leak.rate[l];
        if rate == 0.0 || model.torsion_idx[l] == Some(b) {
            return (self.k[b], self.c[b]);
        }
        let tab = &model.spec.stiffness;
        let p = self.params.pressure_pa[l] * (-rate * t).exp();
        let (k, _) = interp_clamped(&tab.pressure_pa, &tab.k_nm_per_rad, p);
        let (c, _) = interp_clamped(&tab.pressure_pa, &tab.c_nms_per_rad, p);
        (self.k[b] * (k / self.kc0[l][0]), if self.kc0[l][1] > 0.0 { self.c[b] * (c / self.kc0[l][1]) } else { self.c[b] })
    }

    /// Pressure of link `l` at time `t` [Pa].
    #[inline]
    pub fn pressure_at(&self, l: usize, t: f64) -> f64 {
        let rate = self.params.effects.pressure_leak.rate[l];
        if rate == 0.0 {
            self.params.pressure_pa[l]
        } else {
            self.params.pressure_pa[l] * (-rate * t).exp()
        }
    }

    /// Wrinkling-onset moment of link `l` at time `t` [N·m].
    #[inline]
    pub fn mw_at(&self, l: usize, t: f64) -> f64 {
        let rate = self.params.effects.pressure_leak.rate[l];
        if rate == 0.0 {
            self.mw[l]
        } else {
            self.mw[l] * (-rate * t).exp()
        }
    }
}
