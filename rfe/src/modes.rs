//! Natural frequencies and mode shapes: undamped (`K φ = ω² M φ`, real) and complex
//! (`(K + jD) φ = λ M φ`, hysteretic damping: `λ = ω_n² (1 + jη)` with loss factor η).
//!
//! Both are solved through `M^-½ · M^-½` scaling (M is diagonal; with point masses, each body's
//! inverse Cholesky factor, [`MassScaling`]) with faer's symmetric and standard eigen solvers,
//! never the generalized one.

use faer::{Mat, Side};

use crate::frf::{ModalSolver, SolveError};
use crate::model::Model;
use crate::system::{MassScaling, System};
use crate::C64;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// One mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// Natural frequency (Hz): `sqrt(Re λ)/2π`; 0 for rigid-body modes.
    pub freq_hz: f64,
    /// Loss factor η = Im λ / Re λ (0 for undamped modes); the equivalent viscous damping ratio
    /// at resonance is about η/2.
    pub loss_factor: f64,
    /// Mode shape over all DOFs (6 per body, body principal axes), scaled so that the largest
    /// component is 1 (real and positive).
    pub shape: Vec<C64>,
    /// Share of the mode's kinetic energy in each body (sums to 1).
    pub energy: Vec<f64>,
}

fn finish(s: &System, lambda: C64, shape: Vec<C64>) -> Mode {
    let freq_hz = lambda.re.max(0.0).sqrt() / TWO_PI;
    let loss_factor = if lambda.re > 0.0 {
        lambda.im / lambda.re
    } else {
        0.0
    };
    let big = shape
        .iter()
        .copied()
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap_or(C64::new(1.0, 0.0));
    let shape: Vec<C64> = if big.norm() > 0.0 {
        shape.iter().map(|v| v / big).collect()
    } else {
        shape
    };
    // Kinetic energy per body, φᴴ M_b φ (M_b with its point masses' couplings).
    let mut energy: Vec<f64> = (0..s.n / 6)
        .map(|b| {
            (0..6)
                .map(|i| s.mass[6 * b + i] * shape[6 * b + i].norm_sqr())
                .sum()
        })
        .collect();
    for &(i, j, v) in &s.mass_coupling {
        energy[i / 6] += v * (shape[i].conj() * shape[j]).re;
    }
    let total: f64 = energy.iter().sum();
    if total > 0.0 {
        energy.iter_mut().for_each(|e| *e /= total);
    }
    Mode {
        freq_hz,
        loss_factor,
        shape,
        energy,
    }
}

/// Undamped modes, ascending in frequency.
pub fn undamped(model: &Model) -> Result<Vec<Mode>, SolveError> {
    let s = System::assemble(model);
    let n = s.n;
    let scale = MassScaling::new(&s)
        .ok_or_else(|| SolveError::Eigen("the mass matrix is not positive definite".into()))?;
    let a = Mat::<f64>::from_fn(n, n, |i, j| scale.congruence(i, j, |k, l| s.k[k * n + l]));
    let eig = a
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| SolveError::Eigen(format!("{e:?}")))?;
    Ok((0..n)
        .map(|m| {
            let lambda = eig.S()[m];
            let shape = (0..n)
                .map(|i| C64::new(scale.left(i, m, |k, mm| eig.U()[(k, mm)]), 0.0))
                .collect();
            finish(&s, C64::new(lambda, 0.0), shape)
        })
        .collect())
}

/// Complex modes of the hysteretically damped system, ascending in frequency.
pub fn complex(model: &Model) -> Result<Vec<Mode>, SolveError> {
    let s = System::assemble(model);
    let solver = ModalSolver::new(&s)?;
    let mut modes: Vec<Mode> = (0..s.n)
        .map(|m| {
            let shape = (0..s.n).map(|i| solver.x[(i, m)]).collect();
            finish(&s, solver.lambda[m], shape)
        })
        .collect();
    modes.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    Ok(modes)
}
