//! Selection of identification points and assembly of `rfe::Measurement`.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use process::selection::{select_points, to_measurement, CharacteristicSpec, SelectionConfig};
use process::C64;
use rfe::Quantity;

fn characteristic() -> (Vec<f64>, Vec<C64>, Vec<f64>) {
    // Two resonances (60 Hz and 300 Hz) of a receptance-like FRF on a 0.25 Hz grid to 1 kHz.
    let freqs: Vec<f64> = (0..=4000).map(|k| k as f64 * 0.25).collect();
    let mode = |f: f64, fr: f64, z: f64, a: f64| a / C64::new(fr * fr - f * f, 2.0 * z * fr * f);
    let h: Vec<C64> = freqs
        .iter()
        .map(|&f| mode(f, 60.0, 0.03, 1.0) + mode(f, 300.0, 0.02, 3.0))
        .collect();
    // Coherence drops in 100-130 Hz (say, a noisy band).
    let coh: Vec<f64> = freqs
        .iter()
        .map(|&f| {
            if (100.0..130.0).contains(&f) {
                0.5
            } else {
                0.97
            }
        })
        .collect();
    (freqs, h, coh)
}

#[test]
fn selects_38_points_log_spread_denser_at_resonances_skipping_incoherent_lines() {
    let (freqs, h, coh) = characteristic();
    let mag: Vec<f64> = h.iter().map(|v| v.norm()).collect();
    let cfg = SelectionConfig {
        band_hz: (10.0, 1000.0),
        ..SelectionConfig::default()
    };
    let pts = select_points("table u1", &freqs, &mag, Some(&coh), &cfg).unwrap();
    assert_eq!(pts.len(), 38);
    assert!(pts.windows(2).all(|w| w[0] < w[1]));
    for &k in &pts {
        assert!(coh[k] >= 0.8 && freqs[k] >= 10.0 && freqs[k] <= 1000.0);
    }
    // Density near resonances exceeds the plain log spread (38 points over 2 decades: about
    // 19 per decade, ~1.6 in ±10 % of a frequency).
    let near = |fr: f64| {
        pts.iter()
            .filter(|&&k| (freqs[k] / fr - 1.0).abs() <= 0.1)
            .count()
    };
    assert!(
        near(60.0) >= 4 && near(300.0) >= 4,
        "near 60 Hz: {}, near 300 Hz: {}",
        near(60.0),
        near(300.0)
    );
    let plain = select_points(
        "x",
        &freqs,
        &mag,
        Some(&coh),
        &SelectionConfig {
            resonance_weight: 0.0,
            ..cfg.clone()
        },
    )
    .unwrap();
    let ratios: Vec<f64> = plain
        .windows(2)
        .map(|w| freqs[w[1]] / freqs[w[0]])
        .collect();
    let mean = ratios.iter().sum::<f64>() / ratios.len() as f64;
    // Log spread: successive ratios roughly constant (except across the skipped band).
    let off = ratios
        .iter()
        .filter(|r| (**r / mean - 1.0).abs() > 0.15)
        .count();
    assert!(off <= 3, "ratios {ratios:?}");
    // Not enough coherent lines: clear error.
    let e = select_points("table u1", &freqs[..50], &mag[..50], Some(&coh[..50]), &cfg)
        .unwrap_err()
        .to_string();
    assert!(e.contains("table u1") && e.contains("38"), "{e}");
}

#[test]
fn measurement_is_scaled_by_the_nominal_force() {
    let (freqs, h, coh) = characteristic();
    let var: Vec<f64> = h.iter().map(|v| 1e-4 * v.norm_sqr()).collect();
    let spec = CharacteristicSpec {
        body: "table".into(),
        dof: 2,
        quantity: Quantity::Displacement,
        nominal_force: 4000.0,
    };
    let pts = [40, 240, 1200];
    let m = to_measurement(&spec, &freqs, &h, Some(&coh), Some(&var), Some(10), &pts).unwrap();
    assert_eq!(m.freqs_hz, vec![10.0, 60.0, 300.0]);
    for (i, &k) in pts.iter().enumerate() {
        assert!((m.amplitude[i] - 4000.0 * h[k].norm()).abs() < 1e-12 * m.amplitude[i]);
        assert!((m.phase_rad.as_ref().unwrap()[i] - h[k].arg()).abs() < 1e-12);
        assert!(
            (m.variance.as_ref().unwrap()[i] - 1.6e7 * var[k]).abs()
                < 1e-9 * m.variance.as_ref().unwrap()[i]
        );
    }
    assert_eq!(m.averages, Some(10));
    // The result is what identify reads.
    let json = serde_json::to_string(&rfe::MeasuredData {
        source: "test".into(),
        characteristics: vec![m],
    })
    .unwrap();
    assert!(json.contains("\"displacement\""));
    assert!(to_measurement(&spec, &freqs, &h, None, None, None, &[240, 40]).is_err());
    assert!(to_measurement(
        &CharacteristicSpec {
            nominal_force: 0.0,
            ..spec
        },
        &freqs,
        &h,
        None,
        None,
        None,
        &pts
    )
    .is_err());
}
