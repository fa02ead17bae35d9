//! # stability — chatter stability lobes from an identified machine-tool model
//!
//! An operator identifies a machine to answer a machining question: how deep can it cut, at
//! which spindle speeds, before it chatters? This crate answers it from the final RFE model and
//! its Cramér-Rao covariance:
//!
//! - [`cut`]: the cutting file — tool and workpiece points, cutting coefficients, turning or
//!   milling (teeth, immersion, up/down, feed direction), spindle speeds, tool modes;
//! - [`oriented`]: the oriented relative tool–workpiece receptance in the cutting plane by
//!   `identify`'s FRF paths, its analytic Jacobian, its split into the model's modes;
//! - [`lobes`](mod@lobes): turning (Tlusty/Tobias) and milling (zeroth-order approximation, Altintas and
//!   Budak) lobes, the boundary, and its gradient with respect to the variables;
//! - [`sd`]: semi-discretization (Insperger and Stépán), the milling reference at low immersion;
//! - [`bands`]: 5–95 % bands, linear through the analytic sensitivities and by Monte Carlo;
//! - [`section`]: the lobes as data (`ident stability --json`, the report's stability section)
//!   and their SVG chart.
//!
//! [`lobes()`] is the workflow: a model, a cut and optionally the covariance in, the boundary,
//! its band and the modes (with their bodies and joints) that set the limit out.
//!
//! ```
//! use rfe::textbook;
//! // A 100 kg body on 10 N/µm springs (ψ = 0.2); a turning tool on it, workpiece fixed.
//! let model = textbook::single_body(100.0, 1.0e7, 0.2);
//! let cut = stability::cut::parse(r#"
//!     operation = "turning"
//!     speed_rpm = [300, 3000]
//!     speeds = 50
//!     [tool]
//!     body = "mass"
//!     point = [0.0, 0.0, 0.0]
//!     [workpiece]
//!     body = "ground"
//!     point = [0.0, 0.0, 0.0]
//!     [cutting]
//!     kt = "1000 MPa"
//!     kr = "1000 MPa"
//!     [turning]
//!     thickness = [0.0, 0.0, 1.0]
//!     cutting = [1.0, 0.0, 0.0]
//! "#, "cut.toml").unwrap();
//! let lobes = stability::lobes(&stability::Request::new(&model, &cut)).unwrap();
//! // One DOF, hysteretic: the lowest depth is k η / K_r (η = ψ/2π).
//! let expected = 1.0e7 * 0.2 / (2.0 * std::f64::consts::PI) / 1.0e9;
//! let min = lobes.points[lobes.minimum].depth;
//! assert!((min - expected).abs() < 0.02 * expected);
//! ```

// No panic on anything from a file, a device or a user (tests may: allow-expect-in-tests).
#![warn(clippy::expect_used)]
// The 2×2 matrix formulas (oriented FRF, directional matrices, eigenvalue derivatives) read as
// written on paper with explicit indices.
#![allow(clippy::needless_range_loop)]

pub mod bands;
pub mod covariance;
pub mod cut;
pub mod lobes;
pub mod oriented;
pub mod sd;
pub mod section;
pub mod tool;

use nalgebra::DMatrix;

use identify::variables::Variables;
use rfe::frf::{Method, SolveError};
use rfe::model::Model;

use crate::bands::Band;
use crate::cut::Cut;
use crate::lobes::{BoundaryPoint, Process};

/// Why lobes could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum StabilityError {
    /// The cutting file.
    #[error(transparent)]
    Cut(#[from] cut::CutError),
    /// The tool or workpiece point does not fit the model.
    #[error("{file}: {field}: {message}")]
    Placement {
        /// Cutting file.
        file: String,
        /// Field (`tool.point`).
        field: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// The model's frequency response.
    #[error("the oriented FRF: {0}")]
    Solve(#[from] SolveError),
    /// No lobe reaches the speed range.
    #[error("{file}: speed_rpm: no stability lobe reaches {lo}–{hi} rpm: {why}")]
    NoLobe {
        /// Cutting file.
        file: String,
        /// Lowest speed (rpm).
        lo: f64,
        /// Highest speed (rpm).
        hi: f64,
        /// Why, and what to change.
        why: String,
    },
    /// The covariance does not match the variables.
    #[error("the covariance is {rows}×{cols} but there are {vars} variables; give the covariance of exactly the variables file's variables")]
    CovarianceShape {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// Variables.
        vars: usize,
    },
}

/// The uncertainty of the model: the variables (their `initial` values are the estimates, as in
/// the final variables file) and their covariance (SI).
#[derive(Debug, Clone, Copy)]
pub struct Uncertainty<'a> {
    /// The identification variables against the model.
    pub variables: &'a Variables,
    /// Their covariance (SI units of the variables).
    pub covariance: &'a DMatrix<f64>,
}

/// One lobe computation.
#[derive(Debug, Clone, Copy)]
pub struct Request<'a> {
    /// The model (the final model of an identification).
    pub model: &'a Model,
    /// The cut.
    pub cut: &'a Cut,
    /// For the linear band.
    pub uncertainty: Option<Uncertainty<'a>>,
    /// FRF path.
    pub method: Method,
}

impl<'a> Request<'a> {
    /// Lobes of `model` for `cut`, no band, the cheaper FRF path.
    pub fn new(model: &'a Model, cut: &'a Cut) -> Request<'a> {
        Request {
            model,
            cut,
            uncertainty: None,
            method: Method::Auto,
        }
    }
}

/// A mode that sets the limit: its share of `Re G` at the chatter frequency (the part of the
/// oriented FRF that makes the cut unstable), and where its energy is.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitingMode {
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Loss factor.
    pub loss_factor: f64,
    /// Share of `Re G` at the chatter frequency (the shares of all modes and the tool sum to 1).
    pub share: f64,
    /// Bodies by kinetic-energy share, largest first (≥ 5 %).
    pub bodies: Vec<(String, f64)>,
    /// SDEs (joints) by strain-energy share, largest first (≥ 5 %).
    pub joints: Vec<(String, f64)>,
}

/// The result.
#[derive(Debug, Clone)]
pub struct Lobes {
    /// The boundary at the cut's speed grid.
    pub points: Vec<BoundaryPoint>,
    /// Index of the lowest critical depth.
    pub minimum: usize,
    /// The modes that set the limit at the minimum, by share, largest first (shares ≥ 5 %).
    pub limiting: Vec<LimitingMode>,
    /// The tool's own modes' share at the minimum (0 without tool modes).
    pub tool_share: f64,
    /// Per speed: the natural frequency (Hz) of the mode with the largest share.
    pub dominant_hz: Vec<f64>,
    /// The linear 5–95 % band, when the request has an uncertainty.
    pub band: Option<Band>,
    /// The frequency lines of the oriented FRF (Hz).
    pub freqs_hz: Vec<f64>,
}

/// Share of modes or bodies worth naming.
const NAMED_SHARE: f64 = 0.05;

/// The frequency grid: `cut.lines` log-spaced lines over the cut's `band_hz`, or by default over
/// the modes that can chatter, from 0.7 × the lowest natural frequency to 1.3 × the highest.
pub fn frequency_grid(split: &oriented::ModalSplit, cut: &Cut) -> Vec<f64> {
    let (lo, hi) = cut.band_hz.unwrap_or_else(|| {
        let (lo, hi) = split
            .freq_hz
            .iter()
            .copied()
            .chain(cut.tool_modes.iter().map(|m| m.freq_hz))
            .filter(|&f| f > 0.0)
            .fold((f64::INFINITY, 0.0f64), |(a, b), f| (a.min(f), b.max(f)));
        (0.7 * lo, 1.3 * hi)
    });
    let n = cut.lines;
    (0..n)
        .map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64))
        .collect()
}

/// Stability lobes of a model for a cut: the boundary, the limiting modes, the band.
pub fn lobes(req: &Request) -> Result<Lobes, StabilityError> {
    let cut = req.cut;
    let placement = oriented::place(req.model, cut)?;
    let split = oriented::modal_split(&placement)?;
    let freqs = frequency_grid(&split, cut);
    let top = freqs.last().copied().unwrap_or(0.0);
    if let Some(t) = cut.tool_frfs.iter().find(|t| t.highest_hz() < top) {
        return Err(StabilityError::Placement {
            file: cut.origin.clone(),
            field: "tool.frf".into(),
            message: format!(
                "the tool FRF {} ends at {:.1} Hz but the lobes need the tool up to {top:.1} Hz; measure the tool over the machine's band, or set band_hz = [lo, hi] with hi ≤ {:.1}",
                t.origin,
                t.highest_hz(),
                t.highest_hz()
            ),
        });
    }
    if let Some(u) = req.uncertainty {
        let n = u.variables.len();
        if u.covariance.nrows() != n || u.covariance.ncols() != n {
            return Err(StabilityError::CovarianceShape {
                rows: u.covariance.nrows(),
                cols: u.covariance.ncols(),
                vars: n,
            });
        }
    }
    let frf = oriented::oriented_frf(
        &placement,
        cut,
        &freqs,
        req.uncertainty.map(|u| u.variables),
        req.method,
    )?;
    let process = Process::of(cut);
    let periods = cut.periods_per_rev();
    let br = lobes::branches(&process, &frf);
    let points = lobes::boundary(&br, periods, &cut.speed_grid());
    let minimum = points
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.depth.total_cmp(&b.1.depth))
        .map(|(i, _)| i)
        .unwrap_or(0);
    if !points[minimum].depth.is_finite() {
        let (lo, hi) = cut.speed_rpm;
        let stable = br.g.iter().all(|g| g.iter().all(|g| g.re >= 0.0));
        return Err(StabilityError::NoLobe {
            file: cut.origin.clone(),
            lo,
            hi,
            why: if stable {
                "the oriented FRF has no negative real part on the frequency grid (the cutting directions do not couple with the model's flexibility); check the tool and workpiece bodies and the directions".into()
            } else {
                format!(
                    "every lobe lies outside it (oriented FRF on {} lines, {:.1}–{:.1} Hz); widen speed_rpm, or band_hz to take in the modes",
                    freqs.len(),
                    freqs.first().copied().unwrap_or(0.0),
                    freqs.last().copied().unwrap_or(0.0)
                )
            },
        });
    }
    // Each mode's share of Re G at the chatter frequency: Φ there is the sum of the modes'
    // contributions and the tool's, and ∂G[Φ_m] sums to G (G is homogeneous of degree 1 in Φ).
    let shares = |p: &BoundaryPoint| -> (Vec<f64>, f64) {
        let f = p.chatter_hz;
        let sign = br.sign[p.branch][p.line];
        let parts: Vec<oriented::Mat2> = (0..split.lambda.len())
            .map(|m| split.contribution(m, f))
            .collect();
        let tool = oriented::tool_receptance(cut, &placement.directions, f);
        let mut phi = tool;
        for c in &parts {
            for i in 0..2 {
                for j in 0..2 {
                    phi[i][j] += c[i][j];
                }
            }
        }
        let g = process.g(&phi, sign);
        let mode: Vec<f64> = parts
            .iter()
            .map(|c| process.dg(&phi, c, sign).re / g.re)
            .collect();
        (mode, process.dg(&phi, &tool, sign).re / g.re)
    };
    let dominant_hz = points
        .iter()
        .map(|p| {
            if !p.depth.is_finite() {
                return f64::NAN;
            }
            let (s, _) = shares(p);
            s.iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map_or(f64::NAN, |(m, _)| split.freq_hz[m])
        })
        .collect();
    let (mode_shares, tool_share) = shares(&points[minimum]);
    let mut limiting: Vec<LimitingMode> = mode_shares
        .iter()
        .enumerate()
        .filter(|(_, &s)| s >= NAMED_SHARE)
        .map(|(m, &share)| LimitingMode {
            freq_hz: split.freq_hz[m],
            loss_factor: split.loss_factor[m],
            share,
            bodies: named(
                split.body_energy[m]
                    .iter()
                    .enumerate()
                    .map(|(b, &e)| (req.model.bodies[b].name.clone(), e)),
            ),
            joints: named(
                split.sde_energy[m]
                    .iter()
                    .map(|&(s, e)| (req.model.sdes[s].name.clone(), e)),
            ),
        })
        .collect();
    limiting.sort_by(|a, b| b.share.total_cmp(&a.share));
    let band = req
        .uncertainty
        .map(|u| bands::linear(&process, &frf, &br, periods, &points, u.covariance));
    Ok(Lobes {
        points,
        minimum,
        limiting,
        tool_share,
        dominant_hz,
        band,
        freqs_hz: freqs,
    })
}

/// Names with shares ≥ [`NAMED_SHARE`], largest first.
fn named(items: impl Iterator<Item = (String, f64)>) -> Vec<(String, f64)> {
    let mut v: Vec<(String, f64)> = items.filter(|(_, e)| *e >= NAMED_SHARE).collect();
    v.sort_by(|a, b| b.1.total_cmp(&a.1));
    v
}
