//! Confidence bands of the stability boundary from the Cramér-Rao covariance of the
//! identification variables.
//!
//! - linear: `σ_a(n)² = gᵀ C g` with `g = ∂a(n)/∂x` from the FRF's analytic Jacobian through
//!   the lobe chain ([`crate::lobes::depth_gradient`]); the 5–95 % band is `a ∓ 1.645 σ_a`
//!   (the estimates are asymptotically normal, and so is a smooth function of them);
//! - Monte Carlo: parameters drawn from `N(x̂, C)`, the model re-solved and the boundary
//!   recomputed for each draw; the band is the 5th and 95th percentile at each speed. It checks
//!   the linear band where the boundary is smooth and shows where it is not (lobe crossings,
//!   where the lowest lobe switches).

use nalgebra::{DMatrix, SymmetricEigen};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

use identify::variables::Variables;
use rfe::frf::Method;

use crate::cut::Cut;
use crate::lobes::{self, BoundaryPoint, Branches, Process};
use crate::oriented::{self, OrientedFrf, Placement};
use crate::StabilityError;

/// The standard normal quantile of 95 %: a two-sided 5–95 % band is ± this many σ.
pub const Z95: f64 = 1.644_853_626_951_472_2;

/// A band around the boundary, per speed (m).
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// 5 % quantile of the critical depth.
    pub lower: Vec<f64>,
    /// 95 % quantile.
    pub upper: Vec<f64>,
    /// Standard deviation (linear: propagated; Monte Carlo: of the draws).
    pub sigma: Vec<f64>,
}

/// The linear (delta-method) band.
pub fn linear(
    process: &Process,
    frf: &OrientedFrf,
    br: &Branches,
    periods: usize,
    points: &[BoundaryPoint],
    covariance: &DMatrix<f64>,
) -> Band {
    let sigma: Vec<f64> = points
        .iter()
        .map(|p| {
            let g = lobes::depth_gradient(process, frf, br, periods, p);
            let n = g.len();
            let mut v = 0.0;
            for i in 0..n {
                for j in 0..n {
                    v += g[i] * covariance[(i, j)] * g[j];
                }
            }
            v.max(0.0).sqrt()
        })
        .collect();
    Band {
        lower: points
            .iter()
            .zip(&sigma)
            .map(|(p, s)| p.depth - Z95 * s)
            .collect(),
        upper: points
            .iter()
            .zip(&sigma)
            .map(|(p, s)| p.depth + Z95 * s)
            .collect(),
        sigma,
    }
}

/// A square root `L` of a covariance (`L Lᵀ = C`), through its eigen-decomposition so that a
/// singular covariance (an undetermined combination) is allowed.
fn root(c: &DMatrix<f64>) -> DMatrix<f64> {
    let e = SymmetricEigen::new(c.clone());
    let mut l = e.eigenvectors.clone();
    for (k, &lam) in e.eigenvalues.iter().enumerate() {
        let s = lam.max(0.0).sqrt();
        l.column_mut(k).scale_mut(s);
    }
    l
}

/// The `q` quantile (0..1) of sorted values, linearly interpolated.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let x = q * (sorted.len() - 1) as f64;
    let (i, t) = (x.floor() as usize, x - x.floor());
    let j = (i + 1).min(sorted.len() - 1);
    sorted[i] + t * (sorted[j] - sorted[i])
}

/// What a Monte Carlo band needs besides the model.
pub struct Sampling<'a> {
    /// The variables (their `initial` values are the estimates x̂).
    pub variables: &'a Variables,
    /// Their covariance (SI).
    pub covariance: &'a DMatrix<f64>,
    /// Draws.
    pub samples: usize,
    /// Seed of the generator.
    pub seed: u64,
}

/// The Monte Carlo band: `samples` draws of the variables, each a full re-solve. Draws that make
/// the model singular (a stiffness drawn below zero) are left out and counted in the second
/// value returned.
pub fn monte_carlo(
    placement: &Placement,
    cut: &Cut,
    freqs_hz: &[f64],
    s: &Sampling,
) -> Result<(Band, usize), StabilityError> {
    let process = Process::of(cut);
    let periods = cut.periods_per_rev();
    let speeds = cut.speed_grid();
    let x0 = s.variables.initial();
    let l = root(s.covariance);
    let mut rng = StdRng::seed_from_u64(s.seed);
    let mut depths: Vec<Vec<f64>> = vec![Vec::with_capacity(s.samples); speeds.len()];
    let mut skipped = 0;
    let mut p = placement.clone();
    for _ in 0..s.samples {
        let z: Vec<f64> = (0..x0.len())
            .map(|_| StandardNormal.sample(&mut rng))
            .collect();
        let x: Vec<f64> = (0..x0.len())
            .map(|i| x0[i] + (0..x0.len()).map(|k| l[(i, k)] * z[k]).sum::<f64>())
            .collect();
        p.aux = placement.aux.clone();
        s.variables.apply(&mut p.aux, &x);
        let frf = match oriented::oriented_frf(&p, cut, freqs_hz, None, Method::Auto) {
            Ok(f) => f,
            Err(StabilityError::Solve(_)) => {
                skipped += 1;
                continue;
            }
            Err(e) => return Err(e),
        };
        let br = lobes::branches(&process, &frf);
        for (d, b) in depths
            .iter_mut()
            .zip(lobes::boundary(&br, periods, &speeds))
        {
            d.push(b.depth);
        }
    }
    let mut band = Band {
        lower: Vec::new(),
        upper: Vec::new(),
        sigma: Vec::new(),
    };
    for mut d in depths {
        d.sort_by(f64::total_cmp);
        band.lower.push(quantile(&d, 0.05));
        band.upper.push(quantile(&d, 0.95));
        let finite: Vec<f64> = d.iter().copied().filter(|v| v.is_finite()).collect();
        let n = finite.len().max(2) as f64;
        let mean = finite.iter().sum::<f64>() / n;
        band.sigma
            .push((finite.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt());
    }
    Ok((band, skipped))
}
