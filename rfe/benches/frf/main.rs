//! FRF + full Jacobian of the FWD-32J model at 114 lines: direct path, modal path, and the plain
//! per-frequency dense solve (`baseline.rs`) as the baseline, in one run. The two paths against
//! the number of lines, where [`Method::Auto`] switches, are `identify`'s `frf_lines` bench
//! (they take the identification's variables).
//!
//! `cargo bench -p rfe --bench frf`

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion};
use rfe::frf::{response, Method};

mod baseline;
use baseline as frf_baseline;

fn fwd32j(c: &mut Criterion) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/models/fwd32j.toml");
    let model = rfe::modelfile::load(std::path::Path::new(path))
        .expect("configs/models/fwd32j.toml")
        .model;
    let params = model.all_params();
    let freqs: Vec<f64> = (0..114)
        .map(|i| 5.0 * (200.0f64 / 5.0).powf(i as f64 / 113.0))
        .collect();
    // the three agree (checked here so a benchmark never times a wrong answer)
    let d = response(&model, &freqs, &params, Method::Direct).unwrap();
    let m = response(&model, &freqs, &params, Method::Modal).unwrap();
    let (bv, bj) = frf_baseline::dense_response(&model, &freqs, &params);
    let scale = bj.iter().map(|v| v.norm()).fold(0.0, f64::max);
    for ((a, b), c) in d.jacobian.iter().zip(&m.jacobian).zip(&bj) {
        assert!((a - c).norm() <= 1e-6 * scale && (b - c).norm() <= 1e-6 * scale);
    }
    assert!(d
        .values
        .iter()
        .zip(&bv)
        .all(|(a, b)| (a - b).norm() <= 1e-9 * b.norm()));
    println!(
        "FWD-32J: {} DOFs, {} parameters, {} outputs, {} lines",
        model.dof_count(),
        params.len(),
        model.outputs.len(),
        freqs.len()
    );
    let mut g = c.benchmark_group("fwd32j_frf_jacobian_114_lines");
    g.sample_size(20);
    g.bench_function("direct", |b| {
        b.iter(|| response(&model, &freqs, &params, Method::Direct).unwrap())
    });
    g.bench_function("modal", |b| {
        b.iter(|| response(&model, &freqs, &params, Method::Modal).unwrap())
    });
    g.bench_function("plain_dense_baseline", |b| {
        b.iter(|| frf_baseline::dense_response(&model, &freqs, &params))
    });
    g.bench_function("frf_only_direct", |b| {
        b.iter(|| response(&model, &freqs, &[], Method::Direct).unwrap())
    });
    g.finish();
}

criterion_group!(benches, fwd32j);
criterion_main!(benches);
