//! The power amplifier and shaker behind a signal generator (the stand file's `[amplifier]`), as
//! the stand file resolves it and the [`GeneratorExciter`](crate::shaker::GeneratorExciter) drives it.

use std::time::Duration;

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
