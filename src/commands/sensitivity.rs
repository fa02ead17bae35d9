//! `ident sensitivity MODEL`: the band sensitivity MI (paper eq. 4.16) of each output
//! characteristic to every SDE parameter, ranked — the table for choosing decision variables.

use std::path::PathBuf;
use std::process::ExitCode;

use super::{load_model, Lines, MethodArg};

/// Arguments of `ident sensitivity`.
#[derive(clap::Args)]
pub struct SensitivityArgs {
    /// Model file (TOML or resolved JSON).
    pub model: PathBuf,
    #[command(flatten)]
    pub lines: Lines,
    /// Show the N most sensitive parameters per characteristic.
    #[arg(long, default_value_t = 20)]
    pub top: usize,
    /// Print JSON (every parameter, MI and relative MI per characteristic).
    #[arg(long)]
    pub json: bool,
    /// Solution path.
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    pub method: MethodArg,
}

/// Runs `ident sensitivity`.
pub fn run(a: SensitivityArgs) -> anyhow::Result<ExitCode> {
    let model = load_model(&a.model)?;
    anyhow::ensure!(
        !model.outputs.is_empty(),
        "{}: the model declares no [[output]] characteristics",
        a.model.display()
    );
    let freqs = a.lines.freqs((1.0, 200.0))?;
    let s = identify::sensitivity::band_sensitivity(&model, &freqs, &[], a.method.into())?;
    if a.json {
        let rows: Vec<serde_json::Value> = s
            .params
            .iter()
            .enumerate()
            .map(|(p, r)| {
                serde_json::json!({
                    "sde": model.sdes[r.sde].name,
                    "param": r.name.as_str(),
                    "value": model.param(*r),
                    "unit": model.sdes[r.sde].law.unit(r.name),
                    "mi": &s.mi[p * s.outputs..(p + 1) * s.outputs],
                    "relative_mi": &s.relative[p * s.outputs..(p + 1) * s.outputs],
                })
            })
            .collect();
        let outputs: Vec<String> = model
            .outputs
            .iter()
            .map(|c| model.characteristic_label(*c))
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"freqs_hz": [freqs[0], freqs[freqs.len() - 1]], "lines": freqs.len(), "outputs": outputs, "params": rows})
            )?
        );
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "band {:.3}-{:.3} Hz, {} lines; relative MI = p·Σ|∂|q|/∂p| / Σ|q| (eq. 4.16 × p)",
        freqs[0],
        freqs[freqs.len() - 1],
        freqs.len()
    );
    for (o, c) in model.outputs.iter().enumerate() {
        println!("\n{}", model.characteristic_label(*c));
        println!(
            "  {:>4} {:<14} {:>12} {:>12}",
            "rank", "parameter", "relative MI", "MI [1/SI]"
        );
        for (i, (p, mi, rel)) in s.ranking(o).into_iter().take(a.top).enumerate() {
            println!(
                "  {:>4} {:<14} {:>12.4e} {:>12.4e}",
                i + 1,
                model.param_label(p).trim_start_matches("sde "),
                rel,
                mi
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
