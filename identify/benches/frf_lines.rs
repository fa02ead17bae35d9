//! Direct against modal by the number of lines, FRF plus the Jacobian of the FWD-32J
//! identification's parameters: the break-even `rfe::frf::Method::Auto` uses (its constants come
//! from this group). In `identify` because the parameters are the identification's variables.
//!
//! `cargo bench -p identify --bench frf_lines`

// Benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use criterion::{criterion_group, criterion_main, Criterion};
use rfe::frf::{response, Method};

/// Direct against modal, FRF plus the Jacobian of the FWD-32J identification's parameters, from
/// 38 to 600 lines: the break-even `Method::Auto` uses.
fn lines_break_even(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = rfe::modelfile::load(&root.join("configs/models/fwd32j-initial.toml"))
        .expect("FWD-32J initial model")
        .model;
    let vars = identify::variables::load(&root.join("configs/identification/fwd32j.toml"), &model)
        .expect("variables");
    let params = vars.params();
    let mut g = c.benchmark_group("fwd32j_direct_vs_modal_by_lines");
    g.sample_size(10);
    g.measurement_time(std::time::Duration::from_secs(2));
    for lines in [38usize, 75, 114, 150, 225, 300, 600] {
        let freqs: Vec<f64> = (0..lines)
            .map(|i| 3.0 * (1000.0f64 / 3.0).powf(i as f64 / (lines - 1) as f64))
            .collect();
        for (name, method) in [("direct", Method::Direct), ("modal", Method::Modal)] {
            g.bench_with_input(criterion::BenchmarkId::new(name, lines), &freqs, |b, f| {
                b.iter(|| response(&model, f, &params, method).unwrap())
            });
        }
    }
    g.finish();
}

criterion_group!(benches, lines_break_even);
criterion_main!(benches);
