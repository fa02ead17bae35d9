//! Cost of ranking every candidate effect of the FWD-32J model by the score test, against the
//! cost of one Jacobian of the identification (the yardstick) and against refitting each
//! candidate (approximated from below by one FRF evaluation per candidate, which any refit needs
//! at least once per iteration).
//!
//! `cargo bench -p diagnose --bench diagnose`

use criterion::{criterion_group, criterion_main, Criterion};
use diagnose::{generate, problem::Problem, score};
use identify::{self as idn, data, synthetic, variables, JacobianMode, Options};

fn setup() -> (rfe::Model, idn::Observations, idn::Variables, Vec<f64>) {
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let truth = rfe::modelfile::load(&root.join("configs/models/fwd32j.toml"))
        .expect("model")
        .model;
    let data =
        synthetic::amplitude_data(&truth, &synthetic::fwd32j_lines(), 0.01, || 0.0).expect("FRF");
    let vars =
        variables::load(&root.join("configs/identification/fwd32j.toml"), &truth).expect("vars");
    let obs = data::validate(&data, &truth, "bench").expect("data");
    let x: Vec<f64> = vars
        .vars
        .iter()
        .map(|v| truth.value(v.targets[0].param).unwrap_or(v.initial) / v.targets[0].ratio)
        .collect();
    (truth, obs, vars, x)
}

fn bench(c: &mut Criterion) {
    let (model, obs, vars, x) = setup();
    let opts = Options::default();
    let p = Problem::new(&model, &vars, &obs, &opts, Vec::new(), 400.0);
    let realized = p.realize(&[]).expect("realize");
    let mut crit = p.criterion(&realized).expect("criterion");
    let (e, jac) = crit
        .evaluate(&x, Some(JacobianMode::Analytic))
        .expect("evaluate");
    let jac = jac.expect("jacobian");
    let labels: Vec<String> = obs
        .characteristics
        .iter()
        .map(|c| c.label.clone())
        .collect();
    let cands = generate::candidates(&crit.model_at(&x), &vars, &x, &labels, 20.0, 400.0);
    println!(
        "FWD-32J: {} candidates, {} residuals, {} variables",
        cands.len(),
        e.len(),
        x.len()
    );
    let fit = score::FitPoint {
        crit: &crit,
        x: &x,
        gains: &realized.gains,
        e: &e,
        jac: &jac,
        sigma2: 1.0,
    };
    let mut g = c.benchmark_group("diagnose");
    g.sample_size(10);
    g.bench_function("one Jacobian (identification criterion, analytic)", |b| {
        let mut crit = p.criterion(&realized).expect("criterion");
        b.iter(|| {
            crit.evaluate(&x, Some(JacobianMode::Analytic))
                .expect("evaluate")
        })
    });
    g.bench_function("score test of every candidate", |b| {
        b.iter(|| score::score_all(&fit, &cands).expect("scores"))
    });
    g.bench_function(
        "one FRF evaluation per candidate (lower bound of refitting each)",
        |b| {
            let mut pc = Problem::new(&model, &vars, &obs, &opts, Vec::new(), 400.0);
            b.iter(|| {
                for cand in &cands {
                    pc.effects = vec![cand.clone()];
                    pc.params = cand.params(400.0);
                    let gamma: Vec<f64> = pc
                        .params
                        .iter()
                        .map(|q| if q.nested == 0.0 { q.scale } else { q.nested })
                        .collect();
                    let _ = pc.residuals(&x, &gamma, false);
                }
            })
        },
    );
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
