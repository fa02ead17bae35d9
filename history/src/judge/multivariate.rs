//! The multivariate chart: Hotelling's T² = r' R⁻¹ r of the standardized residual vector `r`
//! of the parameters judged tonight, against a correlation matrix `R` that is usable with 20-30
//! baseline runs.
//!
//! - When the baseline runs carry their Cramér-Rao correlations (every ident report does), `R`
//!   is their mean over the baseline: the correlation structure the fit itself predicts, scaled
//!   by the learned scatter of each parameter (the residuals are already divided by it). It
//!   costs no degrees of freedom, so T² is χ²(p) up to the baseline's own error, and the limit is
//!   the χ²(p) quantile at `1 − α` times `1 + 1/n`.
//! - Otherwise `R` is the baseline's sample correlation shrunk toward the identity with the
//!   Schäfer-Strimmer (2005) weight, and the limit is the F limit of a new observation against
//!   an estimated covariance, `p(n+1)(n−1) / (n(n−p)) · F(p, n−p)`, conservative for the shrunk
//!   matrix.
//!
//! Correlated parameters moving along their correlation are normal; across it they are not: a
//! pair at ρ = −0.78 moving +1.5 sd each is a 4.5-sd move in its direction of least scatter.

use nalgebra::{DMatrix, DVector};
use statrs::distribution::{ChiSquared, ContinuousCDF, FisherSnedecor};

use crate::record::RunRecord;

/// One parameter's part of the vector.
pub(crate) struct Component<'a> {
    /// Variable name.
    pub variable: &'a str,
    /// Tonight's standardized residual.
    pub r: f64,
    /// Baseline run ids with their standardized residuals.
    pub baseline: Vec<(&'a str, f64)>,
}

/// T² and how it was computed.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct T2 {
    /// The statistic.
    pub t2: f64,
    /// Its limit at the chart's α.
    pub limit: f64,
    /// Where the correlation came from, in words.
    pub correlation: String,
}

/// Why T² could not be computed.
pub(crate) fn t2(parts: &[Component], base: &[&RunRecord], alpha: f64) -> Result<T2, String> {
    let p = parts.len();
    if p < 2 {
        return Err("fewer than 2 parameters judged".into());
    }
    let n = base.len();
    let (rho, mut limit, what) = match cramer_rao(parts, base) {
        Some(r) => {
            let q = ChiSquared::new(p as f64)
                .map_err(|e| e.to_string())?
                .inverse_cdf(1.0 - alpha);
            (
                r,
                q * (1.0 + 1.0 / n as f64),
                "the Cramér-Rao correlations of the baseline runs".to_string(),
            )
        }
        None => {
            if n <= p + 2 {
                return Err(format!(
                    "no Cramér-Rao correlations recorded and {n} baseline runs for {p} parameters (a sample covariance needs more than {})",
                    p + 2
                ));
            }
            let (r, lambda) = shrunk(parts);
            let q = FisherSnedecor::new(p as f64, (n - p) as f64)
                .map_err(|e| e.to_string())?
                .inverse_cdf(1.0 - alpha);
            (
                r,
                q * (p * (n + 1) * (n - 1)) as f64 / (n * (n - p)) as f64,
                format!("the baseline's sample correlation shrunk {lambda:.2} toward independence"),
            )
        }
    };
    let ch = rho.cholesky().ok_or("the correlation matrix is singular")?;
    let r = DVector::from_iterator(p, parts.iter().map(|c| c.r));
    let t2 = r.dot(&ch.solve(&r));
    if !limit.is_finite() {
        limit = f64::INFINITY;
    }
    Ok(T2 {
        t2,
        limit,
        correlation: what,
    })
}

/// The mean Cramér-Rao correlation over the baseline, when every baseline run recorded every
/// pair of `parts`.
fn cramer_rao(parts: &[Component], base: &[&RunRecord]) -> Option<DMatrix<f64>> {
    let p = parts.len();
    let mut r = DMatrix::<f64>::identity(p, p);
    if base.iter().any(|b| b.correlations.is_empty()) {
        return None;
    }
    for a in 0..p {
        for b in a + 1..p {
            let mut sum = 0.0;
            for run in base {
                sum += run.correlation(parts[a].variable, parts[b].variable)?;
            }
            let m = (sum / base.len() as f64).clamp(-0.999, 0.999);
            r[(a, b)] = m;
            r[(b, a)] = m;
        }
    }
    Some(r)
}

/// The baseline's sample correlation of the standardized residuals (runs common to every
/// part), shrunk toward the identity with the Schäfer-Strimmer weight
/// `λ = Σ Var(r_ij) / Σ r_ij²` over i ≠ j; returns the matrix and λ.
fn shrunk(parts: &[Component]) -> (DMatrix<f64>, f64) {
    let p = parts.len();
    // Runs where every part has a residual, outliers (beyond 5 scatters) left out.
    let runs: Vec<&str> = parts[0]
        .baseline
        .iter()
        .map(|(id, _)| *id)
        .filter(|id| {
            parts.iter().all(|c| {
                c.baseline
                    .iter()
                    .any(|(j, v)| j == id && v.abs() <= super::normal::SCREEN_MADS)
            })
        })
        .collect();
    let n = runs.len();
    if n < 3 {
        return (DMatrix::identity(p, p), 1.0);
    }
    // Standardize each column over the common runs.
    let mut x = DMatrix::<f64>::zeros(n, p);
    for (j, c) in parts.iter().enumerate() {
        for (i, id) in runs.iter().enumerate() {
            x[(i, j)] = c
                .baseline
                .iter()
                .find(|(k, _)| k == id)
                .map(|(_, v)| *v)
                .unwrap_or(0.0);
        }
        let col = x.column(j);
        let m = col.mean();
        let s = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        for i in 0..n {
            x[(i, j)] = if s > 0.0 { (x[(i, j)] - m) / s } else { 0.0 };
        }
    }
    let nf = n as f64;
    let mut r = DMatrix::<f64>::identity(p, p);
    let (mut var_sum, mut sq_sum) = (0.0, 0.0);
    for a in 0..p {
        for b in a + 1..p {
            let w: Vec<f64> = (0..n).map(|i| x[(i, a)] * x[(i, b)]).collect();
            let wm = w.iter().sum::<f64>() / nf;
            let rab = wm * nf / (nf - 1.0);
            let var = nf / (nf - 1.0).powi(3) * w.iter().map(|v| (v - wm).powi(2)).sum::<f64>();
            var_sum += var;
            sq_sum += rab * rab;
            r[(a, b)] = rab;
            r[(b, a)] = rab;
        }
    }
    let lambda = if sq_sum > 0.0 {
        (var_sum / sq_sum).clamp(0.0, 1.0)
    } else {
        1.0
    };
    for a in 0..p {
        for b in 0..p {
            if a != b {
                r[(a, b)] *= 1.0 - lambda;
            }
        }
    }
    (r, lambda)
}
