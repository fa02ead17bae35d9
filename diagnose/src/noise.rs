//! The noise level the data imply by themselves, independent of any model's fit: the level a
//! misfit is judged "large" against when the noise is known only up to scale.
//!
//! With a relative-error noise model (`σ = ε|z|`, the default for vendor data without variances
//! or coherence) the covariance is `R = s²·diag(σ²)` with `s²` unknown, and the fit's own
//! estimate `σ̂² = 2J/(m − p)` makes every misfit's reduced χ² equal to 1: a model far from the
//! data and one at its noise level look alike. This module estimates `s²` from the measured
//! curves alone.
//!
//! **Estimator.** Per characteristic and per residual component (the log-amplitude, the
//! amplitude, or the real and imaginary parts, as the criterion fits them), the measured values
//! `y_i` at frequencies `f_i` (ascending) give the Gasser-Sroka-Jennen pseudo-residuals
//!
//! `ε_i = (a_i y_{i−1} + b_i y_{i+1} − y_i) / √(a_i² σ²_{i−1} + b_i² σ²_{i+1} + σ²_i)`,
//! `a_i = (f_{i+1} − f_i)/(f_{i+1} − f_{i−1})`, `b_i = 1 − a_i`,
//!
//! the deviation of each point from the straight line through its two neighbours, whitened by
//! the criterion's `σ`: for noise of covariance `s²·diag(σ²)` and a curve locally linear over
//! three lines, `E ε_i = 0` and `Var ε_i = s²` exactly (the divisor is the difference's own
//! standard deviation, so no degrees-of-freedom correction is left to make). The scale is the
//! median absolute pseudo-residual times 1.4826 (`1/Φ⁻¹(3/4)`, which makes the MAD consistent
//! for Gaussian noise), squared: `s²_c` for characteristic `c`. The level returned is their mean
//! over the observations, `Σ n_c s²_c / m`, so that a fit at the noise level has
//! `E|e|² = m · level`, comparable with the whitened residuals `e` the criterion gives.
//!
//! **Bias.** A curve that is not linear over three lines adds its second difference to `ε_i`:
//! negligible on a smooth stretch of an FRF, large at a resonance or antiresonance narrower than
//! a few lines (a lightly damped structure's peak spans 1-3 lines of a hammer test). Those lines
//! are a small share of a band, and the median ignores them as long as they stay under half of a
//! characteristic's lines; the level is then the noise of the smooth stretches. Noise correlated
//! between adjacent lines (overlapping windows, leakage) makes neighbours alike and the level
//! low; a low level only makes a misfit count as large sooner (the diagnosis explores more, it
//! does not miss an effect). Data with no scatter at all (noiseless simulated curves) have no
//! level: the gates then use the fit's σ̂².

use identify::{Criterion, FitKind};

use crate::tuning::{NOISE_MIN_PSEUDO_RESIDUALS, REAL_FLOOR_OVER_NOISE};

/// `1/Φ⁻¹(3/4)`: the MAD of a Gaussian sample times this estimates its standard deviation.
const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// The level the diagnosis's gates judge a misfit "large" and "above the noise" against: with
/// R known (`data_noise` `None`), the fit's `sigma2` (1); with R known only up to scale, the
/// data's own noise level `data_noise` times [`REAL_FLOOR_OVER_NOISE`]² — the misfit a model of
/// the right form leaves on real data, where effects no library holds keep it far above the
/// measurement noise; only a misfit well above that floor counts as large.
pub(crate) fn gate_level(data_noise: Option<f64>, sigma2: f64) -> f64 {
    data_noise.map_or(sigma2, |s2| REAL_FLOOR_OVER_NOISE.powi(2) * s2)
}

/// The data-implied noise level (the unknown scale `s²` of `R = s²·diag(σ²)`, in the units of
/// the whitened residuals) of the criterion's observations when its noise is known only up to
/// scale; `None` when the scale is known (the level is 1 by construction) or the data give no
/// level (too few lines on every characteristic, or no scatter).
pub(crate) fn data_level(crit: &Criterion) -> Option<f64> {
    if !crit.noise.scale_unknown() {
        return None;
    }
    let lines = crit.lines();
    let z = crit.measured();
    let points = crit.points();
    let (mut weighted, mut counted) = (0.0, 0usize);
    for (_, range) in &crit.groups {
        let f: Vec<f64> = points[range.clone()]
            .iter()
            .map(|&(_, line, _)| lines[line])
            .collect();
        let sigma: Vec<f64> = points[range.clone()].iter().map(|p| p.2).collect();
        let z = &z[range.clone()];
        let components: Vec<Vec<f64>> = match crit.fit() {
            FitKind::LogAmplitude => vec![z.iter().map(|z| z.re.ln()).collect()],
            FitKind::Amplitude => vec![z.iter().map(|z| z.re).collect()],
            FitKind::Complex => vec![
                z.iter().map(|z| z.re).collect(),
                z.iter().map(|z| z.im).collect(),
            ],
        };
        let mut eps = Vec::new();
        for y in &components {
            eps.extend(pseudo_residuals(&f, y, &sigma));
        }
        if let Some(s2) = robust_variance(&mut eps) {
            weighted += s2 * (range.len() * components.len()) as f64;
            counted += range.len() * components.len();
        }
    }
    let level = weighted / counted as f64;
    (counted > 0 && level.is_finite() && level > 0.0).then_some(level)
}

/// The whitened Gasser-Sroka-Jennen pseudo-residuals of values `y` with standard deviations
/// `sigma` at ascending abscissae `f`: one per interior point (see the module doc).
fn pseudo_residuals(f: &[f64], y: &[f64], sigma: &[f64]) -> Vec<f64> {
    (1..y.len().saturating_sub(1))
        .filter_map(|i| {
            let span = f[i + 1] - f[i - 1];
            if !(span > 0.0) {
                return None;
            }
            let a = (f[i + 1] - f[i]) / span;
            let b = 1.0 - a;
            let d = a * y[i - 1] + b * y[i + 1] - y[i];
            let s =
                (a * a * sigma[i - 1].powi(2) + b * b * sigma[i + 1].powi(2) + sigma[i].powi(2))
                    .sqrt();
            let e = d / s;
            e.is_finite().then_some(e)
        })
        .collect()
}

/// `(1.4826 · median |ε|)²`: the variance of zero-mean pseudo-residuals `eps`, robust to the
/// few large ones a sharp resonance makes; `None` for fewer than
/// [`NOISE_MIN_PSEUDO_RESIDUALS`].
fn robust_variance(eps: &mut [f64]) -> Option<f64> {
    if eps.len() < NOISE_MIN_PSEUDO_RESIDUALS {
        return None;
    }
    for e in eps.iter_mut() {
        *e = e.abs();
    }
    eps.sort_by(f64::total_cmp);
    let n = eps.len();
    let median = if n % 2 == 1 {
        eps[n / 2]
    } else {
        0.5 * (eps[n / 2 - 1] + eps[n / 2])
    };
    Some((MAD_TO_SIGMA * median).powi(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic standard-normal sample (Box-Muller on a fixed LCG).
    fn normals(n: usize, mut state: u64) -> Vec<f64> {
        let mut uniform = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| {
                let (u, v) = (uniform(), uniform());
                (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
            })
            .collect()
    }

    #[test]
    fn the_level_of_noise_on_a_smooth_curve_is_its_variance() {
        // A smooth curve (a slow sine on unequal steps) plus noise of s = 0.3 in units of σ.
        let n = 4000;
        let f: Vec<f64> = (0..n).map(|i| i as f64 + 0.3 * (i as f64).sin()).collect();
        let sigma: Vec<f64> = (0..n).map(|i| 0.01 * (1.0 + (i % 3) as f64)).collect();
        let noise = normals(n, 7);
        let y: Vec<f64> = (0..n)
            .map(|i| (f[i] / 400.0).sin() + 0.3 * sigma[i] * noise[i])
            .collect();
        let mut eps = pseudo_residuals(&f, &y, &sigma);
        let s2 = robust_variance(&mut eps).unwrap();
        assert!((s2.sqrt() / 0.3 - 1.0).abs() < 0.05, "s = {}", s2.sqrt());
    }

    #[test]
    fn sharp_peaks_on_a_few_lines_do_not_raise_the_level() {
        // The same noise with 5 % of the lines on narrow peaks 100 σ high: the median ignores them.
        let n = 2000;
        let f: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let sigma = vec![1.0; n];
        let noise = normals(n, 11);
        let y: Vec<f64> = (0..n)
            .map(|i| noise[i] + if i % 60 == 0 { 100.0 } else { 0.0 })
            .collect();
        let mut eps = pseudo_residuals(&f, &y, &sigma);
        let s2 = robust_variance(&mut eps).unwrap();
        assert!((s2.sqrt() - 1.0).abs() < 0.1, "s = {}", s2.sqrt());
        // Their mean square would not: the peaks dominate it.
        let ms = pseudo_residuals(&f, &y, &sigma)
            .iter()
            .map(|e| e * e)
            .sum::<f64>()
            / (n - 2) as f64;
        assert!(ms > 50.0, "{ms}");
    }

    /// The criterion of FWD-32J's log-amplitude data with multiplicative noise `rel`
    /// (`|z| = |q|(1 + rel·n)`) at 400 lines over 20-400 Hz, under the noise model `noise`.
    fn fwd32j_criterion(rel: f64, noise: identify::NoiseChoice) -> Criterion {
        let model = crate::test_support::fwd32j();
        let lines = identify::synthetic::log_lines(20.0, 400.0, 400);
        let mut n = normals(lines.len() * model.outputs.len(), 5).into_iter();
        let mut d =
            identify::synthetic::amplitude_data(&model, &lines, rel, || n.next().unwrap_or(0.0))
                .unwrap();
        if !matches!(noise, identify::NoiseChoice::Variance) {
            for c in &mut d.characteristics {
                c.variance = None;
            }
        }
        let obs = identify::data::validate(&d, &model, "synthetic").unwrap();
        let vars = identify::Variables {
            origin: "none".into(),
            vars: Vec::new(),
            extra_starts: Vec::new(),
        };
        Criterion::new(
            &model,
            &obs,
            &vars,
            FitKind::LogAmplitude,
            noise,
            rfe::frf::Method::Auto,
        )
        .unwrap()
    }

    #[test]
    fn a_machine_s_curves_give_their_noise_in_the_criterion_s_units() {
        // 2 % noise on the amplitudes, R assumed at 1 %: the unknown scale is 2² = 4, though the
        // curves hold FWD-32J's resonances.
        let crit = fwd32j_criterion(0.02, identify::NoiseChoice::Relative(0.01));
        let level = data_level(&crit).unwrap();
        eprintln!("FWD-32J, 2 % noise at R's 1 %: level {level:.3} (4 expected)");
        assert!((level / 4.0 - 1.0).abs() < 0.15, "{level}");
        // With R known there is no level to estimate: the gates keep σ̂² = 1.
        let known = fwd32j_criterion(0.02, identify::NoiseChoice::Variance);
        assert_eq!(data_level(&known), None);
        assert_eq!(gate_level(None, 1.0), 1.0);
        assert_eq!(
            gate_level(Some(level), 1.0),
            REAL_FLOOR_OVER_NOISE.powi(2) * level
        );
    }

    #[test]
    fn too_few_lines_give_no_level() {
        let mut eps = vec![1.0; NOISE_MIN_PSEUDO_RESIDUALS - 1];
        assert!(robust_variance(&mut eps).is_none());
    }
}
