//! # identify — the maximum-likelihood fit of an RFE model to measured characteristics
//!
//! Identification of SDE parameters (and masses, point masses, sensor gains) from measured
//! amplitude-frequency characteristics: the fit of the paper's section 4 with Cramér-Rao errors.
//! The model and its frequency response are the `rfe` crate's; the search for effects the
//! model lacks, once it is fitted, is the `diagnose` crate's.
//!
//! - [`fit`]: the one call that fits ([`identify()`]), its options and its result;
//! - [`data`]: measured characteristics (JSON, CSV), validated against the model;
//! - [`line_choice`]: which measured lines enter the fit (band, excluded lines, coherence);
//! - [`variables`]: the decision variables (variables TOML: single parameters, groups, ratio ties,
//!   bounds, scaling);
//! - [`criterion`]: `J = ½ rᵀR⁻¹r` (eq. 4.4), amplitude or complex residuals, the noise model R,
//!   and the analytic Jacobian;
//! - [`optimize`]: bounded Levenberg-Marquardt, Gauss-Newton with line search (eq. 4.12-4.13),
//!   BFGS with a Wolfe line search;
//! - [`uncertainty`]: Cramér-Rao bound (eq. 4.15), correlations, identifiability;
//! - [`report`]: the Table-1-like table (text, JSON, CSV) and the updated model (TOML, JSON);
//! - [`problem`]: the fit problem as JSON for external tools (the Python baseline);
//! - [`prefit`]: a start from the measured modes (pairing by MAC or frequency, natural
//!   frequencies matched with analytic eigen-sensitivities, weighted by their uncertainty);
//! - [`starts`]: multi-start (Latin hypercube in log-parameter space), distinct optima, warnings
//!   about ambiguous optima and degenerate corners;
//! - [`synthetic`]: synthetic measured data from a model (tests, benchmarks);
//! - [`misfit`]: the headline verdict when the model does not explain the data; [`stats`]: the
//!   χ² tail and runs test shared with the diagnosis;
//! - [`measurement_map`]: a vendor file's channels onto the model's characteristics;
//!   [`plausibility`]: the band and level of the data against the initial model;
//! - [`request`]: the identification problem as one call — model, data (ident JSON/CSV or UFF
//!   with its map), line choice, decimation, variables and start in, the prepared
//!   [`request::Problem`] out — used by the command line, the workflows and the tests;
//!   [`modal_start`]: the start from the measured modes (`process::modal` extraction, then
//!   [`prefit`]).
//!
//! ```
//! use identify::{identify, variables, data::Observations, Options};
//! use rfe::{frf, textbook};
//! // Truth: k1 = 20 N/µm, k2 = 5 N/µm, ψ = 0.5; measure both outputs at 40 lines over
//! // 10-60 Hz, then fit k1 and k2 from 14 and 7 N/µm.
//! let truth = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
//! let freqs: Vec<f64> = (0..40).map(|i| 10.0 + 50.0 * i as f64 / 39.0).collect();
//! let r = frf::response(&truth, &freqs, &[], frf::Method::Direct).unwrap();
//! let data = rfe::MeasuredData {
//!     source: "synthetic".into(),
//!     characteristics: (0..2).map(|o| rfe::Measurement {
//!         body: truth.bodies[o].name.clone(), dof: 2, quantity: rfe::measured::QuantityName::Displacement,
//!         freqs_hz: freqs.clone(), amplitude: r.output(o).iter().map(|v| v.norm()).collect(),
//!         phase_rad: None, variance: None, coherence: None, averages: None, at: None, reference: None, relative: false,
//!     }).collect(),
//! };
//! let obs = identify::data::validate(&data, &truth, "synthetic").unwrap();
//! let vars = variables::parse(r#"
//!     [[variable]]
//!     sdes = "k1"
//!     parameter = "k"
//!     initial = "14 N/um"
//!     [[variable]]
//!     sdes = "k2"
//!     parameter = "k"
//!     initial = "7 N/um"
//! "#, "vars.toml", &truth).unwrap();
//! let id = identify(&truth, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
//! assert!(id.stop.converged());
//! assert!((id.estimate[0] / 2.0e7 - 1.0).abs() < 1e-6);
//! assert!((id.estimate[1] / 5.0e6 - 1.0).abs() < 1e-6);
//! ```

// `expect` is linted here (not workspace-wide yet): nothing read from a file, a device or a
// user may panic; tests may expect (clippy.toml).
#![warn(clippy::expect_used)]

pub mod criterion;
pub mod data;
pub mod fit;
pub mod line_choice;
pub mod measurement_map;
pub mod misfit;
pub mod modal_start;
pub mod optimize;
pub mod plausibility;
pub mod prefit;
pub mod problem;
pub mod report;
pub mod request;
pub mod starts;
pub mod stats;
pub mod synthetic;
pub mod uncertainty;
pub mod variables;

pub use criterion::{Criterion, Evaluations, FitKind, JacobianMode, NoiseChoice, NoiseSource};
pub use data::{DataError, Observations};
pub use fit::{identify, uncertainty_at, Identification, IdentifyError, Options, StartSummary};
pub use optimize::{EvalError, Optimizer, Progress, Settings, StopReason};
pub use uncertainty::{AtBound, Uncertainty, WeakDirection};
pub use variables::{Variables, VarsError};
