//! Whole FWD-32J identification (20 variables, 114 points; data from `fwd32j.toml` with 1 %
//! noise, started from the Table 1 initial values): wall time with the analytic Jacobian, and the
//! ratios to (a) the same fit with forward-difference Jacobians and (b) the Python baseline
//! `bench/python/ident_baseline.py` (numpy FRF + scipy.optimize.least_squares on the problem
//! `identification::problem` exports: same model, data, variables, scaling, bounds and start;
//! with the same adjoint analytic Jacobian, and with scipy's 2-point differences), measured in
//! the same run. `bench/python/identify_vs_scipy.py` does the same against the `ident` binary.
//!
//! `cargo bench -p identify --bench identification` (needs python3 with numpy and scipy; the
//! baseline is skipped with a message, never silently, when they are missing).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion as Bench};
use identify::{self as idn, data, variables, JacobianMode, Options};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::measured::MeasuredData;
use rfe::model::Model;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn load(name: &str) -> Model {
    rfe::modelfile::load(&root().join("configs/models").join(name))
        .expect("FWD-32J model")
        .model
}

/// The benchmark's data: the synthetic FWD-32J measurement, 1 % noise, seed 32.
fn synthetic(truth: &Model) -> MeasuredData {
    let mut rng = StdRng::seed_from_u64(32);
    idn::synthetic::amplitude_data(truth, &idn::synthetic::fwd32j_lines(), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .expect("truth solves")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn bench(c: &mut Bench) {
    let truth = load("fwd32j.toml");
    let initial = load("fwd32j-initial.toml");
    let d = synthetic(&truth);
    let obs = data::validate(&d, &initial, "bench").expect("data");
    let vars = variables::load(&root().join("configs/identification/fwd32j.toml"), &initial)
        .expect("variables");
    let analytic = Options::default();
    let fd = Options {
        jacobian: JacobianMode::ForwardDifference,
        ..Options::default()
    };
    let run = |o: &Options| {
        idn::identify(&initial, &obs, &vars, o, &mut |_, _| {}).expect("identification")
    };

    // Same-run comparison (medians of 5).
    let time = |o: &Options| {
        median(
            (0..5)
                .map(|_| {
                    let t = Instant::now();
                    std::hint::black_box(run(o));
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        )
    };
    let a = run(&analytic);
    let f = run(&fd);
    let ta = time(&analytic);
    let tf = time(&fd);
    println!(
        "FWD-32J identification, analytic Jacobian: {:.2} ms, {} iterations, {} model evaluations ({} with Jacobian), J {:.3} -> {:.3}, {}",
        ta * 1e3, a.iterations, a.evaluations.model, a.evaluations.with_jacobian, a.criterion_initial, a.criterion, a.stop.describe()
    );
    println!(
        "FWD-32J identification, forward differences: {:.2} ms, {} iterations, {} model evaluations, J -> {:.3}; ratio fd/analytic = {:.1}",
        tf * 1e3, f.iterations, f.evaluations.model, f.criterion, tf / ta
    );
    let dir = std::env::temp_dir().join(format!("ident-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let problem = dir.join("fwd32j-problem.json");
    std::fs::write(
        &problem,
        serde_json::to_string(
            &idn::problem::to_json(&initial, &obs, &vars, &analytic).expect("problem"),
        )
        .expect("json"),
    )
    .expect("write");
    let script = root().join("bench/python/ident_baseline.py");
    for (jac, repeat) in [("analytic", "3"), ("2-point", "1")] {
        match Command::new("python3")
            .arg(&script)
            .arg(&problem)
            .args(["--repeat", repeat, "--jac", jac])
            .output()
        {
            Ok(out) if out.status.success() => {
                let text = String::from_utf8_lossy(&out.stdout);
                let v: serde_json::Value =
                    serde_json::from_str(text.trim()).expect("baseline prints JSON");
                let tp = v["median_s"].as_f64().expect("median_s");
                let cost = v["cost"].as_f64().unwrap_or(f64::NAN);
                // A ratio of wall times compares speed only when both ends are the same optimum.
                if !((cost / a.criterion - 1.0).abs() <= 1e-6) {
                    println!(
                        "Python baseline ({jac}) did NOT reach ident's optimum (J {cost:.6} against {:.6}): its time is its path, not the same fit; per evaluation: python {:.3} ms, ident {:.3} ms",
                        a.criterion,
                        tp * 1e3 / v["nfev"].as_f64().unwrap_or(f64::NAN),
                        ta * 1e3 / a.evaluations.model as f64
                    );
                }
                println!(
                    "Python baseline (numpy FRF + scipy least_squares, {jac} Jacobian): {:.1} ms, {} residual + {} Jacobian evaluations, J {:.9} (ident {:.9}); FRF check vs ident: max rel diff {:.2e}; ratio python/ident = {:.1}",
                    tp * 1e3, v["nfev"], v["njev"], v["cost"].as_f64().unwrap_or(f64::NAN), a.criterion,
                    v["frf_check_max_rel"].as_f64().unwrap_or(f64::NAN), tp / ta
                );
            }
            Ok(out) => println!(
                "Python baseline ({jac}) FAILED: {}",
                String::from_utf8_lossy(&out.stderr)
            ),
            Err(e) => println!("Python baseline NOT RUN: python3 could not be started ({e})"),
        }
    }
    let _ = std::fs::remove_dir_all(&dir);

    let mut g = c.benchmark_group("fwd32j_identification");
    g.sample_size(10);
    g.bench_function("analytic_jacobian", |b| b.iter(|| run(&analytic)));
    g.bench_function("finite_difference_jacobian", |b| b.iter(|| run(&fd)));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
