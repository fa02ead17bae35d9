//! The check on the simulated FWD-32J data: with every body's mass and inertias 20 % off
//! in the identification model (a seeded sign per body, as masses from drawings are), freeing them
//! (one `mJ` scale per body) recovers the truth within 3 standard errors, masses and stiffnesses
//! alike, while holding them leaves a biased fit; and a 10 % gain error of one characteristic is
//! recovered within 3 standard errors. Seeded.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use common::{load_model, load_variables};
use identify::{self as idn, data, variables, Identification, Options, Settings};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rfe::model::Model;

/// `fwd32j-initial.toml` with each body's mass and principal inertias scaled by 0.8 or 1.2.
fn perturbed(rng: &mut StdRng) -> (Model, Vec<f64>) {
    let mut m = load_model("fwd32j-initial.toml");
    let mut factors = Vec::new();
    for b in &mut m.bodies {
        let f = if rng.random_bool(0.5) { 1.2 } else { 0.8 };
        b.mass *= f;
        for j in &mut b.inertia {
            *j *= f;
        }
        factors.push(f);
    }
    (m, factors)
}

/// `configs/identification/fwd32j.toml`, or with `masses` `fwd32j-masses.toml` (the same and one
/// `mJ` factor per body).
fn vars_for(model: &Model, masses: bool) -> variables::Variables {
    load_variables(
        if masses {
            "fwd32j-masses.toml"
        } else {
            "fwd32j.toml"
        },
        model,
    )
}

fn fit(model: &Model, obs: &data::Observations, vars: &variables::Variables) -> Identification {
    let opts = Options {
        settings: Settings {
            max_iterations: 300,
            ..Settings::default()
        },
        ..Options::default()
    };
    idn::identify(model, obs, vars, &opts, &mut |_, _| {}).unwrap()
}

/// The truth of every variable: an SDE parameter's value in `truth`, or for a scale of a body's
/// mass and inertias, the truth's mass over the identification model's.
fn truth_of(truth: &Model, model: &Model, vars: &variables::Variables) -> Vec<f64> {
    vars.vars
        .iter()
        .map(|v| {
            let t = v.targets[0];
            match v.tie {
                variables::Tie::Scale => {
                    truth.value(t.param).unwrap() / model.value(t.param).unwrap()
                }
                // A gain is not in the model: its truth is 1 unless the test says otherwise.
                variables::Tie::Equal => truth.value(t.param).unwrap_or(t.ratio) / t.ratio,
            }
        })
        .collect()
}

#[test]
fn freeing_the_masses_recovers_fwd32j_from_masses_20_percent_off() {
    let truth = load_model("fwd32j.toml");
    let mut rng = StdRng::seed_from_u64(13);
    let (model, factors) = perturbed(&mut rng);
    assert!(
        factors.contains(&0.8) && factors.contains(&1.2),
        "{factors:?}"
    );
    let d = common::fwd32j_data(&truth, 0.01, &mut rng);
    let obs = data::validate(&d, &model, "synthetic").unwrap();

    let held = vars_for(&model, false);
    let held_id = fit(&model, &obs, &held);
    println!("masses held:\n{}", idn::report::text(&held_id));
    let held_z = common::deviations_from_truth(&held_id, &truth_of(&truth, &model, &held));

    let free = vars_for(&model, true);
    assert_eq!(free.len(), held.len() + model.bodies.len());
    let free_id = fit(&model, &obs, &free);
    println!("masses free:\n{}", idn::report::text(&free_id));
    let xt = truth_of(&truth, &model, &free);
    let free_z = common::deviations_from_truth(&free_id, &xt);

    assert!(free_id.stop.converged(), "{}", free_id.stop.describe());
    for (v, z) in free.vars.iter().zip(&free_z) {
        assert!(
            z.abs() < 3.0,
            "{}: {z:+.2} standard errors from the truth",
            v.name
        );
    }
    // Every free mass factor undoes its perturbation (the truth is 1/0.8 or 1/1.2).
    for (i, f) in factors.iter().enumerate() {
        let x = free_id.estimate[held.len() + i];
        assert!((xt[held.len() + i] * f - 1.0).abs() < 1e-12);
        assert!(x.is_finite() && x > 0.0);
    }
    // Held at the wrong values, the masses bias the stiffnesses: the fit is far worse and
    // estimates sit many standard errors from the truth.
    let worst = held_z.iter().fold(0.0f64, |a, z| a.max(z.abs()));
    assert!(
        worst > 3.0,
        "held masses left no estimate biased (worst {worst:.2} se)"
    );
    assert!(
        held_id.uncertainty.reduced_chi2 > 3.0 * free_id.uncertainty.reduced_chi2,
        "reduced chi2 held {} vs free {}",
        held_id.uncertainty.reduced_chi2,
        free_id.uncertainty.reduced_chi2
    );
}

#[test]
fn a_ten_percent_gain_error_of_one_characteristic_is_recovered_on_fwd32j() {
    let truth = load_model("fwd32j.toml");
    let initial = load_model("fwd32j-initial.toml");
    let mut rng = StdRng::seed_from_u64(31);
    let mut d = common::fwd32j_data(&truth, 0.01, &mut rng);
    let c = &mut d.characteristics[1];
    for a in &mut c.amplitude {
        *a *= 1.1;
    }
    if let Some(v) = &mut c.variance {
        for x in v {
            *x *= 1.21;
        }
    }
    let label = format!("table {}", rfe::model::DOF_NAMES[c.dof as usize]);
    let obs = data::validate(&d, &initial, "synthetic").unwrap();
    let mut text =
        std::fs::read_to_string(common::repo().join("configs/identification/fwd32j.toml")).unwrap();
    text.push_str(&format!(
        "\n[[variable]]\ncharacteristics = \"{label}\"\nparameter = \"gain\"\n"
    ));
    let vars = variables::parse(&text, "fwd32j-gain.toml", &initial).unwrap();
    let id = fit(&initial, &obs, &vars);
    println!("{}", idn::report::text(&id));
    let g = vars.len() - 1;
    let mut xt = truth_of(&truth, &initial, &vars);
    xt[g] = 1.1;
    let z = common::deviations_from_truth(&id, &xt);
    assert!(id.stop.converged(), "{}", id.stop.describe());
    assert!(
        z[g].abs() < 3.0,
        "gain {} ± {}",
        id.estimate[g],
        id.uncertainty.std_error[g]
    );
    assert!(
        id.uncertainty.std_error[g] < 0.02,
        "the gain is barely determined: se {}",
        id.uncertainty.std_error[g]
    );
    for (v, z) in vars.vars.iter().zip(&z) {
        assert!(
            z.abs() < 3.0,
            "{}: {z:+.2} standard errors from the truth",
            v.name
        );
    }
}
