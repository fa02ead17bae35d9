//! Vendor FRF files into identification: pyuff writes the same FRFs as receptance (m/N, ASCII),
//! mobility ((mm/s)/N, 58b little endian) and accelerance (g/N, 58b big endian, after a dataset
//! ident skips); ident reads them through a measurement map, and CSV files declaring the same
//! three units; every form gives the same data and the same estimates.
#![allow(clippy::unwrap_used, missing_docs)]

// The Python runner and the signal helpers of process's cross-checks, shared (the scripts are
// looked up in this crate's tests/python).
#[path = "../../process/tests/common/mod.rs"]
mod common;

use identify::{self as idn, data, measurement_map, variables, Options};
use process::uff;
use process::C64;
use rfe::frf::{self, Method};
use rfe::model::Model;
use rfe::textbook;
use rfe::MeasuredData;
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
                rfe::measured::QuantityName::Displacement,
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
/// The case's FRFs as UFF58b (ident's writer) in `num`/`den` (record 9/10 labels) with the
/// values in that unit: `h` (m/N) times (jω)^power / scale.
fn uff_in(f: &[f64], h: &[Vec<C64>], num: &str, den: &str, scale: f64, power: i32) -> Vec<u8> {
    let values = h
        .iter()
        .map(|ho| {
            ho.iter()
                .zip(f)
                .map(|(z, fk)| z * C64::new(0.0, 2.0 * PI * fk).powi(power) / scale)
                .collect()
        })
        .collect();
    uff_58b("units", uff::function_type::FRF, f, values, 9, (num, den))
}

/// `values` at the lines `f`, one per response node 1, 2 along +Z against node `reference` along
/// +Z, as a UFF58b file of functions `name` of type `kind` labelled `num`/`den` (records 9/10).
fn uff_58b(
    name: &str,
    kind: u32,
    f: &[f64],
    values: Vec<Vec<C64>>,
    reference: i64,
    (num, den): (&str, &str),
) -> Vec<u8> {
    let sets: Vec<uff::Function> = [1i64, 2]
        .into_iter()
        .zip(values)
        .map(|(node, v)| {
            let mut g = uff::Function::frf_between(name, f.to_vec(), v, (node, 3), (reference, 3));
            g.func_type = kind;
            g.axes[1].units = num.into();
            g.axes[2].units = den.into();
            g
        })
        .collect();
    uff::to_bytes(&sets, uff::Encoding::Binary).unwrap()
}

#[test]
fn pounds_kilonewtons_micrometres_and_millimetres_give_the_same_estimates() {
    let (model, f, h) = case();
    let dir = tempfile::tempdir().unwrap();
    let lbf = 4.448_221_615_260_5;
    let g = 9.80665;
    let reference = {
        let path = dir.path().join("si.csv");
        std::fs::write(&path, csv(&f, &h, "m/N", 1.0, 0)).unwrap();
        estimate(&model, &data::load_for_model(&path, &model).unwrap())
    };
    // CSV: the value in each unit is the SI value / (unit in SI); a plain response (mm, no
    // "per force") is the response to the model's 4 kN excitation.
    for (unit, scale, power) in [
        ("um/kN", 1e-9, 0),
        ("µm/N", 1e-6, 0),
        ("mm/lbf", 1e-3 / lbf, 0),
        ("(mm/s)/kN", 1e-6, 1),
        ("g/lbf", g / lbf, 2),
        ("mm", 1e-3 / 4000.0, 0),
    ] {
        let path = dir.path().join("units.csv");
        std::fs::write(&path, csv(&f, &h, unit, scale, power)).unwrap();
        let d = data::load_for_model(&path, &model).unwrap();
        let e = estimate(&model, &d);
        for (a, b) in e.iter().zip(&reference) {
            assert!(
                (a / b - 1.0).abs() < 1e-9,
                "CSV {unit}: {e:?} vs {reference:?}"
            );
        }
    }
    // UFF: the units from records 9 and 10.
    for (num, den, scale, power) in [
        ("µm", "kN", 1e-9, 0),
        ("mm/s", "lbf", 1e-3 / lbf, 1),
        ("g", "lbf", g / lbf, 2),
        ("m/s^2", "kN", 1e-3, 2),
    ] {
        let bytes = uff_in(&f, &h, num, den, scale, power);
        let file = uff::parse_file(&bytes, "units.uff").unwrap();
        let (channels, _) = uff::measured_channels(&file, "units.uff").unwrap();
        let map = measurement_map::parse(MAP, "map.toml", &model).unwrap();
        let d = map.apply(&channels, "units.uff", &model).unwrap();
        let e = estimate(&model, &d);
        for (a, b) in e.iter().zip(&reference) {
            assert!(
                (a / b - 1.0).abs() < 1e-9,
                "UFF {num}/{den}: {e:?} vs {reference:?}"
            );
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

#[test]
fn a_file_without_frfs_says_what_it_holds() {
    // A geometry dataset (15) and an auto-spectrum (58, function type 2): nothing to identify.
    let mut psd = uff::Function::frf("psd", 0.0, 1.0, vec![]);
    psd.func_type = uff::function_type::AUTO_SPECTRUM;
    psd.data = uff::Ordinate::Real(vec![1.0, 2.0, 3.0]);
    psd.response_node = 1;
    psd.response_dir = 3;
    let body = String::from_utf8(uff::to_bytes(&[psd], uff::Encoding::Ascii).unwrap()).unwrap();
    let text = format!("    -1\n    15\n         1         0         0         0 0.0000000E+00 0.0000000E+00 0.0000000E+00\n    -1\n{body}");
    let file = uff::parse_file(text.as_bytes(), "spectra.uff").unwrap();
    let e = uff::measured_channels(&file, "spectra.uff")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("spectra.uff")
            && e.contains("no frequency response function")
            && e.contains("dataset 1 (line 2) is of type 15")
            && e.contains("function type 2 is not an FRF"),
        "{e}"
    );
}

/// The two-mass chain on a shaker table moving along z (`[[reference]] "table"`), declared
/// outputs: both bodies' u3 displacement. Its absolute transmissibilities x/x_b at `f`.
fn on_a_table(f: &[f64]) -> (Model, Vec<Vec<C64>>) {
    use rfe::model::{Characteristic, Excitation, Reference};
    let mut m = textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
    m.references.push(Reference {
        name: "table".into(),
        excitation: Excitation::BaseMotion {
            direction: [0.0, 0.0, 1.0],
        },
    });
    let mut t = m.clone();
    t.outputs = m
        .outputs
        .iter()
        .map(|c| Characteristic { reference: 1, ..*c })
        .collect();
    let r = frf::response(&t, f, &[], Method::Direct).unwrap();
    let h = (0..2).map(|o| r.output(o).to_vec()).collect();
    (m, h)
}

const TABLE_MAP: &str = r#"
[[reference]]
node = 100
dir = "+Z"
name = "table"

[[channel]]
node = 1
dir = "+Z"
body = "first"

[[channel]]
node = 2
dir = "+Z"
body = "second"
"#;

#[test]
fn transmissibilities_in_g_per_g_or_any_like_ratio_are_read_exactly() {
    let f: Vec<f64> = (0..50).map(|i| 5.0 + 1.3 * i as f64).collect();
    let (model, t) = on_a_table(&f);
    // UFF type 5 in g/g; type 4 in (mm/s^2)/g (× 1000 / 9.80665 of the ratio); type 5 with
    // record 10 empty.
    let forms: [(u32, &str, &str, f64); 3] = [
        (uff::function_type::TRANSMISSIBILITY, "g", "g", 1.0),
        (uff::function_type::FRF, "mm/s^2", "g", 1e3 * 9.80665),
        (uff::function_type::TRANSMISSIBILITY, "m/s^2", "", 1.0),
    ];
    for (kind, num, den, factor) in forms {
        let values = t
            .iter()
            .map(|to| to.iter().map(|z| z * factor).collect())
            .collect();
        let bytes = uff_58b("table", kind, &f, values, 100, (num, den));
        let file = uff::parse_file(&bytes, "table.uff").unwrap();
        let (channels, _) = uff::measured_channels(&file, "table.uff").unwrap();
        let map = measurement_map::parse(TABLE_MAP, "map.toml", &model).unwrap();
        let d = map.apply(&channels, "table.uff", &model).unwrap();
        assert!(d.source.contains("transmissibility in"), "{}", d.source);
        for (o, c) in d.characteristics.iter().enumerate() {
            assert_eq!(c.reference.as_deref(), Some("table"));
            for (k, want) in t[o].iter().enumerate() {
                let got = C64::from_polar(c.amplitude[k], c.phase_rad.as_ref().unwrap()[k]);
                assert!(
                    (got - want).norm() <= 1e-12 * want.norm(),
                    "{num}/{den} output {o} line {k}: {got} vs {want}"
                );
            }
        }
        // k1, k2 and ψ from the transmissibilities (the model gains its outputs under the
        // table, as `ident identify` adds them).
        let e = estimate(&data::with_measured_outputs(&model, &d), &d);
        for (x, truth) in e.iter().zip([2.0e7, 5.0e6, 0.5]) {
            assert!((x / truth - 1.0).abs() < 1e-6, "{num}/{den}: {e:?}");
        }
    }
    // CSV: `# unit = g/g` with a reference column.
    let mut csv = String::from("# unit = g/g\nbody,dof,reference,freq_hz,amplitude,phase_rad\n");
    for (o, body) in ["first", "second"].iter().enumerate() {
        for (k, fk) in f.iter().enumerate() {
            let z = t[o][k];
            csv.push_str(&format!(
                "{body},u3,table,{fk:?},{:?},{:?}\n",
                z.norm(),
                z.arg()
            ));
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("table.csv");
    std::fs::write(&path, &csv).unwrap();
    let d = data::load_for_model(&path, &model).unwrap();
    let got = C64::from_polar(
        d.characteristics[1].amplitude[7],
        d.characteristics[1].phase_rad.as_ref().unwrap()[7],
    );
    assert!((got - t[1][7]).norm() <= 1e-12 * t[1][7].norm());
    // A transmissibility without a base-motion reference: what to name.
    std::fs::write(&path, csv.replace(",table,", ",excitation,")).unwrap();
    let e = data::load_for_model(&path, &model).unwrap_err().to_string();
    assert!(
        e.contains("table.csv:1:")
            && e.contains("a transmissibility (g/g)")
            && e.contains("reference = \"table\""),
        "{e}"
    );
    // A force-type unit on a type-5 function is refused.
    let mut g = uff::Function::frf("bad", 0.0, 1.0, vec![C64::new(1.0, 0.0); 3]);
    g.func_type = uff::function_type::TRANSMISSIBILITY;
    g.response_node = 1;
    g.response_dir = 3;
    g.axes[1].units = "g".into();
    g.axes[2].units = "N".into();
    let bytes = uff::to_bytes(&[g], uff::Encoding::Binary).unwrap();
    let file = uff::parse_file(&bytes, "bad.uff").unwrap();
    let (channels, _) = uff::measured_channels(&file, "bad.uff").unwrap();
    let e = channels[0].unit.as_ref().unwrap_err().to_string();
    assert!(
        e.contains("function type 5") && e.contains("accelerance"),
        "{e}"
    );
}
