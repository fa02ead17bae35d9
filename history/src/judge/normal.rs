//! What normal looks like for one parameter over the baseline window: a centre and a robust
//! run-to-run scatter, optionally as a straight line on a covariate (temperature).
//!
//! MAD screens outliers out of the baseline (beyond [`SCREEN_MADS`]); the scatter is the standard
//! deviation of the rest (MAD alone is too noisy on a few tens of runs: 37 % efficiency). Values
//! that are not finite never enter: a run whose value is NaN or infinite is left out of the
//! baseline of that parameter and counted in `Normal::left_out`.

use crate::record::RunRecord;

/// MAD × this = σ for normal data.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// Baseline residuals beyond this many MAD scatters are outliers, left out of the scatter.
pub const SCREEN_MADS: f64 = 5.0;

pub(crate) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median and robust σ (MAD × 1.4826) of `v`.
pub fn robust_scatter(v: &[f64]) -> (f64, f64) {
    let mut w = v.to_vec();
    let m = median(&mut w);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    (m, MAD_TO_SIGMA * median(&mut dev))
}

/// Normal for one parameter over the baseline.
pub(crate) struct Normal {
    pub unit: String,
    pub factor: f64,
    /// Centre at covariate `c`: a + b (c − c̄) (SI).
    pub a: f64,
    pub b: f64,
    pub c_mean: f64,
    pub scatter: f64,
    /// Σ (c − c̄)² over the baseline (0 without a covariate).
    pub scc: f64,
    /// Baseline runs that gave a finite value.
    pub n: usize,
    /// Baseline runs left out because their value was not finite.
    pub left_out: usize,
    /// Baseline run ids with their residual (SI), in baseline order, for the covariance.
    pub residuals: Vec<(String, f64)>,
    /// Residuals beyond [`SCREEN_MADS`] MAD scatters (outliers left out of the scatter).
    pub screened: usize,
}

impl Normal {
    /// The normal value at covariate `c` (SI).
    pub fn centre(&self, c: Option<f64>) -> f64 {
        self.a + self.b * c.map(|c| c - self.c_mean).unwrap_or(0.0)
    }

    /// Widening of the limits for the baseline's own error: √(1 + 1/n) for a centre,
    /// √(1 + 1/n + (c − c̄)² / Σ(c − c̄)²) for a regression line at covariate `c` (the prediction
    /// interval of a new observation).
    pub fn widen(&self, c: Option<f64>) -> f64 {
        let lever = match c {
            Some(c) if self.scc > 0.0 => (c - self.c_mean).powi(2) / self.scc,
            _ => 0.0,
        };
        (1.0 + 1.0 / self.n as f64 + lever).sqrt()
    }
}

/// Learns normal for `variable` over `base`; `None` when a baseline run lacks the parameter
/// (the caller says so).
pub(crate) fn learn(
    base: &[&RunRecord],
    variable: &str,
    covariate: Option<&str>,
) -> Option<Normal> {
    let first = base.iter().find_map(|r| r.parameter(variable))?;
    let mut ids = Vec::new();
    let mut xs = Vec::new();
    let mut cs = Vec::new();
    let mut left_out = 0;
    for r in base {
        let p = r.parameter(variable)?;
        if !p.estimate.is_finite() {
            left_out += 1;
            continue;
        }
        let c = covariate.and_then(|c| r.covariate(c));
        ids.push(r.run_id.clone());
        xs.push(p.estimate);
        cs.push(c);
    }
    let cs: Option<Vec<f64>> = covariate.and_then(|_| cs.into_iter().collect());
    let n = xs.len();
    if n == 0 {
        return None;
    }
    let mut scc = 0.0;
    let (a, b, c_mean, residuals): (f64, f64, f64, Vec<f64>) = match cs {
        Some(cs) if n >= 3 => {
            let cm = cs.iter().sum::<f64>() / n as f64;
            let xm = xs.iter().sum::<f64>() / n as f64;
            scc = cs.iter().map(|c| (c - cm).powi(2)).sum();
            let b = if scc > 0.0 {
                cs.iter()
                    .zip(&xs)
                    .map(|(c, x)| (c - cm) * (x - xm))
                    .sum::<f64>()
                    / scc
            } else {
                0.0
            };
            let res: Vec<f64> = cs
                .iter()
                .zip(&xs)
                .map(|(c, x)| x - xm - b * (c - cm))
                .collect();
            let (m, _) = robust_scatter(&res);
            (xm + m, b, cm, res.iter().map(|r| r - m).collect())
        }
        _ => {
            let (m, _) = robust_scatter(&xs);
            (m, 0.0, 0.0, xs.iter().map(|x| x - m).collect())
        }
    };
    let (_, mad_sigma) = robust_scatter(&residuals);
    let kept: Vec<f64> = residuals
        .iter()
        .copied()
        .filter(|r| r.abs() <= SCREEN_MADS * mad_sigma)
        .collect();
    let dof = kept.len() as f64 - if scc > 0.0 { 2.0 } else { 1.0 };
    let scatter = if dof >= 1.0 {
        (kept.iter().map(|r| r * r).sum::<f64>() / dof).sqrt()
    } else {
        mad_sigma
    };
    let screened = n - kept.len();
    Some(Normal {
        unit: first.unit.clone(),
        factor: first.unit_factor,
        a,
        b,
        c_mean,
        scatter,
        scc,
        n,
        left_out,
        residuals: ids.into_iter().zip(residuals).collect(),
        screened,
    })
}
