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

pub use crate::scenario::TOPICS as TOPIC_NAMES;
pub use topics::{Topic, TOPICS};
pub use writer::{LogEnd, McapLogger, RunMeta};

/// The logger's options are the scenario's `[log]` table.
pub use crate::scenario::{Compression, LogSettings as LogOptions};
