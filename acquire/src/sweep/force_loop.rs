//! The stepped sine's force loop: the drive for the target force, predicted from the measured
//! path gain (measured force per commanded force) and kept within what the force channel can
//! read, and what a clipped reading of the force channel lets the loop do.

use crate::stand::{Stand, CLIP_FRACTION};

/// The largest share of the force channel's full scale the loop aims at: room for the noise and
/// for the gain changing from one reading (or line) to the next.
pub const FORCE_RANGE_USE: f64 = 0.97;

/// The force loop of a stepped sine, carried from line to line.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceLoop {
    /// Force to hold (N, peak).
    target_n: f64,
    /// Accepted relative deviation from the target.
    tolerance: f64,
    /// The exciter's limit on the drive (N; infinite for a generator stand, whose exciter
    /// refuses an over-voltage itself).
    max_drive_n: f64,
    /// The force the force channel reads before it clips (N, peak).
    full_scale_n: f64,
    /// The exciter's force limit (N): a force beyond it stops the sweep.
    force_limit_n: f64,
    /// Path gain of the latest reading and of the one before (force per commanded force), once
    /// measured.
    gain: Option<f64>,
    previous_gain: Option<f64>,
}

impl ForceLoop {
    /// The loop holding `target_n` (N, peak) within `tolerance` on `stand`, whose exciter takes
    /// drives up to `max_drive_n` (N).
    pub fn new(stand: &Stand, target_n: f64, tolerance: f64, max_drive_n: f64) -> ForceLoop {
        ForceLoop {
            target_n,
            tolerance,
            max_drive_n,
            full_scale_n: force_full_scale_n(stand),
            force_limit_n: stand.shaker.max_force_n,
            gain: None,
            previous_gain: None,
        }
    }

    /// The accepted relative deviation from the target.
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// The force the force channel reads before it clips (N, peak).
    pub fn full_scale_n(&self) -> f64 {
        self.full_scale_n
    }

    /// True when the target, with its tolerance, lies within [`FORCE_RANGE_USE`] of the force
    /// channel's full scale: the loop then keeps its drive below the range and answers a clipped
    /// reading by driving less. A target beyond it cannot be measured unclipped.
    pub fn target_within_range(&self) -> bool {
        self.target_n * (1.0 + self.tolerance) <= FORCE_RANGE_USE * self.full_scale_n
    }

    /// The drive (N) for the target force: the target over the latest gain (1 until measured),
    /// at most the exciter's limit and — target within range — at most what gives
    /// [`FORCE_RANGE_USE`] of the full scale with the larger of the last two gains. A reading
    /// that came too early (data taken before the last drive change) understates the gain of a
    /// raised drive; the larger gain keeps the next force within the range even then.
    pub fn drive_n(&self) -> f64 {
        let gain = self.gain.unwrap_or(1.0);
        let mut drive = self.target_n / gain;
        if self.target_within_range() {
            let largest = gain.max(self.previous_gain.unwrap_or(gain));
            drive = drive.min(FORCE_RANGE_USE * self.full_scale_n / largest);
        }
        drive.min(self.max_drive_n)
    }

    /// Learns the path gain from a reading of `force_n` (N) with `drive_n` (N) commanded; a
    /// reading of no force teaches nothing.
    pub fn learn(&mut self, force_n: f64, drive_n: f64) {
        if force_n > 0.0 && drive_n > 0.0 {
            self.previous_gain = self.gain;
            self.gain = Some(force_n / drive_n);
        }
    }

    /// True when a reading clipped at the range, whose force was about `amplitude_n` (N, from
    /// the share of clipped samples), may be answered by driving less: the target lies within
    /// the range and that force stayed within the exciter's force limit. Otherwise the sweep
    /// stops.
    pub fn may_drive_less(&self, amplitude_n: f64) -> bool {
        self.target_within_range() && amplitude_n <= self.force_limit_n
    }
}

/// The force the force channel reads before it clips (N, peak): [`CLIP_FRACTION`] of the DAQ's
/// input range over the load cell's sensitivity.
pub fn force_full_scale_n(stand: &Stand) -> f64 {
    let sensitivity = stand
        .channels
        .get(stand.force_channel())
        .map(|c| c.sensitivity)
        .unwrap_or(f64::NAN);
    CLIP_FRACTION * stand.daq.input_range_v / sensitivity
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The FWD-32J stand's loop: 4 kN within 3 %, a 6 kN exciter, 2.25 mV/N on ±10 V.
    fn fwd32j() -> ForceLoop {
        ForceLoop {
            target_n: 4000.0,
            tolerance: 0.03,
            max_drive_n: 6000.0,
            full_scale_n: CLIP_FRACTION * 10.0 / 2.25e-3,
            force_limit_n: 6000.0,
            gain: None,
            previous_gain: None,
        }
    }

    #[test]
    fn the_drive_follows_the_gain_and_a_stale_reading_cannot_push_it_past_the_range() {
        let mut l = fwd32j();
        assert!(l.target_within_range());
        assert_eq!(l.drive_n(), 4000.0, "a gain of 1 until measured");
        // The shaker delivers 0.85 of its command.
        l.learn(3400.0, 4000.0);
        let d = l.drive_n();
        assert!((d - 4000.0 / 0.85).abs() < 1e-9, "{d}");
        // The next window still holds the old drive's force (what the loaded vcan VM read): the
        // gain reads 0.72 and target / gain would be 5538 N, 4707 N of force, beyond the
        // 4440 N full scale. The larger of the last two gains keeps it at 97 % of full scale.
        l.learn(3400.0, d);
        let capped = l.drive_n();
        assert!(
            (capped - 0.97 * l.full_scale_n() / 0.85).abs() < 1e-9,
            "{capped}"
        );
        assert!(
            0.85 * capped < l.full_scale_n() && 0.85 * 4000.0 / (3400.0 / d) > l.full_scale_n()
        );
    }

    #[test]
    fn a_target_beyond_the_range_is_not_capped_and_a_clipped_reading_then_stops() {
        // A load cell twice as sensitive: 2.2 kN full scale, below the 4 kN target.
        let mut l = ForceLoop {
            full_scale_n: CLIP_FRACTION * 10.0 / 4.5e-3,
            ..fwd32j()
        };
        assert!(!l.target_within_range());
        l.learn(3400.0, 4000.0);
        assert!((l.drive_n() - 4000.0 / 0.85).abs() < 1e-9);
        assert!(!l.may_drive_less(2300.0));
    }

    #[test]
    fn a_clipped_reading_drives_less_unless_its_force_was_beyond_the_limit() {
        let l = fwd32j();
        assert!(l.may_drive_less(4600.0));
        assert!(l.may_drive_less(6000.0));
        assert!(!l.may_drive_less(6001.0), "over-force stops");
        // Just within range with its tolerance: 4180 × 1.03 = 4305 ≤ 0.97 × 4440 = 4307.
        let edge = ForceLoop {
            target_n: 4180.0,
            ..fwd32j()
        };
        assert!(edge.target_within_range());
        let beyond = ForceLoop {
            target_n: 4200.0,
            ..fwd32j()
        };
        assert!(!beyond.target_within_range());
    }

    #[test]
    fn a_reading_of_no_force_teaches_nothing_and_the_exciter_limit_holds() {
        let mut l = fwd32j();
        l.learn(0.0, 4000.0);
        assert_eq!((l.gain, l.previous_gain), (None, None));
        // A weak path (0.5) would need 8 kN: the exciter's 6 kN is the most.
        l.learn(2000.0, 4000.0);
        l.learn(2000.0, 4000.0);
        assert_eq!(l.drive_n(), 6000.0);
    }
}
