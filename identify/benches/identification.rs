//! Whole FWD-32J identification (20 variables, 114 points; data from `fwd32j.toml` with 1 %
//! noise, started from the Table 1 initial values): wall time with the analytic Jacobian, and the
//! ratios to (a) the same fit with forward-difference Jacobians and (b) the Python baseline
//! `bench/python/ident_baseline.py` (numpy FRF + scipy.optimize.least_squares on the same model,
//! data and variables), measured in the same run.
//!
//! `cargo bench -p identify --bench identification` (needs python3 with numpy and scipy; the
//! baseline is skipped with a message, never silently, when they are missing).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion as Bench};
use identify::frf::{self, Method};
use identify::identification::{self as idn, data, variables, JacobianMode, Options};
use identify::measured::{MeasuredData, Measurement, QuantityName};
use identify::model::Model;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn load(name: &str) -> Model {
    identify::modelfile::load(&root().join("configs/models").join(name)).expect("FWD-32J model").model
}

fn synthetic(truth: &Model) -> MeasuredData {
    let f: Vec<f64> = (0..38).map(|i| 20.0 * 20.0f64.powf(i as f64 / 37.0)).collect();
    let r = frf::response(truth, &f, &[], Method::Auto).expect("truth solves");
    let mut rng = StdRng::seed_from_u64(32);
    MeasuredData {
        source: "bench".into(),
        characteristics: truth
            .outputs
            .iter()
            .enumerate()
            .map(|(o, c)| {
                let q: Vec<f64> = r.output(o).iter().map(|v| v.norm()).collect();
                Measurement {
                    body: truth.bodies[c.body].name.clone(),
                    dof: c.dof,
                    quantity: QuantityName::from(c.quantity),
                    freqs_hz: f.clone(),
                    amplitude: q
                        .iter()
                        .map(|a| {
                            let n: f64 = StandardNormal.sample(&mut rng);
                            a * (1.0 + 0.01 * n)
                        })
                        .collect(),
                    phase_rad: None,
                    variance: Some(q.iter().map(|a| 2.0 * (0.01 * a).powi(2)).collect()),
                    coherence: None,
                    averages: None,
                }
            })
            .collect(),
    }
}

/// The problem for the Python baseline: resolved model, observations, and per variable the
/// change of each SDE's six stiffnesses and dissipations per unit of the variable.
fn problem_json(model: &Model, obs: &data::Observations, vars: &variables::Variables) -> serde_json::Value {
    let resolved = identify::contract::to_json(model);
    let enabled: Vec<usize> = (0..model.sdes.len()).filter(|&i| model.sdes[i].enabled).collect();
    let vj: Vec<serde_json::Value> = vars
        .vars
        .iter()
        .map(|v| {
            let terms: Vec<serde_json::Value> = v
                .targets
                .iter()
                .map(|t| {
                    let (dk, dpsi) = model.sdes[t.param.sde].law.derivative(t.param.name).expect("parameter");
                    let idx = enabled.iter().position(|&i| i == t.param.sde).expect("enabled");
                    serde_json::json!({
                        "sde": idx,
                        "dk": dk.map(|x| x * t.ratio),
                        "dpsi": dpsi.map(|x| x * t.ratio),
                    })
                })
                .collect();
            serde_json::json!({
                "name": v.name, "x0": v.initial, "lower": v.lower,
                "upper": if v.upper.is_finite() { serde_json::json!(v.upper) } else { serde_json::json!(null) },
                "scale": v.scale, "terms": terms,
            })
        })
        .collect();
    let chars: Vec<serde_json::Value> = obs
        .characteristics
        .iter()
        .map(|c| {
            let mut m = model.clone();
            m.outputs = vec![c.characteristic];
            let r = frf::response(&m, &c.freqs_hz, &[], Method::Direct).expect("model solves");
            let check: Vec<f64> = r.output(0).iter().map(|v| v.norm()).collect();
            serde_json::json!({
                "check_amplitude": check,
                "body": c.characteristic.body, "dof": c.characteristic.dof,
                "freqs_hz": c.freqs_hz, "amplitude": c.amplitude,
                "sigma": c.variance.as_ref().expect("variances").iter().map(|v| (v / 2.0).sqrt()).collect::<Vec<f64>>(),
            })
        })
        .collect();
    serde_json::json!({ "model": resolved, "characteristics": chars, "variables": vj })
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
    let vars = variables::load(&root().join("configs/identification/fwd32j.toml"), &initial).expect("variables");
    let analytic = Options::default();
    let fd = Options { jacobian: JacobianMode::ForwardDifference, ..Options::default() };
    let run = |o: &Options| idn::identify(&initial, &obs, &vars, o, &mut |_, _| {}).expect("identification");

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
    std::fs::write(&problem, serde_json::to_string(&problem_json(&initial, &obs, &vars)).expect("json")).expect("write");
    let script = root().join("bench/python/ident_baseline.py");
    match Command::new("python3").arg(&script).arg(&problem).arg("--repeat").arg("3").output() {
        Ok(out) if out.status.success() => {
            let text = String::from_utf8_lossy(&out.stdout);
            let v: serde_json::Value = serde_json::from_str(text.trim()).expect("baseline prints JSON");
            let tp = v["median_s"].as_f64().expect("median_s");
            println!(
                "Python baseline (numpy FRF + scipy least_squares, 2-point Jacobian): {:.1} ms, {} function evaluations, cost {:.3}; FRF check vs ident: max rel diff {:.2e}; ratio python/ident = {:.0}",
                tp * 1e3, v["nfev"], v["cost"], v["frf_check_max_rel"].as_f64().unwrap_or(f64::NAN), tp / ta
            );
        }
        Ok(out) => println!("Python baseline FAILED: {}", String::from_utf8_lossy(&out.stderr)),
        Err(e) => println!("Python baseline NOT RUN: python3 could not be started ({e})"),
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
