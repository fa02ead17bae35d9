//! How well the data determine each variable: the Cramér-Rao lower bound
//! `CV = (HᵀR⁻¹H)⁻¹` (paper eq. 4.15) at the estimate, standard errors, variability factors σ/x,
//! the correlation matrix, and identifiability (the near-singular directions of the information
//! matrix, named as combinations of variables).
//!
//! Variables that end at a bound are flagged: their estimate is not normally distributed, and
//! their standard error is the unconstrained bound `sqrt([F⁻¹]_ii)` of the full information
//! matrix F, as for every other variable. The covariance is not conditioned on the active bounds:
//! a bound reached because of noise (a weakly determined variable pushed to 0) says nothing
//! certain about the truth, and conditioning on it would understate the errors of the variables
//! correlated with it.

use nalgebra::{DMatrix, SymmetricEigen};

use super::variables::Variables;

/// Which bound a variable ended at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtBound {
    /// At its lower bound.
    Lower,
    /// At its upper bound.
    Upper,
}

/// A direction in (relative) parameter space the data determine poorly.
#[derive(Debug, Clone, PartialEq)]
pub struct WeakDirection {
    /// Relative standard error of the combination `Σ v_i δx_i / x_i` (1 = 100 %).
    pub relative_std: f64,
    /// Components `(variable name, v_i)`, largest first, |v_i| ≥ 0.2 (unit vector).
    pub components: Vec<(String, f64)>,
}

impl WeakDirection {
    /// `"0.71·kn 8 − 0.70·kn 23"`.
    pub fn combination(&self) -> String {
        let mut s = String::new();
        for (k, (name, v)) in self.components.iter().enumerate() {
            let sign = if *v < 0.0 { "−" } else { "+" };
            if k == 0 {
                if *v < 0.0 {
                    s.push('−');
                }
            } else {
                s.push_str(&format!(" {sign} "));
            }
            s.push_str(&format!("{:.2}·{name}", v.abs()));
        }
        s
    }
}

/// Uncertainty of the estimates.
#[derive(Debug, Clone, PartialEq)]
pub struct Uncertainty {
    /// Standard error per variable (SI; `NaN` when undetermined).
    pub std_error: Vec<f64>,
    /// Standard error / |x| per variable (`INFINITY` when x = 0).
    pub variability: Vec<f64>,
    /// Bound a variable ended at, if any.
    pub at_bound: Vec<Option<AtBound>>,
    /// Covariance (SI), over all variables (full information matrix, pseudo-inverse if singular).
    pub covariance: DMatrix<f64>,
    /// Correlation matrix from [`Uncertainty::covariance`].
    pub correlation: DMatrix<f64>,
    /// Factor applied to `(HᵀR⁻¹H)⁻¹`: 1 when R is known, the residual variance
    /// `2J/(m − n_free)` when R is known only up to scale.
    pub covariance_scale: f64,
    /// Reduced χ² = 2J/(m − n_free) (≈ 1 when R is right and the model fits).
    pub reduced_chi2: f64,
    /// Condition number of the relative information matrix.
    pub condition: f64,
    /// Poorly determined directions (relative σ above the threshold, or numerically singular).
    pub weak: Vec<WeakDirection>,
}

/// Computes the uncertainty at estimate `x` (SI) from the whitened Jacobian `jac` (∂e/∂x, SI),
/// the criterion `j`, whether R is known only up to scale, and the threshold on the relative σ of
/// a combination above which it is reported as poorly identifiable (e.g. 0.5).
pub fn uncertainty(
    vars: &Variables,
    x: &[f64],
    jac: &DMatrix<f64>,
    j: f64,
    scale_unknown: bool,
    weak_threshold: f64,
) -> Uncertainty {
    let n = x.len();
    let m = jac.nrows();
    let at_bound = bounds_hit(vars, x);
    let free: Vec<usize> = (0..n).filter(|&i| at_bound[i].is_none()).collect();
    let dof = m.saturating_sub(free.len()).max(1);
    let reduced_chi2 = 2.0 * j / dof as f64;
    let covariance_scale = if scale_unknown { reduced_chi2 } else { 1.0 };
    // Relative scaling D = diag(|x| or x_scale): F̃ = D F D is dimensionless.
    let d: Vec<f64> = vars
        .vars
        .iter()
        .zip(x)
        .map(|(v, &xi)| {
            if xi.abs() > 1e-6 * v.scale {
                xi.abs()
            } else {
                v.scale
            }
        })
        .collect();
    let f = jac.tr_mul(jac);
    let ft = DMatrix::from_fn(n, n, |a, b| f[(a, b)] * d[a] * d[b]);
    let eig = SymmetricEigen::new(ft.clone());
    let lmax = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
    let cutoff = 1e-14 * lmax;
    // Pseudo-inverse of F̃.
    let mut pinv = DMatrix::zeros(n, n);
    for k in 0..n {
        let l = eig.eigenvalues[k];
        if l > cutoff {
            let v = eig.eigenvectors.column(k);
            pinv += (v * v.transpose()) / l;
        }
    }
    let covariance = DMatrix::from_fn(n, n, |a, b| pinv[(a, b)] * d[a] * d[b] * covariance_scale);
    let correlation = DMatrix::from_fn(n, n, |a, b| {
        let s = (covariance[(a, a)] * covariance[(b, b)]).sqrt();
        if s > 0.0 {
            covariance[(a, b)] / s
        } else {
            f64::NAN
        }
    });
    let mut std_error: Vec<f64> = (0..n).map(|i| covariance[(i, i)].max(0.0).sqrt()).collect();
    for k in 0..n {
        if eig.eigenvalues[k] <= cutoff {
            // Directions with no information at all: the variables in them are undetermined.
            let v = eig.eigenvectors.column(k);
            for i in 0..n {
                if v[i].abs() > 0.2 {
                    std_error[i] = f64::NAN;
                }
            }
        }
    }
    let variability = std_error
        .iter()
        .zip(x)
        .map(|(s, xi)| {
            if *xi != 0.0 {
                s / xi.abs()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let lmin = eig
        .eigenvalues
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let condition = if lmin > 0.0 {
        lmax / lmin
    } else {
        f64::INFINITY
    };
    let weak = weak_directions(vars, &eig, cutoff, covariance_scale, weak_threshold);
    Uncertainty {
        std_error,
        variability,
        at_bound,
        covariance,
        correlation,
        covariance_scale,
        reduced_chi2,
        condition,
        weak,
    }
}

/// Which variables sit at a bound (within 1e-9 of their scale).
fn bounds_hit(vars: &Variables, x: &[f64]) -> Vec<Option<AtBound>> {
    vars.vars
        .iter()
        .zip(x)
        .map(|(v, &xi)| {
            let tol = 1e-9 * v.scale;
            if xi <= v.lower + tol {
                Some(AtBound::Lower)
            } else if xi >= v.upper - tol {
                Some(AtBound::Upper)
            } else {
                None
            }
        })
        .collect()
}

/// The eigen-directions of the scaled information matrix whose relative standard deviation
/// exceeds `weak_threshold`, worst first, each with the variables that make it up.
fn weak_directions(
    vars: &Variables,
    eig: &SymmetricEigen<f64, nalgebra::Dyn>,
    cutoff: f64,
    covariance_scale: f64,
    weak_threshold: f64,
) -> Vec<WeakDirection> {
    let n = eig.eigenvalues.len();
    let mut weak: Vec<WeakDirection> = (0..n)
        .filter_map(|k| {
            let l = eig.eigenvalues[k];
            let rel = if l > cutoff {
                (covariance_scale / l).sqrt()
            } else {
                f64::INFINITY
            };
            if rel <= weak_threshold {
                return None;
            }
            let v = eig.eigenvectors.column(k);
            let mut comps: Vec<(String, f64)> = (0..n)
                .filter(|&i| v[i].abs() >= 0.2)
                .map(|i| (vars.vars[i].name.clone(), v[i]))
                .collect();
            comps.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
            if comps.first().is_some_and(|c| c.1 < 0.0) {
                for c in &mut comps {
                    c.1 = -c.1;
                }
            }
            Some(WeakDirection {
                relative_std: rel,
                components: comps,
            })
        })
        .collect();
    weak.sort_by(|a, b| b.relative_std.total_cmp(&a.relative_std));
    weak
}
