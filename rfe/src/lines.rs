//! Solves `A(ω) q = b` at [`LANES`] frequency lines at once: the direct path's kernel.
//!
//! `A(ω) = K + jD − ω²M` is complex symmetric (K, D, M are real symmetric), so it factors as
//! `A = L Δ Lᵀ` with `L` unit lower triangular and `Δ` diagonal: half the work of an LU, and no
//! pivoting, so every line does the same operations in the same order. That lets one SIMD lane
//! carry one line: entry `(i, j)` of every line of a batch sits side by side
//! (`re[i * n + j][lane]`), the loops run over the lanes innermost, and the compiler vectorises
//! them (dispatched at run time by `pulp` to the widest instruction set the machine has).
//!
//! **Why no pivoting is safe here, and when it is not.** Where the damping matrix `D` is positive
//! definite every leading principal submatrix of `A` is nonsingular (its imaginary part is), so the
//! factorisation exists; but nothing bounds its element growth in general. So each line's growth
//! is measured: the backward error of `L Δ Lᵀ` is bounded by `n u ‖ |L| |Δ| |Lᵀ| ‖` (Higham,
//! *Accuracy and Stability of Numerical Algorithms*, §10.4), whose largest entry is at most
//! `max_i Σ_k |l_ik|² |δ_k|` (Cauchy–Schwarz). A line whose bound exceeds [`GROWTH_LIMIT`] times
//! `max |a_ij|`, or with a zero or non-finite pivot, is marked [`Batch::accurate`]` = false`, and
//! the caller solves it again with partial pivoting.
//!
//! **Sparsity.** `A` is zero in every 6×6 block of two bodies no SDE joins, and `L` keeps those
//! zeros except where elimination fills them in. [`Batch::new`] finds the blocks of `L` that can
//! be nonzero (a symbolic elimination over the bodies) and the factorisation and the solves
//! visit only those: on FWD-32J (seven bodies joined in a ring) a third of a dense
//! factorisation's work. Every product left out is an exact zero, and the ones kept are summed
//! into the same partial sums in the same order as a dense sweep would (`dot_sub`), so the
//! results are the dense ones bit for bit.
//!
//! Invariants: buffers are sized once per system size ([`Batch::new`]); `Batch::factor` and
//! `Batch::solve` allocate nothing.

use crate::system::{ParamBlock, System};
use crate::C64;

/// Lines per batch: 8 `f64` lanes fill two AVX2 registers or one AVX-512 register.
pub const LANES: usize = 8;

/// Largest accepted growth `max_i Σ_k |l_ik|² |δ_k| / max |a_ij|`. A partial-pivoting LU
/// typically grows by 1–10; 1e3 keeps the backward error within about 1e-12 relative.
pub const GROWTH_LIMIT: f64 = 1.0e3;

type Lane = [f64; LANES];

const ZERO: Lane = [0.0; LANES];

/// Per-lane derivative sums of one batch ([`Batch::derivatives`]), with their scratch.
pub struct Derivatives {
    outputs: usize,
    /// `(p * outputs + o)`: the sum for parameter `p`, output `o`.
    re: Vec<Lane>,
    im: Vec<Lane>,
    /// Deformation of one SDE under each right-hand side: `[c][row]`.
    def_re: Vec<[Lane; 6]>,
    def_im: Vec<[Lane; 6]>,
    /// `(T w_o)_i (T q)_i` per SDE block and output: `[block * outputs + o][i]`.
    prod_re: Vec<[Lane; 6]>,
    prod_im: Vec<[Lane; 6]>,
}

impl Derivatives {
    /// Buffers for `params` parameters of `system`.
    pub fn new(system: &System, params: usize) -> Derivatives {
        let outputs = system.output_rows.len();
        let blocks = system.sdes.len();
        Derivatives {
            outputs,
            re: vec![ZERO; params * outputs],
            im: vec![ZERO; params * outputs],
            def_re: vec![[ZERO; 6]; system.columns()],
            def_im: vec![[ZERO; 6]; system.columns()],
            prod_re: vec![[ZERO; 6]; blocks * outputs],
            prod_im: vec![[ZERO; 6]; blocks * outputs],
        }
    }

    /// True when these buffers are sized for `params` parameters of `system` (and can be used
    /// again for it: every entry a batch reads is written first).
    pub fn fits(&self, system: &System, params: usize) -> bool {
        let outputs = system.output_rows.len();
        self.outputs == outputs
            && self.re.len() == params * outputs
            && self.def_re.len() == system.columns()
            && self.prod_re.len() == system.sdes.len() * outputs
    }

    /// The sum for parameter `p`, output `o` in lane `l`.
    #[inline]
    pub fn at(&self, p: usize, o: usize, l: usize) -> C64 {
        let at = p * self.outputs + o;
        C64::new(self.re[at][l], self.im[at][l])
    }
}

struct DerivativeWork<'a> {
    batch: &'a Batch,
    s: &'a System,
    blocks: &'a [ParamBlock],
    used: &'a [usize],
    out: &'a mut Derivatives,
}

impl pulp::WithSimd for DerivativeWork<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let (b, d) = (self.batch, self.out);
        let outputs = d.outputs;
        for &blk in self.used {
            let sde = &self.s.sdes[blk];
            // Two right-hand sides at a time: their sums are independent, so the fused
            // multiply-adds of one tap need not wait for the previous tap's (each sum still
            // takes its taps in order).
            let mut c = 0;
            while c + 1 < b.cols {
                deformations::<2>(b, sde, c, &mut d.def_re, &mut d.def_im);
                c += 2;
            }
            if c < b.cols {
                deformations::<1>(b, sde, c, &mut d.def_re, &mut d.def_im);
            }
            for o in 0..outputs {
                let col = self.s.output_rows[o].column;
                let (qr, qi) = (&d.def_re[col], &d.def_im[col]);
                let (wr, wi) = (&d.def_re[o + 1], &d.def_im[o + 1]);
                // Formed in locals and stored whole (see `Batch::factor`).
                let (mut pr, mut pi) = ([ZERO; 6], [ZERO; 6]);
                for i in 0..6 {
                    for l in 0..LANES {
                        pr[i][l] = wr[i][l] * qr[i][l] - wi[i][l] * qi[i][l];
                        pi[i][l] = wr[i][l] * qi[i][l] + wi[i][l] * qr[i][l];
                    }
                }
                d.prod_re[blk * outputs + o] = pr;
                d.prod_im[blk * outputs + o] = pi;
            }
        }
        for (p, pb) in self.blocks.iter().enumerate() {
            for o in 0..outputs {
                let (pr, pi) = (
                    &d.prod_re[pb.block * outputs + o],
                    &d.prod_im[pb.block * outputs + o],
                );
                let (mut ar, mut ai) = (ZERO, ZERO);
                for (i, c) in pb.coeff.iter().enumerate() {
                    // Most parameters touch one or three of the six directions (kn, ψn, …).
                    if *c == C64::new(0.0, 0.0) {
                        continue;
                    }
                    for l in 0..LANES {
                        ar[l] += c.re * pr[i][l] - c.im * pi[i][l];
                        ai[l] += c.re * pi[i][l] + c.im * pr[i][l];
                    }
                }
                d.re[p * outputs + o] = ar;
                d.im[p * outputs + o] = ai;
            }
        }
    }
}

/// The deformation `T x` of SDE `sde` under the solutions of right-hand sides `c..c + C` in
/// every lane, into `def_re[c + m]`, `def_im[c + m]`: row by row, each row's taps in order.
#[inline(always)]
fn deformations<const C: usize>(
    b: &Batch,
    sde: &crate::system::SdeBlock,
    c: usize,
    def_re: &mut [[Lane; 6]],
    def_im: &mut [[Lane; 6]],
) {
    let n = b.n;
    for row in 0..6 {
        // Local sums: the compiler then knows they alias nothing and vectorises the taps.
        let mut sum = [(ZERO, ZERO); C];
        for &(_, dof, v) in &sde.taps[sde.tap_rows[row]..sde.tap_rows[row + 1]] {
            for (m, (sr, si)) in sum.iter_mut().enumerate() {
                let at = (c + m) * n + dof;
                let (r, i) = (&b.x_re[at], &b.x_im[at]);
                for l in 0..LANES {
                    sr[l] = v.mul_add(r[l], sr[l]);
                    si[l] = v.mul_add(i[l], si[l]);
                }
            }
        }
        for (m, (sr, si)) in sum.into_iter().enumerate() {
            def_re[c + m][row] = sr;
            def_im[c + m][row] = si;
        }
    }
}

/// One batch's work, run by `pulp` inside a function compiled for the machine's SIMD level (the
/// `inline(always)` chain below is what lets those loops be vectorised with it).
struct Work<'a> {
    batch: &'a mut Batch,
    s: &'a System,
    w2: Lane,
}

impl pulp::WithSimd for Work<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        let b = self.batch;
        let amax = b.fill(self.s, &self.w2);
        let growth = b.factor();
        for l in 0..LANES {
            let ok = growth[l].is_finite() && growth[l] <= GROWTH_LIMIT * amax[l];
            b.accurate[l] = ok && b.inv_re.iter().chain(&b.inv_im).all(|v| v[l].is_finite());
        }
        b.solve(self.s);
    }
}

/// The blocks of `L` (6×6, one per pair of bodies) that can be nonzero, as DOF segments.
#[derive(Debug, Clone, PartialEq)]
struct Pattern {
    /// Per block row `I`: the DOF segments `[6K, 6K + 6)` of the blocks `K < I` where `L` can
    /// be nonzero, ascending.
    row: Vec<Vec<(usize, usize)>>,
    /// Per block pair `(I, J)`, `J ≤ I`, at `I * blocks + J`: the segments of the blocks `K < J`
    /// where both rows can be nonzero; `None` where `L(I, J)` is zero.
    common: Vec<Option<Vec<(usize, usize)>>>,
    /// Per block column `J`: the DOF segments `[6I, 6I + 6)` of the blocks `I > J` where `L` can
    /// be nonzero, ascending.
    column: Vec<Vec<(usize, usize)>>,
    /// The blocks of `A` it was built from ([`Pattern::blocks_of`]): a system with the same
    /// ones has the same pattern.
    of_a: Vec<bool>,
}

impl Pattern {
    /// The pattern of `s`'s `L Δ Lᵀ`: `A`'s nonzero blocks (K, D and M's couplings), then the
    /// fill of eliminating the blocks in order (eliminating block `K` joins every pair of
    /// blocks after it that `K` is joined to). A system whose size is not a whole number of
    /// blocks is treated as one dense block.
    fn of(s: &System) -> Pattern {
        Pattern::from_blocks(s.n, Pattern::blocks_of(s))
    }

    /// The nonzero blocks of `A` (K, D and M's couplings, and the diagonal), `I * blocks + J`.
    fn blocks_of(s: &System) -> Vec<bool> {
        let n = s.n;
        let (size, blocks) = Pattern::tiling(n);
        let mut nz = vec![false; blocks * blocks];
        // Whether block (bi, bj) of K or D holds a nonzero, looking no further than the first.
        let any = |bi: usize, bj: usize| {
            (bi * size..(bi + 1) * size).any(|i| {
                let row = i * n + bj * size..i * n + (bj + 1) * size;
                s.k[row.clone()].iter().chain(&s.d[row]).any(|v| *v != 0.0)
            })
        };
        for bi in 0..blocks {
            for bj in 0..bi {
                if any(bi, bj) || any(bj, bi) {
                    nz[bi * blocks + bj] = true;
                    nz[bj * blocks + bi] = true;
                }
            }
        }
        for &(i, j, _) in &s.mass_coupling {
            nz[(i / size) * blocks + j / size] = true;
        }
        for b in 0..blocks {
            nz[b * blocks + b] = true;
        }
        nz
    }

    /// `(block size, blocks)` of an `n`-DOF system: 6-DOF blocks, or one dense block when `n`
    /// is not a whole number of them.
    fn tiling(n: usize) -> (usize, usize) {
        if n.is_multiple_of(6) {
            (6, n / 6)
        } else {
            (n, 1)
        }
    }

    /// The pattern of `L` from the nonzero blocks `of_a` of `A`: the fill of eliminating the
    /// blocks in order.
    fn from_blocks(n: usize, of_a: Vec<bool>) -> Pattern {
        let (size, blocks) = Pattern::tiling(n);
        let mut nz = of_a.clone();
        for k in 0..blocks {
            let joined: Vec<usize> = (k + 1..blocks).filter(|&i| nz[i * blocks + k]).collect();
            for &i in &joined {
                for &j in &joined {
                    nz[i * blocks + j] = true;
                }
            }
        }
        let seg = |b: usize| (b * size, (b + 1) * size);
        let row: Vec<Vec<(usize, usize)>> = (0..blocks)
            .map(|i| (0..i).filter(|&k| nz[i * blocks + k]).map(seg).collect())
            .collect();
        let column = (0..blocks)
            .map(|j| {
                (j + 1..blocks)
                    .filter(|&i| nz[i * blocks + j])
                    .map(seg)
                    .collect()
            })
            .collect();
        let common = (0..blocks)
            .flat_map(|i| (0..blocks).map(move |j| (i, j)))
            .map(|(i, j)| {
                (j <= i && nz[i * blocks + j]).then(|| {
                    (0..j)
                        .filter(|&k| nz[i * blocks + k] && nz[j * blocks + k])
                        .map(seg)
                        .collect()
                })
            })
            .collect();
        Pattern {
            row,
            common,
            column,
            of_a,
        }
    }
}

/// The share of a dense `L Δ Lᵀ`'s block products that `s`'s pattern keeps: the sum over the
/// nonzero blocks `L(I, J)` of the blocks `K < J` both rows share, against the same sum with every
/// block nonzero (1 for one dense block). What the direct path's cost model scales by.
pub fn fill_share(s: &System) -> f64 {
    // A fit asks this of the same structure at every evaluation: the last answer is kept per
    // thread with the blocks of A it was found for.
    thread_local! {
        static LAST: std::cell::RefCell<(Vec<bool>, f64)> =
            const { std::cell::RefCell::new((Vec::new(), 1.0)) };
    }
    let of_a = Pattern::blocks_of(s);
    if let Some(share) = LAST.with(|l| {
        let l = l.borrow();
        (!l.0.is_empty() && l.0 == of_a).then_some(l.1)
    }) {
        return share;
    }
    let share = share_of(&Pattern::from_blocks(s.n, of_a.clone()));
    LAST.with(|l| *l.borrow_mut() = (of_a, share));
    share
}

/// [`fill_share`] of a pattern.
fn share_of(p: &Pattern) -> f64 {
    let blocks = p.row.len();
    let kept: usize = p.common.iter().flatten().map(Vec::len).sum();
    let dense: usize = (0..blocks).map(|j| (blocks - j) * j).sum();
    if dense == 0 {
        1.0
    } else {
        kept as f64 / dense as f64
    }
}

/// Factors and solves a batch of up to [`LANES`] lines of one system.
pub struct Batch {
    n: usize,
    cols: usize,
    /// DOFs per block of the pattern (6, or `n` for one dense block).
    size: usize,
    /// The blocks of `L` that can be nonzero.
    pattern: Pattern,
    /// Lower triangle: `A` after filling, then `L` below the diagonal and `Δ` on it.
    re: Vec<Lane>,
    im: Vec<Lane>,
    /// `1/δ_j`.
    inv_re: Vec<Lane>,
    inv_im: Vec<Lane>,
    /// Row `j` of `L Δ` while column `j` is computed.
    v_re: Vec<Lane>,
    v_im: Vec<Lane>,
    /// Right-hand sides, then solutions: column `c`, DOF `i` at `c * n + i`.
    x_re: Vec<Lane>,
    x_im: Vec<Lane>,
    /// Per lane: the factorisation is usable (finite nonzero pivots, growth within the limit).
    accurate: [bool; LANES],
}

impl Batch {
    /// Buffers for `system`'s size, with the load and one unit load per output as right-hand
    /// sides (columns 0 and 1..=outputs, as in the per-line solver).
    pub fn new(system: &System) -> Batch {
        let n = system.n;
        let cols = system.columns();
        Batch {
            n,
            cols,
            size: if n.is_multiple_of(6) { 6 } else { n.max(1) },
            pattern: Pattern::of(system),
            re: vec![ZERO; n * n],
            im: vec![ZERO; n * n],
            inv_re: vec![ZERO; n],
            inv_im: vec![ZERO; n],
            v_re: vec![ZERO; n],
            v_im: vec![ZERO; n],
            x_re: vec![ZERO; cols * n],
            x_im: vec![ZERO; cols * n],
            accurate: [false; LANES],
        }
    }

    /// True when these buffers are sized for `system` (its DOFs and right-hand sides).
    pub fn fits(&self, system: &System) -> bool {
        self.n == system.n && self.cols == system.columns()
    }

    /// Makes a batch sized for `system` ([`Batch::fits`]) ready for it: its pattern. Every
    /// buffer entry a factorisation or solve reads it writes first, so nothing else is reset.
    pub fn prepare(&mut self, system: &System) {
        // A fit solves the same structure with new values a hundred times: the symbolic
        // elimination is redone only when the blocks of A differ.
        let of_a = Pattern::blocks_of(system);
        if of_a != self.pattern.of_a {
            self.pattern = Pattern::from_blocks(system.n, of_a);
        }
    }

    /// Factors `A(ω)` and solves for every right-hand side at `freqs_hz` (at most [`LANES`]; unused
    /// lanes repeat the last line). Afterwards [`Batch::accurate`] says which lanes to trust.
    pub fn factor_and_solve(&mut self, s: &System, freqs_hz: &[f64]) {
        debug_assert!(!freqs_hz.is_empty() && freqs_hz.len() <= LANES && s.n == self.n);
        let mut w2 = ZERO;
        for (l, w) in w2.iter_mut().enumerate() {
            let f = freqs_hz[l.min(freqs_hz.len() - 1)];
            *w = (2.0 * std::f64::consts::PI * f).powi(2);
        }
        pulp::Arch::new().dispatch(Work { batch: self, s, w2 });
    }

    /// True when lane `l`'s solution can be used (otherwise solve that line with pivoting).
    pub fn accurate(&self, l: usize) -> bool {
        self.accurate[l]
    }

    /// Solution for right-hand side `col` at DOF `i` in lane `l`.
    #[inline]
    pub fn x(&self, l: usize, col: usize, i: usize) -> C64 {
        let at = col * self.n + i;
        C64::new(self.x_re[at][l], self.x_im[at][l])
    }

    /// Replaces lane `l`'s solutions (same layout as [`Batch::solution`]): for a line solved
    /// again with pivoting.
    pub fn set_solution(&mut self, l: usize, sol: &[C64]) {
        for ((v, re), im) in sol.iter().zip(&mut self.x_re).zip(&mut self.x_im) {
            re[l] = v.re;
            im[l] = v.im;
        }
    }

    /// `Σ_i c_pi (T w_o)_i (T q)_i` for every parameter `p` and output `o`, in every lane: the
    /// adjoint-form derivative of the frf module (times `−factor_o`), with `T` the SDE's
    /// deformation taps, `q` the load's solution and `w_o` output `o`'s unit-load solution.
    pub fn derivatives(
        &self,
        s: &System,
        blocks: &[ParamBlock],
        used: &[usize],
        out: &mut Derivatives,
    ) {
        pulp::Arch::new().dispatch(DerivativeWork {
            batch: self,
            s,
            blocks,
            used,
            out,
        });
    }

    /// Lane `l`'s solutions: `out[c * n + i]` is DOF `i` of right-hand side `c`.
    pub fn solution(&self, l: usize, out: &mut [C64]) {
        for ((o, re), im) in out.iter_mut().zip(&self.x_re).zip(&self.x_im) {
            *o = C64::new(re[l], im[l]);
        }
    }

    /// Lower triangle of `A(ω)` per lane, in the blocks of the [`Pattern`] (the only ones the
    /// factorisation reads; the others are zero in `A`); returns `max |a_ij|` per lane (max of
    /// |re|, |im|).
    #[inline(always)]
    fn fill(&mut self, s: &System, w2: &Lane) -> Lane {
        let (n, size) = (self.n, self.size);
        let blocks = n / size;
        let mut amax = ZERO;
        for i in 0..n {
            let ib = i / size;
            let kept = (0..=ib).filter(|&jb| self.pattern.common[ib * blocks + jb].is_some());
            for j in kept.flat_map(|jb| jb * size..((jb + 1) * size).min(i + 1)) {
                let (k, d) = (s.k[i * n + j], s.d[i * n + j]);
                let (re, im) = (&mut self.re[i * n + j], &mut self.im[i * n + j]);
                for l in 0..LANES {
                    re[l] = if i == j { k - w2[l] * s.mass[i] } else { k };
                    im[l] = d;
                    amax[l] = amax[l].max(re[l].abs()).max(d.abs());
                }
            }
        }
        // Point masses couple DOFs of one body through M.
        for &(i, j, v) in s.mass_coupling.iter().filter(|c| c.1 < c.0) {
            let re = &mut self.re[i * n + j];
            for l in 0..LANES {
                re[l] -= w2[l] * v;
                amax[l] = amax[l].max(re[l].abs());
            }
        }
        amax
    }

    /// Left-looking `L Δ Lᵀ` in place over the blocks of the [`Pattern`]; returns the growth
    /// bound `max_i Σ_k |l_ik|² |δ_k|` per lane.
    #[inline(always)]
    fn factor(&mut self) -> Lane {
        let (n, size) = (self.n, self.size);
        let blocks = n / size;
        let pattern = &self.pattern;
        let mut growth = ZERO;
        for j in 0..n {
            let (jb, j0) = (j / size, j / size * size);
            // v_k = l_jk δ_k where row j of L can be nonzero (k < j); read once here.
            for (lo, hi) in pattern.row[jb].iter().copied().chain([(j0, j)]) {
                for k in lo..hi {
                    let (lr, li) = (&self.re[j * n + k], &self.im[j * n + k]);
                    let (dr, di) = (&self.re[k * n + k], &self.im[k * n + k]);
                    // Formed in locals and stored whole: the compiler cannot tell that `v`
                    // and `L` do not overlap, and would not vectorise a store into one between
                    // loads from the other.
                    let (mut vr, mut vi) = (ZERO, ZERO);
                    for l in 0..LANES {
                        vr[l] = lr[l] * dr[l] - li[l] * di[l];
                        vi[l] = lr[l] * di[l] + li[l] * dr[l];
                    }
                    self.v_re[k] = vr;
                    self.v_im[k] = vi;
                }
            }
            // δ_j and the rest of column j: a_ij − Σ_k l_ik v_k for i ≥ j, in the blocks where
            // column j of L can be nonzero, over the k where both rows can be.
            for ib in jb..blocks {
                let Some(common) = &pattern.common[ib * blocks + jb] else {
                    continue;
                };
                for i in j.max(ib * size)..(ib + 1) * size {
                    let (mut ar, mut ai) = (self.re[i * n + j], self.im[i * n + j]);
                    let (row_re, row_im) = (&self.re[i * n..i * n + j], &self.im[i * n..i * n + j]);
                    let (v_re, v_im) = (&self.v_re[..j], &self.v_im[..j]);
                    dot_sub(
                        &mut ar,
                        &mut ai,
                        common.iter().copied().chain([(j0, j)]),
                        0,
                        |k| (&row_re[k], &row_im[k]),
                        |k| (&v_re[k], &v_im[k]),
                    );
                    if i == j {
                        let (mut inr, mut ini) = (ZERO, ZERO);
                        for l in 0..LANES {
                            let m = ar[l] * ar[l] + ai[l] * ai[l];
                            inr[l] = ar[l] / m;
                            ini[l] = -ai[l] / m;
                        }
                        self.inv_re[j] = inr;
                        self.inv_im[j] = ini;
                        self.re[j * n + j] = ar;
                        self.im[j * n + j] = ai;
                    } else {
                        let (inr, ini) = (&self.inv_re[j], &self.inv_im[j]);
                        let (mut lr, mut li) = (ZERO, ZERO);
                        for l in 0..LANES {
                            lr[l] = ar[l] * inr[l] - ai[l] * ini[l];
                            li[l] = ar[l] * ini[l] + ai[l] * inr[l];
                        }
                        self.re[i * n + j] = lr;
                        self.im[i * n + j] = li;
                    }
                }
            }
        }
        // |δ_k| once per pivot (in `v_re`, free now), not once per row that reads it.
        for k in 0..n {
            let (dr, di) = (&self.re[k * n + k], &self.im[k * n + k]);
            let mut dabs = ZERO;
            for l in 0..LANES {
                dabs[l] = (dr[l] * dr[l] + di[l] * di[l]).sqrt();
            }
            self.v_re[k] = dabs;
        }
        // Growth bound, row by row: Σ_k |l_ik|² |δ_k| with l_ii = 1, where l_ik can be nonzero.
        for i in 0..n {
            let (ib, i0) = (i / size, i / size * size);
            let mut acc = ZERO;
            for (lo, hi) in pattern.row[ib].iter().copied().chain([(i0, i)]) {
                for k in lo..hi {
                    let (lr, li) = (&self.re[i * n + k], &self.im[i * n + k]);
                    let dabs = &self.v_re[k];
                    for l in 0..LANES {
                        acc[l] += (lr[l] * lr[l] + li[l] * li[l]) * dabs[l];
                    }
                }
            }
            let dabs = &self.v_re[i];
            for l in 0..LANES {
                acc[l] += dabs[l];
            }
            for l in 0..LANES {
                // NaN-propagating max: a NaN pivot must fail the growth test.
                growth[l] = if acc[l].is_nan() || growth[l].is_nan() {
                    f64::NAN
                } else {
                    growth[l].max(acc[l])
                };
            }
        }
        growth
    }

    /// Right-hand sides (the load, then each output's row as a load) and
    /// `x = L⁻ᵀ Δ⁻¹ L⁻¹ b` for each of them, over the blocks of the [`Pattern`].
    #[inline(always)]
    fn solve(&mut self, s: &System) {
        let (n, size) = (self.n, self.size);
        let pattern = &self.pattern;
        self.x_re.fill(ZERO);
        self.x_im.fill(ZERO);
        for i in 0..n {
            self.x_re[i] = [s.load[i]; LANES];
        }
        let past = 1 + s.output_rows.len();
        for (r, load) in s.reference_loads.iter().enumerate() {
            for (x, &p) in self.x_re[(past + r) * n..(past + r + 1) * n]
                .iter_mut()
                .zip(load)
            {
                *x = [p; LANES];
            }
        }
        for (o, row) in s.output_rows.iter().enumerate() {
            for &(d, v) in &row.taps {
                self.x_re[(o + 1) * n + d] = [v; LANES];
            }
        }
        for c in 0..self.cols {
            let (xr, xi) = (
                &mut self.x_re[c * n..(c + 1) * n],
                &mut self.x_im[c * n..(c + 1) * n],
            );
            // L y = b, row by row, from b's first nonzero (y is zero before it; a unit load's
            // right-hand side has one nonzero).
            let first = xr
                .iter()
                .zip(xi.iter())
                .position(|(r, i)| r.iter().chain(i).any(|v| *v != 0.0))
                .unwrap_or(n);
            for i in first.max(1)..n {
                let (ib, i0) = (i / size, i / size * size);
                let (mut ar, mut ai) = (xr[i], xi[i]);
                let (row_re, row_im) = (&self.re[i * n..i * n + i], &self.im[i * n..i * n + i]);
                let (yr, yi) = (&xr[..i], &xi[..i]);
                dot_sub(
                    &mut ar,
                    &mut ai,
                    pattern.row[ib]
                        .iter()
                        .copied()
                        .chain([(i0, i)])
                        .map(|(lo, hi)| (lo.max(first), hi)),
                    0,
                    |k| (&row_re[k], &row_im[k]),
                    |k| (&yr[k], &yi[k]),
                );
                xr[i] = ar;
                xi[i] = ai;
            }
            // z = Δ⁻¹ y, then Lᵀ x = z from the bottom: x_i = z_i − Σ_{k>i} l_ki x_k.
            for i in (0..n).rev() {
                let ib = i / size;
                let (mut ar, mut ai) = (ZERO, ZERO);
                let (yr, yi) = (&xr[i], &xi[i]);
                let (inr, ini) = (&self.inv_re[i], &self.inv_im[i]);
                for l in 0..LANES {
                    ar[l] = yr[l] * inr[l] - yi[l] * ini[l];
                    ai[l] = yr[l] * ini[l] + yi[l] * inr[l];
                }
                let (l_re, l_im) = (&self.re, &self.im);
                let (tr, ti) = (&*xr, &*xi);
                let col = |k: usize| (&l_re[k * n + i], &l_im[k * n + i]);
                dot_sub(
                    &mut ar,
                    &mut ai,
                    [(i + 1, (ib + 1) * size)]
                        .into_iter()
                        .chain(pattern.column[ib].iter().copied()),
                    i + 1,
                    col,
                    |k| (&tr[k], &ti[k]),
                );
                xr[i] = ar;
                xi[i] = ai;
            }
        }
    }
}

/// `acc −= Σ_k a_k b_k` per lane (complex) over the index `segments` (ascending `[lo, hi)`,
/// `k ≥ base`). Two sets of partial sums, so that the fused multiply-adds of consecutive `k` do
/// not wait on each other: the terms with `k − base` even go to the first, odd to the second,
/// each in ascending `k`. The indices left out between segments carry exact zeros, so the sums
/// are those of one dense sweep over `base..` bit for bit.
#[inline(always)]
fn dot_sub<'a, 'b>(
    acc_re: &mut Lane,
    acc_im: &mut Lane,
    segments: impl IntoIterator<Item = (usize, usize)>,
    base: usize,
    a: impl Fn(usize) -> (&'a Lane, &'a Lane),
    b: impl Fn(usize) -> (&'b Lane, &'b Lane),
) {
    #[inline(always)]
    fn term(sr: &mut Lane, si: &mut Lane, (ar, ai): (&Lane, &Lane), (br, bi): (&Lane, &Lane)) {
        for l in 0..LANES {
            sr[l] = ar[l].mul_add(br[l], (-ai[l]).mul_add(bi[l], sr[l]));
            si[l] = ar[l].mul_add(bi[l], ai[l].mul_add(br[l], si[l]));
        }
    }
    let mut sum = [ZERO; 4];
    for (lo, hi) in segments {
        let mut k = lo;
        let [s0, s1, s2, s3] = &mut sum;
        if k < hi && (k - base) % 2 == 1 {
            term(s2, s3, a(k), b(k));
            k += 1;
        }
        while k + 1 < hi {
            term(s0, s1, a(k), b(k));
            term(s2, s3, a(k + 1), b(k + 1));
            k += 2;
        }
        if k < hi {
            term(s0, s1, a(k), b(k));
        }
    }
    for l in 0..LANES {
        acc_re[l] -= sum[0][l] + sum[2][l];
        acc_im[l] -= sum[1][l] + sum[3][l];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::Mat;

    /// The pivoted LU solution of every right-hand side at `f` Hz, for reference.
    fn reference(s: &System, f: f64) -> Vec<C64> {
        let n = s.n;
        let w2 = (2.0 * std::f64::consts::PI * f).powi(2);
        let a = Mat::<C64>::from_fn(n, n, |i, j| {
            C64::new(
                s.k[i * n + j] - if i == j { w2 * s.mass[i] } else { 0.0 },
                s.d[i * n + j],
            )
        });
        let cols = s.columns();
        let mut b = Mat::<C64>::zeros(n, cols);
        for c in 0..cols {
            for i in 0..n {
                b[(i, c)] = C64::new(s.load_entry(c, i), 0.0);
            }
        }
        for (o, row) in s.output_rows.iter().enumerate() {
            for &(d, v) in &row.taps {
                b[(d, o + 1)] = C64::new(v, 0.0);
            }
        }
        let x = faer::linalg::solvers::Solve::solve(&a.partial_piv_lu(), &b);
        (0..cols)
            .flat_map(|c| (0..n).map(move |i| (c, i)))
            .map(|(c, i)| x[(i, c)])
            .collect()
    }

    fn fwd32j() -> System {
        System::assemble(&crate::modelfile::fwd32j())
    }

    #[test]
    fn batched_solutions_agree_with_a_pivoted_lu_on_fwd32j() {
        let s = fwd32j();
        // 38 log-spaced lines over 3–1000 Hz: below, through and above every resonance; the last
        // batch is partial.
        let freqs: Vec<f64> = (0..38)
            .map(|k| 3.0 * (1000.0f64 / 3.0).powf(k as f64 / 37.0))
            .collect();
        let mut batch = Batch::new(&s);
        let mut sol = vec![C64::new(0.0, 0.0); s.columns() * s.n];
        let mut worst = 0.0f64;
        for chunk in freqs.chunks(LANES) {
            batch.factor_and_solve(&s, chunk);
            for (l, &f) in chunk.iter().enumerate() {
                assert!(batch.accurate(l), "FWD-32J at {f} Hz needed pivoting");
                batch.solution(l, &mut sol);
                let r = reference(&s, f);
                let scale = r.iter().map(|v| v.norm()).fold(0.0, f64::max);
                let err = sol
                    .iter()
                    .zip(&r)
                    .map(|(a, b)| (a - b).norm())
                    .fold(0.0, f64::max)
                    / scale;
                worst = worst.max(err);
            }
        }
        assert!(
            worst < 1e-10,
            "largest difference from the pivoted LU: {worst:e} of the largest entry"
        );
    }

    /// A batch kept between solves takes the pattern of the system it is prepared for (found
    /// again only when the blocks of A differ), and solves as a new batch does, bit for bit; the
    /// kept fill share is the one found afresh.
    #[test]
    fn a_kept_batch_takes_the_pattern_of_each_system_it_is_prepared_for() {
        let s = fwd32j();
        // The ring cut open: no coupling left between the first two bodies.
        let mut cut = s.clone();
        let n = s.n;
        for i in 0..6 {
            for j in 6..12 {
                for at in [i * n + j, j * n + i] {
                    cut.k[at] = 0.0;
                    cut.d[at] = 0.0;
                }
            }
        }
        assert_ne!(Pattern::blocks_of(&s), Pattern::blocks_of(&cut));
        let freqs = [20.0, 55.0, 130.0];
        let mut batch = Batch::new(&s);
        for system in [&cut, &s, &s, &cut] {
            batch.prepare(system);
            assert_eq!(batch.pattern, Pattern::of(system));
            batch.factor_and_solve(system, &freqs);
            let mut new = Batch::new(system);
            new.factor_and_solve(system, &freqs);
            assert_eq!((&batch.x_re, &batch.x_im), (&new.x_re, &new.x_im));
        }
        for system in [&s, &cut, &s] {
            assert_eq!(fill_share(system), share_of(&Pattern::of(system)));
        }
        assert!(share_of(&Pattern::of(&cut)) < share_of(&Pattern::of(&s)));
    }

    #[test]
    fn the_pattern_of_fwd32j_is_its_ring_of_bodies_with_the_fill() {
        // Column–overarm–spindle head–table–upper saddle–lower saddle–knee–column: a ring of
        // seven bodies; eliminating in file order fills four more block pairs.
        let s = fwd32j();
        let p = Pattern::of(&s);
        let blocks = s.n / 6;
        assert_eq!(blocks, 7);
        let kept = |i: usize, j: usize| p.common[i * blocks + j].is_some();
        let lower: usize = (0..blocks)
            .map(|i| (0..=i).filter(|&j| kept(i, j)).count())
            .sum();
        assert_eq!(lower, 18, "{:?}", p.row);
        // Every nonzero entry of K and D lies in a kept block.
        for i in 0..s.n {
            for j in 0..=i {
                if s.k[i * s.n + j] != 0.0 || s.d[i * s.n + j] != 0.0 {
                    assert!(kept(i / 6, j / 6), "A({i}, {j}) outside the pattern");
                }
            }
        }
        // The column lists are the row lists transposed.
        for (j, col) in p.column.iter().enumerate() {
            for &(lo, _) in col {
                assert!(p.row[lo / 6].contains(&(6 * j, 6 * j + 6)));
            }
        }
    }

    #[test]
    fn a_zero_pivot_is_flagged_and_the_other_lanes_are_kept() {
        // Undamped single body whose first DOF is tuned so that a_00 = k − ω²m is exactly zero at
        // 10 Hz: the unpivoted factorisation breaks down there (the matrix itself may not be
        // singular, so the line must go back to a pivoted solver, not fail).
        let mut s = System::assemble(&crate::textbook::single_body(100.0, 1.0e6, 0.0));
        let w2 = (2.0 * std::f64::consts::PI * 10.0f64).powi(2);
        s.k[0] = w2 * s.mass[0];
        s.d.iter_mut().for_each(|d| *d = 0.0);
        let mut batch = Batch::new(&s);
        batch.factor_and_solve(&s, &[5.0, 10.0, 20.0]);
        assert!(batch.accurate(0) && batch.accurate(2));
        assert!(!batch.accurate(1), "a zero pivot must not be trusted");
        let mut sol = vec![C64::new(0.0, 0.0); s.columns() * s.n];
        batch.solution(2, &mut sol);
        let r = reference(&s, 20.0);
        let err = sol
            .iter()
            .zip(&r)
            .map(|(a, b)| (a - b).norm())
            .fold(0.0, f64::max);
        assert!(err <= 1e-12 * r.iter().map(|v| v.norm()).fold(0.0, f64::max));
    }

    #[test]
    fn large_growth_is_flagged() {
        // a_00 tiny but nonzero: the pivot exists, yet |l|²|δ| grows by ~1/ε.
        let mut s = System::assemble(&crate::textbook::single_body(100.0, 1.0e6, 0.0));
        let w2 = (2.0 * std::f64::consts::PI * 10.0f64).powi(2);
        s.k[0] = w2 * s.mass[0] * (1.0 + 1e-9);
        s.k[1] = 1.0e5;
        s.k[s.n] = 1.0e5;
        s.d.iter_mut().for_each(|d| *d = 0.0);
        let mut batch = Batch::new(&s);
        batch.factor_and_solve(&s, &[10.0]);
        assert!(
            !batch.accurate(0),
            "growth of ~1e9 must send the line to the pivoted solver"
        );
    }
}
