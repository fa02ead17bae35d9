//! The DAQ-over-CAN wire format (docs/daq-can.md), pure and I/O-free: messages are segmented into
//! classic (8-byte) or CAN FD (64-byte) frames carrying a 7-bit frame counter, reassembled with
//! gap/duplicate/CRC detection, and decoded into commands, answers and sample blocks.

use super::frame::{CanId, FrameKind, WireFrame};
use crate::wire::{FieldErrors, LeReader};

/// Longest message body (bytes) a segment may carry: the 16-bit length field's range.
pub const MAX_BODY: usize = u16::MAX as usize;

/// Start-of-message flag in a frame's control byte (bit 7); bits 0–6 are the frame counter.
pub const SOM_FLAG: u8 = 0x80;

const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// Valid CAN FD data lengths; a final FD frame is zero-padded up to the next one.
const FD_LENGTHS: [usize; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// Smallest valid CAN FD data length ≥ `len` (`len` ≤ 64).
pub fn fd_length_at_least(len: usize) -> usize {
    FD_LENGTHS.iter().copied().find(|&l| l >= len).unwrap_or(64)
}

/// Errors building a message for the wire (the caller's data does not fit the format).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// The message body is longer than the 16-bit length field allows.
    #[error("message body of {len} bytes exceeds the DAQ-over-CAN limit of {MAX_BODY} bytes; use smaller blocks (fewer samples per block or channels)")]
    TooLong {
        /// Body length (bytes).
        len: usize,
    },
    /// A sample block is inconsistent or does not fit its sample format.
    #[error("sample block: {detail}")]
    Block {
        /// What is wrong.
        detail: String,
    },
    /// A field does not fit its wire width.
    #[error("{field} = {value} does not fit the wire format ({limit})")]
    Field {
        /// Field name.
        field: &'static str,
        /// Offending value.
        value: String,
        /// Allowed range.
        limit: &'static str,
    },
}

/// Splits message bodies into frames: `[control][length u16 LE][body][CRC-16 LE]`, 7 (classic) or
/// 63 (FD) bytes after each frame's control byte. Keeps the per-stream frame counter.
#[derive(Debug, Clone)]
pub struct Segmenter {
    id: CanId,
    kind: FrameKind,
    counter: u8,
    scratch: Vec<u8>,
}

impl Segmenter {
    /// A segmenter sending on `id` with frames of `kind`; the counter starts at 0.
    pub fn new(id: CanId, kind: FrameKind) -> Segmenter {
        Segmenter {
            id,
            kind,
            counter: 0,
            scratch: Vec::new(),
        }
    }

    /// The frame counter of the next frame (0–127).
    pub fn counter(&self) -> u8 {
        self.counter
    }

    /// Appends the frames carrying `body` to `out` (which is not cleared).
    pub fn segment(&mut self, body: &[u8], out: &mut Vec<WireFrame>) -> Result<(), EncodeError> {
        if body.len() > MAX_BODY {
            return Err(EncodeError::TooLong { len: body.len() });
        }
        self.scratch.clear();
        self.scratch
            .extend_from_slice(&(body.len() as u16).to_le_bytes());
        self.scratch.extend_from_slice(body);
        let crc = CRC16.checksum(&self.scratch);
        self.scratch.extend_from_slice(&crc.to_le_bytes());
        let chunk = self.kind.max_data() - 1;
        for (i, part) in self.scratch.chunks(chunk).enumerate() {
            let control = (self.counter & 0x7F) | if i == 0 { SOM_FLAG } else { 0 };
            self.counter = (self.counter + 1) & 0x7F;
            let mut data = [0u8; 64];
            data[0] = control;
            data[1..1 + part.len()].copy_from_slice(part);
            let len = match self.kind {
                FrameKind::Classic => 1 + part.len(),
                FrameKind::Fd => fd_length_at_least(1 + part.len()),
            };
            out.push(WireFrame::from_parts(self.id, self.kind, &data[..len]));
        }
        Ok(())
    }
}

/// A problem found while reassembling frames. The message it concerns is lost (or, for a
/// duplicate, the copy ignored); nothing damaged is ever delivered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SegmentFault {
    /// Frames are missing: the counter jumped from `expected` to `received`.
    Gap {
        /// Counter expected (0–127).
        expected: u8,
        /// Counter received.
        received: u8,
        /// Frames missing (modulo 128).
        missing: u8,
        /// A partly received message was dropped because of it.
        message_lost: bool,
    },
    /// The frame repeats the previous one's counter; it was ignored.
    Duplicate {
        /// The repeated counter.
        counter: u8,
    },
    /// The reassembled message failed its CRC-16; it was dropped.
    Crc {
        /// CRC carried by the message.
        received: u16,
        /// CRC computed over length and body.
        computed: u16,
    },
    /// The frame or message violates the format (empty frame, new message before the previous
    /// one was complete, frame outside any message).
    Framing {
        /// What was wrong.
        detail: String,
    },
}

impl std::fmt::Display for SegmentFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SegmentFault::Gap {
                expected,
                received,
                missing,
                message_lost,
            } => {
                write!(
                f,
                "frame counter jumped from {expected} to {received} ({missing} frame(s) missing){}",
                if *message_lost { "; the message in progress was dropped" } else { "" }
            )
            }
            SegmentFault::Duplicate { counter } => {
                write!(f, "frame {counter} received twice; copy ignored")
            }
            SegmentFault::Crc { received, computed } => {
                write!(f, "message CRC mismatch (carried {received:#06x}, computed {computed:#06x}); message dropped")
            }
            SegmentFault::Framing { detail } => f.write_str(detail),
        }
    }
}

/// What one frame produced: at most one fault and at most one complete message body.
#[derive(Debug, Default)]
pub struct Pushed<'a> {
    /// A fault detected while taking this frame.
    pub fault: Option<SegmentFault>,
    /// A complete, CRC-checked message body.
    pub message: Option<&'a [u8]>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Waiting for a start-of-message frame; `quiet` = the loss was already reported.
    Idle { quiet: bool },
    /// Collecting `need` bytes (length field + body + CRC).
    Collecting { need: usize },
}

/// Reassembles one CAN identifier's frames into message bodies (the inverse of [`Segmenter`]).
/// Allocation happens only while the buffer grows to the largest message seen.
#[derive(Debug, Clone)]
pub struct Reassembler {
    last: Option<u8>,
    state: State,
    buf: Vec<u8>,
    done: Vec<u8>,
}

impl Default for Reassembler {
    fn default() -> Self {
        Reassembler::new()
    }
}

impl Reassembler {
    /// A reassembler that synchronises on the first frame it sees.
    pub fn new() -> Reassembler {
        Reassembler {
            last: None,
            state: State::Idle { quiet: false },
            buf: Vec::new(),
            done: Vec::new(),
        }
    }

    /// Forgets the counter and any partial message (after the stream was stopped and restarted).
    pub fn reset(&mut self) {
        self.last = None;
        self.state = State::Idle { quiet: false };
        self.buf.clear();
    }

    /// Bytes of a message still being collected (frames lost at the end of a stream show here).
    pub fn in_progress(&self) -> Option<usize> {
        match self.state {
            State::Collecting { .. } => Some(self.buf.len()),
            State::Idle { .. } => None,
        }
    }

    /// Checks frame counter `counter` against the last one: `Err` for a repeated frame (to be
    /// ignored), `Ok(Some(gap))` when frames were lost (the message being collected is dropped).
    fn check_counter(&mut self, counter: u8) -> Result<Option<SegmentFault>, SegmentFault> {
        let mut fault = None;
        if let Some(last) = self.last {
            let expected = (last + 1) & 0x7F;
            if counter == last {
                return Err(SegmentFault::Duplicate { counter });
            }
            if counter != expected {
                let lost = matches!(self.state, State::Collecting { .. });
                fault = Some(SegmentFault::Gap {
                    expected,
                    received: counter,
                    missing: counter.wrapping_sub(expected) & 0x7F,
                    message_lost: lost,
                });
                self.buf.clear();
                self.state = State::Idle { quiet: true };
            }
        }
        self.last = Some(counter);
        Ok(fault)
    }

    /// Takes one frame's data bytes.
    pub fn push(&mut self, data: &[u8]) -> Pushed<'_> {
        let Some((&control, payload)) = data.split_first() else {
            return Pushed {
                fault: Some(SegmentFault::Framing {
                    detail: "empty frame (no control byte); ignored".into(),
                }),
                message: None,
            };
        };
        let counter = control & 0x7F;
        let som = control & SOM_FLAG != 0;
        let mut fault = match self.check_counter(counter) {
            Ok(gap) => gap,
            Err(duplicate) => {
                return Pushed {
                    fault: Some(duplicate),
                    message: None,
                }
            }
        };

        if som {
            if let State::Collecting { need } = self.state {
                fault = Some(SegmentFault::Framing {
                    detail: format!(
                        "new message started after {} of {need} bytes of the previous one; previous message dropped",
                        self.buf.len()
                    ),
                });
            }
            self.buf.clear();
            if payload.len() < 2 {
                self.state = State::Idle { quiet: true };
                return Pushed {
                    fault: fault.or(Some(SegmentFault::Framing {
                        detail:
                            "start-of-message frame too short for the length field; message dropped"
                                .into(),
                    })),
                    message: None,
                };
            }
            let len = u16::from_le_bytes([payload[0], payload[1]]) as usize;
            self.state = State::Collecting { need: 2 + len + 2 };
        } else if let State::Idle { quiet } = self.state {
            self.state = State::Idle { quiet: true };
            if fault.is_none() && !quiet {
                fault = Some(SegmentFault::Framing {
                    detail: format!("continuation frame {counter} outside any message; ignored"),
                });
            }
            return Pushed {
                fault,
                message: None,
            };
        }

        let State::Collecting { need } = self.state else {
            return Pushed {
                fault,
                message: None,
            };
        };
        let take = payload.len().min(need - self.buf.len());
        self.buf.extend_from_slice(&payload[..take]);
        if self.buf.len() < need {
            return Pushed {
                fault,
                message: None,
            };
        }
        // Complete (bytes after `need` in the final frame are padding).
        self.state = State::Idle { quiet: false };
        let (content, crc_bytes) = self.buf.split_at(need - 2);
        let received = u16::from_le_bytes([crc_bytes[0], crc_bytes[1]]);
        let computed = CRC16.checksum(content);
        if received != computed {
            self.buf.clear();
            return Pushed {
                fault: fault.or(Some(SegmentFault::Crc { received, computed })),
                message: None,
            };
        }
        std::mem::swap(&mut self.done, &mut self.buf);
        self.buf.clear();
        let body = &self.done[2..need - 2];
        Pushed {
            fault,
            message: Some(body),
        }
    }
}

/// Sample encoding of a block on the wire (little-endian two's complement ADC counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleFormat {
    /// 16-bit counts (code 1).
    I16,
    /// 24-bit counts, 3 bytes each (code 2).
    I24,
    /// 32-bit counts (code 3).
    I32,
}

impl SampleFormat {
    /// Wire code.
    pub fn code(self) -> u8 {
        match self {
            SampleFormat::I16 => 1,
            SampleFormat::I24 => 2,
            SampleFormat::I32 => 3,
        }
    }

    /// From a wire code.
    pub fn from_code(code: u8) -> Option<SampleFormat> {
        match code {
            1 => Some(SampleFormat::I16),
            2 => Some(SampleFormat::I24),
            3 => Some(SampleFormat::I32),
            _ => None,
        }
    }

    /// Bytes per sample.
    pub fn width(self) -> usize {
        match self {
            SampleFormat::I16 => 2,
            SampleFormat::I24 => 3,
            SampleFormat::I32 => 4,
        }
    }

    /// Range of representable counts.
    pub fn range(self) -> (i32, i32) {
        match self {
            SampleFormat::I16 => (i16::MIN as i32, i16::MAX as i32),
            SampleFormat::I24 => (-(1 << 23), (1 << 23) - 1),
            SampleFormat::I32 => (i32::MIN, i32::MAX),
        }
    }
}

/// A block of ADC counts as it travels on the wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WireBlock {
    /// Block counter (0 at start, wraps at 2³²).
    pub seq: u32,
    /// Sample encoding.
    pub format: SampleFormat,
    /// Channels per sample (the stride of `counts`), 1–255.
    pub channel_count: u8,
    /// ADC counts, interleaved sample-major: `counts[i · channel_count + c]`.
    pub counts: Vec<i32>,
}

impl WireBlock {
    /// Samples per channel.
    pub fn samples_per_channel(&self) -> usize {
        if self.channel_count == 0 {
            0
        } else {
            self.counts.len() / self.channel_count as usize
        }
    }
}

/// Channel as announced on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WireChannel {
    /// Device channel number.
    pub device_channel: u16,
    /// Volts per ADC count (V).
    pub volts_per_count: f32,
}

/// Every DAQ-over-CAN message (the body's first byte is the type).
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// Host → DAQ 0x01: who are you?
    Identify,
    /// Host → DAQ 0x02: stream these channels at this rate in blocks of this size.
    Configure {
        /// Sample rate (mHz).
        sample_rate_mhz: u32,
        /// Samples per channel per block.
        samples_per_block: u16,
        /// Device channels, in block order.
        channels: Vec<u16>,
    },
    /// Host → DAQ 0x03: start streaming (block counter restarts at 0).
    Start,
    /// Host → DAQ 0x04: stop streaming.
    Stop,
    /// DAQ → host 0x81: `manufacturer,model,serial,firmware` (UTF-8).
    Identity(String),
    /// DAQ → host 0x82: the stream the device will send.
    Announce {
        /// Actual sample rate (mHz).
        sample_rate_mhz: u32,
        /// Samples per channel per block.
        samples_per_block: u16,
        /// Channels in block order.
        channels: Vec<WireChannel>,
    },
    /// DAQ → host 0x83: command accepted.
    Ack {
        /// Type byte of the accepted command.
        command: u8,
    },
    /// DAQ → host 0x84: command refused.
    Nak {
        /// Type byte of the refused command.
        command: u8,
        /// Device error code.
        code: i16,
        /// Device message (UTF-8).
        message: String,
    },
    /// DAQ → host 0x85: an in-band device problem (ADC overrun, buffer overflow).
    DeviceFault {
        /// Device error code.
        code: i16,
        /// Device message (UTF-8).
        message: String,
    },
    /// DAQ → host 0x90 (data identifier): a sample block.
    Block(WireBlock),
}

/// Message type bytes.
pub mod kind {
    /// Identify.
    pub const IDENTIFY: u8 = 0x01;
    /// Configure.
    pub const CONFIGURE: u8 = 0x02;
    /// Start.
    pub const START: u8 = 0x03;
    /// Stop.
    pub const STOP: u8 = 0x04;
    /// Identity.
    pub const IDENTITY: u8 = 0x81;
    /// Announce.
    pub const ANNOUNCE: u8 = 0x82;
    /// Ack.
    pub const ACK: u8 = 0x83;
    /// Nak.
    pub const NAK: u8 = 0x84;
    /// Device fault.
    pub const DEVICE_FAULT: u8 = 0x85;
    /// Block.
    pub const BLOCK: u8 = 0x90;
}

/// A message body that is not valid DAQ-over-CAN.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("malformed {message} message: {detail}")]
pub struct MessageError {
    /// Message type name (or the unknown type byte).
    pub message: String,
    /// What is wrong.
    pub detail: String,
}

/// The field errors of message `.0`, as [`MessageError`]s.
struct MessageErrors(&'static str);

impl FieldErrors for MessageErrors {
    type Error = MessageError;
    fn ends_before(&self, field: &str, left: usize, needed: usize) -> MessageError {
        MessageError {
            message: self.0.into(),
            detail: format!("ends before `{field}` ({left} byte(s) left, {needed} needed)"),
        }
    }
    fn trailing(&self, count: usize) -> MessageError {
        MessageError {
            message: self.0.into(),
            detail: format!("{count} unexpected trailing byte(s)"),
        }
    }
    fn not_utf8(&self, e: std::string::FromUtf8Error) -> MessageError {
        MessageError {
            message: self.0.into(),
            detail: format!("text is not UTF-8: {e}"),
        }
    }
}

impl Message {
    /// Name for messages and records.
    pub fn name(&self) -> &'static str {
        match self {
            Message::Identify => "IDENTIFY",
            Message::Configure { .. } => "CONFIGURE",
            Message::Start => "START",
            Message::Stop => "STOP",
            Message::Identity(_) => "IDENTITY",
            Message::Announce { .. } => "ANNOUNCE",
            Message::Ack { .. } => "ACK",
            Message::Nak { .. } => "NAK",
            Message::DeviceFault { .. } => "DEVICE_FAULT",
            Message::Block(_) => "BLOCK",
        }
    }

    /// Writes the body into `out` (cleared first).
    pub fn encode(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        out.clear();
        match self {
            Message::Identify => out.push(kind::IDENTIFY),
            Message::Start => out.push(kind::START),
            Message::Stop => out.push(kind::STOP),
            Message::Configure {
                sample_rate_mhz,
                samples_per_block,
                channels,
            } => {
                out.push(kind::CONFIGURE);
                out.extend_from_slice(&sample_rate_mhz.to_le_bytes());
                out.extend_from_slice(&samples_per_block.to_le_bytes());
                out.push(count_u8("channel count", channels.len())?);
                for c in channels {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
            Message::Identity(text) => {
                out.push(kind::IDENTITY);
                out.extend_from_slice(text.as_bytes());
            }
            Message::Announce {
                sample_rate_mhz,
                samples_per_block,
                channels,
            } => {
                out.push(kind::ANNOUNCE);
                out.extend_from_slice(&sample_rate_mhz.to_le_bytes());
                out.extend_from_slice(&samples_per_block.to_le_bytes());
                out.push(count_u8("channel count", channels.len())?);
                for c in channels {
                    out.extend_from_slice(&c.device_channel.to_le_bytes());
                    out.extend_from_slice(&c.volts_per_count.to_le_bytes());
                }
            }
            Message::Ack { command } => out.extend_from_slice(&[kind::ACK, *command]),
            Message::Nak {
                command,
                code,
                message,
            } => {
                out.extend_from_slice(&[kind::NAK, *command]);
                out.extend_from_slice(&code.to_le_bytes());
                out.extend_from_slice(message.as_bytes());
            }
            Message::DeviceFault { code, message } => {
                out.push(kind::DEVICE_FAULT);
                out.extend_from_slice(&code.to_le_bytes());
                out.extend_from_slice(message.as_bytes());
            }
            Message::Block(b) => encode_block(b, out)?,
        }
        if out.len() > MAX_BODY {
            return Err(EncodeError::TooLong { len: out.len() });
        }
        Ok(())
    }

    /// Parses a reassembled body.
    pub fn decode(body: &[u8]) -> Result<Message, MessageError> {
        let Some((&t, rest)) = body.split_first() else {
            return Err(MessageError {
                message: "(empty)".into(),
                detail: "no type byte".into(),
            });
        };
        let name = match t {
            kind::IDENTIFY => "IDENTIFY",
            kind::CONFIGURE => "CONFIGURE",
            kind::START => "START",
            kind::STOP => "STOP",
            kind::IDENTITY => "IDENTITY",
            kind::ANNOUNCE => "ANNOUNCE",
            kind::ACK => "ACK",
            kind::NAK => "NAK",
            kind::DEVICE_FAULT => "DEVICE_FAULT",
            kind::BLOCK => "BLOCK",
            other => {
                return Err(MessageError {
                    message: format!("type {other:#04x}"),
                    detail: "unknown message type".into(),
                })
            }
        };
        let mut r = LeReader::new(rest, MessageErrors(name));
        let m = match t {
            kind::IDENTIFY => Message::Identify,
            kind::START => Message::Start,
            kind::STOP => Message::Stop,
            kind::CONFIGURE => {
                let sample_rate_mhz = r.u32("sample_rate_mhz")?;
                let samples_per_block = r.u16("samples_per_block")?;
                let n = r.u8("channel_count")?;
                let mut channels = Vec::with_capacity(n as usize);
                for _ in 0..n {
                    channels.push(r.u16("channel")?);
                }
                Message::Configure {
                    sample_rate_mhz,
                    samples_per_block,
                    channels,
                }
            }
            kind::IDENTITY => Message::Identity(r.text()?),
            kind::ANNOUNCE => {
                let sample_rate_mhz = r.u32("sample_rate_mhz")?;
                let samples_per_block = r.u16("samples_per_block")?;
                let n = r.u8("channel_count")?;
                let mut channels = Vec::with_capacity(n as usize);
                for _ in 0..n {
                    let device_channel = r.u16("device_channel")?;
                    let v = r.u32("volts_per_count")?;
                    channels.push(WireChannel {
                        device_channel,
                        volts_per_count: f32::from_bits(v),
                    });
                }
                Message::Announce {
                    sample_rate_mhz,
                    samples_per_block,
                    channels,
                }
            }
            kind::ACK => Message::Ack {
                command: r.u8("command")?,
            },
            kind::NAK => {
                let command = r.u8("command")?;
                let code = r.i16("code")?;
                Message::Nak {
                    command,
                    code,
                    message: r.text()?,
                }
            }
            kind::DEVICE_FAULT => {
                let code = r.i16("code")?;
                Message::DeviceFault {
                    code,
                    message: r.text()?,
                }
            }
            _ => Message::Block(decode_block(&mut r)?),
        };
        r.end()?;
        Ok(m)
    }
}

fn count_u8(field: &'static str, n: usize) -> Result<u8, EncodeError> {
    u8::try_from(n).map_err(|_| EncodeError::Field {
        field,
        value: n.to_string(),
        limit: "0..=255",
    })
}

fn encode_block(b: &WireBlock, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    if b.channel_count == 0 {
        return Err(EncodeError::Block {
            detail: "channel_count is 0".into(),
        });
    }
    if !b.counts.len().is_multiple_of(b.channel_count as usize) {
        return Err(EncodeError::Block {
            detail: format!(
                "{} counts is not a multiple of {} channels",
                b.counts.len(),
                b.channel_count
            ),
        });
    }
    let spb = b.samples_per_channel();
    let spb = u16::try_from(spb).map_err(|_| EncodeError::Field {
        field: "samples_per_block",
        value: spb.to_string(),
        limit: "0..=65535",
    })?;
    let width = b.format.width();
    let len = 9 + b.counts.len() * width;
    if len > MAX_BODY {
        return Err(EncodeError::TooLong { len });
    }
    out.reserve(len);
    out.push(kind::BLOCK);
    out.extend_from_slice(&b.seq.to_le_bytes());
    out.push(b.format.code());
    out.push(b.channel_count);
    out.extend_from_slice(&spb.to_le_bytes());
    let (lo, hi) = b.format.range();
    for (i, &c) in b.counts.iter().enumerate() {
        if c < lo || c > hi {
            return Err(EncodeError::Block {
                detail: format!(
                    "count {c} (index {i}) outside the {:?} range {lo}..={hi}",
                    b.format
                ),
            });
        }
        out.extend_from_slice(&c.to_le_bytes()[..width]);
    }
    Ok(())
}

fn decode_block(r: &mut LeReader<'_, MessageErrors>) -> Result<WireBlock, MessageError> {
    let seq = r.u32("seq")?;
    let code = r.u8("format")?;
    let format = SampleFormat::from_code(code).ok_or_else(|| MessageError {
        message: "BLOCK".into(),
        detail: format!("unknown sample format {code}"),
    })?;
    let channel_count = r.u8("channel_count")?;
    if channel_count == 0 {
        return Err(MessageError {
            message: "BLOCK".into(),
            detail: "channel_count is 0".into(),
        });
    }
    let spb = r.u16("samples_per_block")? as usize;
    let n = spb * channel_count as usize;
    let width = format.width();
    let bytes = r.take(n * width, "samples")?;
    let counts = bytes
        .chunks_exact(width)
        .map(|c| match format {
            SampleFormat::I16 => i16::from_le_bytes([c[0], c[1]]) as i32,
            // Sign-extend 24 bits: place in the top of an i32 and shift back.
            SampleFormat::I24 => i32::from_le_bytes([0, c[0], c[1], c[2]]) >> 8,
            SampleFormat::I32 => i32::from_le_bytes([c[0], c[1], c[2], c[3]]),
        })
        .collect();
    Ok(WireBlock {
        seq,
        format,
        channel_count,
        counts,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use proptest::prelude::*;

    const ID: CanId = CanId::Standard(0x102);

    fn frames_for(kind: FrameKind, bodies: &[Vec<u8>]) -> Vec<WireFrame> {
        let mut s = Segmenter::new(ID, kind);
        let mut out = Vec::new();
        for b in bodies {
            s.segment(b, &mut out).unwrap();
        }
        out
    }

    fn collect(frames: &[WireFrame]) -> (Vec<Vec<u8>>, Vec<SegmentFault>) {
        let mut r = Reassembler::new();
        let (mut msgs, mut faults) = (Vec::new(), Vec::new());
        for f in frames {
            let p = r.push(f.data());
            if let Some(x) = p.fault {
                faults.push(x);
            }
            if let Some(m) = p.message {
                msgs.push(m.to_vec());
            }
        }
        (msgs, faults)
    }

    #[test]
    fn classic_frames_carry_seven_bytes_and_fd_frames_use_valid_lengths() {
        let body: Vec<u8> = (0..100u8).collect();
        let classic = frames_for(FrameKind::Classic, std::slice::from_ref(&body));
        // 2 (length) + 100 + 2 (CRC) = 104 bytes in chunks of 7 → 15 frames.
        assert_eq!(classic.len(), 15);
        assert!(classic.iter().all(|f| f.data().len() <= 8 && !f.is_fd()));
        assert_eq!(classic[0].data()[0], SOM_FLAG);
        assert_eq!(classic[1].data()[0], 1);
        let fd = frames_for(FrameKind::Fd, &[body]);
        assert_eq!(fd.len(), 2); // 63 + 41 → 41+1 = 42 padded to 48
        assert_eq!(fd[1].data().len(), 48);
        assert!(fd.iter().all(|f| f.is_fd()));
    }

    #[test]
    fn known_message_bytes_match_the_spec_example() {
        // docs/daq-can.md: START as one classic frame.
        let mut body = Vec::new();
        Message::Start.encode(&mut body).unwrap();
        let f = frames_for(FrameKind::Classic, &[body]);
        assert_eq!(f.len(), 1);
        // Bytes and CRC as in the spec (CRC computed independently with a bitwise implementation).
        assert_eq!(f[0].data(), &[0x80, 0x01, 0x00, 0x03, 0xCF, 0xCB]);
        let mut ack = Vec::new();
        Message::Ack {
            command: kind::START,
        }
        .encode(&mut ack)
        .unwrap();
        let mut s = Segmenter::new(ID, FrameKind::Classic);
        let mut out = Vec::new();
        s.segment(&[], &mut out).unwrap(); // counter 0: an empty message
        s.segment(&ack, &mut out).unwrap();
        assert_eq!(out[1].data(), &[0x81, 0x02, 0x00, 0x83, 0x03, 0x00, 0x17]);
        // CRC-16/IBM-3740 check value.
        assert_eq!(CRC16.checksum(b"123456789"), 0x29B1);
    }

    #[test]
    fn every_message_round_trips() {
        let msgs = vec![
            Message::Identify,
            Message::Start,
            Message::Stop,
            Message::Configure {
                sample_rate_mhz: 25_600_000,
                samples_per_block: 64,
                channels: vec![0, 3, 7],
            },
            Message::Identity("IDENT-SIM,CANDAQ-4,0001,1.0".into()),
            Message::Announce {
                sample_rate_mhz: 25_600_000,
                samples_per_block: 64,
                channels: vec![WireChannel {
                    device_channel: 3,
                    volts_per_count: 1.25e-6,
                }],
            },
            Message::Ack {
                command: kind::START,
            },
            Message::Nak {
                command: kind::CONFIGURE,
                code: -3,
                message: "rate out of range".into(),
            },
            Message::DeviceFault {
                code: 7,
                message: "ADC overrun".into(),
            },
            Message::Block(WireBlock {
                seq: 9,
                format: SampleFormat::I24,
                channel_count: 2,
                counts: vec![-8_388_608, 8_388_607, 0, -1],
            }),
        ];
        for m in msgs {
            let mut body = Vec::new();
            m.encode(&mut body).unwrap();
            assert_eq!(Message::decode(&body).unwrap(), m);
        }
    }

    #[test]
    fn out_of_range_counts_and_bad_shapes_are_refused() {
        let mut out = Vec::new();
        let b = WireBlock {
            seq: 0,
            format: SampleFormat::I16,
            channel_count: 1,
            counts: vec![40_000],
        };
        assert!(matches!(
            Message::Block(b).encode(&mut out),
            Err(EncodeError::Block { .. })
        ));
        let b = WireBlock {
            seq: 0,
            format: SampleFormat::I16,
            channel_count: 2,
            counts: vec![1, 2, 3],
        };
        assert!(matches!(
            Message::Block(b).encode(&mut out),
            Err(EncodeError::Block { .. })
        ));
        let b = WireBlock {
            seq: 0,
            format: SampleFormat::I32,
            channel_count: 1,
            counts: vec![0; 20_000],
        };
        assert!(matches!(
            Message::Block(b).encode(&mut out),
            Err(EncodeError::TooLong { .. })
        ));
    }

    #[test]
    fn lost_frame_drops_the_message_and_the_next_one_decodes() {
        let bodies: Vec<Vec<u8>> = (0..3).map(|i| vec![i as u8; 20]).collect();
        let mut frames = frames_for(FrameKind::Classic, &bodies);
        // 24 bytes per message → 4 frames each; drop the 2nd frame of message 1.
        frames.remove(5);
        let (msgs, faults) = collect(&frames);
        assert_eq!(msgs, vec![bodies[0].clone(), bodies[2].clone()]);
        assert_eq!(
            faults,
            vec![SegmentFault::Gap {
                expected: 5,
                received: 6,
                missing: 1,
                message_lost: true
            }]
        );
    }

    #[test]
    fn duplicate_frame_is_reported_and_ignored() {
        let bodies = vec![vec![7u8; 30]];
        let mut frames = frames_for(FrameKind::Classic, &bodies);
        let dup = frames[2];
        frames.insert(3, dup);
        let (msgs, faults) = collect(&frames);
        assert_eq!(msgs, bodies);
        assert_eq!(faults, vec![SegmentFault::Duplicate { counter: 2 }]);
    }

    #[test]
    fn corrupted_byte_fails_the_crc() {
        let bodies = vec![vec![1u8; 30]];
        let mut frames = frames_for(FrameKind::Fd, &bodies);
        let mut data = frames[0].data().to_vec();
        data[10] ^= 0x40;
        frames[0] = WireFrame::from_parts(ID, FrameKind::Fd, &data);
        let (msgs, faults) = collect(&frames);
        assert!(msgs.is_empty());
        assert!(matches!(faults[..], [SegmentFault::Crc { .. }]));
    }

    fn arb_block() -> impl Strategy<Value = WireBlock> {
        (any::<u32>(), 0..3usize, 1..6u8, 0..40usize).prop_flat_map(|(seq, f, ch, spb)| {
            let format = [SampleFormat::I16, SampleFormat::I24, SampleFormat::I32][f];
            let (lo, hi) = format.range();
            proptest::collection::vec(lo..=hi, spb * ch as usize).prop_map(move |counts| {
                WireBlock {
                    seq,
                    format,
                    channel_count: ch,
                    counts,
                }
            })
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, rng_seed: proptest::test_runner::RngSeed::Fixed(0x05ee_dca4), ..ProptestConfig::default() })]

        #[test]
        fn blocks_round_trip_over_classic_and_fd(blocks in proptest::collection::vec(arb_block(), 1..5), fd in any::<bool>()) {
            let kind = if fd { FrameKind::Fd } else { FrameKind::Classic };
            let bodies: Vec<Vec<u8>> = blocks.iter().map(|b| {
                let mut v = Vec::new();
                Message::Block(b.clone()).encode(&mut v).unwrap();
                v
            }).collect();
            let frames = frames_for(kind, &bodies);
            let (msgs, faults) = collect(&frames);
            prop_assert!(faults.is_empty());
            let decoded: Vec<Message> = msgs.iter().map(|m| Message::decode(m).unwrap()).collect();
            let expected: Vec<Message> = blocks.into_iter().map(Message::Block).collect();
            prop_assert_eq!(decoded, expected);
        }

        /// Dropping, duplicating or corrupting frames never yields a wrong message: every message
        /// delivered is one that was sent, and every lost one is accounted for by a fault.
        #[test]
        fn damaged_streams_never_deliver_wrong_messages(
            bodies in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 1..200), 1..8),
            fd in any::<bool>(),
            edits in proptest::collection::vec((0..4u8, any::<proptest::sample::Index>(), any::<u8>()), 0..6),
        ) {
            let kind = if fd { FrameKind::Fd } else { FrameKind::Classic };
            let mut seg = Segmenter::new(ID, kind);
            // The receiver is already synchronised by an earlier, undamaged message.
            let mut lead = Vec::new();
            seg.segment(&[0xDD], &mut lead).unwrap();
            let mut frames = Vec::new();
            for b in &bodies {
                seg.segment(b, &mut frames).unwrap();
            }
            for (op, at, x) in edits {
                if frames.is_empty() { break; }
                let i = at.index(frames.len());
                match op {
                    0 => { frames.remove(i); }
                    1 => { let f = frames[i]; frames.insert(i, f); }
                    2 => {
                        let mut d = frames[i].data().to_vec();
                        let j = 1 + (x as usize % (d.len().max(2) - 1)).min(d.len() - 1);
                        if j < d.len() { d[j] ^= 1 << (x % 8); }
                        frames[i] = WireFrame::from_parts(ID, kind, &d);
                    }
                    _ => { let n = frames.len(); frames.swap(i, (i + 1) % n); }
                }
            }
            // A live stream goes on: an undamaged message after the damage reveals losses at the end.
            seg.segment(&[0xEE], &mut frames).unwrap();
            lead.extend(frames);
            let frames = lead;
            let mut r = Reassembler::new();
            let (mut msgs, mut faults) = (Vec::new(), Vec::new());
            for f in &frames {
                let p = r.push(f.data());
                faults.extend(p.fault);
                msgs.extend(p.message.map(<[u8]>::to_vec));
            }
            if r.in_progress().is_some() {
                faults.push(SegmentFault::Framing { detail: "stream ended inside a message".into() });
            }
            prop_assert!(msgs.last().is_some_and(|m| m == &[0xEE]) || !faults.is_empty());
            msgs.retain(|m| m != &[0xEE] && m != &[0xDD]);
            for m in &msgs {
                prop_assert!(bodies.contains(m), "delivered a message that was never sent");
            }
            if msgs.len() < bodies.len() {
                prop_assert!(!faults.is_empty(), "messages lost without a fault");
            }
        }

        /// Arbitrary frame bytes and message bodies never panic the decoders.
        #[test]
        fn garbage_never_panics(frames in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..65), 0..50)) {
            let mut r = Reassembler::new();
            for f in &frames {
                let p = r.push(f);
                if let Some(m) = p.message {
                    let _ = Message::decode(m);
                }
                let _ = Message::decode(f);
            }
        }
    }
}
