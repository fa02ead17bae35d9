//! The screen's model evaluations as low-rank updates of the current fit ([`crate::lowrank`]).
//!
//! A screen fits one candidate's own parameters with the variables and earlier effects held at
//! the current fit: every evaluation is the current fit's model changed by that one candidate.
//! The current fit's solves are made once per round ([`Shared::new`]); each evaluation then
//! costs the candidate's update on its support per line — independent of the model's size — and
//! gives the same residuals as a full solve to rounding (`identify/tests/lowrank.rs`: 1e-9
//! relative on every kind). A candidate that is no update of the current fit's system (none
//! today; a change of the excitation under base motion would be one) falls back to the full
//! solve.

use nalgebra::DVector;

use super::problem::Problem;
use crate::identification::EvalError;
use crate::lowrank::Base;

/// The current fit's solves, shared by every screen of a round.
pub(super) struct Shared {
    base: Base,
}

impl Shared {
    /// The solves of the problem `pc` (the current effects) at its scaled values `u`; `None`
    /// when the low-rank path cannot take this model (then every screen solves in full).
    pub(super) fn new(pc: &Problem, u: &DVector<f64>) -> Option<Shared> {
        let (x, gamma) = pc.split(u);
        let r = pc.realize(&gamma).ok()?;
        let crit = pc.criterion(&r).ok()?;
        let model = crit.model_at(&x);
        let base = Base::new(&model, crit.lines(), pc.frf_method()).ok()?;
        Some(Shared { base })
    }

    /// The whitened residuals (gains applied) of the extended problem `p` — the current effects
    /// and one candidate — at scaled `u`, the current effects' and variables' values those of
    /// the shared fit; `None` when the change is no update of the shared system.
    pub(super) fn residuals(
        &self,
        p: &Problem,
        u: &DVector<f64>,
    ) -> Option<Result<DVector<f64>, EvalError>> {
        let (x, gamma) = p.split(u);
        let r = match p.realize(&gamma) {
            Ok(r) => r,
            Err(e) => return Some(Err(e)),
        };
        let crit = match p.criterion(&r) {
            Ok(c) => c,
            Err(e) => return Some(Err(e)),
        };
        let update = self.base.update(&crit.model_at(&x)).ok()?;
        let y = self.base.changed_response(&update).ok()?;
        let mut e = crit.residuals_of(&x, |o, k| y[o][k]);
        Problem::gained(&crit, &mut e, &r.gains);
        if e.iter().any(|v| !v.is_finite()) {
            return Some(Err(EvalError::NotFinite("extended model's response")));
        }
        Some(Ok(e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::{generate, machine};
    use crate::identification::optimize::Residuals as _;
    use crate::identification::{data, Options};

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
}
