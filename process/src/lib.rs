//! # process — from sampled force and acceleration to principal-axis characteristics
//!
//! The chain that turns what the DAQ recorded into what identification consumes
//! ([`rfe::MeasuredData`]):
//!
//! 1. [`spectra`]: streaming Welch auto/cross-spectral matrices (rustfft planned once, buffers
//!    reused, bounded memory), with the windows of [`window`] (rectangular, Hann, Hamming,
//!    Blackman-Harris, flat-top, force, exponential).
//! 2. [`estimate`](mod@estimate): H1 / H2 / Hv, ordinary and multiple coherence, MIMO H1, the variance of each
//!    FRF point. [`sine`]: stepped-sine least-squares fits instead, for sine excitation (with
//!    distortion, noise level and FRF variance per step).
//! 3. [`calibration`]: sensitivities, accelerance ↔ mobility ↔ receptance.
//! 4. [`principal`]: per frequency, the least-squares 6-DOF rigid-body motion of a solid at its
//!    centre of mass in its principal axes, with a rigidity indicator.
//! 5. [`selection`]: picking identification points (log spread, denser at resonances, coherent
//!    lines only) and building [`rfe::Measurement`]s.
//!
//! Exchange: [`uff`] (universal file dataset 58, ASCII and binary 58b), [`npy`] (NumPy arrays).
//!
//! ```
//! use process::{estimate::{estimate, Estimator}, spectra::{Welch, WelchConfig}, window::Window};
//!
//! // A force and a response that is exactly 2·force delayed by one sample.
//! let fs = 1000.0;
//! let force: Vec<f64> = (0..4096).map(|i| ((i * 7919 % 1013) as f64 / 1013.0) - 0.5).collect();
//! let response: Vec<f64> = (0..4096).map(|i| if i == 0 { 0.0 } else { 2.0 * force[i - 1] }).collect();
//!
//! let mut welch = Welch::new(WelchConfig::new(fs, 256, Window::Hann), &["force"], &["acc"])?;
//! welch.push(&[&force], &[&response])?; // blocks of any length, as they arrive
//! let frf = estimate(&welch.finish()?, Estimator::H1)?;
//!
//! let k = 32; // 125 Hz
//! let expected = 2.0 * num_complex::Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * frf.freqs_hz[k] / fs);
//! assert!((frf.h(k, 0, 0) - expected).norm() < 0.05);
//! assert!(frf.coherence(k, 0, 0) > 0.95);
//! # Ok::<(), process::ProcessError>(())
//! ```

// `expect` is linted here (not workspace-wide yet): nothing read from a file, a device or a
// user may panic; tests may expect (clippy.toml).
#![warn(clippy::expect_used)]

pub mod calibration;
pub mod error;
pub mod estimate;
pub mod modal;
pub mod npy;
pub mod principal;
pub mod selection;
pub mod sine;
pub mod spectra;
pub mod uff;
pub mod window;

pub use error::{ProcessError, Result};
pub use estimate::{estimate, Estimator, Frf};
pub use spectra::{cross_spectra, CrossSpectra, Detrend, Signal, Welch, WelchConfig};
pub use window::Window;

/// Complex double (same type as [`rfe::C64`]).
pub type C64 = num_complex::Complex<f64>;
