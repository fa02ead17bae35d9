//! The DAQ serial wire format (docs/daq-serial.md), I/O free: COBS framing with a zero delimiter,
//! a type byte, a 32-bit sequence counter, the payload and a CRC-32. [`FrameDecoder`] is a pure
//! state machine fed with whatever bytes arrived; [`encode_frame`] and the `Message` codecs build
//! frames. Both the host driver and the simulated DAQ use this module.

use crc::{Crc, CRC_32_ISO_HDLC};

use super::{ChannelInfo, DaqConfig, StreamInfo};
use crate::wire::{FieldErrors, LeReader};

/// CRC-32 (ISO-HDLC, the zlib/Ethernet CRC) over type, sequence and payload.
pub const FRAME_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Largest decoded frame (type + seq + payload + CRC), bytes.
pub const MAX_FRAME: usize = 4096;
/// Header bytes before the payload: type (1) and sequence (4).
pub const HEADER: usize = 5;
/// Trailer bytes: CRC-32.
pub const TRAILER: usize = 4;

/// Frame type codes.
pub mod kind {
    /// Host → device: identify yourself.
    pub const HELLO: u8 = 0x01;
    /// Host → device: configure the stream.
    pub const CONFIGURE: u8 = 0x02;
    /// Host → device: start streaming.
    pub const START: u8 = 0x03;
    /// Host → device: stop streaming.
    pub const STOP: u8 = 0x04;
    /// Device → host: command accepted.
    pub const ACK: u8 = 0x80;
    /// Device → host: identity string.
    pub const IDENTITY: u8 = 0x81;
    /// Device → host: stream announcement.
    pub const ANNOUNCE: u8 = 0x82;
    /// Device → host: command refused.
    pub const NAK: u8 = 0x8F;
    /// Device → host: a block of samples.
    pub const DATA: u8 = 0x90;
    /// Device → host: asynchronous device status (e.g. ADC overrun).
    pub const STATUS: u8 = 0x91;
}

/// A decoded, CRC-checked frame borrowing the decoder's buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    /// Type code (see [`kind`]).
    pub kind: u8,
    /// Sequence number: block counter for DATA, request id for commands and their answers.
    pub seq: u32,
    /// Payload bytes.
    pub payload: &'a [u8],
}

/// Why a received frame was discarded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The CRC did not match.
    #[error("CRC mismatch (frame says {expected:#010x}, computed {computed:#010x}, {len} bytes)")]
    Crc {
        /// CRC carried by the frame.
        expected: u32,
        /// CRC computed over the frame.
        computed: u32,
        /// Decoded length.
        len: usize,
    },
    /// Invalid COBS encoding.
    #[error("invalid COBS encoding ({len} bytes before the delimiter)")]
    Cobs {
        /// Encoded length.
        len: usize,
    },
    /// Shorter than header + CRC.
    #[error("frame too short ({len} bytes, minimum 9)")]
    Short {
        /// Decoded length.
        len: usize,
    },
    /// More than [`MAX_FRAME`] bytes without a delimiter; bytes were skipped up to the next one.
    #[error("frame longer than {MAX_FRAME} bytes; skipped to the next delimiter")]
    Oversize,
}

/// Incremental frame decoder: feed it bytes in any chunking; it yields each complete frame or the
/// reason it was discarded. Never panics, never allocates after construction.
#[derive(Debug)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    overflow: bool,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    /// A decoder with its buffer sized once.
    pub fn new() -> Self {
        FrameDecoder {
            buf: Vec::with_capacity(cobs::max_encoding_length(MAX_FRAME) + 1),
            overflow: false,
        }
    }

    /// Feeds received bytes; calls `sink` once per delimiter seen, in order.
    pub fn feed(&mut self, bytes: &[u8], mut sink: impl FnMut(Result<Frame<'_>, FrameError>)) {
        let limit = cobs::max_encoding_length(MAX_FRAME);
        for &b in bytes {
            if b != 0 {
                if self.buf.len() < limit {
                    self.buf.push(b);
                } else {
                    self.overflow = true;
                }
                continue;
            }
            // Delimiter: a frame ends here.
            if self.overflow {
                self.overflow = false;
                self.buf.clear();
                sink(Err(FrameError::Oversize));
                continue;
            }
            if self.buf.is_empty() {
                continue; // idle delimiters are allowed
            }
            let enc_len = self.buf.len();
            match cobs::decode_in_place(&mut self.buf) {
                Err(_) => sink(Err(FrameError::Cobs { len: enc_len })),
                Ok(n) => sink(parse_decoded(&self.buf[..n])),
            }
            self.buf.clear();
        }
    }

    /// Bytes of an unfinished frame currently buffered.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }
}

fn parse_decoded(d: &[u8]) -> Result<Frame<'_>, FrameError> {
    if d.len() < HEADER + TRAILER {
        return Err(FrameError::Short { len: d.len() });
    }
    let body = &d[..d.len() - TRAILER];
    let mut crc_bytes = [0u8; 4];
    crc_bytes.copy_from_slice(&d[d.len() - TRAILER..]);
    let expected = u32::from_le_bytes(crc_bytes);
    let computed = FRAME_CRC.checksum(body);
    if expected != computed {
        return Err(FrameError::Crc {
            expected,
            computed,
            len: d.len(),
        });
    }
    let mut seq = [0u8; 4];
    seq.copy_from_slice(&body[1..5]);
    Ok(Frame {
        kind: body[0],
        seq: u32::from_le_bytes(seq),
        payload: &body[HEADER..],
    })
}

/// Appends one encoded frame (COBS + trailing zero) to `out`. `scratch` is reused between calls.
/// Payloads longer than `MAX_FRAME − 9` are refused (returns `false`, `out` unchanged).
pub fn encode_frame(
    kind: u8,
    seq: u32,
    payload: &[u8],
    scratch: &mut Vec<u8>,
    out: &mut Vec<u8>,
) -> bool {
    if payload.len() + HEADER + TRAILER > MAX_FRAME {
        return false;
    }
    scratch.clear();
    scratch.push(kind);
    scratch.extend_from_slice(&seq.to_le_bytes());
    scratch.extend_from_slice(payload);
    let crc = FRAME_CRC.checksum(scratch);
    scratch.extend_from_slice(&crc.to_le_bytes());
    let start = out.len();
    out.resize(start + cobs::max_encoding_length(scratch.len()), 0);
    let n = cobs::encode(scratch, &mut out[start..]);
    out.truncate(start + n);
    out.push(0);
    true
}

/// A decoded message (host or device side).
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    /// Host: identify.
    Hello,
    /// Host: configure.
    Configure(DaqConfig),
    /// Host: start.
    Start,
    /// Host: stop.
    Stop,
    /// Device: command of type `.0` accepted.
    Ack(u8),
    /// Device: identity `manufacturer,model,serial,firmware`.
    Identity(String),
    /// Device: stream announcement.
    Announce(StreamInfo),
    /// Device: command refused.
    Nak {
        /// Type of the refused command.
        command: u8,
        /// Error code (negative, SCPI-like).
        code: i16,
        /// Explanation.
        message: String,
    },
    /// Device: samples, ADC counts interleaved sample-major.
    Data(Vec<i32>),
    /// Device: status report.
    Status {
        /// Status code.
        code: u16,
        /// Explanation.
        message: String,
    },
}

/// Why a CRC-valid frame's payload could not be understood.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("frame type {kind:#04x}: {detail}")]
pub struct PayloadError {
    /// Frame type.
    pub kind: u8,
    /// What was wrong.
    pub detail: String,
}

/// The payload errors of frame type `.0`, as [`PayloadError`]s.
struct PayloadErrors(u8);

impl FieldErrors for PayloadErrors {
    type Error = PayloadError;
    fn ends_before(&self, field: &str, _left: usize, _needed: usize) -> PayloadError {
        PayloadError {
            kind: self.0,
            detail: format!("payload ends before {field}"),
        }
    }
    fn trailing(&self, count: usize) -> PayloadError {
        PayloadError {
            kind: self.0,
            detail: format!("{count} unexpected trailing bytes"),
        }
    }
    fn not_utf8(&self, _: std::string::FromUtf8Error) -> PayloadError {
        PayloadError {
            kind: self.0,
            detail: "text is not UTF-8".into(),
        }
    }
}

impl Message {
    /// The frame type this message travels in.
    pub fn kind(&self) -> u8 {
        match self {
            Message::Hello => kind::HELLO,
            Message::Configure(_) => kind::CONFIGURE,
            Message::Start => kind::START,
            Message::Stop => kind::STOP,
            Message::Ack(_) => kind::ACK,
            Message::Identity(_) => kind::IDENTITY,
            Message::Announce(_) => kind::ANNOUNCE,
            Message::Nak { .. } => kind::NAK,
            Message::Data(_) => kind::DATA,
            Message::Status { .. } => kind::STATUS,
        }
    }

    /// Writes the payload bytes into `out` (cleared first).
    pub fn write_payload(&self, out: &mut Vec<u8>) {
        out.clear();
        match self {
            Message::Hello | Message::Start | Message::Stop => {}
            Message::Configure(c) => {
                out.extend_from_slice(&c.sample_rate_hz.to_le_bytes());
                out.extend_from_slice(&c.samples_per_block.to_le_bytes());
                out.push(c.channels.len().min(255) as u8);
                for ch in c.channels.iter().take(255) {
                    out.extend_from_slice(&ch.to_le_bytes());
                }
            }
            Message::Ack(k) => out.push(*k),
            Message::Identity(s) => out.extend_from_slice(s.as_bytes()),
            Message::Announce(a) => {
                out.extend_from_slice(&a.sample_rate_hz.to_le_bytes());
                out.extend_from_slice(&a.samples_per_block.to_le_bytes());
                out.push(a.channels.len().min(255) as u8);
                for ch in a.channels.iter().take(255) {
                    out.extend_from_slice(&ch.device_channel.to_le_bytes());
                    out.extend_from_slice(&(ch.volts_per_count as f32).to_le_bytes());
                }
            }
            Message::Nak {
                command,
                code,
                message,
            } => {
                out.push(*command);
                out.extend_from_slice(&code.to_le_bytes());
                out.extend_from_slice(message.as_bytes());
            }
            Message::Data(counts) => {
                for c in counts {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
            Message::Status { code, message } => {
                out.extend_from_slice(&code.to_le_bytes());
                out.extend_from_slice(message.as_bytes());
            }
        }
    }

    /// Parses a CRC-valid frame's payload.
    pub fn parse(frame: &Frame<'_>) -> Result<Message, PayloadError> {
        let mut c = LeReader::new(frame.payload, PayloadErrors(frame.kind));
        let m = match frame.kind {
            kind::HELLO => Message::Hello,
            kind::START => Message::Start,
            kind::STOP => Message::Stop,
            kind::CONFIGURE => {
                let sample_rate_hz = c.f64("sample rate")?;
                let samples_per_block = c.u16("samples per block")?;
                let n = c.u8("channel count")?;
                let mut channels = Vec::with_capacity(n as usize);
                for _ in 0..n {
                    channels.push(c.u16("channel number")?);
                }
                Message::Configure(DaqConfig {
                    sample_rate_hz,
                    channels,
                    samples_per_block,
                })
            }
            kind::ACK => Message::Ack(c.u8("acknowledged type")?),
            kind::IDENTITY => Message::Identity(c.text()?),
            kind::ANNOUNCE => {
                let sample_rate_hz = c.f64("sample rate")?;
                let samples_per_block = c.u16("samples per block")?;
                let n = c.u8("channel count")?;
                let mut channels = Vec::with_capacity(n as usize);
                for _ in 0..n {
                    let device_channel = c.u16("channel number")?;
                    let volts_per_count = c.f32("volts per count")? as f64;
                    channels.push(ChannelInfo {
                        device_channel,
                        volts_per_count,
                    });
                }
                Message::Announce(StreamInfo {
                    sample_rate_hz,
                    channels,
                    samples_per_block,
                })
            }
            kind::NAK => {
                let command = c.u8("refused type")?;
                let code = c.i16("error code")?;
                Message::Nak {
                    command,
                    code,
                    message: c.text()?,
                }
            }
            kind::DATA => {
                if !frame.payload.len().is_multiple_of(4) {
                    return Err(PayloadError {
                        kind: frame.kind,
                        detail: format!(
                            "data payload of {} bytes is not a whole number of 32-bit samples",
                            frame.payload.len()
                        ),
                    });
                }
                let counts = frame
                    .payload
                    .chunks_exact(4)
                    .map(|s| i32::from_le_bytes([s[0], s[1], s[2], s[3]]))
                    .collect();
                c.take_rest();
                Message::Data(counts)
            }
            kind::STATUS => {
                let code = c.u16("status code")?;
                Message::Status {
                    code,
                    message: c.text()?,
                }
            }
            other => {
                return Err(PayloadError {
                    kind: other,
                    detail: "unknown frame type".into(),
                });
            }
        };
        c.end()?;
        Ok(m)
    }

    /// Encodes this message as one frame appended to `out`; `false` if it does not fit in a frame.
    pub fn encode(
        &self,
        seq: u32,
        payload_scratch: &mut Vec<u8>,
        frame_scratch: &mut Vec<u8>,
        out: &mut Vec<u8>,
    ) -> bool {
        self.write_payload(payload_scratch);
        encode_frame(self.kind(), seq, payload_scratch, frame_scratch, out)
    }
}

/// Extends a 32-bit wire counter to the 64-bit block number closest to `expected`.
pub fn unwrap_seq(expected: u64, raw: u32) -> u64 {
    let diff = raw.wrapping_sub(expected as u32) as i32 as i64;
    (expected as i64 + diff).max(0) as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn roundtrip(m: &Message, seq: u32) -> Vec<Result<(u8, u32, Message), String>> {
        let mut out = Vec::new();
        assert!(m.encode(seq, &mut Vec::new(), &mut Vec::new(), &mut out));
        assert_eq!(
            out.iter().filter(|b| **b == 0).count(),
            1,
            "exactly one delimiter"
        );
        let mut dec = FrameDecoder::new();
        let mut got = Vec::new();
        dec.feed(&out, |f| {
            got.push(match f {
                Ok(f) => Message::parse(&f)
                    .map(|m| (f.kind, f.seq, m))
                    .map_err(|e| e.to_string()),
                Err(e) => Err(e.to_string()),
            })
        });
        got
    }

    #[test]
    fn every_message_round_trips() {
        let msgs = vec![
            Message::Hello,
            Message::Start,
            Message::Stop,
            Message::Ack(kind::START),
            Message::Identity("IDENT-SIM,DAQ-8,0001,1.0".into()),
            Message::Configure(DaqConfig {
                sample_rate_hz: 5120.0,
                channels: vec![0, 3, 7],
                samples_per_block: 64,
            }),
            Message::Announce(StreamInfo {
                sample_rate_hz: 5120.0,
                samples_per_block: 64,
                channels: vec![ChannelInfo {
                    device_channel: 3,
                    volts_per_count: 1.0 / 8388608.0,
                }],
            }),
            Message::Nak {
                command: kind::CONFIGURE,
                code: -222,
                message: "rate out of range".into(),
            },
            Message::Data(vec![0, -1, i32::MAX, i32::MIN, 12345]),
            Message::Status {
                code: 2,
                message: "ADC overrun".into(),
            },
        ];
        for m in msgs {
            let got = roundtrip(&m, 0xDEAD_BEEF);
            assert_eq!(got, vec![Ok((m.kind(), 0xDEAD_BEEF, m.clone()))]);
        }
    }

    #[test]
    fn corrupted_byte_is_a_crc_error_and_decoder_resyncs() {
        let mut out = Vec::new();
        let m = Message::Data(vec![1, 2, 3, 4]);
        m.encode(7, &mut Vec::new(), &mut Vec::new(), &mut out);
        let mut bad = out.clone();
        bad[5] ^= 0x10;
        if bad[5] == 0 {
            bad[5] = 0x33;
        }
        bad.extend_from_slice(&out);
        let mut dec = FrameDecoder::new();
        let mut kinds = Vec::new();
        dec.feed(&bad, |f| {
            kinds.push(
                f.map(|f| f.seq)
                    .map_err(|e| matches!(e, FrameError::Crc { .. } | FrameError::Cobs { .. })),
            )
        });
        assert_eq!(kinds, vec![Err(true), Ok(7)]);
    }

    #[test]
    fn oversize_garbage_is_reported_once_then_resyncs() {
        let mut bytes = vec![0x55u8; MAX_FRAME * 2];
        bytes.push(0);
        Message::Hello.encode(1, &mut Vec::new(), &mut Vec::new(), &mut bytes);
        let mut dec = FrameDecoder::new();
        let mut got = Vec::new();
        dec.feed(&bytes, |f| got.push(f.map(|f| f.kind)));
        assert_eq!(got, vec![Err(FrameError::Oversize), Ok(kind::HELLO)]);
    }

    #[test]
    fn unwrap_seq_handles_wrap_and_small_jumps() {
        assert_eq!(unwrap_seq(0, 0), 0);
        assert_eq!(unwrap_seq(10, 13), 13);
        assert_eq!(unwrap_seq(10, 9), 9);
        assert_eq!(unwrap_seq(u32::MAX as u64, 0), u32::MAX as u64 + 1);
        assert_eq!(unwrap_seq(u32::MAX as u64 + 5, 2), u32::MAX as u64 + 3);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 512, rng_seed: proptest::test_runner::RngSeed::Fixed(5), ..ProptestConfig::default() })]

        /// Arbitrary bytes in arbitrary chunks: never panics, and every delimiter yields at most
        /// one result.
        #[test]
        fn decoder_survives_garbage(bytes in proptest::collection::vec(any::<u8>(), 0..3000), split in 0usize..3000) {
            let mut dec = FrameDecoder::new();
            let split = split.min(bytes.len());
            let mut n = 0;
            dec.feed(&bytes[..split], |f| { n += 1; if let Ok(f) = f { let _ = Message::parse(&f); } });
            dec.feed(&bytes[split..], |f| { n += 1; if let Ok(f) = f { let _ = Message::parse(&f); } });
            let zeros = bytes.iter().filter(|b| **b == 0).count();
            prop_assert!(n <= zeros);
        }

        /// Valid frames interleaved with garbage ending in a delimiter are all recovered, in order,
        /// regardless of chunking.
        #[test]
        fn frames_survive_garbage_between_them(
            payloads in proptest::collection::vec(proptest::collection::vec(any::<i32>(), 0..64), 1..8),
            garbage in proptest::collection::vec(1u8..=255, 0..50),
            chunk in 1usize..97,
        ) {
            let mut stream = Vec::new();
            let (mut a, mut b) = (Vec::new(), Vec::new());
            for (i, p) in payloads.iter().enumerate() {
                stream.extend_from_slice(&garbage);
                stream.push(0);
                Message::Data(p.clone()).encode(i as u32, &mut a, &mut b, &mut stream);
            }
            let mut dec = FrameDecoder::new();
            let mut good = Vec::new();
            for c in stream.chunks(chunk) {
                dec.feed(c, |f| if let Ok(f) = f { if let Ok(Message::Data(d)) = Message::parse(&f) { good.push((f.seq, d)); } });
            }
            let want: Vec<(u32, Vec<i32>)> = payloads.iter().cloned().enumerate().map(|(i, p)| (i as u32, p)).collect();
            prop_assert_eq!(good, want);
        }

        /// Any single-bit flip in a frame is never accepted as a different valid frame.
        #[test]
        fn bit_flips_are_detected(payload in proptest::collection::vec(any::<i32>(), 1..32), pos in any::<usize>(), bit in 0u8..8) {
            let mut frame = Vec::new();
            Message::Data(payload.clone()).encode(3, &mut Vec::new(), &mut Vec::new(), &mut frame);
            let pos = pos % (frame.len() - 1);
            frame[pos] ^= 1 << bit;
            frame.push(0);
            let mut dec = FrameDecoder::new();
            let mut accepted = Vec::new();
            dec.feed(&frame, |f| if let Ok(f) = f { if let Ok(Message::Data(d)) = Message::parse(&f) { accepted.push(d); } });
            // A flip may split the frame (creating a zero); no resulting piece may be accepted
            // as data unless it is exactly the original.
            for d in accepted { prop_assert_eq!(d, payload.clone()); }
        }
    }
}
