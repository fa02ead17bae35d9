//! Generator + power amplifier + shaker as an exciter whose force loop the host closes: the sweep
//! asks for a force, this turns it into the generator's voltage through the amplifier's gain
//! estimate, ramps the amplitude at the stand's rate, holds the voltage and force limits, and
//! records every setting and every measured force in the session (`/drive`). A broadband drive
//! (periodic random, burst random, chirp) is uploaded as an arbitrary waveform played at the DAQ's
//! sample rate, its amplitude set from the gain estimate, checked on every period's measured force
//! RMS and peak, and corrected during the settling periods (the transfer learned there).

use async_trait::async_trait;

use super::amplifier::{Amplifier, RAMP_TICK};
use super::waveform::{self, DriveWaveform};
use super::{Generator, GeneratorError};
use crate::device::DeviceIdentity;
use crate::record::{DriveKind, DriveRecord};
use crate::session::SessionHandle;
use crate::shaker::{ForceReading, PeriodForce, Shaker, ShakerError, ShakerStatus, Waveform};

/// The amplitude the output idles at (V peak): the smallest every model accepts (1 mVpp).
pub const IDLE_V: f64 = 0.0005;

/// A measured force below this fraction of what the drive should give means the force signal is
/// lost (amplifier tripped, shaker disconnected, force sensor cable).
pub const LOST_FORCE_FRACTION: f64 = 0.1;

/// The broadband drive now loaded.
#[derive(Debug, Clone)]
struct Broadband {
    waveform: Waveform,
    /// RMS of the samples over the driven part (force RMS per full-scale force for random and
    /// burst; a chirp's force is its peak).
    drive_rms: f64,
    /// RMS of the samples over the whole period.
    period_rms: f64,
    /// The period after which the amplitude was last corrected.
    corrected_after: Option<u64>,
}

impl Broadband {
    /// Full-scale volts per newton of the plan's force (RMS for random/burst, peak for chirp).
    fn volts_per_plan_newton(&self, gain_n_per_v: f64) -> f64 {
        let per = match self.waveform {
            Waveform::Chirp { .. } => 1.0,
            _ => self.drive_rms,
        };
        1.0 / (gain_n_per_v * per)
    }
}

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
    /// Rate arbitrary waveforms are played at (Sa/s): the DAQ's, so a period is the same whole
    /// number of samples on both.
    sample_rate_hz: Option<f64>,
    broadband: Option<Broadband>,
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
            sample_rate_hz: None,
            broadband: None,
        }
    }

    /// Plays broadband drives at `hz` samples per second (the stand's DAQ sample rate).
    pub fn with_sample_rate(mut self, hz: f64) -> Self {
        self.sample_rate_hz = Some(hz);
        self
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
            waveform: None,
            sample_rate_hz: None,
            seed: None,
            codes: None,
            code_range: None,
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
        if *waveform == Waveform::Sine {
            if self.broadband.take().is_some() {
                self.switch_off().await?;
                self.gen.prepare_sine().await?;
                self.volts = IDLE_V;
            }
            return Ok(());
        }
        if self.on {
            return Err(
                self.limit("a broadband waveform is loaded with the output off only".to_string())
            );
        }
        let drive = self.broadband_samples(waveform)?;
        let codes = self
            .gen
            .play_arbitrary(&drive.samples, drive.sample_rate_hz)
            .await?;
        self.settings += 1;
        let period_rms =
            (drive.samples.iter().map(|x| x * x).sum::<f64>() / drive.samples.len() as f64).sqrt();
        self.broadband = Some(Broadband {
            waveform: waveform.clone(),
            drive_rms: drive.rms,
            period_rms,
            corrected_after: None,
        });
        if let Some(s) = &self.session {
            let range = self.gen.arbitrary().map(|a| (a.code_min, a.code_max));
            let r = DriveRecord {
                kind: DriveKind::Waveform,
                port: self.port.clone(),
                step: None,
                frequency_hz: self.frequency_hz,
                volts_peak: self.volts,
                output_on: self.on,
                force_n: None,
                target_n: None,
                settings_this_line: self.settings,
                waveform: Some(waveform.clone()),
                sample_rate_hz: Some(drive.sample_rate_hz),
                seed: Some(drive.seed),
                codes: Some(codes),
                code_range: range,
            };
            if let Err(e) = s.record(&r) {
                tracing::warn!("drive record not written: {e}");
            }
        }
        Ok(())
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
        let per_newton = match &self.broadband {
            Some(b) => b.volts_per_plan_newton(self.amp.gain_n_per_v),
            None => 1.0 / self.amp.gain_n_per_v,
        };
        let volts = (newtons * per_newton).max(IDLE_V);
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

    async fn period_force_measured(&mut self, r: &PeriodForce) -> Result<bool, ShakerError> {
        let Some(b) = self.broadband.clone() else {
            return Ok(false);
        };
        // The period's force RMS the plan asks for: the plan's force through the waveform's
        // shape (a burst is silent for part of the period; a chirp's force is its peak).
        let target = r.target_n * b.volts_per_plan_newton(1.0) * b.period_rms;
        self.record(
            DriveKind::Measurement,
            Some(&ForceReading {
                step: r.period as usize,
                frequency_hz: self.frequency_hz,
                target_n: target,
                commanded_n: self.volts * self.amp.gain_n_per_v * b.period_rms,
                measured_n: r.rms_n,
            }),
        );
        if r.peak_n > self.amp.force_limit_n {
            return Err(self.limit(format!(
                "over-force: {:.1} N peak measured in broadband period {} ({:.3} V full scale), above amplifier.force_limit {:.1} N",
                r.peak_n, r.period, self.volts, self.amp.force_limit_n
            )));
        }
        let expected = self.volts * self.amp.gain_n_per_v * b.period_rms;
        if self.on && r.rms_n < LOST_FORCE_FRACTION * expected {
            return Err(self.limit(format!(
                "lost force signal: {:.1} N RMS measured in broadband period {} where {:.3} V full scale should give about {expected:.0} N RMS; check the amplifier (fault, interlock), the shaker's cable and the force sensor",
                r.rms_n, r.period, self.volts
            )));
        }
        let mixed = b.corrected_after.is_some_and(|p| r.period <= p + 1);
        if !r.may_adjust
            || mixed
            || !self.on
            || (r.rms_n / target - 1.0).abs() <= self.amp.tolerance
        {
            return Ok(false);
        }
        // The transfer learned from this period: force RMS per volt RMS.
        let learned = r.rms_n / (self.volts * b.period_rms);
        let volts = target / (learned * b.period_rms);
        if volts > self.amp.voltage_limit_v {
            return Err(self.limit(format!(
                "over-voltage: {:.1} N RMS needs {volts:.3} V full scale at the learned {learned:.1} N/V, above amplifier.voltage_limit {:.3} V",
                target, self.amp.voltage_limit_v
            )));
        }
        self.amp.gain_n_per_v = learned;
        self.ramp_to(volts).await?;
        if let Some(bb) = &mut self.broadband {
            bb.corrected_after = Some(r.period);
        }
        Ok(true)
    }
}

impl GeneratorExciter {
    /// One period of `w` at the DAQ's sample rate, checked against the model's arbitrary
    /// waveform limits with messages naming the stand file's fields.
    fn broadband_samples(&self, w: &Waveform) -> Result<DriveWaveform, ShakerError> {
        let model = self.gen.model_name().to_string();
        let Some(a) = self.gen.arbitrary() else {
            return Err(GeneratorError::NoArbitrary {
                instrument: self.port.clone(),
                model,
            }
            .into());
        };
        let Some(rate) = self.sample_rate_hz else {
            return Err(self.limit(
                "no sample rate for the arbitrary waveform (the stand's [daq] sample_rate)".into(),
            ));
        };
        let period = waveform::period_s(w).unwrap_or(0.0);
        let points = (period * rate).round() as usize;
        let limit = |detail: String, fix: &str| -> ShakerError {
            GeneratorError::ArbitraryLimit {
                instrument: self.port.clone(),
                model: model.clone(),
                detail,
                fix: fix.to_string(),
            }
            .into()
        };
        if rate > a.max_sample_rate_hz {
            return Err(limit(
                format!("the stand's [daq] sample_rate {rate} Hz is above the model's {} Sa/s", a.max_sample_rate_hz),
                "lower `sample_rate` in [daq] of the stand file (the waveform is played at the DAQ's rate)",
            ));
        }
        if points > a.max_points || points < a.min_points {
            return Err(limit(
                format!(
                    "a period of {period} s at the stand's [daq] sample_rate {rate} Hz is {points} points, the model takes {}..{} per upload",
                    a.min_points, a.max_points
                ),
                &format!(
                    "shorten the broadband period (period_s; random drives repeat every 1 s) or lower `sample_rate` in [daq] so that period × sample_rate ≤ {}",
                    a.max_points
                ),
            ));
        }
        waveform::synthesize(w, rate, waveform::DEFAULT_SEED).map_err(|e| self.limit(e.to_string()))
    }
}
