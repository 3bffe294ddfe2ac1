//! The popup sample topics: which columns of the sensor and controller rows each topic
//! carries, and their JSON schemas.

use crate::control::closed_loop::CTRL_CHANNELS;
use crate::sensor::{CHANNELS, UNITS};

/// Where a topic's columns come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Columns of the sensor row.
    Sensor,
    /// Columns of the controller row.
    Control,
}

/// One popup sample topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Topic {
    /// Key in `[log] topics`.
    pub key: &'static str,
    /// MCAP topic.
    pub topic: &'static str,
    /// Schema name.
    pub schema: &'static str,
    /// Row the columns are taken from.
    pub source: Source,
    /// Column range in that row.
    pub cols: (usize, usize),
}

/// The sample topics, in the reader's column order.
pub const TOPICS: [Topic; 7] = [
    Topic { key: "joints", topic: "/popup/joints", schema: "popup.Joints", source: Source::Sensor, cols: (1, 10) },
    Topic { key: "imu", topic: "/popup/imu", schema: "popup.Imu", source: Source::Sensor, cols: (13, 19) },
    Topic { key: "end_effector", topic: "/popup/end_effector", schema: "popup.EndEffector", source: Source::Sensor, cols: (10, 13) },
    Topic { key: "pressure", topic: "/popup/pressure", schema: "popup.Pressure", source: Source::Sensor, cols: (19, 21) },
    Topic { key: "bending", topic: "/popup/bending", schema: "popup.Bending", source: Source::Sensor, cols: (21, 36) },
    Topic { key: "reference", topic: "/popup/reference", schema: "popup.Reference", source: Source::Control, cols: (0, 3) },
    Topic { key: "control", topic: "/popup/control", schema: "popup.Control", source: Source::Control, cols: (3, 17) },
];


const CTRL_UNITS: [&str; 17] =
    ["rad", "rad", "rad", "rad/s", "rad/s", "rad/s", "rad/s", "rad/s", "rad/s", "m/s²", "m/s²", "m/s²", "N·m", "N·m", "N·m", "1", "m"];

impl Topic {
    /// Column names, in order.
    pub fn names(&self) -> &'static [&'static str] {
        match self.source {
            Source::Sensor => &CHANNELS[self.cols.0..self.cols.1],
            Source::Control => &CTRL_CHANNELS[self.cols.0..self.cols.1],
        }
    }

    fn units(&self) -> &'static [&'static str] {
        match self.source {
            Source::Sensor => &UNITS[self.cols.0..self.cols.1],
            Source::Control => &CTRL_UNITS[self.cols.0..self.cols.1],
        }
    }

    /// The JSON schema (draft 2020-12) of the topic's messages.
    pub fn schema_json(&self) -> String {
        let mut props = serde_json::Map::new();
        props.insert("timestamp".into(), time_schema("sample time"));
        props.insert("t".into(), serde_json::json!({"type": "number", "description": "sample time since the start of the run [s]"}));
        for (n, u) in self.names().iter().zip(self.units()) {
            props.insert((*n).into(), serde_json::json!({"type": "number", "description": format!("[{u}]")}));
        }
        serde_json::json!({
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": self.schema,
            "description": "one sample of a group of popup channels (docs/logging.md); a key may be absent (not measured)",
            "type": "object",
            "properties": props,
            "required": ["timestamp", "t"],
        })
        .to_string()
    }
}

/// The JSON schema of `{sec, nsec}` times.
pub fn time_schema(what: &str) -> serde_json::Value {
    serde_json::json!({
        "type": "object", "title": "time", "description": what,
        "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}},
        "required": ["sec", "nsec"],
    })
}

/// Schema of `/popup/events`.
pub fn event_schema_json() -> String {
    let s = |d: &str| serde_json::json!({"type": "string", "description": d});
    serde_json::json!({
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "popup.Event",
        "description": "one entry of the run's event log (docs/logging.md)",
        "type": "object",
        "properties": {
            "timestamp": time_schema("event time"),
            "t": {"type": "number", "description": "event time [s]"},
            "kind": s("transition, timeout, fault, alarm, contact, payload, pressure, wrinkle_start, wrinkle_end, interrupted"),
            "from": s("state before"),
            "to": s("state after"),
            "detail": s("what happened"),
        },
        "required": ["timestamp", "t", "kind", "from", "to", "detail"],
    })
    .to_string()
}
