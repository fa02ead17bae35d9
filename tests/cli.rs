//! End-to-end tests of the `ident` command line: model export, the FRF JSON contract against an
//! independent numpy implementation of docs/model-json.md, error messages, exit codes.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{assert_success, ident, root};

fn python_with_numpy() -> &'static str {
    let ok = Command::new("python3")
        .args(["-c", "import numpy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(ok, "python3 with numpy is needed for this cross-check: run `.ci/setup` (installs .ci/requirements.txt)");
    "python3"
}

fn frf_values(v: &serde_json::Value) -> Vec<(f64, f64)> {
    v["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|o| {
            let re = o["re"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect::<Vec<_>>();
            let im = o["im"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect::<Vec<_>>();
            re.into_iter().zip(im)
        })
        .collect()
}

/// Exports `model` to resolved JSON, computes its FRF with ident and with the independent numpy
/// implementation, and returns the largest relative difference.
fn compare_with_numpy(model: &Path, freqs: &str) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("model.json");
    let out = ident(&[
        "model",
        "export",
        model.to_str().unwrap(),
        "--json",
        "-o",
        json.to_str().unwrap(),
    ]);
    assert_success(&out);
    let ours = ident(&["frf", json.to_str().unwrap(), "--hz", freqs, "--json"]);
    assert_success(&ours);
    let theirs = Command::new(python_with_numpy())
        .arg(root().join("tests/python/contract_frf.py"))
        .args([json.to_str().unwrap(), freqs])
        .output()
        .unwrap();
    assert_success(&theirs);
    let a: serde_json::Value = serde_json::from_slice(&ours.stdout).unwrap();
    let b: serde_json::Value = serde_json::from_slice(&theirs.stdout).unwrap();
    assert_eq!(a["freqs_hz"], b["freqs_hz"]);
    let (va, vb) = (frf_values(&a), frf_values(&b));
    assert_eq!(va.len(), vb.len());
    va.iter()
        .zip(&vb)
        .map(|(x, y)| ((x.0 - y.0).hypot(x.1 - y.1)) / y.0.hypot(y.1).max(1e-300))
        .fold(0.0, f64::max)
}

#[test]
fn frf_agrees_with_an_independent_implementation_of_the_contract() {
    let freqs = "0.5,3,7.25,12,20,33,50,75,110,160,240";
    let models: Vec<PathBuf> = std::fs::read_dir(root().join("configs/models"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    assert!(
        models.len() >= 2,
        "configs/models should hold the FWD-32J and textbook models"
    );
    for m in models {
        let err = compare_with_numpy(&m, freqs);
        assert!(
            err <= 1e-8,
            "{}: ident vs numpy max relative difference {err:e}",
            m.display()
        );
    }
}

#[test]
fn frf_csv_and_json_forms() {
    let m = root().join("configs/models/textbook-two-mass.toml");
    let csv = ident(&[
        "frf",
        m.to_str().unwrap(),
        "--from",
        "1",
        "--to",
        "100",
        "--points",
        "5",
        "--log",
    ]);
    assert_success(&csv);
    let text = String::from_utf8(csv.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 6, "{text}");
    assert!(lines[0].starts_with("freq_hz,"));
    let f: Vec<f64> = lines[1..]
        .iter()
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(
        (f[0] - 1.0).abs() < 1e-12 && (f[4] - 100.0).abs() < 1e-9 && (f[2] - 10.0).abs() < 1e-9,
        "{f:?}"
    );
    let json = ident(&["frf", m.to_str().unwrap(), "--hz", "10,20", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(v["freqs_hz"], serde_json::json!([10.0, 20.0]));
    let o = &v["outputs"][0];
    for key in ["body", "dof", "quantity", "re", "im"] {
        assert!(o.get(key).is_some(), "missing {key} in {o}");
    }
}

#[test]
fn bad_model_exits_2_with_location() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[[body]]\nname = \"a\"\nmass = \"3 furlong\"\nposition = [0,0,0]\ninertia = [1,1,1]\n",
    )
    .unwrap();
    let out = ident(&["frf", bad.to_str().unwrap(), "--hz", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("bad.toml:3:8") && err.contains("unknown unit \"furlong\""),
        "{err}"
    );
    let missing = ident(&["model", "check", "/nonexistent/model.toml"]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&missing.stderr).contains("cannot read the model file"));
}

#[test]
fn files_that_are_not_sessions_get_a_clear_error_and_a_failing_exit() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let csv = dir.path().join("frf.csv");
    std::fs::write(&csv, "frequency,amplitude\n10,1e-6\n").unwrap();
    let magic = dir.path().join("magic.mcap");
    std::fs::write(&magic, b"\x89MCAP0\r\n").unwrap();
    for (file, want) in [
        (&empty, "is not an MCAP file (the file is empty)"),
        (&csv, "is not an MCAP file"),
        (&magic, "no message can be recovered"),
    ] {
        let out = ident(&["mcap", "recover", file.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{}: {err}", file.display());
        assert!(err.contains(want), "{}: {err}", file.display());
    }
    let out = ident(&["process", csv.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("frf.csv is not an MCAP file") && !err.contains("/stand"),
        "{err}"
    );
}

#[test]
fn process_exports_uff58_that_pyuff_reads_back_to_the_same_frfs() {
    let dir = tempfile::tempdir().unwrap();
    let session = root().join("acquire/tests/fixtures/session-v1.mcap");
    let uff = dir.path().join("frf.uff");
    let out = ident(&[
        "process",
        session.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--uff",
        uff.to_str().unwrap(),
    ]);
    assert_success(&out);
    let script = r#"
import json, sys
import pyuff
sets = pyuff.UFF(sys.argv[1]).read_sets()
sets = sets if isinstance(sets, list) else [sets]
print(json.dumps([{
    "type": int(s["type"]), "name": s["id1"].strip(), "func_type": int(s["func_type"]),
    "rsp_node": int(s["rsp_node"]), "rsp_dir": int(s["rsp_dir"]), "ref_node": int(s["ref_node"]),
    "x": [float(v) for v in s["x"]],
    "re": [float(v.real) for v in s["data"]], "im": [float(v.imag) for v in s["data"]],
    "num_units": s["ordinate_axis_units_lab"].strip(), "den_units": s["orddenom_axis_units_lab"].strip(),
} for s in sets]))
"#;
    let py = Command::new(python_with_numpy())
        .args(["-c", script])
        .arg(&uff)
        .output()
        .unwrap();
    assert!(
        py.status.success(),
        "pyuff: {}",
        String::from_utf8_lossy(&py.stderr)
    );
    let sets: Vec<serde_json::Value> = serde_json::from_slice(&py.stdout).unwrap();
    let a = acquire::analysis::characteristics(&session, &Default::default()).unwrap();
    let close = |p: f64, q: f64| (p - q).abs() <= 1e-11 * q.abs().max(1e-300);
    // 7 accelerometers, then the table's characteristics.
    let sensors: Vec<&acquire::stand::Channel> = a
        .channels
        .iter()
        .filter(|c| c.kind == acquire::stand::ChannelKind::Acceleration)
        .collect();
    assert_eq!(sets.len(), sensors.len() + a.measured.characteristics.len());
    for (set, ch) in sets.iter().zip(&sensors) {
        assert_eq!(set["type"], 58);
        assert_eq!(set["func_type"], 4, "FRF");
        assert_eq!(set["name"], ch.name.as_str());
        assert_eq!(set["num_units"], "m/s^2");
        assert_eq!(set["den_units"], "N");
        let c = a.channels.iter().position(|x| x.name == ch.name).unwrap();
        assert_eq!(set["rsp_node"], c as i64 + 1);
        for (k, s) in a.steps.iter().enumerate() {
            let (re, im) = (s.channels[c].frf_re, s.channels[c].frf_im);
            // UFF 58 ASCII writes an uneven abscissa as E13.5 (6 significant digits), the format's
            // own limit; the ordinates as E20.12.
            let x = set["x"][k].as_f64().unwrap();
            assert!((x - s.frequency_hz).abs() <= 5e-6 * s.frequency_hz, "{set}");
            assert!(
                close(set["re"][k].as_f64().unwrap(), re),
                "{} re {k}",
                ch.name
            );
            assert!(
                close(set["im"][k].as_f64().unwrap(), im),
                "{} im {k}",
                ch.name
            );
        }
    }
    for (set, m) in sets[sensors.len()..]
        .iter()
        .zip(&a.measured.characteristics)
    {
        assert_eq!(set["rsp_dir"], i64::from(m.dof) + 1);
        assert_eq!(set["den_units"], "N");
        for k in 0..m.freqs_hz.len() {
            let amp = (set["re"][k].as_f64().unwrap().powi(2)
                + set["im"][k].as_f64().unwrap().powi(2))
            .sqrt();
            assert!(
                close(amp * a.geometry.nominal_force_n, m.amplitude[k]),
                "{} dof {}: {amp} per N",
                m.body,
                m.dof
            );
        }
    }
}

#[test]
fn modes_and_sensitivity_run_on_the_textbook_model() {
    let m = root().join("configs/models/textbook-two-mass.toml");
    let out = ident(&["modes", m.to_str().unwrap()]);
    assert_success(&out);
    let out = ident(&[
        "sensitivity",
        m.to_str().unwrap(),
        "--from",
        "1",
        "--to",
        "100",
        "--json",
    ]);
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(!v["params"].as_array().unwrap().is_empty());
}

#[test]
fn demo_runs_the_whole_pipeline_over_the_simulated_devices() {
    let dir = tempfile::tempdir().unwrap();
    let out = ident(&["demo", "--out", dir.path().to_str().unwrap(), "--quiet"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("(38 steps, 0 stream faults)"), "{stdout}");
    // RMS amplitude error per characteristic: "x dB -> y dB   (a % -> b %)"; the fit lowers it.
    let rms: Vec<(f64, f64)> = stdout
        .lines()
        .filter(|l| l.contains(" dB -> "))
        .map(|l| {
            let db = l
                .rsplit_once(": ")
                .unwrap()
                .1
                .split(" dB")
                .collect::<Vec<_>>();
            let (a, b) = (db[0], db[1].trim_start_matches(" -> "));
            (a.trim().parse().unwrap(), b.trim().parse().unwrap())
        })
        .collect();
    assert_eq!(rms.len(), 3, "{stdout}");
    assert!(rms.iter().all(|(a, b)| b < a), "{rms:?}");
    // The stand's truth has the hydraulic actuator (SDE 34) the identification model lacks:
    // identification alone leaves structure far above the noise; diagnosis must add a spring
    // between spindle head and table along the actuator's axis, with the truth's stiffness
    // (0.5639 N/µm) within 4 standard errors, and bring the fit to the noise floor.
    let (before, after) = common::reduced_chi2_before_after(&stdout);
    let reduced = [before, after];
    assert!(
        reduced[0] > 100.0,
        "identification alone should not explain the stand: {reduced:?}"
    );
    assert!(
        reduced[1] < 1.5,
        "diagnosis should reach the noise floor: {reduced:?}\n{stdout}"
    );
    let added: Vec<&str> = stdout
        .lines()
        .filter(|l| l.trim_start().starts_with("added: "))
        .collect();
    assert_eq!(added.len(), 1, "{stdout}");
    assert!(
        added[0].contains("spring spindle head–table")
            || added[0].contains("spring spindle head–upper saddle"),
        "{}",
        added[0]
    );
    let k: Vec<f64> = added[0]
        .split("k = ")
        .nth(1)
        .unwrap()
        .split(" N/µm")
        .next()
        .unwrap()
        .split(" ± ")
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (k[0] - 0.5639).abs() < 4.0 * k[1],
        "actuator stiffness {k:?} N/µm, truth 0.5639"
    );
    assert!(
        stdout.contains("after: the model explains the data to the noise level"),
        "{stdout}"
    );
    let report = stdout
        .lines()
        .find_map(|l| l.strip_prefix("report: "))
        .expect("report path");
    for f in [
        "session.mcap",
        "report.html",
        "report.json",
        "measured.json",
        "identification.json",
        "identification.csv",
        "identified-model.json",
        "diagnosis.json",
        "diagnosed-model.json",
        "final-model.toml",
        "final-variables.toml",
    ] {
        assert!(
            Path::new(report).join(f).is_file(),
            "missing {f} in {report}"
        );
    }
}
