//! The covariance of the final model's variables, read from an identification report
//! (`report.json`, `docs/report-json.md`) and the final variables file.
//!
//! The report holds, per variable, its relative standard error (`variability` = σ/|x|) and the
//! correlation matrix of the estimates. The relative error is unit-free, so it carries over to
//! the final variables file however its units are written; a scale-tied variable starts again at
//! the factor 1 there, and σ/|x| is then the σ of that factor. When the diagnosis added effects,
//! the report's `diagnosis.final_parameters` and `diagnosis.final_correlation` give the errors
//! and the correlation of the final fit. A report written before the final correlation was
//! stored has only the first fit's, which is then used with the final errors and said so in a
//! note. The added effects' own variables are held at their estimates (the report has no errors
//! for them), also said in a note.

use nalgebra::DMatrix;
use serde::Deserialize;

use identify::variables::Variables;

/// A report that cannot give the covariance.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CovarianceError {
    /// Not the report JSON.
    #[error("{file}: not an identification report ({message}); give the report.json of `ident identify --out` / `ident diagnose --out` / `ident demo`")]
    Format {
        /// File.
        file: String,
        /// Parser message.
        message: String,
    },
    /// No variable of the variables file is in the report.
    #[error("{file}: none of the variables of {vars} is in identification.parameters; give the report of the run that wrote those variables")]
    Unmatched {
        /// Report file.
        file: String,
        /// Variables file.
        vars: String,
    },
}

#[derive(Deserialize)]
struct Row {
    variable: String,
    variability: Option<f64>,
}

#[derive(Deserialize)]
struct Ident {
    parameters: Vec<Row>,
    correlation: Vec<Vec<Option<f64>>>,
}

#[derive(Deserialize)]
struct Diag {
    #[serde(default)]
    final_parameters: Vec<Row>,
    #[serde(default)]
    final_correlation: Vec<Vec<Option<f64>>>,
}

#[derive(Deserialize)]
struct Report {
    identification: Ident,
    diagnosis: Option<Diag>,
}

/// The covariance (SI, over `vars` in order) and notes on what it assumes.
#[derive(Debug, Clone, PartialEq)]
pub struct FromReport {
    /// Covariance of the variables.
    pub matrix: DMatrix<f64>,
    /// What the reader should know (variables without errors, first-fit correlation).
    pub notes: Vec<String>,
}

/// The covariance of `vars` (their `initial` values are the estimates) from a report's text.
pub fn from_report(
    text: &str,
    file: &str,
    vars: &Variables,
) -> Result<FromReport, CovarianceError> {
    let r: Report = serde_json::from_str(text).map_err(|e| CovarianceError::Format {
        file: file.into(),
        message: e.to_string(),
    })?;
    let first = &r.identification.parameters;
    let mut notes = Vec::new();
    let (rows, corr) = match &r.diagnosis {
        Some(d) if !d.final_parameters.is_empty() => {
            if d.final_correlation.len() == d.final_parameters.len() {
                (&d.final_parameters, &d.final_correlation)
            } else {
                notes.push("the errors are the final fit's; the correlation is the first fit's (this report does not store the final fit's)".to_string());
                (&d.final_parameters, &r.identification.correlation)
            }
        }
        _ => (first, &r.identification.correlation),
    };
    let n = vars.len();
    let x = vars.initial();
    // Index in the report table and σ (SI) of each variable.
    let mut found: Vec<Option<(usize, f64)>> = vec![None; n];
    let mut missing = Vec::new();
    for (i, v) in vars.vars.iter().enumerate() {
        match rows.iter().position(|r| r.variable == v.name) {
            Some(k) => {
                let rel = rows[k].variability.unwrap_or(f64::NAN);
                if rel.is_finite() {
                    found[i] = Some((k, rel * x[i].abs()));
                } else {
                    missing.push(format!("{} (undetermined)", v.name));
                }
            }
            None => missing.push(v.name.clone()),
        }
    }
    if found.iter().all(Option::is_none) {
        return Err(CovarianceError::Unmatched {
            file: file.into(),
            vars: vars.origin.clone(),
        });
    }
    if !missing.is_empty() {
        notes.push(format!(
            "held at their estimates (no standard error in the report): {}",
            missing.join(", ")
        ));
    }
    let matrix = DMatrix::from_fn(n, n, |i, j| match (found[i], found[j]) {
        (Some((a, sa)), Some((b, sb))) => {
            let rho = if i == j {
                1.0
            } else {
                corr.get(a)
                    .and_then(|row| row.get(b))
                    .copied()
                    .flatten()
                    .unwrap_or(0.0)
            };
            rho * sa * sb
        }
        _ => 0.0,
    });
    Ok(FromReport { matrix, notes })
}
