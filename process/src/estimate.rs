//! FRF estimators (H1, H2, Hv), ordinary and multiple coherence and the random error of each FRF
//! point, from averaged cross-spectral matrices.
//!
//! With references x (forces) and responses y, `G_xy = E[conj(X) Y]`:
//! - **H1** (noise on the response): `H1 = G_xy / G_xx`; with R references, per response j the
//!   R×R system `G_xx h_j = g_xy,j` (MIMO through the cross-spectral matrix).
//! - **H2** (noise on the force): `H2 = G_yy / G_yx`, one reference only.
//! - **Hv** (total least squares, equal noise on both): `Hv = (G_yy − G_xx + √((G_xx − G_yy)² + 4|G_xy|²)) / (2 G_yx)`, one reference.
//! - ordinary coherence `γ²_ij = |G_xiyj|² / (G_xixi G_yjyj)`; multiple coherence
//!   `γ²_j = g_xy,jᴴ G_xx⁻¹ g_xy,j / G_yjyj` (equal to the ordinary one for one reference).
//!
//! **Random error** (Bendat & Piersol, *Random Data*, 4th ed., eq. 9.90 and §7.4.3): with `n`
//! averages, R references and multiple coherence γ², the normalized random error of |H| is
//! `ε = √(1−γ²) / (γ √(2(n−R+1)))`, so `var(|H|) ≈ (1−γ²)/(2(n−R+1)γ²)·|H|²` and the phase
//! standard deviation (rad) is ε as well. The variance of the complex estimate, as the
//! identification's R wants it, is `E|Ĥ−H|² ≈ var(|H|) + |H|² var(φ) = (1−γ²)/((n−R+1)γ²)·|H|²`.
//! `n` counts segments; overlapping segments are not fully independent, so with 50 % overlap
//! these are slightly optimistic.

use num_complex::Complex;

use crate::error::{ProcessError, Result};
use crate::spectra::CrossSpectra;

type C64 = Complex<f64>;

/// Which FRF estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimator {
    /// Least squares with noise on the responses; any number of references.
    H1,
    /// Noise on the reference; one reference.
    H2,
    /// Total least squares; one reference.
    Hv,
}

impl Estimator {
    fn name(self) -> &'static str {
        match self {
            Estimator::H1 => "H1",
            Estimator::H2 => "H2",
            Estimator::Hv => "Hv",
        }
    }
}

/// Frequency response functions of P responses to R references with their coherence.
///
/// Units: response unit per reference unit (e.g. (m/s²)/N). Lines where the force spectrum is
/// zero (or the references are linearly dependent) hold NaN and coherence 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Number of references R.
    pub references: usize,
    /// Number of responses P.
    pub responses: usize,
    /// Number of averages behind each point.
    pub averages: u32,
    /// Estimator used.
    pub estimator: Estimator,
    /// `H[k][j][i]` (response j per unit of reference i), flattened `(k·P + j)·R + i`.
    pub h: Vec<C64>,
    /// Ordinary coherence `γ²[k][j][i]`, same layout as `h`.
    pub coherence: Vec<f64>,
    /// Multiple coherence of response j with all references, `k·P + j`.
    pub multiple_coherence: Vec<f64>,
}

impl Frf {
    /// `H` of response `j` to reference `i` at line `k`.
    pub fn h(&self, k: usize, j: usize, i: usize) -> C64 {
        self.h[(k * self.responses + j) * self.references + i]
    }

    /// Ordinary coherence of response `j` with reference `i` at line `k`.
    pub fn coherence(&self, k: usize, j: usize, i: usize) -> f64 {
        self.coherence[(k * self.responses + j) * self.references + i]
    }

    /// Multiple coherence of response `j` at line `k`.
    pub fn multiple_coherence(&self, k: usize, j: usize) -> f64 {
        self.multiple_coherence[k * self.responses + j]
    }

    /// The FRF of response `j` to reference `i` over all lines.
    pub fn line(&self, j: usize, i: usize) -> Vec<C64> {
        (0..self.freqs_hz.len()).map(|k| self.h(k, j, i)).collect()
    }

    /// Variance of |H| at a point (see the module doc): `(1−γ²)/(2(n−R+1)γ²)·|H|²`; infinite where γ² = 0.
    pub fn magnitude_variance(&self, k: usize, j: usize, i: usize) -> f64 {
        let g = self.multiple_coherence(k, j);
        let dof = (self.averages as f64 - self.references as f64 + 1.0).max(1.0);
        if g <= 0.0 {
            return f64::INFINITY;
        }
        (1.0 - g).max(0.0) / (2.0 * dof * g) * self.h(k, j, i).norm_sqr()
    }

    /// Variance of the complex estimate `E|Ĥ−H|²` at a point: twice [`Frf::magnitude_variance`].
    pub fn variance(&self, k: usize, j: usize, i: usize) -> f64 {
        2.0 * self.magnitude_variance(k, j, i)
    }
}

/// Estimates FRFs and coherences from averaged spectra.
pub fn estimate(s: &CrossSpectra, estimator: Estimator) -> Result<Frf> {
    let (r, p) = (s.references, s.responses);
    if estimator != Estimator::H1 && r != 1 {
        return Err(ProcessError::EstimatorNeedsSingleReference {
            estimator: estimator.name(),
            references: r,
        });
    }
    let nf = s.freqs_hz.len();
    let mut h = vec![C64::default(); nf * p * r];
    let mut coherence = vec![0.0; nf * p * r];
    let mut multiple = vec![0.0; nf * p];
    let mut a = vec![C64::default(); r * r];
    let mut b = vec![C64::default(); r];
    let mut perm = vec![0usize; r];
    for k in 0..nf {
        for j in 0..p {
            let gyy = s.gyy(k, j);
            for i in 0..r {
                let gxx = s.gxx(k, i, i).re;
                let gxy = s.gxy(k, i, j);
                coherence[(k * p + j) * r + i] = if gxx > 0.0 && gyy > 0.0 {
                    (gxy.norm_sqr() / (gxx * gyy)).min(1.0)
                } else {
                    0.0
                };
            }
            let out = &mut h[(k * p + j) * r..(k * p + j + 1) * r];
            match estimator {
                Estimator::H1 => {
                    for i in 0..r {
                        b[i] = s.gxy(k, i, j);
                        for l in 0..r {
                            a[i * r + l] = s.gxx(k, i, l);
                        }
                    }
                    if solve_in_place(&mut a, &mut b, &mut perm, r) {
                        out.copy_from_slice(&b);
                        // γ² = g^H G^{-1} g / Gyy = Σ conj(g_i) h_i / Gyy.
                        let num: f64 = (0..r).map(|i| (s.gxy(k, i, j).conj() * out[i]).re).sum();
                        multiple[k * p + j] = if gyy > 0.0 {
                            (num / gyy).clamp(0.0, 1.0)
                        } else {
                            0.0
                        };
                    } else {
                        out.iter_mut()
                            .for_each(|v| *v = C64::new(f64::NAN, f64::NAN));
                        multiple[k * p + j] = 0.0;
                    }
                }
                Estimator::H2 | Estimator::Hv => {
                    let gxx = s.gxx(k, 0, 0).re;
                    let gyx = s.gxy(k, 0, j).conj();
                    let val = if gyx.norm_sqr() == 0.0 {
                        C64::new(f64::NAN, f64::NAN)
                    } else if estimator == Estimator::H2 {
                        gyy / gyx
                    } else {
                        let d = gxx - gyy;
                        (gyy - gxx + (d * d + 4.0 * gyx.norm_sqr()).sqrt()) / (2.0 * gyx)
                    };
                    out[0] = val;
                    multiple[k * p + j] = coherence[(k * p + j) * r];
                }
            }
        }
    }
    Ok(Frf {
        freqs_hz: s.freqs_hz.clone(),
        references: r,
        responses: p,
        averages: s.averages,
        estimator,
        h,
        coherence,
        multiple_coherence: multiple,
    })
}

/// Solves `A x = b` (A: n×n row-major, overwritten) by Gaussian elimination with partial
/// pivoting; `b` receives x. Returns false if A is (numerically) singular.
fn solve_in_place(a: &mut [C64], b: &mut [C64], perm: &mut [usize], n: usize) -> bool {
    let scale = (0..n).map(|i| a[i * n + i].norm()).fold(0.0, f64::max);
    if scale == 0.0 || !scale.is_finite() {
        return false;
    }
    for (i, p) in perm.iter_mut().enumerate() {
        *p = i;
    }
    for c in 0..n {
        let (mut best, mut piv) = (0.0, c);
        for rr in c..n {
            let v = a[rr * n + c].norm();
            if v > best {
                best = v;
                piv = rr;
            }
        }
        if best <= 1e-12 * scale {
            return false;
        }
        if piv != c {
            for l in 0..n {
                a.swap(c * n + l, piv * n + l);
            }
            b.swap(c, piv);
        }
        let d = a[c * n + c];
        for rr in c + 1..n {
            let f = a[rr * n + c] / d;
            if f != C64::default() {
                for l in c..n {
                    let t = a[c * n + l];
                    a[rr * n + l] -= f * t;
                }
                let t = b[c];
                b[rr] -= f * t;
            }
        }
    }
    for c in (0..n).rev() {
        let mut v = b[c];
        for l in c + 1..n {
            v -= a[c * n + l] * b[l];
        }
        b[c] = v / a[c * n + c];
    }
    true
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn solver_solves_and_detects_singular() {
        let mut a = vec![
            C64::new(0.0, 0.0),
            C64::new(2.0, 1.0),
            C64::new(1.0, 0.0),
            C64::new(3.0, 0.0),
        ];
        let x = [C64::new(1.0, -1.0), C64::new(0.5, 2.0)];
        let mut b = vec![a[0] * x[0] + a[1] * x[1], a[2] * x[0] + a[3] * x[1]];
        let mut perm = vec![0; 2];
        assert!(solve_in_place(&mut a, &mut b, &mut perm, 2));
        assert!((b[0] - x[0]).norm() < 1e-14 && (b[1] - x[1]).norm() < 1e-14);
        let mut s = vec![
            C64::new(1.0, 0.0),
            C64::new(2.0, 0.0),
            C64::new(2.0, 0.0),
            C64::new(4.0, 0.0),
        ];
        let mut b = vec![C64::new(1.0, 0.0); 2];
        assert!(!solve_in_place(&mut s, &mut b, &mut perm, 2));
    }
}
