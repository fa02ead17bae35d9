//! The fit of a model extended by effects: the identification's variables plus every effect's
//! parameters, as one least-squares problem for the identification's minimizers.
//!
//! The variables keep their analytic Jacobian (the identification criterion); so do the effects'
//! parameters that move only physical parameters of the model (most of them: a stiffness, a
//! mass, a tuning), from the same solves. The others (a place, a gain, a change of the model's
//! structure at its nested value) get forward-difference columns, one extra solve each.

use nalgebra::{DMatrix, DVector};

use super::effects::{Effect, EffectParam, Realized};
use identify::{self, Criterion, EvalError, FitKind, Observations, Variables};
use rfe::model::{Model, Param};

/// The extended fit problem. Optimizers see `u = value / scale`: the variables first, then
/// each effect's parameters in order.
pub struct Problem<'a> {
    base: &'a Model,
    vars: &'a Variables,
    obs: &'a Observations,
    opts: &'a identify::Options,
    /// The effects, in the order they are applied.
    pub effects: Vec<Effect>,
    /// Their parameters, flattened.
    pub params: Vec<EffectParam>,
    /// Highest measured frequency (Hz): sets stiff mounts above the band.
    pub f_max: f64,
    /// Scale of every `u`.
    pub scale: Vec<f64>,
    /// Model evaluations (each over all lines).
    pub evaluations: usize,
}

impl<'a> Problem<'a> {
    /// The problem for `effects` on top of the identification (`base`, `vars`, `obs`).
    pub fn new(
        base: &'a Model,
        vars: &'a Variables,
        obs: &'a Observations,
        opts: &'a identify::Options,
        effects: Vec<Effect>,
        f_max: f64,
    ) -> Problem<'a> {
        let params: Vec<EffectParam> = effects.iter().flat_map(|e| e.params(f_max)).collect();
        let scale = vars
            .vars
            .iter()
            .map(|v| v.scale)
            .chain(params.iter().map(|p| p.scale))
            .collect();
        Problem {
            base,
            vars,
            obs,
            opts,
            effects,
            params,
            f_max,
            scale,
            evaluations: 0,
        }
    }

    /// The identification's model, without the effects.
    pub fn base(&self) -> &Model {
        self.base
    }

    /// Number of identification variables.
    pub fn nx(&self) -> usize {
        self.vars.len()
    }

    /// `(x, γ)` in SI from scaled `u`.
    pub fn split(&self, u: &DVector<f64>) -> (Vec<f64>, Vec<f64>) {
        let v: Vec<f64> = u.iter().zip(&self.scale).map(|(u, s)| u * s).collect();
        let (x, g) = v.split_at(self.nx());
        (x.to_vec(), g.to_vec())
    }

    /// Bounds of `u`.
    pub fn bounds(&self) -> (DVector<f64>, DVector<f64>) {
        let lo = self
            .vars
            .vars
            .iter()
            .map(|v| v.lower)
            .chain(self.params.iter().map(|p| p.lower));
        let hi = self
            .vars
            .vars
            .iter()
            .map(|v| v.upper)
            .chain(self.params.iter().map(|p| p.upper));
        let n = self.scale.len();
        (
            DVector::from_iterator(n, lo.zip(&self.scale).map(|(l, s)| l / s)),
            DVector::from_iterator(n, hi.zip(&self.scale).map(|(h, s)| h / s)),
        )
    }

    /// The model, variables and gains with effect parameters `gamma` (SI).
    pub fn realize(&self, gamma: &[f64]) -> Result<Realized, EvalError> {
        let mut r = Realized {
            model: self.base.clone(),
            vars: self.vars.clone(),
            gains: vec![1.0; self.obs.characteristics.len()],
        };
        let mut at = 0;
        for e in &self.effects {
            let n = e.params(self.f_max).len();
            e.apply(&mut r, &gamma[at..at + n], self.f_max)?;
            at += n;
        }
        Ok(r)
    }

    /// The identification criterion of a realized model.
    pub fn criterion(&self, r: &Realized) -> Result<Criterion, EvalError> {
        Criterion::new(
            &r.model,
            self.obs,
            &r.vars,
            self.opts.fit,
            self.opts.noise,
            self.opts.frf_method,
        )
        .map_err(|e| EvalError::Setup(Box::new(e)))
    }

    /// The FRF path the identification's options choose.
    pub fn frf_method(&self) -> rfe::frf::Method {
        self.opts.frf_method
    }

    /// Whitened residuals with the gains applied: `e' = (1 − G) z/σ + G e`, i.e. `(z − G q)/σ`
    /// (log-amplitude fit: `e − ln G / σ`).
    pub(super) fn gained(crit: &Criterion, e: &mut DVector<f64>, gains: &[f64]) {
        if gains.iter().all(|g| *g == 1.0) {
            return;
        }
        let z = crit.measured();
        let np = z.len();
        let log = crit.fit() == FitKind::LogAmplitude;
        for (i, (o, _, sigma)) in crit.points().into_iter().enumerate() {
            let g = gains[o];
            if log {
                e[i] -= g.ln() / sigma;
                continue;
            }
            e[i] = (1.0 - g) * z[i].re / sigma + g * e[i];
            if e.len() > np {
                e[np + i] = (1.0 - g) * z[i].im / sigma + g * e[np + i];
            }
        }
    }

    /// Whitened residuals at `(x, γ)`, with the Jacobian in scaled `u` if asked.
    ///
    /// An effect parameter that moves only physical parameters of the realized model (an added
    /// spring's stiffness and ψ, a point mass's or resonator's mass and tuning, a freed
    /// direction's stiffness, a body's mass, a split body's joints, a split ψ) has its column
    /// from the same solves as the variables': the chain `Σ (∂p/∂γ) ∂e/∂p` over the parameters
    /// `p` it moves, `∂p/∂γ` by differencing the realized models (no solve). A parameter that
    /// moves anything else — a place, a sensor gain, or the model's structure at its nested
    /// value — gets a forward-difference column, one more evaluation.
    pub fn residuals(
        &mut self,
        x: &[f64],
        gamma: &[f64],
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError> {
        let r = self.realize(gamma)?;
        let mut crit = self.criterion(&r)?;
        // The chains of the effect parameters that move physical parameters only.
        let chains: Vec<Option<Vec<(Param, f64)>>> = if jacobian {
            let mut here = r.model.clone();
            r.vars.apply(&mut here, x);
            (0..gamma.len())
                .map(|j| self.chain(&here, &r.gains, x, gamma, j))
                .collect()
        } else {
            Vec::new()
        };
        let further: Vec<Vec<(Param, f64)>> = chains.iter().flatten().cloned().collect();
        let (mut e, jx) = if jacobian {
            let (e, jx) = crit.evaluate_with(x, &further)?;
            (e, Some(jx))
        } else {
            (crit.evaluate(x, None)?.0, None)
        };
        self.evaluations += 1;
        Self::gained(&crit, &mut e, &r.gains);
        if e.iter().any(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite("extended model's response"));
        }
        let Some(jx) = jx else { return Ok((e, None)) };
        let (m, nx) = (e.len(), x.len());
        let mut jac = DMatrix::zeros(m, nx + gamma.len());
        let points = crit.points();
        // A gain scales the response, so the amplitude residuals' derivatives; a log-amplitude
        // residual's derivative does not change with it.
        let log = crit.fit() == FitKind::LogAmplitude;
        let gain_of = |i: usize| {
            let o = points[i % points.len()].0;
            if log {
                1.0
            } else {
                r.gains[o]
            }
        };
        for c in 0..nx {
            for i in 0..m {
                jac[(i, c)] = jx[(i, c)] * gain_of(i) * self.scale[c];
            }
        }
        let mut analytic = nx;
        let mut g = gamma.to_vec();
        for j in 0..gamma.len() {
            let scale = self.scale[nx + j];
            if chains[j].is_some() {
                for i in 0..m {
                    jac[(i, nx + j)] = jx[(i, analytic)] * gain_of(i) * scale;
                }
                analytic += 1;
                continue;
            }
            let h = self.step(gamma, j);
            g[j] = gamma[j] + h;
            let rh = self.realize(&g)?;
            let mut ch = self.criterion(&rh)?;
            let (mut eh, _) = ch.evaluate(x, None)?;
            self.evaluations += 1;
            Self::gained(&ch, &mut eh, &rh.gains);
            g[j] = gamma[j];
            let col = (eh - &e) / h * scale;
            jac.set_column(nx + j, &col);
        }
        if jac.iter().any(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite("extended model's Jacobian"));
        }
        Ok((e, Some(jac)))
    }

    /// The difference step of effect parameter `j` at `gamma`: 1e-5 of its value or scale,
    /// inside its upper bound.
    fn step(&self, gamma: &[f64], j: usize) -> f64 {
        let p = &self.params[j];
        let h = 1e-5 * gamma[j].abs().max(p.scale);
        if gamma[j] + h > p.upper {
            -h
        } else {
            h
        }
    }

    /// `∂p/∂γ_j` of every physical parameter `p` of `here` (the realized model at variables `x`,
    /// with sensor gains `gains`) that effect parameter `j` moves, when it moves nothing else
    /// (see [`Problem::residuals`]): central differences of the realized models where the step
    /// fits inside the bounds (exact for the parameters linear in γ, second order otherwise),
    /// else a one-sided one. `None` when the parameter moves a gain or anything but physical
    /// parameters.
    fn chain(
        &self,
        here: &Model,
        gains: &[f64],
        x: &[f64],
        gamma: &[f64],
        j: usize,
    ) -> Option<Vec<(Param, f64)>> {
        // The change of the physical parameters from `here` for γ_j moved by `shift`.
        let changes = |shift: f64| -> Option<Vec<(Param, f64)>> {
            let mut g = gamma.to_vec();
            g[j] += shift;
            let rs = self.realize(&g).ok()?;
            if rs.gains != gains {
                return None;
            }
            let mut m = rs.model;
            rs.vars.apply(&mut m, x);
            here.param_changes(&m)
        };
        let h = self.step(gamma, j);
        let p = &self.params[j];
        let central = gamma[j] - h.abs() >= p.lower && gamma[j] + h.abs() <= p.upper;
        if !central {
            // One-sided: the change over the signed step.
            return Some(changes(h)?.into_iter().map(|(p, d)| (p, d / h)).collect());
        }
        let (h, width) = (h.abs(), 2.0 * h.abs());
        let up = changes(h)?;
        let down = changes(-h)?;
        let mut chain: Vec<(Param, f64)> = up.iter().map(|&(p, d)| (p, d / width)).collect();
        for (p, d) in down {
            match chain.iter_mut().find(|(q, _)| *q == p) {
                Some((_, c)) => *c -= d / width,
                None => chain.push((p, -d / width)),
            }
        }
        Some(chain)
    }
}

impl identify::optimize::Residuals for Problem<'_> {
    fn eval(
        &mut self,
        u: &DVector<f64>,
        jacobian: bool,
    ) -> Result<(DVector<f64>, Option<DMatrix<f64>>), EvalError> {
        let (x, g) = self.split(u);
        self.residuals(&x, &g, jacobian)
    }

    /// The Jacobian costs one evaluation when every effect parameter has its analytic column
    /// (see [`Problem::residuals`]): then a trial point is evaluated with it, so that an
    /// accepted step needs no second evaluation. A place or a gain differences the response.
    fn cheap_jacobian(&self) -> bool {
        self.effects.iter().all(|e| {
            !matches!(
                e,
                Effect::PlacedSpring { .. } | Effect::PlacedMass { .. } | Effect::Gain { .. }
            )
        })
    }
}
