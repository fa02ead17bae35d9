//! Milling stability by semi-discretization (Insperger and Stépán, 2002/2004): the time-periodic
//! delay-differential equation of the milling process is discretized over one tooth period, and
//! the cut is stable when the spectral radius of the period's transition (monodromy) matrix is
//! below one. It keeps the time variation of the directional matrix that the zeroth-order
//! approximation averages out, so it is the reference at low radial immersion (where the
//! period-doubling "flip" lobes appear).
//!
//! The structure is a viscously damped modal model in the cutting plane ([`ModalModel`]):
//! `q̈ + 2ζω q̇ + ω² q = Uᵀ F`, `r = U q` the relative tool–workpiece displacement, mass-normalized
//! shapes `U` (2 × modes). The force is `F(t) = a H(t) (r(t) − r(t − τ))` with
//! `H(t) = K_t Σ_j g(φ_j) [[−s(c + ρs), −c(c + ρs)], [s(s − ρc), c(s − ρc)]]`, `s = sin φ_j`,
//! `c = cos φ_j`, `ρ = K_r/K_t`, the same force model whose average is the zeroth-order
//! approximation's `½ K_t A₀` ([`crate::lobes::directional_matrix`]).
//!
//! First-order semi-discretization: on each of `steps` intervals of length Δt = τ/steps the
//! periodic coefficient is replaced by its interval mean and the delayed displacement by the line
//! through its two neighbouring samples; each interval is then solved exactly by one matrix
//! exponential of the augmented system.

use std::f64::consts::PI;

use nalgebra::DMatrix;

use rfe::modes;
use rfe::system::System;
use rfe::C64;

use crate::cut::Milling;
use crate::oriented::{Mat2, OrientedFrf, Placement};
use crate::StabilityError;

/// One viscously damped mode of the relative tool–workpiece motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViscousMode {
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Viscous damping ratio ζ.
    pub damping_ratio: f64,
    /// Relative displacement along the two cutting directions per unit modal coordinate, mass
    /// normalized (m/√kg).
    pub shape: [f64; 2],
}

/// A modal model of the relative tool–workpiece receptance.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalModel {
    /// Its modes.
    pub modes: Vec<ViscousMode>,
}

impl ModalModel {
    /// A single-DOF structure along the first direction: mass `m` (kg), natural frequency
    /// `freq_hz`, damping ratio `zeta`.
    pub fn single(m: f64, freq_hz: f64, zeta: f64) -> ModalModel {
        ModalModel {
            modes: vec![ViscousMode {
                freq_hz,
                damping_ratio: zeta,
                shape: [1.0 / m.sqrt(), 0.0],
            }],
        }
    }

    /// Its oriented FRF `Φ_ij = Σ u_i u_j / (ω_n² − ω² + 2jζω_nω)` (m/N) on `freqs_hz`.
    pub fn frf(&self, freqs_hz: &[f64]) -> OrientedFrf {
        let phi = freqs_hz
            .iter()
            .map(|&f| {
                let w = 2.0 * PI * f;
                let mut p: Mat2 = [[C64::new(0.0, 0.0); 2]; 2];
                for m in &self.modes {
                    let wn = 2.0 * PI * m.freq_hz;
                    let h = C64::new(wn * wn - w * w, 2.0 * m.damping_ratio * wn * w).inv();
                    for i in 0..2 {
                        for j in 0..2 {
                            p[i][j] += h * (m.shape[i] * m.shape[j]);
                        }
                    }
                }
                p
            })
            .collect();
        OrientedFrf {
            freqs_hz: freqs_hz.to_vec(),
            phi,
            dphi: Vec::new(),
        }
    }

    /// The modal model of a placed cut: the model's undamped modes up to `max_hz`, mass
    /// normalized, with ζ = η/2 from each mode's loss factor `η = φᵀDφ / φᵀKφ` (hysteretic
    /// damping has no time-domain form; at resonance the two agree, which is where chatter is).
    pub fn of_placement(p: &Placement, max_hz: f64) -> Result<ModalModel, StabilityError> {
        let s = System::assemble(&p.aux);
        let n = s.n;
        let mut out = Vec::new();
        for m in modes::undamped(&p.aux)? {
            if m.freq_hz <= 0.0 || m.freq_hz > max_hz {
                continue;
            }
            let x: Vec<f64> = m.shape.iter().map(|v| v.re).collect();
            let mut mu: f64 = (0..n).map(|i| s.mass[i] * x[i] * x[i]).sum();
            for &(i, j, v) in &s.mass_coupling {
                mu += v * x[i] * x[j];
            }
            let quad = |a: &[f64]| -> f64 {
                (0..n)
                    .map(|i| x[i] * (0..n).map(|j| a[i * n + j] * x[j]).sum::<f64>())
                    .sum()
            };
            let eta = quad(&s.d) / quad(&s.k);
            let mut shape = [0.0; 2];
            for &(o, i, j, sign) in &p.taps {
                if j == 0 {
                    shape[i] += sign * s.output_rows[o].apply(|d| C64::new(x[d], 0.0)).re;
                }
            }
            let norm = mu.sqrt();
            out.push(ViscousMode {
                freq_hz: m.freq_hz,
                damping_ratio: 0.5 * eta,
                shape: [shape[0] / norm, shape[1] / norm],
            });
        }
        Ok(ModalModel { modes: out })
    }
}

/// `H(t)/K_t` of one tooth at angle φ (rad), `ρ = K_r/K_t`.
fn tooth_matrix(phi: f64, rho: f64) -> [[f64; 2]; 2] {
    let (s, c) = phi.sin_cos();
    [
        [-s * (c + rho * s), -c * (c + rho * s)],
        [s * (s - rho * c), c * (s - rho * c)],
    ]
}

/// `H(t)` (N/m² per m of depth, i.e. the force per depth and per relative displacement) at
/// time `t` (s) for spindle speed `rpm`.
fn cutting_matrix(m: &Milling, kt: f64, kr: f64, rpm: f64, t: f64) -> [[f64; 2]; 2] {
    let (st, ex) = m.immersion();
    let mut h = [[0.0; 2]; 2];
    for j in 0..m.teeth {
        let phi =
            (2.0 * PI * rpm / 60.0 * t + 2.0 * PI * j as f64 / m.teeth as f64).rem_euclid(2.0 * PI);
        if phi > st && phi < ex {
            let a = tooth_matrix(phi, kr / kt);
            for r in 0..2 {
                for c in 0..2 {
                    h[r][c] += kt * a[r][c];
                }
            }
        }
    }
    h
}

/// Sub-samples per interval for the interval mean of H(t) (the tooth enters and leaves within
/// an interval).
const MEAN_SAMPLES: usize = 8;

/// Spectral radius of the monodromy matrix at spindle speed `rpm` and axial depth `depth` (m),
/// with `steps` intervals per tooth period: < 1 stable.
pub fn spectral_radius(
    model: &ModalModel,
    m: &Milling,
    kt: f64,
    kr: f64,
    rpm: f64,
    depth: f64,
    steps: usize,
) -> f64 {
    let nm = model.modes.len();
    let tau = 60.0 / (rpm * m.teeth as f64);
    let dt = tau / steps as f64;
    let dim = 2 * nm + steps * nm;
    let u = DMatrix::from_fn(2, nm, |i, k| model.modes[k].shape[i]);
    let mut z = DMatrix::<f64>::identity(dim, dim);
    for i in 0..steps {
        // Interval mean of W = Uᵀ H U.
        let mut h = DMatrix::<f64>::zeros(2, 2);
        for s in 0..MEAN_SAMPLES {
            let t = (i as f64 + (s as f64 + 0.5) / MEAN_SAMPLES as f64) * dt;
            let hs = cutting_matrix(m, kt, kr, rpm, t);
            for r in 0..2 {
                for c in 0..2 {
                    h[(r, c)] += hs[r][c] / MEAN_SAMPLES as f64;
                }
            }
        }
        let w = u.transpose() * h * &u * depth;
        // Augmented generator [[L, R, 0], [0, 0, I], [0, 0, 0]] for ẏ = L y + R (u0 + s u1).
        let mut g = DMatrix::<f64>::zeros(4 * nm, 4 * nm);
        for k in 0..nm {
            let mode = &model.modes[k];
            let wn = 2.0 * PI * mode.freq_hz;
            g[(k, nm + k)] = 1.0;
            g[(nm + k, k)] -= wn * wn;
            g[(nm + k, nm + k)] = -2.0 * mode.damping_ratio * wn;
            g[(2 * nm + k, 3 * nm + k)] = 1.0;
        }
        for r in 0..nm {
            for c in 0..nm {
                g[(nm + r, c)] += w[(r, c)];
                g[(nm + r, 2 * nm + c)] = -w[(r, c)];
            }
        }
        let e = (g * dt).exp();
        let e11 = e.view((0, 0), (2 * nm, 2 * nm)).into_owned();
        let e12 = e.view((0, 2 * nm), (2 * nm, nm)).into_owned();
        let e13 = e.view((0, 3 * nm), (2 * nm, nm)).into_owned() / dt;
        // y_{i+1} = E11 y_i + (E12 − E13/Δt) q_{i−m} + (E13/Δt) q_{i−m+1}; the delayed samples
        // q_{i−1} … q_{i−m} sit after y in the state, q_{i−j} at 2nm + (j−1)nm.
        let oldest = 2 * nm + (steps - 1) * nm;
        let next = if steps >= 2 {
            2 * nm + (steps - 2) * nm
        } else {
            0
        };
        let y = z.rows(0, 2 * nm).into_owned();
        let q_old = z.rows(oldest, nm).into_owned();
        let q_next = z.rows(next, nm).into_owned();
        let top = &e11 * &y + (&e12 - &e13) * &q_old + &e13 * &q_next;
        let mut znew = DMatrix::<f64>::zeros(dim, dim);
        znew.rows_mut(0, 2 * nm).copy_from(&top);
        znew.rows_mut(2 * nm, nm).copy_from(&y.rows(0, nm));
        if steps >= 2 {
            let shifted = z.rows(2 * nm, (steps - 1) * nm).into_owned();
            znew.rows_mut(3 * nm, (steps - 1) * nm).copy_from(&shifted);
        }
        z = znew;
    }
    z.complex_eigenvalues()
        .iter()
        .map(|l| l.norm())
        .fold(0.0, f64::max)
}

/// The critical depth (m) at each speed: the lowest depth at which the spectral radius reaches
/// 1, found by scanning `depth_max / 40` steps upwards and bisecting the first unstable step
/// (the boundary is not monotone in depth where flip lobes close); `INFINITY` when stable up to
/// `depth_max`.
pub fn boundary(
    model: &ModalModel,
    m: &Milling,
    kt: f64,
    kr: f64,
    speeds_rpm: &[f64],
    depth_max: f64,
    steps: usize,
) -> Vec<f64> {
    const SCAN: usize = 40;
    const BISECTIONS: usize = 14;
    speeds_rpm
        .iter()
        .map(|&rpm| {
            let unstable = |a: f64| spectral_radius(model, m, kt, kr, rpm, a, steps) >= 1.0;
            let mut lo = 0.0;
            let mut hi = f64::INFINITY;
            for j in 1..=SCAN {
                let a = depth_max * j as f64 / SCAN as f64;
                if unstable(a) {
                    hi = a;
                    break;
                }
                lo = a;
            }
            if !hi.is_finite() {
                return f64::INFINITY;
            }
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                if unstable(mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            0.5 * (lo + hi)
        })
        .collect()
}
