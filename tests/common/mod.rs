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
