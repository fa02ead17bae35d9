//! `ident stability`: lobes of FWD-32J's final model against an independent numpy/scipy
//! implementation, the band end to end from an identification's report, and the errors.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;
use std::process::Command;

use common::{assert_success, ident, root};
use identify::synthetic;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

fn python_with_scipy() -> &'static str {
    let ok = Command::new("python3")
        .args(["-c", "import numpy, scipy, tomllib"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(ok, "python3 (3.11+) with numpy and scipy is needed for this cross-check: run `.ci/setup` (installs .ci/requirements.txt)");
    "python3"
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

/// Rows of the CSV as (header → column) lookups.
fn csv_columns(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let mut lines = text.lines();
    let head: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (head, rows)
}

fn column(head: &[String], rows: &[Vec<String>], name: &str) -> Vec<f64> {
    let i = head.iter().position(|h| h == name).unwrap();
    rows.iter()
        .map(|r| r[i].parse::<f64>().unwrap_or(f64::INFINITY))
        .collect()
}

/// FWD-32J's final model (the identified values of the paper's Table 1), face milling: the
/// critical depth at each of the 200 speeds as numpy/scipy compute it independently.
#[test]
fn fwd32j_lobes_agree_with_an_independent_implementation() {
    let dir = tempfile::tempdir().unwrap();
    let model = root().join("configs/models/fwd32j.toml");
    let json = dir.path().join("model.json");
    assert_success(&ident(&[
        "model",
        "export",
        p(&model),
        "--json",
        "-o",
        p(&json),
    ]));
    // The face mill's limit is set by the machine's modes (their joints are named); the slender
    // end mill's by its own modes.
    for (cut, limit) in [
        ("fwd32j-face-milling.toml", "joints SDE"),
        ("fwd32j-end-mill.toml", "tool modes:"),
    ] {
        let cut = root().join("configs/cuts").join(cut);
        let csv = dir.path().join("lobes.csv");
        let svg = dir.path().join("lobes.svg");
        let o = ident(&[
            "stability",
            p(&model),
            "--cut",
            p(&cut),
            "--csv",
            p(&csv),
            "--svg",
            p(&svg),
        ]);
        assert_success(&o);
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains("minimum critical depth"), "{stdout}");
        assert!(stdout.contains(limit), "{limit} named: {stdout}");
        let svg_text = std::fs::read_to_string(&svg).unwrap();
        assert!(svg_text.starts_with("<svg") && svg_text.contains("<polyline"));
        let (head, rows) = csv_columns(&std::fs::read_to_string(&csv).unwrap());
        let ours = column(&head, &rows, "depth_mm");
        let hz = column(&head, &rows, "chatter_hz");
        assert_eq!(ours.len(), 200);
        let theirs = Command::new(python_with_scipy())
            .arg(root().join("tests/python/stability_zoa.py"))
            .args([p(&json), p(&cut)])
            .output()
            .unwrap();
        assert_success(&theirs);
        let v: serde_json::Value = serde_json::from_slice(&theirs.stdout).unwrap();
        let depth: Vec<f64> = v["depth_m"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().map_or(f64::INFINITY, |d| d * 1e3))
            .collect();
        let chatter: Vec<f64> = v["chatter_hz"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap_or(f64::NAN))
            .collect();
        for i in 0..ours.len() {
            assert!(
                (ours[i] - depth[i]).abs() <= 1e-5 * depth[i] + 1e-7,
                "{}: speed {i}: ident {} mm, numpy {} mm",
                cut.display(),
                ours[i],
                depth[i]
            );
            assert!(
                (hz[i] - chatter[i]).abs() <= 0.01 + 1e-5 * chatter[i],
                "{}: speed {i}: chatter {} Hz vs {} Hz",
                cut.display(),
                hz[i],
                chatter[i]
            );
        }
    }
}

const TWO_MASS_VARS: &str = r#"
[[variable]]
sdes = "k1"
parameter = "k"
initial = "14 N/um"

[[variable]]
sdes = "k2"
parameter = "k"
initial = "7 N/um"
"#;

/// Identify the two-mass chain from synthetic data, then the lobes of the final model with the
/// band from the report: the final model and variables files (`--write-model`, `--write-vars`)
/// and the report folder's report.json; the linear band and the Monte Carlo band agree at the minimum.
#[test]
fn the_band_comes_from_the_report_of_an_identification() {
    let dir = tempfile::tempdir().unwrap();
    let truth = rfe::modelfile::load(&root().join(common::TWO_MASS))
        .unwrap()
        .model;
    let mut rng = StdRng::seed_from_u64(3);
    let d = synthetic::amplitude_data(&truth, &synthetic::log_lines(10.0, 60.0, 40), 0.01, || {
        StandardNormal.sample(&mut rng)
    })
    .unwrap();
    let data = dir.path().join("data.json");
    std::fs::write(&data, serde_json::to_string(&d).unwrap()).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, TWO_MASS_VARS).unwrap();
    let out = dir.path().join("out");
    let (fin, fin_vars) = (
        dir.path().join("final-model.toml"),
        dir.path().join("final-variables.toml"),
    );
    assert_success(&common::identify_two_mass(
        &data,
        &vars,
        &[
            "--out",
            p(&out),
            "--write-model",
            p(&fin),
            "--write-vars",
            p(&fin_vars),
            "--cut",
            p(&root().join("configs/cuts/textbook-two-mass-turning.toml")),
        ],
        &[],
    ));
    let csv = dir.path().join("lobes.csv");
    let o = ident(&[
        "stability",
        p(&fin),
        "--cut",
        p(&root().join("configs/cuts/textbook-two-mass-turning.toml")),
        "--vars",
        p(&fin_vars),
        "--report",
        p(&out.join("report.json")),
        "--monte-carlo",
        "300",
        "--csv",
        p(&csv),
    ]);
    assert_success(&o);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("5–95 %"), "{stdout}");
    let (head, rows) = csv_columns(&std::fs::read_to_string(&csv).unwrap());
    let depth = column(&head, &rows, "depth_mm");
    let (lo, hi) = (
        column(&head, &rows, "lower_mm"),
        column(&head, &rows, "upper_mm"),
    );
    let (mlo, mhi) = (
        column(&head, &rows, "mc_lower_mm"),
        column(&head, &rows, "mc_upper_mm"),
    );
    let i = (0..depth.len())
        .min_by(|&a, &b| depth[a].total_cmp(&depth[b]))
        .unwrap();
    assert!(
        lo[i] < depth[i] && depth[i] < hi[i],
        "the band brackets the boundary"
    );
    let (w, mw) = (hi[i] - lo[i], mhi[i] - mlo[i]);
    assert!(
        w > 0.0 && (mw / w - 1.0).abs() < 0.2,
        "linear width {w} mm vs Monte Carlo {mw} mm"
    );

    // `--json` is the report's section: `identify --cut` put the same lobes and band in the
    // report as `ident stability` computes from the files the run wrote.
    let o = ident(&[
        "stability",
        p(&fin),
        "--cut",
        p(&root().join("configs/cuts/textbook-two-mass-turning.toml")),
        "--vars",
        p(&fin_vars),
        "--report",
        p(&out.join("report.json")),
        "--json",
    ]);
    assert_success(&o);
    let json: stability::section::Stability = serde_json::from_slice(&o.stdout).unwrap();
    let report: report::Report =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let section = report
        .stability
        .expect("the report has the stability section");
    let (a, b) = (&json.minimum, &section.minimum);
    assert!(
        (a.depth_mm - b.depth_mm).abs() < 1e-6 * a.depth_mm && a.speed_rpm == b.speed_rpm,
        "{a:?} vs {b:?}"
    );
    let (ja, jb) = (a.band_mm.unwrap(), b.band_mm.unwrap());
    assert!(
        (ja[0] - jb[0]).abs() < 1e-4 * a.depth_mm && (ja[1] - jb[1]).abs() < 1e-4 * a.depth_mm,
        "{ja:?} vs {jb:?}"
    );
    assert!(
        (a.depth_mm - depth[i]).abs() < 1e-6 * a.depth_mm,
        "the JSON is the CSV's minimum"
    );
    assert_eq!(json.points.len(), depth.len());
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("id=\"stability\"") && html.contains("minimum critical depth"));
}

#[test]
fn bad_input_names_the_file_field_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    let model = root().join("configs/models/fwd32j.toml");
    let text =
        std::fs::read_to_string(root().join("configs/cuts/fwd32j-face-milling.toml")).unwrap();
    let cases = [
        (
            text.replace("kt = \"1800 MPa\"\n", ""),
            "cutting.kt: missing; write the tangential cutting coefficient as a pressure",
        ),
        (
            text.replace("point = [0.0, 0.9, 0.95]", "point = [0.0, 0.9, 0.5]"),
            "workpiece.point: (0.0000, 0.9000, 0.5000) m is",
        ),
        (
            text.replace("[200, 2000]", "[1e9, 2e9]")
                .replace("speeds = 200", "speeds = 20\nband_hz = [5, 300]"),
            "speed_rpm: no stability lobe reaches",
        ),
    ];
    for (k, (t, expected)) in cases.iter().enumerate() {
        let cut = dir.path().join(format!("cut{k}.toml"));
        std::fs::write(&cut, t).unwrap();
        let o = ident(&["stability", p(&model), "--cut", p(&cut)]);
        assert_eq!(o.status.code(), Some(2));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("{}: {expected}", cut.display())),
            "{err}"
        );
    }
}
