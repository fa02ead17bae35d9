//! A 32-start identification of a 10-body model on 1000 lines: a ten-storey shear frame of the
//! `examples/real-three-storey` kind (ten 5.2 kg floors, one general SDE per storey), force on
//! floor 1, displacements of floors 1, 5 and 10 at 1000 log-spaced lines over 0.5-40 Hz (1 %
//! noise, seed 10), eleven variables (ten storey sway stiffnesses, one ψ) from the written
//! start, 31 extra starts of `identification::starts::latin_hypercube`. Wall time of the whole
//! multi-start fit, and the same fit in Python in the same run: `bench/python/multistart_scipy.py`
//! (numpy FRF of the exported problem + `scipy.optimize.least_squares` with the same adjoint
//! Jacobian from the same 32 start points), and the ratio.
//!
//! `cargo bench --profile test -p identify --bench multistart` (python3 with numpy and scipy; the
//! Python side reports why when it cannot run).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use identify::{self as idn, data, starts, variables, Options};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

const FLOORS: usize = 10;
const STARTS: usize = 32;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The ten-storey frame as a model file, storey sway stiffnesses `k` (N/m).
fn frame(k: &[f64]) -> String {
    let mut s = String::from("name = \"ten-storey frame\"\n");
    for f in 0..FLOORS {
        s += &format!(
            "[[body]]\nname = \"floor {}\"\nmass = \"5.2 kg\"\nposition = [0.0, 0.0, {}]\ninertia = \"0.0392 0.0392 0.0780 kg m^2\"\n",
            f + 1,
            0.2 + 0.18 * f as f64
        );
    }
    for (f, kf) in k.iter().enumerate() {
        let lower = if f == 0 {
            "ground".to_string()
        } else {
            format!("floor {f}")
        };
        s += &format!(
            "[[sde]]\nname = \"storey {}\"\nkind = \"general\"\nbodies = [\"{lower}\", \"floor {}\"]\npoint = [0.0, 0.0, {}]\naxes = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nk = [{kf}, 3.65e6, 1.37e8, 3.08e6, 3.08e6, 8.3e4]\npsi = 0.03\n",
            f + 1,
            f + 1,
            0.11 + 0.18 * f as f64
        );
    }
    s += "[[excitation.force]]\nbody = \"floor 1\"\nforce = [1.0, 0.0, 0.0]\n";
    for f in [1, 5, 10] {
        s += &format!("[[output]]\nbody = \"floor {f}\"\ndof = \"u1\"\n");
    }
    s
}

fn main() {
    let truth_k: Vec<f64> = (0..FLOORS)
        .map(|i| 52.5e3 * (0.75 + 0.05 * i as f64))
        .collect();
    let truth = rfe::modelfile::parse_toml(&frame(&truth_k), "truth.toml")
        .expect("truth")
        .model;
    let model = rfe::modelfile::parse_toml(&frame(&[52.5e3; FLOORS]), "frame.toml")
        .expect("model")
        .model;
    let mut vars_text = String::new();
    for f in 1..=FLOORS {
        vars_text += &format!(
            "[[variable]]\nname = \"k storey {f}\"\nsdes = \"storey {f}\"\nparameter = \"k1\"\n"
        );
    }
    vars_text +=
        "[[variable]]\nname = \"psi\"\nsdes = \"1-10\"\nparameter = \"psi1\"\ninitial = 0.025\n";
    let vars_text = vars_text.replace(
        "sdes = \"1-10\"",
        &format!(
            "sdes = [{}]",
            (1..=FLOORS)
                .map(|f| format!("\"storey {f}\""))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    );
    let vars = variables::parse(&vars_text, "vars.toml", &model).expect("variables");
    let mut rng = StdRng::seed_from_u64(10);
    let lines = idn::synthetic::log_lines(0.5, 40.0, 1000);
    let d =
        idn::synthetic::amplitude_data(&truth, &lines, 0.01, || StandardNormal.sample(&mut rng))
            .expect("truth solves");
    let obs = data::validate(&d, &model, "bench").expect("data");
    let opts = Options {
        starts: STARTS,
        seed: 1,
        ..Options::default()
    };

    let t = Instant::now();
    let id = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {}).expect("identification");
    let ti = t.elapsed().as_secs_f64();
    let analysis = starts::analyse(&id);
    let iterations: usize = id.starts.iter().map(|s| s.iterations).sum();
    println!(
        "ident, {STARTS} starts, {} bodies, {} variables, {} observations: {:.2} s; {iterations} iterations, {} model evaluations ({} with Jacobian); best J {:.6e}; {} distinct optima, the best reached by {} starts",
        model.bodies.len(), vars.len(), obs.points(), ti, id.evaluations.model,
        id.evaluations.with_jacobian, id.criterion, analysis.optima.len(),
        analysis.optima.first().map_or(0, |o| o.starts.len())
    );

    for (k, o) in analysis.optima.iter().take(6).enumerate() {
        let far = o
            .estimate
            .iter()
            .zip(&id.estimate)
            .zip(&id.uncertainty.std_error)
            .map(|((a, b), s)| (a - b).abs() / s)
            .fold(0.0, f64::max);
        println!(
            "  optimum {}: J {:.6e}, {} start(s), farthest variable {:.1} standard errors from the best",
            k + 1,
            o.criterion,
            o.starts.len(),
            far
        );
    }
    for w in &analysis.warnings {
        println!("  warning: {w}");
    }
    let dir = std::env::temp_dir().join(format!("ident-bench-multistart-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let problem = dir.join("problem.json");
    let start_file = dir.join("starts.json");
    std::fs::write(
        &problem,
        serde_json::to_string(&idn::problem::to_json(&model, &obs, &vars, &opts).expect("problem"))
            .expect("json"),
    )
    .expect("write");
    std::fs::write(
        &start_file,
        serde_json::to_string(&starts::latin_hypercube(&vars, STARTS, opts.seed)).expect("json"),
    )
    .expect("write");
    let script = root().join("bench/python/multistart_scipy.py");
    if std::env::var_os("IDENT_BENCH_NO_SCIPY").is_some() {
        println!("scipy side skipped (IDENT_BENCH_NO_SCIPY is set)");
        let _ = std::fs::remove_dir_all(&dir);
        return;
    }
    match Command::new("python3")
        .arg(&script)
        .arg(&problem)
        .arg(&start_file)
        .output()
    {
        Ok(out) if out.status.success() => {
            let v: serde_json::Value =
                serde_json::from_str(String::from_utf8_lossy(&out.stdout).trim()).expect("JSON");
            let tp = v["seconds"].as_f64().unwrap_or(f64::NAN);
            println!(
                "scipy least_squares (numpy FRF, analytic Jacobian), the same {STARTS} starts: {:.2} s; {} residual + {} Jacobian evaluations; best J {:.6e} (ident {:.6e}); ratio scipy/ident = {:.1}",
                tp, v["nfev"], v["njev"], v["best_cost"].as_f64().unwrap_or(f64::NAN), id.criterion, tp / ti
            );
        }
        Ok(out) => println!(
            "scipy side FAILED: {}",
            String::from_utf8_lossy(&out.stderr)
        ),
        Err(e) => println!("scipy side NOT RUN: python3 could not be started ({e})"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}
