//! The accelerometer DAQ over CAN: a [`Daq`] that speaks docs/daq-can.md on a SocketCAN interface.

use std::collections::VecDeque;
use std::time::Duration;

use async_trait::async_trait;

use crate::can::codec::{kind, Message, Reassembler, SegmentFault, Segmenter, WireBlock};
use crate::can::{BusEvent, CanBus, CanError, CanId, FrameKind, WireFrame};
use crate::daq::{
    ChannelInfo, Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock, StreamFault,
    StreamInfo,
};
use crate::device::DeviceIdentity;
use crate::transport::{ByteTap, Direction};

/// Identifiers, frame kind and timeouts of a CAN DAQ (the stand file's `can` section).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CanDaqSettings {
    /// Host → DAQ commands (default standard 0x100).
    pub command_id: CanId,
    /// DAQ → host answers and announcements (default 0x101).
    pub status_id: CanId,
    /// DAQ → host sample blocks (default 0x102).
    pub data_id: CanId,
    /// Frames the host sends its commands in (the DAQ chooses its own for data).
    pub frames: FrameKind,
    /// Longest wait for an answer to a command (the stand file's `daq.timeout`).
    pub answer_timeout: Duration,
    /// Times a command is sent again after its answer timed out (the stand file's `daq.retries`).
    /// IDENTIFY, CONFIGURE and STOP are idempotent; START is re-sent after a STOP, so that a START
    /// the device did receive cannot leave two streams' block counters interleaved.
    #[serde(default = "default_retries")]
    pub retries: u32,
    /// Longest wait for the next data frame while streaming.
    pub data_timeout: Duration,
    /// Socket receive buffer (bytes) that absorbs bursts while the host is busy.
    pub receive_buffer: usize,
}

impl Default for CanDaqSettings {
    fn default() -> Self {
        CanDaqSettings {
            command_id: CanId::Standard(0x100),
            status_id: CanId::Standard(0x101),
            data_id: CanId::Standard(0x102),
            frames: FrameKind::Classic,
            answer_timeout: Duration::from_secs(1),
            retries: default_retries(),
            data_timeout: Duration::from_secs(2),
            receive_buffer: 4 << 20,
        }
    }
}

fn default_retries() -> u32 {
    2
}

impl CanDaqSettings {
    /// Checks identifier ranges and that the three identifiers differ.
    pub fn validate(&self) -> Result<(), CanError> {
        self.command_id.validate("command")?;
        self.status_id.validate("status")?;
        self.data_id.validate("data")?;
        let ids = [self.command_id, self.status_id, self.data_id];
        if ids[0] == ids[1] || ids[0] == ids[2] || ids[1] == ids[2] {
            return Err(CanError::Config {
                detail: format!(
                    "command ({}), status ({}) and data ({}) identifiers must all differ",
                    self.command_id, self.status_id, self.data_id
                ),
            });
        }
        Ok(())
    }
}

/// A DAQ on a CAN interface. Every fault on the data stream (lost, duplicated, corrupted frames,
/// missing blocks, error frames) comes out of [`Daq::next_event`] as a [`DaqEvent::Fault`];
/// bus-off ends the stream with [`DaqError::Bus`].
pub struct CanDaq {
    bus: CanBus,
    settings: CanDaqSettings,
    tx: Segmenter,
    rx_status: Reassembler,
    rx_data: Reassembler,
    info: Option<StreamInfo>,
    streaming: bool,
    pending: VecDeque<DaqEvent>,
    answers: VecDeque<Message>,
    /// Commands (type bytes) sent again after a timeout whose first answers may still arrive:
    /// such an answer is expected, not a fault.
    late: Vec<u8>,
    next_seq: u64,
    last_raw_seq: Option<u32>,
    frames: Vec<WireFrame>,
    body: Vec<u8>,
    tap: Option<std::sync::Arc<dyn ByteTap>>,
}

impl CanDaq {
    /// Opens `interface` for a DAQ using `settings`.
    pub fn open(interface: &str, settings: CanDaqSettings) -> Result<CanDaq, CanError> {
        settings.validate()?;
        let bus = CanBus::open_filtered(interface, &[settings.status_id, settings.data_id])?;
        bus.set_receive_buffer(settings.receive_buffer)?;
        Ok(CanDaq {
            bus,
            tx: Segmenter::new(settings.command_id, settings.frames),
            settings,
            rx_status: Reassembler::new(),
            rx_data: Reassembler::new(),
            info: None,
            streaming: false,
            pending: VecDeque::new(),
            answers: VecDeque::new(),
            late: Vec::new(),
            next_seq: 0,
            last_raw_seq: None,
            frames: Vec::new(),
            body: Vec::new(),
            tap: None,
        })
    }

    /// Copies every frame sent and received (command, status and data identifiers) to `tap`, one
    /// line per frame in `cansend`/`candump -L` notation (`102#80010003CFCB\n`, FD `102##0…`).
    pub fn with_tap(mut self, tap: std::sync::Arc<dyn ByteTap>) -> CanDaq {
        self.tap = Some(tap);
        self
    }

    fn record(&self, direction: Direction, f: &WireFrame) {
        if let Some(tap) = &self.tap {
            let mut line = f.to_cansend();
            line.push('\n');
            tap.bytes(self.bus.interface(), direction, line.as_bytes());
        }
    }

    /// The announced stream, once configured.
    pub fn stream_info(&self) -> Option<&StreamInfo> {
        self.info.as_ref()
    }

    fn port(&self) -> String {
        self.bus.interface().to_string()
    }

    fn can_err(&self, e: CanError) -> DaqError {
        match e {
            CanError::Io { source, .. } => DaqError::from_io(self.bus.interface(), source),
            other => DaqError::Bus {
                port: self.port(),
                detail: other.to_string(),
            },
        }
    }

    async fn send(&mut self, m: &Message) -> Result<(), DaqError> {
        m.encode(&mut self.body).map_err(|e| DaqError::State {
            port: self.port(),
            detail: format!("cannot encode {}: {e}", m.name()),
        })?;
        self.frames.clear();
        self.tx
            .segment(&self.body, &mut self.frames)
            .map_err(|e| DaqError::State {
                port: self.port(),
                detail: format!("cannot encode {}: {e}", m.name()),
            })?;
        for i in 0..self.frames.len() {
            let f = self.frames[i];
            self.bus.send(&f).await.map_err(|e| self.can_err(e))?;
            self.record(Direction::Tx, &f);
        }
        Ok(())
    }

    /// Receives one bus event (or times out at `deadline`) and files what it produced.
    async fn pump(&mut self, deadline: tokio::time::Instant, what: &str) -> Result<(), DaqError> {
        let ev = match tokio::time::timeout_at(deadline, self.bus.recv()).await {
            Err(_) => {
                return Err(DaqError::Timeout {
                    port: self.port(),
                    what: what.to_string(),
                    waited: deadline
                        .saturating_duration_since(tokio::time::Instant::now())
                        .max(Duration::ZERO),
                })
            }
            Ok(r) => r.map_err(|e| self.can_err(e))?,
        };
        if let BusEvent::Frame(f) = &ev {
            self.record(Direction::Rx, f);
        }
        match ev {
            BusEvent::Frame(f) if f.id() == self.settings.data_id => {
                let p = self.rx_data.push(f.data());
                let fault = p.fault;
                let msg = p.message.map(Message::decode);
                if let Some(fault) = fault {
                    let seq = matches!(
                        fault,
                        SegmentFault::Gap {
                            message_lost: true,
                            ..
                        } | SegmentFault::Crc { .. }
                    )
                    .then_some(self.next_seq);
                    self.fault(
                        fault_kind(&fault),
                        seq,
                        format!("data frames (id {}): {fault}", self.settings.data_id),
                    );
                }
                match msg {
                    None => {}
                    Some(Ok(Message::Block(b))) => self.accept_block(b),
                    Some(Ok(other)) => self.fault(
                        FaultKind::Framing,
                        None,
                        format!(
                            "{} message on the data identifier {}; ignored",
                            other.name(),
                            self.settings.data_id
                        ),
                    ),
                    Some(Err(e)) => self.fault(
                        FaultKind::Framing,
                        Some(self.next_seq),
                        format!("data: {e}; block dropped"),
                    ),
                }
            }
            BusEvent::Frame(f) if f.id() == self.settings.status_id => {
                let p = self.rx_status.push(f.data());
                let fault = p.fault;
                let msg = p.message.map(Message::decode);
                if let Some(fault) = fault {
                    self.fault(
                        fault_kind(&fault),
                        None,
                        format!("status frames (id {}): {fault}", self.settings.status_id),
                    );
                }
                match msg {
                    None => {}
                    Some(Ok(Message::DeviceFault { code, message })) => self.fault(
                        FaultKind::Device,
                        None,
                        format!("device fault {code}: {message}"),
                    ),
                    Some(Ok(m)) => self.answers.push_back(m),
                    Some(Err(e)) => self.fault(FaultKind::Framing, None, format!("status: {e}")),
                }
            }
            BusEvent::Frame(_) | BusEvent::Remote(_) => {}
            BusEvent::Error(report) => {
                if report.bus_off {
                    return Err(DaqError::Bus {
                        port: self.port(),
                        detail: report.to_string(),
                    });
                }
                self.fault(FaultKind::Bus, None, report.to_string());
            }
        }
        Ok(())
    }

    fn fault(&mut self, kind: FaultKind, seq: Option<u64>, detail: String) {
        self.pending
            .push_back(DaqEvent::Fault(StreamFault { kind, seq, detail }));
    }

    fn accept_block(&mut self, b: WireBlock) {
        let Some((channels, samples_per_block)) = self
            .info
            .as_ref()
            .map(|i| (i.channels.len(), i.samples_per_block))
        else {
            self.fault(
                FaultKind::Framing,
                None,
                format!("block {} before any announcement; ignored", b.seq),
            );
            return;
        };
        if !self.streaming {
            return; // in flight after STOP: discarded by contract
        }
        if b.channel_count as usize != channels
            || b.samples_per_channel() != samples_per_block as usize
        {
            let detail = format!(
                "block {} has {} channel(s) × {} samples, the announcement says {channels} × {samples_per_block}; block dropped",
                b.seq,
                b.channel_count,
                b.samples_per_channel(),
            );
            self.fault(FaultKind::Framing, Some(self.next_seq), detail);
            return;
        }
        let expected = self.next_seq as u32;
        let ahead = b.seq.wrapping_sub(expected);
        if ahead >= 1 << 31 {
            let (kind, what) = if Some(b.seq) == self.last_raw_seq {
                (FaultKind::Duplicate, "again")
            } else {
                (FaultKind::OutOfOrder, "out of order")
            };
            let seq = self
                .next_seq
                .wrapping_sub(expected.wrapping_sub(b.seq) as u64);
            self.fault(
                kind,
                Some(seq),
                format!("block {} arrived {what}; discarded", b.seq),
            );
            return;
        }
        if ahead > 0 {
            self.fault(
                FaultKind::Gap,
                Some(self.next_seq),
                format!(
                    "{ahead} block(s) missing: expected block {}, received {}",
                    self.next_seq,
                    self.next_seq + ahead as u64
                ),
            );
        }
        let seq = self.next_seq + ahead as u64;
        let spb = samples_per_block as u64;
        let mut volts = Vec::with_capacity(b.counts.len());
        if let Some(info) = &self.info {
            for (i, &c) in b.counts.iter().enumerate() {
                volts.push((c as f64 * info.channels[i % channels].volts_per_count) as f32);
            }
        }
        self.pending.push_back(DaqEvent::Block(SampleBlock {
            seq,
            first_sample: seq * spb,
            channel_count: channels as u16,
            volts,
        }));
        self.next_seq = seq + 1;
        self.last_raw_seq = Some(b.seq);
    }

    /// Sends `m` and waits for the answer `accept` picks out (NAK → [`DaqError::Rejected`]),
    /// sending it again up to `settings.retries` times when the answer times out.
    async fn request<T>(
        &mut self,
        m: Message,
        accept: impl Fn(&Message) -> Option<T>,
    ) -> Result<T, DaqError> {
        let name = m.name();
        let command = match m {
            Message::Identify => kind::IDENTIFY,
            Message::Configure { .. } => kind::CONFIGURE,
            Message::Start => kind::START,
            _ => kind::STOP,
        };
        let what = format!(
            "answer to {name} on identifier {} (command sent on {})",
            self.settings.status_id, self.settings.command_id
        );
        let attempts = self.settings.retries + 1;
        self.answers.clear();
        for attempt in 0..attempts {
            if attempt > 0 {
                tracing::warn!(
                    interface = self.bus.interface(),
                    "no {what} within {:?}; sending it again",
                    self.settings.answer_timeout
                );
                if command == kind::START {
                    // The first START may have started a stream whose ACK is late: stop it, so
                    // the next START's block counter is the only one on the bus.
                    self.send(&Message::Stop).await?;
                    self.expect_late(kind::STOP);
                }
            }
            self.send(&m).await?;
            let deadline = tokio::time::Instant::now() + self.settings.answer_timeout;
            loop {
                while let Some(a) = self.answers.pop_front() {
                    if let Some(t) = accept(&a) {
                        // Each earlier attempt the device may have received owes an answer.
                        (0..attempt).for_each(|_| self.expect_late(command));
                        return Ok(t);
                    }
                    match a {
                        Message::Nak {
                            command: c,
                            code,
                            message,
                        } if c == command => {
                            return Err(DaqError::Rejected {
                                port: self.port(),
                                command: name.into(),
                                code: code as i32,
                                message,
                            })
                        }
                        other => {
                            let late = answered_command(&other)
                                .and_then(|k| self.late.iter().position(|&l| l == k));
                            match late {
                                Some(i) => {
                                    self.late.swap_remove(i);
                                    tracing::debug!(
                                        interface = self.bus.interface(),
                                        "late {} to a command sent again; ignored",
                                        other.name()
                                    );
                                }
                                None => {
                                    let detail = format!(
                                        "{} while waiting for the answer to {name}; ignored",
                                        other.name()
                                    );
                                    self.fault(FaultKind::Framing, None, detail);
                                }
                            }
                        }
                    }
                }
                match self.pump(deadline, &what).await {
                    Err(DaqError::Timeout { .. }) => break,
                    r => r?,
                }
            }
        }
        Err(DaqError::Timeout {
            port: self.port(),
            what: format!("{what}, {attempts} attempt(s)"),
            waited: self.settings.answer_timeout,
        })
    }

    /// Notes that an answer to `command` may still arrive (bounded: a device that never got the
    /// command owes nothing, and its entry must not pile up).
    fn expect_late(&mut self, command: u8) {
        if self.late.len() >= 16 {
            self.late.remove(0);
        }
        self.late.push(command);
    }
}

/// The command an answer answers (type byte), if it is one.
fn answered_command(m: &Message) -> Option<u8> {
    match m {
        Message::Identity(_) => Some(kind::IDENTIFY),
        Message::Announce { .. } => Some(kind::CONFIGURE),
        Message::Ack { command } | Message::Nak { command, .. } => Some(*command),
        _ => None,
    }
}

fn fault_kind(f: &SegmentFault) -> FaultKind {
    match f {
        SegmentFault::Gap { .. } => FaultKind::Gap,
        SegmentFault::Duplicate { .. } => FaultKind::Duplicate,
        SegmentFault::Crc { .. } => FaultKind::Crc,
        SegmentFault::Framing { .. } => FaultKind::Framing,
    }
}

#[async_trait]
impl Daq for CanDaq {
    fn port(&self) -> &str {
        self.bus.interface()
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, DaqError> {
        let text = self
            .request(Message::Identify, |m| match m {
                Message::Identity(t) => Some(t.clone()),
                _ => None,
            })
            .await?;
        DeviceIdentity::parse_idn(&text).ok_or_else(|| DaqError::Protocol {
            port: self.port(),
            command: "IDENTIFY".into(),
            detail: format!("identity `{text}` is not `manufacturer,model,serial,firmware`"),
        })
    }

    async fn configure(&mut self, config: &DaqConfig) -> Result<StreamInfo, DaqError> {
        let mhz = (config.sample_rate_hz * 1000.0).round();
        if !(1.0..=u32::MAX as f64).contains(&mhz) {
            return Err(DaqError::State {
                port: self.port(),
                detail: format!(
                    "sample rate {} Hz is outside what DAQ-over-CAN carries (0.001 Hz to 4.29 MHz)",
                    config.sample_rate_hz
                ),
            });
        }
        if config.channels.is_empty()
            || config.channels.len() > 255
            || config.samples_per_block == 0
        {
            return Err(DaqError::State {
                port: self.port(),
                detail: format!(
                    "{} channel(s) and {} samples per block requested; need 1–255 channels and ≥ 1 sample",
                    config.channels.len(),
                    config.samples_per_block
                ),
            });
        }
        self.streaming = false;
        let m = Message::Configure {
            sample_rate_mhz: mhz as u32,
            samples_per_block: config.samples_per_block,
            channels: config.channels.clone(),
        };
        let (rate, spb, channels) = self
            .request(m, |m| match m {
                Message::Announce {
                    sample_rate_mhz,
                    samples_per_block,
                    channels,
                } => Some((*sample_rate_mhz, *samples_per_block, channels.clone())),
                _ => None,
            })
            .await?;
        let got: Vec<u16> = channels.iter().map(|c| c.device_channel).collect();
        if got != config.channels || spb != config.samples_per_block {
            return Err(DaqError::Announcement {
                port: self.port(),
                detail: format!(
                    "requested channels {:?} × {} samples, device announced {got:?} × {spb}",
                    config.channels, config.samples_per_block
                ),
            });
        }
        let info = StreamInfo {
            sample_rate_hz: rate as f64 / 1000.0,
            channels: channels
                .iter()
                .map(|c| ChannelInfo {
                    device_channel: c.device_channel,
                    volts_per_count: c.volts_per_count as f64,
                })
                .collect(),
            samples_per_block: spb,
        };
        self.info = Some(info.clone());
        Ok(info)
    }

    async fn start(&mut self) -> Result<(), DaqError> {
        if self.info.is_none() {
            return Err(DaqError::State {
                port: self.port(),
                detail: "start before configure".into(),
            });
        }
        self.rx_data.reset();
        self.pending.clear();
        self.next_seq = 0;
        self.last_raw_seq = None;
        self.request(Message::Start, |m| {
            matches!(
                m,
                Message::Ack {
                    command: kind::START
                }
            )
            .then_some(())
        })
        .await?;
        // Data frames before the ACK belong to an earlier (or a re-sent START's aborted) stream;
        // the device sends the new stream's frames after the ACK.
        self.rx_data.reset();
        self.streaming = true;
        Ok(())
    }

    async fn next_event(&mut self) -> Result<DaqEvent, DaqError> {
        if let Some(e) = self.pending.pop_front() {
            return Ok(e); // includes faults recorded while stopping
        }
        if !self.streaming {
            return Err(DaqError::State {
                port: self.port(),
                detail: "next_event before start (or after stop)".into(),
            });
        }
        let deadline = tokio::time::Instant::now() + self.settings.data_timeout;
        loop {
            if let Some(e) = self.pending.pop_front() {
                return Ok(e);
            }
            let what = format!("data frame on identifier {}", self.settings.data_id);
            match self.pump(deadline, &what).await {
                Err(DaqError::Timeout { port, what, .. }) => {
                    return Err(DaqError::Timeout {
                        port,
                        what,
                        waited: self.settings.data_timeout,
                    })
                }
                r => r?,
            }
        }
    }

    async fn stop(&mut self) -> Result<(), DaqError> {
        self.streaming = false;
        let r = self
            .request(Message::Stop, |m| {
                matches!(
                    m,
                    Message::Ack {
                        command: kind::STOP
                    }
                )
                .then_some(())
            })
            .await;
        self.pending.retain(|e| matches!(e, DaqEvent::Fault(_)));
        self.rx_data.reset();
        r
    }
}
