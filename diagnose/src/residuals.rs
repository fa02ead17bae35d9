//! Residual analysis after a fit: standardized residuals per characteristic and frequency, the χ²
//! goodness-of-fit test of the criterion against its expectation under R, a runs test for
//! structure along frequency, and where the misfit concentrates (near which modes).

use identify::stats::{chi2_tail, runs_test};
use nalgebra::DVector;
use serde::Serialize;

use identify::{Criterion, FitKind};
use rfe::model::Model;
use rfe::modes;
use rfe::C64;

/// One characteristic's residuals.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CharacteristicResiduals {
    /// `"table u1 displacement"`.
    pub label: String,
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Standardized amplitude residuals `(|z| − |q|)/σ`.
    pub amplitude: Vec<f64>,
    /// Standardized phase residuals `|q|·Δφ/σ` (complex fits only).
    pub phase: Option<Vec<f64>>,
    /// Σ of squared standardized residuals.
    pub chi2: f64,
    /// RMS relative amplitude error `sqrt(mean(((|q| − |z|)/|z|)²))`.
    pub rms_relative: f64,
    /// RMS amplitude error in dB, `sqrt(mean((20 log10(|q|/|z|))²))`: unlike the relative error
    /// not dominated by the anti-resonance lines.
    pub rms_db: f64,
    /// Number of runs of equal sign of the amplitude residuals along frequency.
    pub runs: usize,
    /// Their expectation for independent residuals.
    pub runs_expected: f64,
    /// One-sided p-value of too few runs (structure along frequency).
    pub runs_p: f64,
}

/// Share of the misfit near one mode of the model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Band {
    /// The mode's natural frequency (Hz).
    pub mode_hz: f64,
    /// The body carrying most of the mode's kinetic energy, and its share.
    pub body: String,
    /// Energy share of that body.
    pub body_share: f64,
    /// Frequency range of the points nearest this mode (Hz).
    pub from_hz: f64,
    /// Upper end.
    pub to_hz: f64,
    /// Share of Σe² in this band.
    pub share: f64,
    /// Share of the points in this band (the share of Σe² to expect at the noise level).
    pub points_share: f64,
}

/// The residual analysis of one fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResidualAnalysis {
    /// Criterion J = ½ Σ e².
    pub criterion: f64,
    /// Scalar observations.
    pub observations: usize,
    /// Free parameters of the fit.
    pub parameters: usize,
    /// `2J` against χ² with `observations − parameters` degrees of freedom: the p-value, when R is
    /// known (variances or coherence); `None` when R is known only up to scale.
    pub chi2_p: Option<f64>,
    /// `2J / (observations − parameters)`: ≈ 1 at the noise level.
    pub reduced_chi2: f64,
    /// RMS amplitude error in dB over every fitted point.
    pub rms_db: f64,
    /// Per characteristic.
    pub characteristics: Vec<CharacteristicResiduals>,
    /// Misfit by mode band, largest excess first.
    pub bands: Vec<Band>,
    /// True when the model explains the data to the noise level.
    pub explained: bool,
    /// The verdict in words.
    pub verdict: String,
}

/// Analyses the whitened residuals `e` of `crit` for `model` (the fitted model, for its modes),
/// with `parameters` free parameters and `gains` (1 + g per characteristic) applied to the model.
pub fn analyze(
    crit: &Criterion,
    e: &DVector<f64>,
    parameters: usize,
    model: &Model,
    alpha: f64,
) -> ResidualAnalysis {
    let characteristics: Vec<CharacteristicResiduals> = crit
        .groups
        .iter()
        .map(|(label, range)| characteristic_residuals(crit, e, label, range.clone()))
        .collect();
    let m = e.len();
    let dof = m.saturating_sub(parameters).max(1);
    let two_j = e.norm_squared();
    let reduced_chi2 = two_j / dof as f64;
    let chi2_p = (!crit.noise.scale_unknown()).then(|| chi2_tail(dof as f64, two_j));
    let bands = mode_bands(model, &characteristics, crit);
    let structured: Vec<&CharacteristicResiduals> = characteristics
        .iter()
        .filter(|c| c.runs_p < alpha / characteristics.len().max(1) as f64)
        .collect();
    let chi2_bad = chi2_p.is_some_and(|p| p < alpha);
    let explained = !chi2_bad && structured.is_empty();
    let verdict = verdict(
        (two_j, dof, reduced_chi2, chi2_p),
        alpha,
        &structured,
        &bands,
    );
    ResidualAnalysis {
        criterion: 0.5 * two_j,
        observations: m,
        parameters,
        chi2_p,
        reduced_chi2,
        rms_db: rms_db(crit, e),
        characteristics,
        bands,
        explained,
        verdict,
    }
}

/// One characteristic's whitened residuals along frequency (rotated into amplitude and phase
/// for a complex fit), χ², RMS relative amplitude error and runs test.
fn characteristic_residuals(
    crit: &Criterion,
    e: &DVector<f64>,
    label: &str,
    range: std::ops::Range<usize>,
) -> CharacteristicResiduals {
    let points = crit.points();
    let measured = crit.measured();
    let freqs = crit.lines();
    let np = points.len();
    let complex = crit.fit() == FitKind::Complex;
    let mut c = CharacteristicResiduals {
        label: label.to_string(),
        freqs_hz: Vec::new(),
        amplitude: Vec::new(),
        phase: complex.then(Vec::new),
        chi2: 0.0,
        rms_relative: 0.0,
        rms_db: 0.0,
        runs: 0,
        runs_expected: 0.0,
        runs_p: 1.0,
    };
    let (mut rel, mut db, mut n_db) = (0.0, 0.0, 0usize);
    for i in range {
        let (_, line, _) = points[i];
        let z = measured[i];
        c.freqs_hz.push(freqs[line]);
        let q = modelled(crit.fit(), &points, &measured, e, i);
        let amp = if complex {
            let d = C64::new(e[i], e[np + i]);
            let unit = if z.norm() > 0.0 {
                z.conj() / z.norm()
            } else {
                C64::new(1.0, 0.0)
            };
            let rot = unit * d;
            if let Some(p) = c.phase.as_mut() {
                p.push(rot.im);
            }
            c.chi2 += d.norm_sqr();
            rot.re
        } else {
            c.chi2 += e[i] * e[i];
            e[i]
        };
        c.amplitude.push(amp);
        if z.norm() > 0.0 {
            rel += ((q.norm() - z.norm()) / z.norm()).powi(2);
            if q.norm() > 0.0 {
                db += (20.0 * (q.norm() / z.norm()).log10()).powi(2);
                n_db += 1;
            }
        }
    }
    let n = c.amplitude.len().max(1);
    c.rms_relative = (rel / n as f64).sqrt();
    c.rms_db = (db / n_db.max(1) as f64).sqrt();
    (c.runs, c.runs_expected, c.runs_p) = runs_test(&c.amplitude);
    c
}

/// The model's value at point `i` (of `points`, measured values `measured`) that the whitened
/// residuals `e` of a fit of kind `fit` imply (`z − σe`; for
/// the log-amplitude fit `|z| e^{−σe}`; amplitude fits give the amplitude).
fn modelled(
    fit: FitKind,
    points: &[(usize, usize, f64)],
    measured: &[C64],
    e: &DVector<f64>,
    i: usize,
) -> C64 {
    let (_, _, sigma) = points[i];
    let z = measured[i];
    match fit {
        FitKind::Complex => z - C64::new(e[i], e[points.len() + i]) * sigma,
        FitKind::LogAmplitude => C64::new(z.re * (-sigma * e[i]).exp(), 0.0),
        FitKind::Amplitude => C64::new(z.re - sigma * e[i], 0.0),
    }
}

/// The RMS amplitude error in dB, `sqrt(mean((20 log10(|q|/|z|))²))` over every point of `crit`
/// whose measured and modelled amplitudes are > 0, of the fit whose whitened residuals are `e`
/// (gains included: the residuals carry them).
pub fn rms_db(crit: &Criterion, e: &DVector<f64>) -> f64 {
    let (points, z) = (crit.points(), crit.measured());
    let (mut sum, mut n) = (0.0, 0usize);
    for (i, zi) in z.iter().enumerate() {
        let q = modelled(crit.fit(), &points, &z, e, i).norm();
        if zi.norm() > 0.0 && q > 0.0 {
            sum += (20.0 * (q / zi.norm()).log10()).powi(2);
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// The sentence that says whether the model explains the data, and if not why and where.
fn verdict(
    (two_j, dof, reduced_chi2, chi2_p): (f64, usize, f64, Option<f64>),
    alpha: f64,
    structured: &[&CharacteristicResiduals],
    bands: &[Band],
) -> String {
    let chi2_bad = chi2_p.is_some_and(|p| p < alpha);
    let explained = !chi2_bad && structured.is_empty();
    if explained {
        match chi2_p {
            Some(p) => format!(
                "the model explains the data to the noise level (2J = {two_j:.1} for {dof} degrees of freedom, χ² p = {}; no structure along frequency)", rfe::display::p_value(p)
            ),
            None => format!(
                "no structure along frequency (runs tests pass); R is known only up to scale, so the χ² level cannot be tested (reduced χ² {reduced_chi2:.2} sets the scale)"
            ),
        }
    } else {
        let mut why = Vec::new();
        if let Some(p) = chi2_p.filter(|p| *p < alpha) {
            why.push(format!(
                "2J = {two_j:.1} is {:.1}× its expectation {dof} (χ² p = {p:.1e})",
                two_j / dof as f64
            ));
        }
        for c in structured {
            why.push(format!(
                "{} has {} runs where {:.1} were expected (p = {:.1e})",
                c.label, c.runs, c.runs_expected, c.runs_p
            ));
        }
        let place = bands
            .first()
            .map(|b| format!("; the misfit concentrates near the {:.0} Hz mode ({} {:.0} %): {:.0} % of Σe² on {:.0} % of the points ({:.0}-{:.0} Hz)", b.mode_hz, b.body, 100.0 * b.body_share, 100.0 * b.share, 100.0 * b.points_share, b.from_hz, b.to_hz))
            .unwrap_or_default();
        format!(
            "the model does NOT explain the data: {}{place}",
            why.join("; ")
        )
    }
}

fn mode_bands(model: &Model, chars: &[CharacteristicResiduals], crit: &Criterion) -> Vec<Band> {
    let lines = crit.lines();
    let (Some(&lo), Some(&hi)) = (lines.first(), lines.last()) else {
        return Vec::new();
    };
    let Ok(modes) = modes::undamped(model) else {
        return Vec::new();
    };
    let modes: Vec<&modes::Mode> = modes
        .iter()
        .filter(|m| m.freq_hz > lo / 1.5 && m.freq_hz < hi * 1.5)
        .collect();
    if modes.is_empty() {
        return Vec::new();
    }
    let mut sum = vec![0.0; modes.len()];
    let mut count = vec![0usize; modes.len()];
    let mut range = vec![(f64::INFINITY, 0.0f64); modes.len()];
    let (mut total, mut points) = (0.0, 0usize);
    for c in chars {
        for (k, f) in c.freqs_hz.iter().enumerate() {
            let nearest = (0..modes.len())
                .min_by(|&a, &b| {
                    let d = |i: usize| (f.max(1e-9) / modes[i].freq_hz.max(1e-9)).ln().abs();
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(0);
            let e2 = c.amplitude[k].powi(2) + c.phase.as_ref().map_or(0.0, |p| p[k].powi(2));
            sum[nearest] += e2;
            count[nearest] += 1;
            range[nearest] = (range[nearest].0.min(*f), range[nearest].1.max(*f));
            total += e2;
            points += 1;
        }
    }
    let mut bands: Vec<Band> = (0..modes.len())
        .filter(|&i| count[i] > 0)
        .map(|i| {
            let (body, share) = modes[i]
                .energy
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|(b, s)| (model.bodies[b].name.clone(), *s))
                .unwrap_or_default();
            Band {
                mode_hz: modes[i].freq_hz,
                body,
                body_share: share,
                from_hz: range[i].0,
                to_hz: range[i].1,
                share: if total > 0.0 { sum[i] / total } else { 0.0 },
                points_share: count[i] as f64 / points.max(1) as f64,
            }
        })
        .collect();
    bands.sort_by(|a, b| (b.share - b.points_share).total_cmp(&(a.share - a.points_share)));
    bands
}
