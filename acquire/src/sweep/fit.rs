//! Least-squares sine fit at a known frequency, I/O free and allocation free per block: the live
//! amplitude/phase estimate of each channel during a stepped-sine step.

use num_complex::Complex;

/// Fit result of one channel: `x(t) ≈ Re{amplitude · e^{jωt}} + offset`, `t = sample / fs`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SineEstimate {
    /// Complex amplitude (peak, in the samples' unit).
    pub amplitude: Complex<f64>,
    /// Constant offset.
    pub offset: f64,
    /// 1 − residual variance / signal variance (1 = perfect sine, 0 = noise only).
    pub quality: f64,
}

/// Accumulates the normal equations of `a cos ωt + b sin ωt + c` for several channels sampled
/// together.
#[derive(Debug, Clone)]
pub struct SineFit {
    omega_per_sample: f64,
    /// Σ over samples of [cc, cs, c, ss, s, 1].
    m: [f64; 6],
    /// Per channel Σ [x c, x s, x, x²].
    rhs: Vec<[f64; 4]>,
}

impl SineFit {
    /// A fit at `freq_hz` for `channels` channels sampled at `fs` (Hz).
    pub fn new(freq_hz: f64, fs: f64, channels: usize) -> Self {
        SineFit { omega_per_sample: 2.0 * std::f64::consts::PI * freq_hz / fs, m: [0.0; 6], rhs: vec![[0.0; 4]; channels] }
    }

    /// Samples added so far.
    pub fn samples(&self) -> u64 {
        self.m[5] as u64
    }

    /// Adds one sample of every channel at absolute sample index `n` (interleaved values).
    pub fn push(&mut self, n: u64, values: impl IntoIterator<Item = f64>) {
        // Reduce the phase argument to keep precision for large n.
        let ph = (n as f64 * self.omega_per_sample) % (2.0 * std::f64::consts::PI);
        let (s, c) = ph.sin_cos();
        self.m[0] += c * c;
        self.m[1] += c * s;
        self.m[2] += c;
        self.m[3] += s * s;
        self.m[4] += s;
        self.m[5] += 1.0;
        for (r, x) in self.rhs.iter_mut().zip(values) {
            r[0] += x * c;
            r[1] += x * s;
            r[2] += x;
            r[3] += x * x;
        }
    }

    /// Solves for every channel; `None` if the window is too short to separate cos, sin and offset.
    pub fn solve(&self) -> Option<Vec<SineEstimate>> {
        let [cc, cs, c1, ss, s1, n] = self.m;
        let a = [[cc, cs, c1], [cs, ss, s1], [c1, s1, n]];
        let det = det3(&a);
        if !(det.abs() > 1e-9 * n.powi(3).max(1.0)) {
            return None;
        }
        Some(
            self.rhs
                .iter()
                .map(|r| {
                    let b = [r[0], r[1], r[2]];
                    let mut sol = [0.0; 3];
                    for (k, s) in sol.iter_mut().enumerate() {
                        let mut ak = a;
                        for row in 0..3 {
                            ak[row][k] = b[row];
                        }
                        *s = det3(&ak) / det;
                    }
                    let [ca, cb, off] = sol;
                    // Residual sum of squares = Σx² − solᵀ b (normal equations).
                    let ssr = (r[3] - (ca * b[0] + cb * b[1] + off * b[2])).max(0.0);
                    let mean = r[2] / n;
                    let sst = (r[3] - n * mean * mean).max(0.0);
                    let quality = if sst > 0.0 { (1.0 - ssr / sst).clamp(0.0, 1.0) } else { 0.0 };
                    // a cos + b sin = Re{(a − jb) e^{jωt}}
                    SineEstimate { amplitude: Complex::new(ca, -cb), offset: off, quality }
                })
                .collect(),
        )
    }
}

fn det3(a: &[[f64; 3]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn recovers_amplitude_phase_and_offset_with_non_integer_cycles() {
        let fs = 5120.0;
        let f = 37.3;
        let want = Complex::from_polar(2.5, 0.7);
        let mut fit = SineFit::new(f, fs, 2);
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let noise = Normal::new(0.0, 0.05).unwrap();
        for n in 1000..(1000 + 3001u64) {
            let t = n as f64 / fs;
            let x = (want * Complex::from_polar(1.0, 2.0 * std::f64::consts::PI * f * t)).re + 0.3;
            fit.push(n, [x, x + noise.sample(&mut rng)]);
        }
        let r = fit.solve().unwrap();
        assert!((r[0].amplitude - want).norm() < 1e-9, "{:?}", r[0]);
        assert!((r[0].offset - 0.3).abs() < 1e-9);
        assert!(r[0].quality > 0.999_999);
        // With noise σ = 0.05 over 3001 samples, the amplitude error is ~σ·sqrt(2/N) ≈ 1.3e-3.
        assert!((r[1].amplitude - want).norm() < 6e-3, "{:?}", r[1]);
        assert!(r[1].quality < 0.9999 && r[1].quality > 0.99);
    }

    #[test]
    fn too_short_window_is_refused() {
        let mut fit = SineFit::new(1.0, 1000.0, 1);
        fit.push(0, [1.0]);
        fit.push(1, [1.0]);
        assert!(fit.solve().is_none());
    }
}
