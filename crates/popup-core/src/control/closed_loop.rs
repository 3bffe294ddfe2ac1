//! The closed-loop run: the physics at its step `dt`, the controller (state machine,
//! references, cascade, damping PIDs, current loops, collision queries) at its period
//! `T = n dt`, the drive torques held in between. Deterministic: no allocation on the
//! per-step path except log entries, no hashing, fixed evaluation order.

use crate::control::collision::{Capsule, CollisionWorld};
use crate::control::law::{Lpf, Pi, Pid, PidState};
use crate::control::machine::{Command, Event, FaultAction, Phase};
use crate::control::{CartesianArm, ClosedLoop};
use crate::drive::Drive;
use crate::dynamics::forward_pass;
use crate::error::{Error, Result};
use crate::forward::{accel_with, locked_moments, locked_moments_at};
use crate::integrate::{step_with, Workspace};
use crate::kinematics::prbm::{frames_with, Frames};
use crate::kinematics::rigid::RigidArm;
use crate::math::{MatN, Vec3, VecN};
use crate::model::Model;
use crate::params::{ParamData, Params};
use crate::sensor::{bending_moments, sample, NCH};
use crate::sim::{alarm_events, check_initial, check_step, diverged, rest_state, track_alarms, Alarm, State, Trajectory};
use crate::stream::{either, Collect, DelayLine, Flow, Sink, StateView};
use crate::statics::gravity_torque;

/// Number of controller channels.
pub const NCTRL: usize = 17;

/// Controller channel names (units: rad, rad/s, rad/s, m/s², N·m, code, m): position
/// references, velocity references into the velocity loops (after the damping term), damping-PID
/// outputs, filtered relative tip accelerations (the damping inputs), torque references
/// (after the limit, before the current loop), the active phase code (index into the
/// sequence; −1 WrinkleAlarm, −2 Saturated, −3 Contact, −4 Unstable) and the minimum
/// clearance to any obstacle (`inf` with none).
pub const CTRL_CHANNELS: [&str; NCTRL] = [
    "ref_q1", "ref_q2", "ref_q3", "vref1", "vref2", "vref3", "u_damp1", "u_damp2", "u_damp3", "a_rel1", "a_rel2", "a_rel3", "tau_cmd1", "tau_cmd2",
    "tau_cmd3", "phase", "d_min",
];

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// Ran for the whole duration.
    Completed,
    /// Stopped in the `Unstable` fault (non-finite or runaway state); later rows are NaN.
    Unstable,
    /// Stopped by the sink (Ctrl-C on a logged run); later rows are NaN.
    Interrupted,
}

impl Status {
    /// `completed`, `unstable` or `interrupted`.
    pub fn name(self) -> &'static str {
        match self {
            Status::Completed => "completed",
            Status::Unstable => "unstable",
            Status::Interrupted => "interrupted",
        }
    }
}

/// How a streamed closed-loop run ended (the samples went to the sink).
#[derive(Debug, Clone, PartialEq)]
pub struct RunEnd {
    /// Samples handed to the sink.
    pub nsample: usize,
    /// Samples a full run has (`duration / sample_period + 1`).
    pub nsample_full: usize,
    /// Wrinkling-alarm episodes in time order.
    pub alarms: Vec<Alarm>,
    /// State at the end of the run.
    pub final_state: State,
    /// Warnings (pressure clamped, ...).
    pub warnings: Vec<String>,
    /// The event log (also handed to the sink as it happened).
    pub events: Vec<Event>,
    /// How the run ended.
    pub status: Status,
}

/// Result of a closed-loop run.
#[derive(Debug, Clone, PartialEq)]
pub struct ClosedTrajectory {
    /// Sensor channels (as [`crate::sim::run`]).
    pub traj: Trajectory,
    /// Controller channels, row-major (nsample × [`NCTRL`]).
    pub control: Vec<f64>,
    /// Log: every transition, fault, contact, payload and pressure change.
    pub events: Vec<Event>,
    /// How the run ended.
    pub status: Status,
}

const FAULT_NAMES: [&str; 4] = ["WrinkleAlarm", "Saturated", "Contact", "Unstable"];

#[derive(Debug, Clone, Copy, PartialEq)]
struct Fault {
    kind: usize,
    action: FaultAction,
    q_hold: [f64; 3],
    k0: usize,
    clear_ticks: usize,
}

/// The rigid equivalent of the model's chain (bending and torsion at zero) as a 3-DOF DH
/// table, for workspace checks of Cartesian targets.
pub fn rigid_equivalent(model: &Model) -> Result<RigidArm> {
    let fr = frames_with(model, &model.rotations(&VecN::zeros()));
    let (ish, iel) = (model.motor_idx[1], model.motor_idx[2]);
    let o_sh = fr.p_wb[ish];
    let z_sh = fr.r_wb[ish].column(2).into_owned();
    let o_el = fr.p_wb[iel];
    let p_e = fr.point(model.ee.0 + 1, &model.ee.1);
    let lat = z_sh.dot(&(p_e - o_sh));
    let a2 = (o_el - o_sh - z_sh * z_sh.dot(&(o_el - o_sh))).norm();
    let a3 = (p_e - o_el - z_sh * z_sh.dot(&(p_e - o_el))).norm();
    RigidArm::new(format!("{} (rigid equivalent of its PRBM chain)", model.spec.name), [o_sh.z, 0.0, lat], [0.0, a2, a3], [std::f64::consts::FRAC_PI_2, 0.0, 0.0], [0.0; 3])
}

/// Rigid tip position and translational Jacobian of the chain at motor angles `qm` (passive
/// joints at zero) [m], [m/rad].
fn rigid_tip(model: &Model, qm: &[f64; 3]) -> (Vec3, [Vec3; 3]) {
    let mut q = VecN::zeros();
    for (k, &i) in model.motor_idx.iter().enumerate() {
        q[i] = qm[k];
    }
    let fr = frames_with(model, &model.rotations(&q));
    let p = fr.point(model.ee.0 + 1, &model.ee.1);
    let cols = std::array::from_fn(|k| {
        let i = model.motor_idx[k];
        fr.r_wb[i].column(2).into_owned().cross(&(p - fr.p_wb[i]))
    });
    (p, cols)
}

/// Collision parts of the arm at `fr`: one capsule per chain segment of each link (from
/// frame i to frame i+1 beyond the shoulder), then the payload sphere. Writes `parts`,
/// returns how many.
pub(crate) fn arm_parts(model: &Model, fr: &Frames, payload: f64, payload_radius: f64, parts: &mut [Capsule], names: &mut [usize]) -> usize {
    let mut n = 0;
    for i in model.motor_idx[1]..model.nv {
        let (a, b) = (fr.p_wb[i], fr.p_wb[i + 1]);
        if (b - a).norm() < 1e-9 {
            continue;
        }
        let l = usize::from(i >= model.motor_idx[2]);
        parts[n] = Capsule { a: [a.x, a.y, a.z], b: [b.x, b.y, b.z], radius: model.link_radius[l] };
        names[n] = l;
        n += 1;
    }
    if payload > 0.0 && payload_radius > 0.0 {
        let c = fr.point(model.payload_body + 1, &model.payload_com);
        parts[n] = Capsule { a: [c.x, c.y, c.z], b: [c.x, c.y, c.z], radius: payload_radius };
        names[n] = 2;
        n += 1;
    }
    n
}

/// Run one closed-loop simulation.
///
/// # Errors
/// Bad configuration ([`Error::InvalidParameter`], [`Error::Input`]: controller period not a
/// whole multiple of dt, sample period not a multiple of dt, bad phases, obstacles),
/// [`Error::Unreachable`] for a Cartesian target outside the rigid workspace,
/// [`Error::StepTooLarge`] from the step check. A run that goes unstable is not an error: it
/// ends in the `Unstable` fault (see [`Status`]).
pub fn run_closed_loop(model: &Model, params: &Params, cfg: &ClosedLoop) -> Result<ClosedTrajectory> {
    run_closed_loop_until(model, params, cfg, &std::sync::atomic::AtomicBool::new(false))
}

/// [`run_closed_loop`] that ends (status `Interrupted`, the rest NaN) once `stop` is raised.
///
/// # Errors
/// As [`run_closed_loop`].
pub fn run_closed_loop_until(model: &Model, params: &Params, cfg: &ClosedLoop, stop: &std::sync::atomic::AtomicBool) -> Result<ClosedTrajectory> {
    let mut col = Collect::default();
    let end = run_closed_loop_into(model, params, cfg, &mut crate::stream::Stoppable { inner: &mut col, flag: stop })?;
    let (mut data, mut control) = (col.data, col.ctrl);
    data.resize(end.nsample_full * NCH, f64::NAN);
    control.resize(end.nsample_full * NCTRL, f64::NAN);
    Ok(ClosedTrajectory {
        traj: Trajectory { data, nsample: end.nsample_full, alarms: end.alarms, final_state: end.final_state, warnings: end.warnings },
        control,
        events: end.events,
        status: end.status,
    })
}

/// [`run_closed_loop`] streamed: samples (after the sensor delays), events (the log, and
/// `wrinkle_start`/`wrinkle_end` for each alarm episode) and the true states go to `sink`
/// as the run produces them; nothing per sample is kept, so memory does not grow with the
/// duration. A sink returning [`Flow::Stop`] ends the run at that sample with
/// [`Status::Interrupted`] (an `interrupted` event is logged).
///
/// # Errors
/// As [`run_closed_loop`], and the sink's errors.
pub fn run_closed_loop_into(model: &Model, params: &Params, cfg: &ClosedLoop, sink: &mut dyn Sink) -> Result<RunEnd> {
    let c = &cfg.controller;
    c.validate()?;
    cfg.sequence.validate()?;
    let dt = model.options.dt;
    let period = c.period();
    let nsub = (period / dt).round() as usize;
    if nsub == 0 || ((nsub as f64) * dt - period).abs() > 1e-9 * period {
        return Err(Error::input(
            "controller.rate_hz",
            format!("controller period T = {period:e} s must be a whole multiple of the physics step dt = {dt:e} s (set dt = T/n)"),
        ));
    }
    // bounded work: the step count is checked before the loop starts
    let nstep = crate::limits::check_steps("duration", cfg.duration, dt)?;
    let every = crate::sim::check_sample_period(cfg.sample_period, dt)?;
    if !(cfg.payload_radius.is_finite() && cfg.payload_radius >= 0.0) {
        return Err(Error::param("payload_radius", cfg.payload_radius, "must be finite and >= 0 m"));
    }
    if pd_gap(params) {
        return Err(Error::param("effects.backlash.gap", format!("{:?}", params.effects.backlash.gap), "backlash needs encoder replay in this version"));
    }
    let rigid = match c.cartesian_arm {
        CartesianArm::Prbm => rigid_equivalent(model)?,
        CartesianArm::AsBuilt => model.spec.rigid_arm("as_built")?,
        CartesianArm::Ik => model.spec.rigid_arm("ik")?,
    };
    for (i, ph) in cfg.sequence.phases.iter().enumerate() {
        if let Command::Cartesian { target } = ph.command {
            rigid.in_workspace(&Vec3::from(target)).map_err(|e| match e {
                Error::Unreachable { target, arm, reason } => Error::Unreachable { target, arm, reason: format!("phases[{i}] ({}): {reason}", ph.name) },
                e => e,
            })?;
        }
    }
    let world = CollisionWorld::new(&cfg.obstacles)?;
    let mut pd = ParamData::new(model, params)?;
    let mut st = match cfg.initial {
        Some(s) => {
            check_initial(model, &s)?;
            s
        }
        None => rest_state(model, &pd, 0.0, cfg.q0)?,
    };
    let t0 = st.t;
    if cfg.check_step {
        check_step(model, &pd, &st.q, false)?;
    }
    let nsample_full = nstep / every + 1;
    let sd = &params.effects.sensor_delay;
    let mut line = DelayLine::for_sensors(every as f64 * dt, sd, true);
    let mut nsample = 0usize;
    let mut emitted = 0usize;
    let mut row = [0.0; NCH];
    let mut events: Vec<Event> = Vec::new();
    let mut alarms: Vec<Alarm> = Vec::new();
    let mut open: [Option<usize>; 2] = [None, None];
    let phases = &cfg.sequence.phases;
    let pol = &cfg.sequence.faults;
    let mi = model.motor_idx;

    // controller state
    let g = &c.gains;
    let mot = &c.motors;
    let lpf = Lpf::new(c.damping_lpf, period);
    let alpha: [f64; 3] = std::array::from_fn(|j| if mot[j].current_bandwidth.is_finite() { 1.0 - (-mot[j].current_bandwidth * period).exp() } else { 1.0 });
    let hold = gravity_torque(model, &pd, &st.q);
    let mut tau: [f64; 3] = std::array::from_fn(|j| hold[mi[j]].clamp(-mot[j].tau_max, mot[j].tau_max));
    let mut iv: [f64; 3] = std::array::from_fn(|j| tau[j] / mot[j].torque_per_unit);
    let mut ip = [0.0; 3];
    let mut lpf_y = [0.0f64; 3];
    let mut pid = [PidState::default(); 3];
    let mut v_prev: [f64; 3] = std::array::from_fn(|j| st.v[mi[j]]);
    let mut sat = [false; 3];
    let mut sat_ticks = [0usize; 3];
    let mut out = [0.0; NCTRL];
    let mut cur = 0usize;
    let mut phase_ticks = 0usize;
    let mut q_start: [f64; 3] = std::array::from_fn(|j| mot[j].encode(st.q[mi[j]]));
    let mut fault: Option<Fault> = None;
    let mut terminal = false;
    let mut payload_now = params.payload_kg;
    let mut pressure_now = params.pressure_pa;
    let mut parts = [Capsule { a: [0.0; 3], b: [0.0; 3], radius: 0.0 }; crate::math::NMAX + 1];
    let mut part_link = [0usize; crate::math::NMAX + 1];
    let mut dist = [0.0; crate::math::NMAX + 1];
    let part_names = ["link 1", "link 2", "payload"];
    let mut m_scratch = MatN::zeros();
    let mut ws = Workspace::new();
    let mut drive = Drive::Hold(tau);
    let mut status = Status::Completed;
    // |M|/M_w > 1 on either link at the previous controller tick (onset of `continue` alarms)
    let mut wrinkled_prev = false;
    // |M|/M_w per link at the current state (for the state sink)
    let mut ratio_now = [0.0; 2];

    let phase_name = |cur: usize, fault: &Option<Fault>| -> String {
        match fault {
            Some(f) => FAULT_NAMES[f.kind].to_string(),
            None => phases[cur].name.clone(),
        }
    };

    // entry actions of phase `i`
    let enter = |i: usize, t: f64, events: &mut Vec<Event>, payload_now: &mut f64, pressure_now: &mut [f64; 2]| -> Option<Params> {
        let ph: &Phase = &phases[i];
        let mut changed = None;
        if let Some(m) = ph.payload_kg {
            if m != *payload_now {
                events.push(Event { t, kind: "payload", from: format!("{payload_now} kg"), to: format!("{m} kg"), detail: format!("payload set on entry to {}", ph.name) });
                *payload_now = m;
                changed = Some(());
            }
        }
        if let Some(p) = ph.pressure_pa {
            if p != *pressure_now {
                events.push(Event { t, kind: "pressure", from: format!("{pressure_now:?} Pa"), to: format!("{p:?} Pa"), detail: format!("pressure set on entry to {}", ph.name) });
                *pressure_now = p;
                changed = Some(());
            }
        }
        changed.map(|_| Params { payload_kg: *payload_now, pressure_pa: *pressure_now, effects: params.effects })
    };
    if let Some(p) = enter(0, t0, &mut events, &mut payload_now, &mut pressure_now) {
        pd = ParamData::new(model, &p)?;
    }
    events.push(Event { t: t0, kind: "transition", from: "Start".into(), to: phases[0].name.clone(), detail: "run starts".into() });


    let mut k = 0usize;
    loop {
        if k % nsub == 0 {
            // ---- controller tick at t_k ----
            let t = st.t;
            let qe: [f64; 3] = std::array::from_fn(|j| mot[j].encode(st.q[mi[j]]));
            let ve: [f64; 3] = std::array::from_fn(|j| st.v[mi[j]]);
            let am: [f64; 3] = std::array::from_fn(|j| if k == 0 { 0.0 } else { (ve[j] - v_prev[j]) / period });
            v_prev = ve;
            // IMUs (specific force, mount axes) with the torques held since the last tick
            let rot = model.rotations(&st.q);
            let qdd = accel_with(model, &pd, &drive, t, &st.q, &st.v, None, 0.0, &mut m_scratch);
            let bm = forward_pass(model, &rot, &st.v, &qdd, &(-model.gravity));
            let fr = frames_with(model, &rot);
            // rigid equivalent: passive joints at rest, motor accelerations from the encoder rates
            let (mut qr, mut vr, mut ar) = (VecN::zeros(), VecN::zeros(), VecN::zeros());
            for j in 0..3 {
                qr[mi[j]] = st.q[mi[j]];
                vr[mi[j]] = ve[j];
                ar[mi[j]] = am[j];
            }
            let rot_r = model.rotations(&qr);
            let bmr = forward_pass(model, &rot_r, &vr, &ar, &(-model.gravity));
            let fr_r = frames_with(model, &rot_r);
            let mut arel = [Vec3::zeros(); 2];
            for s in 0..2 {
                let (b, p) = &model.imu[s];
                let f = bm.a[*b] + bm.wd[*b].cross(p) + bm.w[*b].cross(&bm.w[*b].cross(p));
                let fr_rig = bmr.a[*b] + bmr.wd[*b].cross(p) + bmr.w[*b].cross(&bmr.w[*b].cross(p));
                // the rigid tip's specific force, re-expressed in the (bent) IMU axes
                let f_rig_imu = fr.r_wb[b + 1].transpose() * (fr_r.r_wb[b + 1] * fr_rig);
                arel[s] = f - f_rig_imu;
            }
            // joint 1: lateral (z) difference of the two links; joints 2, 3: in-plane (y) of links 1, 2
            let sig = [arel[0].z - arel[1].z, arel[0].y, arel[1].y];
            let (_, ratio) = bending_moments(model, &pd, t, &st.q, &st.v, &locked_moments(model, &pd, &rot, &st.v, &qdd));
            ratio_now = ratio;
            let wrinkled = ratio[0] > 1.0 || ratio[1] > 1.0;
            // collision
            let np = arm_parts(model, &fr, payload_now, cfg.payload_radius, &mut parts, &mut part_link);
            let closest = world.distances(&parts[..np], &mut dist[..np])?;
            let d_min = closest.map_or(f64::INFINITY, |cl| cl.distance);

            // ---- state machine ----
            let name_before = phase_name(cur, &fault);
            if let Some(f) = fault.as_mut() {
                let cleared = match f.kind {
                    0 => ratio[0] < pol.wrinkle_clear_ratio && ratio[1] < pol.wrinkle_clear_ratio,
                    1 => !sat.iter().any(|&s| s),
                    2 => d_min > 2.0 * pol.contact_margin,
                    _ => false,
                };
                f.clear_ticks = if cleared { f.clear_ticks + 1 } else { 0 };
                if f.action == FaultAction::Hold && f.clear_ticks as f64 * period >= pol.clear_time {
                    // the phase resumes where its clock stopped, from its original start angles
                    fault = None;
                    events.push(Event { t, kind: "transition", from: name_before.clone(), to: phases[cur].name.clone(), detail: "fault cleared: phase resumes".into() });
                }
            } else if !terminal {
                // faults
                let sat_limit = (pol.saturation_time / period).ceil() as usize;
                let raised = if ratio[0] > 1.0 || ratio[1] > 1.0 {
                    let l = if ratio[0] >= ratio[1] { 0 } else { 1 };
                    Some((0usize, pol.wrinkle, format!("|M|/M_w = {:.3} on link {} (M_w = {:.3} N·m)", ratio[l], l + 1, pd.mw_at(l, t))))
                } else if let Some(j) = (0..3).find(|&j| sat_ticks[j] >= sat_limit.max(1)) {
                    Some((1, pol.saturation, format!("drive q{} at its torque limit {:.3} N·m for {:.3} s", j + 1, mot[j].tau_max, sat_ticks[j] as f64 * period)))
                } else if let (Some(cl), true) = (closest, d_min < pol.contact_margin) {
                    Some((
                        2,
                        pol.contact,
                        format!(
                            "{} within {:.4} m of obstacle {:?} at p_W = [{:.4}, {:.4}, {:.4}] m (margin {} m)",
                            part_names[part_link[cl.part]],
                            cl.distance,
                            world.names()[cl.obstacle],
                            cl.point_arm[0],
                            cl.point_arm[1],
                            cl.point_arm[2],
                            pol.contact_margin
                        ),
                    ))
                } else {
                    None
                };
                if let Some((kind, action, detail)) = raised {
                    if action == FaultAction::Continue {
                        // log the onset of each episode only
                        let onset = match kind {
                            0 => !wrinkled_prev,
                            1 => sat_ticks.iter().any(|&s| s == sat_limit.max(1)),
                            _ => events.last().map_or(true, |e| e.kind != "contact" || t - e.t > pol.clear_time),
                        };
                        if onset {
                            events.push(Event { t, kind: if kind == 2 { "contact" } else { "alarm" }, from: name_before.clone(), to: name_before.clone(), detail });
                        }
                    } else {
                        fault = Some(Fault { kind, action, q_hold: qe, k0: k, clear_ticks: 0 });
                        if action != FaultAction::Hold {
                            terminal = true;
                        }
                        events.push(Event { t, kind: if kind == 2 { "contact" } else { "fault" }, from: name_before.clone(), to: FAULT_NAMES[kind].into(), detail });
                    }
                }
                // guards
                if fault.is_none() && cur + 1 < phases.len() {
                    let ph = &phases[cur];
                    let el = phase_ticks as f64 * period;
                    let gd = &ph.until;
                    let r_now = reference(&ph.command, el, &q_start);
                    let settled = gd.settled.map_or(true, |tol| (0..3).all(|j| (r_now[j] - qe[j]).abs() < tol && ve[j].abs() < 10.0 * tol));
                    let still = gd.still.map_or(true, |tol| lpf_y.iter().all(|y| y.abs() < tol));
                    let at_target = match (gd.at_target, &ph.command) {
                        (Some(tol), Command::Cartesian { target }) => (rigid_tip(model, &qe).0 - Vec3::from(*target)).norm() < tol,
                        _ => true,
                    };
                    let fire = if el >= gd.min_time && settled && still && at_target {
                        Some(if gd.settled.is_some() || gd.still.is_some() || gd.at_target.is_some() { "guard holds" } else { "min_time elapsed" })
                    } else if el >= gd.max_time {
                        Some("timeout (max_time)")
                    } else {
                        None
                    };
                    if let Some(why) = fire {
                        cur += 1;
                        phase_ticks = 0;
                        q_start = qe;
                        events.push(Event { t, kind: if why.starts_with("timeout") { "timeout" } else { "transition" }, from: ph.name.clone(), to: phases[cur].name.clone(), detail: format!("{why} after {el:.4} s") });
                        if let Some(p) = enter(cur, t, &mut events, &mut payload_now, &mut pressure_now) {
                            pd = ParamData::new(model, &p)?;
                        }
                    }
                }
            }

            wrinkled_prev = wrinkled;

            // ---- references ----
            let ph = &phases[cur];
            let damp_on = match (&fault, ph.damping) {
                (_, Some(d)) => d,
                _ => c.damping,
            };
            let vel_cmd = match (&fault, &ph.command) {
                (None, Command::Velocity(s)) => Some(std::array::from_fn::<f64, 3, _>(|j| s[j].eval(phase_ticks as f64 * period))),
                _ => None,
            };
            let (r, cart) = match &fault {
                Some(f) if f.action == FaultAction::Retreat => {
                    let s = ((k - f.k0) as f64 * period).min(1.0);
                    let w = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
                    (std::array::from_fn(|j| f.q_hold[j] + (q_start[j] - f.q_hold[j]) * w), None)
                }
                Some(f) => (f.q_hold, None),
                None => match &ph.command {
                    Command::Cartesian { target } => (qe, Some(Vec3::from(*target))),
                    Command::Velocity(_) => (qe, None),
                    cmd => (reference(cmd, phase_ticks as f64 * period, &q_start), None),
                },
            };
            // ---- cascade ----
            let vstar: [f64; 3] = match (cart, vel_cmd) {
                (_, Some(vc)) => vc,
                (Some(p_t), None) => {
                    let (p, jc) = match c.cartesian_arm {
                        CartesianArm::Prbm => rigid_tip(model, &qe),
                        _ => {
                            let jr = rigid.jacobian(&qe);
                            (rigid.fk(&qe), std::array::from_fn(|k| Vec3::new(jr[(0, k)], jr[(1, k)], jr[(2, k)])))
                        }
                    };
                    let e = p_t - p;
                    std::array::from_fn(|j| (g.cart_k * jc[j].dot(&e)).clamp(-c.v_max, c.v_max))
                }
                (None, None) => std::array::from_fn(|j| {
                    let pi = Pi { kp: g.pos_kp[j], ki: if c.anti_windup && sat[j] { 0.0 } else { g.pos_ki[j] }, u_max: c.v_max };
                    pi.step(&mut ip[j], r[j] - qe[j], period).0
                }),
            };
            for j in 0..3 {
                let y = lpf.step(&mut lpf_y[j], sig[j]);
                let ud = if damp_on[j] {
                    Pid { kp: g.damp_kp[j], ki: g.damp_ki[j], kd: g.damp_kd[j] }.step(&mut pid[j], y, period)
                } else {
                    pid[j] = PidState { s: 0.0, y_prev: y };
                    0.0
                };
                let ev = vstar[j] - ud - ve[j];
                let umax = mot[j].tau_max / mot[j].torque_per_unit;
                let pi = Pi { kp: g.vel_kp[j], ki: g.vel_ki[j], u_max: umax };
                let (u, s) = if c.anti_windup {
                    pi.step(&mut iv[j], ev, period)
                } else {
                    let u = pi.kp * ev + iv[j];
                    iv[j] += pi.ki * period * ev;
                    let us = u.clamp(-umax, umax);
                    (us, us != u)
                };
                sat[j] = s;
                sat_ticks[j] = if s { sat_ticks[j] + 1 } else { 0 };
                let tcmd = mot[j].torque_per_unit * u;
                tau[j] += alpha[j] * (tcmd - tau[j]);
                out[j] = r[j];
                out[3 + j] = vstar[j] - ud;
                out[6 + j] = ud;
                out[9 + j] = y;
                out[12 + j] = tcmd;
            }
            out[15] = match &fault {
                Some(f) => -1.0 - f.kind as f64,
                None => cur as f64,
            };
            out[16] = d_min;
            drive = Drive::Hold(tau);
            if fault.is_none() {
                phase_ticks += 1;
            }
        }
        let mut flow = if k % crate::limits::POLL_EVERY_STEPS == crate::limits::POLL_EVERY_STEPS - 1 { sink.poll() } else { Flow::Go };
        while emitted < events.len() {
            flow = either(flow, sink.event(&events[emitted])?);
            emitted += 1;
        }
        if k % every == 0 {
            flow = either(flow, sink.state(&StateView { t: st.t, q: &st.q, v: &st.v, pd: &pd, ratio: ratio_now })?);
            sample(model, &pd, &drive, st.t, &st.q, &st.v, None, &mut row);
            flow = either(flow, line.push(&row, Some(&out), sink)?);
            nsample += 1;
        }
        if flow == Flow::Stop && k < nstep {
            let e = Event { t: st.t, kind: "interrupted", from: phase_name(cur, &fault), to: "Stopped".into(), detail: "run stopped by its sink (interrupt)".into() };
            sink.event(&e)?;
            events.push(e);
            status = Status::Interrupted;
            break;
        }
        if k == nstep {
            break;
        }
        let t = st.t;
        step_with(model, &pd, &drive, t, dt, &mut st.q, &mut st.v, &mut ws);
        st.t = t0 + (k + 1) as f64 * dt;
        if let Some(e) = diverged(model, k, t, &st.q, &st.v) {
            let from = phase_name(cur, &fault);
            let e = Event { t: st.t, kind: "fault", from, to: "Unstable".into(), detail: e.to_string() };
            sink.event(&e)?;
            events.push(e);
            status = Status::Unstable;
            break;
        }
        let (_, rt) = bending_moments(model, &pd, st.t, &st.q, &st.v, &locked_moments_at(model, &pd, &drive, st.t, &st.q, &st.v));
        ratio_now = rt;
        let before = open;
        track_alarms(&mut open, &mut alarms, st.t, rt);
        alarm_events(before, open, &alarms, st.t, sink)?;
        k += 1;
    }
    line.finish(sink)?;
    Ok(RunEnd { nsample, nsample_full, alarms, final_state: st, warnings: pd.warnings.clone(), events, status })
}

fn pd_gap(p: &Params) -> bool {
    p.effects.backlash.gap != [0.0; 3]
}

/// Position reference of a joint-space command at `el` seconds into the phase [rad].
fn reference(cmd: &Command, el: f64, q_start: &[f64; 3]) -> [f64; 3] {
    match cmd {
        Command::Hold | Command::Cartesian { .. } | Command::Velocity(_) => *q_start,
        Command::Track(s) => std::array::from_fn(|j| s[j].eval(el)),
        Command::MoveTo { q, duration } => {
            let s = (el / duration).clamp(0.0, 1.0);
            let w = s * s * s * (10.0 + s * (-15.0 + 6.0 * s));
            std::array::from_fn(|j| q_start[j] + (q[j] - q_start[j]) * w)
        }
    }
}

/// Run a batch of closed-loop jobs on `threads` threads (0 = all cores); results in job
/// order, bit-identical for any thread count.
pub fn rollout_closed(model: &Model, jobs: &[(Params, ClosedLoop)], threads: usize) -> Vec<Result<ClosedTrajectory>> {
    rollout_closed_until(model, jobs, threads, &std::sync::atomic::AtomicBool::new(false))
}

/// [`rollout_closed`] that stops once `stop` is raised (runs end `Interrupted`).
pub fn rollout_closed_until(model: &Model, jobs: &[(Params, ClosedLoop)], threads: usize, stop: &std::sync::atomic::AtomicBool) -> Vec<Result<ClosedTrajectory>> {
    crate::rollout::par_map(jobs, threads, |(p, c)| run_closed_loop_until(model, p, c, stop))
}
