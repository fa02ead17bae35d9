//! Helpers shared by the integration tests that cross-check against Python.
#![allow(clippy::unwrap_used, missing_docs)]
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `python3` with the given script and arguments; panics with a clear message if Python or
/// a needed package is missing (never passes silently).
pub fn python(script: &str, args: &[&str], modules: &str) {
    let probe = Command::new("python3")
        .args(["-c", &format!("import {modules}")])
        .output();
    match probe {
        Ok(o) if o.status.success() => {}
        Ok(o) => panic!(
            "python3 lacks the modules '{modules}' ({}): run `.ci/setup` (installs .ci/requirements.txt)",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => panic!("python3 not found ({e}): run `.ci/setup` to install Python and .ci/requirements.txt"),
    }
    let path = script_path(script);
    let out = Command::new("python3")
        .arg(&path)
        .args(args)
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "{} failed: {}\n(if a module is missing, run `.ci/setup`)",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

pub fn script_path(script: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python")
        .join(script)
}

pub fn write_f64(path: &Path, data: &[f64]) {
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(path, bytes).expect("write signal file");
}

pub fn read_f64(path: &Path) -> Vec<f64> {
    let b = std::fs::read(path).expect("read python output");
    b.chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

/// Seeded white noise.
pub fn noise(seed: u64, n: usize, sd: f64) -> Vec<f64> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let d = rand_distr::Normal::new(0.0, sd).unwrap();
    (0..n).map(|_| rng.sample(d)).collect()
}

/// Output of a 2nd-order resonant IIR filter (a known FRF) driven by x.
pub fn resonator(x: &[f64], b: [f64; 3], a: [f64; 2]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for n in 0..x.len() {
        let xm1 = if n >= 1 { x[n - 1] } else { 0.0 };
        let xm2 = if n >= 2 { x[n - 2] } else { 0.0 };
        let ym1 = if n >= 1 { y[n - 1] } else { 0.0 };
        let ym2 = if n >= 2 { y[n - 2] } else { 0.0 };
        y[n] = b[0] * x[n] + b[1] * xm1 + b[2] * xm2 - a[0] * ym1 - a[1] * ym2;
    }
    y
}

/// The filter's exact FRF at normalized frequency f/fs.
pub fn resonator_frf(b: [f64; 3], a: [f64; 2], f_over_fs: f64) -> num_complex::Complex<f64> {
    let z1 = num_complex::Complex::from_polar(1.0, -2.0 * std::f64::consts::PI * f_over_fs);
    let z2 = z1 * z1;
    (b[0] + z1 * b[1] + z2 * b[2]) / (1.0 + z1 * a[0] + z2 * a[1])
}

/// Poles of `data` in `band` picked automatically from LSCF orders 1..=`order` (stable over
/// `min_orders`, default tolerances, damping below 0.2), printed as (frequency, damping ratio).
pub fn auto_poles(
    data: &process::modal::ModalData,
    band: (f64, f64),
    order: usize,
    min_orders: usize,
) -> Vec<process::modal::Pole> {
    use process::modal::{lscf, select_auto, stabilize, LscfSettings, SelectionSettings};
    let orders = lscf(
        data,
        &LscfSettings {
            max_order: order,
            band_hz: Some(band),
        },
    )
    .unwrap();
    let diagram = stabilize(orders, process::modal::StabilityTolerances::default());
    let poles = select_auto(
        &diagram,
        &SelectionSettings {
            band_hz: band,
            min_orders,
            max_damping: 0.2,
        },
    );
    eprintln!(
        "ident: {:?}",
        poles
            .iter()
            .map(|p| (p.freq_hz, p.damping_ratio))
            .collect::<Vec<_>>()
    );
    poles
}
