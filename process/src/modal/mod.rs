//! # modal — modal parameters straight from measured FRFs
//!
//! A start from the measurement: natural frequencies, damping ratios, participation vectors and
//! mode shapes of the structure, before any model is written.
//!
//! 0. [`layout`]: the test layout (roving hammer, roving accelerometer, multi-reference, mixed)
//!    recognised from the FRFs' channels and arranged as points × fixed channels, the side with
//!    fewer channels carrying the polynomial (transposed by reciprocity for a roving hammer).
//! 1. [`lscf`](mod@lscf): the poly-reference least-squares complex frequency-domain estimator
//!    (pLSCF, Guillaume, Verboven, Vanlanduit, Van der Auweraer & Peeters 2003; Peeters et al.
//!    2004). A right matrix-fraction model `H(ω) = B(z) A(z)⁻¹`, `z = exp(iωΔt)`, with real matrix
//!    coefficients, fitted by linear least squares over model orders 1..=N_max. The normal
//!    equations are reduced to the denominator once (Cholesky of the common `R`, one rank update
//!    per order), so all orders cost little more than the highest one.
//! 2. [`stabilization`]: the stabilization diagram (frequency, damping and participation-vector
//!    stability between consecutive orders, tolerances as [`StabilityTolerances`]), automatic pole
//!    selection (stable poles clustered across orders) and the user's override (a list of
//!    approximate frequencies).
//! 3. [`lsfd()`]: residues by linear least squares in the frequency domain with lower and upper
//!    residuals, the residue matrix of each mode split into mode shape × participation (rank 1).
//! 4. [`mac`] and [`complexity`]: modal assurance criterion between shape sets and the modal
//!    complexity factor of a shape; [`indicators`]: MPC, MPD and MCF of a shape and the complex
//!    mode indicator function of the FRF matrix.
//!
//! Units: SI inside (frequencies in Hz at the interface, poles in rad/s); the FRF's own unit is
//! kept (residues carry it). Damping is the ratio of critical ζ; the loss factor is η = 2ζ.
//!
//! ```
//! use process::modal::{self, FrfKind, ModalData, LscfSettings};
//! use process::C64;
//!
//! // One mode at 50 Hz, 2 % damping, receptance, one output and one reference.
//! let (fn_hz, zeta) = (50.0, 0.02);
//! let w = 2.0 * std::f64::consts::PI * fn_hz;
//! let lambda = C64::new(-zeta * w, w * (1.0 - zeta * zeta).sqrt());
//! let freqs: Vec<f64> = (1..=400).map(|k| k as f64 * 0.25).collect();
//! let h: Vec<C64> = freqs.iter().map(|&f| {
//!     let s = C64::new(0.0, 2.0 * std::f64::consts::PI * f);
//!     C64::new(0.0, -1e-3) / (s - lambda) + C64::new(0.0, 1e-3) / (s - lambda.conj())
//! }).collect();
//! let data = ModalData::new(freqs, 1, 1, h, FrfKind::Receptance)?;
//! let orders = modal::lscf(&data, &LscfSettings { max_order: 8, band_hz: None })?;
//! let best = orders.last().unwrap().poles.iter()
//!     .min_by(|a, b| (a.freq_hz - fn_hz).abs().total_cmp(&(b.freq_hz - fn_hz).abs())).unwrap();
//! assert!((best.freq_hz - fn_hz).abs() < 1e-6 * fn_hz);
//! assert!((best.damping_ratio - zeta).abs() < 1e-6);
//! # Ok::<(), process::modal::ModalError>(())
//! ```

pub mod indicators;
pub mod layout;
pub mod lscf;
pub mod lsfd;
pub mod stabilization;

pub use layout::{arrange, Channel, Layout, LayoutKind, MeasuredFrf};
pub use lscf::{lscf, LscfSettings, OrderPoles, Pole, PoleStd};
pub use lsfd::{lsfd, ModalModel, Mode};
pub use stabilization::{
    select_auto, select_near, stabilize, SelectionSettings, Stability, StabilityTolerances,
    StabilizationDiagram,
};

use crate::C64;

/// Everything that can go wrong in modal parameter extraction; each says what to change.
#[derive(Debug, thiserror::Error)]
pub enum ModalError {
    /// The FRF array does not have outputs × references × lines values.
    #[error("FRF matrix: expected {outputs} outputs × {references} references × {lines} lines = {expected} values, got {got}")]
    Shape {
        /// Outputs.
        outputs: usize,
        /// References.
        references: usize,
        /// Lines.
        lines: usize,
        /// Values expected.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A frequency or an FRF value is not finite, or frequencies are not increasing.
    #[error("FRF data line {line} ({what}): {reason}")]
    BadLine {
        /// Index of the spectral line.
        line: usize,
        /// Which quantity.
        what: &'static str,
        /// What is wrong and how to fix it.
        reason: String,
    },
    /// A setting is out of range.
    #[error("invalid modal setting {field} = {value}: {reason}")]
    InvalidSetting {
        /// Name of the setting.
        field: &'static str,
        /// Its value as given.
        value: String,
        /// What is allowed.
        reason: String,
    },
    /// Too few lines in the band for the requested model order.
    #[error("{lines} lines in the band {lo_hz}..{hi_hz} Hz are too few for model order {order} with {references} references: widen the band or lower --max-order")]
    TooFewLines {
        /// Lines in the band.
        lines: usize,
        /// Lower band edge (Hz).
        lo_hz: f64,
        /// Upper band edge (Hz).
        hi_hz: f64,
        /// Highest model order.
        order: usize,
        /// References.
        references: usize,
    },
    /// The least-squares system is singular (FRFs all zero, or duplicated lines).
    #[error("the least-squares system of {what} is singular: the FRFs carry no information in the band (all zero, or too few distinct lines)")]
    Singular {
        /// Which system.
        what: &'static str,
    },
    /// The same response-reference pair is measured twice.
    #[error("{first} and {second} both hold the FRF of response {response} to reference {reference}: keep one (or average them before extraction)")]
    DuplicateFrf {
        /// Response channel (node:direction).
        response: String,
        /// Reference channel.
        reference: String,
        /// Where the first one came from.
        first: String,
        /// Where the second one came from.
        second: String,
    },
    /// The FRFs do not fill the points × fixed-channels grid, even read by reciprocity.
    #[error("{count} of the {points} points × {} fixed channels ({}) FRFs are missing, measured in neither direction (response ← reference): {}{}; measure them or leave the points or channels they belong to out of the file", fixed.len(), fixed.join(", "), missing.join(", "), if *count > missing.len() { ", …" } else { "" })]
    MissingFrfs {
        /// Number of points.
        points: usize,
        /// The fixed channels (node:direction).
        fixed: Vec<String>,
        /// Number of missing FRFs.
        count: usize,
        /// The first missing ones, `response ← reference` as the file would hold them.
        missing: Vec<String>,
    },
    /// The set cannot be arranged for the estimator.
    #[error("FRF set: {reason}")]
    Layout {
        /// What is wrong and how to fix it.
        reason: String,
    },
    /// Scaling (unit modal mass) needs a driving-point FRF.
    #[error("unit-modal-mass shapes need a driving point (an FRF whose response and reference are the same node and direction) at one of the fixed channels {fixed}; none is measured: measure one, or leave the shapes unscaled")]
    NoDrivingPoint {
        /// The fixed channels.
        fixed: String,
    },
    /// No pole was found near a frequency the user asked for.
    #[error("no stable pole within {window_pct} % of {freq_hz} Hz in the stabilization diagram: check the frequency, widen the band or raise --max-order")]
    NoPoleNear {
        /// Frequency asked for (Hz).
        freq_hz: f64,
        /// Search window (% of the frequency).
        window_pct: f64,
    },
}

/// Result of modal extraction.
pub type Result<T> = std::result::Result<T, ModalError>;

/// What an FRF relates: displacement, velocity or acceleration per force.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrfKind {
    /// Displacement / force.
    Receptance,
    /// Velocity / force.
    Mobility,
    /// Acceleration / force.
    Accelerance,
}

impl FrfKind {
    /// Power of `iω` that turns a receptance into this kind.
    pub fn derivative_order(self) -> i32 {
        match self {
            FrfKind::Receptance => 0,
            FrfKind::Mobility => 1,
            FrfKind::Accelerance => 2,
        }
    }
}

/// A measured FRF matrix: `outputs × references` functions on common lines.
#[derive(Debug, Clone)]
pub struct ModalData {
    /// Frequencies of the lines (Hz), strictly increasing.
    pub freqs_hz: Vec<f64>,
    /// Number of outputs (responses).
    pub outputs: usize,
    /// Number of references (inputs).
    pub references: usize,
    /// Values, `h[(o * references + r) * lines + k]`: each FRF's lines contiguous.
    pub h: Vec<C64>,
    /// What the FRFs relate.
    pub kind: FrfKind,
}

impl ModalData {
    /// Checks shape, finiteness and increasing frequencies.
    pub fn new(
        freqs_hz: Vec<f64>,
        outputs: usize,
        references: usize,
        h: Vec<C64>,
        kind: FrfKind,
    ) -> Result<ModalData> {
        let lines = freqs_hz.len();
        let expected = outputs * references * lines;
        if expected == 0 || h.len() != expected {
            return Err(ModalError::Shape {
                outputs,
                references,
                lines,
                expected,
                got: h.len(),
            });
        }
        for (k, f) in freqs_hz.iter().enumerate() {
            if !f.is_finite() || *f < 0.0 {
                return Err(ModalError::BadLine {
                    line: k,
                    what: "frequency",
                    reason: format!("{f} Hz is not a finite non-negative frequency"),
                });
            }
            if k > 0 && !(*f > freqs_hz[k - 1]) {
                return Err(ModalError::BadLine {
                    line: k,
                    what: "frequency",
                    reason: format!(
                        "{f} Hz does not follow {} Hz: lines must be sorted and distinct",
                        freqs_hz[k - 1]
                    ),
                });
            }
        }
        if let Some(i) = h
            .iter()
            .position(|v| !v.re.is_finite() || !v.im.is_finite())
        {
            let k = i % lines;
            let fr = i / lines;
            return Err(ModalError::BadLine {
                line: k,
                what: "FRF value",
                reason: format!(
                    "output {}, reference {} is {}: remove the line (--band) or fix the file",
                    fr / references,
                    fr % references,
                    h[i]
                ),
            });
        }
        Ok(ModalData {
            freqs_hz,
            outputs,
            references,
            h,
            kind,
        })
    }

    /// Number of lines.
    pub fn lines(&self) -> usize {
        self.freqs_hz.len()
    }

    /// The FRF from reference `r` to output `o`, all lines.
    pub fn frf(&self, o: usize, r: usize) -> &[C64] {
        let n = self.lines();
        let at = (o * self.references + r) * n;
        &self.h[at..at + n]
    }
}

/// Modal assurance criterion between two sets of (complex) shapes: `mac[i][j]` compares `a[i]`
/// with `b[j]`; 1 for collinear shapes, 0 for orthogonal ones (and for a zero shape).
pub fn mac(a: &[Vec<C64>], b: &[Vec<C64>]) -> Vec<Vec<f64>> {
    a.iter()
        .map(|x| {
            b.iter()
                .map(|y| {
                    let xy: C64 = x.iter().zip(y).map(|(p, q)| p.conj() * q).sum();
                    let xx: f64 = x.iter().map(|p| p.norm_sqr()).sum();
                    let yy: f64 = y.iter().map(|q| q.norm_sqr()).sum();
                    if xx > 0.0 && yy > 0.0 {
                        xy.norm_sqr() / (xx * yy)
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// Modal complexity factor of a shape: 0 when all components are in phase (or opposite), 1 when
/// the real and imaginary parts are equal and orthogonal (a travelling wave).
pub fn complexity(shape: &[C64]) -> f64 {
    let sxx: f64 = shape.iter().map(|v| v.re * v.re).sum();
    let syy: f64 = shape.iter().map(|v| v.im * v.im).sum();
    let sxy: f64 = shape.iter().map(|v| v.re * v.im).sum();
    let total = sxx + syy;
    if total > 0.0 {
        (1.0 - ((sxx - syy).powi(2) + 4.0 * sxy * sxy) / (total * total)).max(0.0)
    } else {
        0.0
    }
}
