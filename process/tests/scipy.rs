//! Cross-checks of Welch spectra, H1 and coherence against scipy.signal.csd on identical data and
//! settings (relative difference ≤ 1e-9), including the real hammer-impact records.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::*;
use process::{estimate, spectra::Welch, Detrend, Estimator, WelchConfig, Window};

fn rel(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / b.abs().max(floor)
}

struct Case {
    window: Window,
    scipy: &'static str,
    nperseg: usize,
    overlap: usize,
    detrend: Detrend,
}

fn check_welch(case: &Case, refs: &[Vec<f64>], resps: &[Vec<f64>], fs: f64) {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("signals.bin");
    let out = dir.path().join("scipy.bin");
    let all: Vec<f64> = refs.iter().chain(resps).flatten().copied().collect();
    write_f64(&inp, &all);
    let (r, p) = (refs.len(), resps.len());
    python(
        "h1_scipy.py",
        &[
            "welch",
            inp.to_str().unwrap(),
            out.to_str().unwrap(),
            &fs.to_string(),
            &case.nperseg.to_string(),
            &case.overlap.to_string(),
            case.scipy,
            match case.detrend {
                Detrend::None => "none",
                Detrend::Constant => "constant",
                Detrend::Linear => "linear",
            },
            &r.to_string(),
            &p.to_string(),
        ],
        "numpy, scipy",
    );
    let py = read_f64(&out);
    let mut cfg = WelchConfig::new(fs, case.nperseg, case.window.clone());
    cfg.overlap = case.overlap;
    cfg.detrend = case.detrend;
    let rn: Vec<String> = (0..r).map(|i| format!("f{i}")).collect();
    let pn: Vec<String> = (0..p).map(|j| format!("a{j}")).collect();
    let mut w = Welch::new(
        cfg,
        &rn.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        &pn.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
    )
    .unwrap();
    // Feed in uneven blocks to exercise the streaming path.
    let len = refs[0].len();
    let mut at = 0;
    let mut block = 777;
    while at < len {
        let end = (at + block).min(len);
        let rs: Vec<&[f64]> = refs.iter().map(|x| &x[at..end]).collect();
        let ps: Vec<&[f64]> = resps.iter().map(|x| &x[at..end]).collect();
        w.push(&rs, &ps).unwrap();
        at = end;
        block = block * 3 % 2000 + 1;
    }
    let s = w.finish().unwrap();
    let frf = estimate(&s, Estimator::H1).unwrap();
    let nf = case.nperseg / 2 + 1;
    assert_eq!(py.len(), nf * (2 * r * p + p + r + p), "python output size");
    let hmax = frf.h.iter().map(|h| h.norm()).fold(0.0, f64::max);
    // Lines where a force spectrum is numerically zero (DC after mean removal with a rectangular
    // window) hold round-off ratios on both sides: left out of the H comparison.
    let gmax = (0..nf).map(|k| s.gxx(k, 0, 0).re).fold(0.0, f64::max);
    let determined = |k: usize| (0..r).all(|i| s.gxx(k, i, i).re > 1e-20 * gmax);
    let mut worst: f64 = 0.0;
    let mut o = 0;
    for j in 0..p {
        for i in 0..r {
            for k in (0..nf).filter(|&k| determined(k)) {
                let py_h = num_complex::Complex::new(py[o + k], py[o + nf + k]);
                let e = (frf.h(k, j, i) - py_h).norm() / py_h.norm().max(1e-12 * hmax);
                worst = worst.max(e);
            }
            o += 2 * nf;
        }
    }
    let h_err = worst;
    for j in 0..p {
        for k in (1..nf - 1).filter(|&k| determined(k)) {
            worst = worst.max(rel(frf.multiple_coherence(k, j), py[o + k], 1e-12));
        }
        o += nf;
    }
    for i in 0..r {
        let m = (0..nf).map(|k| py[o + k]).fold(0.0, f64::max);
        for k in 0..nf {
            worst = worst.max(rel(s.gxx(k, i, i).re, py[o + k], 1e-12 * m));
        }
        o += nf;
    }
    for j in 0..p {
        let m = (0..nf).map(|k| py[o + k]).fold(0.0, f64::max);
        for k in 0..nf {
            worst = worst.max(rel(s.gyy(k, j), py[o + k], 1e-12 * m));
        }
        o += nf;
    }
    eprintln!(
        "window {}: worst relative difference to scipy {worst:.2e} (H1 {h_err:.2e})",
        case.scipy
    );
    assert!(
        worst <= 1e-9,
        "window {}: worst relative difference to scipy {worst:e} (H: {h_err:e})",
        case.scipy
    );
}

#[test]
fn siso_h1_coherence_and_densities_match_scipy_for_every_window() {
    let fs = 2048.0;
    let x = noise(1, 20_000, 1.0);
    let (b, a) = ([0.02, 0.01, 0.0], [-1.8, 0.9]);
    let mut y = resonator(&x, b, a);
    for (i, (yi, n)) in y.iter_mut().zip(noise(2, 20_000, 0.05)).enumerate() {
        *yi += n + 0.3 + 2e-5 * i as f64; // offset and drift exercise the trend removal
    }
    let cases = [
        (Window::Rectangular, "boxcar", 1024, 0, Detrend::Constant),
        (Window::Hann, "hann", 1024, 512, Detrend::Constant),
        (Window::Hamming, "hamming", 1000, 333, Detrend::None),
        (
            Window::BlackmanHarris,
            "blackmanharris",
            2048,
            1024,
            Detrend::Constant,
        ),
        (Window::FlatTop, "flattop", 512, 256, Detrend::Constant),
        (Window::Hann, "hann", 1024, 768, Detrend::Linear),
    ];
    for (window, scipy, nperseg, overlap, detrend) in cases {
        check_welch(
            &Case {
                window,
                scipy,
                nperseg,
                overlap,
                detrend,
            },
            std::slice::from_ref(&x),
            std::slice::from_ref(&y),
            fs,
        );
    }
}

#[test]
fn mimo_h1_and_multiple_coherence_match_scipy_cross_spectral_matrices() {
    let fs = 1000.0;
    let n = 16_384;
    let x1 = noise(11, n, 1.0);
    let x2: Vec<f64> = noise(12, n, 1.0)
        .iter()
        .zip(&x1)
        .map(|(a, b)| a + 0.3 * b)
        .collect(); // correlated references
    let r1 = resonator(&x1, [0.02, 0.0, 0.0], [-1.6, 0.8]);
    let r2 = resonator(&x2, [0.01, 0.01, 0.0], [-1.2, 0.7]);
    let y1: Vec<f64> = r1
        .iter()
        .zip(&r2)
        .zip(noise(13, n, 0.01))
        .map(|((a, b), e)| a + b + e)
        .collect();
    let y2: Vec<f64> = r1
        .iter()
        .zip(&r2)
        .zip(noise(14, n, 0.02))
        .map(|((a, b), e)| a - 0.5 * b + e)
        .collect();
    let y3: Vec<f64> = r2
        .iter()
        .zip(noise(15, n, 0.05))
        .map(|(b, e)| 2.0 * b + e)
        .collect();
    check_welch(
        &Case {
            window: Window::Hann,
            scipy: "hann",
            nperseg: 512,
            overlap: 256,
            detrend: Detrend::None,
        },
        &[x1, x2],
        &[y1, y2, y3],
        fs,
    );
}

#[test]
fn impact_h1_from_real_hammer_records_matches_scipy() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/pyfrf-impact");
    let files: Vec<std::path::PathBuf> = (1..=5)
        .map(|i| dir.join(format!("measurements_{i}.npy")))
        .collect();
    for f in &files {
        assert!(
            f.exists(),
            "real impact data missing: {} (from ladisk/pyFRF data/)",
            f.display()
        );
    }
    let (width, end) = (0.01, 0.05);
    let first = process::npy::read(&files[0]).unwrap();
    let n = first.shape[1];
    let t = first.row(0).unwrap();
    let fs = 1.0 / (t[1] - t[0]);
    let mut w = Welch::new(
        WelchConfig::impact(fs, n, width, end),
        &["hammer"],
        &["acc"],
    )
    .unwrap();
    for f in &files {
        let a = process::npy::read(f).unwrap();
        assert_eq!(a.shape, vec![3, n], "{}", f.display());
        w.start_record();
        w.push(&[a.row(1).unwrap()], &[a.row(2).unwrap()]).unwrap();
    }
    assert_eq!(w.segments(), 5);
    let frf = estimate(&w.finish().unwrap(), Estimator::H1).unwrap();

    let out = tempfile::tempdir().unwrap();
    let out = out.path().join("impact.bin");
    let mut args = vec![
        "impact".to_string(),
        out.to_str().unwrap().into(),
        width.to_string(),
        end.to_string(),
    ];
    args.extend(files.iter().map(|f| f.to_str().unwrap().to_string()));
    python(
        "h1_scipy.py",
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        "numpy, scipy",
    );
    let py = read_f64(&out);
    let nf = n / 2 + 1;
    assert_eq!(py.len(), 3 * nf);
    let hmax = frf.h.iter().map(|h| h.norm()).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    let mut worst_coh: f64 = 0.0;
    let mut at = (0, 0);
    for k in 0..nf {
        let p = num_complex::Complex::new(py[k], py[nf + k]);
        let e = (frf.h(k, 0, 0) - p).norm() / p.norm().max(1e-12 * hmax);
        if e > worst {
            worst = e;
            at.0 = k;
        }
        let e = rel(frf.coherence(k, 0, 0), py[2 * nf + k], 1e-12);
        if e > worst_coh {
            worst_coh = e;
            at.1 = k;
        }
    }
    eprintln!("H1 worst {worst:.2e} at {} Hz (|H|/max {:.1e}); coherence worst {worst_coh:.2e} at {} Hz (γ² = {:.1e})", frf.freqs_hz[at.0], frf.h(at.0, 0, 0).norm() / hmax, frf.freqs_hz[at.1], frf.coherence(at.1, 0, 0));
    eprintln!(
        "  at line {}: process {:.15e}, scipy {:.15e}{:+.15e}i",
        at.0,
        frf.h(at.0, 0, 0),
        py[at.0],
        py[nf + at.0]
    );
    let worst = worst.max(worst_coh);
    eprintln!("impact H1/coherence vs scipy: worst relative difference {worst:.2e}");
    assert!(
        worst <= 1e-9,
        "impact H1 vs scipy: worst relative difference {worst:e}"
    );
    // The data are a real, coherent measurement: most of the band below 5 kHz is coherent.
    let coherent = (1..nf)
        .filter(|&k| frf.freqs_hz[k] < 5000.0 && frf.coherence(k, 0, 0) > 0.9)
        .count();
    assert!(
        coherent > 4000,
        "only {coherent} coherent lines below 5 kHz"
    );
}
