//! Helpers shared by the identify crate's integration tests: the repository's model files and the
//! synthetic FWD-32J measurement.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used, dead_code)]

use std::path::PathBuf;

use identify::{self as idn, data, synthetic, variables};
use identify::{FitKind, NoiseChoice, Options, Settings};
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::frf::{self, Method};
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::model::{Model, Param};

/// The repository's root folder.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A model of `configs/models/`, e.g. `fwd32j.toml`; panics naming the file when it cannot load.
pub fn load_model(name: &str) -> Model {
    let p = repo().join("configs/models").join(name);
    rfe::modelfile::load(&p)
        .unwrap_or_else(|e| panic!("the model {} is needed by this test: {e}", p.display()))
        .model
}

/// A variables file of `configs/identification/`, e.g. `fwd32j.toml`, against `model`; panics
/// naming the file when it cannot load.
pub fn load_variables(name: &str, model: &Model) -> variables::Variables {
    let p = repo().join("configs/identification").join(name);
    variables::load(&p, model)
        .unwrap_or_else(|e| panic!("the variables {} are needed by this test: {e}", p.display()))
}

/// The synthetic FWD-32J measurement (`identification::synthetic`): 38 log-spaced lines over
/// 20-400 Hz per characteristic, multiplicative Gaussian noise of relative σ `rel`, variances
/// stated.
pub fn fwd32j_data(truth: &Model, rel: f64, rng: &mut StdRng) -> MeasuredData {
    synthetic::amplitude_data(truth, &synthetic::fwd32j_lines(), rel, || {
        StandardNormal.sample(&mut *rng)
    })
    .expect("truth FRF")
}

/// The variables file of the textbook two-mass chain: k1, k2 and their common ψ.
pub const TWO_MASS_PSI_VARS: &str =
    include_str!("../../../configs/identification/textbook-two-mass-psi.toml");

/// A model file of one 250 kg body on a six-spring element to the ground at its centre of mass
/// (3·10⁶ N/m along each axis, 3·10⁴ N·m/rad about each, ψ = 0.3), loaded by 1 N along z, its
/// first output the body's u3: the part the model-file tests append their `[[reference]]`s and
/// further `[[output]]`s to.
pub const ONE_BODY_ON_A_SPRING: &str = r#"
name = "one body on a spring"
[[body]]
name = "mass"
mass = "250 kg"
position = [0.0, 0.0, 0.0]
inertia = "25 50 75 kg m^2"
[[sde]]
name = "spring"
kind = "general"
bodies = ["ground", "mass"]
point = [0.0, 0.0, 0.0]
axes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
k = ["3e6 N/m", "3e6 N/m", "3e6 N/m", "3e4 N*m/rad", "3e4 N*m/rad", "3e4 N*m/rad"]
psi = 0.3
[[excitation.force]]
body = "mass"
force = [0.0, 0.0, 1.0]
[[output]]
body = "mass"
dof = "u3"
"#;

/// `model`'s outputs as exact complex data at 40 lines over 10-60 Hz; with `relative_sigma` ε,
/// each point's variance is `(ε |q|)²` (none without).
pub fn exact(model: &Model, relative_sigma: Option<f64>) -> MeasuredData {
    let f: Vec<f64> = (0..40).map(|i| 10.0 + 50.0 * i as f64 / 39.0).collect();
    let r = frf::response(model, &f, &[], Method::Direct).unwrap();
    MeasuredData {
        source: "exact".into(),
        characteristics: model
            .outputs
            .iter()
            .enumerate()
            .map(|(o, c)| Measurement {
                body: model.bodies[c.body].name.clone(),
                dof: c.dof,
                quantity: QuantityName::from(c.quantity),
                freqs_hz: f.clone(),
                amplitude: r.output(o).iter().map(|v| v.norm()).collect(),
                phase_rad: Some(r.output(o).iter().map(|v| v.arg()).collect()),
                variance: relative_sigma.map(|eps| {
                    r.output(o)
                        .iter()
                        .map(|v| (eps * v.norm()).powi(2))
                        .collect()
                }),
                coherence: None,
                averages: None,
                at: c.at,
                reference: (c.reference > 0).then(|| model.reference_name(c.reference).to_string()),
                relative: c.relative,
            })
            .collect(),
    }
}

/// The complex fit of the two-mass chain's k1, k2 and ψ ([`TWO_MASS_PSI_VARS`]) to `measured`,
/// `model`'s outputs completed by the data's, with the `noise` model and up to 300 iterations;
/// asserts that it converged.
pub fn fit_two_mass(
    model: &Model,
    measured: &MeasuredData,
    noise: NoiseChoice,
) -> idn::Identification {
    let model = data::with_measured_outputs(model, measured);
    let obs = data::validate(measured, &model, "exact").unwrap();
    let vars = variables::parse(TWO_MASS_PSI_VARS, "vars.toml", &model).unwrap();
    let opts = Options {
        fit: FitKind::Complex,
        noise,
        settings: Settings {
            max_iterations: 300,
            ..Settings::default()
        },
        ..Options::default()
    };
    let id = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {}).unwrap();
    assert!(id.stop.converged(), "{}", id.stop.describe());
    id
}

/// The default identification of `vars` against `obs`, starting from `model`, with the noise
/// taken as 1 % of each amplitude: the fit of exact data, which states no variances of its own.
pub fn identify_at_one_percent_noise(
    model: &Model,
    obs: &data::Observations,
    vars: &variables::Variables,
) -> idn::Identification {
    idn::identify(
        model,
        obs,
        vars,
        &Options {
            noise: NoiseChoice::Relative(0.01),
            ..Options::default()
        },
        &mut |_, _| {},
    )
    .unwrap()
}

/// `(estimate − truth)/SE` per variable of `id`, `xt` the truth; each variable printed as a row
/// of a "truth vs identified" table in its display unit (truth, initial, identified, standard
/// error, deviation).
pub fn deviations_from_truth(id: &idn::Identification, xt: &[f64]) -> Vec<f64> {
    id.variables
        .vars
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let se = id.uncertainty.std_error[i];
            let z = (id.estimate[i] - xt[i]) / se;
            let f = v.unit.factor;
            println!(
                "{:<22} truth {:>10.5} initial {:>10.5} identified {:>10.5} se {:>10.5} ({z:+.2} se)",
                v.name,
                xt[i] / f,
                id.initial[i] / f,
                id.estimate[i] / f,
                se / f
            );
            z
        })
        .collect()
}

/// Every column of `model`'s Jacobian for `params` at `freqs` (Hz), on both solve paths, against
/// central differences of the direct response (step 10⁻⁶ of the value, of 10⁻³ at least): the
/// difference may be 10⁻⁵ of the column plus `floor` × the output's largest value over the
/// parameter's value (10⁻³ at least).
pub fn assert_jacobian_matches_central_differences(
    model: &Model,
    params: &[Param],
    freqs: &[f64],
    floor: f64,
) {
    for method in [Method::Direct, Method::Modal] {
        let r = frf::response_params(model, freqs, params, method).unwrap();
        for (pi, &p) in params.iter().enumerate() {
            let v = model.value(p).unwrap();
            let h = 1e-6 * v.abs().max(1e-3);
            let at = |x: f64| {
                let mut m = model.clone();
                assert!(m.set_value(p, x));
                frf::response(&m, freqs, &[], Method::Direct).unwrap()
            };
            let (plus, minus) = (at(v + h), at(v - h));
            for o in 0..model.outputs.len() {
                let scale = r.output(o).iter().map(|z| z.norm()).fold(0.0, f64::max);
                for k in 0..freqs.len() {
                    let fd = (plus.output(o)[k] - minus.output(o)[k]) / (2.0 * h);
                    let an = r.derivative(pi, o)[k];
                    assert!(
                        (fd - an).norm() <= 1e-5 * an.norm() + floor * scale / v.abs().max(1e-3),
                        "{method:?} {} output {o} line {k}: analytic {an}, finite difference {fd}",
                        model.label(p)
                    );
                }
            }
        }
    }
}
