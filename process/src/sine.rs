//! Stepped-sine estimation: per frequency step, drop the settling time, then fit
//! `x(t) = c₀ + Σ_h Re(X_h e^{j h ω t})` (DC, fundamental, optional harmonics) by least squares at
//! the known frequency, for the force and every response channel.
//!
//! Time `t` is counted from the first sample of the step record (before settling is dropped),
//! so phases of all channels share one reference. The FRF of a step is `Y₁/F₁`.

use num_complex::Complex;

use crate::error::{invalid, ProcessError, Result};

type C64 = Complex<f64>;

/// Settings of the sine fit.
#[derive(Debug, Clone, PartialEq)]
pub struct SineConfig {
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Time dropped at the start of each step while the structure settles (s).
    pub settle_s: f64,
    /// Harmonics fitted beyond the fundamental (0: none; 2: 2f and 3f). Harmonics at or above
    /// Nyquist are not fitted.
    pub harmonics: usize,
}

/// Fit of one channel at one step.
#[derive(Debug, Clone, PartialEq)]
pub struct SineFit {
    /// Mean value (channel unit).
    pub dc: f64,
    /// Complex amplitude of the fundamental: amplitude = |X|, phase = arg X (rad), channel unit.
    pub fundamental: C64,
    /// Complex amplitudes of harmonics 2, 3, ... that were fitted.
    pub harmonics: Vec<C64>,
    /// Total harmonic distortion `√(Σ|X_h|²)/|X₁|` (0 when no harmonics fitted).
    pub distortion: f64,
    /// RMS of the fit residual (channel unit): the step's noise level.
    pub noise_rms: f64,
}

impl SineFit {
    /// Amplitude of the fundamental.
    pub fn amplitude(&self) -> f64 {
        self.fundamental.norm()
    }
    /// Phase of the fundamental (rad).
    pub fn phase_rad(&self) -> f64 {
        self.fundamental.arg()
    }
    /// Signal-to-noise ratio of the fundamental: `(|X₁|/√2) / noise_rms` (∞ if noise-free).
    pub fn snr(&self) -> f64 {
        self.amplitude() / std::f64::consts::SQRT_2 / self.noise_rms
    }
}

/// Result of one frequency step.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Excitation frequency (Hz).
    pub freq_hz: f64,
    /// Force fit.
    pub force: SineFit,
    /// Fit of each response channel.
    pub responses: Vec<SineFit>,
    /// FRF of each response: `Y₁/F₁` (response unit per force unit).
    pub frf: Vec<C64>,
    /// Samples used per channel after settling.
    pub samples: usize,
}

impl Step {
    /// Variance of the complex FRF estimate of response `j` (E|Ĥ−H|², (unit/N)²), from the fit
    /// residuals: each complex amplitude fitted from N samples with white noise σ² has
    /// E|X̂−X|² = 4σ²/N, so `var(H) ≈ 4(σ_y² + |H|² σ_f²) / (N |F|²)` (first order).
    pub fn variance(&self, j: usize) -> Option<f64> {
        let r = self.responses.get(j)?;
        let h = self.frf.get(j)?;
        let n = self.samples as f64;
        Some(
            4.0 * (r.noise_rms.powi(2) + h.norm_sqr() * self.force.noise_rms.powi(2))
                / (n * self.force.fundamental.norm_sqr()),
        )
    }
}

/// Reusable least-squares sine fitter (basis and normal-equation buffers are kept between steps).
#[derive(Debug, Default)]
pub struct SineFitter {
    basis: Vec<f64>,
    gram: Vec<f64>,
    rhs: Vec<f64>,
}

impl SineFitter {
    /// New fitter with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Fits one step: `force` and each of `responses` are the samples of the step (same length).
    pub fn fit_step(
        &mut self,
        config: &SineConfig,
        freq_hz: f64,
        force: &[f64],
        responses: &[&[f64]],
    ) -> Result<Step> {
        check_step(config, freq_hz, force, responses)?;
        let layout = self.factor_basis(config, freq_hz, force.len())?;
        let f = self.fit_channel(&layout, force, "force")?;
        if f.amplitude() == 0.0 {
            return Err(ProcessError::ZeroForce {
                channel: format!("force at step {freq_hz} Hz"),
            });
        }
        let mut rs = Vec::with_capacity(responses.len());
        for (j, r) in responses.iter().enumerate() {
            rs.push(self.fit_channel(&layout, r, &format!("response {j}"))?);
        }
        let frf = rs.iter().map(|r| r.fundamental / f.fundamental).collect();
        Ok(Step {
            freq_hz,
            force: f,
            responses: rs,
            frf,
            samples: layout.used,
        })
    }

    /// Builds the sine basis (DC and `nh` harmonics below Nyquist) over the samples after
    /// settling, and Cholesky-factors its Gram matrix once for all channels of the step.
    fn factor_basis(&mut self, config: &SineConfig, freq_hz: f64, len: usize) -> Result<Basis> {
        let fs = config.sample_rate_hz;
        let skip = (config.settle_s * fs).ceil() as usize;
        let per_period = fs / freq_hz;
        let used = len.saturating_sub(skip);
        if (used as f64) < per_period.max(8.0) {
            return Err(ProcessError::TooShort {
                channel: format!("step at {freq_hz} Hz"),
                samples: used,
                needed: per_period.max(8.0).ceil() as usize + skip,
            });
        }
        let nh = (1..=1 + config.harmonics)
            .take_while(|h| *h as f64 * freq_hz < fs / 2.0)
            .count();
        let m = 1 + 2 * nh;
        self.basis.clear();
        self.basis.resize(used * m, 0.0);
        let w = 2.0 * std::f64::consts::PI * freq_hz / fs;
        for i in 0..used {
            let n = (skip + i) as f64;
            let row = &mut self.basis[i * m..(i + 1) * m];
            row[0] = 1.0;
            for h in 0..nh {
                let (s, c) = (w * (h + 1) as f64 * n).sin_cos();
                row[1 + 2 * h] = c;
                row[2 + 2 * h] = s;
            }
        }
        // Gram matrix, Cholesky-factored once for all channels of the step.
        self.gram.clear();
        self.gram.resize(m * m, 0.0);
        for i in 0..used {
            let row = &self.basis[i * m..(i + 1) * m];
            for a in 0..m {
                for b in 0..=a {
                    self.gram[a * m + b] += row[a] * row[b];
                }
            }
        }
        if !cholesky(&mut self.gram, m) {
            return Err(ProcessError::TooShort {
                channel: format!("step at {freq_hz} Hz (sine basis is ill-conditioned)"),
                samples: used,
                needed: 2 * per_period.ceil() as usize + skip,
            });
        }
        Ok(Basis { skip, used, nh, m })
    }

    /// Least-squares fit of one channel's samples `x` (after settling) on the factored basis.
    fn fit_channel(&mut self, layout: &Basis, x: &[f64], name: &str) -> Result<SineFit> {
        let Basis { skip, used, nh, m } = *layout;
        let x = &x[skip..];
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(ProcessError::NonFinite {
                channel: name.to_string(),
                index: (skip + i) as u64,
                value: x[i],
            });
        }
        self.rhs.clear();
        self.rhs.resize(m, 0.0);
        for (i, xi) in x.iter().enumerate() {
            let row = &self.basis[i * m..(i + 1) * m];
            for (r, b) in self.rhs.iter_mut().zip(row) {
                *r += b * xi;
            }
        }
        cholesky_solve(&self.gram, &mut self.rhs, m);
        let mut ss = 0.0;
        for (i, xi) in x.iter().enumerate() {
            let row = &self.basis[i * m..(i + 1) * m];
            let model: f64 = row.iter().zip(&self.rhs).map(|(a, b)| a * b).sum();
            ss += (xi - model).powi(2);
        }
        // x = a cos + b sin = Re((a − jb) e^{jωt}).
        let ph = |h: usize| C64::new(self.rhs[1 + 2 * h], -self.rhs[2 + 2 * h]);
        let fundamental = ph(0);
        let harmonics: Vec<C64> = (1..nh).map(ph).collect();
        let hp: f64 = harmonics.iter().map(|c| c.norm_sqr()).sum();
        let distortion = if hp == 0.0 {
            0.0
        } else {
            hp.sqrt() / fundamental.norm()
        };
        let dof = (used - m).max(1) as f64;
        Ok(SineFit {
            dc: self.rhs[0],
            fundamental,
            harmonics,
            distortion,
            noise_rms: (ss / dof).sqrt(),
        })
    }
}

/// Where one step of a stepped-sine record lies.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSpec {
    /// Excitation frequency (Hz).
    pub freq_hz: f64,
    /// First sample of the step in the record.
    pub start: usize,
    /// Samples in the step (settling included).
    pub len: usize,
}

impl SineFitter {
    /// Fits every step of a continuous stepped-sine record (force and responses sampled
    /// together). Each step's phases are referred to its own first sample; FRFs are unaffected.
    pub fn fit_sweep(
        &mut self,
        config: &SineConfig,
        steps: &[StepSpec],
        force: &[f64],
        responses: &[&[f64]],
    ) -> Result<Vec<Step>> {
        check_lengths(force, responses)?;
        let mut out = Vec::with_capacity(steps.len());
        let mut slices: Vec<&[f64]> = Vec::with_capacity(responses.len());
        for (i, s) in steps.iter().enumerate() {
            let end = s
                .start
                .checked_add(s.len)
                .filter(|e| *e <= force.len())
                .ok_or_else(|| ProcessError::TooShort {
                    channel: format!(
                        "record (step {i} at {} Hz ends at sample {})",
                        s.freq_hz,
                        s.start.saturating_add(s.len)
                    ),
                    samples: force.len(),
                    needed: s.start.saturating_add(s.len),
                })?;
            slices.clear();
            slices.extend(responses.iter().map(|r| &r[s.start..end]));
            out.push(self.fit_step(config, s.freq_hz, &force[s.start..end], &slices)?);
        }
        Ok(out)
    }
}

/// The sine basis of one step: samples skipped while settling, samples used, harmonics, and
/// basis functions (1 + 2·harmonics).
#[derive(Debug, Clone, Copy)]
struct Basis {
    skip: usize,
    used: usize,
    nh: usize,
    m: usize,
}

/// A valid sample rate, step frequency (below Nyquist) and settling time, and responses as long
/// as the force.
fn check_step(
    config: &SineConfig,
    freq_hz: f64,
    force: &[f64],
    responses: &[&[f64]],
) -> Result<()> {
    let fs = config.sample_rate_hz;
    if !(fs.is_finite() && fs > 0.0) {
        return Err(invalid(
            "sample_rate_hz",
            fs,
            "must be a positive number of Hz",
        ));
    }
    if !(freq_hz.is_finite() && freq_hz > 0.0 && freq_hz < fs / 2.0) {
        return Err(invalid(
            "step frequency",
            freq_hz,
            format!("must lie in (0, {}) Hz (below Nyquist)", fs / 2.0),
        ));
    }
    if !(config.settle_s.is_finite() && config.settle_s >= 0.0) {
        return Err(invalid("settle_s", config.settle_s, "must be ≥ 0 s"));
    }
    check_lengths(force, responses)
}

/// Every response has as many samples as the force.
fn check_lengths(force: &[f64], responses: &[&[f64]]) -> Result<()> {
    for (j, r) in responses.iter().enumerate() {
        if r.len() != force.len() {
            return Err(ProcessError::LengthMismatch {
                channel: format!("response {j}"),
                samples: r.len(),
                first: "force".into(),
                expected: force.len(),
            });
        }
    }
    Ok(())
}

/// In-place lower Cholesky of a symmetric positive definite m×m matrix (lower triangle used).
fn cholesky(a: &mut [f64], m: usize) -> bool {
    let scale = (0..m).map(|i| a[i * m + i]).fold(0.0, f64::max);
    for j in 0..m {
        let mut d = a[j * m + j];
        for k in 0..j {
            d -= a[j * m + k] * a[j * m + k];
        }
        if d.is_nan() || d <= 1e-12 * scale {
            return false;
        }
        let d = d.sqrt();
        a[j * m + j] = d;
        for i in j + 1..m {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= a[i * m + k] * a[j * m + k];
            }
            a[i * m + j] = s / d;
        }
    }
    true
}

fn cholesky_solve(l: &[f64], b: &mut [f64], m: usize) {
    for i in 0..m {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * m + k] * b[k];
        }
        b[i] = s / l[i * m + i];
    }
    for i in (0..m).rev() {
        let mut s = b[i];
        for k in i + 1..m {
            s -= l[k * m + i] * b[k];
        }
        b[i] = s / l[i * m + i];
    }
}
