//! The drift charts' power, measured: the targets of issue 41 and the power table of
//! docs/nightly.md. Each night is a simulated `report.json` (17 parameters, run-to-run scatter
//! 3-10× their Cramér-Rao errors, correlated as the report's correlation matrix says) read by the
//! history import and judged by `judge_series`, with the default chart settings and a
//! first-30-runs baseline. Not run in CI (`history/tests/power.rs` runs a small fixed subset):
//!
//!     cargo run --release -p history --example power            # targets + table
//!     cargo run --release -p history --example power -- targets # the targets only
//!
//! Targets (20 seeds each, through a history database): false alarms per 1000 parameter-nights,
//! a 3-sd step within 2 nights, a 0.1 sd/night trend within 15 nights of its start, the
//! correlated pair (ρ = −0.78, +1.5 sd each) within 3 nights, alarms after one 20-sd outlier.
//! Table: in-control and out-of-control average run lengths for steps and trends of 1-5 sd with
//! the scatter, the correlation and the baseline length varied.

#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../tests/common/drift_sim.rs"]
mod drift_sim;

use drift_sim::{Change, Outcome, Setup};
use history::judge::{BaselineWindow, JudgeConfig};

fn config(baseline: usize) -> JudgeConfig {
    JudgeConfig {
        baseline: BaselineWindow::First(baseline),
        ..JudgeConfig::default()
    }
}

fn run(setup: &Setup, cfg: &JudgeConfig, seeds: std::ops::Range<u64>) -> Vec<Outcome> {
    seeds
        .map(|s| drift_sim::score(setup, &drift_sim::runs(setup, s), cfg))
        .collect()
}

fn delays(o: &[Outcome]) -> Vec<Option<usize>> {
    o.iter().map(|x| x.delay).collect()
}

fn within(d: &[Option<usize>], k: usize) -> String {
    let n = d.iter().filter(|x| x.is_some_and(|v| v <= k)).count();
    format!(
        "{n}/{} ({:.0} %)",
        d.len(),
        100.0 * n as f64 / d.len() as f64
    )
}

fn median_max(d: &[Option<usize>]) -> String {
    let mut v: Vec<usize> = d.iter().flatten().copied().collect();
    v.sort();
    if v.is_empty() {
        return "never".into();
    }
    format!(
        "median {}, max {}{}",
        v[v.len() / 2],
        v[v.len() - 1],
        if v.len() < d.len() {
            format!(", {} never", d.len() - v.len())
        } else {
            String::new()
        }
    )
}

fn fa_rate(o: &[Outcome]) -> (usize, usize) {
    (
        o.iter().map(|x| x.false_alarms).sum(),
        o.iter().map(|x| x.normal_parameter_nights).sum(),
    )
}

fn targets() {
    let cfg = config(30);
    let setup = |change| Setup {
        nights: 90,
        scatter_crlb: (3.0, 10.0),
        correlated: true,
        change,
        through_store: std::env::var_os("IDENT_POWER_NO_STORE").is_none(),
    };
    let seeds = 1..21;
    println!("## Targets: 20 seeds × 90 nights, first 30 the baseline, 17 parameters, scatter 3-10× CRLB, correlated; import → history database → judge_series\n");
    let all = run(&setup(Change::None), &cfg, seeds.clone());
    let (fa, n) = fa_rate(&all);
    let by: Vec<usize> = (0..4)
        .map(|k| all.iter().map(|x| x.by_rule[k]).sum())
        .collect();
    println!(
        "stable: {fa} false alarms / {n} parameter-nights = {:.2} per 1000 (target ≤ 1); Shewhart {}, CUSUM {}, EWMA {}, T² {}",
        1000.0 * fa as f64 / n as f64,
        by[0],
        by[1],
        by[2],
        by[3]
    );
    let o = run(
        &setup(Change::Step {
            i: 4,
            at: 60,
            sd: 3.0,
        }),
        &cfg,
        seeds.clone(),
    );
    let d = delays(&o);
    println!(
        "3-sd step at night 60: within 2 nights {} (target ≥ 85 %); same night {}; {}",
        within(&d, 2),
        within(&d, 0),
        median_max(&d)
    );
    let o = run(
        &setup(Change::Trend {
            i: 12,
            at: 45,
            per_night: 0.1,
        }),
        &cfg,
        seeds.clone(),
    );
    let d = delays(&o);
    println!(
        "0.1 sd/night trend from night 45: within 15 nights {} (target ≥ 80 %); within 10 {}; {}",
        within(&d, 15),
        within(&d, 10),
        median_max(&d)
    );
    let o = run(
        &setup(Change::Pair { at: 60, sd: 1.5 }),
        &cfg,
        seeds.clone(),
    );
    let d = delays(&o);
    println!(
        "pair (ρ = −0.78) +1.5 sd each at night 60: within 3 nights {} (target ≥ 70 %); {}",
        within(&d, 3),
        median_max(&d)
    );
    let o = run(
        &setup(Change::Outlier {
            i: 3,
            at: 45,
            sd: 20.0,
        }),
        &cfg,
        seeds,
    );
    let d = delays(&o);
    let after: usize = o.iter().map(|x| x.alarms_after_outlier).sum();
    println!(
        "one 20-sd outlier at night 45: caught that night {}; alarms on the 44 nights after, all 20 seeds: {after}\n",
        within(&d, 0)
    );
}

fn table() {
    println!("## Power table: average run length (nights, the change's night counted as 1), 20 seeds per cell; ARL0 from 40 seeds × 150 nights\n");
    println!("| scatter / CRLB | correlation | baseline | ARL0 (parameter-nights per false alarm) | step 1 sd | 2 sd | 3 sd | 4 sd | 5 sd | trend to 1 sd in 30 nights | 2 sd | 3 sd | 4 sd | 5 sd |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (scatter, correlated, baseline) in [
        ((3.0, 3.0), true, 30),
        ((10.0, 10.0), true, 30),
        ((3.0, 10.0), false, 30),
        ((3.0, 10.0), true, 20),
        ((3.0, 10.0), true, 30),
    ] {
        let cfg = config(baseline);
        let setup = |change, nights| Setup {
            nights,
            scatter_crlb: scatter,
            correlated,
            change,
            through_store: false,
        };
        let stable = run(&setup(Change::None, 150), &cfg, 1000..1040);
        let (fa, n) = fa_rate(&stable);
        let arl0 = if fa == 0 {
            format!("> {n}")
        } else {
            format!("{:.0} ({fa} alarms)", n as f64 / fa as f64)
        };
        let at = baseline + 30;
        let arl = |change| {
            let o = run(&setup(change, at + 60), &cfg, 2000..2020);
            let d = delays(&o);
            let caught: Vec<usize> = d.iter().flatten().map(|v| v + 1).collect();
            let mean = caught.iter().sum::<usize>() as f64 / caught.len().max(1) as f64;
            if caught.len() == d.len() {
                format!("{mean:.1}")
            } else {
                format!("{mean:.1} ({} of {} in 60 nights)", caught.len(), d.len())
            }
        };
        let steps: Vec<String> = (1..=5)
            .map(|s| {
                arl(Change::Step {
                    i: 4,
                    at,
                    sd: s as f64,
                })
            })
            .collect();
        let trends: Vec<String> = (1..=5)
            .map(|s| {
                arl(Change::Trend {
                    i: 12,
                    at,
                    per_night: s as f64 / 30.0,
                })
            })
            .collect();
        println!(
            "| {}–{} | {} | {baseline} | {arl0} | {} | {} |",
            scatter.0,
            scatter.1,
            if correlated { "as the report" } else { "none" },
            steps.join(" | "),
            trends.join(" | ")
        );
    }
}

fn main() {
    let what = std::env::args().nth(1).unwrap_or_default();
    targets();
    if what != "targets" {
        table();
    }
}
