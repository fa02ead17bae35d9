//! Helpers shared by the command-line tests: run `ident`, read what it printed, find the
//! repository's files.

// Each test crate uses some of them.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs the `ident` binary with `args` and waits for it.
pub fn ident(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(args)
        .output()
        .expect("run ident")
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
