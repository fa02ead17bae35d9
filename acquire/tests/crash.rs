//! `kill -9` of a process writing a session mid-sweep: every flushed message is recovered by
//! `session::recover`, and the Python `mcap` reader then reads the file.

mod util;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use acquire::session;
use util::*;

#[test]
fn killed_writer_leaves_a_recoverable_session() {
    let (_d, path) = temp_file("killed.mcap");
    let stand =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-sim.toml");
    let mut child = Command::new(env!("CARGO_BIN_EXE_acquire-sim"))
        .arg(&stand)
        .args(["--record"])
        .arg(&path)
        .args([
            "--forever",
            "--speed",
            "8",
            "--flush-ms",
            "100",
            "--steps",
            "6",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn acquire-sim");
    // Wait until the writer has flushed several chunks with sweep steps in them.
    let start = Instant::now();
    let mut steps = 0;
    while start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(200));
        if let Ok(Some(status)) = child.try_wait() {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                use std::io::Read;
                let _ = e.read_to_string(&mut err);
            }
            panic!("acquire-sim exited early ({status}): {err}");
        }
        if let Ok(r) = session::read(&path) {
            steps = r
                .records
                .iter()
                .filter(|r| r.topic == "/sweep/step")
                .count();
            if steps >= 3 {
                break;
            }
        }
    }
    assert!(steps >= 3, "no sweep steps flushed within 60 s");
    child.kill().expect("SIGKILL"); // std's kill is SIGKILL on Unix
    child.wait().expect("reap");

    // The killed file has no footer: readers that need the summary fail on it.
    let before = session::read(&path).unwrap();
    assert!(
        before.truncated.is_some(),
        "file of a killed writer cannot be complete"
    );
    let out = session::recovered_path(&path);
    let rep = session::recover(&path, &out).unwrap();
    assert_eq!(
        rep.messages,
        before.records.len() as u64,
        "every message of every complete chunk is kept"
    );
    let after = records(&out);
    assert_eq!(after, before.records);
    // Per channel, MCAP sequence numbers run without holes (nothing lost in the middle).
    let bytes = std::fs::read(&out).unwrap();
    let mut next: std::collections::BTreeMap<u16, u32> = Default::default();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let want = next.entry(m.channel.id).or_insert(0);
        assert_eq!(m.sequence, *want, "hole in {}", m.channel.topic);
        *want += 1;
    }
    assert!(after.iter().filter(|r| r.topic == "/sweep/step").count() >= 3);
    let (n, topics) = python_read(&out);
    assert_eq!(n, after.len() as u64);
    for t in [
        "/session",
        "/stand",
        "/device/identity",
        "/raw",
        "/daq/stream",
        "/daq/block",
        "/sweep/event",
        "/sweep/step",
    ] {
        assert!(
            topics.iter().any(|x| x == t),
            "topic {t} missing from {topics:?}"
        );
    }
}
