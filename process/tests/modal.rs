//! Modal extraction (pLSCF + stabilization + LSFD) on FRFs built from known poles and residues:
//! exact data give the poles to 1e-6, noisy data within a stated tolerance, shapes by MAC.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use process::modal::{
    self, lscf, lsfd, select_auto, select_near, stabilize, FrfKind, LscfSettings, ModalData, Pole,
    SelectionSettings, StabilityTolerances,
};
use process::C64;
use std::f64::consts::PI;

pub struct Truth {
    pub freqs_hz: Vec<f64>,
    pub zetas: Vec<f64>,
    /// shapes[m][o]
    pub shapes: Vec<Vec<f64>>,
    /// participation[m][r]
    pub parts: Vec<Vec<f64>>,
}

fn lambda(f: f64, z: f64) -> C64 {
    let w = 2.0 * PI * f;
    C64::new(-z * w, w * (1.0 - z * z).sqrt())
}

/// Receptance of a viscously (proportionally) damped system in modal form, mass-normalised real
/// shapes: A = φ_o φ_r / (2 i ω_d).
fn synth(t: &Truth, freqs: &[f64], outputs: usize, refs: usize, kind: FrfKind) -> ModalData {
    let mut h = vec![C64::new(0.0, 0.0); outputs * refs * freqs.len()];
    for o in 0..outputs {
        for r in 0..refs {
            for (k, &f) in freqs.iter().enumerate() {
                let s = C64::new(0.0, 2.0 * PI * f);
                let mut v = C64::new(0.0, 0.0);
                for m in 0..t.freqs_hz.len() {
                    let lam = lambda(t.freqs_hz[m], t.zetas[m]);
                    let a =
                        C64::new(t.shapes[m][o] * t.parts[m][r], 0.0) / C64::new(0.0, 2.0 * lam.im);
                    v += a / (s - lam) + a.conj() / (s - lam.conj());
                }
                h[(o * refs + r) * freqs.len() + k] = v * s.powi(kind.derivative_order());
            }
        }
    }
    ModalData::new(freqs.to_vec(), outputs, refs, h, kind).unwrap()
}

fn three_dof() -> Truth {
    Truth {
        freqs_hz: vec![42.0, 97.5, 161.0],
        zetas: vec![0.015, 0.02, 0.03],
        shapes: vec![
            vec![0.33, 0.59, 0.74],
            vec![0.74, 0.33, -0.59],
            vec![0.59, -0.74, 0.33],
        ],
        parts: vec![vec![0.33, 0.74], vec![0.74, -0.59], vec![0.59, 0.33]],
    }
}

fn two_dof() -> Truth {
    Truth {
        freqs_hz: vec![31.0, 74.0],
        zetas: vec![0.01, 0.025],
        shapes: vec![vec![0.53, 0.85], vec![0.85, -0.53]],
        parts: vec![vec![0.53], vec![0.85]],
    }
}

fn lines(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
        .collect()
}

fn check_exact(t: &Truth, data: &ModalData, max_order: usize) {
    let orders = lscf(
        data,
        &LscfSettings {
            max_order,
            band_hz: None,
        },
    )
    .unwrap();
    let diagram = stabilize(orders, StabilityTolerances::default());
    let band = (data.freqs_hz[0], *data.freqs_hz.last().unwrap());
    let poles = select_auto(
        &diagram,
        &SelectionSettings {
            band_hz: band,
            min_orders: 5,
            max_damping: 0.2,
        },
    );
    assert_eq!(
        poles.len(),
        t.freqs_hz.len(),
        "poles found: {:?}",
        poles.iter().map(|p| p.freq_hz).collect::<Vec<_>>()
    );
    for (p, (f, z)) in poles.iter().zip(t.freqs_hz.iter().zip(&t.zetas)) {
        assert!(
            (p.freq_hz - f).abs() <= 1e-6 * f,
            "f {} vs {}",
            p.freq_hz,
            f
        );
        assert!(
            (p.damping_ratio - z).abs() <= 1e-6 * z,
            "ζ {} vs {}",
            p.damping_ratio,
            z
        );
    }
    let model = lsfd(data, &poles, None).unwrap();
    let est: Vec<Vec<C64>> = model.modes.iter().map(|m| m.shape.clone()).collect();
    let truth: Vec<Vec<C64>> = t
        .shapes
        .iter()
        .map(|s| s.iter().map(|&v| C64::new(v, 0.0)).collect())
        .collect();
    let mac = modal::mac(&est, &truth);
    for (i, row) in mac.iter().enumerate() {
        assert!(row[i] > 1.0 - 1e-9, "MAC diagonal {i}: {}", row[i]);
        assert!(
            model.modes[i].complexity < 1e-9,
            "complexity {}",
            model.modes[i].complexity
        );
    }
    // The modal model reproduces the data.
    let d = data.kind.derivative_order();
    let mut err: f64 = 0.0;
    let mut norm: f64 = 0.0;
    for o in 0..data.outputs {
        for r in 0..data.references {
            for (k, &f) in data.freqs_hz.iter().enumerate().filter(|x| *x.1 > 0.0) {
                let h = data.frf(o, r)[k];
                err += (model.frf(o, r, data.references, d, f) - h).norm_sqr();
                norm += h.norm_sqr();
            }
        }
    }
    assert!(
        (err / norm).sqrt() < 1e-6,
        "relative LSFD residual {}",
        (err / norm).sqrt()
    );
}

#[test]
fn two_dof_exact_receptance() {
    let t = two_dof();
    let data = synth(&t, &lines(0.0, 120.0, 961), 2, 1, FrfKind::Receptance);
    check_exact(&t, &data, 24);
}

#[test]
fn three_dof_exact_two_references_accelerance() {
    let t = three_dof();
    let data = synth(&t, &lines(10.0, 220.0, 1051), 3, 2, FrfKind::Accelerance);
    check_exact(&t, &data, 20);
}

/// Noise of 1 % of the RMS level on every line (seeded): frequencies within 0.2 %, damping within
/// 10 % of its value, the user's override finds the same poles as the automatic selection.
#[test]
fn three_dof_noisy_within_tolerance_and_override_agrees() {
    use rand::{Rng, SeedableRng};
    let t = three_dof();
    let mut data = synth(&t, &lines(10.0, 220.0, 1051), 3, 2, FrfKind::Receptance);
    let rms = (data.h.iter().map(|v| v.norm_sqr()).sum::<f64>() / data.h.len() as f64).sqrt();
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    let nd = rand_distr::Normal::new(0.0, 0.01 * rms).unwrap();
    for v in data.h.iter_mut() {
        *v += C64::new(rng.sample(nd), rng.sample(nd));
    }
    let orders = lscf(
        &data,
        &LscfSettings {
            max_order: 30,
            band_hz: None,
        },
    )
    .unwrap();
    let diagram = stabilize(orders, StabilityTolerances::default());
    let auto = select_auto(
        &diagram,
        &SelectionSettings {
            band_hz: (10.0, 220.0),
            min_orders: 8,
            max_damping: 0.2,
        },
    );
    let freqs: Vec<f64> = auto.iter().map(|p| p.freq_hz).collect();
    assert_eq!(auto.len(), 3, "poles found: {freqs:?}");
    for (p, (f, z)) in auto.iter().zip(t.freqs_hz.iter().zip(&t.zetas)) {
        assert!(
            (p.freq_hz - f).abs() <= 2e-3 * f,
            "f {} vs {}",
            p.freq_hz,
            f
        );
        assert!(
            (p.damping_ratio - z).abs() <= 0.1 * z,
            "ζ {} vs {}",
            p.damping_ratio,
            z
        );
    }
    let near: Vec<Pole> = select_near(&diagram, &[41.0, 99.0, 160.0], 0.05).unwrap();
    for (a, b) in near.iter().zip(&auto) {
        assert!(
            (a.freq_hz - b.freq_hz).abs() <= 2e-3 * b.freq_hz,
            "override {} ζ {} vs auto {} ζ {}",
            a.freq_hz,
            a.damping_ratio,
            b.freq_hz,
            b.damping_ratio
        );
    }
    assert!(
        select_near(&diagram, &[300.0], 0.05).is_err(),
        "no pole at 300 Hz"
    );
}

#[test]
fn bad_input_is_named() {
    let e = ModalData::new(
        vec![1.0, 1.0],
        1,
        1,
        vec![C64::new(1.0, 0.0); 2],
        FrfKind::Receptance,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("line 1") && e.contains("sorted"), "{e}");
    let e = ModalData::new(
        vec![1.0, 2.0],
        1,
        1,
        vec![C64::new(f64::NAN, 0.0); 2],
        FrfKind::Receptance,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("line 0") && e.contains("FRF value"), "{e}");
    let d = ModalData::new(
        vec![1.0, 2.0, 3.0],
        1,
        1,
        vec![C64::new(1.0, 0.0); 3],
        FrfKind::Receptance,
    )
    .unwrap();
    let e = lscf(
        &d,
        &LscfSettings {
            max_order: 10,
            band_hz: None,
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("too few"), "{e}");
}

#[test]
fn mac_and_complexity_of_known_shapes() {
    let a = vec![C64::new(1.0, 0.0), C64::new(-2.0, 0.0), C64::new(0.5, 0.0)];
    // the same shape scaled by a complex factor: MAC 1; an orthogonal one: MAC 0.
    let b: Vec<C64> = a.iter().map(|v| v * C64::new(-0.3, 2.0)).collect();
    let c = vec![C64::new(2.0, 0.0), C64::new(1.0, 0.0), C64::new(0.0, 0.0)];
    let m = modal::mac(std::slice::from_ref(&a), &[b.clone(), c]);
    assert!(
        (m[0][0] - 1.0).abs() < 1e-14 && m[0][1].abs() < 1e-14,
        "{m:?}"
    );
    // rotated real shape: complexity 0; equal, orthogonal real and imaginary parts: 1.
    assert!(modal::complexity(&b) < 1e-14);
    let wave = vec![C64::new(1.0, 0.0), C64::new(0.0, 1.0)];
    assert!((modal::complexity(&wave) - 1.0).abs() < 1e-14);
}
