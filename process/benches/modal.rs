//! Modal extraction of 3 references × 30 responses × 4000 lines (10 modes, 0.5 Hz lines up to
//! 2 kHz): pLSCF over orders 1..40 (120 poles at the top order), then the stabilization diagram,
//! automatic selection and LSFD — against sdypy-EMA 0.27.3's LSCF (`get_poles`, the same 90 FRFs
//! as locations, scalar orders 2..120, so the same 120 poles at the top) on the same data, timed
//! by `benches/sdypy_lscf.py` in the same run.
//!
//! Run: `CARGO_TARGET_DIR=... cargo bench -p process --bench modal`. Prints the time of each side
//! and the ratio.
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use process::modal::{
    lscf, lsfd, select_auto, stabilize, FrfKind, LscfSettings, ModalData, SelectionSettings,
    StabilityTolerances,
};
use process::C64;
use std::f64::consts::PI;
use std::hint::black_box;
use std::time::{Duration, Instant};

const REFS: usize = 3;
const RESPONSES: usize = 30;
const LINES: usize = 4000;
const ORDER: usize = 40;

fn data() -> ModalData {
    let freqs: Vec<f64> = (1..=LINES).map(|k| k as f64 * 0.5).collect();
    let modes: Vec<(f64, f64)> = (0..10)
        .map(|m| {
            (
                90.0 + 175.0 * m as f64 + 20.0 * (m as f64).sin(),
                0.01 + 0.002 * m as f64,
            )
        })
        .collect();
    let mut h = vec![C64::new(0.0, 0.0); RESPONSES * REFS * LINES];
    for o in 0..RESPONSES {
        for r in 0..REFS {
            let frf = &mut h[(o * REFS + r) * LINES..(o * REFS + r + 1) * LINES];
            for (m, &(f, z)) in modes.iter().enumerate() {
                let w = 2.0 * PI * f;
                let lam = C64::new(-z * w, w * (1.0 - z * z).sqrt());
                let phi = ((o + 1) as f64 * (m + 1) as f64 * 0.37).sin();
                let l = ((r + 2) as f64 * (m + 1) as f64 * 0.71).cos();
                let a = C64::new(phi * l, 0.0) / C64::new(0.0, 2.0 * lam.im);
                for (v, &fk) in frf.iter_mut().zip(&freqs) {
                    let s = C64::new(0.0, 2.0 * PI * fk);
                    *v += a / (s - lam) + a.conj() / (s - lam.conj());
                }
            }
        }
    }
    ModalData::new(freqs, RESPONSES, REFS, h, FrfKind::Receptance).unwrap()
}

fn extract(d: &ModalData) -> usize {
    let orders = lscf(
        d,
        &LscfSettings {
            max_order: ORDER,
            band_hz: None,
        },
    )
    .unwrap();
    let diagram = stabilize(orders, StabilityTolerances::default());
    let poles = select_auto(
        &diagram,
        &SelectionSettings {
            band_hz: (0.0, 2000.0),
            min_orders: 10,
            max_damping: 0.2,
        },
    );
    lsfd(d, &poles, None).unwrap().modes.len()
}

fn bench(c: &mut Criterion) {
    let d = data();
    // One timed pass for the ratio, then the baseline in the same run.
    let t0 = Instant::now();
    let modes = extract(&d);
    let ours = t0.elapsed().as_secs_f64();
    println!("process::modal: {modes} modes in {ours:.3} s (pLSCF orders 1..{ORDER} + diagram + selection + LSFD)");
    let t0 = Instant::now();
    black_box(
        lscf(
            &d,
            &LscfSettings {
                max_order: ORDER,
                band_hz: None,
            },
        )
        .unwrap(),
    );
    let ours_lscf = t0.elapsed().as_secs_f64();
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("frf.bin");
    let mut bytes: Vec<u8> = Vec::with_capacity(8 * (LINES + 1 + 2 * d.h.len()));
    // sdypy wants lines from 0 Hz: a zero line at 0 Hz first.
    bytes.extend(0.0f64.to_le_bytes());
    bytes.extend(d.freqs_hz.iter().flat_map(|f| f.to_le_bytes()));
    for fr in 0..RESPONSES * REFS {
        bytes.extend(0.0f64.to_le_bytes());
        bytes.extend(0.0f64.to_le_bytes());
        for v in &d.h[fr * LINES..(fr + 1) * LINES] {
            bytes.extend(v.re.to_le_bytes());
            bytes.extend(v.im.to_le_bytes());
        }
    }
    std::fs::write(&inp, bytes).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/sdypy_lscf.py");
    match std::process::Command::new("python3")
        .arg(&script)
        .arg(&inp)
        .arg((RESPONSES * REFS).to_string())
        .arg((REFS * ORDER / 2).to_string())
        .output()
    {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            print!("{text}");
            if let Some(t) = text
                .lines()
                .find_map(|l| l.strip_prefix("sdypy_seconds "))
                .and_then(|t| t.trim().parse::<f64>().ok())
            {
                println!(
                    "RATIO sdypy get_poles / process::modal lscf = {:.1} (sdypy {t:.3} s, ours {ours_lscf:.3} s); sdypy get_poles / our whole extraction = {:.1}",
                    t / ours_lscf,
                    t / ours
                );
            }
        }
        Ok(o) => println!(
            "sdypy baseline failed: {}",
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => println!("python3 not available for the sdypy baseline ({e}); run .ci/setup"),
    }
    let mut g = c.benchmark_group("modal");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(10));
    g.bench_function("plscf_3x30x4000_order40_diagram_lsfd", |b| {
        b.iter(|| black_box(extract(&d)))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
