//! Ranking candidate effects by a score (Lagrange-multiplier) test at the current fit.
//!
//! With whitened residuals `e` and Jacobian `J` of the free variables at the fit, and `g = ∂e/∂γ`
//! for an effect's parameter at its nested value, the score is `s = gᵀe` (= ∂J/∂γ) and
//!
//! ```text
//! LM = s² / (σ̂² · gᵀ(I − P)g),   P = J(JᵀJ)⁻¹Jᵀ,
//! ```
//!
//! χ²(1) under "no effect" (σ̂² = 1 when R is known). Effects bounded at their nested value
//! (a stiffness, a mass, a compliance cannot be negative) are tested one-sided: only a score that
//! lowers J for γ above the nested value counts, p = ½·P(χ²₁ > LM).
//!
//! Every `g` comes from one set of solves ([`frf::states`]): a spring's, mass's or resonator's
//! first-order action `∂q_o = −w_oᵀ ΔA q` costs O(its support) per line; a body that is not
//! rigid is scored in its rigid limit from the forces its joints would carry
//! (`flexible_first_order`); the damping splits share one Jacobian.

use super::effects::{
    body_index, point_row, resonator_coefficient, split_body, Effect, EffectError, RESONATOR_WIDTH,
};
use super::tuning::TUNING_STEPS_PER_WIDTH;
use identify::stats::chi2_tail;
use identify::Criterion;
use nalgebra::{DMatrix, DVector};
use rfe::frf::{self, States};
use rfe::model::{Model, ParamRef};
use rfe::system::OutputRow;
use rfe::C64;
use serde::Serialize;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// One candidate's score test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scored {
    /// Index into the candidate list.
    pub candidate: usize,
    /// LM statistic (0 where a one-sided test's score points below the nested value).
    pub statistic: f64,
    /// The LM statistic whatever the score's sign: where the one-sided `statistic` is 0 (the
    /// score would take a stiffness or a mass below its nested value), how strongly the data
    /// still pull on the effect. A large effect can lower J where a small one raises it.
    #[serde(skip)]
    pub pull: f64,
    /// p-value (one-sided where the effect is bounded at its nested value).
    pub p_value: f64,
    /// One Gauss-Newton step for γ from the nested value, with the variables re-adjusted (SI).
    pub step: f64,
    /// The candidate's whitened column with the fit's columns projected out, unit length: two
    /// candidates whose directions nearly coincide cannot be told apart by the data.
    #[serde(skip)]
    pub direction: DVector<f64>,
    /// A resonator's tuning frequency (Hz) where its score is largest within its cell.
    pub tuned_hz: Option<f64>,
}

/// The fit the scores are taken at.
pub struct FitPoint<'a> {
    /// The criterion of the current (realized) model.
    pub crit: &'a Criterion,
    /// Variables (SI).
    pub x: &'a [f64],
    /// Sensor gains `1 + g` per characteristic.
    pub gains: &'a [f64],
    /// Whitened residuals.
    pub e: &'a DVector<f64>,
    /// Whitened Jacobian of the free parameters (any column scaling).
    pub jac: &'a DMatrix<f64>,
    /// σ̂² (1 when R is known).
    pub sigma2: f64,
}

/// Why one candidate could not be scored (it is reported as not tried).
#[derive(Debug, thiserror::Error)]
pub enum NotScored {
    /// Its derivative lies in the span of the fitted variables' (or is nil).
    #[error(
        "its effect on the characteristics is indistinguishable from the fitted variables' (or nil)"
    )]
    Indistinguishable,
    /// The effect has no first-order (score) form.
    #[error("this effect has no first-order form")]
    NoFirstOrderForm,
    /// A joint of the split body has a singular stiffness.
    #[error("a split joint's stiffness is singular")]
    SingularJoint,
    /// The damping candidates' Jacobian was not computed.
    #[error("no damping Jacobian")]
    NoDampingJacobian,
    /// The effect cannot be applied to the model.
    #[error(transparent)]
    Effect(#[from] EffectError),
    /// The split model cannot be solved.
    #[error(transparent)]
    Solve(#[from] frf::SolveError),
}

/// Scores every candidate; `Err` entries say why a candidate could not be scored.
pub fn score_all(
    fit: &FitPoint,
    candidates: &[Effect],
) -> Result<Vec<Result<Scored, NotScored>>, frf::SolveError> {
    let crit = fit.crit;
    let model = crit.model_at(fit.x);
    let lines = crit.lines().to_vec();
    let states = frf::states(&model, &lines, frf::Method::Auto)?;
    let outputs: Vec<OutputRow> = model
        .outputs
        .iter()
        .map(|c| OutputRow::of(&model, c))
        .collect();
    let q = |o: usize, k: usize| {
        (outputs[o].apply(|i| states.load_for(k, o)[i]) * states.factor[k * states.outputs + o]
            + states.offset[k * states.outputs + o])
            * fit.gains[o]
    };
    // Orthonormal basis of the fit Jacobian's columns, for the projection.
    let basis = orthonormal_columns(fit.jac);
    let damping = damping_jacobian(&model, &lines, candidates)?;
    let mut out = Vec::with_capacity(candidates.len());
    let mut dq = vec![C64::new(0.0, 0.0); outputs.len() * lines.len()];
    for (ci, cand) in candidates.iter().enumerate() {
        if let Effect::Resonator { tuning, .. } = cand {
            let action = Action {
                model: &model,
                states: &states,
                gains: fit.gains,
                lines: &lines,
            };
            out.push(tuned_resonator(ci, cand, *tuning, &action, &q, fit, &basis));
            continue;
        }
        let filled = fill_derivative(
            cand, &model, &states, &outputs, fit.gains, &lines, &damping, &mut dq,
        );
        let col = match filled {
            Ok(()) => crit.whitened_derivative(q, |o, k| dq[o * lines.len() + k]),
            Err(e) => {
                out.push(Err(e));
                continue;
            }
        };
        out.push(statistic(ci, cand, &col, fit, &basis));
    }
    Ok(out)
}

fn statistic(
    ci: usize,
    cand: &Effect,
    g: &DVector<f64>,
    fit: &FitPoint,
    basis: &DMatrix<f64>,
) -> Result<Scored, NotScored> {
    let s = g.dot(fit.e);
    let resid = g - basis * (basis.transpose() * g);
    let info = resid.norm_squared();
    if !(info.is_finite() && info > 1e-12 * g.norm_squared().max(1e-300)) {
        return Err(NotScored::Indistinguishable);
    }
    let lm = s * s / (info * fit.sigma2);
    let step = -s / info;
    let one_sided = cand.params(1.0)[0].lower >= cand.params(1.0)[0].nested;
    let tail = chi2_tail(1.0, lm);
    let p_value = if one_sided {
        if step > 0.0 {
            0.5 * tail
        } else {
            1.0
        }
    } else {
        tail
    };
    let direction = resid / info.sqrt();
    Ok(Scored {
        candidate: ci,
        statistic: if one_sided && step <= 0.0 { 0.0 } else { lm },
        pull: lm,
        p_value,
        step,
        direction,
        tuned_hz: None,
    })
}

/// What a candidate's first-order action is computed from: the model at the fit, its states
/// (load and adjoint unit responses per line), the gains per characteristic and the lines (Hz).
struct Action<'a> {
    model: &'a Model,
    states: &'a States,
    gains: &'a [f64],
    lines: &'a [f64],
}

/// A resonator's score test maximised over its tuning frequency within `[lo, hi]` (Hz), its
/// p-value multiplied by the number of independent frequencies searched (Bonferroni).
///
/// Its action is `c(ω; f) Σ tᵀt` over its point's three rows, with `c` the tuned mass's dynamic
/// stiffness per unit mass ([`resonator_coefficient`]): the output changes are `c(ω_k; f) b_ok`
/// with `b` from one pass over the states, and the whitened column is
/// `Re c · W(b) + Im c · W(i b)` (the whitening `W` is real-linear). So every frequency costs one
/// projection, and the search can step at a fraction of the resonance's width — a sharply tuned
/// resonator between two grid frequencies scores where it is. Coarse steps of
/// [`TUNING_STEPS_PER_WIDTH`] per width, then a golden-section refinement around the best.
fn tuned_resonator(
    ci: usize,
    cand: &Effect,
    [lo, hi]: [f64; 2],
    action: &Action,
    q: &dyn Fn(usize, usize) -> C64,
    fit: &FitPoint,
    basis: &DMatrix<f64>,
) -> Result<Scored, NotScored> {
    let rows = cand.rows(action.model).ok_or(NotScored::NoFirstOrderForm)?;
    let nl = action.lines.len();
    let unit = C64::new(1.0, 0.0);
    let mut b = vec![C64::new(0.0, 0.0); action.gains.len() * nl];
    for k in 0..nl {
        for (o, g) in action.gains.iter().enumerate() {
            b[o * nl + k] =
                action
                    .states
                    .first_order(k, o, rows.iter().map(|r| (r.as_slice(), unit)))
                    * g;
        }
    }
    let crit = fit.crit;
    let w_re = crit.whitened_derivative(q, |o, k| b[o * nl + k]);
    let w_im = crit.whitened_derivative(q, |o, k| b[o * nl + k] * C64::new(0.0, 1.0));
    let points = crit.points();
    let line_of = |i: usize| points[i % points.len()].1;
    let coefficients = |f: f64| -> Vec<C64> {
        action
            .lines
            .iter()
            .map(|l| resonator_coefficient(TWO_PI * l, f))
            .collect()
    };
    let column = |f: f64| {
        let c = coefficients(f);
        DVector::from_fn(w_re.len(), |i, _| {
            let ck = c[line_of(i)];
            ck.re * w_re[i] + ck.im * w_im[i]
        })
    };
    // The column at tuning f is `Σ_k Re(c_k(f)) w_re|k + Im(c_k(f)) w_im|k` over the lines k
    // (`|k`: the residuals at line k), so its score, norm and projection onto the fit's columns
    // are sums over lines of per-line sums made once: O(lines × variables) per tuning instead
    // of O(residuals × variables).
    let sums = LineSums::new(&w_re, &w_im, fit.e, basis, (nl, &line_of));
    // The one-sided statistic (a mass is not negative): 0 where the score lowers the mass.
    let lm = |f: f64| {
        let (s, info) = sums.score_and_information(&coefficients(f));
        if s < 0.0 && info > 0.0 {
            s * s / info
        } else {
            0.0
        }
    };
    let (ln_lo, ln_hi) = (lo.ln(), hi.ln().max(lo.ln()));
    let step = RESONATOR_WIDTH / TUNING_STEPS_PER_WIDTH;
    let n = ((ln_hi - ln_lo) / step).ceil().max(1.0) as usize;
    let (mut best, mut best_lm) = (ln_lo, f64::NEG_INFINITY);
    for i in 0..=n {
        let x = ln_lo + (ln_hi - ln_lo) * i as f64 / n as f64;
        let v = lm(x.exp());
        if v > best_lm {
            (best, best_lm) = (x, v);
        }
    }
    let h = (ln_hi - ln_lo) / n as f64;
    let tuned = golden_max(
        |x| lm(x.exp()),
        (best - h).max(ln_lo),
        (best + h).min(ln_hi),
    )
    .exp();
    let tuned_cand = match cand {
        Effect::Resonator {
            body,
            point,
            tuning,
            scale,
            ..
        } => Effect::Resonator {
            body: body.clone(),
            point: *point,
            freq_hz: tuned,
            tuning: *tuning,
            scale: *scale,
        },
        other => other.clone(),
    };
    let mut s = statistic(ci, &tuned_cand, &column(tuned), fit, basis)?;
    s.tuned_hz = Some(tuned);
    // The best of many tuning frequencies: its p-value counts the independent ones searched —
    // one per line in the cell (a sharp resonance acts where a line sits) and one between.
    let searched = 1 + action
        .lines
        .iter()
        .filter(|f| (lo..=hi).contains(*f))
        .count();
    s.p_value = (s.p_value * searched as f64).min(1.0);
    Ok(s)
}

/// Per-line sums of a resonator's two whitened columns (`w_re`, `w_im`: its action with a real
/// and an imaginary unit coefficient) against the residuals, each other and the fit's
/// orthonormal columns: what its score test at any tuning needs.
struct LineSums {
    /// Per line: `[w_re·e, w_im·e, w_re·w_re, w_re·w_im, w_im·w_im]` over its residuals.
    scalars: Vec<[f64; 5]>,
    /// Per line: `basisᵀ w_re` and `basisᵀ w_im` over its residuals.
    projections: Vec<[DVector<f64>; 2]>,
}

impl LineSums {
    fn new(
        w_re: &DVector<f64>,
        w_im: &DVector<f64>,
        e: &DVector<f64>,
        basis: &DMatrix<f64>,
        (lines, line_of): (usize, &dyn Fn(usize) -> usize),
    ) -> LineSums {
        let p = basis.ncols();
        let mut scalars = vec![[0.0; 5]; lines];
        let mut projections = vec![[DVector::zeros(p), DVector::zeros(p)]; lines];
        for i in 0..w_re.len() {
            let k = line_of(i);
            let (a, b) = (w_re[i], w_im[i]);
            let t = &mut scalars[k];
            t[0] += a * e[i];
            t[1] += b * e[i];
            t[2] += a * a;
            t[3] += a * b;
            t[4] += b * b;
            let [pa, pb] = &mut projections[k];
            for j in 0..p {
                pa[j] += basis[(i, j)] * a;
                pb[j] += basis[(i, j)] * b;
            }
        }
        LineSums {
            scalars,
            projections,
        }
    }

    /// The score `gᵀe` and the information `gᵀ(I − P)g` of the column with per-line
    /// coefficients `c`.
    fn score_and_information(&self, c: &[C64]) -> (f64, f64) {
        let p = self.projections.first().map_or(0, |v| v[0].len());
        let (mut s, mut norm2) = (0.0, 0.0);
        let mut projected = DVector::<f64>::zeros(p);
        for ((t, [pa, pb]), ck) in self.scalars.iter().zip(&self.projections).zip(c) {
            let (a, b) = (ck.re, ck.im);
            s += a * t[0] + b * t[1];
            norm2 += a * a * t[2] + 2.0 * a * b * t[3] + b * b * t[4];
            projected.axpy(a, pa, 1.0);
            projected.axpy(b, pb, 1.0);
        }
        (s, norm2 - projected.norm_squared())
    }
}

/// The maximum of `f` on `[a, b]` by golden-section search (a unimodal stretch; 30 steps).
fn golden_max(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let (mut c, mut d) = (b - r * (b - a), a + r * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..30 {
        if fc > fd {
            (b, d, fd) = (d, c, fc);
            c = b - r * (b - a);
            fc = f(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + r * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// `∂ output / ∂γ` of one candidate at every (characteristic, line), into `dq[o * lines + k]`.
#[allow(clippy::too_many_arguments)]
fn fill_derivative(
    cand: &Effect,
    model: &Model,
    states: &States,
    outputs: &[OutputRow],
    gains: &[f64],
    lines: &[f64],
    damping: &Option<(Vec<ParamRef>, frf::Response)>,
    dq: &mut [C64],
) -> Result<(), NotScored> {
    let nl = lines.len();
    if let Some(rows) = cand.rows(model) {
        for (k, f) in lines.iter().enumerate() {
            let c = cand.coefficient(TWO_PI * f);
            for (o, g) in gains.iter().enumerate() {
                dq[o * nl + k] =
                    states.first_order(k, o, rows.iter().map(|r| (r.as_slice(), c))) * g;
            }
        }
        return Ok(());
    }
    match cand {
        Effect::Gain { output, .. } => {
            for o in 0..gains.len() {
                for k in 0..nl {
                    dq[o * nl + k] = if o == *output {
                        (outputs[o].apply(|i| states.load_for(k, o)[i])
                            * states.factor[k * states.outputs + o]
                            + states.offset[k * states.outputs + o])
                            * gains[o]
                    } else {
                        C64::new(0.0, 0.0)
                    };
                }
            }
            Ok(())
        }
        Effect::Damping {
            sdes, parameter, ..
        } => {
            let (params, r) = damping.as_ref().ok_or(NotScored::NoDampingJacobian)?;
            dq.iter_mut().for_each(|v| *v = C64::new(0.0, 0.0));
            for (p, pr) in params.iter().enumerate() {
                if pr.name == *parameter && sdes.contains(&model.sdes[pr.sde].name) {
                    for (o, g) in gains.iter().enumerate() {
                        for (k, d) in r.derivative(p, o).iter().enumerate() {
                            dq[o * nl + k] += d * g;
                        }
                    }
                }
            }
            Ok(())
        }
        Effect::Flexible { body, axis, .. } => {
            flexible_first_order(model, states, body, *axis, gains, lines, dq)
        }
        _ => Err(NotScored::NoFirstOrderForm),
    }
}

/// `∂ output / ∂c` of `body` split into three RFEs along `axis` at zero joint compliance c, from
/// the rigid solution alone (no solve of the split model).
///
/// At c → 0 the split model is the rigid one with the joints' wrenches as Lagrange multipliers;
/// the only c-dependent block of that saddle system is the joints' flexibility, so (adjoint)
/// `∂y_o/∂c = factor_o · Σ_j ρ_jᵀ K_j⁻¹ λ_j`: λ_j and ρ_j are the generalized forces joint j
/// exerts on its end third under the load and under a unit load on output o — each end third's
/// equation of motion with the rigid motion inserted, `P − A_free q` on its six DOFs — and `K_j`
/// is joint j's complex stiffness block on those DOFs at c = 1. Checked against a finite
/// difference of the split model in the tests.
fn flexible_first_order(
    model: &Model,
    states: &States,
    body: &str,
    axis: usize,
    gains: &[f64],
    lines: &[f64],
    dq: &mut [C64],
) -> Result<(), NotScored> {
    let b = body_index(model, body)?;
    let n = model.dof_count();
    let mut split = model.clone();
    split_body(&mut split, body, axis, 1.0)?;
    let ns = split.dof_count();
    let joints = [split.sdes.len() - 2, split.sdes.len() - 1];
    let ends = [n / 6, n / 6 + 1];
    // The free part (joints disabled), and each joint's own stiffness block on its end third.
    let mut free = split.clone();
    for j in joints {
        free.sdes[j].enabled = false;
    }
    let sys = rfe::system::System::assemble(&free);
    let joint_inv = joint_inverses(&split, joints, ends)?;
    // Rigid motion of the body carried to the end thirds' centres (same axes).
    let expand = rigid_to_ends(model, b, &split, ends);
    // The end thirds' rows of A_free = K + jD (mass apart), sparse: only the SDEs attached to them.
    let rows = end_rows(&sys, ends);
    let mut full = vec![C64::new(0.0, 0.0); ns];
    // Generalized force on each end third with the rigid motion `x` (n DOFs) inserted: rhs − A_free x.
    let mut end_force =
        |x: &[C64], rhs: &dyn Fn(usize) -> f64, w2: f64, out: &mut [[C64; 6]; 2]| {
            full[..n].copy_from_slice(x);
            for (k, &e) in ends.iter().enumerate() {
                for (i, row) in expand[k].iter().enumerate() {
                    full[6 * e + i] = row
                        .iter()
                        .zip(&x[6 * b..6 * b + 6])
                        .map(|(r, v)| v * r)
                        .sum();
                }
            }
            for (k, &e) in ends.iter().enumerate() {
                for i in 0..6 {
                    let r = 6 * e + i;
                    let mut acc = C64::new(rhs(r), 0.0) + full[r] * (w2 * sys.mass[r]);
                    for &(c, a) in &rows[6 * k + i] {
                        acc -= a * full[c];
                    }
                    out[k][i] = acc;
                }
            }
        };
    let nl = lines.len();
    let mut lambda = [[C64::new(0.0, 0.0); 6]; 2];
    let mut rho = [[C64::new(0.0, 0.0); 6]; 2];
    for (k, f) in lines.iter().enumerate() {
        let w2 = (TWO_PI * f).powi(2);
        for (o, g) in gains.iter().enumerate() {
            let column = sys.output_rows[o].column;
            end_force(
                states.load_for(k, o),
                &|r| sys.load_entry(column, r),
                w2,
                &mut lambda,
            );
            let w = &states.unit[(k * states.outputs + o) * n..(k * states.outputs + o + 1) * n];
            // The unit load sits on an original body's DOF, never on a new end third.
            end_force(w, &|_| 0.0, w2, &mut rho);
            let mut acc = C64::new(0.0, 0.0);
            for (j, inv) in joint_inv.iter().enumerate() {
                let l = nalgebra::Vector6::from_column_slice(&lambda[j]);
                let r = nalgebra::Vector6::from_column_slice(&rho[j]);
                acc += r.dot(&(inv * l));
            }
            dq[o * nl + k] = acc * states.factor[k * states.outputs + o] * g;
        }
    }
    Ok(())
}

/// The inverse of each split joint's complex stiffness block on its end third's DOFs.
fn joint_inverses(
    split: &Model,
    joints: [usize; 2],
    ends: [usize; 2],
) -> Result<Vec<nalgebra::Matrix6<C64>>, NotScored> {
    let ns = split.dof_count();
    let mut joint_inv = Vec::with_capacity(2);
    for (j, e) in joints.iter().zip(ends) {
        let mut only = split.clone();
        for (i, sde) in only.sdes.iter_mut().enumerate() {
            sde.enabled = i == *j;
        }
        let sj = rfe::system::System::assemble(&only);
        let kj = nalgebra::Matrix6::<C64>::from_fn(|r, c| {
            let (i, k) = (6 * e + r, 6 * e + c);
            C64::new(sj.k[i * ns + k], sj.d[i * ns + k])
        });
        joint_inv.push(kj.try_inverse().ok_or(NotScored::SingularJoint)?);
    }
    Ok(joint_inv)
}

/// For each end third: its six DOFs as functions of body `b`'s six (a rigid motion carried to
/// the third's centre, same axes).
fn rigid_to_ends(model: &Model, b: usize, split: &Model, ends: [usize; 2]) -> Vec<[[f64; 6]; 6]> {
    let rot = model.bodies[b].rotation;
    ends.iter()
        .map(|&e| {
            let p = split.bodies[e].position;
            let mut t = [[0.0; 6]; 6];
            for (i, row) in t.iter_mut().enumerate().take(3) {
                for (dof, v) in point_row(model, b, &p, &rot.column(i).into_owned()) {
                    row[dof - 6 * b] = v;
                }
            }
            for (i, row) in t.iter_mut().enumerate().skip(3) {
                row[i] = 1.0;
            }
            t
        })
        .collect()
}

/// The end thirds' rows of `K + jD` of the split model with its joints disabled, sparse.
fn end_rows(sys: &rfe::system::System, ends: [usize; 2]) -> Vec<Vec<(usize, C64)>> {
    let ns = sys.n;
    ends.iter()
        .flat_map(|&e| (0..6).map(move |i| 6 * e + i))
        .map(|r| {
            (0..ns)
                .filter_map(|c| {
                    let v = C64::new(sys.k[r * ns + c], sys.d[r * ns + c]);
                    (v != C64::new(0.0, 0.0)).then_some((c, v))
                })
                .collect()
        })
        .collect()
}

/// One Jacobian of every ψ parameter the damping candidates split off.
fn damping_jacobian(
    model: &Model,
    lines: &[f64],
    candidates: &[Effect],
) -> Result<Option<(Vec<ParamRef>, frf::Response)>, frf::SolveError> {
    let mut params: Vec<ParamRef> = Vec::new();
    for c in candidates {
        if let Effect::Damping {
            sdes, parameter, ..
        } = c
        {
            for s in sdes {
                if let Some(i) = model.sde_index(s) {
                    let p = ParamRef {
                        sde: i,
                        name: *parameter,
                    };
                    if !params.contains(&p) {
                        params.push(p);
                    }
                }
            }
        }
    }
    if params.is_empty() {
        return Ok(None);
    }
    let r = frf::response(model, lines, &params, frf::Method::Auto)?;
    Ok(Some((params, r)))
}

/// An orthonormal basis of the column space of `j` (thin QR; near-dependent columns dropped).
pub fn orthonormal_columns(j: &DMatrix<f64>) -> DMatrix<f64> {
    if j.ncols() == 0 {
        return DMatrix::zeros(j.nrows(), 0);
    }
    let qr = j.clone().qr();
    let (q, r) = (qr.q(), qr.r());
    let big = (0..r.nrows().min(r.ncols()))
        .map(|i| r[(i, i)].abs())
        .fold(0.0, f64::max);
    let keep: Vec<usize> = (0..r.nrows().min(r.ncols()))
        .filter(|&i| r[(i, i)].abs() > 1e-10 * big)
        .collect();
    DMatrix::from_fn(q.nrows(), keep.len(), |a, b| q[(a, keep[b])])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::effects::Realized;

    /// A resonator's per-line sums give the score and information of the column built in full,
    /// `gᵀe` and `gᵀ(I − P)g`, at any coefficients (here pseudo-random ones, two residuals a
    /// line as an amplitude fit of two characteristics has).
    #[test]
    fn line_sums_give_the_full_columns_score_and_information() {
        let (lines, m) = (7usize, 14usize);
        let wave = |i: usize, k: f64| ((i as f64 + 1.0) * k).sin();
        let w_re = DVector::from_fn(m, |i, _| wave(i, 0.7));
        let w_im = DVector::from_fn(m, |i, _| wave(i, 1.3));
        let e = DVector::from_fn(m, |i, _| wave(i, 2.9));
        let basis = orthonormal_columns(&DMatrix::from_fn(m, 3, |i, j| wave(i, 0.4 + j as f64)));
        let line_of = |i: usize| i % lines;
        let sums = LineSums::new(&w_re, &w_im, &e, &basis, (lines, &line_of));
        let c: Vec<C64> = (0..lines)
            .map(|k| C64::new(wave(k, 0.9), wave(k, 0.5)))
            .collect();
        let g = DVector::from_fn(m, |i, _| {
            let ck = c[line_of(i)];
            ck.re * w_re[i] + ck.im * w_im[i]
        });
        let (s, info) = sums.score_and_information(&c);
        let full_info = g.norm_squared() - (basis.transpose() * &g).norm_squared();
        assert!((s - g.dot(&e)).abs() < 1e-12, "{s} against {}", g.dot(&e));
        assert!(
            (info - full_info).abs() < 1e-12,
            "{info} against {full_info}"
        );
    }

    /// The first-order action of every candidate that acts through `A(ω)` — springs, masses,
    /// resonators, freed SDE directions (left out, and held stiff by a general element), body
    /// masses — against a central difference of the model with the effect applied.
    #[test]
    fn first_order_actions_match_a_central_difference_of_the_applied_effect() {
        let fwd = crate::test_support::fwd32j();
        let chain = rfe::textbook::two_in_series(100.0, 50.0, 1e6, 2e6, 0.2);
        let vars_of = |_: &Model| identify::Variables {
            vars: Vec::new(),
            origin: String::new(),
            extra_starts: Vec::new(),
        };
        let mut checked = std::collections::BTreeMap::<&str, usize>::new();
        for model in [&fwd, &chain] {
            let lines = [20.0, 57.0, 131.0, 250.0, 400.0];
            let labels: Vec<String> = (0..model.outputs.len()).map(|o| o.to_string()).collect();
            let vars = vars_of(model);
            let candidates = crate::generate::candidates(model, &vars, &[], &labels, 20.0, 400.0);
            let states = frf::states(model, &lines, frf::Method::Direct).unwrap();
            let outputs: Vec<OutputRow> = model
                .outputs
                .iter()
                .map(|c| OutputRow::of(model, c))
                .collect();
            let gains = vec![1.0; outputs.len()];
            let nl = lines.len();
            let base = frf::response(model, &lines, &[], frf::Method::Direct).unwrap();
            // A few of each kind (the first, the middle and the last).
            let mut kinds: Vec<&str> = candidates.iter().map(Effect::kind).collect();
            kinds.dedup();
            for kind in kinds {
                let of: Vec<&Effect> = candidates.iter().filter(|c| c.kind() == kind).collect();
                for cand in [of[0], of[of.len() / 2], of[of.len() - 1]] {
                    if cand.rows(model).is_none() {
                        continue;
                    }
                    let mut dq = vec![C64::new(0.0, 0.0); outputs.len() * nl];
                    fill_derivative(
                        cand, model, &states, &outputs, &gains, &lines, &None, &mut dq,
                    )
                    .unwrap();
                    let np = &cand.params(400.0)[0];
                    // Large enough that the change stands above the solves' rounding (the
                    // structure's stiffnesses span six decades), small enough to be linear.
                    // (A resonator near a line acts strongly and nonlinearly: a smaller step.)
                    let h = np.scale
                        * if matches!(cand, Effect::Resonator { .. }) {
                            1e-4
                        } else {
                            1e-2
                        };
                    let at = |g: f64| {
                        let mut r = Realized {
                            model: model.clone(),
                            vars: vars.clone(),
                            gains: gains.clone(),
                        };
                        let mut v: Vec<f64> = cand.params(400.0).iter().map(|p| p.nested).collect();
                        v[0] = g;
                        cand.apply(&mut r, &v, 400.0).unwrap();
                        frf::response(&r.model, &lines, &[], frf::Method::Direct).unwrap()
                    };
                    // One-sided parameters (bounded at their nested value) by a forward
                    // difference with Richardson extrapolation, the others centrally.
                    let one_sided = np.lower >= np.nested;
                    let (rp, rm, rp2) = if one_sided {
                        (at(np.nested + h), None, Some(at(np.nested + 2.0 * h)))
                    } else {
                        (at(np.nested + h), Some(at(np.nested - h)), None)
                    };
                    for o in 0..outputs.len() {
                        let fd: Vec<C64> = (0..nl)
                            .map(|k| match (&rm, &rp2) {
                                (Some(rm), _) => (rp.output(o)[k] - rm.output(o)[k]) / (2.0 * h),
                                (None, Some(rp2)) => {
                                    let y0 = base.output(o)[k];
                                    let d1 = (rp.output(o)[k] - y0) / h;
                                    let d2 = (rp2.output(o)[k] - y0) / (2.0 * h);
                                    2.0 * d1 - d2
                                }
                                _ => unreachable!(),
                            })
                            .collect();
                        let scale = fd.iter().map(|v| v.norm()).fold(0.0, f64::max);
                        // An added point mass is a small body on a stiff mount (30× above the
                        // band), a rigid mass in its first-order form.
                        let tol = match cand {
                            Effect::Mass { .. } => 1e-3,
                            _ => 1e-4,
                        };
                        for (k, fd) in fd.into_iter().enumerate() {
                            let a = dq[o * nl + k];
                            assert!(
                                (a - fd).norm() <= tol * scale + 1e-30,
                                "{}: output {o}, {} Hz: first order {a}, difference {fd}",
                                cand.describe(),
                                lines[k]
                            );
                        }
                    }
                    *checked.entry(cand.kind()).or_default() += 1;
                }
            }
        }
        for kind in ["spring", "mass", "resonator", "SDE direction", "body mass"] {
            assert!(checked.get(kind).is_some_and(|n| *n >= 3), "{checked:?}");
        }
        // The chain's guides hold their directions at a stiffness: those are freed as compliances.
        let vars = vars_of(&chain);
        let held = crate::generate::candidates(&chain, &vars, &[], &[], 20.0, 400.0)
            .into_iter()
            .filter(|c| matches!(c, Effect::Direction { held, .. } if *held > 0.0))
            .count();
        assert!(held >= 8, "{held}");
    }

    /// The rigid-limit derivative of every split body of FWD-32J against a finite difference of
    /// the split model (O(h) accurate).
    #[test]
    fn flexible_body_derivative_matches_a_finite_difference_of_the_split_model() {
        let model = crate::test_support::fwd32j();
        let lines = [20.0, 57.0, 131.0, 250.0, 400.0];
        let states = frf::states(&model, &lines, frf::Method::Direct).unwrap();
        let outputs: Vec<OutputRow> = model
            .outputs
            .iter()
            .map(|c| OutputRow::of(&model, c))
            .collect();
        let gains = vec![1.0; outputs.len()];
        let nl = lines.len();
        let mut analytic = vec![C64::new(0.0, 0.0); outputs.len() * nl];
        let mut checked = 0;
        for body in ["table", "column", "knee", "spindle head"] {
            for axis in 0..3 {
                flexible_first_order(&model, &states, body, axis, &gains, &lines, &mut analytic)
                    .unwrap();
                // The split response is linear in c to first order: Richardson-extrapolate two
                // forward differences (c = 1e-12 and 1e-13 m/N; the structure's compliances
                // are ~1e-8) to cancel the O(c) term.
                let fd_at = |h: f64| {
                    let mut split = model.clone();
                    split_body(&mut split, body, axis, h).unwrap();
                    (
                        h,
                        frf::response(&split, &lines, &[], frf::Method::Direct).unwrap(),
                    )
                };
                let (h1, r1) = fd_at(1e-12);
                let (h2, r2) = fd_at(1e-13);
                for o in 0..outputs.len() {
                    let fd: Vec<C64> = (0..nl)
                        .map(|k| {
                            let y0 = outputs[o].apply(|i| states.load_at(k)[i])
                                * states.factor[k * states.outputs + o];
                            let (d1, d2) =
                                ((r1.output(o)[k] - y0) / h1, (r2.output(o)[k] - y0) / h2);
                            (d2 * 10.0 - d1) / 9.0
                        })
                        .collect();
                    // Relative to the characteristic's largest derivative: where the derivative is
                    // tiny, the differences are rounding noise of the solves.
                    let scale = fd.iter().map(|v| v.norm()).fold(0.0, f64::max);
                    for (k, fd) in fd.into_iter().enumerate() {
                        let a = analytic[o * nl + k];
                        assert!(
                            (a - fd).norm() <= 1e-3 * scale + 1e-30,
                            "{body} axis {axis}, output {o}, {} Hz: analytic {a}, FD {fd}",
                            lines[k]
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert_eq!(checked, 4 * 3 * outputs.len() * nl);
    }
}
