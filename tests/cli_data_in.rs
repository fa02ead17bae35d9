//! `ident identify` on vendor data: a UFF58b file in g/N with a measurement map, a CSV declaring
//! its unit, frequencies in kHz under `freq_hz` (an error naming the band), a misfit headline, a
//! UFF file without a map.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use common::{identify_two_mass, p, root, utf8, TWO_MASS};

use identify::frf::{self, Method};
use process::uff;
use process::C64;

/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm.
const VARS: &str = include_str!("../configs/identification/textbook-two-mass.toml");

const MAP: &str = r#"
[[channel]]
node = 11
dir = "+Z"
body = "first"

[[channel]]
node = 12
dir = "+Z"
body = "second"
"#;

/// The two-mass chain's exact receptances (per N; its excitation is 1 N) at `f`.
fn receptances(f: &[f64]) -> Vec<Vec<C64>> {
    let model = identify::modelfile::load(&root().join(TWO_MASS))
        .unwrap()
        .model;
    let r = frf::response(&model, f, &[], Method::Direct).unwrap();
    (0..2).map(|o| r.output(o).to_vec()).collect()
}

fn lines() -> Vec<f64> {
    (0..40).map(|i| 10.0 + 1.25 * i as f64).collect()
}

#[test]
fn a_uff_file_in_g_per_newton_with_a_map_is_identified() {
    let dir = tempfile::tempdir().unwrap();
    let f = lines();
    let h = receptances(&f);
    let mut sets = Vec::new();
    for (k, node) in [11i64, 12].iter().enumerate() {
        // Accelerance in g/N: −ω² h / g.
        let a: Vec<C64> = h[k]
            .iter()
            .zip(&f)
            .map(|(z, fk)| -z * (2.0 * std::f64::consts::PI * fk).powi(2) / 9.80665)
            .collect();
        let mut s = uff::Function::frf("Prüfstand", 0.0, 0.0, a);
        s.abscissa = uff::Abscissa::Uneven(f.clone());
        s.response_entity = "Prüfstand".into();
        s.response_node = *node;
        s.response_dir = 3;
        s.reference_node = 1;
        s.reference_dir = 3;
        s.axes[1].spec_data_type = 12;
        s.axes[1].units = "g".into();
        s.axes[2].spec_data_type = 13;
        s.axes[2].units = "N".into();
        sets.push(s);
    }
    let data = dir.path().join("run.unv");
    uff::write(&data, &sets, uff::Encoding::Binary).unwrap();
    let map = dir.path().join("map.toml");
    std::fs::write(&map, MAP).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let o = identify_two_mass(&data, &vars, &["--map", p(&map), "--format", "json"], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", utf8(&o.stderr));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("data: first u3: accelerance in (g)/(N) converted to (m/s²)/N (× 9.80665)")
            && err.contains("acceleration converted to the model's displacement output by (jω)^-2"),
        "{err}"
    );
    let j: serde_json::Value = serde_json::from_str(&utf8(&o.stdout)).unwrap();
    let table = j["table"].as_array().unwrap();
    for (row, truth) in table.iter().zip([20.0, 5.0]) {
        let v = row["identified"].as_f64().unwrap();
        assert!((v / truth - 1.0).abs() < 1e-6, "{row}");
    }
    assert!(j["misfit"].is_null());
    // Without the map: what to give.
    let o = identify_two_mass(&data, &vars, &[], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        utf8(&o.stderr).contains("give --map FILE"),
        "{}",
        utf8(&o.stderr)
    );
}

#[test]
fn frequencies_in_khz_under_freq_hz_stop_before_a_confident_wrong_fit() {
    let dir = tempfile::tempdir().unwrap();
    let f = lines();
    let h = receptances(&f);
    let mut csv = String::from("# unit = mm/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            csv.push_str(&format!(
                "{body},u3,{:?},{:?}\n",
                fk / 1000.0,
                h[k][i].norm() * 1e3
            ));
        }
    }
    let data = dir.path().join("khz.csv");
    std::fs::write(&data, &csv).unwrap();
    let vars = dir.path().join("vars.toml");
    std::fs::write(&vars, VARS).unwrap();
    let o = identify_two_mass(&data, &vars, &[], &[]);
    assert_eq!(o.status.code(), Some(2), "{}", utf8(&o.stdout));
    let err = utf8(&o.stderr);
    assert!(
        err.contains("khz.csv: frequencies:") && err.contains("kHz"),
        "{err}"
    );
    // The same lines in Hz are fine; with one output 9.81x too high the level warning names g and
    // the fit's headline says the model does not explain the data.
    let mut csv = String::from("# unit = mm/N\nbody,dof,freq_hz,amplitude\n");
    for (k, body) in ["first", "second"].iter().enumerate() {
        for (i, fk) in f.iter().enumerate() {
            let g = if k == 1 { 9.80665 } else { 1.0 };
            csv.push_str(&format!(
                "{body},u3,{fk:?},{:?}\n",
                h[k][i].norm() * 1e3 * g
            ));
        }
    }
    std::fs::write(&data, &csv).unwrap();
    let o = identify_two_mass(&data, &vars, &[], &[]);
    let err = utf8(&o.stderr);
    assert!(
        err.contains("warning: second u3 displacement") && err.contains("g read as m/s²"),
        "{err}"
    );
    let out = utf8(&o.stdout);
    assert!(
        out.starts_with("THE MODEL DOES NOT EXPLAIN THE DATA"),
        "{out}"
    );
}
