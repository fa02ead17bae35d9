//! The statistics of a fit's residuals shared by the identification's verdict and the
//! diagnosis: χ² tail probabilities far into the tail, and the Wald-Wolfowitz runs test of
//! residual signs along frequency.

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

/// `P(X ≥ x)` for `X ~ χ²(dof)`, accurate far into the tail (the survival function, not
/// `1 − cdf`, which is 0 below 1e-16 and made every large effect's p-value tie); NaN when `dof`
/// is not positive.
pub fn chi2_tail(dof: f64, x: f64) -> f64 {
    ChiSquared::new(dof).map(|d| d.sf(x)).unwrap_or(f64::NAN)
}

/// Wald-Wolfowitz runs test on the signs of `r`: (runs, expected runs, one-sided p of too few).
pub fn runs_test(r: &[f64]) -> (usize, f64, f64) {
    let signs: Vec<bool> = r.iter().filter(|v| **v != 0.0).map(|v| *v > 0.0).collect();
    let n = signs.len();
    let np = signs.iter().filter(|s| **s).count() as f64;
    let nm = n as f64 - np;
    let runs = if n == 0 {
        0
    } else {
        1 + signs.windows(2).filter(|w| w[0] != w[1]).count()
    };
    if np == 0.0 || nm == 0.0 {
        // All one sign: the strongest possible structure when there are enough points.
        let p = if n >= 2 {
            0.5f64.powi(n as i32 - 1)
        } else {
            1.0
        };
        return (runs, 1.0, p);
    }
    let nf = n as f64;
    let mean = 1.0 + 2.0 * np * nm / nf;
    let var = 2.0 * np * nm * (2.0 * np * nm - nf) / (nf * nf * (nf - 1.0));
    let p = if var > 0.0 {
        // Continuity correction: runs are integers.
        let z = (runs as f64 + 0.5 - mean) / var.sqrt();
        Normal::standard().cdf(z)
    } else {
        1.0
    };
    (runs, mean, p)
}

#[cfg(test)]
mod tests {
    use super::chi2_tail;

    /// Far in the tail, where `1 − cdf` is 0: P(χ²₁ ≥ 100) = erfc(√50) = 1.5239706048320995e-23
    /// (Python's `math.erfc`, and scipy's `chi2.sf(100, 1)`); two large statistics stay ordered.
    #[test]
    fn the_chi2_tail_is_accurate_far_beyond_1e_16() {
        let p = chi2_tail(1.0, 100.0);
        assert!((p / 1.5239706048320995e-23 - 1.0).abs() < 1e-9, "{p:e}");
        assert!(chi2_tail(2.0, 300.0) > chi2_tail(2.0, 310.0));
        assert!(chi2_tail(2.0, 310.0) > 0.0);
    }
}
