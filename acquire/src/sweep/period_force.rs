//! The force of a broadband drive period by period, for the exciter's limits and force loop:
//! RMS and peak of the force channel (N) over each whole period counted from the stream's start,
//! as [`super::periodic::PeriodAverager`] counts them; a period with a gap is not reported.

/// Collects the force channel of a stream into whole periods.
#[derive(Debug, Clone)]
pub struct PeriodForceMonitor {
    n: u64,
    force_channel: usize,
    channels: usize,
    /// Volts per newton of the force channel.
    sensitivity: f64,
    period: u64,
    filled: u64,
    sum_sq: f64,
    peak: f64,
}

/// One whole period's force (N).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PeriodForceStats {
    /// Period number since the stream's start.
    pub period: u64,
    /// RMS over the period (N).
    pub rms_n: f64,
    /// Largest |force| sample (N).
    pub peak_n: f64,
}

impl PeriodForceMonitor {
    /// A monitor of periods of `period_samples`, the force being channel `force_channel` of
    /// `channels` with `sensitivity` V/N.
    pub fn new(
        period_samples: usize,
        force_channel: usize,
        channels: usize,
        sensitivity: f64,
    ) -> Self {
        PeriodForceMonitor {
            n: period_samples.max(1) as u64,
            force_channel,
            channels: channels.max(1),
            sensitivity,
            period: 0,
            filled: 0,
            sum_sq: 0.0,
            peak: 0.0,
        }
    }

    /// Feeds a block starting at sample `first_sample`, `volts` interleaved sample-major;
    /// returns the periods it completed.
    pub fn push_block(&mut self, first_sample: u64, volts: &[f32]) -> Vec<PeriodForceStats> {
        let mut done = Vec::new();
        for (i, row) in volts.chunks_exact(self.channels).enumerate() {
            let s = first_sample + i as u64;
            let p = s / self.n;
            if p != self.period {
                self.period = p;
                self.filled = 0;
                self.sum_sq = 0.0;
                self.peak = 0.0;
            }
            if s % self.n != self.filled {
                continue; // a gap: this period is incomplete
            }
            let f = f64::from(row[self.force_channel]) / self.sensitivity;
            self.sum_sq += f * f;
            self.peak = self.peak.max(f.abs());
            self.filled += 1;
            if self.filled == self.n {
                done.push(PeriodForceStats {
                    period: p,
                    rms_n: (self.sum_sq / self.n as f64).sqrt(),
                    peak_n: self.peak,
                });
            }
        }
        done
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_periods_only_with_their_rms_and_peak() {
        // Two channels; the force (channel 1, 0.5 V/N) is a square wave of ±2 N.
        let n = 8;
        let mut m = PeriodForceMonitor::new(n, 1, 2, 0.5);
        let block = |start: u64, len: u64| -> Vec<f32> {
            (start..start + len)
                .flat_map(|s| [9.0, if s % 2 == 0 { 1.0 } else { -1.0 }])
                .collect()
        };
        let got = m.push_block(0, &block(0, 12));
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].period, 0);
        assert!((got[0].rms_n - 2.0).abs() < 1e-12 && (got[0].peak_n - 2.0).abs() < 1e-12);
        // A gap in period 1: not reported; period 2 is.
        assert!(m.push_block(14, &block(14, 2)).is_empty());
        let got = m.push_block(16, &block(16, 8));
        assert_eq!(got.iter().map(|p| p.period).collect::<Vec<_>>(), [2]);
    }
}
