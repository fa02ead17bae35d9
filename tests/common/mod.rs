//! Helpers shared by the command-line tests: run `ident`, read what it printed, find the
//! repository's files.

// Each test crate uses some of them.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The textbook two-mass chain, relative to the repository's root.
pub const TWO_MASS: &str = "configs/models/textbook-two-mass.toml";

/// Runs the `ident` binary with `args` and waits for it.
pub fn ident(args: &[&str]) -> Output {
    ident_with(args, &[])
}

/// Runs the `ident` binary with `args` and the environment variables `env` added (`IDENT_LOG`
/// from the caller's environment removed, so logging is what the test asks for).
pub fn ident_with(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ident"));
    c.args(args).env_remove("IDENT_LOG");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("run ident")
}

/// Runs `ident identify` on the two-mass model with the data file `data` and the variables file
/// `vars`, then the flags `extra`, with the environment variables `env` added.
pub fn identify_two_mass(data: &Path, vars: &Path, extra: &[&str], env: &[(&str, &str)]) -> Output {
    let model = root().join(TWO_MASS);
    let mut args = vec!["identify", p(&model), "--data", p(data), "--vars", p(vars)];
    args.extend_from_slice(extra);
    ident_with(&args, env)
}

/// Runs `ident identify` on `model` with the measured file `data` read through the measurement
/// map `map` and the variables file `vars`, then the flags `extra`.
pub fn identify_mapped(
    model: &Path,
    data: &Path,
    map: &Path,
    vars: &Path,
    extra: &[&str],
) -> Output {
    mapped("identify", model, (data, map), vars, extra)
}

/// Runs `ident command` (`identify`, `diagnose`) on `model` with the measured file `data` read
/// through the measurement map `map` and the variables file `vars`, then the flags `extra`.
pub fn mapped(
    command: &str,
    model: &Path,
    (data, map): (&Path, &Path),
    vars: &Path,
    extra: &[&str],
) -> Output {
    let mut args = vec![
        command,
        p(model),
        "--data",
        p(data),
        "--map",
        p(map),
        "--vars",
        p(vars),
    ];
    args.extend_from_slice(extra);
    ident(&args)
}

/// Asserts that a run (of `ident` or another program) succeeded; its stderr is the failure
/// message.
#[track_caller]
pub fn assert_success(o: &Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Bytes a run printed, as text.
pub fn utf8(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A path as a command-line argument.
pub fn p(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

/// What a run printed: stdout, a newline, stderr.
pub fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The repository's root folder.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The report folder a run printed (`report: DIR`).
pub fn report_dir(o: &Output) -> PathBuf {
    PathBuf::from(
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .find_map(|l| l.strip_prefix("report: "))
            .unwrap_or_else(|| panic!("no report path: {}", text(o))),
    )
}

/// A JSON file, read and parsed.
pub fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(
        &std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Runs a short demo (10 lines, 8x real time) into `out`, asserting it succeeded; returns the
/// run and its report folder (which holds the session and a copy of the configs).
pub fn short_demo(out: &Path) -> (Output, PathBuf) {
    let o = ident(&[
        "demo",
        "--out",
        out.to_str().expect("utf-8 path"),
        "--points",
        "10",
        "--speed",
        "8",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let dir = report_dir(&o);
    (o, dir)
}

/// Writes a nightly job file `dir/FILE` for the demo's stand, identification model and variables
/// (from the configs a demo copied into `live`), with `measure`, the `sessions` folder, and
/// `extra` TOML appended.
pub fn nightly_job(
    dir: &Path,
    file: &str,
    live: &Path,
    measure: &str,
    sessions: &Path,
    extra: &str,
) -> PathBuf {
    let cfg = dir.join(file);
    let c = live.join("configs");
    let text = format!(
        "name = \"test job\"\nmeasure = \"{measure}\"\nstand = \"{}\"\nmodel = \"{}\"\nvariables = \"{}\"\nsessions = \"{}\"\nreports = \"reports\"\nlog = \"nightly.log\"\nlock = \"nightly.lock\"\n{extra}",
        c.join("stands/fwd32j-model-sim.toml").display(),
        c.join("models/fwd32j-no-actuator.toml").display(),
        c.join("identification/fwd32j-no-actuator.toml").display(),
        sessions.display()
    );
    std::fs::write(&cfg, text).expect("write the job file");
    cfg
}

/// The reduced χ² before and after diagnosis, from the `reduced χ²  a → b` row of the
/// diagnosis' before/after table in `out`.
pub fn reduced_chi2_before_after(out: &str) -> (f64, f64) {
    let reduced: Vec<f64> = out
        .lines()
        .find(|l| l.trim_start().starts_with("reduced χ²"))
        .unwrap_or_else(|| panic!("no before/after table: {out}"))
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    assert_eq!(reduced.len(), 2, "{out}");
    (reduced[0], reduced[1])
}
