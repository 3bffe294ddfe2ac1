//! Bounds on the work a call may start, and the plausibility limits of measured data: the
//! one registry every front end (Python, CLI) reads.
//!
//! - [`check_steps`]: a run's step count, derived from its duration and `dt`, is checked
//!   before its loop starts (a replay of 1e300 s is refused with the reason, not run).
//! - [`check_collected`]: the values a batch keeps in memory.
//! - [`threads`]: a requested thread count, validated against the machine's cores.
//! - [`CHANNEL_LIMITS`]: what a measured channel can physically hold (errors) and what
//!   looks wrong but may be right (warnings); `popup.io` checks measured runs with it.

use crate::error::{Error, Result};

/// Most physics steps one run may take: 1e9 (about 11.6 days of simulated time at
/// dt = 1 ms; hours of wall time at the engine's speed).
pub const MAX_STEPS: f64 = 1e9;

/// Most values (f64) a batch may collect in memory: 2^30 (8 GiB).
pub const MAX_COLLECTED_VALUES: f64 = 1_073_741_824.0;

/// Steps between two polls of a run's sink for a stop request (Ctrl-C).
pub const POLL_EVERY_STEPS: usize = 1024;

/// Thread counts above this many per core are refused (between the core count and this,
/// the count is capped at the cores: results do not depend on it).
pub const MAX_THREADS_PER_CORE: usize = 4;

/// Shortest decimal text of a float (`1e300`, not 301 digits).
pub fn num(x: f64) -> String {
    format!("{x:?}")
}

/// The number of steps of a run of `duration` [s] at `dt` [s], refused beyond
/// [`MAX_STEPS`] with the reason (checked before the loop starts).
///
/// # Errors
/// [`Error::Input`] naming `what` (the duration's source), the step count and the limit.
pub fn check_steps(what: &str, duration: f64, dt: f64) -> Result<usize> {
    if !(duration.is_finite() && duration >= 0.0) {
        return Err(Error::input(what, format!("{} s must be finite and >= 0", num(duration))));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(Error::input("dt", format!("{} s must be finite and > 0", num(dt))));
    }
    let n = (duration / dt + 1e-9).floor();
    if n > MAX_STEPS {
        return Err(Error::input(
            what,
            format!(
                "duration {} s at dt {} s is {n:e} steps; the limit is {MAX_STEPS:e} steps (check the time stamps, e.g. the last t of a measured run, or shorten the run)",
                num(duration),
                num(dt)
            ),
        ));
    }
    Ok(n as usize)
}

/// Refuse a batch whose collected output (`nbatch` runs × `nsample` samples × `width`
/// values) exceeds [`MAX_COLLECTED_VALUES`].
///
/// # Errors
/// [`Error::Input`] with the sizes and the limit.
pub fn check_collected(nbatch: usize, nsample: f64, width: usize) -> Result<()> {
    let v = nbatch as f64 * nsample * width as f64;
    if v > MAX_COLLECTED_VALUES {
        return Err(Error::input(
            "rollout",
            format!(
                "{nbatch} run(s) of {nsample:e} samples × {width} channels is {v:e} values ({:.1} GiB); the limit is {MAX_COLLECTED_VALUES:e} values: lower the sample rate, the duration or the batch",
                v * 8.0 / 1073741824.0
            ),
        ));
    }
    Ok(())
}

/// The machine's cores (1 when unknown).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// A requested thread count: 0 = all cores; 1..=cores as given; up to
/// [`MAX_THREADS_PER_CORE`] × cores capped at the cores; negative or more refused.
///
/// # Errors
/// [`Error::Input`] naming `what` and the machine's core count.
pub fn threads(what: &str, requested: i64) -> Result<usize> {
    let c = cores();
    let max = (MAX_THREADS_PER_CORE * c) as i64;
    if requested < 0 || requested > max {
        return Err(Error::input(
            what,
            format!("{requested} is out of range: this machine has {c} core{}; use 0 (all cores) or 1 to {c} (at most {max} is accepted, capped at {c})", if c == 1 { "" } else { "s" }),
        ));
    }
    Ok((requested as usize).min(c))
}

/// How a measured channel's value is judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelLimit {
    /// Column names (measured-run.md) the limit applies to.
    pub columns: &'static [&'static str],
    /// Unit of the columns.
    pub unit: &'static str,
    /// Lowest value that can be right (`-inf`: no lower bound beyond `-error_abs`).
    pub min: f64,
    /// `|value|` above this is a warning: may be right, but look.
    pub warn_abs: f64,
    /// `|value|` above this is an error: no arm of this kind produces it.
    pub error_abs: f64,
    /// What the limits stand for and what to do.
    pub advice: &'static str,
}

const INF: f64 = f64::INFINITY;

/// The plausibility limits of measured runs, one entry per channel group.
pub const CHANNEL_LIMITS: &[ChannelLimit] = &[
    ChannelLimit {
        columns: &["t"],
        unit: "s",
        min: -1e6,
        warn_abs: 1e6,
        error_abs: 1e6,
        advice: "time since the start of the run: more than 11 days is a logging glitch (a stamp in ns or epoch time?); fix or drop the row",
    },
    ChannelLimit {
        columns: &["q1", "q2", "q3", "ref_q1", "ref_q2", "ref_q3"],
        unit: "rad",
        min: -INF,
        warn_abs: 2.0 * std::f64::consts::PI,
        error_abs: 8.0 * std::f64::consts::PI,
        advice: "motor angles beyond a turn look like degrees (convert with × π/180); beyond 4 turns they cannot be the arm's",
    },
    ChannelLimit {
        columns: &["dq1", "dq2", "dq3"],
        unit: "rad/s",
        min: -INF,
        warn_abs: 100.0,
        error_abs: 1e4,
        advice: "encoder rates beyond 100 rad/s look like deg/s or rpm; beyond 1e4 rad/s they cannot be the arm's",
    },
    ChannelLimit {
        columns: &["tau1", "tau2", "tau3"],
        unit: "N·m",
        min: -INF,
        warn_abs: 1e3,
        error_abs: 1e5,
        advice: "joint torques of the arm's drives are tens of N·m; beyond 1e3 N·m look like N·mm, beyond 1e5 N·m they cannot be right",
    },
    ChannelLimit {
        columns: &["ee_x", "ee_y", "ee_z"],
        unit: "m",
        min: -INF,
        warn_abs: 10.0,
        error_abs: 1e3,
        advice: "the end effector stays within a few metres of the base; beyond 10 m looks like mm",
    },
    ChannelLimit {
        columns: &["imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az"],
        unit: "m/s²",
        min: -INF,
        warn_abs: 1e3,
        error_abs: 1e5,
        advice: "specific forces of the arm's links are a few g; beyond 100 g a sensor saturated or the unit is wrong",
    },
    ChannelLimit {
        columns: &["p1", "p2"],
        unit: "Pa",
        min: -1.1e5,
        warn_abs: 1e6,
        error_abs: 1e8,
        advice: "link pressures are gauge pressures of tens of kPa; beyond 10 bar looks like a wrong unit, beyond 1000 bar cannot be right",
    },
];

/// A time step of a measured run longer than this many median steps is a warning (samples
/// were lost; the replay interpolates across the gap).
pub const GAP_WARN_STEPS: f64 = 10.0;

/// A time step of a measured run longer than this many median steps is an error (a
/// logging glitch: no replay across it means anything).
pub const GAP_ERROR_STEPS: f64 = 1e4;

/// The limit of a measured-run column, if it has one.
pub fn channel_limit(column: &str) -> Option<&'static ChannelLimit> {
    CHANNEL_LIMITS.iter().find(|l| l.columns.contains(&column))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_bound_names_the_numbers() {
        assert_eq!(check_steps("duration", 1.0, 1e-3).unwrap(), 1000);
        let e = check_steps("duration", 1e300, 1e-3).unwrap_err().to_string();
        assert!(e.contains("duration 1e300 s at dt 0.001 s is 1e303 steps; the limit is 1e9"), "{e}");
        assert!(check_steps("duration", f64::NAN, 1e-3).unwrap_err().to_string().contains("NaN s must be finite"));
    }

    #[test]
    fn threads_are_validated() {
        let c = cores();
        assert_eq!(threads("threads", 0).unwrap(), 0);
        assert_eq!(threads("threads", 1).unwrap(), 1);
        assert_eq!(threads("threads", (2 * c) as i64).unwrap(), c);
        for bad in [-1, 1_000_000] {
            let e = threads("threads", bad).unwrap_err().to_string();
            assert!(e.contains(&format!("input threads: {bad} is out of range")) && e.contains(&format!("{c} core")), "{e}");
        }
    }

    #[test]
    fn every_measured_column_has_one_limit() {
        for l in CHANNEL_LIMITS {
            assert!(l.warn_abs <= l.error_abs && l.min < 0.0);
            for c in l.columns {
                assert_eq!(channel_limit(c), Some(l));
            }
        }
        assert!(channel_limit("nope").is_none());
    }
}
