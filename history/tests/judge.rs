//! Drift judgement on analytic cases: robust scatter, steps, slow drifts, a correlated pair along
//! and across its direction, temperature compensation, new effects, too few runs, other models.

#![allow(clippy::unwrap_used)]

use history::judge::{
    judge_latest, judge_series, robust_scatter, BaselineWindow, JudgeConfig, Rule, Verdict,
};
use history::record::{Covariate, ParameterRecord, RunRecord};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// A run with parameters in N/µm (SI = 1e6 × value).
fn run(
    i: usize,
    hash: &str,
    values: &[(&str, f64)],
    temp: Option<f64>,
    effects: &[&str],
) -> RunRecord {
    RunRecord {
        run_id: format!("n{i:03}"),
        time_utc: format!("2026-01-01T00:00:{i:02}Z"),
        stand: None,
        model_hash: hash.into(),
        session: None,
        outcome: "ok".into(),
        reduced_chi2: None,
        parameters: values
            .iter()
            .map(|(n, v)| ParameterRecord {
                variable: (*n).into(),
                unit: "N/um".into(),
                unit_factor: 1e6,
                estimate: v * 1e6,
                std_error: Some(1e3),
            })
            .collect(),
        characteristics: vec![],
        effects: effects.iter().map(|e| (*e).into()).collect(),
        covariates: temp
            .map(|t| {
                vec![Covariate {
                    name: "temperature".into(),
                    unit: "degC".into(),
                    value: t,
                }]
            })
            .unwrap_or_default(),
        correlations: vec![],
        quantities: vec![],
    }
}

fn normal_runs(n: usize, seed: u64, sigma: f64) -> Vec<RunRecord> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n)
        .map(|i| {
            let e: f64 = StandardNormal.sample(&mut rng);
            let f: f64 = StandardNormal.sample(&mut rng);
            run(
                i,
                "A",
                &[("k1", 100.0 + sigma * e), ("k2", 50.0 + sigma * f)],
                None,
                &[],
            )
        })
        .collect()
}

fn cfg(n: usize) -> JudgeConfig {
    JudgeConfig {
        baseline: BaselineWindow::First(n),
        ..JudgeConfig::default()
    }
}

#[test]
fn robust_scatter_is_median_and_mad_times_1_4826_and_ignores_an_outlier() {
    let (m, s) = robust_scatter(&[1.0, 2.0, 3.0, 4.0, 100.0]);
    assert_eq!(m, 3.0);
    assert!((s - 1.4826).abs() < 1e-12);
}

#[test]
fn too_few_baseline_runs_are_not_judged_and_say_why() {
    let runs = normal_runs(5, 1, 1.0);
    let j = judge_series(&runs, &cfg(20));
    for x in &j {
        match &x.verdict {
            Verdict::NotJudged(why) => assert!(why.contains("too few baseline runs"), "{why}"),
            v => panic!("{v:?}"),
        }
        assert!(x.alarms.is_empty());
    }
    assert!(j[4].summary().contains("4 of the 20"), "{}", j[4].summary());
}

#[test]
fn runs_of_another_model_are_not_compared() {
    let mut runs = normal_runs(25, 2, 1.0);
    let mut b = run(25, "B", &[("k1", 60.0), ("k2", 50.0)], None, &[]);
    b.time_utc = "2026-01-02T00:00:00Z".into();
    runs.push(b);
    let j = judge_series(&runs, &cfg(20)).pop().unwrap();
    assert!(
        matches!(j.verdict, Verdict::NotJudged(_)),
        "{:?}",
        j.verdict
    );
    assert!(
        j.notes.iter().any(|n| n
            .contains("25 earlier run(s) identified another model (identity A)")
            && n.contains("(B)")),
        "{:?}",
        j.notes
    );
}

#[test]
fn a_step_is_a_shewhart_alarm_with_its_size_and_start() {
    let sigma = 0.5; // N/µm
    let mut runs = normal_runs(20, 3, sigma);
    runs.push(run(20, "A", &[("k1", 100.0), ("k2", 50.0)], None, &[]));
    runs.push(run(21, "A", &[("k1", 80.0), ("k2", 50.0)], None, &[]));
    runs.push(run(22, "A", &[("k1", 80.2), ("k2", 50.0)], None, &[]));
    let j = judge_series(&runs, &cfg(20));
    assert!(j[..20]
        .iter()
        .all(|x| matches!(x.verdict, Verdict::NotJudged(_))));
    assert!(!j[20].alarm(), "{:?}", j[20].alarms);
    let base: Vec<f64> = runs[..20]
        .iter()
        .map(|r| r.parameters[0].in_unit())
        .collect();
    let (centre, mad) = robust_scatter(&base);
    // The scatter: standard deviation about the median of the runs within 5 MAD scatters.
    let kept: Vec<f64> = base
        .iter()
        .map(|x| x - centre)
        .filter(|r| r.abs() <= 5.0 * mad)
        .collect();
    let scatter = (kept.iter().map(|r| r * r).sum::<f64>() / (kept.len() - 1) as f64).sqrt();
    let x = &j[21];
    let a = x.alarms.iter().find(|a| a.rule == Rule::Shewhart).unwrap();
    assert_eq!(a.subject, "k1");
    assert_eq!(a.since_run, "n021", "the change started at the step");
    let v = runs[21].parameters[0].in_unit();
    assert!((a.change.unwrap() - (v - centre)).abs() < 1e-9);
    assert!((a.multiples.unwrap() - (v - centre) / scatter).abs() < 1e-9);
    assert!(a.message.contains("N/um"), "{}", a.message);
    assert!(!x.alarms.iter().any(|a| a.subject == "k2"));
    // The night after: no second alarm; the change is followed, confirmed, from its change point.
    let x = &j[22];
    assert!(!x.alarm(), "{:?}", x.alarms);
    let c = x.changes.iter().find(|c| c.subject == "k1").unwrap();
    assert_eq!(c.change_point_run, "n021");
    assert_eq!(c.persists, Some(true));
    assert!(c.message.contains("persists"), "{}", c.message);
}

#[test]
fn a_slow_drift_is_caught_by_the_cusum_or_ewma_long_before_the_shewhart_limit() {
    let sigma = 0.5;
    let mut runs = normal_runs(20, 4, sigma);
    // 0.4 σ per run, no noise: Shewhart needs |r| > 4.6, i.e. ~12 runs.
    for t in 0..20 {
        runs.push(run(
            20 + t,
            "A",
            &[("k1", 100.0 - 0.4 * sigma * (t + 1) as f64), ("k2", 50.0)],
            None,
            &[],
        ));
    }
    let j = judge_series(&runs, &cfg(20));
    let first = j
        .iter()
        .position(|x| x.alarms.iter().any(|a| a.subject == "k1"))
        .unwrap();
    assert!(first - 20 <= 10, "the drift took {} runs", first - 20);
    let a = j[first].alarms.iter().find(|a| a.subject == "k1").unwrap();
    assert!(matches!(a.rule, Rule::Cusum | Rule::Ewma), "{a:?}");
    assert!(a.change.unwrap() < 0.0 && a.multiples.unwrap() < 0.0);
    assert!(a.since_run.as_str() <= j[first].run_id.as_str() && a.since_run.as_str() >= "n020");
    // Raised once: the later nights follow the change instead of repeating the alarm.
    assert!(j[first + 1..]
        .iter()
        .all(|x| !x.alarms.iter().any(|a| a.subject == "k1")));
    assert!(j
        .last()
        .unwrap()
        .changes
        .iter()
        .any(|c| c.subject == "k1" && c.persists == Some(true)));
}

#[test]
fn one_outlier_night_is_one_alarm_and_the_normal_nights_after_raise_none() {
    let sigma = 0.5;
    let mut runs = normal_runs(60, 9, sigma);
    // Night 30: a 20-sd outlier in k1; the nights after are normal again.
    runs[30].parameters[0].estimate += 20.0 * sigma * 1e6;
    let j = judge_series(&runs, &cfg(20));
    let alarms: Vec<(usize, Rule)> = j
        .iter()
        .enumerate()
        .flat_map(|(i, x)| {
            x.alarms
                .iter()
                .filter(|a| a.subject == "k1")
                .map(move |a| (i, a.rule))
        })
        .collect();
    assert_eq!(alarms, vec![(30, Rule::Shewhart)]);
    // The outlier never entered the CUSUM or EWMA, and the change closed as a bad night.
    let k1 = |i: usize| {
        j[i].parameters
            .iter()
            .find(|p| p.variable == "k1")
            .unwrap()
            .clone()
    };
    assert!(k1(30).held_out);
    assert!(j[33].changes.iter().all(|c| c.subject != "k1"));
    assert!(
        j[30..34]
            .iter()
            .flat_map(|x| &x.notes)
            .any(|n| n.contains("did not persist")),
        "{:?}",
        j[32].notes
    );
    assert!(k1(40).cusum.iter().all(|c| *c < 3.5));
}

#[test]
fn a_value_that_is_not_a_number_is_not_judged_and_says_why() {
    let mut runs = normal_runs(22, 10, 0.5);
    runs[21].parameters[0].estimate = f64::NAN;
    // A NaN inside the baseline is left out of it, not learnt from.
    runs[5].parameters[1].estimate = f64::NAN;
    let j = judge_series(&runs, &cfg(20));
    let last = j.last().unwrap();
    assert_eq!(last.verdict, Verdict::Judged);
    let n = last.not_judged.iter().find(|n| n.variable == "k1").unwrap();
    assert!(n.why.contains("NaN"), "{}", n.why);
    let k2 = last.parameters.iter().find(|p| p.variable == "k2").unwrap();
    assert!(k2.scatter.is_finite() && k2.centre.is_finite());
    assert!(!last.alarm());
}

#[test]
fn the_cramer_rao_correlation_makes_a_pair_moving_across_it_a_t2_alarm() {
    // ρ = −0.78 between k1 and k2, as the fit's Cramér-Rao correlation says.
    let rho: f64 = -0.78;
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    let mut runs: Vec<RunRecord> = (0..30)
        .map(|i| {
            let u: f64 = StandardNormal.sample(&mut rng);
            let e: f64 = StandardNormal.sample(&mut rng);
            let v = rho * u + (1.0 - rho * rho).sqrt() * e;
            run(i, "A", &[("k1", 100.0 + u), ("k2", 50.0 + v)], None, &[])
        })
        .collect();
    for r in &mut runs {
        r.correlations = vec![history::record::Correlation {
            a: "k1".into(),
            b: "k2".into(),
            value: rho,
        }];
    }
    // Each +1.5 sd: across the correlation, 4.5 sd in its direction of least scatter.
    let mut across = run(30, "A", &[("k1", 101.5), ("k2", 51.5)], None, &[]);
    across.correlations = runs[0].correlations.clone();
    let j = judge_latest(&runs, &across, &cfg(30));
    assert!(
        j.alarms.iter().any(|a| a.rule == Rule::HotellingT2),
        "{:?} {:?}",
        j.t2,
        j.notes
    );
    assert!(
        j.notes.iter().any(|n| n.contains("Cramér-Rao")),
        "{:?}",
        j.notes
    );
    // The limit is the χ²(2) quantile at 1 − α, widened by 1 + 1/n.
    let [_, limit] = j.t2.unwrap();
    let q = -2.0 * JudgeConfig::default().t2_alpha.ln();
    assert!((limit - q * (1.0 + 1.0 / 30.0)).abs() < 1e-6, "{limit}");
}

#[test]
fn hotelling_t2_accepts_a_correlated_pair_along_its_direction_and_flags_it_across() {
    // k1 and k2 share a common factor (ρ ≈ 0.98): u ~ N(0, 1), e ~ N(0, 0.2).
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    let mut runs: Vec<RunRecord> = (0..30)
        .map(|i| {
            let u: f64 = StandardNormal.sample(&mut rng);
            let e: [f64; 2] = [
                StandardNormal.sample(&mut rng),
                StandardNormal.sample(&mut rng),
            ];
            run(
                i,
                "A",
                &[
                    ("k1", 100.0 + u + 0.2 * e[0]),
                    ("k2", 50.0 + u + 0.2 * e[1]),
                ],
                None,
                &[],
            )
        })
        .collect();
    let base: Vec<&RunRecord> = runs.iter().collect();
    let med = |k: usize| {
        robust_scatter(
            &base
                .iter()
                .map(|r| r.parameters[k].in_unit())
                .collect::<Vec<_>>(),
        )
        .0
    };
    let (m1, m2) = (med(0), med(1));
    let along = run(30, "A", &[("k1", m1 + 2.5), ("k2", m2 + 2.5)], None, &[]);
    let across = run(30, "A", &[("k1", m1 + 1.0), ("k2", m2 - 1.0)], None, &[]);
    let c = cfg(30);
    let ja = judge_latest(&runs, &along, &c);
    let jx = judge_latest(&runs, &across, &c);
    let [t_along, limit] = ja.t2.unwrap();
    let [t_across, _] = jx.t2.unwrap();
    assert!(t_along < limit, "along: T² {t_along} ≥ {limit}");
    assert!(t_across > limit, "across: T² {t_across} ≤ {limit}");
    assert!(!ja.alarm(), "{:?}", ja.alarms);
    assert!(jx.alarms.iter().any(|a| a.rule == Rule::HotellingT2));
    // Neither moved beyond its own Shewhart limit: only the pattern tells them apart.
    assert!(!jx.alarms.iter().any(|a| a.rule == Rule::Shewhart));
    runs.push(across);
}

#[test]
fn temperature_compensation_removes_the_normal_thermal_swing() {
    // k1 = 100 − 0.5 (T − 20) N/µm exactly, plus 0.05 N/µm noise; baseline T in 18..22 °C.
    let mut rng = rand::rngs::StdRng::seed_from_u64(6);
    let mut runs: Vec<RunRecord> = (0..20)
        .map(|i| {
            let t = 18.0 + 4.0 * (i as f64 * 0.37).fract();
            let e: f64 = StandardNormal.sample(&mut rng);
            let f: f64 = StandardNormal.sample(&mut rng);
            run(
                i,
                "A",
                &[
                    ("k1", 100.0 - 0.5 * (t - 20.0) + 0.05 * e),
                    ("k2", 50.0 + 0.05 * f),
                ],
                Some(t),
                &[],
            )
        })
        .collect();
    // A warm night (30 °C) on the same line: normal once compensated.
    let warm = run(20, "A", &[("k1", 95.0), ("k2", 50.0)], Some(30.0), &[]);
    let plain = judge_latest(&runs, &warm, &cfg(20));
    assert!(
        plain
            .alarms
            .iter()
            .any(|a| a.subject == "k1" && a.rule == Rule::Shewhart),
        "uncompensated: the warm night looks like a step"
    );
    let comp = JudgeConfig {
        covariate: Some("temperature".into()),
        ..cfg(20)
    };
    let j = judge_latest(&runs, &warm, &comp);
    assert!(!j.alarm(), "{:?}", j.alarms);
    let k1 = j.parameters.iter().find(|p| p.variable == "k1").unwrap();
    assert!(
        (k1.slope.unwrap() + 0.5).abs() < 0.02,
        "slope {:?}",
        k1.slope
    );
    assert!((k1.centre - 95.0).abs() < 0.2, "centre {}", k1.centre);
    // A real 2 % loss at the warm temperature is still seen.
    runs.push(run(20, "A", &[("k1", 93.0), ("k2", 50.0)], Some(30.0), &[]));
    let j = judge_series(&runs, &comp).pop().unwrap();
    assert!(j
        .alarms
        .iter()
        .any(|a| a.subject == "k1" && a.rule == Rule::Shewhart));
}

#[test]
fn an_effect_no_baseline_run_needed_is_a_new_effect_alarm() {
    let mut runs = normal_runs(20, 7, 0.5);
    runs[3].effects = vec!["spring spindle head–table".into()];
    let known = run(
        20,
        "A",
        &[("k1", 100.0), ("k2", 50.0)],
        None,
        &["spring spindle head–table"],
    );
    assert!(!judge_latest(&runs, &known, &cfg(20)).alarm());
    let new = run(
        20,
        "A",
        &[("k1", 100.0), ("k2", 50.0)],
        None,
        &["spring column–bed"],
    );
    let j = judge_latest(&runs, &new, &cfg(20));
    let a = j.alarms.iter().find(|a| a.rule == Rule::NewEffect).unwrap();
    assert_eq!(a.subject, "spring column–bed");
    assert!(a.message.contains("none of the 20 baseline runs"));
}

#[test]
fn a_rolling_window_follows_the_last_runs_and_a_failed_run_is_not_judged() {
    let mut runs = normal_runs(30, 8, 0.5);
    let mut failed = run(30, "A", &[], None, &[]);
    failed.outcome = "failure".into();
    runs.push(failed);
    let c = JudgeConfig {
        baseline: BaselineWindow::Rolling(10),
        ..JudgeConfig::default()
    };
    let j = judge_series(&runs, &c);
    assert!(matches!(j[30].verdict, Verdict::NotJudged(ref w) if w.contains("failed")));
    // The window: the 10 runs just before, leaving out those with an alarm or a confirmed change.
    let flagged = |x: &history::judge::Judgement| {
        x.alarm() || x.changes.iter().any(|c| c.persists == Some(true))
    };
    let want: Vec<String> = j[..29]
        .iter()
        .filter(|x| !flagged(x))
        .map(|x| x.run_id.clone())
        .collect();
    assert_eq!(j[29].baseline_runs, want[want.len() - 10..].to_vec());
}
