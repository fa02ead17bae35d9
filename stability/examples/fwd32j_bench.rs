//! Benchmark: FWD-32J face-milling lobes (zeroth-order approximation, 200 spindle speeds, 4000
//! FRF lines) with and without the linear band, against the independent numpy/scipy
//! implementation of `tests/python/stability_zoa.py` measured in the same run (its own timer,
//! after reading its files, the same work as the lobes without band).
//!
//! `cargo run --release -p stability --example fwd32j_bench`

// A benchmark's setup unwraps: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use nalgebra::DMatrix;
use stability::{Request, Uncertainty};

const REPEATS: usize = 7;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let model_path = root.join("configs/models/fwd32j.toml");
    let cut_path = root.join("configs/cuts/fwd32j-face-milling.toml");
    let model = rfe::modelfile::load(&model_path).unwrap().model;
    let cut = stability::cut::load(&cut_path).unwrap();
    let mut vars =
        identify::variables::load(&root.join("configs/identification/fwd32j.toml"), &model)
            .unwrap();
    // The variables at the model's values, with 5 % standard errors (the timing does not depend
    // on the values).
    for v in &mut vars.vars {
        let t = v.targets[0];
        v.initial = model.value(t.param).unwrap_or(0.0) / t.ratio;
    }
    let x = vars.initial();
    let cov = DMatrix::from_fn(x.len(), x.len(), |i, j| {
        if i == j {
            (0.05 * x[i]).powi(2)
        } else {
            0.0
        }
    });
    let plain = Request::new(&model, &cut);
    let banded = Request {
        uncertainty: Some(Uncertainty {
            variables: &vars,
            covariance: &cov,
        }),
        ..plain
    };
    let time = |r: &Request| {
        median(
            (0..REPEATS)
                .map(|_| {
                    let t = Instant::now();
                    let l = stability::lobes(r).unwrap();
                    std::hint::black_box(l);
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        )
    };
    let ours = time(&plain);
    let ours_band = time(&banded);

    let dir = std::env::temp_dir().join(format!("stability-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("fwd32j.json");
    std::fs::write(
        &json,
        serde_json::to_string(&rfe::contract::to_json(&model)).unwrap(),
    )
    .unwrap();
    let numpy = median(
        (0..3)
            .map(|_| {
                let o = Command::new("python3")
                    .arg(root.join("tests/python/stability_zoa.py"))
                    .arg(&json)
                    .arg(&cut_path)
                    .output()
                    .expect("python3 with numpy and scipy (.ci/requirements.txt)");
                assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
                let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
                v["seconds"].as_f64().unwrap()
            })
            .collect(),
    );
    let _ = std::fs::remove_dir_all(&dir);
    println!(
        "FWD-32J face milling, {} speeds, {} lines, {} variables (medians)",
        cut.speeds,
        cut.lines,
        vars.len()
    );
    println!("  ident lobes:               {:8.1} ms", ours * 1e3);
    println!("  ident lobes + linear band: {:8.1} ms", ours_band * 1e3);
    println!("  numpy/scipy lobes:         {:8.1} ms", numpy * 1e3);
    println!(
        "  numpy / ident: lobes x{:.1}, lobes + band x{:.1}",
        numpy / ours,
        numpy / ours_band
    );
}
