//! The plain baseline the benchmarks compare against: per frequency line, a dense LU of
//! `A = K + jD − ω²M`, the response `q = A⁻¹P`, and for every parameter the dense derivative
//! `∂q/∂p = −A⁻¹ (∂A/∂p) q` with `∂A/∂p` assembled as an n×n matrix. No adjoint, no block
//! structure, no reuse: what a straightforward implementation of eq. 4.1 and 4.7 does.

use faer::linalg::solvers::Solve;
use faer::Mat;
use rfe::model::{Model, ParamRef};
use rfe::system::System;
use rfe::C64;

/// Values `[o][line]` and Jacobian `[p][o][line]` (flattened like `frf::Response`).
pub fn dense_response(model: &Model, freqs: &[f64], params: &[ParamRef]) -> (Vec<C64>, Vec<C64>) {
    let s = System::assemble(model);
    let blocks: Vec<_> = s
        .param_blocks(model, params)
        .into_iter()
        .map(|b| b.expect("param"))
        .collect();
    let n = s.n;
    let outs = s.output_rows.len();
    let lines = freqs.len();
    let mut values = vec![C64::new(0.0, 0.0); outs * lines];
    let mut jac = vec![C64::new(0.0, 0.0); params.len() * outs * lines];
    for (k, f) in freqs.iter().enumerate() {
        let w2 = (2.0 * std::f64::consts::PI * f).powi(2);
        let a = Mat::<C64>::from_fn(n, n, |i, j| {
            C64::new(
                s.k[i * n + j] - if i == j { w2 * s.mass[i] } else { 0.0 },
                s.d[i * n + j],
            )
        });
        let lu = a.partial_piv_lu();
        let p = Mat::<C64>::from_fn(n, 1, |i, _| C64::new(s.load[i], 0.0));
        let q = lu.solve(&p);
        for (o, row) in s.output_rows.iter().enumerate() {
            values[o * lines + k] =
                row.apply(|d| q[(d, 0)]) * model.outputs[o].quantity.factor(w2.sqrt());
        }
        for (pi, pb) in blocks.iter().enumerate() {
            let b = &s.sdes[pb.block];
            // T (6×n) of this SDE, then ∂A = Tᵀ diag(c) T, dense.
            let mut t = Mat::<C64>::zeros(6, n);
            for (side, sign) in [(0usize, -1.0), (1, 1.0)] {
                if let Some(body) = b.bodies[side] {
                    for r in 0..6 {
                        for c in 0..6 {
                            t[(r, 6 * body + c)] = C64::new(sign * b.g[side][(r, c)], 0.0);
                        }
                    }
                }
            }
            let dt = Mat::<C64>::from_fn(6, n, |r, c| t[(r, c)] * pb.coeff[r]);
            let da = t.transpose() * &dt;
            let rhs = -(&da * &q);
            let dq = lu.solve(&rhs);
            for (o, row) in s.output_rows.iter().enumerate() {
                jac[(pi * outs + o) * lines + k] =
                    row.apply(|d| dq[(d, 0)]) * model.outputs[o].quantity.factor(w2.sqrt());
            }
        }
    }
    (values, jac)
}
