//! The poly-reference least-squares complex frequency-domain estimator (pLSCF).
//!
//! Model, per output `o` (a row over the `l` references): `H_o(ω) = B_o(z) A(z)⁻¹` with
//! `z = exp(iωΔt)`, `A(z) = Σ_{r=0}^{p} z^r α_r` (real `l × l`, `α_p = I`) and
//! `B_o(z) = Σ z^r β_{o,r}` (real `1 × l`). `Δt = 1 / (2 f_hi)` maps the band onto the upper half of
//! the unit circle, as sdypy-EMA does. The linearised error `B_o − H_o A` gives, per output, the
//! real normal-equation blocks `R` (common to all outputs with unit weights), `S_o` and `T_o`, all
//! Toeplitz in the order index and built from the moments `Σ_k c_k z_k^m`. Eliminating `β`
//! leaves `D_p = Σ_o (T_o − S_oᵀ R⁻¹ S_o)` for the denominator. With `R = L Lᵀ` (Cholesky) and
//! `Q_o = L⁻¹ S_o`, the leading rows of `Q_o` serve every lower order, so
//! `Σ_o S_oᵀ R_p⁻¹ S_o` of order `p` is the previous order's sum plus one rank-`outputs` update.
//!
//! The poles are the eigenvalues of the block companion matrix of `A`, `λ = ln(z) / Δt`; the
//! participation vector of a pole is the left null vector of `A(z)` there.
//!
//! Uncertainty: each column `θ_j` of the denominator (its free part `α_j`) is the least-squares
//! solution of the reduced normal equations `D θ_j = 0`, so, for an equation error that is white
//! over lines and outputs, `cov(α_j) = σ̂_j² D_aa⁻¹` with `σ̂_j² = θ_jᵀ D θ_j / (2·lines·outputs −
//! outputs·(p+1) − l·p)` (the residual per degree of freedom). A pole `z` of `A` moves by
//! `δz = −wᵀ δA(z) v / (wᵀ A'(z) v)` (`w`, `v` the left and right null vectors of `A(z)`), which
//! carries the covariance to `z`, then to `λ = ln z / Δt`, the frequency and the damping ratio
//! (first order). This is the covariance of the linearised estimator with one pooled variance
//! (Pintelon, Guillaume & Schoukens 2007 derive the full one): the equation error is the FRF
//! noise weighted by `|A(z_k)|`, smallest near the resonances whose lines fix the poles, so the
//! pooled variance overstates it there and the figures are conservative. Against Monte Carlo
//! (`process/tests/modal_uncertainty.rs`) they are 2.6-4.4 times the scatter: an upper bound
//! and a scale, not an exact standard deviation.

use nalgebra::DMatrix;

use super::{ModalData, ModalError, Result};
use crate::C64;

/// Settings of the estimator.
#[derive(Debug, Clone)]
pub struct LscfSettings {
    /// Highest model order (each order `p` gives `p × references` poles, half of them with
    /// positive frequency).
    pub max_order: usize,
    /// Frequency band used (Hz, inclusive); all lines when `None`.
    pub band_hz: Option<(f64, f64)>,
}

/// One pole of the model.
#[derive(Debug, Clone)]
pub struct Pole {
    /// Continuous-time pole λ (rad/s), `λ = −ζω_n + iω_n√(1−ζ²)`.
    pub lambda: C64,
    /// Natural frequency `|λ| / 2π` (Hz).
    pub freq_hz: f64,
    /// Damping ratio `−Re λ / |λ|` (negative for an unstable pole).
    pub damping_ratio: f64,
    /// Participation vector over the references (unit norm, largest component real positive).
    pub participation: Vec<C64>,
    /// Standard deviations of frequency and damping from the estimator's covariance; `None`
    /// where the least squares has no residual degree of freedom.
    pub std: Option<PoleStd>,
}

/// Standard deviations of a pole's frequency and damping ratio (first-order propagation of the
/// denominator's least-squares covariance).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoleStd {
    /// σ of the natural frequency (Hz).
    pub freq_hz: f64,
    /// σ of the damping ratio.
    pub damping_ratio: f64,
}

impl Pole {
    /// Builds a pole from λ, with its frequency and damping.
    pub fn from_lambda(lambda: C64, participation: Vec<C64>) -> Pole {
        let wn = lambda.norm();
        Pole {
            lambda,
            freq_hz: wn / (2.0 * std::f64::consts::PI),
            damping_ratio: if wn > 0.0 { -lambda.re / wn } else { 0.0 },
            participation,
            std: None,
        }
    }
}

/// The poles of one model order (positive frequencies only, sorted by frequency).
#[derive(Debug, Clone)]
pub struct OrderPoles {
    /// Model order `p`.
    pub order: usize,
    /// Its poles with `Im λ > 0`.
    pub poles: Vec<Pole>,
}

/// The lines of the band: indices into `data.freqs_hz`.
pub(crate) fn band_lines(data: &ModalData, band: Option<(f64, f64)>) -> Result<(usize, usize)> {
    let (lo, hi) = match band {
        Some((lo, hi)) => {
            if !(lo >= 0.0) || !(hi > lo) || !hi.is_finite() {
                return Err(ModalError::InvalidSetting {
                    field: "band_hz",
                    value: format!("{lo}..{hi}"),
                    reason: "give 0 ≤ low < high (Hz)".into(),
                });
            }
            (lo, hi)
        }
        None => (0.0, f64::INFINITY),
    };
    let first = data.freqs_hz.partition_point(|&f| f < lo);
    let end = data.freqs_hz.partition_point(|&f| f <= hi);
    Ok((first, end))
}

/// Runs pLSCF for orders `1..=settings.max_order`: the band's lines, the FRFs scaled to unit RMS,
/// the Toeplitz moments of the normal equations, their reduction to `Q_o` and `T`, then the
/// denominator and poles order by order.
pub fn lscf(data: &ModalData, settings: &LscfSettings) -> Result<Vec<OrderPoles>> {
    let nmax = settings.max_order;
    if nmax == 0 || nmax > 500 {
        return Err(ModalError::InvalidSetting {
            field: "max_order",
            value: nmax.to_string(),
            reason: "give an order between 1 and 500".into(),
        });
    }
    let band = Band::of(data, settings.band_hz, nmax)?;
    let scale = unit_rms_scale(data, &band)?;
    let m = Moments::of(data, &band, nmax, scale);
    let (q, t) = reduce(&m, data.outputs, data.references, nmax)?;
    orders(&q, &t, data.outputs, data.references, nmax, &band)
}

/// The lines of the band a pLSCF of order `nmax` fits, and its time step.
struct Band {
    /// First line.
    first: usize,
    /// One past the last line.
    end: usize,
    /// Lines.
    nf: usize,
    /// `Δt = 1 / (2 f_hi)`.
    dt: f64,
}

impl Band {
    /// The band's lines; too few for the unknowns of order `nmax` is an error.
    fn of(data: &ModalData, band_hz: Option<(f64, f64)>, nmax: usize) -> Result<Band> {
        let (first, end) = band_lines(data, band_hz)?;
        let nf = end.saturating_sub(first);
        let l = data.references;
        let lo_hz = data.freqs_hz.get(first).copied().unwrap_or(f64::NAN);
        let hi_hz = if end > 0 {
            data.freqs_hz[end - 1]
        } else {
            f64::NAN
        };
        // Unknowns: (nmax + 1)·l denominator and (nmax + 1)·l numerator coefficients per output;
        // the real equations are 2·nf per output.
        if nf < 2 || 2 * nf < (nmax + 1) * (l + 1) || !(hi_hz > 0.0) {
            return Err(ModalError::TooFewLines {
                lines: nf,
                lo_hz,
                hi_hz,
                order: nmax,
                references: l,
            });
        }
        Ok(Band {
            first,
            end,
            nf,
            dt: 1.0 / (2.0 * hi_hz),
        })
    }
}

/// The factor that scales the FRFs to unit RMS over the band (poles do not depend on it; it keeps
/// T and S of order 1).
fn unit_rms_scale(data: &ModalData, band: &Band) -> Result<f64> {
    let (no, l, nf) = (data.outputs, data.references, band.nf);
    let ms: f64 = (0..no * l)
        .map(|fr| {
            data.h[fr * data.lines() + band.first..fr * data.lines() + band.end]
                .iter()
                .map(|v| v.norm_sqr())
                .sum::<f64>()
        })
        .sum::<f64>()
        / (no * l * nf) as f64;
    if !(ms > 0.0) {
        return Err(ModalError::Singular {
            what: "pLSCF (FRFs are zero in the band)",
        });
    }
    Ok(1.0 / ms.sqrt())
}

/// The moments `Re Σ_k c_k z_k^m`, `m = −nmax..=nmax` (index `m + nmax`), of the normal
/// equations' Toeplitz blocks.
struct Moments {
    /// `r(m) = Re Σ z^m`.
    r: Vec<f64>,
    /// `s_{o,b}(m) = −Re Σ H_ob z^m`, at `(o·l + b)·nm + m + nmax`.
    s: Vec<f64>,
    /// `t_{ab}(m) = Re Σ_o Σ_k conj(H_oa) H_ob z^m`, at `(a·l + b)·nm + m + nmax`.
    t: Vec<f64>,
}

impl Moments {
    fn of(data: &ModalData, band: &Band, nmax: usize, scale: f64) -> Moments {
        let (first, end, nf) = (band.first, band.end, band.nf);
        let (no, l) = (data.outputs, data.references);
        let n1 = nmax + 1;
        // Powers z_k^m, m = 0..=nmax, for the lines of the band: pow[m * nf + k].
        let mut pow = vec![C64::new(0.0, 0.0); n1 * nf];
        for k in 0..nf {
            let z = C64::from_polar(
                1.0,
                2.0 * std::f64::consts::PI * data.freqs_hz[first + k] * band.dt,
            );
            let mut p = C64::new(1.0, 0.0);
            for m in 0..n1 {
                pow[m * nf + k] = p;
                p *= z;
            }
        }
        // Moments Re Σ_k c_k z_k^m for m = −nmax..=nmax, stored at index m + nmax.
        let moments = |c: &[C64], out: &mut [f64]| {
            for m in 0..n1 {
                let pm = &pow[m * nf..(m + 1) * nf];
                let (mut pos, mut neg) = (0.0, 0.0);
                for (ck, zk) in c.iter().zip(pm) {
                    // Re(c z) and Re(c z̄)
                    let a = ck.re * zk.re;
                    let b = ck.im * zk.im;
                    pos += a - b;
                    neg += a + b;
                }
                out[nmax + m] = pos;
                out[nmax - m] = neg;
            }
        };
        let nm = 2 * nmax + 1;
        let ones = vec![C64::new(1.0, 0.0); nf];
        let mut r_mom = vec![0.0; nm];
        moments(&ones, &mut r_mom);
        let mut s_mom = vec![0.0; no * l * nm];
        let mut t_mom = vec![0.0; l * l * nm];
        let mut buf = vec![C64::new(0.0, 0.0); nf];
        let mut tmp = vec![0.0; nm];
        for o in 0..no {
            for b in 0..l {
                let hb = &data.frf(o, b)[first..end];
                for (x, v) in buf.iter_mut().zip(hb) {
                    *x = -v * scale;
                }
                moments(&buf, &mut s_mom[(o * l + b) * nm..(o * l + b + 1) * nm]);
            }
        }
        let mut prod = vec![C64::new(0.0, 0.0); nf];
        for a in 0..l {
            for b in a..l {
                prod.iter_mut().for_each(|x| *x = C64::new(0.0, 0.0));
                for o in 0..no {
                    let ha = &data.frf(o, a)[first..end];
                    let hb = &data.frf(o, b)[first..end];
                    for ((x, va), vb) in prod.iter_mut().zip(ha).zip(hb) {
                        *x += va.conj() * vb * (scale * scale);
                    }
                }
                moments(&prod, &mut tmp);
                for m in 0..nm {
                    t_mom[(a * l + b) * nm + m] = tmp[m];
                    // t_ba(m) = t_ab(−m)
                    t_mom[(b * l + a) * nm + m] = tmp[nm - 1 - m];
                }
            }
        }
        Moments {
            r: r_mom,
            s: s_mom,
            t: t_mom,
        }
    }
}

/// The reduced normal equations: `Q_o = L⁻¹ S_o` per output (`R = L Lᵀ`) and `T`.
fn reduce(
    m: &Moments,
    no: usize,
    l: usize,
    nmax: usize,
) -> Result<(Vec<DMatrix<f64>>, DMatrix<f64>)> {
    let n1 = nmax + 1;
    let nm = 2 * nmax + 1;
    // R (n1 × n1): R_ij = r(j − i); its Cholesky factor.
    let r = DMatrix::from_fn(n1, n1, |i, j| {
        m.r[(nmax as isize + j as isize - i as isize) as usize]
    });
    let chol = nalgebra::Cholesky::new(r).ok_or(ModalError::Singular {
        what: "pLSCF (R is not positive definite: too few distinct lines)",
    })?;
    let lmat = chol.l();
    let nc = l * n1;
    // Q_o = L⁻¹ S_o, S_o[i][(j, b)] = s_ob(j − i); rows stored per output.
    let mut q = Vec::with_capacity(no);
    for o in 0..no {
        let s = DMatrix::from_fn(n1, nc, |i, c| {
            let (j, b) = (c / l, c % l);
            m.s[(o * l + b) * nm + (nmax as isize + j as isize - i as isize) as usize]
        });
        let qo = lmat
            .solve_lower_triangular(&s)
            .ok_or(ModalError::Singular { what: "pLSCF (R)" })?;
        q.push(qo);
    }
    // T (nc × nc): T[(i,a)][(j,b)] = t_ab(j − i).
    let t = DMatrix::from_fn(nc, nc, |ri, ci| {
        let (i, a) = (ri / l, ri % l);
        let (j, b) = (ci / l, ci % l);
        m.t[(a * l + b) * nm + (nmax as isize + j as isize - i as isize) as usize]
    });
    Ok((q, t))
}

/// The denominator and poles of every order `1..=nmax`, each order's `Σ_o S_oᵀ R⁻¹ S_o` the
/// previous one's plus one row of every `Q_o`.
fn orders(
    q: &[DMatrix<f64>],
    t: &DMatrix<f64>,
    no: usize,
    l: usize,
    nmax: usize,
    band: &Band,
) -> Result<Vec<OrderPoles>> {
    let nc = l * (nmax + 1);
    let nf = band.nf;
    let mut g = DMatrix::<f64>::zeros(nc, nc);
    let mut out = Vec::with_capacity(nmax);
    for p in 0..=nmax {
        // Add row p of every Q_o (only the columns of order ≤ nmax are ever used).
        for qo in q {
            let row = qo.row(p);
            g.ger(1.0, &row.transpose(), &row.transpose(), 1.0);
        }
        if p == 0 {
            continue;
        }
        let na = l * p;
        let d = t.view((0, 0), (na + l, na + l)) - g.view((0, 0), (na + l, na + l));
        let daa = d.view((0, 0), (na, na)).into_owned();
        let rhs = -d.view((0, na), (na, l)).into_owned();
        let (alpha, daa_inv) = match daa.clone().cholesky() {
            Some(c) => (c.solve(&rhs), Some(c.inverse())),
            None => {
                let lu = daa.lu();
                let alpha = lu
                    .solve(&rhs)
                    .ok_or(ModalError::Singular { what: "pLSCF (D)" })?;
                (alpha, lu.try_inverse())
            }
        };
        let dof = (2 * nf * no) as f64 - (no * (p + 1)) as f64 - (l * p) as f64;
        let cov = daa_inv.filter(|_| dof > 0.0).map(|inv| {
            let mut theta = DMatrix::<f64>::zeros(na + l, l);
            theta.view_mut((0, 0), (na, l)).copy_from(&alpha);
            theta.view_mut((na, 0), (l, l)).fill_with_identity();
            let resid = theta.transpose() * &d * &theta;
            let sigma2: Vec<f64> = (0..l).map(|j| resid[(j, j)].max(0.0) / dof).collect();
            Covariance {
                sigma2,
                daa_inv: inv,
            }
        });
        out.push(OrderPoles {
            order: p,
            poles: poles_of(&alpha, l, p, band.dt, cov.as_ref()),
        });
    }
    Ok(out)
}

/// The least-squares covariance of the denominator: `cov(α_j) = sigma2[j] · daa_inv`.
struct Covariance {
    /// Residual variance per column of the denominator.
    sigma2: Vec<f64>,
    /// Inverse of the free part of the reduced normal matrix.
    daa_inv: DMatrix<f64>,
}

/// Poles (Im λ > 0) of `A(z) = Σ z^r α_r + z^p I`, `alpha` stacking `α_0..α_{p−1}` (`l·p × l`).
fn poles_of(
    alpha: &DMatrix<f64>,
    l: usize,
    p: usize,
    dt: f64,
    cov: Option<&Covariance>,
) -> Vec<Pole> {
    let n = l * p;
    let mut comp = DMatrix::<f64>::zeros(n, n);
    for i in 0..n.saturating_sub(l) {
        comp[(i, i + l)] = 1.0;
    }
    // A(z) v = 0 with x = [v; zv; …; z^{p−1}v]: the last block row is z^p v = −Σ α_r z^r v.
    for r in 0..p {
        for i in 0..l {
            for j in 0..l {
                comp[(n - l + i, r * l + j)] = -alpha[(r * l + i, j)];
            }
        }
    }
    let eig = comp.complex_eigenvalues();
    let mut poles: Vec<Pole> = eig
        .iter()
        .filter(|z| z.norm() > 0.0)
        .map(|z| z.ln() / dt)
        .filter(|lam| lam.im > 0.0)
        .map(|lam| {
            let z = (lam * dt).exp();
            let (w, v) = null_vectors(alpha, l, p, z);
            let mut pole = Pole::from_lambda(lam, normalize(w.clone()));
            pole.std = cov.and_then(|c| pole_std(alpha, l, p, dt, z, &w, &v, c));
            pole
        })
        .collect();
    poles.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    poles
}

/// `A(z) = Σ_{r<p} z^r α_r + z^p I`.
fn a_of(alpha: &DMatrix<f64>, l: usize, p: usize, z: C64) -> DMatrix<C64> {
    let mut a = DMatrix::<C64>::identity(l, l) * z.powu(p as u32);
    let mut zr = C64::new(1.0, 0.0);
    for r in 0..p {
        for i in 0..l {
            for j in 0..l {
                a[(i, j)] += zr * alpha[(r * l + i, j)];
            }
        }
        zr *= z;
    }
    a
}

/// Left and right null vectors `(w, v)` of `A(z)` at a pole (`wᵀA(z) = 0`, `A(z) v = 0`). Near
/// the pole `H ≈ B(z) v wᵀ / (z − z_r)`, so `w` is the reference side of the residue: the
/// participation vector.
fn null_vectors(alpha: &DMatrix<f64>, l: usize, p: usize, z: C64) -> (Vec<C64>, Vec<C64>) {
    if l == 1 {
        return (vec![C64::new(1.0, 0.0)], vec![C64::new(1.0, 0.0)]);
    }
    let svd = a_of(alpha, l, p, z).svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return (vec![C64::new(0.0, 0.0); l], vec![C64::new(0.0, 0.0); l]);
    };
    let kmin = svd.singular_values.imin();
    // A = U Σ Vᴴ: A v = 0 for v = conj(row k of Vᴴ); uᴴ A = 0, i.e. wᵀ A = 0 for w = conj(u_k).
    let v = vt.row(kmin).iter().map(|c| c.conj()).collect();
    let w = u.column(kmin).iter().map(|c| c.conj()).collect();
    (w, v)
}

/// First-order standard deviations of a pole's frequency and damping from the covariance of the
/// denominator (see the module's doc).
#[allow(clippy::too_many_arguments)]
fn pole_std(
    alpha: &DMatrix<f64>,
    l: usize,
    p: usize,
    dt: f64,
    z: C64,
    w: &[C64],
    v: &[C64],
    cov: &Covariance,
) -> Option<PoleStd> {
    // wᵀ A'(z) v with A'(z) = Σ r z^{r−1} α_r + p z^{p−1} I.
    let mut da = DMatrix::<C64>::identity(l, l) * (z.powu(p as u32 - 1) * p as f64);
    for r in 1..p {
        let zr = z.powu(r as u32 - 1) * r as f64;
        for i in 0..l {
            for j in 0..l {
                da[(i, j)] += zr * alpha[(r * l + i, j)];
            }
        }
    }
    let mut den = C64::new(0.0, 0.0);
    for i in 0..l {
        for j in 0..l {
            den += w[i] * da[(i, j)] * v[j];
        }
    }
    if den.norm() == 0.0 {
        return None;
    }
    // Covariance of (Re z, Im z): Σ_j σ_j² g_jᵀ D_aa⁻¹ g_j, g_j[(r, i)] = −w_i v_j z^r / den.
    let na = l * p;
    let mut czz = [[0.0; 2]; 2];
    for (j, s2) in cov.sigma2.iter().enumerate() {
        let g: Vec<C64> = (0..na)
            .map(|idx| {
                let (r, i) = (idx / l, idx % l);
                -w[i] * v[j] * z.powu(r as u32) / den
            })
            .collect();
        let gr = DMatrix::from_fn(2, na, |c, idx| if c == 0 { g[idx].re } else { g[idx].im });
        let c = &gr * &cov.daa_inv * gr.transpose() * *s2;
        for a in 0..2 {
            for b in 0..2 {
                czz[a][b] += c[(a, b)];
            }
        }
    }
    // λ = ln z / Δt: dλ = c dz with c = 1 / (z Δt).
    let c = C64::new(1.0, 0.0) / (z * dt);
    let jac = [[c.re, -c.im], [c.im, c.re]];
    let mut cll = [[0.0; 2]; 2];
    for a in 0..2 {
        for b in 0..2 {
            for m in 0..2 {
                for n in 0..2 {
                    cll[a][b] += jac[a][m] * czz[m][n] * jac[b][n];
                }
            }
        }
    }
    let lam = z.ln() / dt;
    let (x, y, r) = (lam.re, lam.im, lam.norm());
    let quad = |g: [f64; 2]| {
        (g[0] * g[0] * cll[0][0] + 2.0 * g[0] * g[1] * cll[0][1] + g[1] * g[1] * cll[1][1])
            .max(0.0)
            .sqrt()
    };
    let two_pi = 2.0 * std::f64::consts::PI;
    let sf = quad([x / (r * two_pi), y / (r * two_pi)]);
    let sz = quad([-y * y / r.powi(3), x * y / r.powi(3)]);
    (sf.is_finite() && sz.is_finite()).then_some(PoleStd {
        freq_hz: sf,
        damping_ratio: sz,
    })
}

/// Unit norm, largest-magnitude component real positive.
pub(crate) fn normalize(mut v: Vec<C64>) -> Vec<C64> {
    let norm: f64 = v.iter().map(|c| c.norm_sqr()).sum::<f64>().sqrt();
    let big = v.iter().copied().fold(
        C64::new(0.0, 0.0),
        |m, c| if c.norm() > m.norm() { c } else { m },
    );
    if norm > 0.0 && big.norm() > 0.0 {
        let rot = big.conj() / (big.norm() * norm);
        v.iter_mut().for_each(|c| *c *= rot);
    }
    v
}
