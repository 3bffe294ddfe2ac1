//! MCAP logs of runs, written while the run streams (`docs/logging.md` is the layout).
//!
//! [`McapLogger`] is a [`crate::stream::Sink`]: plug it into
//! [`crate::control::closed_loop::run_closed_loop_into`] (with
//! [`crate::stream::Tee`] to keep the arrays too) and it writes the popup sample channels, the event log, the
//! Foxglove channels (`/tf`, `/scene`, `/log`) and the metadata records, flushing a
//! finished chunk every `flush_every_s` of simulated time.

mod foxglove;
mod topics;
mod writer;

pub use topics::{Topic, TOPICS, TOPIC_NAMES};
pub use writer::{LogEnd, McapLogger, RunMeta};

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    /// Zstandard (default).
    #[default]
    Zstd,
    /// LZ4 frames.
    Lz4,
    /// Uncompressed chunks.
    None,
}

impl Compression {
    /// From `"zstd"`, `"lz4"` or `"none"`.
    pub fn parse(s: &str) -> Option<Compression> {
        match s {
            "zstd" => Some(Compression::Zstd),
            "lz4" => Some(Compression::Lz4),
            "none" => Some(Compression::None),
            _ => None,
        }
    }
}

/// What and how to log.
#[derive(Debug, Clone, PartialEq)]
pub struct LogOptions {
    /// Rate of `/tf` and `/scene` [Hz] (rounded to a whole number of samples).
    pub viz_rate_hz: f64,
    /// Simulated time between flushes [s]: a killed run loses at most this much.
    pub flush_every_s: f64,
    /// Chunk compression.
    pub compression: Compression,
    /// Target uncompressed chunk size [bytes].
    pub chunk_size_bytes: u64,
    /// Topic keys to write (see [`TOPIC_NAMES`]); `/tf` is always written.
    pub topics: Vec<String>,
}

impl Default for LogOptions {
    fn default() -> Self {
        LogOptions { viz_rate_hz: 30.0, flush_every_s: 1.0, compression: Compression::Zstd, chunk_size_bytes: 1 << 20, topics: TOPIC_NAMES.iter().map(|s| s.to_string()).collect() }
    }
}
