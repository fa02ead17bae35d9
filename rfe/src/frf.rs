//! Frequency response of the output characteristics and its analytic Jacobian with respect to
//! SDE parameters (paper eq. 4.1; sensitivities for eq. 4.7, 4.15, 4.16).
//!
//! Two solution paths give one answer:
//! - **direct**: per frequency line, one factorisation of `A(ω) = K + jD − ω²M` (O(n³) per
//!   line): a complex-symmetric `L Δ Lᵀ` run on eight lines at once, one per SIMD lane
//!   ([`crate::lines`]), with a pivoted LU for any line whose element growth it cannot vouch for;
//! - **modal**: one eigen-decomposition of `M^-½ (K + jD) M^-½ = V Λ V⁻¹` (hysteretic damping
//!   makes it frequency independent), then `A(ω)⁻¹ = X (Λ − ω²)⁻¹ Y` with `X = M^-½ V`,
//!   `Y = V⁻¹ M^-½`: O(n) per output and per parameter per line.
//!
//! The Jacobian uses the adjoint form: with `w_o = A⁻¹ e_o` (A is complex symmetric),
//! `∂q_o/∂p = −w_oᵀ (∂A/∂p) q = −Σ_i c_i (T w_o)_i (T q)_i`, touching only the SDE that owns `p`.
//! A body's mass or principal inertia, or a point mass, enters as `∂A/∂p = −ω² ∂M/∂p`, so
//! `∂q_o/∂p = ω² Σ_ij ∂M_ij/∂p (w_o)_i q_j` over its body's six DOFs (diagonal for the body's
//! own mass and inertias, a full block for a point mass off the centre of mass;
//! [`response_params`]). With point masses M is block-diagonal rather than diagonal, and the
//! modal path's `M^-½` is each body's inverse Cholesky factor ([`MassScaling`]).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::lu::partial_pivoting::{factor, solve};
use faer::{Mat, Par};

use crate::lines::{Batch, LANES};
use crate::model::{Model, Param, ParamRef, Quantity};
use crate::system::{MassScaling, ParamBlock, System};
use crate::C64;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// Which solution path to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Whichever of the two a cost model expects to be cheaper ([`Method::resolve`]).
    #[default]
    Auto,
    /// Per-frequency factorisation (batched `L Δ Lᵀ`, pivoted LU where needed).
    Direct,
    /// One eigen-decomposition, then modal sums per line.
    Modal,
}

/// What an evaluation computes: it sets the modal path's cost per line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Work {
    /// The outputs and their derivatives with respect to `params` parameters ([`response`]).
    Outputs {
        /// Jacobian columns (SDE parameters, not decision variables).
        params: usize,
        /// Load columns solved per line when there are Jacobian columns: the load and one unit
        /// load per output.
        columns: usize,
    },
    /// Full DOF solutions for `rhs` right-hand sides ([`states`]).
    States {
        /// Right-hand sides: the load and one unit load per output.
        rhs: usize,
    },
}

impl Method {
    /// The path [`Method::Auto`] picks for `n` DOFs, `lines` frequency lines and `work`: the
    /// cheaper by a cost model fitted to measurements (FWD-32J with 0–74 parameters and chains of
    /// 24–240 DOFs, 20–600 lines; `cargo bench -p identify --bench frf_lines`, group
    /// `fwd32j_direct_vs_modal_by_lines`). Estimated seconds:
    /// - direct: `lines · 2.4e-10 n^2.7` (one batched `L Δ Lᵀ` per line; the adjoint Jacobian
    ///   adds little);
    /// - modal: `1.5e-8 n^2.7` for the eigen-decomposition, plus per line `1.43e-8 n` for the
    ///   outputs and, for `P` parameters, the cheaper of `3.6e-9 n P` (the deformations of the
    ///   SDEs that carry them from their rows of the mode shapes) and `9.6e-10 n² c + 1.5e-8 P`
    ///   (from the full states of the `c` load columns, then each SDE's taps);
    ///   `9.6e-10 n² rhs` for full solutions.
    ///
    /// Only the ratio matters. Near the break-even the two are within about 1.4× of each other,
    /// so the model need not be exact. On FWD-32J (42 DOFs) the identification's 74 parameters
    /// keep the direct path cheaper at any number of lines; a plain FRF goes modal above about
    /// 70 lines. This is the cost of a dense factorisation; [`Method::resolve_for`] weighs the
    /// system's sparsity.
    pub fn resolve(self, n: usize, lines: usize, work: Work) -> Method {
        self.choose(n, lines, work, 1.0)
    }

    /// [`Method::resolve`] for `system`, the direct path's cost scaled by the share of a dense
    /// factorisation its sparsity keeps ([`crate::lines::fill_share`]: bodies in a chain keep
    /// few of the dense block products, so the direct path's cost grows far slower than n³).
    /// Measured on the generated machines of `diagnose`'s `machine_scaling` example (300 lines,
    /// every SDE parameter the variables set, quiet machine), direct and modal: 14 bodies (84
    /// DOFs, 161 parameters) 2.9 and 15.7 ms; 28 bodies (168, 316) 6.2 and 44.9 ms; 42 bodies
    /// (252, 501) 10.9 and 70.5 ms.
    pub fn resolve_for(self, system: &System, lines: usize, work: Work) -> Method {
        if self != Method::Auto {
            return self;
        }
        self.choose(system.n, lines, work, crate::lines::fill_share(system))
    }

    /// The cheaper path by the cost model, the direct path's cost times `direct_share`.
    fn choose(self, n: usize, lines: usize, work: Work, direct_share: f64) -> Method {
        if self != Method::Auto {
            return self;
        }
        let (nf, lf) = (n as f64, lines as f64);
        let cube = nf.powf(2.7);
        let direct = lf * 2.4e-10 * cube * direct_share;
        let per_line = match work {
            Work::Outputs { params, columns } => {
                let sde_rows = 3.6e-9 * nf * params as f64;
                let states = 9.6e-10 * nf * nf * columns as f64 + 1.5e-8 * params as f64;
                nf * 1.43e-8
                    + if params == 0 {
                        0.0
                    } else {
                        sde_rows.min(states)
                    }
            }
            Work::States { rhs } => 9.6e-10 * nf * nf * rhs as f64,
        };
        let modal = 1.5e-8 * cube + lf * per_line;
        if modal < direct {
            Method::Modal
        } else {
            Method::Direct
        }
    }
}

/// Errors of the frequency-response computation.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SolveError {
    /// `K + jD − ω²M` is singular at this frequency.
    #[error(
        "the model is singular at {freq_hz} Hz: a body or mechanism is free to move (rigid-body \
         mode) and the frequency hits it; check that every body is connected, or leave out 0 Hz"
    )]
    Singular {
        /// Frequency (Hz).
        freq_hz: f64,
    },
    /// A frequency is negative or not finite.
    #[error("frequency {freq_hz} Hz is not a finite, non-negative number")]
    BadFrequency {
        /// Offending value.
        freq_hz: f64,
    },
    /// The eigen-decomposition of the modal path did not converge.
    #[error("eigen-decomposition failed ({0}); use the direct method (--method direct)")]
    Eigen(String),
    /// A requested parameter does not exist in the model.
    #[error("parameter {0} is not a parameter of an enabled SDE of this model")]
    UnknownParam(String),
}

/// Frequency response of a model's outputs, and optionally its Jacobian.
#[derive(Debug, Clone, PartialEq)]
pub struct Response {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// Number of output characteristics.
    pub outputs: usize,
    /// Parameters of the Jacobian (empty if none was requested).
    pub params: Vec<Param>,
    /// `values[o * lines + k]`: output `o` at line `k` (SI units of its quantity).
    pub values: Vec<C64>,
    /// `jacobian[(p * outputs + o) * lines + k]`: ∂ values / ∂ parameter `p` (per SI unit of `p`).
    pub jacobian: Vec<C64>,
}

impl Response {
    /// Output `o` over all lines.
    pub fn output(&self, o: usize) -> &[C64] {
        let l = self.freqs_hz.len();
        &self.values[o * l..(o + 1) * l]
    }

    /// ∂ output `o` / ∂ parameter `p` over all lines.
    pub fn derivative(&self, p: usize, o: usize) -> &[C64] {
        let l = self.freqs_hz.len();
        let s = (p * self.outputs + o) * l;
        &self.jacobian[s..s + l]
    }
}

/// Frequency response of `model`'s outputs at `freqs_hz`, with the Jacobian with respect to
/// `params` (pass `&[]` for none).
///
/// ```
/// # use rfe::frf::{response, Method};
/// # let model = rfe::textbook::single_body(100.0, 1.0e6, 0.2);
/// let r = response(&model, &[10.0, 20.0], &[], Method::Auto).unwrap();
/// assert_eq!(r.output(0).len(), 2);
/// ```
pub fn response(
    model: &Model,
    freqs_hz: &[f64],
    params: &[ParamRef],
    method: Method,
) -> Result<Response, SolveError> {
    let params: Vec<Param> = params.iter().map(|&p| p.into()).collect();
    response_params(model, freqs_hz, &params, method)
}

/// A Jacobian column that is a body's mass or principal inertia, or a point mass:
/// `∂A/∂p = −ω² ∂M/∂p` over the body's six DOFs.
#[derive(Debug, Clone)]
struct InertiaColumn {
    /// Column of the Jacobian.
    col: usize,
    /// Body index.
    body: usize,
    /// The nonzero entries `(i, j, ∂M_ij/∂p)` of the body's 6×6 block (`i, j` in 0..6).
    dm: Vec<(usize, usize, f64)>,
}

impl InertiaColumn {
    /// `∂q_o/∂p` from the body's DOFs under the load (`q`) and under output `o`'s unit load (`w`).
    /// Under a base motion `t = T u_b` the load `ω² M t` depends on the masses too: the solve
    /// gives `z` with `A z = M t`, and `∂z/∂p = A⁻¹ ∂M (t + ω² z)`, so `q + t/ω²` stands for `q`.
    fn derivative(
        &self,
        omega: f64,
        fac: C64,
        base: Option<&[f64]>,
        q: impl Fn(usize) -> C64,
        w: impl Fn(usize) -> C64,
    ) -> C64 {
        let w2 = omega * omega;
        let mut acc = C64::new(0.0, 0.0);
        for &(i, j, dm) in &self.dm {
            let (di, dj) = (6 * self.body + i, 6 * self.body + j);
            let moved = base.map_or(0.0, |t| t[dj] / w2);
            acc += w(di) * (q(dj) + moved) * dm;
        }
        acc * w2 * fac
    }
}

/// [`response`] with the Jacobian with respect to any physical parameters: SDE parameters, body
/// masses and principal inertias ([`Param`]; a gain is not part of the model and is an
/// [`SolveError::UnknownParam`]). Column `p` of the Jacobian is per SI unit of `params[p]`.
pub fn response_params(
    model: &Model,
    freqs_hz: &[f64],
    params: &[Param],
    method: Method,
) -> Result<Response, SolveError> {
    let system = System::assemble(model);
    let mut out = Response {
        freqs_hz: Vec::new(),
        outputs: 0,
        params: Vec::new(),
        values: Vec::new(),
        jacobian: Vec::new(),
    };
    response_params_into(&system, model, freqs_hz, params, method, &mut out)?;
    Ok(out)
}

/// [`response_params`] of `model` through `system`, its assembled system (which the caller may
/// keep between solves of one model with new values: [`System::update_laws`]), written into
/// `out`, whose buffers are reused (a fit's hundred evaluations of one size then allocate
/// nothing there).
pub fn response_params_into(
    system: &System,
    model: &Model,
    freqs_hz: &[f64],
    params: &[Param],
    method: Method,
    out: &mut Response,
) -> Result<(), SolveError> {
    let mut sde_params = Vec::new();
    let mut sde_cols = Vec::new();
    let mut inertia = Vec::new();
    for (col, p) in params.iter().enumerate() {
        match p {
            Param::Sde(r) => {
                sde_params.push(*r);
                sde_cols.push(col);
            }
            _ => match model.mass_derivative(*p) {
                Some((body, dm)) if body < model.bodies.len() => inertia.push(InertiaColumn {
                    col,
                    body,
                    dm: (0..6)
                        .flat_map(|i| (0..6).map(move |j| (i, j)))
                        .filter(|&(i, j)| dm[(i, j)] != 0.0)
                        .map(|(i, j)| (i, j, dm[(i, j)]))
                        .collect(),
                }),
                _ => return Err(SolveError::UnknownParam(model.label(*p))),
            },
        }
    }
    let blocks = system.param_blocks(model, &sde_params);
    let blocks: Vec<ParamBlock> = blocks
        .into_iter()
        .zip(&sde_params)
        .map(|(b, p)| b.ok_or_else(|| SolveError::UnknownParam(model.param_label(*p))))
        .collect::<Result<_, _>>()?;
    let columns = Columns {
        blocks: &blocks,
        sde_cols: &sde_cols,
        inertia: &inertia,
    };
    for &f in freqs_hz {
        if !f.is_finite() || f < 0.0 {
            return Err(SolveError::BadFrequency { freq_hz: f });
        }
    }
    let quantities: Vec<Quantity> = model.outputs.iter().map(|c| c.quantity).collect();
    let zero = C64::new(0.0, 0.0);
    out.freqs_hz.clear();
    out.freqs_hz.extend_from_slice(freqs_hz);
    out.outputs = quantities.len();
    out.params.clear();
    out.params.extend_from_slice(params);
    out.values.clear();
    out.values.resize(quantities.len() * freqs_hz.len(), zero);
    out.jacobian.clear();
    out.jacobian
        .resize(params.len() * quantities.len() * freqs_hz.len(), zero);
    match method.resolve_for(
        system,
        freqs_hz.len(),
        Work::Outputs {
            params: params.len(),
            columns: system.columns(),
        },
    ) {
        Method::Modal => ModalSolver::new(system)?.fill(system, &columns, &quantities, out)?,
        _ => DirectSolver::new().fill(system, &columns, &quantities, out)?,
    }
    Ok(())
}

/// The Jacobian's columns by kind: SDE parameters (`blocks[i]` is column `sde_cols[i]`) and
/// inertia parameters.
struct Columns<'a> {
    blocks: &'a [ParamBlock],
    sde_cols: &'a [usize],
    inertia: &'a [InertiaColumn],
}

impl Columns<'_> {
    fn is_empty(&self) -> bool {
        self.blocks.is_empty() && self.inertia.is_empty()
    }
}

/// The full DOF vector (6 per body, body principal axes, displacement in m and rad) in response
/// to the model's excitation, one vector per frequency. Used by the simulated stand.
pub fn dof_response(model: &Model, freqs_hz: &[f64]) -> Result<Vec<Vec<C64>>, SolveError> {
    let system = System::assemble(model);
    if let Some(&f) = freqs_hz.iter().find(|f| !f.is_finite() || **f < 0.0) {
        return Err(SolveError::BadFrequency { freq_hz: f });
    }
    let n = system.n;
    let mut out = Vec::with_capacity(freqs_hz.len());
    DirectSolver::new().solve_lines(&system, freqs_hz, |k, sol| {
        let q = sol[..n].to_vec();
        if q.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::Singular {
                freq_hz: freqs_hz[k],
            });
        }
        out.push(q);
        Ok(())
    })?;
    Ok(out)
}

/// Every line's full solution under the model's load and under each output's unit load: what a
/// perturbation of `A(ω)` needs for its first-order effect on the outputs
/// (`∂q_o = −w_oᵀ ΔA q`), whatever the perturbation is — an SDE that is not in the model, an added
/// mass, a resonator. Computing it costs one FRF evaluation; each perturbation then costs
/// O(its support) per line. See [`States::first_order`].
#[derive(Debug, Clone)]
pub struct States {
    /// DOFs.
    pub n: usize,
    /// Output characteristics.
    pub outputs: usize,
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// References: the model's excitation and each of [`Model::references`].
    pub references: usize,
    /// `load[(k * references + r) * n + i]`: DOF `i` under reference `r`'s load at line `k` (m,
    /// rad per N; per m of base motion and per ω² for a base motion).
    pub load: Vec<C64>,
    /// `unit[(k * outputs + o) * n + i]`: DOF `i` under output `o`'s row as a load (a unit load
    /// on its DOF for a principal-axis output).
    pub unit: Vec<C64>,
    /// `factor[k * outputs + o]`: displacement → output quantity (1, jω or −ω²; times ω² under
    /// base motion).
    pub factor: Vec<C64>,
    /// `offset[k * outputs + o]`: added to the output (an absolute output under base motion:
    /// the base's own motion, as the output's quantity); 0 otherwise.
    pub offset: Vec<C64>,
    /// The reference each output responds to.
    pub reference_of: Vec<usize>,
}

/// One term of a perturbation `ΔA(ω) = Σ c(ω) t tᵀ`: a row `t` over a few DOFs and its
/// coefficient at one line.
pub type Row = [(usize, f64)];

impl States {
    /// First-order change of output `o` at line `k` per unit of a parameter γ entering as
    /// `∂A/∂γ = Σ_t c_t t_tᵀ t_t` (terms `(row, c)`): `−factor · Σ c (t·w_o)(t·q)`.
    pub fn first_order<'a>(
        &self,
        k: usize,
        o: usize,
        terms: impl IntoIterator<Item = (&'a Row, C64)>,
    ) -> C64 {
        let q = self.load_for(k, o);
        let w = &self.unit[(k * self.outputs + o) * self.n..(k * self.outputs + o + 1) * self.n];
        let mut acc = C64::new(0.0, 0.0);
        for (row, c) in terms {
            let (mut tq, mut tw) = (C64::new(0.0, 0.0), C64::new(0.0, 0.0));
            for &(i, v) in row {
                tq += q[i] * v;
                tw += w[i] * v;
            }
            acc += c * tq * tw;
        }
        -acc * self.factor[k * self.outputs + o]
    }

    /// The DOF vector under the model's excitation (reference 0) at line `k`.
    pub fn load_at(&self, k: usize) -> &[C64] {
        &self.load[k * self.references * self.n..(k * self.references + 1) * self.n]
    }

    /// The DOF vector under output `o`'s reference at line `k`.
    pub fn load_for(&self, k: usize, o: usize) -> &[C64] {
        let at = (k * self.references + self.reference_of[o]) * self.n;
        &self.load[at..at + self.n]
    }
}

/// The [`States`] of `model` at `freqs_hz`.
pub fn states(model: &Model, freqs_hz: &[f64], method: Method) -> Result<States, SolveError> {
    let system = System::assemble(model);
    let n = system.n;
    let outputs = system.output_rows.len();
    let lines = freqs_hz.len();
    for &f in freqs_hz {
        if !f.is_finite() || f < 0.0 {
            return Err(SolveError::BadFrequency { freq_hz: f });
        }
    }
    let refs = 1 + system.reference_loads.len();
    // Load column c of the solve ↔ reference r: c = 0 ↔ 0, c = outputs + r ↔ r ≥ 1.
    let column = |r: usize| if r == 0 { 0 } else { outputs + r };
    let mut st = States {
        n,
        outputs,
        references: refs,
        freqs_hz: freqs_hz.to_vec(),
        load: vec![C64::new(0.0, 0.0); lines * refs * n],
        unit: vec![C64::new(0.0, 0.0); lines * outputs * n],
        factor: vec![C64::new(0.0, 0.0); lines * outputs],
        offset: vec![C64::new(0.0, 0.0); lines * outputs],
        reference_of: system
            .output_rows
            .iter()
            .map(|r| if r.column == 0 { 0 } else { r.column - outputs })
            .collect(),
    };
    let quantities: Vec<Quantity> = model.outputs.iter().map(|c| c.quantity).collect();
    match method.resolve_for(
        &system,
        lines,
        Work::States {
            rhs: refs + outputs,
        },
    ) {
        Method::Modal => {
            let modal = ModalSolver::new(&system)?;
            let b: Vec<Vec<C64>> = (0..refs)
                .map(|r| {
                    (0..n)
                        .map(|m| {
                            (0..n)
                                .map(|i| modal.y[(m, i)] * system.load_entry(column(r), i))
                                .sum()
                        })
                        .collect()
                })
                .collect();
            let lambda_scale = modal.lambda_scale();
            let yo = modal.output_loads(&system);
            let mut eta = vec![C64::new(0.0, 0.0); n];
            let mut inv = vec![C64::new(0.0, 0.0); n];
            for (k, &f) in freqs_hz.iter().enumerate() {
                let w2 = (TWO_PI * f).powi(2);
                for (v, l) in inv.iter_mut().zip(&modal.lambda) {
                    let den = l - w2;
                    if den.norm() <= 1e-13 * lambda_scale {
                        return Err(SolveError::Singular { freq_hz: f });
                    }
                    *v = den.inv();
                }
                for col in 0..refs + outputs {
                    for m in 0..n {
                        eta[m] = inv[m]
                            * if col < refs {
                                b[col][m]
                            } else {
                                yo[col - refs][m]
                            };
                    }
                    let dst = if col < refs {
                        &mut st.load[(k * refs + col) * n..(k * refs + col + 1) * n]
                    } else {
                        let o = col - refs;
                        &mut st.unit[(k * outputs + o) * n..(k * outputs + o + 1) * n]
                    };
                    for (i, d) in dst.iter_mut().enumerate() {
                        *d = (0..n).map(|m| modal.x[(i, m)] * eta[m]).sum();
                    }
                }
            }
        }
        _ => {
            DirectSolver::new().solve_lines(&system, freqs_hz, |k, sol| {
                for r in 0..refs {
                    let c = column(r);
                    st.load[(k * refs + r) * n..(k * refs + r + 1) * n]
                        .copy_from_slice(&sol[c * n..(c + 1) * n]);
                }
                st.unit[k * outputs * n..(k + 1) * outputs * n]
                    .copy_from_slice(&sol[n..(1 + outputs) * n]);
                Ok(())
            })?;
        }
    }
    for (k, &f) in freqs_hz.iter().enumerate() {
        for (o, q) in quantities.iter().enumerate() {
            let omega = TWO_PI * f;
            let (offset, factor) =
                system.output_rows[o].scale(q.factor(omega), omega, C64::new(0.0, 0.0));
            st.factor[k * outputs + o] = factor;
            st.offset[k * outputs + o] = offset;
        }
    }
    if st.load.iter().chain(&st.unit).any(|v| !v.is_finite()) {
        return Err(SolveError::Singular { freq_hz: f64::NAN });
    }
    Ok(st)
}

/// Accumulates `∂q_o/∂p` for every parameter given the SDE deformations under each load column
/// (`dq[column]`, the output's own) and under each output's unit load (`dw[o]`).
#[allow(clippy::too_many_arguments)]
fn jacobian_line(
    s: &System,
    columns: &Columns,
    dq: &[Vec<[C64; 6]>],
    dw: &[Vec<[C64; 6]>],
    factor: &[C64],
    lines: usize,
    k: usize,
    jac: &mut [C64],
) {
    let outputs = factor.len();
    for (pb, &p) in columns.blocks.iter().zip(columns.sde_cols) {
        for o in 0..outputs {
            let q6 = &dq[s.output_rows[o].column][pb.block];
            let w6 = &dw[o][pb.block];
            let mut acc = C64::new(0.0, 0.0);
            for i in 0..6 {
                // Most parameters touch one or three of the six directions (kn, ψn, …).
                if pb.coeff[i] != C64::new(0.0, 0.0) {
                    acc += pb.coeff[i] * (w6[i] * q6[i]);
                }
            }
            jac[(p * outputs + o) * lines + k] = -acc * factor[o];
        }
    }
}

/// The distinct SDE blocks the parameters live in (several parameters share one SDE).
fn distinct_blocks(blocks: &[ParamBlock]) -> Vec<usize> {
    let mut used: Vec<usize> = blocks.iter().map(|b| b.block).collect();
    used.sort_unstable();
    used.dedup();
    used
}

/// The direct path: the batched `L Δ Lᵀ` ([`crate::lines`]), with a per-frequency pivoted LU
/// for the lines it cannot trust, made when the first such line comes (most solves have none,
/// and its buffers and workspace query cost more than a small model's whole solve).
struct DirectSolver {
    lu: Option<PivotedLu>,
}

/// Per-frequency pivoted LU, with buffers sized once.
struct PivotedLu {
    a: Mat<C64>,
    rhs: Mat<C64>,
    perm: Vec<usize>,
    perm_inv: Vec<usize>,
    mem: MemBuffer,
}

impl PivotedLu {
    fn new(system: &System) -> PivotedLu {
        let n = system.n;
        let cols = system.columns();
        let req = StackReq::any_of(&[
            factor::lu_in_place_scratch::<usize, C64>(n, n, Par::Seq, Default::default()),
            solve::solve_in_place_scratch::<usize, C64>(n, cols, Par::Seq),
        ]);
        PivotedLu {
            a: Mat::zeros(n, n),
            rhs: Mat::zeros(n, cols),
            perm: vec![0; n],
            perm_inv: vec![0; n],
            mem: MemBuffer::new(req),
        }
    }

    /// Factors `A(ω)` and solves for the load and every output's unit vector (columns 0 and
    /// 1..=outputs of `rhs`).
    fn factor(&mut self, s: &System, freq_hz: f64) -> Result<(), SolveError> {
        let n = s.n;
        let w2 = (TWO_PI * freq_hz).powi(2);
        for i in 0..n {
            for j in 0..n {
                self.a[(i, j)] = C64::new(s.k[i * n + j], s.d[i * n + j]);
            }
            self.a[(i, i)].re -= w2 * s.mass[i];
        }
        for &(i, j, v) in &s.mass_coupling {
            self.a[(i, j)].re -= w2 * v;
        }
        self.rhs.fill(C64::new(0.0, 0.0));
        for c in (0..s.columns()).filter(|&c| c == 0 || c > s.output_rows.len()) {
            for i in 0..n {
                self.rhs[(i, c)] = C64::new(s.load_entry(c, i), 0.0);
            }
        }
        for (o, row) in s.output_rows.iter().enumerate() {
            for &(d, v) in &row.taps {
                self.rhs[(d, o + 1)] = C64::new(v, 0.0);
            }
        }
        let (_, perm) = factor::lu_in_place(
            self.a.as_mut(),
            &mut self.perm,
            &mut self.perm_inv,
            Par::Seq,
            MemStack::new(&mut self.mem),
            Default::default(),
        );
        solve::solve_in_place(
            self.a.as_ref(),
            self.a.as_ref(),
            perm,
            self.rhs.as_mut(),
            Par::Seq,
            MemStack::new(&mut self.mem),
        );
        let singular = (0..n).any(|i| {
            let u = self.a[(i, i)];
            u == C64::new(0.0, 0.0) || !u.is_finite()
        });
        if singular {
            return Err(SolveError::Singular { freq_hz });
        }
        Ok(())
    }
}

impl DirectSolver {
    fn new() -> DirectSolver {
        DirectSolver { lu: None }
    }

    /// Solves every line for the load and each output's unit load, a batch of up to
    /// [`LANES`] lines at a time through the batched `L Δ Lᵀ` ([`crate::lines`]), and hands
    /// `each(first_line, batch)` every batch in order. A line whose factorisation the batch
    /// cannot trust is solved again here with partial pivoting and its solution put in its lane.
    fn solve_batches(
        &mut self,
        s: &System,
        freqs_hz: &[f64],
        mut each: impl FnMut(usize, &Batch) -> Result<(), SolveError>,
    ) -> Result<(), SolveError> {
        let n = s.n;
        let cols = s.columns();
        let mut batch = scratch::batch(s);
        // A line's pivoted solution, sized when the first such line comes.
        let mut sol = Vec::new();
        for (b, chunk) in freqs_hz.chunks(LANES).enumerate() {
            batch.factor_and_solve(s, chunk);
            for (l, &f) in chunk.iter().enumerate() {
                if !batch.accurate(l) {
                    let lu = self.lu.get_or_insert_with(|| PivotedLu::new(s));
                    lu.factor(s, f)?;
                    sol.resize(cols * n, C64::new(0.0, 0.0));
                    for (c, col) in sol.chunks_exact_mut(n).enumerate() {
                        for (i, v) in col.iter_mut().enumerate() {
                            *v = lu.rhs[(i, c)];
                        }
                    }
                    batch.set_solution(l, &sol);
                }
            }
            each(b * LANES, &batch)?;
        }
        scratch::keep_batch(batch);
        Ok(())
    }

    /// [`DirectSolver::solve_batches`] line by line: `each(k, solution)` with
    /// `solution[c * n + i]` = DOF `i` of right-hand side `c` at line `k`.
    fn solve_lines(
        &mut self,
        s: &System,
        freqs_hz: &[f64],
        mut each: impl FnMut(usize, &[C64]) -> Result<(), SolveError>,
    ) -> Result<(), SolveError> {
        let mut sol = vec![C64::new(0.0, 0.0); s.columns() * s.n];
        self.solve_batches(s, freqs_hz, |first, batch| {
            for (l, k) in (first..freqs_hz.len().min(first + LANES)).enumerate() {
                batch.solution(l, &mut sol);
                each(k, &sol)?;
            }
            Ok(())
        })
    }

    fn fill(
        mut self,
        s: &System,
        columns: &Columns,
        quantities: &[Quantity],
        out: &mut Response,
    ) -> Result<(), SolveError> {
        let blocks = columns.blocks;
        let lines = out.freqs_hz.len();
        let outputs = quantities.len();
        let used = distinct_blocks(blocks);
        let mut derivatives = scratch::derivatives(s, blocks.len());
        let Response {
            freqs_hz: freqs,
            values,
            jacobian,
            ..
        } = out;
        // Per output and lane: the factor of the output's quantity at that line.
        let mut factors = vec![C64::new(0.0, 0.0); outputs * LANES];
        self.solve_batches(s, freqs, |first, batch| {
            if !blocks.is_empty() {
                batch.derivatives(s, blocks, &used, &mut derivatives);
            }
            let batch_lines = first..lines.min(first + LANES);
            for (l, k) in batch_lines.clone().enumerate() {
                let f = freqs[k];
                let omega = TWO_PI * f;
                for (o, q) in quantities.iter().enumerate() {
                    let row = &s.output_rows[o];
                    let (v, fac) = row.scale(
                        q.factor(omega),
                        omega,
                        row.apply(|d| batch.x(l, row.column, d)),
                    );
                    if !v.is_finite() {
                        return Err(SolveError::Singular { freq_hz: f });
                    }
                    values[o * lines + k] = v;
                    factors[o * LANES + l] = fac;
                    for ic in columns.inertia {
                        jacobian[(ic.col * outputs + o) * lines + k] = ic.derivative(
                            omega,
                            fac,
                            s.base_motion_of_column(row.column),
                            |i| batch.x(l, row.column, i),
                            |i| batch.x(l, o + 1, i),
                        );
                    }
                }
            }
            // The SDE columns a parameter and output at a time: the batch's lines are
            // consecutive there.
            for (p, &col) in columns.sde_cols.iter().enumerate() {
                for o in 0..outputs {
                    let base = (col * outputs + o) * lines;
                    let dst = &mut jacobian[base + batch_lines.start..base + batch_lines.end];
                    for (l, j) in dst.iter_mut().enumerate() {
                        *j = -derivatives.at(p, o, l) * factors[o * LANES + l];
                    }
                }
            }
            Ok(())
        })?;
        scratch::keep_derivatives(derivatives);
        Ok(())
    }
}

/// The direct path's large buffers, kept per thread between solves: a fit solves the same
/// system size a hundred times and more, and fresh buffers each time (a third of a megabyte on
/// FWD-32J) cost the allocator's page faults and zeroing, about a tenth of an evaluation. A
/// buffer is taken out while a solve uses it (a solve inside another gets its own) and put back
/// after; one of another size is replaced.
mod scratch {
    use std::cell::RefCell;

    use crate::lines::{Batch, Derivatives};
    use crate::system::System;

    thread_local! {
        static BATCH: RefCell<Option<Batch>> = const { RefCell::new(None) };
        static DERIVATIVES: RefCell<Option<Derivatives>> = const { RefCell::new(None) };
    }

    /// A batch for `s`: the kept one when it fits, else a new one.
    pub(super) fn batch(s: &System) -> Batch {
        match BATCH.with(|b| b.borrow_mut().take()) {
            Some(mut batch) if batch.fits(s) => {
                batch.prepare(s);
                batch
            }
            _ => Batch::new(s),
        }
    }

    /// Keeps `batch` for the next solve on this thread.
    pub(super) fn keep_batch(batch: Batch) {
        BATCH.with(|b| *b.borrow_mut() = Some(batch));
    }

    /// Derivative buffers for `params` parameters of `s`: the kept ones when they fit, else new.
    pub(super) fn derivatives(s: &System, params: usize) -> Derivatives {
        match DERIVATIVES.with(|d| d.borrow_mut().take()) {
            Some(d) if d.fits(s, params) => d,
            _ => Derivatives::new(s, params),
        }
    }

    /// Keeps `d` for the next solve on this thread.
    pub(super) fn keep_derivatives(d: Derivatives) {
        DERIVATIVES.with(|k| *k.borrow_mut() = Some(d));
    }
}

/// Complex modal decomposition of the hysteretically damped system.
pub struct ModalSolver {
    /// Eigenvalues λ of `M^-½ (K + jD) M^-½` (rad²/s², complex).
    pub lambda: Vec<C64>,
    /// `X = M^-½ V` (n×n): physical mode shapes.
    pub x: Mat<C64>,
    /// `Y = V⁻¹ M^-½` (n×n).
    pub y: Mat<C64>,
}

impl ModalSolver {
    /// Decomposes the system (one O(n³) eigen-decomposition and one inverse).
    pub fn new(s: &System) -> Result<ModalSolver, SolveError> {
        let n = s.n;
        let scale = MassScaling::new(s)
            .ok_or_else(|| SolveError::Eigen("the mass matrix is not positive definite".into()))?;
        let a = Mat::<C64>::from_fn(n, n, |i, j| {
            scale.congruence(i, j, |k, l| C64::new(s.k[k * n + l], s.d[k * n + l]))
        });
        let eig = a.eigen().map_err(|e| SolveError::Eigen(format!("{e:?}")))?;
        let v = eig.U();
        let lambda: Vec<C64> = (0..n).map(|i| eig.S()[i]).collect();
        let lu = v.partial_piv_lu();
        let mut v_inv = Mat::<C64>::identity(n, n);
        faer::linalg::solvers::Solve::solve_in_place(&lu, v_inv.as_mut());
        if (0..n).any(|i| (0..n).any(|j| !v_inv[(i, j)].is_finite())) {
            return Err(SolveError::Eigen(
                "the mode shapes are linearly dependent (defective eigenproblem)".into(),
            ));
        }
        let x = Mat::<C64>::from_fn(n, n, |i, j| scale.left(i, j, |k, m| v[(k, m)]));
        let y = Mat::<C64>::from_fn(n, n, |i, j| scale.right(i, j, |m, k| v_inv[(m, k)]));
        Ok(ModalSolver { lambda, x, y })
    }

    /// The largest |λ| (rad²/s²), at least 1: a line is singular where `|λ − ω²|` is below 10⁻¹³
    /// of it.
    fn lambda_scale(&self) -> f64 {
        self.lambda
            .iter()
            .map(|l| l.norm())
            .fold(0.0, f64::max)
            .max(1.0)
    }

    /// Each output's row as a modal load, `Y t_o`: `[o][mode]`.
    fn output_loads(&self, s: &System) -> Vec<Vec<C64>> {
        s.output_rows
            .iter()
            .map(|row| (0..s.n).map(|m| row.apply(|d| self.y[(m, d)])).collect())
            .collect()
    }

    fn fill(
        &self,
        s: &System,
        columns: &Columns,
        quantities: &[Quantity],
        out: &mut Response,
    ) -> Result<(), SolveError> {
        let blocks = columns.blocks;
        let n = s.n;
        let lines = out.freqs_hz.len();
        let outputs = quantities.len();
        // Modal loads b_c = Y P_c (the load columns), output rows of X, unit-load modal vectors
        // Y t_o.
        let cols = s.columns();
        let load_cols: Vec<usize> = (0..cols).filter(|&c| c == 0 || c > outputs).collect();
        let b: Vec<Vec<C64>> = load_cols
            .iter()
            .map(|&c| {
                (0..n)
                    .map(|m| (0..n).map(|i| self.y[(m, i)] * s.load_entry(c, i)).sum())
                    .collect()
            })
            .collect();
        let yo = self.output_loads(s);
        let xo: Vec<Vec<C64>> = s
            .output_rows
            .iter()
            .map(|row| (0..n).map(|m| row.apply(|d| self.x[(d, m)])).collect())
            .collect();
        // E = [T_κ X] stacked for every distinct SDE that carries a parameter (6·B × n), so that
        // one matrix product per line gives every such SDE's deformation under the load and
        // under each output's unit load: [δq, δw_1, …] = E · [η, ζ_1, …]. Below them, the rows
        // of X of every body whose mass or inertia is a parameter give its DOFs alike.
        let used = distinct_blocks(blocks);
        let mut bodies: Vec<usize> = columns.inertia.iter().map(|c| c.body).collect();
        bodies.sort_unstable();
        bodies.dedup();
        let body_row0 = 6 * used.len();
        let rows = body_row0 + 6 * bodies.len();
        // While E has fewer rows than the model has DOFs, the deformations come from `E · rhs`
        // (rows × n per load column and line); else from the full states `X · rhs` (n × n), each
        // SDE's deformation then read from its few taps.
        let via_states = rows > n;
        let mut e = Mat::<C64>::zeros(if via_states { 0 } else { rows }, n);
        for (u, &blk) in used.iter().enumerate().filter(|_| !via_states) {
            let b = &s.sdes[blk];
            for m in 0..n {
                let d = b.deformation(|i| self.x[(i, m)]);
                for r in 0..6 {
                    e[(6 * u + r, m)] = d[r];
                }
            }
        }
        for (u, &b) in bodies.iter().enumerate().filter(|_| !via_states) {
            for r in 0..6 {
                for m in 0..n {
                    e[(body_row0 + 6 * u + r, m)] = self.x[(6 * b + r, m)];
                }
            }
        }
        let mut rhs = Mat::<C64>::zeros(n, cols);
        let mut deform = Mat::<C64>::zeros(rows, cols);
        let mut states = Mat::<C64>::zeros(if via_states { n } else { 0 }, cols);
        let mut dq = vec![vec![[C64::new(0.0, 0.0); 6]; s.sdes.len()]; cols];
        let mut dw = vec![vec![[C64::new(0.0, 0.0); 6]; s.sdes.len()]; outputs];
        let mut fac = vec![C64::new(0.0, 0.0); outputs];
        let lambda_scale = self.lambda_scale();
        for (k, &f) in out.freqs_hz.iter().enumerate() {
            let omega = TWO_PI * f;
            let w2 = omega * omega;
            for m in 0..n {
                let den = self.lambda[m] - w2;
                if den.norm() <= 1e-13 * lambda_scale {
                    return Err(SolveError::Singular { freq_hz: f });
                }
                let inv = den.inv();
                for (bc, &c) in b.iter().zip(&load_cols) {
                    rhs[(m, c)] = bc[m] * inv;
                }
                for o in 0..outputs {
                    rhs[(m, o + 1)] = yo[o][m] * inv;
                }
            }
            for (o, q) in quantities.iter().enumerate() {
                let row = &s.output_rows[o];
                let x: C64 = (0..n).map(|m| xo[o][m] * rhs[(m, row.column)]).sum();
                let (v, factor) = row.scale(q.factor(omega), omega, x);
                fac[o] = factor;
                out.values[o * lines + k] = v;
            }
            if columns.is_empty() {
                continue;
            }
            if via_states {
                faer::linalg::matmul::matmul(
                    states.as_mut(),
                    faer::Accum::Replace,
                    self.x.as_ref(),
                    rhs.as_ref(),
                    C64::new(1.0, 0.0),
                    Par::Seq,
                );
                deformations_from_states(s, &states, &used, &bodies, &mut deform);
            } else {
                faer::linalg::matmul::matmul(
                    deform.as_mut(),
                    faer::Accum::Replace,
                    e.as_ref(),
                    rhs.as_ref(),
                    C64::new(1.0, 0.0),
                    Par::Seq,
                );
            }
            for (u, &blk) in used.iter().enumerate() {
                for &c in &load_cols {
                    dq[c][blk] = std::array::from_fn(|r| deform[(6 * u + r, c)]);
                }
                for (o, dwo) in dw.iter_mut().enumerate() {
                    dwo[blk] = std::array::from_fn(|r| deform[(6 * u + r, o + 1)]);
                }
            }
            jacobian_line(s, columns, &dq, &dw, &fac, lines, k, &mut out.jacobian);
            for ic in columns.inertia {
                let u = bodies.iter().position(|&b| b == ic.body).unwrap_or(0);
                // The body's DOF 6·body + r sits at row body_row0 + 6u + r of `deform`.
                let row = |i: usize| body_row0 + 6 * u + (i - 6 * ic.body);
                for o in 0..outputs {
                    // Under the output's own reference load, and under its unit load.
                    let load = s.output_rows[o].column;
                    out.jacobian[(ic.col * outputs + o) * lines + k] = ic.derivative(
                        omega,
                        fac[o],
                        s.base_motion_of_column(load),
                        |i| deform[(row(i), load)],
                        |i| deform[(row(i), o + 1)],
                    );
                }
            }
        }
        Ok(())
    }
}

/// The rows of `deform` that `E · rhs` would give, from the full states `q` (n × columns): the
/// deformation of each SDE in `used` (6 rows each), then the 6 DOFs of each body in `bodies`.
fn deformations_from_states(
    s: &System,
    q: &Mat<C64>,
    used: &[usize],
    bodies: &[usize],
    deform: &mut Mat<C64>,
) {
    let body_row0 = 6 * used.len();
    for c in 0..q.ncols() {
        for (u, &blk) in used.iter().enumerate() {
            let d = s.sdes[blk].deformation(|i| q[(i, c)]);
            for (r, v) in d.into_iter().enumerate() {
                deform[(6 * u + r, c)] = v;
            }
        }
        for (u, &b) in bodies.iter().enumerate() {
            for r in 0..6 {
                deform[(body_row0 + 6 * u + r, c)] = q[(6 * b + r, c)];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_takes_the_path_the_measurements_found_cheaper() {
        let outputs = |params| Work::Outputs { params, columns: 4 };
        // FWD-32J (42 DOFs): the identification's 74 parameters keep the direct path cheaper
        // even at 600 lines (measured 0.67× the modal time); a plain FRF goes modal past ~70.
        assert_eq!(Method::Auto.resolve(42, 600, outputs(74)), Method::Direct);
        assert_eq!(Method::Auto.resolve(42, 20, outputs(0)), Method::Direct);
        assert_eq!(Method::Auto.resolve(42, 400, outputs(0)), Method::Modal);
        // Full solutions cost the modal path n² per line: direct at 42 DOFs (0.82× at 400 lines).
        assert_eq!(
            Method::Auto.resolve(42, 400, Work::States { rhs: 4 }),
            Method::Direct
        );
        // Large models: modal once the lines amortise the eigen-decomposition.
        assert_eq!(Method::Auto.resolve(240, 20, outputs(20)), Method::Direct);
        assert_eq!(Method::Auto.resolve(240, 100, outputs(20)), Method::Modal);
        assert_eq!(
            Method::Auto.resolve(240, 400, Work::States { rhs: 4 }),
            Method::Modal
        );
        // Many parameters on a large dense model: the full states keep the modal path cheaper.
        assert_eq!(Method::Auto.resolve(168, 300, outputs(316)), Method::Modal);
        assert_eq!(Method::Auto.resolve(252, 300, outputs(501)), Method::Modal);
        // A chain of bodies keeps few of a dense factorisation's block products: the direct
        // path stays cheaper (measured 6.2 against 44.9 ms at 168 DOFs, 316 parameters, 300
        // lines on a generated machine).
        let chain = System::assemble(&crate::textbook::chain(28));
        let share = crate::lines::fill_share(&chain);
        assert!(share < 0.1, "a chain's fill share {share}");
        assert_eq!(
            Method::Auto.resolve_for(&chain, 300, outputs(316)),
            Method::Direct
        );
        // An explicit choice stands.
        assert_eq!(Method::Modal.resolve(42, 1, outputs(74)), Method::Modal);
        assert_eq!(
            Method::Direct.resolve(600, 5000, outputs(0)),
            Method::Direct
        );
    }

    #[test]
    fn a_line_the_batch_cannot_trust_is_solved_again_with_pivoting() {
        // a_00 = k − ω²m is exactly zero at 10 Hz and the body is undamped: no unpivoted
        // factorisation exists, yet the matrix is regular (row 0 is coupled to row 1).
        let mut s = System::assemble(&crate::textbook::single_body(100.0, 1.0e6, 0.0));
        let w2 = (TWO_PI * 10.0f64).powi(2);
        s.k[0] = w2 * s.mass[0];
        s.k[1] = 1.0e5;
        s.k[s.n] = 1.0e5;
        s.d.iter_mut().for_each(|d| *d = 0.0);
        let mut solver = DirectSolver::new();
        let mut lu = PivotedLu::new(&s);
        let mut got = Vec::new();
        solver
            .solve_lines(&s, &[5.0, 10.0], |_, sol| {
                got.push(sol.to_vec());
                Ok(())
            })
            .expect("a regular matrix solves");
        for (k, f) in [5.0, 10.0].into_iter().enumerate() {
            lu.factor(&s, f).expect("pivoted LU");
            let n = s.n;
            let cols = s.columns();
            let scale = (0..cols)
                .flat_map(|c| (0..n).map(move |i| (i, c)))
                .map(|ic| lu.rhs[ic].norm())
                .fold(0.0, f64::max);
            for c in 0..cols {
                for i in 0..n {
                    let d = (got[k][c * n + i] - lu.rhs[(i, c)]).norm();
                    assert!(
                        d <= 1e-12 * scale,
                        "line {f} Hz, column {c}, DOF {i}: differs by {d:e}"
                    );
                }
            }
            assert!(got[k].iter().all(|v| v.is_finite()));
        }
    }
}
