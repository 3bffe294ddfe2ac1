//! Bounds on the work a call may start, and the plausibility limits of measured data: the
//! one registry every front end (Python, CLI) reads.
//!
//! - [`check_steps`]: a run's step count, derived from its duration and `dt`, is checked
//!   before its loop starts (a replay of 1e300 s is refused with the reason, not run).
//! - [`check_collected`]: the values a batch keeps in memory.
//! - [`threads`]: a requested thread count, validated against the machine's cores.
//! - [`CHANNEL_LIMITS`]: what a measured channel can physically hold (errors) and what
//!   looks wrong but may be right (warnings); `popup.io` checks measured runs with it.
//!   Torque and acceleration limits are factors of what the run's arm can produce
//!   ([`Scale`], [`arm::reach`]); [`for_arm`] turns the registry into numbers for one arm.

pub mod arm;

use crate::error::{Error, Result};
use crate::spec::ArmSpec;

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

/// What the `warn` and `error` numbers of a [`ChannelLimit`] are measured in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Absolute values in the channel's unit.
    Absolute,
    /// Factors of the drive torque limit of the column's joint (`motors.tau_max_nm` of the
    /// arm file; `tau1` → joint q1, ...).
    DriveTorque,
    /// Factors of the specific force the arm can reach at the column's IMU mount
    /// ([`arm::reach`]: drive torques and collapse moments through the mass matrix, plus
    /// gravity; `imu1_*` → IMU 1, `imu2_*` → IMU 2).
    ArmAcceleration,
}

impl Scale {
    /// The name Python sees (`""` for absolute limits).
    pub fn name(self) -> &'static str {
        match self {
            Scale::Absolute => "",
            Scale::DriveTorque => "drive torque",
            Scale::ArmAcceleration => "arm acceleration",
        }
    }
}

/// How a measured channel's value is judged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelLimit {
    /// Column names (measured-run.md) the limit applies to.
    pub columns: &'static [&'static str],
    /// Unit of the columns.
    pub unit: &'static str,
    /// Lowest value that can be right (`-inf`: no lower bound beyond `-error`).
    pub min: f64,
    /// What `warn` and `error` are measured in.
    pub scale: Scale,
    /// `|value|` above this is a warning: may be right, but look (in `unit`, or a factor
    /// of the arm's number per `scale`).
    pub warn: f64,
    /// `|value|` above this is an error: no arm of this kind produces it (as `warn`).
    pub error: f64,
    /// What the limits stand for and what to do.
    pub advice: &'static str,
}

const INF: f64 = f64::INFINITY;

/// A measured torque beyond this many times its drive's limit is a warning (a unit slip
/// such as N·mm, another arm's data, or a torque computed without the drive's saturation:
/// runs synthesised by replaying fast motions in the model reach about 3 × the lab drive's
/// 66.83 N·m, which a real drive, clamped at its limit, never reports).
pub const DRIVE_TORQUE_WARN: f64 = 5.0;

/// A measured torque beyond this many times its drive's limit is an error: no drive of the
/// arm produces it.
pub const DRIVE_TORQUE_ERROR: f64 = 100.0;

/// A measured specific force beyond the arm's bound ([`arm::reach`]) times this is a
/// warning (an impact, a saturated sensor, a unit slip). The bound is already a worst case
/// (every joint at its force limit in the worst direction, the links at collapse, the
/// worst configuration): for `popup-lab` some 5000 m/s² at the tip, two orders of
/// magnitude above the few g the arm reaches in use.
pub const ARM_ACCEL_WARN: f64 = 1.0;

/// A measured specific force beyond the arm's bound times this is an error: an order of
/// magnitude beyond the worst case, three beyond use.
pub const ARM_ACCEL_ERROR: f64 = 10.0;

/// The plausibility limits of measured runs, one entry per channel group.
pub const CHANNEL_LIMITS: &[ChannelLimit] = &[
    ChannelLimit {
        columns: &["t"],
        unit: "s",
        min: -1e6,
        scale: Scale::Absolute,
        warn: 1e6,
        error: 1e6,
        advice: "time since the start of the run: more than 11 days is a logging glitch (a stamp in ns or epoch time?); fix or drop the row",
    },
    ChannelLimit {
        columns: &["q1", "q2", "q3", "ref_q1", "ref_q2", "ref_q3"],
        unit: "rad",
        min: -INF,
        scale: Scale::Absolute,
        warn: 2.0 * std::f64::consts::PI,
        error: 8.0 * std::f64::consts::PI,
        advice: "motor angles beyond a turn look like degrees (convert with × π/180); beyond 4 turns they cannot be the arm's",
    },
    ChannelLimit {
        columns: &["dq1", "dq2", "dq3"],
        unit: "rad/s",
        min: -INF,
        scale: Scale::Absolute,
        warn: 100.0,
        error: 1e4,
        advice: "encoder rates beyond 100 rad/s look like deg/s or rpm; beyond 1e4 rad/s they cannot be the arm's",
    },
    ChannelLimit {
        columns: &["tau1", "tau2", "tau3"],
        unit: "N·m",
        min: -INF,
        scale: Scale::DriveTorque,
        warn: DRIVE_TORQUE_WARN,
        error: DRIVE_TORQUE_ERROR,
        advice: "a torque beyond a few times the drive's limit looks like N·mm or another arm's data; check the unit, the sign convention and the arm file's motors.tau_max_nm",
    },
    ChannelLimit {
        columns: &["ee_x", "ee_y", "ee_z"],
        unit: "m",
        min: -INF,
        scale: Scale::Absolute,
        warn: 10.0,
        error: 1e3,
        advice: "the end effector stays within a few metres of the base; beyond 10 m looks like mm",
    },
    ChannelLimit {
        columns: &["imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az"],
        unit: "m/s²",
        min: -INF,
        scale: Scale::ArmAcceleration,
        warn: ARM_ACCEL_WARN,
        error: ARM_ACCEL_ERROR,
        advice: "beyond what the drives, the links and gravity can do, look for an impact, a saturated sensor or a wrong unit (mm/s²?); beyond that by orders of magnitude the value cannot be the arm's: fix the unit or drop the samples",
    },
    ChannelLimit {
        columns: &["p1", "p2"],
        unit: "Pa",
        min: -1.1e5,
        scale: Scale::Absolute,
        warn: 1e6,
        error: 1e8,
        advice: "link pressures are gauge pressures of tens of kPa; beyond 10 bar looks like a wrong unit, beyond 1000 bar cannot be right",
    },
];

/// A plausibility limit in numbers, for one arm: `|value| > warn_abs` is a warning,
/// `|value| > error_abs` or `value < min` an error.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmChannelLimit {
    /// Columns the limit applies to.
    pub columns: Vec<&'static str>,
    /// Unit of the columns.
    pub unit: &'static str,
    /// Lowest value that can be right.
    pub min: f64,
    /// Warning threshold of `|value|` [unit].
    pub warn_abs: f64,
    /// Error threshold of `|value|` [unit].
    pub error_abs: f64,
    /// Where the numbers come from and what to do.
    pub advice: String,
}

/// [`CHANNEL_LIMITS`] in numbers for the arm `spec`: torque limits from its drives,
/// acceleration limits from [`arm::reach`] (one entry per joint or IMU there).
///
/// # Errors
/// As [`arm::reach`] (an arm that does not compile).
pub fn for_arm(spec: &ArmSpec) -> Result<Vec<ArmChannelLimit>> {
    let r = arm::reach(spec)?;
    let name = &spec.name;
    let mut out = Vec::with_capacity(CHANNEL_LIMITS.len() + 4);
    for l in CHANNEL_LIMITS {
        let one = |columns: Vec<&'static str>, basis: f64, what: String| ArmChannelLimit {
            columns,
            unit: l.unit,
            min: l.min,
            warn_abs: l.warn * basis,
            error_abs: l.error * basis,
            advice: if what.is_empty() { l.advice.to_string() } else { format!("{what}; {}", l.advice) },
        };
        match l.scale {
            Scale::Absolute => out.push(one(l.columns.to_vec(), 1.0, String::new())),
            Scale::DriveTorque => {
                for (k, c) in l.columns.iter().enumerate() {
                    let tau = r.tau_max_nm[k];
                    out.push(one(
                        vec![c],
                        tau,
                        format!(
                            "the drive of q{} of arm {name} delivers at most {} N·m (motors.tau_max_nm[{k}]); the limits are {} and {} times that",
                            k + 1,
                            num(tau),
                            num(l.warn),
                            num(l.error)
                        ),
                    ));
                }
            }
            Scale::ArmAcceleration => {
                for (s, cols) in l.columns.chunks(3).enumerate() {
                    let a = r.imu_accel[s];
                    out.push(one(
                        cols.to_vec(),
                        a,
                        format!(
                            "the drives and gravity accelerate IMU {} of arm {name} by at most {a:.4} m/s² (from its mass matrix, drive limits and link collapse moments); the limits are {} and {} times that",
                            s + 1,
                            num(l.warn),
                            num(l.error)
                        ),
                    ));
                }
            }
        }
    }
    Ok(out)
}

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
            assert!(l.warn <= l.error && l.min < 0.0);
            for c in l.columns {
                assert_eq!(channel_limit(c), Some(l));
            }
        }
        assert!(channel_limit("nope").is_none());
    }

    #[test]
    fn arm_limits_come_from_the_arm() {
        let lab = ArmSpec::popup_lab();
        let r = arm::reach(&lab).unwrap();
        let lims = for_arm(&lab).unwrap();
        let find = |c: &str| lims.iter().find(|l| l.columns.contains(&c)).unwrap();
        // every measured column has exactly one limit for the arm
        for l in CHANNEL_LIMITS {
            for c in l.columns {
                assert_eq!(lims.iter().filter(|x| x.columns.contains(c)).count(), 1, "{c}");
            }
        }
        let tau2 = find("tau2");
        assert_eq!(tau2.error_abs, DRIVE_TORQUE_ERROR * lab.motors.tau_max_nm[1]);
        assert_eq!(tau2.warn_abs, DRIVE_TORQUE_WARN * lab.motors.tau_max_nm[1]);
        assert!(tau2.advice.contains("motors.tau_max_nm[1]"), "{}", tau2.advice);
        let imu2 = find("imu2_az");
        assert_eq!(imu2.error_abs, ARM_ACCEL_ERROR * r.imu_accel[1]);
        assert_eq!(find("imu1_ax").warn_abs, ARM_ACCEL_WARN * r.imu_accel[0]);
        assert_eq!(find("q1").error_abs, 8.0 * std::f64::consts::PI);
        // a different drive: a different torque limit on that joint only
        let mut other = lab.clone();
        other.motors.tau_max_nm[2] = 5.0;
        let lo = for_arm(&other).unwrap();
        let f2 = |c: &str| lo.iter().find(|l| l.columns.contains(&c)).unwrap().error_abs;
        assert_eq!(f2("tau3"), 500.0);
        assert_eq!(f2("tau1"), tau2.error_abs);
        assert!(f2("imu2_ax") < imu2.error_abs);
    }
}
