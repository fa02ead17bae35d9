//! Synthetic measured data from a model: its output characteristics at chosen lines with
//! multiplicative Gaussian noise, and the variances that noise has. For tests, benchmarks and
//! experiment design; one generator for all of them (the FWD-32J recovery and calibration tests,
//! the identification benchmark and the CLI end-to-end test).
//!
//! ```
//! use identify::synthetic;
//! use rfe::textbook;
//! let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
//! let lines = synthetic::log_lines(10.0, 60.0, 40);
//! // A fixed "noise" sequence keeps the example deterministic; tests pass a seeded N(0, 1) sampler.
//! let mut k = 0.0f64;
//! let data = synthetic::amplitude_data(&truth, &lines, 0.01, || { k += 0.1; k.sin() }).unwrap();
//! assert_eq!(data.characteristics.len(), truth.outputs.len());
//! assert_eq!(data.characteristics[0].freqs_hz.len(), 40);
//! ```

use rfe::frf::{self, Method};
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::model::Model;

/// `n ≥ 2` log-spaced lines from `from_hz` to `to_hz` (both included, > 0).
pub fn log_lines(from_hz: f64, to_hz: f64, n: usize) -> Vec<f64> {
    let last = n.saturating_sub(1).max(1) as f64;
    (0..n)
        .map(|i| from_hz * (to_hz / from_hz).powf(i as f64 / last))
        .collect()
}

/// The FWD-32J synthetic measurement of the paper's worked problem: 38 log-spaced lines over
/// 20-400 Hz (the band of Table 1's characteristics), per characteristic.
pub fn fwd32j_lines() -> Vec<f64> {
    log_lines(20.0, 400.0, 38)
}

/// Amplitude-only data (no phase, as the paper's A-F characteristics) of every output
/// characteristic of `truth` at `freqs_hz`: `|z| = |q| (1 + ε n)` with `n` drawn from
/// `standard_normal` (one draw per point, characteristic by characteristic, line by line), and the
/// stated complex variance `E|z − z_true|² = 2 (ε |q|)²`, i.e. σ = ε |q| for the amplitude (the
/// noise model `ident identify --noise variance` reads). `ε = relative_sigma`, dimensionless
/// (0.01 = 1 %). Values in SI (the model's response to its declared excitation).
///
/// `Err` when the model cannot be solved at one of the lines.
pub fn amplitude_data(
    truth: &Model,
    freqs_hz: &[f64],
    relative_sigma: f64,
    mut standard_normal: impl FnMut() -> f64,
) -> Result<MeasuredData, frf::SolveError> {
    let r = frf::response(truth, freqs_hz, &[], Method::Auto)?;
    Ok(MeasuredData {
        source: format!(
            "synthetic: {} with relative noise σ = {relative_sigma}·|q|",
            truth.name
        ),
        characteristics: truth
            .outputs
            .iter()
            .enumerate()
            .map(|(o, c)| {
                let q: Vec<f64> = r.output(o).iter().map(|v| v.norm()).collect();
                Measurement {
                    body: truth.bodies[c.body].name.clone(),
                    dof: c.dof,
                    at: c.at,
                    reference: (c.reference > 0)
                        .then(|| truth.reference_name(c.reference).to_string()),
                    relative: c.relative,
                    quantity: QuantityName::from(c.quantity),
                    freqs_hz: freqs_hz.to_vec(),
                    amplitude: q
                        .iter()
                        .map(|a| a * (1.0 + relative_sigma * standard_normal()))
                        .collect(),
                    phase_rad: None,
                    variance: Some(
                        q.iter()
                            .map(|a| 2.0 * (relative_sigma * a).powi(2))
                            .collect(),
                    ),
                    coherence: None,
                    averages: None,
                }
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfe::textbook;

    #[test]
    fn lines_span_the_band_logarithmically() {
        let f = fwd32j_lines();
        assert_eq!(f.len(), 38);
        assert!((f[0] - 20.0).abs() < 1e-12 && (f[37] - 400.0).abs() < 1e-9);
        let r = f[1] / f[0];
        assert!(f.windows(2).all(|w| (w[1] / w[0] - r).abs() < 1e-12));
    }

    #[test]
    fn without_noise_the_data_are_the_model_response() {
        let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
        let f = log_lines(10.0, 60.0, 7);
        let d = amplitude_data(&truth, &f, 0.02, || 0.0).unwrap();
        let r = frf::response(&truth, &f, &[], Method::Direct).unwrap();
        for (o, m) in d.characteristics.iter().enumerate() {
            for (k, a) in m.amplitude.iter().enumerate() {
                let q = r.output(o)[k].norm();
                assert!((a - q).abs() <= 1e-12 * q);
                let v = m.variance.as_ref().unwrap()[k];
                assert!((v - 2.0 * (0.02 * q).powi(2)).abs() <= 1e-12 * v);
            }
        }
        // One unit of noise moves an amplitude by ε of itself.
        let d1 = amplitude_data(&truth, &f, 0.02, || 1.0).unwrap();
        let (a0, a1) = (
            d.characteristics[1].amplitude[3],
            d1.characteristics[1].amplitude[3],
        );
        assert!((a1 / a0 - 1.02).abs() < 1e-12);
    }
}
