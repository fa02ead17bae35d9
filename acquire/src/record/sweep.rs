//! `/sweep/event`, `/sweep/step`, `/sweep/broadband`: the sweep's progress and its per-step and
//! broadband estimates, as measured live and as recomputed on replay.

use num_complex::Complex;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::drive::Waveform;
use super::topic::{Topic, TopicRecord};

/// `/sweep/event`: sweep progress and problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SweepEvent")]
pub struct SweepEvent {
    /// `started`, `step_started`, `force_control`, `retry`, `warning`, `step_completed`,
    /// `average`, `stopped`, `completed` or `error`.
    pub kind: String,
    /// The step concerned.
    #[serde(default)]
    pub step: Option<usize>,
    /// Its frequency (Hz).
    #[serde(default)]
    pub frequency_hz: Option<f64>,
    /// What happened.
    pub detail: String,
}

impl TopicRecord for SweepEvent {
    const TOPIC: Topic = Topic::SweepEvent;
}

/// The record of one completed step (topic `/sweep/step`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SweepStep")]
pub struct StepResult {
    /// Step index in the plan.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Drive amplitude commanded (N).
    pub drive_n: f64,
    /// Measured force amplitude (N).
    pub force_amplitude_n: f64,
    /// First sample of the measurement window.
    pub first_sample: u64,
    /// Samples in the window.
    pub samples: u64,
    /// Closed-loop iterations used.
    pub iterations: u32,
    /// Settings sent to a signal generator for this line (frequency, ramp increments, loop
    /// corrections; generator stands only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub generator_settings: Option<u32>,
    /// Per channel.
    pub channels: Vec<ChannelResult>,
}

impl StepResult {
    /// The FRF of channel `name` (per N).
    pub fn frf(&self, name: &str) -> Option<Complex<f64>> {
        self.channels
            .iter()
            .find(|c| c.name == name)
            .map(|c| Complex::new(c.frf_re, c.frf_im))
    }
}

impl TopicRecord for StepResult {
    const TOPIC: Topic = Topic::SweepStep;
}

/// One channel's result at a step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ChannelResult {
    /// Channel name.
    pub name: String,
    /// Peak amplitude (N or m/s²).
    pub amplitude: f64,
    /// Phase relative to the force channel (rad).
    pub phase_rad: f64,
    /// FRF real part (per N).
    pub frf_re: f64,
    /// FRF imaginary part (per N).
    pub frf_im: f64,
    /// Fraction of the window's power in the fitted sine, `(|X|²/2) / (|X|²/2 + noise²)` (0-1).
    pub fit_quality: f64,
    /// RMS of the fit residual (N or m/s²): the step's noise level on this channel.
    #[serde(default)]
    pub noise_rms: f64,
    /// Variance of the FRF estimate, E|Ĥ−H|² ((m/s²/N)²; 0 for the force channel).
    #[serde(default)]
    pub frf_variance: f64,
}

/// `/sweep/broadband`: a broadband measurement's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "ident.SweepBroadband")]
pub struct BroadbandRecord {
    /// The drive.
    pub waveform: Waveform,
    /// Force: RMS for random/burst, peak for chirp (N).
    pub force_n: f64,
    /// Periods averaged.
    pub averages: u32,
    /// True when the operator stopped it early.
    #[serde(default)]
    pub stopped: bool,
    /// Frequency lines (Hz).
    pub freqs_hz: Vec<f64>,
    /// Per channel, stand order.
    pub channels: Vec<BroadbandChannel>,
}

impl TopicRecord for BroadbandRecord {
    const TOPIC: Topic = Topic::SweepBroadband;
}

/// One channel of a broadband measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BroadbandChannel {
    /// Channel name.
    pub name: String,
    /// H1 real part per line (per N).
    pub h1_re: Vec<f64>,
    /// H1 imaginary part per line (per N).
    pub h1_im: Vec<f64>,
    /// Ordinary coherence with the force per line (0-1).
    pub coherence: Vec<f64>,
}
