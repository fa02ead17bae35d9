//! `ident identify MODEL --data DATA --vars VARS`: maximum-likelihood identification.

use std::process::ExitCode;

/// Arguments of `ident identify`.
#[derive(clap::Args)]
pub struct IdentifyArgs {
    /// Model file (TOML or resolved JSON).
    pub model: std::path::PathBuf,
}

/// Runs the identification.
pub fn run(_args: IdentifyArgs) -> anyhow::Result<ExitCode> {
    anyhow::bail!("identification is not built yet (issue 3)")
}
