//! Generator + power amplifier + shaker as an exciter whose force loop the host closes: the sweep
//! asks for a force, this turns it into the generator's voltage through the amplifier's gain
//! estimate, ramps the amplitude at the stand's rate, holds the voltage and force limits, and
//! records every setting and every measured force in the session (`/drive`).

use std::time::Duration;

use async_trait::async_trait;

use super::{Generator, GeneratorError};
use crate::device::DeviceIdentity;
use crate::session::records::{DriveKind, DriveRecord};
use crate::session::SessionHandle;
use crate::shaker::{ForceReading, Shaker, ShakerError, ShakerStatus, Waveform};

/// The power amplifier and shaker behind the generator (the stand file's `[amplifier]`), SI.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Amplifier {
    /// Estimated force amplitude per generator volt (N/V, peak per peak): amplifier gain times
    /// the shaker's force constant. The loop learns the real transfer; this is the start.
    pub gain_n_per_v: f64,
    /// Largest generator amplitude ever sent (V peak).
    pub voltage_limit_v: f64,
    /// Measured force amplitude that stops the sweep (N peak).
    pub force_limit_n: f64,
    /// Fastest change of the generator amplitude while the output is on (V/s).
    pub ramp_rate_v_per_s: f64,
    /// Accepted relative deviation of the measured force from the target (e.g. 0.02).
    pub tolerance: f64,
}

impl Amplifier {
    /// Largest amplitude change per setting while the output is on (V): the ramp rate over
    /// one [`RAMP_TICK`].
    pub fn ramp_step_v(&self) -> f64 {
        self.ramp_rate_v_per_s * RAMP_TICK.as_secs_f64()
    }
}

/// Time between two amplitude settings of a ramp (stand time).
pub const RAMP_TICK: Duration = Duration::from_millis(50);

/// The amplitude the output idles at (V peak): the smallest every model accepts (1 mVpp).
pub const IDLE_V: f64 = 0.0005;

/// A measured force below this fraction of what the drive should give means the force signal is
/// lost (amplifier tripped, shaker disconnected, force sensor cable).
pub const LOST_FORCE_FRACTION: f64 = 0.1;

/// A generator-driven exciter (see the module docs).
pub struct GeneratorExciter {
    gen: Box<dyn Generator>,
    amp: Amplifier,
    port: String,
    volts: f64,
    on: bool,
    frequency_hz: f64,
    settings: u32,
    session: Option<SessionHandle>,
    speed: f64,
}

impl GeneratorExciter {
    /// An exciter over `gen`; `session` receives the `/drive` records; `speed` is simulated time
    /// per wall-clock time (1 on a real stand) and scales the waits of a ramp.
    pub fn new(
        gen: Box<dyn Generator>,
        amp: Amplifier,
        session: Option<SessionHandle>,
        speed: f64,
    ) -> Self {
        let port = gen.port().to_string();
        GeneratorExciter {
            gen,
            amp,
            port,
            volts: IDLE_V,
            on: false,
            frequency_hz: 0.0,
            settings: 0,
            session,
            speed: if speed > 0.0 { speed } else { 1.0 },
        }
    }

    /// The amplitude now set (V peak).
    pub fn volts(&self) -> f64 {
        self.volts
    }

    fn record(&self, kind: DriveKind, reading: Option<&ForceReading>) {
        let Some(s) = &self.session else { return };
        let r = DriveRecord {
            kind,
            port: self.port.clone(),
            step: reading.map(|r| r.step),
            frequency_hz: self.frequency_hz,
            volts_peak: self.volts,
            output_on: self.on,
            force_n: reading.map(|r| r.measured_n),
            target_n: reading.map(|r| r.target_n),
            settings_this_line: self.settings,
        };
        if let Err(e) = s.record(&r) {
            // The sweep's next record or session check reports the failing session.
            tracing::warn!("drive record not written: {e}");
        }
    }

    fn limit(&self, detail: String) -> ShakerError {
        ShakerError::Limit {
            port: self.port.clone(),
            detail,
        }
    }

    async fn set_volts(&mut self, v: f64) -> Result<(), ShakerError> {
        self.gen.set_amplitude(v).await?;
        self.volts = v;
        self.settings += 1;
        self.record(DriveKind::Amplitude, None);
        Ok(())
    }

    /// Moves the amplitude to `target` (V peak): in one setting while the output is off, in
    /// steps of at most [`Amplifier::ramp_step_v`] one [`RAMP_TICK`] apart while it is on.
    async fn ramp_to(&mut self, target: f64) -> Result<(), ShakerError> {
        if !self.on {
            return self.set_volts(target).await;
        }
        let step = self.amp.ramp_step_v();
        let tick = RAMP_TICK.div_f64(self.speed);
        loop {
            let delta = target - self.volts;
            if delta.abs() <= 1e-9 {
                return Ok(());
            }
            let next = self.volts + delta.clamp(-step, step);
            let last = (target - next).abs() <= 1e-9;
            self.set_volts(if last { target } else { next }).await?;
            if last {
                return Ok(());
            }
            tokio::time::sleep(tick).await;
        }
    }

    /// Ramps down and switches the output off, then checks that the instrument says it is off.
    async fn switch_off(&mut self) -> Result<(), ShakerError> {
        let ramped = if self.on {
            self.ramp_to(IDLE_V).await
        } else {
            Ok(())
        };
        // Off even when the ramp failed (a generator error mid-ramp).
        self.gen.set_output(false).await?;
        self.on = false;
        self.settings += 1;
        self.record(DriveKind::Output, None);
        if self.gen.output().await? {
            return Err(GeneratorError::OutputStillOn {
                instrument: self.port.clone(),
                command: "output off".into(),
            }
            .into());
        }
        ramped
    }
}

#[async_trait]
impl Shaker for GeneratorExciter {
    fn port(&self) -> &str {
        &self.port
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, ShakerError> {
        Ok(self.gen.identify().await?)
    }

    async fn reset(&mut self) -> Result<(), ShakerError> {
        self.gen.prepare_sine().await?;
        // `prepare_sine` switched the output off and set the idle amplitude.
        self.on = false;
        self.volts = IDLE_V;
        self.record(DriveKind::Output, None);
        self.record(DriveKind::Amplitude, None);
        Ok(())
    }

    async fn set_waveform(&mut self, waveform: &Waveform) -> Result<(), ShakerError> {
        match waveform {
            Waveform::Sine => Ok(()),
            other => Err(self.limit(format!(
                "the generator driver drives sines only (stepped sine); {other:?} is not supported yet"
            ))),
        }
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), ShakerError> {
        self.gen.set_frequency(hz).await?;
        self.frequency_hz = hz;
        self.settings = 1;
        self.record(DriveKind::Frequency, None);
        Ok(())
    }

    async fn set_force(&mut self, newtons: f64) -> Result<(), ShakerError> {
        if !(newtons.is_finite() && newtons >= 0.0) {
            return Err(self.limit(format!("refusing a drive of {newtons} N")));
        }
        let volts = (newtons / self.amp.gain_n_per_v).max(IDLE_V);
        if volts > self.amp.voltage_limit_v {
            return Err(self.limit(format!(
                "over-voltage: {newtons:.1} N needs {volts:.3} V at the estimated {:.1} N/V, above amplifier.voltage_limit {:.3} V",
                self.amp.gain_n_per_v, self.amp.voltage_limit_v
            )));
        }
        self.ramp_to(volts).await
    }

    async fn set_output(&mut self, on: bool) -> Result<(), ShakerError> {
        if !on {
            return self.switch_off().await;
        }
        if self.on {
            return Ok(());
        }
        // Switch on at the idle amplitude, then ramp to the amplitude set while off.
        let target = self.volts;
        self.set_volts(IDLE_V).await?;
        self.gen.set_output(true).await?;
        self.on = true;
        self.settings += 1;
        self.record(DriveKind::Output, None);
        self.ramp_to(target).await
    }

    async fn status(&mut self) -> Result<ShakerStatus, ShakerError> {
        let output_on = self.gen.output().await?;
        Ok(ShakerStatus {
            output_on,
            measured_force_n: if output_on {
                self.volts * self.amp.gain_n_per_v
            } else {
                0.0
            },
            questionable: 0,
        })
    }

    async fn force_measured(&mut self, reading: &ForceReading) -> Result<(), ShakerError> {
        self.record(DriveKind::Measurement, Some(reading));
        let f = reading.frequency_hz;
        if reading.measured_n > self.amp.force_limit_n {
            return Err(self.limit(format!(
                "over-force: {:.1} N measured at {f:.2} Hz ({:.3} V), above amplifier.force_limit {:.1} N",
                reading.measured_n, self.volts, self.amp.force_limit_n
            )));
        }
        let expected = self.volts * self.amp.gain_n_per_v;
        if self.on && reading.measured_n < LOST_FORCE_FRACTION * expected {
            return Err(self.limit(format!(
                "lost force signal: {:.1} N measured at {f:.2} Hz where {:.3} V should give about {expected:.0} N; check the amplifier (fault, interlock), the shaker's cable and the force sensor",
                reading.measured_n, self.volts
            )));
        }
        Ok(())
    }

    fn settings_this_line(&self) -> Option<u32> {
        Some(self.settings)
    }
}
