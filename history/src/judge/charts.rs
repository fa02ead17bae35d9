//! The per-parameter control charts and their memory from night to night.
//!
//! Each judged night gives a parameter's standardized residual `r = (x − centre) / scatter`.
//! Three charts read it, each designed for one kind of change (limits in `docs/nightly.md`):
//! - **Shewhart** `|r| > k·w` (`w` the baseline widening): a large jump, caught the same night;
//! - **CUSUM** `S⁺ ← max(0, S⁺ + r − k)`, `S⁻ ← max(0, S⁻ − r − k)` beyond `h`: a step. With the
//!   reference value `k` half the step it is designed for (1 sd for a 2-sd step) the CUSUM is
//!   the sequential likelihood-ratio test for that step (Page 1954);
//! - **EWMA** `z ← λ r + (1 − λ) z` with a small `λ`: a slow trend. Its limit is `L σ_z` with
//!   `σ_z² = λ/(2−λ)·(1 − (1−λ)^{2t}) + 1/n`: the chart's own variance after `t` nights plus the
//!   error of the baseline centre (`1/n`), which every night shares and which dominates the false
//!   alarms of a small-λ chart learnt from a few tens of runs.
//!
//! A bad night does not poison the memory: a night beyond the Shewhart limit is an alarm of its
//! own and does not enter the CUSUM and EWMA, and the CUSUM and EWMA inputs are clipped at
//! ±[`CLIP`]. After an alarm the charts restart from zero and the parameter is followed as a
//! [`Change`]: its change point (the night that maximizes the step
//! likelihood ratio over the nights since the charts last restarted), its new level, and whether
//! the nights after the alarm confirm it (a change persists) or are back to normal (an outlier
//! night; the change closes and the charts resume).

use super::rule::{Change, Rule};

/// CUSUM and EWMA inputs are clipped to ±this many scatters.
pub const CLIP: f64 = 4.0;

/// Nights kept for the change-point estimate.
const MEMORY: usize = 60;

/// A change is confirmed when the mean of the nights after its alarm differs from normal by
/// more than this many standard errors (two-sided 5 %: a weak test, on purpose: it only decides
/// what to call an open change, never raises an alarm).
pub const PERSIST_Z: f64 = 2.0;

/// A change not confirmed after this many nights is closed as a bad night.
pub const CLOSE_AFTER: usize = 2;

/// The memory of one parameter's charts between nights.
#[derive(Debug, Clone, Default)]
pub struct ChartState {
    /// Upper and lower CUSUM.
    pub cusum: [f64; 2],
    /// EWMA.
    pub ewma: f64,
    /// Nights the EWMA has run since it last started.
    pub ewma_nights: u32,
    /// Run ids and standardized residuals since the charts last restarted (newest last).
    pub recent: Vec<(String, f64)>,
    /// The open change, if an alarm was raised.
    pub open: Option<Change>,
}

/// The chart settings one night needs.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// Shewhart limit (scatters, widened).
    pub shewhart: f64,
    /// CUSUM reference value and limit.
    pub cusum_k: f64,
    /// CUSUM limit.
    pub cusum_h: f64,
    /// EWMA weight.
    pub lambda: f64,
    /// EWMA limit in σ_z.
    pub ewma_l: f64,
    /// Baseline runs (for the EWMA's centre error).
    pub n: usize,
}

/// What the charts say about one night.
#[derive(Debug, Clone, PartialEq)]
pub struct Reading {
    /// The charts' statistics after this night.
    pub cusum: [f64; 2],
    /// EWMA after this night.
    pub ewma: f64,
    /// EWMA limit tonight.
    pub ewma_limit: f64,
    /// Rules that fired tonight, with the statistic in multiples of scatter.
    pub fired: Vec<(Rule, f64)>,
    /// The input was clipped or held out of the CUSUM and EWMA.
    pub held_out: bool,
}

impl ChartState {
    /// Feeds tonight's residual `r` of run `run_id` (no change open).
    pub fn update(&mut self, run_id: &str, r: f64, lim: &Limits) -> Reading {
        let mut fired = Vec::new();
        let beyond = r.abs() > lim.shewhart;
        if beyond {
            fired.push((Rule::Shewhart, r));
        }
        let held_out = beyond || r.abs() > CLIP;
        if !beyond {
            let x = r.clamp(-CLIP, CLIP);
            self.cusum[0] = (self.cusum[0] + x - lim.cusum_k).max(0.0);
            self.cusum[1] = (self.cusum[1] - x - lim.cusum_k).max(0.0);
            self.ewma = lim.lambda * x + (1.0 - lim.lambda) * self.ewma;
            self.ewma_nights += 1;
        }
        let ewma_limit = lim.ewma_l * self.ewma_sigma(lim);
        if self.cusum[0] > lim.cusum_h {
            fired.push((Rule::Cusum, self.cusum[0]));
        } else if self.cusum[1] > lim.cusum_h {
            fired.push((Rule::Cusum, -self.cusum[1]));
        }
        if self.ewma.abs() > ewma_limit {
            fired.push((Rule::Ewma, self.ewma));
        }
        self.recent.push((run_id.to_string(), r.clamp(-CLIP, CLIP)));
        if self.recent.len() > MEMORY {
            self.recent.remove(0);
        }
        Reading {
            cusum: self.cusum,
            ewma: self.ewma,
            ewma_limit,
            fired,
            held_out,
        }
    }

    /// σ of the EWMA about the true centre after its nights so far.
    pub fn ewma_sigma(&self, lim: &Limits) -> f64 {
        let l = lim.lambda;
        let t = self.ewma_nights.max(1) as i32;
        (l / (2.0 - l) * (1.0 - (1.0 - l).powi(2 * t)) + 1.0 / lim.n.max(1) as f64).sqrt()
    }

    /// Restarts the charts (after an alarm, or when a change closes).
    pub fn restart(&mut self) {
        self.cusum = [0.0; 2];
        self.ewma = 0.0;
        self.ewma_nights = 0;
        self.recent.clear();
    }
}

/// The change point of the nights `recent` (oldest first) in the direction `sign`: the night τ
/// that maximizes `sign·Σ_{t≥τ} r_t / √(N − τ)`, the likelihood ratio of a step at τ; its index
/// and the mean residual from it on.
pub fn change_point(recent: &[(String, f64)], sign: f64) -> Option<(usize, f64)> {
    let n = recent.len();
    let mut best: Option<(usize, f64, f64)> = None;
    let mut tail = 0.0;
    for tau in (0..n).rev() {
        tail += recent[tau].1;
        let m = (n - tau) as f64;
        let score = sign * tail / m.sqrt();
        if best.is_none_or(|(_, s, _)| score > s) {
            best = Some((tau, score, tail / m));
        }
    }
    best.map(|(t, _, mean)| (t, mean))
}

/// Whether the nights after an alarm confirm the change: their mean residual `mean` over `k`
/// nights, against the change's direction `sign`. `None` before the first night after it.
pub fn persists(sum_after: f64, k: usize, sign: f64) -> Option<bool> {
    (k > 0).then(|| sign * sum_after / (k as f64).sqrt() > PERSIST_Z)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lim() -> Limits {
        Limits {
            shewhart: 4.0,
            cusum_k: 1.0,
            cusum_h: 3.5,
            lambda: 0.1,
            ewma_l: 3.0,
            n: 30,
        }
    }

    #[test]
    fn a_cusum_accumulates_a_step_and_an_outlier_is_held_out() {
        let mut s = ChartState::default();
        let r = s.update("a", 2.0, &lim());
        assert_eq!(r.cusum, [1.0, 0.0]);
        let r = s.update("b", 20.0, &lim());
        assert!(r.held_out && r.fired.iter().any(|f| f.0 == Rule::Shewhart));
        assert_eq!(r.cusum, [1.0, 0.0], "the outlier night is not in the CUSUM");
        let r = s.update("c", 3.0, &lim());
        assert_eq!(r.cusum, [3.0, 0.0]);
        let r = s.update("d", 3.0, &lim());
        assert!(r.fired.iter().any(|f| f.0 == Rule::Cusum && f.1 > 3.5));
    }

    #[test]
    fn the_change_point_is_where_the_step_starts() {
        let nights: Vec<(String, f64)> = [0.1, -0.3, 0.2, 3.1, 2.8, 3.2]
            .iter()
            .enumerate()
            .map(|(i, r)| (format!("n{i}"), *r))
            .collect();
        let (t, mean) = change_point(&nights, 1.0).unwrap();
        assert_eq!(t, 3);
        assert!((mean - 3.0333).abs() < 1e-3);
    }

    #[test]
    fn the_ewma_sigma_includes_the_baseline_centre_error() {
        let mut s = ChartState::default();
        for _ in 0..200 {
            s.update("x", 0.0, &lim());
        }
        let want = (0.1f64 / 1.9 + 1.0 / 30.0).sqrt();
        assert!((s.ewma_sigma(&lim()) - want).abs() < 1e-9);
    }
}
