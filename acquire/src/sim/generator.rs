//! The simulated signal generator + power amplifier + shaker: serves the SCPI function-generator
//! command set (long and short forms, the manuals' optional nodes, channel suffixes, an error
//! queue) on a pseudo-terminal or a local TCP port, and turns the generator's volts into the
//! exciter's force through the amplifier's true gain — which the simulated DAQ then measures
//! through the shaker–structure interaction like any other force. An arbitrary waveform uploaded
//! as a binary block (`SOUR:DATA:ARB:DAC name,#...`) is played at the sample rate set, looping.
//! Injectable faults: the amplifier trips (force drops to nothing, the generator's output stays
//! on) or surges.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use super::signal::ArbitraryDrive;
use super::{lock, send_answer, InjectedFault, SharedRef};
use crate::device::DeviceIdentity;
use crate::generator::arbitrary::{CommandFramer, FramedCommand};
use crate::shaker::scpi::Function;
use crate::transport::Transport;

/// Most points the simulated generator's arbitrary memory holds.
pub const MAX_ARBITRARY_POINTS: usize = 65_536;

/// Highest arbitrary sample rate of the simulated generator (Sa/s).
pub const MAX_SAMPLE_RATE_HZ: f64 = 1e6;

/// Largest peak voltage the simulated generator delivers into a high-impedance load (V), like
/// the 20 Vpp of the real instruments.
pub const MAX_VOLTS_PEAK: f64 = 10.0;

/// What the simulated generator and amplifier are.
#[derive(Debug, Clone, PartialEq)]
pub struct SimGeneratorSetup {
    /// The `*IDN?` answer.
    pub identity: DeviceIdentity,
    /// The channel wired to the amplifier (the other channel drives nothing).
    pub channel: u8,
    /// True amplifier + shaker gain: force amplitude per generator volt (N/V).
    pub amplifier_gain_n_per_v: f64,
    /// The amplifier trips when the generator receives this many frequency settings (lines).
    pub amplifier_trip_after_lines: Option<u64>,
    /// The amplifier's gain surges by `surge_factor` after this many frequency settings.
    pub amplifier_surge_after_lines: Option<u64>,
    /// Gain factor of a surge.
    pub surge_factor: f64,
}

/// One setting the simulated generator accepted, for tests: what and the value (V peak, Hz,
/// 1/0 for the output).
#[derive(Debug, Clone, PartialEq)]
pub struct Accepted {
    /// `amplitude`, `frequency`, `output`.
    pub what: &'static str,
    /// Value.
    pub value: f64,
    /// Output state after it.
    pub output_on: bool,
}

/// The simulated generator's state (channel `channel` of [`SimGeneratorSetup`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratorState {
    /// Output on.
    pub output_on: bool,
    /// Amplitude (V peak at a high-impedance load).
    pub volts_peak: f64,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Sine selected.
    pub sine: bool,
    /// Amplitude unit: true VRMS, false VPP.
    pub vrms: bool,
    /// DC offset (V).
    pub offset_v: f64,
    /// Load setting (Ω; infinite = high impedance). A 50 Ω setting driving the amplifier's high
    /// impedance doubles the real voltage, as on the real instruments.
    pub load_ohm: f64,
    /// The amplifier tripped.
    pub amplifier_tripped: bool,
    /// Amplifier gain factor (1, or the surge factor).
    pub gain_factor: f64,
    /// Frequency settings received.
    pub lines: u64,
    /// The arbitrary function selected (`FUNC ARB`).
    pub arbitrary: bool,
    /// The waveform in volatile memory (name, its samples −1..1), once uploaded.
    pub uploaded: Option<(String, Arc<ArbitraryDrive>)>,
    /// The waveform `FUNC:ARB` selected.
    pub selected: Option<String>,
    /// Arbitrary sample rate (Sa/s).
    pub sample_rate_hz: f64,
    /// Binary blocks least-significant byte first (`FORM:BORD SWAP`).
    pub swapped: bool,
    /// Every accepted setting of the amplifier's channel.
    pub log: Vec<Accepted>,
    errors: VecDeque<(i32, String)>,
}

impl Default for GeneratorState {
    fn default() -> Self {
        GeneratorState {
            output_on: false,
            volts_peak: 0.05,
            frequency_hz: 1000.0,
            sine: true,
            vrms: false,
            offset_v: 0.0,
            load_ohm: 50.0,
            amplifier_tripped: false,
            gain_factor: 1.0,
            lines: 0,
            arbitrary: false,
            uploaded: None,
            selected: None,
            sample_rate_hz: 40_000.0,
            swapped: false,
            log: Vec::new(),
            errors: VecDeque::new(),
        }
    }
}

/// A simulated generator shared by its connections and the simulated DAQ.
#[derive(Clone)]
pub struct SimGenerator {
    setup: SimGeneratorSetup,
    state: Arc<Mutex<GeneratorState>>,
    shared: SharedRef,
}

impl SimGenerator {
    pub(super) fn new(setup: SimGeneratorSetup, shared: SharedRef) -> SimGenerator {
        SimGenerator {
            setup,
            state: Arc::new(Mutex::new(GeneratorState::default())),
            shared,
        }
    }

    /// The generator's state now.
    pub fn state(&self) -> GeneratorState {
        self.state.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Serves one connection until it closes (a TCP client leaving) or, on a pty, forever.
    pub(super) async fn serve<T: Transport>(&self, mut io: T, pty: bool) {
        let mut framer = CommandFramer::new();
        let mut buf = vec![0u8; 4096];
        loop {
            let Some(got) = read_commands(&mut io, &mut framer, &mut buf, &self.shared, pty).await
            else {
                return;
            };
            for c in got {
                let answer = if c.garbage {
                    self.push_error(-100, "Command error");
                    None
                } else {
                    self.handle(&c)
                };
                if !send_answer(&mut io, answer).await {
                    return;
                }
            }
        }
    }

    /// Accepts TCP connections on `listener` and serves them one after another.
    pub(super) async fn serve_tcp(&self, listener: tokio::net::TcpListener) {
        loop {
            let Ok((stream, peer)) = listener.accept().await else {
                tokio::time::sleep(Duration::from_millis(10)).await;
                continue;
            };
            let _ = stream.set_nodelay(true);
            let io = crate::transport::TcpTransport::from_stream(
                &format!("sim-generator:{peer}"),
                stream,
            );
            self.serve(io, false).await;
            if lock(&self.shared).cable_pulled {
                return;
            }
        }
    }

    fn push_error(&self, code: i32, message: &str) {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if st.errors.len() >= 10 {
            st.errors.pop_back();
            st.errors.push_back((-350, "Queue overflow".into()));
        } else {
            st.errors.push_back((code, message.into()));
        }
    }

    /// One command; the answer line for a query.
    fn handle(&self, c: &FramedCommand) -> Option<String> {
        let r = match &c.block {
            Some(block) => self.upload(&c.text, block),
            None => self.apply(&c.text),
        };
        match r {
            Ok(answer) => answer,
            Err((code, message)) => {
                self.push_error(code, &message);
                None
            }
        }
    }

    /// `SOUR{ch}:DATA:ARB:DAC name,<block>`: signed 16-bit codes, most-significant byte first
    /// unless `FORM:BORD SWAP`.
    fn upload(&self, text: &str, block: &[u8]) -> Result<Option<String>, (i32, String)> {
        let (header, args) = text
            .trim()
            .split_once(char::is_whitespace)
            .unwrap_or((text, ""));
        let (path, channel) = canonical(header)?;
        if path != ["DATA", "ARB", "DAC"] {
            return Err((-113, "Undefined header".into()));
        }
        let name = args
            .trim()
            .trim_end_matches(',')
            .trim()
            .to_ascii_uppercase();
        if name.is_empty() || name.len() > 12 || !args.trim().ends_with(',') {
            return Err((-109, "Missing parameter;name,<block>".into()));
        }
        if !block.len().is_multiple_of(2) {
            return Err((-161, "Invalid block data;odd byte count".into()));
        }
        let points = block.len() / 2;
        if points > MAX_ARBITRARY_POINTS {
            return Err((-223, "Too much data".into()));
        }
        if points < 8 {
            return Err((-222, "Data out of range;at least 8 points".into()));
        }
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let samples = block
            .chunks_exact(2)
            .map(|b| {
                let w = if st.swapped {
                    i16::from_le_bytes([b[0], b[1]])
                } else {
                    i16::from_be_bytes([b[0], b[1]])
                };
                f64::from(w.max(-32767)) / 32767.0
            })
            .collect();
        if channel != self.setup.channel {
            return Ok(None);
        }
        st.uploaded = Some((
            name,
            Arc::new(ArbitraryDrive {
                samples,
                sample_rate_hz: st.sample_rate_hz,
            }),
        ));
        self.drive(&st);
        Ok(None)
    }

    fn apply(&self, line: &str) -> Result<Option<String>, (i32, String)> {
        let line = line.trim();
        let (header, args) = match line.split_once(char::is_whitespace) {
            Some((h, a)) => (h, a.trim()),
            None => (line, ""),
        };
        let query = header.ends_with('?');
        let header = header.trim_end_matches('?');
        if let Some(common) = header.strip_prefix('*') {
            return self.common(&common.to_ascii_uppercase(), query);
        }
        let (path, channel) = canonical(header)?;
        if !(1..=2).contains(&channel) {
            return Err((-114, "Header suffix out of range".into()));
        }
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        if path == ["SYST", "ERR"] && query {
            return Ok(Some(match st.errors.pop_front() {
                Some((c, m)) => format!("{c},\"{m}\""),
                None => "0,\"No error\"".into(),
            }));
        }
        // Channel 2 is not wired: it accepts settings and drives nothing.
        let ours = channel == self.setup.channel;
        let mut scratch = GeneratorState::default();
        let s: &mut GeneratorState = if ours { &mut st } else { &mut scratch };
        let answer = match (path.as_slice(), query) {
            (["FUNC"], false) => {
                let w = word(args);
                s.sine = match w.as_str() {
                    "SIN" | "SINUSOID" => true,
                    "SQU" | "SQUARE" | "RAMP" | "PULS" | "PULSE" | "NOIS" | "NOISE" | "DC"
                    | "ARB" | "ARBITRARY" | "PRBS" | "TRI" | "TRIANGLE" => false,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                s.arbitrary = matches!(w.as_str(), "ARB" | "ARBITRARY");
                None
            }
            (["FUNC"], true) => Some(
                if s.sine {
                    "SIN"
                } else if s.arbitrary {
                    "ARB"
                } else {
                    "NOIS"
                }
                .into(),
            ),
            (["FUNC", "ARB"], false) => {
                let name = args.trim().trim_matches('"').to_ascii_uppercase();
                if s.uploaded.as_ref().map(|(n, _)| n) != Some(&name) {
                    return Err((-224, "Illegal parameter value;no such arb waveform".into()));
                }
                s.selected = Some(name);
                None
            }
            (["FUNC", "ARB", "SRAT"], false) => {
                let r = number(args)?;
                if !(1e-6..=MAX_SAMPLE_RATE_HZ).contains(&r) {
                    return Err((-222, "Data out of range".into()));
                }
                s.sample_rate_hz = r;
                if let Some((_, a)) = &mut s.uploaded {
                    *a = Arc::new(ArbitraryDrive {
                        samples: a.samples.clone(),
                        sample_rate_hz: r,
                    });
                }
                None
            }
            (["FUNC", "ARB", "SRAT"], true) => Some(format!("{:E}", s.sample_rate_hz)),
            (["DATA", "VOL", "CLE"], false) => {
                s.uploaded = None;
                s.selected = None;
                None
            }
            (["FORM", "BORD"], false) => {
                s.swapped = match word(args).as_str() {
                    "NORM" | "NORMAL" => false,
                    "SWAP" | "SWAPPED" => true,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                None
            }
            (["FREQ"], false) => {
                let f = number(args)?;
                if !(1e-6..=20e6).contains(&f) {
                    return Err((-222, "Data out of range".into()));
                }
                s.frequency_hz = f;
                if ours {
                    s.lines += 1;
                    s.log.push(Accepted {
                        what: "frequency",
                        value: f,
                        output_on: s.output_on,
                    });
                }
                None
            }
            (["FREQ"], true) => Some(format!("{:E}", s.frequency_hz)),
            (["VOLT"], false) => {
                let x = number(args)?;
                let peak = if s.vrms {
                    x * std::f64::consts::SQRT_2
                } else {
                    0.5 * x
                };
                if !(0.0005 - 1e-12..=MAX_VOLTS_PEAK).contains(&peak)
                    || peak + s.offset_v.abs() > MAX_VOLTS_PEAK
                {
                    return Err((-222, "Data out of range".into()));
                }
                s.volts_peak = peak;
                s.log.push(Accepted {
                    what: "amplitude",
                    value: peak,
                    output_on: s.output_on,
                });
                None
            }
            (["VOLT"], true) => Some(format!(
                "{:E}",
                if s.vrms {
                    s.volts_peak / std::f64::consts::SQRT_2
                } else {
                    2.0 * s.volts_peak
                }
            )),
            (["VOLT", "UNIT"], false) => {
                s.vrms = match word(args).as_str() {
                    "VPP" => false,
                    "VRMS" => true,
                    "DBM" => {
                        return Err((-221, "Settings conflict;dBm needs a 50 Ohm load".into()))
                    }
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                None
            }
            (["VOLT", "UNIT"], true) => Some(if s.vrms { "VRMS" } else { "VPP" }.into()),
            (["VOLT", "OFFS"], false) => {
                let v = number(args)?;
                if v.abs() + s.volts_peak > MAX_VOLTS_PEAK {
                    return Err((-222, "Data out of range".into()));
                }
                s.offset_v = v;
                None
            }
            (["VOLT", "OFFS"], true) => Some(format!("{:E}", s.offset_v)),
            (["OUTP"], false) => {
                s.output_on = match word(args).as_str() {
                    "ON" | "1" => true,
                    "OFF" | "0" => false,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                let on = s.output_on;
                s.log.push(Accepted {
                    what: "output",
                    value: f64::from(u8::from(on)),
                    output_on: on,
                });
                None
            }
            (["OUTP"], true) => Some(if s.output_on { "1" } else { "0" }.into()),
            (["OUTP", "LOAD"] | ["OUTP", "IMP"], false) => {
                s.load_ohm = match word(args).as_str() {
                    "INF" | "INFINITY" | "MAX" | "MAXIMUM" => f64::INFINITY,
                    _ => {
                        let r = number(args)?;
                        if !(1.0..=10_000.0).contains(&r) {
                            return Err((-222, "Data out of range".into()));
                        }
                        r
                    }
                };
                None
            }
            (["OUTP", "LOAD"] | ["OUTP", "IMP"], true) => Some(if s.load_ohm.is_infinite() {
                "9.9E+37".into()
            } else {
                format!("{:E}", s.load_ohm)
            }),
            _ => return Err((-113, "Undefined header".into())),
        };
        if ours && !query {
            self.faults(&mut st);
            self.drive(&st);
        }
        Ok(answer)
    }

    /// IEEE 488.2 common commands.
    fn common(&self, name: &str, query: bool) -> Result<Option<String>, (i32, String)> {
        match (name, query) {
            ("IDN", true) => Ok(Some(self.setup.identity.to_idn())),
            ("OPC", true) => Ok(Some("1".into())),
            ("OPC", false) => Ok(None),
            ("RST", false) => {
                let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
                let keep = (
                    std::mem::take(&mut st.log),
                    std::mem::take(&mut st.errors),
                    st.lines,
                    st.amplifier_tripped,
                    st.gain_factor,
                );
                *st = GeneratorState::default();
                (
                    st.log,
                    st.errors,
                    st.lines,
                    st.amplifier_tripped,
                    st.gain_factor,
                ) = keep;
                self.drive(&st);
                Ok(None)
            }
            ("CLS", false) => {
                self.state
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .errors
                    .clear();
                Ok(None)
            }
            _ => Err((-113, "Undefined header".into())),
        }
    }

    /// Injects the amplifier faults due at this many lines.
    fn faults(&self, st: &mut GeneratorState) {
        let due = |k: Option<u64>| k.is_some_and(|k| st.lines > k);
        if !st.amplifier_tripped && due(self.setup.amplifier_trip_after_lines) {
            st.amplifier_tripped = true;
            lock(&self.shared).injected.push(InjectedFault {
                kind: "amplifier_trip",
                seq: st.lines,
            });
        }
        if st.gain_factor == 1.0 && due(self.setup.amplifier_surge_after_lines) {
            st.gain_factor = self.setup.surge_factor;
            lock(&self.shared).injected.push(InjectedFault {
                kind: "amplifier_surge",
                seq: st.lines,
            });
        }
    }

    /// The force the amplifier and shaker now deliver, for the simulated DAQ.
    fn drive(&self, st: &GeneratorState) {
        let load_factor = if st.load_ohm.is_finite() { 2.0 } else { 1.0 };
        let force = if st.amplifier_tripped {
            0.0
        } else {
            st.volts_peak * load_factor * self.setup.amplifier_gain_n_per_v * st.gain_factor
        };
        let playing = match (&st.uploaded, &st.selected) {
            (Some((name, a)), Some(sel)) if st.arbitrary && name == sel => Some(a.clone()),
            _ => None,
        };
        let mut sh = lock(&self.shared);
        let exc = &mut sh.excitation;
        exc.output_on = st.output_on && (st.sine || playing.is_some());
        exc.function = if st.sine || playing.is_none() {
            Function::Sine
        } else {
            Function::Random
        };
        exc.arbitrary = if st.sine { None } else { playing };
        exc.freq_hz = st.frequency_hz;
        exc.force_n = force;
    }
}

/// The complete commands the host's next bytes finish (binary blocks whole); `None` when the
/// device stops serving this connection ([`super::read_host`]).
async fn read_commands<T: Transport>(
    io: &mut T,
    framer: &mut CommandFramer,
    buf: &mut [u8],
    shared: &SharedRef,
    pty: bool,
) -> Option<Vec<FramedCommand>> {
    let n = super::read_host(io, buf, shared, pty).await?;
    let mut got = Vec::new();
    framer.feed(&buf[..n], |c| got.push(c));
    Some(got)
}

/// The first word of `args`, upper case.
fn word(args: &str) -> String {
    args.split_whitespace()
        .next()
        .unwrap_or("")
        .to_ascii_uppercase()
}

/// A numeric argument (`1.5`, `+1.5E+00`).
fn number(args: &str) -> Result<f64, (i32, String)> {
    let w = args.split_whitespace().next().unwrap_or("");
    if w.is_empty() {
        return Err((-109, "Missing parameter".into()));
    }
    w.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or((-104, "Data type error".into()))
}

/// Long form, short form of the mnemonics this generator knows; `None` = an optional node the
/// manuals allow and that changes nothing (`SOURce`, `LEVel`, `IMMediate`, …).
const MNEMONICS: [(&str, &str, Option<&str>); 27] = [
    ("NEXT", "NEXT", None),
    ("SOURCE", "SOUR", None),
    ("LEVEL", "LEV", None),
    ("IMMEDIATE", "IMM", None),
    ("AMPLITUDE", "AMPL", None),
    ("STATE", "STAT", None),
    ("FIXED", "FIX", None),
    ("SHAPE", "SHAP", None),
    ("CW", "CW", None),
    ("FUNCTION", "FUNC", Some("FUNC")),
    ("FREQUENCY", "FREQ", Some("FREQ")),
    ("VOLTAGE", "VOLT", Some("VOLT")),
    ("UNIT", "UNIT", Some("UNIT")),
    ("OFFSET", "OFFS", Some("OFFS")),
    ("OUTPUT", "OUTP", Some("OUTP")),
    ("LOAD", "LOAD", Some("LOAD")),
    ("IMPEDANCE", "IMP", Some("IMP")),
    ("SYSTEM", "SYST", Some("SYST")),
    ("ERROR", "ERR", Some("ERR")),
    ("DATA", "DATA", Some("DATA")),
    ("ARBITRARY", "ARB", Some("ARB")),
    ("DAC", "DAC", Some("DAC")),
    ("VOLATILE", "VOL", Some("VOL")),
    ("CLEAR", "CLE", Some("CLE")),
    ("SRATE", "SRAT", Some("SRAT")),
    ("FORMAT", "FORM", Some("FORM")),
    ("BORDER", "BORD", Some("BORD")),
];

/// A header as its canonical short-form path and channel (`SOURce2:VOLTage:LEVel:IMMediate:
/// AMPLitude` → `[VOLT]`, 2). Unknown mnemonics are `-113 Undefined header`.
fn canonical(header: &str) -> Result<(Vec<&'static str>, u8), (i32, String)> {
    let mut path = Vec::new();
    let mut channel = 1u8;
    for node in header.trim_start_matches(':').split(':') {
        let digits = node.len() - node.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let (name, suffix) = node.split_at(node.len() - digits);
        let upper = name.to_ascii_uppercase();
        let Some((long, _, canon)) = MNEMONICS
            .iter()
            .find(|(long, short, _)| upper == *long || upper == *short)
        else {
            return Err((-113, "Undefined header".into()));
        };
        if !suffix.is_empty() {
            if !matches!(*long, "SOURCE" | "OUTPUT") {
                return Err((-113, "Undefined header".into()));
            }
            channel = suffix
                .parse()
                .map_err(|_| (-114, "Header suffix out of range".to_string()))?;
        }
        if let Some(c) = canon {
            path.push(*c);
        }
    }
    Ok((path, channel))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_of_the_three_manuals_reduce_to_one_path() {
        let c = |h: &str| canonical(h).unwrap();
        assert_eq!(
            c("SOURce1:VOLTage:LEVel:IMMediate:AMPLitude"),
            (vec!["VOLT"], 1)
        );
        assert_eq!(c(":SOUR2:VOLT"), (vec!["VOLT"], 2));
        assert_eq!(c("sour:volt:offs"), (vec!["VOLT", "OFFS"], 1));
        assert_eq!(c("SOURce1:FUNCtion:SHAPe"), (vec!["FUNC"], 1));
        assert_eq!(c("SOURce1:FREQuency:FIXed"), (vec!["FREQ"], 1));
        assert_eq!(c("OUTPut2:STATe"), (vec!["OUTP"], 2));
        assert_eq!(c("OUTP1:IMPedance"), (vec!["OUTP", "IMP"], 1));
        assert_eq!(c("SYSTem:ERRor"), (vec!["SYST", "ERR"], 1));
        assert_eq!(c("SYST:ERR:NEXT"), (vec!["SYST", "ERR"], 1));
        assert!(canonical("SOUR1:FORCe").is_err());
        assert!(
            canonical("VOLT3").is_err(),
            "a suffix only on SOURce/OUTPut"
        );
        assert!(
            canonical("SOURc:VOLT").is_err(),
            "neither long nor short form"
        );
    }
}
