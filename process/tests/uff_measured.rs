//! Vendor FRF files into identification: pyuff writes the same FRFs as receptance (m/N, ASCII),
//! mobility ((mm/s)/N, 58b little endian) and accelerance (g/N, 58b big endian, after a dataset
//! ident skips); ident reads them through a measurement map, and CSV files declaring the same
//! three units; every form gives the same data and the same estimates.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use identify::frf::{self, Method};
use identify::identification::{self as idn, data, measurement_map, variables, Options};
use identify::model::Model;
use identify::textbook;
use identify::MeasuredData;
use process::uff;
use process::C64;
use std::f64::consts::PI;
use std::path::Path;

const MAP: &str = r#"
[[channel]]
node = 1
dir = "+Z"
body = "first"
point = "0 0 0 mm"

[[channel]]
node = 2
dir = "Z"
body = "second"
"#;

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm, and their common ψ at 0.3.
const VARS: &str = include_str!("../../configs/identification/textbook-two-mass-psi.toml");

/// The textbook chain with a 4 kN excitation (so "per N" must be scaled), and its measured
/// receptances per N at 60 uneven lines with 1 % seeded noise.
fn case() -> (Model, Vec<f64>, Vec<Vec<C64>>) {
    let mut m = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    m.forces[0].force *= 4000.0;
    let f: Vec<f64> = (0..60)
        .map(|i| 8.0 + 0.9 * i as f64 + 0.01 * (i % 3) as f64)
        .collect();
    let r = frf::response(&m, &f, &[], Method::Direct).unwrap();
    let noise = common::noise(7, 4 * f.len(), 0.01);
    let h = (0..2)
        .map(|o| {
            r.output(o)
                .iter()
                .enumerate()
                .map(|(k, z)| {
                    let e = C64::new(
                        noise[(2 * o) * f.len() + k],
                        noise[(2 * o + 1) * f.len() + k],
                    );
                    z * (C64::new(1.0, 0.0) + e) / 4000.0
                })
                .collect()
        })
        .collect();
    (m, f, h)
}

fn from_uff(path: &Path, model: &Model, map: &str) -> MeasuredData {
    let file = uff::read_file(path).unwrap();
    let (channels, notes) = uff::measured_channels(&file, "test.uff").unwrap();
    let map = measurement_map::parse(map, "map.toml", model).unwrap();
    let mut d = map.apply(&channels, "test.uff", model).unwrap();
    d.source.push_str(&notes.join("; "));
    d
}

fn estimate(model: &Model, d: &MeasuredData) -> Vec<f64> {
    let obs = data::validate(d, model, "test").unwrap();
    let vars = variables::parse(VARS, "vars.toml", model).unwrap();
    let id = idn::identify(model, &obs, &vars, &Options::default(), &mut |_, _| {}).unwrap();
    assert!(id.stop.converged(), "{}", id.stop.describe());
    id.estimate
}

/// The CSV form of the receptances `h` (per N) in `unit`: `# unit = ...`, amplitude and phase.
fn csv(f: &[f64], h: &[Vec<C64>], unit: &str, scale: f64, power: i32) -> String {
    let mut s = format!(
        "# measured on the textbook chain\n# unit = {unit}\nbody,dof,freq_hz,amplitude,phase_rad\n"
    );
    for (o, body) in ["first", "second"].iter().enumerate() {
        for (k, fk) in f.iter().enumerate() {
            let v = h[o][k] * C64::new(0.0, 2.0 * PI * fk).powi(power) / scale;
            s.push_str(&format!("{body},u3,{fk:?},{:?},{:?}\n", v.norm(), v.arg()));
        }
    }
    s
}

#[test]
fn the_same_frfs_in_any_unit_and_file_give_the_same_estimates() {
    let (model, f, h) = case();
    let dir = tempfile::tempdir().unwrap();
    let mut bin = vec![f.len() as f64];
    bin.extend(&f);
    for ho in &h {
        bin.extend(ho.iter().map(|z| z.re));
        bin.extend(ho.iter().map(|z| z.im));
    }
    let inp = dir.path().join("h.bin");
    common::write_f64(&inp, &bin);
    let prefix = dir.path().join("chain");
    common::python(
        "uff_frf_units.py",
        &[inp.to_str().unwrap(), prefix.to_str().unwrap()],
        "numpy, pyuff",
    );
    let mut forms: Vec<(String, MeasuredData)> = Vec::new();
    for kind in ["receptance", "mobility", "accelerance"] {
        let path = dir.path().join(format!("chain-{kind}.uff"));
        forms.push((format!("UFF {kind}"), from_uff(&path, &model, MAP)));
    }
    // The big-endian accelerance file skipped its dataset 164 and said so.
    assert!(
        forms[2].1.source.contains("type 164"),
        "{}",
        forms[2].1.source
    );
    assert!(
        forms[2]
            .1
            .source
            .contains("accelerance in (g)/(N) converted to (m/s²)/N (× 9.80665)"),
        "{}",
        forms[2].1.source
    );
    for (unit, scale, power) in [("m/N", 1.0, 0), ("(mm/s)/N", 1e-3, 1), ("g/N", 9.80665, 2)] {
        let path = dir.path().join(format!("chain-{power}.csv"));
        std::fs::write(&path, csv(&f, &h, unit, scale, power)).unwrap();
        forms.push((
            format!("CSV {unit}"),
            data::load_for_model(&path, &model).unwrap(),
        ));
    }
    // Every form holds the measured displacements to the model's 4 kN: exactly (binary, CSV
    // with 17 digits) or to pyuff's ASCII precision (12 significant digits).
    for (name, d) in &forms {
        assert_eq!(d.characteristics.len(), 2, "{name}");
        let tol = if name == "UFF receptance" {
            1e-11
        } else {
            1e-12
        };
        for (o, m) in d.characteristics.iter().enumerate() {
            assert_eq!(
                m.quantity,
                identify::measured::QuantityName::Displacement,
                "{name}"
            );
            for (k, fk) in f.iter().enumerate() {
                assert!(
                    (m.freqs_hz[k] - fk).abs() <= 1e-12 * fk,
                    "{name}: {} vs {fk}",
                    m.freqs_hz[k]
                );
                let want = h[o][k] * 4000.0;
                let got = C64::from_polar(m.amplitude[k], m.phase_rad.as_ref().unwrap()[k]);
                assert!(
                    (got - want).norm() <= tol * want.norm(),
                    "{name} output {o} line {k}: {got} vs {want}"
                );
            }
        }
    }
    let reference = estimate(&model, &forms[0].1);
    for (t, e) in [2.0e7, 5.0e6, 0.5].iter().zip(&reference) {
        assert!((e / t - 1.0).abs() < 0.05, "estimate {e} vs truth {t}");
    }
    for (name, d) in &forms[1..] {
        let e = estimate(&model, d);
        for (a, b) in e.iter().zip(&reference) {
            assert!((a / b - 1.0).abs() < 1e-9, "{name}: {e:?} vs {reference:?}");
        }
    }
}

#[test]
fn a_file_without_units_needs_them_in_the_map() {
    let (model, f, h) = case();
    let mut fs: Vec<uff::Function> = Vec::new();
    for (k, node) in [1i64, 2].iter().enumerate() {
        fs.push(uff::Function::frf_between(
            "no units",
            f.clone(),
            h[k].clone(),
            (*node, 3),
            (9, 3),
        ));
    }
    let mut coh = uff::Function::frf("coherence", 0.0, 0.0, vec![]);
    coh.func_type = uff::function_type::COHERENCE;
    coh.abscissa = uff::Abscissa::Uneven(f.clone());
    coh.data = uff::Ordinate::Real(vec![0.9; f.len()]);
    coh.response_dir = 3;
    coh.reference_node = 9;
    coh.reference_dir = 3;
    fs.push(coh);
    let bytes = uff::to_bytes(&fs, uff::Encoding::Binary).unwrap();
    let file = uff::parse_file(&bytes, "plain.uff").unwrap();
    let (channels, notes) = uff::measured_channels(&file, "plain.uff").unwrap();
    assert_eq!(
        channels[0].coherence.as_deref(),
        Some(&vec![0.9; f.len()][..]),
        "{notes:?}"
    );
    let map = measurement_map::parse(MAP, "map.toml", &model).unwrap();
    let e = map
        .apply(&channels, "plain.uff", &model)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("plain.uff: dataset 1 (line 2)")
            && e.contains("record 9")
            && e.contains("unit = \"g/N\""),
        "{e}"
    );
    // The unit given in the map: the data are read as m/N.
    let with_unit = format!("unit = \"m/N\"\n{MAP}");
    let map = measurement_map::parse(&with_unit, "map.toml", &model).unwrap();
    let d = map.apply(&channels, "plain.uff", &model).unwrap();
    assert!(
        (d.characteristics[1].amplitude[3] - 4000.0 * h[1][3].norm()).abs()
            < 1e-12 * d.characteristics[1].amplitude[3]
    );
    assert!(
        d.source.contains("map.toml (top-level unit)"),
        "{}",
        d.source
    );
    // A map naming a node the file does not hold: the map's file, line and field.
    let bad = MAP.replace("node = 2", "node = 5");
    let map =
        measurement_map::parse(&format!("unit = \"m/N\"\n{bad}"), "map.toml", &model).unwrap();
    let e = map
        .apply(&channels, "plain.uff", &model)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("map.toml:")
            && e.contains("node 5 +Z is not in plain.uff")
            && e.contains("node 2 +Z"),
        "{e}"
    );
}

#[test]
fn a_kilohertz_abscissa_is_converted_and_a_time_abscissa_refused() {
    let (_, f, h) = case();
    let mut g = uff::Function::frf("khz", 0.0, 0.0, h[0].clone());
    g.abscissa = uff::Abscissa::Uneven(f.iter().map(|x| x / 1000.0).collect());
    g.axes[0].units = "kHz".into();
    g.axes[1].units = "m".into();
    g.axes[2].units = "N".into();
    g.response_node = 1;
    g.response_dir = 3;
    let bytes = uff::to_bytes(std::slice::from_ref(&g), uff::Encoding::Binary).unwrap();
    let file = uff::parse_file(&bytes, "khz.uff").unwrap();
    let (channels, _) = uff::measured_channels(&file, "khz.uff").unwrap();
    for (a, b) in channels[0].freqs_hz.iter().zip(&f) {
        assert!((a - b).abs() <= 1e-12 * b, "{a} vs {b}");
    }
    g.axes[0].spec_data_type = 17;
    let bytes = uff::to_bytes(&[g], uff::Encoding::Binary).unwrap();
    let file = uff::parse_file(&bytes, "time.uff").unwrap();
    let e = uff::measured_channels(&file, "time.uff")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("time.uff")
            && e.contains("dataset 1")
            && e.contains("record 8")
            && e.contains("time"),
        "{e}"
    );
}
