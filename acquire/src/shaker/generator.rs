//! Generator + power amplifier + shaker as an exciter whose force loop the host closes: the sweep
//! asks for a force, this turns it into the generator's voltage through the amplifier's gain
//! estimate, ramps the amplitude at the stand's rate (timed from the previous amplitude change,
//! on every path: switch-on, between lines, ramp-down, abort), keeps every amplitude inside the
//! model's data-sheet range, holds the voltage and force limits, and
//! records every setting and every measured force in the session (`/drive`). A broadband drive
//! (periodic random, burst random, chirp) is uploaded as an arbitrary waveform played at the DAQ's
//! sample rate, its amplitude set from the gain estimate, checked on every period's measured force
//! RMS and peak, and corrected during the settling periods (the transfer learned there).

use async_trait::async_trait;

use super::{ForceReading, PeriodForce, Shaker, ShakerError, ShakerStatus, Waveform};
use crate::device::DeviceIdentity;
use crate::generator::amplifier::{Amplifier, RAMP_TICK};
use crate::generator::limits::{LimitError, Load};
use crate::generator::waveform::{self, DriveWaveform};
use crate::generator::{Generator, GeneratorError};
use crate::record::{DriveKind, DriveRecord};
use crate::session::SessionHandle;

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
    /// The amplitude the output idles at (V peak): the smallest the model accepts into a high
    /// impedance (from its data sheet, known after [`Shaker::reset`]).
    idle_v: f64,
    /// When the last amplitude change while the output was on (or the switch-on) was confirmed:
    /// the next change waits one ramp tick from it.
    last_change: Option<tokio::time::Instant>,
    /// The smallest amplitude step of the model (V peak).
    quantum_v: f64,
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
            volts: 0.0,
            idle_v: 0.0,
            last_change: None,
            quantum_v: 0.0,
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

    /// The amplitude the output idles at (V peak), after [`Shaker::reset`].
    pub fn idle_volts(&self) -> f64 {
        self.idle_v
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

    /// One amplitude setting. While the output is on it waits until one ramp tick has passed
    /// since the previous change was confirmed, so that no two changes come closer than the
    /// ramp rate allows, whichever path (switch-on, line, ramp-down, abort) sends them.
    async fn set_volts(&mut self, v: f64) -> Result<(), ShakerError> {
        if self.on {
            if let Some(t) = self.last_change {
                tokio::time::sleep_until(t + RAMP_TICK.div_f64(self.speed)).await;
            }
        }
        let result = self.gen.set_amplitude(v).await;
        if self.on {
            self.last_change = Some(tokio::time::Instant::now());
        }
        let set = match result {
            Ok(set) => set,
            Err(e) => {
                // The instrument may have taken the value before it failed (an error-queue entry,
                // a lost confirmation): a ramp-down starts from the higher of the two.
                self.volts = self.volts.max(v);
                return Err(e.into());
            }
        };
        self.volts = set;
        self.settings += 1;
        self.record(DriveKind::Amplitude, None);
        Ok(())
    }

    /// `v` (V peak) on the model's amplitude grid, at least the idle amplitude, checked against
    /// the model's range into a high impedance.
    fn sendable(&self, v: f64) -> Result<f64, ShakerError> {
        let Some(l) = self.gen.limits() else {
            return Ok(v.max(self.idle_v));
        };
        l.amplitude_to_send(v.max(self.idle_v), Load::HighImpedance)
            .map_err(|source| {
                GeneratorError::Limits {
                    instrument: self.port.clone(),
                    model: self.gen.model_name().to_string(),
                    source: Box::new(source),
                }
                .into()
            })
    }

    /// Moves the amplitude to `target` (V peak): in one setting while the output is off, in
    /// steps of at most [`Amplifier::ramp_step_v`] (less one amplitude step of the model, so
    /// that the instrument's rounding cannot exceed it) one [`RAMP_TICK`] apart while it is on.
    async fn ramp_to(&mut self, target: f64) -> Result<(), ShakerError> {
        let target = self.sendable(target)?;
        if !self.on {
            return self.set_volts(target).await;
        }
        let step = (self.amp.ramp_step_v() - self.quantum_v).max(self.quantum_v);
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
        }
    }

    /// Checks, before the output is ever switched on, that the stand's limits fit the model's
    /// range: the idle amplitude and the voltage limit within it.
    fn check_model_range(&mut self) -> Result<(), ShakerError> {
        let model = self.gen.model_name().to_string();
        let Some(l) = self.gen.limits().cloned() else {
            return Err(GeneratorError::Limits {
                instrument: self.port.clone(),
                model,
                source: Box::new(LimitError::NoRange {
                    field: "amplitude_high_z_vpp",
                    load: "into a high impedance",
                }),
            }
            .into());
        };
        let range = |e| -> ShakerError {
            GeneratorError::Limits {
                instrument: self.port.clone(),
                model: model.clone(),
                source: Box::new(e),
            }
            .into()
        };
        let [lo, hi] = l.amplitude_peak(Load::HighImpedance).map_err(range)?;
        self.idle_v = lo;
        self.quantum_v = 0.5 * l.amplitude_step_vpp;
        if self.amp.voltage_limit_v > hi + 1e-12 {
            return Err(self.limit(format!(
                "amplifier.voltage_limit {} V peak is above what the {model} delivers into the amplifier's high impedance ({hi} V peak = {} Vpp, {}); lower amplifier.voltage_limit in the stand file to at most {hi} V",
                self.amp.voltage_limit_v,
                2.0 * hi,
                l.source
            )));
        }
        Ok(())
    }

    /// Ramps down and switches the output off, then checks that the instrument says it is off.
    async fn switch_off(&mut self) -> Result<(), ShakerError> {
        let ramped = if self.on {
            self.ramp_to(self.idle_v).await
        } else {
            Ok(())
        };
        // Off even when the ramp failed (a generator error mid-ramp).
        self.gen.set_output(false).await?;
        self.last_change = None;
        self.on = false;
        self.settings += 1;
        // The driver read the state back: a generator still on failed the call above.
        self.record(DriveKind::Output, None);
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
        self.check_model_range()?;
        self.gen.prepare_sine().await?;
        // `prepare_sine` switched the output off and set the idle amplitude.
        self.on = false;
        self.last_change = None;
        self.volts = self.idle_v;
        self.record(DriveKind::Output, None);
        self.record(DriveKind::Amplitude, None);
        Ok(())
    }

    async fn set_waveform(&mut self, waveform: &Waveform) -> Result<(), ShakerError> {
        if *waveform == Waveform::Sine {
            if self.broadband.take().is_some() {
                self.switch_off().await?;
                self.gen.prepare_sine().await?;
                self.volts = self.idle_v;
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
        let volts = (newtons * per_newton).max(self.idle_v);
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
        // Switch on at the idle amplitude, then ramp to the amplitude set while off; the
        // switch-on is the first change the ramp is timed from.
        let target = self.volts;
        let idle = self.idle_v;
        self.set_volts(idle).await?;
        self.gen.set_output(true).await?;
        self.on = true;
        self.last_change = Some(tokio::time::Instant::now());
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
