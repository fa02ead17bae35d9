//! Identification on the textbook two-mass chain: the criterion's analytic Jacobian against
//! finite differences, recovery by every optimizer, complex fits, noise models, bounds, the
//! iteration limit, multi-start, and the TOML write-back. Seeded.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use identify::{
    self as idn, data, report, variables, AtBound, Criterion, FitKind, JacobianMode, NoiseChoice,
    NoiseSource, Optimizer, Options, Settings, StopReason,
};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::frf::{self, Method};
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::model::Model;
use rfe::textbook;

fn truth() -> Model {
    textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5)
}

/// Both outputs at 40 lines over 10-60 Hz, with relative noise `rel` (0 = exact), phases,
/// variances and coherence/averages consistent with it.
fn measured(model: &Model, rel: f64, seed: u64) -> MeasuredData {
    let f: Vec<f64> = (0..40).map(|i| 10.0 + 50.0 * i as f64 / 39.0).collect();
    let r = frf::response(model, &f, &[], Method::Direct).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    MeasuredData {
        source: "textbook".into(),
        characteristics: (0..2)
            .map(|o| {
                let q = r.output(o);
                let noisy: Vec<rfe::C64> = q
                    .iter()
                    .map(|v| {
                        let a: f64 = StandardNormal.sample(&mut rng);
                        let b: f64 = StandardNormal.sample(&mut rng);
                        v + rfe::C64::new(a, b) * (rel * v.norm() / std::f64::consts::SQRT_2)
                    })
                    .collect();
                // γ² such that the H1 amplitude variance (1 − γ²)/(2 n γ²)·|z|² equals the
                // amplitude part of the complex variance, rel²|z|²/2, with n = 10.
                let n = 10u32;
                let g2 = 1.0 / (1.0 + n as f64 * rel * rel);
                Measurement {
                    body: model.bodies[model.outputs[o].body].name.clone(),
                    dof: 2,
                    quantity: QuantityName::Displacement,
                    freqs_hz: f.clone(),
                    amplitude: noisy.iter().map(|v| v.norm()).collect(),
                    phase_rad: Some(noisy.iter().map(|v| v.arg()).collect()),
                    variance: (rel > 0.0)
                        .then(|| q.iter().map(|v| (rel * v.norm()).powi(2)).collect()),
                    coherence: (rel > 0.0).then(|| vec![g2; f.len()]),
                    averages: (rel > 0.0).then_some(n),
                    at: None,
                    reference: None,
                    relative: false,
                }
            })
            .collect(),
    }
}

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm, and their common ψ at 0.3.
const VARS: &str = include_str!("../../configs/identification/textbook-two-mass-psi.toml");

fn setup(rel: f64, seed: u64) -> (Model, data::Observations, variables::Variables) {
    let m = truth();
    let d = measured(&m, rel, seed);
    let obs = data::validate(&d, &m, "textbook").unwrap();
    let vars = variables::parse(VARS, "vars.toml", &m).unwrap();
    (m, obs, vars)
}

#[test]
fn the_criterion_jacobian_matches_finite_differences() {
    let (m, obs, vars) = setup(0.02, 1);
    for fit in [FitKind::Amplitude, FitKind::LogAmplitude, FitKind::Complex] {
        let mut c =
            Criterion::new(&m, &obs, &vars, fit, NoiseChoice::Variance, Method::Direct).unwrap();
        let x = vars.initial();
        let (_, ja) = c.evaluate(&x, Some(JacobianMode::Analytic)).unwrap();
        let ja = ja.unwrap();
        // Central differences, independent of the library's forward-difference mode.
        for v in 0..x.len() {
            let h = 1e-6 * x[v];
            let mut xp = x.clone();
            xp[v] += h;
            let (ep, _) = c.evaluate(&xp, None).unwrap();
            xp[v] -= 2.0 * h;
            let (em, _) = c.evaluate(&xp, None).unwrap();
            let fd = (ep - em) / (2.0 * h);
            let col = ja.column(v);
            let err = (&fd - col).norm() / col.norm();
            assert!(err < 1e-6, "{fit:?}, variable {v}: relative error {err:e}");
        }
    }
}

/// The criterion keeps its assembled system and response buffers between evaluations: after
/// evaluations elsewhere, an evaluation equals a fresh criterion's bit for bit, and the
/// responses, residuals and error measures from one solve equal those of separate ones.
#[test]
fn a_kept_criterion_evaluates_as_a_fresh_one() {
    let (m, obs, vars) = setup(0.02, 1);
    for fit in [FitKind::Amplitude, FitKind::Complex] {
        let fresh =
            || Criterion::new(&m, &obs, &vars, fit, NoiseChoice::Variance, Method::Auto).unwrap();
        let mut kept = fresh();
        let x0 = vars.initial();
        let x1: Vec<f64> = x0.iter().map(|v| v * 1.3).collect();
        let x2: Vec<f64> = x0.iter().map(|v| v * 0.8).collect();
        kept.evaluate(&x1, Some(JacobianMode::Analytic)).unwrap();
        kept.evaluate(&x0, None).unwrap();
        let (e, j) = kept.evaluate(&x2, Some(JacobianMode::Analytic)).unwrap();
        let (ef, jf) = fresh().evaluate(&x2, Some(JacobianMode::Analytic)).unwrap();
        assert_eq!(e, ef, "{fit:?}");
        assert_eq!(j.unwrap(), jf.unwrap(), "{fit:?}");

        let (ep, jp, q) = kept.evaluate_predicted(&x1).unwrap();
        let mut other = fresh();
        assert_eq!(q, other.predicted(&x1).unwrap());
        let (e1, j1) = other.evaluate(&x1, Some(JacobianMode::Analytic)).unwrap();
        assert_eq!((ep.clone(), jp), (e1, j1.unwrap()));
        assert_eq!(kept.residuals_of_predicted(&q), ep);
        assert_eq!(
            kept.rms_relative_error_of(&q),
            other.rms_relative_error(&x1).unwrap()
        );
        assert_eq!(kept.rms_db_error_of(&q), other.rms_db_error(&x1).unwrap());
    }
}

#[test]
fn every_optimizer_recovers_exact_data() {
    let (m, obs, vars) = setup(0.0, 1);
    let xt = [2.0e7, 5.0e6, 0.5];
    for optimizer in [
        Optimizer::LevenbergMarquardt,
        Optimizer::GaussNewton,
        Optimizer::Bfgs,
    ] {
        for fit in [FitKind::Amplitude, FitKind::LogAmplitude, FitKind::Complex] {
            let opts = Options {
                optimizer,
                fit,
                settings: Settings {
                    max_iterations: 300,
                    ..Settings::default()
                },
                ..Options::default()
            };
            let mut iterations = 0;
            let id = idn::identify(&m, &obs, &vars, &opts, &mut |_, p| iterations = p.iteration)
                .unwrap();
            assert!(
                id.stop.converged(),
                "{optimizer:?} {fit:?}: {}",
                id.stop.describe()
            );
            assert_eq!(iterations, id.iterations);
            for (e, t) in id.estimate.iter().zip(xt) {
                assert!(
                    (e / t - 1.0).abs() < 1e-5,
                    "{optimizer:?} {fit:?}: {:?}",
                    id.estimate
                );
            }
            assert!(id.criterion < 1e-8 * id.criterion_initial);
            assert_eq!(
                id.noise,
                NoiseSource::Relative(0.01),
                "no variances → relative model"
            );
            assert!(id.rms.iter().all(|(_, r)| *r < 1e-6));
            assert!(
                id.rms_db.iter().all(|(_, _, db)| *db < 1e-4),
                "{:?}",
                id.rms_db
            );
        }
    }
}

/// Amplitudes with multiplicative (log-normal) noise of `rel`, and nothing else: no phases, no
/// variances, no coherence, as in a vendor file of measured magnitudes.
fn magnitudes_only(model: &Model, rel: f64, seed: u64) -> data::Observations {
    let mut d = measured(model, 0.0, seed);
    let mut rng = StdRng::seed_from_u64(seed);
    for c in &mut d.characteristics {
        for a in &mut c.amplitude {
            let n: f64 = StandardNormal.sample(&mut rng);
            *a *= (rel * n).exp();
        }
        c.phase_rad = None;
    }
    data::validate(&d, model, "magnitudes.json").unwrap()
}

#[test]
fn the_log_amplitude_fit_is_unbiased_where_the_amplitude_fit_lowers_the_peaks() {
    // 15 % multiplicative noise, σ known only relative to the level: the amplitude criterion
    // weights each point by 1/|z|², so points that came out low pull the model down and ψ up;
    // the log-amplitude criterion sees symmetric noise.
    let m = truth();
    let vars = variables::parse(VARS, "vars.toml", &m).unwrap();
    let runs = 80;
    let bias = |fit: FitKind| {
        let psi: Vec<f64> = (0..runs)
            .map(|seed| {
                let obs = magnitudes_only(&m, 0.15, 100 + seed);
                let opts = Options {
                    fit,
                    noise: NoiseChoice::Relative(0.15),
                    ..Options::default()
                };
                let id = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
                assert!(id.stop.converged(), "{fit:?}: {}", id.stop.describe());
                id.estimate[2] / 0.5 - 1.0
            })
            .collect();
        let mean = psi.iter().sum::<f64>() / runs as f64;
        let sd = (psi.iter().map(|p| (p - mean).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt();
        (mean, sd / (runs as f64).sqrt())
    };
    let (amp, amp_se) = bias(FitKind::Amplitude);
    let (log, log_se) = bias(FitKind::LogAmplitude);
    eprintln!(
        "relative ψ bias: amplitude {amp:+.4} ± {amp_se:.4}, log-amplitude {log:+.4} ± {log_se:.4}"
    );
    assert!(
        log.abs() < 3.0 * log_se,
        "log-amplitude ψ bias {log} ± {log_se}"
    );
    assert!(
        amp > 3.0 * amp_se,
        "amplitude ψ bias {amp} ± {amp_se}: expected upward"
    );
    // And the automatic choice picks the log fit for such data.
    let obs = magnitudes_only(&m, 0.1, 1);
    assert_eq!(
        FitKind::for_data(&obs, NoiseChoice::Auto),
        FitKind::LogAmplitude
    );
    let with_variances = setup(0.02, 1).1;
    assert_eq!(
        FitKind::for_data(&with_variances, NoiseChoice::Auto),
        FitKind::Amplitude
    );
}

#[test]
fn the_finite_difference_mode_gives_the_same_estimate() {
    let (m, obs, vars) = setup(0.01, 3);
    let a = idn::identify(&m, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    let fd = Options {
        jacobian: JacobianMode::ForwardDifference,
        ..Options::default()
    };
    let b = idn::identify(&m, &obs, &vars, &fd, &mut |_, _| {}).unwrap();
    for i in 0..3 {
        let se = a.uncertainty.std_error[i];
        assert!(
            (a.estimate[i] - b.estimate[i]).abs() < 1e-3 * se,
            "variable {i}"
        );
    }
    assert!(
        b.evaluations.model > a.evaluations.model,
        "finite differences cost more model evaluations"
    );
}

#[test]
fn noise_models_are_chosen_and_reported() {
    let (m, obs, vars) = setup(0.01, 5);
    let auto = idn::identify(&m, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    assert_eq!(auto.noise, NoiseSource::Variance);
    assert_eq!(auto.uncertainty.covariance_scale, 1.0);
    let coh = Options {
        noise: NoiseChoice::Coherence,
        ..Options::default()
    };
    let c = idn::identify(&m, &obs, &vars, &coh, &mut |_, _| {}).unwrap();
    assert_eq!(c.noise, NoiseSource::Coherence);
    // Coherence chosen to imply the same σ as the variances (measured |z| instead of |q|).
    for i in 0..3 {
        let r = c.uncertainty.std_error[i] / auto.uncertainty.std_error[i];
        assert!((0.9..1.1).contains(&r), "variable {i}: ratio {r}");
    }
    let rel = Options {
        noise: NoiseChoice::Relative(0.05),
        ..Options::default()
    };
    let r = idn::identify(&m, &obs, &vars, &rel, &mut |_, _| {}).unwrap();
    assert!(r.noise.scale_unknown());
    assert_eq!(r.uncertainty.covariance_scale, r.uncertainty.reduced_chi2);
    // Scaled by the residual variance, the errors do not depend on the assumed ε.
    let rel2 = Options {
        noise: NoiseChoice::Relative(0.5),
        ..Options::default()
    };
    let r2 = idn::identify(&m, &obs, &vars, &rel2, &mut |_, _| {}).unwrap();
    for i in 0..3 {
        let q = r.uncertainty.std_error[i] / r2.uncertainty.std_error[i];
        assert!((q - 1.0).abs() < 1e-6, "variable {i}: {q}");
    }
    assert!(idn::report::text(&r).contains("known only up to scale"));
}

#[test]
fn a_complex_fit_needs_phases() {
    let m = truth();
    let mut d = measured(&m, 0.01, 2);
    d.characteristics[1].phase_rad = None;
    let obs = data::validate(&d, &m, "nophase.json").unwrap();
    let vars = variables::parse(VARS, "vars.toml", &m).unwrap();
    let opts = Options {
        fit: FitKind::Complex,
        ..Options::default()
    };
    let e = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("nophase.json") && e.contains("second u3") && e.contains("phase_rad"),
        "{e}"
    );
}

#[test]
fn the_iteration_limit_keeps_the_best_point_and_says_so() {
    let (m, obs, vars) = setup(0.01, 4);
    let opts = Options {
        settings: Settings {
            max_iterations: 1,
            ..Settings::default()
        },
        ..Options::default()
    };
    let id = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    assert_eq!(id.stop, StopReason::IterationLimit);
    assert!(!id.stop.converged());
    assert!(id.criterion < id.criterion_initial);
    assert!(report::text(&id).contains("NOT converged"));
    assert!(!report::json(&id).converged);
}

#[test]
fn a_bound_below_the_truth_is_where_the_estimate_ends() {
    let (m, obs, _) = setup(0.0, 1);
    let vars = variables::parse(
        "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"14 N/um\"\nupper = \"16 N/um\"\n\
         [[variable]]\nsdes = \"k2\"\nparameter = \"k\"\ninitial = \"7 N/um\"\n",
        "bounded.toml",
        &m,
    )
    .unwrap();
    for optimizer in [
        Optimizer::LevenbergMarquardt,
        Optimizer::GaussNewton,
        Optimizer::Bfgs,
    ] {
        let opts = Options {
            optimizer,
            ..Options::default()
        };
        let id = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
        assert!(id.stop.converged(), "{optimizer:?}: {}", id.stop.describe());
        assert_eq!(id.estimate[0], 16.0e6, "{optimizer:?}");
        assert_eq!(id.uncertainty.at_bound[0], Some(AtBound::Upper));
        assert_eq!(id.uncertainty.at_bound[1], None);
        assert!(report::text(&id).contains("at upper bound"));
    }
}

#[test]
fn multiple_starts_are_seeded_and_find_the_minimum() {
    let (m, obs, vars) = setup(0.0, 1);
    let opts = Options {
        starts: 4,
        seed: 9,
        ..Options::default()
    };
    let a = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    let b = idn::identify(&m, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    assert_eq!(a.starts.len(), 4);
    assert_eq!(a.starts, b.starts, "same seed, same starts");
    assert_eq!(a.starts[0].x0, vars.initial());
    assert!(a.starts[1..].iter().all(|s| s.x0 != vars.initial()));
    assert!((a.estimate[0] / 2.0e7 - 1.0).abs() < 1e-6);
}

#[test]
fn tied_and_scaled_variables_move_their_parameters_together() {
    let m = truth();
    let d = measured(&m, 0.0, 1);
    let obs = data::validate(&d, &m, "textbook").unwrap();
    // k2 = 0.25 k1 (the truth's ratio), and one factor on both ψ.
    let tied = |model: &Model| {
        variables::parse(
            "[[variable]]\nname = \"k chain\"\nsdes = [\"k1\", \"k2\"]\nparameter = \"k\"\nratios = [1.0, 0.25]\ninitial = \"12 N/um\"\n\
             [[variable]]\nname = \"psi factor\"\nsdes = \"k1, k2\"\nparameter = \"psi\"\ntie = \"scale\"\n",
            "tied.toml",
            model,
        )
        .unwrap()
    };
    let vars = tied(&m);
    assert_eq!(vars.vars[1].initial, 1.0);
    let mut start = m.clone();
    vars.apply(&mut start, &[1.2e7, 0.6]);
    let obs2 = data::validate(&d, &start, "textbook").unwrap();
    let vars2 = tied(&start);
    let id = idn::identify(&start, &obs2, &vars2, &Options::default(), &mut |_, _| {}).unwrap();
    assert!(id.stop.converged());
    assert!(
        (id.estimate[0] / 2.0e7 - 1.0).abs() < 1e-6,
        "{:?}",
        id.estimate
    );
    assert!(
        (id.estimate[1] * 0.3 / 0.5 - 1.0).abs() < 1e-6,
        "{:?}",
        id.estimate
    );
    let k2 = id
        .model
        .param(rfe::ParamRef {
            sde: 1,
            name: rfe::ParamName::K,
        })
        .unwrap();
    assert!((k2 / 5.0e6 - 1.0).abs() < 1e-6);
    let _ = obs;
}

#[test]
fn the_updated_model_is_written_back_into_the_toml_text() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/models/textbook-two-mass.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let m = rfe::modelfile::parse_toml(&text, "two-mass.toml")
        .unwrap()
        .model;
    let d = measured(&m, 0.0, 1);
    // Start away from the file's values and fit back to them.
    let mut start = m.clone();
    start.set_param(
        rfe::ParamRef {
            sde: 0,
            name: rfe::ParamName::K,
        },
        1.4e7,
    );
    let obs = data::validate(&d, &start, "textbook").unwrap();
    let vars = variables::parse(VARS, "vars.toml", &start).unwrap();
    let id = idn::identify(&start, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    let out = report::update_toml(&text, "two-mass.toml", &id).unwrap();
    assert!(out.contains("# Textbook case"), "comments are kept");
    let back = rfe::modelfile::parse_toml(&out, "out.toml").unwrap().model;
    for v in &vars.vars {
        for t in &v.targets {
            let a = back.value(t.param).unwrap();
            let b = id.model.value(t.param).unwrap();
            assert!((a / b - 1.0).abs() < 1e-9, "{}: {a} vs {b}", v.name);
        }
    }
    // The resolved JSON of the updated model loads back to the same stiffnesses.
    let json = serde_json::to_string(&rfe::contract::to_json(&id.model)).unwrap();
    let j = rfe::modelfile::parse_json(&json, "model.json")
        .unwrap()
        .model;
    assert_eq!(j.sdes[0].law.stiffness(), id.model.sdes[0].law.stiffness());
    // The table in JSON and CSV.
    let rj = serde_json::to_value(report::json(&id)).unwrap();
    assert_eq!(rj["table"].as_array().unwrap().len(), 3);
    let csv = report::csv(&id);
    assert_eq!(csv.lines().count(), 4);
    assert!(csv.starts_with("variable,sdes,parameter,unit,initial,identified,std_error"));
}

#[test]
fn more_variables_than_observations_is_an_error() {
    let m = truth();
    let mut d = measured(&m, 0.0, 1);
    d.characteristics.truncate(1);
    for c in &mut d.characteristics {
        c.freqs_hz.truncate(2);
        c.amplitude.truncate(2);
        c.phase_rad = None;
    }
    let obs = data::validate(&d, &m, "short.json").unwrap();
    let vars = variables::parse(VARS, "vars.toml", &m).unwrap();
    let e = idn::identify(&m, &obs, &vars, &Options::default(), &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(e.contains("3 variables but only 2 observations"), "{e}");
}
