//! The host driver for the serial DAQ protocol (docs/daq-serial.md): a thin tokio wrapper around
//! the I/O-free [`frame`](super::frame) codec.

use std::collections::VecDeque;
use std::time::Duration;

use async_trait::async_trait;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

use super::frame::{kind, unwrap_seq, FrameDecoder, FrameError, Message};
use super::{Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock, StreamFault, StreamInfo};
use crate::device::DeviceIdentity;
use crate::transport::Transport;

/// Timeouts and retries of the serial DAQ driver.
#[derive(Debug, Clone, PartialEq)]
pub struct DaqOptions {
    /// How long to wait for the answer to a command before re-sending it.
    pub command_timeout: Duration,
    /// How many times a command is re-sent after a timeout.
    pub retries: u32,
    /// How long the stream may be silent before [`DaqError::Timeout`]; at least four block periods
    /// are always allowed.
    pub data_timeout: Duration,
}

impl Default for DaqOptions {
    fn default() -> Self {
        DaqOptions {
            command_timeout: Duration::from_millis(500),
            retries: 2,
            data_timeout: Duration::from_millis(1000),
        }
    }
}

/// A DAQ speaking the serial protocol over any [`Transport`].
pub struct SerialDaq<T: Transport = Box<dyn Transport>> {
    io: T,
    port: String,
    opts: DaqOptions,
    dec: FrameDecoder,
    rx: Vec<u8>,
    state: StreamState,
    tx: Vec<u8>,
    s1: Vec<u8>,
    s2: Vec<u8>,
    next_request: u32,
}

#[derive(Default)]
struct StreamState {
    events: VecDeque<DaqEvent>,
    replies: VecDeque<(u32, Message)>,
    info: Option<StreamInfo>,
    streaming: bool,
    expected: u64,
    /// Bytes that did not decode as frames since the last command was sent.
    undecodable: usize,
    /// Frames decoded since the last command was sent.
    decoded: usize,
}

impl<T: Transport> SerialDaq<T> {
    /// A driver over `io`. Nothing is sent until the first call.
    pub fn new(io: T, opts: DaqOptions) -> Self {
        let port = io.port().to_string();
        SerialDaq {
            io,
            port,
            opts,
            dec: FrameDecoder::new(),
            rx: vec![0; 16384],
            state: StreamState::default(),
            tx: Vec::with_capacity(4200),
            s1: Vec::with_capacity(4200),
            s2: Vec::with_capacity(4200),
            next_request: 1,
        }
    }

    /// The stream announced by the last successful configure.
    pub fn stream_info(&self) -> Option<&StreamInfo> {
        self.state.info.as_ref()
    }

    /// Reads once (bounded by `deadline`) and decodes what arrived.
    async fn fill(&mut self, deadline: Instant, what: &str) -> Result<(), DaqError> {
        let n = match tokio::time::timeout_at(deadline, self.io.read(&mut self.rx)).await {
            Err(_) => {
                // Bytes that never decoded point at the wrong device or baud rate; a frame
                // begun but not finished is a device (or a simulator) that stopped mid-frame.
                let junk = self.state.undecodable;
                let cut = self.dec.pending();
                let extra = match (junk, cut) {
                    (0, 0) => String::new(),
                    (0, cut) if self.state.decoded > 0 => format!(" (the last frame stopped after {cut} bytes: the device stopped sending mid-frame; a simulated stand whose host is too busy does that)"),
                    (junk, cut) => format!(" (received {} bytes that are not DAQ frames: wrong device or baud rate?)", junk + cut),
                };
                return Err(DaqError::Timeout {
                    port: self.port.clone(),
                    what: format!("{what}{extra}"),
                    waited: Duration::ZERO,
                });
            }
            Ok(Err(e)) => return Err(DaqError::from_io(&self.port, e)),
            Ok(Ok(0)) => {
                return Err(DaqError::Disconnected {
                    port: self.port.clone(),
                    detail: "end of stream".into(),
                })
            }
            Ok(Ok(n)) => n,
        };
        let state = &mut self.state;
        self.dec.feed(&self.rx[..n], |f| match f {
            Err(e) => state.frame_error(e),
            Ok(f) => {
                state.decoded += 1;
                match Message::parse(&f) {
                    Err(e) => state.fault(FaultKind::Framing, None, e.to_string()),
                    Ok(Message::Data(counts)) => state.data(f.seq, counts),
                    Ok(Message::Status { code, message }) => state.fault(
                        FaultKind::Device,
                        None,
                        format!("device status {code}: {message}"),
                    ),
                    Ok(m) => state.replies.push_back((f.seq, m)),
                }
            }
        });
        Ok(())
    }

    /// Sends a command and waits for its answer, re-sending after a timeout.
    async fn command(&mut self, msg: Message, name: &str) -> Result<Message, DaqError> {
        let mut last_timeout = None;
        for _attempt in 0..=self.opts.retries {
            let id = self.next_request;
            self.next_request = self.next_request.wrapping_add(1);
            self.tx.clear();
            msg.encode(id, &mut self.s1, &mut self.s2, &mut self.tx);
            self.state.undecodable = 0;
            self.state.decoded = 0;
            self.io
                .write_all(&self.tx)
                .await
                .map_err(|e| DaqError::from_io(&self.port, e))?;
            self.io
                .flush()
                .await
                .map_err(|e| DaqError::from_io(&self.port, e))?;
            let deadline = Instant::now() + self.opts.command_timeout;
            loop {
                if let Some(pos) = self.state.replies.iter().position(|(s, _)| *s == id) {
                    let reply = self.state.replies.remove(pos).map(|(_, m)| m);
                    self.state.replies.clear(); // stale answers to earlier attempts
                    return match reply {
                        Some(Message::Nak { code, message, .. }) => Err(DaqError::Rejected {
                            port: self.port.clone(),
                            command: name.to_string(),
                            code: code as i32,
                            message,
                        }),
                        Some(m) => Ok(m),
                        None => continue,
                    };
                }
                match self.fill(deadline, &format!("answer to {name}")).await {
                    Ok(()) => {}
                    Err(DaqError::Timeout { port, what, .. }) => {
                        last_timeout = Some(DaqError::Timeout {
                            port,
                            what: format!("{what} after {} attempt(s)", self.opts.retries + 1),
                            waited: self.opts.command_timeout,
                        });
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
        }
        Err(last_timeout.unwrap_or(DaqError::Timeout {
            port: self.port.clone(),
            what: format!("answer to {name}"),
            waited: self.opts.command_timeout,
        }))
    }

    fn unexpected(&self, command: &str, got: &Message) -> DaqError {
        DaqError::Protocol {
            port: self.port.clone(),
            command: command.to_string(),
            detail: format!("{got:?}"),
        }
    }

    fn data_timeout(&self) -> Duration {
        let block = self
            .state
            .info
            .as_ref()
            .map(|i| {
                Duration::from_secs_f64(
                    4.0 * i.samples_per_block as f64 / i.sample_rate_hz.max(1e-3),
                )
            })
            .unwrap_or_default();
        self.opts.data_timeout.max(block)
    }
}

impl StreamState {
    fn fault(&mut self, kind: FaultKind, seq: Option<u64>, detail: String) {
        self.events
            .push_back(DaqEvent::Fault(StreamFault { kind, seq, detail }));
    }

    fn frame_error(&mut self, e: FrameError) {
        let kind = match e {
            FrameError::Crc { .. } => FaultKind::Crc,
            _ => FaultKind::Framing,
        };
        if let FrameError::Cobs { len } | FrameError::Short { len } = e {
            self.undecodable += len;
        }
        if let FrameError::Oversize = e {
            self.undecodable += super::frame::MAX_FRAME;
        }
        self.fault(kind, None, e.to_string());
    }

    fn data(&mut self, raw_seq: u32, counts: Vec<i32>) {
        let Some(info) = self.info.clone() else {
            self.fault(
                FaultKind::Framing,
                None,
                "data frame before any stream announcement".into(),
            );
            return;
        };
        if !self.streaming {
            return; // in flight after STOP; documented as discarded (the byte log keeps it)
        }
        let n = info.channels.len();
        let spb = info.samples_per_block as usize;
        if counts.len() != n * spb {
            self.fault(
                FaultKind::Framing,
                None,
                format!(
                    "data frame with {} samples; the announcement says {} channels × {} samples",
                    counts.len(),
                    n,
                    spb
                ),
            );
            return;
        }
        let seq = unwrap_seq(self.expected, raw_seq);
        if seq < self.expected {
            let kind = if seq + 1 == self.expected {
                FaultKind::Duplicate
            } else {
                FaultKind::OutOfOrder
            };
            self.fault(
                kind,
                Some(seq),
                format!("block {seq} received again (expected {})", self.expected),
            );
            return;
        }
        if seq > self.expected {
            let lost = seq - self.expected;
            self.fault(
                FaultKind::Gap,
                Some(self.expected),
                format!(
                    "blocks {}..={} missing ({} blocks, {} samples per channel)",
                    self.expected,
                    seq - 1,
                    lost,
                    lost * spb as u64
                ),
            );
        }
        let volts = counts
            .iter()
            .enumerate()
            .map(|(i, &c)| (c as f64 * info.channels[i % n].volts_per_count) as f32)
            .collect();
        self.events.push_back(DaqEvent::Block(SampleBlock {
            seq,
            first_sample: seq * spb as u64,
            channel_count: n as u16,
            volts,
        }));
        self.expected = seq + 1;
    }
}

#[async_trait]
impl<T: Transport> Daq for SerialDaq<T> {
    fn port(&self) -> &str {
        &self.port
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, DaqError> {
        match self.command(Message::Hello, "HELLO").await? {
            Message::Identity(s) => {
                DeviceIdentity::parse_idn(&s).ok_or_else(|| DaqError::Protocol {
                    port: self.port.clone(),
                    command: "HELLO".into(),
                    detail: format!("identity `{s}` is not `manufacturer,model,serial,firmware`"),
                })
            }
            other => Err(self.unexpected("HELLO", &other)),
        }
    }

    async fn configure(&mut self, config: &DaqConfig) -> Result<StreamInfo, DaqError> {
        if config.channels.is_empty()
            || config.channels.len() > 255
            || config.samples_per_block == 0
        {
            return Err(DaqError::Announcement {
                port: self.port.clone(),
                detail: format!("requested {} channels and {} samples per block; need 1-255 channels and ≥ 1 sample", config.channels.len(), config.samples_per_block),
            });
        }
        self.state.streaming = false;
        match self
            .command(Message::Configure(config.clone()), "CONFIGURE")
            .await?
        {
            Message::Announce(info) => {
                let got = info.device_channels();
                if got != config.channels || info.samples_per_block != config.samples_per_block {
                    return Err(DaqError::Announcement {
                        port: self.port.clone(),
                        detail: format!(
                            "asked channels {:?} × {} samples, device announces {:?} × {}",
                            config.channels, config.samples_per_block, got, info.samples_per_block
                        ),
                    });
                }
                if !(info.sample_rate_hz.is_finite() && info.sample_rate_hz > 0.0) {
                    return Err(DaqError::Announcement {
                        port: self.port.clone(),
                        detail: format!("announced sample rate {} Hz", info.sample_rate_hz),
                    });
                }
                self.state.info = Some(info.clone());
                Ok(info)
            }
            other => Err(self.unexpected("CONFIGURE", &other)),
        }
    }

    async fn start(&mut self) -> Result<(), DaqError> {
        if self.state.info.is_none() {
            return Err(DaqError::State {
                port: self.port.clone(),
                detail: "start before configure".into(),
            });
        }
        self.state.expected = 0;
        // Data may follow the ACK in the same read: accept it from now on.
        self.state.streaming = true;
        match self.command(Message::Start, "START").await {
            Ok(Message::Ack(k)) if k == kind::START => Ok(()),
            Ok(other) => {
                self.state.streaming = false;
                Err(self.unexpected("START", &other))
            }
            Err(e) => {
                self.state.streaming = false;
                Err(e)
            }
        }
    }

    async fn next_event(&mut self) -> Result<DaqEvent, DaqError> {
        loop {
            if let Some(e) = self.state.events.pop_front() {
                return Ok(e);
            }
            if !self.state.streaming {
                return Err(DaqError::State {
                    port: self.port.clone(),
                    detail: "next_event while not streaming".into(),
                });
            }
            let waited = self.data_timeout();
            match self.fill(Instant::now() + waited, "sample data").await {
                Ok(()) => {}
                Err(DaqError::Timeout { port, what, .. }) => {
                    return Err(DaqError::Timeout { port, what, waited })
                }
                Err(e) => return Err(e),
            }
        }
    }

    async fn stop(&mut self) -> Result<(), DaqError> {
        self.state.streaming = false;
        let r = self.command(Message::Stop, "STOP").await;
        // Blocks still queued belong to the stopped stream; faults are kept for the caller.
        self.state
            .events
            .retain(|e| matches!(e, DaqEvent::Fault(_)));
        match r? {
            Message::Ack(k) if k == kind::STOP => Ok(()),
            other => Err(self.unexpected("STOP", &other)),
        }
    }
}
