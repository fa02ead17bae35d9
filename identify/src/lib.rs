//! # identify — rigid-finite-element models of machine tools and the identification of their joints
//!
//! A machine tool's supporting system is modelled, as in the IDENT method (Gutowski & Berczyński,
//! 1997), as rigid finite elements (RFEs, six DOFs each) joined by spring-damping elements (SDEs:
//! slideway and rotary joints, lead screws, vibration isolators) with hysteretic damping. Its
//! frequency response solves `(K + jD − ω²M) q = P`.
//!
//! - [`model`]: the resolved model (SI units, global frame) every computation takes;
//! - [`system`]: assembly of M, K, D and P;
//! - [`frf`]: frequency response and analytic Jacobian, direct and modal paths;
//! - [`modes`]: natural frequencies, mode shapes (undamped and complex), loss factors;
//! - [`sensitivity`]: band sensitivity MI (eq. 4.16) to pick decision variables;
//! - [`measured`]: measured characteristics, as processing produces them;
//! - [`modelfile`], [`contract`], [`units`], [`check`]: model files (TOML with units, resolved
//!   JSON) and their validation;
//! - [`diagnose`]: after a fit, residual analysis and the search for effects the model lacks;
//! - [`final_model`]: the final model as a model file (values written back, accepted effects
//!   added) and the variables file for the next run;
//! - [`textbook`]: small models with closed-form answers.
//!
//! ```
//! use identify::{frf, textbook};
//! // A 100 kg body on 1 N/µm springs with ψ = 0.2, driven by 1 N.
//! let model = textbook::single_body(100.0, 1.0e6, 0.2);
//! let r = frf::response(&model, &[0.0], &[], frf::Method::Direct).unwrap();
//! let static_compliance = r.output(0)[0].norm();
//! // |q| = 1 / |k (1 + jψ/2π)| at 0 Hz
//! let expected = 1.0 / (1.0e6 * (1.0 + (0.2 / (2.0 * std::f64::consts::PI)).powi(2)).sqrt());
//! assert!((static_compliance - expected).abs() < 1e-12 * expected);
//! ```

pub mod check;
pub mod contract;
pub mod csv_text;
pub mod diagnose;
pub mod display;
pub mod final_model;
pub mod frf;
pub mod identification;
pub mod lines;
pub mod measured;
pub mod model;
pub mod modelfile;
pub mod modes;
pub mod sensitivity;
pub mod source;
pub mod system;
pub mod textbook;
pub mod units;

pub use measured::{MeasuredData, Measurement};
pub use model::{
    Body, Characteristic, Model, Param, ParamName, ParamRef, PointForce, Quantity, Sde, SdeKind,
    SdeLaw, Tangential,
};

/// Complex double, the scalar of every frequency response (same type as faer's `c64`).
pub type C64 = num_complex::Complex<f64>;
