//! `ident nightly` with `[stability]`: each night's report has the chatter-stability section of
//! the final model, the minimum stable depth over the cut's speed range is recorded in the run
//! history beside the parameters and written to the Prometheus textfile, `ident history series`
//! prints its series, and a night whose depth fell below the learned normal raises the alarm
//! that says so ("… fell from … to … mm"). That a loosening joint lowers the depth enough to be
//! alarmed is `history/tests/stable_depth.rs`; here the history is seeded with a deeper normal.

#![allow(clippy::unwrap_used)]

mod common;

use common::{ident, json, report_dir, root, text};
use history::store::Store;

#[test]
fn the_nightly_records_judges_and_exports_the_stable_depth() {
    let dir = tempfile::tempdir().unwrap();
    let (_, live) = common::short_demo(dir.path());
    let cut = root().join("configs/cuts/fwd32j-face-milling.toml");
    let extra = format!(
        "prometheus = \"metrics/ident.prom\"\n[history]\ndatabase = \"history.sqlite\"\nbaseline_runs = 6\n[stability]\ncut = \"{}\"\nspeed_rpm = [300, 1800]\n",
        cut.display()
    );
    let cfg = common::nightly_job(
        dir.path(),
        "nightly.toml",
        &live,
        "newest-session",
        &live,
        &extra,
    );
    let cfg_s = cfg.to_str().unwrap();
    let db = dir.path().join("history.sqlite");
    let prom = dir.path().join("metrics/ident.prom");
    let name = "stable depth 300–1800 rpm (fwd32j-face-milling)";

    // First night: the report's section, the history's quantity, the textfile's gauge.
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
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
    let runs = Store::open_read_only(&db).unwrap().runs().unwrap();
    assert_eq!(runs.len(), 1);
    let first = runs[0].clone();
    assert_eq!(first.quantities.len(), 1);
    let q = &first.quantities[0];
    assert_eq!((q.variable.as_str(), q.unit.as_str()), (name, "mm"));
    assert!((q.in_unit() - depth_mm).abs() < 1e-9 * depth_mm);
    assert!(q.std_error.is_some_and(|s| s > 0.0));
    let p = std::fs::read_to_string(&prom).unwrap();
    let gauge =
        format!("ident_nightly_stable_depth_mm{{job_name=\"test job\",quantity=\"{name}\"}} ");
    let line = p
        .lines()
        .find(|l| l.starts_with(&gauge))
        .unwrap_or_else(|| panic!("{p}"));
    let exported: f64 = line[gauge.len()..].parse().unwrap();
    assert!((exported - depth_mm).abs() < 1e-9 * depth_mm, "{line}");
    assert!(p.contains("ident_nightly_stable_depth_sigma_mm{"), "{p}");

    // A history in which the depth was 30 % deeper (with a little scatter): tonight, the same
    // measurement again, the depth fell.
    {
        std::fs::remove_file(&db).unwrap();
        let mut s = Store::open(&db).unwrap();
        let mut deeper = first.clone();
        deeper.quantities[0].estimate *= 1.3;
        s.append(&deeper).unwrap();
        for i in 0..6 {
            let mut run = deeper.clone();
            run.run_id = format!("earlier-{i}");
            run.time_utc = format!("2000-01-0{}T02:00:00Z", i + 1);
            run.quantities[0].estimate *= 1.0 + 0.004 * ((i % 5) as f64 - 2.0);
            s.append(&run).unwrap();
        }
    }
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    assert_eq!(r["status"]["outcome"], "alarm");
    let ms: Vec<String> = r["status"]["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m.as_str().unwrap().to_string())
        .collect();
    let alarm = ms
        .iter()
        .find(|m| m.starts_with("drift alarm (") && m.contains(&format!("): {name} fell from ")))
        .unwrap_or_else(|| panic!("{ms:?}"));
    assert!(alarm.contains(" mm, -"), "{alarm}");
    let log = std::fs::read_to_string(dir.path().join("nightly.log")).unwrap();
    assert!(log.contains(&format!("ALARM: {alarm}")), "{log}");
    let p = std::fs::read_to_string(&prom).unwrap();
    assert!(
        p.contains(&format!("ident_nightly_parameter_deviation_scatters{{job_name=\"test job\",variable=\"{name}\"}} -")),
        "{p}"
    );

    // The series of the depth, and the CSV, from the history.
    let o = ident(&[
        "history",
        db.to_str().unwrap(),
        "series",
        name,
        "--baseline-runs",
        "6",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(out.lines().count(), 1 + 8, "{out}");
    assert!(out.lines().last().unwrap().contains("Shewhart"), "{out}");
    let o = ident(&["history", db.to_str().unwrap(), "csv"]);
    assert!(String::from_utf8_lossy(&o.stdout).contains(name));
}
