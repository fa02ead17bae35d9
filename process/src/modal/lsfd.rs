//! Residues by least squares in the frequency domain (LSFD) for chosen poles.
//!
//! Model of every FRF `H_or(ω)`, with `s = iω` and `d` the derivative order of the FRF kind
//! (0 receptance, 1 mobility, 2 accelerance):
//! `H_or = s^d [ Σ_m ( A_orm / (s − λ_m) + conj(A_orm) / (s − conj λ_m) ) + LR_or / s² + UR_or ]`
//! with complex residues `A` and complex lower and upper residuals `LR`, `UR` (the modes below and
//! above the band; complex, as sdypy-EMA's, because measured FRFs carry offsets in phase
//! quadrature — force-window and leakage effects of hammer tests — which real residuals cannot
//! take up, so they leak into the real parts of the weakest modes' residues). The design matrix is the same for all FRFs: one SVD, all right-hand sides.
//! The residue matrix of each mode (outputs × references) is split into mode shape ×
//! participation by its leading singular pair.

use nalgebra::DMatrix;

use super::lscf::{band_lines, Pole};
use super::{complexity, ModalData, ModalError, Result};
use crate::C64;

/// One identified mode.
#[derive(Debug, Clone)]
pub struct Mode {
    /// Its pole.
    pub pole: Pole,
    /// Mode shape over the outputs (residue's output side, largest component real positive;
    /// `residue[o][r] ≈ shape[o] · participation[r]`).
    pub shape: Vec<C64>,
    /// Participation over the references (residue's reference side).
    pub participation: Vec<C64>,
    /// Residues `A_orm`, `residues[o * references + r]` (FRF unit × rad/s).
    pub residues: Vec<C64>,
    /// Modal complexity factor of the shape (0 real, 1 fully complex).
    pub complexity: f64,
    /// How well the residue matrix is rank one: σ₁² / Σσ² (1 for a single-mode residue).
    pub rank_one: f64,
}

/// Modes and residuals from LSFD.
#[derive(Debug, Clone)]
pub struct ModalModel {
    /// The modes, in the order of the poles given.
    pub modes: Vec<Mode>,
    /// Lower residuals `LR`, `[o * references + r]`.
    pub lower: Vec<C64>,
    /// Upper residuals `UR`, `[o * references + r]`.
    pub upper: Vec<C64>,
    /// Frequency band used (Hz).
    pub band_hz: (f64, f64),
}

impl ModalModel {
    /// The model's FRF from reference `r` to output `o` at `freq_hz`.
    pub fn frf(&self, o: usize, r: usize, references: usize, d: i32, freq_hz: f64) -> C64 {
        let s = C64::new(0.0, 2.0 * std::f64::consts::PI * freq_hz);
        let i = o * references + r;
        let mut h = self.upper[i] + self.lower[i] / (s * s);
        for m in &self.modes {
            let a = m.residues[i];
            h += a / (s - m.pole.lambda) + a.conj() / (s - m.pole.lambda.conj());
        }
        h * s.powi(d)
    }
}

/// Residues, shapes and residuals of the given poles over the band (lines at 0 Hz are left out).
pub fn lsfd(data: &ModalData, poles: &[Pole], band_hz: Option<(f64, f64)>) -> Result<ModalModel> {
    let (first, end) = band_lines(data, band_hz)?;
    let first = first + data.freqs_hz[first..end].partition_point(|&f| f <= 0.0);
    let nf = end.saturating_sub(first);
    let nm = poles.len();
    let ncol = 2 * nm + 4;
    if 2 * nf < ncol + 1 {
        return Err(ModalError::TooFewLines {
            lines: nf,
            lo_hz: data.freqs_hz.get(first).copied().unwrap_or(f64::NAN),
            hi_hz: data
                .freqs_hz
                .get(end.wrapping_sub(1))
                .copied()
                .unwrap_or(f64::NAN),
            order: nm,
            references: data.references,
        });
    }
    let d = data.kind.derivative_order();
    let mut design = DMatrix::<f64>::zeros(2 * nf, ncol);
    for k in 0..nf {
        let s = C64::new(0.0, 2.0 * std::f64::consts::PI * data.freqs_hz[first + k]);
        let sd = s.powi(d);
        let mut put = |col: usize, v: C64| {
            design[(2 * k, col)] = v.re;
            design[(2 * k + 1, col)] = v.im;
        };
        for (m, p) in poles.iter().enumerate() {
            let g1 = sd / (s - p.lambda);
            let g2 = sd / (s - p.lambda.conj());
            put(2 * m, g1 + g2); // Re A
            put(2 * m + 1, C64::new(0.0, 1.0) * (g1 - g2)); // Im A
        }
        let i = C64::new(0.0, 1.0);
        put(2 * nm, sd / (s * s));
        put(2 * nm + 1, i * sd / (s * s));
        put(2 * nm + 2, sd);
        put(2 * nm + 3, i * sd);
    }
    // Column scaling for conditioning.
    let norms: Vec<f64> = (0..ncol)
        .map(|c| {
            let n = design.column(c).norm();
            if n > 0.0 {
                n
            } else {
                1.0
            }
        })
        .collect();
    for (c, n) in norms.iter().enumerate() {
        design.column_mut(c).scale_mut(1.0 / n);
    }
    let nfrf = data.outputs * data.references;
    let mut rhs = DMatrix::<f64>::zeros(2 * nf, nfrf);
    for fr in 0..nfrf {
        let h = &data.h[fr * data.lines() + first..fr * data.lines() + end];
        for (k, v) in h.iter().enumerate() {
            rhs[(2 * k, fr)] = v.re;
            rhs[(2 * k + 1, fr)] = v.im;
        }
    }
    let svd = design.svd(true, true);
    let smax = svd.singular_values.max();
    if !(smax > 0.0) || svd.singular_values.min() <= smax * 1e-13 {
        return Err(ModalError::Singular {
            what: "LSFD (two poles coincide or the band holds too few lines)",
        });
    }
    let x = svd
        .solve(&rhs, smax * 1e-14)
        .map_err(|_| ModalError::Singular { what: "LSFD" })?;
    let coef = |c: usize, fr: usize| x[(c, fr)] / norms[c];

    let l = data.references;
    let mut modes = Vec::with_capacity(nm);
    for (m, p) in poles.iter().enumerate() {
        let residues: Vec<C64> = (0..nfrf)
            .map(|fr| C64::new(coef(2 * m, fr), coef(2 * m + 1, fr)))
            .collect();
        let rm = DMatrix::from_fn(data.outputs, l, |o, r| residues[o * l + r]);
        let sv = rm.svd(true, true);
        let (mut shape, mut part) = (
            vec![C64::new(0.0, 0.0); data.outputs],
            vec![C64::new(0.0, 0.0); l],
        );
        let total: f64 = sv.singular_values.iter().map(|s| s * s).sum();
        let mut rank_one = 0.0;
        if let (Some(u), Some(vt)) = (&sv.u, &sv.v_t) {
            let k = sv.singular_values.imax();
            let s1 = sv.singular_values[k];
            rank_one = if total > 0.0 { s1 * s1 / total } else { 0.0 };
            // R ≈ s1 u vᴴ: shape = s1·u, participation = conj(v) = row k of vᴴ.
            let u_col: Vec<C64> = u.column(k).iter().map(|c| c * s1).collect();
            let v_row: Vec<C64> = vt.row(k).iter().copied().collect();
            // Rotate so the shape's largest component is real positive (participation opposite).
            let big = u_col.iter().copied().fold(C64::new(0.0, 0.0), |a, c| {
                if c.norm() > a.norm() {
                    c
                } else {
                    a
                }
            });
            if big.norm() > 0.0 {
                let rot = big.conj() / big.norm();
                shape = u_col.iter().map(|c| c * rot).collect();
                part = v_row.iter().map(|c| c / rot).collect();
            }
        }
        modes.push(Mode {
            pole: p.clone(),
            complexity: complexity(&shape),
            shape,
            participation: part,
            residues,
            rank_one,
        });
    }
    Ok(ModalModel {
        modes,
        lower: (0..nfrf)
            .map(|fr| C64::new(coef(2 * nm, fr), coef(2 * nm + 1, fr)))
            .collect(),
        upper: (0..nfrf)
            .map(|fr| C64::new(coef(2 * nm + 2, fr), coef(2 * nm + 3, fr)))
            .collect(),
        band_hz: (data.freqs_hz[first], data.freqs_hz[end - 1]),
    })
}
