//! `ident diagnose` end to end: the paper's case (the hydraulic actuator missing from the model)
//! from a data file, and bad options.

use std::path::PathBuf;
use std::process::Command;

use identify::synthetic;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn ident() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ident"))
}

/// Table characteristics of the full FWD-32J model (with its actuator), 1 % noise, stated variances.
fn write_data(path: &std::path::Path) {
    let truth = rfe::modelfile::load(&root().join("configs/models/fwd32j.toml"))
        .expect("model")
        .model;
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let data = synthetic::amplitude_data(&truth, &synthetic::fwd32j_lines(), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .expect("FRF");
    std::fs::write(path, serde_json::to_string(&data).expect("json")).expect("write data");
}

#[test]
fn diagnose_finds_the_missing_actuator_from_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("measured.json");
    write_data(&data);
    let json = dir.path().join("diagnosis.json");
    let out = ident()
        .current_dir(root())
        .args([
            "diagnose",
            "configs/models/fwd32j-no-actuator.toml",
            "--vars",
            "configs/identification/fwd32j-no-actuator.toml",
        ])
        .arg("--data")
        .arg(&data)
        .arg("--json")
        .arg(&json)
        .arg("--write-model")
        .arg(dir.path().join("final.toml"))
        .arg("--write-vars")
        .arg(dir.path().join("next.toml"))
        .arg("--out")
        .arg(dir.path().join("report"))
        .args(["--cut", "configs/cuts/fwd32j-face-milling.toml"])
        .output()
        .expect("run ident");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout:\n{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("added: spring spindle head–"), "{stdout}");
    assert!(stdout.contains("error before → after"), "{stdout}");
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json written"))
            .expect("valid JSON");
    assert_eq!(d["accepted"][0]["kind"], "spring");
    assert_eq!(d["before"]["explained"], false);
    assert_eq!(d["after"]["explained"], true);
    assert!(
        d["rounds"][0]["candidates"].as_u64().unwrap_or(0) > 500,
        "hundreds of candidates: {}",
        d["rounds"][0]["candidates"]
    );
    // --write-model: the final model as TOML with the actuator as a spring SDE, which loads and
    // is the diagnosis's; --write-vars: the next run's variables, which load against it.
    let toml = std::fs::read_to_string(dir.path().join("final.toml")).expect("final model");
    assert!(toml.contains("# Added by `ident diagnose`"), "{toml}");
    let fin = rfe::modelfile::parse_toml(&toml, "final.toml")
        .expect("the final model loads")
        .model;
    let spring = fin
        .sdes
        .iter()
        .find(|s| s.name == "diagnosed spring 1")
        .expect("the actuator as an SDE");
    let k = d["accepted"][0]["params"][0]["value"]
        .as_f64()
        .unwrap_or(0.0);
    assert!(
        (spring.law.stiffness()[0] - k).abs() <= 1e-9 * k,
        "{:?} vs {k}",
        spring.law
    );
    let vars = std::fs::read_to_string(dir.path().join("next.toml")).expect("next variables");
    let next =
        identify::variables::parse(&vars, "next.toml", &fin).expect("the next variables load");
    assert!(
        next.vars.iter().any(|v| v.name == "k diagnosed spring 1"),
        "{vars}"
    );
    // --out: the report with its diagnosis section, the final model's curves and modes.
    let r: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("report/report.json")).expect("report.json"),
    )
    .expect("valid JSON");
    assert_eq!(r["source"]["workflow"], "diagnose");
    let candidates = r["diagnosis"]["candidates"].as_array().expect("candidates");
    assert!(candidates.len() > 10 && candidates.iter().any(|c| c["accepted"] == true));
    let stages = r["characteristics"][0]["stages"]
        .as_array()
        .expect("stages");
    let diagnosed = stages
        .iter()
        .find(|s| s["stage"] == "diagnosed")
        .expect("diagnosed stage");
    assert!(
        diagnosed["dense"]["freqs_hz"]
            .as_array()
            .map_or(0, Vec::len)
            >= 400
    );
    assert!(r["natural_frequencies"]
        .as_array()
        .expect("natural_frequencies")
        .iter()
        .any(|m| m["stage"] == "diagnosed" && !m["modes"].as_array().expect("modes").is_empty()));
    // The final fit's correlation: square over the final table, unit diagonal, symmetric, and
    // not the first fit's (the actuator changed the fit).
    let fc = r["diagnosis"]["final_correlation"]
        .as_array()
        .expect("final_correlation");
    let n = r["diagnosis"]["final_parameters"]
        .as_array()
        .expect("final_parameters")
        .len();
    assert!(n > 0 && fc.len() == n);
    let at = |i: usize, j: usize| fc[i][j].as_f64();
    for (i, row) in fc.iter().enumerate() {
        assert_eq!(row.as_array().map_or(0, Vec::len), n);
        assert!(at(i, i).is_none_or(|v| (v - 1.0).abs() < 1e-9));
        for j in 0..n {
            if let (Some(a), Some(b)) = (at(i, j), at(j, i)) {
                assert!((a - b).abs() < 1e-9 && a.abs() <= 1.0);
            }
        }
    }
    assert_ne!(
        r["diagnosis"]["final_correlation"],
        r["identification"]["correlation"]
    );
    // --cut: the stability section of the final model, its band from the final fit (the added
    // spring's own variables held at their estimates, said in a note).
    let st = &r["stability"];
    assert!(
        st["minimum"]["depth_mm"].as_f64().unwrap_or(0.0) > 0.0,
        "{st}"
    );
    assert!(st["minimum"]["band_mm"].is_array(), "{st}");
    let notes: Vec<&str> = st["band_notes"]
        .as_array()
        .expect("band_notes")
        .iter()
        .filter_map(|n| n.as_str())
        .collect();
    assert!(
        notes
            .iter()
            .any(|n| n.contains("held at their estimates") && n.contains("diagnosed spring 1"))
            && !notes.iter().any(|n| n.contains("first fit's")),
        "{notes:?}"
    );
    let html = std::fs::read_to_string(dir.path().join("report/report.html")).expect("report.html");
    assert!(html.find("id=\"final\"") < html.find("id=\"stability\""));
    let (top, rest) = html
        .split_once("<details>")
        .expect("the long ranking is collapsed");
    let table = top
        .split("<table class=\"candidates\">")
        .nth(1)
        .and_then(|t| t.split("</table>").next())
        .expect("the candidate table");
    assert_eq!(
        table.matches("<tr").count(),
        1 + 10,
        "header and ten candidates"
    );
    assert!(rest.contains("<table class=\"candidates\">"));
    assert!(!html.contains("<script"));
}

#[test]
fn diagnose_rejects_a_bad_significance_level() {
    let out = ident()
        .current_dir(root())
        .args([
            "diagnose",
            "configs/models/fwd32j.toml",
            "--data",
            "nope.json",
            "--vars",
            "configs/identification/fwd32j.toml",
            "--alpha",
            "2",
        ])
        .output()
        .expect("run ident");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--alpha 2"), "{err}");
}
