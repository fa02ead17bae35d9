//! Reports of an identification: the Table-1-like table (variable, SDEs, unit, initial,
//! identified, standard error) as text, JSON and CSV, and the updated model written back into
//! the original TOML text (comments and layout kept, via `toml_edit`).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use toml_edit::{DocumentMut, Item};

use super::uncertainty::AtBound;
use super::variables::Tie;
use super::Identification;
use rfe::display::num;
use rfe::model::ParamName;
use rfe::write_back::{sde_table, write_back_bodies, write_params};

/// One row of the table, in the variable's display unit. The same record is a row of
/// report.json's parameter tables (`report::document::Parameter`), whose JSON Schema is derived
/// from it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "Parameter", title = "Parameter")]
pub struct Row {
    /// Variable name.
    pub variable: String,
    /// SDE names (`"2-10, 13-17"`).
    pub sdes: String,
    /// Parameter name (`kn`, `psi_n`, ...).
    pub parameter: String,
    /// Display unit (`MPa/um`, `N/um`, `-`).
    pub unit: String,
    /// Initial value.
    pub initial: f64,
    /// Identified value.
    pub identified: f64,
    /// Standard error (Cramér-Rao), `null` when undetermined.
    pub std_error: Option<f64>,
    /// Standard error / |identified| (`null` when identified = 0 or undetermined).
    pub variability: Option<f64>,
    /// `"lower"` / `"upper"` when the estimate is at a bound.
    #[schemars(extend("enum" = ["lower", "upper", null]))]
    pub at_bound: Option<String>,
}

/// The table rows.
pub fn rows(id: &Identification) -> Vec<Row> {
    id.variables
        .vars
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let f = v.unit.factor;
            let se = id.uncertainty.std_error[i];
            let vf = id.uncertainty.variability[i];
            Row {
                variable: v.name.clone(),
                sdes: v.sdes.clone(),
                parameter: if v.tie == Tie::Scale {
                    format!("{} (factor)", v.parameter)
                } else {
                    v.parameter.clone()
                },
                unit: v.unit.symbol.clone(),
                initial: id.initial[i] / f,
                identified: id.estimate[i] / f,
                std_error: se.is_finite().then_some(se / f),
                variability: vf.is_finite().then_some(vf),
                at_bound: id.uncertainty.at_bound[i].map(|b| match b {
                    AtBound::Lower => "lower".into(),
                    AtBound::Upper => "upper".into(),
                }),
            }
        })
        .collect()
}

/// The whole report as text: set-up, convergence, criterion before and after, the table, RMS
/// errors per characteristic, identifiability warnings and strong correlations.
pub fn text(id: &Identification) -> String {
    let mut s = String::new();
    let u = &id.uncertainty;
    if let Some(m) = super::misfit::misfit(id) {
        s.push_str(&format!("{}\n\n", m.message));
    }
    s.push_str(&format!(
        "identification: {} variables, {} observations ({} fit), optimizer {}\n",
        id.variables.len(),
        id.observations,
        id.fit.as_str(),
        id.optimizer.as_str()
    ));
    s.push_str(&format!("noise model: {}\n", id.noise.describe()));
    s.push_str(&format!(
        "stopped: {} after {} iterations; {} model evaluations ({} with Jacobian)\n",
        id.stop.describe(),
        id.iterations,
        id.evaluations.model,
        id.evaluations.with_jacobian
    ));
    if id.starts.len() > 1 {
        for (k, st) in id.starts.iter().enumerate() {
            s.push_str(&format!(
                "  start {k}: J = {} ({})\n",
                num(st.criterion),
                st.stop.describe()
            ));
        }
    }
    s.push_str(&format!(
        "criterion J: initial {} -> identified {}; reduced χ² {:.3}{}\n",
        num(id.criterion_initial),
        num(id.criterion),
        u.reduced_chi2,
        if id.noise.scale_unknown() {
            format!(
                " (covariance scaled by the residual variance {:.3})",
                u.covariance_scale
            )
        } else {
            String::new()
        }
    ));
    s.push_str(&super::starts::text(id));
    parameter_table(&mut s, id);
    s.push_str(
        "\nRMS amplitude error per characteristic, in dB and relative (initial -> identified):\n",
    );
    for (((label, a), (_, b)), (_, da, db)) in id.rms_initial.iter().zip(&id.rms).zip(&id.rms_db) {
        s.push_str(&format!(
            "  {label}: {:.2} dB -> {:.2} dB   ({} -> {})\n",
            da,
            db,
            rfe::display::relative(*a),
            rfe::display::relative(*b)
        ));
    }
    identifiability_text(&mut s, id);
    s
}

/// The variables' table: initial, identified, standard error, relative error, bounds hit.
fn parameter_table(s: &mut String, id: &Identification) {
    let rows = rows(id);
    let w = rows
        .iter()
        .map(|r| r.variable.len())
        .max()
        .unwrap_or(8)
        .max(8);
    let ws = rows.iter().map(|r| r.sdes.len()).max().unwrap_or(4).max(4);
    s.push_str(&format!(
        "\n{:<w$}  {:<ws$}  {:<8}  {:>12}  {:>12}  {:>12}  {:>8}\n",
        "variable", "sdes", "unit", "initial", "identified", "std error", "sigma/x"
    ));
    for r in &rows {
        s.push_str(&format!(
            "{:<w$}  {:<ws$}  {:<8}  {:>12}  {:>12}  {:>12}  {:>8}{}\n",
            r.variable,
            r.sdes,
            r.unit,
            num(r.initial),
            num(r.identified),
            r.std_error
                .map(num)
                .unwrap_or_else(|| "undetermined".into()),
            r.variability
                .map(rfe::display::relative)
                .unwrap_or_else(|| "-".into()),
            r.at_bound
                .as_ref()
                .map(|b| format!("  at {b} bound"))
                .unwrap_or_default()
        ));
    }
}

/// Poorly identifiable combinations and strongly correlated estimates.
fn identifiability_text(s: &mut String, id: &Identification) {
    let u = &id.uncertainty;
    if !u.weak.is_empty() {
        s.push_str(&format!(
            "\npoorly identifiable combinations (relative sigma > threshold; condition number {:.3e}):\n",
            u.condition
        ));
        for d in &u.weak {
            let rel = if d.relative_std.is_finite() {
                format!("±{:.0} %", 100.0 * d.relative_std)
            } else {
                "no information".into()
            };
            s.push_str(&format!("  {} ({rel})\n", d.combination()));
        }
        s.push_str("  (relative changes along these directions barely change the characteristics: group these variables or add measurements)\n");
    }
    let n = id.variables.len();
    let mut strong = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            let c = u.correlation[(a, b)];
            if c.abs() > 0.9 {
                strong.push(format!(
                    "  {} ~ {}: {c:+.3}",
                    id.variables.vars[a].name, id.variables.vars[b].name
                ));
            }
        }
    }
    if !strong.is_empty() {
        s.push_str("\nstrongly correlated estimates (|rho| > 0.9):\n");
        s.push_str(&strong.join("\n"));
        s.push('\n');
    }
}

/// The JSON report.
#[derive(Debug, Clone, Serialize)]
pub struct ReportJson {
    /// Optimizer name.
    pub optimizer: String,
    /// Converged or not.
    pub converged: bool,
    /// Why it stopped.
    pub stop: String,
    /// Iterations.
    pub iterations: usize,
    /// Model evaluations (FRF solves).
    pub model_evaluations: usize,
    /// Of those with the analytic Jacobian.
    pub jacobian_evaluations: usize,
    /// `amplitude` or `complex`.
    pub fit: String,
    /// Noise model sentence.
    pub noise: String,
    /// Scalar observations.
    pub observations: usize,
    /// J at the initial values.
    pub criterion_initial: f64,
    /// J at the estimate.
    pub criterion: f64,
    /// 2J/(m − n_free).
    pub reduced_chi2: f64,
    /// The headline verdict when the model does not explain the data (reduced χ² far above 1:
    /// the standard errors are not to be trusted), `null` otherwise.
    pub misfit: Option<super::misfit::Misfit>,
    /// Factor applied to the covariance.
    pub covariance_scale: f64,
    /// The table.
    pub table: Vec<Row>,
    /// Correlation matrix, rows in table order.
    pub correlation: Vec<Vec<Option<f64>>>,
    /// RMS relative amplitude errors: `[label, initial, identified]`.
    pub rms_relative_error: Vec<(String, f64, f64)>,
    /// RMS amplitude errors in dB: `[label, initial, identified]`.
    pub rms_db_error: Vec<(String, f64, f64)>,
    /// Poorly identifiable combinations: `[combination, relative σ]`.
    pub weak_directions: Vec<(String, Option<f64>)>,
    /// Criterion per start.
    pub starts: Vec<(f64, String)>,
    /// Distinct optima of the starts and warnings (ambiguous optima, degenerate corners).
    pub start_analysis: super::starts::StartsAnalysis,
}

/// The JSON report of an identification.
pub fn json(id: &Identification) -> ReportJson {
    let n = id.variables.len();
    let c = &id.uncertainty.correlation;
    ReportJson {
        optimizer: id.optimizer.as_str().into(),
        converged: id.stop.converged(),
        stop: id.stop.describe(),
        iterations: id.iterations,
        model_evaluations: id.evaluations.model,
        jacobian_evaluations: id.evaluations.with_jacobian,
        fit: id.fit.as_str().into(),
        noise: id.noise.describe(),
        observations: id.observations,
        criterion_initial: id.criterion_initial,
        criterion: id.criterion,
        reduced_chi2: id.uncertainty.reduced_chi2,
        misfit: super::misfit::misfit(id),
        covariance_scale: id.uncertainty.covariance_scale,
        table: rows(id),
        correlation: (0..n)
            .map(|a| {
                (0..n)
                    .map(|b| Some(c[(a, b)]).filter(|v| v.is_finite()))
                    .collect()
            })
            .collect(),
        rms_relative_error: id
            .rms_initial
            .iter()
            .zip(&id.rms)
            .map(|((l, a), (_, b))| (l.clone(), *a, *b))
            .collect(),
        rms_db_error: id.rms_db.clone(),
        weak_directions: id
            .uncertainty
            .weak
            .iter()
            .map(|d| {
                (
                    d.combination(),
                    Some(d.relative_std).filter(|v| v.is_finite()),
                )
            })
            .collect(),
        starts: id
            .starts
            .iter()
            .map(|s| (s.criterion, s.stop.describe()))
            .collect(),
        start_analysis: super::starts::analyse(id),
    }
}

/// The table as CSV: `variable,sdes,parameter,unit,initial,identified,std_error,variability,at_bound`.
pub fn csv(id: &Identification) -> String {
    let mut s = rfe::csv_text::CsvText::new();
    s.row([
        "variable",
        "sdes",
        "parameter",
        "unit",
        "initial",
        "identified",
        "std_error",
        "variability",
        "at_bound",
    ]);
    for r in rows(id) {
        s.row([
            r.variable,
            r.sdes,
            r.parameter,
            r.unit,
            format!("{:?}", r.initial),
            format!("{:?}", r.identified),
            r.std_error.map(|v| format!("{v:?}")).unwrap_or_default(),
            r.variability.map(|v| format!("{v:?}")).unwrap_or_default(),
            r.at_bound.unwrap_or_default(),
        ]);
    }
    s.finish()
}

/// Why the TOML write-back failed.
#[derive(Debug, thiserror::Error)]
pub enum WriteBackError {
    /// The original text is not valid TOML (it loaded before, so this means it changed).
    #[error("{origin}: cannot re-read the model TOML for writing back: {message}")]
    Parse {
        /// File.
        origin: String,
        /// Parser message.
        message: String,
    },
    /// An SDE of the model is not found in the TOML text.
    #[error("{origin}: no [[sde]] named \"{sde}\" in the file; write the resolved JSON instead")]
    MissingSde {
        /// File.
        origin: String,
        /// SDE name.
        sde: String,
    },
    /// The fitted masses or inertias could not be written into the `[[body]]` tables.
    #[error("{origin}: cannot write the fitted masses and inertias: {message}")]
    Bodies {
        /// File.
        origin: String,
        /// What went wrong.
        message: String,
    },
}

/// Writes the identified values into the model's TOML text (`[[sde]]` tables matched by name,
/// and the `mass` and `inertia` of `[[body]]` tables whose mass or inertias were variables),
/// keeping comments and layout. An isolator given one `psi` whose `psi_n` or `psi_t` was
/// identified gets both keys; a general element's `k`/`psi` arrays are rewritten in SI.
pub fn update_toml(
    text: &str,
    origin: &str,
    id: &Identification,
) -> Result<String, WriteBackError> {
    let mut doc: DocumentMut =
        text.parse()
            .map_err(|e: toml_edit::TomlError| WriteBackError::Parse {
                origin: origin.into(),
                message: e.to_string(),
            })?;
    let model = &id.model;
    let mut touched: Vec<usize> = id.variables.params().iter().map(|p| p.sde).collect();
    touched.sort_unstable();
    touched.dedup();
    let Some(sdes) = doc.get_mut("sde").and_then(Item::as_array_of_tables_mut) else {
        let sde = touched
            .first()
            .map(|&i| model.sdes[i].name.clone())
            .unwrap_or_default();
        return Err(WriteBackError::MissingSde {
            origin: origin.into(),
            sde,
        });
    };
    for &si in &touched {
        let sde = &model.sdes[si];
        let Some(table) = sde_table(sdes, &sde.name) else {
            return Err(WriteBackError::MissingSde {
                origin: origin.into(),
                sde: sde.name.clone(),
            });
        };
        let params: Vec<ParamName> = id
            .variables
            .params()
            .iter()
            .filter(|p| p.sde == si)
            .map(|p| p.name)
            .collect();
        write_params(table, &sde.law, &params);
    }
    // Bodies whose mass or inertias were identified: their `mass` and `inertia` rewritten.
    write_back_bodies(
        &mut doc,
        origin,
        (model, model),
        &id.variables.model_params(),
        &[],
    )
    .map_err(|e| WriteBackError::Bodies {
        origin: origin.into(),
        message: e.to_string(),
    })?;
    Ok(doc.to_string())
}
