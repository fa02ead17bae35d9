//! Where the stand's devices are and how to reach them: the exciter's and the DAQ's ports, link
//! settings and expected identities.

use std::time::Duration;

use serde::Serialize;

/// Where a device is.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PortSpec {
    /// `"sim"`: served by the simulated stand.
    Sim,
    /// A device path such as `/dev/ttyUSB0`.
    Path(String),
    /// `"can:IFACE"`: the DAQ on a SocketCAN interface (docs/daq-can.md).
    Can(String),
}

/// Shaker-controller settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShakerPort {
    /// Port.
    pub port: PortSpec,
    /// Baud rate (bit/s).
    pub baud: u32,
    /// Expected identity `manufacturer,model` (empty: accept any).
    pub identity: String,
    /// Answer timeout.
    pub timeout: Duration,
    /// Retries after a timeout.
    pub retries: u32,
    /// Largest force the sweep may command (N).
    pub max_force_n: f64,
}

/// DAQ settings.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DaqPort {
    /// Port.
    pub port: PortSpec,
    /// Baud rate (bit/s).
    pub baud: u32,
    /// Expected identity `manufacturer,model` (empty: accept any).
    pub identity: String,
    /// Number of analog inputs the DAQ has (`daq.inputs`), when the stand file says; every
    /// channel's `device_channel` is then below it.
    pub inputs: Option<u16>,
    /// Requested sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Samples per channel per block.
    pub samples_per_block: u16,
    /// Command timeout.
    pub timeout: Duration,
    /// Retries after a timeout.
    pub retries: u32,
    /// The inputs' range (V, ±): a force sample at [`CLIP_FRACTION`](super::CLIP_FRACTION) of it or beyond is a clipped
    /// force signal, which stops a sweep (`daq.input_range`, default 10 V).
    pub input_range_v: f64,
    /// Identifiers and frames when the DAQ is on CAN (`[daq.can]`).
    pub can: crate::can::CanDaqSettings,
    /// The DAQ is a CANopen node (`[daq.canopen]`, docs/canopen.md) rather than the DAQ-over-CAN
    /// protocol of docs/daq-can.md.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub canopen: Option<super::canopen::CanOpenPort>,
}
