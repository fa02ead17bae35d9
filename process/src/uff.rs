//! Universal file format (UFF/UNV) dataset 58: functions at nodal DOFs (FRFs, time histories,
//! spectra, coherences), in ASCII and in the binary variant 58b, as exchanged with modal-analysis
//! tools. Other datasets in a file are skipped.
//!
//! The reader is tolerant where real files differ (CRLF line ends, Fortran `D` exponents, numbers
//! run together in fixed-width fields, short lines) and strict where data would be lost: a value
//! count that disagrees with record 7, a missing end marker or a truncated binary block is an
//! error naming the file, the dataset and the line.
//!
//! Note on precision: record 7 holds the abscissa start and increment as `E13.5` (6 significant
//! digits), as the format defines; ASCII ordinates are written `E20.12` (13 digits) for double
//! precision, 58b stores them bit-exactly.

use std::path::Path;

use num_complex::Complex;

use rfe::channel::{ChannelName, MeasuredChannel, NoUsableUnit};
use rfe::frf_units::FrfUnit;
use rfe::model::Quantity;

use crate::error::{ProcessError, Result};

type C64 = Complex<f64>;

/// Function type codes of record 6 used here.
pub mod function_type {
    /// Time response.
    pub const TIME_RESPONSE: u32 = 1;
    /// Auto-spectrum.
    pub const AUTO_SPECTRUM: u32 = 2;
    /// Cross-spectrum.
    pub const CROSS_SPECTRUM: u32 = 3;
    /// Frequency response function.
    pub const FRF: u32 = 4;
    /// Transmissibility (a response per the same quantity of a base motion).
    pub const TRANSMISSIBILITY: u32 = 5;
    /// Coherence.
    pub const COHERENCE: u32 = 6;
}

/// Abscissa of a function.
#[derive(Debug, Clone, PartialEq)]
pub enum Abscissa {
    /// `x_n = min + n·increment`.
    Even {
        /// First abscissa value (s or Hz).
        min: f64,
        /// Spacing.
        increment: f64,
    },
    /// Explicit values, one per point.
    Uneven(Vec<f64>),
}

/// Ordinate values.
#[derive(Debug, Clone, PartialEq)]
pub enum Ordinate {
    /// Real values (time histories, auto-spectra, coherence).
    Real(Vec<f64>),
    /// Complex values (FRFs, cross-spectra).
    Complex(Vec<C64>),
}

impl Ordinate {
    /// Number of points.
    pub fn len(&self) -> usize {
        match self {
            Ordinate::Real(v) => v.len(),
            Ordinate::Complex(v) => v.len(),
        }
    }
    /// True if no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Data characteristics of one axis (records 8-11).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Axis {
    /// Specific data type (0 unknown, 1 general, 8 displacement, 11 velocity, 12 acceleration,
    /// 13 excitation force, 17 time, 18 frequency, ...).
    pub spec_data_type: i64,
    /// Length units exponent.
    pub length_exp: i64,
    /// Force units exponent.
    pub force_exp: i64,
    /// Temperature units exponent.
    pub temperature_exp: i64,
    /// Axis label (≤ 20 characters).
    pub label: String,
    /// Units label (≤ 20 characters).
    pub units: String,
}

/// One dataset 58.
#[derive(Debug, Clone, PartialEq)]
pub struct Function {
    /// Records 1-5: free text (≤ 80 characters each; record 3 is usually the date).
    pub ids: [String; 5],
    /// Function type (see [`function_type`]).
    pub func_type: u32,
    /// Function identification number.
    pub func_id: i64,
    /// Version or sequence number.
    pub version: i64,
    /// Load case.
    pub load_case: i64,
    /// Response entity name.
    pub response_entity: String,
    /// Response node.
    pub response_node: i64,
    /// Response direction (±1..±6 = ±X,Y,Z,RX,RY,RZ; 0 scalar).
    pub response_dir: i64,
    /// Reference entity name.
    pub reference_entity: String,
    /// Reference node.
    pub reference_node: i64,
    /// Reference direction.
    pub reference_dir: i64,
    /// Double precision (ordinate data types 4/6) rather than single (2/5).
    pub double: bool,
    /// Abscissa.
    pub abscissa: Abscissa,
    /// Z-axis value.
    pub z_value: f64,
    /// Abscissa, ordinate numerator, ordinate denominator, z axis.
    pub axes: [Axis; 4],
    /// Values.
    pub data: Ordinate,
}

impl Function {
    /// A complex FRF at evenly spaced frequencies (Hz).
    pub fn frf(name: &str, f0_hz: f64, df_hz: f64, h: Vec<C64>) -> Function {
        let mut f = Function::blank(
            function_type::FRF,
            Abscissa::Even {
                min: f0_hz,
                increment: df_hz,
            },
            Ordinate::Complex(h),
        );
        f.ids[0] = name.into();
        f.axes[0].spec_data_type = 18;
        f.axes[0].label = "Frequency".into();
        f.axes[0].units = "Hz".into();
        f
    }

    /// A complex FRF at the frequencies `freqs_hz` (Hz, any spacing) between the response at
    /// `response` and the excitation at `reference`, each a node and a direction (±1..±6 =
    /// ±X,Y,Z,RX,RY,RZ).
    pub fn frf_between(
        name: &str,
        freqs_hz: Vec<f64>,
        h: Vec<C64>,
        response: (i64, i64),
        reference: (i64, i64),
    ) -> Function {
        let mut f = Function::frf(name, 0.0, 0.0, h);
        f.abscissa = Abscissa::Uneven(freqs_hz);
        (f.response_node, f.response_dir) = response;
        (f.reference_node, f.reference_dir) = reference;
        f
    }

    /// A real time history sampled at `sample_rate_hz` from t = 0.
    pub fn time_history(name: &str, sample_rate_hz: f64, samples: Vec<f64>) -> Function {
        let mut f = Function::blank(
            function_type::TIME_RESPONSE,
            Abscissa::Even {
                min: 0.0,
                increment: 1.0 / sample_rate_hz,
            },
            Ordinate::Real(samples),
        );
        f.ids[0] = name.into();
        f.axes[0].spec_data_type = 17;
        f.axes[0].label = "Time".into();
        f.axes[0].units = "s".into();
        f
    }

    fn blank(func_type: u32, abscissa: Abscissa, data: Ordinate) -> Function {
        Function {
            ids: [
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
                "NONE".into(),
            ],
            func_type,
            func_id: 0,
            version: 0,
            load_case: 0,
            response_entity: "NONE".into(),
            response_node: 1,
            response_dir: 1,
            reference_entity: "NONE".into(),
            reference_node: 1,
            reference_dir: 1,
            double: true,
            abscissa,
            z_value: 0.0,
            axes: Default::default(),
            data,
        }
    }

    /// Abscissa values (one per point).
    pub fn x(&self) -> Vec<f64> {
        match &self.abscissa {
            Abscissa::Even { min, increment } => (0..self.data.len())
                .map(|i| min + i as f64 * increment)
                .collect(),
            Abscissa::Uneven(x) => x.clone(),
        }
    }

    /// This function as a recorded [`crate::Signal`]: it must be a real, evenly sampled time
    /// response (function type 1). Named after record 1 (or `fallback_name` if that is empty or
    /// "NONE").
    pub fn to_signal(&self, fallback_name: &str) -> Result<crate::Signal> {
        let name = match self.ids[0].trim() {
            "" | "NONE" => fallback_name.to_string(),
            s => s.to_string(),
        };
        let fail = |m: String| ProcessError::Format {
            file: name.clone(),
            location: "dataset 58".into(),
            message: m,
        };
        if self.func_type != function_type::TIME_RESPONSE {
            return Err(fail(format!(
                "function type {} is not a time response (1)",
                self.func_type
            )));
        }
        let increment = match self.abscissa {
            Abscissa::Even { increment, .. } if increment.is_finite() && increment > 0.0 => {
                increment
            }
            Abscissa::Even { increment, .. } => {
                return Err(fail(format!("time increment {increment} s must be > 0")))
            }
            Abscissa::Uneven(_) => {
                return Err(fail(
                    "unevenly sampled time history: resample it first".into(),
                ))
            }
        };
        match &self.data {
            Ordinate::Real(v) => Ok(crate::Signal {
                name,
                sample_rate_hz: 1.0 / increment,
                samples: v.clone(),
            }),
            Ordinate::Complex(_) => Err(fail("complex time history: expected real samples".into())),
        }
    }

    fn ord_type(&self) -> i64 {
        match (&self.data, self.double) {
            (Ordinate::Real(_), false) => 2,
            (Ordinate::Real(_), true) => 4,
            (Ordinate::Complex(_), false) => 5,
            (Ordinate::Complex(_), true) => 6,
        }
    }

    /// Flat list of stored values in file order.
    fn values(&self) -> Vec<f64> {
        let xs = match &self.abscissa {
            Abscissa::Uneven(x) => Some(x),
            Abscissa::Even { .. } => None,
        };
        let mut out = Vec::new();
        match &self.data {
            Ordinate::Real(v) => {
                for (i, y) in v.iter().enumerate() {
                    if let Some(x) = xs {
                        out.push(x[i]);
                    }
                    out.push(*y);
                }
            }
            Ordinate::Complex(v) => {
                for (i, y) in v.iter().enumerate() {
                    if let Some(x) = xs {
                        out.push(x[i]);
                    }
                    out.push(y.re);
                    out.push(y.im);
                }
            }
        }
        out
    }
}

/// ASCII (58) or binary (58b).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// Dataset 58, text.
    Ascii,
    /// Dataset 58b, little-endian IEEE binary data block.
    Binary,
}

/// Reads every dataset 58/58b of a file.
pub fn read(path: &Path) -> Result<Vec<Function>> {
    let bytes = std::fs::read(path).map_err(|source| ProcessError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&bytes, &path.display().to_string())
}

/// Writes datasets to a file.
pub fn write(path: &Path, functions: &[Function], encoding: Encoding) -> Result<()> {
    let bytes = to_bytes(functions, encoding)?;
    std::fs::write(path, bytes).map_err(|source| ProcessError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Fortran-style `Ew.d`: `-1.23456E+02`, exponent at least two digits, right-aligned in `w`.
fn fmt_e(v: f64, w: usize, d: usize) -> String {
    let s = if v == 0.0 {
        format!("{:.*}E+00", d, 0.0)
    } else if !v.is_finite() {
        format!("{v}")
    } else {
        let r = format!("{:.*e}", d, v);
        let (m, e) = r.split_once('e').unwrap_or((&r, "0"));
        let e: i32 = e.parse().unwrap_or(0);
        format!("{m}E{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
    };
    format!("{s:>w$}")
}

fn clip(s: &str, n: usize) -> String {
    s.chars().take(n).collect()
}

/// Serializes datasets.
pub fn to_bytes(functions: &[Function], encoding: Encoding) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    for (i, f) in functions.iter().enumerate() {
        let n = f.data.len();
        if n == 0 {
            return Err(ProcessError::Format {
                file: "<output>".into(),
                location: format!("dataset {}", i + 1),
                message: "has no points; UFF 58 needs at least one".into(),
            });
        }
        if let Abscissa::Uneven(x) = &f.abscissa {
            if x.len() != n {
                return Err(ProcessError::Format {
                    file: "<output>".into(),
                    location: format!("dataset {}", i + 1),
                    message: format!("{} abscissa values for {n} points", x.len()),
                });
            }
        }
        let values = f.values();
        out.extend_from_slice(header(f, encoding, values.len()).as_bytes());
        data_block(&mut out, f, encoding, &values);
        out.extend_from_slice(b"    -1\n");
    }
    Ok(out)
}

/// The delimiter and records 1-11 of one dataset 58 (58b: with the binary block's size).
fn header(f: &Function, encoding: Encoding, n_values: usize) -> String {
    let n = f.data.len();
    let width = if f.double { 8 } else { 4 };
    let mut h = String::new();
    h.push_str("    -1\n");
    match encoding {
        Encoding::Ascii => h.push_str(&format!("{:>6}{:74}\n", 58, "")),
        Encoding::Binary => h.push_str(&format!(
            "{:>6}b{:>6}{:>6}{:>12}{:>12}{:>6}{:>6}{:>12}{:>12}\n",
            58,
            1,
            2,
            11,
            n_values * width,
            0,
            0,
            0,
            0
        )),
    }
    for id in &f.ids {
        h.push_str(&format!("{:<80}\n", clip(id, 80)));
    }
    h.push_str(&format!(
        "{:>5}{:>10}{:>5}{:>10} {:<10}{:>10}{:>4} {:<10}{:>10}{:>4}\n",
        f.func_type,
        f.func_id,
        f.version,
        f.load_case,
        clip(&f.response_entity, 10),
        f.response_node,
        f.response_dir,
        clip(&f.reference_entity, 10),
        f.reference_node,
        f.reference_dir
    ));
    let (even, min, inc) = match &f.abscissa {
        Abscissa::Even { min, increment } => (1, *min, *increment),
        Abscissa::Uneven(_) => (0, 0.0, 0.0),
    };
    h.push_str(&format!(
        "{:>10}{:>10}{:>10}{}{}{}\n",
        f.ord_type(),
        n,
        even,
        fmt_e(min, 13, 5),
        fmt_e(inc, 13, 5),
        fmt_e(f.z_value, 13, 5)
    ));
    for a in &f.axes {
        h.push_str(&format!(
            "{:>10}{:>5}{:>5}{:>5} {:<20} {:<20}\n",
            a.spec_data_type,
            a.length_exp,
            a.force_exp,
            a.temperature_exp,
            clip(&a.label, 20),
            clip(&a.units, 20)
        ));
    }
    h
}

/// The data block: little-endian IEEE values (58b) or fixed-width text lines (the format's
/// E13.5 for single precision and uneven abscissas, E20.12 for double values).
fn data_block(out: &mut Vec<u8>, f: &Function, encoding: Encoding, values: &[f64]) {
    let even = matches!(f.abscissa, Abscissa::Even { .. });
    match encoding {
        Encoding::Binary => {
            for v in values {
                if f.double {
                    out.extend_from_slice(&v.to_le_bytes());
                } else {
                    out.extend_from_slice(&(*v as f32).to_le_bytes());
                }
            }
        }
        Encoding::Ascii => {
            let mut s = String::new();
            // Per line: a pattern of (width, decimals) fields.
            let pattern: Vec<(usize, usize)> = match (f.double, even, &f.data) {
                (false, _, _) => vec![(13, 5); 6],
                (true, true, _) => vec![(20, 12); 4],
                (true, false, Ordinate::Real(_)) => vec![(13, 5), (20, 12), (13, 5), (20, 12)],
                (true, false, Ordinate::Complex(_)) => vec![(13, 5), (20, 12), (20, 12)],
            };
            for chunk in values.chunks(pattern.len()) {
                for (v, (w, d)) in chunk.iter().zip(&pattern) {
                    s.push_str(&fmt_e(*v, *w, *d));
                }
                s.push('\n');
            }
            out.extend_from_slice(s.as_bytes());
        }
    }
}

/// Reader position over the file's bytes.
struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
    line: usize,
    file: &'a str,
}

impl<'a> Cursor<'a> {
    /// Next line without its `\n`/`\r\n`, or None at end of file.
    fn next_line(&mut self) -> Option<&'a [u8]> {
        if self.pos >= self.bytes.len() {
            return None;
        }
        let rest = &self.bytes[self.pos..];
        let end = rest.iter().position(|b| *b == b'\n').unwrap_or(rest.len());
        self.pos += (end + 1).min(rest.len());
        self.line += 1;
        let mut l = &rest[..end];
        if l.last() == Some(&b'\r') {
            l = &l[..l.len() - 1];
        }
        Some(l)
    }

    fn err(&self, dataset: usize, message: impl Into<String>) -> ProcessError {
        ProcessError::Format {
            file: self.file.to_string(),
            location: format!("dataset {dataset} (line {})", self.line),
            message: message.into(),
        }
    }
}

fn is_delimiter(line: &[u8]) -> bool {
    line.trim_ascii() == b"-1"
}

/// Fixed-width field of columns `[start, start+w)` of a header line, counted in characters
/// (blank if the line is shorter): a header line written by a tool counts columns in characters,
/// so a `Prüfstand` or `m/s²` earlier on the line must not shift the fields after it.
fn field(line: &str, start: usize, w: usize) -> String {
    let s: String = line.chars().skip(start).take(w).collect();
    s.trim().to_string()
}

/// A header line as text: UTF-8 when it is valid UTF-8, else Latin-1 (ISO 8859-1, one byte per
/// character, as older Windows tools write `Prüfstand` or `m/s²`); never a lossy replacement,
/// which would turn one Latin-1 byte into three bytes and shift the columns after it.
fn header_text(line: &[u8]) -> String {
    match std::str::from_utf8(line) {
        Ok(s) => s.to_string(),
        Err(_) => line.iter().map(|&b| char::from(b)).collect(),
    }
}

fn parse_f64(s: &str) -> Option<f64> {
    let t: String = s
        .trim()
        .chars()
        .map(|c| if c == 'D' || c == 'd' { 'E' } else { c })
        .collect();
    t.parse::<f64>().ok()
}

/// Splits a data line into numeric tokens: at whitespace, and before a sign that follows a digit
/// or point (fixed-width fields run together, e.g. `1.0E+00-2.0E+00`).
fn tokens(line: &str, out: &mut Vec<String>) {
    let mut cur = String::new();
    let mut prev: Option<char> = None;
    for c in line.chars() {
        if c.is_whitespace() {
            if !cur.is_empty() {
                out.push(std::mem::take(&mut cur));
            }
        } else if (c == '-' || c == '+')
            && !cur.is_empty()
            && prev.is_some_and(|p| p.is_ascii_digit() || p == '.')
        {
            out.push(std::mem::take(&mut cur));
            cur.push(c);
        } else {
            cur.push(c);
        }
        prev = if c.is_whitespace() { None } else { Some(c) };
    }
    if !cur.is_empty() {
        out.push(cur);
    }
}

/// A dataset of another type than 58/58b, skipped by the reader and reported.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedDataset {
    /// Position of the dataset in the file (1-based).
    pub dataset: usize,
    /// Its type as written (`"151"`, `"164"`, `"2414"`, ...).
    pub kind: String,
    /// Line of its type record (1-based).
    pub line: usize,
}

impl std::fmt::Display for SkippedDataset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "dataset {} (line {}) is of type {}, not 58/58b: skipped",
            self.dataset, self.line, self.kind
        )
    }
}

/// The datasets 58/58b of a file and the other datasets it skipped.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct UffFile {
    /// Every dataset 58/58b, in file order.
    pub functions: Vec<Function>,
    /// Every other dataset, skipped (so a caller can say so rather than drop it silently).
    pub skipped: Vec<SkippedDataset>,
    /// For each of `functions`: its position in the file (1-based) and the line of its type
    /// record, for messages.
    pub positions: Vec<(usize, usize)>,
}

/// Parses all datasets 58/58b in `bytes`; `file` names the source in errors.
pub fn parse(bytes: &[u8], file: &str) -> Result<Vec<Function>> {
    parse_file(bytes, file).map(|u| u.functions)
}

/// Reads every dataset 58/58b of a file, with the datasets of other types it skipped.
pub fn read_file(path: &Path) -> Result<UffFile> {
    let bytes = std::fs::read(path).map_err(|source| ProcessError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_file(&bytes, &path.display().to_string())
}

/// True when `bytes` look like a UFF file: the first non-blank line is the delimiter `-1`.
pub fn looks_like_uff(bytes: &[u8]) -> bool {
    bytes
        .split(|b| *b == b'\n')
        .map(<[u8]>::trim_ascii)
        .find(|l| !l.is_empty())
        .is_some_and(|l| l == b"-1")
}

/// Parses all datasets 58/58b in `bytes` and lists the datasets of other types it skipped.
pub fn parse_file(bytes: &[u8], file: &str) -> Result<UffFile> {
    let mut c = Cursor {
        bytes,
        pos: 0,
        line: 0,
        file,
    };
    let mut out = Vec::new();
    let mut skipped = Vec::new();
    let mut positions = Vec::new();
    let mut dataset = 0;
    loop {
        // Find the start delimiter.
        let line = loop {
            match c.next_line() {
                None => {
                    return Ok(UffFile {
                        functions: out,
                        skipped,
                        positions,
                    })
                }
                Some(l) if is_delimiter(l) => break l,
                Some(l) if l.trim_ascii().is_empty() => continue,
                Some(l) => {
                    let shown = String::from_utf8_lossy(&l[..l.len().min(40)]).into_owned();
                    return Err(c.err(dataset + 1, format!("expected the dataset delimiter '    -1', found {shown:?}: the file is not UFF or a previous dataset has the wrong length")));
                }
            }
        };
        let _ = line;
        dataset += 1;
        let header = c
            .next_line()
            .ok_or_else(|| c.err(dataset, "file ends after the delimiter: truncated"))?;
        let header = String::from_utf8_lossy(header).into_owned();
        let kind = header
            .split_whitespace()
            .next()
            .unwrap_or("")
            .to_ascii_lowercase();
        if kind == "58" || kind == "58b" {
            positions.push((dataset, c.line));
        }
        match kind.as_str() {
            "58" => out.push(parse_58(&mut c, dataset, None)?),
            "58b" => {
                let f: Vec<&str> = header.split_whitespace().collect();
                let num = |i: usize, what: &str| -> Result<i64> {
                    f.get(i).and_then(|s| s.parse::<i64>().ok()).ok_or_else(|| {
                        c.err(
                            dataset,
                            format!("58b header lacks the {what} field (header: {header:?})"),
                        )
                    })
                };
                let order = num(1, "byte order")?;
                let fp = num(2, "floating-point format")?;
                let n_ascii = num(3, "ASCII line count")?;
                let n_bytes = num(4, "byte count")?;
                if fp != 2 {
                    return Err(c.err(dataset, format!("58b floating-point format {fp} is not IEEE 754 (2); convert the file to IEEE")));
                }
                if order != 1 && order != 2 {
                    return Err(c.err(dataset, format!("58b byte order {order} is neither 1 (little endian) nor 2 (big endian)")));
                }
                if n_ascii != 11 {
                    return Err(c.err(dataset, format!("58b header says {n_ascii} ASCII lines; dataset 58 has 11 (records 1-11)")));
                }
                if n_bytes < 0 {
                    return Err(c.err(dataset, format!("58b byte count {n_bytes} is negative")));
                }
                out.push(parse_58(
                    &mut c,
                    dataset,
                    Some((order == 1, n_bytes as usize)),
                )?);
            }
            _ => {
                // Another dataset type: skip to its end delimiter, and say so.
                skipped.push(SkippedDataset {
                    dataset,
                    kind: header.split_whitespace().next().unwrap_or("").to_string(),
                    line: c.line,
                });
                loop {
                    match c.next_line() {
                        None => {
                            return Err(c.err(
                                dataset,
                                format!(
                                    "dataset {kind:?} has no end delimiter '    -1': truncated"
                                ),
                            ))
                        }
                        Some(l) if is_delimiter(l) => break,
                        Some(_) => {}
                    }
                }
            }
        }
    }
}

fn parse_58(c: &mut Cursor, dataset: usize, binary: Option<(bool, usize)>) -> Result<Function> {
    let rec = header_records(c, dataset)?;
    let int = |line: &str, start: usize, w: usize, what: &str, r: usize, c: &Cursor| {
        int_field(c, dataset, line, (start, w), what, r)
    };
    let r6 = &rec[5];
    let func_type = int(r6, 0, 5, "function type", 6, c)?;
    if field(r6, 0, 5).is_empty() || func_type < 0 {
        return Err(c.err(
            dataset,
            format!("record 6 has no valid function type in columns 1-5 ({r6:?})"),
        ));
    }
    let layout = Layout::of_record_7(&rec[6], c, dataset)?;
    let mut axes: [Axis; 4] = Default::default();
    for (a, axis) in axes.iter_mut().enumerate() {
        let l = &rec[7 + a];
        *axis = Axis {
            spec_data_type: int(l, 0, 10, "specific data type", 8 + a, c)?,
            length_exp: int(l, 10, 5, "length units exponent", 8 + a, c)?,
            force_exp: int(l, 15, 5, "force units exponent", 8 + a, c)?,
            temperature_exp: int(l, 20, 5, "temperature units exponent", 8 + a, c)?,
            label: field(l, 26, 20),
            units: field(l, 47, 20),
        };
    }
    let values = match binary {
        Some((little, n_bytes)) => binary_values(c, dataset, &layout, little, n_bytes)?,
        None => ascii_values(c, dataset, &layout)?,
    };
    let (abscissa, data) = layout.split(values);
    let ids = [0, 1, 2, 3, 4].map(|i| rec[i].trim_end().to_string());
    Ok(Function {
        ids,
        func_type: func_type as u32,
        func_id: int(r6, 5, 10, "function id", 6, c)?,
        version: int(r6, 15, 5, "version", 6, c)?,
        load_case: int(r6, 20, 10, "load case", 6, c)?,
        response_entity: field(r6, 31, 10),
        response_node: int(r6, 41, 10, "response node", 6, c)?,
        response_dir: int(r6, 51, 4, "response direction", 6, c)?,
        reference_entity: field(r6, 56, 10),
        reference_node: int(r6, 66, 10, "reference node", 6, c)?,
        reference_dir: int(r6, 76, 4, "reference direction", 6, c)?,
        double: layout.double,
        abscissa,
        z_value: layout.z_value,
        axes,
        data,
    })
}

/// Records 1-11 of a dataset 58 header, as text.
fn header_records(c: &mut Cursor, dataset: usize) -> Result<Vec<String>> {
    let mut rec = Vec::with_capacity(11);
    for r in 1..=11 {
        let l = c.next_line().ok_or_else(|| {
            c.err(
                dataset,
                format!("file ends before record {r} of 11: truncated header"),
            )
        })?;
        if is_delimiter(l) {
            return Err(c.err(dataset, format!("end delimiter where record {r} was expected: the header has only {} of 11 records", r - 1)));
        }
        rec.push(header_text(l));
    }
    Ok(rec)
}

/// The integer in columns `start..start + width` of header record `r` (0 when blank).
fn int_field(
    c: &Cursor,
    dataset: usize,
    line: &str,
    (start, width): (usize, usize),
    what: &str,
    r: usize,
) -> Result<i64> {
    let s = field(line, start, width);
    if s.is_empty() {
        return Ok(0);
    }
    s.parse::<i64>().map_err(|_| {
        c.err(
            dataset,
            format!("record {r} field '{what}' is {s:?}, not an integer"),
        )
    })
}

/// What record 7 says about the data block.
struct Layout {
    ord_type: i64,
    /// Number of points.
    n: usize,
    /// 1 even abscissa, 0 uneven (each point carries its abscissa).
    even: i64,
    min: f64,
    inc: f64,
    z_value: f64,
    complex: bool,
    double: bool,
    /// Values per point.
    per: usize,
    /// Values in the block.
    expected: usize,
}

impl Layout {
    fn of_record_7(r7: &str, c: &Cursor, dataset: usize) -> Result<Layout> {
        let int = |start, w, what| int_field(c, dataset, r7, (start, w), what, 7);
        let ord_type = int(0, 10, "ordinate data type")?;
        let num_pts = int(10, 10, "number of points")?;
        let even = int(20, 10, "abscissa spacing")?;
        let real7 = |start: usize, what: &str| -> Result<f64> {
            let s = field(r7, start, 13);
            if s.is_empty() {
                return Ok(0.0);
            }
            parse_f64(&s).ok_or_else(|| {
                c.err(
                    dataset,
                    format!("record 7 field '{what}' is {s:?}, not a number"),
                )
            })
        };
        let min = real7(30, "abscissa minimum")?;
        let inc = real7(43, "abscissa increment")?;
        let z_value = real7(56, "z-axis value")?;
        let (complex, double) = match ord_type {
            2 => (false, false),
            4 => (false, true),
            5 => (true, false),
            6 => (true, true),
            t => {
                return Err(c.err(
                    dataset,
                    format!("record 7 ordinate data type {t} is not 2, 4, 5 or 6 (real/complex, single/double)"),
                ))
            }
        };
        if num_pts <= 0 {
            return Err(c.err(
                dataset,
                format!("record 7 number of points is {num_pts}; must be ≥ 1"),
            ));
        }
        if even != 0 && even != 1 {
            return Err(c.err(
                dataset,
                format!("record 7 abscissa spacing is {even}; must be 0 (uneven) or 1 (even)"),
            ));
        }
        let n = num_pts as usize;
        let per = if complex { 2 } else { 1 } + if even == 0 { 1 } else { 0 };
        let expected = n
            .checked_mul(per)
            .filter(|e| *e < 1 << 40)
            .ok_or_else(|| c.err(dataset, format!("record 7 number of points {n} is absurd")))?;
        Ok(Layout {
            ord_type,
            n,
            even,
            min,
            inc,
            z_value,
            complex,
            double,
            per,
            expected,
        })
    }

    /// The abscissa and ordinates of the block's values.
    fn split(&self, values: Vec<f64>) -> (Abscissa, Ordinate) {
        let Layout {
            min,
            inc,
            complex,
            per,
            ..
        } = *self;
        let (abscissa, data) = if self.even == 1 {
            let data = if complex {
                Ordinate::Complex(
                    values
                        .chunks_exact(2)
                        .map(|p| C64::new(p[0], p[1]))
                        .collect(),
                )
            } else {
                Ordinate::Real(values)
            };
            (
                Abscissa::Even {
                    min,
                    increment: inc,
                },
                data,
            )
        } else {
            let x: Vec<f64> = values.chunks_exact(per).map(|p| p[0]).collect();
            let data = if complex {
                Ordinate::Complex(
                    values
                        .chunks_exact(3)
                        .map(|p| C64::new(p[1], p[2]))
                        .collect(),
                )
            } else {
                Ordinate::Real(values.chunks_exact(2).map(|p| p[1]).collect())
            };
            (Abscissa::Uneven(x), data)
        };
        (abscissa, data)
    }
}

/// The values of a 58b binary block (record 7 decides its size), and its end delimiter.
fn binary_values(
    c: &mut Cursor,
    dataset: usize,
    layout: &Layout,
    little: bool,
    n_bytes: usize,
) -> Result<Vec<f64>> {
    let Layout {
        n,
        ord_type,
        double,
        expected,
        ..
    } = *layout;
    let width = if double { 8 } else { 4 };
    // Record 7 decides the block size: some writers (pyuff ≤ 2.5 for complex data) put
    // half the true byte count in the 58b header. The end delimiter must follow the block.
    let need = expected * width;
    let end = c.pos.checked_add(need).filter(|e| *e <= c.bytes.len()).ok_or_else(|| {
    c.err(dataset, format!("binary block of {need} bytes (record 7: {n} points, type {ord_type}; header says {n_bytes}) runs past the end of the file ({} bytes left): truncated", c.bytes.len() - c.pos))
})?;
    let block = &c.bytes[c.pos..end];
    c.pos = end;
    let v = if double {
        block
            .chunks_exact(8)
            .map(|b| {
                let a = [b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]];
                if little {
                    f64::from_le_bytes(a)
                } else {
                    f64::from_be_bytes(a)
                }
            })
            .collect()
    } else {
        block
            .chunks_exact(4)
            .map(|b| {
                let a = [b[0], b[1], b[2], b[3]];
                (if little {
                    f32::from_le_bytes(a)
                } else {
                    f32::from_be_bytes(a)
                }) as f64
            })
            .collect()
    };
    // The end delimiter may follow directly or after a line break.
    loop {
        match c.next_line() {
        None => return Err(c.err(dataset, "no end delimiter '    -1' after the binary block: truncated")),
        Some(l) if is_delimiter(l) => break,
        Some(l) if l.trim_ascii().is_empty() => continue,
        Some(_) => {
            return Err(c.err(dataset, format!("no end delimiter after the {need}-byte binary block that record 7 announces ({n} points, type {ord_type}; header says {n_bytes} bytes): wrong record length")))
        }
    }
    }
    Ok(v)
}

/// The values of an ASCII data block, up to its end delimiter.
fn ascii_values(c: &mut Cursor, dataset: usize, layout: &Layout) -> Result<Vec<f64>> {
    let Layout {
        n,
        ord_type,
        expected,
        ..
    } = *layout;
    let mut v = Vec::with_capacity(expected.min(1 << 24));
    let mut toks = Vec::new();
    loop {
        let l = c.next_line().ok_or_else(|| c.err(dataset, format!("file ends after {} of {expected} values and without the end delimiter: truncated", v.len())))?;
        if is_delimiter(l) {
            break;
        }
        let text = std::str::from_utf8(l).map_err(|_| {
            c.err(
                dataset,
                "data line is not text (binary data in an ASCII dataset 58?)",
            )
        })?;
        toks.clear();
        tokens(text, &mut toks);
        for t in &toks {
            let x = parse_f64(t)
                .ok_or_else(|| c.err(dataset, format!("data value {t:?} is not a number")))?;
            v.push(x);
        }
        if v.len() > expected {
            return Err(c.err(dataset, format!("more than the {expected} values record 7 announces ({n} points, type {ord_type}): wrong record length")));
        }
    }
    if v.len() != expected {
        return Err(c.err(dataset, format!("{} values before the end delimiter, record 7 announces {expected} ({n} points, type {ord_type}): truncated or wrong record length", v.len())));
    }
    Ok(v)
}

/// The FRFs of a UFF file (function type 4) as measured channels for identification
/// (the `identify` crate's `measurement_map` maps them onto a model): response node and
/// direction, reference, abscissa converted to Hz (record 8's unit; Hz when it gives none, and
/// noted), values as amplitude and phase, the unit from records 9-10 (the ordinate's numerator
/// and denominator units labels, checked against the numerator's specific data type), and the
/// coherence of a matching function type 6. Returns the channels and notes (datasets skipped,
/// functions not used, what was assumed).
pub fn measured_channels(
    file: &UffFile,
    origin: &str,
) -> Result<(Vec<MeasuredChannel>, Vec<String>)> {
    let mut notes: Vec<String> = file.skipped.iter().map(|s| s.to_string()).collect();
    let mut channels = Vec::new();
    let mut coherences = Vec::new();
    for (f, &(dataset, line)) in file.functions.iter().zip(&file.positions) {
        let item = format!("dataset {dataset} (line {line})");
        let fail = |field: &str, message: String| ProcessError::Format {
            file: origin.to_string(),
            location: format!("{item}, {field}"),
            message,
        };
        match f.func_type {
            function_type::FRF | function_type::TRANSMISSIBILITY => {}
            function_type::COHERENCE => {
                coherences.push((f, item));
                continue;
            }
            t => {
                notes.push(format!(
                    "{item}: function type {t} is not an FRF (4) or a transmissibility (5): not used"
                ));
                continue;
            }
        }
        let freqs =
            frequencies_hz(f, &mut notes, &item).map_err(|m| fail("record 8 (abscissa)", m))?;
        let (amplitude, phase_rad) = match &f.data {
            Ordinate::Complex(v) => (
                v.iter().map(|h| h.norm()).collect(),
                Some(v.iter().map(|h| h.arg()).collect()),
            ),
            Ordinate::Real(v) => {
                notes.push(format!(
                    "{item}: real-valued FRF, used as amplitudes without phase"
                ));
                (v.iter().map(|x| x.abs()).collect(), None)
            }
        };
        if !(1..=6).contains(&f.response_dir.abs()) {
            return Err(fail(
                "record 6 field 'response direction'",
                format!("{} is not ±1..6 (X, Y, Z, RX, RY, RZ); the measurement map needs a node and direction", f.response_dir),
            ));
        }
        let (num, den) = (f.axes[1].units.trim(), f.axes[2].units.trim());
        channels.push(MeasuredChannel {
            name: ChannelName::Node {
                node: f.response_node,
                dir: f.response_dir,
            },
            item: item.clone(),
            reference: Some((f.reference_node, f.reference_dir)),
            unit: ordinate_unit(f).map_err(NoUsableUnit),
            unit_source: format!("{item} records 9-10: \"{num}\" per \"{den}\""),
            freqs_hz: freqs,
            amplitude,
            phase_rad,
            coherence: None,
        });
    }
    for (g, item) in coherences {
        let key = (
            g.response_node,
            g.response_dir,
            g.reference_node,
            g.reference_dir,
        );
        let values = match &g.data {
            Ordinate::Real(v) => v.clone(),
            Ordinate::Complex(v) => v.iter().map(|c| c.re).collect(),
        };
        let target = channels.iter_mut().find(|c| {
            matches!(c.name, ChannelName::Node { node, dir } if (node, dir) == (key.0, key.1))
                && c.reference == Some((key.2, key.3))
        });
        match target {
            Some(c) if c.freqs_hz.len() == values.len() && c.coherence.is_none() => {
                c.coherence = Some(values);
                notes.push(format!("{item}: coherence of {}", c.name));
            }
            _ => notes.push(format!("{item}: coherence without a matching FRF (same nodes, directions and lines): not used")),
        }
    }
    if channels.is_empty() {
        return Err(ProcessError::Format {
            file: origin.to_string(),
            location: "every dataset".into(),
            message: format!(
                "no frequency response function (dataset 58/58b of function type 4, or 5 for a transmissibility) in the file; it holds: {}. Export the FRFs (H1, accelerance/mobility/receptance) as UFF58",
                if notes.is_empty() { "nothing".to_string() } else { notes.join("; ") }
            ),
        });
    }
    Ok((channels, notes))
}

/// The abscissa in Hz: record 8's units label read by the one unit parser (`Hz`, `kHz`), `rad/s`
/// divided by 2π, none given → Hz (noted); a time abscissa is an error.
fn frequencies_hz(
    f: &Function,
    notes: &mut Vec<String>,
    item: &str,
) -> std::result::Result<Vec<f64>, String> {
    let a = &f.axes[0];
    if a.spec_data_type == 17 {
        return Err("the abscissa is time (specific data type 17); an FRF needs frequency".into());
    }
    let label = a.units.trim();
    let factor = if label.is_empty() || label.eq_ignore_ascii_case("none") {
        notes.push(format!("{item}: record 8 gives no abscissa unit: Hz assumed (the UFF convention for frequency)"));
        1.0
    } else if label.eq_ignore_ascii_case("rad/s") {
        1.0 / (2.0 * std::f64::consts::PI)
    } else {
        rfe::units::parse_quantity(&format!("1 {label}"), rfe::units::Dim::FREQUENCY)
            .map_err(|e| format!("field 'units label' \"{label}\": {e}; use Hz, kHz or rad/s"))?
    };
    Ok(f.x().into_iter().map(|x| x * factor).collect())
}

/// The unit of an FRF's values from records 9 (numerator) and 10 (denominator), or why not.
fn ordinate_unit(f: &Function) -> std::result::Result<FrfUnit, String> {
    let (num, den) = (f.axes[1].units.trim(), f.axes[2].units.trim());
    let empty = |s: &str| s.is_empty() || s.eq_ignore_ascii_case("none");
    if empty(num) {
        return Err(format!(
            "record 9 (ordinate numerator, specific data type {}) has no units label",
            f.axes[1].spec_data_type
        ));
    }
    let transmissibility = f.func_type == function_type::TRANSMISSIBILITY;
    let unit = match FrfUnit::parse(num) {
        Ok(u) if u.per_force || u.per_base_motion => u,
        // A transmissibility whose denominator is not written: the ratio of like quantities.
        _ if transmissibility && empty(den) => FrfUnit::parse(&format!("({num})/({num})"))
            .map_err(|e| format!("record 9 units \"{num}\" of a transmissibility: {e}"))?,
        _ if empty(den) => {
            return Err(format!(
                "record 10 (ordinate denominator) has no units label, so the force unit of \"{num}\" is unknown"
            ))
        }
        _ => FrfUnit::parse(&format!("({num})/({den})"))
            .map_err(|e| format!("records 9-10 units \"{num}\" per \"{den}\": {e}"))?,
    };
    if transmissibility && !unit.per_base_motion {
        return Err(format!(
            "function type 5 (transmissibility), but records 9-10 units \"{num}\" per \"{den}\" are a {}; a transmissibility is a response per the same quantity (g/g, m/m)",
            unit.kind()
        ));
    }
    if unit.per_base_motion {
        return Ok(unit);
    }
    if !unit.per_force {
        return Err(format!(
            "records 9-10 units \"{num}\" per \"{den}\" are not a response per force"
        ));
    }
    let declared = match f.axes[1].spec_data_type {
        8 => Some(Quantity::Displacement),
        11 => Some(Quantity::Velocity),
        12 => Some(Quantity::Acceleration),
        _ => None,
    };
    if let Some(q) = declared.filter(|q| *q != unit.quantity) {
        return Err(format!(
            "record 9 says {} (specific data type {}) but its units \"{num}\" per \"{den}\" are a {}",
            q.as_str(),
            f.axes[1].spec_data_type,
            unit.kind()
        ));
    }
    Ok(unit)
}
