//! # report — what an identification run tells its reader
//!
//! One run (demo, replay, nightly) becomes a [`Report`]: measured versus model amplitude-frequency
//! characteristics at each stage (initial, identified, diagnosed), standardized residuals, the
//! Table-1-like parameter table with Cramér-Rao errors, the diagnosis (ranked candidate effects, error before and after), the band
//! sensitivity (MI) map, a picture of the final model with its mode shapes in the band, and the
//! drift of every parameter across nights. It is written twice:
//!
//! - [`html::render`]: one self-contained HTML file — inline CSS, inline SVG drawn with
//!   `plotters` (text as SVG `<text>`, no font files, no scripts, no external resources); it
//!   opens offline in any browser;
//! - [`Report`] serialized as JSON (schema `ident.report/1`, `docs/report-json.md`).
//!
//! Modules: [`document`] (the data, = the JSON schema), [`build`] (from `identify`'s results),
//! [`drift`] (history across runs and alarms), [`plot`] (the SVG charts), [`picture`] (the model
//! and its mode shapes as a drawing), [`html`] (the page).
//!
//! ```
//! use identify::{data, identify, variables, Options};
//! use rfe::{frf, textbook, MeasuredData, Measurement};
//! // Measure a two-mass textbook model, fit its two stiffnesses, and report.
//! let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
//! let freqs: Vec<f64> = (0..30).map(|i| 10.0 + 2.0 * i as f64).collect();
//! let r = frf::response(&truth, &freqs, &[], frf::Method::Direct).unwrap();
//! let measured = MeasuredData {
//!     source: "synthetic".into(),
//!     characteristics: (0..2).map(|o| Measurement {
//!         body: truth.bodies[o].name.clone(), dof: 2,
//!         quantity: rfe::measured::QuantityName::Displacement,
//!         freqs_hz: freqs.clone(), amplitude: r.output(o).iter().map(|v| v.norm()).collect(),
//!         phase_rad: None, variance: None, coherence: None, averages: None, at: None, reference: None, relative: false,
//!     }).collect(),
//! };
//! let obs = data::validate(&measured, &truth, "synthetic").unwrap();
//! let vars = variables::parse("[[variable]]\nsdes = \"k1\"\nparameter = \"k\"\ninitial = \"15 N/um\"\n",
//!     "vars.toml", &truth).unwrap();
//! let id = identify(&truth, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
//! let report = report::build::build(report::build::Inputs::new("two masses", &obs, &id)).unwrap();
//! assert_eq!(report.characteristics.len(), 2);
//! let html = report::html::render(&report).unwrap();
//! assert!(html.contains("<svg") && !html.contains("http://www.w3.org/1999/xlink\" href"));
//! ```

// No panic on anything from a file, a device or a user (tests may: allow-expect-in-tests).
#![warn(clippy::expect_used)]

pub mod build;
pub mod document;
pub mod drift;
pub mod html;
pub mod picture;
pub mod plot;
pub mod stabilization;

use std::path::{Path, PathBuf};

pub use document::{Diagnosis, Drift, Outcome, Report, SCHEMA};

/// A drawing failed (plotters' SVG backend). Defined here, below the modules that draw
/// ([`plot`], [`picture`]), so that the report's data ([`document`]) → picture and plot →
/// document form no circle.
pub type DrawError = plotters::drawing::DrawingAreaErrorKind<std::io::Error>;

/// Why a report could not be made or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// A model curve could not be computed.
    #[error("report: the {stage} model cannot be evaluated: {source}")]
    Model {
        /// Stage (`initial`, `identified`, `diagnosed`).
        stage: String,
        /// Solver error.
        source: rfe::frf::SolveError,
    },
    /// A plot could not be drawn.
    #[error("report: cannot draw the {chart} chart: {source}")]
    Plot {
        /// Which chart.
        chart: String,
        /// Plotters' error.
        source: DrawError,
    },
    /// A file could not be written (disk full, permissions).
    #[error("cannot write {path}: {source} (nothing was replaced: free space or fix permissions and re-run)")]
    Write {
        /// File.
        path: String,
        /// OS error.
        source: std::io::Error,
    },
    /// A file could not be read.
    #[error("cannot read {path}: {message}")]
    Read {
        /// File.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// JSON encoding failed.
    #[error("report JSON: {0}")]
    Json(#[from] serde_json::Error),
}

/// Paths of a written report.
#[derive(Debug, Clone, PartialEq)]
pub struct Written {
    /// `report.html`.
    pub html: PathBuf,
    /// `report.json`.
    pub json: PathBuf,
}

/// Writes `report.json` and `report.html` into `dir` (which must exist). Each file is written to
/// a temporary name and renamed, so a full disk leaves no half-written report behind.
pub fn write(report: &Report, dir: &Path) -> Result<Written, ReportError> {
    let json = serde_json::to_string_pretty(report)?;
    let html = html::render(report)?;
    let jp = dir.join("report.json");
    let hp = dir.join("report.html");
    write_atomic(&jp, json.as_bytes())?;
    write_atomic(&hp, html.as_bytes())?;
    Ok(Written { html: hp, json: jp })
}

/// Writes `bytes` to `path` via `path.partial` and a rename; on error the partial file is removed.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|source| {
        let _ = std::fs::remove_file(&tmp);
        ReportError::Write {
            path: path.display().to_string(),
            source,
        }
    })
}

/// Reads a report JSON file.
pub fn read(path: &Path) -> Result<Report, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReportError::Read {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    serde_json::from_str(&text).map_err(|e| ReportError::Read {
        path: path.display().to_string(),
        message: format!(
            "line {} column {}: {e} (not an {SCHEMA} report)",
            e.line(),
            e.column()
        ),
    })
}
