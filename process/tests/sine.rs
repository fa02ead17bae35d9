//! Stepped-sine least-squares fit: exact recovery on noise-free signals (≤ 1e-9), distortion and
//! noise level reporting.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use process::sine::{SineConfig, SineFitter};
use process::C64;
use std::f64::consts::PI;

fn tone(
    fs: f64,
    n: usize,
    f: f64,
    dc: f64,
    parts: &[(usize, f64, f64)],
    settle: Option<(f64, f64)>,
) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let t = i as f64 / fs;
            let mut v = dc;
            // An anti-aliased DAQ: nothing at or above Nyquist.
            for &(h, amp, ph) in parts.iter().filter(|p| (p.0 as f64 * f) < fs / 2.0) {
                v += amp * (2.0 * PI * h as f64 * f * t + ph).cos();
            }
            if let Some((a, tau)) = settle {
                v += a * (-t / tau).exp() * (2.0 * PI * 37.0 * t).sin();
            }
            v
        })
        .collect()
}

#[test]
fn noise_free_steps_are_recovered_to_1e_9() {
    let fs = 5120.0;
    let mut fitter = SineFitter::new();
    let cfg = SineConfig {
        sample_rate_hz: fs,
        settle_s: 0.5,
        harmonics: 3,
    };
    for (step, f) in [3.3, 17.77, 123.456, 999.9, 2000.1].into_iter().enumerate() {
        let n = 5120 + 777 * step; // non-integer number of periods
                                   // Transient decays well within the settling time (e^-50).
        let force = tone(fs, n, f, 0.2, &[(1, 100.0, 0.3)], Some((50.0, 0.01)));
        let r1 = tone(
            fs,
            n,
            f,
            -1.0,
            &[(1, 2.5e-3, -1.2), (2, 1e-4, 0.5), (3, 3e-5, 2.0)],
            Some((1.0, 0.01)),
        );
        let r2 = tone(fs, n, f, 0.0, &[(1, 7.0, 3.0)], None);
        let s = fitter.fit_step(&cfg, f, &force, &[&r1, &r2]).unwrap();
        assert!(
            (s.force.amplitude() - 100.0).abs() < 1e-9 * 100.0,
            "{f} Hz force amp {}",
            s.force.amplitude()
        );
        assert!((s.force.phase_rad() - 0.3).abs() < 1e-9);
        assert!((s.force.dc - 0.2).abs() < 1e-9);
        assert!((s.responses[0].amplitude() - 2.5e-3).abs() < 1e-9 * 2.5e-3);
        assert!((s.responses[0].phase_rad() + 1.2).abs() < 1e-9);
        let want_h = C64::from_polar(2.5e-5, -1.5);
        assert!(
            (s.frf[0] - want_h).norm() < 1e-9 * want_h.norm(),
            "{f} Hz FRF {}",
            s.frf[0]
        );
        let have_harm = (2.0 * f) < fs / 2.0;
        if have_harm {
            let h2 = s.responses[0].harmonics[0];
            assert!((h2 - C64::from_polar(1e-4, 0.5)).norm() < 1e-9 * 1e-4 + 1e-15);
            let thd = ((1e-4f64).powi(2) + (3e-5f64).powi(2)).sqrt() / 2.5e-3;
            if 3.0 * f < fs / 2.0 {
                assert!((s.responses[0].distortion - thd).abs() < 1e-8 * thd);
            }
        }
        assert!(
            s.responses[0].noise_rms < 1e-9 * 2.5e-3,
            "noise {}",
            s.responses[0].noise_rms
        );
        assert!((s.responses[1].amplitude() - 7.0).abs() < 1e-9 * 7.0);
    }
}

#[test]
fn noise_level_is_reported() {
    let fs = 2000.0;
    let n = 40_000;
    let f = 55.0;
    let clean = tone(fs, n, f, 0.0, &[(1, 1.0, 0.0)], None);
    let noisy: Vec<f64> = clean
        .iter()
        .zip(common::noise(7, n, 0.01))
        .map(|(a, e)| a + e)
        .collect();
    let cfg = SineConfig {
        sample_rate_hz: fs,
        settle_s: 0.0,
        harmonics: 0,
    };
    let s = SineFitter::new()
        .fit_step(&cfg, f, &clean, &[&noisy])
        .unwrap();
    let r = &s.responses[0];
    assert!((r.noise_rms - 0.01).abs() < 0.0005, "noise {}", r.noise_rms);
    assert!((r.amplitude() - 1.0).abs() < 4.0 * 0.01 * (2.0 / n as f64).sqrt() * 3.0);
    assert!(r.snr() > 60.0 && r.snr() < 80.0);
}

#[test]
fn predicted_frf_variance_matches_monte_carlo() {
    let (fs, n, f) = (1000.0, 2000, 37.0);
    let force = tone(fs, n, f, 0.0, &[(1, 10.0, 0.2)], None);
    let resp = tone(fs, n, f, 0.0, &[(1, 0.5, -0.7)], None);
    let cfg = SineConfig {
        sample_rate_hz: fs,
        settle_s: 0.0,
        harmonics: 1,
    };
    let truth = C64::from_polar(0.05, -0.9);
    let mut fit = SineFitter::new();
    let (mut mse, mut pred) = (0.0, 0.0);
    let trials = 400;
    for t in 0..trials {
        let fm: Vec<f64> = force
            .iter()
            .zip(common::noise(1000 + t, n, 0.3))
            .map(|(a, e)| a + e)
            .collect();
        let rm: Vec<f64> = resp
            .iter()
            .zip(common::noise(5000 + t, n, 0.05))
            .map(|(a, e)| a + e)
            .collect();
        let s = fit.fit_step(&cfg, f, &fm, &[&rm]).unwrap();
        mse += (s.frf[0] - truth).norm_sqr() / trials as f64;
        pred += s.variance(0).unwrap() / trials as f64;
    }
    assert!(
        (mse / pred - 1.0).abs() < 0.2,
        "Monte-Carlo {mse:e} vs predicted {pred:e}"
    );
}

#[test]
fn a_continuous_sweep_is_split_into_steps() {
    use process::sine::StepSpec;
    let fs = 4096.0;
    let freqs = [20.0, 45.5, 130.25];
    let mut force = Vec::new();
    let mut resp = Vec::new();
    let mut steps = Vec::new();
    for (i, &f) in freqs.iter().enumerate() {
        let len = 4096 + 100 * i;
        steps.push(StepSpec {
            freq_hz: f,
            start: force.len(),
            len,
        });
        force.extend(tone(fs, len, f, 0.0, &[(1, 50.0, 0.1 * i as f64)], None));
        resp.extend(tone(
            fs,
            len,
            f,
            0.0,
            &[(1, 0.5 * (i + 1) as f64, 0.1 * i as f64 - 0.4)],
            None,
        ));
    }
    let cfg = SineConfig {
        sample_rate_hz: fs,
        settle_s: 0.1,
        harmonics: 0,
    };
    let out = SineFitter::new()
        .fit_sweep(&cfg, &steps, &force, &[&resp])
        .unwrap();
    for (i, s) in out.iter().enumerate() {
        let want = C64::from_polar(0.01 * (i + 1) as f64, -0.4);
        assert!(
            (s.frf[0] - want).norm() < 1e-9 * want.norm(),
            "step {i}: {}",
            s.frf[0]
        );
    }
    let mut bad = steps.clone();
    bad[2].len += 1;
    let e = SineFitter::new()
        .fit_sweep(&cfg, &bad, &force, &[&resp])
        .unwrap_err()
        .to_string();
    assert!(e.contains("step 2"), "{e}");
}

#[test]
fn bad_steps_are_errors() {
    let cfg = SineConfig {
        sample_rate_hz: 1000.0,
        settle_s: 0.5,
        harmonics: 1,
    };
    let x = vec![1.0; 550]; // 50 samples after settling, a period is 100
    let mut fit = SineFitter::new();
    let e = fit.fit_step(&cfg, 10.0, &x, &[&x]).unwrap_err().to_string();
    assert!(e.contains("50 samples") && e.contains("fewer"), "{e}");
    assert!(fit
        .fit_step(&cfg, 600.0, &x, &[&x])
        .unwrap_err()
        .to_string()
        .contains("Nyquist"));
    let zero = vec![0.0; 2000];
    let resp = tone(1000.0, 2000, 50.0, 0.0, &[(1, 1.0, 0.0)], None);
    assert!(fit
        .fit_step(&cfg, 50.0, &zero, &[&resp])
        .unwrap_err()
        .to_string()
        .contains("zero"));
    let mut nan = resp.clone();
    nan[1500] = f64::NAN;
    let e = fit
        .fit_step(&cfg, 50.0, &resp, &[&nan])
        .unwrap_err()
        .to_string();
    assert!(e.contains("response 0") && e.contains("1500"), "{e}");
    let short = vec![1.0; 10];
    assert!(fit.fit_step(&cfg, 50.0, &resp, &[&short]).is_err());
}
