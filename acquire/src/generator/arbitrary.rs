//! Arbitrary waveforms uploaded as samples: each model's upload commands, DAC code range, byte
//! order and limits (the `[model.arbitrary]` entries of `models.toml`, data rather than code),
//! the samples as DAC codes in an IEEE 488.2 definite-length binary block (`#<n><len><bytes>`)
//! or a comma list, and the block-aware command framing an instrument reads them with.

use serde::{Deserialize, Serialize};

/// How the uploaded points travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DataFormat {
    /// IEEE 488.2 definite-length binary block of 16-bit codes, `#<n><len><bytes>`.
    BinaryBlock,
    /// Decimal codes separated by commas.
    CommaList,
}

/// Byte order of the 16-bit codes in a binary block.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ByteOrder {
    /// Least-significant byte first (SCPI `FORMat:BORDer SWAPped`).
    Little,
    /// Most-significant byte first (SCPI `FORMat:BORDer NORMal`).
    Big,
}

/// What the rate command sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RateSetting {
    /// The sample rate (Sa/s).
    SampleRate,
    /// The waveform's repetition frequency (Hz): sample rate over the number of points.
    RepetitionFrequency,
}

/// One model's arbitrary-waveform commands. Templates: `{ch}` channel number, `{value}` a
/// number, `{block}` the data (binary block or comma list). Every command is confirmed (`*OPC?`)
/// and followed by reading the error queue, the upload included.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ArbitraryDialect {
    /// Settings sent before the upload (byte order, clearing the volatile memory, rate mode).
    #[serde(default)]
    pub before_upload: Vec<String>,
    /// The upload, `{block}` standing for the data.
    pub upload: String,
    /// Settings that select the uploaded waveform afterwards.
    #[serde(default)]
    pub select: Vec<String>,
    /// Sets the rate (`{value}`).
    pub rate: String,
    /// What `rate` sets.
    pub rate_is: RateSetting,
    /// How the points travel.
    pub data: DataFormat,
    /// Byte order of a binary block.
    pub byte_order: ByteOrder,
    /// DAC code of the waveform's negative full scale (−amplitude/2 in Vpp terms).
    pub code_min: i32,
    /// DAC code of the positive full scale.
    pub code_max: i32,
    /// Fewest points the model accepts.
    pub min_points: usize,
    /// Most points one upload may carry.
    pub max_points: usize,
    /// Highest sample rate (Sa/s).
    pub max_sample_rate_hz: f64,
}

/// A waveform beyond one model's arbitrary-waveform limits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArbitraryLimitError {
    /// Too few or too many points for one upload.
    #[error("{points} points, the model takes {min}..{max} per upload")]
    Points {
        /// Points asked for.
        points: usize,
        /// Fewest the model takes.
        min: usize,
        /// Most the model takes.
        max: usize,
    },
    /// A sample rate the model does not play.
    #[error("a sample rate of {rate_hz} Sa/s, the model plays at most {max_hz} Sa/s")]
    SampleRate {
        /// Rate asked for (Sa/s).
        rate_hz: f64,
        /// Highest the model plays (Sa/s).
        max_hz: f64,
    },
}

impl ArbitraryDialect {
    /// Checks a waveform of `points` at `sample_rate_hz` against the model's limits; the error
    /// names what is exceeded and the limit.
    pub fn check(&self, points: usize, sample_rate_hz: f64) -> Result<(), ArbitraryLimitError> {
        if points < self.min_points || points > self.max_points {
            return Err(ArbitraryLimitError::Points {
                points,
                min: self.min_points,
                max: self.max_points,
            });
        }
        if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0)
            || sample_rate_hz > self.max_sample_rate_hz
        {
            return Err(ArbitraryLimitError::SampleRate {
                rate_hz: sample_rate_hz,
                max_hz: self.max_sample_rate_hz,
            });
        }
        Ok(())
    }

    /// Samples in −1..1 (full scale) as the model's DAC codes (rounded, clamped).
    pub fn codes(&self, samples: &[f64]) -> Vec<i32> {
        let mid = 0.5 * (f64::from(self.code_max) + f64::from(self.code_min));
        let half = 0.5 * (f64::from(self.code_max) - f64::from(self.code_min));
        samples
            .iter()
            .map(|x| {
                let c = (mid + half * x.clamp(-1.0, 1.0)).round();
                (c as i32).clamp(self.code_min, self.code_max)
            })
            .collect()
    }

    /// DAC codes back as samples in −1..1.
    pub fn samples(&self, codes: &[i32]) -> Vec<f64> {
        let mid = 0.5 * (f64::from(self.code_max) + f64::from(self.code_min));
        let half = 0.5 * (f64::from(self.code_max) - f64::from(self.code_min));
        codes.iter().map(|c| (f64::from(*c) - mid) / half).collect()
    }

    /// The codes as this model's data: a binary block (16 bits per point in `byte_order`) or a
    /// comma list.
    pub fn data_bytes(&self, codes: &[i32]) -> Vec<u8> {
        match self.data {
            DataFormat::CommaList => codes
                .iter()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(",")
                .into_bytes(),
            DataFormat::BinaryBlock => {
                let mut payload = Vec::with_capacity(2 * codes.len());
                for &c in codes {
                    // Codes are within code_min..code_max: 16 bits, signed or unsigned.
                    let w = c as u16;
                    match self.byte_order {
                        ByteOrder::Little => payload.extend_from_slice(&w.to_le_bytes()),
                        ByteOrder::Big => payload.extend_from_slice(&w.to_be_bytes()),
                    }
                }
                definite_block(&payload)
            }
        }
    }

    /// The codes a binary block's payload (or a comma list) carries, in this model's encoding;
    /// `None` if it is malformed.
    pub fn decode(&self, data: &[u8]) -> Option<Vec<i32>> {
        match self.data {
            DataFormat::CommaList => std::str::from_utf8(data)
                .ok()?
                .split(',')
                .map(|w| w.trim().parse::<i32>().ok())
                .collect(),
            DataFormat::BinaryBlock => {
                if !data.len().is_multiple_of(2) {
                    return None;
                }
                let signed = self.code_min < 0;
                Some(
                    data.chunks_exact(2)
                        .map(|b| {
                            let w = match self.byte_order {
                                ByteOrder::Little => u16::from_le_bytes([b[0], b[1]]),
                                ByteOrder::Big => u16::from_be_bytes([b[0], b[1]]),
                            };
                            if signed {
                                i32::from(w as i16)
                            } else {
                                i32::from(w)
                            }
                        })
                        .collect(),
                )
            }
        }
    }
}

/// `payload` as an IEEE 488.2 definite-length block: `#`, the number of length digits, the
/// length in bytes, the bytes.
pub fn definite_block(payload: &[u8]) -> Vec<u8> {
    let len = payload.len().to_string();
    let mut out = Vec::with_capacity(payload.len() + len.len() + 2);
    out.push(b'#');
    out.extend_from_slice(len.len().to_string().as_bytes());
    out.extend_from_slice(len.as_bytes());
    out.extend_from_slice(payload);
    out
}

/// One command as an instrument frames it: its text, with a definite-length block's payload
/// taken out (`text` ends where the block's `#` was).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramedCommand {
    /// The command's text (the part before a block).
    pub text: String,
    /// A binary block's payload, if the command carried one.
    pub block: Option<Vec<u8>>,
    /// True if the bytes were not a valid command (not text, or a block header that is not one).
    pub garbage: bool,
}

/// Longest command text accepted (a comma list of 64 k points fits).
const MAX_TEXT: usize = 1 << 20;

/// Frames commands the way an IEEE 488.2 instrument parses them: up to the line terminator,
/// except that the bytes of a definite-length block (`#<n><len>`) are taken as data even when
/// they contain a newline.
#[derive(Debug, Default)]
pub struct CommandFramer {
    text: Vec<u8>,
    block: Option<Vec<u8>>,
    /// Header digits of a block being read: `Some(n)` after `#n`, with the length so far.
    header: Option<(usize, String)>,
    /// Payload bytes still expected.
    remaining: usize,
    garbage: bool,
}

impl CommandFramer {
    /// An empty framer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds bytes; calls `sink` for every complete command.
    pub fn feed(&mut self, bytes: &[u8], mut sink: impl FnMut(FramedCommand)) {
        for &b in bytes {
            if self.remaining > 0 {
                if let Some(p) = self.block.as_mut() {
                    p.push(b);
                }
                self.remaining -= 1;
                continue;
            }
            if let Some((n, digits)) = self.header.as_mut() {
                if *n == 0 {
                    // `#` then the digit count.
                    match (b as char).to_digit(10) {
                        Some(d) if d > 0 => *n = d as usize,
                        _ => {
                            self.garbage = true;
                            self.header = None;
                        }
                    }
                    continue;
                }
                match (b as char).to_digit(10) {
                    Some(_) => digits.push(b as char),
                    None => self.garbage = true,
                }
                if digits.len() == *n || self.garbage {
                    let len = digits.parse::<usize>().unwrap_or(0);
                    self.header = None;
                    self.block = Some(Vec::with_capacity(len.min(MAX_TEXT)));
                    self.remaining = len;
                }
                continue;
            }
            match b {
                b'\n' => {
                    if self.text.last() == Some(&b'\r') {
                        self.text.pop();
                    }
                    let text = String::from_utf8(std::mem::take(&mut self.text));
                    let garbage = self.garbage
                        || text
                            .as_ref()
                            .map_or(true, |t| t.chars().any(|c| c.is_control() && c != '\t'));
                    sink(FramedCommand {
                        text: text.unwrap_or_default(),
                        block: self.block.take(),
                        garbage,
                    });
                    self.garbage = false;
                }
                b'#' if self.block.is_none() && !in_quotes(&self.text) => {
                    self.header = Some((0, String::new()));
                }
                _ if self.block.is_some() => {
                    // Only the terminator may follow a block.
                    if !b.is_ascii_whitespace() {
                        self.garbage = true;
                    }
                }
                _ if self.text.len() < MAX_TEXT => self.text.push(b),
                _ => self.garbage = true,
            }
        }
    }
}

/// True if `text` ends inside a quoted string.
fn in_quotes(text: &[u8]) -> bool {
    text.iter().filter(|&&c| c == b'"').count() % 2 == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dialect(data: DataFormat, order: ByteOrder, lo: i32, hi: i32) -> ArbitraryDialect {
        ArbitraryDialect {
            before_upload: vec![],
            upload: "DATA {block}".into(),
            select: vec![],
            rate: "SRAT {value}".into(),
            rate_is: RateSetting::SampleRate,
            data,
            byte_order: order,
            code_min: lo,
            code_max: hi,
            min_points: 8,
            max_points: 16384,
            max_sample_rate_hz: 60e6,
        }
    }

    #[test]
    fn codes_cover_the_dac_range_and_come_back() {
        let k = dialect(DataFormat::BinaryBlock, ByteOrder::Little, -32767, 32767);
        assert_eq!(
            k.codes(&[-1.0, 0.0, 1.0, 2.0]),
            vec![-32767, 0, 32767, 32767]
        );
        let r = dialect(DataFormat::BinaryBlock, ByteOrder::Little, 0, 16383);
        assert_eq!(r.codes(&[-1.0, 1.0]), vec![0, 16383]);
        let back = r.samples(&r.codes(&[0.25]));
        assert!((back[0] - 0.25).abs() < 1.0 / 8191.0, "{back:?}");
    }

    #[test]
    fn binary_blocks_in_both_byte_orders_and_comma_lists_round_trip() {
        let codes = vec![-32767, -1, 0, 1, 10, 32767];
        for order in [ByteOrder::Little, ByteOrder::Big] {
            let d = dialect(DataFormat::BinaryBlock, order, -32767, 32767);
            let block = d.data_bytes(&codes);
            assert_eq!(&block[..4], b"#212", "{order:?}");
            assert_eq!(d.decode(&block[4..]).unwrap(), codes);
        }
        let little = dialect(DataFormat::BinaryBlock, ByteOrder::Little, -32767, 32767);
        assert_eq!(&little.data_bytes(&[1])[3..], &[1, 0]);
        let big = dialect(DataFormat::BinaryBlock, ByteOrder::Big, -32767, 32767);
        assert_eq!(&big.data_bytes(&[1])[3..], &[0, 1]);
        let u = dialect(DataFormat::BinaryBlock, ByteOrder::Big, 0, 16383);
        assert_eq!(
            u.decode(&u.data_bytes(&[0, 16383])[3..]).unwrap(),
            [0, 16383]
        );
        let c = dialect(DataFormat::CommaList, ByteOrder::Big, -32767, 32767);
        assert_eq!(c.data_bytes(&[3, -4]), b"3,-4");
        assert_eq!(c.decode(b"3,-4").unwrap(), [3, -4]);
        assert!(c.decode(b"3,x").is_none());
        assert_eq!(definite_block(&[0u8; 1000])[..6], *b"#41000");
    }

    #[test]
    fn limits_name_what_is_exceeded() {
        let d = dialect(DataFormat::BinaryBlock, ByteOrder::Little, 0, 16383);
        assert!(d.check(4096, 5120.0).is_ok());
        assert!(d
            .check(20000, 5120.0)
            .unwrap_err()
            .to_string()
            .contains("8..16384"));
        assert!(d.check(4, 5120.0).is_err());
        assert!(d
            .check(4096, 1e9)
            .unwrap_err()
            .to_string()
            .contains("60000000"));
    }

    #[test]
    fn the_framer_takes_a_blocks_newlines_as_data() {
        let mut f = CommandFramer::new();
        let mut got = Vec::new();
        let mut bytes = b"*IDN?\nDATA:DAC VOLATILE,".to_vec();
        bytes.extend_from_slice(&definite_block(&[b'\n', 0, b'#', b'\r']));
        bytes.extend_from_slice(b"\r\nSYST:ERR?\n");
        // In pieces, as a socket delivers them.
        for chunk in bytes.chunks(3) {
            f.feed(chunk, |c| got.push(c));
        }
        assert_eq!(got.len(), 3, "{got:?}");
        assert_eq!(got[0].text, "*IDN?");
        assert_eq!(got[1].text, "DATA:DAC VOLATILE,");
        assert_eq!(got[1].block.as_deref(), Some(&[b'\n', 0, b'#', b'\r'][..]));
        assert!(!got[1].garbage);
        assert_eq!(got[2].text, "SYST:ERR?");
        let mut bad = Vec::new();
        f.feed(b"DATA #x12\nOK\n", |c| bad.push(c));
        assert!(bad[0].garbage, "{bad:?}");
        assert_eq!(bad.last().unwrap().text, "OK");
        let mut quoted = Vec::new();
        f.feed(b"DISP:TEXT \"#1\"\n", |c| quoted.push(c));
        assert_eq!(quoted[0].text, "DISP:TEXT \"#1\"");
        assert!(quoted[0].block.is_none());
    }
}
