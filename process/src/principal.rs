//! Transformation of accelerometer FRFs to a solid's rigid-body motion at its centre of mass in
//! its principal central axes, with a rigidity indicator.
//!
//! A point `x` (global) of a rigid solid with centre of mass `c` and `global_from_body` rotation
//! `R` moves by `R(u + r × s)`, `s = Rᵀ(x − c)`, where `q = [u1,u2,u3,r1,r2,r3]` are the
//! translations (m) and small rotations (rad) along/about the principal axes. A channel measuring
//! along the global unit direction `d` reads `e·u + r·(s × e)` with `e = Rᵀd`: one row of a real
//! matrix `A` (channels × 6). Per frequency the complex `q` is the least-squares solution of
//! `A q = y` (pseudo-inverse computed once per layout). The **rigidity indicator** is the relative
//! residual `‖y − A q‖ / ‖y‖`: zero for a rigid solid and ideal sensors, larger where the solid
//! deforms (needs more channels than fitted DOFs to say anything).

use nalgebra::{DMatrix, Vector3};
use num_complex::Complex;

use rfe::Body;

use crate::error::{check_count, ProcessError, Result};

type C64 = Complex<f64>;

/// An accelerometer channel mounted on the solid.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    /// Channel name.
    pub name: String,
    /// Mounting point in the global frame (m).
    pub position: Vector3<f64>,
    /// Measuring direction in the global frame (normalized on use; must be nonzero).
    pub direction: Vector3<f64>,
}

/// Which DOFs to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dofs {
    /// Six DOFs; the layout must observe all of them.
    Six,
    /// Three translations only (rotations assumed zero).
    Translations,
    /// Six if observable, otherwise three translations if those are, otherwise an error.
    Auto,
}

/// Least-squares rigid-body fit for one solid and one sensor layout.
#[derive(Debug, Clone)]
pub struct RigidFit {
    body: String,
    /// Number of fitted DOFs (6, or 3 for translations only).
    dofs: usize,
    /// channels × dofs.
    a: DMatrix<f64>,
    /// dofs × channels.
    pinv: DMatrix<f64>,
}

/// Rigid-body motion of the solid per frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct PrincipalResponse {
    /// Frequencies (Hz).
    pub freqs_hz: Vec<f64>,
    /// `q[k] = [u1,u2,u3,r1,r2,r3]` at line k (response unit per force unit; for rotations per metre
    /// of lever, i.e. rad-based). Rotations are zero when only translations were fitted.
    pub q: Vec<[C64; 6]>,
    /// Rigidity indicator `‖y − A q‖/‖y‖` at line k (0 = rigid).
    pub residual: Vec<f64>,
    /// Variance of each fitted DOF at line k (E|q̂−q|², propagated from the channels' FRF
    /// variances), when the input carried them.
    pub variance: Option<Vec<[f64; 6]>>,
    /// Number of fitted DOFs (6 or 3).
    pub dofs: usize,
}

impl PrincipalResponse {
    /// The characteristic of one DOF (0-5) over all lines.
    pub fn dof(&self, dof: usize) -> Vec<C64> {
        self.q.iter().map(|q| q[dof.min(5)]).collect()
    }
}

const DOF_NAMES: [&str; 6] = ["u1", "u2", "u3", "r1", "r2", "r3"];

impl RigidFit {
    /// Builds the fit for `body` measured by `sensors`.
    pub fn new(body: &Body, sensors: &[Sensor], dofs: Dofs) -> Result<RigidFit> {
        let degenerate = |missing: String| ProcessError::DegenerateLayout {
            body: body.name.clone(),
            missing,
        };
        let rt = body.rotation.transpose();
        let n = sensors.len();
        let mut a = DMatrix::<f64>::zeros(n, 6);
        let mut lever: f64 = 0.0;
        for (i, s) in sensors.iter().enumerate() {
            let norm = s.direction.norm();
            if !(norm.is_finite() && norm > 0.0 && s.position.iter().all(|v| v.is_finite())) {
                return Err(degenerate(format!("sensor '{}' has a zero or non-finite direction/position; give a unit measuring direction", s.name)));
            }
            let e = rt * (s.direction / norm);
            let sb = rt * (s.position - body.position);
            lever = lever.max(sb.norm());
            let m = sb.cross(&e);
            for c in 0..3 {
                a[(i, c)] = e[c];
                a[(i, 3 + c)] = m[c];
            }
        }
        let want_six = matches!(dofs, Dofs::Six | Dofs::Auto);
        if want_six {
            match unobserved_motions(&a, lever) {
                None => return Self::finish(body, a, 6),
                Some(missing) if dofs == Dofs::Six => {
                    return Err(degenerate(format!("{missing}; {n} channel(s) given, at least 6 in independent directions/places are needed for 6 DOFs (or fit translations only)")));
                }
                Some(_) => {}
            }
        }
        let t = a.columns(0, 3).into_owned();
        match unobserved_motions(&t, 1.0) {
            None => Self::finish(body, t, 3),
            Some(missing) => Err(degenerate(format!("{missing}; {n} channel(s) given: add sensors so that their directions span all three principal axes"))),
        }
    }

    fn finish(body: &Body, a: DMatrix<f64>, dofs: usize) -> Result<RigidFit> {
        let pinv = a
            .clone()
            .pseudo_inverse(1e-12)
            .map_err(|e| ProcessError::DegenerateLayout {
                body: body.name.clone(),
                missing: e.to_string(),
            })?;
        Ok(RigidFit {
            body: body.name.clone(),
            dofs,
            a,
            pinv,
        })
    }

    /// Number of fitted DOFs: 6, or 3 (translations only).
    pub fn dofs(&self) -> usize {
        self.dofs
    }

    /// Body name.
    pub fn body(&self) -> &str {
        &self.body
    }

    /// Channels in the layout.
    pub fn channels(&self) -> usize {
        self.a.nrows()
    }

    /// Fits one frequency line: `y[i]` is channel i's FRF value. Writes `q` (rotations zero when
    /// only translations are fitted) and returns the rigidity indicator. No allocation.
    pub fn fit_line(&self, y: &[C64], q: &mut [C64; 6]) -> Result<f64> {
        let n = self.a.nrows();
        check_count("sensor channels", n, y.len())?;
        *q = [C64::default(); 6];
        for (d, qd) in q.iter_mut().enumerate().take(self.dofs) {
            *qd = (0..n).map(|i| y[i] * self.pinv[(d, i)]).sum();
        }
        let (mut res, mut tot) = (0.0, 0.0);
        for (i, yi) in y.iter().enumerate() {
            let pred: C64 = (0..self.dofs).map(|d| q[d] * self.a[(i, d)]).sum();
            res += (yi - pred).norm_sqr();
            tot += yi.norm_sqr();
        }
        Ok(if tot > 0.0 { (res / tot).sqrt() } else { 0.0 })
    }

    /// Variance of each fitted DOF from the variances of the channels (assumed independent):
    /// `var(q_d) = Σ_i P_di² var(y_i)` with `P` the pseudo-inverse. Rotations are 0 when only
    /// translations are fitted.
    pub fn variance(&self, channel_variance: &[f64]) -> Result<[f64; 6]> {
        let n = self.a.nrows();
        check_count("channel variances", n, channel_variance.len())?;
        let mut out = [0.0; 6];
        for (d, o) in out.iter_mut().enumerate().take(self.dofs) {
            *o = (0..n)
                .map(|i| self.pinv[(d, i)].powi(2) * channel_variance[i])
                .sum();
        }
        Ok(out)
    }

    /// Fits every line: `channels[i][k]` is channel i's FRF at `freqs_hz[k]`.
    pub fn transform(&self, freqs_hz: &[f64], channels: &[Vec<C64>]) -> Result<PrincipalResponse> {
        let n = self.a.nrows();
        check_count("sensor channels", n, channels.len())?;
        for c in channels {
            check_count("frequency lines of a sensor FRF", freqs_hz.len(), c.len())?;
        }
        let mut y = vec![C64::default(); n];
        let mut out = PrincipalResponse {
            freqs_hz: freqs_hz.to_vec(),
            q: Vec::with_capacity(freqs_hz.len()),
            residual: Vec::with_capacity(freqs_hz.len()),
            variance: None,
            dofs: self.dofs,
        };
        for k in 0..freqs_hz.len() {
            for (yi, c) in y.iter_mut().zip(channels) {
                *yi = c[k];
            }
            let mut q = [C64::default(); 6];
            let r = self.fit_line(&y, &mut q)?;
            out.q.push(q);
            out.residual.push(r);
        }
        Ok(out)
    }
}

impl RigidFit {
    /// Transforms the FRFs of `frf` to the principal axes: `sensor_responses[i]` is the response
    /// index in `frf` of sensor i, `reference` the force. Carries each line's variance through.
    pub fn transform_frf(
        &self,
        frf: &crate::Frf,
        reference: usize,
        sensor_responses: &[usize],
    ) -> Result<PrincipalResponse> {
        let n = self.a.nrows();
        check_count("sensor-to-response indices", n, sensor_responses.len())?;
        if reference >= frf.references {
            return Err(ProcessError::ChannelCount {
                what: "references in the FRF (reference index out of range)",
                expected: reference + 1,
                got: frf.references,
            });
        }
        if let Some(&bad) = sensor_responses.iter().find(|&&j| j >= frf.responses) {
            return Err(ProcessError::ChannelCount {
                what: "responses in the FRF (sensor index out of range)",
                expected: bad + 1,
                got: frf.responses,
            });
        }
        let channels: Vec<Vec<C64>> = sensor_responses
            .iter()
            .map(|&j| frf.line(j, reference))
            .collect();
        let mut out = self.transform(&frf.freqs_hz, &channels)?;
        let mut var = Vec::with_capacity(frf.freqs_hz.len());
        let mut cv = vec![0.0; n];
        for k in 0..frf.freqs_hz.len() {
            for (v, &j) in cv.iter_mut().zip(sensor_responses) {
                *v = frf.variance(k, j, reference);
            }
            var.push(self.variance(&cv)?);
        }
        out.variance = Some(var);
        Ok(out)
    }
}

/// Builds a [`Body`] from mass properties given as a full inertia tensor about the centre of mass
/// (kg·m², global axes): its eigen-decomposition gives the principal moments (ascending) and the
/// principal axes (columns of `rotation`, right-handed).
pub fn body_from_inertia_tensor(
    name: &str,
    mass: f64,
    centre_of_mass: Vector3<f64>,
    tensor: &nalgebra::Matrix3<f64>,
) -> Result<Body> {
    let bad = |what: String| ProcessError::InvalidSetting {
        field: "inertia tensor",
        value: name.to_string(),
        reason: what,
    };
    if !(mass.is_finite() && mass > 0.0) {
        return Err(bad(format!("mass {mass} kg must be > 0")));
    }
    if !tensor.iter().all(|v| v.is_finite())
        || (tensor - tensor.transpose()).abs().max() > 1e-9 * tensor.abs().max()
    {
        return Err(bad("the tensor must be finite and symmetric".into()));
    }
    let eig = nalgebra::SymmetricEigen::new(*tensor);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let inertia = order.map(|i| eig.eigenvalues[i]);
    if inertia[0] <= 0.0 {
        return Err(bad(format!(
            "principal moments {inertia:?} must all be > 0"
        )));
    }
    let (a, b, c) = (order[0], order[1], order[2]);
    let mut rotation = nalgebra::Matrix3::from_columns(&[
        eig.eigenvectors.column(a),
        eig.eigenvectors.column(b),
        eig.eigenvectors.column(c),
    ]);
    if rotation.determinant() < 0.0 {
        rotation.column_mut(2).neg_mut();
    }
    Ok(Body {
        name: name.to_string(),
        mass,
        inertia,
        position: centre_of_mass,
        rotation,
    })
}

/// None if `a` has full column rank; otherwise a description of the motions no sensor sees and
/// what to add. Rotation columns are scaled by `lever` (m) so that translations and rotations
/// compare.
fn unobserved_motions(a: &DMatrix<f64>, lever: f64) -> Option<String> {
    let m = a.ncols();
    let mut scaled = a.clone();
    let lever = if lever > 0.0 { lever } else { 1.0 };
    for c in 3..m {
        scaled.column_mut(c).scale_mut(1.0 / lever);
    }
    if scaled.nrows() < m {
        // Pad so the SVD exposes the whole null space.
        scaled = scaled.insert_rows(a.nrows(), m - a.nrows(), 0.0);
    }
    let svd = scaled.svd(false, true);
    let vt = match svd.v_t {
        Some(v) => v,
        None => return Some("the layout matrix could not be decomposed".into()),
    };
    let smax = svd.singular_values.max();
    let mut missing = Vec::new();
    for (i, s) in svd.singular_values.iter().enumerate() {
        if smax.is_nan() || smax <= 0.0 || *s <= 1e-9 * smax {
            let v = vt.row(i);
            let big = v.iter().map(|x| x.abs()).fold(0.0, f64::max);
            let terms: Vec<String> = v
                .iter()
                .enumerate()
                .filter(|(_, x)| x.abs() > 0.05 * big)
                .map(|(d, x)| format!("{:+.2} {}", x / big, DOF_NAMES[d]))
                .collect();
            missing.push(format!("[{}]", terms.join(" ")));
        }
    }
    (!missing.is_empty()).then(|| {
        format!(
            "no sensor sees the motion(s) {} of the principal axes (translations u, rotations r); add a sensor whose reading changes under it (another direction, or off the line of the existing ones)",
            missing.join(", ")
        )
    })
}
