//! Serving a recorded session through the simulated devices (`ident replay --serve`).
//!
//! The session's own stand configuration is served by [`crate::sim::SimStand`] on new
//! pseudo-terminals, with the recorded device identities, and with the structure replaced by what
//! the session measured: a [`RecordedPlant`] answers each frequency with the FRFs of every
//! acceleration channel recomputed from the session's raw blocks ([`crate::analysis`]), per newton
//! of delivered force. Sensor noise is the noise level the session measured on each channel (its
//! median over the steps). So `ident sweep` against the served ports runs the whole live path —
//! rig, SCPI and stream drivers, the closed force loop, the session writer — on a real session's
//! structure, deterministically: it does not replay the raw bytes, whose timing a live host
//! cannot reproduce (the closed loop decides differently when its windows move by a block).
//!
//! At a recorded step frequency the response is the recorded one exactly; between steps it is
//! interpolated linearly in log frequency (real and imaginary parts); outside the recorded band
//! the nearest step's is held.

use std::path::Path;
use std::sync::Arc;

use crate::analysis::{characteristics, AnalysisOptions, SessionAnalysis};
use crate::device::DeviceIdentity;
use crate::record::{DeviceIdentityRecord, Role, StandRecord};
use crate::session;
use crate::sim::plant::{Interaction, Plant, PlantError, C64};
use crate::sim::signal::{SimChannel, Source};
use crate::sim::{SimIdentities, SimSetup};
use crate::stand::{ChannelKind, Faults, Stand};

/// Why a session cannot be served.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The session cannot be read.
    #[error(transparent)]
    Session(#[from] session::SessionError),
    /// The session's records cannot be analysed.
    #[error(transparent)]
    Analysis(#[from] crate::analysis::AnalysisError),
    /// The session lacks what serving needs.
    #[error("{path}: {what}")]
    Incomplete {
        /// Session file.
        path: String,
        /// What is missing, and what to do.
        what: String,
    },
}

/// Why a session's analysis gives no structure to serve.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RecordingGap {
    /// A step lacks one of the stand's acceleration channels.
    #[error("step {step} has no channel `{channel}`")]
    MissingChannel {
        /// Step number.
        step: usize,
        /// The stand's channel name.
        channel: String,
    },
    /// Nothing was measured.
    #[error("it has no usable step (nothing measured to serve)")]
    NoSteps,
}

/// The response a session measured, as the simulated stand's structure.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedPlant {
    /// Step frequencies (Hz), ascending, distinct.
    freqs_hz: Vec<f64>,
    /// `frf[step][sensor]`: acceleration per newton of delivered force (m/s²/N).
    frf: Vec<Vec<C64>>,
}

impl RecordedPlant {
    /// The FRFs of `analysis` for the stand's acceleration channels (stand order, by name).
    pub fn from_analysis(
        analysis: &SessionAnalysis,
        stand: &Stand,
    ) -> Result<RecordedPlant, RecordingGap> {
        let sensors: Vec<&str> = stand
            .channels
            .iter()
            .filter(|c| c.kind == ChannelKind::Acceleration)
            .map(|c| c.name.as_str())
            .collect();
        let mut steps: Vec<(f64, Vec<C64>)> = Vec::new();
        for s in &analysis.steps {
            if steps.iter().any(|(f, _)| *f == s.frequency_hz) {
                continue; // a frequency measured twice keeps its first measurement, as the analysis does
            }
            let row = sensors
                .iter()
                .map(|name| {
                    s.channels
                        .iter()
                        .find(|c| c.name == *name)
                        .map(|c| C64::new(c.frf_re, c.frf_im))
                        .ok_or_else(|| RecordingGap::MissingChannel {
                            step: s.step,
                            channel: name.to_string(),
                        })
                })
                .collect::<Result<Vec<_>, _>>()?;
            steps.push((s.frequency_hz, row));
        }
        if steps.is_empty() {
            return Err(RecordingGap::NoSteps);
        }
        steps.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (freqs_hz, frf) = steps.into_iter().unzip();
        Ok(RecordedPlant { freqs_hz, frf })
    }

    /// The recorded step frequencies (Hz).
    pub fn frequencies(&self) -> &[f64] {
        &self.freqs_hz
    }

    fn at(&self, f: f64) -> Vec<C64> {
        let fs = &self.freqs_hz;
        let last = fs.len() - 1;
        if !(f > fs[0]) {
            return self.frf[0].clone();
        }
        if f >= fs[last] {
            return self.frf[last].clone();
        }
        let i = fs.partition_point(|&x| x <= f) - 1;
        if fs[i] == f {
            return self.frf[i].clone();
        }
        let t = (f.ln() - fs[i].ln()) / (fs[i + 1].ln() - fs[i].ln());
        self.frf[i]
            .iter()
            .zip(&self.frf[i + 1])
            .map(|(a, b)| a * (1.0 - t) + b * t)
            .collect()
    }
}

impl Plant for RecordedPlant {
    fn sensor_count(&self) -> usize {
        self.frf[0].len()
    }

    fn response(&self, freqs_hz: &[f64]) -> Result<Vec<Vec<C64>>, PlantError> {
        Ok(freqs_hz.iter().map(|&f| self.at(f)).collect())
    }
}

/// What serving a session needs: its stand (ports set to `"sim"`), the simulated devices' setup,
/// and the plant (for reports).
pub struct Served {
    /// The recorded stand configuration.
    pub stand: Stand,
    /// The simulated devices, answering with the recorded structure and identities.
    pub setup: SimSetup,
    /// The recorded structure.
    pub plant: Arc<RecordedPlant>,
}

/// Prepares `session` for serving at `speed` (recorded time per wall-clock time; `None`: the
/// recorded simulated stand's own speed, or 1 = real time).
pub fn prepare(session: &Path, speed: Option<f64>) -> Result<Served, ReplayError> {
    let path = session.display().to_string();
    let incomplete = |what: String| ReplayError::Incomplete {
        path: path.clone(),
        what,
    };
    let rep = session::read(session)?;
    let stand_rec: StandRecord = rep.first()?.ok_or_else(|| incomplete("no /stand record: the session was not written by a sweep, or was cut before the stand was recorded".into()))?;
    if stand_rec.text.is_empty() {
        return Err(incomplete(
            "the /stand record has no stand file text".into(),
        ));
    }
    let file = if stand_rec.file.is_empty() {
        "recorded stand"
    } else {
        &stand_rec.file
    };
    let stand = Stand::parse(&stand_rec.text, file)
        .map_err(|e| incomplete(format!("the recorded stand file does not load here: {e}")))?;
    let ids: Vec<DeviceIdentityRecord> = rep.all()?;
    let identity = |role: Role| -> Result<DeviceIdentity, ReplayError> {
        let r = ids.iter().find(|r| r.role == role).ok_or_else(|| {
            incomplete(format!("no /device/identity record for the {role:?}: the rig never connected; nothing to serve"))
        })?;
        Ok(DeviceIdentity {
            manufacturer: r.manufacturer.clone(),
            model: r.model.clone(),
            serial: r.serial.clone(),
            firmware: r.firmware.clone(),
        })
    };
    let identities = SimIdentities {
        shaker: identity(Role::Shaker)?,
        daq: identity(Role::Daq)?,
    };
    let analysis = characteristics(session, &AnalysisOptions::default())?;
    let plant = RecordedPlant::from_analysis(&analysis, &stand)
        .map_err(|gap| incomplete(gap.to_string()))?;
    let plant = Arc::new(plant);
    let speed = speed
        .or(stand.truth.as_ref().map(|t| t.speed))
        .unwrap_or(1.0);
    if !(speed.is_finite() && speed > 0.0) {
        return Err(incomplete(format!(
            "speed {speed}: give a factor > 0 (1 = real time)"
        )));
    }
    let channels = sim_channels(&stand, &analysis);
    let interaction = stand
        .truth
        .as_ref()
        .map(|t| Interaction {
            gain: t.shaker_gain,
            cutoff_hz: t.shaker_cutoff_hz,
        })
        .unwrap_or(Interaction {
            gain: 1.0,
            cutoff_hz: f64::INFINITY,
        });
    // A generator stand's session is served by the simulated generator, answering with the
    // recorded identity and without the recorded stand's injected faults.
    let generator = crate::sim::SimGeneratorSetup::from_stand(&stand).map(|mut g| {
        g.device.identity = identities.shaker.clone();
        g.device.amplifier_trip_after_lines = None;
        g.device.amplifier_surge_after_lines = None;
        g
    });
    let setup = SimSetup {
        plant: plant.clone(),
        interaction,
        channels,
        sample_rate_hz: stand.daq.sample_rate_hz,
        speed,
        seed: stand.truth.as_ref().map(|t| t.seed).unwrap_or(1),
        faults: Faults::default(),
        max_force_n: stand.shaker.max_force_n * 1.25,
        identities,
        generator,
    };
    Ok(Served {
        stand,
        setup,
        plant,
    })
}

/// The simulated DAQ's inputs for the recorded stand: the force and each accelerometer, with
/// the noise level the session measured on it (its median over the steps).
fn sim_channels(stand: &Stand, analysis: &SessionAnalysis) -> Vec<SimChannel> {
    let median_noise = |name: &str| -> f64 {
        let mut v: Vec<f64> = analysis
            .steps
            .iter()
            .flat_map(|s| {
                s.channels
                    .iter()
                    .filter(|c| c.name == name)
                    .map(|c| c.noise_rms)
            })
            .filter(|x| x.is_finite())
            .collect();
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let mut sensor = 0;
    stand
        .channels
        .iter()
        .map(|c| {
            let source = match c.kind {
                ChannelKind::Force => Source::Force,
                ChannelKind::Acceleration => {
                    sensor += 1;
                    Source::Sensor(sensor - 1)
                }
            };
            SimChannel {
                device_channel: c.device_channel,
                source,
                sensitivity: c.sensitivity,
                noise_rms: median_noise(&c.name),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_response_is_exact_at_steps_and_interpolated_between() {
        let p = RecordedPlant {
            freqs_hz: vec![10.0, 100.0],
            frf: vec![vec![C64::new(1.0, 0.0)], vec![C64::new(3.0, -2.0)]],
        };
        let r = p
            .response(&[10.0, 100.0, 31.622776601683793, 5.0, 500.0])
            .unwrap();
        assert_eq!(r[0][0], C64::new(1.0, 0.0));
        assert_eq!(r[1][0], C64::new(3.0, -2.0));
        assert!(
            (r[2][0] - C64::new(2.0, -1.0)).norm() < 1e-12,
            "{}",
            r[2][0]
        );
        assert_eq!(r[3][0], C64::new(1.0, 0.0));
        assert_eq!(r[4][0], C64::new(3.0, -2.0));
    }
}
