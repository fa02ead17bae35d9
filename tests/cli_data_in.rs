//! `ident identify` on vendor data: a UFF58b file in g/N with a measurement map, a CSV declaring
//! its unit, frequencies in kHz under `freq_hz` (an error naming the band), a misfit headline, a
//! UFF file without a map.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use std::path::{Path, PathBuf};

use common::{identify_two_mass, p, root, utf8, TWO_MASS};

use process::uff;
use process::C64;
use rfe::frf::{self, Method};

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm.
const VARS: &str = include_str!("../configs/identification/textbook-two-mass.toml");

const MAP: &str = r#"
[[channel]]
node = 11
dir = "+Z"
body = "first"

[[channel]]
node = 12
dir = "+Z"
body = "second"
"#;

/// The two-mass chain's exact receptances (per N; its excitation is 1 N) at `f`.
fn receptances(f: &[f64]) -> Vec<Vec<C64>> {
    let model = rfe::modelfile::load(&root().join(TWO_MASS)).unwrap().model;
    let r = frf::response(&model, f, &[], Method::Direct).unwrap();
    (0..2).map(|o| r.output(o).to_vec()).collect()
}

fn lines() -> Vec<f64> {
    (0..40).map(|i| 10.0 + 1.25 * i as f64).collect()
}

#[test]
fn a_uff_file_in_g_per_newton_with_a_map_is_identified() {
    let dir = tempfile::tempdir().unwrap();
    let f = lines();
    let h = receptances(&f);
    let mut sets = Vec::new();
    for (k, node) in [11i64, 12].iter().enumerate() {
        // Accelerance in g/N: −ω² h / g.
        let a: Vec<C64> = h[k]
            .iter()
            .zip(&f)
            .map(|(z, fk)| -z * (2.0 * std::f64::consts::PI * fk).powi(2) / 9.80665)
            .collect();
        let mut s = uff::Function::frf_between("Prüfstand", f.clone(), a, (*node, 3), (1, 3));
        s.response_entity = "Prüfstand".into();
        s.axes[1].spec_data_type = 12;
        s.axes[1].units = "g".into();
        s.axes[2].spec_data_type = 13;
        s.axes[2].units = "N".into();
        sets.push(s);
    }
    let data = dir.path().join("run.unv");
    uff::write(&data, &sets, uff::Encoding::Binary).unwrap();
    let map = dir.path().join("map.toml");
    std::fs::write(&map, MAP).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let o = identify_two_mass(&data, &vars, &["--map", p(&map), "--format", "json"], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("data: first u3: accelerance in (g)/(N) converted to (m/s²)/N (× 9.80665)")
            && err.contains("acceleration converted to the model's displacement output by (jω)^-2"),
        "{err}"
    );
    let j: serde_json::Value = serde_json::from_str(&utf8(&o.stdout)).unwrap();
    let table = j["table"].as_array().unwrap();
    for (row, truth) in table.iter().zip([20.0, 5.0]) {
        let v = row["identified"].as_f64().unwrap();
        assert!((v / truth - 1.0).abs() < 1e-6, "{row}");
    }
    assert!(j["misfit"].is_null());
    // Without the map: what to give.
    let o = identify_two_mass(&data, &vars, &[], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        utf8(&o.stderr).contains("give --map FILE"),
        "{}",
        utf8(&o.stderr)
    );
}

#[test]
fn frequencies_in_khz_under_freq_hz_stop_before_a_confident_wrong_fit() {
    let dir = tempfile::tempdir().unwrap();
    let f = lines();
    let h = receptances(&f);
    let mut csv = String::from("# unit = mm/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            csv.push_str(&format!(
                "{body},u3,{:?},{:?}\n",
                fk / 1000.0,
                h[k][i].norm() * 1e3
            ));
        }
    }
    let data = dir.path().join("khz.csv");
    std::fs::write(&data, &csv).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let o = identify_two_mass(&data, &vars, &[], &[]);
    assert_eq!(o.status.code(), Some(2), "{}", utf8(&o.stdout));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("khz.csv: frequencies:") && err.contains("kHz"),
        "{err}"
    );
    // The same lines in Hz are fine; with one output 9.81x too high the level warning names g and
    // the fit's headline says the model does not explain the data.
    let mut csv = String::from("# unit = mm/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            let g = if k == 1 { 9.80665 } else { 1.0 };
            csv.push_str(&format!(
                "{body},u3,{fk:?},{:?}\n",
                h[k][i].norm() * 1e3 * g
            ));
        }
    }
    std::fs::write(&data, &csv).unwrap();
    let report = dir.path().join("report");
    let o = identify_two_mass(&data, &vars, &["--out", p(&report)], &[]);
    let err = utf8(&o.stderr);
    assert!(
        err.contains("warning: second u3 displacement") && err.contains("g read as m/s²"),
        "{err}"
    );
    let out = utf8(&o.stdout);
    assert!(
        out.starts_with("THE MODEL DOES NOT EXPLAIN THE DATA"),
        "{out}"
    );
    // The report says it first too, in its status, and the page shows it.
    let json = std::fs::read_to_string(report.join("report.json")).unwrap();
    let r: serde_json::Value = serde_json::from_str(&json).unwrap();
    let first = r["status"]["messages"][0].as_str().unwrap();
    assert!(
        first.starts_with("THE MODEL DOES NOT EXPLAIN THE DATA: reduced χ²"),
        "{first}"
    );
    let html = std::fs::read_to_string(report.join("report.html")).unwrap();
    assert!(html.contains("<li>THE MODEL DOES NOT EXPLAIN THE DATA"));
}

#[test]
fn frequencies_in_khz_that_still_overlap_the_band_end_in_the_misfit_headline() {
    // Measured from 10 Hz to 4 kHz and written in kHz under freq_hz: 0.01-4 "Hz", which reaches
    // within a decade of the model's first resonance (25 Hz), so the band check lets it through.
    // The fit must not pass for a result: its headline says the model does not explain the data,
    // that the standard errors are not to be trusted, and names kHz among the likely causes.
    let dir = tempfile::tempdir().unwrap();
    let f: Vec<f64> = (0..60)
        .map(|i| 10.0 * 400f64.powf(i as f64 / 59.0))
        .collect();
    let h = receptances(&f);
    let mut csv = String::from("# unit = m/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            csv.push_str(&format!(
                "{body},u3,{:?},{:?}\n",
                fk / 1000.0,
                h[k][i].norm()
            ));
        }
    }
    let data = dir.path().join("khz.csv");
    std::fs::write(&data, &csv).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let o = identify_two_mass(&data, &vars, &[], &[]);
    let out = utf8(&o.stdout);
    let first = out.lines().next().unwrap_or_default();
    assert!(
        first.starts_with("THE MODEL DOES NOT EXPLAIN THE DATA")
            && first.contains("NOT to be trusted")
            && first.contains("kHz vs Hz"),
        "{out}\n{}",
        utf8(&o.stderr)
    );
}

/// A dense CSV of the two-mass chain (mm/N, 0.05 Hz lines over 2-80 Hz) with what real spectra
/// carry: a mains line at 50 Hz and its neighbours 20× too high, and junk below 5 Hz.
fn dense_with_disturbances(dir: &Path) -> PathBuf {
    let f: Vec<f64> = (40..=1600).map(|i| i as f64 * 0.05).collect();
    let h = receptances(&f);
    let mut csv = String::from("# unit = mm/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            let disturbed = (fk - 50.0).abs() <= 0.3 || *fk < 5.0;
            let a = h[k][i].norm() * 1e3 * if disturbed { 20.0 } else { 1.0 };
            csv.push_str(&format!("{body},u3,{fk:?},{a:?}\n"));
        }
    }
    let data = dir.join("dense.csv");
    std::fs::write(&data, csv).unwrap();
    data
}

#[test]
fn band_mains_and_decimation_choose_the_lines_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let data = dense_with_disturbances(dir.path());
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let estimates = |extra: &[&str]| {
        let mut args = vec!["--format", "json"];
        args.extend_from_slice(extra);
        let o = identify_two_mass(&data, &vars, &args, &[]);
        assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let k: Vec<f64> = j["table"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["identified"].as_f64().unwrap())
            .collect();
        (k, utf8(&o.stderr), j["fit"].as_str().unwrap().to_string())
    };
    // All 1561 lines, disturbances included: the estimates are pulled off the truth.
    let (k, _, fit) = estimates(&[]);
    assert_eq!(fit, "log-amplitude", "magnitudes without variances");
    let off = (k[0] / 20.0 - 1.0).abs().max((k[1] / 5.0 - 1.0).abs());
    assert!(off > 1e-3, "the disturbances should bias the fit: {k:?}");
    // Band from 5 Hz, mains harmonics out, decimated to 150 lines: the truth.
    let (k, err, _) = estimates(&["--band", "5:", "--mains", "50", "--points", "150"]);
    for (v, truth) in k.iter().zip([20.0, 5.0]) {
        assert!((v / truth - 1.0).abs() < 1e-6, "{k:?}\n{err}");
    }
    assert!(
        err.contains(
            "lines: first u3: 1480 of 1561 lines kept (dropped 60 outside the band, 21 near excluded lines)"
        ),
        "{err}"
    );
    assert!(
        err.contains("decimated from") && err.contains("to 150 lines"),
        "{err}"
    );

    // Bad choices: exit 2, the option and the fix named.
    for (args, want) in [
        (
            vec!["--band", "90:10"],
            "--band 90:10: the lower edge must be below the upper one",
        ),
        (
            vec!["--band", "500:"],
            "none of its 1561 lines (2-80 Hz) is left",
        ),
        (vec!["--band", "x"], "give LO:HI in Hz"),
        (vec!["--points", "1"], "--points 1: give at least 2"),
    ] {
        let o = identify_two_mass(&data, &vars, &args, &[]);
        let e = utf8(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(want), "{args:?}: {e}");
    }
}
