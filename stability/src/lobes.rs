//! Stability lobes from an oriented FRF: the process turns the 2×2 oriented FRF into one or two
//! scalar transfer functions `G(ω)` (turning: Tlusty/Tobias; milling: the eigenvalues of the
//! zeroth-order approximation of Altintas and Budak), each giving a lobe family, and the
//! stability boundary is the lowest lobe at each spindle speed.
//!
//! Both reduce to the characteristic equation `1 + a (1 − e^{−jωT}) G(jω) = 0` (a the axial
//! depth, T the delay between passes). With a real: `a = −1 / (2 Re G)` where `Re G < 0`, and
//! `e^{−jωT} = −conj(G)/G`, so `ωT = ε + 2πk` with `ε = 2 arg G − π ∈ (0, 2π)`
//! (`arg G ∈ (π/2, 3π/2)`) and lobe `k = 0, 1, …`; the spindle speed is
//! `n = 60 f / (N (ε/2π + k))` rpm for N periods per revolution.
//!
//! - turning (chip thickness along e₀, tangential force along e₁, force per unit chip area
//!   `K_r e₀ + K_t e₁` on the tool): `G = K_r Φ₀₀ + K_t Φ₀₁`;
//! - milling (x = feed, y = axis × feed, force `F = ½ a K_t A₀ (r(t) − r(t − T))` with the
//!   average directional matrix `A₀ = (N/2π) [α]`): the eigenvalues λ of `A₀ Φ`, `G = −½ K_t λ`
//!   (the same lobes as Altintas' `Λ = −(N/4π) a K_t (1 − e^{−jωT})`).
//!
//! The derivative of the boundary at a fixed speed with respect to a variable follows the chain
//! `∂Φ → ∂G → (∂a, ∂ε) → ∂n` on the two lines that bracket the speed, and the interpolation
//! between them ([`depth_gradient`]).

use std::f64::consts::PI;

use rfe::C64;

use crate::cut::{Cut, Milling, Operation};
use crate::oriented::{Mat2, OrientedFrf};

/// The process: how the oriented FRF becomes the transfer functions G of the lobes.
#[derive(Debug, Clone, PartialEq)]
pub enum Process {
    /// `G = K_r Φ₀₀ + K_t Φ₀₁`.
    Turning {
        /// Tangential coefficient (N/m²).
        kt: f64,
        /// Radial coefficient (N/m²).
        kr: f64,
    },
    /// `G = −½ K_t λ(A₀ Φ)`, two branches.
    Milling {
        /// Tangential coefficient (N/m²).
        kt: f64,
        /// `A₀ = (N/2π)[α]` (dimensionless; the ratio K_r/K_t is inside).
        a0: [[f64; 2]; 2],
    },
}

/// The average directional coefficients `A₀ = (N/2π)[α]` of Altintas and Budak (1995) for a
/// cutter of `teeth` teeth between entry and exit angles `(φ_st, φ_ex)`, with `ratio = K_r/K_t`.
pub fn directional_matrix(teeth: usize, (st, ex): (f64, f64), ratio: f64) -> [[f64; 2]; 2] {
    let at = |p: f64| {
        let (s2, c2) = (2.0 * p).sin_cos();
        [
            [
                0.5 * (c2 - 2.0 * ratio * p + ratio * s2),
                0.5 * (-s2 - 2.0 * p + ratio * c2),
            ],
            [
                0.5 * (-s2 + 2.0 * p + ratio * c2),
                0.5 * (-c2 - 2.0 * ratio * p - ratio * s2),
            ],
        ]
    };
    let (a, b) = (at(ex), at(st));
    let f = teeth as f64 / (2.0 * PI);
    [
        [f * (a[0][0] - b[0][0]), f * (a[0][1] - b[0][1])],
        [f * (a[1][0] - b[1][0]), f * (a[1][1] - b[1][1])],
    ]
}

impl Process {
    /// The process of a cutting file.
    pub fn of(cut: &Cut) -> Process {
        match &cut.operation {
            Operation::Turning(_) => Process::Turning {
                kt: cut.kt,
                kr: cut.kr,
            },
            Operation::Milling(m) => Process::milling(m, cut.kt, cut.kr),
        }
    }

    /// Milling with cutter `m` and coefficients `kt`, `kr` (N/m²).
    pub fn milling(m: &Milling, kt: f64, kr: f64) -> Process {
        Process::Milling {
            kt,
            a0: directional_matrix(m.teeth, m.immersion(), kr / kt),
        }
    }

    /// Lobe families: 1 for turning, 2 for milling.
    pub fn branches(&self) -> usize {
        match self {
            Process::Turning { .. } => 1,
            Process::Milling { .. } => 2,
        }
    }

    /// `B = A₀ Φ` (milling).
    fn product(a0: &[[f64; 2]; 2], phi: &Mat2) -> Mat2 {
        let mut b = [[C64::new(0.0, 0.0); 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                b[i][j] = phi[0][j] * a0[i][0] + phi[1][j] * a0[i][1];
            }
        }
        b
    }

    /// G of branch `sign` (+1 or −1; ignored for turning) at Φ.
    pub fn g(&self, phi: &Mat2, sign: f64) -> C64 {
        match self {
            Process::Turning { kt, kr } => phi[0][0] * *kr + phi[0][1] * *kt,
            Process::Milling { kt, a0 } => {
                let b = Self::product(a0, phi);
                let (tr, sq) = trace_root(&b);
                -0.5 * kt * (tr + sq * sign) * 0.5
            }
        }
    }

    /// ∂G of branch `sign` at Φ in the direction ∂Φ (first order; for milling the eigenvalue
    /// derivative `∂λ = ½ ∂tr ± ∂disc / (4 √disc)`).
    pub fn dg(&self, phi: &Mat2, dphi: &Mat2, sign: f64) -> C64 {
        match self {
            Process::Turning { kt, kr } => dphi[0][0] * *kr + dphi[0][1] * *kt,
            Process::Milling { kt, a0 } => {
                let b = Self::product(a0, phi);
                let db = Self::product(a0, dphi);
                let (_, sq) = trace_root(&b);
                let (a, bb, c, d) = (b[0][0], b[0][1], b[1][0], b[1][1]);
                let dtr = db[0][0] + db[1][1];
                let ddisc =
                    (a - d) * (db[0][0] - db[1][1]) * 2.0 + (db[0][1] * c + bb * db[1][0]) * 4.0;
                let dl = dtr * 0.5
                    + if sq.norm() > 0.0 {
                        ddisc / (sq * 4.0) * sign
                    } else {
                        C64::new(0.0, 0.0)
                    };
                -0.5 * kt * dl
            }
        }
    }
}

/// Trace and √discriminant of a 2×2 matrix: eigenvalues `(tr ± √disc)/2`.
fn trace_root(b: &Mat2) -> (C64, C64) {
    let tr = b[0][0] + b[1][1];
    let disc = (b[0][0] - b[1][1]) * (b[0][0] - b[1][1]) + b[0][1] * b[1][0] * 4.0;
    (tr, disc.sqrt())
}

/// G per line and branch, with the branches followed across lines (the two eigenvalues keep
/// their identity where the square root's sign would swap them).
#[derive(Debug, Clone)]
pub struct Branches {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// `g[b][k]`: branch b at line k.
    pub g: Vec<Vec<C64>>,
    /// `sign[b][k]`: the root's sign that branch b takes at line k.
    pub sign: Vec<Vec<f64>>,
}

/// The branches of `process` over the lines of `frf`.
pub fn branches(process: &Process, frf: &OrientedFrf) -> Branches {
    let nb = process.branches();
    let lines = frf.phi.len();
    let mut g = vec![Vec::with_capacity(lines); nb];
    let mut sign = vec![Vec::with_capacity(lines); nb];
    let mut prev: Option<[C64; 2]> = None;
    for phi in &frf.phi {
        if nb == 1 {
            g[0].push(process.g(phi, 1.0));
            sign[0].push(1.0);
            continue;
        }
        let (p, m) = (process.g(phi, 1.0), process.g(phi, -1.0));
        let swap = prev.is_some_and(|q| {
            (p - q[0]).norm() + (m - q[1]).norm() > (m - q[0]).norm() + (p - q[1]).norm()
        });
        let (s0, s1) = if swap { (-1.0, 1.0) } else { (1.0, -1.0) };
        let (g0, g1) = if swap { (m, p) } else { (p, m) };
        g[0].push(g0);
        g[1].push(g1);
        sign[0].push(s0);
        sign[1].push(s1);
        prev = Some([g0, g1]);
    }
    Branches {
        freqs_hz: frf.freqs_hz.clone(),
        g,
        sign,
    }
}

/// One point of the stability boundary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryPoint {
    /// Spindle speed (rpm).
    pub speed_rpm: f64,
    /// Critical axial depth (m); `INFINITY` where no lobe reaches this speed.
    pub depth: f64,
    /// Chatter frequency (Hz).
    pub chatter_hz: f64,
    /// Lobe number k (0 = the rightmost lobe).
    pub lobe: usize,
    /// Branch (lobe family).
    pub branch: usize,
    /// The first of the two lines that bracket the speed.
    pub line: usize,
    /// Interpolation weight between `line` and `line + 1`.
    pub t: f64,
}

/// `ε = 2 arg G − π ∈ (0, 2π)` for `Re G < 0`.
fn phase(g: C64) -> f64 {
    let mut arg = g.im.atan2(g.re);
    if arg < 0.0 {
        arg += 2.0 * PI;
    }
    2.0 * arg - PI
}

/// Spindle speed (rpm) of lobe `k` at frequency `f` (Hz) and phase ε.
fn speed(f: f64, eps: f64, k: usize, periods: usize) -> f64 {
    60.0 * f / (periods as f64 * (eps / (2.0 * PI) + k as f64))
}

/// The stability boundary at `speeds_rpm` (ascending): the lowest lobe of every branch at each
/// speed, interpolated between the bracketing lines.
pub fn boundary(br: &Branches, periods: usize, speeds_rpm: &[f64]) -> Vec<BoundaryPoint> {
    let mut out: Vec<BoundaryPoint> = speeds_rpm
        .iter()
        .map(|&s| BoundaryPoint {
            speed_rpm: s,
            depth: f64::INFINITY,
            chatter_hz: f64::NAN,
            lobe: 0,
            branch: 0,
            line: 0,
            t: 0.0,
        })
        .collect();
    let (Some(&lo), Some(&hi)) = (speeds_rpm.first(), speeds_rpm.last()) else {
        return out;
    };
    let fmax = br.freqs_hz.iter().copied().fold(0.0, f64::max);
    // Lobes beyond this one lie entirely below the lowest speed.
    let kmax = ((60.0 * fmax / (periods as f64 * lo)).floor() as usize).min(100_000);
    for (b, gs) in br.g.iter().enumerate() {
        for l in 0..gs.len().saturating_sub(1) {
            let (g0, g1) = (gs[l], gs[l + 1]);
            if !(g0.re < 0.0 && g1.re < 0.0) {
                continue;
            }
            let (e0, e1) = (phase(g0), phase(g1));
            if (e1 - e0).abs() > PI {
                continue;
            }
            let (a0, a1) = (-0.5 / g0.re, -0.5 / g1.re);
            let (f0, f1) = (br.freqs_hz[l], br.freqs_hz[l + 1]);
            for k in 0..=kmax {
                let (n0, n1) = (speed(f0, e0, k, periods), speed(f1, e1, k, periods));
                let (nlo, nhi) = (n0.min(n1), n0.max(n1));
                if nhi < lo {
                    break;
                }
                if nlo > hi || nhi == nlo {
                    continue;
                }
                let start = speeds_rpm.partition_point(|&s| s < nlo);
                let end = speeds_rpm.partition_point(|&s| s <= nhi);
                for (i, &s) in speeds_rpm.iter().enumerate().take(end).skip(start) {
                    let t = (s - n0) / (n1 - n0);
                    let a = a0 + t * (a1 - a0);
                    if a < out[i].depth {
                        out[i] = BoundaryPoint {
                            speed_rpm: s,
                            depth: a,
                            chatter_hz: f0 + t * (f1 - f0),
                            lobe: k,
                            branch: b,
                            line: l,
                            t,
                        };
                    }
                }
            }
        }
    }
    out
}

/// ∂depth/∂x_v at a boundary point for every variable (m per SI unit of the variable), from the
/// FRF's derivatives `frf.dphi`.
pub fn depth_gradient(
    process: &Process,
    frf: &OrientedFrf,
    br: &Branches,
    periods: usize,
    p: &BoundaryPoint,
) -> Vec<f64> {
    if !p.depth.is_finite() {
        return vec![f64::NAN; frf.dphi.len()];
    }
    let (l, b, k, t) = (p.line, p.branch, p.lobe, p.t);
    let lines = [l, l + 1];
    let g = lines.map(|i| br.g[b][i]);
    let a = g.map(|g| -0.5 / g.re);
    let eps = g.map(phase);
    let n = [0, 1].map(|i| speed(br.freqs_hz[lines[i]], eps[i], k, periods));
    frf.dphi
        .iter()
        .map(|d| {
            let dg =
                [0, 1].map(|i| process.dg(&frf.phi[lines[i]], &d[lines[i]], br.sign[b][lines[i]]));
            let da = [0, 1].map(|i| dg[i].re / (2.0 * g[i].re * g[i].re));
            let deps = [0, 1].map(|i| 2.0 * (dg[i] / g[i]).im);
            let dn =
                [0, 1].map(|i| -n[i] * (deps[i] / (2.0 * PI)) / (eps[i] / (2.0 * PI) + k as f64));
            let dt = (-dn[0] - t * (dn[1] - dn[0])) / (n[1] - n[0]);
            da[0] + dt * (a[1] - a[0]) + t * (da[1] - da[0])
        })
        .collect()
}
