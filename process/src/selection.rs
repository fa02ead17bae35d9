//! Selection of identification points from a measured characteristic (as the paper did by hand:
//! about 38 per characteristic) and assembly of [`rfe::Measurement`]s.
//!
//! Points are spread with a density that is uniform in log-frequency plus a bump of extra density
//! around each resonance peak; lines whose coherence is below a threshold are never chosen.

use num_complex::Complex;
use rfe::{measured::QuantityName, Measurement, Quantity};

use crate::error::{check_count, invalid, ProcessError, Result};

type C64 = Complex<f64>;

/// Settings of the point selection.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectionConfig {
    /// Points wanted (the paper used 38).
    pub count: usize,
    /// Band (Hz), inclusive; lines at 0 Hz are never chosen.
    pub band_hz: (f64, f64),
    /// Lines with coherence below this (0..1) are skipped.
    pub min_coherence: f64,
    /// Extra density at a resonance relative to the log-uniform base (0: plain log spread).
    pub resonance_weight: f64,
    /// Relative half-width of the extra density around a resonance (0.1 = ±10 % in frequency);
    /// also the neighbourhood in which a peak must be the maximum.
    pub resonance_width: f64,
}

impl Default for SelectionConfig {
    fn default() -> Self {
        SelectionConfig {
            count: 38,
            band_hz: (0.0, f64::INFINITY),
            min_coherence: 0.8,
            resonance_weight: 4.0,
            resonance_width: 0.1,
        }
    }
}

/// Indices (into `freqs_hz`, increasing) of the selected points of one characteristic.
///
/// `magnitude` is |H| per line; `coherence`, when given, the coherence per line; `name` labels
/// errors.
pub fn select_points(
    name: &str,
    freqs_hz: &[f64],
    magnitude: &[f64],
    coherence: Option<&[f64]>,
    config: &SelectionConfig,
) -> Result<Vec<usize>> {
    check_selection(freqs_hz, magnitude, coherence, config)?;
    let (lo, hi) = config.band_hz;
    let cand: Vec<usize> = (0..freqs_hz.len())
        .filter(|&k| {
            let f = freqs_hz[k];
            f > 0.0
                && f >= lo
                && f <= hi
                && magnitude[k].is_finite()
                && coherence.is_none_or(|c| c[k] >= config.min_coherence)
        })
        .collect();
    if cand.len() < config.count {
        return Err(ProcessError::NotEnoughPoints {
            name: name.into(),
            usable: cand.len(),
            wanted: config.count,
            min_coherence: config.min_coherence,
        });
    }
    let lf: Vec<f64> = cand.iter().map(|&k| freqs_hz[k].ln()).collect();
    let w = (1.0 + config.resonance_width).ln();
    let peaks = resonance_peaks(&cand, &lf, magnitude, w);
    let cum = cumulative_weights(&lf, &peaks, w, config.resonance_weight);
    let mut out = quantile_picks(&cand, &cum, config.count);
    out.sort_unstable();
    Ok(out)
}

/// One magnitude (and coherence) per frequency, at least one point, a valid resonance width
/// and weight.
fn check_selection(
    freqs_hz: &[f64],
    magnitude: &[f64],
    coherence: Option<&[f64]>,
    config: &SelectionConfig,
) -> Result<()> {
    check_count(
        "magnitudes (one per frequency)",
        freqs_hz.len(),
        magnitude.len(),
    )?;
    if let Some(c) = coherence {
        check_count("coherences (one per frequency)", freqs_hz.len(), c.len())?;
    }
    if config.count == 0 {
        return Err(invalid("count", 0, "select at least one point"));
    }
    if config.resonance_width.is_nan()
        || config.resonance_width <= 0.0
        || config.resonance_weight.is_nan()
        || config.resonance_weight < 0.0
    {
        return Err(invalid(
            "resonance_width/weight",
            format!("{}/{}", config.resonance_width, config.resonance_weight),
            "width > 0 and weight ≥ 0",
        ));
    }
    Ok(())
}

/// Log-frequencies of the resonance peaks among the candidates: a candidate that is the largest
/// within ±`w` (log-frequency) and clearly above the smallest there (a half-power drop).
fn resonance_peaks(cand: &[usize], lf: &[f64], magnitude: &[f64], w: f64) -> Vec<f64> {
    let mut peaks = Vec::new();
    for (a, &k) in cand.iter().enumerate() {
        let (mut mx, mut mn) = (0.0f64, f64::INFINITY);
        for (b, &l) in cand.iter().enumerate() {
            if (lf[b] - lf[a]).abs() <= w {
                mx = mx.max(magnitude[l]);
                mn = mn.min(magnitude[l]);
            }
        }
        if magnitude[k] >= mx && magnitude[k] > std::f64::consts::SQRT_2 * mn {
            peaks.push(lf[a]);
        }
    }
    peaks
}

/// Cumulative weights of the candidates: each one's share of log-frequency, raised near the
/// resonance peaks.
fn cumulative_weights(lf: &[f64], peaks: &[f64], w: f64, resonance_weight: f64) -> Vec<f64> {
    let n = lf.len();
    let mut cum = Vec::with_capacity(n);
    let mut total = 0.0;
    for a in 0..n {
        let left = if a > 0 {
            (lf[a] - lf[a - 1]) / 2.0
        } else {
            0.0
        };
        let right = if a + 1 < n {
            (lf[a + 1] - lf[a]) / 2.0
        } else {
            0.0
        };
        let span = if n == 1 { 1.0 } else { left + right };
        let bump: f64 = peaks
            .iter()
            .map(|p| (-0.5 * ((lf[a] - p) / (w / 2.0)).powi(2)).exp())
            .sum();
        total += span * (1.0 + resonance_weight * bump);
        cum.push(total);
    }
    cum
}

/// `count` candidates at evenly spaced quantiles of the cumulative weight, the nearest free
/// one where a quantile's is taken.
fn quantile_picks(cand: &[usize], cum: &[f64], count: usize) -> Vec<usize> {
    let n = cand.len();
    let total = cum.last().copied().unwrap_or(0.0);
    let mut taken = vec![false; n];
    let mut out = Vec::with_capacity(count);
    for q in 0..count {
        let target = (q as f64 + 0.5) / count as f64 * total;
        let a = cum.partition_point(|c| *c < target).min(n - 1);
        // Nearest free candidate.
        let mut pick = None;
        for d in 0..n {
            if a + d < n && !taken[a + d] {
                pick = Some(a + d);
                break;
            }
            if d <= a && !taken[a - d] {
                pick = Some(a - d);
                break;
            }
        }
        if let Some(p) = pick {
            taken[p] = true;
            out.push(cand[p]);
        }
    }
    out
}

/// What one characteristic is, for [`to_measurement`].
#[derive(Debug, Clone, PartialEq)]
pub struct CharacteristicSpec {
    /// Body name in the model.
    pub body: String,
    /// DOF 0-5 (u1..u3, r1..r3 in principal axes).
    pub dof: u8,
    /// Quantity of `h` (and of the measurement).
    pub quantity: Quantity,
    /// Amplitude of the model's declared excitation (N, or N·m): the per-unit FRF is scaled by it.
    pub nominal_force: f64,
}

/// Builds a [`Measurement`] from per-unit-force FRF values `h` at the `points` (indices into
/// `freqs_hz`), scaled by the nominal force. `coherence` and `variance` (of the per-unit FRF,
/// E|Ĥ−H|²) are per line and optional.
pub fn to_measurement(
    spec: &CharacteristicSpec,
    freqs_hz: &[f64],
    h: &[C64],
    coherence: Option<&[f64]>,
    variance: Option<&[f64]>,
    averages: Option<u32>,
    points: &[usize],
) -> Result<Measurement> {
    if spec.dof > 5 {
        return Err(invalid("dof", spec.dof, "0-2 translations, 3-5 rotations"));
    }
    if !(spec.nominal_force.is_finite() && spec.nominal_force > 0.0) {
        return Err(invalid(
            "nominal_force",
            spec.nominal_force,
            "the model's excitation amplitude, > 0 (N)",
        ));
    }
    check_count("FRF values (one per frequency)", freqs_hz.len(), h.len())?;
    for opt in [coherence, variance].into_iter().flatten() {
        check_count(
            "coherence/variance values (one per frequency)",
            freqs_hz.len(),
            opt.len(),
        )?;
    }
    let mut last = f64::NEG_INFINITY;
    for &k in points {
        if k >= freqs_hz.len() || freqs_hz[k] <= last {
            return Err(invalid(
                "points",
                k,
                "indices must be in range and at strictly increasing frequencies",
            ));
        }
        last = freqs_hz[k];
    }
    let s = spec.nominal_force;
    let z: Vec<C64> = points.iter().map(|&k| h[k] * s).collect();
    Ok(Measurement {
        body: spec.body.clone(),
        dof: spec.dof,
        quantity: QuantityName::from(spec.quantity),
        freqs_hz: points.iter().map(|&k| freqs_hz[k]).collect(),
        amplitude: z.iter().map(|v| v.norm()).collect(),
        phase_rad: Some(z.iter().map(|v| v.arg()).collect()),
        variance: variance.map(|v| points.iter().map(|&k| v[k] * s * s).collect()),
        coherence: coherence.map(|c| points.iter().map(|&k| c[k]).collect()),
        averages,
        at: None,
        reference: None,
        relative: false,
    })
}
