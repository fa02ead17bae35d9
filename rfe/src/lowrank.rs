//! A change of the model as a low-rank update of its dynamic stiffness: the outputs of a changed
//! model from the base model's solves, at a cost per change and line that does not grow with the
//! model.
//!
//! Every candidate effect of the diagnosis changes `A(ω) = K + jD − ω²M` on a few DOFs (its
//! *support* S: the bodies it touches) and may add a few DOFs N of its own (a point mass or a
//! resonator on its mount, the two end thirds of a split body). With `E` the columns of the
//! identity at S, the changed system condensed onto the base's DOFs is
//!
//! ```text
//! A' = A + E Δ(ω) Eᵀ,   Δ = ΔA_SS − A_SN A_NN⁻¹ A_NS,   P' = P + E p̃,   p̃ = ΔP_S − A_SN A_NN⁻¹ P_N
//! ```
//!
//! (`A_NN`, `A_SN` the changed system's blocks on the new DOFs: the Schur complement of the new
//! DOFs; without new DOFs only `ΔA_SS` and `ΔP_S` remain). With the base's solves `q = A⁻¹P`,
//! `w_o = A⁻¹ t_o` (A is complex symmetric, so the adjoint solve of output row `t_o` is a plain
//! solve) and the base's receptance on the support `G = Eᵀ A⁻¹ E`, Sherman-Morrison-Woodbury
//! gives the changed state on the support and every output:
//!
//! ```text
//! q'_S = (I + G Δ)⁻¹ (q_S + G p̃)
//! t_oᵀ q' = t_oᵀ q + w_o,Sᵀ (p̃ − Δ q'_S)
//! q'_N = A_NN⁻¹ (P_N − A_NS q'_S)
//! ```
//!
//! and an output whose row changes (an output on a split body reads its third) adds the change of
//! its row on S and its row on N. The update's rank is at most |S| (a spring: rank 1 within its
//! two bodies' 12 DOFs; a point mass, a resonator, an SDE direction, a body's mass: rank ≤ 6).
//! Where the columns of its blocks span fewer than |S| dimensions, it is applied in their
//! orthonormal basis `Q` (`Δ = Q C Qᵀ`, C r × r): `q'_S = b − G Q (I + C Qᵀ G Q)⁻¹ C Qᵀ b` with
//! `b = q_S + G p̃`, |S|² r operations per line instead of the |S|³ of `I + G Δ`; a change of
//! full rank on its support (a body's mass) is applied as a whole. Either way the cost per line
//! is a constant factor, not growth with the model. A split body is no low-rank change
//! of the same system — it adds 12 DOFs and moves the joints of the body to its thirds — but in
//! this bordered form it is one like the others: its support is the body and the bodies its
//! joints reach, its new DOFs the two end thirds.
//!
//! The derivative with respect to a parameter γ of the change follows alike,
//! `∂(t_oᵀq')/∂γ = −w'_o,Sᵀ (∂Δ/∂γ) q'_S` with `w'_o,S = (I + G Δ)⁻¹ w_o,S` ([`Base::derivative`]),
//! for a change without new DOFs that leaves the load alone.
//!
//! Two paths give the base's receptance, as for the FRF itself ([`crate::frf`]):
//! - **direct**: `A(ω)⁻¹` per line from one LU factorization (O(n³) per line, once for every
//!   change; kept in memory, n² complex numbers per line), then `G` is read off;
//! - **modal**: `G = X_S (Λ − ω²)⁻¹ Y_S` from the base's modes (O(|S|² n) per support and line).
//!
//! Either way `G` is kept per support ([`Base`]'s cache), so a change evaluated again — at another
//! size, as a screen and a refit do — costs O(|S|² r) per line.
//!
//! The base must be driven by its own excitation (no further references, no base motion): a base
//! motion's load `M T u_b` changes with every mass change.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use faer::Mat;
use nalgebra::{DMatrix, DVector};

use crate::frf::{self, Method, ModalSolver, SolveError, States, Work};
use crate::model::Model;
use crate::system::System;
use crate::C64;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Why a change cannot be applied as a low-rank update.
#[derive(Debug, thiserror::Error)]
pub enum LowRankError {
    /// The base model cannot be solved.
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// The changed model has fewer DOFs than the base: a body was removed, which no update of
    /// the base's system describes.
    #[error(
        "the changed model has {changed} DOFs, fewer than the base's {base}; use a full solve"
    )]
    FewerDofs {
        /// DOFs of the base.
        base: usize,
        /// DOFs of the changed model.
        changed: usize,
    },
    /// A reference other than the model's own excitation (a further reference or a base
    /// motion).
    #[error("the low-rank path solves the model's own excitation only (no further references, no base motion); use a full solve")]
    References,
    /// The changed model has another number of outputs.
    #[error("the changed model has {changed} outputs, the base {base}; both must read the same characteristics")]
    Outputs {
        /// Outputs of the base.
        base: usize,
        /// Outputs of the changed model.
        changed: usize,
    },
    /// The changed system is singular at a line (the update's capacitance or the new DOFs'
    /// block cannot be inverted).
    #[error("the changed system is singular at {freq_hz} Hz")]
    Singular {
        /// The line (Hz).
        freq_hz: f64,
    },
    /// [`Base::derivative`] of a change that adds DOFs or moves the load.
    #[error("the analytic derivative needs a change without new DOFs and with the same load; difference two updates instead")]
    NotLinear,
}

/// The base's receptance on any support.
enum Receptance {
    /// `A(ω_k)⁻¹`, row-major, per line.
    Direct(Vec<C64>),
    /// The base's complex modes.
    Modal(ModalSolver),
}

/// The base model's solves at every line, from which any [`Update`] is evaluated.
pub struct Base {
    system: System,
    states: States,
    receptance: Receptance,
    /// The receptance at every line on each support evaluated so far: a change evaluated at
    /// many sizes (a screen, a refit's steps) reads it again at O(|S|²) per line, whatever the
    /// path. At most [`CACHED_SUPPORTS`] supports are kept.
    cache: Mutex<HashMap<Vec<usize>, Receptances>>,
}

/// The receptance on one support at every line, shared between evaluations.
type Receptances = Arc<Vec<DMatrix<C64>>>;

/// Supports whose receptances a [`Base`] keeps (a round screens a few dozen candidates).
const CACHED_SUPPORTS: usize = 256;

/// A change of the base model in bordered low-rank form (see the module docs), built by
/// [`Base::update`] from the changed model.
#[derive(Debug, Clone)]
pub struct Update {
    /// The support S: base DOFs where the system, the load or an output row changes, or that
    /// couple to the new DOFs.
    pub support: Vec<usize>,
    /// Number of new DOFs.
    pub new_dofs: usize,
    /// `ΔK + jΔD` on S×S.
    k_ss: DMatrix<C64>,
    /// `ΔM` on S×S.
    m_ss: DMatrix<f64>,
    /// `K + jD` of the changed system on S×N, and its M.
    k_sn: DMatrix<C64>,
    m_sn: DMatrix<f64>,
    /// `K + jD` of the changed system on N×N, and its M.
    k_nn: DMatrix<C64>,
    m_nn: DMatrix<f64>,
    /// `ΔP` on S and `P` on N.
    p_s: DVector<f64>,
    p_n: DVector<f64>,
    /// Change of each output row on S (outputs × S) and each row on N (outputs × N).
    r_s: DMatrix<f64>,
    r_n: DMatrix<f64>,
    /// The change in the basis of its own columns, where that basis is smaller than S.
    reduced: Option<Reduced>,
}

/// An update in the basis of the columns it can have: `Q` (S × r, orthonormal, real) spans
/// the columns of `ΔK`, `ΔD`, `ΔM` on S×S and of `K`, `D`, `M` on S×N, so that
/// `Δ(ω) = Q (Qᵀ Δ(ω) Q) Qᵀ` at every ω, Schur complement included (all of them are symmetric,
/// and the Schur complement's columns are those of `A_SN`). A spring's `r` is 1 within its two
/// bodies' 12 DOFs.
#[derive(Debug, Clone)]
struct Reduced {
    /// `Q` as complex numbers.
    q: DMatrix<C64>,
    /// `Qᵀ (ΔK + jΔD) Q` and `Qᵀ ΔM Q` (r × r).
    k_rr: DMatrix<C64>,
    m_rr: DMatrix<f64>,
    /// `Qᵀ (K + jD)_SN` and `Qᵀ M_SN` (r × N).
    k_rn: DMatrix<C64>,
    m_rn: DMatrix<f64>,
}

/// A column of the (scaled) blocks whose part outside the basis so far is below this is in it:
/// the blocks' own rounding, relative to their largest entry.
const REDUCED_RANK_TOLERANCE: f64 = 1e-11;

impl Reduced {
    /// The reduced form of the blocks of an update on S, or `None` where their columns span S
    /// (nothing to gain). The basis is built column by column (Gram-Schmidt, orthogonalised
    /// twice), |S| r operations a column, and given up once it reaches |S|. Each block is
    /// scaled to its largest entry, so that a mass change is not lost beside a stiffness change
    /// eight decades larger.
    fn of(
        k_ss: &DMatrix<C64>,
        m_ss: &DMatrix<f64>,
        k_sn: &DMatrix<C64>,
        m_sn: &DMatrix<f64>,
    ) -> Option<Reduced> {
        let s = k_ss.nrows();
        if s == 0 {
            return None;
        }
        let blocks: [DMatrix<f64>; 6] = [
            k_ss.map(|v| v.re),
            k_ss.map(|v| v.im),
            m_ss.clone(),
            k_sn.map(|v| v.re),
            k_sn.map(|v| v.im),
            m_sn.clone(),
        ];
        let mut basis: Vec<DVector<f64>> = Vec::new();
        for block in &blocks {
            let max = block.amax();
            if max == 0.0 {
                continue;
            }
            for column in block.column_iter() {
                let mut v: DVector<f64> = column / max;
                for _ in 0..2 {
                    for b in &basis {
                        let along = b.dot(&v);
                        v.axpy(-along, b, 1.0);
                    }
                }
                let norm = v.norm();
                if norm > REDUCED_RANK_TOLERANCE {
                    basis.push(v / norm);
                    if 2 * basis.len() > s {
                        return None;
                    }
                }
            }
        }
        let q = DMatrix::from_columns(&basis);
        let qt = q.transpose();
        let qc = q.map(|v| C64::new(v, 0.0));
        let qct = qc.transpose();
        Some(Reduced {
            k_rr: &qct * k_ss * &qc,
            m_rr: &qt * m_ss * &q,
            k_rn: &qct * k_sn,
            m_rn: &qt * m_sn,
            q: qc,
        })
    }

    /// The reduced form of `factor` times a change without new DOFs.
    fn scaled(&self, factor: f64) -> Reduced {
        Reduced {
            k_rr: self.k_rr.map(|v| v * factor),
            m_rr: self.m_rr.map(|v| v * factor),
            ..self.clone()
        }
    }
}

impl Update {
    /// The update times `factor`: `∂ΔA/∂γ` of a change linear in γ is its update at γ divided
    /// by γ (differencing a unit change against the base would lose its digits to rounding).
    /// `None` for a change that adds DOFs or moves the load or the outputs, which is not linear.
    pub fn scaled(&self, factor: f64) -> Option<Update> {
        let linear = self.new_dofs == 0
            && self.p_s.iter().all(|v| *v == 0.0)
            && self.r_s.iter().all(|v| *v == 0.0);
        linear.then(|| Update {
            k_ss: self.k_ss.map(|v| v * factor),
            m_ss: self.m_ss.map(|v| v * factor),
            reduced: self.reduced.as_ref().map(|r| r.scaled(factor)),
            ..self.clone()
        })
    }

    /// `|S|`, the size of the block the update is applied on.
    pub fn rank_bound(&self) -> usize {
        self.support.len()
    }

    /// The rank the update is applied in: that of its blocks' columns where smaller than
    /// `|S|` (see [`Base::changed_response`]), else `|S|`.
    pub fn rank(&self) -> usize {
        self.reduced
            .as_ref()
            .map_or(self.support.len(), |r| r.q.ncols())
    }

    /// `(ΔA_SS, A_SN, A_NN)` at `omega`.
    fn blocks(&self, omega: f64) -> (DMatrix<C64>, DMatrix<C64>, DMatrix<C64>) {
        let w2 = omega * omega;
        (
            with_mass(&self.k_ss, &self.m_ss, w2),
            with_mass(&self.k_sn, &self.m_sn, w2),
            with_mass(&self.k_nn, &self.m_nn, w2),
        )
    }
}

/// `K + jD − ω² M` of a block, `w2` = ω².
fn with_mass(k: &DMatrix<C64>, m: &DMatrix<f64>, w2: f64) -> DMatrix<C64> {
    DMatrix::from_fn(k.nrows(), k.ncols(), |i, j| k[(i, j)] - m[(i, j)] * w2)
}

/// The dense mass matrix of a system (its diagonal and couplings), row-major.
fn dense_mass(s: &System) -> Vec<f64> {
    let n = s.n;
    let mut m = vec![0.0; n * n];
    for (i, v) in s.mass.iter().enumerate() {
        m[i * n + i] = *v;
    }
    for &(i, j, v) in &s.mass_coupling {
        m[i * n + j] += v;
    }
    m
}

/// A row over the DOFs of an output row's taps.
fn dense_row(taps: &[(usize, f64)], n: usize) -> Vec<f64> {
    let mut r = vec![0.0; n];
    for &(i, v) in taps {
        r[i] += v;
    }
    r
}

impl Base {
    /// The solves of `model` at `freqs_hz` by `method` (`Auto` chooses as the FRF does).
    pub fn new(model: &Model, freqs_hz: &[f64], method: Method) -> Result<Base, LowRankError> {
        let system = System::assemble(model);
        if !system.reference_loads.is_empty()
            || system.base_motion.iter().any(Option::is_some)
            || system.output_rows.iter().any(|r| r.column != 0 || r.base)
        {
            return Err(LowRankError::References);
        }
        let n = system.n;
        let outputs = system.output_rows.len();
        let method = method.resolve(n, freqs_hz.len(), Work::States { rhs: 1 + outputs });
        let states = frf::states(model, freqs_hz, method)?;
        let receptance = match method {
            Method::Modal => Receptance::Modal(ModalSolver::new(&system)?),
            _ => Receptance::Direct(direct_inverses(&system, freqs_hz)?),
        };
        Ok(Base {
            system,
            states,
            receptance,
            cache: Mutex::new(HashMap::new()),
        })
    }

    /// Number of lines.
    pub fn lines(&self) -> usize {
        self.states.freqs_hz.len()
    }

    /// Number of outputs.
    pub fn outputs(&self) -> usize {
        self.states.outputs
    }

    /// The base model's outputs, `[o][k]` (the model's quantities).
    pub fn response(&self) -> Vec<Vec<C64>> {
        (0..self.outputs())
            .map(|o| {
                (0..self.lines())
                    .map(|k| self.factor(k, o) * self.reading(k, o))
                    .collect()
            })
            .collect()
    }

    fn factor(&self, k: usize, o: usize) -> C64 {
        self.states.factor[k * self.states.outputs + o]
    }

    /// `t_oᵀ q` at line `k`.
    fn reading(&self, k: usize, o: usize) -> C64 {
        let q = self.states.load_at(k);
        self.system.output_rows[o].apply(|i| q[i])
    }

    /// `w_o` at line `k`.
    fn unit(&self, k: usize, o: usize) -> &[C64] {
        let (n, outs) = (self.states.n, self.states.outputs);
        &self.states.unit[(k * outs + o) * n..(k * outs + o + 1) * n]
    }

    /// The base's receptance on `support` at every line, from the cache or computed and kept.
    fn receptances(&self, support: &[usize]) -> Result<Receptances, LowRankError> {
        if let Some(g) = self.cache.lock().ok().and_then(|c| c.get(support).cloned()) {
            return Ok(g);
        }
        let g = (0..self.lines())
            .map(|k| self.receptance(k, support))
            .collect::<Result<Vec<_>, _>>()?;
        let g = Arc::new(g);
        if let Ok(mut c) = self.cache.lock() {
            if c.len() >= CACHED_SUPPORTS {
                c.clear();
            }
            c.insert(support.to_vec(), Arc::clone(&g));
        }
        Ok(g)
    }

    /// The base's receptance `Eᵀ A(ω_k)⁻¹ E` on `support`.
    fn receptance(&self, k: usize, support: &[usize]) -> Result<DMatrix<C64>, LowRankError> {
        let s = support.len();
        let n = self.states.n;
        match &self.receptance {
            Receptance::Direct(inv) => {
                let at = k * n * n;
                Ok(DMatrix::from_fn(s, s, |a, b| {
                    inv[at + support[a] * n + support[b]]
                }))
            }
            Receptance::Modal(m) => {
                let f = self.states.freqs_hz[k];
                let w2 = (TWO_PI * f).powi(2);
                let scale = m.lambda.iter().map(|l| l.norm()).fold(1.0, f64::max);
                let mut g = DMatrix::<C64>::zeros(s, s);
                for (r, l) in m.lambda.iter().enumerate() {
                    let den = l - w2;
                    if den.norm() <= 1e-13 * scale {
                        return Err(LowRankError::Singular { freq_hz: f });
                    }
                    let inv = den.inv();
                    for b in 0..s {
                        let yb = m.y[(r, support[b])] * inv;
                        for a in 0..s {
                            g[(a, b)] += m.x[(support[a], r)] * yb;
                        }
                    }
                }
                Ok(g)
            }
        }
    }

    /// The update that turns the base model into `changed` (the same bodies first, in the same
    /// order, and the same outputs; new bodies after them).
    pub fn update(&self, changed: &Model) -> Result<Update, LowRankError> {
        let c = System::assemble(changed);
        let b = &self.system;
        let (n0, n1) = (b.n, c.n);
        if n1 < n0 {
            return Err(LowRankError::FewerDofs {
                base: n0,
                changed: n1,
            });
        }
        if !c.reference_loads.is_empty()
            || c.base_motion.iter().any(Option::is_some)
            || c.output_rows.iter().any(|r| r.column != 0 || r.base)
        {
            return Err(LowRankError::References);
        }
        let outputs = b.output_rows.len();
        if c.output_rows.len() != outputs {
            return Err(LowRankError::Outputs {
                base: outputs,
                changed: c.output_rows.len(),
            });
        }
        let (mb, mc) = (dense_mass(b), dense_mass(&c));
        let mb = |i: usize, j: usize| mb[i * n0 + j];
        let mc = |i: usize, j: usize| mc[i * n1 + j];
        let kc = |i: usize, j: usize| C64::new(c.k[i * n1 + j], c.d[i * n1 + j]);
        let kb = |i: usize, j: usize| C64::new(b.k[i * n0 + j], b.d[i * n0 + j]);
        let rows_b: Vec<Vec<f64>> = b
            .output_rows
            .iter()
            .map(|r| dense_row(&r.taps, n0))
            .collect();
        let rows_c: Vec<Vec<f64>> = c
            .output_rows
            .iter()
            .map(|r| dense_row(&r.taps, n1))
            .collect();
        // Rounding of the assembly: a difference below it is no change.
        let tol_k = 1e-15 * c.k.iter().chain(&c.d).fold(0.0f64, |a, v| a.max(v.abs()));
        let tol_m = 1e-15 * c.mass.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let support: Vec<usize> = (0..n0)
            .filter(|&i| {
                let stiff = (0..n0).any(|j| (kc(i, j) - kb(i, j)).norm() > tol_k)
                    || (n0..n1).any(|j| kc(i, j).norm() > tol_k);
                let mass = (0..n0).any(|j| (mc(i, j) - mb(i, j)).abs() > tol_m)
                    || (n0..n1).any(|j| mc(i, j).abs() > tol_m);
                let load = c.load[i] != b.load[i];
                let row = rows_b.iter().zip(&rows_c).any(|(rb, rc)| rb[i] != rc[i]);
                stiff || mass || load || row
            })
            .collect();
        let s = support.len();
        let m = n1 - n0;
        let sup = |a: usize| support[a];
        let k_ss = DMatrix::from_fn(s, s, |a, bb| kc(sup(a), sup(bb)) - kb(sup(a), sup(bb)));
        let m_ss = DMatrix::from_fn(s, s, |a, bb| mc(sup(a), sup(bb)) - mb(sup(a), sup(bb)));
        let k_sn = DMatrix::from_fn(s, m, |a, j| kc(sup(a), n0 + j));
        let m_sn = DMatrix::from_fn(s, m, |a, j| mc(sup(a), n0 + j));
        Ok(Update {
            reduced: Reduced::of(&k_ss, &m_ss, &k_sn, &m_sn),
            k_ss,
            m_ss,
            k_sn,
            m_sn,
            k_nn: DMatrix::from_fn(m, m, |i, j| kc(n0 + i, n0 + j)),
            m_nn: DMatrix::from_fn(m, m, |i, j| mc(n0 + i, n0 + j)),
            p_s: DVector::from_fn(s, |a, _| c.load[sup(a)] - b.load[sup(a)]),
            p_n: DVector::from_fn(m, |j, _| c.load[n0 + j]),
            r_s: DMatrix::from_fn(outputs, s, |o, a| rows_c[o][sup(a)] - rows_b[o][sup(a)]),
            r_n: DMatrix::from_fn(outputs, m, |o, j| rows_c[o][n0 + j]),
            new_dofs: m,
            support,
        })
    }

    /// The changed model's outputs, `[o][k]`, from the base's solves and `u`.
    pub fn changed_response(&self, u: &Update) -> Result<Vec<Vec<C64>>, LowRankError> {
        let (lines, outputs) = (self.lines(), self.outputs());
        let mut out = vec![vec![C64::new(0.0, 0.0); lines]; outputs];
        let g = self.receptances(&u.support)?;
        for k in 0..lines {
            let line = match &u.reduced {
                Some(reduced) => self.line_reduced(k, u, reduced, &g[k])?,
                None => self.line(k, u, &g[k])?,
            };
            for (o, y) in out.iter_mut().enumerate() {
                y[k] = self.factor(k, o) * line.reading(o);
            }
        }
        Ok(out)
    }

    /// `∂y_o/∂γ`, `[o][k]`, of the changed model `u` for a parameter γ of the change whose
    /// derivative `∂ΔA/∂γ` is `du` (a change without new DOFs and with the same load, on a
    /// support within `u`'s).
    pub fn derivative(&self, u: &Update, du: &Update) -> Result<Vec<Vec<C64>>, LowRankError> {
        let linear = du.new_dofs == 0
            && du.p_s.iter().all(|v| *v == 0.0)
            && du.r_s.iter().all(|v| *v == 0.0)
            && du.support.iter().all(|i| u.support.contains(i));
        if !linear {
            return Err(LowRankError::NotLinear);
        }
        let at: Vec<usize> = du
            .support
            .iter()
            .map(|i| u.support.iter().position(|j| j == i).unwrap_or(0))
            .collect();
        let (lines, outputs) = (self.lines(), self.outputs());
        let mut out = vec![vec![C64::new(0.0, 0.0); lines]; outputs];
        if du.support.is_empty() {
            return Ok(out);
        }
        let g = self.receptances(&u.support)?;
        for k in 0..lines {
            let omega = TWO_PI * self.states.freqs_hz[k];
            let line = self.line(k, u, &g[k])?;
            let (d_small, _, _) = du.blocks(omega);
            let s = u.support.len();
            let mut d = DMatrix::<C64>::zeros(s, s);
            for (a, &ia) in at.iter().enumerate() {
                for (bb, &ib) in at.iter().enumerate() {
                    d[(ia, ib)] += d_small[(a, bb)];
                }
            }
            let dq = &d * &line.q_s;
            for (o, y) in out.iter_mut().enumerate() {
                let w = self.unit(k, o);
                let w_s = DVector::from_fn(s, |a, _| w[u.support[a]]);
                let w1 =
                    line.t
                        .as_ref()
                        .and_then(|t| t.solve(&w_s))
                        .ok_or(LowRankError::Singular {
                            freq_hz: self.states.freqs_hz[k],
                        })?;
                y[k] = -self.factor(k, o) * w1.dot(&dq);
            }
        }
        Ok(out)
    }

    /// The changed state at line `k`.
    fn line<'u>(
        &'u self,
        k: usize,
        u: &'u Update,
        g: &DMatrix<C64>,
    ) -> Result<Line<'u>, LowRankError> {
        let f = self.states.freqs_hz[k];
        let omega = TWO_PI * f;
        let singular = LowRankError::Singular { freq_hz: f };
        let s = u.support.len();
        let (mut delta, a_sn, a_nn) = u.blocks(omega);
        let mut p = u.p_s.map(|v| C64::new(v, 0.0));
        let p_n = u.p_n.map(|v| C64::new(v, 0.0));
        let nn_lu = a_nn.clone().lu();
        if u.new_dofs > 0 {
            // The Schur complement of the new DOFs.
            let x = nn_lu.solve(&a_sn.transpose()).ok_or(singular)?;
            delta -= &a_sn * &x;
            let y = nn_lu
                .solve(&p_n)
                .ok_or(LowRankError::Singular { freq_hz: f })?;
            p -= &a_sn * y;
        }
        let q = self.states.load_at(k);
        let q_s = DVector::from_fn(s, |a, _| q[u.support[a]]);
        let t = (DMatrix::<C64>::identity(s, s) + g * &delta).lu();
        // An empty support (no change, or new DOFs tied to the ground only): nothing to solve.
        let q_s1 = if s == 0 {
            q_s
        } else {
            t.solve(&(q_s + g * &p))
                .ok_or(LowRankError::Singular { freq_hz: f })?
        };
        let q_n1 = if u.new_dofs > 0 {
            nn_lu
                .solve(&(p_n - a_sn.transpose() * &q_s1))
                .ok_or(LowRankError::Singular { freq_hz: f })?
        } else {
            DVector::zeros(0)
        };
        let rhs = &p - &delta * &q_s1;
        Ok(Line {
            base: self,
            k,
            u,
            q_s: q_s1,
            q_n: q_n1,
            rhs,
            t: Some(t),
        })
    }

    /// The changed state at line `k` as [`Base::line`] gives it, in the update's reduced basis
    /// `Q` (`r` columns): with `Δ = Q C Qᵀ`, Woodbury's identity
    /// `(I + G Q C Qᵀ)⁻¹ = I − G Q (I + C Qᵀ G Q)⁻¹ C Qᵀ` needs an r × r factorisation and
    /// `G Q` (|S|² r) instead of `I + G Δ`'s |S|³ product and factorisation.
    fn line_reduced<'u>(
        &'u self,
        k: usize,
        u: &'u Update,
        reduced: &Reduced,
        g: &DMatrix<C64>,
    ) -> Result<Line<'u>, LowRankError> {
        let f = self.states.freqs_hz[k];
        let w2 = (TWO_PI * f).powi(2);
        let singular = || LowRankError::Singular { freq_hz: f };
        let q = &reduced.q;
        let mut c = with_mass(&reduced.k_rr, &reduced.m_rr, w2);
        let mut p = u.p_s.map(|v| C64::new(v, 0.0));
        let p_n = u.p_n.map(|v| C64::new(v, 0.0));
        let a_sn = with_mass(&u.k_sn, &u.m_sn, w2);
        let nn_lu = with_mass(&u.k_nn, &u.m_nn, w2).lu();
        if u.new_dofs > 0 {
            // The Schur complement of the new DOFs, in the reduced basis.
            let a_rn = with_mass(&reduced.k_rn, &reduced.m_rn, w2);
            let x = nn_lu.solve(&a_rn.transpose()).ok_or_else(singular)?;
            c -= &a_rn * x;
            let y = nn_lu.solve(&p_n).ok_or_else(singular)?;
            p -= &a_sn * y;
        }
        let load = self.states.load_at(k);
        let q_s = DVector::from_fn(u.support.len(), |a, _| load[u.support[a]]);
        let gq = g * q;
        let h = q.transpose() * &gq;
        let t = (DMatrix::<C64>::identity(c.nrows(), c.nrows()) + &c * h).lu();
        let b = if p.iter().all(|v| *v == C64::new(0.0, 0.0)) {
            q_s
        } else {
            q_s + g * &p
        };
        let z = t.solve(&(&c * (q.transpose() * &b))).ok_or_else(singular)?;
        let q_s1 = b - &gq * z;
        let q_n1 = if u.new_dofs > 0 {
            nn_lu
                .solve(&(p_n - a_sn.transpose() * &q_s1))
                .ok_or_else(singular)?
        } else {
            DVector::zeros(0)
        };
        let rhs = &p - q * (&c * (q.transpose() * &q_s1));
        Ok(Line {
            base: self,
            k,
            u,
            q_s: q_s1,
            q_n: q_n1,
            rhs,
            t: None,
        })
    }
}

/// The changed state at one line.
struct Line<'a> {
    base: &'a Base,
    k: usize,
    u: &'a Update,
    /// `q'_S`, `q'_N`.
    q_s: DVector<C64>,
    q_n: DVector<C64>,
    /// `p̃ − Δ q'_S`.
    rhs: DVector<C64>,
    /// LU of `I + G Δ` (made by [`Base::line`], for the derivative's adjoint solve).
    t: Option<nalgebra::LU<C64, nalgebra::Dyn, nalgebra::Dyn>>,
}

impl Line<'_> {
    /// The changed reading `t'_oᵀ q'` of output `o`.
    fn reading(&self, o: usize) -> C64 {
        let w = self.base.unit(self.k, o);
        let mut y = self.base.reading(self.k, o);
        for (a, &i) in self.u.support.iter().enumerate() {
            y += w[i] * self.rhs[a] + self.q_s[a] * self.u.r_s[(o, a)];
        }
        for j in 0..self.u.new_dofs {
            y += self.q_n[j] * self.u.r_n[(o, j)];
        }
        y
    }
}

/// `A(ω)⁻¹` at every line (row-major, lines × n × n) by LU with partial pivoting.
fn direct_inverses(s: &System, freqs_hz: &[f64]) -> Result<Vec<C64>, LowRankError> {
    let n = s.n;
    let mass = dense_mass(s);
    let mut out = Vec::with_capacity(freqs_hz.len() * n * n);
    for &f in freqs_hz {
        let w2 = (TWO_PI * f).powi(2);
        let a = Mat::<C64>::from_fn(n, n, |i, j| {
            C64::new(s.k[i * n + j] - w2 * mass[i * n + j], s.d[i * n + j])
        });
        let lu = a.partial_piv_lu();
        let mut inv = Mat::<C64>::identity(n, n);
        faer::linalg::solvers::Solve::solve_in_place(&lu, inv.as_mut());
        for i in 0..n {
            for j in 0..n {
                let v = inv[(i, j)];
                if !v.is_finite() {
                    return Err(LowRankError::Singular { freq_hz: f });
                }
                out.push(v);
            }
        }
    }
    Ok(out)
}
