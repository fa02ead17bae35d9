//! The worked real-data example (`examples/real-three-storey`, data in `data/dtop-three-storey`):
//! `ident identify` from the documented start against an independent numpy/scipy fit of the same
//! model form, lines and criterion (`examples/real-three-storey/reference_fit.py`).

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::Command;

use common::{identify_mapped, json, p, root, text};

/// The documented command, with `extra` flags appended.
fn identify_example(extra: &[&str]) -> std::process::Output {
    let vars = root().join("examples/real-three-storey/variables.toml");
    identify_example_from(&vars, extra)
}

/// The documented command with the variables file `vars`, and `extra` flags appended.
fn identify_example_from(vars: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let ex = root().join("examples/real-three-storey");
    let data = root().join("data/dtop-three-storey/three-storey-hammer.uff");
    let (model, map) = (ex.join("model.toml"), ex.join("map.toml"));
    let flags = [&["--band", "3:40"][..], extra].concat();
    identify_mapped(&model, &data, &map, vars, &flags)
}

/// Runs the reference fit; fails (never skips) without python3, numpy, scipy or pyuff.
fn reference_fit(out: &std::path::Path) -> serde_json::Value {
    let probe = Command::new("python3")
        .args(["-c", "import numpy, scipy, pyuff"])
        .output();
    match probe {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "python3 lacks numpy, scipy or pyuff ({}): run `.ci/setup` (installs .ci/requirements.txt)",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => panic!("python3 not found ({e}): run `.ci/setup`"),
    }
    let script = root().join("examples/real-three-storey/reference_fit.py");
    let o = Command::new("python3")
        .args([p(&script), "--json", p(out)])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "reference_fit.py failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    json(out)
}

#[test]
fn identify_reaches_the_independent_scipy_fit() {
    let dir = tempfile::tempdir().unwrap();
    let out = identify_example(&["--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let id: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let reference = reference_fit(&dir.path().join("reference.json"));

    // The same lines: 3 characteristics × the script's lines.
    let lines = reference["lines"].as_u64().unwrap();
    assert_eq!(id["observations"].as_u64().unwrap(), 3 * lines);
    // ident's RMS dB over all observations (every characteristic has the same lines).
    let per: Vec<f64> = id["rms_db_error"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r[2].as_f64().unwrap())
        .collect();
    assert_eq!(per.len(), 3);
    let ident_db = (per.iter().map(|v| v * v).sum::<f64>() / 3.0).sqrt();
    let scipy_db = reference["rms_db_overall"].as_f64().unwrap();
    eprintln!("RMS dB: ident {ident_db:.4}, scipy {scipy_db:.4}");
    assert!(
        ident_db <= 1.2 * scipy_db,
        "ident {ident_db} dB vs the reference fit's {scipy_db} dB"
    );
    // And the same optimum: every estimate within 0.1 % of the reference's.
    for row in id["table"].as_array().unwrap() {
        let name = row["variable"].as_str().unwrap();
        let ours = row["identified"].as_f64().unwrap();
        let theirs = reference["estimates"][name].as_f64().unwrap();
        // the table is in report units (N/µm for stiffness), the script in SI
        let theirs = if name.starts_with('k') {
            theirs * 1e-6
        } else {
            theirs
        };
        assert!(
            (ours / theirs - 1.0).abs() < 1e-3,
            "{name}: ident {ours}, reference {theirs}"
        );
    }
}

#[test]
fn many_starts_find_the_same_best_optimum_and_report_the_others() {
    let one = identify_example(&["--format", "json"]);
    let many = identify_example(&["--format", "json", "--starts", "12", "--seed", "3"]);
    assert_eq!(many.status.code(), Some(0), "{}", text(&many));
    let one: serde_json::Value = serde_json::from_slice(&one.stdout).unwrap();
    let many: serde_json::Value = serde_json::from_slice(&many.stdout).unwrap();
    let j1 = one["criterion"].as_f64().unwrap();
    let jm = many["criterion"].as_f64().unwrap();
    assert!(
        jm <= j1 * (1.0 + 1e-9),
        "12 starts {jm} vs the documented start {j1}"
    );
    assert!(
        (jm / j1 - 1.0).abs() < 1e-6,
        "the documented start is the best optimum"
    );
    let optima = many["start_analysis"]["optima"].as_array().unwrap();
    let reached: usize = optima
        .iter()
        .map(|o| o["starts"].as_array().unwrap().len())
        .sum();
    assert_eq!(reached, 12, "every start ends in one optimum");
    assert!(
        optima[0]["starts"].as_array().unwrap().contains(&0.into()),
        "the documented start reaches the best optimum"
    );
    // Starts spread over [x0/10, 10 x0] also reach other, much worse optima (degenerate corners):
    // reported, and since they are significantly worse, no ambiguity warning.
    assert!(optima.len() >= 2, "{optima:?}");
    for o in &optima[1..] {
        assert!(o["criterion"].as_f64().unwrap() > 1.5 * jm);
    }
    assert_eq!(
        many["start_analysis"]["warnings"].as_array().unwrap().len(),
        0
    );
}

#[test]
fn a_modal_start_matches_the_measured_frequencies_and_reaches_the_same_optimum_from_far_off() {
    // A variables file whose start is far off (storey stiffnesses 10x in opposite directions,
    // ψ 12x): the pre-fit must bring the three model frequencies onto the measured ones.
    let vars = root().join("examples/real-three-storey/far-start.toml");
    let out = identify_example_from(&vars, &["--start", "modal", "--format", "json"]);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("start: modal pre-fit on 3 measured mode(s) (3 paired)"),
        "{err}"
    );
    // Each pair: "measured F Hz (η E) <- model A Hz -> B Hz, MAC M" with B = F, M near 1.
    let pairs: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("start: measured"))
        .collect();
    assert_eq!(pairs.len(), 3, "{err}");
    for l in pairs {
        let nums: Vec<f64> = l
            .split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .filter_map(|t| t.parse().ok())
            .collect();
        let (measured, after, mac) = (nums[0], nums[3], nums[4]);
        assert!((after / measured - 1.0).abs() < 1e-6, "{l}");
        assert!(mac > 0.9, "{l}");
    }
    assert!(
        (6.4..6.6).contains(
            &err.lines()
                .find(|l| l.starts_with("start: measured"))
                .and_then(|l| l.split_whitespace().nth(2))
                .and_then(|t| t.parse::<f64>().ok())
                .unwrap()
        ),
        "the first storey mode at 6.5 Hz"
    );
    let modal: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let documented = identify_example(&["--format", "json"]);
    let documented: serde_json::Value = serde_json::from_slice(&documented.stdout).unwrap();
    let (jm, jd) = (
        modal["criterion"].as_f64().unwrap(),
        documented["criterion"].as_f64().unwrap(),
    );
    assert!(
        (jm / jd - 1.0).abs() < 1e-6,
        "modal start {jm} vs documented start {jd}"
    );
    assert!(
        modal["criterion_initial"].as_f64().unwrap()
            < documented["criterion_initial"].as_f64().unwrap(),
        "the pre-fit start is better than the model's values"
    );
}
