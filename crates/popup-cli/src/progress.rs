//! Progress of a run (bar with simulated time, speed and ETA on a terminal; one line per
//! flush interval with `--progress lines`; nothing otherwise) and the stop flag that
//! SIGINT/SIGTERM raise.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use popup_core::control::closed_loop::NCTRL;
use popup_core::control::machine::Event;
use popup_core::sensor::NCH;
use popup_core::stream::{Flow, Sink, StateView};
use popup_core::Result;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// How progress is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Mode {
    /// A bar when stderr is a terminal, nothing otherwise.
    Auto,
    /// One line on stderr per flush interval (for logs of headless jobs).
    Lines,
    /// Nothing.
    None,
}

/// Stop flags raised by signals (SIGINT, SIGTERM).
#[derive(Debug, Clone, Default)]
pub struct StopFlags {
    /// SIGINT received.
    pub int: Arc<AtomicBool>,
    /// SIGTERM received.
    pub term: Arc<AtomicBool>,
}

impl StopFlags {
    /// Flags set by SIGINT and SIGTERM from now until [`StopFlags::unregister`].
    pub fn register() -> (StopFlags, Vec<signal_hook::SigId>) {
        let f = StopFlags::default();
        let mut ids = Vec::new();
        if let Ok(id) = signal_hook::flag::register(signal_hook::consts::SIGINT, f.int.clone()) {
            ids.push(id);
        }
        if let Ok(id) = signal_hook::flag::register(signal_hook::consts::SIGTERM, f.term.clone()) {
            ids.push(id);
        }
        (f, ids)
    }

    /// Remove the handlers registered by [`StopFlags::register`].
    pub fn unregister(ids: Vec<signal_hook::SigId>) {
        for id in ids {
            signal_hook::low_level::unregister(id);
        }
    }

    /// Whether a stop was asked.
    pub fn raised(&self) -> bool {
        self.int.load(Ordering::Relaxed) || self.term.load(Ordering::Relaxed)
    }

    /// The exit code of an interrupted run: 130 (SIGINT) or 143 (SIGTERM).
    pub fn exit_code(&self) -> i32 {
        if self.term.load(Ordering::Relaxed) {
            143
        } else {
            130
        }
    }
}

/// Progress reporting of one run.
pub struct Progress {
    bar: Option<ProgressBar>,
    lines: bool,
    duration: f64,
    every: f64,
    next_line: f64,
    start: Instant,
    stop: StopFlags,
}

impl Progress {
    /// Progress of a run of `duration` [s] simulated; lines every `every` [s] simulated.
    pub fn new(mode: Mode, duration: f64, every: f64, stop: StopFlags) -> Progress {
        let bar = (mode == Mode::Auto).then(|| {
            let b = ProgressBar::with_draw_target(Some((duration * 1000.0).round() as u64), ProgressDrawTarget::stderr());
            b.set_style(
                ProgressStyle::with_template("{bar:40} {msg} ETA {eta}").unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b
        });
        Progress { bar: bar.filter(|b| !b.is_hidden()), lines: mode == Mode::Lines, duration, every, next_line: every, start: Instant::now(), stop }
    }

    /// A silent progress that only watches the stop flag (sweeps).
    pub fn silent(stop: StopFlags) -> Progress {
        Progress::new(Mode::None, 0.0, f64::INFINITY, stop)
    }

    fn on_state(&mut self, t: f64) -> Flow {
        let wall = self.start.elapsed().as_secs_f64();
        let speed = if wall > 0.0 { t / wall } else { 0.0 };
        if let Some(b) = &self.bar {
            b.set_position((t * 1000.0).round() as u64);
            b.set_message(format!("t = {t:.2}/{:.2} s, {speed:.1}x real time", self.duration));
        }
        if self.lines && t >= self.next_line - 1e-9 * self.every {
            let eta = if speed > 0.0 { (self.duration - t) / speed } else { f64::NAN };
            eprintln!("popup: t = {t:.6} s of {} s simulated ({speed:.1}x real time, ETA {eta:.0} s); log flushed", self.duration);
            while self.next_line <= t + 1e-9 * self.every {
                self.next_line += self.every;
            }
        }
        if self.stop.raised() {
            Flow::Stop
        } else {
            Flow::Go
        }
    }

    /// Clear the bar.
    pub fn done(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

/// A sink wrapper that reports progress and stops the run when a stop flag is raised.
pub struct Watch<'a> {
    /// The sink fed.
    pub inner: &'a mut dyn Sink,
    /// The progress.
    pub progress: &'a mut Progress,
}

impl Sink for Watch<'_> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        self.inner.sample(row, ctrl)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        self.inner.event(e)
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        let f = self.inner.state(s)?;
        Ok(if f == Flow::Stop { Flow::Stop } else { self.progress.on_state(s.t) })
    }
}
