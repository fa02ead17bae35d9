//! The run history of unattended identifications and the drift judgement learned from it.
//!
//! Cramér-Rao errors describe the noise of one measurement; on a real machine the identified
//! stiffness and damping move from night to night (temperature, lubrication, re-clamping) by far
//! more. This crate keeps every run in one SQLite file ([`store`]: WAL, one transaction per run,
//! a schema version) and judges a new run against what normal looked like over a baseline window
//! of earlier runs ([`judge`]: robust per-parameter scatter; Shewhart, CUSUM and EWMA charts per
//! parameter; Hotelling T² against the Cramér-Rao correlation structure; optional compensation
//! of a covariate such as temperature; new effects; one false-alarm budget across the charts).
//! Runs come from reports ([`import`], reading the report crate's own [`report::Report`] type:
//! history depends on report, never the reverse). Values in SI inside; alarms speak the
//! parameters' display units.
//!
//! ```
//! use history::record::{ParameterRecord, RunRecord};
//! use history::store::Store;
//! let dir = tempfile::tempdir().unwrap();
//! let mut store = Store::open(&dir.path().join("history.sqlite")).unwrap();
//! store.append(&RunRecord {
//!     run_id: "2026-03-01T020000Z".into(),
//!     time_utc: "2026-03-01T02:00:00Z".into(),
//!     stand: Some("FWD-32J".into()),
//!     model_hash: history::record::model_hash(b"model file bytes"),
//!     session: None,
//!     outcome: "ok".into(),
//!     reduced_chi2: Some(1.02),
//!     parameters: vec![ParameterRecord {
//!         variable: "kn_table".into(),
//!         unit: "MPa/um".into(),
//!         unit_factor: 1e12,
//!         estimate: 0.05e12,
//!         std_error: Some(0.0005e12),
//!     }],
//!     characteristics: vec![],
//!     effects: vec![],
//!     covariates: vec![],
//!     correlations: vec![],
//!     quantities: vec![],
//! }).unwrap();
//! let runs = store.runs().unwrap();
//! assert_eq!(runs[0].parameters[0].in_unit(), 0.05);
//! ```

// No panic on anything from a file, a device or a user (tests may: allow-expect-in-tests).
#![warn(clippy::expect_used)]

pub mod error;
pub mod import;
pub mod judge;
pub mod record;
pub mod store;
pub mod trend;

pub use error::HistoryError;
