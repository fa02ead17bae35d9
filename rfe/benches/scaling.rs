//! Scaling of FRF + Jacobian with model size: chains of 10, 100 and 200 bodies, 2000 lines, up to
//! 100 parameters, direct vs modal path. The direct path at 100 and 200 bodies is timed on a
//! subset of lines and scaled to 2000 (its cost is exactly linear in the number of lines: one LU
//! per line); the table says so. Plain timing with medians, not criterion: one run of the direct
//! path at 200 bodies and 2000 lines would take tens of minutes.
//!
//! `cargo bench -p rfe --bench scaling`

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::time::Instant;

use rfe::frf::{response, Method};
use rfe::textbook::chain;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time(reps: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

fn main() {
    let lines = 2000;
    let freqs: Vec<f64> = (0..lines)
        .map(|i| 1.0 + 299.0 * i as f64 / (lines - 1) as f64)
        .collect();
    println!(
        "{:>7} {:>6} {:>7} {:>14} {:>14} {:>9} {:>20}",
        "bodies", "DOFs", "params", "direct [s]", "modal [s]", "ratio", "direct timed on"
    );
    for n in [10usize, 100, 200] {
        let model = chain(n);
        let params: Vec<_> = model.all_params().into_iter().take(100).collect();
        let modal = time(if n <= 10 { 5 } else { 3 }, || {
            response(&model, &freqs, &params, Method::Modal).unwrap();
        });
        let subset = match n {
            0..=10 => lines,
            11..=100 => 200,
            _ => 20,
        };
        let sub: Vec<f64> = freqs
            .iter()
            .step_by(lines / subset)
            .copied()
            .take(subset)
            .collect();
        let direct = time(3, || {
            response(&model, &sub, &params, Method::Direct).unwrap();
        }) * lines as f64
            / sub.len() as f64;
        // same answer on the subset
        let a = response(&model, &sub, &params, Method::Direct).unwrap();
        let b = response(&model, &sub, &params, Method::Modal).unwrap();
        let scale = a.values.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let err = a
            .values
            .iter()
            .zip(&b.values)
            .map(|(x, y)| (x - y).norm())
            .fold(0.0, f64::max)
            / scale;
        println!(
            "{:>7} {:>6} {:>7} {:>14.3} {:>14.3} {:>8.1}x {:>14} lines   (max rel diff {err:.1e})",
            n,
            6 * n,
            params.len(),
            direct,
            modal,
            direct / modal,
            sub.len()
        );
    }
}
