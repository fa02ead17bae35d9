//! One period of a broadband drive as the samples a signal generator plays: a periodic random
//! (random-phase multisine, flat over the band's lines, seeded), a burst of it, or a linear chirp,
//! scaled to full scale (peak 1) so the generator's amplitude is the waveform's peak.

use rand::SeedableRng;
use rand_distr::{Distribution, Uniform};
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;

use crate::record::Waveform;

/// The seed of the random phases when none is given: the waveform is the same on every run.
pub const DEFAULT_SEED: u64 = 0x1de7_5eed;

/// One period of a broadband drive at a sample rate.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveWaveform {
    /// Samples of one period, peak |x| = 1.
    pub samples: Vec<f64>,
    /// Sample rate they are played at (Sa/s).
    pub sample_rate_hz: f64,
    /// RMS of `samples` over the driven part of the period (the burst for burst random, the
    /// whole period otherwise): force RMS = peak force × this.
    pub rms: f64,
    /// Seed of the random phases (random and burst random).
    pub seed: u64,
}

/// Why a waveform cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("broadband drive: {0}")]
pub struct WaveformError(pub String);

/// The period (s) a broadband waveform repeats with: 1 s for random (as
/// [`crate::sweep::broadband_period`] averages it), `period_s` otherwise.
pub fn period_s(w: &Waveform) -> Option<f64> {
    match w {
        Waveform::Sine => None,
        Waveform::Random { .. } => Some(1.0),
        Waveform::BurstRandom { period_s, .. } | Waveform::Chirp { period_s, .. } => {
            Some(*period_s)
        }
    }
}

/// Samples of one period of `w` at `sample_rate_hz`, random phases from `seed`.
pub fn synthesize(
    w: &Waveform,
    sample_rate_hz: f64,
    seed: u64,
) -> Result<DriveWaveform, WaveformError> {
    let period =
        period_s(w).ok_or_else(|| WaveformError("a sine is not a broadband waveform".into()))?;
    let exact = period * sample_rate_hz;
    let n = exact.round() as usize;
    if !(exact.is_finite() && n >= 8 && (exact - n as f64).abs() < 1e-6) {
        return Err(WaveformError(format!(
            "a period of {period} s at {sample_rate_hz} Sa/s is not a whole number of at least 8 samples"
        )));
    }
    let (lo, hi) = match *w {
        Waveform::Random { f_lo_hz, f_hi_hz }
        | Waveform::BurstRandom {
            f_lo_hz, f_hi_hz, ..
        }
        | Waveform::Chirp {
            f_lo_hz, f_hi_hz, ..
        } => (f_lo_hz.min(f_hi_hz), f_lo_hz.max(f_hi_hz)),
        Waveform::Sine => (0.0, 0.0),
    };
    if !(lo >= 0.0 && hi < 0.5 * sample_rate_hz && hi > lo) {
        return Err(WaveformError(format!(
            "band {lo}..{hi} Hz must lie below half the sample rate ({} Hz)",
            0.5 * sample_rate_hz
        )));
    }
    let df = sample_rate_hz / n as f64;
    let (mut x, on) = match *w {
        Waveform::Chirp { .. } => {
            let t_end = n as f64 / sample_rate_hz;
            let x: Vec<f64> = (0..n)
                .map(|i| {
                    let t = i as f64 / sample_rate_hz;
                    let ph =
                        2.0 * std::f64::consts::PI * (lo * t + (hi - lo) * t * t / (2.0 * t_end));
                    ph.sin()
                })
                .collect();
            (x, n)
        }
        _ => {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let phase = Uniform::new(0.0, 2.0 * std::f64::consts::PI)
                .map_err(|e| WaveformError(e.to_string()))?;
            let mut spec = vec![Complex::new(0.0, 0.0); n];
            let mut lines = 0;
            for k in 1..n.div_ceil(2) {
                let f = k as f64 * df;
                let p = phase.sample(&mut rng);
                if (lo..=hi).contains(&f) {
                    spec[k] = Complex::from_polar(1.0, p);
                    spec[n - k] = spec[k].conj();
                    lines += 1;
                }
            }
            if lines == 0 {
                return Err(WaveformError(format!(
                    "no frequency line of the {df} Hz grid within {lo}..{hi} Hz"
                )));
            }
            FftPlanner::<f64>::new()
                .plan_fft_inverse(n)
                .process(&mut spec);
            let mut x: Vec<f64> = spec.iter().map(|c| c.re).collect();
            let on = match *w {
                Waveform::BurstRandom { duty, .. } => {
                    ((duty.clamp(0.0, 1.0) * n as f64) as usize).max(1)
                }
                _ => n,
            };
            for v in x.iter_mut().skip(on) {
                *v = 0.0;
            }
            (x, on)
        }
    };
    let peak = x.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    if peak <= 0.0 {
        return Err(WaveformError("the waveform is all zeros".into()));
    }
    for v in &mut x {
        *v /= peak;
    }
    let rms = (x.iter().take(on).map(|v| v * v).sum::<f64>() / on as f64).sqrt();
    Ok(DriveWaveform {
        samples: x,
        sample_rate_hz,
        rms,
        seed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spectrum(x: &[f64]) -> Vec<f64> {
        let mut c: Vec<Complex<f64>> = x.iter().map(|v| Complex::new(*v, 0.0)).collect();
        FftPlanner::<f64>::new()
            .plan_fft_forward(c.len())
            .process(&mut c);
        c.iter().map(|v| v.norm()).collect()
    }

    #[test]
    fn periodic_random_is_flat_in_band_empty_outside_and_seeded() {
        let w = Waveform::Random {
            f_lo_hz: 20.0,
            f_hi_hz: 400.0,
        };
        let d = synthesize(&w, 2048.0, 7).unwrap();
        assert_eq!(d.samples.len(), 2048);
        let peak = d.samples.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((peak - 1.0).abs() < 1e-12);
        // A random-phase multisine's crest factor is 3-5.
        assert!(d.rms > 0.2 && d.rms < 0.34, "rms {}", d.rms);
        let s = spectrum(&d.samples);
        let inband: Vec<f64> = (20..=400).map(|k| s[k]).collect();
        let (mn, mx) = inband
            .iter()
            .fold((f64::MAX, 0.0_f64), |(a, b), v| (a.min(*v), b.max(*v)));
        assert!(mx / mn < 1.0 + 1e-9, "flat: {mn}..{mx}");
        assert!((1..20).chain(401..1024).all(|k| s[k] < 1e-9 * mx));
        assert_eq!(synthesize(&w, 2048.0, 7).unwrap(), d, "seeded");
        assert_ne!(synthesize(&w, 2048.0, 8).unwrap().samples, d.samples);
    }

    #[test]
    fn chirp_and_burst_and_bad_plans() {
        let c = synthesize(
            &Waveform::Chirp {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
                period_s: 0.5,
            },
            2048.0,
            0,
        )
        .unwrap();
        assert_eq!(c.samples.len(), 1024);
        assert!((c.rms - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.01);
        let b = synthesize(
            &Waveform::BurstRandom {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
                duty: 0.5,
                period_s: 1.0,
            },
            2048.0,
            1,
        )
        .unwrap();
        assert!(b.samples[1024..].iter().all(|v| *v == 0.0));
        assert!(synthesize(&Waveform::Sine, 2048.0, 0).is_err());
        let r = Waveform::Random {
            f_lo_hz: 20.0,
            f_hi_hz: 400.0,
        };
        assert!(synthesize(&r, 700.0, 0).unwrap_err().0.contains("half"));
        assert!(synthesize(&r, 2048.5, 0).unwrap_err().0.contains("whole"));
    }
}
