//! Data windows for spectral estimation: the classic periodic (DFT-even) windows as defined by
//! `scipy.signal.get_window`, plus the force and exponential windows of impact testing.

use crate::error::{invalid, Result};
use std::f64::consts::PI;

/// A data window applied to each segment before its FFT.
#[derive(Debug, Clone, PartialEq)]
pub enum Window {
    /// All ones (scipy `boxcar`).
    Rectangular,
    /// Periodic Hann, `0.5 − 0.5 cos(2πn/N)`.
    Hann,
    /// Periodic Hamming, `0.54 − 0.46 cos(2πn/N)`.
    Hamming,
    /// 4-term Blackman-Harris (−92 dB side lobes).
    BlackmanHarris,
    /// Flat-top (scipy coefficients), for amplitude-accurate sine peaks.
    FlatTop,
    /// Force window of impact tests: 1 for the first `width` fraction of the segment (the impact),
    /// 0 after it, suppressing the noise of the force channel after the hit.
    Force {
        /// Fraction of the segment kept, in (0, 1].
        width: f64,
    },
    /// Exponential window of impact tests, `exp(n/(N−1) · ln(end))`: forces a lightly damped
    /// response to decay within the segment (adds known damping).
    Exponential {
        /// Value at the last sample, in (0, 1].
        end: f64,
    },
    /// Product of several windows (e.g. force × exponential on the hammer channel).
    Product(Vec<Window>),
    /// Explicit coefficients; their length must equal the segment length.
    Custom(Vec<f64>),
}

impl Window {
    /// Coefficients for a segment of `n` samples.
    pub fn coefficients(&self, n: usize) -> Result<Vec<f64>> {
        if n == 0 {
            return Err(invalid("segment length", n, "must be at least 1 sample"));
        }
        let cosine = |a: &[f64]| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let fac = -PI + 2.0 * PI * i as f64 / n as f64;
                    a.iter()
                        .enumerate()
                        .map(|(k, ak)| ak * (k as f64 * fac).cos())
                        .sum()
                })
                .collect()
        };
        Ok(match self {
            Window::Rectangular => vec![1.0; n],
            Window::Hann => cosine(&[0.5, 0.5]),
            Window::Hamming => cosine(&[0.54, 0.46]),
            Window::BlackmanHarris => cosine(&[0.35875, 0.48829, 0.14128, 0.01168]),
            Window::FlatTop => cosine(&[
                0.21557895,
                0.41663158,
                0.277263158,
                0.083578947,
                0.006947368,
            ]),
            Window::Force { width } => {
                if !(*width > 0.0 && *width <= 1.0) {
                    return Err(invalid(
                        "force window width",
                        width,
                        "a fraction of the segment in (0, 1]",
                    ));
                }
                let keep = ((width * n as f64).round() as usize).clamp(1, n);
                (0..n).map(|i| if i < keep { 1.0 } else { 0.0 }).collect()
            }
            Window::Exponential { end } => {
                if !(*end > 0.0 && *end <= 1.0) {
                    return Err(invalid(
                        "exponential window end",
                        end,
                        "the value at the last sample, in (0, 1]",
                    ));
                }
                let rate = if n > 1 {
                    end.ln() / (n - 1) as f64
                } else {
                    0.0
                };
                (0..n).map(|i| (rate * i as f64).exp()).collect()
            }
            Window::Product(parts) => {
                let mut w = vec![1.0; n];
                for p in parts {
                    for (a, b) in w.iter_mut().zip(p.coefficients(n)?) {
                        *a *= b;
                    }
                }
                w
            }
            Window::Custom(c) => {
                if c.len() != n {
                    return Err(invalid(
                        "custom window length",
                        c.len(),
                        format!("must equal the segment length {n}"),
                    ));
                }
                if c.iter().any(|v| !v.is_finite()) {
                    return Err(invalid(
                        "custom window",
                        "non-finite value",
                        "all coefficients must be finite",
                    ));
                }
                c.clone()
            }
        })
    }

    /// Exponential window as a damping time constant: `exp(−t/τ)` over a segment of `n` samples at
    /// `sample_rate_hz`. The added damping of a mode at ω is `1/(ω τ)` of critical.
    pub fn exponential_from_tau(tau_s: f64, n: usize, sample_rate_hz: f64) -> Result<Window> {
        if !(tau_s > 0.0 && sample_rate_hz > 0.0) {
            return Err(invalid(
                "exponential window tau",
                tau_s,
                "must be > 0 s (and the sample rate > 0)",
            ));
        }
        let t_end = n.saturating_sub(1) as f64 / sample_rate_hz;
        Ok(Window::Exponential {
            end: (-t_end / tau_s).exp().max(f64::MIN_POSITIVE),
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn hann_is_periodic_and_symmetric_about_centre() {
        let w = Window::Hann.coefficients(8).unwrap();
        assert!(w[0].abs() < 1e-15);
        assert!((w[4] - 1.0).abs() < 1e-15);
        for i in 1..8 {
            assert!((w[i] - w[8 - i]).abs() < 1e-15);
        }
    }

    #[test]
    fn exponential_hits_end_value_and_force_keeps_fraction() {
        let w = Window::Exponential { end: 0.01 }.coefficients(101).unwrap();
        assert!((w[100] - 0.01).abs() < 1e-14);
        let f = Window::Force { width: 0.25 }.coefficients(100).unwrap();
        assert_eq!(f.iter().filter(|v| **v == 1.0).count(), 25);
        assert!(Window::Force { width: 0.0 }.coefficients(10).is_err());
        assert!(Window::Custom(vec![1.0; 3]).coefficients(4).is_err());
    }

    #[test]
    fn flat_top_peak_is_about_one() {
        let w = Window::FlatTop.coefficients(1000).unwrap();
        assert!((w[500] - 1.0).abs() < 1e-3, "{}", w[500]);
    }
}
