//! Streaming runs: a run hands its samples, events and states to a [`Sink`] as it goes,
//! so a log of any length is written with flat memory, and a sink can stop the run
//! (Ctrl-C). The batch results (`run_closed_loop`) are a collecting sink, so streamed and
//! batch samples are the same bits.
//!
//! Also here: the sensor-delay line that delays channels with a bounded history, and
//! the seeded sensor-noise stage.

use crate::control::closed_loop::NCTRL;
use crate::control::machine::Event;
use crate::error::Result;
use crate::math::VecN;
use crate::params::ParamData;
use crate::sensor::NCH;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Whether a run goes on after a sink call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// Go on.
    Go,
    /// Stop at this sample (the run ends with status `Interrupted`).
    Stop,
}

/// The true mechanical state at a sample time, for sinks that draw the arm.
pub struct StateView<'a> {
    /// Time [s].
    pub t: f64,
    /// Joint coordinates, chain order [rad].
    pub q: &'a VecN,
    /// Joint rates [rad/s].
    pub v: &'a VecN,
    /// The parameters in force (payload and pressures change with the task's phases).
    pub pd: &'a ParamData,
    /// |M|/M_w per link at this state (the `m1_ratio`, `m2_ratio` channels; for a rigid link
    /// it needs the accelerations, so the run loop, which has them, supplies it).
    pub ratio: [f64; 2],
}

/// Receiver of a run's output, in time order per kind. Samples may reach the sink a few
/// samples after their state (the sensor-delay line needs one sample of look-ahead).
pub trait Sink {
    /// One sample row: the sensor channels ([`crate::sensor::CHANNELS`]) and the
    /// controller channels ([`NCTRL`], closed loop only).
    ///
    /// # Errors
    /// The sink's own (e.g. I/O) errors end the run with that error.
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow>;
    /// A log entry (transition, fault, alarm, ...), at its time.
    ///
    /// # Errors
    /// As [`Sink::sample`].
    fn event(&mut self, _e: &Event) -> Result<Flow> {
        Ok(Flow::Go)
    }
    /// The true state at every sample time (before sensor delays).
    ///
    /// # Errors
    /// As [`Sink::sample`].
    fn state(&mut self, _s: &StateView<'_>) -> Result<Flow> {
        Ok(Flow::Go)
    }
    /// Asked every [`crate::limits::POLL_EVERY_STEPS`] physics steps, between samples:
    /// whether the run should stop (a stop request such as Ctrl-C is seen within that
    /// many steps even when samples are far apart).
    fn poll(&mut self) -> Flow {
        Flow::Go
    }
}

/// A sink that stops the run once `flag` is raised (checked at every sample, event, state
/// and poll), passing everything else to `inner`.
pub struct Stoppable<'a> {
    /// The sink fed.
    pub inner: &'a mut dyn Sink,
    /// Raised (e.g. by a Ctrl-C watcher) to stop the run.
    pub flag: &'a std::sync::atomic::AtomicBool,
}

impl Stoppable<'_> {
    fn flow(&self, f: Flow) -> Flow {
        either(f, if self.flag.load(std::sync::atomic::Ordering::Relaxed) { Flow::Stop } else { Flow::Go })
    }
}

impl Sink for Stoppable<'_> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        let f = self.inner.sample(row, ctrl)?;
        Ok(self.flow(f))
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        let f = self.inner.event(e)?;
        Ok(self.flow(f))
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        let f = self.inner.state(s)?;
        Ok(self.flow(f))
    }
    fn poll(&mut self) -> Flow {
        let f = self.inner.poll();
        self.flow(f)
    }
}

/// A sink that keeps everything: the batch result of a run.
#[derive(Debug, Clone, Default)]
pub struct Collect {
    /// Sensor rows, row-major (n × NCH).
    pub data: Vec<f64>,
    /// Controller rows, row-major (n × NCTRL).
    pub ctrl: Vec<f64>,
    /// Events.
    pub events: Vec<Event>,
}

impl Collect {
    /// A collector with room for `n` samples.
    pub fn with_capacity(n: usize) -> Collect {
        Collect { data: Vec::with_capacity(n * NCH), ctrl: Vec::with_capacity(n * NCTRL), events: Vec::new() }
    }
}

impl Sink for Collect {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        self.data.extend_from_slice(row);
        if let Some(c) = ctrl {
            self.ctrl.extend_from_slice(c);
        }
        Ok(Flow::Go)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        self.events.push(e.clone());
        Ok(Flow::Go)
    }
}

/// Two sinks fed the same output (e.g. a [`Collect`] and a log); the run stops when
/// either asks.
pub struct Tee<'a, 'b> {
    /// First sink.
    pub a: &'a mut dyn Sink,
    /// Second sink.
    pub b: &'b mut dyn Sink,
}

/// `Stop` if either says stop.
pub(crate) fn either(x: Flow, y: Flow) -> Flow {
    if x == Flow::Stop || y == Flow::Stop {
        Flow::Stop
    } else {
        Flow::Go
    }
}

impl Sink for Tee<'_, '_> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        Ok(either(self.a.sample(row, ctrl)?, self.b.sample(row, ctrl)?))
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        Ok(either(self.a.event(e)?, self.b.event(e)?))
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        Ok(either(self.a.state(s)?, self.b.state(s)?))
    }
    fn poll(&mut self) -> Flow {
        either(self.a.poll(), self.b.poll())
    }
}

/// Delay of a group of channels: columns `cols` lag by `delay` [s].
#[derive(Debug, Clone, PartialEq)]
pub struct Delay {
    /// Columns of the sensor row.
    pub cols: std::ops::Range<usize>,
    /// Delay [s], >= 0.
    pub delay: f64,
}

/// A streaming sensor-delay line: column group g of output row k is the cubic
/// (Catmull–Rom) interpolation of its input at the fractional row `k − delay/ts`, held
/// at row 0 before the start and at the last row after the end. Output lags input by one
/// row when any delay is non-zero; memory is `ceil(max delay / ts) + 4` rows.
#[derive(Debug, Clone)]
pub struct DelayLine {
    groups: Vec<(std::ops::Range<usize>, f64)>,
    cap: usize,
    rows: Vec<[f64; NCH]>,
    ctrl: Vec<[f64; NCTRL]>,
    has_ctrl: bool,
    /// Rows received.
    n_in: usize,
    /// Rows emitted.
    n_out: usize,
}

impl DelayLine {
    /// A delay line for sample period `ts` [s]; zero delays are dropped.
    pub fn new(ts: f64, delays: &[Delay]) -> DelayLine {
        let groups: Vec<(std::ops::Range<usize>, f64)> = delays.iter().filter(|d| d.delay != 0.0).map(|d| (d.cols.clone(), d.delay / ts)).collect();
        let smax = groups.iter().fold(0.0f64, |a, g| a.max(g.1));
        let cap = smax.ceil() as usize + 4;
        DelayLine { groups, cap, rows: vec![[0.0; NCH]; cap], ctrl: vec![[0.0; NCTRL]; cap], has_ctrl: false, n_in: 0, n_out: 0 }
    }

    /// The line of the `sensor_delay` effect: IMU, torque and motion-capture columns, and
    /// the encoder columns when `encoder` (not in replay, where the encoder is the input).
    pub fn for_sensors(ts: f64, sd: &crate::effects::SensorDelay, encoder: bool) -> DelayLine {
        DelayLine::new(
            ts,
            &[
                Delay { cols: 13..19, delay: sd.imu },
                Delay { cols: 7..10, delay: sd.torque },
                Delay { cols: 10..13, delay: sd.mocap },
                Delay { cols: 1..7, delay: if encoder { sd.encoder } else { 0.0 } },
            ],
        )
    }

    /// Whether the line delays nothing (rows pass straight through).
    pub fn is_identity(&self) -> bool {
        self.groups.is_empty()
    }

    /// Feed one input row; emits the rows that became complete to `sink`.
    ///
    /// # Errors
    /// The sink's errors.
    pub fn push(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>, sink: &mut dyn Sink) -> Result<Flow> {
        if self.is_identity() {
            return sink.sample(row, ctrl);
        }
        let slot = self.n_in % self.cap;
        self.rows[slot] = *row;
        if let Some(c) = ctrl {
            self.ctrl[slot] = *c;
            self.has_ctrl = true;
        }
        self.n_in += 1;
        if self.n_in >= 2 {
            return self.emit(self.n_in - 2, sink);
        }
        Ok(Flow::Go)
    }

    /// Emit the rows still held (the end of the run).
    ///
    /// # Errors
    /// The sink's errors.
    pub fn finish(&mut self, sink: &mut dyn Sink) -> Result<Flow> {
        while !self.is_identity() && self.n_out < self.n_in {
            if self.emit(self.n_out, sink)? == Flow::Stop {
                return Ok(Flow::Stop);
            }
        }
        Ok(Flow::Go)
    }

    fn emit(&mut self, k: usize, sink: &mut dyn Sink) -> Result<Flow> {
        let n = self.n_in as isize;
        let cap = self.cap;
        let oldest = self.n_in.saturating_sub(cap) as isize;
        let rows = &self.rows;
        let at = |i: isize, c: usize| {
            let j = i.clamp(0, n - 1).max(oldest) as usize;
            rows[j % cap][c]
        };
        let mut out = rows[k % cap];
        for (cols, s) in &self.groups {
            let x = k as f64 - s;
            for c in cols.clone() {
                out[c] = if x <= 0.0 {
                    at(0, c)
                } else {
                    let i = x.floor() as isize;
                    let u = x - i as f64;
                    let (p0, p1, p2, p3) = (at(i - 1, c), at(i, c), at(i + 1, c), at(i + 2, c));
                    p1 + 0.5 * u * (p2 - p0 + u * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + u * (3.0 * (p1 - p2) + p3 - p0)))
                };
            }
        }
        self.n_out = k + 1;
        let ctrl = self.ctrl[k % cap];
        sink.sample(&out, if self.has_ctrl { Some(&ctrl) } else { None })
    }
}

/// Gaussian sensor noise (standard deviations; 0 = off), drawn from a ChaCha8 stream
/// seeded by `seed` (the same numbers on every platform).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Noise {
    /// Encoder angles q1..q3 [rad] (rates dq are derived, not noised).
    pub encoder_rad: f64,
    /// IMU specific forces [m/s²].
    pub imu_m_s2: f64,
    /// Joint torques [N·m].
    pub torque_nm: f64,
    /// End-effector position (motion capture) [m].
    pub mocap_m: f64,
}

impl Noise {
    /// Whether all standard deviations are zero.
    pub fn is_off(&self) -> bool {
        *self == Noise::default()
    }
}

/// A sink stage adding [`Noise`] to the sensor rows before passing them on.
pub struct Noisy<'a> {
    inner: &'a mut dyn Sink,
    rng: ChaCha8Rng,
    groups: [(std::ops::Range<usize>, f64); 4],
}

impl<'a> Noisy<'a> {
    /// Noise with `seed` in front of `inner`. Standard deviations that are not finite and
    /// > 0 add nothing (a scenario refuses them before this point).
    pub fn new(inner: &'a mut dyn Sink, noise: &Noise, seed: u64) -> Noisy<'a> {
        Noisy {
            inner,
            rng: ChaCha8Rng::seed_from_u64(seed),
            groups: [(1..4, noise.encoder_rad), (7..10, noise.torque_nm), (10..13, noise.mocap_m), (13..19, noise.imu_m_s2)],
        }
    }
}

impl Sink for Noisy<'_> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        let mut r = *row;
        for (cols, sd) in &self.groups {
            if let Some(dist) = Normal::new(0.0, *sd).ok().filter(|_| sd.is_finite() && *sd > 0.0) {
                for c in cols.clone() {
                    r[c] += dist.sample(&mut self.rng);
                }
            }
        }
        self.inner.sample(&r, ctrl)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        self.inner.event(e)
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        self.inner.state(s)
    }
    fn poll(&mut self) -> Flow {
        self.inner.poll()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The streaming line equals the whole-array interpolation written out directly.
    #[test]
    fn delay_line_matches_batch_formula() {
        let n = 40;
        let ts = 0.01;
        let rows: Vec<[f64; NCH]> = (0..n).map(|k| std::array::from_fn(|c| ((k * 7 + c * 3) as f64 * 0.37).sin())).collect();
        for delay in [0.0, 0.004, 0.01, 0.023, 0.1] {
            let mut line = DelayLine::new(ts, &[Delay { cols: 13..19, delay }, Delay { cols: 7..10, delay: delay * 0.5 }]);
            let mut out = Collect::default();
            for r in &rows {
                line.push(r, None, &mut out).unwrap();
            }
            line.finish(&mut out).unwrap();
            assert_eq!(out.data.len(), n * NCH);
            for (cols, d) in [(13..19, delay), (7..10, delay * 0.5)] {
                let s = d / ts;
                for c in cols {
                    let col: Vec<f64> = rows.iter().map(|r| r[c]).collect();
                    let at = |i: isize| col[i.clamp(0, n as isize - 1) as usize];
                    for k in 0..n {
                        let x = k as f64 - s;
                        let want = if d == 0.0 {
                            col[k]
                        } else if x <= 0.0 {
                            col[0]
                        } else {
                            let i = x.floor() as isize;
                            let u = x - i as f64;
                            let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
                            p1 + 0.5 * u * (p2 - p0 + u * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + u * (3.0 * (p1 - p2) + p3 - p0)))
                        };
                        assert_eq!(out.data[k * NCH + c].to_bits(), want.to_bits(), "delay {delay} col {c} row {k}");
                    }
                }
            }
            // undelayed columns pass through
            assert_eq!(out.data[5 * NCH + 2], rows[5][2]);
        }
    }

    #[test]
    fn noise_is_seeded() {
        let row = [0.0; NCH];
        let nz = Noise { imu_m_s2: 0.1, ..Noise::default() };
        let draw = |seed| {
            let mut c = Collect::default();
            let mut s = Noisy::new(&mut c, &nz, seed);
            for _ in 0..3 {
                s.sample(&row, None).unwrap();
            }
            c.data
        };
        assert_eq!(draw(7), draw(7));
        assert_ne!(draw(7), draw(8));
        let d = draw(7);
        assert!(d[13] != 0.0 && d[1] == 0.0 && d[7] == 0.0);
    }
}
