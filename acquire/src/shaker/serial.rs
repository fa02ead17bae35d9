//! The host driver for the SCPI shaker controller (docs/shaker-scpi.md) over any [`Transport`]:
//! queries with a timeout and retries; every setting is followed by `SYST:ERR?` so the
//! controller's errors reach the operator.

use std::time::Duration;

use async_trait::async_trait;

use super::scpi::{self, Command, Function};
use super::{Shaker, ShakerError, ShakerStatus, Waveform};
use crate::device::DeviceIdentity;
use crate::transport::{Answer, LineLink, Transport};

/// Timeouts and retries of the SCPI driver.
#[derive(Debug, Clone, PartialEq)]
pub struct ShakerOptions {
    /// How long to wait for each answer line.
    pub timeout: Duration,
    /// How many times a query is re-sent after a timeout (settings are idempotent and re-sent too).
    pub retries: u32,
}

impl Default for ShakerOptions {
    fn default() -> Self {
        ShakerOptions {
            timeout: Duration::from_millis(500),
            retries: 2,
        }
    }
}

/// A shaker controller speaking the SCPI dialect.
pub struct ScpiShaker<T: Transport = Box<dyn Transport>> {
    link: LineLink<T>,
    port: String,
    opts: ShakerOptions,
}

impl<T: Transport> ScpiShaker<T> {
    /// A driver over `io`. Nothing is sent until the first call.
    pub fn new(io: T, opts: ShakerOptions) -> Self {
        let port = io.port().to_string();
        ScpiShaker {
            link: LineLink::new(io),
            port,
            opts,
        }
    }

    async fn send(&mut self, line: &str) -> Result<(), ShakerError> {
        self.link
            .send(line, "\n")
            .await
            .map_err(|e| ShakerError::from_io(&self.port, e))
    }

    /// Sends a query and returns its answer line, re-sending after a timeout.
    pub async fn query(&mut self, command: &Command) -> Result<String, ShakerError> {
        let line = command.to_string();
        let (timeout, retries) = (self.opts.timeout, self.opts.retries);
        let answer = self.link.query(&line, "\n", timeout, retries).await;
        match answer.map_err(|e| e.on::<ShakerError>(&self.port))? {
            Answer::Text(t) => Ok(t),
            Answer::Garbage(g) => Err(ShakerError::Garbled {
                port: self.port.clone(),
                command: line,
                got: g,
            }),
            Answer::Silent { pending } => {
                let hint = match pending {
                    Some(g) => format!(
                        " (received {g:?} without a line end: wrong device, baud rate or terminator?)"
                    ),
                    None => "; check that the controller is on, the cable, and the baud rate".into(),
                };
                Err(ShakerError::Timeout {
                    port: self.port.clone(),
                    command: line,
                    waited: timeout,
                    attempts: retries + 1,
                    hint,
                })
            }
        }
    }

    async fn query_parsed<V>(
        &mut self,
        command: &Command,
        parse: impl Fn(&str) -> Option<V>,
    ) -> Result<V, ShakerError> {
        let answer = self.query(command).await?;
        parse(&answer).ok_or_else(|| ShakerError::Garbled {
            port: self.port.clone(),
            command: command.to_string(),
            got: answer,
        })
    }

    /// Sends a setting, then reads the error queue; any queued error fails the call.
    pub async fn set(&mut self, command: &Command) -> Result<(), ShakerError> {
        let line = command.to_string();
        self.send(&line).await?;
        let first = self
            .query_parsed(&Command::NextError, scpi::parse_error_entry)
            .await?;
        if first.code == scpi::codes::NO_ERROR {
            return Ok(());
        }
        // Drain the rest of the queue so it does not blame the next command.
        let mut more = Vec::new();
        for _ in 0..16 {
            let e = self
                .query_parsed(&Command::NextError, scpi::parse_error_entry)
                .await?;
            if e.code == scpi::codes::NO_ERROR {
                break;
            }
            more.push(e.to_string());
        }
        Err(ShakerError::Device {
            port: self.port.clone(),
            command: line,
            code: first.code,
            message: first.message,
            more: scpi::also_queued(&more),
        })
    }

    fn check(&self, what: &str, value: f64, min: f64) -> Result<(), ShakerError> {
        if value.is_finite() && value >= min {
            Ok(())
        } else {
            Err(ShakerError::InvalidValue {
                port: self.port.clone(),
                what: what.into(),
                value,
            })
        }
    }
}

#[async_trait]
impl<T: Transport> Shaker for ScpiShaker<T> {
    fn port(&self) -> &str {
        &self.port
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, ShakerError> {
        self.query_parsed(&Command::Identify, DeviceIdentity::parse_idn)
            .await
    }

    async fn reset(&mut self) -> Result<(), ShakerError> {
        self.send(&Command::ClearStatus.to_string()).await?;
        self.set(&Command::Reset).await
    }

    async fn set_waveform(&mut self, w: &Waveform) -> Result<(), ShakerError> {
        match *w {
            Waveform::Sine => self.set(&Command::SetFunction(Function::Sine)).await,
            Waveform::Random { f_lo_hz, f_hi_hz } => {
                self.check("band start (Hz)", f_lo_hz, 0.0)?;
                self.check("band stop (Hz)", f_hi_hz, 0.0)?;
                self.set(&Command::SetFunction(Function::Random)).await?;
                self.set(&Command::SetBandStart(f_lo_hz)).await?;
                self.set(&Command::SetBandStop(f_hi_hz)).await
            }
            Waveform::BurstRandom {
                f_lo_hz,
                f_hi_hz,
                duty,
                period_s,
            } => {
                self.check("band start (Hz)", f_lo_hz, 0.0)?;
                self.check("band stop (Hz)", f_hi_hz, 0.0)?;
                self.check("duty cycle", duty, 0.0)?;
                self.check("period (s)", period_s, 0.0)?;
                self.set(&Command::SetFunction(Function::Burst)).await?;
                self.set(&Command::SetBandStart(f_lo_hz)).await?;
                self.set(&Command::SetBandStop(f_hi_hz)).await?;
                self.set(&Command::SetDutyCycle(duty)).await?;
                self.set(&Command::SetPeriod(period_s)).await
            }
            Waveform::Chirp {
                f_lo_hz,
                f_hi_hz,
                period_s,
            } => {
                self.check("band start (Hz)", f_lo_hz, 0.0)?;
                self.check("band stop (Hz)", f_hi_hz, 0.0)?;
                self.check("period (s)", period_s, 0.0)?;
                self.set(&Command::SetFunction(Function::Chirp)).await?;
                self.set(&Command::SetBandStart(f_lo_hz)).await?;
                self.set(&Command::SetBandStop(f_hi_hz)).await?;
                self.set(&Command::SetPeriod(period_s)).await
            }
        }
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), ShakerError> {
        self.check("frequency (Hz)", hz, 0.0)?;
        self.set(&Command::SetFrequency(hz)).await
    }

    async fn set_force(&mut self, newtons: f64) -> Result<(), ShakerError> {
        self.check("force (N)", newtons, 0.0)?;
        self.set(&Command::SetForce(newtons)).await
    }

    async fn set_output(&mut self, on: bool) -> Result<(), ShakerError> {
        self.set(&Command::SetOutput(on)).await
    }

    async fn status(&mut self) -> Result<ShakerStatus, ShakerError> {
        let output_on = self
            .query_parsed(&Command::QueryOutput, scpi::parse_bool_answer)
            .await?;
        let measured_force_n = self
            .query_parsed(&Command::MeasureForce, scpi::parse_number_answer)
            .await?;
        let questionable = self
            .query_parsed(&Command::QuestionableCondition, |s| {
                s.trim().parse::<u16>().ok()
            })
            .await?;
        Ok(ShakerStatus {
            output_on,
            measured_force_n,
            questionable,
        })
    }
}
