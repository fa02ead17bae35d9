//! The one computation of a stepped-sine step's amplitude and phase per channel, shared by the live
//! sweep and by [`crate::analysis`] (replay from the session file), so both give bit-identical
//! numbers: the measurement window's samples (volts / sensitivity, in SI) go through
//! [`process::sine::SineFitter`] at the known frequency. Buffers are kept between steps.

use process::sine::{SineConfig, SineFitter, Step};
use process::ProcessError;

use crate::record::ChannelResult;

/// Collects one step's measurement window and fits it.
#[derive(Debug)]
pub struct StepEstimator {
    fitter: SineFitter,
    config: SineConfig,
    force_channel: usize,
    sensitivity: Vec<f64>,
    force: Vec<f64>,
    /// Every channel except the force, in stream order.
    responses: Vec<Vec<f64>>,
}

impl StepEstimator {
    /// An estimator for a stream at `sample_rate_hz` (Hz) whose channels have these sensitivities
    /// (V/N or V/(m/s²), stream order), the force being channel `force_channel`.
    pub fn new(sample_rate_hz: f64, sensitivity: &[f64], force_channel: usize) -> StepEstimator {
        StepEstimator {
            fitter: SineFitter::new(),
            config: SineConfig {
                sample_rate_hz,
                settle_s: 0.0,
                harmonics: 0,
            },
            force_channel,
            sensitivity: sensitivity.to_vec(),
            force: Vec::new(),
            responses: vec![Vec::new(); sensitivity.len().saturating_sub(1)],
        }
    }

    /// Empties the window (keeps the buffers).
    pub fn clear(&mut self) {
        self.force.clear();
        self.responses.iter_mut().for_each(Vec::clear);
    }

    /// Samples per channel in the window.
    pub fn len(&self) -> usize {
        self.force.len()
    }

    /// True if the window is empty.
    pub fn is_empty(&self) -> bool {
        self.force.is_empty()
    }

    /// Adds one sample of every channel (volts, stream order; extra values are ignored).
    pub fn push_row(&mut self, volts: &[f32]) {
        let mut r = 0;
        for (c, (&v, s)) in volts.iter().zip(&self.sensitivity).enumerate() {
            let x = f64::from(v) / s;
            if c == self.force_channel {
                self.force.push(x);
            } else if let Some(buf) = self.responses.get_mut(r) {
                buf.push(x);
                r += 1;
            }
        }
    }

    /// The largest force-channel sample of the window in volts (absolute value): what the DAQ
    /// input saw, to compare with its range.
    pub fn force_peak_volts(&self) -> f64 {
        let s = self
            .sensitivity
            .get(self.force_channel)
            .copied()
            .unwrap_or(1.0);
        self.force.iter().fold(0.0f64, |m, x| m.max((x * s).abs()))
    }

    /// The force amplitude (N) of the sine behind a window clipped at ±`clip_n` (N), from the
    /// share of its force samples at or beyond the rails: a sine of amplitude A spends
    /// `(2/π)·acos(C/A)` of each cycle beyond ±C, so `A = C / cos(π/2 · share)`. At most ten
    /// times `clip_n` (a window almost all at the rails says only that the force is far beyond).
    pub fn clipped_force_amplitude(&self, clip_n: f64) -> f64 {
        let beyond = self.force.iter().filter(|x| x.abs() >= clip_n).count();
        let share = beyond as f64 / self.force.len().max(1) as f64;
        clip_n / (std::f64::consts::FRAC_PI_2 * share).cos().max(0.1)
    }

    /// True if the window's force held one amplitude: the force fitted at `freq_hz` (Hz) over
    /// the window's first and second halves agrees within `tolerance` (relative) plus four
    /// standard deviations of the difference the fits' noise allows. A window that straddles a
    /// drive change (data taken before it), or a response still building up, is not settled.
    pub fn force_settled(&mut self, freq_hz: f64, tolerance: f64) -> Result<bool, ProcessError> {
        let half = self.force.len() / 2;
        let mut fit = |x: &[f64]| self.fitter.fit_step(&self.config, freq_hz, x, &[]);
        let (a, b) = (
            fit(&self.force[..half])?.force,
            fit(&self.force[half..])?.force,
        );
        // An amplitude fitted from n samples of noise σ scatters by σ·√(2/n).
        let noise = (a.noise_rms + b.noise_rms) / 2.0 * (2.0 * 2.0 / half.max(1) as f64).sqrt();
        let (a, b) = (a.amplitude(), b.amplitude());
        Ok((a - b).abs() <= tolerance * a.max(b) + 4.0 * noise)
    }

    /// Fits the window at `freq_hz` (Hz). Phases refer to the window's first sample.
    pub fn estimate(&mut self, freq_hz: f64) -> Result<Step, ProcessError> {
        let responses: Vec<&[f64]> = self.responses.iter().map(Vec::as_slice).collect();
        self.fitter
            .fit_step(&self.config, freq_hz, &self.force, &responses)
    }

    /// Per channel (stream order, force included with FRF 1) what a step records.
    pub fn channel_results(&self, step: &Step, names: &[String]) -> Vec<ChannelResult> {
        let quality = |x: &process::sine::SineFit| {
            let p = 0.5 * x.amplitude().powi(2);
            let n = x.noise_rms.powi(2);
            if p + n > 0.0 {
                p / (p + n)
            } else {
                0.0
            }
        };
        let mut r = 0;
        names
            .iter()
            .enumerate()
            .map(|(c, name)| {
                if c == self.force_channel {
                    ChannelResult {
                        name: name.clone(),
                        amplitude: step.force.amplitude(),
                        phase_rad: 0.0,
                        frf_re: 1.0,
                        frf_im: 0.0,
                        fit_quality: quality(&step.force),
                        noise_rms: step.force.noise_rms,
                        frf_variance: 0.0,
                    }
                } else {
                    let j = r;
                    r += 1;
                    let (fit, h) = (&step.responses[j], step.frf[j]);
                    ChannelResult {
                        name: name.clone(),
                        amplitude: fit.amplitude(),
                        phase_rad: h.arg(),
                        frf_re: h.re,
                        frf_im: h.im,
                        fit_quality: quality(fit),
                        noise_rms: fit.noise_rms,
                        frf_variance: step.variance(j).unwrap_or(f64::NAN),
                    }
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn recovers_the_frf_of_a_noisy_window_and_its_variance_is_honest() {
        let fs = 5120.0;
        let f = 37.3;
        // Force on channel 1 (2 mV/N), response on 0 and 2 (10 mV/(m/s²)).
        let sens = [0.01, 0.002, 0.01];
        let h = [
            Complex::from_polar(2.5e-3, 0.7),
            Complex::from_polar(1.0e-3, -2.0),
        ];
        let force = Complex::from_polar(1000.0, 0.3);
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let noise = Normal::new(0.0, 0.05).unwrap();
        let mut est = StepEstimator::new(fs, &sens, 1);
        let n = 3001;
        let mut errors = Vec::new();
        for trial in 0..40 {
            est.clear();
            for i in 0..n {
                let e = Complex::from_polar(
                    1.0,
                    2.0 * std::f64::consts::PI * f * (i + 17 * trial) as f64 / fs,
                );
                let fv = (force * e).re;
                let a0 = (force * h[0] * e).re + noise.sample(&mut rng);
                let a1 = (force * h[1] * e).re;
                est.push_row(&[
                    (a0 * sens[0]) as f32,
                    (fv * sens[1]) as f32,
                    (a1 * sens[2]) as f32,
                ]);
            }
            assert_eq!(est.len(), n);
            let step = est.estimate(f).unwrap();
            let names: Vec<String> = ["a0", "force", "a1"].map(String::from).to_vec();
            let r = est.channel_results(&step, &names);
            assert_eq!((r[1].frf_re, r[1].frf_im), (1.0, 0.0));
            assert!((r[1].amplitude - 1000.0).abs() < 1e-3, "{}", r[1].amplitude);
            // The noiseless channel is exact up to f32 rounding.
            let g1 = Complex::new(r[2].frf_re, r[2].frf_im);
            assert!((g1 - h[1]).norm() < 1e-6 * h[1].norm(), "{g1}");
            errors.push((
                (Complex::new(r[0].frf_re, r[0].frf_im) - h[0]).norm_sqr(),
                r[0].frf_variance,
            ));
            assert!((r[0].noise_rms - 0.05).abs() < 0.005, "{}", r[0].noise_rms);
        }
        // The stated variance E|Ĥ−H|² matches the observed mean square error within sampling error
        // (40 trials: ±~35 % at 2σ).
        let mse = errors.iter().map(|e| e.0).sum::<f64>() / errors.len() as f64;
        let stated = errors.iter().map(|e| e.1).sum::<f64>() / errors.len() as f64;
        assert!(
            (mse / stated - 1.0).abs() < 0.4,
            "mse {mse:e} vs stated {stated:e}"
        );
    }

    /// A window of `n` force samples (1 V/N) at `f` Hz, 5120 Hz, amplitude `amp(i)` N, noise 3 N.
    fn force_window(f: f64, n: usize, amp: impl Fn(usize) -> f64) -> StepEstimator {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let noise = Normal::new(0.0, 3.0).unwrap();
        let mut est = StepEstimator::new(5120.0, &[1.0], 0);
        for i in 0..n {
            let x = amp(i) * (2.0 * std::f64::consts::PI * f * i as f64 / 5120.0).sin();
            est.push_row(&[(x + noise.sample(&mut rng)) as f32]);
        }
        est
    }

    #[test]
    fn a_clipped_sine_tells_its_amplitude_by_its_share_of_samples_at_the_rails() {
        for amplitude in [4500.0, 5000.0, 8000.0] {
            let clip = 4440.0;
            let mut est = StepEstimator::new(5120.0, &[1.0], 0);
            let n = 5120;
            for i in 0..n {
                let x: f64 =
                    amplitude * (2.0 * std::f64::consts::PI * 37.0 * i as f64 / 5120.0).sin();
                est.push_row(&[x.clamp(-clip, clip) as f32]);
            }
            let a = est.clipped_force_amplitude(clip);
            assert!(
                (a - amplitude).abs() < 0.01 * amplitude,
                "{a} vs {amplitude}"
            );
        }
        // Nearly all samples at the rails: only "far beyond", at most ten times the range.
        let mut est = StepEstimator::new(5120.0, &[1.0], 0);
        (0..100).for_each(|i| est.push_row(&[if i % 2 == 0 { 1.0 } else { -1.0 }]));
        assert_eq!(est.clipped_force_amplitude(1.0), 10.0);
    }

    #[test]
    fn a_window_straddling_a_drive_change_is_not_settled() {
        let n = 2560;
        let mut steady = force_window(40.0, n, |_| 4000.0);
        assert!(steady.force_settled(40.0, 0.03).unwrap());
        // The first 30 % taken before the drive rose from 3400 N to 4000 N.
        let mut straddling =
            force_window(40.0, n, |i| if i < 3 * n / 10 { 3400.0 } else { 4000.0 });
        assert!(!straddling.force_settled(40.0, 0.03).unwrap());
        // A change within the tolerance is settled enough.
        let mut small = force_window(40.0, n, |i| if i < n / 2 { 3960.0 } else { 4000.0 });
        assert!(small.force_settled(40.0, 0.03).unwrap());
        // Noise alone never unsettles a weak force: 30 N against 3 N of noise.
        let mut weak = force_window(40.0, n, |_| 30.0);
        assert!(weak.force_settled(40.0, 0.0).unwrap());
    }

    #[test]
    fn too_short_window_is_an_error_not_a_number() {
        let mut est = StepEstimator::new(1000.0, &[1.0, 1.0], 0);
        est.push_row(&[1.0, 1.0]);
        est.push_row(&[1.0, 1.0]);
        assert!(est.estimate(1.0).is_err());
    }
}
