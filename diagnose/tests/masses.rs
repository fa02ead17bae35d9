//! Masses, principal inertias, scale factors and sensor gains as decision variables: their
//! analytic Jacobian against finite differences (frequency response and criterion), a textbook
//! case where mass and stiffness are both identified, the identifiability warning when they
//! cannot be separated, and the variables file's errors. Seeded.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "../../identify/tests/common/mod.rs"]
mod common;

use identify::{
    self as idn, data, synthetic, variables, Criterion, FitKind, JacobianMode, NoiseChoice, Options,
};
use rfe::frf::{response_params, Method};
use rfe::model::{Characteristic, Model, Param, Quantity};
use rfe::textbook;

/// The three-body chain with rotated bodies and joints, all six DOFs of its last body and an
/// acceleration of its first as outputs: every inertia couples into every output.
fn coupled() -> Model {
    let mut m = textbook::chain(3);
    m.outputs = (0..6)
        .map(|dof| Characteristic::dof(2, dof, Quantity::Displacement))
        .collect();
    m.outputs
        .push(Characteristic::dof(0, 1, Quantity::Acceleration));
    m
}

fn inertia_params(m: &Model) -> Vec<Param> {
    (0..m.bodies.len())
        .flat_map(|body| {
            std::iter::once(Param::Mass { body })
                .chain((0..3).map(move |axis| Param::Inertia { body, axis }))
        })
        .collect()
}

#[test]
fn mass_and_inertia_jacobian_matches_finite_differences_on_both_paths() {
    let model = coupled();
    let freqs = [0.5, 3.0, 9.0, 21.0, 47.0, 130.0];
    let params = inertia_params(&model);
    let direct = response_params(&model, &freqs, &params, Method::Direct).unwrap();
    let modal = response_params(&model, &freqs, &params, Method::Modal).unwrap();
    for (pi, &p) in params.iter().enumerate() {
        let x0 = model.value(p).unwrap();
        // A enters affinely in each inertia; a 1e-4 relative step and Richardson extrapolation
        // leave a truncation error far below the tolerance; a wrong sign or ω power is off by 1.
        let h = 1e-4 * x0;
        let eval = |x: f64| {
            let mut m = model.clone();
            assert!(m.set_value(p, x));
            rfe::frf::response(&m, &freqs, &[], Method::Direct).unwrap()
        };
        let (up, down) = (eval(x0 + h), eval(x0 - h));
        let (up2, down2) = (eval(x0 + h / 2.0), eval(x0 - h / 2.0));
        for o in 0..model.outputs.len() {
            let an = direct.derivative(pi, o);
            let scale = an.iter().map(|v| v.norm()).fold(0.0, f64::max);
            assert!(scale > 0.0, "{} moves nothing", model.label(p));
            for (k, an_k) in an.iter().enumerate() {
                let d1 = (up.output(o)[k] - down.output(o)[k]) / (2.0 * h);
                let d2 = (up2.output(o)[k] - down2.output(o)[k]) / h;
                let fd = (d2 * 4.0 - d1) / 3.0;
                let tol =
                    1e-6 * an_k.norm() + 1e-11 * direct.output(o)[k].norm() / h + 1e-9 * scale;
                assert!(
                    (fd - an_k).norm() <= tol,
                    "{} output {o} line {k}: fd {fd} analytic {an_k}",
                    model.label(p)
                );
                let md = modal.derivative(pi, o)[k];
                assert!(
                    (md - an_k).norm() <= 1e-8 * scale,
                    "{} output {o} line {k}: modal {md} direct {an_k}",
                    model.label(p)
                );
            }
        }
    }
}

#[test]
fn a_gain_is_not_a_model_parameter_of_the_frequency_response() {
    let model = coupled();
    let err = response_params(
        &model,
        &[10.0],
        &[Param::Gain { body: 2, dof: 0 }],
        Method::Auto,
    )
    .unwrap_err();
    assert!(err.to_string().contains("gain block 2 u1"), "{err}");
}

fn two_mass() -> Model {
    textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5)
}

/// Exact or noisy amplitude data of every output of `truth` at `lines`, output `gained`'s
/// amplitudes multiplied by `gain`.
fn data_of(
    truth: &Model,
    lines: &[f64],
    rel: f64,
    seed: u64,
    (gained, gain): (usize, f64),
) -> rfe::MeasuredData {
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut d =
        synthetic::amplitude_data(truth, lines, rel, || StandardNormal.sample(&mut rng)).unwrap();
    if rel == 0.0 {
        // Exact data: no variances (σ from a relative level).
        for c in &mut d.characteristics {
            c.variance = None;
        }
    }
    for a in &mut d.characteristics[gained].amplitude {
        *a *= gain;
    }
    if let Some(v) = &mut d.characteristics[gained].variance {
        for x in v {
            *x *= gain * gain;
        }
    }
    d
}

const SCALE_AND_GAIN: &str = r#"
[[variable]]
sdes = "isolator 0"
parameter = "kn"
initial = "6 N/um"

[[variable]]
name = "first block"
bodies = "block 0"
parameter = "mJ"
initial = 1.1

[[variable]]
bodies = "block 2"
parameter = "J1"

[[variable]]
bodies = "block 1"
parameter = "m"
initial = "210 kg"

[[variable]]
characteristics = "block 2 u1"
parameter = "gain"
initial = 0.95
"#;

#[test]
fn criterion_jacobian_of_scale_inertia_and_gain_matches_finite_differences() {
    let truth = coupled();
    let d = data_of(
        &truth,
        &synthetic::log_lines(5.0, 80.0, 30),
        0.02,
        3,
        (0, 1.1),
    );
    let vars = variables::parse(SCALE_AND_GAIN, "vars.toml", &truth).unwrap();
    assert_eq!(vars.vars[1].targets.len(), 4, "m, J1-J3 of the first body");
    assert_eq!(vars.vars[1].tie, variables::Tie::Scale);
    assert_eq!(vars.vars[2].unit.symbol, "kg·m²");
    let x = vars.initial();
    for fit in [FitKind::Amplitude, FitKind::LogAmplitude, FitKind::Complex] {
        let noise = if fit == FitKind::Complex {
            NoiseChoice::Relative(0.02)
        } else {
            NoiseChoice::Variance
        };
        let d = if fit == FitKind::Complex {
            let mut d = d.clone();
            for c in &mut d.characteristics {
                c.phase_rad = Some(vec![0.1; c.freqs_hz.len()]);
            }
            d
        } else {
            d.clone()
        };
        let obs = data::validate(&d, &truth, "synthetic").unwrap();
        let mut c = Criterion::new(&truth, &obs, &vars, fit, noise, Method::Direct).unwrap();
        let (_, ja) = c.evaluate(&x, Some(JacobianMode::Analytic)).unwrap();
        let (_, jf) = c
            .evaluate(&x, Some(JacobianMode::ForwardDifference))
            .unwrap();
        let (ja, jf) = (ja.unwrap(), jf.unwrap());
        for v in 0..vars.len() {
            let (a, f) = (ja.column(v), jf.column(v));
            let rel = (a - f).norm() / a.norm();
            assert!(
                a.norm() > 0.0,
                "{fit:?}: {} has no effect",
                vars.vars[v].name
            );
            assert!(
                rel < 1e-4,
                "{fit:?}: {}: analytic vs forward difference differ by {rel:e}",
                vars.vars[v].name
            );
        }
    }
}

/// Mass `m`, stiffness `k3` and ψ3 of the single body along z, optionally its sensor gain.
fn single_vars(gain: bool) -> String {
    let mut s = String::from(
        r#"
[[variable]]
bodies = "mass"
parameter = "m"
initial = "100 kg"

[[variable]]
sdes = "spring"
parameter = "k3"
initial = "1.3 N/um"

[[variable]]
sdes = "spring"
parameter = "psi3"
initial = 0.3
"#,
    );
    if gain {
        s.push_str("\n[[variable]]\ncharacteristics = \"mass u3\"\nparameter = \"gain\"\n");
    }
    s
}

/// The single body's mass (kg), stiffness (N/m) and ψ.
const SINGLE_BODY: (f64, f64, f64) = (80.0, 2.0e6, 0.4);

/// The single body and its amplitude data (relative noise `rel`, seeded) at 60 log-spaced lines
/// from a tenth of its resonance (the spring line) to ten times it (the mass line).
fn single_body_data(rel: f64, seed: u64) -> (Model, rfe::MeasuredData) {
    let (m, k, psi) = SINGLE_BODY;
    let truth = textbook::single_body(m, k, psi);
    let f0 = (k / m).sqrt() / (2.0 * std::f64::consts::PI);
    let lines = synthetic::log_lines(f0 / 10.0, 10.0 * f0, 60);
    let d = data_of(&truth, &lines, rel, seed, (0, 1.0));
    (truth, d)
}

#[test]
fn mass_and_stiffness_of_one_body_are_both_identified_from_exact_receptance() {
    let (m, k, psi) = SINGLE_BODY;
    let (truth, d) = single_body_data(0.0, 1);
    // The identification model starts 25 % heavy and 35 % stiff.
    let obs = data::validate(&d, &truth, "exact").unwrap();
    let vars = variables::parse(&single_vars(false), "vars.toml", &truth).unwrap();
    assert_eq!(vars.vars[0].unit.symbol, "kg");
    let id = common::identify_at_one_percent_noise(&truth, &obs, &vars);
    let (m_hat, k_hat, psi_hat) = (id.estimate[0], id.estimate[1], id.estimate[2]);
    assert!((m_hat / m - 1.0).abs() < 1e-6, "m {m_hat} vs {m}");
    assert!((k_hat / k - 1.0).abs() < 1e-6, "k {k_hat} vs {k}");
    assert!((psi_hat / psi - 1.0).abs() < 1e-6, "psi {psi_hat} vs {psi}");
    assert!(id.uncertainty.weak.is_empty(), "{:?}", id.uncertainty.weak);
    // The identified model carries the mass.
    assert!((id.model.bodies[0].mass / m - 1.0).abs() < 1e-6);
    // The report names it in kg.
    let text = idn::report::text(&id);
    let row = text
        .lines()
        .find(|l| l.starts_with("m mass"))
        .unwrap_or_else(|| panic!("no mass row in\n{text}"));
    assert!(row.contains("kg") && row.contains("80.000"), "{row}");
}

#[test]
fn mass_stiffness_and_gain_together_are_reported_as_not_separable() {
    // Scaling m, k and the gain together leaves g/(k(1 + jψ/2π) − ω²m) unchanged: the data can
    // never separate them, whatever the band. The identifiability warning must say so.
    let (truth, d) = single_body_data(0.01, 5);
    let obs = data::validate(&d, &truth, "noisy").unwrap();
    let vars = variables::parse(&single_vars(true), "vars.toml", &truth).unwrap();
    let id = idn::identify(&truth, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    println!("{}", idn::report::text(&id));
    let weak = id
        .uncertainty
        .weak
        .first()
        .unwrap_or_else(|| panic!("no identifiability warning:\n{}", idn::report::text(&id)));
    let names: Vec<&str> = weak.components.iter().map(|(n, _)| n.as_str()).collect();
    for want in ["m mass", "k3 spring", "gain mass u3"] {
        assert!(names.contains(&want), "{want} not in {names:?}");
    }
    assert!(idn::report::text(&id).contains("poorly identifiable"));
}

fn error_of(text: &str, model: &Model) -> String {
    variables::parse(text, "masses.toml", model)
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_mass_inertia_and_gain_variables_name_file_line_field_and_fix() {
    let model = two_mass();
    for (text, says) in [
        (
            "[[variable]]\nbodies = \"third\"\nparameter = \"m\"\n",
            &["masses.toml:2", "unknown body \"third\"", "first, second"][..],
        ),
        (
            "[[variable]]\nbodies = \"first\"\nparameter = \"J4\"\n",
            &["masses.toml:3", "J1, J2, J3"],
        ),
        (
            "[[variable]]\nbodies = \"first\"\nparameter = \"m\"\nlower = \"0 kg\"\n",
            &["masses.toml:4", "lower bound 0 kg", "give lower > 0"],
        ),
        (
            "[[variable]]\nbodies = \"first\"\nparameter = \"J2\"\ninitial = \"-3 kg m^2\"\n",
            &["masses.toml:4", "must be > 0"],
        ),
        (
            "[[variable]]\ncharacteristics = \"second u7\"\nparameter = \"gain\"\n",
            &["masses.toml:2", "characteristics", "u1 u2 u3 r1 r2 r3"],
        ),
        (
            "[[variable]]\ncharacteristics = \"saddle u1\"\nparameter = \"gain\"\n",
            &["unknown body \"saddle\""],
        ),
        (
            "[[variable]]\nsdes = \"k1\"\nbodies = \"first\"\nparameter = \"m\"\n",
            &["more than one of"],
        ),
        (
            "[[variable]]\nbodies = \"first\"\nparameter = \"m\"\n[[variable]]\nbodies = [\"second\", \"first\"]\nparameter = \"mJ\"\n",
            &["masses.toml:5", "already set by variable \"m first\""],
        ),
    ] {
        let e = error_of(text, &model);
        for want in says {
            assert!(e.contains(want), "{e}");
        }
    }

    // A gain on a characteristic the model has but the data do not.
    let d = data_of(
        &model,
        &synthetic::log_lines(5.0, 50.0, 10),
        0.0,
        1,
        (0, 1.0),
    );
    let mut only_first = d.clone();
    only_first.characteristics.truncate(1);
    let obs = data::validate(&only_first, &model, "first only").unwrap();
    let vars = variables::parse(
        "[[variable]]\ncharacteristics = \"second u3\"\nparameter = \"gain\"\n",
        "masses.toml",
        &model,
    )
    .unwrap();
    let err = Criterion::new(
        &model,
        &obs,
        &vars,
        FitKind::Amplitude,
        NoiseChoice::Relative(0.01),
        Method::Auto,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("masses.toml"), "{err}");
    assert!(err.contains("second u3"), "{err}");
    assert!(err.contains("remove the variable"), "{err}");
}

#[test]
fn diagnose_works_with_mass_and_gain_variables_and_offers_no_gain_already_free() {
    // The truth's first body is 15 % heavier and its output 8 % hot; the model's mass and that
    // gain are variables, so the diagnosis has nothing to add and must not offer that gain again.
    let model = two_mass();
    let mut truth = two_mass();
    truth.bodies[0].mass *= 1.15;
    let d = data_of(
        &truth,
        &synthetic::log_lines(8.0, 120.0, 50),
        0.01,
        17,
        (0, 1.08),
    );
    let obs = data::validate(&d, &model, "synthetic").unwrap();
    let text = "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\n\
                [[variable]]\nsdes = \"k2\"\nparameter = \"k\"\n\
                [[variable]]\nbodies = \"first\"\nparameter = \"m\"\n\
                [[variable]]\ncharacteristics = \"first u3\"\nparameter = \"gain\"\n";
    let vars = variables::parse(text, "vars.toml", &model).unwrap();
    let opts = Options::default();
    let id = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    let d = diagnose::diagnose(
        &model,
        &obs,
        &vars,
        &id,
        &diagnose::Options::default(),
        &mut |_| {},
    )
    .unwrap();
    assert!(d.accepted.is_empty(), "{}", diagnose::text(&d));
    assert_eq!(d.estimate.len(), vars.len());
    // Nothing accepted: the identification's errors stand.
    assert!(d.std_error.is_empty());
    for (i, want) in [(2, 460.0), (3, 1.08)] {
        let (x, se) = (d.estimate[i], id.uncertainty.std_error[i]);
        assert!(
            (x - want).abs() < 3.0 * se,
            "{}: {x} ± {se} vs {want}",
            vars.vars[i].name
        );
    }
    let offered: Vec<&str> = d
        .rounds
        .iter()
        .flat_map(|r| r.ranked.iter().map(|c| c.effect.as_str()))
        .collect();
    assert!(!offered.is_empty());
    assert!(
        offered
            .iter()
            .all(|e| !e.contains("gain error of first u3")),
        "{offered:?}"
    );
    // The other characteristic's gain is still a candidate.
    assert!(
        offered
            .iter()
            .any(|e| e.contains("gain error of second u3")),
        "{offered:?}"
    );
    // The next variables file keeps the mass and the gain and loads again.
    let next = diagnose::final_model::variables_toml("model.toml", &id, Some(&d)).unwrap();
    assert!(next.contains("bodies = [\"first\"]"), "{next}");
    assert!(next.contains("characteristics = [\"first u3\"]"), "{next}");
    let back = variables::parse(&next, "next.toml", &model).unwrap();
    assert_eq!(back.len(), vars.len());
    assert!((back.vars[3].initial - d.estimate[3]).abs() < 1e-9);
}

#[test]
fn a_calibrated_level_separates_mass_and_stiffness_even_around_one_resonance() {
    // Force and sensor calibrated (no gain variable): the absolute level of the response fixes
    // k and m even from a band of ±10 % around the resonance, only more correlated than over a
    // band with the stiffness and mass lines. (Started near the truth: from far away a band
    // without the resonance in it has other minima.)
    let (m, k, psi) = (80.0, 2.0e6, 0.4);
    let truth = textbook::single_body(m, k, psi);
    let f0 = (k / m).sqrt() / (2.0 * std::f64::consts::PI);
    let near = single_vars(false)
        .replace("100 kg", "81 kg")
        .replace("1.3 N/um", "2.01 N/um")
        .replace("0.3\n", "0.41\n");
    let vars = variables::parse(&near, "vars.toml", &truth).unwrap();
    let mut rho = Vec::new();
    for (lo, hi) in [(0.9, 1.1), (0.1, 10.0)] {
        let d = data_of(
            &truth,
            &synthetic::log_lines(lo * f0, hi * f0, 60),
            0.01,
            5,
            (0, 1.0),
        );
        let obs = data::validate(&d, &truth, "noisy").unwrap();
        let id = idn::identify(&truth, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
        let u = &id.uncertainty;
        println!(
            "band {lo}-{hi} f0: m {:.3} ± {:.3} kg, k {:.5e} ± {:.3e} N/m, correlation {:.4}",
            id.estimate[0],
            u.std_error[0],
            id.estimate[1],
            u.std_error[1],
            u.correlation[(0, 1)]
        );
        assert!(u.weak.is_empty(), "{:?}", u.weak);
        assert!(u.std_error[0] < 0.01 * m && u.std_error[1] < 0.01 * k);
        assert!((id.estimate[0] - m).abs() < 3.0 * u.std_error[0]);
        rho.push(u.correlation[(0, 1)].abs());
    }
    assert!(rho[0] > 0.99 && rho[0] > rho[1], "{rho:?}");
}
