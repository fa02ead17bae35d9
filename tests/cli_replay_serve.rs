//! `ident replay --serve`: a short sweep of the simulated stand is recorded, its devices are served
//! from the recording (recorded stand, identities, measured response and noise), and `ident sweep`
//! against the served ports — the whole live path — must measure the recorded characteristics
//! again, within their measurement noise.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use common::{ident, root, text};

fn only(dir: &Path, suffix: &str) -> PathBuf {
    let v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().ends_with(suffix))
        .collect();
    assert_eq!(v.len(), 1, "one *{suffix} in {}: {v:?}", dir.display());
    v[0].clone()
}

/// Stops the server on drop (a failed assertion must not leave it running).
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-INT", &self.0.id().to_string()])
            .status();
        let _ = self.0.wait();
    }
}

const PLAN: [&str; 6] = ["--points", "6", "--from", "30", "--to", "300"];

#[test]
fn a_sweep_against_a_served_recording_measures_the_recorded_characteristics() {
    let dir = tempfile::tempdir().unwrap();
    let stand = root().join("configs/stands/fwd32j-model-sim.toml");
    let (rec, rep) = (dir.path().join("recorded"), dir.path().join("replayed"));
    let o = ident(
        &[
            &[
                "sweep",
                "--stand",
                stand.to_str().unwrap(),
                "--out",
                rec.to_str().unwrap(),
            ][..],
            &PLAN,
        ]
        .concat(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let recorded = only(&rec, ".mcap");

    let mut child = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(["replay", "--serve", recorded.to_str().unwrap()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let server = Server(child);
    let mut port = |role: &str| {
        let l = lines.next().expect("a port line").unwrap();
        l.strip_prefix(&format!("{role} "))
            .unwrap_or_else(|| panic!("expected `{role} PATH`, got {l:?}"))
            .to_string()
    };
    let (shaker, daq) = (port("shaker"), port("daq"));

    // The stand file as recorded, its ports pointing at the served devices.
    let t = std::fs::read_to_string(&stand).unwrap();
    let t = t
        .replacen("port = \"sim\"", &format!("port = \"{shaker}\""), 1)
        .replacen("port = \"sim\"", &format!("port = \"{daq}\""), 1);
    let t = t.replace(
        "\"../models/",
        &format!("\"{}/configs/models/", root().display()),
    );
    let served = dir.path().join("served.toml");
    std::fs::write(&served, t).unwrap();
    let o = ident(
        &[
            &[
                "sweep",
                "--stand",
                served.to_str().unwrap(),
                "--out",
                rep.to_str().unwrap(),
            ][..],
            &PLAN,
        ]
        .concat(),
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    drop(server);

    // Both sessions processed from their raw blocks: the same characteristics within noise.
    let measured = |session: &Path, out: &Path| -> serde_json::Value {
        let o = ident(&[
            "process",
            session.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        serde_json::from_str(&std::fs::read_to_string(only(out, ".measured.json")).unwrap())
            .unwrap()
    };
    let a = measured(&recorded, &dir.path().join("a"));
    let b = measured(&only(&rep, ".mcap"), &dir.path().join("b"));
    let nums = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let (ca, cb) = (
        a["characteristics"].as_array().unwrap(),
        b["characteristics"].as_array().unwrap(),
    );
    assert_eq!(ca.len(), 3);
    assert_eq!(ca.len(), cb.len());
    for (x, y) in ca.iter().zip(cb) {
        assert_eq!(x["freqs_hz"], y["freqs_hz"]);
        let (ax, ay, vx, vy) = (
            nums(&x["amplitude"]),
            nums(&y["amplitude"]),
            nums(&x["variance"]),
            nums(&y["variance"]),
        );
        assert_eq!(ax.len(), 6);
        for i in 0..ax.len() {
            // Two independent measurements of the same response: their difference has variance
            // var_a + var_b (the served noise is the recorded noise level).
            let z = (ax[i] - ay[i]).abs() / (vx[i] + vy[i]).sqrt();
            assert!(
                z < 5.0,
                "{} line {i}: recorded {} vs replayed {} ({z:.1} σ)",
                x["body"],
                ax[i],
                ay[i]
            );
        }
    }
}

#[test]
fn serving_bad_input_says_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let o = ident(&[
        "replay",
        "--serve",
        dir.path().join("none.mcap").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("no such session file"), "{}", text(&o));
    let junk = dir.path().join("junk.mcap");
    std::fs::write(&junk, b"not an mcap file at all").unwrap();
    let o = ident(&["replay", "--serve", junk.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("junk.mcap"),
        "the error names the file: {}",
        text(&o)
    );
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
}
