//! `/drive`: what the host sent to a signal generator and the forces its loop measured, and the
//! excitation waveforms both a shaker controller and a generator drive.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::topic::{Topic, TopicRecord};

/// `/drive`: every setting sent to a signal generator that drives the shaker through a power
/// amplifier, and every force the closed loop measured (stands with `[generator]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.Drive")]
pub struct DriveRecord {
    /// What happened.
    pub kind: DriveKind,
    /// The generator's port.
    pub port: String,
    /// Sweep step, for measurements.
    #[serde(default)]
    pub step: Option<usize>,
    /// Sine frequency then set (Hz).
    pub frequency_hz: f64,
    /// Generator amplitude then set (V peak).
    pub volts_peak: f64,
    /// Output on after this record.
    pub output_on: bool,
    /// Force amplitude measured on the DAQ's force channel (N peak), for measurements.
    #[serde(default)]
    pub force_n: Option<f64>,
    /// Force amplitude the sweep holds (N peak), for measurements.
    #[serde(default)]
    pub target_n: Option<f64>,
    /// Generator settings sent since this frequency was set (this one included).
    pub settings_this_line: u32,
    /// The broadband drive the uploaded waveform makes (kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waveform: Option<Waveform>,
    /// Rate the uploaded points are played at (Sa/s; kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_rate_hz: Option<f64>,
    /// Seed of the random phases (kind `waveform`, random and burst random).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The DAC codes uploaded, one period, in the model's code range (kind `waveform`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub codes: Option<Vec<i32>>,
    /// The DAC codes of negative and positive full scale (kind `waveform`): code `c` is
    /// `volts_peak × (2c − min − max) / (max − min)` volts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub code_range: Option<(i32, i32)>,
}

impl TopicRecord for DriveRecord {
    const TOPIC: Topic = Topic::Drive;
}

/// What a `/drive` record reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum DriveKind {
    /// A frequency sent to the signal generator.
    Frequency,
    /// An amplitude sent to the signal generator (a ramp increment or a force-loop correction).
    Amplitude,
    /// The generator's output switched on or off.
    Output,
    /// The force amplitude the DAQ measured with the drive then set (for a broadband drive:
    /// the RMS over one period, `step` = the period).
    Measurement,
    /// An arbitrary waveform uploaded and selected (broadband drive): `waveform`,
    /// `sample_rate_hz`, `seed` and the DAC `codes` sent.
    Waveform,
}

/// An excitation waveform. Frequencies in Hz, times in s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Waveform {
    /// A sine at the frequency set by `Shaker::set_frequency`.
    Sine,
    /// Continuous random noise, flat between `f_lo_hz` and `f_hi_hz`.
    Random {
        /// Lower band edge (Hz).
        f_lo_hz: f64,
        /// Upper band edge (Hz).
        f_hi_hz: f64,
    },
    /// Burst random: noise for `duty` (0-1) of each `period_s`, silence for the rest.
    BurstRandom {
        /// Lower band edge (Hz).
        f_lo_hz: f64,
        /// Upper band edge (Hz).
        f_hi_hz: f64,
        /// Fraction of the period with drive (0-1).
        duty: f64,
        /// Burst period (s).
        period_s: f64,
    },
    /// A linear chirp from `f_lo_hz` to `f_hi_hz` over `period_s`, repeated.
    Chirp {
        /// Start frequency (Hz).
        f_lo_hz: f64,
        /// End frequency (Hz).
        f_hi_hz: f64,
        /// Sweep time (s).
        period_s: f64,
    },
}
