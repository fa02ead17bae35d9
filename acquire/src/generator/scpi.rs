//! The host driver for SCPI function generators over any [`Transport`] (serial, raw TCP socket):
//! line terminator, answer timeout and retries, one reconnect when the connection drops (the
//! setting in flight sent again), `*OPC?` after every setting and the error queue read until it is
//! empty, every value inside the model's data-sheet ranges and read back within its resolution.

use std::future::Future;
use std::pin::Pin;
use std::time::Duration;

use async_trait::async_trait;

use super::arbitrary::{ArbitraryDialect, RateSetting};
use super::dialect::{self, Dialect, DialectOverrides};
use super::limits::{Load, ModelLimits};
use super::{Generator, GeneratorError};
use crate::device::DeviceIdentity;
use crate::scpi::{also_queued, parse_bool_answer, parse_error_entry};
use crate::transport::{Answer, LineLink, Transport, TransportError};

/// Opens the instrument's connection again after it dropped (a socket reset, a USB serial
/// adapter re-enumerated).
pub type Reconnect = Box<
    dyn FnMut() -> Pin<Box<dyn Future<Output = Result<Box<dyn Transport>, TransportError>> + Send>>
        + Send,
>;

/// Settings of the SCPI generator driver (the stand file's `[generator]`).
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratorOptions {
    /// Output channel (1 for single-channel instruments).
    pub channel: u8,
    /// How long to wait for each answer line.
    pub timeout: Duration,
    /// Re-sends of a query after a timeout.
    pub retries: u32,
    /// Line terminator sent after each command (`"\n"`; answers may end in `\n` or `\r\n`).
    pub terminator: String,
    /// A command table by name; `None`: chosen from the `*IDN?` answer.
    pub dialect: Option<String>,
    /// Commands overridden by the stand file.
    pub overrides: DialectOverrides,
}

impl Default for GeneratorOptions {
    fn default() -> Self {
        GeneratorOptions {
            channel: 1,
            timeout: Duration::from_millis(1000),
            retries: 2,
            terminator: "\n".into(),
            dialect: None,
            overrides: DialectOverrides::default(),
        }
    }
}

/// Most entries read from an error queue after one setting (SCPI queues hold 10-20).
const MAX_QUEUE: usize = 32;

/// A SCPI function generator.
pub struct ScpiGenerator {
    link: LineLink<Box<dyn Transport>>,
    reconnect: Option<Reconnect>,
    port: String,
    /// `port` and, once known, `manufacturer model`.
    instrument: String,
    opts: GeneratorOptions,
    dialect: Option<Dialect>,
    /// The command table's name and its arbitrary-waveform upload.
    model: String,
    arbitrary: Option<ArbitraryDialect>,
    limits: Option<ModelLimits>,
    /// Connections reopened so far: a setting during which this changed is sent again.
    reconnects: u64,
    /// The instrument stopped answering on this connection: the next command reopens it first
    /// (an LXI socket that hung), so that the output can still be switched off.
    stale: bool,
}

impl ScpiGenerator {
    /// A driver over `io`. Nothing is sent until the first call.
    pub fn new(io: Box<dyn Transport>, opts: GeneratorOptions) -> Self {
        let port = io.port().to_string();
        ScpiGenerator {
            link: LineLink::new(io),
            reconnect: None,
            instrument: port.clone(),
            port,
            opts,
            dialect: None,
            model: String::new(),
            arbitrary: None,
            limits: None,
            reconnects: 0,
            stale: false,
        }
    }

    /// How to open the connection again when it drops (once per command).
    pub fn with_reconnect(mut self, reconnect: Reconnect) -> Self {
        self.reconnect = Some(reconnect);
        self
    }

    /// The command table in use (after [`Generator::identify`]).
    pub fn dialect(&self) -> Option<&Dialect> {
        self.dialect.as_ref()
    }

    async fn send(&mut self, line: &str) -> Result<(), GeneratorError> {
        let r = self.link.send(line, &self.opts.terminator).await;
        r.map_err(|e| GeneratorError::from_io(&self.instrument, e))
    }

    /// Opens the connection again after it dropped, if a way to do so was given; `false` if
    /// not. Counted: a setting in flight meanwhile is sent again.
    async fn reopen(&mut self) -> Result<bool, GeneratorError> {
        let reopened = self.reopen_link().await?;
        if reopened {
            self.reconnects += 1;
        }
        Ok(reopened)
    }

    /// Replaces the connection with a new one, if a way to open one was given.
    async fn reopen_link(&mut self) -> Result<bool, GeneratorError> {
        let Some(r) = self.reconnect.as_mut() else {
            return Ok(false);
        };
        let io = r().await?;
        tracing::warn!("signal generator {}: reconnected", self.instrument);
        self.link.replace(io);
        Ok(true)
    }

    /// Reopens a connection on which the instrument stopped answering, before the next command.
    async fn refresh(&mut self) -> Result<(), GeneratorError> {
        if self.stale {
            self.stale = false;
            self.reopen_link().await?;
        }
        Ok(())
    }

    /// Sends `line` (no answer expected), reconnecting once if the connection dropped.
    pub async fn write(&mut self, line: &str) -> Result<(), GeneratorError> {
        self.refresh().await?;
        match self.send(line).await {
            Err(GeneratorError::Disconnected { .. }) if self.reopen().await? => {
                self.send(line).await
            }
            r => r,
        }
    }

    /// Sends a query and returns its answer line: re-sent after a timeout, and once after a
    /// reconnect when the connection dropped.
    /// A query that times out after all its retries marks the connection stale: the next
    /// command reopens it first.
    pub async fn query(&mut self, line: &str) -> Result<String, GeneratorError> {
        self.refresh().await?;
        let mut reconnected = false;
        loop {
            match self.query_once(line).await {
                Err(GeneratorError::Disconnected { .. })
                    if !reconnected && self.reopen().await? =>
                {
                    reconnected = true;
                }
                Err(e @ GeneratorError::Timeout { .. }) => {
                    self.stale = self.reconnect.is_some();
                    return Err(e);
                }
                r => return r,
            }
        }
    }

    async fn query_once(&mut self, line: &str) -> Result<String, GeneratorError> {
        let (timeout, retries) = (self.opts.timeout, self.opts.retries);
        let answer = self
            .link
            .query(line, &self.opts.terminator, timeout, retries)
            .await;
        match answer.map_err(|e| e.on::<GeneratorError>(&self.instrument))? {
            Answer::Text(t) => Ok(t),
            Answer::Garbage(g) => Err(self.garbled(line, g)),
            Answer::Silent { .. } => Err(GeneratorError::Timeout {
                instrument: self.instrument.clone(),
                command: line.to_string(),
                waited: timeout,
                attempts: retries + 1,
            }),
        }
    }

    fn garbled(&self, command: &str, got: String) -> GeneratorError {
        GeneratorError::Garbled {
            instrument: self.instrument.clone(),
            command: command.to_string(),
            got,
        }
    }

    /// Sends raw bytes (a command with a binary block), reconnecting once if the connection
    /// dropped.
    async fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), GeneratorError> {
        self.refresh().await?;
        match self.send_bytes(bytes).await {
            Err(GeneratorError::Disconnected { .. }) if self.reopen().await? => {
                self.send_bytes(bytes).await
            }
            r => r,
        }
    }

    async fn send_bytes(&mut self, bytes: &[u8]) -> Result<(), GeneratorError> {
        let r = self.link.send_bytes(bytes, &self.opts.terminator).await;
        r.map_err(|e| GeneratorError::from_io(&self.instrument, e))
    }

    /// A command carrying data (`text` for messages, and its bytes), confirmed: `*OPC?` answers
    /// `1`, then the error queue is read until it is empty. Not sent again after a reconnect
    /// (an upload is repeated whole by [`Generator::play_arbitrary`]).
    async fn confirm_raw(&mut self, text: &str, bytes: &[u8]) -> Result<(), GeneratorError> {
        self.write_bytes(bytes).await?;
        self.confirmed(text).await
    }

    /// `*OPC?` answers `1`, then the error queue is empty; errors are blamed on `command`.
    async fn confirmed(&mut self, command: &str) -> Result<(), GeneratorError> {
        let opc = self.query("*OPC?").await.map_err(|e| match e {
            GeneratorError::Timeout { .. } => GeneratorError::Unconfirmed {
                instrument: self.instrument.clone(),
                command: command.to_string(),
                source: Box::new(e),
            },
            e => e,
        })?;
        if opc.trim().trim_start_matches('+') != "1" {
            return Err(self.garbled("*OPC?", opc));
        }
        self.check_errors(command).await
    }

    /// Sends a setting, waits for it to complete (`*OPC?` answers `1`), then reads the error
    /// queue until it says `0,"No error"`; any entry fails the call, naming the command. When the
    /// connection dropped meanwhile (and was reopened), whether the setting reached the
    /// instrument is unknown: it is sent again on the new connection (settings are idempotent),
    /// and a failure then says that the connection dropped.
    pub async fn set(&mut self, line: &str) -> Result<(), GeneratorError> {
        let before = self.reconnects;
        let first = match self.write(line).await {
            Ok(()) => self.confirmed(line).await,
            Err(e) => Err(e),
        };
        if self.reconnects == before {
            return first;
        }
        tracing::warn!(
            "signal generator {}: connection reopened during `{line}`; sending it again",
            self.instrument
        );
        let again = match self.write(line).await {
            Ok(()) => self.confirmed(line).await,
            Err(e) => Err(e),
        };
        again.map_err(|e| GeneratorError::AfterReconnect {
            instrument: self.instrument.clone(),
            command: line.to_string(),
            source: Box::new(e),
        })
    }

    /// A setting whose value is then read back with `query` and compared with `sent` within
    /// `tolerance`; a reconnect during the read-back sends the setting again once.
    async fn set_and_verify(
        &mut self,
        line: &str,
        query: &str,
        sent: f64,
        tolerance: f64,
    ) -> Result<(), GeneratorError> {
        self.set(line).await?;
        let before = self.reconnects;
        let got = self.query(query).await;
        let got = match got {
            Ok(g) if self.reconnects == before => g,
            _ => {
                self.set(line).await?;
                self.query(query)
                    .await
                    .map_err(|e| GeneratorError::AfterReconnect {
                        instrument: self.instrument.clone(),
                        command: line.to_string(),
                        source: Box::new(e),
                    })?
            }
        };
        // Within the resolution, or within half a unit of the answer's last printed digit (an
        // instrument may print fewer digits than it keeps).
        let printed = 0.5 * last_digit(got.trim()) * (1.0 + 1e-9);
        match got.trim().parse::<f64>() {
            Ok(v) if (v - sent).abs() <= tolerance.max(printed) => Ok(()),
            _ => Err(GeneratorError::ReadBack {
                instrument: self.instrument.clone(),
                command: line.to_string(),
                query: query.to_string(),
                sent,
                got,
                tolerance,
            }),
        }
    }

    /// The model's ranges, or the error that the table has none.
    fn model_limits(&self) -> Result<&ModelLimits, GeneratorError> {
        self.limits.as_ref().ok_or_else(|| GeneratorError::Limits {
            instrument: self.instrument.clone(),
            model: self.model.clone(),
            source: Box::new(super::limits::LimitError::NoRange {
                field: "[model.limits]",
                load: "or any other range",
            }),
        })
    }

    fn out_of_limits(&self, source: super::limits::LimitError) -> GeneratorError {
        GeneratorError::Limits {
            instrument: self.instrument.clone(),
            model: self.model.clone(),
            source: Box::new(source),
        }
    }

    /// Reads the error queue until it is empty; errors are blamed on `command`.
    pub async fn check_errors(&mut self, command: &str) -> Result<(), GeneratorError> {
        let query = self
            .dialect
            .as_ref()
            .map(|d| d.error_query.clone())
            .unwrap_or_else(|| "SYST:ERR?".into());
        let mut errors = Vec::new();
        for _ in 0..MAX_QUEUE {
            let answer = self.query(&query).await?;
            let Some(e) = parse_error_entry(&answer) else {
                return Err(self.garbled(&query, answer));
            };
            if e.code == 0 {
                break;
            }
            errors.push(e);
        }
        let mut it = errors.into_iter();
        let Some(first) = it.next() else {
            return Ok(());
        };
        let more: Vec<String> = it.map(|e| e.to_string()).collect();
        Err(GeneratorError::Instrument {
            instrument: self.instrument.clone(),
            command: command.to_string(),
            code: first.code,
            message: first.message,
            more: also_queued(&more),
        })
    }

    fn commands(&self) -> Result<&Dialect, GeneratorError> {
        self.dialect
            .as_ref()
            .ok_or_else(|| GeneratorError::NotIdentified {
                port: self.port.clone(),
            })
    }

    fn check(&self, what: &str, value: f64) -> Result<(), GeneratorError> {
        if value.is_finite() && value >= 0.0 {
            Ok(())
        } else {
            Err(GeneratorError::InvalidValue {
                instrument: self.instrument.clone(),
                what: what.into(),
                value,
                why: String::new(),
            })
        }
    }

    /// The command table for `id`: the stand's named one, or the built-in one for its model,
    /// with the stand's overrides; its name and arbitrary-waveform upload.
    fn choose_dialect(&self, id: &DeviceIdentity) -> Result<ChosenTable, GeneratorError> {
        let known = || dialect::known_names().join(", ");
        if let Some(u) = dialect::unsupported(id)? {
            return Err(GeneratorError::Unsupported {
                port: self.port.clone(),
                idn: id.to_idn(),
                why: u.why,
            });
        }
        let base = match &self.opts.dialect {
            Some(name) => {
                dialect::by_name(name)?.ok_or_else(|| GeneratorError::UnknownDialect {
                    port: self.port.clone(),
                    name: name.clone(),
                    known: known(),
                })?
            }
            None => dialect::for_identity(id)?.ok_or_else(|| GeneratorError::UnknownModel {
                port: self.port.clone(),
                idn: id.to_idn(),
                known: known(),
            })?,
        };
        Ok(ChosenTable {
            commands: self.opts.overrides.apply(&base.commands),
            name: base.name,
            arbitrary: base.arbitrary,
            limits: base.limits,
        })
    }
}

/// The command table chosen for an instrument.
struct ChosenTable {
    commands: Dialect,
    name: String,
    arbitrary: Option<ArbitraryDialect>,
    limits: Option<ModelLimits>,
}

/// The value of one unit in the last digit a number is printed with (`5.4288E+01` → 0.001,
/// `120.5` → 0.1, `50` → 1); 0 for what is not a number.
fn last_digit(answer: &str) -> f64 {
    let (mantissa, exponent) = match answer.split_once(['E', 'e']) {
        Some((m, e)) => (m, e.trim_start_matches('+').parse::<i32>().unwrap_or(0)),
        None => (answer, 0),
    };
    if mantissa.parse::<f64>().is_err() {
        return 0.0;
    }
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    10f64.powi(exponent - decimals)
}

/// The query that reads back what a setting template sets: its header with `?`
/// (`SOURce{ch}:VOLTage {value}` → `SOURce1:VOLTage?`).
fn query_of(template: &str, channel: u8) -> String {
    let header = template.split_whitespace().next().unwrap_or(template);
    format!("{}?", dialect::fill(header, channel, ""))
}

#[async_trait]
impl Generator for ScpiGenerator {
    fn port(&self) -> &str {
        &self.port
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, GeneratorError> {
        let answer = self.query("*IDN?").await?;
        let id = DeviceIdentity::parse_idn(&answer).ok_or_else(|| self.garbled("*IDN?", answer))?;
        self.instrument = format!("{} {} on {}", id.manufacturer, id.model, self.port);
        let t = self.choose_dialect(&id)?;
        self.dialect = Some(t.commands);
        self.model = t.name;
        self.arbitrary = t.arbitrary;
        self.limits = t.limits;
        Ok(id)
    }

    async fn prepare_sine(&mut self) -> Result<(), GeneratorError> {
        let d = self.commands()?.clone();
        let idle = self
            .model_limits()?
            .idle_peak(Load::HighImpedance)
            .map_err(|e| self.out_of_limits(e))?;
        let ch = self.opts.channel;
        self.write("*CLS").await?;
        self.set("*RST").await?;
        self.set(&dialect::fill(&d.output, ch, &d.off)).await?;
        self.set(&dialect::fill(&d.load, ch, &d.high_impedance))
            .await?;
        self.set(&dialect::fill(&d.function_sine, ch, "")).await?;
        self.set(&dialect::fill(&d.voltage_unit, ch, d.unit.word()))
            .await?;
        self.set(&dialect::fill(&d.offset, ch, "0")).await?;
        // The smallest amplitude the model accepts into the high impedance just set.
        self.set_amplitude(idle).await.map(|_| ())
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), GeneratorError> {
        self.check("frequency (Hz)", hz)?;
        let d = self.commands()?.clone();
        let limits = self.model_limits()?;
        let hz = limits.frequency(hz).map_err(|e| self.out_of_limits(e))?;
        let tolerance = limits.frequency_tolerance(hz);
        let ch = self.opts.channel;
        let text = dialect::number(hz);
        let sent = text.parse().unwrap_or(hz);
        let line = dialect::fill(&d.frequency, ch, &text);
        let query = query_of(&d.frequency, ch);
        self.set_and_verify(&line, &query, sent, tolerance).await
    }

    async fn set_amplitude(&mut self, volts_peak: f64) -> Result<f64, GeneratorError> {
        self.check("amplitude (V peak)", volts_peak)?;
        let d = self.commands()?.clone();
        let limits = self.model_limits()?;
        let peak = limits
            .amplitude_to_send(volts_peak, Load::HighImpedance)
            .map_err(|e| self.out_of_limits(e))?;
        let value = d.unit.from_peak(peak);
        let tolerance = limits.amplitude_tolerance(value);
        let ch = self.opts.channel;
        let text = dialect::number(value);
        let sent = text.parse().unwrap_or(value);
        let line = dialect::fill(&d.amplitude, ch, &text);
        let query = query_of(&d.amplitude, ch);
        self.set_and_verify(&line, &query, sent, tolerance).await?;
        Ok(peak)
    }

    async fn set_output(&mut self, on: bool) -> Result<(), GeneratorError> {
        let d = self.commands()?;
        let word = if on { &d.on } else { &d.off };
        let line = dialect::fill(&d.output, self.opts.channel, word);
        self.set(&line).await?;
        let state = self.output().await?;
        if state == on {
            return Ok(());
        }
        if !on {
            return Err(GeneratorError::OutputStillOn {
                instrument: self.instrument.clone(),
                command: line,
            });
        }
        let query = dialect::fill(&self.commands()?.output_query, self.opts.channel, "");
        Err(GeneratorError::ReadBack {
            instrument: self.instrument.clone(),
            command: line,
            query,
            sent: 1.0,
            got: "off".into(),
            tolerance: 0.0,
        })
    }

    async fn output(&mut self) -> Result<bool, GeneratorError> {
        let d = self.commands()?;
        let line = dialect::fill(&d.output_query, self.opts.channel, "");
        let answer = self.query(&line).await?;
        parse_bool_answer(&answer).ok_or_else(|| self.garbled(&line, answer))
    }

    fn model_name(&self) -> &str {
        &self.model
    }

    fn arbitrary(&self) -> Option<&ArbitraryDialect> {
        self.arbitrary.as_ref()
    }

    fn limits(&self) -> Option<&ModelLimits> {
        self.limits.as_ref()
    }

    async fn play_arbitrary(
        &mut self,
        samples: &[f64],
        sample_rate_hz: f64,
    ) -> Result<Vec<i32>, GeneratorError> {
        self.commands()?;
        let Some(a) = self.arbitrary.clone() else {
            return Err(GeneratorError::NoArbitrary {
                instrument: self.instrument.clone(),
                model: self.model.clone(),
            });
        };
        a.check(samples.len(), sample_rate_hz)
            .map_err(|e| GeneratorError::ArbitraryLimit {
                instrument: self.instrument.clone(),
                model: self.model.clone(),
                detail: e.to_string(),
                fix: "use fewer points (a shorter period) or a lower sample rate".into(),
            })?;
        // A connection dropped during the sequence leaves the instrument's memory unknown: the
        // whole sequence (clear, upload, select, rate) is sent again once on the new connection.
        let before = self.reconnects;
        match self.upload_and_select(&a, samples, sample_rate_hz).await {
            Ok(codes) if self.reconnects == before => Ok(codes),
            first => {
                if self.reconnects == before {
                    return first;
                }
                tracing::warn!(
                    "signal generator {}: connection reopened during the upload; uploading again",
                    self.instrument
                );
                let again = self.upload_and_select(&a, samples, sample_rate_hz).await;
                again.map_err(|e| GeneratorError::AfterReconnect {
                    instrument: self.instrument.clone(),
                    command: a.upload.clone(),
                    source: Box::new(e),
                })
            }
        }
    }
}

impl ScpiGenerator {
    /// The arbitrary waveform's settings before the upload, the upload, the selection and the
    /// rate; the DAC codes sent.
    async fn upload_and_select(
        &mut self,
        a: &ArbitraryDialect,
        samples: &[f64],
        sample_rate_hz: f64,
    ) -> Result<Vec<i32>, GeneratorError> {
        let ch = self.opts.channel;
        for c in &a.before_upload {
            self.set(&dialect::fill(c, ch, "")).await?;
        }
        let codes = a.codes(samples);
        let (head, tail) = a.upload.split_once("{block}").unwrap_or((&a.upload, ""));
        let head = dialect::fill(head, ch, "");
        let tail = dialect::fill(tail, ch, "");
        let data = a.data_bytes(&codes);
        let mut bytes = Vec::with_capacity(head.len() + data.len() + tail.len());
        bytes.extend_from_slice(head.as_bytes());
        bytes.extend_from_slice(&data);
        bytes.extend_from_slice(tail.as_bytes());
        let text = format!("{head}<{} points>{tail}", codes.len());
        self.confirm_raw(&text, &bytes).await?;
        for c in &a.select {
            self.set(&dialect::fill(c, ch, "")).await?;
        }
        let value = match a.rate_is {
            RateSetting::SampleRate => sample_rate_hz,
            RateSetting::RepetitionFrequency => sample_rate_hz / samples.len() as f64,
        };
        self.set(&dialect::fill(&a.rate, ch, &dialect::number(value)))
            .await?;
        Ok(codes)
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod read_back_tests {
    use super::last_digit;

    #[test]
    fn the_last_printed_digit_of_each_manuals_number_form() {
        assert!((last_digit("+1.20500000000000E+02") - 1e-12).abs() < 1e-24);
        assert!((last_digit("5.4288E+01") - 1e-3).abs() < 1e-15);
        assert!((last_digit("5.428835E+01") - 1e-5).abs() < 1e-18);
        assert_eq!(last_digit("120.5"), 0.1);
        assert_eq!(last_digit("50"), 1.0);
        assert_eq!(last_digit("ON"), 0.0);
    }
}

#[cfg(test)]
mod arbitrary_tests;
#[cfg(test)]
mod scripted;
