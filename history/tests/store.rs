//! The history database: round trip, WAL readers during a write, refusal of newer, corrupt and
//! locked files without writing, import of report folders.

#![allow(clippy::unwrap_used)]

use history::record::{CharacteristicFit, Covariate, ParameterRecord, RunRecord};
use history::store::{Store, SCHEMA_VERSION};
use history::HistoryError;

fn run(i: usize) -> RunRecord {
    RunRecord {
        run_id: format!("run-{i:03}"),
        time_utc: format!("2026-03-{:02}T02:00:00Z", i + 1),
        stand: Some("FWD-32J".into()),
        model_hash: "00000000000000aa".into(),
        session: Some(format!("sessions/s{i}.mcap")),
        outcome: "ok".into(),
        reduced_chi2: Some(1.0 + 0.01 * i as f64),
        parameters: vec![
            ParameterRecord {
                variable: "kn_table".into(),
                unit: "MPa/um".into(),
                unit_factor: 1e12,
                estimate: (0.05 + 0.001 * i as f64) * 1e12,
                std_error: Some(1e9),
            },
            ParameterRecord {
                variable: "psi".into(),
                unit: "-".into(),
                unit_factor: 1.0,
                estimate: 0.8,
                std_error: None,
            },
        ],
        characteristics: vec![CharacteristicFit {
            label: "table u1 displacement".into(),
            rms_relative_error: 0.012,
        }],
        effects: if i == 2 {
            vec!["spring spindle head–table".into()]
        } else {
            vec![]
        },
        covariates: vec![Covariate {
            name: "temperature".into(),
            unit: "degC".into(),
            value: 20.0 + i as f64,
        }],
        correlations: vec![],
        quantities: vec![],
    }
}

#[test]
fn runs_round_trip_in_time_order_and_a_duplicate_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    let mut s = Store::open(&path).unwrap();
    for i in [2, 0, 1] {
        s.append(&run(i)).unwrap();
    }
    let before = s.runs().unwrap();
    assert!(s.append(&run(1)).is_err());
    drop(s);
    let s = Store::open_read_only(&path).unwrap();
    let runs = s.runs().unwrap();
    assert_eq!(runs, before, "a refused duplicate changes nothing");
    assert_eq!(runs, vec![run(0), run(1), run(2)]);
}

#[test]
fn readers_see_committed_runs_while_a_writer_holds_a_transaction() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    let mut w = Store::open(&path).unwrap();
    w.append(&run(0)).unwrap();
    // A second connection opens a write transaction and keeps it open (a nightly mid-write).
    let raw = rusqlite::Connection::open(&path).unwrap();
    raw.execute_batch("BEGIN IMMEDIATE; INSERT INTO runs (run_id, time_utc, model_hash, outcome) VALUES ('x', 't', 'h', 'ok');")
        .unwrap();
    let r = Store::open_read_only(&path).unwrap();
    assert_eq!(
        r.runs().unwrap(),
        vec![run(0)],
        "WAL: the reader is not blocked and sees only committed runs"
    );
    // The writer's uncommitted run is lost when it dies; the committed one stays.
    drop(raw);
    assert_eq!(Store::open(&path).unwrap().runs().unwrap(), vec![run(0)]);
}

#[test]
fn a_version_2_file_is_read_as_it_is_and_upgraded_for_writing() {
    // A version-2 history: today's file without the quantities table.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    Store::open(&path).unwrap().append(&run(0)).unwrap();
    let c = rusqlite::Connection::open(&path).unwrap();
    c.execute_batch("DROP TABLE quantities; PRAGMA user_version = 2;")
        .unwrap();
    drop(c);
    assert_eq!(
        Store::open_read_only(&path).unwrap().runs().unwrap(),
        vec![run(0)],
        "read as it is, without quantities"
    );
    let version = |p: &std::path::Path| -> i64 {
        rusqlite::Connection::open(p)
            .unwrap()
            .pragma_query_value(None, "user_version", |r| r.get(0))
            .unwrap()
    };
    assert_eq!(version(&path), 2, "reading does not upgrade");
    let mut with_depth = run(1);
    with_depth.quantities.push(ParameterRecord {
        variable: "stable depth 200–2000 rpm (face-milling)".into(),
        unit: "mm".into(),
        unit_factor: 1e-3,
        estimate: 2.1e-3,
        std_error: Some(0.05e-3),
    });
    Store::open(&path).unwrap().append(&with_depth).unwrap();
    assert_eq!(version(&path), SCHEMA_VERSION);
    assert_eq!(
        Store::open_read_only(&path).unwrap().runs().unwrap(),
        vec![run(0), with_depth]
    );
}

#[test]
fn a_newer_schema_is_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    Store::open(&path).unwrap().append(&run(0)).unwrap();
    let c = rusqlite::Connection::open(&path).unwrap();
    c.pragma_update(None, "user_version", SCHEMA_VERSION + 1)
        .unwrap();
    c.pragma_update(None, "journal_mode", "DELETE").unwrap();
    drop(c);
    let bytes = std::fs::read(&path).unwrap();
    match Store::open(&path) {
        Err(HistoryError::NewerVersion {
            found, supported, ..
        }) => {
            assert_eq!((found, supported), (SCHEMA_VERSION + 1, SCHEMA_VERSION));
        }
        other => panic!("expected NewerVersion, got {:?}", other.map(|_| ())),
    }
    assert_eq!(
        std::fs::read(&path).unwrap(),
        bytes,
        "the file is untouched"
    );
    assert!(
        !dir.path().join("h.sqlite-wal").exists(),
        "no WAL was started"
    );
}

#[test]
fn a_corrupt_file_and_a_foreign_database_are_refused_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    let junk = b"this is the nightly config, not a database\n".repeat(100);
    std::fs::write(&path, &junk).unwrap();
    let e = Store::open(&path).err().unwrap();
    assert!(matches!(e, HistoryError::Corrupt { .. }), "{e}");
    assert!(e.to_string().contains("h.sqlite") && e.to_string().contains("move it aside"));
    assert_eq!(std::fs::read(&path).unwrap(), junk);

    let other = dir.path().join("other.sqlite");
    rusqlite::Connection::open(&other)
        .unwrap()
        .execute_batch("CREATE TABLE t (x)")
        .unwrap();
    let e = Store::open(&other).err().unwrap();
    assert!(matches!(e, HistoryError::Corrupt { .. }), "{e}");
}

#[test]
fn a_locked_database_is_a_locked_error_after_the_wait() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("h.sqlite");
    let mut s = Store::open(&path).unwrap();
    let raw = rusqlite::Connection::open(&path).unwrap();
    raw.execute_batch("BEGIN EXCLUSIVE;").unwrap();
    let e = s.append(&run(0)).err().unwrap();
    assert!(matches!(e, HistoryError::Locked { .. }), "{e}");
    raw.execute_batch("ROLLBACK;").unwrap();
    s.append(&run(0)).unwrap();
    assert_eq!(s.runs().unwrap().len(), 1);
}

#[test]
fn report_folders_import_once_with_units_in_si_and_bad_ones_are_listed() {
    let dir = tempfile::tempdir().unwrap();
    let reports = dir.path().join("reports");
    let model = dir.path().join("model.toml");
    std::fs::write(&model, "model bytes").unwrap();
    let report = |t: &str, kn: f64| {
        // A whole `ident.report/1` document: the import reads the report type itself.
        serde_json::json!({
            "schema": "ident.report/1", "title": "night", "created_utc": t,
            "source": {"workflow": "nightly", "session": "s.mcap", "stand": "FWD-32J",
                       "model": model.display().to_string(), "variables": "v.toml",
                       "measurement": "s.mcap", "software": "ident"},
            "status": {"outcome": "ok", "messages": []},
            "identification": {"optimizer": "lm", "converged": true, "stop": "converged",
                "iterations": 5, "observations": 100, "noise": "variance",
                "criterion_initial": 2.0, "criterion": 1.0, "reduced_chi2": 1.1, "parameters": [
                {"variable": "kn_table", "sdes": "2", "parameter": "kn", "unit": "MPa/um",
                 "initial": 0.05, "identified": kn, "std_error": 0.001, "variability": 0.02,
                 "at_bound": null},
                {"variable": "k_screw", "sdes": "9", "parameter": "k", "unit": "N/um",
                 "initial": 300.0, "identified": 300.0, "std_error": null, "variability": null,
                 "at_bound": null}],
                "correlation": [[1.0, 0.0], [0.0, 1.0]], "weak_directions": []},
            "characteristics": [{"label": "table u1 displacement", "body": "table", "dof": 0,
                "quantity": "displacement", "unit": "m", "freqs_hz": [10.0], "measured": [1e-6],
                "sigma": [1e-8], "sigma_kind": "variance", "stages": [
                {"stage": "identified", "amplitude": [1.02e-6], "standardized_residual": [-2.0],
                 "rms_relative_error": 0.02}]}],
            "diagnosis": null, "sensitivity": null, "drift": null
        })
    };
    for (f, t, kn) in [
        ("2026-03-02T020000Z", "2026-03-02T02:00:00Z", 0.051),
        ("2026-03-01T020000Z", "2026-03-01T02:00:00Z", 0.05),
    ] {
        std::fs::create_dir_all(reports.join(f)).unwrap();
        std::fs::write(
            reports.join(f).join("report.json"),
            report(t, kn).to_string(),
        )
        .unwrap();
    }
    std::fs::create_dir_all(reports.join("broken")).unwrap();
    std::fs::write(reports.join("broken/report.json"), "{").unwrap();
    let mut s = Store::open(&dir.path().join("h.sqlite")).unwrap();
    let sum = history::import::import_reports(&mut s, &reports).unwrap();
    assert_eq!(
        (sum.imported, sum.already_stored, sum.skipped.len()),
        (2, 0, 1)
    );
    assert!(sum.skipped[0].contains("broken"));
    let again = history::import::import_reports(&mut s, &reports).unwrap();
    assert_eq!((again.imported, again.already_stored), (0, 2));
    let runs = s.runs().unwrap();
    assert_eq!(runs[0].run_id, "2026-03-01T020000Z");
    let kn = runs[1].parameter("kn_table").unwrap();
    assert!((kn.estimate - 0.051e12).abs() < 1.0 && (kn.std_error.unwrap() - 1e9).abs() < 1e-3);
    assert!((runs[1].parameter("k_screw").unwrap().estimate - 300e6).abs() < 1e-6);
    assert_eq!(
        runs[0].model_hash,
        history::record::model_hash(b"model bytes")
    );
    assert_eq!(runs[0].characteristics[0].rms_relative_error, 0.02);
}
