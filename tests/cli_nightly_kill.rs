//! Unattended means nothing goes wrong silently (issue 18): 20 pairs of `ident nightly` started
//! together, each pair's running job killed with `kill -9` at a random point of its sweep. Exactly
//! one job of each pair runs (the other exits 2 at once, saying another is running); the sessions
//! the killed sweeps leave behind are never identified as complete by a later `newest-session`
//! run, which names every one it skipped and identifies the finished session; no killed run is
//! recorded in the history.

#![allow(clippy::unwrap_used)]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{ident, text};
use rand::{Rng, SeedableRng};

fn job(dir: &Path, live: &Path, measure: &str, sessions: &Path) -> PathBuf {
    let extra = "[sweep]\npoints = 10\nspeed = 8.0\n[history]\ndatabase = \"history.sqlite\"\n";
    let file = format!("{measure}.toml");
    common::nightly_job(dir, &file, live, measure, sessions, extra)
}

#[test]
fn twenty_concurrent_pairs_killed_mid_run_lose_and_misread_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (_, live) = common::short_demo(dir.path());
    let sessions = dir.path().join("sessions");
    std::fs::create_dir_all(&sessions).unwrap();
    let finished = std::fs::read_dir(&live)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "mcap"))
        .unwrap();
    let seed = sessions.join("0000-finished.mcap");
    std::fs::copy(&finished, &seed).unwrap();
    let sweep = job(dir.path(), &live, "sweep", &sessions);
    let mut rng = rand::rngs::StdRng::seed_from_u64(18);
    let mut completed = 0;
    for pair in 0..20 {
        let spawn = || {
            Command::new(env!("CARGO_BIN_EXE_ident"))
                .args(["nightly", sweep.to_str().unwrap()])
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let mut a = spawn();
        let mut b = spawn();
        // The loser exits at once; the winner is killed at a random point of its sweep.
        let started = Instant::now();
        let (mut loser, mut winner) = loop {
            if a.try_wait().unwrap().is_some() {
                break (a, b);
            }
            if b.try_wait().unwrap().is_some() {
                break (b, a);
            }
            assert!(
                started.elapsed() < Duration::from_secs(20),
                "pair {pair}: neither run was locked out"
            );
            std::thread::sleep(Duration::from_millis(5));
        };
        let lo = loser.wait().unwrap();
        let mut err = String::new();
        std::io::Read::read_to_string(loser.stderr.as_mut().unwrap(), &mut err).unwrap();
        assert_eq!(lo.code(), Some(2), "pair {pair}: {err}");
        assert!(
            err.contains("another ident nightly is running"),
            "pair {pair}: {err}"
        );
        std::thread::sleep(Duration::from_millis(rng.random_range(50..700)));
        match winner.try_wait().unwrap() {
            Some(s) => {
                assert!(
                    matches!(s.code(), Some(0 | 1)),
                    "pair {pair}: the running job failed"
                );
                completed += 1;
            }
            None => {
                winner.kill().unwrap(); // SIGKILL
                let s = winner.wait().unwrap();
                assert!(s.code().is_none(), "pair {pair}: killed, not exited");
            }
        }
    }
    let partial: Vec<PathBuf> = std::fs::read_dir(&sessions)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p != &seed)
        .collect();
    // Every killed run that got as far as its session left it unfinished; the history holds only
    // the runs that completed.
    let recorded = if dir.path().join("history.sqlite").exists() {
        history::store::Store::open_read_only(&dir.path().join("history.sqlite"))
            .unwrap()
            .runs()
            .unwrap()
            .len()
    } else {
        0
    };
    assert_eq!(recorded, completed, "only completed runs are recorded");

    // The next newest-session run skips every unfinished session and names it.
    let newest = job(dir.path(), &live, "newest-session", &sessions);
    let o = ident(&["nightly", newest.to_str().unwrap()]);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", text(&o));
    let t = text(&o);
    let mut skipped = 0;
    for p in &partial {
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let bytes = std::fs::read(p).unwrap();
        let finished = bytes.ends_with(b"\x89MCAP0\r\n");
        if !finished {
            assert!(
                t.contains("skipped the unfinished session") && t.contains(&name),
                "{name} not reported: {t}"
            );
            skipped += 1;
        }
    }
    println!(
        "{completed} of 20 runs completed before the kill, {skipped} unfinished sessions skipped"
    );
    assert!(skipped >= 10, "most runs were killed mid-sweep: {skipped}");
    if completed == 0 {
        assert!(
            t.contains(&format!("newest session: {}", seed.display())),
            "{t}"
        );
    }
}
