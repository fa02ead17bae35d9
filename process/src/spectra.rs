//! Auto- and cross-spectral matrices by Welch's method, computed block by block with bounded
//! memory: the FFT is planned once and every buffer is allocated when the estimator is built.
//!
//! Conventions follow `scipy.signal.csd`: `G_xy = E[conj(X)·Y]`, one-sided, density scaling
//! `2/(fs·Σw²)` (DC and Nyquist not doubled), 'mean' averaging over full segments only.

use std::sync::Arc;

use num_complex::Complex;
use rustfft::{Fft, FftPlanner};

use crate::error::{check_count, invalid, ProcessError, Result};
use crate::window::Window;

type C64 = Complex<f64>;

/// Removal of a trend from each segment before windowing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Detrend {
    /// Leave the segment as it is (impact tests).
    None,
    /// Subtract the segment mean (scipy's default `'constant'`).
    #[default]
    Constant,
    /// Subtract the least-squares straight line of the segment (scipy `'linear'`).
    Linear,
}

/// `(mean, slope per sample)` of a segment's trend, the line centred at `(n−1)/2`.
fn trend(x: &[f64], detrend: Detrend) -> (f64, f64) {
    let n = x.len() as f64;
    match detrend {
        Detrend::None => (0.0, 0.0),
        Detrend::Constant => (x.iter().sum::<f64>() / n, 0.0),
        Detrend::Linear => {
            let mean = x.iter().sum::<f64>() / n;
            let c = (n - 1.0) / 2.0;
            let sxy: f64 = x
                .iter()
                .enumerate()
                .map(|(i, v)| (i as f64 - c) * (v - mean))
                .sum();
            let sxx = n * (n * n - 1.0) / 12.0;
            (mean, if sxx > 0.0 { sxy / sxx } else { 0.0 })
        }
    }
}

/// Settings of a Welch estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct WelchConfig {
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Samples per segment (FFT length).
    pub segment_len: usize,
    /// Samples shared by consecutive segments (< `segment_len`); half the segment is usual.
    pub overlap: usize,
    /// Window of the reference (force) channels.
    pub reference_window: Window,
    /// Window of the response channels. Spectral densities are scaled by this window's power.
    pub response_window: Window,
    /// Trend removal per segment.
    pub detrend: Detrend,
    /// Full-scale value of each channel (references first, then responses), in the channel's unit;
    /// samples with `|x| ≥ full scale` are counted as overloads. Empty: no overload check.
    pub full_scale: Vec<f64>,
}

impl WelchConfig {
    /// Same window on every channel, 50 % overlap, mean removal: the usual random-excitation set-up.
    pub fn new(sample_rate_hz: f64, segment_len: usize, window: Window) -> Self {
        WelchConfig {
            sample_rate_hz,
            segment_len,
            overlap: segment_len / 2,
            reference_window: window.clone(),
            response_window: window,
            detrend: Detrend::Constant,
            full_scale: Vec::new(),
        }
    }

    /// Impact-test set-up: one segment per hit (no overlap), force × exponential window on the
    /// hammer, exponential window on the responses, no trend removal.
    pub fn impact(
        sample_rate_hz: f64,
        segment_len: usize,
        force_width: f64,
        exponential_end: f64,
    ) -> Self {
        let exp = Window::Exponential {
            end: exponential_end,
        };
        WelchConfig {
            sample_rate_hz,
            segment_len,
            overlap: 0,
            reference_window: Window::Product(vec![
                Window::Force { width: force_width },
                exp.clone(),
            ]),
            response_window: exp,
            detrend: Detrend::None,
            full_scale: Vec::new(),
        }
    }
}

/// Averaged auto- and cross-spectra of `R` references (x) and `P` responses (y), density-scaled
/// (unit² / Hz), one-sided.
#[derive(Debug, Clone, PartialEq)]
pub struct CrossSpectra {
    /// Frequency of each line (Hz): `k·fs/N`, `k = 0..=N/2`.
    pub freqs_hz: Vec<f64>,
    /// Number of references R.
    pub references: usize,
    /// Number of responses P.
    pub responses: usize,
    /// Number of segments averaged.
    pub averages: u32,
    /// `G_xx[k][i][l] = E[conj(X_i) X_l]`, flattened `(k·R + i)·R + l`.
    pub gxx: Vec<C64>,
    /// `G_xy[k][i][j] = E[conj(X_i) Y_j]`, flattened `(k·R + i)·P + j`.
    pub gxy: Vec<C64>,
    /// `G_yy[k][j] = E[|Y_j|²]`, flattened `k·P + j`.
    pub gyy: Vec<f64>,
    /// Overloaded samples per channel (references first), when full scales were given.
    pub overloads: Vec<u64>,
    /// Per channel, samples (after the first of each sign) that sit exactly on the channel's
    /// largest positive or most negative value: a clipped channel piles samples up on its rails,
    /// an analog signal practically never repeats its extreme. See [`CrossSpectra::clipping_suspected`].
    pub peak_hits: Vec<u64>,
}

impl CrossSpectra {
    /// True if channel `c` (references first) looks clipped although no full scale was given:
    /// more than 4 samples repeat its extreme values exactly.
    pub fn clipping_suspected(&self, c: usize) -> bool {
        self.peak_hits.get(c).is_some_and(|h| *h > 4)
    }

    /// `G_xx[k][i][l]`.
    pub fn gxx(&self, k: usize, i: usize, l: usize) -> C64 {
        self.gxx[(k * self.references + i) * self.references + l]
    }
    /// `G_xy[k][i][j]`.
    pub fn gxy(&self, k: usize, i: usize, j: usize) -> C64 {
        self.gxy[(k * self.references + i) * self.responses + j]
    }
    /// `G_yy[k][j]`.
    pub fn gyy(&self, k: usize, j: usize) -> f64 {
        self.gyy[k * self.responses + j]
    }
}

/// Streaming Welch estimator: feed samples in blocks of any length with [`Welch::push`], then
/// [`Welch::finish`]. Memory is a few segments per channel, whatever the record length.
pub struct Welch {
    config: WelchConfig,
    names: Vec<String>,
    references: usize,
    responses: usize,
    fft: Arc<dyn Fft<f64>>,
    scratch: Vec<C64>,
    ref_window: Vec<f64>,
    resp_window: Vec<f64>,
    /// Per channel, the samples of the segment being filled.
    pending: Vec<Vec<f64>>,
    filled: usize,
    seen: u64,
    segments: u32,
    /// One FFT buffer per pair of channels.
    work: Vec<C64>,
    /// Spectrum of each channel for the current segment, `ch·nf + k`.
    spectra: Vec<C64>,
    acc_gxx: Vec<C64>,
    acc_gxy: Vec<C64>,
    acc_gyy: Vec<f64>,
    overloads: Vec<u64>,
    max_abs: Vec<f64>,
    /// Per channel: (largest value, repeats of it, smallest value, repeats of it).
    extremes: Vec<(f64, u64, f64, u64)>,
}

impl std::fmt::Debug for Welch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Welch")
            .field("config", &self.config)
            .field("channels", &self.names)
            .field("segments", &self.segments)
            .finish_non_exhaustive()
    }
}

impl Welch {
    /// Sets up an estimator for channels named `reference_names` (forces) and `response_names`.
    pub fn new(
        config: WelchConfig,
        reference_names: &[&str],
        response_names: &[&str],
    ) -> Result<Welch> {
        let n = config.segment_len;
        if n < 2 {
            return Err(invalid(
                "segment_len",
                n,
                "need at least 2 samples per segment",
            ));
        }
        if config.overlap >= n {
            return Err(invalid(
                "overlap",
                config.overlap,
                format!("must be smaller than the segment length {n}"),
            ));
        }
        if !(config.sample_rate_hz.is_finite() && config.sample_rate_hz > 0.0) {
            return Err(invalid(
                "sample_rate_hz",
                config.sample_rate_hz,
                "must be a positive number of Hz",
            ));
        }
        if reference_names.is_empty() {
            return Err(ProcessError::ChannelCount {
                what: "reference (force) channels",
                expected: 1,
                got: 0,
            });
        }
        if response_names.is_empty() {
            return Err(ProcessError::ChannelCount {
                what: "response channels",
                expected: 1,
                got: 0,
            });
        }
        let channels = reference_names.len() + response_names.len();
        if !config.full_scale.is_empty() {
            check_count("full-scale values", channels, config.full_scale.len())?;
        }
        let ref_window = config.reference_window.coefficients(n)?;
        let resp_window = config.response_window.coefficients(n)?;
        if resp_window.iter().all(|w| *w == 0.0) {
            return Err(invalid(
                "response_window",
                "all zeros",
                "the window must not be zero everywhere",
            ));
        }
        let fft = FftPlanner::new().plan_fft_forward(n);
        let scratch = vec![C64::default(); fft.get_inplace_scratch_len()];
        let nf = n / 2 + 1;
        let (r, p) = (reference_names.len(), response_names.len());
        Ok(Welch {
            names: reference_names
                .iter()
                .chain(response_names)
                .map(|s| s.to_string())
                .collect(),
            references: r,
            responses: p,
            fft,
            scratch,
            ref_window,
            resp_window,
            pending: vec![vec![0.0; n]; channels],
            filled: 0,
            seen: 0,
            segments: 0,
            work: vec![C64::default(); n],
            spectra: vec![C64::default(); channels * nf],
            acc_gxx: vec![C64::default(); nf * r * r],
            acc_gxy: vec![C64::default(); nf * r * p],
            acc_gyy: vec![0.0; nf * p],
            overloads: vec![0; channels],
            max_abs: vec![0.0; channels],
            extremes: vec![(f64::NEG_INFINITY, 0, f64::INFINITY, 0); channels],
            config,
        })
    }

    /// Number of full segments averaged so far.
    pub fn segments(&self) -> u32 {
        self.segments
    }

    /// Starts a new, separate record (e.g. the next hammer hit): samples of an unfinished segment
    /// are dropped so no segment spans two records. Returns how many samples were dropped.
    pub fn start_record(&mut self) -> usize {
        let dropped = self.filled;
        self.filled = 0;
        dropped
    }

    /// Feeds the next block of samples: `references[i]` and `responses[j]` are consecutive samples
    /// of each channel, all of the same length.
    pub fn push(&mut self, references: &[&[f64]], responses: &[&[f64]]) -> Result<()> {
        check_count("reference channels", self.references, references.len())?;
        check_count("response channels", self.responses, responses.len())?;
        let len = references[0].len();
        for (c, ch) in references.iter().chain(responses).enumerate() {
            if ch.len() != len {
                return Err(ProcessError::LengthMismatch {
                    channel: self.names[c].clone(),
                    samples: ch.len(),
                    first: self.names[0].clone(),
                    expected: len,
                });
            }
            if let Some(i) = ch.iter().position(|v| !v.is_finite()) {
                return Err(ProcessError::NonFinite {
                    channel: self.names[c].clone(),
                    index: self.seen + i as u64,
                    value: ch[i],
                });
            }
            if let Some(fs) = self.config.full_scale.get(c) {
                self.overloads[c] += ch.iter().filter(|v| v.abs() >= *fs).count() as u64;
            }
            let m = ch.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            self.max_abs[c] = self.max_abs[c].max(m);
            let e = &mut self.extremes[c];
            for &v in ch.iter() {
                if v > e.0 {
                    *e = (v, 0, e.2, e.3);
                } else if v == e.0 {
                    e.1 += 1;
                }
                if v < e.2 {
                    *e = (e.0, e.1, v, 0);
                } else if v == e.2 {
                    e.3 += 1;
                }
            }
        }
        let n = self.config.segment_len;
        let step = n - self.config.overlap;
        let mut at = 0;
        while at < len {
            let take = (n - self.filled).min(len - at);
            for (c, ch) in references.iter().chain(responses).enumerate() {
                self.pending[c][self.filled..self.filled + take]
                    .copy_from_slice(&ch[at..at + take]);
            }
            self.filled += take;
            at += take;
            if self.filled == n {
                self.process_segment();
                for buf in &mut self.pending {
                    buf.copy_within(step.., 0);
                }
                self.filled = n - step;
            }
        }
        self.seen += len as u64;
        Ok(())
    }

    fn process_segment(&mut self) {
        let channels = self.pending.len();
        // Two real channels per complex FFT: z = a + jb.
        let mut c = 0;
        while c < channels {
            self.spectra_of_pair(c);
            c += 2;
        }
        self.accumulate();
        self.segments += 1;
    }

    /// The one-sided spectra of pending channels `c` and `c + 1` (if there is one), detrended
    /// and windowed, from one complex FFT, into `spectra`.
    fn spectra_of_pair(&mut self, c: usize) {
        let n = self.config.segment_len;
        let nf = n / 2 + 1;
        let channels = self.pending.len();
        let r = self.references;
        let pair = c + 1 < channels;
        let wa = if c < r {
            &self.ref_window
        } else {
            &self.resp_window
        };
        let wb = if c + 1 < r {
            &self.ref_window
        } else {
            &self.resp_window
        };
        let (ma, sa) = trend(&self.pending[c], self.config.detrend);
        let (mb, sb) = if pair {
            trend(&self.pending[c + 1], self.config.detrend)
        } else {
            (0.0, 0.0)
        };
        let centre = (n as f64 - 1.0) / 2.0;
        if pair {
            let (a, b) = (&self.pending[c], &self.pending[c + 1]);
            if sa == 0.0 && sb == 0.0 {
                for i in 0..n {
                    self.work[i] = C64::new((a[i] - ma) * wa[i], (b[i] - mb) * wb[i]);
                }
            } else {
                for i in 0..n {
                    let t = i as f64 - centre;
                    self.work[i] =
                        C64::new((a[i] - ma - sa * t) * wa[i], (b[i] - mb - sb * t) * wb[i]);
                }
            }
        } else {
            let a = &self.pending[c];
            for i in 0..n {
                let t = i as f64 - centre;
                self.work[i] = C64::new((a[i] - ma - sa * t) * wa[i], 0.0);
            }
        }
        // Bring both packed channels to a similar magnitude by exact powers of two, so the
        // round-off of a strong channel does not swamp a weak one sharing the FFT.
        let (mut pa, mut pb) = (0.0f64, 0.0f64);
        for z in &self.work {
            pa = pa.max(z.re.abs());
            pb = pb.max(z.im.abs());
        }
        let exponent = |m: f64| {
            if m > 0.0 && m.is_finite() {
                m.log2().round().clamp(-1000.0, 1000.0) as i32
            } else {
                0
            }
        };
        let (ea, eb) = (exponent(pa), exponent(pb));
        if ea != eb {
            let (sa, sb) = (2f64.powi(-ea), 2f64.powi(-eb));
            for z in &mut self.work {
                *z = C64::new(z.re * sa, z.im * sb);
            }
        }
        self.fft
            .process_with_scratch(&mut self.work, &mut self.scratch);
        let (ua, ub) = if ea != eb {
            (2f64.powi(ea) * 0.5, 2f64.powi(eb) * 0.5)
        } else {
            (0.5, 0.5)
        };
        let (head, tail) = self.spectra.split_at_mut((c + 1) * nf);
        let sa = &mut head[c * nf..];
        if pair {
            let sb = &mut tail[..nf];
            for k in 0..nf {
                let z = self.work[k];
                let zc = self.work[(n - k) % n].conj();
                sa[k] = (z + zc) * ua;
                let d = z - zc;
                sb[k] = C64::new(d.im * ub, -d.re * ub);
            }
        } else {
            let u = ua * 2.0;
            for (s, z) in sa.iter_mut().zip(&self.work[..nf]) {
                *s = z * u;
            }
        }
    }

    /// Adds the segment's auto- and cross-products to the accumulators.
    fn accumulate(&mut self) {
        let n = self.config.segment_len;
        let nf = n / 2 + 1;
        let r = self.references;
        let p = self.responses;
        let (x, y) = self.spectra.split_at(r * nf);
        for k in 0..nf {
            for i in 0..r {
                let xi = x[i * nf + k].conj();
                let gxx = &mut self.acc_gxx[(k * r + i) * r..(k * r + i + 1) * r];
                for (l, g) in gxx.iter_mut().enumerate() {
                    *g += xi * x[l * nf + k];
                }
                let gxy = &mut self.acc_gxy[(k * r + i) * p..(k * r + i + 1) * p];
                for (j, g) in gxy.iter_mut().enumerate() {
                    *g += xi * y[j * nf + k];
                }
            }
            let gyy = &mut self.acc_gyy[k * p..(k + 1) * p];
            for (j, g) in gyy.iter_mut().enumerate() {
                *g += y[j * nf + k].norm_sqr();
            }
        }
    }

    /// Ends the record and returns the averaged spectra. Errors if no full segment was seen or a
    /// reference channel was zero throughout.
    pub fn finish(self) -> Result<CrossSpectra> {
        self.spectra()
    }

    /// The spectra averaged so far (the estimator goes on; for progress displays and for
    /// measurements that stop after a number of averages). Errors as [`Welch::finish`].
    pub fn spectra(&self) -> Result<CrossSpectra> {
        let n = self.config.segment_len;
        if self.segments == 0 {
            let channel = self.names[0].clone();
            return Err(if self.seen == 0 {
                ProcessError::Empty { channel, needed: n }
            } else {
                ProcessError::TooShort {
                    channel,
                    samples: self.seen as usize,
                    needed: n,
                }
            });
        }
        for i in 0..self.references {
            if self.max_abs[i] == 0.0 {
                return Err(ProcessError::ZeroForce {
                    channel: self.names[i].clone(),
                });
            }
        }
        let nf = n / 2 + 1;
        let fs = self.config.sample_rate_hz;
        let power: f64 = self.resp_window.iter().map(|w| w * w).sum();
        let base = 1.0 / (fs * power * self.segments as f64);
        let scale = |k: usize| {
            if k == 0 || (n.is_multiple_of(2) && k == n / 2) {
                base
            } else {
                2.0 * base
            }
        };
        let (r, p) = (self.references, self.responses);
        let mut gxx = self.acc_gxx.clone();
        let mut gxy = self.acc_gxy.clone();
        let mut gyy = self.acc_gyy.clone();
        for k in 0..nf {
            let s = scale(k);
            gxx[k * r * r..(k + 1) * r * r]
                .iter_mut()
                .for_each(|g| *g *= s);
            gxy[k * r * p..(k + 1) * r * p]
                .iter_mut()
                .for_each(|g| *g *= s);
            gyy[k * p..(k + 1) * p].iter_mut().for_each(|g| *g *= s);
        }
        Ok(CrossSpectra {
            freqs_hz: (0..nf).map(|k| k as f64 * fs / n as f64).collect(),
            references: r,
            responses: p,
            averages: self.segments,
            gxx,
            gxy,
            gyy,
            overloads: self.overloads.clone(),
            peak_hits: self.extremes.iter().map(|e| e.1 + e.3).collect(),
        })
    }
}

/// A sampled channel with its name and rate, as recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// Channel name (used in error messages).
    pub name: String,
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Samples, calibrated (SI units).
    pub samples: Vec<f64>,
}

/// Welch spectra of whole recorded signals (references = forces, responses). Checks that all
/// channels share the configured sample rate and length.
pub fn cross_spectra(
    config: &WelchConfig,
    references: &[Signal],
    responses: &[Signal],
) -> Result<CrossSpectra> {
    let all: Vec<&Signal> = references.iter().chain(responses).collect();
    if let Some(first) = all.first() {
        for s in &all {
            if (s.sample_rate_hz - config.sample_rate_hz).abs() > 1e-9 * config.sample_rate_hz {
                return Err(ProcessError::SampleRateMismatch {
                    channel: s.name.clone(),
                    rate_hz: s.sample_rate_hz,
                    first: "the analysis settings".into(),
                    expected_hz: config.sample_rate_hz,
                });
            }
            if s.samples.is_empty() {
                return Err(ProcessError::Empty {
                    channel: s.name.clone(),
                    needed: config.segment_len,
                });
            }
            if s.samples.len() != first.samples.len() {
                return Err(ProcessError::LengthMismatch {
                    channel: s.name.clone(),
                    samples: s.samples.len(),
                    first: first.name.clone(),
                    expected: first.samples.len(),
                });
            }
        }
    }
    let rn: Vec<&str> = references.iter().map(|s| s.name.as_str()).collect();
    let pn: Vec<&str> = responses.iter().map(|s| s.name.as_str()).collect();
    let mut w = Welch::new(config.clone(), &rn, &pn)?;
    let rs: Vec<&[f64]> = references.iter().map(|s| s.samples.as_slice()).collect();
    let ps: Vec<&[f64]> = responses.iter().map(|s| s.samples.as_slice()).collect();
    w.push(&rs, &ps)?;
    w.finish()
}
