//! Turning lobes against the one-DOF closed form, the boundary's analytic gradient against finite
//! differences, and the confidence bands: linear against Monte Carlo, and shrinking with the
//! noise of the data the model was identified from.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::f64::consts::PI;
use std::path::PathBuf;

use identify::{self as idn, data, synthetic, variables};
use nalgebra::DMatrix;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::model::Model;
use rfe::{textbook, C64};
use stability::cut::{self, Cut};
use stability::{bands, lobes, oriented, Request, Uncertainty};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn turning_cut(body: &str, point: [f64; 3], speeds: (f64, f64), n: usize) -> Cut {
    cut::parse(
        &format!(
            r#"
operation = "turning"
speed_rpm = [{}, {}]
speeds = {n}
[tool]
body = "{body}"
point = [{}, {}, {}]
[workpiece]
body = "ground"
point = [0.0, 0.0, 0.0]
[cutting]
kt = "2000 MPa"
kr = "800 MPa"
[turning]
thickness = [0.0, 0.0, 1.0]
cutting = [1.0, 0.0, 0.0]
"#,
            speeds.0, speeds.1, point[0], point[1], point[2]
        ),
        "turning.toml",
    )
    .unwrap()
}

/// One body on a hysteretic spring: `Φ = 1/(k(1 + jη) − mω²)` along the chip thickness, so
/// `Re Φ` is lowest, `−1/(2kη)`, at `k − mω² = −kη` and the lowest stable depth is `k η / K_r`;
/// every boundary point solves `1 + a (1 − e^{−jωT}) K_r Φ(jω) = 0` at its chatter frequency.
#[test]
fn turning_lobes_match_the_one_dof_closed_form() {
    let (m, k, psi) = (100.0, 1.0e7, 0.2);
    let model = textbook::single_body(m, k, psi);
    let cut = turning_cut("mass", [0.0; 3], (300.0, 2000.0), 400);
    let l = stability::lobes(&Request::new(&model, &cut)).unwrap();
    let eta = psi / (2.0 * PI);
    let kr = 8.0e8;
    let expected = k * eta / kr;
    let min = l.points[l.minimum].depth;
    assert!(
        (min - expected).abs() < 0.005 * expected,
        "minimum {min} vs k η / K_r = {expected}"
    );
    let fc = ((k * (1.0 + eta)) / m).sqrt() / (2.0 * PI);
    let f = l.points[l.minimum].chatter_hz;
    assert!(
        (f - fc).abs() < 0.01 * fc,
        "chatter at the minimum {f} Hz vs {fc} Hz"
    );
    assert!(
        l.points.iter().all(|p| p.depth.is_finite()),
        "every speed has a lobe"
    );
    let mut checked = 0;
    for p in &l.points {
        let w = 2.0 * PI * p.chatter_hz;
        let phi = C64::new(k - m * w * w, k * eta).inv();
        let t = 60.0 / p.speed_rpm;
        let r = C64::new(1.0, 0.0)
            + (C64::new(1.0, 0.0) - C64::from_polar(1.0, -w * t)) * (phi * kr * p.depth);
        if p.depth > 2.0 * expected {
            // On a lobe's flank next to the resonance `a ∝ 1/(f − f_n)` is too curved for the
            // linear interpolation between lines to solve the equation this closely.
            continue;
        }
        // Within 1 %: the lines are 0.05 % apart, but the lobe bottoms lie within a few lines
        // of the resonance, where G turns fastest.
        assert!(
            r.norm() < 1e-2,
            "{} rpm: characteristic equation residual {}",
            p.speed_rpm,
            r.norm()
        );
        checked += 1;
    }
    assert!(
        checked >= 100,
        "only {checked} points near the lobe bottoms"
    );
    // The limiting mode is the body's translation along z, through the one spring.
    assert_eq!(l.limiting.len(), 1);
    assert!((l.limiting[0].share - 1.0).abs() < 1e-6);
    assert_eq!(l.limiting[0].joints[0].0, "spring");
}

fn two_mass() -> Model {
    rfe::modelfile::load(&root().join("configs/models/textbook-two-mass.toml"))
        .unwrap()
        .model
}

fn two_mass_vars(model: &Model) -> variables::Variables {
    variables::load(
        &root().join("configs/identification/textbook-two-mass.toml"),
        model,
    )
    .unwrap()
}

/// The variables with their `initial` values at `x` (as a final variables file has them).
fn at(vars: &variables::Variables, x: &[f64]) -> variables::Variables {
    let mut v = vars.clone();
    for (var, &xi) in v.vars.iter_mut().zip(x) {
        var.initial = xi;
    }
    v
}

/// The analytic gradient of the critical depth at fixed speeds against central differences of
/// the whole computation (model re-solved at x ± h).
#[test]
fn the_boundary_gradient_matches_finite_differences() {
    let model = two_mass();
    let vars = two_mass_vars(&model);
    let x0: Vec<f64> = vars
        .vars
        .iter()
        .map(|v| model.value(v.targets[0].param).unwrap())
        .collect();
    let vars = at(&vars, &x0);
    let cut = turning_cut("second", [0.0, 0.0, 1.0], (100.0, 1500.0), 60);
    let placement = oriented::place(&model, &cut).unwrap();
    let split = oriented::modal_split(&placement).unwrap();
    let freqs = stability::frequency_grid(&split, &cut);
    let process = lobes::Process::of(&cut);
    let speeds = cut.speed_grid();
    let solve = |x: &[f64]| {
        let mut p = placement.clone();
        vars.apply(&mut p.aux, x);
        let frf =
            oriented::oriented_frf(&p, &cut, &freqs, Some(&vars), rfe::frf::Method::Auto).unwrap();
        let br = lobes::branches(&process, &frf);
        let pts = lobes::boundary(&br, 1, &speeds);
        (frf, br, pts)
    };
    let (frf, br, pts) = solve(&x0);
    let grads: Vec<Vec<f64>> = pts
        .iter()
        .map(|p| lobes::depth_gradient(&process, &frf, &br, 1, p))
        .collect();
    let mut compared = 0;
    for v in 0..x0.len() {
        let h = 1e-6 * x0[v];
        let mut xp = x0.clone();
        xp[v] += h;
        let mut xm = x0.clone();
        xm[v] -= h;
        let (_, _, pp) = solve(&xp);
        let (_, _, pm) = solve(&xm);
        for (i, p) in pts.iter().enumerate() {
            let same = |q: &lobes::BoundaryPoint| q.line == p.line && q.lobe == p.lobe;
            if !(p.depth.is_finite() && same(&pp[i]) && same(&pm[i])) {
                continue;
            }
            let fd = (pp[i].depth - pm[i].depth) / (2.0 * h);
            let g = grads[i][v];
            assert!(
                (g - fd).abs() <= 1e-4 * fd.abs().max(1e-3 * p.depth / x0[v]),
                "{} rpm, variable {v}: analytic {g:e} vs finite difference {fd:e}",
                p.speed_rpm
            );
            compared += 1;
        }
    }
    assert!(compared >= 60, "only {compared} points compared");
}

/// Linear band against Monte Carlo: where the boundary is smooth the two 5–95 % widths agree.
#[test]
fn linear_band_agrees_with_monte_carlo() {
    let model = two_mass();
    let vars = two_mass_vars(&model);
    let x0: Vec<f64> = vars
        .vars
        .iter()
        .map(|v| model.value(v.targets[0].param).unwrap())
        .collect();
    let vars = at(&vars, &x0);
    // 3 % and 4 % standard errors, correlation −0.6 (a typical pair of springs in series).
    let s = [0.03 * x0[0], 0.04 * x0[1]];
    let rho = -0.6;
    let cov = DMatrix::from_row_slice(
        2,
        2,
        &[
            s[0] * s[0],
            rho * s[0] * s[1],
            rho * s[0] * s[1],
            s[1] * s[1],
        ],
    );
    let cut = turning_cut("second", [0.0, 0.0, 1.0], (100.0, 1500.0), 100);
    let l = stability::lobes(&Request {
        uncertainty: Some(Uncertainty {
            variables: &vars,
            covariance: &cov,
        }),
        ..Request::new(&model, &cut)
    })
    .unwrap();
    let band = l.band.as_ref().unwrap();
    let placement = oriented::place(&model, &cut).unwrap();
    let (mc, skipped) = bands::monte_carlo(
        &placement,
        &cut,
        &l.freqs_hz,
        &bands::Sampling {
            variables: &vars,
            covariance: &cov,
            samples: 400,
            seed: 11,
        },
    )
    .unwrap();
    assert_eq!(skipped, 0);
    let mut ratios: Vec<f64> = (0..l.points.len())
        .filter(|&i| l.points[i].depth.is_finite() && band.sigma[i] > 0.0)
        .map(|i| (mc.upper[i] - mc.lower[i]) / (band.upper[i] - band.lower[i]))
        .collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    assert!(
        (0.85..1.18).contains(&median),
        "median Monte Carlo / linear width {median}"
    );
    // The band brackets the boundary, and the bands' centres agree to a fraction of the width.
    let i = l.minimum;
    assert!(band.lower[i] < l.points[i].depth && l.points[i].depth < band.upper[i]);
    let mid = |b: &bands::Band| 0.5 * (b.lower[i] + b.upper[i]);
    assert!(
        (mid(band) - mid(&mc)).abs() < 0.25 * (band.upper[i] - band.lower[i]),
        "centres {} vs {}",
        mid(band),
        mid(&mc)
    );
}

/// The band from an identification on synthetic data shrinks with the data's noise (σ of the
/// estimates ∝ the noise, so the band's width ∝ the noise: 4× less noise, about 4× narrower).
#[test]
fn the_band_shrinks_as_the_data_noise_shrinks() {
    let truth = two_mass();
    let vars = two_mass_vars(&truth);
    let cut = turning_cut("second", [0.0, 0.0, 1.0], (100.0, 1500.0), 100);
    let width = |noise: f64| {
        let mut rng = StdRng::seed_from_u64(5);
        let measured =
            synthetic::amplitude_data(&truth, &synthetic::log_lines(5.0, 60.0, 40), noise, || {
                StandardNormal.sample(&mut rng)
            })
            .unwrap();
        let obs = data::validate(&measured, &truth, "synthetic").unwrap();
        let id = idn::identify(
            &truth,
            &obs,
            &vars,
            &idn::Options::default(),
            &mut |_, _| {},
        )
        .unwrap();
        assert!(id.stop.converged());
        let mut model = truth.clone();
        vars.apply(&mut model, &id.estimate);
        let v = at(&vars, &id.estimate);
        let l = stability::lobes(&Request {
            uncertainty: Some(Uncertainty {
                variables: &v,
                covariance: &id.uncertainty.covariance,
            }),
            ..Request::new(&model, &cut)
        })
        .unwrap();
        let b = l.band.unwrap();
        b.upper[l.minimum] - b.lower[l.minimum]
    };
    let (wide, narrow) = (width(0.02), width(0.005));
    let ratio = wide / narrow;
    assert!(
        (2.5..6.5).contains(&ratio),
        "band width at 2 % noise {wide:e} m, at 0.5 % {narrow:e} m: ratio {ratio}"
    );
}
