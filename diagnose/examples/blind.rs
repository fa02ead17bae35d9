//! The blind suite over many cases: right effect first, exactly the injected set, false adds on
//! clean data, median wall time; then the FWD-32J demo case's time split.
//!
//! `cargo run -p diagnose --profile test --example blind -- [CASES] [FIRST_SEED] [KIND]` (default
//! 200 cases from seed 1; with KIND, e.g. `resonator`, only the cases that inject that kind). Each case: FWD-32J with one or two hidden effects (or none), 0.5-3 %
//! noise, the identification started ±30 % away (`diagnose::blind`). One case prints its
//! diagnosis; none or ten or more also the demo's time split.

// An example unwraps: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::time::Instant;

#[path = "../tests/support/blind.rs"]
mod blind;

use identify::{self as idn, data, synthetic, variables};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(200);
    let first: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(1);
    let kind = args.get(3).cloned();
    let root = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = rfe::modelfile::load(&root.join("configs/models/fwd32j.toml"))
        .expect("model")
        .model;
    let vars =
        variables::load(&root.join("configs/identification/fwd32j.toml"), &model).expect("vars");
    let lines = synthetic::fwd32j_lines();
    let opts = diagnose::Options::default();
    let mut outcomes = Vec::new();
    // Cases with effects not exactly found, by verdict.
    let mut misses: Vec<blind::Miss> = Vec::new();
    for seed in first..first + n {
        let case = blind::draw(&model, &vars, &lines, seed, None).expect("case");
        if let Some(kind) = &kind {
            if !case.injected.iter().any(|i| i.effect.kind() == kind) {
                continue;
            }
        }
        match blind::run(&model, &case, &opts) {
            Ok((o, d)) => {
                if n == 1 {
                    println!("{}", diagnose::text(&d));
                }
                let truth: Vec<String> = case
                    .injected
                    .iter()
                    .map(|i| {
                        format!(
                            "{} ({}; signal {:.0})",
                            i.effect.describe(),
                            values(&i.effect, &i.values),
                            i.signal
                        )
                    })
                    .collect();
                let added: Vec<String> = d
                    .accepted
                    .iter()
                    .map(|a| {
                        let ps: Vec<String> = a.params.iter().map(|p| p.describe()).collect();
                        format!("{} ({})", a.effect, ps.join(", "))
                    })
                    .collect();
                println!(
                    "seed {seed}: noise {:.1} %, injected [{}]; added [{}]; first {} named {} ranked {} exact {} ({:.1} s)",
                    100.0 * case.noise,
                    truth.join("; "),
                    added.join("; "),
                    o.right_first,
                    o.named_first,
                    o.ranked_first,
                    o.exact,
                    o.seconds
                );
                println!("  {}", diagnose::timing_text(&d));
                if !o.exact && !case.injected.is_empty() {
                    let starts = [d.estimate.clone(), case.vars.initial()];
                    let j = blind::truth_form(&model, &case, &starts, &opts).expect("truth's form");
                    let miss = blind::miss(d.after.criterion, j, d.after.observations);
                    println!(
                        "  not exact: the diagnosis ends at J {:.1}, the truth's own form refitted at {:.1}: {}",
                        d.after.criterion,
                        j,
                        match miss {
                            blind::Miss::CannotTell => "the data cannot tell them apart",
                            blind::Miss::Missed => "the search missed it",
                            blind::Miss::Undecided => "the truth's own refit is off the noise level too (undecided)",
                        }
                    );
                    misses.push(miss);
                }
                outcomes.push(o);
            }
            Err(e) => println!("seed {seed}: failed: {e}"),
        }
    }
    let r = blind::rates(&outcomes);
    println!(
        "\n{} cases ({} with effects, {} clean): right first {:.1} % (named first {:.1} %, ranked first {:.1} %), exact set {:.1} %, false adds on clean {:.1} %, median wall time {:.2} s per case ({:.2} s diagnosis)",
        outcomes.len(),
        r.with_effects,
        r.clean,
        100.0 * r.right_first,
        100.0 * r.named_first,
        100.0 * r.ranked_first,
        100.0 * r.exact,
        100.0 * r.false_add,
        r.median_seconds,
        r.median_diagnosis_seconds
    );
    let count = |m: blind::Miss| misses.iter().filter(|&&x| x == m).count();
    println!(
        "of the {} cases with effects not exactly found, {} end within LR {} of the truth's own form refitted (the data cannot tell them apart), {} above it (the search missed it), {} undecided (the truth's own refit is off the noise level too)",
        misses.len(),
        count(blind::Miss::CannotTell),
        diagnose::EQUIVALENT_LR,
        count(blind::Miss::Missed),
        count(blind::Miss::Undecided)
    );
    if n == 0 || n >= 10 {
        demo_split(&root);
    }
}

/// An injected effect's parameter values, named, in report units.
fn values(effect: &diagnose::Effect, v: &[f64]) -> String {
    effect
        .params(400.0)
        .iter()
        .zip(v)
        .map(|(p, x)| {
            diagnose::ParamEstimate {
                name: p.name.into(),
                unit: p.unit.into(),
                value: *x,
                std_error: 0.0,
            }
            .describe()
            .replace(" ± 0.00e0", "")
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The FWD-32J demo case (truth with the actuator, model without), seeded 1 % noise: the time of
/// the identification and of the diagnosis's parts.
fn demo_split(root: &std::path::Path) {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let truth = rfe::modelfile::load(&root.join("configs/models/fwd32j.toml"))
        .expect("truth")
        .model;
    let model = rfe::modelfile::load(&root.join("configs/models/fwd32j-no-actuator.toml"))
        .expect("model")
        .model;
    let vars = variables::load(
        &root.join("configs/identification/fwd32j-no-actuator.toml"),
        &model,
    )
    .expect("vars");
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let d = synthetic::amplitude_data(&truth, &synthetic::fwd32j_lines(), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .expect("data");
    let obs = data::validate(&d, &model, "demo").expect("data");
    let t0 = Instant::now();
    let id = idn::identify(
        &model,
        &obs,
        &vars,
        &idn::Options::default(),
        &mut |_, _| {},
    )
    .expect("identification");
    let t1 = Instant::now();
    let dg = diagnose::diagnose(
        &model,
        &obs,
        &vars,
        &id,
        &diagnose::Options::default(),
        &mut |_| {},
    )
    .expect("diagnosis");
    let t2 = Instant::now();
    println!(
        "FWD-32J demo: identification {:.2} s, diagnosis {:.2} s; added [{}]",
        (t1 - t0).as_secs_f64(),
        (t2 - t1).as_secs_f64(),
        dg.effects
            .iter()
            .map(|e| e.describe())
            .collect::<Vec<_>>()
            .join("; ")
    );
    println!("{}", diagnose::timing_text(&dg));
}
