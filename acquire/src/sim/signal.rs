//! The simulated DAQ's signals, I/O free: each channel's samples from the commanded excitation
//! through the shaker interaction and the truth plant, plus sensor noise, quantised to ADC counts.

use std::sync::Arc;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use rustfft::FftPlanner;

use super::plant::{Interaction, Plant, PlantError, C64};
use crate::shaker::scpi::Function;

/// ADC: 24 bits over ±10 V.
pub const VOLTS_PER_COUNT: f64 = 10.0 / 8_388_608.0;
const MAX_COUNT: f64 = 8_388_607.0;

/// What the simulated shaker controller currently drives (shared with the simulated DAQ).
#[derive(Debug, Clone, PartialEq)]
pub struct Excitation {
    /// Output on.
    pub output_on: bool,
    /// Waveform.
    pub function: Function,
    /// Sine frequency (Hz).
    pub freq_hz: f64,
    /// Commanded force: peak (sine, chirp) or RMS (random, burst) (N).
    pub force_n: f64,
    /// Band (Hz) of random, burst and chirp.
    pub band_hz: (f64, f64),
    /// Burst duty cycle (0-1).
    pub duty: f64,
    /// Period of the broadband waveforms (s).
    pub period_s: f64,
    /// An arbitrary waveform a signal generator plays (looping); when set, it is the drive
    /// (`force_n` is then the force at full scale) and `function` is ignored unless it is a sine.
    pub arbitrary: Option<Arc<ArbitraryDrive>>,
}

/// Samples a simulated signal generator plays, repeated.
#[derive(Debug, Clone, PartialEq)]
pub struct ArbitraryDrive {
    /// One period, −1..1 (full scale).
    pub samples: Vec<f64>,
    /// Rate they are played at (Sa/s).
    pub sample_rate_hz: f64,
}

impl Default for Excitation {
    fn default() -> Self {
        Excitation {
            output_on: false,
            function: Function::Sine,
            freq_hz: 100.0,
            force_n: 0.0,
            band_hz: (10.0, 500.0),
            duty: 0.5,
            period_s: 1.0,
            arbitrary: None,
        }
    }
}

/// Where a simulated channel's signal comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// The delivered force (N).
    Force,
    /// Sensor `i` of the plant.
    Sensor(usize),
}

/// One simulated DAQ input.
#[derive(Debug, Clone, PartialEq)]
pub struct SimChannel {
    /// Device channel number.
    pub device_channel: u16,
    /// Signal.
    pub source: Source,
    /// V per physical unit.
    pub sensitivity: f64,
    /// Noise RMS in the physical unit.
    pub noise_rms: f64,
}

struct Periodic {
    key: (u8, u64, u64, u64, u64, u64),
    arbitrary: Option<Arc<ArbitraryDrive>>,
    /// Per channel, one period of the physical signal per newton of command.
    data: Vec<Vec<f64>>,
}

/// Generates the DAQ's sample stream.
pub struct SignalGenerator {
    fs: f64,
    plant: Arc<dyn Plant>,
    interaction: Interaction,
    channels: Vec<SimChannel>,
    sample: u64,
    phase: f64,
    sine_cache: Option<(f64, Vec<C64>)>,
    periodic: Option<Periodic>,
    rng: rand::rngs::StdRng,
    buf: Vec<f64>,
}

impl SignalGenerator {
    /// A generator at `fs` (Hz) for `channels`; `seed` seeds the noise.
    pub fn new(
        fs: f64,
        plant: Arc<dyn Plant>,
        interaction: Interaction,
        channels: Vec<SimChannel>,
        seed: u64,
    ) -> Self {
        SignalGenerator {
            fs,
            plant,
            interaction,
            channels,
            sample: 0,
            phase: 0.0,
            sine_cache: None,
            periodic: None,
            rng: rand::rngs::StdRng::seed_from_u64(seed),
            buf: Vec::new(),
        }
    }

    /// Restarts the sample clock (on START).
    pub fn restart(&mut self) {
        self.sample = 0;
    }

    /// Sample rate (Hz).
    pub fn sample_rate(&self) -> f64 {
        self.fs
    }

    /// Channel descriptions.
    pub fn channels(&self) -> &[SimChannel] {
        &self.channels
    }

    /// Each channel's complex amplitude per commanded newton of a sine at `f` (Hz).
    pub fn sine_coefficients(&self, f: f64) -> Result<Vec<C64>, PlantError> {
        let g = self.interaction.at(f);
        let h = self.plant.response(&[f])?;
        let h = h.into_iter().next().unwrap_or_default();
        Ok(self
            .channels
            .iter()
            .map(|c| match c.source {
                Source::Force => g,
                Source::Sensor(i) => g * h.get(i).copied().unwrap_or_default(),
            })
            .collect())
    }

    /// Appends `n` samples of every channel (interleaved sample-major) as ADC counts to `out`.
    pub fn block(
        &mut self,
        exc: &Excitation,
        n: usize,
        out: &mut Vec<i32>,
    ) -> Result<(), PlantError> {
        let nch = self.channels.len();
        self.buf.clear();
        self.buf.resize(n * nch, 0.0);
        let amp = if exc.output_on { exc.force_n } else { 0.0 };
        match exc.function {
            Function::Sine => {
                if self.sine_cache.as_ref().map(|(f, _)| *f) != Some(exc.freq_hz) {
                    let c = self.sine_coefficients(exc.freq_hz)?;
                    self.sine_cache = Some((exc.freq_hz, c));
                }
                let coef = self
                    .sine_cache
                    .as_ref()
                    .map(|(_, c)| c.clone())
                    .unwrap_or_default();
                let dphi = 2.0 * std::f64::consts::PI * exc.freq_hz / self.fs;
                for i in 0..n {
                    let e = C64::from_polar(1.0, self.phase);
                    for (c, k) in coef.iter().enumerate() {
                        self.buf[i * nch + c] = amp * (k * e).re;
                    }
                    self.phase = (self.phase + dphi) % (2.0 * std::f64::consts::PI);
                }
            }
            _ => {
                self.ensure_periodic(exc)?;
                if let Some(p) = &self.periodic {
                    let len = p.data.first().map(|d| d.len()).unwrap_or(1).max(1);
                    for i in 0..n {
                        let k = ((self.sample + i as u64) % len as u64) as usize;
                        for c in 0..nch {
                            self.buf[i * nch + c] = amp * p.data[c][k];
                        }
                    }
                }
            }
        }
        self.sample += n as u64;
        out.reserve(n * nch);
        for i in 0..n {
            for (c, ch) in self.channels.iter().enumerate() {
                let mut x = self.buf[i * nch + c];
                if ch.noise_rms > 0.0 {
                    if let Ok(d) = Normal::new(0.0, ch.noise_rms) {
                        x += d.sample(&mut self.rng);
                    }
                }
                let counts = (x * ch.sensitivity / VOLTS_PER_COUNT)
                    .round()
                    .clamp(-MAX_COUNT, MAX_COUNT);
                out.push(counts as i32);
            }
        }
        Ok(())
    }

    fn ensure_periodic(&mut self, exc: &Excitation) -> Result<(), PlantError> {
        let key = (
            exc.function as u8,
            exc.band_hz.0.to_bits(),
            exc.band_hz.1.to_bits(),
            exc.duty.to_bits(),
            exc.period_s.to_bits(),
            self.fs.to_bits(),
        );
        let same_arbitrary = |p: &Periodic| match (&p.arbitrary, &exc.arbitrary) {
            (None, None) => true,
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        if self
            .periodic
            .as_ref()
            .is_some_and(|p| p.key == key && same_arbitrary(p))
        {
            return Ok(());
        }
        let period_s = match &exc.arbitrary {
            Some(a) => a.samples.len() as f64 / a.sample_rate_hz,
            None => exc.period_s,
        };
        let n = ((period_s * self.fs).round() as usize).clamp(64, 1 << 20);
        let (lo, hi) = (
            exc.band_hz.0.min(exc.band_hz.1),
            exc.band_hz.0.max(exc.band_hz.1),
        );
        let df = self.fs / n as f64;
        let mut planner = FftPlanner::<f64>::new();
        let fft = planner.plan_fft_forward(n);
        let ifft = planner.plan_fft_inverse(n);
        // Commanded waveform per newton (RMS for random/burst, peak for chirp, full scale for an
        // arbitrary waveform).
        let mut u: Vec<C64> = match exc.function {
            _ if exc.arbitrary.is_some() => {
                let a = exc.arbitrary.as_deref().map(|a| a.samples.as_slice());
                played(a.unwrap_or_default(), n, &mut planner)
            }
            Function::Random | Function::Burst => {
                let mut spec = vec![C64::new(0.0, 0.0); n];
                let mut rng = rand::rngs::StdRng::seed_from_u64(0x5eed ^ n as u64);
                let uni = rand_distr::Uniform::new(0.0, 2.0 * std::f64::consts::PI)
                    .map_err(|e| PlantError(e.to_string()))?;
                for (k, s) in spec.iter_mut().enumerate().take(n / 2).skip(1) {
                    let f = k as f64 * df;
                    if f >= lo && f <= hi {
                        *s = C64::from_polar(1.0, uni.sample(&mut rng));
                    }
                    let _ = k;
                }
                for k in 1..n / 2 {
                    spec[n - k] = spec[k].conj();
                }
                ifft.process(&mut spec);
                let mut x: Vec<f64> = spec.iter().map(|c| c.re).collect();
                let on = if exc.function == Function::Burst {
                    ((exc.duty.clamp(0.0, 1.0)) * n as f64) as usize
                } else {
                    n
                };
                for v in x.iter_mut().skip(on) {
                    *v = 0.0;
                }
                let rms = (x.iter().take(on).map(|v| v * v).sum::<f64>() / on.max(1) as f64).sqrt();
                let s = if rms > 0.0 { 1.0 / rms } else { 0.0 };
                x.iter().map(|v| C64::new(v * s, 0.0)).collect()
            }
            _ => {
                let t_end = n as f64 / self.fs;
                (0..n)
                    .map(|i| {
                        let t = i as f64 / self.fs;
                        let ph = 2.0
                            * std::f64::consts::PI
                            * (lo * t + (hi - lo) * t * t / (2.0 * t_end));
                        C64::new(ph.sin(), 0.0)
                    })
                    .collect()
            }
        };
        fft.process(&mut u);
        let freqs: Vec<f64> = (0..=n / 2).map(|k| k as f64 * df).collect();
        // The structure's response only where the drive has energy (a band-limited drive leaves
        // most lines empty, and the truth model's response is the expensive part).
        let peak = u
            .iter()
            .take(n / 2 + 1)
            .fold(0.0_f64, |m, c| m.max(c.norm()));
        let driven: Vec<usize> = (0..=n / 2)
            .filter(|&k| u[k].norm() > 1e-12 * peak)
            .collect();
        let at: Vec<f64> = driven.iter().map(|&k| freqs[k]).collect();
        let mut h = vec![Vec::new(); n / 2 + 1];
        for (k, r) in driven.iter().zip(self.plant.response(&at)?) {
            h[*k] = r;
        }
        let mut data = Vec::with_capacity(self.channels.len());
        for ch in &self.channels {
            let mut y = vec![C64::new(0.0, 0.0); n];
            for k in 0..=n / 2 {
                let g = self.interaction.at(freqs[k]);
                let coef = match ch.source {
                    Source::Force => g,
                    Source::Sensor(i) => g * h[k].get(i).copied().unwrap_or_default(),
                };
                y[k] = u[k] * coef;
                if k > 0 && k < n - k {
                    y[n - k] = y[k].conj();
                }
            }
            ifft.process(&mut y);
            data.push(y.iter().map(|c| c.re / n as f64).collect());
        }
        self.periodic = Some(Periodic {
            key,
            arbitrary: exc.arbitrary.clone(),
            data,
        });
        Ok(())
    }
}

/// What a DAC playing `samples` (one period) and its reconstruction filter put out, sampled `n`
/// times over the same period: the samples' own Fourier series, band-limited to the lower of the
/// two Nyquist frequencies (the identity when `n` is the number of samples).
fn played(samples: &[f64], n: usize, planner: &mut FftPlanner<f64>) -> Vec<C64> {
    let m = samples.len();
    if m == 0 {
        return vec![C64::new(0.0, 0.0); n];
    }
    let mut spec: Vec<C64> = samples.iter().map(|x| C64::new(*x, 0.0)).collect();
    planner.plan_fft_forward(m).process(&mut spec);
    let mut out = vec![C64::new(0.0, 0.0); n];
    let half = m.min(n).div_ceil(2);
    let scale = 1.0 / m as f64;
    out[0] = spec[0] * scale;
    for k in 1..half {
        out[k] = spec[k] * scale;
        out[n - k] = out[k].conj();
    }
    if m == n && m.is_multiple_of(2) {
        out[m / 2] = spec[m / 2] * scale;
    }
    planner.plan_fft_inverse(n).process(&mut out);
    out.iter().map(|c| C64::new(c.re, 0.0)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::plant::SdofPlant;

    fn gen(noise: f64) -> SignalGenerator {
        let plant = Arc::new(SdofPlant {
            mass: 100.0,
            stiffness: 4e7,
            loss_factor: 0.05,
            gains: vec![1.0],
        });
        SignalGenerator::new(
            4096.0,
            plant,
            Interaction {
                gain: 0.9,
                cutoff_hz: 300.0,
            },
            vec![
                SimChannel {
                    device_channel: 0,
                    source: Source::Force,
                    sensitivity: 1e-3,
                    noise_rms: noise,
                },
                SimChannel {
                    device_channel: 1,
                    source: Source::Sensor(0),
                    sensitivity: 0.01,
                    noise_rms: 0.0,
                },
            ],
            3,
        )
    }

    #[test]
    fn sine_block_has_the_delivered_force_amplitude() {
        let mut g = gen(0.0);
        let exc = Excitation {
            output_on: true,
            freq_hz: 64.0,
            force_n: 1000.0,
            ..Default::default()
        };
        let mut out = Vec::new();
        g.block(&exc, 4096, &mut out).unwrap();
        let peak = out
            .iter()
            .step_by(2)
            .map(|c| (*c as f64 * VOLTS_PER_COUNT / 1e-3).abs())
            .fold(0.0, f64::max);
        let want = 1000.0
            * Interaction {
                gain: 0.9,
                cutoff_hz: 300.0,
            }
            .at(64.0)
            .norm();
        assert!((peak - want).abs() < 1e-3 * want, "{peak} vs {want}");
    }

    #[test]
    fn output_off_gives_only_noise() {
        let mut g = gen(2.0);
        let mut out = Vec::new();
        g.block(&Excitation::default(), 8192, &mut out).unwrap();
        let f: Vec<f64> = out
            .iter()
            .step_by(2)
            .map(|c| *c as f64 * VOLTS_PER_COUNT / 1e-3)
            .collect();
        let rms = (f.iter().map(|x| x * x).sum::<f64>() / f.len() as f64).sqrt();
        assert!((rms - 2.0).abs() < 0.1, "{rms}");
        assert!(out.iter().skip(1).step_by(2).all(|c| *c == 0));
    }

    #[test]
    fn an_arbitrary_waveform_is_played_sample_for_sample_and_looped() {
        let mut g = gen(0.0);
        let samples: Vec<f64> = (0..2048)
            .map(|i| (2.0 * std::f64::consts::PI * 37.0 * i as f64 / 2048.0).sin())
            .collect();
        let exc = Excitation {
            output_on: true,
            function: Function::Random,
            force_n: 100.0,
            arbitrary: Some(Arc::new(ArbitraryDrive {
                samples: samples.clone(),
                sample_rate_hz: 2048.0,
            })),
            ..Default::default()
        };
        // Played at half the DAQ's rate: one period (1 s) is 4096 DAQ samples, and the 37 cycles
        // in it are a 37 Hz sine.
        let mut out = Vec::new();
        g.block(&exc, 8192, &mut out).unwrap();
        let force: Vec<f64> = out
            .iter()
            .step_by(2)
            .map(|c| *c as f64 * VOLTS_PER_COUNT / 1e-3)
            .collect();
        let want = 100.0
            * Interaction {
                gain: 0.9,
                cutoff_hz: 300.0,
            }
            .at(37.0)
            .norm();
        let peak = force.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!((peak - want).abs() < 1e-3 * want, "{peak} vs {want}");
        // Looping: the second period equals the first.
        for i in 0..4096 {
            assert!((force[i] - force[i + 4096]).abs() < 1e-3, "sample {i}");
        }
        let same = played(&samples, 2048, &mut FftPlanner::new());
        assert!(same
            .iter()
            .zip(&samples)
            .all(|(a, b)| (a.re - b).abs() < 1e-12));
    }

    #[test]
    fn periodic_random_has_requested_rms_and_frf() {
        let mut g = gen(0.0);
        let exc = Excitation {
            output_on: true,
            function: Function::Random,
            force_n: 100.0,
            band_hz: (20.0, 400.0),
            period_s: 1.0,
            ..Default::default()
        };
        let mut out = Vec::new();
        g.block(&exc, 4096, &mut out).unwrap();
        // The FRF of one period (sensor / force) equals the plant's accelerance at a bin in band.
        let n = 4096;
        let mut f: Vec<C64> = out
            .iter()
            .step_by(2)
            .map(|c| C64::new(*c as f64 * VOLTS_PER_COUNT / 1e-3, 0.0))
            .collect();
        let mut a: Vec<C64> = out
            .iter()
            .skip(1)
            .step_by(2)
            .map(|c| C64::new(*c as f64 * VOLTS_PER_COUNT / 0.01, 0.0))
            .collect();
        let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
        fft.process(&mut f);
        fft.process(&mut a);
        let k = 100; // 100 Hz at 1 Hz resolution
        let h = a[k] / f[k];
        let want = SdofPlant {
            mass: 100.0,
            stiffness: 4e7,
            loss_factor: 0.05,
            gains: vec![1.0],
        }
        .accelerance(100.0);
        assert!((h - want).norm() < 2e-3 * want.norm(), "{h} vs {want}");
    }
}
