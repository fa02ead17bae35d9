//! A real report for the tests: a two-mass textbook model measured with 1 % seeded noise on the
//! amplitudes (and the exact phases), identified, with a diagnosis section and a drift history
//! attached.

#![allow(dead_code)]

use identify::{data, identify, variables, Identification, Observations, Options};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use report::document::*;
use rfe::{frf, textbook, MeasuredData, Measurement, Model};

pub struct Fixture {
    pub truth: Model,
    pub obs: Observations,
    pub id: Identification,
}

pub fn fixture(seed: u64) -> Fixture {
    let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    let freqs: Vec<f64> = (0..40)
        .map(|i| 8.0 * (80.0f64 / 8.0).powf(i as f64 / 39.0))
        .collect();
    let r = frf::response(&truth, &freqs, &[], frf::Method::Direct).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let eps = 0.01;
    let measured = MeasuredData {
        source: format!("synthetic, 1 % noise, seed {seed}"),
        characteristics: (0..2)
            .map(|o| Measurement {
                body: truth.bodies[o].name.clone(),
                dof: 2,
                quantity: rfe::measured::QuantityName::Displacement,
                freqs_hz: freqs.clone(),
                amplitude: r
                    .output(o)
                    .iter()
                    .map(|v| v.norm() + eps * v.norm() * n.sample(&mut rng))
                    .collect(),
                phase_rad: Some(r.output(o).iter().map(|v| v.arg()).collect()),
                variance: Some(
                    r.output(o)
                        .iter()
                        .map(|v| 2.0 * (eps * v.norm()).powi(2))
                        .collect(),
                ),
                coherence: None,
                averages: None,
                at: None,
                reference: None,
                relative: false,
            })
            .collect(),
    };
    let obs = data::validate(&measured, &truth, "synthetic").unwrap();
    let vars = variables::parse(
        "[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"14 N/um\"\n[[variable]]\nsdes = \"k2\"\nparameter = \"k\"\ninitial = \"7 N/um\"\n",
        "vars.toml",
        &truth,
    )
    .unwrap();
    let id = identify(&truth, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    Fixture { truth, obs, id }
}

/// `n` ranked candidates of two rounds, strongest first in each, one accepted per round: the
/// accepted one of round 1 weak enough to rank beyond the top ten by statistic.
pub fn many_candidates(n: usize) -> Vec<Candidate> {
    (0..n)
        .map(|i| {
            let round = if i < n / 2 { 1 } else { 2 };
            let accepted = i == n / 2 - 1 || i == n / 2;
            Candidate {
                round,
                name: "spring".into(),
                location: format!("candidate {i}"),
                statistic: 1000.0 / (1.0 + i as f64),
                p_value: if i == 0 { 0.0 } else { 1e-3 * i as f64 },
                accepted,
                estimate: accepted.then_some(2.5),
                std_error: accepted.then_some(0.1),
                unit: "N/um".into(),
                rms_db_before: accepted.then_some(6.0),
                rms_db_after: accepted.then_some(0.5),
            }
        })
        .collect()
}

/// A diagnosis section as the pipeline would pass it (values are illustrative inputs to the
/// renderer, not a diagnosis result).
pub fn diagnosis_section(f: &Fixture) -> Diagnosis {
    let rms: Vec<LabelledValue> =
        f.id.rms
            .iter()
            .map(|(l, v)| LabelledValue {
                label: l.clone(),
                value: *v,
            })
            .collect();
    let db: Vec<LabelledValue> = rms
        .iter()
        .map(|l| LabelledValue {
            label: l.label.clone(),
            value: 20.0 * (1.0 + l.value).log10(),
        })
        .collect();
    Diagnosis {
        candidates: vec![
            Candidate {
                round: 1,
                name: "spring".into(),
                location: "k1-body–ground".into(),
                statistic: 42.0,
                p_value: 1e-10,
                accepted: true,
                estimate: Some(0.5),
                std_error: Some(0.05),
                unit: "N/um".into(),
                rms_db_before: Some(6.0),
                rms_db_after: Some(0.5),
            },
            Candidate {
                round: 1,
                name: "joint stiffness kn".into(),
                location: "SDE k2".into(),
                statistic: 0.3,
                p_value: 0.58,
                accepted: false,
                estimate: None,
                std_error: None,
                unit: "N/um".into(),
                rms_db_before: None,
                rms_db_after: None,
            },
        ],
        before: FitQuality {
            criterion: f.id.criterion * 3.0,
            chi2_p_value: Some(1e-6),
            reduced_chi2: 3.0,
            rms_relative_error: rms.clone(),
            rms_db_error: db.clone(),
        },
        after: FitQuality {
            criterion: f.id.criterion,
            chi2_p_value: None,
            reduced_chi2: 1.0,
            rms_relative_error: rms,
            rms_db_error: db,
        },
        final_model: "two masses + spring k1-body–ground".into(),
        look_alikes: vec!["spring k1-body–ground ≡ spring k2-body–ground".into()],
        final_parameters: vec![Parameter {
            variable: f.id.variables.vars[0].name.clone(),
            sdes: "k1".into(),
            parameter: "k".into(),
            unit: "N/um".into(),
            initial: 9.0,
            identified: 10.5,
            std_error: Some(0.2),
            variability: Some(0.019),
            at_bound: None,
        }],
        final_correlation: vec![vec![Some(1.0)]],
        explained: true,
        verdict: "the model explains the data to the noise level".into(),
        not_tried: vec![NotTried {
            effect: "point mass on k2-body".into(),
            reason: "the model becomes singular".into(),
        }],
    }
}

/// A full report: every optional section present, a drift history of three earlier runs of
/// which the last moved `k1` by `shift` standard errors.
pub fn full_report(f: &Fixture, shift: f64) -> Report {
    let mut inputs = report::build::Inputs::new("two masses <test & check>", &f.obs, &f.id);
    inputs.created_utc = "2025-01-04T02:00:00Z".into();
    inputs.source.workflow = "nightly".into();
    inputs.source.model = "textbook two_in_series".into();
    inputs.source.variables = "vars.toml".into();
    inputs.source.session = Some("session.mcap".into());
    inputs.source.stand = Some("bench".into());
    inputs.source.measurement = f.obs.origin.clone();
    inputs.diagnosis = Some((diagnosis_section(f), &f.id.model));
    let mut r = report::build::build(inputs).unwrap();
    r.stability = Some(stability_section(f, &r));
    if r.identification.weak_directions.is_empty() {
        // Well-posed fixture: add one so that every field appears.
        r.identification.weak_directions.push(WeakDirection {
            combination: "0.71 k1 − 0.70 k2".into(),
            relative_std: Some(0.8),
        });
    }
    // The drift section as the history judges it (history::judge::crlb): three earlier runs,
    // the first moved back by `shift` standard errors of the difference in its first parameter.
    let runs: Vec<String> = (1..=3)
        .map(|k| format!("2025-01-0{k}T02:00:00Z"))
        .chain([r.created_utc.clone()])
        .collect();
    let parameters = r
        .identification
        .parameters
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let s = p.std_error.unwrap();
            let first = if i == 0 {
                p.identified - shift * (2.0f64).sqrt() * s
            } else {
                p.identified
            };
            let mut series = report::document::DriftSeries {
                variable: p.variable.clone(),
                unit: p.unit.clone(),
                values: vec![
                    Some(first),
                    Some(p.identified),
                    Some(p.identified),
                    Some(p.identified),
                ],
                std_errors: vec![Some(s); 4],
                deviation_sigma: None,
                alarm: false,
            };
            series.deviation_sigma = report::drift::deviation(&series, 0, 3);
            series.alarm = series.deviation_sigma.is_some_and(|d| d.abs() > 3.0);
            series
        })
        .collect();
    let d = report::Drift {
        k_sigma: 3.0,
        runs,
        baseline: 0,
        parameters,
    };
    report::drift::attach(&mut r, d);
    r
}

/// The stability section of the fixture's final model for the two-mass turning cut
/// (configs/cuts/textbook-two-mass-turning.toml), with its band from the report's covariance.
pub fn stability_section(f: &Fixture, r: &Report) -> stability::section::Stability {
    let file = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../configs/cuts/textbook-two-mass-turning.toml");
    let cut = stability::cut::load(&file).unwrap();
    let mut vars = f.id.variables.clone();
    for (v, x) in vars.vars.iter_mut().zip(&f.id.estimate) {
        v.initial = *x;
    }
    let c = stability::covariance::from_report(&serde_json::to_string(r).unwrap(), "report", &vars)
        .unwrap();
    let req = stability::Request {
        uncertainty: Some(stability::Uncertainty {
            variables: &vars,
            covariance: &c.matrix,
        }),
        ..stability::Request::new(&f.id.model, &cut)
    };
    let lobes = stability::lobes(&req).unwrap();
    stability::section::Stability::new(&cut, &lobes, None, &c.notes)
}
