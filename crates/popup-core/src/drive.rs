//! What drives the motor joints: motor torques (torque-driven) or encoder angles that the
//! motors follow exactly (encoder-driven replay).
//!
//! Replay interpolates each encoder channel with a natural cubic spline (C², so q, q̇, q̈
//! are the exact derivatives of one curve and consistent with each other). Torque inputs
//! are interpolated linearly between their samples and held at the ends.

use crate::error::{Error, Result};
use crate::math::NM;

/// Natural cubic spline through (t_i, y_i) for three channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Spline3 {
    t: Vec<f64>,
    y: Vec<[f64; NM]>,
    m: Vec<[f64; NM]>,
}

fn check_times(what: &str, t: &[f64], n_values: usize) -> Result<()> {
    if t.len() < 2 {
        return Err(Error::input(what, format!("needs at least 2 samples, got {}", t.len())));
    }
    if t.len() != n_values {
        return Err(Error::input(what, format!("{} time stamps but {} value rows", t.len(), n_values)));
    }
    for i in 0..t.len() {
        if !t[i].is_finite() {
            return Err(Error::input(what, format!("time stamp at row {i} is {}", t[i])));
        }
        if i > 0 && t[i] <= t[i - 1] {
            return Err(Error::input(what, format!("time must be strictly increasing: t[{i}] = {} <= t[{}] = {}", t[i], i - 1, t[i - 1])));
        }
    }
    Ok(())
}

fn check_values(what: &str, y: &[[f64; NM]]) -> Result<()> {
    for (i, row) in y.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            if !v.is_finite() {
                return Err(Error::input(what, format!("value at row {i}, column {c} is {v}")));
            }
        }
    }
    Ok(())
}

impl Spline3 {
    /// Fit the spline.
    ///
    /// # Errors
    /// [`Error::Input`] for fewer than 2 samples, mismatched lengths, non-increasing or
    /// non-finite times, non-finite values.
    pub fn new(t: &[f64], y: &[[f64; NM]]) -> Result<Spline3> {
        check_times("encoder replay", t, y.len())?;
        check_values("encoder replay angles", y)?;
        // plausibility (popup_core::limits): an angle no motor joint reaches is refused, not
        // handed to the static solve (1e300 rad ended as "equilibrium did not converge")
        let lim = crate::limits::channel_limit("q1").map_or(f64::INFINITY, |l| l.error);
        for (i, row) in y.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                if v.abs() > lim {
                    return Err(Error::input(
                        "encoder replay angles",
                        format!("value at row {i}, column {c} (q{}) is {} rad, beyond {} rad (4 turns): no motor joint reaches it; degrees? (convert with × π/180)", c + 1, crate::limits::num(*v), crate::limits::num(lim)),
                    ));
                }
            }
        }
        let n = t.len();
        let mut m = vec![[0.0; NM]; n];
        if n > 2 {
            // tridiagonal system for interior second derivatives (natural ends: m = 0)
            let k = n - 2;
            let mut cp = vec![0.0; k];
            let mut dp = vec![[0.0; NM]; k];
            for i in 0..k {
                let (h0, h1) = (t[i + 1] - t[i], t[i + 2] - t[i + 1]);
                let (a, b, c) = (h0 / 6.0, (h0 + h1) / 3.0, h1 / 6.0);
                let denom = b - if i > 0 { a * cp[i - 1] } else { 0.0 };
                cp[i] = c / denom;
                for ch in 0..NM {
                    let r = (y[i + 2][ch] - y[i + 1][ch]) / h1 - (y[i + 1][ch] - y[i][ch]) / h0;
                    let prev = if i > 0 { a * dp[i - 1][ch] } else { 0.0 };
                    dp[i][ch] = (r - prev) / denom;
                }
            }
            for i in (0..k).rev() {
                for ch in 0..NM {
                    let next = if i + 1 < k { m[i + 2][ch] } else { 0.0 };
                    m[i + 1][ch] = dp[i][ch] - cp[i] * next;
                }
            }
        }
        Ok(Spline3 { t: t.to_vec(), y: y.to_vec(), m })
    }

    /// Knot times [s] and values.
    pub fn knots(&self) -> (&[f64], &[[f64; NM]]) {
        (&self.t, &self.y)
    }

    /// First and last knot times [s].
    pub fn span(&self) -> (f64, f64) {
        (self.t[0], self.t[self.t.len() - 1])
    }

    /// Value, first and second derivative at `x` (clamped to the span).
    #[inline]
    pub fn eval(&self, x: f64) -> ([f64; NM], [f64; NM], [f64; NM]) {
        let n = self.t.len();
        let x = x.clamp(self.t[0], self.t[n - 1]);
        let i = (self.t.partition_point(|&v| v <= x).max(1) - 1).min(n - 2);
        let h = self.t[i + 1] - self.t[i];
        let a = (self.t[i + 1] - x) / h;
        let b = (x - self.t[i]) / h;
        let mut q = [0.0; NM];
        let mut qd = [0.0; NM];
        let mut qdd = [0.0; NM];
        for c in 0..NM {
            let (m0, m1, y0, y1) = (self.m[i][c], self.m[i + 1][c], self.y[i][c], self.y[i + 1][c]);
            q[c] = a * y0 + b * y1 + ((a * a * a - a) * m0 + (b * b * b - b) * m1) * h * h / 6.0;
            qd[c] = (y1 - y0) / h + ((3.0 * b * b - 1.0) * m1 - (3.0 * a * a - 1.0) * m0) * h / 6.0;
            qdd[c] = a * m0 + b * m1;
        }
        (q, qd, qdd)
    }
}

/// Piecewise-linear signal of three channels (motor torques).
#[derive(Debug, Clone, PartialEq)]
pub struct Linear3 {
    t: Vec<f64>,
    y: Vec<[f64; NM]>,
}

impl Linear3 {
    /// Build from samples.
    ///
    /// # Errors
    /// As [`Spline3::new`]; a single sample is allowed (constant signal).
    pub fn new(t: &[f64], y: &[[f64; NM]]) -> Result<Linear3> {
        if t.len() == 1 && y.len() == 1 {
            check_values("motor torques", y)?;
            return Ok(Linear3 { t: vec![t[0], t[0] + 1.0], y: vec![y[0], y[0]] });
        }
        check_times("motor torques", t, y.len())?;
        check_values("motor torques", y)?;
        Ok(Linear3 { t: t.to_vec(), y: y.to_vec() })
    }

    /// Value at `x`, held constant outside the span.
    #[inline]
    pub fn eval(&self, x: f64) -> [f64; NM] {
        let n = self.t.len();
        if x <= self.t[0] {
            return self.y[0];
        }
        if x >= self.t[n - 1] {
            return self.y[n - 1];
        }
        let i = self.t.partition_point(|&v| v <= x) - 1;
        let w = (x - self.t[i]) / (self.t[i + 1] - self.t[i]);
        std::array::from_fn(|c| self.y[i][c] + w * (self.y[i + 1][c] - self.y[i][c]))
    }
}

/// How the motor joints are driven during a run.
#[derive(Debug, Clone, PartialEq)]
pub enum Drive {
    /// Motor torques (reflected to the joint output, armature included in the model) [N·m].
    Torque(Linear3),
    /// Encoder-driven replay: the motor joints follow these angles exactly [rad].
    Replay(Spline3),
    /// Constant motor torques at the joint outputs [N·m] (the zero-order hold of a
    /// controller between two of its ticks).
    Hold([f64; NM]),
}

impl Drive {
    /// True for replay.
    pub fn is_replay(&self) -> bool {
        matches!(self, Drive::Replay(_))
    }

    /// Motor torques at `t` for the torque-driven variants [N·m] (`None` in replay).
    #[inline]
    pub fn torque(&self, t: f64) -> Option<[f64; NM]> {
        match self {
            Drive::Torque(sig) => Some(sig.eval(t)),
            Drive::Hold(tau) => Some(*tau),
            Drive::Replay(_) => None,
        }
    }
}
