//! Reference generators: position references per motor joint [rad] as functions of time
//! [s] measured from the start of the phase that uses them.

use crate::error::{Error, Result};

/// One joint's position reference r(t) [rad]. In TOML: a table with `kind` = the variant
/// name in snake case and the fields, e.g. `{ kind = "step", from = 0.0, to = 0.5, delay = 2.0 }`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Signal {
    /// Constant value.
    Const {
        /// Value [rad].
        value: f64,
    },
    /// `from` until `delay`, then `to`.
    Step {
        /// Value before the step [rad].
        from: f64,
        /// Value after the step [rad].
        to: f64,
        /// Time of the step [s].
        delay: f64,
    },
    /// `low` until `delay`, then alternating `high` / `low` every half period (starting high).
    Square {
        /// Low value [rad].
        low: f64,
        /// High value [rad].
        high: f64,
        /// Full period [s].
        period: f64,
        /// Start of the first high half [s].
        delay: f64,
    },
    /// `from` until `delay`, then `from + rate (t − delay)` until it reaches `to`.
    Ramp {
        /// Start value [rad].
        from: f64,
        /// End value [rad].
        to: f64,
        /// Slope magnitude [rad/s] (> 0; the sign follows `to − from`).
        rate: f64,
        /// Start of the ramp [s].
        delay: f64,
    },
    /// Minimum-jerk move from `from` to `to` in `duration`, starting at `delay`:
    /// `r = from + (to − from)(10 s³ − 15 s⁴ + 6 s⁵)`, `s = (t − delay)/duration ∈ [0, 1]`.
    MinJerk {
        /// Start value [rad].
        from: f64,
        /// End value [rad].
        to: f64,
        /// Start time [s].
        delay: f64,
        /// Duration [s] (> 0).
        duration: f64,
    },
    /// `offset + amplitude sin(2π f (t − delay) + phase)` for t ≥ delay, `offset + amplitude sin(phase)` before.
    Sine {
        /// Mean value [rad].
        offset: f64,
        /// Amplitude [rad].
        amplitude: f64,
        /// Frequency [Hz].
        freq_hz: f64,
        /// Phase [rad].
        phase: f64,
        /// Start [s].
        delay: f64,
    },
    /// Linear chirp `offset + amplitude sin(2π (f0 τ + (f1 − f0) τ² / (2 D)))`, τ = t − delay ∈ [0, D], `offset` outside.
    Chirp {
        /// Mean value [rad].
        offset: f64,
        /// Amplitude [rad].
        amplitude: f64,
        /// Start frequency [Hz].
        f0_hz: f64,
        /// End frequency [Hz].
        f1_hz: f64,
        /// Sweep duration D [s] (> 0).
        duration: f64,
        /// Start [s].
        delay: f64,
    },
    /// User samples, linear interpolation, held at the ends.
    Samples {
        /// Strictly increasing times [s].
        t: Vec<f64>,
        /// Values [rad].
        y: Vec<f64>,
    },
}

fn min_jerk(s: f64) -> f64 {
    let s = s.clamp(0.0, 1.0);
    s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
}

impl Signal {
    /// Value at `t` [s] (time since the phase started).
    #[inline]
    pub fn eval(&self, t: f64) -> f64 {
        use std::f64::consts::TAU;
        match self {
            Signal::Const { value } => *value,
            Signal::Step { from, to, delay } => {
                if t < *delay {
                    *from
                } else {
                    *to
                }
            }
            Signal::Square { low, high, period, delay } => {
                if t < *delay {
                    return *low;
                }
                let ph = ((t - delay) / period).fract();
                if ph < 0.5 {
                    *high
                } else {
                    *low
                }
            }
            Signal::Ramp { from, to, rate, delay } => {
                if t < *delay {
                    return *from;
                }
                let span = (to - from).abs();
                let moved = (rate * (t - delay)).min(span);
                from + moved.copysign(to - from)
            }
            Signal::MinJerk { from, to, delay, duration } => from + (to - from) * min_jerk((t - delay) / duration),
            Signal::Sine { offset, amplitude, freq_hz, phase, delay } => offset + amplitude * (TAU * freq_hz * (t - delay).max(0.0) + phase).sin(),
            Signal::Chirp { offset, amplitude, f0_hz, f1_hz, duration, delay } => {
                let tau = t - delay;
                if tau < 0.0 || tau > *duration {
                    return *offset;
                }
                offset + amplitude * (TAU * (f0_hz * tau + (f1_hz - f0_hz) * tau * tau / (2.0 * duration))).sin()
            }
            Signal::Samples { t: ts, y } => {
                let n = ts.len();
                if t <= ts[0] {
                    return y[0];
                }
                if t >= ts[n - 1] {
                    return y[n - 1];
                }
                let i = ts.partition_point(|&v| v <= t) - 1;
                let w = (t - ts[i]) / (ts[i + 1] - ts[i]);
                y[i] + w * (y[i + 1] - y[i])
            }
        }
    }

    /// Check the parameters; `what` names the signal in errors.
    ///
    /// # Errors
    /// [`Error::InvalidParameter`] for non-finite numbers, non-positive periods, rates or
    /// durations, and (for samples) empty, mismatched or non-increasing arrays.
    pub fn validate(&self, what: &str) -> Result<()> {
        let fin = |n: &str, v: f64| if v.is_finite() { Ok(()) } else { Err(Error::param(format!("{what}.{n}"), v, "must be finite")) };
        let pos = |n: &str, v: f64| if v.is_finite() && v > 0.0 { Ok(()) } else { Err(Error::param(format!("{what}.{n}"), v, "must be finite and > 0")) };
        match self {
            Signal::Const { value } => fin("value", *value),
            Signal::Step { from, to, delay } => fin("from", *from).and(fin("to", *to)).and(fin("delay", *delay)),
            Signal::Square { low, high, period, delay } => fin("low", *low).and(fin("high", *high)).and(pos("period", *period)).and(fin("delay", *delay)),
            Signal::Ramp { from, to, rate, delay } => fin("from", *from).and(fin("to", *to)).and(pos("rate", *rate)).and(fin("delay", *delay)),
            Signal::MinJerk { from, to, delay, duration } => fin("from", *from).and(fin("to", *to)).and(fin("delay", *delay)).and(pos("duration", *duration)),
            Signal::Sine { offset, amplitude, freq_hz, phase, delay } => {
                fin("offset", *offset).and(fin("amplitude", *amplitude)).and(fin("freq_hz", *freq_hz)).and(fin("phase", *phase)).and(fin("delay", *delay))
            }
            Signal::Chirp { offset, amplitude, f0_hz, f1_hz, duration, delay } => fin("offset", *offset)
                .and(fin("amplitude", *amplitude))
                .and(fin("f0_hz", *f0_hz))
                .and(fin("f1_hz", *f1_hz))
                .and(pos("duration", *duration))
                .and(fin("delay", *delay)),
            Signal::Samples { t, y } => {
                if t.is_empty() || t.len() != y.len() {
                    return Err(Error::input(what, format!("samples need equal, non-zero lengths (t: {}, y: {})", t.len(), y.len())));
                }
                for i in 0..t.len() {
                    if !t[i].is_finite() || !y[i].is_finite() {
                        return Err(Error::input(what, format!("sample {i} is (t = {}, y = {})", t[i], y[i])));
                    }
                    if i > 0 && t[i] <= t[i - 1] {
                        return Err(Error::input(what, format!("t must be strictly increasing: t[{i}] = {} <= t[{}] = {}", t[i], i - 1, t[i - 1])));
                    }
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes() {
        assert_eq!(Signal::Step { from: 0.0, to: 1.0, delay: 2.0 }.eval(1.999), 0.0);
        assert_eq!(Signal::Step { from: 0.0, to: 1.0, delay: 2.0 }.eval(2.0), 1.0);
        let sq = Signal::Square { low: -1.0, high: 1.0, period: 4.0, delay: 1.0 };
        assert_eq!([sq.eval(0.5), sq.eval(1.5), sq.eval(3.5), sq.eval(5.5)], [-1.0, 1.0, -1.0, 1.0]);
        let r = Signal::Ramp { from: 1.0, to: 0.0, rate: 0.5, delay: 1.0 };
        assert_eq!([r.eval(0.0), r.eval(2.0), r.eval(10.0)], [1.0, 0.5, 0.0]);
        let mj = Signal::MinJerk { from: 0.0, to: 2.0, delay: 1.0, duration: 2.0 };
        assert_eq!([mj.eval(0.0), mj.eval(2.0), mj.eval(3.0), mj.eval(9.0)], [0.0, 1.0, 2.0, 2.0]);
        // minimum jerk: zero velocity and acceleration at both ends (finite differences)
        let h = 1e-5;
        for t0 in [1.0, 3.0] {
            let v = (mj.eval(t0 + h) - mj.eval(t0 - h)) / (2.0 * h);
            assert!(v.abs() < 1e-8, "v({t0}) = {v}");
        }
        let s = Signal::Sine { offset: 0.1, amplitude: 0.2, freq_hz: 0.5, phase: 0.0, delay: 0.0 };
        assert!((s.eval(0.5) - 0.3).abs() < 1e-12);
        let c = Signal::Chirp { offset: 0.0, amplitude: 1.0, f0_hz: 1.0, f1_hz: 3.0, duration: 2.0, delay: 0.0 };
        // instantaneous frequency f0 + (f1 − f0) τ / D: phase at τ = 2 is 2π (2 + 2) → sin = 0
        assert!(c.eval(2.0).abs() < 1e-9);
        let u = Signal::Samples { t: vec![0.0, 1.0], y: vec![0.0, 2.0] };
        assert_eq!([u.eval(-1.0), u.eval(0.25), u.eval(5.0)], [0.0, 0.5, 2.0]);
    }

    #[test]
    fn validation_names_the_field() {
        let e = Signal::Square { low: 0.0, high: 1.0, period: 0.0, delay: 0.0 }.validate("phases[2].reference[0]").unwrap_err();
        assert!(e.to_string().contains("phases[2].reference[0].period"), "{e}");
        let e = Signal::Samples { t: vec![0.0, 0.0], y: vec![1.0, 2.0] }.validate("ref").unwrap_err();
        assert!(e.to_string().contains("strictly increasing"), "{e}");
    }
}
