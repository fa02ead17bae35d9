//! The records of a session (docs/mcap-session.md): one serde type per topic, used by the writers
//! (the sweep, the rig, the byte tap) and by the readers (processing, replay, resume), with the data
//! types they carry (the stand's channel map and geometry, a step's estimates, the drive's
//! waveform). This module is the bottom of `acquire`: it imports nothing from the crate, and the
//! modules above it (`stand`, `sweep`, `shaker`, `daq`, `transport`, `session`) re-export the types
//! that belong to their vocabulary.
//!
//! The channel schemas recorded in every session file are generated from these types
//! ([`Topic::schema`], `schemars`), and docs/mcap-session.md shows the same schemas (a test
//! compares them), so a field renamed in one place cannot silently break replay.
//!
//! Versions: `/session` carries [`SessionStart::version`]. Version 1 (sessions recorded before the
//! field existed) reads with it absent; fields added since are optional or have defaults, so an
//! old session reads unchanged (`acquire/tests/fixtures/session-v1.mcap`).

mod daq;
mod drive;
mod session;
mod stand;
mod sweep;
pub mod topic;

pub use daq::{BlockRecord, ChannelInfo, DaqStreamRecord, Direction, FaultRecord, RawBytes};
pub use drive::{DriveKind, DriveRecord, Waveform};
pub use session::{DeviceIdentityRecord, Role, SessionStart, VERSION};
pub use stand::{BodyGeometry, Channel, ChannelKind, Geometry, GeometryOutput, StandRecord};
pub use sweep::{BroadbandChannel, BroadbandRecord, ChannelResult, StepResult, SweepEvent};
pub use topic::{schema_of, Topic, TopicRecord, ALL};

impl Topic {
    /// The JSON Schema (draft 2020-12) of this topic's messages, generated from its record type
    /// (this module's types).
    pub fn schema(&self) -> serde_json::Value {
        match self {
            Topic::Session => schema_of::<SessionStart>(),
            Topic::Stand => schema_of::<StandRecord>(),
            Topic::Identity => schema_of::<DeviceIdentityRecord>(),
            Topic::Raw => schema_of::<RawBytes>(),
            Topic::DaqStream => schema_of::<DaqStreamRecord>(),
            Topic::DaqBlock => schema_of::<BlockRecord>(),
            Topic::DaqFault => schema_of::<FaultRecord>(),
            Topic::SweepEvent => schema_of::<SweepEvent>(),
            Topic::SweepStep => schema_of::<StepResult>(),
            Topic::SweepBroadband => schema_of::<BroadbandRecord>(),
            Topic::Drive => schema_of::<DriveRecord>(),
        }
    }
}

/// The schemas of every topic as the Markdown section of docs/mcap-session.md between its
/// `generated schemas` markers (`IDENT_BLESS=1 cargo test -p acquire --test session_records`
/// rewrites it).
pub fn schemas_markdown() -> String {
    let mut out = String::new();
    for t in ALL {
        let pretty = serde_json::to_string_pretty(&t.schema()).unwrap_or_default();
        out.push_str(&format!(
            "### `{}` (`{}`)\n\n```json\n{pretty}\n```\n\n",
            t.name(),
            t.schema_name()
        ));
    }
    out
}
