//! The report's JSON against its documented schema (JSON Schema via Python `jsonschema`, and the
//! field table of docs/report-json.md), round trips, the HTML's self-containment, the
//! standardized residuals' scale, drift alarms, and atomic writing.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::process::Command;

use common::*;
use rfe::frf;
use serde_json::Value;

fn docs() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs")
}

/// Every field path in a JSON value, in the docs' notation (`a.b[].c`).
fn paths(v: &Value, prefix: &str, out: &mut BTreeSet<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let p = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                out.insert(p.clone());
                paths(x, &p, out);
            }
        }
        Value::Array(a) => {
            for x in a {
                if x.is_object() {
                    paths(x, &format!("{prefix}[]"), out);
                }
            }
        }
        _ => {}
    }
}

#[test]
fn json_report_validates_against_the_json_schema() {
    let f = fixture(3);
    let dir = tempfile::tempdir().unwrap();
    // A full report, and one without the optional sections.
    let full = full_report(&f, 5.0);
    let mut bare_in = report::build::Inputs::new("bare", &f.obs, &f.id);
    bare_in.sensitivity = false;
    bare_in.source.workflow = "identify".into();
    let bare = report::build::build(bare_in).unwrap();
    let mut files = Vec::new();
    for (name, r) in [("full.json", &full), ("bare.json", &bare)] {
        let p = dir.path().join(name);
        std::fs::write(&p, serde_json::to_string_pretty(r).unwrap()).unwrap();
        files.push(p);
    }
    // A report that violates the schema must be rejected (the check can fail).
    let mut bad: Value = serde_json::to_value(&full).unwrap();
    bad["status"]["outcome"] = "fine".into();
    let bad_path = dir.path().join("bad.json");
    std::fs::write(&bad_path, bad.to_string()).unwrap();
    let script = r#"
import json, sys
try:
    import jsonschema
except ImportError:
    sys.exit("python3 module jsonschema missing: run .ci/setup (it installs .ci/requirements.txt)")
schema = json.load(open(sys.argv[1]))
jsonschema.Draft202012Validator.check_schema(schema)
v = jsonschema.Draft202012Validator(schema)
for f in sys.argv[2:-1]:
    errs = list(v.iter_errors(json.load(open(f))))
    if errs:
        sys.exit(f + ": " + "; ".join(f"{list(e.absolute_path)}: {e.message}" for e in errs[:5]))
if not list(v.iter_errors(json.load(open(sys.argv[-1])))):
    sys.exit("the schema accepted an invalid report")
print("ok")
"#;
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .arg(docs().join("report.schema.json"))
        .args(&files)
        .arg(&bad_path)
        .output()
        .expect("python3 not found: run .ci/setup");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn docs_table_lists_exactly_the_report_fields() {
    let f = fixture(3);
    let r = full_report(&f, 5.0);
    let mut actual = BTreeSet::new();
    paths(&serde_json::to_value(&r).unwrap(), "", &mut actual);
    let md = std::fs::read_to_string(docs().join("report-json.md")).unwrap();
    let documented: BTreeSet<String> = md
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .map(str::to_string)
        .collect();
    let undocumented: Vec<_> = actual.difference(&documented).collect();
    let stale: Vec<_> = documented.difference(&actual).collect();
    assert!(
        undocumented.is_empty(),
        "fields missing from docs/report-json.md: {undocumented:?}"
    );
    assert!(
        stale.is_empty(),
        "docs/report-json.md documents fields a report does not have: {stale:?}"
    );
}

#[test]
fn json_round_trips_and_write_leaves_no_partial_files() {
    let f = fixture(4);
    let r = full_report(&f, 1.0);
    let dir = tempfile::tempdir().unwrap();
    let w = report::write(&r, dir.path()).unwrap();
    let back = report::read(&w.json).unwrap();
    assert_eq!(back, r);
    let names: BTreeSet<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        ["report.html", "report.json"]
            .iter()
            .map(|s| s.to_string())
            .collect()
    );
    // Writing into a folder that does not exist fails with the path in the message, and
    // leaves nothing behind.
    let missing = dir.path().join("gone");
    let e = report::write(&r, &missing).unwrap_err().to_string();
    assert!(e.contains("gone/report.json"), "{e}");
    assert!(!missing.exists());
    // A malformed report file is an error naming file and line.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\n \"schema\": 3\n}").unwrap();
    let e = report::read(&bad).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("line 2"), "{e}");
}

#[test]
fn html_is_self_contained_with_every_plot() {
    let f = fixture(5);
    let r = full_report(&f, 5.0);
    let html = report::html::render(&r).unwrap();
    for banned in ["<script", "<link", "<img", "@import", "url(", "https://"] {
        assert!(
            !html.contains(banned),
            "the page must be self-contained, found {banned}"
        );
    }
    // The only URLs are XML namespace names, which are never fetched.
    for (i, _) in html.match_indices("http://") {
        let tail = &html[i..i + 30.min(html.len() - i)];
        assert!(
            tail.starts_with("http://www.w3.org/"),
            "unexpected URL {tail}"
        );
    }
    let svgs = html.matches("<svg").count();
    // amplitude + phase (the fixture has phases) + residual per characteristic, parameters,
    // sensitivity, drift, the stability lobes, the model picture and one figure per mode in the
    // band
    let shapes = r.picture.as_ref().map_or(0, |p| p.modes.len());
    assert!(shapes > 0);
    assert_eq!(
        svgs,
        3 * r.characteristics.len() + 3 + 1 + 1 + shapes,
        "plots: {svgs}"
    );
    assert_eq!(
        html.matches("data-chart=\"phase\"").count(),
        r.characteristics.len()
    );
    // The final model's modes in the band are marked on every amplitude chart.
    let modes = &r.natural_frequencies.last().unwrap().modes;
    assert!(!modes.is_empty());
    let labels = html.matches("\nmode ").count();
    assert!(
        labels >= r.characteristics.len() && labels <= modes.len() * r.characteristics.len(),
        "labelled mode markers: {labels}"
    );
    assert!(
        html.contains("two masses &lt;test &amp; check&gt;"),
        "titles are escaped"
    );
    assert!(html.contains("ALARM") && html.contains("outcome: alarm"));
    // An added effect the data cannot tell from others is shown with them, under the final model.
    assert!(html.contains("<li>spring k1-body–ground ≡ spring k2-body–ground</li>"));
    // Every parameter row is in the table.
    for p in &r.identification.parameters {
        assert!(html.contains(&format!("<td class=\"l\">{}</td>", p.variable)));
    }
}

#[test]
fn the_stability_section_comes_right_after_the_final_model() {
    let f = fixture(5);
    let r = full_report(&f, 1.0);
    let s = r.stability.as_ref().unwrap();
    let html = report::html::render(&r).unwrap();
    let at = |needle: &str| {
        html.find(needle)
            .unwrap_or_else(|| panic!("{needle} missing"))
    };
    assert!(at("id=\"final\"") < at("id=\"stability\""));
    assert!(at("id=\"stability\"") < at("id=\"identification\""));
    // The minimum with its band, the lobes with the band shaded, the limiting modes' joints.
    let [lo, hi] = s.minimum.band_mm.unwrap();
    assert!(
        lo < s.minimum.depth_mm && s.minimum.depth_mm < hi,
        "{:?}",
        s.minimum
    );
    assert!(html.contains("minimum critical depth"));
    assert!(html.contains("5–95 % band (linear)"));
    assert!(!s.limiting.is_empty());
    for l in &s.limiting {
        for j in &l.joints {
            assert!(html.contains(&j.name), "joint {} named", j.name);
        }
    }
    // The covariance note (the second variable has no final-fit error in the fixture).
    assert!(s
        .band_notes
        .iter()
        .any(|n| n.contains("held at their estimates")));
    // Without a diagnosis the identification's table is the final model: the section follows it.
    let mut plain = r.clone();
    plain.diagnosis = None;
    let html = report::html::render(&plain).unwrap();
    let at = |needle: &str| {
        html.find(needle)
            .unwrap_or_else(|| panic!("{needle} missing"))
    };
    assert!(at("id=\"parameters\"") < at("id=\"stability\""));
}

#[test]
fn dense_curves_are_log_spaced_cover_the_band_keep_the_peaks_and_match_a_direct_solve() {
    let f = fixture(7);
    let r = full_report(&f, 1.0);
    let stages_with_modes: Vec<&str> = r
        .natural_frequencies
        .iter()
        .map(|m| m.stage.as_str())
        .collect();
    assert_eq!(stages_with_modes, ["identified", "diagnosed"]);
    let modes = &r.natural_frequencies[0].modes;
    assert!(!modes.is_empty(), "the two-mass chain resonates in 8-80 Hz");
    for (c, obs) in r.characteristics.iter().zip(&f.obs.characteristics) {
        let (lo, hi) = (c.freqs_hz[0], *c.freqs_hz.last().unwrap());
        for s in &c.stages {
            let Some(d) = &s.dense else {
                assert_eq!(
                    s.stage, "initial",
                    "only the initial model has no dense curve"
                );
                continue;
            };
            let g = &d.freqs_hz;
            // Dense, log-spaced, across the band, with every measured line and resonance on it.
            assert!(g.len() >= report::build::DENSE_LINES, "{}", g.len());
            assert_eq!((g[0], *g.last().unwrap()), (lo, hi));
            assert!(g.windows(2).all(|w| w[1] > w[0]));
            let step = (hi / lo).powf(1.0 / (report::build::DENSE_LINES - 1) as f64);
            assert!(g.windows(2).all(|w| w[1] / w[0] <= step * (1.0 + 1e-9)));
            for x in c.freqs_hz.iter().chain(modes.iter().map(|m| &m.freq_hz)) {
                assert!(
                    g.iter().any(|y| (y - x).abs() <= 1e-12 * x),
                    "{x} Hz on the grid"
                );
            }
            // No peak lost between grid lines: the curve reaches every per-line model value.
            let line_max = s.amplitude.iter().copied().fold(0.0, f64::max);
            let dense_max = d.amplitude.iter().copied().fold(0.0, f64::max);
            assert!(dense_max >= line_max, "{dense_max} < {line_max}");
            // The same numbers as a direct solve of the identified model (the fixture's diagnosed
            // model is the identified one) at a few grid points.
            let picks = [0, g.len() / 3, g.len() / 2, g.len() - 1];
            let hz: Vec<f64> = picks.iter().map(|&k| g[k]).collect();
            let direct = frf::response(&f.id.model, &hz, &[], frf::Method::Direct).unwrap();
            let phase = d.phase_rad.as_ref().expect("the data have phase");
            for (j, &k) in picks.iter().enumerate() {
                let v = direct.output(obs.output)[j];
                assert!(
                    (d.amplitude[k] - v.norm()).abs() <= 1e-9 * v.norm(),
                    "line {k}"
                );
                let z = rfe::C64::from_polar(d.amplitude[k], phase[k]);
                assert!((z - v).norm() <= 1e-9 * v.norm(), "phase at line {k}");
            }
        }
    }
}

#[test]
fn candidate_table_shows_ten_with_every_accepted_and_collapses_the_rest() {
    let f = fixture(8);
    let mut r = full_report(&f, 1.0);
    let d = r.diagnosis.as_mut().unwrap();
    d.candidates = many_candidates(30);
    let html = report::html::render(&r).unwrap();
    let (top, rest) = html
        .split_once("<details>")
        .expect("the rest is collapsed behind <details>");
    let table = top
        .split("<table class=\"candidates\">")
        .nth(1)
        .and_then(|t| t.split("</table>").next())
        .unwrap();
    assert_eq!(table.matches("<tr").count(), 1 + 10, "header and ten rows");
    // Both accepted candidates are in the top table, though round 1's ranks 15th by statistic.
    assert_eq!(table.matches("class=\"accepted\"").count(), 2);
    assert!(table.contains("candidate 14<") && table.contains("candidate 15<"));
    assert!(table.contains("candidate 0<") && !table.contains("candidate 9<"));
    // A p-value of 0 is not printed as 0.
    assert!(!table.contains("<td>0</td>"), "{table}");
    let (details, _) = rest.split_once("</details>").unwrap();
    assert_eq!(details.matches("<tr").count(), 1 + 20);
    assert!(!html.contains("<script"));
    // Few candidates: one table, nothing collapsed.
    r.diagnosis.as_mut().unwrap().candidates = many_candidates(6);
    let html = report::html::render(&r).unwrap();
    assert!(!html.contains("<details>"));
}

#[test]
fn standardized_residuals_have_unit_scale_at_the_estimate() {
    // Data with 1 % noise and stated variances: at the identified model the residuals are
    // draws of N(0, 1); at the initial model they are far larger.
    let f = fixture(6);
    let r = report::build::build(report::build::Inputs::new("t", &f.obs, &f.id)).unwrap();
    let rms = |stage: &str| {
        let v: Vec<f64> = r
            .characteristics
            .iter()
            .flat_map(|c| {
                c.stages
                    .iter()
                    .filter(|s| s.stage == stage)
                    .flat_map(|s| s.standardized_residual.iter().copied())
            })
            .collect();
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    };
    let (ini, ide) = (rms("initial"), rms("identified"));
    assert!(
        (0.75..1.3).contains(&ide),
        "RMS standardized residual at the estimate {ide}"
    );
    assert!(ini > 5.0 * ide, "initial {ini} vs identified {ide}");
    for c in &r.characteristics {
        assert_eq!(c.sigma_kind, "variance");
        // The report's RMS relative error equals identification's own.
        let own = f.id.rms.iter().find(|(l, _)| *l == c.label).unwrap().1;
        let mine = c
            .stages
            .iter()
            .find(|s| s.stage == "identified")
            .unwrap()
            .rms_relative_error;
        assert!(
            (own - mine).abs() <= 1e-9 * own.max(1e-30),
            "{}: {own} vs {mine}",
            c.label
        );
    }
    // The sensitivity map covers every decision parameter and characteristic, all positive.
    let s = r.sensitivity.as_ref().unwrap();
    assert_eq!(s.parameters, vec!["SDE k1 k", "SDE k2 k"]);
    assert!(s.relative.iter().flatten().all(|v| *v > 0.0));
}

#[test]
fn an_attached_drift_alarm_becomes_a_message_and_the_alarm_outcome() {
    let f = fixture(7);
    let quiet = full_report(&f, 2.5);
    let d = quiet.drift.as_ref().unwrap();
    assert_eq!(d.runs.len(), 4);
    assert!((d.parameters[0].deviation_sigma.unwrap() - 2.5).abs() < 1e-9);
    assert!(d.parameters.iter().all(|p| !p.alarm));
    assert_eq!(quiet.status.outcome, report::Outcome::Ok);
    let loud = full_report(&f, -3.5);
    let d = loud.drift.as_ref().unwrap();
    assert!(d.parameters[0].alarm && !d.parameters[1].alarm);
    assert_eq!(loud.status.outcome, report::Outcome::Alarm);
    assert!(
        loud.status
            .messages
            .iter()
            .any(|m| m.contains("drift alarm") && m.contains(&d.parameters[0].variable)),
        "{:?}",
        loud.status.messages
    );
}
