//! 90 simulated nights × 20 seeds (issue 18): the history's drift rules (temperature
//! compensated, and without compensation) side by side with today's `k_sigma` rule. Not run in
//! CI (`history/tests/simulated_nights.rs` runs 8 seeds); run it with
//!
//!     cargo run --release -p history --example simulated_nights
//!
//! Prints, per rule: nights from the step (−20 % in joint 2 at night 65) to its first alarm, from
//! the start of the wear trend (joint 1, −0.1 %/night from night 40) to its first alarm, and false
//! alarms per 1000 parameter-nights whose truth was normal.

#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "../tests/common/nights.rs"]
mod nights;

use history::judge::{BaselineWindow, JudgeConfig};
use nights::{Figures, Scenario};

fn main() {
    let sc = Scenario::default();
    let seeds = 20u64;
    let compensated = JudgeConfig {
        baseline: BaselineWindow::First(30),
        covariate: Some("temperature".into()),
        ..JudgeConfig::default()
    };
    let plain = JudgeConfig {
        covariate: None,
        ..compensated.clone()
    };
    let t = std::time::Instant::now();
    let mut rows: Vec<(&str, Vec<Figures>)> = vec![
        ("history, temperature compensated", vec![]),
        ("history, uncompensated", vec![]),
        ("k_sigma = 3 vs the first run", vec![]),
    ];
    for seed in 1..=seeds {
        let ns = nights::simulate(&sc, seed);
        let failed = ns.iter().filter(|n| n.record.outcome != "ok").count();
        if failed > 0 {
            println!("seed {seed}: {failed} fits did not converge (judged as failed runs)");
        }
        rows[0]
            .1
            .push(nights::judge_history(&sc, &ns, &compensated));
        rows[1].1.push(nights::judge_history(&sc, &ns, &plain));
        rows[2].1.push(nights::judge_k_sigma(&sc, &ns, 3.0, 30));
    }
    println!(
        "{} nights × {seeds} seeds in {:.1} s; step at night {}, trend from night {}",
        sc.nights,
        t.elapsed().as_secs_f64(),
        sc.step.1,
        sc.trend.1
    );
    println!(
        "{:<36} {:>14} {:>22} {:>24}",
        "rule", "step on night", "trend delay (nights)", "false alarms / 1000"
    );
    for (name, fs) in &rows {
        let on_night = fs
            .iter()
            .filter(|f| f.step_detected == Some(sc.step.1))
            .count();
        let delays: Vec<usize> = fs
            .iter()
            .filter_map(|f| f.trend_detected.map(|n| n - sc.trend.1))
            .collect();
        let missed = fs.len() - delays.len();
        let (mn, mx) = (
            delays.iter().min().copied().unwrap_or(0),
            delays.iter().max().copied().unwrap_or(0),
        );
        let mean = delays.iter().sum::<usize>() as f64 / delays.len().max(1) as f64;
        let mut total = Figures::default();
        for f in fs {
            total.add_counts(f);
        }
        println!(
            "{:<36} {:>9}/{:<4} {:>8.1} [{mn}-{mx}]{} {:>10.2} ({}/{})",
            name,
            on_night,
            fs.len(),
            mean,
            if missed > 0 {
                format!(" missed {missed}")
            } else {
                String::new()
            },
            1000.0 * total.false_alarms as f64 / total.normal_parameter_nights as f64,
            total.false_alarms,
            total.normal_parameter_nights
        );
    }
}
