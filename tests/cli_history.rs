//! `ident nightly` with a run history (`[history]`, issue 18): every run is recorded, too few
//! baseline runs are said so, a step against the learned normal is an alarm (exit 1) with the
//! rule and size, a corrupt history database is reported and left untouched while the run's
//! report is still written, the Prometheus textfile follows each run, and an unfinished session
//! (a nightly killed mid-sweep) is skipped and said so. With `[stability]` each night's report has
//! the chatter-stability section, the minimum stable depth is recorded beside the parameters,
//! exported to the textfile and judged: a night whose depth fell below the learned normal raises
//! the alarm that says so ("… fell from … to … mm"). That a loosening joint lowers the depth
//! enough to be alarmed is `history/tests/stable_depth.rs`; here the history is seeded.

#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};

use common::{ident, json, report_dir, text};
use history::store::Store;

fn messages(r: &serde_json::Value) -> Vec<String> {
    r["status"]["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap().to_string())
        .collect()
}

/// The stable depth of the job's cut (`[stability]` of [`write_job`]).
const DEPTH: &str = "stable depth 300–1800 rpm (fwd32j-face-milling)";

fn write_job(dir: &Path, live: &Path, database: &str) -> PathBuf {
    let extra = format!(
        "prometheus = \"metrics/ident.prom\"\n[history]\ndatabase = \"{database}\"\nbaseline_runs = 6\n[stability]\ncut = \"{}\"\nspeed_rpm = [300, 1800]\n",
        common::root()
            .join("configs/cuts/fwd32j-face-milling.toml")
            .display()
    );
    common::nightly_job(dir, "nightly.toml", live, "newest-session", live, &extra)
}

#[test]
fn nightly_records_every_run_and_judges_drift_from_the_history() {
    let dir = tempfile::tempdir().unwrap();
    let (_, live) = common::short_demo(dir.path());
    let cfg = write_job(dir.path(), &live, "history.sqlite");
    let cfg_s = cfg.to_str().unwrap();
    let db = dir.path().join("history.sqlite");
    let prom = dir.path().join("metrics/ident.prom");

    // First night: recorded, not judged yet, and the report says why.
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    assert!(
        messages(&r)
            .iter()
            .any(|m| m.contains("drift not judged") && m.contains("0 of the 6")),
        "{:?}",
        messages(&r)
    );
    let runs = Store::open_read_only(&db).unwrap().runs().unwrap();
    assert_eq!(runs.len(), 1);
    let first = runs[0].clone();
    assert_eq!(
        first.run_id,
        report_dir(&o).file_name().unwrap().to_string_lossy()
    );
    assert_eq!(first.outcome, "ok");
    assert!(!first.parameters.is_empty() && first.reduced_chi2.is_some());
    let p = std::fs::read_to_string(&prom).unwrap();
    assert!(
        p.contains("ident_nightly_exit_code{job_name=\"test job\"} 0"),
        "{p}"
    );
    assert!(
        p.contains("ident_nightly_drift_judged{job_name=\"test job\"} 0"),
        "{p}"
    );
    assert!(!dir.path().join("metrics/ident.prom.partial").exists());

    // The stable depth: the report's section, the history's quantity, the textfile's gauge.
    let s = &r["stability"];
    assert_eq!(s["speed_rpm"], serde_json::json!([300.0, 1800.0]));
    let depth_mm = s["minimum"]["depth_mm"].as_f64().unwrap();
    assert!(depth_mm > 0.0, "{s}");
    assert!(
        s["minimum"]["band_mm"].is_array(),
        "the band from the final fit: {s}"
    );
    assert!(!s["limiting"].as_array().unwrap().is_empty());
    let html = std::fs::read_to_string(report_dir(&o).join("report.html")).unwrap();
    assert!(html.contains("id=\"stability\""));
    assert_eq!(first.quantities.len(), 1);
    let q = &first.quantities[0];
    assert_eq!((q.variable.as_str(), q.unit.as_str()), (DEPTH, "mm"));
    assert!((q.in_unit() - depth_mm).abs() < 1e-9 * depth_mm);
    assert!(q.std_error.is_some_and(|s| s > 0.0));
    let gauge =
        format!("ident_nightly_stable_depth_mm{{job_name=\"test job\",quantity=\"{DEPTH}\"}} ");
    let line = p
        .lines()
        .find(|l| l.starts_with(&gauge))
        .unwrap_or_else(|| panic!("{p}"));
    let exported: f64 = line[gauge.len()..].parse().unwrap();
    assert!((exported - depth_mm).abs() < 1e-9 * depth_mm, "{line}");
    assert!(p.contains("ident_nightly_stable_depth_sigma_mm{"), "{p}");

    // Six earlier nights and the first one on which the first parameter was 20 % stiffer and the
    // stable depth 30 % deeper (normal scatter 0.3 %): tonight, the same measurement again, is a
    // step down in both. The history is
    // written anew so that the first night is at the earlier level too: an alarm is raised once,
    // on the first night beyond the limits, and a first night already off would take it.
    {
        std::fs::remove_file(&db).unwrap();
        let mut s = Store::open(&db).unwrap();
        let mut stiffer = first.clone();
        stiffer.parameters[0].estimate *= 1.2;
        stiffer.quantities[0].estimate *= 1.3;
        s.append(&stiffer).unwrap();
        for i in 0..6 {
            let mut run = first.clone();
            run.run_id = format!("earlier-{i}");
            run.time_utc = format!("2000-01-0{}T02:00:00Z", i + 1);
            for (k, p) in run.parameters.iter_mut().enumerate() {
                let wobble = 1.0 + 0.003 * (((i * 7 + k * 3) % 5) as f64 - 2.0);
                p.estimate *= wobble * if k == 0 { 1.2 } else { 1.0 };
            }
            run.quantities[0].estimate *= 1.3 * (1.0 + 0.003 * ((i % 5) as f64 - 2.0));
            s.append(&run).unwrap();
        }
    }
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    assert_eq!(r["status"]["outcome"], "alarm");
    let name = first.parameters[0].variable.clone();
    let ms = messages(&r);
    let step = ms
        .iter()
        .find(|m| m.starts_with("drift alarm (Shewhart)") && m.contains(&name))
        .unwrap_or_else(|| panic!("{ms:?}"));
    assert!(
        step.contains(&first.parameters[0].unit) && step.contains("normal scatter"),
        "{step}"
    );
    assert!(
        ms.iter()
            .any(|m| m.starts_with("drift: ") && m.contains("alarm(s)")),
        "{ms:?}"
    );
    // The k_sigma comparison against the first run (identical) raises nothing and says it is shown for reference.
    assert!(
        ms.iter().any(|m| m.contains("shown for reference")),
        "{ms:?}"
    );
    let log = std::fs::read_to_string(dir.path().join("nightly.log")).unwrap();
    assert!(log.contains("ALARM: drift alarm (Shewhart)"), "{log}");
    let fell = ms
        .iter()
        .find(|m| m.starts_with("drift alarm (") && m.contains(&format!("): {DEPTH} fell from ")))
        .unwrap_or_else(|| panic!("{ms:?}"));
    assert!(fell.contains(" mm, -"), "{fell}");
    assert!(log.contains(&format!("ALARM: {fell}")), "{log}");
    let runs = Store::open_read_only(&db).unwrap().runs().unwrap();
    assert_eq!(runs.len(), 8);
    assert_eq!(runs.last().unwrap().outcome, "alarm");
    let p = std::fs::read_to_string(&prom).unwrap();
    assert!(
        p.contains("ident_nightly_exit_code{job_name=\"test job\"} 1"),
        "{p}"
    );
    assert!(
        p.contains("ident_nightly_outcome{job_name=\"test job\",outcome=\"alarm\"} 1"),
        "{p}"
    );
    assert!(
        p.contains(&format!(
            "ident_nightly_parameter_deviation_scatters{{job_name=\"test job\",variable=\"{DEPTH}\"}} -"
        )),
        "{p}"
    );
    // The depth's series and the CSV, from the history.
    let o = ident(&[
        "history",
        db.to_str().unwrap(),
        "series",
        DEPTH,
        "--baseline-runs",
        "6",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(out.lines().count(), 1 + 8, "{out}");
    assert!(out.lines().last().unwrap().contains("Shewhart"), "{out}");
    let o = ident(&["history", db.to_str().unwrap(), "csv"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains(DEPTH));

    // `ident identify --record-history`: the same model hashes alike; two runs, two records.
    let c = live.join("configs");
    let model = c.join("models/fwd32j-no-actuator.toml");
    let vars = c.join("identification/fwd32j-no-actuator.toml");
    let db2 = dir.path().join("manual.sqlite");
    for _ in 0..2 {
        let o = ident(&[
            "identify",
            model.to_str().unwrap(),
            "--data",
            live.join("measured.json").to_str().unwrap(),
            "--vars",
            vars.to_str().unwrap(),
            "--record-history",
            db2.to_str().unwrap(),
        ]);
        assert!(
            text(&o).contains("recorded as run identify-"),
            "{}",
            text(&o)
        );
    }
    let manual = Store::open_read_only(&db2).unwrap().runs().unwrap();
    assert_eq!(manual.len(), 2);
    assert_ne!(manual[0].run_id, manual[1].run_id);
    assert_eq!(manual[0].model_hash, first.model_hash);
    assert_eq!(manual[0].parameters.len(), first.parameters.len());

    // A corrupt history database: said so, left untouched, the report still written.
    let junk = b"not a database\n".repeat(200);
    std::fs::write(dir.path().join("broken.sqlite"), &junk).unwrap();
    let cfg = write_job(dir.path(), &live, "broken.sqlite");
    let o = ident(&["nightly", cfg.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    assert!(
        messages(&r)
            .iter()
            .any(|m| m.contains("run history is not used")
                && m.contains("broken.sqlite")
                && m.contains("damaged")),
        "{:?}",
        messages(&r)
    );
    assert_eq!(
        std::fs::read(dir.path().join("broken.sqlite")).unwrap(),
        junk
    );
}

fn synthetic_run(i: usize, k1: f64) -> history::record::RunRecord {
    history::record::RunRecord {
        run_id: format!("2026-01-{:02}T020000Z", i + 1),
        time_utc: format!("2026-01-{:02}T02:00:00Z", i + 1),
        stand: Some("FWD-32J".into()),
        model_hash: "00000000000000aa".into(),
        session: None,
        outcome: "ok".into(),
        reduced_chi2: Some(1.0),
        parameters: vec![history::record::ParameterRecord {
            variable: "kn 2".into(),
            unit: "MPa/um".into(),
            unit_factor: 1e12,
            estimate: k1 * 1e12,
            std_error: Some(1e8),
        }],
        characteristics: vec![],
        effects: vec![],
        covariates: vec![],
        correlations: vec![],
        quantities: vec![],
    }
}

#[test]
fn history_lists_shows_a_series_exports_csv_and_draws_the_trend_page() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("h.sqlite");
    {
        let mut s = Store::open(&db).unwrap();
        for i in 0..12 {
            let wobble = 0.0005 * (((i * 7) % 5) as f64 - 2.0);
            s.append(&synthetic_run(i, 0.05 + wobble)).unwrap();
        }
        s.append(&synthetic_run(12, 0.04)).unwrap();
    }
    let db_s = db.to_str().unwrap();
    let o = ident(&["history", db_s, "list"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 14);

    let o = ident(&["history", db_s, "series", "kn 2", "--baseline-runs", "10"]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout).to_string();
    let last = out.lines().last().unwrap();
    assert!(
        last.starts_with("2026-01-13T020000Z\t") && last.contains("Shewhart"),
        "{out}"
    );
    assert!(!out.lines().nth(11).unwrap().contains("Shewhart"), "{out}");
    let o = ident(&["history", db_s, "series", "kn 9"]);
    assert!(
        !o.status.success() && text(&o).contains("no run in"),
        "{}",
        text(&o)
    );

    let csv = dir.path().join("h.csv");
    let o = ident(&["history", db_s, "csv", "--out", csv.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let t = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(t.lines().count(), 14);
    assert!(t.lines().last().unwrap().contains(",MPa/um,0.04,"), "{t}");

    let html = dir.path().join("trend.html");
    let o = ident(&[
        "history",
        db_s,
        "html",
        html.to_str().unwrap(),
        "--baseline-runs",
        "10",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("13 runs, 1 with alarms"), "{}", text(&o));
    let page = std::fs::read_to_string(&html).unwrap();
    assert_eq!(page.matches("data-chart=\"trend\"").count(), 1);
    assert!(page.contains("<svg") && page.contains("drift alarm (Shewhart)"));

    // A database from a newer ident: a clear error naming the file, nothing changed.
    let c = rusqlite::Connection::open(&db).unwrap();
    c.pragma_update(None, "user_version", 99).unwrap();
    drop(c);
    let o = ident(&["history", db_s, "list"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("schema version 99") && text(&o).contains("h.sqlite"),
        "{}",
        text(&o)
    );
}
