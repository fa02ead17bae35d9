//! Multi-start: space-filling start points (a Latin hypercube in log-parameter space within the
//! bounds), the distinct optima the starts reach (clustered by their distance in standard
//! errors), and warnings when the best optima disagree or an optimum sits at a degenerate corner
//! (a stiffness at a bound or run away from its start, ψ far above 1).

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::uncertainty::AtBound;
use super::variables::{Variable, Variables};
use super::Identification;

/// Two start outcomes are the same optimum when no variable differs by more than this many
/// standard errors.
pub const SAME_OPTIMUM_STD_ERRORS: f64 = 3.0;

/// A stiffness that ends more than this factor away from its start (up or down) has run off to a
/// corner of the parameter space (→ 0 or → ∞).
pub const RUNAWAY_FACTOR: f64 = 100.0;

/// ψ above this (a loss factor η = ψ/2π above 1) is no joint's damping: the fit uses damping to
/// flatten a resonance it cannot place.
pub const PSI_DEGENERATE: f64 = 2.0 * std::f64::consts::PI;

/// The starting points: the initial values, then `starts − 1` points of a Latin hypercube over
/// each variable's start range (one point in each of `starts − 1` equal slices of every range,
/// the slices paired at random, seeded by `seed`). A range is the bounds where both are finite
/// (in log when the lower bound is > 0), else `[x0/10, 10·x0] ∩ bounds` in log.
pub fn latin_hypercube(vars: &Variables, starts: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut pts = vec![vars.initial()];
    let m = starts.max(1) - 1;
    if m == 0 {
        return pts;
    }
    let columns: Vec<Vec<f64>> = vars
        .vars
        .iter()
        .map(|v| {
            let mut slices: Vec<usize> = (0..m).collect();
            slices.shuffle(&mut rng);
            slices
                .into_iter()
                .map(|s| at_fraction(v, (s as f64 + rng.random::<f64>()) / m as f64))
                .collect()
        })
        .collect();
    for i in 0..m {
        pts.push(columns.iter().map(|c| c[i]).collect());
    }
    pts
}

/// The value at fraction `t` ∈ [0, 1] of `v`'s start range.
fn at_fraction(v: &Variable, t: f64) -> f64 {
    if v.upper.is_finite() && v.lower <= 0.0 {
        return v.lower + t * (v.upper - v.lower);
    }
    let (lo, hi) = if v.upper.is_finite() {
        (v.lower, v.upper)
    } else {
        let c = if v.initial > 0.0 { v.initial } else { v.scale };
        ((c / 10.0).max(v.lower).max(f64::MIN_POSITIVE), c * 10.0)
    };
    (lo.ln() + t * (hi.ln() - lo.ln())).exp()
}

/// One distinct optimum reached by one or more starts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Optimum {
    /// Criterion J there (the lowest of its starts).
    pub criterion: f64,
    /// The estimate of its best start (SI).
    pub estimate: Vec<f64>,
    /// The starts (indices into [`Identification::starts`]) that ended there.
    pub starts: Vec<usize>,
}

/// What the starts found, and what to beware of.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StartsAnalysis {
    /// Distinct optima, best (lowest J) first; empty for a single start.
    pub optima: Vec<Optimum>,
    /// Warnings, as sentences: optima the data cannot tell apart, degenerate corners.
    pub warnings: Vec<String>,
}

/// The starts of `id` clustered into distinct optima, with the warnings.
pub fn analyse(id: &Identification) -> StartsAnalysis {
    let optima = if id.starts.len() > 1 {
        cluster(id)
    } else {
        Vec::new()
    };
    let mut warnings = Vec::new();
    if let Some(w) = ambiguity(id, &optima) {
        warnings.push(w);
    }
    warnings.extend(degenerate_corners(&id.variables, &id.estimate, |i| {
        id.uncertainty.at_bound.get(i).copied().flatten()
    }));
    StartsAnalysis { optima, warnings }
}

/// The unit of distance of variable `i`: its standard error at the best estimate, at least
/// 1e-4 of its size (so that starts which converged to round-off are never told apart).
fn distance_unit(id: &Identification, i: usize) -> f64 {
    let v = &id.variables.vars[i];
    let floor = 1e-4
        * id.estimate[i]
            .abs()
            .max(v.scale.abs())
            .max(f64::MIN_POSITIVE);
    match id.uncertainty.std_error.get(i) {
        Some(s) if s.is_finite() && *s > floor => *s,
        _ => floor,
    }
}

/// Whether a start was stopped before its end as hopeless (its end is no optimum).
fn stopped_early(s: &crate::StartSummary) -> bool {
    matches!(s.stop, crate::StopReason::Abandoned(_))
}

/// Greedy clustering, best first: a start joins the first optimum whose estimate lies within
/// [`SAME_OPTIMUM_STD_ERRORS`] standard errors in every variable. Starts stopped early are left
/// out: where they stopped is no optimum.
fn cluster(id: &Identification) -> Vec<Optimum> {
    let units: Vec<f64> = (0..id.variables.len())
        .map(|i| distance_unit(id, i))
        .collect();
    let mut order: Vec<usize> = (0..id.starts.len())
        .filter(|&k| {
            id.starts[k].criterion.is_finite()
                && id.starts[k].estimate.len() == units.len()
                && !stopped_early(&id.starts[k])
        })
        .collect();
    order.sort_by(|&a, &b| id.starts[a].criterion.total_cmp(&id.starts[b].criterion));
    let mut optima: Vec<Optimum> = Vec::new();
    for k in order {
        let x = &id.starts[k].estimate;
        let home = optima.iter_mut().find(|o| {
            o.estimate
                .iter()
                .zip(x)
                .zip(&units)
                .all(|((a, b), u)| (a - b).abs() <= SAME_OPTIMUM_STD_ERRORS * u)
        });
        match home {
            Some(o) => o.starts.push(k),
            None => optima.push(Optimum {
                criterion: id.starts[k].criterion,
                estimate: x.clone(),
                starts: vec![k],
            }),
        }
    }
    optima
}

/// A warning when an optimum other than the best is not significantly worse (likelihood ratio
/// 2ΔJ/s² below the 95 % quantile of χ² with as many degrees of freedom as variables) yet lies
/// more than [`SAME_OPTIMUM_STD_ERRORS`] standard errors away: the data do not decide between
/// them, and the standard errors of the best understate the uncertainty.
fn ambiguity(id: &Identification, optima: &[Optimum]) -> Option<String> {
    let best = optima.first()?;
    let s2 = if id.noise.scale_unknown() {
        id.uncertainty.covariance_scale
    } else {
        1.0
    };
    if !(s2.is_finite() && s2 > 0.0) {
        return None;
    }
    let limit = ChiSquared::new(id.variables.len().max(1) as f64)
        .ok()?
        .inverse_cdf(0.95);
    let rivals: Vec<String> = optima[1..]
        .iter()
        .filter(|o| 2.0 * (o.criterion - best.criterion) / s2 < limit)
        .map(|o| {
            let far = (0..id.variables.len())
                .max_by(|&a, &b| {
                    let da = (o.estimate[a] - best.estimate[a]).abs() / distance_unit(id, a);
                    let db = (o.estimate[b] - best.estimate[b]).abs() / distance_unit(id, b);
                    da.total_cmp(&db)
                })
                .unwrap_or(0);
            let v = &id.variables.vars[far];
            format!(
                "J = {} ({} start(s)), where {} = {} against {} ({:.0} standard errors away)",
                rfe::display::num(o.criterion),
                o.starts.len(),
                v.name,
                shown(v, o.estimate[far]),
                shown(v, best.estimate[far]),
                (o.estimate[far] - best.estimate[far]).abs() / distance_unit(id, far)
            )
        })
        .collect();
    (!rivals.is_empty()).then(|| {
        format!(
            "the data do not decide between the best optimum (J = {}) and {} other(s) not significantly worse: {}; \
             the standard errors understate the uncertainty — add characteristics, group parameters or fix one of them",
            rfe::display::num(best.criterion),
            rivals.len(),
            rivals.join("; ")
        )
    })
}

/// `x` (SI) in the variable's report unit, with the unit unless it is dimensionless.
fn shown(v: &Variable, x: f64) -> String {
    let n = rfe::display::num(x / v.unit.factor);
    if v.unit.symbol == "-" {
        n
    } else {
        format!("{n} {}", v.unit.symbol)
    }
}

/// Warnings for an estimate at a degenerate corner: a stiffness (or factor) at a bound or more
/// than [`RUNAWAY_FACTOR`] from its start, a ψ above [`PSI_DEGENERATE`]. `at_bound(i)` tells
/// whether variable `i` ended at a bound.
pub fn degenerate_corners(
    vars: &Variables,
    estimate: &[f64],
    at_bound: impl Fn(usize) -> Option<AtBound>,
) -> Vec<String> {
    let mut out = Vec::new();
    for (i, (v, &x)) in vars.vars.iter().zip(estimate).enumerate() {
        let shown = shown(v, x);
        if v.dissipation {
            if x > PSI_DEGENERATE {
                out.push(format!(
                    "{} = {shown}: a loss factor ψ/2π above 1 is no joint's damping; the fit flattens a resonance it cannot place \
                     (check the model form: a missing stiffness, masses off)",
                    v.name
                ));
            }
            continue;
        }
        match at_bound(i) {
            Some(AtBound::Lower) => out.push(format!(
                "{} ended at its lower bound ({shown}): the element does nothing in the fit; either the data do not see it \
                 or the model form lacks what it stands in for",
                v.name
            )),
            Some(AtBound::Upper) => out.push(format!(
                "{} ended at its upper bound ({shown}): the element is made rigid; the model form may lack a flexibility elsewhere",
                v.name
            )),
            None => {
                let ratio = x / v.initial;
                if v.initial > 0.0 && !(1.0 / RUNAWAY_FACTOR..=RUNAWAY_FACTOR).contains(&ratio) {
                    out.push(format!(
                        "{} ran {} its start by a factor {:.3e} ({shown}): a degenerate corner (stiffness → {}) rather than a fit",
                        v.name,
                        if ratio > 1.0 { "above" } else { "below" },
                        if ratio > 1.0 { ratio } else { 1.0 / ratio },
                        if ratio > 1.0 { "∞" } else { "0" }
                    ));
                }
            }
        }
    }
    out
}

/// The analysis as text for the report: the distinct optima (when several starts ran) and the
/// warnings, each on its own line; empty when there is nothing to say.
pub fn text(id: &Identification) -> String {
    let a = analyse(id);
    let mut s = String::new();
    if !a.optima.is_empty() {
        s.push_str(&format!(
            "distinct optima: {} from {} starts (same optimum = within {} standard errors in every variable)\n",
            a.optima.len(),
            id.starts.len(),
            SAME_OPTIMUM_STD_ERRORS
        ));
        for (k, o) in a.optima.iter().enumerate() {
            s.push_str(&format!(
                "  optimum {}: J = {}, reached by {} start(s){}\n",
                k + 1,
                rfe::display::num(o.criterion),
                o.starts.len(),
                if k == 0 { " (best, reported)" } else { "" }
            ));
        }
        let stopped = id.starts.iter().filter(|s| stopped_early(s)).count();
        if stopped > 0 {
            s.push_str(&format!(
                "  {stopped} start(s) stopped early, heading for optima far above the best (criterion over 100× the best start's and settling)\n"
            ));
        }
    }
    for w in &a.warnings {
        s.push_str(&format!("warning: {w}\n"));
    }
    s
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::variables;
    use rfe::textbook;

    fn two_mass_vars(extra: &str) -> Variables {
        let model = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
        let text = format!(
            r#"
            [[variable]]
            sdes = "k1"
            parameter = "k"
            initial = "14 N/um"
            [[variable]]
            sdes = "k2"
            parameter = "k"
            initial = "7 N/um"
            lower = "1 N/um"
            upper = "100 N/um"
            [[variable]]
            name = "psi"
            sdes = ["k1", "k2"]
            parameter = "psi"
            initial = 0.3
            {extra}
            "#
        );
        variables::parse(&text, "vars.toml", &model).unwrap()
    }

    #[test]
    fn the_hypercube_puts_one_start_in_each_slice_of_every_range() {
        let vars = two_mass_vars("");
        let n = 9;
        let pts = latin_hypercube(&vars, n + 1, 7);
        assert_eq!(pts.len(), n + 1);
        assert_eq!(pts[0], vars.initial());
        // Variable 0: no upper bound, log over [1.4, 140] N/µm; variable 1: log over [1, 100].
        for (i, (lo, hi)) in [(1.4e6, 1.4e8), (1.0e6, 1.0e8)].into_iter().enumerate() {
            let mut slices: Vec<usize> = pts[1..]
                .iter()
                .map(|p| {
                    assert!(p[i] >= lo && p[i] <= hi, "{} outside [{lo}, {hi}]", p[i]);
                    ((p[i] / lo).ln() / (hi / lo).ln() * n as f64).floor() as usize
                })
                .collect();
            slices.sort_unstable();
            assert_eq!(slices, (0..n).collect::<Vec<_>>(), "variable {i}");
        }
        assert_eq!(pts, latin_hypercube(&vars, n + 1, 7), "seeded");
        assert_ne!(pts, latin_hypercube(&vars, n + 1, 8));
    }

    #[test]
    fn degenerate_corners_are_named() {
        let vars = two_mass_vars("");
        // k1 ran 1000x above its start, k2 at its lower bound, ψ = 10 (η = 1.6).
        let w = degenerate_corners(&vars, &[1.4e10, 1.0e6, 10.0], |i| {
            (i == 1).then_some(AtBound::Lower)
        });
        assert_eq!(w.len(), 3, "{w:?}");
        assert!(
            w[0].starts_with("k k1 ran above its start by a factor 1.000e3"),
            "{}",
            w[0]
        );
        assert!(w[1].contains("lower bound"), "{}", w[1]);
        assert!(w[2].starts_with("psi = 10"), "{}", w[2]);
        // A sound estimate: nothing to say.
        assert!(degenerate_corners(&vars, &[2.0e7, 5.0e6, 0.5], |_| None).is_empty());
    }
}
