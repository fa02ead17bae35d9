//! # rfe — rigid-finite-element models of machine tools
//!
//! A machine tool's supporting system is modelled, as in the IDENT method (Gutowski & Berczyński,
//! 1997), as rigid finite elements (RFEs, six DOFs each) joined by spring-damping elements (SDEs:
//! slideway and rotary joints, lead screws, vibration isolators) with hysteretic damping. Its
//! frequency response solves `(K + jD − ω²M) q = P`. This crate is the model and what can be
//! computed from it alone; fitting it to measurements is the `identify` crate's job, and the
//! search for what it lacks the `diagnose` crate's.
//!
//! - [`model`]: the resolved model (SI units, global frame) every computation takes;
//! - [`system`]: assembly of M, K, D and P;
//! - [`frf`] (with the line kernels in [`lines`]): frequency response and analytic Jacobian,
//!   direct and modal paths;
//! - [`lowrank`]: a change of the model (a spring, a mass, a freed direction) as a low-rank
//!   update of `K + jD − ω²M`, its response from the base's solves (Sherman-Morrison-Woodbury);
//! - [`modes`]: natural frequencies, mode shapes (undamped and complex), loss factors;
//! - [`sensitivity`]: band sensitivity MI (eq. 4.16) to pick decision variables;
//! - [`measured`]: measured characteristics, as processing produces them; [`channel`]: a vendor
//!   file's channels before they are mapped onto the model; [`frf_units`]: their units (receptance, mobility, accelerance);
//! - [`modelfile`], [`contract`], [`units`], [`source`], [`check`]: model files (TOML with
//!   units, resolved JSON) and their validation; [`write_back`]: values written back into a
//!   model file, its comments and layout kept;
//! - [`csv_text`]: the one CSV reader and writer (RFC 4180 through the `csv` crate, `#` comment
//!   lines, line numbers for messages) every CSV file of the project goes through;
//! - [`display`]: numbers for readers (significant digits, relative errors, p-values);
//! - [`textbook`]: small models with closed-form answers.
//!
//! ```
//! use rfe::{frf, textbook};
//! // A 100 kg body on 1 N/µm springs with ψ = 0.2, driven by 1 N.
//! let model = textbook::single_body(100.0, 1.0e6, 0.2);
//! let r = frf::response(&model, &[0.0], &[], frf::Method::Direct).unwrap();
//! let static_compliance = r.output(0)[0].norm();
//! // |q| = 1 / |k (1 + jψ/2π)| at 0 Hz
//! let expected = 1.0 / (1.0e6 * (1.0 + (0.2 / (2.0 * std::f64::consts::PI)).powi(2)).sqrt());
//! assert!((static_compliance - expected).abs() < 1e-12 * expected);
//! ```

// `expect` is linted here (not workspace-wide yet): nothing read from a file, a device or a
// user may panic; tests may expect (clippy.toml).
#![warn(clippy::expect_used)]

pub mod channel;
pub mod check;
pub mod contract;
pub mod csv_text;
pub mod display;
pub mod frf;
pub mod frf_units;
pub mod lines;
pub mod lowrank;
pub mod measured;
pub mod model;
pub mod modelfile;
pub mod modes;
pub mod sensitivity;
pub mod source;
pub mod system;
pub mod textbook;
pub mod units;
pub mod write_back;

pub use measured::{MeasuredData, Measurement};
pub use model::{
    Body, Characteristic, Model, Param, ParamName, ParamRef, PointForce, Quantity, Sde, SdeKind,
    SdeLaw, Tangential,
};

/// Complex double, the scalar of every frequency response (same type as faer's `c64`).
pub type C64 = num_complex::Complex<f64>;
