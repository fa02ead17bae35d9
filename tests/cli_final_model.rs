//! The final model file end to end: the demo's report folder holds `final-model.toml`, which
//! `ident model check` accepts and whose FRF (`ident frf --json` at the measured lines) is the
//! report's final curves; and `--write-model` / `--write-vars` on `ident identify` from a resolved
//! JSON model (no TOML text to keep) write a TOML model and a variables file the next run loads.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use common::{ident, json, root, text};
use identify::synthetic;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The written numbers carry 12 significant digits (parameters within 5e-12 relative); the
/// response near the demo's lightly damped modes amplifies a parameter error by at most ~1e2,
/// so 1e-6 leaves four orders of margin while a parameter off by 1e-4 (a rounding to 4 digits,
/// a unit slip) fails.
const CURVE_TOLERANCE: f64 = 1e-6;

#[test]
fn the_demos_final_model_file_reproduces_the_reports_final_curves() {
    let dir = tempfile::tempdir().unwrap();
    let (_, report) = common::short_demo(dir.path());
    let model_file = report.join("final-model.toml");
    let toml = std::fs::read_to_string(&model_file).unwrap();
    let r = json(&report.join("report.json"));
    let d = json(&report.join("diagnosis.json"));
    let accepted = d["accepted"].as_array().unwrap();
    // The header says which fit is final; every accepted effect is an element with its origin.
    if accepted.is_empty() {
        assert!(toml.contains("the first fit is final"), "{toml}");
    } else {
        assert!(toml.contains("The first fit is\n# superseded"), "{toml}");
    }
    assert_eq!(
        toml.matches("# Added by `ident diagnose`").count(),
        accepted.len(),
        "{toml}"
    );
    // It loads: `ident model check` exits 0.
    let o = ident(&["model", "check", model_file.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // Its FRF at the measured lines is the report's final stage.
    let model = rfe::modelfile::load(&model_file).unwrap().model;
    let mut compared = 0;
    for c in r["characteristics"].as_array().unwrap() {
        let freqs = floats(&c["freqs_hz"]);
        let stage = ["diagnosed", "identified"]
            .iter()
            .find_map(|s| {
                c["stages"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|x| x["stage"] == *s)
            })
            .unwrap();
        let expected = floats(&stage["amplitude"]);
        let hz: Vec<String> = freqs.iter().map(|f| format!("{f:?}")).collect();
        let o = ident(&[
            "frf",
            model_file.to_str().unwrap(),
            "--hz",
            &hz.join(","),
            "--json",
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        let f: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let out = f["outputs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| {
                let body = x["body"].as_u64().unwrap() as usize;
                model.bodies[body].name == c["body"].as_str().unwrap()
                    && x["dof"] == c["dof"]
                    && x["quantity"] == c["quantity"]
            })
            .unwrap_or_else(|| panic!("no output for {}", c["label"]));
        let (re, im) = (floats(&out["re"]), floats(&out["im"]));
        for (k, e) in expected.iter().enumerate() {
            let a = re[k].hypot(im[k]);
            assert!(
                (a - e).abs() <= CURVE_TOLERANCE * e.abs(),
                "{} at {} Hz: final-model.toml gives {a}, the report {e}",
                c["label"],
                freqs[k]
            );
            compared += 1;
        }
    }
    assert!(compared >= 30, "compared {compared} points");
    // The next run's variables load against it.
    let vars = report.join("final-variables.toml");
    let o = ident(&[
        "identify",
        model_file.to_str().unwrap(),
        "--data",
        report.join("measured.json").to_str().unwrap(),
        "--vars",
        vars.to_str().unwrap(),
        "--max-iterations",
        "1",
    ]);
    assert!(
        matches!(o.status.code(), Some(0 | 1)),
        "the next variables must load: {}",
        text(&o)
    );
}

/// The two-mass chain's k1 and k2: in the resolved JSON every SDE is `general`, and the
/// springs' stiffness along their axis 1 (z) is `k1`.
const VARS: &str = r#"
[[variable]]
sdes = "k1"
parameter = "k1"
initial = "14 N/um"

[[variable]]
sdes = "k2"
parameter = "k1"
initial = "7 N/um"
"#;

#[test]
fn a_resolved_json_model_is_written_as_toml_and_the_next_run_starts_at_the_estimates() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let s = |path: &Path| path.to_str().unwrap().to_string();
    let o = ident(&[
        "model",
        "export",
        root()
            .join("configs/models/textbook-two-mass.toml")
            .to_str()
            .unwrap(),
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    std::fs::write(p("model.json"), &o.stdout).unwrap();
    let truth = rfe::modelfile::load(&p("model.json")).unwrap().model;
    let mut rng = StdRng::seed_from_u64(4);
    let data =
        synthetic::amplitude_data(&truth, &synthetic::log_lines(10.0, 60.0, 40), 0.01, || {
            StandardNormal.sample(&mut rng)
        })
        .unwrap();
    std::fs::write(p("data.json"), serde_json::to_string(&data).unwrap()).unwrap();
    std::fs::write(p("vars.toml"), VARS).unwrap();
    let o = ident(&[
        "identify",
        &s(&p("model.json")),
        "--data",
        &s(&p("data.json")),
        "--vars",
        &s(&p("vars.toml")),
        "--format",
        "json",
        "--write-model",
        &s(&p("final.toml")),
        "--write-vars",
        &s(&p("next.toml")),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let table: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let toml = std::fs::read_to_string(p("final.toml")).unwrap();
    assert!(toml.contains("source was JSON"), "{toml}");
    assert!(toml.contains("the first fit"), "{toml}");
    let o = ident(&["model", "check", &s(&p("final.toml"))]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // The written model holds the estimates; the next run starts there and stays.
    let back = rfe::modelfile::load(&p("final.toml")).unwrap().model;
    for row in table["table"].as_array().unwrap() {
        let name = row["sdes"].as_str().unwrap();
        let k = back
            .sdes
            .iter()
            .find(|x| x.name == name)
            .unwrap()
            .law
            .stiffness()[0];
        let x = row["identified"].as_f64().unwrap() * 1e6;
        assert!((k - x).abs() <= 1e-9 * x, "{name}: {k} vs {x}");
    }
    let o = ident(&[
        "identify",
        &s(&p("final.toml")),
        "--data",
        &s(&p("data.json")),
        "--vars",
        &s(&p("next.toml")),
        "--format",
        "json",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let next: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for (a, b) in table["table"]
        .as_array()
        .unwrap()
        .iter()
        .zip(next["table"].as_array().unwrap())
    {
        let (x, x0) = (
            a["identified"].as_f64().unwrap(),
            b["initial"].as_f64().unwrap(),
        );
        assert!((x - x0).abs() <= 1e-9 * x, "{a} then {b}");
    }
}
