//! H1 + coherence for 8 response channels (plus the force) × 2^24 samples, segment 8192, 50 %
//! overlap, Hann — streamed block by block with bounded memory — against scipy.signal.csd on
//! the same data (`benches/scipy_csd.py`, run from this benchmark, same machine, same run).
//!
//! Run: `CARGO_TARGET_DIR=... cargo bench -p process --bench welch`. Prints the time of each side,
//! the ratio, and peak memory (VmHWM of this process; ru_maxrss of the Python process).
//! Data: both sides generate identical signals from splitmix64 (seeded by channel and index).
#![allow(clippy::unwrap_used, missing_docs)]

use criterion::{criterion_group, criterion_main, Criterion};
use process::{estimate, spectra::Welch, Estimator, WelchConfig, Window};
use std::hint::black_box;
use std::time::{Duration, Instant};

const LEN: usize = 1 << 24;
const RESPONSES: usize = 8;
const SEG: usize = 8192;
const BLOCK: usize = 65_536;

fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn uniform(ch: u64, n: u64) -> f64 {
    (splitmix((ch << 40) | n) >> 11) as f64 * (1.0 / (1u64 << 53) as f64) - 0.5
}

/// Fills one block: force = u0, response j = (0.5 + 0.1 j)·force + u_{j+1}.
fn generate(start: usize, force: &mut [f64], resp: &mut [Vec<f64>]) {
    for (i, f) in force.iter_mut().enumerate() {
        *f = uniform(0, (start + i) as u64);
    }
    for (j, r) in resp.iter_mut().enumerate() {
        let g = 0.5 + 0.1 * j as f64;
        for (i, v) in r.iter_mut().enumerate() {
            *v = g * force[i] + uniform(j as u64 + 1, (start + i) as u64);
        }
    }
}

fn run(generate_only: bool) -> Option<process::Frf> {
    let names: Vec<String> = (0..RESPONSES).map(|j| format!("acc{j}")).collect();
    let names: Vec<&str> = names.iter().map(|s| s.as_str()).collect();
    let mut welch =
        Welch::new(WelchConfig::new(1.0, SEG, Window::Hann), &["force"], &names).expect("welch");
    let mut force = vec![0.0; BLOCK];
    let mut resp = vec![vec![0.0; BLOCK]; RESPONSES];
    let mut start = 0;
    while start < LEN {
        generate(start, &mut force, &mut resp);
        if !generate_only {
            let r: Vec<&[f64]> = resp.iter().map(|v| v.as_slice()).collect();
            welch.push(&[&force], &r).expect("push");
        }
        start += BLOCK;
    }
    black_box(&resp);
    if generate_only {
        return None;
    }
    Some(estimate(&welch.finish().expect("finish"), Estimator::H1).expect("h1"))
}

fn vm_hwm_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let l = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    l.split_whitespace().nth(1)?.parse().ok()
}

fn scipy_baseline(rust: &process::Frf) {
    let dir = std::env::temp_dir().join(format!("process-bench-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let out = dir.join("h1.bin");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/scipy_csd.py");
    let res = std::process::Command::new("python3")
        .arg(script)
        .arg(&out)
        .output();
    match res {
        Ok(o) if o.status.success() => {
            let text = String::from_utf8_lossy(&o.stdout);
            print!("{text}");
            let b = std::fs::read(&out).unwrap_or_default();
            let py: Vec<f64> = b
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                .collect();
            // python writes Re H, Im H, coherence of every response at lines 100, 1000, 3000.
            let mut worst: f64 = 0.0;
            for (n, k) in [100usize, 1000, 3000].iter().enumerate() {
                for j in 0..RESPONSES {
                    let o = (n * RESPONSES + j) * 3;
                    if o + 2 < py.len() {
                        let h = num_complex::Complex::new(py[o], py[o + 1]);
                        worst = worst.max((rust.h(*k, j, 0) - h).norm() / h.norm());
                        worst = worst.max((rust.coherence(*k, j, 0) - py[o + 2]).abs() / py[o + 2]);
                    }
                }
            }
            println!("same data check: max relative difference of H1/coherence vs scipy at 3 lines × 8 channels: {worst:.2e}");
            if let Some(t) = text.lines().find_map(|l| l.strip_prefix("scipy_seconds ")) {
                if let Ok(t) = t.trim().parse::<f64>() {
                    let rust_t = RUST_SECONDS.with(|c| c.get());
                    println!("RATIO scipy/process = {:.2} (scipy {t:.3} s, process {rust_t:.3} s incl. signal generation)", t / rust_t);
                }
            }
        }
        Ok(o) => println!(
            "scipy baseline failed (run .ci/setup): {}",
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => println!("python3 not available for the scipy baseline ({e}); run .ci/setup"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

thread_local! {
    static RUST_SECONDS: std::cell::Cell<f64> = const { std::cell::Cell::new(f64::NAN) };
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("h1_coherence_8ch_2^24");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(20));
    g.bench_function("generate_only", |b| b.iter(|| run(true)));
    g.bench_function("generate+welch+h1", |b| b.iter(|| run(false)));
    g.finish();
    // One timed pass for the ratio, then the baseline in the same run.
    let t0 = Instant::now();
    let frf = run(false).expect("frf");
    let dt = t0.elapsed().as_secs_f64();
    RUST_SECONDS.with(|c| c.set(dt));
    println!("process: one pass {dt:.3} s; peak memory (VmHWM) {:.1} MiB; record size would be {:.0} MiB", vm_hwm_kib().unwrap_or(0) as f64 / 1024.0, (LEN * (RESPONSES + 1) * 8) as f64 / (1 << 20) as f64);
    scipy_baseline(&frf);
}

criterion_group!(benches, bench);
criterion_main!(benches);
