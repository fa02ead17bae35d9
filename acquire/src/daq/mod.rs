//! The accelerometer DAQ seam: what a sweep needs from any data-acquisition unit (serial, CAN,
//! simulated), the sample blocks it delivers and the stream faults it reports.
//!
//! A DAQ is driven as: [`Daq::identify`] → [`Daq::configure`] (the device answers with its
//! [`StreamInfo`] announcement: actual sample rate and channel map) → [`Daq::start`] → repeated
//! [`Daq::next_event`] → [`Daq::stop`]. Faults on the stream (lost, corrupted, duplicated frames)
//! are *events*, returned in order with the blocks, so that the caller records every one of them;
//! only conditions that end the stream (timeout, unplugged cable, device refusing a command) are
//! errors.

pub mod frame;
pub mod serial;

pub use serial::{DaqOptions, SerialDaq};

use std::time::Duration;

use async_trait::async_trait;
use serde::{Deserialize, Serialize};

use crate::device::DeviceIdentity;
pub use crate::record::ChannelInfo;
use crate::record::FaultRecord;

/// A data-acquisition unit streaming simultaneously sampled channels (accelerometers and the
/// force transducer).
///
/// Object safe; a sweep holds a `Box<dyn Daq>`. Every method is bounded by the implementation's
/// timeout: none waits forever.
#[async_trait]
pub trait Daq: Send {
    /// Where the device is connected (`/dev/ttyUSB1`, `can0`), for messages and records.
    fn port(&self) -> &str;

    /// Asks the device who it is.
    async fn identify(&mut self) -> Result<DeviceIdentity, DaqError>;

    /// Configures sample rate, channel list and block size. The device answers with what it will
    /// actually stream (its rate may differ from the request); the stream is stopped afterwards.
    async fn configure(&mut self, config: &DaqConfig) -> Result<StreamInfo, DaqError>;

    /// Starts streaming. Block sequence numbers and sample indices restart at 0.
    async fn start(&mut self) -> Result<(), DaqError>;

    /// The next block or stream fault, in stream order. Errors end the stream.
    async fn next_event(&mut self) -> Result<DaqEvent, DaqError>;

    /// Stops streaming and discards what is still in flight (each discarded frame is still decoded
    /// and recorded by the implementation's byte tap, if any).
    async fn stop(&mut self) -> Result<(), DaqError>;

    /// The index of the next sample the device will take, where the host paces the sampling (a
    /// CANopen master producing SYNC) or reads the device's own count (the simulated DAQ in the
    /// same process, [`crate::sim::clock`]): every sample from it on is taken after now. `None`
    /// where the device's own clock paces it unseen; the sweep then reckons from wall-clock time
    /// since START.
    fn sample_clock(&self) -> Option<u64> {
        None
    }
}

/// Reads a started stream to its end: every block and fault in stream order, then the error
/// that ended it (a lost device, a timeout).
pub async fn events_until_error(daq: &mut dyn Daq) -> (Vec<DaqEvent>, DaqError) {
    let mut events = Vec::new();
    loop {
        match daq.next_event().await {
            Ok(ev) => events.push(ev),
            Err(e) => return (events, e),
        }
    }
}

/// What the host asks the DAQ to stream.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DaqConfig {
    /// Requested sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Device channel numbers to stream, in this order.
    pub channels: Vec<u16>,
    /// Samples per channel in each block (≥ 1).
    pub samples_per_block: u16,
}

/// The device's announcement of the stream it will send (answer to configure).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StreamInfo {
    /// Actual sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Channels in block order.
    pub channels: Vec<ChannelInfo>,
    /// Samples per channel in each block.
    pub samples_per_block: u16,
}

impl StreamInfo {
    /// The announced channels' device numbers in block order: what a configure request's
    /// [`DaqConfig::channels`] must equal.
    pub fn device_channels(&self) -> Vec<u16> {
        self.channels.iter().map(|c| c.device_channel).collect()
    }
}

/// A block of simultaneously sampled channels.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleBlock {
    /// Block number since [`Daq::start`] (0, 1, 2, …), unwrapped from the device's frame counter.
    /// A jump means lost blocks; a [`FaultKind::Gap`] event precedes the block.
    pub seq: u64,
    /// Index of the block's first sample since start: `seq · samples_per_block`, so the time of
    /// sample `i` is `(first_sample + i) / sample_rate_hz` (s).
    pub first_sample: u64,
    /// Number of channels (the stride of `volts`).
    pub channel_count: u16,
    /// Samples in volts, interleaved sample-major: `volts[i · channel_count + c]`.
    pub volts: Vec<f32>,
}

impl SampleBlock {
    /// Samples per channel in this block.
    pub fn len(&self) -> usize {
        match self.channel_count {
            0 => 0,
            n => self.volts.len() / n as usize,
        }
    }

    /// True if the block holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Iterator over channel `c`'s samples (V).
    pub fn channel(&self, c: usize) -> impl Iterator<Item = f32> + '_ {
        self.volts
            .iter()
            .skip(c)
            .step_by(self.channel_count.max(1) as usize)
            .copied()
    }
}

/// What a DAQ delivers, in stream order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DaqEvent {
    /// A good block.
    Block(SampleBlock),
    /// Something was wrong on the stream; the data it concerns is lost (or, for duplicates, ignored).
    Fault(StreamFault),
}

impl DaqEvent {
    /// The detail of a device fault (a lost node, an EMCY, an instrument error), else `None`.
    pub fn device_fault(&self) -> Option<&str> {
        match self {
            DaqEvent::Fault(f) if f.kind == FaultKind::Device => Some(&f.detail),
            _ => None,
        }
    }
}

/// A detected stream fault. Recorded in the session; never silently dropped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StreamFault {
    /// What happened.
    pub kind: FaultKind,
    /// Block number the fault concerns, if known.
    pub seq: Option<u64>,
    /// Human-readable detail (which bytes, expected vs got).
    pub detail: String,
}

// Defined here rather than with the record so that the records depend on nothing above them.
impl FaultRecord {
    /// The record of fault `f` on the DAQ at `port`.
    pub fn of(port: &str, f: &StreamFault) -> FaultRecord {
        FaultRecord {
            port: port.to_string(),
            kind: f.kind.as_str().to_string(),
            seq: f.seq,
            detail: f.detail.clone(),
        }
    }
}

/// Kinds of stream faults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum FaultKind {
    /// Blocks are missing: the sequence counter jumped.
    Gap,
    /// A frame failed its CRC.
    Crc,
    /// A frame could not be decoded (bad COBS, wrong length, unknown type, oversize).
    Framing,
    /// A block arrived twice (same sequence number); the copy was discarded.
    Duplicate,
    /// A block arrived with an older sequence number than one already delivered; discarded.
    OutOfOrder,
    /// The device reported an internal problem (ADC overrun, buffer overflow) in-band.
    Device,
    /// A bus-level error (CAN error frame, error-passive) — used by bus transports.
    Bus,
}

impl FaultKind {
    /// The name used in session records: `gap`, `crc`, ….
    pub fn as_str(&self) -> &'static str {
        match self {
            FaultKind::Gap => "gap",
            FaultKind::Crc => "crc",
            FaultKind::Framing => "framing",
            FaultKind::Duplicate => "duplicate",
            FaultKind::OutOfOrder => "out_of_order",
            FaultKind::Device => "device",
            FaultKind::Bus => "bus",
        }
    }
}

/// Errors that end a DAQ operation. Each names the port and says what to check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DaqError {
    /// The transport could not be opened.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// Reading or writing failed.
    #[error("DAQ on {port}: I/O error: {source}; check the cable and that the device is powered")]
    Io {
        /// Port.
        port: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The device went away (end of stream / hang-up): cable pulled or device reset.
    #[error("DAQ on {port}: connection lost ({detail}); check the cable and the device's power, then resume the sweep")]
    Disconnected {
        /// Port.
        port: String,
        /// What was seen.
        detail: String,
    },
    /// No answer or no data within the timeout.
    #[error("DAQ on {port}: no {what} within {waited:?}; check that the device is powered, the baud rate and that `port` is the DAQ, not another device")]
    Timeout {
        /// Port.
        port: String,
        /// What was awaited.
        what: String,
        /// How long.
        waited: Duration,
    },
    /// The device answered something that is not this protocol.
    #[error("DAQ on {port}: unexpected answer to {command}: {detail}; is `port` really the DAQ?")]
    Protocol {
        /// Port.
        port: String,
        /// Command that was sent.
        command: String,
        /// What came back.
        detail: String,
    },
    /// The device identified itself as something else than the stand file expects.
    #[error("DAQ on {port}: identifies as `{got}`, stand file expects `{expected}`; check which device is on this port")]
    WrongIdentity {
        /// Port.
        port: String,
        /// Identity received.
        got: String,
        /// Identity expected.
        expected: String,
    },
    /// The device refused a command (NAK with a code and message).
    #[error("DAQ on {port}: refused {command}: error {code}: {message}")]
    Rejected {
        /// Port.
        port: String,
        /// Command.
        command: String,
        /// Device error code.
        code: i32,
        /// Device message.
        message: String,
    },
    /// The announced stream does not match what was requested (channel map or block size).
    #[error("DAQ on {port}: announced stream does not match the request: {detail}; check `device_channel` numbers in the stand file against the device's channel count")]
    Announcement {
        /// Port.
        port: String,
        /// Mismatch.
        detail: String,
    },
    /// A bus-level failure that ends the stream (e.g. CAN bus-off).
    #[error("DAQ on {port}: bus failure: {detail}")]
    Bus {
        /// Interface.
        port: String,
        /// What happened.
        detail: String,
    },
    /// An operation was attempted in the wrong state (e.g. next_event before start).
    #[error("DAQ on {port}: {detail}")]
    State {
        /// Port.
        port: String,
        /// What was wrong.
        detail: String,
    },
}

impl DaqError {
    /// Maps an I/O error on `port`: end-of-stream and hang-up become [`DaqError::Disconnected`].
    pub fn from_io(port: &str, e: std::io::Error) -> DaqError {
        use std::io::ErrorKind as K;
        match e.kind() {
            K::UnexpectedEof
            | K::BrokenPipe
            | K::ConnectionReset
            | K::ConnectionAborted
            | K::NotConnected => DaqError::Disconnected {
                port: port.to_string(),
                detail: e.to_string(),
            },
            _ if e.raw_os_error() == Some(5) => {
                // EIO: a serial adapter or pty whose other end has gone.
                DaqError::Disconnected {
                    port: port.to_string(),
                    detail: e.to_string(),
                }
            }
            _ => DaqError::Io {
                port: port.to_string(),
                source: e,
            },
        }
    }
}
