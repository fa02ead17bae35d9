//! A UFF58b file with two references (the model's 4 kN excitation on the second body and a 250 N
//! hammer on the first) and sensors off the principal-axis lines, written with ident's UFF
//! writer: the measurement map names each file reference as one of the model's and each channel
//! as a point output; the mapped data equal the model's point outputs under each reference, the
//! fit uses both, and the map's mistakes are errors naming the file, line and field.
#![allow(clippy::unwrap_used, missing_docs)]

use identify::{self as idn, data, measurement_map, variables, Options};
use process::uff;
use process::C64;
use rfe::frf::{self, Method};
use rfe::model::{Characteristic, Excitation, Model, PointForce, PointOutput, Quantity, Reference};
use rfe::textbook;

const VARS: &str = include_str!("../../configs/identification/textbook-two-mass-psi.toml");

const MAP: &str = r#"
unit = "m/N"

[[reference]]
node = 9
dir = "+Z"

[[reference]]
node = 8
dir = "+Z"
name = "hammer"

[[channel]]
node = 11
dir = "+Z"
body = "first"
point = "120 -40 30 mm"
direction = [0.2, 0.1, 1]

[[channel]]
node = 12
dir = "+Z"
body = "second"
point = "-80 60 1000 mm"
"#;

/// The chain, a 4 kN excitation on body 2 and a 250 N hammer on body 1.
fn model() -> Model {
    let mut m = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    m.forces[0].force *= 4000.0;
    m.references.push(Reference {
        name: "hammer".into(),
        excitation: Excitation::Forces(vec![PointForce {
            body: 0,
            point: m.bodies[0].position,
            force: nalgebra::Vector3::new(0.0, 0.0, 250.0),
            moment: nalgebra::Vector3::zeros(),
        }]),
    });
    m
}

/// The two sensors of [`MAP`] under reference `reference`.
fn sensors(m: &Model, reference: u8) -> Vec<Characteristic> {
    [
        (0, [0.12, -0.04, 0.03], [0.2, 0.1, 1.0]),
        (1, [-0.08, 0.06, 1.0], [0.0, 0.0, 1.0]),
    ]
    .into_iter()
    .map(|(body, p, d)| {
        let at = PointOutput::new(p.into(), d.into()).unwrap();
        Characteristic {
            body,
            dof: at.nearest_axis(&m.bodies[body]).0,
            quantity: Quantity::Displacement,
            at: Some(at),
            reference,
            relative: false,
        }
    })
    .collect()
}

fn lines() -> Vec<f64> {
    (0..40).map(|i| 10.0 + 1.25 * i as f64).collect()
}

/// The truth's receptances per N of both sensors under both references, as UFF58b.
fn uff_bytes(m: &Model) -> Vec<u8> {
    let f = lines();
    let mut truth = m.clone();
    truth.outputs = [sensors(m, 0), sensors(m, 1)].concat();
    let r = frf::response(&truth, &f, &[], Method::Direct).unwrap();
    let mut sets = Vec::new();
    for (o, c) in truth.outputs.iter().enumerate() {
        let per_newton = if c.reference == 0 { 4000.0 } else { 250.0 };
        let h: Vec<C64> = r.output(o).iter().map(|z| z / per_newton).collect();
        let reference_node = if c.reference == 0 { 9 } else { 8 };
        sets.push(uff::Function::frf_between(
            "two references",
            f.clone(),
            h,
            (11 + c.body as i64, 3),
            (reference_node, 3),
        ));
    }
    uff::to_bytes(&sets, uff::Encoding::Binary).unwrap()
}

fn channels(m: &Model) -> Vec<rfe::channel::MeasuredChannel> {
    let file = uff::parse_file(&uff_bytes(m), "mimo.uff").unwrap();
    uff::measured_channels(&file, "mimo.uff").unwrap().0
}

#[test]
fn two_references_and_off_axis_sensors_map_onto_the_model_and_fit() {
    let m = model();
    let chans = channels(&m);
    assert_eq!(chans.len(), 4);
    let map = measurement_map::parse(MAP, "map.toml", &m).unwrap();
    let d = map.apply(&chans, "mimo.uff", &m).unwrap();
    assert_eq!(d.characteristics.len(), 4, "{}", d.source);
    assert!(
        d.source
            .contains("reference node 8 +Z is the model's hammer"),
        "{}",
        d.source
    );
    // Each mapped FRF is the model's point output under its reference, to the model's forces.
    let with = data::with_measured_outputs(&m, &d);
    let obs = data::validate(&d, &with, "mimo.uff").unwrap();
    let f = lines();
    for (i, o) in obs.characteristics.iter().enumerate() {
        let mut one = with.clone();
        one.outputs = vec![o.characteristic];
        let want = frf::response(&one, &f, &[], Method::Direct).unwrap();
        let refs = if i < 2 { 0 } else { 1 };
        assert_eq!(o.characteristic.reference, refs, "{}", o.label);
        assert!(o.characteristic.at.is_some(), "{}", o.label);
        for k in 0..f.len() {
            let got = C64::from_polar(o.amplitude[k], o.phase_rad.as_ref().unwrap()[k]);
            let w = want.output(0)[k];
            assert!(
                (got - w).norm() <= 1e-12 * w.norm(),
                "{} line {k}: {got} vs {w}",
                o.label
            );
        }
    }
    let vars = variables::parse(VARS, "vars.toml", &with).unwrap();
    let id = idn::identify(&with, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    assert!(id.stop.converged(), "{}", id.stop.describe());
    for (e, t) in id.estimate.iter().zip([2.0e7, 5.0e6, 0.5]) {
        assert!((e / t - 1.0).abs() < 1e-6, "{:?}", id.estimate);
    }
    assert_eq!(id.observations, 4 * f.len());
}

#[test]
fn a_maps_references_are_checked_against_the_file_and_the_model() {
    let m = model();
    let chans = channels(&m);
    let parse = |t: &str| {
        measurement_map::parse(t, "map.toml", &m)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    // A reference the model does not have.
    let e = parse(&MAP.replace("name = \"hammer\"", "name = \"hamer\""));
    assert!(
        e.starts_with("map.toml:11:8: reference.name: the model has no [[reference]] \"hamer\"; its references: excitation, hammer"),
        "{e}"
    );
    // Base-motion output on a model without base excitation.
    let e = parse(&MAP.replace(
        "name = \"hammer\"",
        "name = \"hammer\"\nmotion = \"relative\"",
    ));
    assert!(
        e.starts_with("map.toml:12:10: reference.motion:") && e.contains("not one"),
        "{e}"
    );
    // A body that does not exist, a zero direction.
    let e = parse(&MAP.replace("body = \"second\"", "body = \"third\""));
    assert!(
        e.starts_with("map.toml:23:8: body: the model has no body \"third\""),
        "{e}"
    );
    let e = parse(&MAP.replace("direction = [0.2, 0.1, 1]", "direction = [0, 0, 0]"));
    assert!(
        e.starts_with("map.toml:18:13: direction: the zero vector"),
        "{e}"
    );
    // A reference the file does not hold.
    let map = measurement_map::parse(&MAP.replace("node = 8", "node = 7"), "map.toml", &m).unwrap();
    let e = map.apply(&chans, "mimo.uff", &m).unwrap_err().to_string();
    assert!(
        e.starts_with("map.toml:9:")
            && e.contains("mimo.uff holds no FRFs of reference node 7 +Z; its references: node 8 +Z, node 9 +Z"),
        "{e}"
    );
    // Without [[reference]]s, two references are an error that says how to name them.
    let single = MAP
        .split("[[channel]]")
        .skip(1)
        .fold(String::from("unit = \"m/N\"\n"), |s, c| {
            s + "[[channel]]" + c
        });
    let map = measurement_map::parse(&single, "map.toml", &m).unwrap();
    let e = map.apply(&chans, "mimo.uff", &m).unwrap_err().to_string();
    assert!(
        e.contains("2 references (node 8 +Z, node 9 +Z)") && e.contains("[[reference]]"),
        "{e}"
    );
}
