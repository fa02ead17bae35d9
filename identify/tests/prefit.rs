//! The modal pre-fit as a start for the FRF fit: on the three-storey example's model form with
//! synthetic data, a start far from the truth (storey stiffnesses 10× off in opposite directions)
//! ends the log-amplitude fit at a wrong optimum; the pre-fit from the truth's modes (frequencies
//! and loss factors, as a modal extraction of the data gives them) brings the same start to the
//! truth.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use identify::prefit::{modal_prefit, with_start, MeasuredMode};
use identify::{self as idn, data, synthetic, variables, FitKind, Options};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::model::Model;

fn example() -> Model {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples/real-three-storey/model.toml");
    rfe::modelfile::load(&path).unwrap().model
}

/// The storey stiffnesses 10× off in opposite directions and ψ 12× (the example's far start).
const VARS: &str = include_str!("../../examples/real-three-storey/far-start.toml");

const TRUTH: [f64; 4] = [37.0e3, 47.5e3, 42.1e3, 0.03];

#[test]
fn a_start_from_the_measured_modes_reaches_the_truth_where_the_naive_start_does_not() {
    let model = example();
    let vars = variables::parse(VARS, "vars.toml", &model).unwrap();
    let mut truth = model.clone();
    vars.apply(&mut truth, &TRUTH);
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    let lines = synthetic::log_lines(3.0, 40.0, 200);
    let measured =
        synthetic::amplitude_data(&truth, &lines, 0.01, || StandardNormal.sample(&mut rng))
            .unwrap();
    // Data without variances: the log-amplitude fit a vendor file gets.
    let mut measured = measured;
    for c in &mut measured.characteristics {
        c.variance = None;
    }
    let obs = data::validate(&measured, &model, "synthetic").unwrap();
    let opts = Options {
        fit: FitKind::LogAmplitude,
        ..Options::default()
    };
    let err = |x: &[f64]| -> f64 {
        x.iter()
            .zip(&TRUTH)
            .map(|(a, b)| (a / b - 1.0).abs())
            .fold(0.0, f64::max)
    };

    let naive = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    eprintln!(
        "naive: {:?}, J {}, largest relative error {:.3}",
        naive.estimate,
        naive.criterion,
        err(&naive.estimate)
    );
    assert!(
        err(&naive.estimate) > 0.2,
        "the premise: the naive start misses the truth"
    );

    // The measured modes: the truth's complex modes in the band (an ideal modal extraction).
    let modes: Vec<MeasuredMode> = rfe::modes::complex(&truth)
        .unwrap()
        .into_iter()
        .filter(|m| m.freq_hz > 3.0 && m.freq_hz < 40.0)
        .map(|m| MeasuredMode {
            freq_hz: m.freq_hz,
            loss_factor: Some(m.loss_factor),
            shape: None,
        })
        .collect();
    assert_eq!(modes.len(), 3, "three sway modes in the band");
    let pre = modal_prefit(&model, &vars, &modes).unwrap();
    eprintln!("pre-fit: {:?}", pre);
    assert!(
        pre.rms_log_freq.1 < 1e-3,
        "frequencies matched: {:?}",
        pre.rms_log_freq
    );
    for p in &pre.pairs {
        assert!(
            (p.model_hz_after / p.measured_hz - 1.0).abs() < 1e-3,
            "{p:?}"
        );
    }
    let from_modes = idn::identify(
        &model,
        &obs,
        &with_start(&vars, &pre.start),
        &opts,
        &mut |_, _| {},
    )
    .unwrap();
    eprintln!(
        "from the pre-fit: {:?}, J {}, largest relative error {:.4}",
        from_modes.estimate,
        from_modes.criterion,
        err(&from_modes.estimate)
    );
    assert!(from_modes.criterion < naive.criterion);
    for (i, (x, t)) in from_modes.estimate.iter().zip(TRUTH).enumerate() {
        let se = from_modes.uncertainty.std_error[i];
        assert!(
            (x - t).abs() < 4.0 * se,
            "variable {i}: {x} vs truth {t} (σ {se})"
        );
    }
}
