//! Bad input to the spectral chain: clear errors naming the channel, never panics.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use process::{
    cross_spectra, estimate, spectra::Welch, Estimator, ProcessError, Signal, WelchConfig, Window,
};

fn cfg() -> WelchConfig {
    WelchConfig::new(1000.0, 256, Window::Hann)
}

fn sig(name: &str, fs: f64, samples: Vec<f64>) -> Signal {
    Signal {
        name: name.into(),
        sample_rate_hz: fs,
        samples,
    }
}

#[test]
fn mismatched_rates_lengths_and_counts_are_named() {
    let x = common::noise(1, 2000, 1.0);
    let e = cross_spectra(
        &cfg(),
        &[sig("hammer", 1000.0, x.clone())],
        &[sig("acc1", 1024.0, x.clone())],
    )
    .unwrap_err();
    assert!(
        matches!(e, ProcessError::SampleRateMismatch { .. }) && e.to_string().contains("acc1"),
        "{e}"
    );
    let e = cross_spectra(
        &cfg(),
        &[sig("hammer", 1000.0, x.clone())],
        &[sig("acc1", 1000.0, x[..1500].to_vec())],
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("acc1") && e.to_string().contains("1500"),
        "{e}"
    );
    let e = cross_spectra(
        &cfg(),
        &[sig("hammer", 1000.0, vec![])],
        &[sig("acc1", 1000.0, vec![])],
    )
    .unwrap_err();
    assert!(matches!(e, ProcessError::Empty { .. }), "{e}");
    let e = cross_spectra(
        &cfg(),
        &[sig("hammer", 1000.0, x[..100].to_vec())],
        &[sig("acc1", 1000.0, x[..100].to_vec())],
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("100 samples") && e.to_string().contains("256"),
        "{e}"
    );
    let mut w = Welch::new(cfg(), &["f"], &["a", "b"]).unwrap();
    assert!(matches!(
        w.push(&[&x], &[&x]).unwrap_err(),
        ProcessError::ChannelCount {
            expected: 2,
            got: 1,
            ..
        }
    ));
    assert!(Welch::new(cfg(), &[], &["a"]).is_err());
    let mut bad = cfg();
    bad.overlap = 256;
    assert!(Welch::new(bad, &["f"], &["a"])
        .unwrap_err()
        .to_string()
        .contains("overlap"));
}

#[test]
fn nan_samples_zero_force_and_overloads() {
    let mut x = common::noise(2, 3000, 1.0);
    let y = x.clone();
    x[2100] = f64::NAN;
    let mut w = Welch::new(cfg(), &["hammer"], &["acc"]).unwrap();
    w.push(&[&x[..2000]], &[&y[..2000]]).unwrap();
    let e = w
        .push(&[&x[2000..]], &[&y[2000..]])
        .unwrap_err()
        .to_string();
    assert!(e.contains("hammer") && e.contains("2100"), "{e}");

    let zero = vec![0.0; 3000];
    let e = cross_spectra(
        &cfg(),
        &[sig("hammer", 1000.0, zero)],
        &[sig("acc", 1000.0, y.clone())],
    )
    .unwrap_err();
    assert!(
        matches!(e, ProcessError::ZeroForce { .. }) && e.to_string().contains("hammer"),
        "{e}"
    );

    // Clipped response: samples at full scale are counted.
    let clipped: Vec<f64> = y.iter().map(|v| v.clamp(-1.5, 1.5)).collect();
    let expected = clipped.iter().filter(|v| v.abs() >= 1.5).count() as u64;
    assert!(expected > 0);
    let mut c = cfg();
    c.full_scale = vec![10.0, 1.5];
    let mut w = Welch::new(c, &["hammer"], &["acc"]).unwrap();
    w.push(&[&y], &[&clipped]).unwrap();
    let s = w.finish().unwrap();
    assert_eq!(s.overloads, vec![0, expected]);
    // Without a full scale the clipping still shows: samples pile up on the rails.
    assert!(
        !s.clipping_suspected(0) && s.clipping_suspected(1),
        "peak hits {:?}",
        s.peak_hits
    );
    assert_eq!(s.peak_hits[1], expected - 2);
}

#[test]
fn estimators_reject_unsupported_layouts() {
    let x1 = common::noise(3, 4000, 1.0);
    let x2 = common::noise(4, 4000, 1.0);
    let mut w = Welch::new(cfg(), &["f1", "f2"], &["a"]).unwrap();
    w.push(&[&x1, &x2], &[&x1]).unwrap();
    let s = w.finish().unwrap();
    assert!(estimate(&s, Estimator::H2)
        .unwrap_err()
        .to_string()
        .contains("H1"));
    // Identical references: G_xx singular at every line -> NaN, coherence 0, no panic.
    let mut w = Welch::new(cfg(), &["f1", "f1copy"], &["a"]).unwrap();
    w.push(&[&x1, &x1], &[&x2]).unwrap();
    let f = estimate(&w.finish().unwrap(), Estimator::H1).unwrap();
    assert!(f.h(10, 0, 0).re.is_nan() && f.multiple_coherence(10, 0) == 0.0);
}
