//! Quality indicators of identified modes and the mode indicator function of the FRF matrix.
//!
//! A normal mode of a proportionally damped structure has all shape components in phase (or in
//! opposition): plotted in the complex plane they lie on one line through the origin. The
//! indicators measure how far a shape is from that:
//!
//! - **MPC**, modal phase collinearity (Pappa, Elliott & Schenk 1993): with the centred real and
//!   imaginary parts' covariance `[[s_xx, s_xy], [s_xy, s_yy]]` and its eigenvalues `e₁ ≥ e₂`,
//!   `MPC = ((e₁ − e₂) / (e₁ + e₂))²`; 1 for a line, 0 for a circle.
//! - **MPD**, mean phase deviation (Reynders, Houbrechts & De Roeck 2012): the angle between each
//!   component and the best line through the origin (the leading right singular vector of
//!   `[Re φ, Im φ]`), averaged with weights `|φ_j|`; 0° for a real mode.
//! - **MCF**, modal complexity factor (as sdypy-EMA computes it), `1 − ((S_xx − S_yy)² + 4S_xy²)
//!   / (S_xx + S_yy)²` with uncentred sums about the origin; 0 for a real mode, 1 for a
//!   travelling wave ([`complexity`]).
//!
//! A spurious (numerical) pole usually has a scattered, complex shape: a low MPC, a large MPD.
//!
//! The **complex mode indicator function** (Shih, Tsuei, Allemang & Brown 1988) is, per line, the
//! singular values of the points × fixed-channels FRF matrix: peaks of the first mark modes,
//! peaks of the second at the same frequency mark repeated or close modes.

use nalgebra::DMatrix;

use super::{complexity, ModalData};
use crate::C64;

/// The three shape indicators.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeQuality {
    /// Modal phase collinearity (0..1, 1 for a real mode).
    pub mpc: f64,
    /// Mean phase deviation (degrees, 0 for a real mode).
    pub mpd_deg: f64,
    /// Modal complexity factor (0..1, 0 for a real mode).
    pub mcf: f64,
}

/// MPC, MPD and MCF of a shape.
pub fn shape_quality(shape: &[C64]) -> ShapeQuality {
    ShapeQuality {
        mpc: mpc(shape),
        mpd_deg: mpd_deg(shape),
        mcf: complexity(shape),
    }
}

/// Modal phase collinearity (centred, Pappa et al.).
pub fn mpc(shape: &[C64]) -> f64 {
    let n = shape.len() as f64;
    if shape.is_empty() {
        return 0.0;
    }
    let (mx, my) = (
        shape.iter().map(|v| v.re).sum::<f64>() / n,
        shape.iter().map(|v| v.im).sum::<f64>() / n,
    );
    let sxx: f64 = shape.iter().map(|v| (v.re - mx).powi(2)).sum();
    let syy: f64 = shape.iter().map(|v| (v.im - my).powi(2)).sum();
    let sxy: f64 = shape.iter().map(|v| (v.re - mx) * (v.im - my)).sum();
    let total = sxx + syy;
    if total > 0.0 {
        // (e₁ − e₂)² = (s_xx − s_yy)² + 4 s_xy², e₁ + e₂ = s_xx + s_yy.
        ((sxx - syy).powi(2) + 4.0 * sxy * sxy) / (total * total)
    } else {
        // All components equal: one point, collinear.
        1.0
    }
}

/// Mean phase deviation in degrees (weights `|φ_j|`).
pub fn mpd_deg(shape: &[C64]) -> f64 {
    let total: f64 = shape.iter().map(|v| v.norm()).sum();
    if total <= 0.0 {
        return 0.0;
    }
    // The best line through the origin: leading eigenvector of [Re Im]ᵀ[Re Im].
    let sxx: f64 = shape.iter().map(|v| v.re * v.re).sum();
    let syy: f64 = shape.iter().map(|v| v.im * v.im).sum();
    let sxy: f64 = shape.iter().map(|v| v.re * v.im).sum();
    let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let (ux, uy) = (theta.cos(), theta.sin());
    shape
        .iter()
        .map(|v| {
            let r = v.norm();
            if r > 0.0 {
                let c = ((v.re * ux + v.im * uy).abs() / r).min(1.0);
                r * c.acos().to_degrees()
            } else {
                0.0
            }
        })
        .sum::<f64>()
        / total
}

/// The complex mode indicator function: per line of `data`, its singular values (descending),
/// at most `count` of them.
pub fn cmif(data: &ModalData, count: usize) -> Vec<Vec<f64>> {
    let (no, nr) = (data.outputs, data.references);
    (0..data.lines())
        .map(|k| {
            let m = DMatrix::<C64>::from_fn(no, nr, |o, r| data.frf(o, r)[k]);
            let mut sv: Vec<f64> = m.singular_values().iter().copied().collect();
            sv.sort_by(|a, b| b.total_cmp(a));
            sv.truncate(count);
            sv
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::modal::FrfKind;

    #[test]
    fn a_real_mode_is_collinear_and_a_wave_is_not() {
        let rot = C64::from_polar(1.0, 0.7);
        let real: Vec<C64> = [0.3, -1.0, 0.6, 0.1]
            .iter()
            .map(|&v| C64::new(v, 0.0) * rot)
            .collect();
        let q = shape_quality(&real);
        assert!(
            (q.mpc - 1.0).abs() < 1e-12 && q.mpd_deg < 1e-6 && q.mcf < 1e-12,
            "{q:?}"
        );
        // Four components a quarter turn apart (a travelling wave).
        let wave: Vec<C64> = (0..4)
            .map(|k| C64::from_polar(1.0, k as f64 * std::f64::consts::FRAC_PI_2))
            .collect();
        let q = shape_quality(&wave);
        assert!(q.mpc < 1e-12 && (q.mcf - 1.0).abs() < 1e-12, "{q:?}");
        // Half of the components on the line, half at 90°: mean deviation 45°.
        assert!((q.mpd_deg - 45.0).abs() < 1e-9, "{q:?}");
        // Components at 0°, 0° and 30° of equal magnitude: the best line lies at
        // θ = ½ atan2(2 s_xy, s_xx − s_yy) with s_xx = 2 + cos²30°, s_yy = sin²30°,
        // s_xy = cos30° sin30°, and the deviations are θ, θ, 30° − θ.
        let mut tilted = vec![C64::new(1.0, 0.0); 3];
        let t = 30f64.to_radians();
        tilted[2] = C64::from_polar(1.0, t);
        let theta = 0.5 * (2.0 * t.cos() * t.sin()).atan2(2.0 + t.cos().powi(2) - t.sin().powi(2));
        let expected = (theta.to_degrees() + 30.0) / 3.0;
        let d = mpd_deg(&tilted);
        assert!((d - expected).abs() < 1e-9, "{d} vs {expected}");
    }

    #[test]
    fn cmif_of_a_rank_one_matrix_has_one_value() {
        let freqs = vec![1.0, 2.0];
        let (u, v) = ([1.0, 2.0, 2.0], [3.0, 4.0]);
        let h: Vec<C64> = (0..3)
            .flat_map(|o| (0..2).flat_map(move |r| [C64::new(u[o] * v[r], 0.0); 2]))
            .collect();
        let data = ModalData::new(freqs, 3, 2, h, FrfKind::Receptance).unwrap();
        let c = cmif(&data, 2);
        assert!(
            (c[0][0] - 15.0).abs() < 1e-12 && c[0][1].abs() < 1e-12,
            "{c:?}"
        );
    }
}
