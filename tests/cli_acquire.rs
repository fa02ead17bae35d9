//! End-to-end tests of `ident sweep`, `ident process` and `ident sim` on the simulated FWD-32J
//! stand: a sweep into a session file, its characteristics for `ident identify --data`, Ctrl-C
//! leaving a complete file that `--resume` finishes, the simulator serving ports until Ctrl-C,
//! exit codes, and the operator-facing messages for bad input.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{ident, text};

fn stand() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("configs/stands/fwd32j-model-sim.toml")
        .display()
        .to_string()
}

fn sessions(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    }; // not created yet
    let mut v: Vec<PathBuf> = entries
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    v.sort();
    v
}

fn sigint(pid: u32) {
    let st = Command::new("kill")
        .args(["-INT", &pid.to_string()])
        .status()
        .expect("run kill");
    assert!(st.success());
}

/// `ident sweep` of `stand` into `out` with the plan's `flags`.
fn ident_sweep(stand: &str, out: &Path, flags: &[&str]) -> std::process::Output {
    let mut args = vec!["sweep", "--stand", stand, "--out", out.to_str().unwrap()];
    args.extend_from_slice(flags);
    ident(&args)
}

/// `ident process` of `session` into `out` succeeds and recomputes all its `steps` live estimates
/// bit for bit.
fn assert_process_equals_live(session: &Path, out: &Path, steps: usize) {
    let o = ident(&[
        "process",
        session.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains(&format!(
            "{steps} of {steps} steps equal the live estimate bit for bit"
        )),
        "{}",
        text(&o)
    );
}

#[test]
fn sweep_then_process_gives_data_for_identify() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let o = ident_sweep(
        &stand(),
        &out,
        &["--points", "8", "--from", "30", "--to", "300"],
    );
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("8 of 8 steps measured"), "{}", text(&o));
    let s = sessions(&out);
    assert_eq!(s.len(), 1);
    let name = s[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("fwd32j-model-sim-") && name.ends_with("Z.mcap"),
        "session named by stand and UTC time: {name}"
    );

    assert_process_equals_live(&s[0], &dir.path().join("p"), 8);
    let stem = name.trim_end_matches(".mcap");
    let measured = dir.path().join("p").join(format!("{stem}.measured.json"));
    let m: rfe::MeasuredData =
        serde_json::from_str(&std::fs::read_to_string(&measured).unwrap()).unwrap();
    assert_eq!(m.characteristics.len(), 3);
    assert!(m
        .characteristics
        .iter()
        .all(|c| c.body == "table" && c.freqs_hz.len() == 8 && c.variance.is_some()));
    let steps =
        std::fs::read_to_string(dir.path().join("p").join(format!("{stem}.steps.csv"))).unwrap();
    assert_eq!(
        steps.lines().count(),
        1 + 8 * 8,
        "header + 8 steps × 8 channels"
    );
    // The CSV form reads back into the same data through identification's own loader.
    let csv = dir.path().join("p").join(format!("{stem}.measured.csv"));
    let back = identify::data::load(&csv).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.characteristics.len(), 3);
    for (a, b) in back.characteristics.iter().zip(&m.characteristics) {
        assert_eq!(a.freqs_hz, b.freqs_hz);
        for (x, y) in a.amplitude.iter().zip(&b.amplitude) {
            assert!((x - y).abs() <= 1e-12 * y.abs(), "{x} vs {y}");
        }
    }
    // And identification accepts it against the model (validation only: a fit is tested elsewhere).
    let model = rfe::modelfile::load(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("configs/models/fwd32j-initial.toml"),
    )
    .unwrap()
    .model;
    identify::data::validate(&m, &model, "measured.json").unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn ctrl_c_leaves_a_complete_session_and_resume_finishes_the_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let args = [
        "--stand",
        &stand(),
        "--out",
        out.to_str().unwrap(),
        "--points",
        "12",
        "--speed",
        "2",
    ];
    let child = Command::new(env!("CARGO_BIN_EXE_ident"))
        .arg("sweep")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Interrupt once the session file holds a few flushed chunks.
    let t0 = Instant::now();
    while sessions(&out)
        .first()
        .and_then(|p| std::fs::metadata(p).ok())
        .is_none_or(|m| m.len() < 200_000)
    {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the sweep did not start recording"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    sigint(child.id());
    let o = child.wait_with_output().unwrap();
    assert_eq!(
        o.status.code(),
        Some(1),
        "an interrupted sweep is incomplete: {}",
        text(&o)
    );
    assert!(text(&o).contains("--resume"), "{}", text(&o));
    let first = sessions(&out)[0].clone();
    let rep = acquire::session::read(&first).unwrap();
    assert_eq!(rep.truncated, None, "Ctrl-C must leave a complete file");
    assert!(rep
        .records
        .iter()
        .any(|r| r.topic == "/sweep/event" && r.value["kind"] == "stopped"));
    let done = rep
        .records
        .iter()
        .filter(|r| r.topic == "/sweep/step")
        .count();
    assert!(done < 12, "stopped before the end ({done} steps)");

    let mut resume: Vec<&str> = vec!["sweep"];
    resume.extend(args);
    resume.extend(["--resume", first.to_str().unwrap()]);
    let o = ident(&resume);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains(&"12 of 12 steps measured in".to_string()),
        "{}",
        text(&o)
    );
    assert!(
        text(&o).contains(&format!("({} in this run, {done} from", 12 - done)),
        "{}",
        text(&o)
    );
}

#[test]
fn sim_serves_ports_until_ctrl_c() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(["sim", "--stand", &stand()])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let shaker = lines.next().unwrap().unwrap();
    let daq = lines.next().unwrap().unwrap();
    let port = |l: &str, role: &str| {
        let p = l
            .strip_prefix(&format!("{role} "))
            .unwrap_or_else(|| panic!("`{l}` should be `{role} PATH`"))
            .to_string();
        assert!(p.starts_with("/dev/pts/") && Path::new(&p).exists(), "{p}");
        p
    };
    assert_ne!(port(&shaker, "shaker"), port(&daq, "daq"));
    sigint(child.id());
    let st = child.wait().unwrap();
    assert_eq!(st.code(), Some(0));
}

fn stand_with(dir: &Path, edit: impl Fn(String) -> String) -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("configs/stands/fwd32j-model-sim.toml")).unwrap();
    let text = edit(text).replace("../models/", &format!("{}/configs/models/", root.display()));
    let p = dir.join("stand.toml");
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn bad_input_gets_messages_naming_what_to_fix() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep = |stand: &str| ident_sweep(stand, &out, &["--points", "3"]);

    // A sensor that is not on the body it names (the table is 740..1060 mm in y).
    let s = stand_with(dir.path(), |t| {
        t.replacen(
            "position = [\"-450 mm\", \"1000 mm\", \"950 mm\"]",
            "position = [\"-450 mm\", \"1150 mm\", \"950 mm\"]",
            1,
        )
    });
    let o = sweep(&s);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let line = std::fs::read_to_string(&s)
        .unwrap()
        .lines()
        .position(|l| l.contains("name = \"table-b-y\""))
        .unwrap();
    assert!(
        text(&o).contains(&format!("{s}:{line}:1: channel `table-b-y`: position [-450, 1150, 950] mm is not on body `table`")),
        "{}",
        text(&o)
    );
    assert!(
        text(&o).contains("reaches only ±[625, 160, 60] mm"),
        "{}",
        text(&o)
    );

    // Inconsistent channel map: two channels on one DAQ input.
    let s = stand_with(dir.path(), |t| {
        t.replacen("device_channel = 2\n", "device_channel = 1\n", 1)
    });
    let o = sweep(&s);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o).contains(
            "channel `table-a-y`: device_channel 1 is already used by channel `table-a-x`"
        ),
        "{}",
        text(&o)
    );

    // A port that does not exist.
    let s = stand_with(dir.path(), |t| {
        t.replacen("port = \"sim\"", "port = \"/dev/ttyUSB97\"", 1)
            .replacen("port = \"sim\"", "port = \"/dev/ttyUSB98\"", 1)
    });
    let o = sweep(&s);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o).contains("serial port /dev/ttyUSB97: no such device; check the `port` in the stand file and that the adapter is plugged in"),
        "{}",
        text(&o)
    );
    // The failed session is still a complete file that records why.
    let rec = acquire::session::read(&sessions(&out)[0]).unwrap();
    assert_eq!(rec.truncated, None);

    // A CAN interface that does not exist (or a kernel without CAN): named, with what to check.
    let o = ident(&[
        "sweep",
        "--stand",
        &stand(),
        "--out",
        out.to_str().unwrap(),
        "--can",
        "nocan7",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        text(&o).contains("CAN interface `nocan7`")
            && (text(&o).contains("ip link") || text(&o).contains("modprobe can-raw")),
        "{}",
        text(&o)
    );

    // Permission denied: a device node the operator may not open (run as `nobody` when root).
    let node = dir.path().join("ttyLOCKED");
    std::fs::write(&node, b"").unwrap();
    let s = stand_with(dir.path(), |t| {
        t.replacen(
            "port = \"sim\"",
            &format!("port = \"{}\"", node.display()),
            1,
        )
        .replacen("port = \"sim\"", "port = \"/dev/null\"", 1)
    });
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&node, std::fs::Permissions::from_mode(0o600)).unwrap();
    for p in [dir.path().to_path_buf(), out.clone()] {
        std::fs::set_permissions(&p, std::fs::Permissions::from_mode(0o777)).unwrap();
    }
    std::fs::set_permissions(&s, std::fs::Permissions::from_mode(0o644)).unwrap();
    let root_user = String::from_utf8_lossy(&Command::new("id").arg("-u").output().unwrap().stdout)
        .trim()
        == "0";
    let o = if root_user {
        Command::new("setpriv")
            .args([
                "--reuid=65534",
                "--regid=65534",
                "--clear-groups",
                env!("CARGO_BIN_EXE_ident"),
                "sweep",
                "--stand",
                &s,
                "--out",
                out.to_str().unwrap(),
            ])
            .output()
            .expect("setpriv (util-linux) to drop root for the permission test")
    } else {
        ident(&["sweep", "--stand", &s, "--out", out.to_str().unwrap()])
    };
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains(&format!(
            "serial port {}: permission denied; add your user to the `dialout` group",
            node.display()
        )),
        "{}",
        text(&o)
    );

    // Not a session file.
    let bogus = dir.path().join("bogus.mcap");
    std::fs::write(&bogus, b"not an mcap file").unwrap();
    let o = ident(&["process", bogus.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains(bogus.to_str().unwrap()), "{}", text(&o));
}

/// A disk that fills up mid-sweep: the sweep stops with exit 2 and a message naming the file and
/// the cause, and everything flushed before the disk filled is recoverable and usable. The full
/// disk is a 3 MiB tmpfs mounted in a private user and mount namespace (`unshare` from
/// util-linux; no root needed where user namespaces are allowed, as on CI).
#[test]
fn a_disk_that_fills_up_stops_the_sweep_cleanly_and_keeps_what_was_written() {
    let dir = tempfile::tempdir().unwrap();
    let disk = dir.path().join("disk");
    let out = dir.path().join("out");
    std::fs::create_dir_all(&disk).unwrap();
    std::fs::create_dir_all(&out).unwrap();
    // The tmpfs lives only as long as the namespace: copy the session out before leaving it.
    let script = r#"mount -t tmpfs -o size=3m tmpfs "$1" || exit 97
"$2" sweep --stand "$3" --out "$1" >"$4/sweep.txt" 2>&1
echo $? >"$4/rc"
cp "$1"/*.mcap "$4/kept.mcap""#;
    let o = Command::new("unshare")
        .args([
            "--user",
            "--map-root-user",
            "--mount",
            "sh",
            "-c",
            script,
            "sh",
        ])
        .args([
            disk.to_str().unwrap(),
            env!("CARGO_BIN_EXE_ident"),
            &stand(),
            out.to_str().unwrap(),
        ])
        .output()
        .expect("run unshare (util-linux)");
    assert!(
        o.status.success(),
        "the namespace with a small tmpfs could not be set up (user namespaces disabled?): {}",
        text(&o)
    );
    let sweep = std::fs::read_to_string(out.join("sweep.txt")).unwrap();
    assert_eq!(
        std::fs::read_to_string(out.join("rc")).unwrap().trim(),
        "2",
        "{sweep}"
    );
    assert!(
        sweep.contains("could not be completed") && sweep.contains("disk space"),
        "the error names the cause: {sweep}"
    );
    assert!(!sweep.contains("panicked"), "{sweep}");
    // What was flushed before the disk filled is there: recover it, then process it.
    let kept = out.join("kept.mcap");
    let recovered = out.join("recovered.mcap");
    let r = ident(&[
        "mcap",
        "recover",
        kept.to_str().unwrap(),
        "--output",
        recovered.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", text(&r));
    let p = ident(&[
        "process",
        recovered.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let t = text(&p);
    assert!(p.status.success(), "{t}");
    let points: usize = t
        .lines()
        .filter(|l| l.contains("table u1"))
        .find_map(|l| l.split(": ").nth(1)?.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no table u1 line: {t}"));
    assert!(
        points >= 2,
        "steps measured before the disk filled are usable: {t}"
    );
}

/// The generator stand's file, edited, with its model paths made absolute.
fn generator_stand_with(dir: &Path, edit: impl Fn(String) -> String) -> String {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let text =
        std::fs::read_to_string(root.join("configs/stands/fwd32j-generator-sim.toml")).unwrap();
    let text = edit(text).replace("../models/", &format!("{}/configs/models/", root.display()));
    let p = dir.join(format!("gen-{}.toml", std::process::id()));
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn a_generator_stand_is_swept_and_served_over_a_local_tcp_port() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = |stand: &str, out: &Path| {
        ident_sweep(
            stand,
            out,
            &["--points", "5", "--from", "30", "--to", "300"],
        )
    };
    // `ident sweep` starts the simulated generator itself (port = "sim").
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let stand = root.join("configs/stands/fwd32j-generator-sim.toml");
    let o = sweep(stand.to_str().unwrap(), &dir.path().join("a"));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("5 of 5 steps measured"), "{}", text(&o));
    assert!(
        text(&o).contains("generator settings per line"),
        "{}",
        text(&o)
    );
    // Processing the generator session recomputes every live estimate bit for bit.
    let session = sessions(&dir.path().join("a")).remove(0);
    assert_process_equals_live(&session, &dir.path().join("p"), 5);

    // `ident sim` serves it on 127.0.0.1; a stand file pointing there is swept like a real one.
    let sim_stand = generator_stand_with(dir.path(), |t| {
        t.replacen(
            "port = \"sim\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
            "port = \"sim:tcp\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
            1,
        )
    });
    let mut child = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(["sim", "--stand", &sim_stand])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let generator = lines.next().unwrap().unwrap();
    let daq = lines.next().unwrap().unwrap();
    let address = generator
        .strip_prefix("generator tcp:127.0.0.1:")
        .unwrap_or_else(|| panic!("`{generator}` should be `generator tcp:127.0.0.1:PORT`"));
    assert!(address.parse::<u16>().is_ok(), "{generator}");
    let daq = daq.strip_prefix("daq ").unwrap().to_string();
    let wired = generator_stand_with(dir.path(), |t| {
        t.replacen(
            "port = \"sim\"\nidentity = \"IDENT-SIM,SIGGEN-2\"",
            &format!("port = \"tcp:127.0.0.1:{address}\"\nidentity = \"IDENT-SIM,SIGGEN-2\""),
            1,
        )
        .replacen(
            "[daq]\nport = \"sim\"",
            &format!("[daq]\nport = \"{daq}\""),
            1,
        )
    });
    let o = sweep(&wired, &dir.path().join("b"));
    sigint(child.id());
    assert_eq!(child.wait().unwrap().code(), Some(0));
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("5 of 5 steps measured"), "{}", text(&o));
}
