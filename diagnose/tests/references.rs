//! Several references and base excitation: a force at another point as a second column of the
//! FRF matrix (fit on both, Cramér-Rao errors against one), and prescribed base motion (shaker
//! table) against the closed-form transmissibility of a mass on a hysteretic spring, its
//! Jacobian, and a fit of k and ψ from transmissibility data.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

#[path = "../../identify/tests/common/mod.rs"]
mod common;

use identify::{self as idn, data, NoiseChoice};
use nalgebra::Vector3;
use rfe::frf::{self, Method};
use rfe::measured::MeasuredData;
use rfe::model::{Characteristic, Excitation, Model, PointForce, Quantity, Reference};
use rfe::{textbook, C64};

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// The two-mass chain with a second reference: 1 N along z on the first body ("hammer").
fn two_references() -> Model {
    let mut m = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    m.references.push(Reference {
        name: "hammer".into(),
        excitation: Excitation::Forces(vec![PointForce {
            body: 0,
            point: m.bodies[0].position,
            force: Vector3::new(0.0, 0.0, 1.0),
            moment: Vector3::zeros(),
        }]),
    });
    m
}

/// `model`'s outputs as exact data with relative standard deviation 1 % as their variance.
fn exact(model: &Model) -> MeasuredData {
    common::exact(model, Some(0.01))
}

fn fit(model: &Model, measured: &MeasuredData) -> idn::Identification {
    common::fit_two_mass(model, measured, NoiseChoice::Variance)
}

#[test]
fn a_second_reference_is_one_more_right_hand_side_of_the_same_solve() {
    let mut m = two_references();
    let declared = m.outputs.clone();
    m.outputs.extend(
        declared
            .iter()
            .map(|c| Characteristic { reference: 1, ..*c }),
    );
    let freqs = [12.0, 31.0, 58.0];
    let both = frf::response(&m, &freqs, &[], Method::Direct).unwrap();
    // The same outputs of a model whose only excitation is the hammer's force.
    let mut alone = m.clone();
    alone.forces = match &m.references[0].excitation {
        Excitation::Forces(f) => f.clone(),
        Excitation::BaseMotion { .. } => unreachable!(),
    };
    alone.references.clear();
    alone.outputs = declared.clone();
    let hammer = frf::response(&alone, &freqs, &[], Method::Direct).unwrap();
    for method in [Method::Direct, Method::Modal] {
        let r = frf::response(&m, &freqs, &[], method).unwrap();
        for o in 0..2 {
            for k in 0..freqs.len() {
                let (a, b) = (r.output(2 + o)[k], hammer.output(o)[k]);
                assert!((a - b).norm() <= 1e-10 * b.norm(), "{method:?}: {a} vs {b}");
                let (a, b) = (r.output(o)[k], both.output(o)[k]);
                assert!((a - b).norm() <= 1e-10 * b.norm(), "{method:?}: {a} vs {b}");
            }
        }
        // Reciprocity: body 2 under the hammer on body 1 = body 1 under the force on body 2.
        for k in 0..freqs.len() {
            let (a, b) = (r.output(3)[k], r.output(0)[k]);
            assert!((a - b).norm() <= 1e-10 * b.norm(), "{method:?}: {a} vs {b}");
        }
    }
}

#[test]
fn a_fit_on_two_references_recovers_the_truth_with_smaller_errors_than_on_one() {
    let mut m = two_references();
    let one = exact(&m);
    let declared = m.outputs.clone();
    m.outputs.extend(
        declared
            .iter()
            .map(|c| Characteristic { reference: 1, ..*c }),
    );
    let two = exact(&m);
    assert_eq!(two.characteristics.len(), 4);
    assert_eq!(two.characteristics[3].reference.as_deref(), Some("hammer"));
    // The model declares its outputs under its own excitation only: the data add the rest.
    m.outputs = declared;
    let (a, b) = (fit(&m, &one), fit(&m, &two));
    for ((x1, x2), t) in a.estimate.iter().zip(&b.estimate).zip([2.0e7, 5.0e6, 0.5]) {
        assert!(
            (x1 / t - 1.0).abs() < 1e-6,
            "one reference: {:?}",
            a.estimate
        );
        assert!(
            (x2 / t - 1.0).abs() < 1e-6,
            "two references: {:?}",
            b.estimate
        );
    }
    assert_eq!(b.observations, 2 * a.observations);
    for (v, (s1, s2)) in a
        .uncertainty
        .std_error
        .iter()
        .zip(&b.uncertainty.std_error)
        .enumerate()
    {
        assert!(
            s2 < s1,
            "variable {v}: σ {s2:e} with two references, {s1:e} with one"
        );
    }
}

#[test]
fn an_unknown_reference_or_a_relative_output_under_a_force_is_an_error() {
    let m = two_references();
    let mut d = exact(&m);
    d.characteristics[0].reference = Some("shaker 3".into());
    let e = data::validate(&d, &m, "run.json").unwrap_err().to_string();
    assert!(
        e.contains("run.json")
            && e.contains("$.characteristics[0]")
            && e.contains("reference \"shaker 3\" is not one of the model's (excitation, hammer)"),
        "{e}"
    );
    let mut d = exact(&m);
    d.characteristics[1].relative = true;
    let e = data::validate(&d, &m, "run.json").unwrap_err().to_string();
    assert!(
        e.contains("$.characteristics[1]")
            && e.contains("relative: a motion relative to the base is an output under base motion"),
        "{e}"
    );
}

/// One body on a six-spring element whose ground end is a shaker table moving along z.
fn on_a_table(m: f64, k: f64, psi: f64) -> Model {
    let mut model = textbook::single_body(m, k, psi);
    model.references.push(Reference {
        name: "table".into(),
        excitation: Excitation::BaseMotion {
            direction: [0.0, 0.0, 1.0],
        },
    });
    let u3 = model.outputs[0];
    model.outputs = vec![
        Characteristic { reference: 1, ..u3 },
        Characteristic {
            reference: 1,
            relative: true,
            ..u3
        },
        Characteristic {
            reference: 1,
            quantity: Quantity::Acceleration,
            ..u3
        },
    ];
    model
}

#[test]
fn base_motion_gives_the_closed_form_transmissibility() {
    let (m, k, psi) = (250.0, 3.0e6, 0.3);
    let model = on_a_table(m, k, psi);
    let freqs = [2.0, 9.0, 17.4, 25.0, 80.0];
    for method in [Method::Direct, Method::Modal] {
        let r = frf::response(&model, &freqs, &[], method).unwrap();
        for (i, f) in freqs.iter().enumerate() {
            let w2 = (TWO_PI * f).powi(2);
            let ks = C64::new(k, k * psi / TWO_PI);
            let t = ks / (ks - w2 * m);
            let rel = w2 * m / (ks - w2 * m);
            for (o, want) in [(0, t), (1, rel), (2, -w2 * t)] {
                let got = r.output(o)[i];
                assert!(
                    (got - want).norm() <= 1e-9 * want.norm(),
                    "{method:?} output {o} at {f} Hz: {got} vs {want}"
                );
            }
        }
    }
}

/// Two masses in series on a table moving along z; outputs: the first's transmissibility, the
/// second's motion relative to the table, and the second's response to the force.
fn two_masses_on_a_table() -> Model {
    let mut model = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    model.references.push(Reference {
        name: "table".into(),
        excitation: Excitation::BaseMotion {
            direction: [0.0, 0.0, 1.0],
        },
    });
    let u3 = model.outputs.clone();
    model.outputs = vec![
        Characteristic {
            reference: 1,
            ..u3[0]
        },
        Characteristic {
            reference: 1,
            relative: true,
            ..u3[1]
        },
        u3[1],
    ];
    model
}

#[test]
fn the_jacobian_under_base_motion_matches_finite_differences() {
    let model = two_masses_on_a_table();
    let params: Vec<rfe::model::Param> = model.all_params().into_iter().map(Into::into).collect();
    assert_columns_match_central_differences(&model, &params);
}

/// Every column of the Jacobian for `params`, on both solve paths, against central differences
/// of the direct response at 14, 33 and 47 Hz.
fn assert_columns_match_central_differences(model: &Model, params: &[rfe::model::Param]) {
    common::assert_jacobian_matches_central_differences(model, params, &[14.0, 33.0, 47.0], 1e-9);
}

#[test]
fn mass_and_inertia_columns_under_base_motion_match_finite_differences() {
    use rfe::model::Param;
    let model = two_masses_on_a_table();
    let params = [
        Param::Mass { body: 0 },
        Param::Mass { body: 1 },
        Param::Inertia { body: 1, axis: 0 },
    ];
    assert_columns_match_central_differences(&model, &params);
}

#[test]
fn k_and_psi_are_identified_from_transmissibility_data() {
    let mut truth = two_masses_on_a_table();
    truth.outputs.truncate(2);
    let declared = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5).outputs;
    let d = exact(&truth);
    assert_eq!(d.characteristics[0].reference.as_deref(), Some("table"));
    assert!(d.characteristics[1].relative);
    let mut model = truth.clone();
    model.outputs = declared;
    let id = fit(&model, &d);
    for (x, t) in id.estimate.iter().zip([2.0e7, 5.0e6, 0.5]) {
        assert!((x / t - 1.0).abs() < 1e-6, "{:?}", id.estimate);
    }
    assert!(id
        .uncertainty
        .std_error
        .iter()
        .all(|s| s.is_finite() && *s > 0.0));
}

#[test]
fn a_model_file_declares_references_and_base_motion() {
    let text = String::from(common::ONE_BODY_ON_A_SPRING)
        + r#"[[reference]]
name = "side"
[[reference.force]]
body = "mass"
point = "0 0 100 mm"
force = [1.0, 0.0, 0.0]
[[reference]]
name = "table"
base_motion = [0, 0, 2]
[[output]]
body = "mass"
dof = "u3"
reference = "table"
motion = "relative"
[[output]]
body = "mass"
dofs = ["u1", "r2"]
reference = "side"
"#;
    let m = rfe::modelfile::parse_toml(&text, "table.toml")
        .unwrap()
        .model;
    assert_eq!(m.references.len(), 2);
    assert_eq!(
        m.references[1].excitation,
        Excitation::BaseMotion {
            direction: [0.0, 0.0, 1.0]
        }
    );
    let refs: Vec<(u8, bool)> = m
        .outputs
        .iter()
        .map(|c| (c.reference, c.relative))
        .collect();
    assert_eq!(refs, [(0, false), (2, true), (1, false), (1, false)]);
    // The relative transmissibility of the file's model is the closed form's.
    let r = frf::response(&m, &[10.0], &[], Method::Direct).unwrap();
    let (w2, ks) = (
        (TWO_PI * 10.0f64).powi(2),
        C64::new(3e6, 3e6 * 0.3 / TWO_PI),
    );
    let want = w2 * 250.0 / (ks - w2 * 250.0);
    assert!((r.output(1)[0] - want).norm() <= 1e-9 * want.norm());
    // JSON contract round trip.
    let back = rfe::contract::from_json(&rfe::contract::to_json(&m)).unwrap();
    assert_eq!(
        (back.references, back.outputs),
        (m.references.clone(), m.outputs.clone())
    );
    // The model file ident writes (final model) reads back to the same references and outputs,
    // a point output under a reference included.
    let mut with_point = m.clone();
    let at =
        rfe::model::PointOutput::new(Vector3::new(0.1, -0.2, 0.05), Vector3::new(0.3, 0.1, 1.0))
            .unwrap();
    with_point.outputs.push(Characteristic {
        at: Some(at),
        reference: 2,
        ..m.outputs[0]
    });
    let written = diagnose::final_model::resolved_toml(&with_point);
    let read = rfe::modelfile::parse_toml(&written, "written.toml")
        .unwrap()
        .model;
    assert_eq!(read.references, with_point.references, "{written}");
    assert_eq!(read.outputs, with_point.outputs, "{written}");

    for (bad, says) in [
        (
            text.replace(
                "reference = \"table\"\nmotion",
                "reference = \"tabel\"\nmotion",
            ),
            "no [[reference]] \"tabel\"; its references: excitation, side, table",
        ),
        (
            text.replace(
                "reference = \"side\"",
                "reference = \"side\"\nmotion = \"relative\"",
            ),
            "motion: absolute or relative motion is an output under base motion",
        ),
        (
            text.replace("base_motion = [0, 0, 2]", "base_motion = [0, 0, 0]"),
            "zero length",
        ),
        (
            text.replace("name = \"side\"", "name = \"table\""),
            "unique",
        ),
    ] {
        let e = rfe::modelfile::parse_toml(&bad, "table.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("table.toml:") && e.contains(says), "{e}");
    }
}
