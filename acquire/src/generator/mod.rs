//! Function/arbitrary generators driving a power amplifier and an electrodynamic shaker: the
//! SCPI-99 / IEEE 488.2 command set such generators share ([`scpi::ScpiGenerator`]) with
//! per-model command tables ([`dialect`]), and the narrow [`Generator`] trait a sweep drives.
//! The exciter made of generator + amplifier + shaker, whose force loop the host closes on the
//! DAQ's force channel, is a shaker implementation: `shaker::GeneratorExciter`
//! (docs/scpi-generator.md). Nothing here imports `shaker`.

pub mod amplifier;
pub mod arbitrary;
pub mod dialect;
pub mod limits;
pub mod scpi;
pub mod waveform;

pub use amplifier::Amplifier;
pub use scpi::{GeneratorOptions, ScpiGenerator};

use std::time::Duration;

use async_trait::async_trait;

use crate::device::DeviceIdentity;

/// A signal generator's output channel, as a sweep needs it. Object safe; amplitudes are the
/// sine's peak voltage (V) at the generator's output into a high-impedance load, frequencies Hz.
/// Every setting is confirmed (`*OPC?`) and followed by reading the error queue; an error there
/// fails the call with [`GeneratorError::Instrument`].
#[async_trait]
pub trait Generator: Send {
    /// Where the instrument is connected (`/dev/ttyUSB0`, `tcp:192.168.1.20:5025`).
    fn port(&self) -> &str;
    /// Asks the instrument who it is (`*IDN?`) and selects its command table.
    async fn identify(&mut self) -> Result<DeviceIdentity, GeneratorError>;
    /// `*RST`, `*CLS`, then: output off, high-impedance load, sine, amplitude unit, zero offset,
    /// the smallest amplitude the model accepts into a high impedance. Call after
    /// [`Generator::identify`].
    async fn prepare_sine(&mut self) -> Result<(), GeneratorError>;
    /// Sine frequency (Hz), read back.
    async fn set_frequency(&mut self, hz: f64) -> Result<(), GeneratorError>;
    /// Sine amplitude (V peak), sent on the model's amplitude grid and read back; returns the
    /// amplitude set (V peak). Refused before sending when outside the model's range.
    async fn set_amplitude(&mut self, volts_peak: f64) -> Result<f64, GeneratorError>;
    /// Switches the output on or off, and reads the state back.
    async fn set_output(&mut self, on: bool) -> Result<(), GeneratorError>;
    /// Asks whether the output is on.
    async fn output(&mut self) -> Result<bool, GeneratorError>;
    /// The name of the command table in use (after [`Generator::identify`]).
    fn model_name(&self) -> &str {
        ""
    }
    /// The model's ranges from its data sheet (after [`Generator::identify`]); `None` if its
    /// table has none.
    fn limits(&self) -> Option<&limits::ModelLimits> {
        None
    }
    /// The model's arbitrary-waveform upload and its limits (after [`Generator::identify`]);
    /// `None` if the model has none.
    fn arbitrary(&self) -> Option<&arbitrary::ArbitraryDialect> {
        None
    }
    /// Uploads `samples` (−1..1 = the amplitude's full scale) as the model's arbitrary waveform,
    /// played at `sample_rate_hz` and repeated, and selects it; the amplitude set afterwards is
    /// the waveform's full-scale peak. Returns the DAC codes sent. The output should be off.
    async fn play_arbitrary(
        &mut self,
        samples: &[f64],
        sample_rate_hz: f64,
    ) -> Result<Vec<i32>, GeneratorError> {
        let _ = (samples, sample_rate_hz);
        Err(GeneratorError::NoArbitrary {
            instrument: self.port().to_string(),
            model: "this generator".into(),
        })
    }
}

/// Errors of a signal generator. Each names the instrument (its port, and its identity once
/// known) and says what to check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GeneratorError {
    /// The transport could not be opened.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// Reading or writing failed.
    #[error("signal generator {instrument}: I/O error: {detail}; check the cable or network and that the generator is on")]
    Io {
        /// Port and identity.
        instrument: String,
        /// What the operating system said.
        detail: String,
    },
    /// The instrument went away and could not be reached again.
    #[error("signal generator {instrument}: connection lost ({detail}); check the cable or network and the generator's power")]
    Disconnected {
        /// Port and identity.
        instrument: String,
        /// What was seen.
        detail: String,
    },
    /// No answer within the timeout, after all retries.
    #[error("signal generator {instrument}: no answer to `{command}` within {waited:?} ({attempts} attempts); check that the generator is on, the cable or address, the baud rate and the line terminator")]
    Timeout {
        /// Port and identity.
        instrument: String,
        /// Command sent.
        command: String,
        /// Timeout per attempt.
        waited: Duration,
        /// Attempts made.
        attempts: u32,
    },
    /// The answer could not be understood.
    #[error("signal generator {instrument}: answer to `{command}` is not understood: {got:?}; is this port really the generator (baud rate, terminator)?")]
    Garbled {
        /// Port and identity.
        instrument: String,
        /// Command sent.
        command: String,
        /// What came back.
        got: String,
    },
    /// The instrument reported an error for a command (from its `SYSTem:ERRor?` queue).
    #[error("signal generator {instrument}: `{command}` failed: {code},\"{message}\"{more}; check the command table (dialect) in the stand file and the value's range")]
    Instrument {
        /// Port and identity.
        instrument: String,
        /// Command that failed.
        command: String,
        /// SCPI error code.
        code: i32,
        /// The instrument's message.
        message: String,
        /// Further queued errors, if any.
        more: String,
    },
    /// The instrument is of a family the driver does not drive (the built-in table's
    /// `[[unsupported]]`).
    #[error("signal generator on {port}: `*IDN?` says `{idn}`: {why}")]
    Unsupported {
        /// Port.
        port: String,
        /// The identity received.
        idn: String,
        /// Why, and what to use instead.
        why: String,
    },
    /// The instrument's model has no command table.
    #[error("signal generator on {port}: `*IDN?` says `{idn}`, a model with no built-in command table (known: {known}); set `dialect = \"generic\"` in [generator] for plain SCPI-99 commands, or name a table and override commands in [generator.commands] (docs/scpi-generator.md)")]
    UnknownModel {
        /// Port.
        port: String,
        /// The identity received.
        idn: String,
        /// Built-in tables.
        known: String,
    },
    /// The stand file names a command table that does not exist.
    #[error("signal generator on {port}: no command table named `{name}` (known: {known}); fix `dialect` in [generator]")]
    UnknownDialect {
        /// Port.
        port: String,
        /// Name asked for.
        name: String,
        /// Built-in tables.
        known: String,
    },
    /// The instrument identified itself as something else.
    #[error("signal generator on {port}: identifies as `{got}`, stand file expects `{expected}`; check which instrument is on this port or address")]
    WrongIdentity {
        /// Port.
        port: String,
        /// Identity received.
        got: String,
        /// Identity expected.
        expected: String,
    },
    /// A value this driver refuses to send (NaN, negative, above the stand's voltage limit).
    #[error("signal generator {instrument}: refusing to send {what} = {value}{why}")]
    InvalidValue {
        /// Port and identity.
        instrument: String,
        /// Which quantity.
        what: String,
        /// The value.
        value: f64,
        /// Why.
        why: String,
    },
    /// The output was switched off but the instrument still reports it on.
    #[error("signal generator {instrument}: output still on after `{command}`; switch it off at the front panel and check the command table")]
    OutputStillOn {
        /// Port and identity.
        instrument: String,
        /// The command sent.
        command: String,
    },
    /// A setting was used before [`Generator::identify`] chose the command table.
    #[error("signal generator on {port}: not identified yet (the driver asks `*IDN?` first to choose its command table)")]
    NotIdentified {
        /// Port.
        port: String,
    },
    /// The model's command table has no arbitrary-waveform upload.
    #[error("signal generator {instrument}: the command table `{model}` has no arbitrary-waveform upload, so it drives sines only; use a stepped sine, or a model with [model.arbitrary] in acquire/src/generator/models.toml (Keysight 33500B/33600A, Rigol DG800/DG1000Z, Tektronix AFG31000; set `dialect` in [generator]) (docs/scpi-generator.md)")]
    NoArbitrary {
        /// Port and identity.
        instrument: String,
        /// The command table's name.
        model: String,
    },
    /// A waveform beyond what the model plays.
    #[error("signal generator {instrument}: the {model} cannot play this arbitrary waveform: {detail}; {fix}")]
    ArbitraryLimit {
        /// Port and identity.
        instrument: String,
        /// The command table's name.
        model: String,
        /// What is exceeded.
        detail: String,
        /// What to change.
        fix: String,
    },
    /// The built-in command table is unreadable (a defect of this build).
    #[error(transparent)]
    Table(#[from] dialect::TableError),
    /// A value outside the model's range, or a model table without the range needed; refused
    /// before it is sent.
    #[error("signal generator {instrument}: the {model}: {source}")]
    Limits {
        /// Port and identity.
        instrument: String,
        /// The command table's name.
        model: String,
        /// What is outside which range.
        source: Box<limits::LimitError>,
    },
    /// A setting the instrument accepted reads back as something else.
    #[error("signal generator {instrument}: `{command}` was accepted, but `{query}` reads back {got:?} where {sent} was sent (resolution {tolerance}); the setting did not take: check the command table (dialect) and the generator's front panel (remote lock, another controller)")]
    ReadBack {
        /// Port and identity.
        instrument: String,
        /// The setting.
        command: String,
        /// The query that read it back.
        query: String,
        /// The value sent.
        sent: f64,
        /// The answer.
        got: String,
        /// The accepted deviation.
        tolerance: f64,
    },
    /// A setting was sent but the instrument did not confirm it (`*OPC?` unanswered).
    #[error("signal generator {instrument}: `{command}` was sent but not confirmed: {source}")]
    Unconfirmed {
        /// Port and identity.
        instrument: String,
        /// The setting.
        command: String,
        /// What happened to the confirmation.
        source: Box<GeneratorError>,
    },
    /// The connection dropped while a setting was being sent; it was reopened and the setting
    /// sent again, and then this happened.
    #[error("signal generator {instrument}: the connection dropped while `{command}` was being sent and was reopened; sending it again: {source}")]
    AfterReconnect {
        /// Port and identity.
        instrument: String,
        /// The setting in flight.
        command: String,
        /// What happened after the reconnect.
        source: Box<GeneratorError>,
    },
}

impl GeneratorError {
    /// Maps an I/O error on `instrument`: end-of-stream, hang-up and EIO become
    /// [`GeneratorError::Disconnected`].
    pub fn from_io(instrument: &str, e: std::io::Error) -> GeneratorError {
        use std::io::ErrorKind as K;
        let lost = matches!(
            e.kind(),
            K::UnexpectedEof | K::BrokenPipe | K::ConnectionReset | K::NotConnected
        ) || e.raw_os_error() == Some(5);
        let (instrument, detail) = (instrument.to_string(), e.to_string());
        if lost {
            GeneratorError::Disconnected { instrument, detail }
        } else {
            GeneratorError::Io { instrument, detail }
        }
    }
}

impl crate::transport::LinkFailure for GeneratorError {
    fn io(instrument: &str, e: std::io::Error) -> GeneratorError {
        GeneratorError::from_io(instrument, e)
    }

    fn closed(instrument: &str) -> GeneratorError {
        GeneratorError::Disconnected {
            instrument: instrument.to_string(),
            detail: "end of stream".into(),
        }
    }
}
