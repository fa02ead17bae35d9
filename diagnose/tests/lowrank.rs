//! The low-rank path (`rfe::lowrank`) against full solves: every kind of candidate effect
//! of the diagnosis, applied at a random size to a random generated machine, gives the changed
//! model's outputs from the base's solves to 1e-9 relative on both the direct and the modal
//! path; the derivative with respect to a spring's stiffness matches the full solve's analytic
//! one (`frf::response` with the spring's `k` as a parameter).

// Tests unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

#[path = "support/blind.rs"]
mod blind;
#[path = "support/machine.rs"]
mod machine;

use diagnose::effects::Realized;
use diagnose::lowrank::{Shared, Solves};
use diagnose::problem::Problem;
use diagnose::{generate, Effect};
use identify::optimize::Residuals as _;
use identify::synthetic::log_lines;
use identify::{data, Options};
use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rfe::frf::{self, Method};
use rfe::lowrank::Base;
use rfe::model::{ParamName, ParamRef};
use rfe::C64;

/// Largest difference over the lines relative to the largest full-solve output, worst output.
fn rel_error(a: &[Vec<C64>], full: &frf::Response) -> f64 {
    a.iter()
        .enumerate()
        .map(|(o, y)| {
            let f = full.output(o);
            let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
            y.iter()
                .zip(f)
                .map(|(p, q)| (p - q).norm())
                .fold(0.0, f64::max)
                / scale
        })
        .fold(0.0, f64::max)
}

/// A size for each of `effect`'s parameters: the nested value moved by 0.3-3 of its scale
/// (a size nested at a positive value: 0.5-2 times it), within the bounds; later parameters
/// (ψ, a resonator's tuning) at their initial values.
fn sizes(effect: &Effect, f_max: f64, rng: &mut StdRng) -> Vec<f64> {
    effect
        .params(f_max)
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let v = if i > 0 {
                p.initial
            } else if p.nested > 0.0 {
                p.nested * rng.random_range(0.5..2.0)
            } else {
                p.nested + p.scale * rng.random_range(0.3..3.0)
            };
            v.clamp(p.lower, p.upper)
        })
        .collect()
}

/// Every kind of candidate on machines of 5 and 6 bodies, `per_kind` candidates of each, on
/// `method`'s path.
fn every_kind(method: Method) {
    let kinds = [
        "spring",
        "mass",
        "resonator",
        "flexible body",
        "SDE direction",
        "body mass",
        "joint damping",
    ];
    let mut tested = std::collections::BTreeMap::<&str, usize>::new();
    for (bodies, seed) in [(5usize, 11u64), (6, 12)] {
        let m = machine::machine(bodies, seed).unwrap();
        let (lo, hi) = machine::band(&m.model).unwrap();
        let freqs = log_lines(lo, hi, 40);
        let x = m.vars.initial();
        let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
        let library = generate::candidates(&m.model, &m.vars, &x, &labels, lo, hi);
        let base = Base::new(&m.model, &freqs, method).unwrap();
        let mut rng = StdRng::seed_from_u64(seed);
        for kind in kinds {
            let of_kind: Vec<&Effect> = library.iter().filter(|e| e.kind() == kind).collect();
            for _ in 0..3.min(of_kind.len()) {
                let effect = of_kind[rng.random_range(0..of_kind.len())];
                let gamma = sizes(effect, hi, &mut rng);
                let mut r = Realized {
                    model: m.model.clone(),
                    vars: m.vars.clone(),
                    gains: vec![1.0; 3],
                };
                effect.apply(&mut r, &gamma, hi).unwrap();
                let full = frf::response(&r.model, &freqs, &[], Method::Direct).unwrap();
                let u = base.update(&r.model).unwrap();
                let low = base.changed_response(&u).unwrap();
                let err = rel_error(&low, &full);
                assert!(
                    err < 1e-9,
                    "{method:?}, {bodies} bodies: {} at {gamma:?}: relative error {err:.2e} (support {} DOFs, {} new)",
                    effect.describe(),
                    u.support.len(),
                    u.new_dofs
                );
                assert!(
                    u.support.len() <= 6 * 6,
                    "{}: support of {} DOFs",
                    effect.describe(),
                    u.support.len()
                );
                *tested.entry(kind).or_default() += 1;
            }
        }
    }
    for kind in kinds {
        assert!(
            tested.get(kind).copied().unwrap_or(0) > 0,
            "no {kind} candidate was tested: {tested:?}"
        );
    }
}

#[test]
fn every_kind_of_candidate_direct() {
    every_kind(Method::Direct);
}

#[test]
fn every_kind_of_candidate_modal() {
    every_kind(Method::Modal);
}

#[test]
fn a_spring_is_rank_one_on_two_bodies_and_its_derivative_matches_the_full_solve() {
    let m = machine::machine(5, 3).unwrap();
    let (lo, hi) = machine::band(&m.model).unwrap();
    let freqs = log_lines(lo, hi, 30);
    let x = m.vars.initial();
    let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
    let spring = generate::candidates(&m.model, &m.vars, &x, &labels, lo, hi)
        .into_iter()
        .find(|e| matches!(e, Effect::Spring { bodies, .. } if bodies.iter().all(Option::is_some)))
        .unwrap();
    let with = |k: f64| {
        let mut r = Realized {
            model: m.model.clone(),
            vars: m.vars.clone(),
            gains: vec![1.0; 3],
        };
        let psi = spring.params(hi)[1].initial;
        spring.apply(&mut r, &[k, psi], hi).unwrap();
        r.model
    };
    for method in [Method::Direct, Method::Modal] {
        let base = Base::new(&m.model, &freqs, method).unwrap();
        let k = spring.params(hi)[0].scale;
        let u = base.update(&with(k)).unwrap();
        // Two bodies' DOFs at most: rank 1 within them, and applied in that rank.
        assert!(u.support.len() <= 12 && u.new_dofs == 0, "{:?}", u.support);
        assert_eq!(u.rank(), 1, "a spring's update has rank 1");
        // ΔA is linear in k: ∂ΔA/∂k is the update divided by k.
        let du = u.scaled(1.0 / k).unwrap();
        let d = base.derivative(&u, &du).unwrap();
        // The full solve's own analytic derivative with respect to the added spring's k.
        let changed = with(k);
        let param = ParamRef {
            sde: changed.sdes.len() - 1,
            name: ParamName::K,
        };
        let full = frf::response(&changed, &freqs, &[param], Method::Direct).unwrap();
        for (o, dy) in d.iter().enumerate() {
            let scale = dy.iter().map(|v| v.norm()).fold(0.0, f64::max);
            for (l, v) in dy.iter().enumerate() {
                let want = full.derivative(0, o)[l];
                assert!(
                    (v - want).norm() < 1e-9 * scale,
                    "{method:?}: output {o} line {l}: {v} against {want}"
                );
            }
        }
    }
}

#[test]
fn no_change_is_an_empty_update() {
    let m = machine::machine(4, 5).unwrap();
    let (lo, hi) = machine::band(&m.model).unwrap();
    let freqs = log_lines(lo, hi, 10);
    let base = Base::new(&m.model, &freqs, Method::Direct).unwrap();
    let u = base.update(&m.model).unwrap();
    assert!(u.support.is_empty() && u.new_dofs == 0);
    let full = frf::response(&m.model, &freqs, &[], Method::Direct).unwrap();
    assert!(rel_error(&base.changed_response(&u).unwrap(), &full) < 1e-12);
}

/// The screen's low-rank residuals are the full solve's, for a candidate of each kind at a
/// nonzero size on top of the current fit.
#[test]
fn low_rank_residuals_are_the_full_solves() {
    let m = machine::machine(5, 21).unwrap();
    let case = machine::case(&m, 60, (500.0, 0.01), 0.1, 21).unwrap();
    let obs = data::validate(&case.data, &m.model, "test").unwrap();
    let opts = Options::default();
    let (lo, hi) = machine::band(&m.model).unwrap();
    let pc = Problem::new(&m.model, &case.vars, &obs, &opts, Vec::new(), hi);
    let u = DVector::from_iterator(pc.nx(), case.vars.vars.iter().map(|v| v.initial / v.scale));
    let shared = Shared::new(&pc, &u).unwrap();
    let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
    let x = case.vars.initial();
    let library = generate::candidates(&m.model, &case.vars, &x, &labels, lo, hi);
    let mut kinds: Vec<&str> = Vec::new();
    for cand in &library {
        if kinds.contains(&cand.kind()) {
            continue;
        }
        kinds.push(cand.kind());
        let mut p = Problem::new(&m.model, &case.vars, &obs, &opts, vec![cand.clone()], hi);
        let g: Vec<f64> = p
            .params
            .iter()
            .enumerate()
            .map(|(i, q)| {
                if i == 0 {
                    (q.nested + q.scale).clamp(q.lower, q.upper) / q.scale
                } else {
                    q.initial / q.scale
                }
            })
            .collect();
        let uc = DVector::from_iterator(u.len() + g.len(), u.iter().copied().chain(g));
        let fast = shared.residuals(&p, &uc).unwrap().unwrap();
        let full = p.eval(&uc, false).unwrap().0;
        let err = (&fast - &full).norm() / full.norm();
        assert!(
            err < 1e-9,
            "{}: relative difference {err:.2e}",
            cand.describe()
        );
    }
    assert!(kinds.len() >= 7, "{kinds:?}");
}

/// The round's held solves evaluate a point that changes one candidate's parameters of a held
/// fit (the current fit, the fresh start) as that fit's update, to 1e-9 of the full solve; any
/// other point — a variable moved, other earlier effects — is solved in full, bit for bit; on a
/// model too small for the update to pay, nothing is held.
#[test]
fn held_solves_take_only_the_points_they_hold() {
    let m = machine::machine(17, 21).unwrap();
    assert!(6 * m.model.bodies.len() > 100);
    let case = machine::case(&m, 40, (500.0, 0.01), 0.1, 21).unwrap();
    let obs = data::validate(&case.data, &m.model, "test").unwrap();
    let opts = Options::default();
    let (lo, hi) = machine::band(&m.model).unwrap();
    let pc = Problem::new(&m.model, &case.vars, &obs, &opts, Vec::new(), hi);
    let u = DVector::from_iterator(pc.nx(), case.vars.vars.iter().map(|v| v.initial / v.scale));
    let mut fresh = u.clone();
    fresh[0] *= 1.1;
    let solves = Solves::default();
    solves.hold(&pc, &[u.clone(), fresh.clone()]);
    assert!(solves.at(&pc, &u).is_some() && solves.at(&pc, &fresh).is_some());
    let labels: Vec<String> = (0..3).map(|o| format!("#{o}")).collect();
    let library = generate::candidates(&m.model, &case.vars, &case.vars.initial(), &labels, lo, hi);
    let spring = library
        .iter()
        .find(|c| matches!(c, Effect::Spring { .. }))
        .unwrap();
    let mut p = Problem::new(&m.model, &case.vars, &obs, &opts, vec![spring.clone()], hi);
    let g: Vec<f64> = p
        .params
        .iter()
        .map(|q| (q.nested + q.scale) / q.scale)
        .collect();
    let at = |prefix: &DVector<f64>| {
        DVector::from_iterator(
            prefix.len() + g.len(),
            prefix.iter().copied().chain(g.clone()),
        )
    };
    let full = |p: &mut Problem, u: &DVector<f64>| p.eval(u, false).unwrap().0.norm_squared();
    for prefix in [&u, &fresh] {
        let uc = at(prefix);
        let (fast, exact) = (solves.sum_of_squares(&mut p, &uc), full(&mut p, &uc));
        assert!(
            (fast - exact).abs() <= 1e-9 * exact,
            "{fast} against {exact}"
        );
    }
    let mut moved = u.clone();
    moved[1] *= 0.9;
    let uc = at(&moved);
    assert_eq!(solves.sum_of_squares(&mut p, &uc), full(&mut p, &uc));
    let small = machine::machine(5, 21).unwrap();
    let case = machine::case(&small, 40, (500.0, 0.01), 0.1, 21).unwrap();
    let obs = data::validate(&case.data, &small.model, "test").unwrap();
    let pc = Problem::new(&small.model, &case.vars, &obs, &opts, Vec::new(), hi);
    let u = DVector::from_iterator(pc.nx(), case.vars.vars.iter().map(|v| v.initial / v.scale));
    solves.hold(&pc, std::slice::from_ref(&u));
    assert!(solves.at(&pc, &u).is_none());
}
