//! One module per subcommand; each has an `Args` struct (clap) and a `run` returning the exit code.

pub mod demo;
pub mod diagnose;
pub mod frf;
pub mod history;
pub mod identify;
pub mod mcap;
pub mod model;
pub mod modes;
pub mod modes_from_data;
pub mod nightly;
pub mod process;
pub mod prometheus;
pub mod replay;
pub mod sensitivity;
pub mod sim;
pub mod stability;
pub mod sweep;

use std::path::Path;

use anyhow::Context;

/// Loads a model file (TOML or resolved JSON), printing its warnings to stderr.
pub fn load_model(path: &Path) -> anyhow::Result<::rfe::Model> {
    let loaded = ::rfe::modelfile::load(path)?;
    for w in &loaded.warnings {
        eprintln!("{w}");
    }
    Ok(loaded.model)
}

/// Prints a workflow step's note on stderr, as it happens (`pipeline::Note`).
pub fn note(n: pipeline::Note) {
    eprintln!("{n}");
}

/// Frequency lines from `--hz` or `--from/--to/--points [--log]`.
#[derive(clap::Args, Debug, Clone)]
pub struct Lines {
    /// Explicit frequencies (Hz), comma-separated: --hz 10,20,35.5
    #[arg(long, value_delimiter = ',', conflicts_with_all = ["from", "to"])]
    pub hz: Vec<f64>,
    /// First frequency of a range (Hz).
    #[arg(long)]
    pub from: Option<f64>,
    /// Last frequency of a range (Hz).
    #[arg(long)]
    pub to: Option<f64>,
    /// Number of lines in the range.
    #[arg(long, default_value_t = 200)]
    pub points: usize,
    /// Space the range logarithmically.
    #[arg(long)]
    pub log: bool,
}

impl Lines {
    /// The frequencies, validated.
    pub fn freqs(&self, default: (f64, f64)) -> anyhow::Result<Vec<f64>> {
        if !self.hz.is_empty() {
            for f in &self.hz {
                anyhow::ensure!(
                    f.is_finite() && *f >= 0.0,
                    "--hz: {f} is not a frequency ≥ 0 Hz"
                );
            }
            return Ok(self.hz.clone());
        }
        let (a, b) = (self.from.unwrap_or(default.0), self.to.unwrap_or(default.1));
        anyhow::ensure!(
            a.is_finite() && b.is_finite() && a >= 0.0 && b > a,
            "--from {a} --to {b}: need 0 ≤ from < to"
        );
        anyhow::ensure!(self.points >= 2, "--points must be at least 2");
        anyhow::ensure!(!self.log || a > 0.0, "--log needs --from > 0");
        let n = self.points;
        Ok((0..n)
            .map(|i| {
                let t = i as f64 / (n - 1) as f64;
                if self.log {
                    a * (b / a).powf(t)
                } else {
                    a + (b - a) * t
                }
            })
            .collect())
    }
}

/// `--method auto|direct|modal`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default)]
pub enum MethodArg {
    /// The cheaper of the two for the DOFs, lines and parameters (a measured cost model).
    #[default]
    Auto,
    /// A factorisation per frequency line.
    Direct,
    /// One eigen-decomposition, then modal sums per line.
    Modal,
}

impl From<MethodArg> for ::rfe::frf::Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Auto => ::rfe::frf::Method::Auto,
            MethodArg::Direct => ::rfe::frf::Method::Direct,
            MethodArg::Modal => ::rfe::frf::Method::Modal,
        }
    }
}

/// Writes `text` to `path`, or to stdout when `path` is `None`.
pub fn emit(path: Option<&Path>, text: &str) -> anyhow::Result<()> {
    match path {
        Some(p) => std::fs::write(p, text).with_context(|| format!("cannot write {}", p.display())),
        None => {
            use std::io::Write;
            let mut out = std::io::stdout().lock();
            out.write_all(text.as_bytes())?;
            Ok(())
        }
    }
}
