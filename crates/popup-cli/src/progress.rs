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

/// The process-wide handlers: installed once, armed only while a run is going.
struct Handlers {
    int: Arc<AtomicBool>,
    term: Arc<AtomicBool>,
    disarmed: Arc<AtomicBool>,
}

static HANDLERS: std::sync::OnceLock<Option<Handlers>> = std::sync::OnceLock::new();

fn handlers() -> Option<&'static Handlers> {
    HANDLERS
        .get_or_init(|| {
            use signal_hook::consts::{SIGINT, SIGTERM};
            let h = Handlers { int: Arc::default(), term: Arc::default(), disarmed: Arc::new(AtomicBool::new(true)) };
            // disarmed, SIGTERM keeps its default action (terminate); SIGINT falls through to
            // the handler installed before ours (Python's KeyboardInterrupt in the Python front)
            signal_hook::flag::register(SIGINT, h.int.clone()).ok()?;
            signal_hook::flag::register(SIGTERM, h.term.clone()).ok()?;
            signal_hook::flag::register_conditional_default(SIGTERM, h.disarmed.clone()).ok()?;
            Some(h)
        })
        .as_ref()
}

/// Disarms the signal handlers when dropped.
pub struct Armed(());

impl Drop for Armed {
    fn drop(&mut self) {
        if let Some(h) = handlers() {
            h.disarmed.store(true, Ordering::SeqCst);
        }
    }
}

impl StopFlags {
    /// Flags raised by SIGINT and SIGTERM while the returned guard lives (the handlers are
    /// installed once per process and re-armed for each run, so any number of runs in one
    /// process, e.g. the Python front, each finish their file on Ctrl-C).
    pub fn register() -> (StopFlags, Armed) {
        match handlers() {
            Some(h) => {
                h.int.store(false, Ordering::SeqCst);
                h.term.store(false, Ordering::SeqCst);
                h.disarmed.store(false, Ordering::SeqCst);
                (StopFlags { int: h.int.clone(), term: h.term.clone() }, Armed(()))
            }
            None => (StopFlags::default(), Armed(())),
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
        if self.stop.raised() {
            Flow::Stop
        } else {
            Flow::Go
        }
    }

    /// After the sample at `t` was handed to the log (which flushes at the same times).
    fn on_sample(&mut self, t: f64) {
        let wall = self.start.elapsed().as_secs_f64();
        let speed = if wall > 0.0 { t / wall } else { 0.0 };
        if self.lines && t >= self.next_line - 1e-9 * self.every {
            let eta = if speed > 0.0 { (self.duration - t) / speed } else { f64::NAN };
            eprintln!("popup: t = {t:.6} s of {} s simulated ({speed:.1}x real time, ETA {eta:.0} s); log flushed", self.duration);
            while self.next_line <= t + 1e-9 * self.every {
                self.next_line += self.every;
            }
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
        let f = self.inner.sample(row, ctrl)?;
        self.progress.on_sample(row[0]);
        Ok(f)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        self.inner.event(e)
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        let f = self.inner.state(s)?;
        Ok(if f == Flow::Stop { Flow::Stop } else { self.progress.on_state(s.t) })
    }
    fn poll(&mut self) -> Flow {
        if self.inner.poll() == Flow::Stop || self.progress.stop.raised() {
            Flow::Stop
        } else {
            Flow::Go
        }
    }
}
