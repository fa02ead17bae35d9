//! The session's topics (docs/mcap-session.md) and the trait that ties a record type to its topic.
//! Every channel carries `json` messages with a `jsonschema` schema generated from its record
//! type, which Foxglove and the Python `mcap` reader decode.

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::Serialize;

/// A session topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// `/session`: software, start time, sweep plan, resume origin.
    Session,
    /// `/stand`: the stand file verbatim and its resolved channel map and calibration.
    Stand,
    /// `/device/identity`: each device's identity.
    Identity,
    /// `/raw`: every byte sent to and received from a device.
    Raw,
    /// `/daq/stream`: the DAQ's stream announcement.
    DaqStream,
    /// `/daq/block`: decoded sample blocks (volts).
    DaqBlock,
    /// `/daq/fault`: stream faults (gap, CRC, duplicate, …).
    DaqFault,
    /// `/sweep/event`: sweep progress and problems.
    SweepEvent,
    /// `/sweep/step`: per-step amplitude/phase estimates.
    SweepStep,
    /// `/sweep/broadband`: H1 estimates and coherence of a broadband measurement.
    SweepBroadband,
    /// `/drive`: signal-generator settings and the forces the host's loop measured.
    Drive,
}

/// All topics, in channel-registration order.
pub const ALL: [Topic; 11] = [
    Topic::Session,
    Topic::Stand,
    Topic::Identity,
    Topic::Raw,
    Topic::DaqStream,
    Topic::DaqBlock,
    Topic::DaqFault,
    Topic::SweepEvent,
    Topic::SweepStep,
    Topic::SweepBroadband,
    Topic::Drive,
];

impl Topic {
    /// MCAP topic name.
    pub fn name(&self) -> &'static str {
        match self {
            Topic::Session => "/session",
            Topic::Stand => "/stand",
            Topic::Identity => "/device/identity",
            Topic::Raw => "/raw",
            Topic::DaqStream => "/daq/stream",
            Topic::DaqBlock => "/daq/block",
            Topic::DaqFault => "/daq/fault",
            Topic::SweepEvent => "/sweep/event",
            Topic::SweepStep => "/sweep/step",
            Topic::SweepBroadband => "/sweep/broadband",
            Topic::Drive => "/drive",
        }
    }

    /// Schema name.
    pub fn schema_name(&self) -> &'static str {
        match self {
            Topic::Session => "ident.Session",
            Topic::Stand => "ident.Stand",
            Topic::Identity => "ident.DeviceIdentity",
            Topic::Raw => "ident.RawBytes",
            Topic::DaqStream => "ident.DaqStream",
            Topic::DaqBlock => "ident.SampleBlock",
            Topic::DaqFault => "ident.StreamFault",
            Topic::SweepEvent => "ident.SweepEvent",
            Topic::SweepStep => "ident.SweepStep",
            Topic::SweepBroadband => "ident.SweepBroadband",
            Topic::Drive => "ident.Drive",
        }
    }

    /// Position in [`ALL`].
    pub fn index(&self) -> usize {
        ALL.iter().position(|t| t == self).unwrap_or(0)
    }
}

/// A record type and the topic it is written on.
pub trait TopicRecord: Serialize + DeserializeOwned + JsonSchema {
    /// Its topic.
    const TOPIC: Topic;
}

/// The JSON Schema (draft 2020-12) of the record type `R`.
pub fn schema_of<R: TopicRecord>() -> serde_json::Value {
    serde_json::Value::from(schemars::schema_for!(R))
}
