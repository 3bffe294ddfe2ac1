//! Scenario files: one TOML file describing a headless run (`docs/logging.md`, "Scenario
//! files"): the arm and its parameters, the controller and its task (the control file
//! format of [`crate::control::config`]), the effects, the sensor noise, the run's timing
//! and what to log. `popup run`, `popup sweep` and `popup check` read it.
//!
//! [`Scenario::parse`] reports every problem at once, each with the file, the line of the
//! key (or of its table header) and the key path ([`Problem`]). Defaults: `arm =
//! "popup-lab"`, payload and pressures the arm's, `gravity = true`, `q0 = [0, 0, 0]` rad,
//! `dt` = the controller period, `integrator = "rk4"`, `sample_rate_hz = 100`, `seed = 0`,
//! no noise, the [`LogSettings`] defaults, and without `[[phases]]` one phase holding `q0`
//! for the whole run. `duration_s` is required.
//!
//! [`set_key`] and [`parse_values`] serve `popup sweep --param KEY=VALUES`.

use crate::control::closed_loop::rigid_equivalent;
use crate::control::config::{hold_phase, join, read_control, segments, Doc, Seg, Val, CONTROL_KEYS};
use crate::control::{ClosedLoop, Command, ControllerSpec};
use crate::effects::{Effects, EFFECT_NAMES};
use crate::error::Error;
use crate::math::Vec3;
use crate::model::{Disable, Integrator, Model, Options};
use crate::params::{ParamData, Params};
use crate::sim::{check_step, rest_state};
use crate::spec::arm::ArmSpec;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};
use toml::de::{DeTable, DeValue};

pub use crate::control::config::Problem;
pub use crate::stream::Noise;

/// The `format` value of a scenario file.
pub const SCENARIO_FORMAT: &str = "popup-scenario/1";

/// The topics a log may carry (`[log] topics`); `/tf` is always written.
pub const TOPICS: [&str; 10] = ["joints", "imu", "end_effector", "pressure", "bending", "reference", "control", "events", "scene", "log"];

/// Top-level keys of a scenario besides the control tables ([`CONTROL_KEYS`]).
const SCENARIO_KEYS: [&str; 15] =
    ["format", "description", "arm", "payload_kg", "pressure_pa", "gravity", "q0", "duration_s", "dt", "integrator", "sample_rate_hz", "seed", "effects", "noise", "log"];

/// Keys of `[noise]` (standard deviations, in the units of their names).
const NOISE_KEYS: [&str; 4] = ["encoder_rad", "imu_m_s2", "torque_nm", "mocap_m"];

/// Keys of `[log]`.
const LOG_KEYS: [&str; 5] = ["viz_rate_hz", "flush_every_s", "compression", "chunk_size_bytes", "topics"];

/// Keys whose value is an integer (written as one by [`set_key`]).
const INTEGER_KEYS: [&str; 3] = ["seed", "chunk_size_bytes", "encoder_counts"];

/// Chunk compression of the MCAP log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// Zstandard (default).
    #[default]
    Zstd,
    /// LZ4.
    Lz4,
    /// None.
    None,
}

impl Compression {
    /// The name in a scenario file.
    pub fn name(self) -> &'static str {
        match self {
            Compression::Zstd => "zstd",
            Compression::Lz4 => "lz4",
            Compression::None => "none",
        }
    }

    /// Parse `"zstd"`, `"lz4"` or `"none"`.
    pub fn parse(s: &str) -> Option<Compression> {
        [Compression::Zstd, Compression::Lz4, Compression::None].into_iter().find(|c| c.name() == s)
    }
}

/// What the log writer writes, and how often it flushes.
#[derive(Debug, Clone, PartialEq)]
pub struct LogSettings {
    /// Rate of `/tf` and `/scene` [Hz] (at most the sample rate). Default 30 Hz, or the sample
    /// rate when that is lower.
    pub viz_rate_hz: f64,
    /// Simulated time between flushes [s]. Default 1 s.
    pub flush_every_s: f64,
    /// Chunk compression. Default zstd.
    pub compression: Compression,
    /// Chunk size [bytes]. Default 1 MiB.
    pub chunk_size_bytes: u64,
    /// Topics written (names of [`TOPICS`], in the file's order). Default all.
    pub topics: Vec<String>,
}

impl Default for LogSettings {
    fn default() -> Self {
        LogSettings { viz_rate_hz: 30.0, flush_every_s: 1.0, compression: Compression::Zstd, chunk_size_bytes: 1 << 20, topics: TOPICS.iter().map(|t| t.to_string()).collect() }
    }
}

/// A parsed and validated scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// File name for messages.
    pub source: String,
    /// The complete TOML text as read.
    pub text: String,
    /// Free text.
    pub description: String,
    /// The arm: the built-in one named, or the arm file (relative to the scenario's folder),
    /// with the scenario's `[effects.*]` tables merged into its effects (so structural
    /// effects reach [`Model::compile`]).
    pub arm: ArmSpec,
    /// `arm` as written in the file.
    pub arm_name: String,
    /// The arm file's path (the scenario's folder joined with `arm_name`); `None` for a
    /// built-in arm.
    pub arm_file: Option<PathBuf>,
    /// Physics step [s] (default the controller period), integrator, gravity (`gravity =
    /// false` sets `disable.gravity`, as Python's `Model(gravity=False)`).
    pub options: Options,
    /// Initial payload [kg], pressures [Pa] and effects (the arm's, overridden by the
    /// scenario's `[effects.*]`).
    pub params: Params,
    /// The closed-loop run: controller, task, obstacles, `q0` [rad], duration [s], sample
    /// period [s] = 1/`sample_rate_hz`.
    pub closed: ClosedLoop,
    /// Sensor noise (standard deviations).
    pub noise: Noise,
    /// Log settings.
    pub log: LogSettings,
    /// Seed of the sensor noise.
    pub seed: u64,
}

/// The top-level values of a scenario (before defaults that depend on other parts).
#[derive(Debug, Clone)]
struct Head {
    description: String,
    arm_name: String,
    payload_kg: Option<f64>,
    pressure_pa: Option<[f64; 2]>,
    gravity: bool,
    q0: [f64; 3],
    duration: f64,
    dt: Option<f64>,
    integrator: Integrator,
    sample_rate_hz: f64,
    seed: u64,
}

/// Top-level entry `key` read as `T`: (line of the key, value).
fn get<T: DeserializeOwned>(doc: &Doc<'_>, key: &str, out: &mut Vec<Problem>) -> Option<(usize, T)> {
    let (line, v) = doc.entry(doc.root(), key)?;
    doc.value::<T>(key, v, out).map(|x| (line, x))
}

/// Top-level number `key`, which must satisfy `ok` (described by `need`).
fn number(doc: &Doc<'_>, key: &str, ok: fn(f64) -> bool, need: &str, out: &mut Vec<Problem>) -> Option<f64> {
    let (line, x) = get::<f64>(doc, key, out)?;
    if ok(x) {
        Some(x)
    } else {
        out.push(doc.problem(key, line, format!("invalid value {x}: {need}")));
        None
    }
}

fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

fn non_negative(x: f64) -> bool {
    x.is_finite() && x >= 0.0
}

/// An array of `n` numbers at `key` (a single number for every element when `broadcast`),
/// each satisfying `ok`; problems name the element.
fn numbers(doc: &Doc<'_>, key: &str, n: usize, broadcast: bool, ok: fn(f64) -> bool, need: &str, out: &mut Vec<Problem>) -> Option<Vec<f64>> {
    let (line, v) = doc.entry(doc.root(), key)?;
    let xs = match v.get_ref() {
        DeValue::Array(_) => doc.value::<Vec<f64>>(key, v, out)?,
        _ if broadcast => vec![doc.value::<f64>(key, v, out)?; n],
        _ => {
            out.push(doc.problem(key, line, format!("must be an array of {n} numbers")));
            return None;
        }
    };
    if xs.len() != n {
        out.push(doc.problem(key, line, format!("needs {n} values, got {}", xs.len())));
        return None;
    }
    let n0 = out.len();
    for (i, &x) in xs.iter().enumerate() {
        if !ok(x) {
            let k = format!("{key}[{i}]");
            let l = doc.locate(&k).0.map_or(line, |e| doc.line_at(e.span().start));
            out.push(doc.problem(&k, l, format!("invalid value {x}: {need}")));
        }
    }
    (out.len() == n0).then_some(xs)
}

/// The top-level values.
fn read_head(doc: &Doc<'_>, out: &mut Vec<Problem>) -> Head {
    if let Some((line, f)) = get::<String>(doc, "format", out) {
        if f != SCENARIO_FORMAT {
            out.push(doc.problem("format", line, format!("unsupported format {f:?}; this version reads {SCENARIO_FORMAT:?}")));
        }
    }
    let integrator = match get::<String>(doc, "integrator", out) {
        Some((line, s)) => Integrator::parse(&s).unwrap_or_else(|e| {
            doc.error("integrator", line, &e, out);
            Integrator::Rk4
        }),
        None => Integrator::Rk4,
    };
    if doc.entry(doc.root(), "duration_s").is_none() {
        out.push(doc.problem("duration_s", 0, "missing: the simulated time of the run [s] is required"));
    }
    let q0 = numbers(doc, "q0", 3, false, f64::is_finite, "must be finite [rad]", out);
    let pressure = numbers(doc, "pressure_pa", 2, true, non_negative, "must be finite and >= 0 Pa (relative pressure)", out);
    Head {
        description: get::<String>(doc, "description", out).map(|x| x.1).unwrap_or_default(),
        arm_name: get::<String>(doc, "arm", out).map_or_else(|| "popup-lab".to_string(), |x| x.1),
        payload_kg: number(doc, "payload_kg", non_negative, "must be finite and >= 0 kg", out),
        pressure_pa: pressure.map(|p| [p[0], p[1]]),
        gravity: get::<bool>(doc, "gravity", out).map_or(true, |x| x.1),
        q0: q0.map_or([0.0; 3], |q| [q[0], q[1], q[2]]),
        duration: number(doc, "duration_s", positive, "must be finite and > 0 s", out).unwrap_or(1.0),
        dt: number(doc, "dt", positive, "must be finite and > 0 s", out),
        integrator,
        sample_rate_hz: number(doc, "sample_rate_hz", positive, "must be finite and > 0 Hz", out).unwrap_or(100.0),
        seed: get::<u64>(doc, "seed", out).map_or(0, |x| x.1),
    }
}

/// The arm named `name`: a built-in (or packaged) arm, or an arm file relative to
/// `base_dir` ([`ArmSpec::resolve`], the one resolution of every front end).
fn load_arm(name: &str, base_dir: &Path) -> std::result::Result<(ArmSpec, Option<PathBuf>), String> {
    ArmSpec::resolve(name, base_dir).map_err(|e| match e {
        crate::Error::UnknownArm { .. } => {
            format!("{name:?} is neither a built-in arm ({}) nor an arm file (no file {})", ArmSpec::BUILTIN.join(", "), base_dir.join(name).display())
        }
        e => e.to_string(),
    })
}

/// An array of numbers, or one number for all `n` elements.
fn numbers_or_one(doc: &Doc<'_>, key: &str, v: &Val<'_>, n: usize, out: &mut Vec<Problem>) -> Option<Vec<f64>> {
    match v.get_ref() {
        DeValue::Array(_) => doc.value::<Vec<f64>>(key, v, out),
        _ => doc.value::<f64>(key, v, out).map(|x| vec![x; n]),
    }
}

/// One `[effects.<name>]` table merged over the arm's values of that effect, each parameter
/// checked for shape (one number sets every element of a per-joint or per-link
/// parameter); then the effect is validated on its own. `None` on a problem.
fn merge_effect(doc: &Doc<'_>, name: &str, v: &Val<'_>, arm: &toml::Table, out: &mut Vec<Problem>) -> Option<toml::Table> {
    let path = format!("effects.{name}");
    let t = doc.table(&path, v, out)?;
    let mut sub = arm.get(name).and_then(toml::Value::as_table).cloned().unwrap_or_default();
    let known: Vec<&str> = sub.keys().map(String::as_str).collect();
    doc.check_keys(&path, t, &known, out);
    let n0 = out.len();
    for (k, kv) in t.iter() {
        let key = join(&path, k.get_ref());
        let new = match sub.get(k.get_ref().as_ref()) {
            Some(toml::Value::Array(a)) => match numbers_or_one(doc, &key, kv, a.len(), out) {
                Some(xs) if xs.len() == a.len() => toml::Value::Array(xs.into_iter().map(toml::Value::Float).collect()),
                Some(xs) => {
                    out.push(doc.problem(&key, doc.line_at(k.span().start), format!("needs {} values, got {}", a.len(), xs.len())));
                    continue;
                }
                None => continue,
            },
            Some(_) => match doc.value::<f64>(&key, kv, out) {
                Some(x) => toml::Value::Float(x),
                None => continue,
            },
            None => continue,
        };
        sub.insert(k.get_ref().to_string(), new);
    }
    if out.len() > n0 {
        return None;
    }
    let one = toml::Table::from_iter([(name.to_string(), toml::Value::Table(sub.clone()))]);
    let line = doc.locate(&path).1;
    match toml::Value::Table(one).try_into::<Effects>().map(|e| e.validate()) {
        Ok(Ok(())) => Some(sub),
        Ok(Err(err)) => {
            doc.error(&path, line, &err, out);
            None
        }
        Err(err) => {
            out.push(doc.problem(&path, line, err.to_string()));
            None
        }
    }
}

/// The arm's effects with the scenario's `[effects.*]` tables merged in.
fn read_effects(doc: &Doc<'_>, arm: &ArmSpec, out: &mut Vec<Problem>) -> Effects {
    let Some(t) = doc.entry(doc.root(), "effects").and_then(|(_, v)| doc.table("effects", v, out)) else { return arm.effects };
    doc.check_keys("effects", t, &EFFECT_NAMES, out);
    let Ok(mut merged) = toml::Table::try_from(arm.effects) else { return arm.effects };
    let base = merged.clone();
    for (k, v) in t.iter() {
        let name = k.get_ref().as_ref();
        if !EFFECT_NAMES.contains(&name) {
            continue;
        }
        if let Some(sub) = merge_effect(doc, name, v, &base, out) {
            merged.insert(name.to_string(), toml::Value::Table(sub));
        }
    }
    toml::Value::Table(merged).try_into().unwrap_or(arm.effects)
}

/// `[noise]`: standard deviations, finite and >= 0.
fn read_noise(doc: &Doc<'_>, out: &mut Vec<Problem>) -> Noise {
    let mut noise = Noise::default();
    let Some(t) = doc.entry(doc.root(), "noise").and_then(|(_, v)| doc.table("noise", v, out)) else { return noise };
    doc.check_keys("noise", t, &NOISE_KEYS, out);
    let slots = [&mut noise.encoder_rad, &mut noise.imu_m_s2, &mut noise.torque_nm, &mut noise.mocap_m];
    for (name, slot) in NOISE_KEYS.iter().zip(slots) {
        let key = format!("noise.{name}");
        let Some((line, v)) = doc.entry(t, name) else { continue };
        match doc.value::<f64>(&key, v, out) {
            Some(x) if non_negative(x) => *slot = x,
            Some(x) => out.push(doc.problem(&key, line, format!("invalid value {x}: a standard deviation must be finite and >= 0"))),
            None => {}
        }
    }
    noise
}

/// `[log] topics`: names of [`TOPICS`]; each unknown one is a problem.
fn read_topics(doc: &Doc<'_>, t: &DeTable<'_>, out: &mut Vec<Problem>) -> Option<Vec<String>> {
    let (_, v) = doc.entry(t, "topics")?;
    let topics = doc.value::<Vec<String>>("log.topics", v, out)?;
    let n0 = out.len();
    for (i, name) in topics.iter().enumerate() {
        if !TOPICS.contains(&name.as_str()) {
            let key = format!("log.topics[{i}]");
            let line = doc.locate(&key).1;
            out.push(doc.problem(&key, line, format!("unknown topic {name:?}; known: {}", TOPICS.join(", "))));
        }
    }
    (out.len() == n0).then_some(topics)
}

/// `[log]`. `viz_rate_hz` defaults to min(30 Hz, `sample_rate_hz`).
fn read_log(doc: &Doc<'_>, sample_rate_hz: f64, out: &mut Vec<Problem>) -> LogSettings {
    let mut log = LogSettings { viz_rate_hz: LogSettings::default().viz_rate_hz.min(sample_rate_hz), ..LogSettings::default() };
    let Some(t) = doc.entry(doc.root(), "log").and_then(|(_, v)| doc.table("log", v, out)) else { return log };
    doc.check_keys("log", t, &LOG_KEYS, out);
    let num = |name: &str, out: &mut Vec<Problem>| -> Option<(usize, f64)> {
        let (line, v) = doc.entry(t, name)?;
        doc.value::<f64>(&format!("log.{name}"), v, out).map(|x| (line, x))
    };
    if let Some((line, x)) = num("viz_rate_hz", out) {
        if !positive(x) {
            out.push(doc.problem("log.viz_rate_hz", line, format!("invalid value {x}: must be finite and > 0 Hz")));
        } else if x > sample_rate_hz {
            out.push(doc.problem("log.viz_rate_hz", line, format!("{x} Hz is above the sample rate sample_rate_hz = {sample_rate_hz} Hz")));
        } else {
            log.viz_rate_hz = x;
        }
    }
    if let Some((line, x)) = num("flush_every_s", out) {
        if positive(x) {
            log.flush_every_s = x;
        } else {
            out.push(doc.problem("log.flush_every_s", line, format!("invalid value {x}: must be finite and > 0 s")));
        }
    }
    if let Some((line, v)) = doc.entry(t, "compression") {
        if let Some(s) = doc.value::<String>("log.compression", v, out) {
            match Compression::parse(&s) {
                Some(c) => log.compression = c,
                None => out.push(doc.problem("log.compression", line, format!("unknown compression {s:?}; known: zstd, lz4, none"))),
            }
        }
    }
    if let Some((line, v)) = doc.entry(t, "chunk_size_bytes") {
        match doc.value::<u64>("log.chunk_size_bytes", v, out) {
            Some(0) => out.push(doc.problem("log.chunk_size_bytes", line, "must be > 0 bytes")),
            Some(n) => log.chunk_size_bytes = n,
            None => {}
        }
    }
    if let Some(topics) = read_topics(doc, t, out) {
        log.topics = topics;
    }
    log
}

/// Whether `period` is a whole multiple (>= 1) of `dt` (within 1e-9 relative).
fn whole_multiple(period: f64, dt: f64) -> bool {
    let n = (period / dt).round();
    n >= 1.0 && (n * dt - period).abs() <= 1e-9 * period
}

/// The timing checks: controller period and sample period whole multiples of dt. Returns dt.
fn check_timing(doc: &Doc<'_>, head: &Head, c: &ControllerSpec, out: &mut Vec<Problem>) -> f64 {
    let period = c.period();
    let rate_ok = positive(c.rate_hz);
    let dt = head.dt.unwrap_or(if rate_ok { period } else { 1e-4 });
    let line = |k: &str| doc.entry(doc.root(), k).map_or(0, |e| e.0);
    if rate_ok && head.dt.is_some() && !whole_multiple(period, dt) {
        let (key, l) = match doc.locate("controller.rate_hz") {
            (Some(_), l) => ("controller.rate_hz", l),
            _ => ("dt", line("dt")),
        };
        out.push(doc.problem(key, l, format!("the controller period T = {period:e} s (controller.rate_hz = {}) must be a whole multiple of the physics step dt = {dt:e} s", c.rate_hz)));
    }
    let ts = 1.0 / head.sample_rate_hz;
    if !whole_multiple(ts, dt) {
        let l = if line("sample_rate_hz") > 0 { line("sample_rate_hz") } else { line("dt") };
        out.push(doc.problem("sample_rate_hz", l, format!("the sample period {ts:e} s (1/{} Hz) must be a whole multiple of dt = {dt:e} s", head.sample_rate_hz)));
    }
    dt
}

/// The parameters derived for the model (payload, pressures and effects checked together);
/// `None` on a problem.
fn check_params(doc: &Doc<'_>, model: &Model, params: &Params, out: &mut Vec<Problem>) -> Option<ParamData> {
    if params.effects.backlash.gap != [0.0; 3] {
        let line = doc.locate("effects.backlash.gap").1;
        out.push(doc.problem("effects.backlash.gap", line, "backlash needs encoder replay: a closed-loop scenario cannot use it in this version"));
    }
    match ParamData::new(model, params) {
        Ok(pd) => Some(pd),
        Err(e) => {
            let top = error_root(&e);
            doc.error(&top, doc.locate(&top).1, &e, out);
            None
        }
    }
}

/// The first step of the key path an error names (`payload_kg`, `effects`, ...).
fn error_root(e: &Error) -> String {
    match e {
        Error::InvalidParameter { what, .. } | Error::Input { what, .. } => what.split(['.', '[', ' ']).next().unwrap_or("").to_string(),
        _ => String::new(),
    }
}

/// The start of the run: the rest state at `q0` exists and `dt` is stable for the
/// linearised arm there (what the run checks first).
fn check_start(doc: &Doc<'_>, model: &Model, pd: &ParamData, closed: &ClosedLoop, out: &mut Vec<Problem>) {
    let line = |k: &str| doc.entry(doc.root(), k).map_or(0, |e| e.0);
    match rest_state(model, pd, 0.0, closed.q0) {
        Err(e) => out.push(doc.problem("q0", line("q0"), format!("no rest state at q0: {e}"))),
        Ok(st) => {
            if let Err(e) = check_step(model, pd, &st.q, false) {
                let (key, l) = if line("dt") > 0 { ("dt", line("dt")) } else { ("controller.rate_hz", doc.locate("controller.rate_hz").1) };
                out.push(doc.problem(key, l, e.to_string()));
            }
        }
    }
}

/// Every Cartesian target inside the rigid workspace of the model's chain.
fn check_targets(doc: &Doc<'_>, model: &Model, closed: &ClosedLoop, out: &mut Vec<Problem>) {
    let Ok(rigid) = rigid_equivalent(model) else { return };
    for (i, ph) in closed.sequence.phases.iter().enumerate() {
        if let Command::Cartesian { target } = ph.command {
            if let Err(e) = rigid.in_workspace(&Vec3::from(target)) {
                let key = format!("phases[{i}].cartesian.target");
                let line = doc.locate(&key).1;
                out.push(doc.problem(&key, line, format!("phases[{i}] ({}): {e}", ph.name)));
            }
        }
    }
}

/// The checks that need the compiled model: parameters, the start of the run (rest state,
/// stable step), Cartesian targets inside the workspace.
fn check_with_model(doc: &Doc<'_>, model: &Model, params: &Params, closed: &ClosedLoop, out: &mut Vec<Problem>) {
    if let Some(pd) = check_params(doc, model, params, out) {
        check_start(doc, model, &pd, closed, out);
    }
    check_targets(doc, model, closed, out);
}

impl Scenario {
    /// Parse and validate a scenario. `source` names the file in problems; an arm file path
    /// is relative to `base_dir`.
    ///
    /// # Errors
    /// Every problem found (a TOML syntax error is the only one reported alone), sorted by
    /// line.
    pub fn parse(text: &str, source: &str, base_dir: &Path) -> std::result::Result<Scenario, Vec<Problem>> {
        let doc = Doc::parse(text, source).map_err(|p| vec![p])?;
        let mut out = Vec::new();
        let known: Vec<&str> = SCENARIO_KEYS.iter().chain(CONTROL_KEYS.iter()).copied().collect();
        doc.check_keys("", doc.root(), &known, &mut out);
        let head = read_head(&doc, &mut out);
        let arm_line = doc.entry(doc.root(), "arm").map_or(0, |e| e.0);
        let (mut arm, arm_file, arm_ok) = match load_arm(&head.arm_name, base_dir) {
            Ok((a, f)) => (a, f, true),
            Err(m) => {
                out.push(doc.problem("arm", arm_line, m));
                (ArmSpec::popup_lab(), None, false)
            }
        };
        arm.effects = read_effects(&doc, &arm, &mut out);
        let noise = read_noise(&doc, &mut out);
        let log = read_log(&doc, head.sample_rate_hz, &mut out);
        let control = read_control(&arm, &doc, &mut out);
        let dt = check_timing(&doc, &head, &control.controller, &mut out);
        let options = Options { dt, integrator: head.integrator, gravity: None, disable: Disable { gravity: !head.gravity, ..Disable::default() }, ..Options::default() };
        let params = Params {
            payload_kg: head.payload_kg.unwrap_or(arm.payload.default_kg),
            pressure_pa: head.pressure_pa.unwrap_or([arm.links[0].pressure_pa, arm.links[1].pressure_pa]),
            effects: arm.effects,
        };
        let closed = closed_loop(control, &head);
        if out.is_empty() && arm_ok {
            match Model::compile(&arm, options) {
                Ok(model) => check_with_model(&doc, &model, &params, &closed, &mut out),
                Err(e) => doc.error("arm", arm_line, &e, &mut out),
            }
        }
        if !out.is_empty() {
            out.sort_by_key(|p| p.line);
            return Err(out);
        }
        Ok(Scenario {
            source: source.to_string(),
            text: text.to_string(),
            description: head.description,
            arm,
            arm_name: head.arm_name,
            arm_file,
            options,
            params,
            closed,
            noise,
            log,
            seed: head.seed,
        })
    }

    /// Read and parse a scenario file (arm files relative to its folder).
    ///
    /// # Errors
    /// As [`Scenario::parse`]; an unreadable file is one problem.
    pub fn read(path: &Path) -> std::result::Result<Scenario, Vec<Problem>> {
        let source = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| vec![Problem { file: source.clone(), line: 0, key: String::new(), message: format!("cannot read the scenario: {e}") }])?;
        Scenario::parse(&text, &source, path.parent().unwrap_or(Path::new(".")))
    }

    /// The compiled model of the scenario's arm and options.
    ///
    /// # Errors
    /// As [`Model::compile`] (cannot happen for a scenario that parsed).
    pub fn model(&self) -> crate::Result<Model> {
        Model::compile(&self.arm, self.options)
    }

    /// What the scenario can already tell will produce non-finite outputs: a link at zero
    /// pressure has a zero wrinkling moment M_w, so its `m*_ratio` (|M|/M_w) channel is
    /// infinite (left out of the log, counted in `nonfinite_dropped`).
    pub fn nonfinite_warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        let mut check = |where_: &str, p: [f64; 2]| {
            for (l, &v) in p.iter().enumerate() {
                if v == 0.0 {
                    out.push(format!(
                        "{where_} pressure_pa[{l}] (link {}) = 0 Pa: the wrinkling moment M_w of link {} is 0, so m{}_ratio = |M|/M_w is infinite and will be left out of the log (the other channels are kept); use a pressure > 0 unless the deflated link is intended",
                        l + 1,
                        l + 1,
                        l + 1
                    ));
                }
            }
        };
        check("initial", self.params.pressure_pa);
        for (i, ph) in self.closed.sequence.phases.iter().enumerate() {
            if let Some(p) = ph.pressure_pa {
                check(&format!("phases[{i}] ({})", ph.name), p);
            }
        }
        out
    }

    /// The run as a measured-run `experiment.toml` (`shared/spec/measured-run.md`):
    /// `format = "popup-run/1"`, the arm (its name, or the arm file's path), the initial
    /// payload and pressures, gravity, `replay = "reference"`, the description and the
    /// scenario's `[controller]` table as written (an empty table for the defaults).
    pub fn experiment_toml(&self) -> String {
        let s = |x: &str| toml::Value::String(x.to_string()).to_string();
        // an absolute path: a log is read from another folder than the scenario's
        let arm = self.arm_file.as_ref().map_or_else(|| self.arm_name.clone(), |p| std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()).display().to_string());
        let p = self.params.pressure_pa;
        let mut out = format!(
            "format = \"popup-run/1\"\narm = {}\npayload_kg = {}\npressure_pa = [{}, {}]\ngravity = {}\nreplay = \"reference\"\ndescription = {}\n\n",
            s(&arm),
            num(self.params.payload_kg),
            num(p[0]),
            num(p[1]),
            !self.options.disable.gravity,
            s(&self.description)
        );
        let controller = toml::from_str::<toml::Table>(&self.text).ok().and_then(|mut t| t.remove("controller")).and_then(|c| c.as_table().cloned()).unwrap_or_default();
        let wrapped = toml::Table::from_iter([("controller".to_string(), toml::Value::Table(controller))]);
        out.push_str(&toml::to_string(&wrapped).unwrap_or_else(|_| "[controller]\n".into()));
        out
    }
}

/// The closed-loop run of a scenario: its control file parts, `q0`, duration and sample
/// period; without phases one phase holds `q0` for the whole run.
fn closed_loop(c: crate::control::config::ControlFile, head: &Head) -> ClosedLoop {
    let mut sequence = c.sequence;
    if sequence.phases.is_empty() {
        sequence.phases.push(hold_phase("Holding"));
    }
    ClosedLoop {
        controller: c.controller,
        sequence,
        obstacles: c.obstacles,
        payload_radius: c.payload_radius,
        q0: head.q0,
        initial: None,
        duration: head.duration,
        sample_period: 1.0 / head.sample_rate_hz,
        check_step: true,
    }
}

/// A number as a TOML float (`inf`, `nan` included).
fn num(x: f64) -> String {
    toml::Value::Float(x).to_string()
}

// ---------------------------------------------------------------------------------------
// set_key

/// Where a new key can be written: a table the text defines explicitly.
#[derive(Debug, Clone, Copy)]
enum Anchor {
    /// The top level (before the first table header).
    Root,
    /// A `[table]` or `[[array]]` header ending at this byte.
    Header(usize),
    /// An inline table `{ ... }` spanning these bytes.
    Inline(usize, usize),
}

/// The anchor a table value `v` provides, if it is written explicitly.
fn anchor_of(text: &str, v: &Val<'_>) -> Option<Anchor> {
    let s = v.span();
    let src = text.get(s.clone()).unwrap_or("");
    match v.get_ref() {
        DeValue::Table(_) if src.starts_with('[') => Some(Anchor::Header(s.end)),
        DeValue::Table(_) if src.starts_with('{') => Some(Anchor::Inline(s.start, s.end)),
        _ => None,
    }
}

/// Byte offset of the first table header at the top level of the text (or its length).
fn first_header(text: &str, t: &DeTable<'_>) -> usize {
    let mut first = text.len();
    for (k, v) in t.iter() {
        let at = match v.get_ref() {
            DeValue::Table(sub) => match anchor_of(text, v) {
                Some(Anchor::Header(_)) => v.span().start,
                Some(_) => continue,
                None if v.span() == k.span() => first_header(text, sub),
                None => continue,
            },
            DeValue::Array(a) => match a.first() {
                Some(e) if text.get(e.span()).is_some_and(|s| s.starts_with("[[")) => e.span().start,
                _ => continue,
            },
            _ => continue,
        };
        first = first.min(at);
    }
    first
}

/// End of the last key/value written at the top level before byte `limit`.
fn last_root_value(t: &DeTable<'_>, limit: usize) -> Option<usize> {
    t.iter()
        .filter(|(k, _)| k.span().start < limit)
        .map(|(k, v)| match v.get_ref() {
            // a table made by dotted keys (`a.b = 1`): its last value
            DeValue::Table(sub) if v.span() == k.span() => last_root_value(sub, limit).unwrap_or(v.span().end),
            _ => v.span().end,
        })
        .filter(|&e| e <= limit)
        .max()
}

/// Offset just after the line containing byte `at`.
fn after_line(text: &str, at: usize) -> usize {
    text[at..].find('\n').map_or(text.len(), |i| at + i + 1)
}

/// Insert `pair` (`key = value`) into the table at `anchor`.
fn insert_at(text: &str, root: &DeTable<'_>, anchor: Anchor, pair: &str) -> String {
    let (pos, piece) = match anchor {
        Anchor::Root => {
            let limit = first_header(text, root);
            match last_root_value(root, limit) {
                Some(end) => (after_line(text, end), format!("{pair}\n")),
                None => (text[..limit].rfind('\n').map_or(0, |i| i + 1).min(limit), format!("{pair}\n")),
            }
        }
        Anchor::Header(end) => (after_line(text, end), format!("{pair}\n")),
        Anchor::Inline(start, end) => {
            let close = end - 1;
            let body = text[start + 1..close].trim_end();
            let pos = start + 1 + body.len();
            (pos, if body.trim().is_empty() { format!(" {pair}") } else { format!(", {pair}") })
        }
    };
    let mut s = String::with_capacity(text.len() + piece.len() + 1);
    s.push_str(&text[..pos]);
    if pos == text.len() && !text.is_empty() && !text.ends_with('\n') {
        s.push('\n');
    }
    s.push_str(&piece);
    s.push_str(&text[pos..]);
    s
}

/// The text of number `value` for the value it replaces (an integer literal stays an
/// integer when `value` is whole).
fn literal(value: f64, integer: bool) -> String {
    if integer && value.fract() == 0.0 && value.abs() < 9.0e15 {
        format!("{}", value as i64)
    } else {
        num(value)
    }
}

/// The byte ranges to overwrite with the number when setting existing value `v` at `path`.
fn targets(path: &str, v: &Val<'_>) -> std::result::Result<Vec<(std::ops::Range<usize>, bool)>, String> {
    let is_num = |v: &Val<'_>| matches!(v.get_ref(), DeValue::Integer(_) | DeValue::Float(_));
    match v.get_ref() {
        DeValue::Integer(_) => Ok(vec![(v.span(), true)]),
        DeValue::Float(_) => Ok(vec![(v.span(), false)]),
        DeValue::Array(a) if !a.is_empty() && a.iter().all(is_num) => Ok(a.iter().map(|e| (e.span(), matches!(e.get_ref(), DeValue::Integer(_)))).collect()),
        other => Err(format!("{path} is {}, not a number or an array of numbers", other.type_str())),
    }
}

/// Set the key at `path` (`payload_kg`, `pressure_pa` (a number sets every element of an
/// array), `pressure_pa[1]`, `controller.gains.vel_kp`, `effects.joint_friction.tau_c`) in
/// the scenario text to `value` and return the new text. Everything else in the text,
/// comments included, is kept. A missing key is added to the deepest table the text
/// writes explicitly (as a dotted key when tables in between are missing).
///
/// # Errors
/// A TOML syntax error, a malformed path, a path through something that is not a table
/// (or an index into something that is not an array, or past its end), or an existing
/// value that is not a number or an array of numbers.
pub fn set_key(text: &str, path: &str, value: f64) -> std::result::Result<String, Problem> {
    let doc = Doc::parse(text, "<scenario>")?;
    let fail = |line: usize, m: String| Problem { file: "<scenario>".into(), line, key: path.to_string(), message: m };
    let segs = segments(path).filter(|s| !s.is_empty()).ok_or_else(|| fail(0, "malformed key path (expected e.g. a.b[1].c)".into()))?;
    let mut anchor = (Anchor::Root, 0usize);
    let mut cur: Option<&Val<'_>> = None;
    for (d, seg) in segs.iter().enumerate() {
        let here = || {
            let mut p = String::new();
            for s in &segs[..d] {
                match s {
                    Seg::Key(k) => p = join(&p, k),
                    Seg::Index(i) => p.push_str(&format!("[{i}]")),
                }
            }
            if p.is_empty() {
                "the top level".to_string()
            } else {
                p
            }
        };
        let line = cur.map_or(0, |v| doc.line_at(v.span().start));
        let table = match cur.map(|v| v.get_ref()) {
            None => Some(doc.root()),
            Some(DeValue::Table(t)) => Some(t),
            _ => None,
        };
        let next = match (seg, table, cur.map(|v| v.get_ref())) {
            (Seg::Key(k), Some(t), _) => match t.get(*k) {
                Some(v) => v,
                None => return insert_missing(&doc, &segs, anchor, value).map_err(|m| fail(line, m)),
            },
            (Seg::Index(i), _, Some(DeValue::Array(a))) => a.get(*i).ok_or_else(|| fail(line, format!("{} has {} elements, no index {i}", here(), a.len())))?,
            (Seg::Index(_), _, _) => return Err(fail(line, format!("{} is not an array", here()))),
            (Seg::Key(_), None, _) => return Err(fail(line, format!("the parent {} is not a table", here()))),
        };
        if let Some(a) = anchor_of(text, next) {
            anchor = (a, d + 1);
        }
        cur = Some(next);
    }
    let v = cur.expect("non-empty path");
    let spans = targets(path, v).map_err(|m| fail(doc.line_at(v.span().start), m))?;
    let mut s = text.to_string();
    for (span, integer) in spans.into_iter().rev() {
        s.replace_range(span, &literal(value, integer));
    }
    Ok(s)
}

/// Add the missing key `segs[anchor.1..]` (relative to the anchor) = `value`.
fn insert_missing(doc: &Doc<'_>, segs: &[Seg<'_>], anchor: (Anchor, usize), value: f64) -> std::result::Result<String, String> {
    let mut keys = Vec::new();
    for s in &segs[anchor.1..] {
        match s {
            Seg::Key(k) => keys.push(*k),
            Seg::Index(i) => return Err(format!("cannot create element [{i}] of a missing array")),
        }
    }
    let last = keys.last().copied().unwrap_or("");
    let pair = format!("{} = {}", keys.join("."), literal(value, INTEGER_KEYS.contains(&last)));
    let text = insert_at(doc.text(), doc.root(), anchor.0, &pair);
    if let Err(p) = Doc::parse(&text, "<scenario>") {
        return Err(format!("the edit would not be valid TOML ({})", p.message));
    }
    Ok(text)
}

// ---------------------------------------------------------------------------------------
// parse_values

/// Parse a sweep value spec: `"a:b:step"` (from a to b inclusive, b included when within
/// 1e-9 of the step count; the last value snapped to b), or a comma list `"0,1,2.5"`.
///
/// # Errors
/// A value that is not a number, a zero, non-finite or wrong-signed step, an empty item,
/// or more than 1 000 000 values.
pub fn parse_values(spec: &str) -> std::result::Result<Vec<f64>, String> {
    let numf = |s: &str| s.trim().parse::<f64>().map_err(|_| format!("{:?} is not a number (in {spec:?})", s.trim()));
    let parts: Vec<&str> = spec.split(':').collect();
    match parts.len() {
        1 => spec.split(',').map(numf).collect(),
        3 => {
            let (a, b, step) = (numf(parts[0])?, numf(parts[1])?, numf(parts[2])?);
            if !(a.is_finite() && b.is_finite() && step.is_finite()) || step == 0.0 {
                return Err(format!("range {spec:?}: start, stop and step must be finite and the step non-zero"));
            }
            let r = (b - a) / step;
            if r < -1e-9 {
                return Err(format!("range {spec:?}: the step {step} goes away from the stop {b}"));
            }
            let n = (r + 1e-9 * r.abs().max(1.0)).floor().max(0.0);
            if n > 1e6 {
                return Err(format!("range {spec:?} has more than 1000000 values"));
            }
            let n = n as usize;
            let mut v: Vec<f64> = (0..=n).map(|k| a + k as f64 * step).collect();
            if let Some(last) = v.last_mut() {
                if (*last - b).abs() <= 1e-9 * step.abs() {
                    *last = b;
                }
            }
            Ok(v)
        }
        _ => Err(format!("{spec:?}: expected start:stop:step or a comma list of numbers")),
    }
}
