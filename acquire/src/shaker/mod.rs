//! The shaker-controller seam: what a sweep needs from any exciter controller, its waveforms,
//! status and errors, and its implementations: a SCPI shaker controller on a serial port
//! ([`serial`], or the simulated one) and a signal generator driving a power amplifier
//! ([`generator::GeneratorExciter`], on `crate::generator`'s drivers).

pub mod generator;
pub mod scpi;
pub mod serial;

pub use generator::GeneratorExciter;
pub use serial::{ScpiShaker, ShakerOptions};

use std::time::Duration;

use async_trait::async_trait;
use serde::{Deserialize, Serialize};

use crate::device::DeviceIdentity;
pub use crate::record::Waveform;

/// An exciter controller. Object safe; a sweep holds a `Box<dyn Shaker>`. Every method is bounded
/// by the implementation's timeout and retries; errors reported by the device are returned as
/// [`ShakerError::Device`], never swallowed.
#[async_trait]
pub trait Shaker: Send {
    /// Where the controller is connected, for messages and records.
    fn port(&self) -> &str;
    /// Asks the controller who it is (`*IDN?`).
    async fn identify(&mut self) -> Result<DeviceIdentity, ShakerError>;
    /// Returns the controller to its power-on state (output off) and clears its error queue.
    async fn reset(&mut self) -> Result<(), ShakerError>;
    /// Selects the waveform and its parameters.
    async fn set_waveform(&mut self, waveform: &Waveform) -> Result<(), ShakerError>;
    /// Sine frequency (Hz).
    async fn set_frequency(&mut self, hz: f64) -> Result<(), ShakerError>;
    /// Drive force amplitude (N): peak for sine and chirp, RMS for random and burst random.
    async fn set_force(&mut self, newtons: f64) -> Result<(), ShakerError>;
    /// Switches the amplifier output on or off.
    async fn set_output(&mut self, on: bool) -> Result<(), ShakerError>;
    /// Output state, the controller's own force reading and its questionable-status flags.
    async fn status(&mut self) -> Result<ShakerStatus, ShakerError>;
    /// The force the DAQ measured with the drive now set. An exciter whose force loop the host
    /// closes (a signal generator driving a power amplifier, [`crate::generator`]) records it and
    /// checks its limits (over-force, lost force signal); a controller with its own loop ignores it.
    async fn force_measured(&mut self, _reading: &ForceReading) -> Result<(), ShakerError> {
        Ok(())
    }
    /// Settings sent to the instrument since the frequency was last set, if the exciter counts
    /// them (a signal generator does: ramp increments and loop corrections).
    fn settings_this_line(&self) -> Option<u32> {
        None
    }
    /// The force the DAQ measured over one whole period of a broadband drive. An exciter whose
    /// force loop the host closes records it, checks its limits (over-force, lost force signal)
    /// and, while `may_adjust`, corrects its amplitude towards the target; returns whether it
    /// changed the drive. A controller with its own loop ignores it.
    async fn period_force_measured(&mut self, _reading: &PeriodForce) -> Result<bool, ShakerError> {
        Ok(false)
    }
}

/// The force over one whole period of a broadband drive, measured on the DAQ's force channel.
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodForce {
    /// Period number since the stream's start.
    pub period: u64,
    /// The plan's force: RMS for random and burst random, peak for a chirp (N).
    pub target_n: f64,
    /// RMS of the measured force over the period (N).
    pub rms_n: f64,
    /// Largest |force| sample in the period (N).
    pub peak_n: f64,
    /// The period is a settling one whose successor is also settling: the drive may change.
    pub may_adjust: bool,
}

/// One force measurement of the sweep's closed loop (N peak, Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct ForceReading {
    /// Sweep step.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Force amplitude held (N).
    pub target_n: f64,
    /// Drive commanded (N): the force the exciter's gain estimate expects.
    pub commanded_n: f64,
    /// Force amplitude measured on the DAQ's force channel (N).
    pub measured_n: f64,
}

/// The controller's status.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShakerStatus {
    /// Amplifier output on.
    pub output_on: bool,
    /// Force amplitude measured by the controller's own load cell (N; peak for sine).
    pub measured_force_n: f64,
    /// Questionable-status condition register (see [`scpi::questionable`]).
    pub questionable: u16,
}

impl ShakerStatus {
    /// Names of the questionable-status bits that are set (`interlock open`, …).
    pub fn problems(&self) -> Vec<&'static str> {
        scpi::questionable::names(self.questionable)
    }
}

/// Errors of a shaker controller. Each names the port and says what to check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ShakerError {
    /// The transport could not be opened.
    #[error(transparent)]
    Transport(#[from] crate::transport::TransportError),
    /// Reading or writing failed.
    #[error("shaker controller on {port}: I/O error: {source}; check the cable and that the controller is on")]
    Io {
        /// Port.
        port: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The controller went away (end of stream / hang-up).
    #[error("shaker controller on {port}: connection lost ({detail}); check the cable and the controller's power")]
    Disconnected {
        /// Port.
        port: String,
        /// What was seen.
        detail: String,
    },
    /// No answer within the timeout, after all retries.
    #[error("shaker controller on {port}: no answer to `{command}` within {waited:?} ({attempts} attempts){hint}")]
    Timeout {
        /// Port.
        port: String,
        /// Command sent.
        command: String,
        /// Timeout per attempt.
        waited: Duration,
        /// Attempts made.
        attempts: u32,
        /// What to check.
        hint: String,
    },
    /// The answer could not be understood.
    #[error("shaker controller on {port}: answer to `{command}` is not understood: {got:?}; is `port` really the shaker controller, at the right baud rate?")]
    Garbled {
        /// Port.
        port: String,
        /// Command sent.
        command: String,
        /// What came back (lossily decoded).
        got: String,
    },
    /// The controller identified itself as something else.
    #[error("shaker controller on {port}: identifies as `{got}`, stand file expects `{expected}`; check which device is on this port")]
    WrongIdentity {
        /// Port.
        port: String,
        /// Identity received.
        got: String,
        /// Identity expected.
        expected: String,
    },
    /// The controller reported an error for a command (from its `SYST:ERR?` queue).
    #[error("shaker controller on {port}: `{command}` failed: {code},\"{message}\"{more}")]
    Device {
        /// Port.
        port: String,
        /// Command that failed.
        command: String,
        /// SCPI error code.
        code: i32,
        /// SCPI error message.
        message: String,
        /// Further queued errors, if any.
        more: String,
    },
    /// The signal generator of a generator-driven exciter.
    #[error(transparent)]
    Generator(#[from] crate::generator::GeneratorError),
    /// A generator-driven exciter stopped the drive: over-force, over-voltage or lost force signal.
    #[error("exciter on {port}: {detail}; the drive is ramped down and the output switched off")]
    Limit {
        /// Generator port.
        port: String,
        /// What was exceeded or lost, with the values.
        detail: String,
    },
    /// A value outside what this driver may send (NaN, negative force).
    #[error("shaker controller on {port}: refusing to send {what} = {value}")]
    InvalidValue {
        /// Port.
        port: String,
        /// Which quantity.
        what: String,
        /// The value.
        value: f64,
    },
}

impl crate::transport::LinkFailure for ShakerError {
    fn io(port: &str, e: std::io::Error) -> ShakerError {
        ShakerError::from_io(port, e)
    }

    fn closed(port: &str) -> ShakerError {
        ShakerError::Disconnected {
            port: port.to_string(),
            detail: "end of stream".into(),
        }
    }
}

impl ShakerError {
    /// Maps an I/O error on `port`: end-of-stream and hang-up become [`ShakerError::Disconnected`].
    pub fn from_io(port: &str, e: std::io::Error) -> ShakerError {
        use std::io::ErrorKind as K;
        match e.kind() {
            K::UnexpectedEof | K::BrokenPipe | K::ConnectionReset | K::NotConnected => {
                ShakerError::Disconnected {
                    port: port.to_string(),
                    detail: e.to_string(),
                }
            }
            _ if e.raw_os_error() == Some(5) => ShakerError::Disconnected {
                port: port.to_string(),
                detail: e.to_string(),
            },
            _ => ShakerError::Io {
                port: port.to_string(),
                source: e,
            },
        }
    }
}
