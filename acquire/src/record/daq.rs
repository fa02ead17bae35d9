//! `/raw`, `/daq/stream`, `/daq/block`, `/daq/fault`: every byte moved on a device port and the
//! DAQ's stream as it was announced, decoded and faulted.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::topic::{Topic, TopicRecord};

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

/// Which way bytes travelled, seen from the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    /// Host to device.
    Tx,
    /// Device to host.
    Rx,
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

/// One channel as the device announces it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ChannelInfo {
    /// Device channel number (the stand file's `device_channel`).
    pub device_channel: u16,
    /// Volts per ADC count: a block's value is `count · volts_per_count` (V).
    pub volts_per_count: f64,
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

impl TopicRecord for FaultRecord {
    const TOPIC: Topic = Topic::DaqFault;
}
