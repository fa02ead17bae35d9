//! The simulated signal generator + power amplifier + shaker: emulates a Keysight 33522B, a Rigol
//! DG1062Z, a Tektronix AFG31022 or a plain SCPI generator ([`emulation`]) on a pseudo-terminal or
//! a local TCP port — refusing what that instrument's manual refuses (headers, parameter words,
//! ranges by load, channels) with its error numbers and texts, keeping its state and answering
//! queries in its format — and turns the generator's volts into the exciter's force through the
//! amplifier's true gain, which the simulated DAQ then measures through the shaker–structure
//! interaction like any other force. An uploaded arbitrary waveform is played at the sample rate
//! set, looping. Every accepted setting is logged with the time it arrived. Injectable faults:
//! the amplifier trips or surges; the connection drops before or after a command; the instrument
//! stops answering on a connection; an error-queue entry appears.

pub mod emulation;
mod header;

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::link::{lock, read_host, send_answer, InjectedFault, SharedRef};
use super::signal::ArbitraryDrive;
use crate::device::DeviceIdentity;
use crate::generator::arbitrary::{CommandFramer, FramedCommand};
use crate::shaker::scpi::Function;
use crate::transport::Transport;
use emulation::{Emulation, Upload, MIN_FREQUENCY_HZ};
use header::{canonical, undefined, ScpiFault};

/// Most error-queue entries kept (the last becomes `-350,"Queue overflow"`).
const QUEUE_LENGTH: usize = 10;

/// What the simulated generator and amplifier are.
#[derive(Debug, Clone, PartialEq)]
pub struct SimGeneratorSetup {
    /// The `*IDN?` answer; its manufacturer and model choose the emulated instrument
    /// ([`Emulation::for_identity`]; any other identity gets the plain generator).
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
    /// Faults of the connection and the instrument.
    pub faults: GeneratorFaults,
}

/// The `nth` command (counted from 1 over the generator's life) whose text contains `contains`,
/// compared case-insensitively with the text as sent (`"VOLT "` matches `SOUR1:VOLT 0.002`, not
/// `SOUR1:VOLT:UNIT VPP`; give the spelling of the command table in use).
#[derive(Debug, Clone, PartialEq)]
pub struct CommandMatch {
    /// Text the command contains.
    pub contains: String,
    /// Which occurrence (1 = the first).
    pub nth: u64,
}

/// Faults the simulated generator injects, each once.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GeneratorFaults {
    /// The connection closes when this command arrives, before it is applied (the setting is
    /// lost on the way). Connection faults act on a TCP connection (`sim:tcp`); a pty is never
    /// closed by its device.
    pub drop_before: Option<CommandMatch>,
    /// The connection closes right after this command is applied, before anything is answered.
    pub drop_after: Option<CommandMatch>,
    /// The instrument stops answering on this connection from this command on (applies nothing
    /// more on it); a new connection is served normally (an LXI socket that hung).
    pub silent_from: Option<CommandMatch>,
    /// This command is applied and the error-queue entry `code,"message"` appears with it.
    pub error_at: Option<(CommandMatch, i32, String)>,
}

/// One setting the simulated generator accepted, for tests: what, the value (V peak at the
/// amplifier's high-impedance input, Hz, 1/0 for the output), and when it arrived.
#[derive(Debug, Clone, PartialEq)]
pub struct Accepted {
    /// `amplitude`, `frequency`, `output`.
    pub what: &'static str,
    /// Value.
    pub value: f64,
    /// Output state after it.
    pub output_on: bool,
    /// Wall-clock time since the generator started when it was applied.
    pub at: Duration,
}

/// The simulated generator's state (channel `channel` of [`SimGeneratorSetup`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratorState {
    /// Output on.
    pub output_on: bool,
    /// Amplitude as the instrument shows it (V peak) for its load setting; the voltage at the
    /// amplifier's high-impedance input is twice it when the load is left at 50 Ω.
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
    /// The arbitrary function selected.
    pub arbitrary: bool,
    /// The waveform in volatile memory (name, its samples −1..1), once uploaded.
    pub uploaded: Option<(String, Arc<ArbitraryDrive>)>,
    /// The waveform selected to play.
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
    /// The state after `*RST` (the manuals' defaults: 1 kHz, 100 mVpp, 50 Ω, output off).
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

impl GeneratorState {
    fn high_z(&self) -> bool {
        self.load_ohm.is_infinite()
    }

    fn accept(&mut self, what: &'static str, value: f64, at: Duration) {
        let output_on = self.output_on;
        self.log.push(Accepted {
            what,
            value,
            output_on,
            at,
        });
    }
}

/// What a fault does to one arriving command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Disposition {
    Apply,
    DropBefore,
    DropAfter,
    Silent,
}

/// A simulated generator shared by its connections and the simulated DAQ.
#[derive(Clone)]
pub struct SimGenerator {
    setup: SimGeneratorSetup,
    emulation: Emulation,
    state: Arc<Mutex<GeneratorState>>,
    shared: SharedRef,
    started: Instant,
    /// Commands received, per fault pattern: (drop_before, drop_after, silent_from, error_at).
    counts: Arc<Mutex<[u64; 4]>>,
}

impl SimGenerator {
    pub(super) fn new(setup: SimGeneratorSetup, shared: SharedRef) -> SimGenerator {
        let id = &setup.identity;
        let mut emulation = Emulation::for_identity(&format!("{},{}", id.manufacturer, id.model));
        // The stand's own channel count when a plain generator is told to use more.
        emulation.channels = emulation.channels.max(setup.channel);
        SimGenerator {
            setup,
            emulation,
            state: Arc::new(Mutex::new(GeneratorState::default())),
            shared,
            started: Instant::now(),
            counts: Arc::new(Mutex::new([0; 4])),
        }
    }

    /// The generator's state now.
    pub fn state(&self) -> GeneratorState {
        self.lock_state().clone()
    }

    /// The instrument emulated.
    pub fn emulation(&self) -> &Emulation {
        &self.emulation
    }

    fn lock_state(&self) -> std::sync::MutexGuard<'_, GeneratorState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Serves one connection until it closes (a TCP client leaving, or a dropped-connection
    /// fault) or, on a pty, forever.
    pub(super) async fn serve<T: Transport>(&self, mut io: T, pty: bool) {
        let mut framer = CommandFramer::new();
        let mut buf = vec![0u8; 4096];
        let mut silent = false;
        loop {
            let Some(got) = read_commands(&mut io, &mut framer, &mut buf, &self.shared, pty).await
            else {
                return;
            };
            for c in got {
                if silent {
                    continue;
                }
                let disposition = self.disposition(&c.text);
                match disposition {
                    Disposition::DropBefore if !pty => return,
                    Disposition::Silent => {
                        silent = true;
                        continue;
                    }
                    _ => {}
                }
                let answer = if c.garbage {
                    self.push_error(-100, "Command error");
                    None
                } else {
                    self.handle(&c)
                };
                let dropped = disposition == Disposition::DropAfter && !pty;
                if dropped || !send_answer(&mut io, answer).await {
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

    /// Counts `text` against each fault's pattern and says what happens to it; an `error_at`
    /// fault queues its entry here (the command is then applied as usual).
    fn disposition(&self, text: &str) -> Disposition {
        let f = &self.setup.faults;
        let upper = text.to_ascii_uppercase();
        let mut counts = self.counts.lock().unwrap_or_else(|p| p.into_inner());
        let mut hit = |i: usize, m: &Option<CommandMatch>| -> bool {
            let Some(m) = m else { return false };
            if !upper.contains(&m.contains.to_ascii_uppercase()) {
                return false;
            }
            counts[i] += 1;
            counts[i] == m.nth
        };
        let (before, after, silent) = (
            hit(0, &f.drop_before),
            hit(1, &f.drop_after),
            hit(2, &f.silent_from),
        );
        let error = f
            .error_at
            .as_ref()
            .filter(|(m, _, _)| hit(3, &Some(m.clone())));
        drop(counts);
        let (kind, d) = if before {
            ("generator_drop_before", Disposition::DropBefore)
        } else if silent {
            ("generator_silent", Disposition::Silent)
        } else if after {
            ("generator_drop_after", Disposition::DropAfter)
        } else if let Some((_, code, message)) = error {
            self.push_error(*code, message);
            ("generator_error", Disposition::Apply)
        } else {
            return Disposition::Apply;
        };
        let seq = self.lock_state().log.len() as u64;
        lock(&self.shared)
            .injected
            .push(InjectedFault { kind, seq });
        d
    }

    fn push_error(&self, code: i32, message: &str) {
        let mut st = self.lock_state();
        if st.errors.len() >= QUEUE_LENGTH {
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

    fn out_of_range(&self) -> ScpiFault {
        (-222, self.emulation.out_of_range.into())
    }

    fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }

    /// The header checked against the emulated instrument's manual: its optional nodes, its
    /// load node, its channels.
    fn header(&self, text: &str) -> Result<header::Header, ScpiFault> {
        let h = canonical(text)?;
        let e = &self.emulation;
        if h.optional
            .iter()
            .any(|n| !matches!(*n, "SOURCE" | "NEXT") && !e.optional_nodes.contains(n))
        {
            return Err(undefined());
        }
        let load_node = |n: &str| match n {
            "LOAD" => Some("LOAD"),
            "IMP" => Some("IMPEDANCE"),
            _ => None,
        };
        if let (Some(&"OUTP"), Some(n)) = (h.path.first(), h.path.get(1).and_then(|n| load_node(n)))
        {
            if !e.load_nodes.contains(&n) {
                return Err(undefined());
            }
        }
        if !(1..=e.channels).contains(&h.channel) {
            return Err((-114, "Header suffix out of range".into()));
        }
        Ok(h)
    }

    /// A command that carried a binary block: the emulated instrument's upload.
    fn upload(&self, text: &str, block: &[u8]) -> Result<Option<String>, ScpiFault> {
        let (head, args) = text
            .trim()
            .split_once(char::is_whitespace)
            .unwrap_or((text, ""));
        let h = self.header(head)?;
        let args: Vec<String> = args
            .split(',')
            .map(|a| a.trim().to_ascii_uppercase())
            .collect();
        let (name, channel, codes) = match (self.emulation.upload, h.path.as_slice()) {
            (Upload::KeysightDac, ["DATA", "ARB", "DAC"]) => {
                let name = args.first().cloned().unwrap_or_default();
                if name.is_empty() || name.len() > 12 || args.len() != 2 {
                    return Err((-109, "Missing parameter;name,<block>".into()));
                }
                let swapped = self.lock_state().swapped;
                (name, h.channel, words(block, !swapped, true)?)
            }
            (Upload::RigolDac16, ["TRAC", "DATA", "DAC16"]) => {
                if args.len() != 3
                    || args[0] != "VOLATILE"
                    || !matches!(args[1].as_str(), "END" | "CON")
                {
                    return Err((-109, "Missing parameter;VOLATILE,END,<block>".into()));
                }
                (
                    "VOLATILE".to_string(),
                    h.channel,
                    words(block, false, false)?,
                )
            }
            (Upload::TektronixEmem, ["TRAC", "DATA"]) => {
                let channel = match args.first().map(String::as_str) {
                    Some("EMEMORY1" | "EMEM1" | "EMEMORY" | "EMEM") => 1,
                    Some("EMEMORY2" | "EMEM2") => 2,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                (
                    format!("EMEMORY{channel}"),
                    channel,
                    words(block, true, false)?,
                )
            }
            _ => return Err(undefined()),
        };
        let e = &self.emulation;
        if codes.len() > e.max_points {
            return Err((-223, "Too much data".into()));
        }
        let (min_points, full_scale, mid) = match e.upload {
            Upload::KeysightDac => (8, 32767.0, 0.0),
            Upload::RigolDac16 => (8, 8191.5, 8191.5),
            Upload::TektronixEmem => (2, 8191.5, 8191.5),
        };
        if codes.len() < min_points {
            return Err(self.out_of_range());
        }
        if codes
            .iter()
            .any(|&c| (f64::from(c) - mid).abs() > full_scale)
        {
            return Err(self.out_of_range());
        }
        if channel != self.setup.channel {
            return Ok(None);
        }
        let samples = codes
            .iter()
            .map(|&c| (f64::from(c) - mid) / full_scale)
            .collect();
        let mut st = self.lock_state();
        let rate = st.sample_rate_hz;
        st.uploaded = Some((
            name.clone(),
            Arc::new(ArbitraryDrive {
                samples,
                sample_rate_hz: rate,
            }),
        ));
        if e.upload == Upload::RigolDac16 && args.get(1).map(String::as_str) == Some("END") {
            // END switches the channel to the waveform just loaded.
            st.selected = Some(name);
            st.arbitrary = true;
            st.sine = false;
        }
        self.drive(&st);
        Ok(None)
    }

    /// One command without a block: common commands, the error queue, then the settings and
    /// queries of the emulated instrument.
    fn apply(&self, line: &str) -> Result<Option<String>, ScpiFault> {
        let line = line.trim();
        let (head, args) = match line.split_once(char::is_whitespace) {
            Some((h, a)) => (h, a.trim()),
            None => (line, ""),
        };
        let query = head.ends_with('?');
        let head = head.trim_end_matches('?');
        if let Some(common) = head.strip_prefix('*') {
            return self.common(&common.to_ascii_uppercase(), query);
        }
        let h = self.header(head)?;
        let mut st = self.lock_state();
        if h.path == ["SYST", "ERR"] && query {
            let (code, message) = st.errors.pop_front().unwrap_or((0, "No error".into()));
            return Ok(Some(self.emulation.error_entry(code, &message)));
        }
        // Only the amplifier's channel is wired: the other accepts settings and drives nothing.
        let ours = h.channel == self.setup.channel;
        let mut scratch = GeneratorState::default();
        let s: &mut GeneratorState = if ours { &mut st } else { &mut scratch };
        let at = self.elapsed();
        let answer = if query {
            Some(self.query(&h.path, s)?)
        } else {
            self.set(&h.path, args, s, at)?;
            None
        };
        if ours && !query {
            self.faults(&mut st);
            self.drive(&st);
        }
        Ok(answer)
    }

    /// A query's answer, in the emulated instrument's format.
    fn query(&self, path: &[&str], s: &GeneratorState) -> Result<String, ScpiFault> {
        let e = &self.emulation;
        Ok(match path {
            ["FUNC"] => if s.sine {
                "SIN"
            } else if s.arbitrary {
                match e.upload {
                    Upload::KeysightDac => "ARB",
                    Upload::RigolDac16 => "USER",
                    Upload::TektronixEmem => "EMEM1",
                }
            } else {
                "NOIS"
            }
            .into(),
            ["FUNC", "ARB", "SRAT"] => e.number(s.sample_rate_hz),
            ["FREQ"] => e.number(s.frequency_hz),
            ["VOLT"] => e.number(if s.vrms {
                s.volts_peak / std::f64::consts::SQRT_2
            } else {
                2.0 * s.volts_peak
            }),
            ["VOLT", "UNIT"] => if s.vrms { "VRMS" } else { "VPP" }.into(),
            ["VOLT", "OFFS"] => e.number(s.offset_v),
            ["OUTP"] => e.state(s.output_on).into(),
            ["OUTP", "LOAD" | "IMP"] => {
                if s.high_z() {
                    e.number(9.9e37)
                } else {
                    e.number(s.load_ohm)
                }
            }
            _ => return Err(undefined()),
        })
    }

    /// A setting, refused as the emulated instrument refuses it.
    fn set(
        &self,
        path: &[&str],
        args: &str,
        s: &mut GeneratorState,
        at: Duration,
    ) -> Result<(), ScpiFault> {
        match path {
            ["FUNC"] => self.set_function(args, s),
            ["FUNC", "ARB"] => self.select_arbitrary(args, s),
            ["FUNC", "ARB", "SRAT"] => self.set_sample_rate(args, s),
            ["FUNC", "ARB", "MODE"] if self.emulation.upload == Upload::RigolDac16 => {
                match word(args).as_str() {
                    "SRATE" | "SRAT" | "FREQ" | "FREQUENCY" => Ok(()),
                    _ => Err((-224, "Illegal parameter value".into())),
                }
            }
            ["DATA", "VOL", "CLE"] if self.emulation.upload == Upload::KeysightDac => {
                s.uploaded = None;
                s.selected = None;
                Ok(())
            }
            ["FORM", "BORD"] if self.emulation.upload == Upload::KeysightDac => {
                s.swapped = match word(args).as_str() {
                    "NORM" | "NORMAL" => false,
                    "SWAP" | "SWAPPED" => true,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                Ok(())
            }
            ["FREQ"] => self.set_frequency(args, s, at),
            ["VOLT"] => self.set_amplitude(args, s, at),
            ["VOLT", "UNIT"] => {
                s.vrms = match word(args).as_str() {
                    "VPP" => false,
                    "VRMS" => true,
                    "DBM" if s.high_z() => {
                        return Err((-221, "Settings conflict;dBm needs a 50 Ohm load".into()))
                    }
                    "DBM" => return Err((-224, "Illegal parameter value".into())),
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                Ok(())
            }
            ["VOLT", "OFFS"] => {
                let v = number(args)?;
                if v.abs() + s.volts_peak > self.emulation.offset_limit_v(s.high_z()) {
                    return Err(self.out_of_range());
                }
                s.offset_v = v;
                Ok(())
            }
            ["OUTP"] => {
                s.output_on = match word(args).as_str() {
                    "ON" | "1" => true,
                    "OFF" | "0" => false,
                    _ => return Err((-224, "Illegal parameter value".into())),
                };
                s.accept("output", f64::from(u8::from(s.output_on)), at);
                Ok(())
            }
            ["OUTP", "LOAD" | "IMP"] => self.set_load(args, s),
            _ => Err(undefined()),
        }
    }

    /// `FUNCtion <word>`: only the words the manual lists.
    fn set_function(&self, args: &str, s: &mut GeneratorState) -> Result<(), ScpiFault> {
        let e = &self.emulation;
        let w = word(args);
        let Some(f) = e.function(&w) else {
            return Err((-224, "Illegal parameter value".into()));
        };
        s.sine = f == "SINUSOID";
        s.arbitrary = f == e.arbitrary_word || (f == "ARBITRARY" && e.arbitrary_word == "ARB");
        if s.arbitrary && e.upload == Upload::TektronixEmem {
            // The edit memory plays what was loaded into it.
            s.selected = s.uploaded.as_ref().map(|(n, _)| n.clone());
        }
        Ok(())
    }

    /// `FUNCtion:ARBitrary <name>` (Keysight): a waveform in volatile memory.
    fn select_arbitrary(&self, args: &str, s: &mut GeneratorState) -> Result<(), ScpiFault> {
        if self.emulation.upload != Upload::KeysightDac {
            return Err(undefined());
        }
        let name = args.trim().trim_matches('"').to_ascii_uppercase();
        if s.uploaded.as_ref().map(|(n, _)| n) != Some(&name) {
            return Err((-224, "Illegal parameter value;no such arb waveform".into()));
        }
        s.selected = Some(name);
        Ok(())
    }

    /// `FUNCtion:ARBitrary:SRATe <Sa/s>` (Keysight, Rigol).
    fn set_sample_rate(&self, args: &str, s: &mut GeneratorState) -> Result<(), ScpiFault> {
        if self.emulation.upload == Upload::TektronixEmem {
            return Err(undefined());
        }
        let r = number(args)?;
        if !(1e-6..=self.emulation.max_sample_rate_hz).contains(&r) {
            return Err(self.out_of_range());
        }
        set_rate(s, r);
        Ok(())
    }

    /// `FREQuency <Hz>`: the sine's frequency, or (Tektronix, edit memory playing) the
    /// waveform's repetition frequency.
    fn set_frequency(
        &self,
        args: &str,
        s: &mut GeneratorState,
        at: Duration,
    ) -> Result<(), ScpiFault> {
        let f = number(args)?;
        let e = &self.emulation;
        if e.upload == Upload::TektronixEmem && s.arbitrary {
            let points = s.uploaded.as_ref().map_or(0, |(_, a)| a.samples.len());
            let rate = f * points as f64;
            if !(rate > 0.0 && rate <= e.max_sample_rate_hz) {
                return Err(self.out_of_range());
            }
            set_rate(s, rate);
            return Ok(());
        }
        if !(MIN_FREQUENCY_HZ..=e.max_frequency_hz).contains(&f) {
            return Err(self.out_of_range());
        }
        s.frequency_hz = f;
        s.lines += 1;
        s.accept("frequency", f, at);
        Ok(())
    }

    /// `VOLTage <value>` in the unit set: within the data sheet's range at the load set, and
    /// with the offset within the output's limit.
    fn set_amplitude(
        &self,
        args: &str,
        s: &mut GeneratorState,
        at: Duration,
    ) -> Result<(), ScpiFault> {
        let x = number(args)?;
        let peak = if s.vrms {
            x * std::f64::consts::SQRT_2
        } else {
            0.5 * x
        };
        let e = &self.emulation;
        let (lo, hi) = e.amplitude_vpp(s.high_z());
        let vpp = 2.0 * peak;
        if vpp < lo * (1.0 - 1e-9)
            || vpp > hi * (1.0 + 1e-9)
            || peak + s.offset_v.abs() > e.offset_limit_v(s.high_z()) * (1.0 + 1e-9)
        {
            return Err(self.out_of_range());
        }
        s.volts_peak = peak;
        // The voltage at the amplifier's high-impedance input.
        let real = if s.high_z() { peak } else { 2.0 * peak };
        s.accept("amplitude", real, at);
        Ok(())
    }

    /// `OUTPut:LOAD` / `OUTPut:IMPedance`: the amplitude shown is rescaled so the output voltage
    /// stays the same (as the 33500B guide says of a changed termination).
    fn set_load(&self, args: &str, s: &mut GeneratorState) -> Result<(), ScpiFault> {
        let load = match word(args).as_str() {
            "INF" | "INFINITY" => f64::INFINITY,
            "MAX" | "MAXIMUM" => 10_000.0,
            "MIN" | "MINIMUM" => 1.0,
            _ => {
                let r = number(args)?;
                if !(1.0..=10_000.0).contains(&r) {
                    return Err(self.out_of_range());
                }
                r
            }
        };
        let shown = |ohm: f64| if ohm.is_infinite() { 1.0 } else { 0.5 };
        s.volts_peak *= shown(load) / shown(s.load_ohm);
        s.load_ohm = load;
        Ok(())
    }

    /// IEEE 488.2 common commands.
    fn common(&self, name: &str, query: bool) -> Result<Option<String>, ScpiFault> {
        match (name, query) {
            ("IDN", true) => Ok(Some(self.setup.identity.to_idn())),
            ("OPC", true) => Ok(Some("1".into())),
            ("OPC", false) => Ok(None),
            ("RST", false) => {
                let mut st = self.lock_state();
                let kept = GeneratorState {
                    log: std::mem::take(&mut st.log),
                    errors: std::mem::take(&mut st.errors),
                    lines: st.lines,
                    amplifier_tripped: st.amplifier_tripped,
                    gain_factor: st.gain_factor,
                    ..GeneratorState::default()
                };
                *st = kept;
                self.drive(&st);
                Ok(None)
            }
            ("CLS", false) => {
                self.lock_state().errors.clear();
                Ok(None)
            }
            _ => Err(undefined()),
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
        let load_factor = if st.high_z() { 1.0 } else { 2.0 };
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

/// The arbitrary sample rate, applied to the waveform in memory too.
fn set_rate(s: &mut GeneratorState, rate: f64) {
    s.sample_rate_hz = rate;
    if let Some((_, a)) = &mut s.uploaded {
        *a = Arc::new(ArbitraryDrive {
            samples: a.samples.clone(),
            sample_rate_hz: rate,
        });
    }
}

/// A block's 16-bit words: most-significant byte first when `big`, signed when `signed`.
fn words(block: &[u8], big: bool, signed: bool) -> Result<Vec<i32>, ScpiFault> {
    if !block.len().is_multiple_of(2) {
        return Err((-161, "Invalid block data;odd byte count".into()));
    }
    Ok(block
        .chunks_exact(2)
        .map(|b| {
            let raw = if big {
                u16::from_be_bytes([b[0], b[1]])
            } else {
                u16::from_le_bytes([b[0], b[1]])
            };
            if signed {
                i32::from(raw as i16)
            } else {
                i32::from(raw)
            }
        })
        .collect())
}

/// The complete commands the host's next bytes finish (binary blocks whole); `None` when the
/// device stops serving this connection ([`read_host`]).
async fn read_commands<T: Transport>(
    io: &mut T,
    framer: &mut CommandFramer,
    buf: &mut [u8],
    shared: &SharedRef,
    pty: bool,
) -> Option<Vec<FramedCommand>> {
    let n = read_host(io, buf, shared, pty).await?;
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
fn number(args: &str) -> Result<f64, ScpiFault> {
    let w = args.split_whitespace().next().unwrap_or("");
    if w.is_empty() {
        return Err((-109, "Missing parameter".into()));
    }
    w.parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or((-104, "Data type error".into()))
}

#[cfg(test)]
mod tests;
