//! Reports into run records: a value that is not a number names the report, the parameter and
//! the fix; the model identity does not depend on the current directory; the Cramér-Rao
//! comparison of a short history (`judge::crlb`).

#![allow(clippy::unwrap_used, dead_code)]

mod common;

use history::import::{run_from_report_text, runs_from_reports};
use history::judge::crlb::{compare, Baseline};

fn report(night: usize, k1: &str) -> String {
    format!(
        r#"{{"schema":"ident.report/1","title":"t","created_utc":"2026-01-0{night}T02:00:00Z",
"source":{{"workflow":"nightly","session":null,"stand":null,"model":"models/m.toml","variables":"v.toml","measurement":"m","software":"ident"}},
"status":{{"outcome":"ok","messages":[]}},"characteristics":[],
"identification":{{"optimizer":"lm","converged":true,"stop":"s","iterations":1,"observations":10,"noise":"n",
"criterion_initial":1.0,"criterion":0.5,"reduced_chi2":1.0,
"parameters":[{{"variable":"kn 1","sdes":"1","parameter":"kn","unit":"N/um","initial":1.0,"identified":{k1},"std_error":0.1,"variability":0.1,"at_bound":null}}],
"correlation":[[1.0]],"weak_directions":[]}},
"diagnosis":null,"sensitivity":null,"drift":null}}"#
    )
}

#[test]
fn a_nan_in_a_report_names_the_report_the_parameter_and_the_fix() {
    let e = run_from_report_text(
        &report(1, "NaN"),
        std::path::Path::new("reports/2026-01-01/report.json"),
        "r",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("reports/2026-01-01/report.json"), "{e}");
    assert!(
        e.contains("parameter kn 1") && e.contains("\"identified\""),
        "{e}"
    );
    assert!(e.contains("re-run") && e.contains("move its folder"), "{e}");
}

#[test]
fn the_model_identity_does_not_depend_on_the_current_directory() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("models")).unwrap();
    std::fs::write(dir.path().join("models/m.toml"), "model bytes").unwrap();
    for n in 1..=3 {
        let f = dir.path().join(format!("reports/n{n}"));
        std::fs::create_dir_all(&f).unwrap();
        std::fs::write(
            f.join("report.json"),
            report(n, &format!("{}", 10.0 + n as f64)),
        )
        .unwrap();
    }
    // The report names `models/m.toml` relative to the job's folder, not to where we run.
    let (runs, summary) = runs_from_reports(&dir.path().join("reports")).unwrap();
    assert_eq!(runs.len(), 3);
    let want = history::record::model_hash(b"model bytes");
    assert!(
        runs.iter().all(|r| r.model_hash == want),
        "{:?}",
        runs[0].model_hash
    );
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    // The model file gone: the identity is the file name, and a mixed folder warns with both.
    std::fs::remove_file(dir.path().join("models/m.toml")).unwrap();
    let moved = dir.path().join("reports/n4");
    std::fs::create_dir_all(&moved).unwrap();
    std::fs::write(moved.join("report.json"), report(4, "14.0")).unwrap();
    let (runs, _) = runs_from_reports(&dir.path().join("reports")).unwrap();
    assert!(runs.iter().all(|r| r.model_hash == "file:m.toml"));
}

#[test]
fn the_short_history_comparison_is_in_cramer_rao_errors_of_the_difference() {
    let p = std::path::Path::new("r.json");
    let a = run_from_report_text(&report(1, "10.0"), p, "a").unwrap();
    let b = run_from_report_text(&report(2, "10.8"), p, "b").unwrap();
    let now = run_from_report_text(&report(3, "11.0"), p, "now").unwrap();
    let d = compare(&[a.clone(), b.clone()], &now, &Baseline::First, 3.0)
        .unwrap()
        .unwrap();
    let want = 1.0 / (0.1f64 * 0.1 * 2.0).sqrt();
    assert!((d.parameters[0].deviation_sigma.unwrap() - want).abs() < 1e-9);
    assert!(d.parameters[0].alarm);
    let d = compare(
        &[a.clone(), b.clone()],
        &now,
        &Baseline::Run("b".into()),
        3.0,
    )
    .unwrap()
    .unwrap();
    assert_eq!(d.baseline, 1);
    assert!(!d.parameters[0].alarm);
    let e = compare(&[a, b], &now, &Baseline::Run("zz".into()), 3.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("\"zz\"") && e.contains("baseline"), "{e}");
}
