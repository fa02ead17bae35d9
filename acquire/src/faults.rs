//! The faults a simulated stand injects (the stand file's `[faults]`): read by [`crate::stand`],
//! acted on by the simulated devices ([`crate::sim`], [`crate::can::sim`]). Plain data at the
//! bottom of the crate, so the devices' simulators need not import the stand file's parser.

use std::time::Duration;

use serde::Serialize;

/// Faults injected by the simulated stand. Probabilities per frame (0-1).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Faults {
    /// Seed of the fault generator.
    pub seed: u64,
    /// DAQ frames dropped.
    pub drop: f64,
    /// DAQ frames with a corrupted byte.
    pub corrupt: f64,
    /// DAQ frames sent twice.
    pub duplicate: f64,
    /// DAQ frames delayed by `delay_time`.
    pub delay: f64,
    /// Delay applied to delayed frames.
    pub delay_time: Duration,
    /// The DAQ goes silent (no data, no answers) after this many blocks.
    pub daq_silent_after_blocks: Option<u64>,
    /// The shaker controller stops answering after this many command lines.
    pub shaker_silent_after_commands: Option<u64>,
    /// Both cables are pulled (ptys closed) after this many DAQ blocks.
    pub cable_pull_after_blocks: Option<u64>,
    /// The simulated power amplifier trips (no force, generator output still on) once the
    /// generator has received this many frequency settings (sweep lines).
    pub amplifier_trip_after_lines: Option<u64>,
    /// The simulated amplifier's gain surges by `amplifier_surge_factor` after this many lines.
    pub amplifier_surge_after_lines: Option<u64>,
    /// Gain factor of a surge (default 2).
    pub amplifier_surge_factor: f64,
}

impl Default for Faults {
    fn default() -> Self {
        Faults {
            seed: 0,
            drop: 0.0,
            corrupt: 0.0,
            duplicate: 0.0,
            delay: 0.0,
            delay_time: Duration::ZERO,
            daq_silent_after_blocks: None,
            shaker_silent_after_commands: None,
            cable_pull_after_blocks: None,
            amplifier_trip_after_lines: None,
            amplifier_surge_after_lines: None,
            amplifier_surge_factor: 2.0,
        }
    }
}
