//! `ident frf MODEL`: frequency response of the model's output characteristics, as the contract's
//! JSON (`--json`) or CSV (frequency, then re, im, amplitude, phase per characteristic).

use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use super::{emit, load_model, Lines, MethodArg};

/// Arguments of `ident frf`.
#[derive(clap::Args)]
pub struct FrfArgs {
    /// Model file (TOML or resolved JSON).
    pub model: PathBuf,
    #[command(flatten)]
    pub lines: Lines,
    /// Print the JSON form of docs/model-json.md instead of CSV.
    #[arg(long)]
    pub json: bool,
    /// Solution path.
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    pub method: MethodArg,
    /// Write to this file instead of stdout.
    #[arg(long, short)]
    pub output: Option<PathBuf>,
}

/// Runs `ident frf`.
pub fn run(a: FrfArgs) -> anyhow::Result<ExitCode> {
    let model = load_model(&a.model)?;
    anyhow::ensure!(!model.outputs.is_empty(), "{}: the model declares no [[output]] characteristics; add one, e.g. [[output]] body = \"table\" dofs = [\"u1\", \"u2\", \"u3\"]", a.model.display());
    let freqs = a.lines.freqs((1.0, 200.0))?;
    let r = rfe::frf::response(&model, &freqs, &[], a.method.into())?;
    let text = if a.json {
        serde_json::to_string(&rfe::contract::frf_json(&model, &r))? + "\n"
    } else {
        let mut s = String::from("freq_hz");
        for c in &model.outputs {
            // A point output's label holds "(x, y, z)": no commas in a CSV header.
            let l = model
                .characteristic_label(*c)
                .replace(", ", ";")
                .replace(' ', "_");
            write!(s, ",{l}_re,{l}_im,{l}_amp,{l}_phase_deg")?;
        }
        s.push('\n');
        for (k, f) in freqs.iter().enumerate() {
            write!(s, "{f}")?;
            for o in 0..model.outputs.len() {
                let v = r.output(o)[k];
                write!(
                    s,
                    ",{:e},{:e},{:e},{:.4}",
                    v.re,
                    v.im,
                    v.norm(),
                    v.arg().to_degrees()
                )?;
            }
            s.push('\n');
        }
        s
    };
    emit(a.output.as_deref(), &text)?;
    Ok(ExitCode::SUCCESS)
}
