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
            freq_std_hz: None,
            loss_factor: Some(m.loss_factor),
            loss_factor_std: None,
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

/// One 2 kg body held at its centre of mass by three springs along x, y and z whose stiffnesses
/// one variable sets in the ratios 1 : 2 : 3, and a ψ shared by them: the three translation modes
/// have `λ_k = r_k x / m` exactly, so the frequency match is linear in ln x and its weighted
/// least-squares answer is known in closed form. The rotations have stiffness only from a general
/// element with no translational part and are not seen at the outputs (u1, u2, u3).
const THREE_SPRINGS: &str = r#"
name = "a body on three springs"
[[body]]
name = "mass"
mass = "2 kg"
position = [0.0, 0.0, 0.0]
inertia = "1 1 1 kg m^2"
[[sde]]
name = "x"
kind = "spring"
bodies = ["ground", "mass"]
point = [0.0, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]
k = "1e5 N/m"
psi = 0.02
[[sde]]
name = "y"
kind = "spring"
bodies = ["ground", "mass"]
point = [0.0, 0.0, 0.0]
axis = [0.0, 1.0, 0.0]
k = "2e5 N/m"
psi = 0.02
[[sde]]
name = "z"
kind = "spring"
bodies = ["ground", "mass"]
point = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
k = "3e5 N/m"
psi = 0.02
[[sde]]
name = "rotations"
kind = "general"
bodies = ["ground", "mass"]
point = [0.0, 0.0, 0.0]
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
k = ["0 N/m", "0 N/m", "0 N/m", "1e3 N*m/rad", "1e3 N*m/rad", "1e3 N*m/rad"]
psi = 0.02
[[excitation.force]]
body = "mass"
force = [1.0, 1.0, 1.0]
[[output]]
body = "mass"
dof = "u1"
[[output]]
body = "mass"
dof = "u2"
[[output]]
body = "mass"
dof = "u3"
"#;

const THREE_SPRINGS_VARS: &str = r#"
[[variable]]
name = "k"
sdes = ["x", "y", "z"]
parameter = "k"
ratios = [1.0, 2.0, 3.0]
initial = "1e5 N/m"
[[variable]]
name = "psi"
sdes = ["x", "y", "z"]
parameter = "psi"
"#;

/// The true stiffness of the three-springs body's x spring (the start is 1e5 N/m).
const X_TRUE: f64 = 1.3e5;

/// The three-springs body's measured modes at [`X_TRUE`], the third `shift` times its true
/// frequency, with relative frequency standard deviations `rel_std` (`None`: not known).
fn three_spring_modes(shift: f64, rel_std: [Option<f64>; 3]) -> Vec<MeasuredMode> {
    (0..3)
        .map(|k| {
            let f = ((k + 1) as f64 * X_TRUE / 2.0).sqrt() / (2.0 * std::f64::consts::PI);
            let f = if k == 2 { f * shift } else { f };
            MeasuredMode {
                freq_hz: f,
                freq_std_hz: rel_std[k].map(|s| s * f),
                loss_factor: None,
                loss_factor_std: None,
                shape: None,
            }
        })
        .collect()
}

/// The weighted least-squares answer of the frequency match in closed form: ln λ_k = ln x +
/// const, so ln x̂ = ln x₀ + Σ w_k 2 ln(f_k/f_k(x₀)) / Σ w_k.
fn closed_form(pre: &identify::prefit::Prefit, x0: f64, weights: &[f64]) -> f64 {
    let (num, den) = pre
        .pairs
        .iter()
        .zip(weights)
        .fold((0.0, 0.0), |(n, d), (p, w)| {
            (
                n + w * 2.0 * (p.measured_hz / p.model_hz_before).ln(),
                d + w,
            )
        });
    x0 * (num / den).exp()
}

#[test]
fn an_uncertain_mode_with_a_wrong_frequency_pulls_the_start_less_than_the_sharp_ones() {
    let model = rfe::modelfile::parse_toml(THREE_SPRINGS, "three-springs.toml")
        .unwrap()
        .model;
    let vars = variables::parse(THREE_SPRINGS_VARS, "vars.toml", &model).unwrap();
    let x0 = vars.initial()[0];
    let tau = identify::prefit::MODEL_FORM_LOG_FREQ_STD;
    // The third mode 10 % off, its frequency known to 10 %; the other two sharp (0.01 %).
    let uncertain = three_spring_modes(1.1, [Some(1e-4), Some(1e-4), Some(0.1)]);
    let pre = modal_prefit(&model, &vars, &uncertain).unwrap();
    eprintln!("{pre:?}");
    let var = |s: f64| s * s + tau * tau;
    let w = [1.0, 1.0, var(1e-4) / var(0.1)];
    for (p, want) in pre.pairs.iter().zip(w) {
        assert!((p.weight - want).abs() < 1e-12, "{p:?} want weight {want}");
    }
    assert!(
        (pre.pairs[2].sigma_log_freq - (0.1f64).hypot(tau)).abs() < 1e-12,
        "{:?}",
        pre.pairs[2]
    );
    let x = pre.start[0];
    let want = closed_form(&pre, x0, &w);
    assert!((x / want - 1.0).abs() < 1e-6, "x {x} vs closed form {want}");
    assert!(
        (x / X_TRUE - 1.0).abs() < 0.01,
        "the start follows the two sharp modes: x {x} vs truth {X_TRUE}"
    );

    // Equal σ: the unweighted match (the plain mean of the log ratios), whatever the σ.
    let equal = three_spring_modes(1.1, [Some(0.1); 3]);
    let pre_equal = modal_prefit(&model, &vars, &equal).unwrap();
    let plain = closed_form(&pre_equal, x0, &[1.0; 3]);
    assert!(pre_equal.pairs.iter().all(|p| p.weight == 1.0));
    assert!(
        (pre_equal.start[0] / plain - 1.0).abs() < 1e-6,
        "{} vs {plain}",
        pre_equal.start[0]
    );
    assert!(
        pre_equal.start[0] / X_TRUE - 1.0 > 0.05,
        "equally weighted, the wrong mode moves the start: {}",
        pre_equal.start[0]
    );
    // σ not known: the same iterates as with equal σ.
    let unknown = three_spring_modes(1.1, [None; 3]);
    let pre_unknown = modal_prefit(&model, &vars, &unknown).unwrap();
    assert_eq!(pre_unknown.start, pre_equal.start);
    assert_eq!(pre_unknown.iterations, pre_equal.iterations);
}

#[test]
fn psi_starts_at_the_inverse_variance_mean_of_the_loss_factors() {
    let model = rfe::modelfile::parse_toml(THREE_SPRINGS, "three-springs.toml")
        .unwrap()
        .model;
    let vars = variables::parse(THREE_SPRINGS_VARS, "vars.toml", &model).unwrap();
    let with_eta = |etas: [(f64, Option<f64>); 3]| -> Vec<MeasuredMode> {
        three_spring_modes(1.0, [Some(1e-4); 3])
            .into_iter()
            .zip(etas)
            .map(|(m, (eta, std))| MeasuredMode {
                loss_factor: Some(eta),
                loss_factor_std: std,
                ..m
            })
            .collect()
    };
    let two_pi = 2.0 * std::f64::consts::PI;
    // Two sharp loss factors that agree and one ten times larger known only to ±75 %: the
    // between-mode spread is within the uncertain one's σ, so the inverse-variance mean follows
    // the sharp two.
    let pre = modal_prefit(
        &model,
        &vars,
        &with_eta([
            (0.004, Some(1e-4)),
            (0.0041, Some(1e-4)),
            (0.04, Some(0.03)),
        ]),
    )
    .unwrap();
    let eta = pre.loss_factor.unwrap();
    eprintln!("{eta:?}");
    let (w1, w3) = (1.0 / 1e-8, 1.0 / 9e-4);
    let want = (w1 * 0.004 + w1 * 0.0041 + w3 * 0.04) / (2.0 * w1 + w3);
    assert!((eta.value - want).abs() < 1e-12, "{eta:?} vs {want}");
    assert_eq!(eta.between_modes_std, 0.0);
    assert!((pre.start[1] - two_pi * want).abs() < 1e-12);
    // Equal σ: the plain mean, as without σ.
    let plain = (0.004 + 0.0041 + 0.04) / 3.0;
    for std in [Some(1e-3), None] {
        let pre = modal_prefit(
            &model,
            &vars,
            &with_eta([(0.004, std), (0.0041, std), (0.04, std)]),
        )
        .unwrap();
        let eta = pre.loss_factor.unwrap();
        assert!((eta.value - plain).abs() < 1e-15, "{std:?}: {eta:?}");
        assert!(pre.pairs.iter().all(|p| p.loss_factor_weight == Some(1.0)));
    }
    // Sharp loss factors that disagree far beyond their σ: modes that really differ, so the
    // between-mode spread dominates and the mean tends to the plain one.
    let pre = modal_prefit(
        &model,
        &vars,
        &with_eta([
            (0.004, Some(1e-6)),
            (0.008, Some(1e-5)),
            (0.012, Some(1e-6)),
        ]),
    )
    .unwrap();
    let eta = pre.loss_factor.unwrap();
    assert!(eta.between_modes_std > 0.003, "{eta:?}");
    assert!((eta.value / 0.008 - 1.0).abs() < 0.01, "{eta:?}");
}

#[test]
fn a_negative_or_nan_standard_deviation_is_an_error_naming_the_mode() {
    let model = rfe::modelfile::parse_toml(THREE_SPRINGS, "three-springs.toml")
        .unwrap()
        .model;
    let vars = variables::parse(THREE_SPRINGS_VARS, "vars.toml", &model).unwrap();
    let err = modal_prefit(
        &model,
        &vars,
        &three_spring_modes(1.0, [Some(1e-4), Some(-1e-4), None]),
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .contains("mode 1 has frequency standard deviation"),
        "{err}"
    );
}
