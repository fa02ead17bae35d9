//! H1/H2/Hv on synthetic signals through a known FRF: recovery within the predicted random error,
//! and the textbook biases (H1 low with force noise, H2 unbiased then).
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::*;
use process::{estimate, spectra::Welch, Estimator, WelchConfig, Window};

const B: [f64; 3] = [0.05, 0.02, 0.0];
const A: [f64; 2] = [-1.6, 0.8];

fn spectra(x_meas: &[f64], y_meas: &[f64]) -> process::CrossSpectra {
    let mut w = Welch::new(
        WelchConfig::new(1000.0, 512, Window::Hann),
        &["force"],
        &["acc"],
    )
    .unwrap();
    w.push(&[x_meas], &[y_meas]).unwrap();
    w.finish().unwrap()
}

#[test]
fn h1_recovers_known_frf_within_predicted_error() {
    let n = 200_000;
    let x = noise(21, n, 1.0);
    let y: Vec<f64> = resonator(&x, B, A)
        .iter()
        .zip(noise(22, n, 0.2))
        .map(|(a, e)| a + e)
        .collect();
    let s = spectra(&x, &y);
    let frf = estimate(&s, Estimator::H1).unwrap();
    assert!(frf.averages > 700);
    let (mut sum, mut count, mut outliers) = (0.0, 0, 0);
    for k in 1..frf.freqs_hz.len() - 1 {
        let truth = resonator_frf(B, A, frf.freqs_hz[k] / 1000.0);
        let err2 = (frf.h(k, 0, 0) - truth).norm_sqr();
        let var = frf.variance(k, 0, 0);
        assert!(var.is_finite() && var > 0.0);
        let z = err2 / var;
        sum += z;
        count += 1;
        if z > 16.0 {
            outliers += 1;
        }
    }
    let mean = sum / count as f64;
    // E|Ĥ−H|²/predicted ≈ 1 (a little above with 50 % overlap); a wrong formula (e.g. a missing
    // factor 2 or n) lands far outside.
    assert!(
        (0.7..1.5).contains(&mean),
        "mean normalized squared error {mean}"
    );
    assert!(outliers <= 2, "{outliers} lines beyond 4 sigma");
}

#[test]
fn h2_is_unbiased_and_h1_biased_low_when_the_force_is_noisy() {
    let n = 200_000;
    let x = noise(31, n, 1.0);
    let y = resonator(&x, B, A);
    let nx = 0.5; // force noise sd: Gnn/Gxx = 0.25
    let x_meas: Vec<f64> = x.iter().zip(noise(32, n, nx)).map(|(a, e)| a + e).collect();
    let s = spectra(&x_meas, &y);
    let h1 = estimate(&s, Estimator::H1).unwrap();
    let h2 = estimate(&s, Estimator::H2).unwrap();
    let hv = estimate(&s, Estimator::Hv).unwrap();
    let (mut r1, mut r2, mut rv, mut m) = (0.0, 0.0, 0.0, 0);
    for k in 5..200 {
        let truth = resonator_frf(B, A, h1.freqs_hz[k] / 1000.0);
        r1 += (h1.h(k, 0, 0) / truth).re;
        r2 += (h2.h(k, 0, 0) / truth).re;
        rv += (hv.h(k, 0, 0) / truth).re;
        m += 1;
    }
    let (r1, r2, rv) = (r1 / m as f64, r2 / m as f64, rv / m as f64);
    // Theory: H1 = H·Gxx/(Gxx+Gnn) = H/1.25 = 0.8 H.
    assert!((r1 - 0.8).abs() < 0.01, "H1/H = {r1}");
    assert!((r2 - 1.0).abs() < 0.01, "H2/H = {r2}");
    assert!(rv > r1 && rv < 1.01, "Hv/H = {rv}");
}

#[test]
fn noise_free_estimators_agree_exactly_and_coherence_is_one() {
    let n = 50_000;
    let x = noise(41, n, 1.0);
    let y: Vec<f64> = x.iter().map(|v| -3.0 * v).collect();
    let s = spectra(&x, &y);
    for e in [Estimator::H1, Estimator::H2, Estimator::Hv] {
        let f = estimate(&s, e).unwrap();
        for k in 1..f.freqs_hz.len() {
            assert!(
                (f.h(k, 0, 0) - process::C64::new(-3.0, 0.0)).norm() < 1e-12,
                "{e:?} line {k}"
            );
            assert!((f.coherence(k, 0, 0) - 1.0).abs() < 1e-12);
        }
    }
}
