//! End-to-end tests of the operator workflows: `ident demo` over the simulated serial devices,
//! `ident replay` (bit-identical to the live run, truncated recordings), and `ident nightly`
//! (lock, drift alarm, unreachable stand, bad config). The full disk is in `cli_acquire.rs`.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{ident, json, report_dir, text};

/// A short demo (10 lines, 8x real time): the live run that records a session.
fn short_demo(out: &Path) -> PathBuf {
    let (o, dir) = common::short_demo(out);
    assert_reads_cleanly(&text(&o), "demo output");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    assert_reads_cleanly(&html, "report.html");
    // The final model comes first: after the actuator is added, every variable at the final fit.
    let r = json(&dir.join("report.json"));
    let d = &r["diagnosis"];
    let added = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["accepted"] == true);
    let finals = d["final_parameters"].as_array().unwrap();
    let variables = r["identification"]["parameters"].as_array().unwrap().len();
    assert_eq!(finals.len(), if added { variables } else { 0 }, "{d}");
    let at = |needle: &str| html.find(needle).unwrap_or(usize::MAX);
    assert!(
        at("id=\"final\"") < at("id=\"identification\""),
        "final model first"
    );
    assert!(text(&o).contains("FINAL MODEL"), "{}", text(&o));
    // The picture of the final model: an accepted spring (the actuator) is drawn highlighted,
    // and every stored mode in the band has its figure.
    let p = &r["picture"];
    let springs = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .any(|c| c["accepted"] == true && c["name"] == "spring");
    let drawn_added = p["sdes"]
        .as_array()
        .unwrap()
        .iter()
        .any(|s| s["added"] == true && s["kind"] == "spring");
    assert_eq!(drawn_added, springs, "{p}");
    assert_eq!(html.matches("data-chart=\"model\"").count(), 1);
    assert_eq!(
        html.matches("data-chart=\"mode\"").count(),
        p["modes"].as_array().unwrap().len()
    );
    dir
}

/// No float noise (`3999.9999999999995`) and no relative error printed as `0.000`.
fn assert_reads_cleanly(text: &str, what: &str) {
    let around = |a: usize, b: usize| {
        let (mut a, mut b) = (a.saturating_sub(80), (b + 20).min(text.len()));
        while !text.is_char_boundary(a) {
            a -= 1;
        }
        while !text.is_char_boundary(b) {
            b += 1;
        }
        &text[a..b]
    };
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if !bytes[i].is_ascii_digit() || (i > 0 && (bytes[i - 1].is_ascii_alphanumeric())) {
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.') {
            i += 1;
        }
        let number = &text[start..i];
        let exponent = bytes.get(i).is_some_and(|b| *b == b'e' || *b == b'E');
        if let Some((_, fraction)) = number.split_once('.') {
            assert!(
                exponent || !(fraction.contains("999999") || fraction.contains("000000")),
                "{what}: float noise {number:?} in …{}…",
                around(start, i)
            );
        }
        assert!(
            number != "0.000",
            "{what}: a number printed as 0.000 in …{}…",
            around(start, i)
        );
    }
}

/// `ident replay SESSION` with the demo's identification model and variables (copied into the
/// demo's folder `live`), its report folder under `out`.
fn replay_into(live: &Path, session: &Path, out: &Path) -> Output {
    let model = live.join("configs/models/fwd32j-no-actuator.toml");
    let vars = live.join("configs/identification/fwd32j-no-actuator.toml");
    ident(&[
        "replay",
        session.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--vars",
        vars.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn replay_reproduces_the_live_run_bit_for_bit_and_reports_truncation() {
    let dir = tempfile::tempdir().unwrap();
    let live = short_demo(dir.path());
    let session = live.join("session.mcap");
    let replays = dir.path().join("replays");
    let o = replay_into(&live, &session, &replays);
    assert!(o.status.success(), "{}", text(&o));
    let replay = report_dir(&o);
    // Floats are written shortest-round-trip, so equal text means equal bits.
    for f in [
        "measured.json",
        "identification.json",
        "identification.csv",
        "identified-model.json",
        "identified-model.toml",
        "final-model.toml",
        "final-variables.toml",
    ] {
        let (a, b) = (
            std::fs::read(live.join(f)).unwrap(),
            std::fs::read(replay.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs between the live run and the replay");
    }
    let (a, b) = (
        json(&live.join("report.json")),
        json(&replay.join("report.json")),
    );
    for k in ["characteristics", "identification", "sensitivity"] {
        assert_eq!(a[k], b[k], "report.json {k}");
    }
    assert_eq!(a["source"]["workflow"], "demo");
    assert_eq!(b["source"]["workflow"], "replay");

    // A recording cut short (the writer killed mid-sweep): the complete steps are used and the
    // report says precisely what is lost. The low lines' long windows hold most of the bytes, so
    // the cut is at 5/6 of the file: at 2/3 a loaded machine (more force corrections early on)
    // left 6 of 10 lines, 18 observations for the 19 variables, which cannot be identified.
    let bytes = std::fs::read(&session).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 5 / 6]).unwrap();
    let o = replay_into(&live, &cut, &replays);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("truncated") && t.contains("lost"), "{t}");
    let r = json(&report_dir(&o).join("report.json"));
    let steps = r["characteristics"][0]["freqs_hz"]
        .as_array()
        .unwrap()
        .len();
    assert!(
        (1..10).contains(&steps),
        "{steps} of 10 steps survive the cut"
    );
    assert!(r["status"]["messages"]
        .as_array()
        .unwrap()
        .iter()
        .any(|m| m.as_str().unwrap().contains("truncated")));
}

fn write_job(dir: &Path, live: &Path, extra: &str) -> PathBuf {
    common::nightly_job(dir, "nightly.toml", live, "newest-session", live, extra)
}

#[test]
fn nightly_locks_compares_with_history_and_alarms_on_drift() {
    let dir = tempfile::tempdir().unwrap();
    let live = short_demo(dir.path());
    let cfg = write_job(dir.path(), &live, "[drift]\nk_sigma = 3.0\n");
    let cfg_s = cfg.to_str().unwrap();

    // A live process holds the lock (util-linux `flock`, the same advisory lock, taken by a
    // program nobody on this project wrote): the second run exits 2 and says so, touching nothing.
    let lock = dir.path().join("nightly.lock");
    // `-o`: the lock is flock's own, not inherited by `sleep`, so killing flock releases it.
    let mut holder = Command::new("flock")
        .arg("-o")
        .arg(&lock)
        .args(["sleep", "30"])
        .spawn()
        .expect("util-linux flock");
    let held = std::time::Instant::now();
    while Command::new("flock")
        .args(["-n", lock.to_str().unwrap(), "true"])
        .status()
        .unwrap()
        .success()
    {
        assert!(held.elapsed().as_secs() < 10, "flock never took the lock");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("another ident nightly is running"),
        "{}",
        text(&o)
    );
    assert!(
        !dir.path().join("reports").exists(),
        "a locked-out run writes nothing"
    );
    holder.kill().unwrap();
    holder.wait().unwrap();
    // A run killed with -9 leaves its PID in the file but no lock (the kernel dropped it): the
    // next run takes it over, says so in the log, and releases it at its end.
    let mut dead = Command::new("true").spawn().unwrap();
    dead.wait().unwrap();
    std::fs::write(&lock, format!("{}\n", dead.id())).unwrap();
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let log = std::fs::read_to_string(dir.path().join("nightly.log")).unwrap();
    assert!(log.contains("stale lock"), "{log}");
    assert_eq!(
        std::fs::read_to_string(&lock).unwrap(),
        "",
        "a clean exit empties the PID"
    );
    assert!(
        Command::new("flock")
            .args(["-n", lock.to_str().unwrap(), "true"])
            .status()
            .unwrap()
            .success(),
        "the lock is released"
    );
    let first = report_dir(&o);
    let r = json(&first.join("report.json"));
    assert_eq!(r["status"]["outcome"], "ok");
    assert!(r["drift"].is_null(), "no history on the first night");
    assert_eq!(json(&first.join("status.json"))["outcome"], "ok");

    // Second night, same session: no drift.
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    let d = &r["drift"];
    assert_eq!(d["runs"].as_array().unwrap().len(), 2);
    assert!(
        d["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .all(|p| p["deviation_sigma"].as_f64().is_none_or(|v| v == 0.0) && p["alarm"] == false),
        "{d}"
    );

    // The baseline night's joint was much stiffer (edit its report, in the identification's table
    // and, when the diagnosis added an effect, the final model's, which the comparison reads):
    // tonight is an alarm.
    let mut base = json(&first.join("report.json"));
    let stiffer = |p0: &mut serde_json::Value| {
        let v = p0["identified"].as_f64().unwrap();
        let s = p0["std_error"].as_f64().unwrap();
        p0["identified"] = (v + 20.0 * s).into();
        p0["variable"].as_str().unwrap().to_string()
    };
    let name = stiffer(&mut base["identification"]["parameters"][0]);
    if let Some(finals) = base["diagnosis"]["final_parameters"].as_array_mut() {
        if let Some(f0) = finals.first_mut() {
            assert_eq!(stiffer(f0), name);
        }
    }
    std::fs::write(
        first.join("report.json"),
        serde_json::to_string(&base).unwrap(),
    )
    .unwrap();
    let o = ident(&["nightly", cfg_s]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let r = json(&report_dir(&o).join("report.json"));
    assert_eq!(r["status"]["outcome"], "alarm");
    let alarmed: Vec<&str> = r["drift"]["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["alarm"] == true)
        .map(|p| p["variable"].as_str().unwrap())
        .collect();
    assert_eq!(alarmed, vec![name.as_str()]);
    let log = std::fs::read_to_string(dir.path().join("nightly.log")).unwrap();
    assert!(log.contains("ALARM") && log.contains(&name), "{log}");
    let html = std::fs::read_to_string(report_dir(&o).join("report.html")).unwrap();
    assert!(html.contains("ALARM"));
}

#[test]
fn nightly_with_an_unreachable_stand_fails_with_exit_2_and_keeps_the_session() {
    let dir = tempfile::tempdir().unwrap();
    let configs = dir.path().join("configs");
    for (rel, src) in [
        ("stands/s.toml", "configs/stands/fwd32j-model-sim.toml"),
        (
            "models/fwd32j-no-actuator.toml",
            "configs/models/fwd32j-no-actuator.toml",
        ),
        ("models/fwd32j.toml", "configs/models/fwd32j.toml"),
        (
            "identification/v.toml",
            "configs/identification/fwd32j-no-actuator.toml",
        ),
    ] {
        let p = configs.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        let mut t =
            std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(src)).unwrap();
        if rel.starts_with("stands") {
            // A real stand whose shaker controller is not plugged in.
            t = t.replacen("port = \"sim\"", "port = \"/dev/ttyIDENT-NOT-THERE\"", 1);
        }
        std::fs::write(p, t).unwrap();
    }
    let cfg = configs.join("nightly.toml");
    std::fs::write(&cfg, "name = \"t\"\nmeasure = \"sweep\"\nstand = \"stands/s.toml\"\nmodel = \"models/fwd32j-no-actuator.toml\"\nvariables = \"identification/v.toml\"\nsessions = \"../sessions\"\nreports = \"../reports\"\nlog = \"../n.log\"\nlock = \"../n.lock\"\n").unwrap();
    let o = ident(&["nightly", cfg.to_str().unwrap()]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(2), "{t}");
    assert!(
        t.contains("/dev/ttyIDENT-NOT-THERE"),
        "the failure names the port: {t}"
    );
    let sessions: Vec<PathBuf> = std::fs::read_dir(dir.path().join("sessions"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(sessions.len(), 1, "the partial session is kept");
    let runs: Vec<PathBuf> = std::fs::read_dir(dir.path().join("reports"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    let status = json(&runs[0].join("status.json"));
    assert_eq!(status["outcome"], "failure");
    assert!(status["error"]
        .as_str()
        .unwrap()
        .contains("ttyIDENT-NOT-THERE"));
    // The operator's page says the same.
    let html = std::fs::read_to_string(runs[0].join("report.html")).unwrap();
    assert!(
        html.contains("outcome: failure")
            && html.contains("ttyIDENT-NOT-THERE")
            && html.contains("the session is kept"),
        "{html}"
    );
    assert!(std::fs::read_to_string(dir.path().join("n.log"))
        .unwrap()
        .contains("FAILURE"));
}

#[test]
fn nightly_config_errors_point_at_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("nightly.toml");
    std::fs::write(&cfg, "name = \"t\"\nmeasure = \"sweep\"\nstand = \"s.toml\"\nmodel = \"m.toml\"\nvariables = \"v.toml\"\nsessions = \"s\"\nreports = \"r\"\nlog = \"l\"\nlock = \"k\"\n[drift]\nk_sigma = \"three\"\n").unwrap();
    let o = ident(&["nightly", cfg.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let t = text(&o);
    assert!(t.contains("nightly.toml:11:"), "{t}");
    std::fs::write(&cfg, "name = \"t\"\nmeasure = \"sweeep\"\n").unwrap();
    let t = text(&ident(&["nightly", cfg.to_str().unwrap()]));
    assert!(
        t.contains("nightly.toml:2:") && t.contains("newest-session"),
        "{t}"
    );
    std::fs::write(&cfg, "name = \"t\"\nmeasure = \"newest-session\"\nmodel = \"m.toml\"\nvariables = \"v.toml\"\nsessions = \"s\"\nreports = \"r\"\nlog = \"l\"\nlock = \"k\"\n[stability]\ncut = \"c.toml\"\nspeed_rpm = [2000, 200]\n").unwrap();
    let t = text(&ident(&["nightly", cfg.to_str().unwrap()]));
    assert!(
        t.contains("nightly.toml:11:") && t.contains("[stability] speed_rpm"),
        "{t}"
    );
    // The shipped job file loads (its paths are checked when it runs).
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/nightly.toml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    let _: toml::Table = toml::from_str(&text).unwrap();
}
