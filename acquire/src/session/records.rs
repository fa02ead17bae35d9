//! The session's records: one serde type per topic, used by the writers (the sweep, the rig, the
//! byte tap) and by the readers (processing, replay, resume). The channel schemas recorded in
//! every session file are generated from these types ([`Topic::schema`], `schemars`), and
//! docs/mcap-session.md shows the same schemas (a test compares them), so a field renamed in one
//! place cannot silently break replay.
//!
//! Versions: `/session` carries [`SessionStart::version`]. Version 1 (sessions recorded before the
//! field existed) reads with it absent; fields added since are optional or have defaults, so an
//! old session reads unchanged (`acquire/tests/fixtures/session-v1.mcap`).

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::schema::Topic;
use crate::daq::ChannelInfo;
use crate::shaker::Waveform;
use crate::stand::{Channel, Geometry};
use crate::sweep::StepResult;
use crate::transport::Direction;

/// The record version this code writes in `/session`.
pub const VERSION: u32 = 2;

/// A record type and the topic it is written on.
pub trait TopicRecord: Serialize + DeserializeOwned + JsonSchema {
    /// Its topic.
    const TOPIC: Topic;
}

fn version_1() -> u32 {
    1
}

/// `/session`: what started the recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Session")]
pub struct SessionStart {
    /// Record version ([`VERSION`]); absent (1) in sessions recorded before it existed.
    #[serde(default = "version_1")]
    pub version: u32,
    /// Writing software and its version.
    pub software: String,
    /// Start time (ns since the Unix epoch).
    pub started_unix_ns: u64,
    /// The stand file's path as given.
    pub stand_file: String,
    /// The sweep plan (stepped sine or broadband) as its own serde form.
    #[serde(default)]
    pub plan: Option<serde_json::Value>,
    /// The earlier session a resumed sweep continues.
    #[serde(default)]
    pub resumed_from: Option<String>,
    /// Steps that earlier session completed (not measured again).
    #[serde(default)]
    pub completed_steps_before: Vec<usize>,
}

impl TopicRecord for SessionStart {
    const TOPIC: Topic = Topic::Session;
}

/// `/stand`: the stand file verbatim and what it resolved to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Stand")]
pub struct StandRecord {
    /// Stand name.
    pub name: String,
    /// The stand file's path as given.
    #[serde(default)]
    pub file: String,
    /// The stand file's text.
    pub text: String,
    /// The resolved channel map (sensitivity V/N or V/(m/s²), positions m, directions unit).
    pub channels: Vec<Channel>,
    /// Bodies the sensors are on, from the stand's `[geometry]` model (absent without one).
    #[serde(default)]
    pub geometry: Option<Geometry>,
}

impl TopicRecord for StandRecord {
    const TOPIC: Topic = Topic::Stand;
}

/// Which device an identity belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// The exciter's controller.
    Shaker,
    /// The data acquisition unit.
    Daq,
}

/// `/device/identity`: one device's identity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.DeviceIdentity")]
pub struct DeviceIdentityRecord {
    /// Which device.
    pub role: Role,
    /// Its port.
    pub port: String,
    /// Manufacturer.
    pub manufacturer: String,
    /// Model.
    pub model: String,
    /// Serial number.
    #[serde(default)]
    pub serial: String,
    /// Firmware version.
    #[serde(default)]
    pub firmware: String,
}

impl TopicRecord for DeviceIdentityRecord {
    const TOPIC: Topic = Topic::Identity;
}

/// `/raw`: bytes moved on a device port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.RawBytes")]
pub struct RawBytes {
    /// The port.
    pub port: String,
    /// `tx` host → device, `rx` device → host.
    pub direction: Direction,
    /// The bytes, base64.
    #[schemars(extend("contentEncoding" = "base64"))]
    pub data: String,
}

impl TopicRecord for RawBytes {
    const TOPIC: Topic = Topic::Raw;
}

/// `/daq/stream`: the DAQ's announcement of its stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.DaqStream")]
pub struct DaqStreamRecord {
    /// The DAQ's port.
    pub port: String,
    /// Actual sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Samples per channel in each block.
    pub samples_per_block: u16,
    /// Channels in block order.
    pub channels: Vec<ChannelInfo>,
    /// The stand's channel names in block order.
    #[serde(default)]
    pub names: Option<Vec<String>>,
}

impl TopicRecord for DaqStreamRecord {
    const TOPIC: Topic = Topic::DaqStream;
}

/// `/daq/block`: a good block of samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SampleBlock")]
pub struct BlockRecord {
    /// Block number since the stream's start.
    pub seq: u64,
    /// Index of the block's first sample since the stream's start.
    pub first_sample: u64,
    /// Sample rate (Hz).
    #[serde(default)]
    pub sample_rate_hz: Option<f64>,
    /// Volts per channel (in `/daq/stream` order), per sample.
    pub volts: Vec<Vec<f32>>,
}

impl TopicRecord for BlockRecord {
    const TOPIC: Topic = Topic::DaqBlock;
}

/// `/daq/fault`: a stream fault (gap, CRC, framing, duplicate, out of order, device, bus).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.StreamFault")]
pub struct FaultRecord {
    /// The DAQ's port.
    pub port: String,
    /// `gap`, `crc`, `framing`, `duplicate`, `out_of_order`, `device` or `bus`.
    pub kind: String,
    /// The block number concerned, when known.
    #[serde(default)]
    pub seq: Option<u64>,
    /// What happened.
    pub detail: String,
}

impl FaultRecord {
    /// The record of fault `f` on the DAQ at `port`.
    pub fn of(port: &str, f: &crate::daq::StreamFault) -> FaultRecord {
        FaultRecord {
            port: port.to_string(),
            kind: f.kind.as_str().to_string(),
            seq: f.seq,
            detail: f.detail.clone(),
        }
    }
}

impl TopicRecord for FaultRecord {
    const TOPIC: Topic = Topic::DaqFault;
}

/// `/sweep/event`: sweep progress and problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SweepEvent")]
pub struct SweepEvent {
    /// `started`, `step_started`, `force_control`, `retry`, `warning`, `step_completed`,
    /// `average`, `stopped`, `completed` or `error`.
    pub kind: String,
    /// The step concerned.
    #[serde(default)]
    pub step: Option<usize>,
    /// Its frequency (Hz).
    #[serde(default)]
    pub frequency_hz: Option<f64>,
    /// What happened.
    pub detail: String,
}

impl TopicRecord for SweepEvent {
    const TOPIC: Topic = Topic::SweepEvent;
}

impl TopicRecord for StepResult {
    const TOPIC: Topic = Topic::SweepStep;
}

/// One channel of a broadband measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BroadbandChannel {
    /// Channel name.
    pub name: String,
    /// H1 real part per line (per N).
    pub h1_re: Vec<f64>,
    /// H1 imaginary part per line (per N).
    pub h1_im: Vec<f64>,
    /// Ordinary coherence with the force per line (0-1).
    pub coherence: Vec<f64>,
}

/// `/sweep/broadband`: a broadband measurement's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SweepBroadband")]
pub struct BroadbandRecord {
    /// The drive.
    pub waveform: Waveform,
    /// Force: RMS for random/burst, peak for chirp (N).
    pub force_n: f64,
    /// Periods averaged.
    pub averages: u32,
    /// True when the operator stopped it early.
    #[serde(default)]
    pub stopped: bool,
    /// Frequency lines (Hz).
    pub freqs_hz: Vec<f64>,
    /// Per channel, stand order.
    pub channels: Vec<BroadbandChannel>,
}

impl TopicRecord for BroadbandRecord {
    const TOPIC: Topic = Topic::SweepBroadband;
}

/// What a `/drive` record reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DriveKind {
    /// A frequency sent to the signal generator.
    Frequency,
    /// An amplitude sent to the signal generator (a ramp increment or a force-loop correction).
    Amplitude,
    /// The generator's output switched on or off.
    Output,
    /// The force amplitude the DAQ measured with the drive then set (for a broadband drive:
    /// the RMS over one period, `step` = the period).
    Measurement,
    /// An arbitrary waveform uploaded and selected (broadband drive): `waveform`,
    /// `sample_rate_hz`, `seed` and the DAC `codes` sent.
    Waveform,
}

/// `/drive`: every setting sent to a signal generator that drives the shaker through a power
/// amplifier, and every force the closed loop measured (stands with `[generator]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Drive")]
pub struct DriveRecord {
    /// What happened.
    pub kind: DriveKind,
    /// The generator's port.
    pub port: String,
    /// Sweep step, for measurements.
    #[serde(default)]
    pub step: Option<usize>,
    /// Sine frequency then set (Hz).
    pub frequency_hz: f64,
    /// Generator amplitude then set (V peak).
    pub volts_peak: f64,
    /// Output on after this record.
    pub output_on: bool,
    /// Force amplitude measured on the DAQ's force channel (N peak), for measurements.
    #[serde(default)]
    pub force_n: Option<f64>,
    /// Force amplitude the sweep holds (N peak), for measurements.
    #[serde(default)]
    pub target_n: Option<f64>,
    /// Generator settings sent since this frequency was set (this one included).
    pub settings_this_line: u32,
    /// The broadband drive the uploaded waveform makes (kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waveform: Option<Waveform>,
    /// Rate the uploaded points are played at (Sa/s; kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_rate_hz: Option<f64>,
    /// Seed of the random phases (kind `waveform`, random and burst random).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The DAC codes uploaded, one period, in the model's code range (kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub codes: Option<Vec<i32>>,
    /// The DAC codes of negative and positive full scale (kind `waveform`): code `c` is
    /// `volts_peak × (2c − min − max) / (max − min)` volts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code_range: Option<(i32, i32)>,
}

impl TopicRecord for DriveRecord {
    const TOPIC: Topic = Topic::Drive;
}

/// The JSON Schema (draft 2020-12) of the record type `R`.
pub fn schema_of<R: TopicRecord>() -> serde_json::Value {
    serde_json::Value::from(schemars::schema_for!(R))
}

/// The schemas of every topic as the Markdown section of docs/mcap-session.md between its
/// `generated schemas` markers (`IDENT_BLESS=1 cargo test -p acquire --test session_records`
/// rewrites it).
pub fn schemas_markdown() -> String {
    let mut out = String::new();
    for t in super::schema::ALL {
        let pretty = serde_json::to_string_pretty(&t.schema()).unwrap_or_default();
        out.push_str(&format!(
            "### `{}` (`{}`)\n\n```json\n{pretty}\n```\n\n",
            t.name(),
            t.schema_name()
        ));
    }
    out
}
