//! How the closed loop scales with the model: generated machine-tool-like models
//! (`diagnose::machine`: bed, column, ram, head, saddles, table; 2-6 SDEs per joint;
//! one undeclared spring between the column and the table; 3 characteristics × 300 lines, 1 %
//! noise, variables started 20 % off), identified and diagnosed as `ident diagnose` does, size by
//! size. Prints per size the model's size, the identification's and the diagnosis's wall time
//! (and the diagnosis's split), the candidates ranked, the base fit's criterion against the fit
//! started at the truth's values (what the model can reach), whether the injected spring was
//! the first effect found, and at the end the growth exponent of each time against the number of
//! bodies (least squares on log-log) and the peak memory. Before each size's diagnosis, the cost
//! of one screen evaluation (the model changed by one candidate) by a full solve and as a
//! low-rank update ([`rfe::lowrank`]), measured in the same run.
//!
//! `cargo run --release -p diagnose --example machine_scaling -- [BODIES…] [--limit SECONDS]
//! [--seed SEED] [--signal CHI2] [--progress]` (default bodies 4 7 14, limit 900 s per size, seed
//! 1, signal 3000; `--progress` prints the diagnosis's progress lines with the seconds since its
//! start). A size that has no answer within the limit ends the run (the process exits: a
//! diagnosis cannot be interrupted) after printing what was measured.

// An example unwraps: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::sync::mpsc;
use std::time::{Duration, Instant};

use diagnose::effects::Realized;
#[path = "../tests/support/blind.rs"]
mod blind;
#[path = "../tests/support/machine.rs"]
mod machine;

use diagnose::generate;
use identify::{self as idn, data};
use rfe::frf;
use rfe::lowrank;

/// One size's figures.
struct Row {
    bodies: usize,
    identify_s: f64,
    diagnose_s: f64,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut sizes: Vec<usize> = Vec::new();
    let (mut limit, mut seed, mut signal) = (900.0, 1u64, 3000.0);
    let mut progress = false;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--limit" => limit = it.next().and_then(|v| v.parse().ok()).expect("--limit S"),
            "--seed" => seed = it.next().and_then(|v| v.parse().ok()).expect("--seed N"),
            "--signal" => signal = it.next().and_then(|v| v.parse().ok()).expect("--signal X"),
            "--progress" => progress = true,
            n => sizes.push(n.parse().expect("a number of bodies")),
        }
    }
    if sizes.is_empty() {
        sizes = vec![4, 7, 14];
    }
    println!(
        "{:>6} {:>5} {:>5} {:>5} {:>6} {:>10} {:>10} {:>10} {:>10} {:>9} {:>6}",
        "bodies",
        "DOFs",
        "SDEs",
        "vars",
        "cands",
        "identify s",
        "diagnose s",
        "J base",
        "J truth",
        "converged",
        "found"
    );
    let mut rows: Vec<Row> = Vec::new();
    for &n in &sizes {
        let m = machine::machine(n, seed).expect("machine");
        let case = machine::case(&m, 300, (signal, 0.01), 0.2, seed).expect("case");
        screen_cost(&m, &case);
        jacobian_cost(&m, &case);
        let (tx, rx) = mpsc::channel();
        let (model, vars) = (m.model.clone(), m.vars.clone());
        std::thread::spawn(move || {
            let opts = diagnose::Options::default();
            let obs = data::validate(&case.data, &model, "generated").expect("data");
            let t0 = Instant::now();
            let id = idn::identify(
                &model,
                &obs,
                &case.vars,
                &opts.identification,
                &mut |_, _| {},
            )
            .expect("identify");
            let t1 = Instant::now();
            let mut show = |line: &str| {
                if progress {
                    eprintln!("{:8.1} s  {line}", t1.elapsed().as_secs_f64());
                }
            };
            let d = diagnose::diagnose(&model, &obs, &case.vars, &id, &opts, &mut show)
                .expect("diagnose");
            let t2 = Instant::now();
            // What the model without the spring can reach: the fit started at the truth's values.
            let at_truth = idn::identify(&model, &obs, &vars, &opts.identification, &mut |_, _| {})
                .expect("fit from the truth");
            let o = blind::judge(&case, &d, (t2 - t0).as_secs_f64(), (t2 - t1).as_secs_f64());
            // A miss is judged as the blind suite judges one: against the truth's own form refitted.
            let verdict = (!o.right_first).then(|| {
                let starts = [d.estimate.clone(), case.vars.initial()];
                let j = blind::truth_form(&model, &case, &starts, &opts).expect("truth's form");
                blind::miss(d.after.criterion, j, d.after.observations)
            });
            let injected: Vec<String> = case.injected.iter().map(|i| i.effect.describe()).collect();
            tx.send((
                (t1 - t0).as_secs_f64(),
                (t2 - t1).as_secs_f64(),
                d,
                (o, verdict, injected),
                at_truth.criterion,
            ))
            .ok();
        });
        let Ok((ti, td, d, (o, verdict, injected), j_truth)) =
            rx.recv_timeout(Duration::from_secs_f64(limit))
        else {
            println!(
                "{n:>6} {:>5} {:>5} {:>5}   no answer within {limit:.0} s",
                m.model.dof_count(),
                m.model.sdes.len(),
                m.vars.len()
            );
            finish(&rows);
            std::process::exit(0);
        };
        println!(
            "{:>6} {:>5} {:>5} {:>5} {:>6} {:>10.1} {:>10.1} {:>10.1} {:>10.1} {:>9} {:>6}",
            m.model.bodies.len(),
            m.model.dof_count(),
            m.model.sdes.len(),
            m.vars.len(),
            d.rounds.first().map_or(0, |r| r.candidates),
            ti,
            td,
            d.base.criterion,
            j_truth,
            d.base.converged,
            if o.named_first {
                "yes"
            } else if o.right_first {
                "equiv"
            } else {
                "no"
            }
        );
        println!(
            "       {}; injected [{}]; added [{}]",
            diagnose::timing_text(&d),
            injected.join("; "),
            o.added.join("; ")
        );
        if let Some(verdict) = verdict {
            println!(
                "       not found: {}",
                match verdict {
                    blind::Miss::CannotTell =>
                        "the data cannot tell the answer from the truth's own form (within an LR of 3.84)",
                    blind::Miss::Missed => "the truth's own form fits better: the search missed it",
                    blind::Miss::Undecided =>
                        "the truth's own refit is off the noise level too (undecided)",
                }
            );
        }
        rows.push(Row {
            bodies: n,
            identify_s: ti,
            diagnose_s: td,
        });
    }
    finish(&rows);
}

/// One screen evaluation — the model changed by one candidate, every output at every line — by a
/// full solve (what the screen did before) and as a low-rank update of the current model's
/// solves (what it does now), one candidate of each kind at a nonzero size, in the same run;
/// and the shared solves' cost, made once per round.
fn screen_cost(m: &machine::Machine, case: &blind::BlindCase) {
    let (lo, hi) = machine::band(&m.model).expect("band");
    let lines: Vec<f64> = case.data.characteristics[0].freqs_hz.clone();
    let x = m.vars.initial();
    let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
    let library = generate::candidates(&m.model, &m.vars, &x, &labels, lo, hi);
    let mut changed = Vec::new();
    let mut kinds: Vec<&str> = Vec::new();
    for c in &library {
        if kinds.contains(&c.kind()) || c.kind() == "sensor gain" {
            continue;
        }
        kinds.push(c.kind());
        let gamma: Vec<f64> = c
            .params(hi)
            .iter()
            .enumerate()
            .map(|(i, p)| {
                if i == 0 {
                    (p.nested + p.scale).min(p.upper)
                } else {
                    p.initial
                }
            })
            .collect();
        let mut r = Realized {
            model: m.model.clone(),
            vars: m.vars.clone(),
            gains: vec![1.0; 3],
        };
        c.apply(&mut r, &gamma, hi).expect("apply");
        changed.push(r.model);
    }
    let t0 = Instant::now();
    for c in &changed {
        frf::response(c, &lines, &[], frf::Method::Auto).expect("full solve");
    }
    let full = t0.elapsed().as_secs_f64() / changed.len() as f64;
    let t1 = Instant::now();
    let base = lowrank::Base::new(&m.model, &lines, frf::Method::Auto).expect("base solves");
    let shared = t1.elapsed().as_secs_f64();
    // The first evaluation of a candidate computes its support's receptance; the screen's
    // further ones (a few dozen per candidate) read it again.
    let pass = || {
        let t = Instant::now();
        for c in &changed {
            let u = base.update(c).expect("update");
            base.changed_response(&u).expect("low-rank response");
        }
        t.elapsed().as_secs_f64() / changed.len() as f64
    };
    let (first, again) = (pass(), pass());
    println!(
        "       screen evaluation ({} kinds): full solve {:.2} ms; low-rank first {:.2} ms (x{:.1}), again {:.2} ms (x{:.1}); shared solves {:.0} ms once per round",
        changed.len(),
        1e3 * full,
        1e3 * first,
        full / first,
        1e3 * again,
        full / again,
        1e3 * shared
    );
}

/// One evaluation of the outputs and the variables' Jacobian (every SDE parameter the variables
/// set) by each path, and the path [`frf::Method::Auto`] picks, in the same run.
fn jacobian_cost(m: &machine::Machine, case: &blind::BlindCase) {
    let lines: Vec<f64> = case.data.characteristics[0].freqs_hz.clone();
    let params = m.vars.model_params();
    // The least of three runs: the machine may be shared.
    let time = |method: frf::Method| {
        (0..3)
            .map(|_| {
                let t = Instant::now();
                frf::response_params(&m.model, &lines, &params, method).expect("response");
                t.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let (direct, modal) = (time(frf::Method::Direct), time(frf::Method::Modal));
    let system = rfe::system::System::assemble(&m.model);
    let share = rfe::lines::fill_share(&system);
    let auto = frf::Method::Auto.resolve_for(
        &system,
        lines.len(),
        frf::Work::Outputs {
            params: params.len(),
            columns: 1 + m.model.outputs.len(),
        },
    );
    println!(
        "       Jacobian evaluation ({} parameters, {} lines): direct {:.1} ms (fill share {share:.3}), modal {:.1} ms; auto takes {auto:?}",
        params.len(),
        lines.len(),
        1e3 * direct,
        1e3 * modal
    );
}

/// The growth exponents and the peak memory.
fn finish(rows: &[Row]) {
    if rows.len() >= 2 {
        let b: Vec<f64> = rows.iter().map(|r| r.bodies as f64).collect();
        println!(
            "growth exponent (time ∝ bodies^p): identify p = {:.2}, diagnose p = {:.2}",
            exponent(&b, &rows.iter().map(|r| r.identify_s).collect::<Vec<_>>()),
            exponent(&b, &rows.iter().map(|r| r.diagnose_s).collect::<Vec<_>>())
        );
    }
    if let Some(kb) = peak_kb() {
        println!("peak resident memory: {:.0} MB", kb / 1024.0);
    }
}

/// The least-squares slope of ln y against ln x.
fn exponent(x: &[f64], y: &[f64]) -> f64 {
    let lx: Vec<f64> = x.iter().map(|v| v.ln()).collect();
    let ly: Vec<f64> = y.iter().map(|v| v.max(1e-9).ln()).collect();
    let n = lx.len() as f64;
    let (mx, my) = (lx.iter().sum::<f64>() / n, ly.iter().sum::<f64>() / n);
    let sxy: f64 = lx.iter().zip(&ly).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = lx.iter().map(|a| (a - mx) * (a - mx)).sum();
    sxy / sxx
}

/// The process's peak resident set (kB) where the system reports it (Linux `/proc`).
fn peak_kb() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}
