//! The one computation of a broadband measurement's FRFs, shared by the live sweep and by
//! [`crate::analysis`] (replay from the session file), so both give bit-identical numbers.
//!
//! The drive repeats with a period of `n` samples (random noise is generated per period by the
//! simulated and by most real controllers; chirps and bursts are periodic by construction). Whole
//! periods, counted from the stream's first sample, after `settle` periods, without a stream fault
//! or a gap, are the segments of a Welch estimate ([`process::spectra::Welch`]: rectangular window,
//! no overlap, no detrending — leakage-free for a periodic drive) and the FRFs are H1
//! ([`process::estimate()`]) of every channel against the force, per newton (samples are volts /
//! sensitivity, in SI). Buffers are allocated once.

use process::estimate::{estimate, Estimator};
use process::spectra::{Detrend, Welch, WelchConfig};
use process::window::Window;
use process::ProcessError;

/// Averages whole periods of a stream into H1 estimates.
#[derive(Debug)]
pub struct PeriodAverager {
    n: usize,
    settle: u64,
    target: u32,
    force_channel: usize,
    sensitivity: Vec<f64>,
    welch: Welch,
    /// The period being collected: force, then the responses (stream order without the force).
    force: Vec<f64>,
    responses: Vec<Vec<f64>>,
    period: u64,
    filled: usize,
    fault: bool,
    averages: u32,
}

/// A broadband estimate in the band, per channel in stream order (the force's own H1 is 1).
#[derive(Debug, Clone, PartialEq)]
pub struct PeriodicFrf {
    /// Frequency lines in the band (Hz).
    pub freqs_hz: Vec<f64>,
    /// `h1[channel][line]` (unit per N).
    pub h1: Vec<Vec<num_complex::Complex<f64>>>,
    /// `coherence[channel][line]` with the force (0-1).
    pub coherence: Vec<Vec<f64>>,
    /// `variance[channel][line]`: E|Ĥ−H|² from the coherence and the number of averages.
    pub variance: Vec<Vec<f64>>,
    /// Periods averaged.
    pub averages: u32,
}

impl PeriodAverager {
    /// An averager for a stream at `sample_rate_hz` whose channels (`names`, stream order) have
    /// these sensitivities (V/N or V/(m/s²)), the force being `force_channel`; periods of
    /// `period_samples`, the first `settle_periods` skipped, at most `target` averaged.
    pub fn new(
        sample_rate_hz: f64,
        period_samples: usize,
        settle_periods: u32,
        target: u32,
        names: &[&str],
        sensitivity: &[f64],
        force_channel: usize,
    ) -> Result<PeriodAverager, ProcessError> {
        let config = WelchConfig {
            sample_rate_hz,
            segment_len: period_samples,
            overlap: 0,
            reference_window: Window::Rectangular,
            response_window: Window::Rectangular,
            detrend: Detrend::None,
            full_scale: Vec::new(),
        };
        let responses: Vec<&str> = (0..names.len())
            .filter(|c| *c != force_channel)
            .map(|c| names[c])
            .collect();
        let welch = Welch::new(config, &[names[force_channel]], &responses)?;
        Ok(PeriodAverager {
            n: period_samples,
            settle: u64::from(settle_periods),
            target,
            force_channel,
            sensitivity: sensitivity.to_vec(),
            welch,
            force: vec![0.0; period_samples],
            responses: vec![vec![0.0; period_samples]; responses.len()],
            period: 0,
            filled: 0,
            fault: false,
            averages: 0,
        })
    }

    /// A stream fault happened: the period being collected is not averaged.
    pub fn fault(&mut self) {
        self.fault = true;
    }

    /// Periods averaged so far.
    pub fn averages(&self) -> u32 {
        self.averages
    }

    /// True once `target` periods are averaged; later samples are ignored.
    pub fn done(&self) -> bool {
        self.averages >= self.target
    }

    /// Feeds a block starting at sample `first_sample`, `volts` interleaved sample-major;
    /// returns how many periods it completed.
    pub fn push_block(&mut self, first_sample: u64, volts: &[f32]) -> Result<u32, ProcessError> {
        let nch = self.sensitivity.len();
        let n = self.n as u64;
        let before = self.averages;
        for (i, row) in volts.chunks_exact(nch).enumerate() {
            if self.done() {
                break;
            }
            let s = first_sample + i as u64;
            let p = s / n;
            if p != self.period {
                self.period = p;
                self.filled = 0;
                self.fault = false;
            }
            let k = (s % n) as usize;
            if p < self.settle || k != self.filled {
                continue; // settling, or a gap: this period is incomplete
            }
            let mut r = 0;
            for (c, v) in row.iter().enumerate() {
                let x = f64::from(*v) / self.sensitivity[c];
                if c == self.force_channel {
                    self.force[k] = x;
                } else {
                    self.responses[r][k] = x;
                    r += 1;
                }
            }
            self.filled += 1;
            if self.filled == self.n && !self.fault {
                let responses: Vec<&[f64]> = self.responses.iter().map(Vec::as_slice).collect();
                self.welch.push(&[&self.force], &responses)?;
                self.averages += 1;
            }
        }
        Ok(self.averages - before)
    }

    /// H1 and coherence of every channel over the lines within `[lo_hz, hi_hz]` (DC and Nyquist
    /// excluded).
    pub fn estimate(&self, lo_hz: f64, hi_hz: f64) -> Result<PeriodicFrf, ProcessError> {
        let frf = estimate(&self.welch.spectra()?, Estimator::H1)?;
        let lines: Vec<usize> = (1..self.n / 2)
            .filter(|&k| (lo_hz..=hi_hz).contains(&frf.freqs_hz[k]))
            .collect();
        let nch = self.sensitivity.len();
        let mut out = PeriodicFrf {
            freqs_hz: lines.iter().map(|&k| frf.freqs_hz[k]).collect(),
            h1: Vec::with_capacity(nch),
            coherence: Vec::with_capacity(nch),
            variance: Vec::with_capacity(nch),
            averages: self.averages,
        };
        for c in 0..nch {
            if c == self.force_channel {
                out.h1
                    .push(vec![num_complex::Complex::new(1.0, 0.0); lines.len()]);
                out.coherence.push(vec![1.0; lines.len()]);
                out.variance.push(vec![0.0; lines.len()]);
                continue;
            }
            let j = if c > self.force_channel { c - 1 } else { c };
            out.h1.push(lines.iter().map(|&k| frf.h(k, j, 0)).collect());
            out.coherence
                .push(lines.iter().map(|&k| frf.coherence(k, j, 0)).collect());
            out.variance
                .push(lines.iter().map(|&k| frf.variance(k, j, 0)).collect());
        }
        Ok(out)
    }

    /// The mean coherence of the responses over the band so far (progress display).
    pub fn mean_coherence(&self, lo_hz: f64, hi_hz: f64) -> f64 {
        let Ok(e) = self.estimate(lo_hz, hi_hz) else {
            return 0.0;
        };
        let all: Vec<f64> = (0..e.coherence.len())
            .filter(|c| *c != self.force_channel)
            .flat_map(|c| e.coherence[c].iter().copied())
            .collect();
        if all.is_empty() {
            0.0
        } else {
            all.iter().sum::<f64>() / all.len() as f64
        }
    }
}
