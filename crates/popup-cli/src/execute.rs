//! One scenario run: the closed loop streamed through the sensor noise into an optional
//! MCAP log and the summary metrics, with a stop flag and progress reporting.

use crate::progress::{Progress, Watch};
use popup_core::control::closed_loop::{run_closed_loop_into, Status, NCTRL};
use popup_core::control::machine::Event;
use popup_core::log::{McapLogger, RunMeta};
use popup_core::scenario::Scenario;
use popup_core::sensor::NCH;
use popup_core::stream::{Flow, Noisy, Sink, StateView, Tee};
use popup_core::{Error, Result};
use std::collections::BTreeMap;
use std::path::Path;

/// Scalar results of a run (one row of a sweep's summary), computed while it streams.
#[derive(Debug, Clone, PartialEq)]
pub struct Metrics {
    /// Samples seen.
    pub samples: usize,
    /// Time of the last sample [s].
    pub t_last: f64,
    /// Peak |M|/M_w of link 1 and 2.
    pub peak_ratio: [f64; 2],
    /// Sum of squared position tracking errors `ref_q − q` per joint [rad²].
    sse: [f64; 3],
    /// Peak |tau| per joint [N·m].
    pub peak_tau: [f64; 3],
    /// Last end-effector position [m].
    pub ee: [f64; 3],
    /// Wrinkling-alarm episodes (onsets).
    pub wrinkle_alarms: usize,
    /// Fault events.
    pub faults: usize,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics { samples: 0, t_last: f64::NAN, peak_ratio: [0.0; 2], sse: [0.0; 3], peak_tau: [0.0; 3], ee: [f64::NAN; 3], wrinkle_alarms: 0, faults: 0 }
    }
}

impl Metrics {
    /// RMS position tracking error per joint [rad].
    pub fn rms_track(&self) -> [f64; 3] {
        self.sse.map(|s| if self.samples > 0 { (s / self.samples as f64).sqrt() } else { f64::NAN })
    }
}

impl Sink for Metrics {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        self.samples += 1;
        self.t_last = row[0];
        for l in 0..2 {
            self.peak_ratio[l] = self.peak_ratio[l].max(row[33 + l]);
        }
        for j in 0..3 {
            if let Some(c) = ctrl {
                let e = c[j] - row[1 + j];
                self.sse[j] += e * e;
            }
            self.peak_tau[j] = self.peak_tau[j].max(row[7 + j].abs());
            self.ee[j] = row[10 + j];
        }
        Ok(Flow::Go)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        match e.kind {
            "wrinkle_start" => self.wrinkle_alarms += 1,
            "fault" => self.faults += 1,
            _ => {}
        }
        Ok(Flow::Go)
    }
}

/// A duration override [s]: finite and > 0.
///
/// # Errors
/// [`Error::Input`] naming `what`.
pub fn check_duration(what: &str, d: f64) -> Result<f64> {
    if d.is_finite() && d > 0.0 {
        Ok(d)
    } else {
        Err(Error::input(what, format!("{d} s must be finite and > 0")))
    }
}

/// How a run went.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// completed / unstable / interrupted.
    pub status: Status,
    /// Summary metrics.
    pub metrics: Metrics,
    /// Non-finite values left out of the log (their samples' finite values are kept).
    pub nonfinite: usize,
    /// Warnings of the run (pressure clamped, ...).
    pub warnings: Vec<String>,
    /// Wrinkling-alarm episodes.
    pub alarms: Vec<popup_core::sim::Alarm>,
}


/// Run `sc` (its duration and seed as given), logging to `out` when set; `progress`
/// reports and carries the stop flag.
///
/// # Errors
/// Model/run configuration errors, log I/O errors.
/// `also` receives the same (noisy) output, e.g. a [`popup_core::stream::Collect`] to keep
/// the arrays.
pub fn execute(sc: &Scenario, out: Option<&Path>, progress: &mut Progress, extra: BTreeMap<String, String>, also: Option<&mut dyn Sink>) -> Result<Outcome> {
    let model = sc.model()?;
    let mut metrics = Metrics::default();
    let meta = RunMeta { experiment_toml: sc.experiment_toml(), scenario: sc.text.clone(), seed: sc.seed, extra };
    let mut logger = match out {
        Some(p) => Some(McapLogger::create(p, &model, &sc.log, &meta, sc.closed.sample_period, sc.closed.payload_radius)?),
        None => None,
    };
    let res = {
        let mut null = Null;
        let sink_log: &mut dyn Sink = match logger.as_mut() {
            Some(l) => l,
            None => &mut null,
        };
        let mut null2 = Null;
        let mut inner = Tee { a: sink_log, b: also.unwrap_or(&mut null2) };
        let mut tee = Tee { a: &mut metrics, b: &mut inner };
        let mut noisy = Noisy::new(&mut tee, &sc.noise, sc.seed);
        let mut watch = Watch { inner: &mut noisy, progress: &mut *progress };
        run_closed_loop_into(&model, &sc.params, &sc.closed, &mut watch)
    };
    progress.done();
    match res {
        Ok(end) => {
            let nonfinite = match logger {
                Some(l) => l.finish(end.status.name())?.nonfinite_dropped,
                None => 0,
            };
            Ok(Outcome { status: end.status, metrics, nonfinite, warnings: end.warnings, alarms: end.alarms })
        }
        Err(e) => {
            if let Some(l) = logger {
                // keep what was logged: the file is finished with status failed
                let _ = l.finish("failed");
            }
            Err(e)
        }
    }
}

/// A sink that drops everything (no log).
struct Null;

impl Sink for Null {
    fn sample(&mut self, _row: &[f64; NCH], _ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        Ok(Flow::Go)
    }
    fn state(&mut self, _s: &StateView<'_>) -> Result<Flow> {
        Ok(Flow::Go)
    }
}
