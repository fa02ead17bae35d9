//! The final model file and the next variables file (`diagnose::final_model`), round trip: a
//! diagnosis of the two-mass chain whose truth has a spring to ground the model lacks; its final
//! model written as TOML, loaded back and compared with the diagnosis's final model element by
//! element; the same for the other effect kinds the candidate library can accept (a point mass,
//! a resonator, a flexible body, a joint's own damping), realized on that model; the variables
//! file for the next run loads against the written model; a sensor gain is refused by name; a
//! diagnosis that accepted nothing writes the first fit and says so. Seeded.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;

use diagnose::effects::{Effect, Realized};
use diagnose::final_model::{self, FinalModelError, Source};
use diagnose::{self, ParamEstimate};
use identify::{self as idn, data, synthetic, variables};
use nalgebra::{Matrix3, Vector3};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::model::{Model, Sde, SdeKind, SdeLaw};

const TWO_MASS: &str = "configs/models/textbook-two-mass.toml";

/// k1 and k2 of the two-mass chain, and the ψ of both.
const VARS: &str = r#"
[[variable]]
sdes = "k1"
parameter = "k"
initial = "14 N/um"

[[variable]]
sdes = "k2"
parameter = "k"
initial = "7 N/um"

[[variable]]
name = "psi springs"
sdes = ["k1", "k2"]
parameter = "psi"
initial = 0.4
"#;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

struct Case {
    text: String,
    id: idn::Identification,
    d: diagnose::Diagnosis,
}

/// The chain's truth plus a 3 N/µm spring from the ground to `second` along z (built here,
/// independently of the diagnosis' own realization), measured with 1 % noise; identified and
/// diagnosed.
fn diagnosed() -> Case {
    let text = std::fs::read_to_string(root().join(TWO_MASS)).unwrap();
    let model = rfe::modelfile::parse_toml(&text, TWO_MASS).unwrap().model;
    let mut truth = model.clone();
    truth.sdes.push(Sde {
        name: "support".into(),
        kind: SdeKind::Spring,
        bodies: [None, Some(1)],
        point: Vector3::new(0.0, 0.0, 1.0),
        rotation: Matrix3::from_columns(&[Vector3::z(), Vector3::x(), Vector3::y()]),
        law: SdeLaw::Axial { k: 3.0e6, psi: 0.3 },
        enabled: true,
    });
    let mut rng = StdRng::seed_from_u64(7);
    let measured =
        synthetic::amplitude_data(&truth, &synthetic::log_lines(10.0, 60.0, 40), 0.01, || {
            StandardNormal.sample(&mut rng)
        })
        .unwrap();
    let vars = variables::parse(VARS, "vars.toml", &model).unwrap();
    let obs = data::validate(&measured, &model, "synthetic").unwrap();
    let opts = idn::Options::default();
    let id = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    let d = diagnose::diagnose(
        &model,
        &obs,
        &vars,
        &id,
        &diagnose::Options {
            identification: opts,
            ..diagnose::Options::default()
        },
        &mut |_| {},
    )
    .unwrap();
    Case { text, id, d }
}

/// Relative closeness of two arrays, scaled by their largest magnitude.
fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    let s = a.iter().chain(b).fold(0.0_f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .all(|(x, y)| (x - y).abs() <= tol * s.max(1e-300))
}

/// The written model, loaded back, is the final model: bodies, SDEs (ends, place, frame,
/// stiffness, dissipation to 1e-9 relative), excitation and outputs.
fn assert_same(back: &Model, fin: &Model) {
    assert_eq!(back.bodies.len(), fin.bodies.len());
    assert_eq!(back.sdes.len(), fin.sdes.len());
    for (a, b) in back.bodies.iter().zip(&fin.bodies) {
        assert_eq!(a.name, b.name);
        assert!(close(&[a.mass], &[b.mass], 1e-9), "{}: mass", a.name);
        assert!(close(&a.inertia, &b.inertia, 1e-9), "{}: inertia", a.name);
        assert!((a.position - b.position).norm() < 1e-9, "{}", a.name);
        assert!((a.rotation - b.rotation).norm() < 1e-9, "{}", a.name);
    }
    for (a, b) in back.sdes.iter().zip(&fin.sdes) {
        assert_eq!(a.name, b.name);
        assert_eq!(a.kind, b.kind, "{}", a.name);
        assert_eq!(a.bodies, b.bodies, "{}", a.name);
        assert!((a.point - b.point).norm() < 1e-9, "{}", a.name);
        assert!(
            (a.rotation.column(0) - b.rotation.column(0)).norm() < 1e-9,
            "{}",
            a.name
        );
        let (ka, kb) = (a.law.stiffness(), b.law.stiffness());
        for i in 0..6 {
            assert!(
                (ka[i] - kb[i]).abs() <= 1e-9 * kb[i].abs(),
                "{} k{}: {} vs {}",
                a.name,
                i + 1,
                ka[i],
                kb[i]
            );
        }
        assert!(
            close(&a.law.dissipation(), &b.law.dissipation(), 1e-9),
            "{}",
            a.name
        );
    }
    assert_eq!(back.forces.len(), fin.forces.len());
    for (a, b) in back.forces.iter().zip(&fin.forces) {
        assert_eq!(a.body, b.body);
        assert!((a.force - b.force).norm() <= 1e-9 * b.force.norm());
    }
    assert_eq!(back.outputs, fin.outputs);
}

/// Writes the final model and the next variables file of `d`, checks both load and that the
/// model is `d.model`; returns the texts.
fn round_trip(c: &Case, d: &diagnose::Diagnosis) -> (String, String) {
    let source = Source {
        origin: TWO_MASS,
        text: Some(&c.text),
    };
    let text = final_model::model_toml(source, &c.id, Some(d)).unwrap();
    println!("{text}");
    let back = rfe::modelfile::parse_toml(&text, "final.toml")
        .unwrap_or_else(|e| panic!("{e}\n{text}"))
        .model;
    assert_same(&back, &d.model);
    let vars = final_model::variables_toml("final.toml", &c.id, Some(d)).unwrap();
    let next =
        variables::parse(&vars, "next.toml", &back).unwrap_or_else(|e| panic!("{e}\n{vars}"));
    // The original variables start at the final estimates.
    for (v, x) in c.id.variables.vars.iter().zip(&d.estimate) {
        let n = next.vars.iter().find(|n| n.name == v.name).unwrap();
        assert!(
            (n.initial - x).abs() <= 1e-9 * x.abs(),
            "{}: {} vs {x}",
            v.name,
            n.initial
        );
    }
    (text, vars)
}

/// `d` with its accepted effects replaced by `effect` at parameters `gamma`, realized on the
/// identified model at the diagnosis' estimates as `diagnose` realizes its final model.
fn accepting(c: &Case, effect: Effect, gamma: &[f64]) -> diagnose::Diagnosis {
    let mut d = c.d.clone();
    let mut r = Realized {
        model: c.id.model.clone(),
        vars: c.id.variables.clone(),
        gains: vec![1.0; c.id.model.outputs.len()],
    };
    effect.apply(&mut r, gamma, 60.0).unwrap();
    r.vars.apply(&mut r.model, &d.estimate);
    let template = d.accepted.first().cloned().unwrap();
    let params = effect.params(60.0);
    d.accepted = vec![diagnose::Refit {
        effect: effect.describe(),
        kind: effect.kind().into(),
        params: params
            .iter()
            .zip(gamma)
            .map(|(p, g)| ParamEstimate {
                name: p.name.into(),
                unit: p.unit.into(),
                value: *g,
                std_error: 0.01 * g.abs(),
            })
            .collect(),
        ..template
    }];
    d.effects = vec![effect];
    d.model = r.model;
    d
}

#[test]
fn the_final_model_file_is_the_diagnosed_model_for_every_effect_kind() {
    let c = diagnosed();
    // The diagnosis finds the support: a spring to ground.
    assert_eq!(c.d.accepted.len(), 1, "{}", diagnose::text(&c.d));
    assert_eq!(c.d.accepted[0].kind, "spring");
    let (text, vars) = round_trip(&c, &c.d);
    // The original's comments are kept, the values written back, the spring appended with where
    // it came from.
    assert!(
        text.contains("# Textbook case: two masses in series"),
        "{text}"
    );
    assert!(
        text.contains("`ident diagnose` added 1 effect(s)"),
        "{text}"
    );
    // (An earlier round may accept a stand-in that the backward check removes later.)
    let round =
        c.d.rounds
            .iter()
            .position(|r| {
                r.accepted
                    .is_some_and(|k| r.refits[k].effect == c.d.accepted[0].effect)
            })
            .unwrap()
            + 1;
    let origin = format!(
        "# Added by `ident diagnose`, round {round}: {}",
        c.d.accepted[0].effect
    );
    assert!(
        text.contains(&origin),
        "{origin}\n{text}\n{}",
        diagnose::text(&c.d)
    );
    assert!(text.contains("likelihood-ratio test: LR"), "{text}");
    assert!(text.contains("kind = \"spring\""), "{text}");
    assert!(!text.contains("20260"), "date-free: {text}");
    // The spring's k and ψ are variables of the next run, at their estimates.
    let k = c.d.accepted[0].params[0].value;
    let back = rfe::modelfile::parse_toml(&text, "final.toml")
        .unwrap()
        .model;
    let next = variables::parse(&vars, "next.toml", &back).unwrap();
    let kv = next
        .vars
        .iter()
        .find(|v| v.name.starts_with("k diagnosed spring"))
        .unwrap_or_else(|| panic!("{vars}"));
    assert!((kv.initial - k).abs() <= 1e-9 * k, "{} vs {k}", kv.initial);

    // A point mass on `second`, a resonator on `first`, the chain's `second` not rigid.
    let mass = Effect::Mass {
        body: "second".into(),
        point: Vector3::new(0.05, 0.1, 1.2),
        scale: 10.0,
    };
    let (text, _) = round_trip(&c, &accepting(&c, mass, &[12.5]));
    assert!(text.contains("name = \"diagnosed mass 1\""), "{text}");
    assert!(text.contains("mass = \"12.5 kg\""), "{text}");
    let resonator = Effect::Resonator {
        body: "first".into(),
        point: Vector3::new(0.1, 0.0, 0.2),
        freq_hz: 35.0,
        tuning: [30.0, 40.0],
        scale: 10.0,
    };
    round_trip(&c, &accepting(&c, resonator, &[4.0, 33.3]));
    let flexible = Effect::Flexible {
        body: "second".into(),
        axis: 0,
        scale: 1e-8,
    };
    let (text, _) = round_trip(&c, &accepting(&c, flexible, &[2e-9]));
    assert!(text.contains("Split by `ident diagnose`"), "{text}");
    // A joint's own damping: k2 leaves the ψ group, with a variable of its own next time.
    let damping = Effect::Damping {
        variable: 2,
        variable_name: "psi springs".into(),
        sdes: vec!["k2".into()],
        parameter: rfe::ParamName::Psi,
        value: c.id.estimate[2],
    };
    let (_, vars) = round_trip(&c, &accepting(&c, damping, &[0.9]));
    assert!(vars.contains("name = \"psi k2\""), "{vars}");
    // A direction k1's axial law leaves out, freed: a parallel general element carrying that one
    // stiffness, its k2 a variable next time.
    let left_out = Effect::Direction {
        sde: "k1".into(),
        axis: 1,
        held: 0.0,
        psi: 0.2,
        scale: 1e6,
    };
    let (text, vars) = round_trip(&c, &accepting(&c, left_out, &[3.0e5]));
    assert!(text.contains("name = \"k1 freed k2 1\""), "{text}");
    assert!(vars.contains("parameter = \"k2\""), "{vars}");
    // A direction guide 2 holds stiff, made compliant: its own k4 written in place.
    let held = Effect::Direction {
        sde: "guide 2".into(),
        axis: 3,
        held: 1.0e6,
        psi: 0.1,
        scale: 1e6,
    };
    let (text, _) = round_trip(&c, &accepting(&c, held, &[1.0e-6]));
    assert!(
        text.contains("500000"),
        "k4 = 1/(1/1e6 + 1e-6) = 5e5: {text}"
    );
    // `second` 20 % heavier: its mass and inertias written back, mJ a variable next time.
    let body = Effect::BodyMass {
        body: "second".into(),
        mass: 120.0,
    };
    let (text, vars) = round_trip(&c, &accepting(&c, body, &[144.0]));
    assert!(text.contains("mass = \"144 kg\""), "{text}");
    assert!(text.contains("\"14.4 kg m^2\""), "{text}");
    assert!(vars.contains("parameter = \"mJ\""), "{vars}");
}

#[test]
fn a_sensor_gain_is_refused_by_name_and_nothing_accepted_writes_the_first_fit() {
    let c = diagnosed();
    let gain = Effect::Gain {
        output: 1,
        label: "second u3 displacement".into(),
    };
    let d = accepting(&c, gain, &[0.02]);
    let source = Source {
        origin: TWO_MASS,
        text: Some(&c.text),
    };
    match final_model::model_toml(source, &c.id, Some(&d)) {
        Err(e @ FinalModelError::NotExpressible { .. }) => {
            assert!(e.to_string().contains("gain error of second u3"), "{e}")
        }
        other => panic!("a gain must be refused: {other:?}"),
    }
    // Nothing accepted: the first fit is final, and the header says so.
    let mut none = c.d.clone();
    none.accepted.clear();
    none.effects.clear();
    none.model = c.id.model.clone();
    none.estimate = c.id.estimate.clone();
    let (text, _) = round_trip(&c, &none);
    assert!(text.contains("accepted no effect"), "{text}");
    assert!(text.contains("the first fit is final"), "{text}");
    // A resolved JSON model (no text): written whole from the resolved model.
    let json = Source {
        origin: "model.json",
        text: None,
    };
    let text = final_model::model_toml(json, &c.id, Some(&c.d)).unwrap();
    assert!(text.contains("source was JSON"), "{text}");
    let back = rfe::modelfile::parse_toml(&text, "final.toml")
        .unwrap()
        .model;
    assert_same(&back, &c.d.model);
}
