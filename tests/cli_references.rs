//! `ident identify` on a UFF58b file with two references (the model's excitation and a hammer on
//! the other body) and sensors off the principal-axis lines, through a measurement map naming
//! both references and point outputs: it runs, uses both, and prints the recovered stiffnesses.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::{ident, identify_mapped, p, root, utf8, TWO_MASS};

use process::uff;
use rfe::frf::{self, Method};
use rfe::model::{Characteristic, PointOutput, Quantity};

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm.
const VARS: &str = include_str!("../configs/identification/textbook-two-mass.toml");

/// The two-mass model with a second reference: 1 N along z on the first body.
const HAMMER: &str = r#"
[[reference]]
name = "hammer"
[[reference.force]]
body = "first"
point = [0.0, 0.0, 0.0]
force = [0.0, 0.0, 1.0]
"#;

const MAP: &str = r#"
unit = "m/N"

[[reference]]
node = 1
dir = "+Z"

[[reference]]
node = 2
dir = "+Z"
name = "hammer"

[[channel]]
node = 11
dir = "+Z"
body = "first"
point = "150 -50 20 mm"
direction = [0.1, 0.3, 1]

[[channel]]
node = 12
dir = "+Z"
body = "second"
point = "-90 40 1000 mm"
"#;

#[test]
fn identify_fits_two_references_of_point_outputs_from_a_uff_file() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join(TWO_MASS)).unwrap() + HAMMER;
    let model_path = dir.path().join("two-mass-hammer.toml");
    std::fs::write(&model_path, &text).unwrap();
    let mut truth = rfe::modelfile::parse_toml(&text, "model").unwrap().model;
    let sensors = [
        (0, [0.15, -0.05, 0.02], [0.1, 0.3, 1.0]),
        (1, [-0.09, 0.04, 1.0], [0.0, 0.0, 1.0]),
    ];
    truth.outputs = (0..2u8)
        .flat_map(|reference| {
            sensors.iter().map(move |&(body, pt, d)| {
                let at = PointOutput::new(pt.into(), d.into()).unwrap();
                Characteristic {
                    body,
                    dof: 2,
                    quantity: Quantity::Displacement,
                    at: Some(at),
                    reference,
                    relative: false,
                }
            })
        })
        .collect();
    let f: Vec<f64> = (0..40).map(|i| 10.0 + 1.25 * i as f64).collect();
    let r = frf::response(&truth, &f, &[], Method::Direct).unwrap();
    let sets: Vec<uff::Function> = truth
        .outputs
        .iter()
        .enumerate()
        .map(|(o, c)| {
            uff::Function::frf_between(
                "mimo",
                f.clone(),
                r.output(o).to_vec(),
                (11 + c.body as i64, 3),
                (1 + i64::from(c.reference), 3),
            )
        })
        .collect();
    let data = dir.path().join("mimo.uff");
    uff::write(&data, &sets, uff::Encoding::Binary).unwrap();
    let map = dir.path().join("map.toml");
    std::fs::write(&map, MAP).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let identify = |extra: &[&str]| identify_mapped(&model_path, &data, &map, &vars, extra);
    let o = identify(&["--format", "json"]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("reference node 2 +Z is the model's hammer"),
        "{err}"
    );
    let j: serde_json::Value = serde_json::from_str(&utf8(&o.stdout)).unwrap();
    let table = j["table"].as_array().unwrap();
    assert_eq!(table.len(), 2, "{j}");
    for (row, truth) in table.iter().zip([20.0, 5.0]) {
        let v = row["identified"].as_f64().unwrap();
        assert!((v / truth - 1.0).abs() < 1e-6, "{row}");
    }
    // The plain run prints the result table with both stiffnesses, and writes the identified
    // model with the measured point outputs under both references.
    let written = dir.path().join("identified.toml");
    let o = identify(&["--write-model", p(&written)]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let back = rfe::modelfile::load(&written).unwrap().model;
    let points: Vec<(u8, bool)> = back
        .outputs
        .iter()
        .filter(|c| c.at.is_some())
        .map(|c| {
            (
                c.reference,
                c.at == truth.outputs[usize::from(c.reference) * 2 + c.body].at,
            )
        })
        .collect();
    assert_eq!(points, [(0, true), (0, true), (1, true), (1, true)]);
    let out = utf8(&o.stdout);
    assert!(
        out.contains("k1") && out.contains("k2") && out.contains("20"),
        "{out}"
    );
}

#[test]
fn frf_prints_point_outputs_and_references_as_csv_columns_and_json() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join(TWO_MASS)).unwrap()
        + HAMMER
        + "\n[[output]]\nbody = \"first\"\npoint = \"150 -50 20 mm\"\ndirection = [0.1, 0.3, 1]\nreference = \"hammer\"\n";
    let model = dir.path().join("points.toml");
    std::fs::write(&model, &text).unwrap();
    let o = ident(&["frf", p(&model), "--hz", "10,20"]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let out = utf8(&o.stdout);
    let rows: Vec<Vec<&str>> = out.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 3, "{out}");
    assert!(rows.iter().all(|r| r.len() == 1 + 4 * 3), "{out}");
    assert!(
        rows[0][9].starts_with("first_at_(150;-50;20)_mm_along_")
            && rows[0][9].ends_with("/_hammer_re"),
        "{out}"
    );
    let o = ident(&["frf", p(&model), "--hz", "10", "--json"]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let j: serde_json::Value = serde_json::from_str(&utf8(&o.stdout)).unwrap();
    let third = &j["outputs"][2];
    assert_eq!(third["reference"], 1, "{j}");
    assert_eq!(third["at"]["point"][0], 0.15, "{j}");
}
