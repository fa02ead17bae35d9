//! `ident modes-from-data` on a UFF58 file of a known 3-mode system (3 responses × 2 references):
//! the printed table, the JSON poles (frequencies and damping to 1e-6, shapes by MAC) and the SVG
//! stabilization diagram; a file that does not say its FRF kind is refused without --kind.
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

use process::uff::{self, Encoding, Function};
use process::C64;
use std::f64::consts::PI;
use std::process::{Command, Output};

const FREQS: [f64; 3] = [42.0, 97.5, 161.0];
const ZETAS: [f64; 3] = [0.015, 0.02, 0.03];
const PHI: [[f64; 3]; 3] = [[0.33, 0.59, 0.74], [0.74, 0.33, -0.59], [0.59, -0.74, 0.33]];
const PART: [[f64; 2]; 3] = [[0.33, 0.74], [0.74, -0.59], [0.59, 0.33]];

/// `ident modes-from-data FILE --band 20:220 --max-order 20`, then `extra`.
fn modes_in_band(file: &std::path::Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(["modes-from-data", file.to_str().unwrap()])
        .args(["--band", "20:220", "--max-order", "20"])
        .args(extra)
        .output()
        .unwrap()
}

fn write_uff(path: &std::path::Path, spec_data_type: i64) {
    let (f0, df, n) = (0.0, 0.25, 1001);
    let mut functions = Vec::new();
    for o in 0..3 {
        for r in 0..2 {
            let h: Vec<C64> = (0..n)
                .map(|k| {
                    let s = C64::new(0.0, 2.0 * PI * (f0 + df * k as f64));
                    (0..3)
                        .map(|m| {
                            let w = 2.0 * PI * FREQS[m];
                            let lam =
                                C64::new(-ZETAS[m] * w, w * (1.0 - ZETAS[m] * ZETAS[m]).sqrt());
                            let a =
                                C64::new(PHI[m][o] * PART[m][r], 0.0) / C64::new(0.0, 2.0 * lam.im);
                            a / (s - lam) + a.conj() / (s - lam.conj())
                        })
                        .sum::<C64>()
                })
                .collect();
            let mut f = Function::frf(&format!("H{o}{r}"), f0, df, h);
            f.double = true;
            f.response_node = 10 + o as i64;
            f.response_dir = 3;
            f.reference_node = 1 + r as i64;
            f.reference_dir = 3;
            f.axes[1].spec_data_type = spec_data_type;
            functions.push(f);
        }
    }
    uff::write(path, &functions, Encoding::Ascii).unwrap();
}

#[test]
fn modes_from_uff_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("frf.uff");
    write_uff(&file, 8);
    let (svg, json) = (dir.path().join("stab.svg"), dir.path().join("modes.json"));
    let out = modes_in_band(
        &file,
        &[
            "--svg",
            svg.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ],
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("3 × 2 receptance FRFs"), "{stdout}");
    for f in FREQS {
        assert!(
            stdout.contains(&format!("{f:.4}")),
            "{f} Hz missing:\n{stdout}"
        );
    }
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let modes = doc["modes"].as_array().unwrap();
    assert_eq!(modes.len(), 3);
    for (m, mode) in modes.iter().enumerate() {
        let f = mode["freq_hz"].as_f64().unwrap();
        let z = mode["damping_ratio"].as_f64().unwrap();
        assert!((f - FREQS[m]).abs() <= 1e-6 * FREQS[m], "f {f}");
        assert!((z - ZETAS[m]).abs() <= 1e-6 * ZETAS[m], "ζ {z}");
        assert!((mode["loss_factor"].as_f64().unwrap() - 2.0 * z).abs() < 1e-15);
        let shape: Vec<C64> = mode["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| C64::new(v[0].as_f64().unwrap(), v[1].as_f64().unwrap()))
            .collect();
        let truth: Vec<C64> = PHI[m].iter().map(|&v| C64::new(v, 0.0)).collect();
        let mac = process::modal::mac(&[shape], &[truth])[0][0];
        assert!(mac > 1.0 - 1e-9, "MAC {mac}");
    }
    assert_eq!(doc["stabilization"].as_array().unwrap().len(), 20);
    assert_eq!(doc["responses"][2], "12:3");
    let svg = std::fs::read_to_string(&svg).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("Stabilization diagram"));

    // The user's override picks the same poles.
    let out = modes_in_band(&file, &["--freqs", "40,100,158"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    for f in FREQS {
        assert!(
            stdout.contains(&format!("{f:.4}")),
            "{f} Hz missing:\n{stdout}"
        );
    }
}

#[test]
fn unknown_kind_needs_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("frf.uff");
    write_uff(&file, 0);
    let out = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(["modes-from-data", file.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--kind") && err.contains("frf.uff"), "{err}");
    let out = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args([
            "modes-from-data",
            file.to_str().unwrap(),
            "--kind",
            "receptance",
            "--max-order",
            "20",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The FRFs of a repository data file whose (response node, reference node) pass `keep`, written
/// to `out` (UFF58, binary).
fn subset(rel: &str, out: &std::path::Path, keep: impl Fn(i64, i64) -> bool) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(rel);
    let file = uff::read_file(&path).unwrap();
    let functions: Vec<Function> = file
        .functions
        .into_iter()
        .filter(|f| keep(f.response_node, f.reference_node))
        .collect();
    assert!(!functions.is_empty());
    uff::write(out, &functions, Encoding::Binary).unwrap();
}

fn run_ident(args: &[&str]) -> (Output, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ident"))
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    (out, stdout, stderr)
}

/// Issue 42: real hammer-test FRFs with one accelerometer and the hammer roved over five points
/// (one response node, five reference nodes) gave one mode; the polynomial now sits on the one
/// response (FRFs transposed by reciprocity, said in the output and the JSON) and the beam's four
/// clear bending modes come out, with their uncertainty and quality indicators.
#[test]
fn roving_hammer_file_gives_the_clear_modes() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("hammer.uff");
    subset("sdypy-beam/beam-hammer.uff", &file, |r, q| {
        r == 2 && q <= 15
    });
    let json = dir.path().join("modes.json");
    let (out, stdout, stderr) = run_ident(&[
        "modes-from-data",
        file.to_str().unwrap(),
        "--band",
        "10:2000",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("roving hammer") && stdout.contains("transposed by reciprocity"),
        "{stdout}"
    );
    assert!(stdout.contains("5 × 1 accelerance FRFs"), "{stdout}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(doc["layout"]["kind"], "roving hammer");
    assert_eq!(doc["layout"]["transposed_by_reciprocity"], true);
    assert_eq!(doc["layout"]["polynomial_side"], "responses");
    assert_eq!(doc["responses"][0], "2:3");
    assert_eq!(doc["shapes_over"].as_array().unwrap().len(), 5);
    let modes = doc["modes"].as_array().unwrap();
    for f in [177.0, 477.0, 933.0, 1535.0] {
        let m = modes
            .iter()
            .find(|m| (m["freq_hz"].as_f64().unwrap() - f).abs() < 0.01 * f)
            .unwrap_or_else(|| panic!("mode near {f} Hz missing:\n{stdout}"));
        let sf = m["freq_std_hz"].as_f64().unwrap();
        let sz = m["damping_std"].as_f64().unwrap();
        assert!(sf > 0.0 && sf < 0.01 * f, "σf {sf}");
        assert!(
            sz > 0.0 && sz < m["damping_ratio"].as_f64().unwrap(),
            "σζ {sz}"
        );
        let mpc = m["mpc"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&mpc) && m["mpd_deg"].as_f64().unwrap() >= 0.0);
        assert_eq!(m["shape"].as_array().unwrap().len(), 5);
    }
}

/// A grid with a hole, and unit-modal-mass shapes without a driving point, are refused with what
/// is missing; with a driving point (the three-storey structure's floor 1) the scaled shapes come.
#[test]
fn unusable_sets_are_refused_with_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("holes.uff");
    subset("sdypy-beam/beam-hammer.uff", &file, |r, q| {
        r <= 2 && q <= 13 && !(r == 2 && q == 12)
    });
    let (out, _, stderr) = run_ident(&["modes-from-data", file.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("2:3 ← 12:3") && stderr.contains("holes.uff"),
        "{stderr}"
    );

    let file = dir.path().join("row.uff");
    subset("sdypy-beam/beam-hammer.uff", &file, |r, q| {
        r == 1 && q <= 13
    });
    let (out, _, stderr) = run_ident(&[
        "modes-from-data",
        file.to_str().unwrap(),
        "--mass-normalize",
    ]);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("driving point") && stderr.contains("1:3"),
        "{stderr}"
    );

    let file = dir.path().join("storey.uff");
    subset(
        "dtop-three-storey/three-storey-hammer.uff",
        &file,
        |r, _| r == 1,
    );
    let json = dir.path().join("storey.json");
    let (out, stdout, stderr) = run_ident(&[
        "modes-from-data",
        file.to_str().unwrap(),
        "--band",
        "2:40",
        "--mass-normalize",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(doc["layout"]["driving_points"][0], "1:1");
    let scaled = doc["modes"][0]["shape_unit_modal_mass"].as_array().unwrap();
    assert_eq!(scaled.len(), 3);
}
