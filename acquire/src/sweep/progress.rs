//! Progress display of a sweep: an indicatif bar for operators, nothing for tests.

use indicatif::{ProgressBar, ProgressStyle};

/// Receives sweep progress.
pub trait SweepProgress: Send + Sync {
    /// A sweep of `total` steps starts, `done` of them already done.
    fn start(&self, total: u64, done: u64);
    /// A step finished: frequency (Hz), force amplitude (N), fit quality or coherence (0-1).
    fn step(&self, step: usize, freq_hz: f64, force_n: f64, quality: f64);
    /// The sweep ended (`done`, `stopped`, `failed`).
    fn finish(&self, how: &str);
}

/// No display.
pub struct NoProgress;

impl SweepProgress for NoProgress {
    fn start(&self, _: u64, _: u64) {}
    fn step(&self, _: usize, _: f64, _: f64, _: f64) {}
    fn finish(&self, _: &str) {}
}

/// An indicatif progress bar on stderr: step, frequency, force, coherence/fit quality.
pub struct IndicatifProgress {
    bar: ProgressBar,
}

impl Default for IndicatifProgress {
    fn default() -> Self {
        Self::new()
    }
}

impl IndicatifProgress {
    /// A hidden bar until [`SweepProgress::start`].
    pub fn new() -> Self {
        let bar = ProgressBar::new(0);
        let style =
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] step {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
        bar.set_style(style);
        IndicatifProgress { bar }
    }
}

impl SweepProgress for IndicatifProgress {
    fn start(&self, total: u64, done: u64) {
        self.bar.set_length(total);
        self.bar.set_position(done);
    }
    fn step(&self, _step: usize, freq_hz: f64, force_n: f64, quality: f64) {
        self.bar.inc(1);
        self.bar.set_message(format!(
            "{freq_hz:8.2} Hz  {force_n:7.1} N  coh {quality:.3}"
        ));
    }
    fn finish(&self, how: &str) {
        self.bar.finish_with_message(how.to_string());
    }
}
