//! The extended fit's Jacobian columns for effect parameters (`diagnose::problem`): an effect
//! parameter that moves only physical parameters of the model has its column from the same
//! solves as the variables' (the chain through the parameters it moves), in one evaluation;
//! every column, analytic or differenced, agrees with central differences of the residuals.

// Tests unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "support/blind.rs"]
mod blind;
#[path = "support/machine.rs"]
mod machine;

use diagnose::generate;
use diagnose::problem::Problem;
use identify::optimize::Residuals as _;
use identify::{data, Options};
use nalgebra::DVector;

/// Kinds whose every parameter moves physical parameters only (at a size off the nested value):
/// their Jacobian costs one evaluation.
const ANALYTIC: [&str; 7] = [
    "spring",
    "mass",
    "resonator",
    "flexible body",
    "SDE direction",
    "body mass",
    "joint damping",
];

#[test]
fn every_effect_column_matches_central_differences() {
    let m = machine::machine(5, 31).unwrap();
    let case = machine::case(&m, 60, (500.0, 0.01), 0.1, 31).unwrap();
    let obs = data::validate(&case.data, &m.model, "test").unwrap();
    let opts = Options::default();
    let (lo, hi) = machine::band(&m.model).unwrap();
    let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
    let x = case.vars.initial();
    let library = generate::candidates(&m.model, &case.vars, &x, &labels, lo, hi);
    let u: Vec<f64> = case.vars.vars.iter().map(|v| v.initial / v.scale).collect();
    let mut kinds: Vec<&str> = Vec::new();
    for cand in &library {
        if kinds.contains(&cand.kind()) {
            continue;
        }
        kinds.push(cand.kind());
        let mut p = Problem::new(&m.model, &case.vars, &obs, &opts, vec![cand.clone()], hi);
        let g = p.params.iter().enumerate().map(|(i, q)| {
            let v = if i == 0 {
                q.nested + q.scale
            } else {
                q.initial
            };
            v.clamp(q.lower, q.upper) / q.scale
        });
        let uc = DVector::from_iterator(u.len() + p.params.len(), u.iter().copied().chain(g));
        let before = p.evaluations;
        let (e, jac) = p.eval(&uc, true).unwrap();
        let jac = jac.unwrap();
        let cost = p.evaluations - before;
        if ANALYTIC.contains(&cand.kind()) {
            assert_eq!(
                cost,
                1,
                "{}: the Jacobian took {cost} evaluations, not one",
                cand.describe()
            );
        }
        for c in 0..uc.len() {
            // Central differences at two steps, the better kept: a tuned resonator's response is
            // sharp in its frequency (truncation needs a small step), a weak column loses digits
            // to rounding at one.
            let err = [1e-4, 1e-6]
                .map(|rel| {
                    let h = rel * uc[c].abs().max(1.0);
                    let (mut up, mut down) = (uc.clone(), uc.clone());
                    up[c] += h;
                    down[c] -= h;
                    let fd = (p.eval(&up, false).unwrap().0 - p.eval(&down, false).unwrap().0)
                        / (2.0 * h);
                    (&fd - jac.column(c)).norm() / fd.norm().max(1e-6 * e.norm())
                })
                .into_iter()
                .fold(f64::INFINITY, f64::min);
            assert!(
                err < 1e-5,
                "{}: column {c} of {} differs from central differences by {err:.2e}",
                cand.describe(),
                uc.len()
            );
        }
    }
    for kind in ANALYTIC {
        assert!(kinds.contains(&kind), "no {kind} candidate in {kinds:?}");
    }
}
