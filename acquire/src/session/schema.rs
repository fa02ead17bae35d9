//! The session's topics and their JSON Schemas (docs/mcap-session.md). Every channel carries
//! `json` messages with a `jsonschema` schema, which Foxglove and the Python `mcap` reader decode.

use serde_json::{json, Value};

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
}

/// All topics, in channel-registration order.
pub const ALL: [Topic; 10] = [
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
        }
    }

    /// Position in [`ALL`].
    pub fn index(&self) -> usize {
        ALL.iter().position(|t| t == self).unwrap_or(0)
    }

    /// The JSON Schema (draft 2020-12) of this topic's messages.
    pub fn schema(&self) -> Value {
        let num = json!({"type": "number"});
        let int = json!({"type": "integer"});
        let s = json!({"type": "string"});
        let body = match self {
            Topic::Session => json!({
                "properties": {
                    "software": s, "started_unix_ns": int, "stand_file": s,
                    "plan": {"type": ["object", "null"]},
                    "resumed_from": {"type": ["string", "null"]},
                    "completed_steps_before": {"type": "array", "items": int}
                },
                "required": ["software", "started_unix_ns", "stand_file"]
            }),
            Topic::Stand => json!({
                "properties": {
                    "name": s, "file": s, "text": s,
                    "geometry": {"type": ["object", "null"], "description": "bodies the sensors are on (mass, inertia, position, rotation) and nominal_force_n, from the stand's [geometry] model"},
                    "channels": {"type": "array", "items": {"type": "object", "properties": {
                        "name": s, "device_channel": int, "kind": {"enum": ["force", "acceleration"]},
                        "sensitivity": {"type": "number", "description": "V/N or V/(m/s^2)"},
                        "body": {"type": ["string", "null"]},
                        "position_m": {"type": "array", "items": num},
                        "direction": {"type": "array", "items": num}
                    }}}
                },
                "required": ["name", "text", "channels"]
            }),
            Topic::Identity => json!({
                "properties": {"role": {"enum": ["shaker", "daq"]}, "port": s,
                    "manufacturer": s, "model": s, "serial": s, "firmware": s},
                "required": ["role", "port", "manufacturer", "model"]
            }),
            Topic::Raw => json!({
                "properties": {"port": s, "direction": {"enum": ["tx", "rx"]},
                    "data": {"type": "string", "contentEncoding": "base64"}},
                "required": ["port", "direction", "data"]
            }),
            Topic::DaqStream => json!({
                "properties": {"port": s, "sample_rate_hz": num, "samples_per_block": int,
                    "channels": {"type": "array", "items": {"type": "object", "properties": {
                        "device_channel": int, "volts_per_count": num}}},
                    "names": {"type": "array", "items": s}},
                "required": ["port", "sample_rate_hz", "samples_per_block", "channels"]
            }),
            Topic::DaqBlock => json!({
                "properties": {"seq": int, "first_sample": int, "sample_rate_hz": num,
                    "volts": {"type": "array", "description": "per channel, in /daq/stream order", "items": {"type": "array", "items": num}}},
                "required": ["seq", "first_sample", "volts"]
            }),
            Topic::DaqFault => json!({
                "properties": {"port": s, "kind": s, "seq": {"type": ["integer", "null"]}, "detail": s},
                "required": ["port", "kind", "detail"]
            }),
            Topic::SweepEvent => json!({
                "properties": {"kind": s, "step": {"type": ["integer", "null"]},
                    "frequency_hz": {"type": ["number", "null"]}, "detail": s},
                "required": ["kind", "detail"]
            }),
            Topic::SweepStep => json!({
                "properties": {
                    "step": int, "frequency_hz": num, "drive_n": num, "force_amplitude_n": num,
                    "first_sample": int, "samples": int, "iterations": int,
                    "channels": {"type": "array", "items": {"type": "object", "properties": {
                        "name": s, "amplitude": num, "phase_rad": num,
                        "frf_re": num, "frf_im": num, "fit_quality": num,
                        "noise_rms": num, "frf_variance": num}}}
                },
                "required": ["step", "frequency_hz", "force_amplitude_n", "channels"]
            }),
            Topic::SweepBroadband => json!({
                "properties": {
                    "waveform": {"type": "object"}, "force_n": num, "averages": int, "stopped": {"type": "boolean"},
                    "freqs_hz": {"type": "array", "items": num},
                    "channels": {"type": "array", "items": {"type": "object", "properties": {
                        "name": s,
                        "h1_re": {"type": "array", "items": num, "description": "per N"},
                        "h1_im": {"type": "array", "items": num},
                        "coherence": {"type": "array", "items": num}}}}
                },
                "required": ["freqs_hz", "channels", "averages"]
            }),
        };
        let mut v = body;
        if let Some(o) = v.as_object_mut() {
            o.insert(
                "$schema".into(),
                json!("https://json-schema.org/draft/2020-12/schema"),
            );
            o.insert("title".into(), json!(self.schema_name()));
            o.insert("type".into(), json!("object"));
        }
        v
    }
}
