//! Control files: the controller, the task sequence, the fault policy and the obstacles in
//! TOML (the `[controller]`, `[faults]`, `[[obstacles]]` and `[[phases]]` tables of a
//! scenario; the measured-run format's `[controller]` table is the same). Python's
//! `popup.control` writes exactly this format.
//!
//! ```toml
//! [controller]
//! rate_hz = 10000.0
//! damping = true                 # or [true, true, false]
//! [controller.gains]
//! vel_kp = 5000.0                # a number applies to the three joints
//! [controller.motor]             # the same motoreducer on the three joints
//! tau_max = 123.0
//!
//! [[phases]]
//! kind = "moving"                # deflated inflating ready moving grasping damping holding releasing withdrawing phase
//! track = [{ kind = "const", value = 0.0 }, { kind = "step", from = 0.0, to = 0.5, delay = 2.0 }, { kind = "const", value = 0.0 }]
//! until = { min_time = 5.0 }
//! [[phases]]
//! kind = "grasping"
//! payload_kg = 2.0
//! ```
//!
//! Reading collects every problem instead of stopping at the first: the document is parsed
//! with the byte span of every key and value ([`Doc`]), each key of `[controller]`, each
//! phase, each obstacle and `[faults]` are read and validated on their own, and every
//! problem names its file, line and key path ([`Problem`]). The scenario reader
//! (`crate::scenario`) uses the same machinery for the rest of a scenario file.

use crate::control::collision::{CollisionWorld, Obstacle, ObstacleShape};
use crate::control::machine::{Command, FaultPolicy, Guard, Phase, Sequence};
use crate::control::reference::Signal;
use crate::control::{ControllerSpec, Gains, Motoreducer};
use crate::error::{Error, Result};
use crate::model::Model;
use crate::spec::arm::ArmSpec;
use serde::de::{DeserializeOwned, IntoDeserializer};
use serde::Deserialize;
use std::fmt;
use toml::de::{DeTable, DeValue};
use toml::Spanned;

// ---------------------------------------------------------------------------------------
// Problems and the spanned document

/// One problem found in a TOML file (scenario or control file).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// File name, as given to the reader.
    pub file: String,
    /// 1-based line of the key (or of its table header); 0 when unknown (a missing key).
    pub line: usize,
    /// Key path, e.g. `phases[2].until.max_time`, `controller.gains.vel_kp`,
    /// `pressure_pa[1]`; empty for a syntax error.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() {
            write!(f, "{}:{}: {}", self.file, self.line, self.message)
        } else {
            write!(f, "{}:{}: {}: {}", self.file, self.line, self.key, self.message)
        }
    }
}

/// A value of a parsed document with its byte span in the text.
pub type Val<'a> = Spanned<DeValue<'a>>;

/// One step of a key path: a table key or an array index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seg<'p> {
    /// Table key.
    Key(&'p str),
    /// Array index.
    Index(usize),
}

/// Split a key path (`phases[2].until.max_time`) into its steps; `None` when malformed.
pub fn segments(path: &str) -> Option<Vec<Seg<'_>>> {
    let mut out = Vec::new();
    if path.is_empty() {
        return Some(out);
    }
    for part in path.split('.') {
        let (name, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
        if name.is_empty() {
            return None;
        }
        out.push(Seg::Key(name));
        while !rest.is_empty() {
            let close = rest.find(']')?;
            out.push(Seg::Index(rest.get(1..close)?.parse().ok()?));
            rest = &rest[close + 1..];
            if !rest.is_empty() && !rest.starts_with('[') {
                return None;
            }
        }
    }
    Some(out)
}

/// `path.key`, or `key` at the top level.
pub fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_string()
    } else {
        format!("{path}.{key}")
    }
}

/// A key path as written in error messages of the core (`phases[0] (Grasping).payload_kg`,
/// `pressure_pa[1] (link 2)`) without the parenthesised names.
fn normalize(what: &str) -> String {
    let mut out = String::with_capacity(what.len());
    let mut depth = 0usize;
    let mut chars = what.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            ' ' if depth == 0 && chars.peek() == Some(&'(') => {}
            '(' => depth += 1,
            ')' if depth > 0 => depth -= 1,
            _ if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

/// The key path an error of the core names, if any.
fn error_what(e: &Error) -> Option<&str> {
    match e {
        Error::InvalidParameter { what, .. } | Error::Input { what, .. } => Some(what),
        _ => None,
    }
}

/// The message of a core error for a [`Problem`] (the key is given separately; a name in
/// parentheses, such as the phase's, is kept).
fn error_message(e: &Error) -> String {
    let named = |what: &str, detail: String| match (what.find(" ("), what.find(')')) {
        (Some(a), Some(b)) if a < b => format!("{}: {detail}", &what[..=b]),
        _ => detail,
    };
    match e {
        Error::InvalidParameter { what, value, requirement } => named(what, format!("invalid value {value}: {requirement}")),
        Error::Input { what, message } => named(what, message.clone()),
        other => other.to_string(),
    }
}

/// `e` with the list index in its key path changed from 0 to `i` (an entry validated on its
/// own as the only entry of a list).
fn reindex(e: Error, list: &str, i: usize) -> Error {
    let fix = |what: String| match what.strip_prefix(&format!("{list}[0]")) {
        Some(rest) => format!("{list}[{i}]{rest}"),
        None => what,
    };
    match e {
        Error::InvalidParameter { what, value, requirement } => Error::InvalidParameter { what: fix(what), value, requirement },
        Error::Input { what, message } => Error::Input { what: fix(what), message },
        other => other,
    }
}

/// Clearer words for serde messages about this project's value shapes.
fn friendly(message: &str) -> String {
    if message.contains("untagged enum Three") {
        "expected one value for the three joints or an array of 3 values".into()
    } else {
        message.to_string()
    }
}

/// The field named by serde's "unknown field `x`" message.
fn unknown_field(message: &str) -> Option<&str> {
    let rest = message.strip_prefix("unknown field `")?;
    rest.get(..rest.find('`')?)
}

/// A TOML document parsed with the byte spans of every key and value, so that a problem
/// names the line of the key it is about.
pub struct Doc<'a> {
    file: String,
    text: &'a str,
    root: DeTable<'a>,
}

impl<'a> Doc<'a> {
    /// Parse `text` (`file` names it in problems).
    ///
    /// # Errors
    /// The TOML syntax error as one [`Problem`] with the parser's line.
    pub fn parse(text: &'a str, file: &str) -> std::result::Result<Doc<'a>, Problem> {
        match DeTable::parse(text) {
            Ok(root) => Ok(Doc { file: file.to_string(), text, root: root.into_inner() }),
            Err(e) => {
                let line = e.span().map_or(0, |s| line_at(text, s.start));
                Err(Problem { file: file.to_string(), line, key: String::new(), message: format!("TOML syntax error: {}", e.message()) })
            }
        }
    }

    /// The file name given to [`Doc::parse`].
    pub fn file(&self) -> &str {
        &self.file
    }

    /// The text.
    pub fn text(&self) -> &'a str {
        self.text
    }

    /// The top-level table.
    pub fn root(&self) -> &DeTable<'a> {
        &self.root
    }

    /// 1-based line of byte `offset`.
    pub fn line_at(&self, offset: usize) -> usize {
        line_at(self.text, offset)
    }

    /// A problem in this file.
    pub fn problem(&self, key: &str, line: usize, message: impl Into<String>) -> Problem {
        Problem { file: self.file.clone(), line, key: key.to_string(), message: message.into() }
    }

    /// Entry `key` of table `t`: the line of the key and the value.
    pub fn entry<'d>(&self, t: &'d DeTable<'a>, key: &str) -> Option<(usize, &'d Val<'a>)> {
        t.get_key_value(key).map(|(k, v)| (self.line_at(k.span().start), v))
    }

    /// The value at `path` (`None` when some step is missing) and the line of the deepest
    /// step that exists (the key, or the header of its table; 0 when none does).
    pub fn locate(&self, path: &str) -> (Option<&Val<'a>>, usize) {
        let Some(segs) = segments(path) else { return (None, 0) };
        let mut line = 0;
        let mut cur: Option<&Val<'a>> = None;
        for seg in segs {
            let next = match (seg, cur) {
                (Seg::Key(k), None) => self.root.get_key_value(k).map(|(k, v)| (k.span().start, v)),
                (Seg::Key(k), Some(v)) => match v.get_ref() {
                    DeValue::Table(t) => t.get_key_value(k).map(|(k, v)| (k.span().start, v)),
                    _ => None,
                },
                (Seg::Index(i), Some(v)) => match v.get_ref() {
                    DeValue::Array(a) => a.get(i).map(|e| (e.span().start, e)),
                    _ => None,
                },
                (Seg::Index(_), None) => None,
            };
            match next {
                Some((at, v)) => {
                    line = self.line_at(at);
                    cur = Some(v);
                }
                None => return (None, line),
            }
        }
        (cur, line)
    }

    /// Deserialize `v` (at `path`) into `T`; a failure is recorded with the line and key
    /// path of the offending part.
    pub fn value<T: DeserializeOwned>(&self, path: &str, v: &Val<'a>, out: &mut Vec<Problem>) -> Option<T> {
        match T::deserialize(v.clone().into_deserializer()) {
            Ok(x) => Some(x),
            Err(e) => {
                out.push(self.de_problem(path, v, &e));
                None
            }
        }
    }

    /// A problem for a deserialization error inside `v` (at `path`).
    fn de_problem(&self, path: &str, v: &Val<'a>, e: &toml::de::Error) -> Problem {
        let msg = friendly(e.message());
        let (key, node, at) = match e.span() {
            Some(s) => {
                let (key, node) = node_at(path, v, s.start);
                (key, node, s.start)
            }
            None => (path.to_string(), v, v.span().start),
        };
        match unknown_field(e.message()).and_then(|f| find_key(&key, node, f)) {
            Some((key, at)) => self.problem(&key, self.line_at(at), msg),
            None => self.problem(&key, self.line_at(at), msg),
        }
    }

    /// `v` as a table, or a problem.
    pub fn table<'d>(&self, path: &str, v: &'d Val<'a>, out: &mut Vec<Problem>) -> Option<&'d DeTable<'a>> {
        match v.get_ref() {
            DeValue::Table(t) => Some(t),
            other => {
                out.push(self.problem(path, self.line_at(v.span().start), format!("must be a table, got {}", other.type_str())));
                None
            }
        }
    }

    /// `v` as an array, or a problem.
    pub fn array<'d>(&self, path: &str, v: &'d Val<'a>, out: &mut Vec<Problem>) -> Option<&'d [Val<'a>]> {
        match v.get_ref() {
            DeValue::Array(a) => Some(a),
            other => {
                out.push(self.problem(path, self.line_at(v.span().start), format!("must be an array, got {}", other.type_str())));
                None
            }
        }
    }

    /// Record every key of `t` (at `path`) that is not in `known`.
    pub fn check_keys(&self, path: &str, t: &DeTable<'a>, known: &[&str], out: &mut Vec<Problem>) {
        for (k, _) in t.iter() {
            if !known.contains(&k.get_ref().as_ref()) {
                let what = if path.is_empty() { "top-level key".to_string() } else { format!("key in [{path}]") };
                out.push(self.problem(&join(path, k.get_ref()), self.line_at(k.span().start), format!("unknown {what}; known keys: {}", known.join(", "))));
            }
        }
    }

    /// Each key of `t` (at `path`) that is in `keys`, read on its own into `T` (a struct of
    /// optional fields), so that every bad key is reported: (key path, line, value).
    pub fn each_key<T: DeserializeOwned>(&self, path: &str, t: &DeTable<'a>, keys: &[&str], out: &mut Vec<Problem>) -> Vec<(String, usize, T)> {
        let mut found = Vec::new();
        for (k, v) in t.iter() {
            if !keys.contains(&k.get_ref().as_ref()) {
                continue;
            }
            let mut one = DeTable::new();
            one.insert(k.clone(), v.clone());
            let single = Spanned::new(v.span(), DeValue::Table(one));
            if let Some(x) = self.value::<T>(path, &single, out) {
                found.push((join(path, k.get_ref()), self.line_at(k.span().start), x));
            }
        }
        found
    }

    /// Record a validation error `e` of the part at `key` (line `line`): the key path is the
    /// one the error names when that lies inside `key`, with the line of that exact element.
    pub fn error(&self, key: &str, line: usize, e: &Error, out: &mut Vec<Problem>) {
        let named = error_what(e).map(normalize).filter(|w| w.starts_with(key) && matches!(w.as_bytes().get(key.len()), None | Some(b'.' | b'[')));
        let (key, line) = match named {
            Some(w) => {
                let (found, l) = self.locate(&w);
                let l = if found.is_some() { l } else { line };
                (w, l)
            }
            None => (key.to_string(), line),
        };
        out.push(self.problem(&key, line, error_message(e)));
    }
}

/// 1-based line of byte `offset` of `text`.
fn line_at(text: &str, offset: usize) -> usize {
    text.as_bytes()[..offset.min(text.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// The key path and value of the deepest part of `v` (at `path`) whose key or value
/// contains byte `offset`.
fn node_at<'v, 'a>(path: &str, v: &'v Val<'a>, offset: usize) -> (String, &'v Val<'a>) {
    let inside = |s: std::ops::Range<usize>| s.start <= offset && offset < s.end.max(s.start + 1);
    match v.get_ref() {
        DeValue::Table(t) => {
            for (k, c) in t.iter() {
                if inside(k.span()) {
                    return (join(path, k.get_ref()), c);
                }
                if inside(c.span()) || contains_offset(c, offset) {
                    return node_at(&join(path, k.get_ref()), c, offset);
                }
            }
        }
        DeValue::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                if inside(c.span()) || contains_offset(c, offset) {
                    return node_at(&format!("{path}[{i}]"), c, offset);
                }
            }
        }
        _ => {}
    }
    (path.to_string(), v)
}

/// Whether any key or value below `v` contains byte `offset` (the children of a table
/// given by a header lie outside the header's span).
fn contains_offset(v: &Val<'_>, offset: usize) -> bool {
    let inside = |s: std::ops::Range<usize>| s.start <= offset && offset < s.end.max(s.start + 1);
    match v.get_ref() {
        DeValue::Table(t) => t.iter().any(|(k, c)| inside(k.span()) || inside(c.span()) || contains_offset(c, offset)),
        DeValue::Array(a) => a.iter().any(|c| inside(c.span()) || contains_offset(c, offset)),
        _ => false,
    }
}

/// The first key named `name` below `v` (at `path`): its path and byte offset.
fn find_key(path: &str, v: &Val<'_>, name: &str) -> Option<(String, usize)> {
    match v.get_ref() {
        DeValue::Table(t) => t.iter().find_map(|(k, c)| {
            let p = join(path, k.get_ref());
            if k.get_ref() == name {
                Some((p, k.span().start))
            } else {
                find_key(&p, c, name)
            }
        }),
        DeValue::Array(a) => a.iter().enumerate().find_map(|(i, c)| find_key(&format!("{path}[{i}]"), c, name)),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------
// The control tables

/// A value given once for all three joints or per joint.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(untagged)]
enum Three<T: Copy> {
    One(T),
    Each([T; 3]),
}

impl<T: Copy> Three<T> {
    fn get(self) -> [T; 3] {
        match self {
            Three::One(v) => [v; 3],
            Three::Each(a) => a,
        }
    }
}

/// Keys of `[controller.gains]`, in [`Gains::to_flat`] order (`cart_k` last).
const GAIN_KEYS: [&str; 8] = ["pos_kp", "pos_ki", "vel_kp", "vel_ki", "damp_kp", "damp_ki", "damp_kd", "cart_k"];

#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct GainsToml {
    pos_kp: Option<Three<f64>>,
    pos_ki: Option<Three<f64>>,
    vel_kp: Option<Three<f64>>,
    vel_ki: Option<Three<f64>>,
    damp_kp: Option<Three<f64>>,
    damp_ki: Option<Three<f64>>,
    damp_kd: Option<Three<f64>>,
    cart_k: Option<f64>,
}

impl GainsToml {
    fn apply(&self, g: &mut Gains) {
        let per_joint = [self.pos_kp, self.pos_ki, self.vel_kp, self.vel_ki, self.damp_kp, self.damp_ki, self.damp_kd];
        let mut flat = g.to_flat();
        for (k, v) in per_joint.iter().enumerate() {
            if let Some(v) = v {
                flat[3 * k..3 * k + 3].copy_from_slice(&v.get());
            }
        }
        if let Some(c) = self.cart_k {
            flat[21] = c;
        }
        *g = Gains::from_flat(&flat);
    }
}

/// Keys of `[controller.motor]` and of each `[[controller.motors]]`.
const MOTOR_KEYS: [&str; 5] = ["gear_ratio", "torque_per_unit", "tau_max", "current_bandwidth", "encoder_counts"];

#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct MotorToml {
    gear_ratio: Option<f64>,
    torque_per_unit: Option<f64>,
    tau_max: Option<f64>,
    current_bandwidth: Option<f64>,
    encoder_counts: Option<u32>,
}

impl MotorToml {
    fn apply(&self, m: &mut Motoreducer) {
        m.gear_ratio = self.gear_ratio.unwrap_or(m.gear_ratio);
        m.torque_per_unit = self.torque_per_unit.unwrap_or(m.torque_per_unit);
        m.tau_max = self.tau_max.unwrap_or(m.tau_max);
        m.current_bandwidth = self.current_bandwidth.unwrap_or(m.current_bandwidth);
        m.encoder_counts = self.encoder_counts.unwrap_or(m.encoder_counts);
    }
}

/// Keys of `[controller]` that are plain values.
const CONTROLLER_VALUE_KEYS: [&str; 6] = ["rate_hz", "damping", "damping_lpf_rad_s", "v_max", "anti_windup", "cartesian_arm"];

/// Keys of `[controller]`.
pub const CONTROLLER_KEYS: [&str; 9] = ["rate_hz", "damping", "damping_lpf_rad_s", "v_max", "anti_windup", "cartesian_arm", "gains", "motor", "motors"];

#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerToml {
    rate_hz: Option<f64>,
    damping: Option<Three<bool>>,
    damping_lpf_rad_s: Option<f64>,
    v_max: Option<f64>,
    anti_windup: Option<bool>,
    cartesian_arm: Option<crate::control::CartesianArm>,
}

impl ControllerToml {
    fn apply(&self, c: &mut ControllerSpec) {
        c.rate_hz = self.rate_hz.unwrap_or(c.rate_hz);
        c.damping = self.damping.map_or(c.damping, Three::get);
        c.damping_lpf = self.damping_lpf_rad_s.unwrap_or(c.damping_lpf);
        c.v_max = self.v_max.unwrap_or(c.v_max);
        c.anti_windup = self.anti_windup.unwrap_or(c.anti_windup);
        c.cartesian_arm = self.cartesian_arm.unwrap_or(c.cartesian_arm);
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MoveToToml {
    q: [f64; 3],
    duration: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CartesianToml {
    target: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PhaseToml {
    kind: String,
    name: Option<String>,
    hold: Option<bool>,
    track: Option<[Signal; 3]>,
    velocity: Option<[Signal; 3]>,
    move_to: Option<MoveToToml>,
    cartesian: Option<CartesianToml>,
    payload_kg: Option<f64>,
    pressure_pa: Option<[f64; 2]>,
    damping: Option<Three<bool>>,
    until: Option<Guard>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SphereToml {
    center: [f64; 3],
    radius: f64,
}
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxToml {
    center: [f64; 3],
    half_extents: [f64; 3],
    #[serde(default)]
    yaw: f64,
}
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlaneToml {
    point: [f64; 3],
    normal: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObstacleToml {
    name: String,
    sphere: Option<SphereToml>,
    #[serde(rename = "box")]
    cuboid: Option<BoxToml>,
    plane: Option<PlaneToml>,
}

/// Top-level keys of a control file.
pub const CONTROL_KEYS: [&str; 5] = ["controller", "faults", "obstacles", "payload_radius_m", "phases"];

/// What a control file defines.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlFile {
    /// The controller.
    pub controller: ControllerSpec,
    /// The sequence (empty phases when the file has none: the caller supplies a command).
    pub sequence: Sequence,
    /// Obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Payload collision radius [m].
    pub payload_radius: f64,
}

/// The phase kinds and their defaults.
pub const PHASE_KINDS: [&str; 10] = ["deflated", "inflating", "ready", "moving", "grasping", "damping", "holding", "releasing", "withdrawing", "phase"];

fn title(kind: &str) -> String {
    let mut c = kind.chars();
    c.next().map(|f| f.to_uppercase().collect::<String>() + c.as_str()).unwrap_or_default()
}

/// A phase that holds the motors for the rest of the run (no exit guard), named `name`.
pub fn hold_phase(name: &str) -> Phase {
    Phase { name: name.into(), command: Command::Hold, payload_kg: None, pressure_pa: None, damping: None, until: Guard::default() }
}

fn build_phase(arm: &ArmSpec, i: usize, p: PhaseToml) -> Result<Phase> {
    let name = p.name.clone().unwrap_or_else(|| title(&p.kind));
    let w = format!("phases[{i}] ({name})");
    if !PHASE_KINDS.contains(&p.kind.as_str()) {
        return Err(Error::input(format!("{w}.kind"), format!("unknown kind {:?}; known: {}", p.kind, PHASE_KINDS.join(", "))));
    }
    let given = [p.hold == Some(true), p.track.is_some(), p.velocity.is_some(), p.move_to.is_some(), p.cartesian.is_some()];
    if given.iter().filter(|&&g| g).count() > 1 {
        return Err(Error::input(&w, "give at most one of hold, track, velocity, move_to, cartesian"));
    }
    let command = if let Some(s) = p.track {
        Command::Track(s)
    } else if let Some(s) = p.velocity {
        Command::Velocity(s)
    } else if let Some(m) = p.move_to {
        Command::MoveTo { q: m.q, duration: m.duration }
    } else if let Some(c) = p.cartesian {
        Command::Cartesian { target: c.target }
    } else if matches!(p.kind.as_str(), "moving" | "withdrawing") {
        return Err(Error::input(&w, format!("a {} phase needs a motion: track, velocity, move_to or cartesian", p.kind)));
    } else {
        Command::Hold
    };
    let tab = &arm.stiffness.pressure_pa;
    let lowest = tab.first().copied().unwrap_or(0.0);
    let nominal = [arm.links[0].pressure_pa, arm.links[1].pressure_pa];
    let (payload_kg, pressure_pa, damping, until) = match p.kind.as_str() {
        "deflated" => (None, Some([lowest; 2]), None, Guard { min_time: 0.5, ..Guard::default() }),
        "inflating" => (None, Some(nominal), None, Guard { min_time: 1.0, ..Guard::default() }),
        "grasping" => {
            if p.payload_kg.is_none() {
                return Err(Error::input(&w, "a grasping phase needs payload_kg (the mass of the grasped object, kg)"));
            }
            (None, None, None, Guard { min_time: 0.2, ..Guard::default() })
        }
        "damping" => (None, None, Some([true; 3]), Guard { min_time: 0.5, max_time: 10.0, still: Some(0.05), ..Guard::default() }),
        "releasing" => (Some(0.0), None, None, Guard { min_time: 0.2, ..Guard::default() }),
        "moving" | "withdrawing" => (None, None, None, Guard { settled: Some(0.01), max_time: 30.0, ..Guard::default() }),
        _ => (None, None, None, Guard { min_time: 0.5, ..Guard::default() }),
    };
    Ok(Phase {
        name,
        command,
        payload_kg: p.payload_kg.or(payload_kg),
        pressure_pa: p.pressure_pa.or(pressure_pa),
        damping: p.damping.map(Three::get).or(damping),
        until: p.until.unwrap_or(until),
    })
}

/// One key of the controller tables: where it is written and what it does to the spec.
struct Setting {
    key: String,
    line: usize,
    apply: Box<dyn Fn(&mut ControllerSpec)>,
}

/// The settings of `[controller]` (plain keys, `gains`, `motor`, `motors`).
fn controller_settings(doc: &Doc<'_>, t: &DeTable<'_>, out: &mut Vec<Problem>) -> Vec<Setting> {
    let mut s = Vec::new();
    doc.check_keys("controller", t, &CONTROLLER_KEYS, out);
    for (key, line, one) in doc.each_key::<ControllerToml>("controller", t, &CONTROLLER_VALUE_KEYS, out) {
        s.push(Setting { key, line, apply: Box::new(move |c| one.apply(c)) });
    }
    if let Some(gt) = doc.entry(t, "gains").and_then(|(_, v)| doc.table("controller.gains", v, out)) {
        doc.check_keys("controller.gains", gt, &GAIN_KEYS, out);
        for (key, line, one) in doc.each_key::<GainsToml>("controller.gains", gt, &GAIN_KEYS, out) {
            s.push(Setting { key, line, apply: Box::new(move |c| one.apply(&mut c.gains)) });
        }
    }
    let motor = doc.entry(t, "motor");
    let motors = doc.entry(t, "motors");
    if let (Some(_), Some((line, _))) = (motor, motors) {
        out.push(doc.problem("controller.motors", line, "give either [controller.motor] (all joints) or [[controller.motors]] (three), not both"));
    }
    if let Some(mt) = motor.and_then(|(_, v)| doc.table("controller.motor", v, out)) {
        doc.check_keys("controller.motor", mt, &MOTOR_KEYS, out);
        for (key, line, one) in doc.each_key::<MotorToml>("controller.motor", mt, &MOTOR_KEYS, out) {
            s.push(Setting { key, line, apply: Box::new(move |c| c.motors.iter_mut().for_each(|m| one.apply(m))) });
        }
    }
    if let Some((line, v)) = motors {
        s.extend(motors_settings(doc, line, v, out));
    }
    s
}

/// The settings of `[[controller.motors]]` (three tables, q1..q3).
fn motors_settings(doc: &Doc<'_>, line: usize, v: &Val<'_>, out: &mut Vec<Problem>) -> Vec<Setting> {
    let mut s = Vec::new();
    let Some(list) = doc.array("controller.motors", v, out) else { return s };
    if list.len() != 3 {
        out.push(doc.problem("controller.motors", line, format!("needs 3 entries (q1, q2, q3), got {}", list.len())));
        return s;
    }
    for (j, e) in list.iter().enumerate() {
        let path = format!("controller.motors[{j}]");
        if let Some(mt) = doc.table(&path, e, out) {
            doc.check_keys(&path, mt, &MOTOR_KEYS, out);
            for (key, line, one) in doc.each_key::<MotorToml>(&path, mt, &MOTOR_KEYS, out) {
                s.push(Setting { key, line, apply: Box::new(move |c| one.apply(&mut c.motors[j])) });
            }
        }
    }
    s
}

/// The controller of the document: defaults overridden by each key given; every key is
/// validated on its own (applied to the defaults), so every bad key is reported.
pub fn read_controller(doc: &Doc<'_>, out: &mut Vec<Problem>) -> ControllerSpec {
    let mut spec = ControllerSpec::default();
    let Some(t) = doc.entry(doc.root(), "controller").and_then(|(_, v)| doc.table("controller", v, out)) else { return spec };
    for s in controller_settings(doc, t, out) {
        let mut one = ControllerSpec::default();
        (s.apply)(&mut one);
        if let Err(e) = one.validate() {
            doc.error(&s.key, s.line, &e, out);
        }
        (s.apply)(&mut spec);
    }
    spec
}

/// The fault policy of `[faults]` (defaults when absent).
pub fn read_faults(doc: &Doc<'_>, out: &mut Vec<Problem>) -> FaultPolicy {
    let Some((line, v)) = doc.entry(doc.root(), "faults") else { return FaultPolicy::default() };
    let Some(faults) = doc.value::<FaultPolicy>("faults", v, out) else { return FaultPolicy::default() };
    let check = Sequence { phases: vec![hold_phase("Holding")], faults };
    if let Err(e) = check.validate() {
        doc.error("faults", line, &e, out);
    }
    faults
}

/// The phases of `[[phases]]` for `arm` (the phase kinds' pressures come from it), each read
/// and validated on its own. Only good phases are returned.
pub fn read_phases(arm: &ArmSpec, doc: &Doc<'_>, out: &mut Vec<Problem>) -> Vec<Phase> {
    let mut phases = Vec::new();
    let Some(list) = doc.entry(doc.root(), "phases").and_then(|(_, v)| doc.array("phases", v, out)) else { return phases };
    for (i, e) in list.iter().enumerate() {
        let key = format!("phases[{i}]");
        let line = doc.line_at(e.span().start);
        let Some(p) = doc.value::<PhaseToml>(&key, e, out) else { continue };
        let phase = match build_phase(arm, i, p) {
            Ok(ph) => ph,
            Err(err) => {
                doc.error(&key, line, &err, out);
                continue;
            }
        };
        let check = Sequence { phases: vec![phase], faults: FaultPolicy::default() };
        match check.validate() {
            Ok(()) => phases.extend(check.phases),
            Err(err) => doc.error(&key, line, &reindex(err, "phases", i), out),
        }
    }
    phases
}

/// One obstacle table.
fn obstacle(o: ObstacleToml) -> std::result::Result<Obstacle, (String, String)> {
    let shapes = [o.sphere.is_some(), o.cuboid.is_some(), o.plane.is_some()].iter().filter(|&&b| b).count();
    if shapes != 1 {
        return Err((o.name, "needs exactly one of sphere, box, plane".into()));
    }
    let shape = if let Some(s) = o.sphere {
        ObstacleShape::Sphere { center: s.center, radius: s.radius }
    } else if let Some(b) = o.cuboid {
        ObstacleShape::Box { center: b.center, half_extents: b.half_extents, yaw: b.yaw }
    } else {
        let p = o.plane.expect("counted above");
        ObstacleShape::Plane { point: p.point, normal: p.normal }
    };
    Ok(Obstacle { name: o.name, shape })
}

/// The obstacles of `[[obstacles]]`, each read and checked on its own, then the names for
/// duplicates. Only good obstacles are returned.
pub fn read_obstacles(doc: &Doc<'_>, out: &mut Vec<Problem>) -> Vec<Obstacle> {
    let mut obstacles = Vec::new();
    let Some((list_line, v)) = doc.entry(doc.root(), "obstacles") else { return obstacles };
    let Some(list) = doc.array("obstacles", v, out) else { return obstacles };
    let n0 = out.len();
    for (i, e) in list.iter().enumerate() {
        let key = format!("obstacles[{i}]");
        let line = doc.line_at(e.span().start);
        let Some(o) = doc.value::<ObstacleToml>(&key, e, out) else { continue };
        match obstacle(o) {
            Err((name, msg)) => out.push(doc.problem(&key, line, format!("{key} ({name}): {msg}"))),
            Ok(o) => match CollisionWorld::new(std::slice::from_ref(&o)) {
                Ok(_) => obstacles.push(o),
                Err(err) => doc.error(&key, line, &reindex(err, "obstacles", i), out),
            },
        }
    }
    if out.len() == n0 {
        if let Err(err) = CollisionWorld::new(&obstacles) {
            doc.error("obstacles", list_line, &err, out);
        }
    }
    obstacles
}

/// `payload_radius_m` [m] (default 0.05 m), finite and >= 0.
pub fn read_payload_radius(doc: &Doc<'_>, out: &mut Vec<Problem>) -> f64 {
    let Some((line, v)) = doc.entry(doc.root(), "payload_radius_m") else { return 0.05 };
    match doc.value::<f64>("payload_radius_m", v, out) {
        Some(r) if r.is_finite() && r >= 0.0 => r,
        Some(r) => {
            out.push(doc.problem("payload_radius_m", line, format!("invalid value {r}: must be finite and >= 0 m")));
            0.05
        }
        None => 0.05,
    }
}

/// The control tables of `doc` (`[controller]`, `[faults]`, `[[phases]]`, `[[obstacles]]`,
/// `payload_radius_m`) for `arm`, every part read and validated on its own. Problems are
/// appended to `out`; the result is only meaningful when none was found (bad phases and
/// obstacles are left out, bad controller values are kept). Other top-level keys are not
/// looked at.
pub fn read_control(arm: &ArmSpec, doc: &Doc<'_>, out: &mut Vec<Problem>) -> ControlFile {
    let controller = read_controller(doc, out);
    let faults = read_faults(doc, out);
    let phases = read_phases(arm, doc, out);
    let obstacles = read_obstacles(doc, out);
    let payload_radius = read_payload_radius(doc, out);
    ControlFile { controller, sequence: Sequence { phases, faults }, obstacles, payload_radius }
}

/// Problems as one [`Error::Input`] naming the file: one line per problem, in line order.
pub fn problems_error(source: &str, problems: &[Problem]) -> Error {
    let mut ps = problems.to_vec();
    ps.sort_by_key(|p| p.line);
    let lines: Vec<String> =
        ps.iter().map(|p| if p.key.is_empty() { format!("line {}: {}", p.line, p.message) } else { format!("line {}: {}: {}", p.line, p.key, p.message) }).collect();
    Error::input(source, lines.join("\n"))
}

/// Parse a control file (or the control tables of a scenario) for `model`. Unknown keys
/// are errors; `source` names the file in messages.
///
/// # Errors
/// One [`Error::Input`] naming the file and listing every problem found (line, key path,
/// what is wrong): TOML syntax, unknown keys, wrong types, and the validation errors of the
/// controller, each phase, the fault policy and each obstacle.
pub fn parse_control(model: &Model, text: &str, source: &str) -> Result<ControlFile> {
    let doc = Doc::parse(text, source).map_err(|p| problems_error(source, &[p]))?;
    let mut out = Vec::new();
    doc.check_keys("", doc.root(), &CONTROL_KEYS, &mut out);
    let cf = read_control(&model.spec, &doc, &mut out);
    if out.is_empty() {
        Ok(cf)
    } else {
        Err(problems_error(source, &out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_paths_split_and_normalize() {
        assert_eq!(segments("phases[2].until.max_time").unwrap(), vec![Seg::Key("phases"), Seg::Index(2), Seg::Key("until"), Seg::Key("max_time")]);
        assert_eq!(segments("pressure_pa[1]").unwrap(), vec![Seg::Key("pressure_pa"), Seg::Index(1)]);
        assert!(segments("a..b").is_none() && segments("a[x]").is_none() && segments("a[1]b").is_none());
        assert_eq!(normalize("phases[0] (Grasping).payload_kg"), "phases[0].payload_kg");
        assert_eq!(normalize("pressure_pa[1] (link 2)"), "pressure_pa[1]");
    }

    #[test]
    fn every_controller_key_is_checked_on_its_own() {
        let text = "[controller]\nrate_hz = -1.0\nbogus = 1\n[controller.gains]\nvel_kp = [1.0, nan, 1.0]\npos_kp = \"x\"\n[controller.motor]\ntau_max = -3.0\n";
        let doc = Doc::parse(text, "c.toml").unwrap();
        let mut out = Vec::new();
        read_controller(&doc, &mut out);
        let got: Vec<(usize, &str)> = out.iter().map(|p| (p.line, p.key.as_str())).collect();
        for want in [(2, "controller.rate_hz"), (3, "controller.bogus"), (5, "controller.gains.vel_kp[1]"), (6, "controller.gains.pos_kp"), (8, "controller.motor.tau_max")] {
            assert!(got.contains(&want), "{want:?} not in {got:?}");
        }
        assert_eq!(out.len(), 5, "{out:?}");
    }
}
