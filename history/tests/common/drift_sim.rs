//! Simulated night series for the drift charts' power: each night a report (the `report.json`
//! a nightly writes: 17 identified parameters with their Cramér-Rao errors and correlation
//! matrix) whose values scatter from night to night by 3-10× the Cramér-Rao error with the
//! report's correlation; read by the history import (`history::import::run_from_report_text`),
//! optionally stored in a history database and read back, and judged by `judge_series`: the
//! path a nightly run's record takes. Shared by the CI test (a fixed small subset) and the power
//! example (the table in docs/nightly.md).

use history::judge::{judge_series, JudgeConfig, Judgement, Rule};
use history::record::RunRecord;
use nalgebra::DMatrix;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

/// Parameters judged per night.
pub const P: usize = 17;

/// What changes, from which night.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    /// Nothing.
    None,
    /// Parameter `i` steps by `sd` scatters from night `at`.
    Step { i: usize, at: usize, sd: f64 },
    /// Parameter `i` drifts by `per_night` scatters per night from night `at`.
    Trend { i: usize, at: usize, per_night: f64 },
    /// The correlated pair (0, 1) each moves by `sd` scatters from night `at` (across their
    /// negative correlation).
    Pair { at: usize, sd: f64 },
    /// Parameter `i` is off by `sd` scatters on night `at` only.
    Outlier { i: usize, at: usize, sd: f64 },
}

/// One simulated series.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Nights.
    pub nights: usize,
    /// Scatter in Cramér-Rao errors: each parameter's drawn uniformly from this range.
    pub scatter_crlb: (f64, f64),
    /// Correlated as the report says (else independent scatter, identity correlation reported).
    pub correlated: bool,
    /// The change.
    pub change: Change,
    /// Store each run in a history database and judge what it reads back.
    pub through_store: bool,
}

/// The correlation of the simulated report: the pair (0, 1) at ρ = −0.78 (two joints whose
/// stiffnesses the fit trades against each other), a block of five at +0.5 (isolators seen by
/// the same characteristics), a block of four at −0.25, the rest independent.
pub fn correlation() -> DMatrix<f64> {
    let mut r = DMatrix::<f64>::identity(P, P);
    r[(0, 1)] = -0.78;
    r[(1, 0)] = -0.78;
    for (lo, hi, rho) in [(2usize, 7usize, 0.5), (7, 11, -0.25)] {
        for a in lo..hi {
            for b in lo..hi {
                if a != b {
                    r[(a, b)] = rho;
                }
            }
        }
    }
    r
}

fn report_json(night: usize, values: &[f64], crlb: &[f64], corr: &DMatrix<f64>) -> String {
    let params: Vec<serde_json::Value> = (0..P)
        .map(|i| {
            serde_json::json!({
                "variable": format!("k{i:02}"), "sdes": format!("{i}"), "parameter": "kn",
                "unit": "N/um", "initial": 100.0, "identified": values[i],
                "std_error": crlb[i], "variability": crlb[i] / values[i], "at_bound": null
            })
        })
        .collect();
    let corr: Vec<Vec<f64>> = (0..P)
        .map(|a| (0..P).map(|b| corr[(a, b)]).collect())
        .collect();
    serde_json::json!({
        "schema": "ident.report/1", "title": "simulated night",
        "created_utc": format!("2026-{:02}-{:02}T02:00:00Z", 1 + night / 28, 1 + night % 28),
        "source": {"workflow": "nightly", "session": null, "stand": "simulated", "model": "models/simulated.toml",
                   "variables": "v.toml", "measurement": "simulated", "software": "ident"},
        "status": {"outcome": "ok", "messages": []},
        "characteristics": [],
        "identification": {"optimizer": "lm", "converged": true, "stop": "converged", "iterations": 5,
            "observations": 100, "noise": "simulated", "criterion_initial": 1.0, "criterion": 0.5,
            "reduced_chi2": 1.0, "parameters": params, "correlation": corr, "weak_directions": []},
        "diagnosis": null, "sensitivity": null, "drift": null
    })
    .to_string()
}

/// The true shift of parameter `i` on night `n` (scatters).
fn shift(change: Change, i: usize, n: usize) -> f64 {
    match change {
        Change::None => 0.0,
        Change::Step { i: j, at, sd } => {
            if i == j && n >= at {
                sd
            } else {
                0.0
            }
        }
        Change::Trend {
            i: j,
            at,
            per_night,
        } => {
            if i == j && n >= at {
                per_night * (n - at + 1) as f64
            } else {
                0.0
            }
        }
        Change::Pair { at, sd } => {
            if i < 2 && n >= at {
                sd
            } else {
                0.0
            }
        }
        Change::Outlier { i: j, at, sd } => {
            if i == j && n == at {
                sd
            } else {
                0.0
            }
        }
    }
}

/// The runs of one seed, as the history reads them.
pub fn runs(setup: &Setup, seed: u64) -> Vec<RunRecord> {
    let mut rng = StdRng::seed_from_u64(seed);
    let corr = if setup.correlated {
        correlation()
    } else {
        DMatrix::identity(P, P)
    };
    let l = corr.clone().cholesky().expect("a correlation matrix").l();
    let truth: Vec<f64> = (0..P).map(|i| 50.0 + 5.0 * i as f64).collect();
    let crlb: Vec<f64> = truth.iter().map(|t| 0.002 * t).collect();
    let scatter: Vec<f64> = (0..P)
        .map(|i| crlb[i] * rng.random_range(setup.scatter_crlb.0..=setup.scatter_crlb.1))
        .collect();
    let dir = std::env::temp_dir().join(format!("ident-drift-sim-{}-{seed}", std::process::id()));
    let mut store = setup.through_store.then(|| {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        history::store::Store::open(&dir.join("history.sqlite")).expect("a history database")
    });
    let mut out = Vec::with_capacity(setup.nights);
    for n in 0..setup.nights {
        let e: Vec<f64> = (0..P).map(|_| StandardNormal.sample(&mut rng)).collect();
        let z = &l * nalgebra::DVector::from_vec(e);
        let values: Vec<f64> = (0..P)
            .map(|i| truth[i] + scatter[i] * (z[i] + shift(setup.change, i, n)))
            .collect();
        let text = report_json(n, &values, &crlb, &corr);
        let path = std::path::PathBuf::from(format!("reports/night-{n:03}/report.json"));
        let run = history::import::run_from_report_text(&text, &path, &format!("night-{n:03}"))
            .expect("a simulated report imports");
        match store.as_mut() {
            Some(s) => s.append(&run).expect("stored"),
            None => out.push(run),
        }
    }
    if let Some(s) = store {
        out = s.runs().expect("read back");
        drop(s);
        let _ = std::fs::remove_dir_all(&dir);
    }
    out
}

/// What the charts did on one seed.
#[derive(Debug, Clone, Default)]
pub struct Outcome {
    /// Alarms on parameter-nights whose truth was normal (T² alarms on nights with no change
    /// count once each).
    pub false_alarms: usize,
    /// Judged parameter-nights whose truth was normal.
    pub normal_parameter_nights: usize,
    /// Nights from the change to its first alarm (0: the night it started), if caught.
    pub delay: Option<usize>,
    /// Alarms on nights after an outlier night.
    pub alarms_after_outlier: usize,
    /// False alarms per rule: Shewhart, CUSUM, EWMA, T².
    pub by_rule: [usize; 4],
}

fn names(i: usize) -> String {
    format!("k{i:02}")
}

fn changed(change: Change) -> (Vec<usize>, usize) {
    match change {
        Change::None => (vec![], usize::MAX),
        Change::Step { i, at, .. }
        | Change::Trend { i, at, .. }
        | Change::Outlier { i, at, .. } => (vec![i], at),
        Change::Pair { at, .. } => (vec![0, 1], at),
    }
}

/// Judges one seed's runs and scores them against the truth.
pub fn score(setup: &Setup, runs: &[RunRecord], cfg: &JudgeConfig) -> Outcome {
    let js: Vec<Judgement> = judge_series(runs, cfg);
    let (moved, at) = changed(setup.change);
    let mut o = Outcome::default();
    for (n, j) in js.iter().enumerate() {
        if j.verdict != history::judge::Verdict::Judged {
            continue;
        }
        let is_changed = |i: usize| shift(setup.change, i, n) != 0.0;
        let t2 = j.alarms.iter().any(|a| a.rule == Rule::HotellingT2);
        for i in 0..P {
            if is_changed(i) {
                continue;
            }
            o.normal_parameter_nights += 1;
            let fired = j.alarms.iter().find(|a| a.subject == names(i));
            o.false_alarms += usize::from(fired.is_some());
            if let Some(a) = fired {
                let k = match a.rule {
                    Rule::Shewhart => 0,
                    Rule::Cusum => 1,
                    _ => 2,
                };
                o.by_rule[k] += 1;
            }
        }
        let caught = moved
            .iter()
            .any(|i| j.alarms.iter().any(|a| a.subject == names(*i)))
            || t2;
        if n >= at && caught && o.delay.is_none() {
            o.delay = Some(n - at);
        }
        if t2
            && (0..P).all(|i| !is_changed(i))
            && (n < at || moved.is_empty() || matches!(setup.change, Change::Outlier { .. }))
        {
            o.false_alarms += 1;
            o.by_rule[3] += 1;
        }
        if let Change::Outlier { .. } = setup.change {
            if n > at {
                o.alarms_after_outlier += j.alarms.len();
            }
        }
    }
    o
}
