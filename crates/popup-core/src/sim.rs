//! Running the arm: initial state, pre-run step-size check, the fixed-step loop with
//! divergence detection, sampling of the sensor channels and the wrinkling alarm log.

use crate::drive::{Drive, Spline3};
use crate::control::machine::Event;
use crate::stream::{either, Collect, DelayLine, Flow, Sink, StateView, Stoppable};
use crate::error::{Error, Result};
use crate::limits::{check_steps, num, POLL_EVERY_STEPS};
use crate::forward::locked_moments_at;
use crate::integrate::{step_with, Workspace};
use crate::math::VecN;
use crate::model::{Integrator, Model};
use crate::params::ParamData;
use crate::sensor::{bending_moments, sample_free, NCH};
use crate::statics::{linear_eigs, static_equilibrium};

/// Joint speed above which a run is declared unstable [rad/s].
pub const MAX_JOINT_SPEED: f64 = 1e4;

/// Mechanical state: time and joint coordinates/rates of the chain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State {
    /// Time [s].
    pub t: f64,
    /// Joint coordinates, chain order [rad] (entries `>= nv` are 0).
    pub q: VecN,
    /// Joint rates [rad/s] (entries `>= nv` are 0).
    pub v: VecN,
}

/// One wrinkling-alarm episode: |M|/M_w of a link above 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alarm {
    /// Link (1 or 2).
    pub link: usize,
    /// Time the moment first exceeded M_w [s].
    pub t_start: f64,
    /// Time it fell back below (NaN if still above at the end) [s].
    pub t_end: f64,
    /// Peak |M|/M_w during the episode.
    pub peak_ratio: f64,
}

/// Result of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Samples, row-major (nsample × [`NCH`]), columns as [`crate::sensor::CHANNELS`].
    pub data: Vec<f64>,
    /// Number of samples.
    pub nsample: usize,
    /// Wrinkling-alarm episodes in time order.
    pub alarms: Vec<Alarm>,
    /// State at the end of the run.
    pub final_state: State,
    /// Warnings (pressure clamped, ...).
    pub warnings: Vec<String>,
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunConfig {
    /// Drive of the motor joints.
    pub drive: Drive,
    /// Initial state; `None` = at rest, motors at the drive's first sample (replay) or at
    /// zero (torque), bending joints in static equilibrium.
    pub initial: Option<State>,
    /// Duration [s]; `None` = the replay's span (required for torque drive).
    pub duration: Option<f64>,
    /// Sensor sample period [s]; must be a whole multiple of the model's dt.
    pub sample_period: f64,
    /// Check the step size against the linearised arm before running (default true).
    pub check_step: bool,
}

/// Initial state at rest with the motors at `qm` and the passive (bending and torsion)
/// joints in static equilibrium.
///
/// # Errors
/// As [`static_equilibrium`].
pub fn rest_state(model: &Model, pd: &ParamData, t: f64, qm: [f64; 3]) -> Result<State> {
    let mut q = VecN::zeros();
    for (k, &i) in model.motor_idx.iter().enumerate() {
        q[i] = qm[k];
    }
    let q = static_equilibrium(model, pd, &q)?;
    Ok(State { t, q, v: VecN::zeros() })
}

/// Check a given initial state: finite, zero beyond the model's joints and on the locked
/// joints of rigid links.
///
/// # Errors
/// [`Error::Input`] naming the joint (or entry) and its values.
pub fn check_initial(model: &Model, s: &State) -> Result<()> {
    for i in 0..model.nv {
        if !s.q[i].is_finite() || !s.v[i].is_finite() {
            return Err(Error::input("initial state", format!("joint {} has q = {}, v = {}", model.joint_name(i), s.q[i], s.v[i])));
        }
        if model.is_locked(i) && (s.q[i] != 0.0 || s.v[i] != 0.0) {
            return Err(Error::input(
                "initial state",
                format!("joint {} has q = {}, v = {}, but it belongs to a rigid link (locked at 0): set both to 0", model.joint_name(i), s.q[i], s.v[i]),
            ));
        }
    }
    for i in model.nv..s.q.len() {
        if s.q[i] != 0.0 || s.v[i] != 0.0 {
            return Err(Error::input(
                "initial state",
                format!("entry {i} has q = {}, v = {}, but the model has {} joints: entries beyond them must be 0", s.q[i], s.v[i], model.nv),
            ));
        }
    }
    Ok(())
}

/// Check `dt` against the linearised arm about `q` (free joints: all in torque drive,
/// passive joints in replay).
///
/// # Errors
/// [`Error::StepTooLarge`] naming the mode, its joint and the largest stable step.
pub fn check_step(model: &Model, pd: &ParamData, q: &VecN, replay: bool) -> Result<()> {
    let mut free = model.free_joints(replay);
    if replay {
        // the link side of a gear with play is free inside its gap (crate::backlash)
        let gap = pd.params.effects.backlash.free_gap();
        free.extend(model.motor_idx.iter().enumerate().filter(|&(k, _)| gap[k] != 0.0).map(|(_, &p)| p));
    }
    let h = model.options.dt;
    let integ = model.options.integrator;
    let eigs = linear_eigs(model, pd, q, &free, integ == Integrator::Rk4);
    // per-mode largest stable step
    let stable_at = |lam: nalgebra::Complex<f64>, h: f64| -> bool {
        match integ {
            Integrator::Rk4 => {
                let z = lam * h;
                let r = nalgebra::Complex::new(1.0, 0.0) + z + z * z / 2.0 + z * z * z / 6.0 + z * z * z * z / 24.0;
                r.norm() <= 1.0 + 1e-12
            }
            Integrator::SemiImplicit => h * lam.norm() < 2.0,
        }
    };
    let mut worst: Option<(f64, nalgebra::Complex<f64>, usize)> = None;
    for (lam, joint) in eigs {
        if lam.re > 1e-9 * lam.norm().max(1.0) {
            continue; // statically unstable direction: no step makes it decay
        }
        if lam.norm() == 0.0 || stable_at(lam, h) {
            continue;
        }
        let (mut lo, mut hi) = (0.0, h);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if stable_at(lam, mid) {
                lo = mid
            } else {
                hi = mid
            }
        }
        if worst.map_or(true, |w| lo < w.0) {
            worst = Some((lo, lam, joint));
        }
    }
    if let Some((dt_max, lam, joint)) = worst {
        return Err(Error::StepTooLarge {
            dt: h,
            dt_max: (dt_max * 0.95 * 1e9).floor() / 1e9,
            integrator: integ.name().into(),
            detail: format!(
                "the mode at |λ| = {:.1} rad/s (ζ = {:.3}) dominated by joint {} falls outside its stability region",
                lam.norm(),
                (-lam.re / lam.norm()).max(0.0),
                model.joint_name(joint)
            ),
        });
    }
    Ok(())
}

pub(crate) fn diverged(model: &Model, k: usize, t: f64, q: &VecN, v: &VecN) -> Option<Error> {
    let mut worst: Option<(usize, String)> = None;
    let mut vmax = 0.0;
    for i in 0..model.nv {
        if !q[i].is_finite() || !v[i].is_finite() {
            worst = Some((i, format!("q = {} rad, v = {} rad/s (non-finite)", q[i], v[i])));
            break;
        }
        if v[i].abs() > MAX_JOINT_SPEED && v[i].abs() > vmax {
            vmax = v[i].abs();
            worst = Some((i, format!("|v| = {:.3e} rad/s > {MAX_JOINT_SPEED:e} rad/s", v[i].abs())));
        }
    }
    worst.map(|(i, quantity)| Error::Diverged {
        step: k,
        time: t,
        joint: model.joint_name(i).to_string(),
        quantity,
        advice: format!(
            "reduce dt (now {:e} s) or switch integrator (now {}), and check the inputs (torques, encoder samples) near this time",
            model.options.dt,
            model.options.integrator.name()
        ),
    })
}

/// Update the wrinkling-alarm episodes at time `t` [s] from |M|/M_w per link: open an
/// episode when a ratio exceeds 1, track its peak, close it when the ratio falls back.
/// `open[l]` is the index of link l's open episode.
pub(crate) fn track_alarms(open: &mut [Option<usize>; 2], alarms: &mut Vec<Alarm>, t: f64, ratio: [f64; 2]) {
    for l in 0..2 {
        match open[l] {
            None if ratio[l] > 1.0 => {
                open[l] = Some(alarms.len());
                alarms.push(Alarm { link: l + 1, t_start: t, t_end: f64::NAN, peak_ratio: ratio[l] });
            }
            Some(a) if ratio[l] > 1.0 => alarms[a].peak_ratio = alarms[a].peak_ratio.max(ratio[l]),
            Some(a) => {
                alarms[a].t_end = t;
                open[l] = None;
            }
            None => {}
        }
    }
}

/// The sample interval in steps of `dt` for `sample_period` [s]: finite, > 0, a whole
/// multiple of `dt` and not longer than [`crate::limits::MAX_STEPS`] steps.
///
/// # Errors
/// [`Error::Input`] naming `sample_period`.
pub fn check_sample_period(sample_period: f64, dt: f64) -> Result<usize> {
    if !(sample_period.is_finite() && sample_period > 0.0) {
        return Err(Error::input("sample_period (1/sample_rate)", format!("{} s must be finite and > 0", num(sample_period))));
    }
    let r = (sample_period / dt).round().max(1.0);
    if r > crate::limits::MAX_STEPS || (r * dt - sample_period).abs() > 1e-9 * sample_period {
        return Err(Error::input(
            "sample_period (1/sample_rate)",
            format!(
                "{} s is not a whole multiple of dt = {} s (the sample rate {} Hz must divide the physics rate {} Hz)",
                num(sample_period),
                num(dt),
                num(1.0 / sample_period),
                num(1.0 / dt)
            ),
        ));
    }
    Ok(r as usize)
}

/// Run one simulation.
///
/// # Errors
/// Bad config ([`Error::Input`]), [`Error::StepTooLarge`], [`Error::Diverged`], or the
/// static-equilibrium error for the initial state.
pub fn run(model: &Model, pd: &ParamData, cfg: &RunConfig) -> Result<Trajectory> {
    run_until(model, pd, cfg, &std::sync::atomic::AtomicBool::new(false))
}

/// [`run`] that ends early, with the samples produced so far, once `stop` is raised (seen
/// within [`POLL_EVERY_STEPS`] steps): the caller (e.g. a Ctrl-C watcher) knows it asked.
///
/// # Errors
/// As [`run`].
pub fn run_until(model: &Model, pd: &ParamData, cfg: &RunConfig, stop: &std::sync::atomic::AtomicBool) -> Result<Trajectory> {
    let mut col = Collect::default();
    let end = run_into(model, pd, cfg, &mut Stoppable { inner: &mut col, flag: stop })?;
    Ok(Trajectory { data: col.data, nsample: end.nsample, alarms: end.alarms, final_state: end.final_state, warnings: pd.warnings.clone() })
}

/// How a streamed open-loop run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenEnd {
    /// Samples handed to the sink (fewer than the full run when the sink stopped it).
    pub nsample: usize,
    /// Wrinkling-alarm episodes in time order.
    pub alarms: Vec<Alarm>,
    /// State at the end of the run.
    pub final_state: State,
}

/// The wrinkling-alarm onsets and ends between two tracker states, as events.
pub(crate) fn alarm_events(before: [Option<usize>; 2], open: [Option<usize>; 2], alarms: &[Alarm], t: f64, sink: &mut dyn Sink) -> Result<Flow> {
    let mut flow = Flow::Go;
    for l in 0..2 {
        if open[l] != before[l] {
            let a = &alarms[open[l].or(before[l]).expect("one of them is open")];
            let (kind, detail) = if open[l].is_some() {
                ("wrinkle_start", format!("|M|/M_w > 1 on link {} (wrinkling)", l + 1))
            } else {
                ("wrinkle_end", format!("|M|/M_w back below 1 on link {}; episode from t = {:.4} s, peak {:.3}", l + 1, a.t_start, a.peak_ratio))
            };
            let link = format!("link {}", l + 1);
            flow = either(flow, sink.event(&Event { t, kind, from: link.clone(), to: link, detail })?);
        }
    }
    Ok(flow)
}

/// [`run`] streamed: the true state at every sample time, the samples (after the sensor
/// delays) and the wrinkling-alarm events go to `sink` as they are produced; memory does
/// not grow with the duration. A sink returning [`Flow::Stop`] ends the run there.
///
/// # Errors
/// As [`run`], and the sink's errors.
pub fn run_into(model: &Model, pd: &ParamData, cfg: &RunConfig, sink: &mut dyn Sink) -> Result<OpenEnd> {
    let dt = model.options.dt;
    let (t0, duration) = match (&cfg.drive, cfg.duration) {
        (Drive::Replay(s), d) => {
            let (a, b) = s.span();
            (a, d.unwrap_or(b - a))
        }
        (Drive::Torque(_) | Drive::Hold(_), Some(d)) => (cfg.initial.map_or(0.0, |s| s.t), d),
        (Drive::Torque(_) | Drive::Hold(_), None) => return Err(Error::input("duration", "a torque-driven run needs a duration")),
    };
    let what = if matches!(cfg.drive, Drive::Replay(_)) && cfg.duration.is_none() { "replay span" } else { "duration" };
    // bounded work: the step count is checked before the loop starts
    let nstep = check_steps(what, duration, dt)?;
    let every = check_sample_period(cfg.sample_period, dt)?;
    let fx = &pd.params.effects;
    let (drive, encoder) = effect_drive(model, pd, &cfg.drive)?;
    let cfg = &RunConfig { drive, ..cfg.clone() };
    let mut st = match cfg.initial {
        Some(s) => {
            check_initial(model, &s)?;
            s
        }
        None => {
            let qm = match &cfg.drive {
                Drive::Replay(s) => s.eval(t0).0,
                Drive::Torque(_) | Drive::Hold(_) => [0.0; 3],
            };
            crate::backlash::rest(model, pd, t0, qm)?
        }
    };
    st.t = t0;
    let play = crate::backlash::active(pd, &cfg.drive);
    let mut ws = Workspace::new();
    // the gears' modes at a state (all rigid without backlash)
    let gears = |st: &State, ws: &mut Workspace| if play { crate::backlash::modes(model, pd, &cfg.drive, st.t, &st.q, &st.v, ws.matrix()) } else { crate::backlash::RIGID };
    let g0 = gears(&st, &mut ws);
    crate::backlash::prescribe(model, &cfg.drive, &g0, t0, &mut st.q, &mut st.v);
    if cfg.check_step {
        check_step(model, pd, &st.q, cfg.drive.is_replay())?;
    }
    let sd = &fx.sensor_delay;
    let mut line = DelayLine::for_sensors(every as f64 * dt, sd, !cfg.drive.is_replay());
    let mut alarms: Vec<Alarm> = Vec::new();
    let mut open: [Option<usize>; 2] = [None, None];
    let mut row = [0.0; NCH];
    let mut nsample = 0usize;
    let mut write = |st: &State, ratio: [f64; 2], row: &mut [f64; NCH], sink: &mut dyn Sink| -> Result<Flow> {
        let f = sink.state(&StateView { t: st.t, q: &st.q, v: &st.v, pd, ratio })?;
        output_row(model, pd, &cfg.drive, encoder.as_ref(), play, st, row);
        nsample += 1;
        Ok(either(f, line.push(row, None, sink)?))
    };
    let mut track = |st: &State, alarms: &mut Vec<Alarm>, sink: &mut dyn Sink| -> Result<(Flow, [f64; 2])> {
        let lock = locked_moments_at(model, pd, &cfg.drive, st.t, &st.q, &st.v);
        let (_, ratio) = bending_moments(model, pd, st.t, &st.q, &st.v, &lock);
        let before = open;
        track_alarms(&mut open, alarms, st.t, ratio);
        Ok((alarm_events(before, open, alarms, st.t, sink)?, ratio))
    };
    let (f0, ratio) = track(&st, &mut alarms, sink)?;
    let mut flow = either(f0, write(&st, ratio, &mut row, sink)?);
    for k in 0..nstep {
        if k % POLL_EVERY_STEPS == POLL_EVERY_STEPS - 1 {
            flow = either(flow, sink.poll());
        }
        if flow == Flow::Stop {
            break;
        }
        let t = t0 + k as f64 * dt;
        step_with(model, pd, &cfg.drive, t, dt, &mut st.q, &mut st.v, &mut ws);
        st.t = t0 + (k + 1) as f64 * dt;
        if let Some(e) = diverged(model, k, t, &st.q, &st.v) {
            return Err(e);
        }
        let (f, ratio) = track(&st, &mut alarms, sink)?;
        flow = f;
        if (k + 1) % every == 0 {
            flow = either(flow, write(&st, ratio, &mut row, sink)?);
        }
    }
    line.finish(sink)?;
    Ok(OpenEnd { nsample, alarms, final_state: st })
}

/// One output row of an open-loop run at state `st` (before the sensor delays): the gears'
/// modes at the state (all rigid unless `play`), the prescribed motor rows, the sensor
/// channels, and the encoder's own `q*`/`dq*` where the physics does not give them.
#[allow(clippy::too_many_arguments)]
fn output_row(model: &Model, pd: &ParamData, drive: &Drive, encoder: Option<&Spline3>, play: bool, st: &State, row: &mut [f64; NCH]) {
    let mut q = st.q;
    let mut v = st.v;
    let g = if play { crate::backlash::modes(model, pd, drive, st.t, &st.q, &st.v, Workspace::new().matrix()) } else { crate::backlash::RIGID };
    let am = crate::backlash::prescribe(model, drive, &g, st.t, &mut q, &mut v);
    sample_free(model, pd, drive, st.t, &q, &v, am, &g.free, row);
    if let Some(enc) = encoder {
        encoder_channels(enc, st.t, row);
    }
}

/// A sink that keeps the state of every sample (for [`resample`]) and passes everything
/// on to `inner`.
struct Record<'a> {
    inner: &'a mut dyn Sink,
    states: Vec<State>,
}

impl Sink for Record<'_> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; crate::control::closed_loop::NCTRL]>) -> Result<Flow> {
        self.inner.sample(row, ctrl)
    }
    fn event(&mut self, e: &Event) -> Result<Flow> {
        self.inner.event(e)
    }
    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        self.states.push(State { t: s.t, q: *s.q, v: *s.v });
        self.inner.state(s)
    }
    fn poll(&mut self) -> Flow {
        self.inner.poll()
    }
}

/// A run's motion as its sensor rows before the effects that act on the rows alone
/// ([`crate::effects::OUTPUT_ONLY_IN_REPLAY`]: friction, its clamp, the delays), from which
/// [`resample`] gives the run of any of their values with no step of physics.
#[derive(Debug, Clone, PartialEq)]
pub struct Motion {
    /// Rows at the sample states without friction, clamp, delays or the encoder's own
    /// `q*`/`dq*` (so `dq*` are the physics' motor rates).
    bare: Vec<[f64; NCH]>,
    alarms: Vec<Alarm>,
    final_state: State,
}

/// [`run_until`] that also returns the run's [`Motion`] (an open-loop run in encoder
/// replay; `None` otherwise).
///
/// # Errors
/// As [`run`].
pub fn run_recorded(model: &Model, pd: &ParamData, cfg: &RunConfig, stop: &std::sync::atomic::AtomicBool) -> Result<(Trajectory, Option<Motion>)> {
    let mut col = Collect::default();
    let mut rec = Record { inner: &mut Stoppable { inner: &mut col, flag: stop }, states: Vec::new() };
    let end = run_into(model, pd, cfg, &mut rec)?;
    let states = rec.states;
    let tr = Trajectory { data: col.data, nsample: end.nsample, alarms: end.alarms, final_state: end.final_state, warnings: pd.warnings.clone() };
    let (drive, _) = effect_drive(model, pd, &cfg.drive)?;
    if !drive.is_replay() {
        return Ok((tr, None));
    }
    let mut bare_pd = pd.clone();
    bare_pd.params.effects.joint_friction = Default::default();
    bare_pd.params.effects.actuator_saturation = Default::default();
    // a gear's play: its modes at each state, as the run had them (they do not depend on
    // the motor side's friction or clamp)
    let play = crate::backlash::active(&bare_pd, &drive);
    let bare = states
        .iter()
        .map(|st| {
            let mut row = [0.0; NCH];
            output_row(model, &bare_pd, &drive, None, play, st, &mut row);
            row
        })
        .collect();
    let m = Motion { bare, alarms: tr.alarms.clone(), final_state: tr.final_state };
    Ok((tr, Some(m)))
}

/// The run of `cfg` with parameters `pd` from a [`Motion`] that [`run_recorded`] made with
/// the same `cfg` and parameters that differ from `pd` only in
/// [`crate::effects::OUTPUT_ONLY_IN_REPLAY`] ([`crate::effects::same_motion`]): friction and
/// clamp put on each row, the encoder's own channels, the delays. The same bits as [`run`]
/// with `pd` (`tests/shared_motion.rs`).
///
/// # Errors
/// As [`run`] for a bad `cfg` (the sample period, the drive).
pub fn resample(model: &Model, pd: &ParamData, cfg: &RunConfig, m: &Motion) -> Result<Trajectory> {
    let dt = model.options.dt;
    let every = check_sample_period(cfg.sample_period, dt)?;
    let (drive, encoder) = effect_drive(model, pd, &cfg.drive)?;
    let fx = &pd.params.effects;
    let mut line = DelayLine::for_sensors(every as f64 * dt, &fx.sensor_delay, !drive.is_replay());
    let mut col = Collect::with_capacity(m.bare.len());
    let mut row = [0.0; NCH];
    for bare in &m.bare {
        crate::sensor::with_torque_effects(fx, bare, &mut row);
        if let Some(enc) = &encoder {
            encoder_channels(enc, bare[0], &mut row);
        }
        line.push(&row, None, &mut col)?;
    }
    line.finish(&mut col)?;
    Ok(Trajectory { data: col.data, nsample: m.bare.len(), alarms: m.alarms.clone(), final_state: m.final_state, warnings: pd.warnings.clone() })
}

/// The `q*`, `dq*` channels read from the encoder at `t` (not from the physics).
fn encoder_channels(enc: &Spline3, t: f64, row: &mut [f64; NCH]) {
    let (qe, ve, _) = enc.eval(t);
    row[1..4].copy_from_slice(&qe);
    row[4..7].copy_from_slice(&ve);
}

/// The drive the physics sees in replay under an encoder `sensor_delay` and a `backlash`
/// whose link side is held in its gap: the true motor angle leads the encoder by the delay
/// (`q_m(t) = q_enc(t + delay)`) and a held link side follows the play operator of it
/// ([`crate::backlash::play`]). Returns the drive and, when the `q*`/`dq*` channels must
/// not be read from the physics (a delay, or `backlash`, where the chain holds the link
/// side), the encoder spline for them.
fn effect_drive(model: &Model, pd: &ParamData, drive: &Drive) -> Result<(Drive, Option<Spline3>)> {
    let fx = &pd.params.effects;
    let gap = fx.backlash.gap;
    let held = fx.backlash.held_gap();
    let delay = fx.sensor_delay.encoder;
    match drive {
        Drive::Torque(_) | Drive::Hold(_) if gap != [0.0; 3] => Err(Error::param(
            "effects.backlash.gap",
            format!("{gap:?}"),
            "backlash needs encoder replay in this version (torque drive has no motor-side state until the motoreducer model of the controller issue)",
        )),
        Drive::Replay(_) if fx.backlash.free_gap() != [0.0; 3] && model.has_beam() => Err(Error::param(
            "effects.backlash.gap",
            format!("{gap:?}"),
            "backlash with a free link side is not available with beam links in this version (the articulated-body solver has no free motor rows): use PRBM links or held = 1",
        )),
        Drive::Replay(s) if held != [0.0; 3] => {
            // played at the encoder samples: a joint without a held gap keeps its spline
            // exactly, and a held gap going to 0 is the rigid gear (a finer played grid
            // re-interpolates every joint, which a fit then exploits as a smoother)
            let (t, y) = s.knots();
            let ts: Vec<f64> = t.iter().map(|&x| x - delay).collect();
            Ok((Drive::Replay(Spline3::new(&ts, &crate::backlash::play(y, &held))?), Some(s.clone())))
        }
        Drive::Replay(s) if delay != 0.0 => {
            let (t, y) = s.knots();
            let ts: Vec<f64> = t.iter().map(|&x| x - delay).collect();
            Ok((Drive::Replay(Spline3::new(&ts, y)?), Some(s.clone())))
        }
        Drive::Replay(s) if gap != [0.0; 3] => Ok((drive.clone(), Some(s.clone()))),
        _ => Ok((drive.clone(), None)),
    }
}
