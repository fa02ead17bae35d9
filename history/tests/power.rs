//! A fixed small subset of the power simulation (`examples/power.rs`, docs/nightly.md): simulated
//! reports imported and judged. A 3-sd step is flagged within 2 nights, and one 20-sd outlier
//! night raises its alarm and no alarm on that parameter on the nights after.

#![allow(clippy::unwrap_used, dead_code)]

mod common;

use common::drift_sim::{runs, score, Change, Setup};
use history::judge::{judge_series, BaselineWindow, JudgeConfig};

fn cfg() -> JudgeConfig {
    JudgeConfig {
        baseline: BaselineWindow::First(30),
        ..JudgeConfig::default()
    }
}

fn setup(change: Change) -> Setup {
    Setup {
        nights: 70,
        scatter_crlb: (3.0, 10.0),
        correlated: true,
        change,
        through_store: false,
    }
}

#[test]
fn a_three_sd_step_is_flagged_within_two_nights() {
    let s = setup(Change::Step {
        i: 4,
        at: 60,
        sd: 3.0,
    });
    let caught = (1..=5)
        .filter(|seed| {
            score(&s, &runs(&s, *seed), &cfg())
                .delay
                .is_some_and(|d| d <= 2)
        })
        .count();
    assert!(caught >= 4, "{caught}/5 within 2 nights");
}

#[test]
fn an_outlier_night_raises_no_alarm_on_its_parameter_after_it() {
    let s = setup(Change::Outlier {
        i: 3,
        at: 40,
        sd: 20.0,
    });
    for seed in 1..=3 {
        let rs = runs(&s, seed);
        let js = judge_series(&rs, &cfg());
        assert!(js[40].alarms.iter().any(|a| a.subject == "k03"));
        let after: Vec<&str> = js[41..]
            .iter()
            .flat_map(|j| j.alarms.iter())
            .filter(|a| a.subject == "k03")
            .map(|a| a.message.as_str())
            .collect();
        assert!(after.is_empty(), "seed {seed}: {after:?}");
    }
}
