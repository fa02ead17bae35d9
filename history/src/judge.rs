//! Drift judgement: is this run normal, given what normal looked like over a baseline window of
//! earlier runs of the same model? Pure computation on [`RunRecord`]s.
//!
//! Per parameter the baseline gives a centre and a robust scatter: the median and MAD × 1.4826 of
//! the values or, with a covariate (temperature), of the residuals of a straight-line regression
//! on it; MAD screens outliers out of the baseline (beyond [`SCREEN_MADS`]) and the scatter is the
//! standard deviation of the rest (MAD alone is too noisy on a few tens of runs). A run's standardized residual `r = (x − centre) / scatter` feeds
//! - the **Shewhart** individuals rule `|r| > k` (steps),
//! - an **EWMA** `z ← λ r + (1 − λ) z` with limit `L √(λ / (2 − λ))` (slow drifts),
//! - **Hotelling T²** `d' S⁻¹ d` of the residual vector with the baseline covariance `S` shrunk
//!   toward its diagonal (correlated parameters moving along their known direction are normal;
//!   across it they are not), against the F limit for a new observation.
//!
//! An effect diagnosis accepted that no baseline run needed is a **new effect** alarm. Runs of
//! another model hash are never compared; with fewer baseline runs than asked the run is not judged
//! and the judgement says why. Limits are widened for the baseline's own error (`√(1 + 1/n)`, and
//! the regression's prediction interval with a covariate).

use nalgebra::{DMatrix, DVector};
use rfe::display::sig;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use crate::record::RunRecord;

/// MAD × this = σ for normal data.
pub const MAD_TO_SIGMA: f64 = 1.4826;

/// Baseline residuals beyond this many MAD scatters are outliers, left out of the scatter.
pub const SCREEN_MADS: f64 = 5.0;

/// Which earlier runs define normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "window", content = "runs")]
pub enum BaselineWindow {
    /// The first `n` usable runs of the model; later runs are judged against them.
    First(usize),
    /// The `n` usable runs just before the judged one.
    Rolling(usize),
}

/// The rules' settings (defaults: [`JudgeConfig::default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JudgeConfig {
    /// The baseline window.
    pub baseline: BaselineWindow,
    /// Shewhart limit in robust scatters.
    pub shewhart_k: f64,
    /// EWMA weight λ of the newest run (0 < λ ≤ 1).
    pub ewma_lambda: f64,
    /// EWMA limit L in scatters of the EWMA.
    pub ewma_l: f64,
    /// Hotelling T² false-alarm probability per run.
    pub t2_alpha: f64,
    /// Shrinkage of the baseline covariance toward its diagonal (0: none, 1: diagonal).
    pub t2_shrinkage: f64,
    /// Covariate to regress the parameters on over the baseline (e.g. `"temperature"`).
    pub covariate: Option<String>,
}

impl Default for JudgeConfig {
    fn default() -> Self {
        JudgeConfig {
            baseline: BaselineWindow::First(20),
            shewhart_k: 5.0,
            ewma_lambda: 0.2,
            ewma_l: 5.0,
            t2_alpha: 1e-4,
            t2_shrinkage: 0.01,
            covariate: None,
        }
    }
}

/// A control-chart rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rule {
    /// Individuals chart: one run beyond `k` scatters.
    Shewhart,
    /// Exponentially weighted moving average beyond its limit.
    Ewma,
    /// Hotelling T² of the parameter vector beyond its F limit.
    HotellingT2,
    /// An effect no baseline run needed.
    NewEffect,
}

impl Rule {
    /// Name for readers.
    pub fn as_str(self) -> &'static str {
        match self {
            Rule::Shewhart => "Shewhart",
            Rule::Ewma => "EWMA",
            Rule::HotellingT2 => "Hotelling T²",
            Rule::NewEffect => "new effect",
        }
    }
}

/// One alarm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Alarm {
    /// Which rule fired.
    pub rule: Rule,
    /// The parameter (none for T²), or the effect for a new effect.
    pub subject: String,
    /// The first run of the current excursion.
    pub since_run: String,
    /// The change (this run − normal; for EWMA the smoothed change) in the parameter's display
    /// unit; `None` for T² and new effects.
    pub change: Option<f64>,
    /// Display unit of `change`.
    pub unit: String,
    /// The change in multiples of normal scatter (for T²: T² / limit); `None` for a new effect.
    pub multiples: Option<f64>,
    /// One sentence for the report.
    pub message: String,
}

/// One parameter of the judged run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParameterJudgement {
    /// Variable name.
    pub variable: String,
    /// Display unit.
    pub unit: String,
    /// This run's value (display unit).
    pub value: f64,
    /// Normal value for this run (display unit; with a covariate, at this run's covariate).
    pub centre: f64,
    /// Normal run-to-run scatter (display unit, robust σ).
    pub scatter: f64,
    /// (value − centre) / scatter.
    pub standardized: f64,
    /// The EWMA of `standardized` after this run.
    pub ewma: f64,
    /// Shewhart limits (display unit): centre ∓ k·scatter·√(1 + 1/n).
    pub limits: [f64; 2],
    /// Slope on the covariate (display unit per covariate unit), when regressed.
    pub slope: Option<f64>,
}

/// Whether a run was judged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "state", content = "why")]
pub enum Verdict {
    /// Judged: alarms (possibly none) follow.
    Judged,
    /// Not judged, and why (too few baseline runs, inside the baseline window, a failed run).
    NotJudged(String),
}

/// The judgement of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Judgement {
    /// The judged run.
    pub run_id: String,
    /// Judged or not, and why.
    pub verdict: Verdict,
    /// The baseline runs used.
    pub baseline_runs: Vec<String>,
    /// Per parameter (empty when not judged).
    pub parameters: Vec<ParameterJudgement>,
    /// Hotelling T² and its limit, when computed.
    pub t2: Option<[f64; 2]>,
    /// Alarms.
    pub alarms: Vec<Alarm>,
    /// Remarks (runs of other models left out, parameters not judged).
    pub notes: Vec<String>,
}

impl Judgement {
    /// Whether any rule fired.
    pub fn alarm(&self) -> bool {
        !self.alarms.is_empty()
    }

    /// One line for logs and reports.
    pub fn summary(&self) -> String {
        match &self.verdict {
            Verdict::NotJudged(why) => format!("drift not judged: {why}"),
            Verdict::Judged if self.alarms.is_empty() => format!(
                "drift: normal against {} baseline runs ({} parameters{})",
                self.baseline_runs.len(),
                self.parameters.len(),
                self.t2
                    .map(|[t, l]| format!(", T² {t:.1} below {l:.1}"))
                    .unwrap_or_default()
            ),
            Verdict::Judged => format!("drift: {} alarm(s)", self.alarms.len()),
        }
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median and robust σ (MAD × 1.4826) of `v`.
pub fn robust_scatter(v: &[f64]) -> (f64, f64) {
    let mut w = v.to_vec();
    let m = median(&mut w);
    let mut dev: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    (m, MAD_TO_SIGMA * median(&mut dev))
}

/// Normal for one parameter over the baseline.
struct Normal {
    unit: String,
    factor: f64,
    /// Centre at covariate `c`: a + b (c − c̄) (SI).
    a: f64,
    b: f64,
    c_mean: f64,
    scatter: f64,
    /// Σ (c − c̄)² over the baseline (0 without a covariate).
    scc: f64,
    /// Baseline runs.
    n: usize,
    /// Baseline residuals (SI), for the covariance.
    residuals: Vec<f64>,
}

impl Normal {
    fn centre(&self, c: Option<f64>) -> f64 {
        self.a + self.b * c.map(|c| c - self.c_mean).unwrap_or(0.0)
    }

    /// Widening of the limits for the baseline's own error: √(1 + 1/n) for a centre,
    /// √(1 + 1/n + (c − c̄)² / Σ(c − c̄)²) for a regression line at covariate `c` (the prediction
    /// interval of a new observation).
    fn widen(&self, c: Option<f64>) -> f64 {
        let lever = match c {
            Some(c) if self.scc > 0.0 => (c - self.c_mean).powi(2) / self.scc,
            _ => 0.0,
        };
        (1.0 + 1.0 / self.n as f64 + lever).sqrt()
    }
}

fn learn(base: &[&RunRecord], variable: &str, covariate: Option<&str>) -> Option<Normal> {
    let first = base.first()?.parameter(variable)?;
    let xs: Vec<f64> = base
        .iter()
        .map(|r| r.parameter(variable).map(|p| p.estimate))
        .collect::<Option<_>>()?;
    let cs: Option<Vec<f64>> =
        covariate.and_then(|c| base.iter().map(|r| r.covariate(c)).collect());
    let n = xs.len();
    let mut scc = 0.0;
    let (a, b, c_mean, residuals): (f64, f64, f64, Vec<f64>) = match cs {
        Some(cs) if n >= 3 => {
            let cm = cs.iter().sum::<f64>() / n as f64;
            let xm = xs.iter().sum::<f64>() / n as f64;
            scc = cs.iter().map(|c| (c - cm).powi(2)).sum();
            let b = if scc > 0.0 {
                cs.iter()
                    .zip(&xs)
                    .map(|(c, x)| (c - cm) * (x - xm))
                    .sum::<f64>()
                    / scc
            } else {
                0.0
            };
            let res: Vec<f64> = cs
                .iter()
                .zip(&xs)
                .map(|(c, x)| x - xm - b * (c - cm))
                .collect();
            let (m, _) = robust_scatter(&res);
            (xm + m, b, cm, res.iter().map(|r| r - m).collect())
        }
        _ => {
            let (m, _) = robust_scatter(&xs);
            (m, 0.0, 0.0, xs.iter().map(|x| x - m).collect())
        }
    };
    // MAD screens the outliers (a bad night in the baseline); the scatter is the standard
    // deviation of the rest: MAD alone is too noisy on a few tens of runs (37 % efficiency).
    let (_, mad_sigma) = robust_scatter(&residuals);
    let kept: Vec<f64> = residuals
        .iter()
        .copied()
        .filter(|r| r.abs() <= SCREEN_MADS * mad_sigma)
        .collect();
    let dof = kept.len() as f64 - if scc > 0.0 { 2.0 } else { 1.0 };
    let scatter = if dof >= 1.0 {
        (kept.iter().map(|r| r * r).sum::<f64>() / dof).sqrt()
    } else {
        mad_sigma
    };
    Some(Normal {
        unit: first.unit.clone(),
        factor: first.unit_factor,
        a,
        b,
        c_mean,
        scatter,
        scc,
        n,
        residuals,
    })
}

/// Judges every run of `runs` (oldest first) against the runs before it; the EWMA and the
/// "since" of each alarm carry from run to run. Runs of another model than the judged run's are
/// left out of its history (and said so).
pub fn judge_series(runs: &[RunRecord], cfg: &JudgeConfig) -> Vec<Judgement> {
    let mut out: Vec<Judgement> = Vec::with_capacity(runs.len());
    // Per model hash: EWMA per variable, the current excursion's first run per (rule, subject).
    let mut ewma: std::collections::HashMap<(String, String), f64> = Default::default();
    for (j, run) in runs.iter().enumerate() {
        let judgement = judge_one(&runs[..j], run, cfg, &mut ewma, out.last());
        out.push(judgement);
    }
    out
}

/// Judges `run` against `earlier` (oldest first) alone, with fresh EWMAs: the EWMA starts at the
/// first run after the baseline, so judge a whole history with [`judge_series`] and take the last
/// when the EWMA matters.
pub fn judge_latest(earlier: &[RunRecord], run: &RunRecord, cfg: &JudgeConfig) -> Judgement {
    let mut all = earlier.to_vec();
    all.push(run.clone());
    judge_series(&all, cfg).pop().unwrap_or_else(|| Judgement {
        run_id: run.run_id.clone(),
        verdict: Verdict::NotJudged("nothing to judge".into()),
        baseline_runs: vec![],
        parameters: vec![],
        t2: None,
        alarms: vec![],
        notes: vec![],
    })
}

fn judge_one(
    earlier: &[RunRecord],
    run: &RunRecord,
    cfg: &JudgeConfig,
    ewma: &mut std::collections::HashMap<(String, String), f64>,
    previous: Option<&Judgement>,
) -> Judgement {
    let mut j = Judgement {
        run_id: run.run_id.clone(),
        verdict: Verdict::Judged,
        baseline_runs: vec![],
        parameters: vec![],
        t2: None,
        alarms: vec![],
        notes: vec![],
    };
    let usable = |r: &&RunRecord| r.outcome != "failure" && r.model_hash == run.model_hash;
    let same: Vec<&RunRecord> = earlier.iter().filter(usable).collect();
    let other = earlier
        .iter()
        .filter(|r| r.outcome != "failure" && r.model_hash != run.model_hash)
        .count();
    if other > 0 {
        j.notes.push(format!(
            "{other} earlier run(s) of a different model (hash ≠ {}) are not compared",
            run.model_hash
        ));
    }
    if run.outcome == "failure" {
        j.verdict = Verdict::NotJudged("the run failed".into());
        return j;
    }
    let (want, base): (usize, Vec<&RunRecord>) = match cfg.baseline {
        BaselineWindow::First(n) => (n, same.iter().take(n).copied().collect()),
        BaselineWindow::Rolling(n) => (n, same[same.len().saturating_sub(n)..].to_vec()),
    };
    if base.len() < want.max(3) {
        j.verdict = Verdict::NotJudged(format!(
            "too few baseline runs of this model: {} of the {} the baseline window needs to learn normal run-to-run scatter",
            base.len(),
            want.max(3)
        ));
        return j;
    }
    j.baseline_runs = base.iter().map(|r| r.run_id.clone()).collect();
    let covariate = cfg.covariate.as_deref();
    let c_now = covariate.and_then(|c| run.covariate(c));
    if let Some(c) = covariate {
        if c_now.is_none() {
            j.notes.push(format!(
                "covariate \"{c}\" not recorded with this run: parameters judged uncompensated"
            ));
        }
    }
    let cov = if c_now.is_some() { covariate } else { None };
    let n = base.len();
    let lam = cfg.ewma_lambda.clamp(1e-6, 1.0);
    let prev_since = |rule: Rule, subject: &str| -> Option<String> {
        previous
            .filter(|p| p.verdict == Verdict::Judged)?
            .alarms
            .iter()
            .find(|a| a.rule == rule && a.subject == subject)
            .map(|a| a.since_run.clone())
    };
    let mut normals = Vec::new();
    for p in &run.parameters {
        let Some(nm) = learn(&base, &p.variable, cov) else {
            j.notes.push(format!(
                "{}: not in every baseline run; not judged",
                p.variable
            ));
            continue;
        };
        if !(nm.scatter > 0.0) {
            j.notes.push(format!(
                "{}: no run-to-run scatter over the baseline; not judged",
                p.variable
            ));
            continue;
        }
        let f = nm.factor;
        let centre = nm.centre(c_now);
        let r = (p.estimate - centre) / nm.scatter;
        let key = (run.model_hash.clone(), p.variable.clone());
        let z_prev = ewma.get(&key).copied().unwrap_or(0.0);
        let z = lam * r + (1.0 - lam) * z_prev;
        ewma.insert(key, z);
        let widen = nm.widen(c_now.filter(|_| cov.is_some()));
        let ewma_limit = cfg.ewma_l * (lam / (2.0 - lam)).sqrt() * widen;
        let lim = cfg.shewhart_k * nm.scatter * widen;
        let pj = ParameterJudgement {
            variable: p.variable.clone(),
            unit: nm.unit.clone(),
            value: p.estimate / f,
            centre: centre / f,
            scatter: nm.scatter / f,
            standardized: r,
            ewma: z,
            limits: [(centre - lim) / f, (centre + lim) / f],
            slope: cov.map(|_| nm.b / f),
        };
        // A Shewhart or EWMA alarm on this parameter: `what` fired, `change` in its display unit,
        // `multiples` of its normal scatter. Since: the first run of this alarm's stretch.
        let mut alarm = |rule: Rule, what: String, change: f64, multiples: f64| {
            let since = prev_since(rule, &p.variable).unwrap_or(run.run_id.clone());
            j.alarms.push(Alarm {
                rule,
                subject: p.variable.clone(),
                message: format!("{what} since run {since}"),
                since_run: since,
                change: Some(change),
                unit: pj.unit.clone(),
                multiples: Some(multiples),
            });
        };
        if r.abs() > cfg.shewhart_k * widen {
            alarm(
                Rule::Shewhart,
                format!(
                    "drift alarm (Shewhart): {} is {}{} {} from normal ({:+.1} × its normal scatter {} {}; limit {:.1}×)",
                    p.variable, if pj.value >= pj.centre { "+" } else { "" }, sig(pj.value - pj.centre, 3), pj.unit, r, sig(pj.scatter, 3), pj.unit, cfg.shewhart_k * widen
                ),
                pj.value - pj.centre,
                r,
            );
        }
        if z.abs() > ewma_limit {
            alarm(
                Rule::Ewma,
                format!(
                    "drift alarm (EWMA): {} has drifted {}{} {} ({:+.2} × its normal scatter, limit {:.2}×)",
                    p.variable, if z >= 0.0 { "+" } else { "" }, sig(z * pj.scatter, 3), pj.unit, z, ewma_limit
                ),
                z * pj.scatter,
                z,
            );
        }
        j.parameters.push(pj);
        normals.push((nm, p.estimate - centre));
    }
    // Hotelling T² over the parameters judged.
    let p = normals.len();
    if p >= 2 && n > p + 2 {
        let mut s = DMatrix::<f64>::zeros(p, p);
        for a in 0..p {
            for b in 0..p {
                let (ra, rb) = (&normals[a].0.residuals, &normals[b].0.residuals);
                let (ma, mb) = (
                    ra.iter().sum::<f64>() / n as f64,
                    rb.iter().sum::<f64>() / n as f64,
                );
                s[(a, b)] = ra
                    .iter()
                    .zip(rb)
                    .map(|(x, y)| (x - ma) * (y - mb))
                    .sum::<f64>()
                    / (n - 1) as f64;
            }
        }
        // Scale to correlations so the shrinkage and the inverse are well conditioned.
        let d: Vec<f64> = (0..p).map(|i| s[(i, i)].sqrt()).collect();
        let g = cfg.t2_shrinkage.clamp(0.0, 1.0);
        let mut rho = DMatrix::<f64>::identity(p, p);
        for a in 0..p {
            for b in 0..p {
                if a != b && d[a] > 0.0 && d[b] > 0.0 {
                    rho[(a, b)] = (1.0 - g) * s[(a, b)] / (d[a] * d[b]);
                }
            }
        }
        let dev = DVector::from_iterator(
            p,
            normals.iter().enumerate().map(|(i, (nm, x))| {
                let m = nm.residuals.iter().sum::<f64>() / n as f64;
                if d[i] > 0.0 {
                    (x - m) / d[i]
                } else {
                    0.0
                }
            }),
        );
        let limit = FisherSnedecor::new(p as f64, (n - p) as f64)
            .ok()
            .map(|f| f.inverse_cdf(1.0 - cfg.t2_alpha))
            .map(|q| q * (p * (n + 1) * (n - 1)) as f64 / (n * (n - p)) as f64);
        match (rho.clone().cholesky(), limit) {
            (Some(ch), Some(limit)) if limit.is_finite() => {
                let t2 = dev.dot(&ch.solve(&dev));
                j.t2 = Some([t2, limit]);
                if t2 > limit {
                    let since = prev_since(Rule::HotellingT2, "parameter vector")
                        .unwrap_or(run.run_id.clone());
                    let mut top: Vec<(usize, f64)> = j
                        .parameters
                        .iter()
                        .map(|q| q.standardized)
                        .enumerate()
                        .collect();
                    top.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
                    let names: Vec<String> = top
                        .iter()
                        .take(3)
                        .map(|(i, r)| format!("{} {r:+.1}×", j.parameters[*i].variable))
                        .collect();
                    j.alarms.push(Alarm {
                        rule: Rule::HotellingT2,
                        subject: "parameter vector".into(),
                        message: format!(
                            "drift alarm (Hotelling T²): the parameters together are off their normal correlation pattern, T² {t2:.1} > limit {limit:.1} ({:.1}×) since run {since}; largest single deviations {}",
                            t2 / limit,
                            names.join(", ")
                        ),
                        since_run: since,
                        change: None,
                        unit: String::new(),
                        multiples: Some(t2 / limit),
                    });
                }
            }
            _ => j
                .notes
                .push("Hotelling T² not computed: the baseline covariance is singular".into()),
        }
    } else if p >= 2 {
        j.notes.push(format!(
            "Hotelling T² not computed: {n} baseline runs for {p} parameters (needs more than {})",
            p + 2
        ));
    }
    // New effects.
    for e in &run.effects {
        if !base.iter().any(|r| r.effects.contains(e)) {
            let since = prev_since(Rule::NewEffect, e).unwrap_or(run.run_id.clone());
            j.alarms.push(Alarm {
                rule: Rule::NewEffect,
                subject: e.clone(),
                message: format!(
                    "drift alarm (new effect): diagnosis accepted \"{e}\", which none of the {n} baseline runs needed (a loosened joint, a new contact?), since run {since}"
                ),
                since_run: since,
                change: None,
                unit: String::new(),
                multiples: None,
            });
        }
    }
    j
}
