//! `ident sensitivity MODEL`: the band sensitivity MI (paper eq. 4.16) of each output
//! characteristic to every SDE parameter — and, with `--vars FILE`, to the masses, inertias,
//! point masses and sensor gains that file frees — ranked: the table for choosing decision
//! variables.

use std::path::PathBuf;
use std::process::ExitCode;

use identify::{self as idn};
use rfe::model::Param;

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
    /// A variables file (docs/identification.md): its masses, inertias, point masses and sensor
    /// gains are ranked beside the SDE parameters (at the model's values; a gain at 1).
    #[arg(long)]
    pub vars: Option<PathBuf>,
}

/// One ranked parameter: what it is, its value and unit, and its MI per output.
struct Row {
    /// `"sde 17 kn"`, `"body table m"`, `"gain table u1"`.
    label: String,
    /// The JSON fields that name it: `{"sde": …, "param": …}`, `{"body": …, "param": "m"}`, …
    names: serde_json::Value,
    value: Option<f64>,
    unit: &'static str,
    /// Per output: MI (1/SI) and relative MI.
    mi: Vec<f64>,
    relative: Vec<f64>,
}

/// The rows of the SDE parameters.
fn sde_rows(model: &rfe::Model, s: &rfe::sensitivity::Sensitivity) -> Vec<Row> {
    let n = s.outputs;
    s.params
        .iter()
        .enumerate()
        .map(|(p, r)| Row {
            label: model.param_label(*r),
            names: serde_json::json!({"sde": model.sdes[r.sde].name, "param": r.name.as_str()}),
            value: model.param(*r),
            unit: model.sdes[r.sde].law.unit(r.name),
            mi: s.mi[p * n..(p + 1) * n].to_vec(),
            relative: s.relative[p * n..(p + 1) * n].to_vec(),
        })
        .collect()
}

/// The rows of the variables' masses, inertias and point masses (MI of the model's FRF, as for
/// SDE parameters) and gains (a gain g scales its characteristics: MI = 1/g there, relative MI
/// 1; 0 elsewhere).
fn variable_rows(
    model: &rfe::Model,
    vars: &idn::Variables,
    freqs: &[f64],
    method: rfe::frf::Method,
) -> anyhow::Result<Vec<Row>> {
    let physical: Vec<Param> = vars
        .model_params()
        .into_iter()
        .filter(|p| p.sde().is_none())
        .collect();
    let (mi, relative) = rfe::sensitivity::band_mi(model, freqs, &physical, method)?;
    let n = model.outputs.len();
    let name_of = |p: &Param| match *p {
        Param::Mass { body } | Param::Inertia { body, .. } => {
            serde_json::json!({"body": model.bodies[body].name, "param": p.name()})
        }
        Param::PointMass { index } => {
            serde_json::json!({"point_mass": model.point_masses[index].name, "param": "m"})
        }
        _ => serde_json::Value::Null,
    };
    let mut rows: Vec<Row> = physical
        .iter()
        .enumerate()
        .map(|(k, p)| Row {
            label: model.label(*p),
            names: name_of(p),
            value: model.value(*p),
            unit: p.unit(model),
            mi: mi[k * n..(k + 1) * n].to_vec(),
            relative: relative[k * n..(k + 1) * n].to_vec(),
        })
        .collect();
    for v in &vars.vars {
        for t in &v.targets {
            let Param::Gain { body, dof } = t.param else {
                continue;
            };
            let g = v.initial * t.ratio;
            let own = |c: &rfe::model::Characteristic| c.body == body && c.dof == dof;
            rows.push(Row {
                label: model.label(t.param),
                names: serde_json::json!({
                    "characteristic": format!("{} {}", model.bodies[body].name, rfe::model::DOF_NAMES[dof as usize]),
                    "param": "gain",
                }),
                value: Some(g),
                unit: "-",
                mi: model.outputs.iter().map(|c| if own(c) { 1.0 / g } else { 0.0 }).collect(),
                relative: model.outputs.iter().map(|c| if own(c) { 1.0 } else { 0.0 }).collect(),
            });
        }
    }
    Ok(rows)
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
    let s = rfe::sensitivity::band_sensitivity(&model, &freqs, &[], a.method.into())?;
    let mut rows = sde_rows(&model, &s);
    if let Some(path) = &a.vars {
        let vars = idn::variables::load(path, &model)?;
        rows.extend(variable_rows(&model, &vars, &freqs, a.method.into())?);
    }
    if a.json {
        let rows: Vec<serde_json::Value> = rows
            .iter()
            .map(|r| {
                let mut j = r.names.clone();
                j["value"] = serde_json::json!(r.value);
                j["unit"] = serde_json::json!(r.unit);
                j["mi"] = serde_json::json!(r.mi);
                j["relative_mi"] = serde_json::json!(r.relative);
                j
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
        let mut ranked: Vec<&Row> = rows.iter().collect();
        ranked.sort_by(|x, y| y.relative[o].total_cmp(&x.relative[o]));
        for (i, r) in ranked.into_iter().take(a.top).enumerate() {
            println!(
                "  {:>4} {:<14} {:>12.4e} {:>12.4e}",
                i + 1,
                r.label.trim_start_matches("sde "),
                r.relative[o],
                r.mi[o]
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
