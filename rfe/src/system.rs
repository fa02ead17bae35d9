//! Assembly of the equations of motion `(K + jD − ω²M) q = P` (paper eq. 3.1-3.12, 4.1).
//!
//! Each SDE κ maps the coordinates of its two bodies to its deformation in its own frame,
//! `δ = G_r q_r − G_p q_p`, where for body `b` with arm `a = R_bᵀ(x − c_b)` (the attachment point in
//! body axes) and `R_sb = R_sᵀ R_b` (sde_from_body):
//!
//! ```text
//! G_b = | R_sb   −R_sb [a]× |
//!       |  0       R_sb     |
//! ```
//!
//! so `K = Σ Tκᵀ Kκ Tκ` and `D = Σ Tκᵀ diag(ψ/2π) Kκ Tκ` touch only the 6×6 blocks of the two bodies
//! an SDE joins. `G_b` is the product `S_pκ Θ_pκ` of the paper's eq. 3.3.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

use crate::model::{Characteristic, Excitation, Model, ParamRef};
use crate::C64;

/// The SDE deformation map of one body: `G_b` above (sde_from_body coordinates).
pub fn sde_from_body(
    body_position: &Vector3<f64>,
    global_from_body: &Matrix3<f64>,
    point: &Vector3<f64>,
    global_from_sde: &Matrix3<f64>,
) -> Matrix6<f64> {
    let a = global_from_body.transpose() * (point - body_position);
    let r_sb = global_from_sde.transpose() * global_from_body;
    let skew = a.cross_matrix();
    let mut g = Matrix6::zeros();
    g.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_sb);
    g.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r_sb * skew));
    g.fixed_view_mut::<3, 3>(3, 3).copy_from(&r_sb);
    g
}

/// Generalized force on a body from a force `f` and moment `m` (global frame) applied at `point`:
/// `[R_bᵀ f, a × R_bᵀ f + R_bᵀ m]` with `a` the arm in body axes. Dual of [`sde_from_body`].
pub fn generalized_force(
    body_position: &Vector3<f64>,
    global_from_body: &Matrix3<f64>,
    point: &Vector3<f64>,
    force: &Vector3<f64>,
    moment: &Vector3<f64>,
) -> Vector6<f64> {
    let rt = global_from_body.transpose();
    let a = rt * (point - body_position);
    let f = rt * force;
    let m = a.cross(&f) + rt * moment;
    Vector6::new(f.x, f.y, f.z, m.x, m.y, m.z)
}

/// An output as a row over the global DOFs: `y = Σ v q[dof]` over its taps. A principal-axis
/// characteristic is one tap of 1; a point output on body `b` is `[R_bᵀ d, a × R_bᵀ d]` over the
/// body's six DOFs, with `a = R_bᵀ (p − c_b)` — the generalized force of a unit force `d` at `p`
/// ([`generalized_force`]), so the output's adjoint load is that force (reciprocity).
///
/// An output responds to one excitation, the solve's right-hand side `column`
/// ([`System::load_entry`]). Under base motion the load is `ω² M T u_b`
/// ([`System::assemble`]), so the solution is scaled by `ω²` (`base`), and an absolute output
/// adds the base's own rigid motion, `offset = row · T u_b` (parameter-free: the Jacobian is the
/// relative one's).
#[derive(Debug, Clone, PartialEq)]
pub struct OutputRow {
    /// `(global DOF, coefficient)`, at most six, zeros left out.
    pub taps: Vec<(usize, f64)>,
    /// The right-hand side whose solution the output reads.
    pub column: usize,
    /// The reference is a base motion: the solution is scaled by `ω²`.
    pub base: bool,
    /// Added to the row's reading (before the quantity's `(jω)^k`): the base's rigid motion
    /// for an absolute output under base motion, else 0.
    pub offset: f64,
}

impl OutputRow {
    /// The row of characteristic `c` of `model`.
    pub fn of(model: &Model, c: &Characteristic) -> OutputRow {
        let base = 6 * c.body;
        let taps = match (&c.at, model.bodies.get(c.body)) {
            (Some(at), Some(body)) => {
                let t = generalized_force(
                    &body.position,
                    &body.rotation,
                    &Vector3::from(at.point),
                    &Vector3::from(at.direction),
                    &Vector3::zeros(),
                );
                (0..6)
                    .filter(|&i| t[i] != 0.0)
                    .map(|i| (base + i, t[i]))
                    .collect()
            }
            _ => vec![(base + c.dof as usize, 1.0)],
        };
        OutputRow {
            taps,
            column: 0,
            base: false,
            offset: 0.0,
        }
    }

    /// The output's value and its factor at `omega` (rad/s) from the row's reading `x` of its
    /// column: `value = factor · x + quantity_factor · offset`, and `factor` also scales the
    /// reading's derivatives.
    #[inline]
    pub fn scale(&self, quantity_factor: C64, omega: f64, x: C64) -> (C64, C64) {
        let factor = if self.base {
            quantity_factor * (omega * omega)
        } else {
            quantity_factor
        };
        (factor * x + quantity_factor * self.offset, factor)
    }

    /// `Σ v x(dof)` over the taps.
    #[inline]
    pub fn apply(&self, x: impl Fn(usize) -> C64) -> C64 {
        self.taps
            .iter()
            .fold(C64::new(0.0, 0.0), |acc, &(i, v)| acc + x(i) * v)
    }
}

/// Adds the generalized forces of `forces` to `load`.
fn add_forces(model: &Model, forces: &[crate::model::PointForce], load: &mut [f64]) {
    for f in forces {
        let body = &model.bodies[f.body];
        let p = generalized_force(
            &body.position,
            &body.rotation,
            &f.point,
            &f.force,
            &f.moment,
        );
        for i in 0..6 {
            load[6 * f.body + i] += p[i];
        }
    }
}

/// Each body's 6×6 block of M in its coordinates: `diag(m, m, m, J1, J2, J3)` plus the blocks of
/// the point masses it carries.
pub fn mass_blocks(model: &Model) -> Vec<Matrix6<f64>> {
    let mut blocks: Vec<Matrix6<f64>> = model
        .bodies
        .iter()
        .map(|b| Matrix6::from_diagonal(&Vector6::from(b.inertia_diagonal())))
        .collect();
    for pm in &model.point_masses {
        if let (Some(block), Some(body)) = (blocks.get_mut(pm.body), model.bodies.get(pm.body)) {
            *block += pm.block(body);
        }
    }
    blocks
}

/// The off-diagonal entries of the blocks as global `(i, j, value)`, zeros left out.
fn off_diagonal(blocks: &[Matrix6<f64>]) -> Vec<(usize, usize, f64)> {
    let mut out = Vec::new();
    for (b, m) in blocks.iter().enumerate() {
        for i in 0..6 {
            for j in (0..6).filter(|&j| j != i && m[(i, j)] != 0.0) {
                out.push((6 * b + i, 6 * b + j, m[(i, j)]));
            }
        }
    }
    out
}

/// `S` with `Sᵀ M S = I`, block-diagonal like M: `M^-½` when M is diagonal, else per body
/// `L⁻ᵀ` of the Cholesky factor `M_b = L Lᵀ` (point masses couple a body's DOFs). The modal
/// paths solve the standard eigenproblem of `Sᵀ (K + jD) S = V Λ V⁻¹`; then
/// `A(ω)⁻¹ = S V (Λ − ω²)⁻¹ V⁻¹ Sᵀ`.
#[derive(Debug, Clone)]
pub enum MassScaling {
    /// `S = diag(1/√m_i)`.
    Diagonal(Vec<f64>),
    /// S by rows and by columns: `rows[i]` holds `(column, S_ij)`, `cols[j]` holds
    /// `(row, S_ij)`, all within one body's block.
    Blocks {
        /// Nonzero entries of each row.
        rows: Vec<Vec<(usize, f64)>>,
        /// Nonzero entries of each column.
        cols: Vec<Vec<(usize, f64)>>,
    },
}

impl MassScaling {
    /// The scaling of `s`'s M; `None` when a body's block is not positive definite.
    pub fn new(s: &System) -> Option<MassScaling> {
        if s.mass_coupling.is_empty() {
            return s
                .mass
                .iter()
                .all(|m| *m > 0.0)
                .then(|| MassScaling::Diagonal(s.mass.iter().map(|m| 1.0 / m.sqrt()).collect()));
        }
        let mut rows = vec![Vec::new(); s.n];
        let mut cols = vec![Vec::new(); s.n];
        for b in 0..s.n / 6 {
            let mut m = Matrix6::from_diagonal(&Vector6::from_fn(|i, _| s.mass[6 * b + i]));
            for &(i, j, v) in s.mass_coupling.iter().filter(|c| c.0 / 6 == b) {
                m[(i - 6 * b, j - 6 * b)] = v;
            }
            let l_inv = m.cholesky()?.l().try_inverse()?;
            let st = l_inv.transpose();
            for i in 0..6 {
                for j in (0..6).filter(|&j| st[(i, j)] != 0.0) {
                    rows[6 * b + i].push((6 * b + j, st[(i, j)]));
                    cols[6 * b + j].push((6 * b + i, st[(i, j)]));
                }
            }
        }
        Some(MassScaling::Blocks { rows, cols })
    }

    /// Entry `(i, j)` of `Sᵀ A S` for the n×n matrix `a`.
    #[inline]
    pub fn congruence<T>(&self, i: usize, j: usize, a: impl Fn(usize, usize) -> T) -> T
    where
        T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        match self {
            MassScaling::Diagonal(d) => a(i, j) * (d[i] * d[j]),
            MassScaling::Blocks { cols, .. } => {
                // (Sᵀ A S)_ij = Σ_k Σ_l S_ki A_kl S_lj, over the blocks of i and j.
                let mut acc = T::default();
                for &(k, ski) in &cols[i] {
                    for &(l, slj) in &cols[j] {
                        acc = acc + a(k, l) * (ski * slj);
                    }
                }
                acc
            }
        }
    }

    /// Entry `(i, m)` of `S V` for the n×n matrix `v` (physical shapes from scaled ones).
    #[inline]
    pub fn left<T>(&self, i: usize, m: usize, v: impl Fn(usize, usize) -> T) -> T
    where
        T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        match self {
            MassScaling::Diagonal(d) => v(i, m) * d[i],
            MassScaling::Blocks { rows, .. } => rows[i]
                .iter()
                .fold(T::default(), |acc, &(k, x)| acc + v(k, m) * x),
        }
    }

    /// Entry `(m, j)` of `W Sᵀ` for the n×n matrix `w`.
    #[inline]
    pub fn right<T>(&self, m: usize, j: usize, w: impl Fn(usize, usize) -> T) -> T
    where
        T: Copy + Default + std::ops::Add<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        match self {
            MassScaling::Diagonal(d) => w(m, j) * d[j],
            MassScaling::Blocks { rows, .. } => rows[j]
                .iter()
                .fold(T::default(), |acc, &(k, x)| acc + w(m, k) * x),
        }
    }
}

/// One enabled SDE as the solver sees it.
#[derive(Debug, Clone)]
pub struct SdeBlock {
    /// Index into [`Model::sdes`].
    pub sde: usize,
    /// `[p, r]` body indices (`None` = ground).
    pub bodies: [Option<usize>; 2],
    /// `G_p`, `G_r` (sde_from_body of each side; unused for ground).
    pub g: [Matrix6<f64>; 2],
    /// The six stiffnesses.
    pub k: [f64; 6],
    /// The six dissipation coefficients.
    pub psi: [f64; 6],
    /// The nonzero entries of `[−G_p, G_r]` as (deformation row, global DOF, value): what
    /// [`SdeBlock::deformation`] sums, sorted by row. SDE axes often align with body axes, so
    /// much of G is zero.
    pub taps: Vec<(usize, usize, f64)>,
    /// Row `r`'s taps are `taps[tap_rows[r]..tap_rows[r + 1]]`.
    pub tap_rows: [usize; 7],
}

impl SdeBlock {
    /// Deformation `δ = G_r q_r − G_p q_p` of this SDE for a full coordinate vector `q`.
    pub fn deformation(&self, q: impl Fn(usize) -> C64) -> [C64; 6] {
        let mut d = [C64::new(0.0, 0.0); 6];
        for &(row, dof, v) in &self.taps {
            d[row] += q(dof) * v;
        }
        d
    }

    /// Adds `Tᵀ diag(k) T` to `k` and `Tᵀ diag(ψ k / 2π) T` to `d` (n×n, row-major): per pair of
    /// the SDE's bodies, `s_a s_b G_aᵀ diag(k) G_b`, summed over the deformation rows from
    /// the nonzero entries of G only (the taps; SDE axes mostly align with body axes), each
    /// block's sum formed before it is added.
    fn add_stiffness(&self, n: usize, k: &mut [f64], d: &mut [f64]) {
        let dd: [f64; 6] =
            std::array::from_fn(|i| self.psi[i] / (2.0 * std::f64::consts::PI) * self.k[i]);
        // Local sums over the two sides' 12 DOFs: side · 6 + DOF of the body.
        let (mut kl, mut dl) = ([[0.0f64; 12]; 12], [[0.0f64; 12]; 12]);
        let local = |dof: usize| -> usize {
            let side = usize::from(self.bodies[0] != Some(dof / 6));
            side * 6 + dof % 6
        };
        for (row, (k_row, d_row)) in self.k.iter().zip(dd).enumerate() {
            // A direction with neither stiffness nor damping adds only zeros.
            if *k_row == 0.0 && d_row == 0.0 {
                continue;
            }
            let taps = &self.taps[self.tap_rows[row]..self.tap_rows[row + 1]];
            // A row has at most 6 taps per side; their local DOFs found once.
            debug_assert!(taps.len() <= 12);
            let mut at = [(0usize, 0.0f64); 12];
            for (slot, &(_, dof, v)) in at.iter_mut().zip(taps) {
                *slot = (local(dof), v);
            }
            let at = &at[..taps.len().min(12)];
            for &(a, va) in at {
                let (ka, dka) = (va * k_row, va * d_row);
                let (kr, dr) = (&mut kl[a], &mut dl[a]);
                for &(b, vb) in at {
                    kr[b] += ka * vb;
                    dr[b] += dka * vb;
                }
            }
        }
        for (sa, ba) in self.bodies.iter().enumerate() {
            let Some(ba) = *ba else { continue };
            for (sb, bb) in self.bodies.iter().enumerate() {
                let Some(bb) = *bb else { continue };
                for i in 0..6 {
                    let at = (6 * ba + i) * n + 6 * bb;
                    let (kg, dg) = (&mut k[at..at + 6], &mut d[at..at + 6]);
                    let (ks, ds) = (
                        &kl[6 * sa + i][6 * sb..6 * sb + 6],
                        &dl[6 * sa + i][6 * sb..6 * sb + 6],
                    );
                    for j in 0..6 {
                        kg[j] += ks[j];
                        dg[j] += ds[j];
                    }
                }
            }
        }
    }

    fn taps(bodies: &[Option<usize>; 2], g: &[Matrix6<f64>; 2]) -> Vec<(usize, usize, f64)> {
        let mut taps = Vec::new();
        for row in 0..6 {
            for (side, sign) in [(0usize, -1.0), (1, 1.0)] {
                if let Some(b) = bodies[side] {
                    for j in 0..6 {
                        if g[side][(row, j)] != 0.0 {
                            taps.push((row, 6 * b + j, sign * g[side][(row, j)]));
                        }
                    }
                }
            }
        }
        taps
    }
}

/// How one parameter enters the dynamic stiffness: `∂(K + jD)/∂p = Tᵀ diag(c) T` with
/// `c_i = ∂k_i(1 + jψ_i/2π) + j k_i ∂ψ_i/2π`.
#[derive(Debug, Clone)]
pub struct ParamBlock {
    /// Index into [`System::sdes`] (not the model's SDE index).
    pub block: usize,
    /// `c_i` above.
    pub coeff: [C64; 6],
}

/// The assembled system of a model, in SI units.
#[derive(Debug, Clone)]
pub struct System {
    /// Number of DOFs (6 per body).
    pub n: usize,
    /// Diagonal of M: `[m, m, m, J1, J2, J3]` per body, plus what point masses add there.
    pub mass: Vec<f64>,
    /// The off-diagonal entries of M, `(i, j, value)` with both `(i, j)` and `(j, i)`, all within
    /// one body's 6×6 block: what point masses off a body's centre of mass add
    /// ([`crate::model::PointMass`]). Empty without point masses, when M is diagonal.
    pub mass_coupling: Vec<(usize, usize, f64)>,
    /// Stiffness matrix K (n×n, row-major), symmetric positive semi-definite.
    pub k: Vec<f64>,
    /// Hysteretic damping matrix D (n×n, row-major), symmetric.
    pub d: Vec<f64>,
    /// Generalized force vector P (n) of the model's excitation (reference 0).
    pub load: Vec<f64>,
    /// The load of each further reference ([`Model::references`]), solved as right-hand side
    /// `1 + outputs + i` ([`System::load_entry`]); `M T u_b` for a base motion.
    pub reference_loads: Vec<Vec<f64>>,
    /// Per reference (0 = the model's excitation): the base's rigid motion `T u_b` per DOF when
    /// that reference is a base motion (its load `M T u_b` then depends on the masses too).
    pub base_motion: Vec<Option<Vec<f64>>>,
    /// Enabled SDEs.
    pub sdes: Vec<SdeBlock>,
    /// Each output characteristic as a row over the DOFs.
    pub output_rows: Vec<OutputRow>,
}

impl System {
    /// Assembles M, K, D and P from a model. The model must be valid (see the loader).
    pub fn assemble(model: &Model) -> System {
        let n = model.dof_count();
        let blocks = mass_blocks(model);
        let mass: Vec<f64> = blocks
            .iter()
            .flat_map(|m| (0..6).map(move |i| m[(i, i)]))
            .collect();
        let mass_coupling = off_diagonal(&blocks);
        let mut k = vec![0.0; n * n];
        let mut d = vec![0.0; n * n];
        let mut sdes = Vec::new();
        for (idx, sde) in model.sdes.iter().enumerate().filter(|(_, s)| s.enabled) {
            let g = [0, 1].map(|side| match sde.bodies[side] {
                Some(b) => {
                    let body = &model.bodies[b];
                    sde_from_body(&body.position, &body.rotation, &sde.point, &sde.rotation)
                }
                None => Matrix6::zeros(),
            });
            let taps = SdeBlock::taps(&sde.bodies, &g);
            let block = SdeBlock {
                sde: idx,
                bodies: sde.bodies,
                tap_rows: {
                    let mut rows = [0; 7];
                    for &(r, _, _) in &taps {
                        rows[r + 1] += 1;
                    }
                    for r in 0..6 {
                        rows[r + 1] += rows[r];
                    }
                    rows
                },
                taps,
                g,
                k: sde.law.stiffness(),
                psi: sde.law.dissipation(),
            };
            block.add_stiffness(n, &mut k, &mut d);
            sdes.push(block);
        }
        let mut load = vec![0.0; n];
        add_forces(model, &model.forces, &mut load);
        let outputs = model.outputs.len();
        let mut reference_loads = Vec::new();
        // Per reference: the base's rigid motion `T u_b` (body axes, translations) if it moves.
        let mut base_motion: Vec<Option<Vec<f64>>> = vec![None];
        for r in &model.references {
            let mut p = vec![0.0; n];
            match &r.excitation {
                Excitation::Forces(forces) => {
                    add_forces(model, forces, &mut p);
                    base_motion.push(None);
                }
                Excitation::BaseMotion { direction } => {
                    let mut t = vec![0.0; n];
                    for (b, body) in model.bodies.iter().enumerate() {
                        let u = body.rotation.transpose() * Vector3::from(*direction);
                        let tb = Vector6::new(u.x, u.y, u.z, 0.0, 0.0, 0.0);
                        let pb = blocks[b] * tb;
                        for i in 0..6 {
                            t[6 * b + i] = tb[i];
                            p[6 * b + i] = pb[i];
                        }
                    }
                    base_motion.push(Some(t));
                }
            }
            reference_loads.push(p);
        }
        let output_rows = model
            .outputs
            .iter()
            .map(|c| {
                let mut row = OutputRow::of(model, c);
                let r = c.reference as usize;
                if r > 0 && r <= model.references.len() {
                    row.column = outputs + r;
                    if let Some(Some(t)) = base_motion.get(r) {
                        row.base = true;
                        if !c.relative {
                            row.offset = row.taps.iter().map(|&(i, v)| v * t[i]).sum();
                        }
                    }
                }
                row
            })
            .collect();
        System {
            n,
            mass,
            mass_coupling,
            k,
            d,
            load,
            reference_loads,
            base_motion,
            sdes,
            output_rows,
        }
    }

    /// Re-reads every SDE's stiffnesses and dissipations from `model` and sums K and D again,
    /// in the order and from the same taps as [`System::assemble`] (so bit for bit its result).
    /// For `model` the one this system was assembled from with new SDE law values (what a fit's
    /// stiffness and damping variables change): the geometry, the SDEs' bodies and which are
    /// enabled, the masses, loads and outputs are kept as they were.
    pub fn update_laws(&mut self, model: &Model) {
        let n = self.n;
        self.k.fill(0.0);
        self.d.fill(0.0);
        for block in &mut self.sdes {
            let law = &model.sdes[block.sde].law;
            block.k = law.stiffness();
            block.psi = law.dissipation();
            block.add_stiffness(n, &mut self.k, &mut self.d);
        }
    }

    /// `aᵀ M b` (M with its couplings).
    pub fn mass_inner(&self, a: &[f64], b: &[f64]) -> f64 {
        let diag: f64 = a
            .iter()
            .zip(b)
            .zip(&self.mass)
            .map(|((x, y), m)| m * x * y)
            .sum();
        diag + self
            .mass_coupling
            .iter()
            .map(|&(i, j, v)| a[i] * v * b[j])
            .sum::<f64>()
    }

    /// `M x` (M with its couplings).
    pub fn mass_times(&self, x: &[f64]) -> Vec<f64> {
        let mut y: Vec<f64> = self.mass.iter().zip(x).map(|(m, v)| m * v).collect();
        for &(i, j, v) in &self.mass_coupling {
            y[i] += v * x[j];
        }
        y
    }

    /// The base's rigid motion `T u_b` of load column `c`, when its reference is a base motion.
    pub fn base_motion_of_column(&self, c: usize) -> Option<&[f64]> {
        let outputs = self.output_rows.len();
        let r = if c == 0 { 0 } else { c.checked_sub(outputs)? };
        self.base_motion.get(r)?.as_deref()
    }

    /// Right-hand sides of a solve: the load, one per output (its row as a load), one per further
    /// reference.
    pub fn columns(&self) -> usize {
        1 + self.output_rows.len() + self.reference_loads.len()
    }

    /// Column `c`'s load entry `i` (`c` a load column: 0 or past the outputs), else 0.
    #[inline]
    pub fn load_entry(&self, c: usize, i: usize) -> f64 {
        let outputs = self.output_rows.len();
        if c == 0 {
            self.load[i]
        } else if c > outputs {
            self.reference_loads[c - outputs - 1][i]
        } else {
            0.0
        }
    }

    /// The blocks through which each parameter enters; `None` for a parameter of a disabled SDE
    /// or one its law does not have.
    pub fn param_blocks(&self, model: &Model, params: &[ParamRef]) -> Vec<Option<ParamBlock>> {
        params
            .iter()
            .map(|p| {
                let block = self.sdes.iter().position(|b| b.sde == p.sde)?;
                let (dk, dpsi) = model.sdes[p.sde].law.derivative(p.name)?;
                let b = &self.sdes[block];
                let two_pi = 2.0 * std::f64::consts::PI;
                let coeff = std::array::from_fn(|i| {
                    C64::new(dk[i], dk[i] * b.psi[i] / two_pi + b.k[i] * dpsi[i] / two_pi)
                });
                Some(ParamBlock { block, coeff })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `K` and `D` as the sum over the SDEs of `s_a s_b G_aᵀ diag(k) G_b` for every pair of
    /// their bodies, by whole 6×6 matrix products (the paper's eq. 3.6 as written).
    fn by_matrix_products(model: &Model) -> (Vec<f64>, Vec<f64>) {
        let s = System::assemble(model);
        let n = s.n;
        let (mut k, mut d) = (vec![0.0; n * n], vec![0.0; n * n]);
        for b in &s.sdes {
            let kd = Vector6::from(b.k);
            let dd = Vector6::from_fn(|i, _| b.psi[i] / (2.0 * std::f64::consts::PI) * b.k[i]);
            for (sa, sign_a) in [(0usize, -1.0), (1, 1.0)] {
                let Some(ba) = b.bodies[sa] else { continue };
                for (sb, sign_b) in [(0usize, -1.0), (1, 1.0)] {
                    let Some(bb) = b.bodies[sb] else { continue };
                    let sign = sign_a * sign_b;
                    let kab = b.g[sa].transpose() * Matrix6::from_diagonal(&kd) * b.g[sb] * sign;
                    let dab = b.g[sa].transpose() * Matrix6::from_diagonal(&dd) * b.g[sb] * sign;
                    for i in 0..6 {
                        for j in 0..6 {
                            k[(6 * ba + i) * n + 6 * bb + j] += kab[(i, j)];
                            d[(6 * ba + i) * n + 6 * bb + j] += dab[(i, j)];
                        }
                    }
                }
            }
        }
        (k, d)
    }

    /// A system kept between a fit's evaluations and updated with new law values is the one
    /// assembled afresh, bit for bit.
    #[test]
    fn updated_laws_equal_a_fresh_assembly() {
        let mut model = crate::modelfile::fwd32j();
        let mut s = System::assemble(&model);
        let mut moved = 0;
        for sde in 0..model.sdes.len() {
            for (i, name) in model.sdes[sde].law.params().into_iter().enumerate() {
                let p = ParamRef { sde, name };
                let v = model.param(p).expect("a law parameter has a value");
                let factor = 1.0 + 0.1 * ((sde + i) % 7) as f64 - 0.3;
                assert!(model.set_param(p, v * factor));
                moved += 1;
            }
        }
        assert!(moved > 20);
        s.update_laws(&model);
        let fresh = System::assemble(&model);
        assert_eq!(s.k, fresh.k);
        assert_eq!(s.d, fresh.d);
        for (a, b) in s.sdes.iter().zip(&fresh.sdes) {
            assert_eq!((a.k, a.psi), (b.k, b.psi));
        }
        assert_ne!(s.k, System::assemble(&crate::modelfile::fwd32j()).k);
    }

    #[test]
    fn stiffness_from_the_taps_equals_the_matrix_products() {
        let model = crate::modelfile::fwd32j();
        let s = System::assemble(&model);
        let (k, d) = by_matrix_products(&model);
        let scale = k.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f64, f64::max)
        };
        assert!(worst(&s.k, &k) <= 1e-14 * scale);
        assert!(worst(&s.d, &d) <= 1e-14 * scale);
    }
}
