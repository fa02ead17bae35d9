//! Drift judgement: is this run normal, given what normal looked like over a baseline window of
//! earlier runs of the same model? Pure computation on [`RunRecord`]s; the one drift rule of
//! ident (the nightly, `ident history` and the report's drift section all read it).
//!
//! Per parameter the baseline gives a centre and a robust scatter ([`normal`]); a run's
//! standardized residual `r = (x − centre) / scatter` feeds three charts ([`charts`]): Shewhart
//! for large jumps, a CUSUM for steps, an EWMA for slow trends. The vector of residuals feeds
//! Hotelling's T² against the Cramér-Rao correlation structure (`multivariate`). An effect
//! diagnosis accepted that no baseline run needed is a **new effect** alarm.
//!
//! The charts share one false-alarm budget, the one the operator experiences: at most one false
//! alarm per 1000 parameter-nights from all charts together. The default limits spend it as
//! measured by `cargo run --release -p history --example power` (`docs/nightly.md`): the per-
//! parameter charts about 0.5 per 1000 parameter-nights together, T² (one alarm per night,
//! whatever the number of parameters) `α = 2·10⁻³` per night, i.e. 0.12 per 1000 parameter-
//! nights with 17 parameters.
//!
//! An alarm is raised once: the charts then follow the change (its change-point night, its new
//! level, whether the nights after confirm it) instead of repeating the alarm; a change the
//! nights after do not confirm (one bad night) closes and the charts resume. A failed run, a
//! value that is not a number, and runs of another model are never judged nor learnt from, and
//! the judgement says why. Limits are widened for the baseline's own error.

pub mod charts;
pub mod crlb;
mod multivariate;
pub mod normal;
mod rule;

use std::collections::HashMap;

use rfe::display::sig;
use serde::{Deserialize, Serialize};

use crate::record::{ParameterRecord, RunRecord};
use charts::{ChartState, Limits};
use normal::{learn, Normal};

pub use normal::{robust_scatter, MAD_TO_SIGMA, SCREEN_MADS};
pub use rule::{Change, Rule, VECTOR};

/// Which earlier runs define normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", tag = "window", content = "runs")]
pub enum BaselineWindow {
    /// The first `n` usable runs of the model; later runs are judged against them.
    First(usize),
    /// The `n` usable runs just before the judged one (runs with an alarm or a confirmed change
    /// are left out of it).
    Rolling(usize),
}

/// The charts' settings (defaults: [`JudgeConfig::default`], designed in `docs/nightly.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JudgeConfig {
    /// The baseline window.
    pub baseline: BaselineWindow,
    /// Shewhart limit in scatters.
    pub shewhart_k: f64,
    /// CUSUM reference value in scatters (half the step it is designed for).
    pub cusum_k: f64,
    /// CUSUM limit in scatters.
    pub cusum_h: f64,
    /// EWMA weight λ of the newest run (0 < λ ≤ 1).
    pub ewma_lambda: f64,
    /// EWMA limit L in σ of the EWMA (baseline centre error included).
    pub ewma_l: f64,
    /// Hotelling T² false-alarm probability per night.
    pub t2_alpha: f64,
    /// Covariate to regress the parameters on over the baseline (e.g. `"temperature"`).
    pub covariate: Option<String>,
}

impl Default for JudgeConfig {
    fn default() -> Self {
        JudgeConfig {
            baseline: BaselineWindow::First(20),
            shewhart_k: 4.5,
            cusum_k: 1.5,
            cusum_h: 3.0,
            ewma_lambda: 0.1,
            ewma_l: 3.8,
            t2_alpha: 5e-4,
            covariate: None,
        }
    }
}

/// One alarm: raised the night a chart first crosses its limit, once per change.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Alarm {
    /// Which rule fired.
    pub rule: Rule,
    /// The parameter ([`VECTOR`] for T²), or the effect for a new effect.
    pub subject: String,
    /// The estimated first run of the change (change-point estimate).
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

/// One parameter of the judged run: every chart's statistic beside its limit.
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
    /// Shewhart limit on `standardized` (scatters, widened for the baseline's error).
    pub shewhart_limit: f64,
    /// Upper and lower CUSUM after this run (scatters).
    pub cusum: [f64; 2],
    /// CUSUM limit (scatters).
    pub cusum_limit: f64,
    /// The EWMA of `standardized` after this run.
    pub ewma: f64,
    /// EWMA limit (scatters).
    pub ewma_limit: f64,
    /// Shewhart limits (display unit).
    pub limits: [f64; 2],
    /// Slope on the covariate (display unit per covariate unit), when regressed.
    pub slope: Option<f64>,
    /// This run was held out of the CUSUM and EWMA (beyond the Shewhart limit, or clipped).
    pub held_out: bool,
    /// The open change this parameter is followed as (charts paused), if any.
    pub changed_since: Option<String>,
}

/// A parameter of the run that was not judged, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NotJudged {
    /// Variable name.
    pub variable: String,
    /// Why, in words.
    pub why: String,
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
    /// Per parameter judged.
    pub parameters: Vec<ParameterJudgement>,
    /// Parameters of the run not judged, and why.
    pub not_judged: Vec<NotJudged>,
    /// Hotelling T² and its limit, when computed.
    pub t2: Option<[f64; 2]>,
    /// New alarms tonight.
    pub alarms: Vec<Alarm>,
    /// Changes followed after an earlier alarm (or tonight's).
    pub changes: Vec<Change>,
    /// Remarks (runs of other models left out, where T²'s correlation came from).
    pub notes: Vec<String>,
}

impl Judgement {
    fn empty(run: &RunRecord) -> Judgement {
        Judgement {
            run_id: run.run_id.clone(),
            verdict: Verdict::Judged,
            baseline_runs: vec![],
            parameters: vec![],
            not_judged: vec![],
            t2: None,
            alarms: vec![],
            changes: vec![],
            notes: vec![],
        }
    }

    /// Whether any rule fired tonight.
    pub fn alarm(&self) -> bool {
        !self.alarms.is_empty()
    }

    /// One line for logs and reports.
    pub fn summary(&self) -> String {
        let open = self
            .changes
            .iter()
            .filter(|c| c.alarm_run != self.run_id)
            .count();
        let open = if open > 0 {
            format!("; {open} earlier change(s) followed")
        } else {
            String::new()
        };
        match &self.verdict {
            Verdict::NotJudged(why) => format!("drift not judged: {why}"),
            Verdict::Judged if self.alarms.is_empty() => format!(
                "drift: normal against {} baseline runs ({} parameters{}){open}",
                self.baseline_runs.len(),
                self.parameters.len(),
                self.t2
                    .map(|[t, l]| format!(", T² {t:.1} below {l:.1}"))
                    .unwrap_or_default()
            ),
            Verdict::Judged => format!("drift: {} alarm(s){open}", self.alarms.len()),
        }
    }
}

/// What the charts remember between nights, per model hash.
#[derive(Default)]
struct Memory {
    charts: HashMap<(String, String), ChartState>,
    /// The open T² change per model hash.
    vector: HashMap<String, Change>,
    /// New effects already alarmed, per (model hash, effect): the run of the alarm.
    effects: HashMap<(String, String), String>,
}

/// Judges every run of `runs` (oldest first) against the runs before it; the charts' memory
/// carries from run to run. Runs of another model than the judged run's are left out of its
/// history (and said so).
pub fn judge_series(runs: &[RunRecord], cfg: &JudgeConfig) -> Vec<Judgement> {
    let mut out: Vec<Judgement> = Vec::with_capacity(runs.len());
    let mut memory = Memory::default();
    for (j, run) in runs.iter().enumerate() {
        let judgement = judge_one(&runs[..j], &out, run, cfg, &mut memory);
        out.push(judgement);
    }
    out
}

/// Judges `run` after `earlier` (oldest first): the whole history is judged so the charts'
/// memory is tonight's; returns the last judgement.
pub fn judge_latest(earlier: &[RunRecord], run: &RunRecord, cfg: &JudgeConfig) -> Judgement {
    let mut all = earlier.to_vec();
    all.push(run.clone());
    judge_series(&all, cfg)
        .pop()
        .unwrap_or_else(|| Judgement::empty(run))
}

/// One night: choose the baseline, judge each parameter on its charts, then the vector, then
/// the effects.
fn judge_one(
    earlier: &[RunRecord],
    judged: &[Judgement],
    run: &RunRecord,
    cfg: &JudgeConfig,
    memory: &mut Memory,
) -> Judgement {
    let mut j = Judgement::empty(run);
    let base = match select_baseline(earlier, judged, run, cfg, &mut j.notes) {
        Ok(b) => b,
        Err(why) => {
            j.verdict = Verdict::NotJudged(why);
            return j;
        }
    };
    j.baseline_runs = base.iter().map(|r| r.run_id.clone()).collect();
    let covariate = compensated(cfg, run, &mut j.notes);
    for p in &run.parameters {
        judge_parameter(p, &base, covariate, run, cfg, memory, &mut j);
    }
    for q in &run.quantities {
        let before = j.alarms.len();
        judge_parameter(q, &base, covariate, run, cfg, memory, &mut j);
        say_what_moved(&mut j, before);
    }
    judge_vector(&base, run, cfg, memory, &mut j);
    judge_effects(&base, run, memory, &mut j);
    j
}

/// A derived quantity's alarm (the stable depth) says what an operator reads: "drift alarm
/// (Shewhart): stable depth … fell from 2.1 to 1.6 mm, −0.5 mm from normal (…)".
fn say_what_moved(j: &mut Judgement, from: usize) {
    let Some(q) = j.parameters.last() else {
        return;
    };
    let moved = format!(
        "{} {} from {} to {} {},",
        q.variable,
        if q.value < q.centre { "fell" } else { "rose" },
        sig(q.centre, 3),
        sig(q.value, 3),
        q.unit
    );
    for a in j.alarms[from..]
        .iter_mut()
        .filter(|a| a.subject == q.variable)
    {
        a.message = a.message.replacen(&format!("{} is", q.variable), &moved, 1);
    }
}

/// The baseline runs for `run`: same model, not failed, inside the window. Runs flagged by an
/// earlier judgement (an alarm or a confirmed change) are kept out of a rolling window.
fn select_baseline<'a>(
    earlier: &'a [RunRecord],
    judged: &[Judgement],
    run: &RunRecord,
    cfg: &JudgeConfig,
    notes: &mut Vec<String>,
) -> Result<Vec<&'a RunRecord>, String> {
    let same: Vec<&RunRecord> = earlier
        .iter()
        .filter(|r| r.outcome != "failure" && r.model_hash == run.model_hash)
        .collect();
    let others: Vec<&str> = {
        let mut o: Vec<&str> = earlier
            .iter()
            .filter(|r| r.model_hash != run.model_hash)
            .map(|r| r.model_hash.as_str())
            .collect();
        o.sort();
        o.dedup();
        o
    };
    if !others.is_empty() {
        let n = earlier
            .iter()
            .filter(|r| r.model_hash != run.model_hash)
            .count();
        notes.push(format!(
            "warning: {n} earlier run(s) identified another model (identity {}) than this run's ({}): they are not compared; if the model did not change, re-import those reports where their model file can be read",
            others.join(", "),
            run.model_hash
        ));
    }
    if run.outcome == "failure" {
        return Err("the run failed".into());
    }
    let (want, base): (usize, Vec<&RunRecord>) = match cfg.baseline {
        BaselineWindow::First(n) => (n, same.iter().take(n).copied().collect()),
        BaselineWindow::Rolling(n) => {
            let flagged = |r: &RunRecord| {
                judged
                    .iter()
                    .find(|x| x.run_id == r.run_id)
                    .is_some_and(|x| {
                        x.alarm() || x.changes.iter().any(|c| c.persists == Some(true))
                    })
            };
            let clean: Vec<&RunRecord> = same.iter().copied().filter(|r| !flagged(r)).collect();
            if clean.len() < same.len() {
                notes.push(format!(
                    "{} run(s) with an alarm or a confirmed change are left out of the rolling baseline",
                    same.len() - clean.len()
                ));
            }
            (n, clean[clean.len().saturating_sub(n)..].to_vec())
        }
    };
    if base.len() < want.max(3) {
        return Err(format!(
            "too few baseline runs of this model: {} of the {} the baseline window needs to learn normal run-to-run scatter",
            base.len(),
            want.max(3)
        ));
    }
    Ok(base)
}

/// The covariate value to compensate at, when configured and recorded with this run.
fn compensated<'a>(
    cfg: &'a JudgeConfig,
    run: &RunRecord,
    notes: &mut Vec<String>,
) -> Option<(&'a str, f64)> {
    let c = cfg.covariate.as_deref()?;
    match run.covariate(c) {
        Some(v) => Some((c, v)),
        None => {
            notes.push(format!(
                "covariate \"{c}\" not recorded with this run: parameters judged uncompensated"
            ));
            None
        }
    }
}

/// Judges one parameter: learns its normal, then either follows its open change or feeds its
/// charts.
fn judge_parameter(
    p: &ParameterRecord,
    base: &[&RunRecord],
    covariate: Option<(&str, f64)>,
    run: &RunRecord,
    cfg: &JudgeConfig,
    memory: &mut Memory,
    j: &mut Judgement,
) {
    let mut skip = |why: String| {
        j.not_judged.push(NotJudged {
            variable: p.variable.clone(),
            why,
        })
    };
    if !p.estimate.is_finite() {
        return skip(format!(
            "its value is {} (the fit did not determine it): kept out of every chart and of later baselines",
            p.estimate
        ));
    }
    let Some(nm) = learn(base, &p.variable, covariate.map(|c| c.0)) else {
        return skip("not in every baseline run".into());
    };
    if !(nm.scatter > 0.0) || !nm.scatter.is_finite() {
        return skip("no run-to-run scatter over the baseline".into());
    }
    let c_now = covariate.map(|c| c.1);
    let centre = nm.centre(c_now);
    let r = (p.estimate - centre) / nm.scatter;
    let widen = nm.widen(c_now);
    let lim = Limits {
        shewhart: cfg.shewhart_k * widen,
        cusum_k: cfg.cusum_k,
        cusum_h: cfg.cusum_h,
        lambda: cfg.ewma_lambda.clamp(1e-6, 1.0),
        ewma_l: cfg.ewma_l,
        n: nm.n,
    };
    let state = memory
        .charts
        .entry((run.model_hash.clone(), p.variable.clone()))
        .or_default();
    let f = nm.factor;
    let mut pj = ParameterJudgement {
        variable: p.variable.clone(),
        unit: nm.unit.clone(),
        value: p.estimate / f,
        centre: centre / f,
        scatter: nm.scatter / f,
        standardized: r,
        shewhart_limit: lim.shewhart,
        cusum: state.cusum,
        cusum_limit: lim.cusum_h,
        ewma: state.ewma,
        ewma_limit: lim.ewma_l * state.ewma_sigma(&lim),
        limits: [
            (centre - lim.shewhart * nm.scatter) / f,
            (centre + lim.shewhart * nm.scatter) / f,
        ],
        slope: covariate.map(|_| nm.b / f),
        held_out: false,
        changed_since: None,
    };
    if state.open.is_some() {
        follow_change(state, r, &mut pj, j);
    } else {
        feed_charts(state, &run.run_id, r, &lim, &mut pj, j);
    }
    if nm.left_out > 0 {
        j.notes.push(format!(
            "{}: {} baseline run(s) whose value is not a number are left out of its normal",
            p.variable, nm.left_out
        ));
    }
    if nm.screened > 0 {
        j.notes.push(format!(
            "{}: {} baseline run(s) beyond {SCREEN_MADS} MAD scatters are screened out of its scatter as outliers",
            p.variable, nm.screened
        ));
    }
    j.parameters.push(pj);
}

/// Feeds tonight's residual to the charts; the first rule that fires (Shewhart, CUSUM, EWMA)
/// raises the alarm and opens a change at the estimated change point.
fn feed_charts(
    state: &mut ChartState,
    run_id: &str,
    r: f64,
    lim: &Limits,
    pj: &mut ParameterJudgement,
    j: &mut Judgement,
) {
    let reading = state.update(run_id, r, lim);
    pj.cusum = reading.cusum;
    pj.ewma = reading.ewma;
    pj.ewma_limit = reading.ewma_limit;
    pj.held_out = reading.held_out;
    let Some(&(rule, stat)) = reading.fired.first() else {
        return;
    };
    let sign = stat.signum();
    let (tau, level) = if rule == Rule::Shewhart {
        (state.recent.len() - 1, r)
    } else {
        charts::change_point(&state.recent, sign).unwrap_or((state.recent.len() - 1, r))
    };
    let since = state.recent[tau].0.clone();
    let (change, what) = match rule {
        Rule::Ewma => (
            reading.ewma * pj.scatter,
            format!(
                "EWMA {:+.2} beyond its limit ±{:.2}",
                reading.ewma, reading.ewma_limit
            ),
        ),
        Rule::Cusum => (
            level * pj.scatter,
            format!(
                "CUSUM {:.2} beyond its limit {:.2}",
                stat.abs(),
                lim.cusum_h
            ),
        ),
        _ => (
            pj.value - pj.centre,
            format!("{r:+.1} × beyond the limit ±{:.1}×", lim.shewhart),
        ),
    };
    let multiples = if rule == Rule::Ewma {
        reading.ewma
    } else {
        change / pj.scatter
    };
    let message = format!(
        "drift alarm ({}): {} is {}{} {} from normal ({multiples:+.1} × its normal scatter {} {}; {what}) since run {since} (change-point estimate)",
        rule.as_str(),
        pj.variable,
        if change >= 0.0 { "+" } else { "" },
        sig(change, 3),
        pj.unit,
        sig(pj.scatter, 3),
        pj.unit,
    );
    j.alarms.push(Alarm {
        rule,
        subject: pj.variable.clone(),
        since_run: since.clone(),
        change: Some(change),
        unit: pj.unit.clone(),
        multiples: Some(multiples),
        message,
    });
    let change = Change {
        rule,
        subject: pj.variable.clone(),
        alarm_run: run_id.to_string(),
        change_point_run: since.clone(),
        level,
        nights_after: 0,
        persists: None,
        message: format!(
            "{}: changed since run {since} (change point), level {level:+.1} × scatter; the nights after the alarm will tell whether it persists",
            pj.variable
        ),
        sum_after: 0.0,
    };
    pj.changed_since = Some(since);
    state.open = Some(change.clone());
    state.restart();
    j.changes.push(change);
}

/// Follows an open change with tonight's residual: confirmed (persists) or, after
/// [`charts::CLOSE_AFTER`] unconfirmed nights, closed as a bad night and the charts resumed.
fn follow_change(state: &mut ChartState, r: f64, pj: &mut ParameterJudgement, j: &mut Judgement) {
    let Some(c) = state.open.as_mut() else {
        return;
    };
    c.nights_after += 1;
    c.sum_after += r.clamp(-charts::CLIP * 2.0, charts::CLIP * 2.0);
    let k = c.nights_after;
    let sign = c.level.signum();
    c.persists = charts::persists(c.sum_after, k, sign);
    let mean = c.sum_after / k as f64;
    pj.changed_since = Some(c.change_point_run.clone());
    if c.persists == Some(true) {
        c.level = mean;
        c.message = format!(
            "{}: the change since run {} persists: new level {mean:+.1} × scatter ({}{} {}) over {k} night(s) after the alarm",
            c.subject,
            c.change_point_run,
            if mean >= 0.0 { "+" } else { "" },
            sig(mean * pj.scatter, 3),
            pj.unit
        );
        j.changes.push(c.clone());
    } else if k >= charts::CLOSE_AFTER {
        let mut closed = c.clone();
        closed.message = format!(
            "{}: the change at run {} did not persist ({k} nights after it average {mean:+.1} × scatter): back to normal, charts resumed",
            c.subject, c.alarm_run
        );
        j.notes.push(closed.message.clone());
        state.open = None;
        state.restart();
        pj.changed_since = None;
    } else {
        c.message = format!(
            "{}: after the alarm at run {}, {k} night(s) average {mean:+.1} × scatter: not confirmed yet",
            c.subject, c.alarm_run
        );
        j.changes.push(c.clone());
    }
}

/// Hotelling T² over the parameters judged tonight that raised no alarm and follow no change;
/// an open T² change is followed like a parameter's (the nights' T² / limit).
fn judge_vector(
    base: &[&RunRecord],
    run: &RunRecord,
    cfg: &JudgeConfig,
    memory: &mut Memory,
    j: &mut Judgement,
) {
    let covariate = cfg
        .covariate
        .as_deref()
        .filter(|c| run.covariate(c).is_some());
    // Tonight's judged parameters that follow no change: name, residual, baseline normal. The
    // derived quantities are functions of the parameters: they would count twice.
    let judged: Vec<(String, f64, Normal)> = j
        .parameters
        .iter()
        .filter(|p| p.changed_since.is_none())
        .filter(|p| run.parameters.iter().any(|q| q.variable == p.variable))
        .filter_map(|p| {
            Some((
                p.variable.clone(),
                p.standardized,
                learn(base, &p.variable, covariate)?,
            ))
        })
        .collect();
    let parts: Vec<multivariate::Component> = judged
        .iter()
        .map(|(variable, r, nm)| multivariate::Component {
            variable,
            r: *r,
            baseline: nm
                .residuals
                .iter()
                .map(|(id, v)| (id.as_str(), v / nm.scatter))
                .collect(),
        })
        .collect();
    if parts.len() < 2 {
        return;
    }
    let t = match multivariate::t2(&parts, base, cfg.t2_alpha) {
        Ok(t) => t,
        Err(why) => {
            j.notes.push(format!("Hotelling T² not computed: {why}"));
            return;
        }
    };
    j.t2 = Some([t.t2, t.limit]);
    j.notes.push(format!(
        "Hotelling T² {:.1} (limit {:.1}) over {} parameters, correlation from {}",
        t.t2,
        t.limit,
        parts.len(),
        t.correlation
    ));
    let ratio = t.t2 / t.limit;
    if let Some(c) = memory.vector.get_mut(&run.model_hash) {
        c.nights_after += 1;
        // Under no change T² / limit averages p / limit; a persisting change keeps it above 1/2.
        c.sum_after += ratio;
        let mean = c.sum_after / c.nights_after as f64;
        c.persists = Some(mean > 0.5);
        c.level = mean;
        if c.persists == Some(true) || c.nights_after < charts::CLOSE_AFTER {
            c.message = format!(
                "{VECTOR}: after the T² alarm at run {}, {} night(s) average T² {mean:.2} × its limit{}",
                c.alarm_run,
                c.nights_after,
                if c.persists == Some(true) { ": the change persists" } else { "" }
            );
            j.changes.push(c.clone());
        } else {
            j.notes.push(format!(
                "{VECTOR}: the T² change at run {} did not persist (T² back below half its limit): back to normal",
                c.alarm_run
            ));
            memory.vector.remove(&run.model_hash);
        }
        return;
    }
    if ratio <= 1.0 || j.alarm() {
        return;
    }
    let mut top: Vec<(&str, f64)> = judged.iter().map(|(v, r, _)| (v.as_str(), *r)).collect();
    top.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    let names: Vec<String> = top
        .iter()
        .take(3)
        .map(|(v, r)| format!("{v} {r:+.1}×"))
        .collect();
    j.alarms.push(Alarm {
        rule: Rule::HotellingT2,
        subject: VECTOR.into(),
        since_run: run.run_id.clone(),
        change: None,
        unit: String::new(),
        multiples: Some(ratio),
        message: format!(
            "drift alarm (Hotelling T²): the parameters together are off their normal correlation pattern, T² {:.1} > limit {:.1} ({ratio:.1}×) since run {}; largest single deviations {}",
            t.t2,
            t.limit,
            run.run_id,
            names.join(", ")
        ),
    });
    let change = Change {
        rule: Rule::HotellingT2,
        subject: VECTOR.into(),
        alarm_run: run.run_id.clone(),
        change_point_run: run.run_id.clone(),
        level: ratio,
        nights_after: 0,
        persists: None,
        message: format!("{VECTOR}: T² alarm at run {}", run.run_id),
        sum_after: 0.0,
    };
    memory.vector.insert(run.model_hash.clone(), change.clone());
    j.changes.push(change);
}

/// An effect diagnosis accepted that no baseline run needed: an alarm the first night, a
/// persisting change after.
fn judge_effects(base: &[&RunRecord], run: &RunRecord, memory: &mut Memory, j: &mut Judgement) {
    for e in &run.effects {
        if base.iter().any(|r| r.effects.contains(e)) {
            continue;
        }
        let key = (run.model_hash.clone(), e.clone());
        if let Some(first) = memory.effects.get(&key) {
            j.changes.push(Change {
                rule: Rule::NewEffect,
                subject: e.clone(),
                alarm_run: first.clone(),
                change_point_run: first.clone(),
                level: 1.0,
                nights_after: 0,
                persists: Some(true),
                message: format!("new effect \"{e}\" since run {first}: still accepted tonight"),
                sum_after: 0.0,
            });
        } else {
            memory.effects.insert(key, run.run_id.clone());
            j.alarms.push(Alarm {
                rule: Rule::NewEffect,
                subject: e.clone(),
                message: format!(
                    "drift alarm (new effect): diagnosis accepted \"{e}\", which none of the {} baseline runs needed (a loosened joint, a new contact?)",
                    base.len()
                ),
                since_run: run.run_id.clone(),
                change: None,
                unit: String::new(),
                multiples: None,
            });
        }
    }
}
