//! The MCAP writer sink.

use super::foxglove::{self, Level};
use super::topics::{event_schema_json, Source, Topic, TOPICS};
use super::{Compression, LogOptions};
use crate::control::closed_loop::{arm_parts, NCTRL};
use crate::control::collision::Capsule;
use crate::control::machine::Event;
use crate::error::{Error, Result};
use crate::kinematics::prbm::frames_with;
use crate::math::{Vec3, NMAX};
use crate::model::Model;
use crate::params::ParamData;
use crate::sensor::NCH;
use crate::stream::{Flow, Sink, StateView};
use mcap::records::{MessageHeader, Metadata};
use std::collections::BTreeMap;
use std::io::{Seek, Write};

/// What the metadata records say about the run.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RunMeta {
    /// The run as a measured-run `experiment.toml` (`format = "popup-run/1"`).
    pub experiment_toml: String,
    /// The scenario TOML the run came from (empty if none).
    pub scenario: String,
    /// Noise seed.
    pub seed: u64,
    /// More `popup` metadata (dt, sample rate, command line, ...).
    pub extra: BTreeMap<String, String>,
}

/// What a finished log contains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogEnd {
    /// Samples logged.
    pub samples: usize,
    /// Non-finite values left out of their messages (the finite keys of the same sample
    /// are written; a sample with a non-finite time counts all its values).
    pub nonfinite_dropped: usize,
    /// Time of the last sample [s] (NaN if none).
    pub t_last: f64,
}

#[derive(Debug, Clone, Copy)]
struct Chan {
    id: u16,
    seq: u32,
}

impl Chan {
    fn header(&mut self, ns: u64) -> MessageHeader {
        let h = MessageHeader { channel_id: self.id, sequence: self.seq, log_time: ns, publish_time: ns };
        self.seq = self.seq.wrapping_add(1);
        h
    }
}

/// Streams a run into an MCAP file (`docs/logging.md`). Create it, run with it as the
/// sink, then [`McapLogger::finish`] it (status and summary). Dropped unfinished, the mcap
/// writer still writes its summary but there is no `run_end` record; a killed process
/// leaves no summary (readable up to the last flushed chunk).
pub struct McapLogger<'m, W: Write + Seek> {
    w: mcap::Writer<W>,
    path: String,
    model: &'m Model,
    topics: Vec<(Topic, Chan)>,
    events: Option<Chan>,
    tf: Chan,
    scene: Option<Chan>,
    log: Option<Chan>,
    frame_names: Vec<String>,
    viz_every: usize,
    nstate: usize,
    flush_every: f64,
    next_flush: f64,
    payload_radius: f64,
    buf: Vec<u8>,
    nonfinite: usize,
    reported: [bool; 7],
    samples: usize,
    t_last: f64,
}

impl<'m> McapLogger<'m, std::io::BufWriter<std::fs::File>> {
    /// Create (or truncate) the file `path` and start a log on it (see [`McapLogger::new`]).
    ///
    /// # Errors
    /// [`Error::Log`] when the file cannot be created, and as [`McapLogger::new`].
    pub fn create(path: &std::path::Path, model: &'m Model, opts: &LogOptions, meta: &RunMeta, sample_period: f64, payload_radius: f64) -> Result<Self> {
        let name = path.display().to_string();
        let f = std::fs::File::create(path).map_err(|e| Error::Log { path: name.clone(), message: format!("cannot create: {e}") })?;
        McapLogger::new(std::io::BufWriter::with_capacity(1 << 16, f), &name, model, opts, meta, sample_period, payload_radius)
    }
}

fn ns_of(t: f64) -> u64 {
    (t * 1e9).round().max(0.0) as u64
}

impl<'m, W: Write + Seek> McapLogger<'m, W> {
    /// Start a log on `w` (`path` names it in errors): header, schemas, channels and the
    /// `experiment` and `popup` metadata records, flushed. `sample_period` [s] sets the
    /// `/tf`/`/scene` decimation; `payload_radius` [m] the payload sphere.
    ///
    /// # Errors
    /// [`Error::Input`] for bad options, [`Error::Log`] for I/O.
    pub fn new(w: W, path: &str, model: &'m Model, opts: &LogOptions, meta: &RunMeta, sample_period: f64, payload_radius: f64) -> Result<Self> {
        for t in &opts.topics {
            if !super::TOPIC_NAMES.contains(&t.as_str()) {
                return Err(Error::input("log.topics", format!("unknown topic {t:?}; known: {}", super::TOPIC_NAMES.join(", "))));
            }
        }
        if !(opts.viz_rate_hz.is_finite() && opts.viz_rate_hz > 0.0) {
            return Err(Error::param("log.viz_rate_hz", opts.viz_rate_hz, "must be finite and > 0 Hz"));
        }
        if !(opts.flush_every_s.is_finite() && opts.flush_every_s > 0.0) {
            return Err(Error::param("log.flush_every_s", opts.flush_every_s, "must be finite and > 0 s"));
        }
        let io = |e: mcap::McapError| Error::Log { path: path.to_string(), message: e.to_string() };
        let compression = match opts.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        // one compression thread: many logged runs in parallel must not oversubscribe
        let wo = mcap::WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(opts.chunk_size_bytes.max(1024)))
            .compression_threads(0)
            .profile("")
            .library(format!("popup {}", crate::VERSION));
        let mut w = wo.create(w).map_err(io)?;
        let on = |k: &str| opts.topics.iter().any(|t| t == k);
        let no_meta = BTreeMap::new();
        let mut topics = Vec::new();
        for t in TOPICS.iter().filter(|t| on(t.key)) {
            let sid = w.add_schema(t.schema, "jsonschema", t.schema_json().as_bytes()).map_err(io)?;
            let id = w.add_channel(sid, t.topic, "json", &no_meta).map_err(io)?;
            topics.push((*t, Chan { id, seq: 0 }));
        }
        let chan = |w: &mut mcap::Writer<W>, name: &str, schema: &str, topic: &str| -> Result<Chan> {
            let sid = w.add_schema(name, "jsonschema", schema.as_bytes()).map_err(io)?;
            Ok(Chan { id: w.add_channel(sid, topic, "json", &no_meta).map_err(io)?, seq: 0 })
        };
        let events = if on("events") { Some(chan(&mut w, "popup.Event", &event_schema_json(), "/popup/events")?) } else { None };
        let tf = chan(&mut w, "foxglove.FrameTransforms", foxglove::FRAME_TRANSFORMS, "/tf")?;
        let scene = if on("scene") { Some(chan(&mut w, "foxglove.SceneUpdate", foxglove::SCENE_UPDATE, "/scene")?) } else { None };
        let log = if on("log") { Some(chan(&mut w, "foxglove.Log", foxglove::LOG, "/log")?) } else { None };

        let mut exp = BTreeMap::new();
        exp.insert("toml".to_string(), meta.experiment_toml.clone());
        if let Ok(tab) = meta.experiment_toml.parse::<toml::Table>() {
            for (k, v) in tab.iter().filter(|(_, v)| !v.is_table()) {
                exp.insert(k.clone(), v.to_string());
            }
        }
        w.write_metadata(&Metadata { name: "experiment".into(), metadata: exp }).map_err(io)?;
        let mut pm = meta.extra.clone();
        pm.insert("version".into(), crate::VERSION.into());
        pm.insert("build_profile".into(), if cfg!(debug_assertions) { "debug" } else { "release" }.into());
        pm.insert("scenario".into(), meta.scenario.clone());
        pm.insert("seed".into(), meta.seed.to_string());
        pm.insert("flush_every_s".into(), opts.flush_every_s.to_string());
        w.write_metadata(&Metadata { name: "popup".into(), metadata: pm }).map_err(io)?;
        w.flush().map_err(io)?;

        let mut frame_names = vec!["base".to_string()];
        frame_names.extend((0..model.nv).map(|i| model.joint_name(i).to_string()));
        let viz_every = ((1.0 / opts.viz_rate_hz) / sample_period).round().max(1.0) as usize;
        Ok(McapLogger {
            w,
            path: path.to_string(),
            model,
            topics,
            events,
            tf,
            scene,
            log,
            frame_names,
            viz_every,
            nstate: 0,
            flush_every: opts.flush_every_s,
            next_flush: opts.flush_every_s,
            payload_radius,
            buf: Vec::with_capacity(1024),
            nonfinite: 0,
            reported: [false; 7],
            samples: 0,
            t_last: f64::NAN,
        })
    }

    fn err(&self, e: impl std::fmt::Display) -> Error {
        Error::Log { path: self.path.clone(), message: e.to_string() }
    }

    fn write_json(&mut self, ch: &mut Chan, ns: u64, v: &serde_json::Value) -> Result<()> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, v).map_err(|e| self.err(e))?;
        let h = ch.header(ns);
        self.w.write_to_known_channel(&h, &self.buf).map_err(|e| Error::Log { path: self.path.clone(), message: e.to_string() })
    }

    fn write_log(&mut self, ns: u64, level: Level, name: &str, msg: &str) -> Result<()> {
        if let Some(mut ch) = self.log {
            self.write_json(&mut ch, ns, &foxglove::log(ns, level, name, msg))?;
            self.log = Some(ch);
        }
        Ok(())
    }

    /// Write the `run_end` record (`status`: completed, unstable, interrupted) and the
    /// summary; returns what the file holds.
    ///
    /// # Errors
    /// [`Error::Log`] for I/O.
    pub fn finish(mut self, status: &str) -> Result<LogEnd> {
        let mut m = BTreeMap::new();
        m.insert("status".to_string(), status.to_string());
        m.insert("t_end".to_string(), self.t_last.to_string());
        m.insert("samples".to_string(), self.samples.to_string());
        m.insert("nonfinite_dropped".to_string(), self.nonfinite.to_string());
        let path = self.path.clone();
        let io = |e: mcap::McapError| Error::Log { path: path.clone(), message: e.to_string() };
        self.w.write_metadata(&Metadata { name: "run_end".into(), metadata: m }).map_err(io)?;
        self.w.finish().map_err(io)?;
        Ok(LogEnd { samples: self.samples, nonfinite_dropped: self.nonfinite, t_last: self.t_last })
    }

    /// Flush the current chunk to the OS now.
    ///
    /// # Errors
    /// [`Error::Log`] for I/O.
    pub fn flush(&mut self) -> Result<()> {
        let path = self.path.clone();
        self.w.flush().map_err(|e| Error::Log { path, message: e.to_string() })
    }
}

/// Append `"key":value` to a JSON object being built (`value` finite).
fn put(buf: &mut Vec<u8>, key: &str, v: f64) {
    buf.push(b',');
    buf.push(b'"');
    buf.extend_from_slice(key.as_bytes());
    buf.extend_from_slice(b"\":");
    serde_json::to_writer(&mut *buf, &v).expect("finite f64 serialises");
}

impl<W: Write + Seek> Sink for McapLogger<'_, W> {
    fn sample(&mut self, row: &[f64; NCH], ctrl: Option<&[f64; NCTRL]>) -> Result<Flow> {
        let t = row[0];
        let ns = ns_of(t);
        for i in 0..self.topics.len() {
            let (tp, mut ch) = self.topics[i];
            let vals: &[f64] = match (tp.source, ctrl) {
                (Source::Sensor, _) => &row[tp.cols.0..tp.cols.1],
                (Source::Control, Some(c)) => &c[tp.cols.0..tp.cols.1],
                (Source::Control, None) => continue,
            };
            let names = tp.names();
            // a non-finite value is left out of its message (its key absent: a missing
            // sample), never its finite siblings; d_min = +inf means "no obstacle", not an error
            let is_bad = |v: f64, n: &str| !(v.is_finite() || (n == "d_min" && v == f64::INFINITY));
            let nbad = vals.iter().zip(names).filter(|(v, n)| is_bad(**v, n)).count();
            if !t.is_finite() {
                // no time, no sample: the whole group is dropped
                self.nonfinite += vals.len();
            } else {
                self.nonfinite += nbad;
            }
            let first = vals.iter().zip(names).find(|(v, n)| is_bad(**v, n)).map(|(v, n)| (*v, *n));
            if let Some((v, n)) = if t.is_finite() { first } else { Some((t, "t")) } {
                if !self.reported[i] {
                    self.reported[i] = true;
                    let what = if t.is_finite() { format!("key {n} left out, the other keys written") } else { "sample dropped".to_string() };
                    let msg = format!(
                        "non-finite value {n} = {v} on {} at t = {t} s: {what} (further non-finite values on this topic are counted in run_end.nonfinite_dropped)",
                        tp.topic
                    );
                    self.write_log(ns, Level::Error, "popup.log", &msg)?;
                }
            }
            if !t.is_finite() {
                continue;
            }
            self.buf.clear();
            self.buf.extend_from_slice(b"{\"timestamp\":");
            serde_json::to_writer(&mut self.buf, &foxglove::time(ns)).map_err(|e| Error::Log { path: self.path.clone(), message: e.to_string() })?;
            put(&mut self.buf, "t", t);
            for (v, n) in vals.iter().zip(names) {
                if v.is_finite() {
                    put(&mut self.buf, n, *v);
                }
            }
            self.buf.push(b'}');
            let h = ch.header(ns);
            self.w.write_to_known_channel(&h, &self.buf).map_err(|e| Error::Log { path: self.path.clone(), message: e.to_string() })?;
            self.topics[i].1 = ch;
        }
        self.samples += 1;
        self.t_last = t;
        // every sample up to and including the one at the flush time is on disk after this
        if t >= self.next_flush - 1e-9 * self.flush_every {
            self.flush()?;
            while self.next_flush <= t + 1e-9 * self.flush_every {
                self.next_flush += self.flush_every;
            }
        }
        Ok(Flow::Go)
    }

    fn event(&mut self, e: &Event) -> Result<Flow> {
        let ns = ns_of(e.t);
        if let Some(mut ch) = self.events {
            let v = serde_json::json!({"timestamp": foxglove::time(ns), "t": e.t, "kind": e.kind, "from": e.from, "to": e.to, "detail": e.detail});
            self.write_json(&mut ch, ns, &v)?;
            self.events = Some(ch);
        }
        let level = match e.kind {
            "transition" | "timeout" | "payload" | "pressure" => Level::Info,
            "fault" if e.to == "Unstable" => Level::Error,
            _ => Level::Warning,
        };
        let msg = format!("{}: {} -> {}: {}", e.kind, e.from, e.to, e.detail);
        self.write_log(ns, level, "popup.events", &msg)?;
        Ok(Flow::Go)
    }

    fn state(&mut self, s: &StateView<'_>) -> Result<Flow> {
        let k = self.nstate;
        self.nstate += 1;
        if k % self.viz_every != 0 {
            return Ok(Flow::Go);
        }
        let ns = ns_of(s.t);
        let model = self.model;
        let fr = frames_with(model, &model.rotations(s.q));
        let (eb, ep) = &model.ee;
        let p_ee = fr.point(eb + 1, ep);
        let mut tf = self.tf;
        let v = foxglove::frame_transforms(ns, &fr, &self.frame_names, eb + 1, &p_ee);
        self.write_json(&mut tf, ns, &v)?;
        self.tf = tf;
        if let Some(mut ch) = self.scene {
            let pd: &ParamData = s.pd;
            let ratio = s.ratio;
            let mut parts = [Capsule { a: [0.0; 3], b: [0.0; 3], radius: 0.0 }; NMAX + 1];
            let mut link = [0usize; NMAX + 1];
            let np = arm_parts(model, &fr, pd.params.payload_kg, self.payload_radius, &mut parts, &mut link);
            let mut links: [Vec<serde_json::Value>; 2] = [Vec::new(), Vec::new()];
            let mut payload = None;
            for (c, &l) in parts[..np].iter().zip(&link[..np]) {
                let (a, b) = (Vec3::from(c.a), Vec3::from(c.b));
                if l == 2 {
                    payload = Some((a, c.radius, pd.params.payload_kg));
                } else {
                    links[l].push(foxglove::cylinder(&a, &b, c.radius, foxglove::ratio_color(ratio[l])));
                }
            }
            let v = foxglove::scene(ns, links, ratio, payload);
            self.write_json(&mut ch, ns, &v)?;
            self.scene = Some(ch);
        }
        Ok(Flow::Go)
    }
}
