//! The identification problem as one library call (`identify::request::prepare`): a vendor UFF
//! file in g/N through a measurement map, its lines chosen and decimated, is prepared and fitted
//! to the truth; what was converted and dropped comes back as notes; bad requests name the file
//! and the fix.
#![allow(clippy::unwrap_used, missing_docs)]

use std::path::{Path, PathBuf};

use identify::line_choice::LineChoice;
use identify::request::{self, DataRequest, Note, Request, RequestError, Start};
use identify::{FitKind, Options};
use process::uff;
use process::C64;
use rfe::frf::{self, Method};

const MODEL: &str = "../configs/models/textbook-two-mass.toml";
/// k1 and k2 of the two-mass chain started at 14 and 7 N/µm.
const VARS: &str = "../configs/identification/textbook-two-mass.toml";

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

fn at_root(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The two-mass chain's exact accelerances in g/N (its excitation is 1 N) at 40 lines over
/// 10-58.75 Hz, as a UFF58b file with the map beside it.
fn vendor_files(dir: &Path) -> (PathBuf, PathBuf) {
    let model = rfe::modelfile::load(&at_root(MODEL)).unwrap().model;
    let f: Vec<f64> = (0..40).map(|i| 10.0 + 1.25 * i as f64).collect();
    let r = frf::response(&model, &f, &[], Method::Direct).unwrap();
    let mut sets = Vec::new();
    for (k, node) in [11i64, 12].iter().enumerate() {
        let a: Vec<C64> = r
            .output(k)
            .iter()
            .zip(&f)
            .map(|(z, fk)| -z * (2.0 * std::f64::consts::PI * fk).powi(2) / 9.80665)
            .collect();
        let mut s = uff::Function::frf_between("stand", f.clone(), a, (*node, 3), (1, 3));
        s.axes[1].spec_data_type = 12;
        s.axes[1].units = "g".into();
        s.axes[2].spec_data_type = 13;
        s.axes[2].units = "N".into();
        sets.push(s);
    }
    let data = dir.join("run.unv");
    uff::write(&data, &sets, uff::Encoding::Binary).unwrap();
    let map = dir.join("map.toml");
    std::fs::write(&map, MAP).unwrap();
    (data, map)
}

fn request<'a>(data: DataRequest<'a>, model: &'a Path, vars: &'a Path) -> Request<'a> {
    Request {
        model,
        data,
        vars,
        start: Start::Variables,
        fit: Some(FitKind::Amplitude),
        options: Options::default(),
    }
}

#[test]
fn a_uff_file_with_its_map_is_prepared_and_fits_the_truth() {
    let dir = tempfile::tempdir().unwrap();
    let (data, map) = vendor_files(dir.path());
    let (model, vars) = (at_root(MODEL), at_root(VARS));
    let lines = LineChoice {
        band_hz: (Some(15.0), None),
        ..LineChoice::default()
    };
    let req = request(
        DataRequest {
            data: &data,
            map: Some(&map),
            lines: &lines,
            points: Some(20),
        },
        &model,
        &vars,
    );
    let mut notes = Vec::new();
    let p = request::prepare(&req, &mut |n| notes.push(n)).unwrap();
    let said: Vec<String> = notes.iter().map(|n| n.to_string()).collect();
    assert!(
        notes.contains(&Note::Data(
            "first u3: acceleration converted to the model's displacement output by (jω)^-2".into()
        )) && said.iter().any(|n| n.starts_with(
            "data: second u3: accelerance in (g)/(N) converted to (m/s²)/N (× 9.80665)"
        )),
        "{said:#?}"
    );
    assert!(
        said.iter()
            .any(|n| n.starts_with("lines: ") && n.contains("decimated from 36 to 20 lines")),
        "{said:#?}"
    );
    // 36 lines from 15 Hz on, decimated to 20, in the model's displacement per N.
    assert_eq!(p.observations.characteristics.len(), 2);
    for c in &p.observations.characteristics {
        assert_eq!(c.freqs_hz.len(), 20, "{}", c.label);
        assert!(c.freqs_hz[0] >= 15.0, "{}", c.label);
    }
    assert_eq!(p.options.fit, FitKind::Amplitude);
    let id = p.identify(&mut |_, _| {}).unwrap();
    assert!(id.stop.converged(), "{}", id.stop.describe());
    let rows = identify::report::rows(&id);
    for (row, truth) in rows.iter().zip([20.0, 5.0]) {
        assert!(
            (row.identified - truth).abs() < 1e-3 * truth,
            "{}: {} against {truth}",
            row.variable,
            row.identified
        );
    }
}

#[test]
fn bad_requests_name_the_file_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let (data, map) = vendor_files(dir.path());
    let (model, vars) = (at_root(MODEL), at_root(VARS));
    let all = LineChoice::default();
    let prepare = |data: &Path, map: Option<&Path>, points| {
        let req = request(
            DataRequest {
                data,
                map,
                lines: &all,
                points,
            },
            &model,
            &vars,
        );
        request::prepare(&req, &mut |_| {}).unwrap_err()
    };
    let e = prepare(&data, None, None);
    assert!(
        matches!(&e, RequestError::UffWithoutMap { channels: 2, .. })
            && e.to_string().contains("run.unv")
            && e.to_string().contains("give --map FILE"),
        "{e}"
    );
    let csv = dir.path().join("data.csv");
    std::fs::write(&csv, "body,dof,freq_hz,amplitude\nfirst,u3,10,1e-7\n").unwrap();
    let e = prepare(&csv, Some(&map), None);
    assert!(
        matches!(&e, RequestError::MapWithoutUff { .. }) && e.to_string().contains("data.csv"),
        "{e}"
    );
    let e = prepare(&data, Some(&map), Some(1));
    assert!(matches!(e, RequestError::TooFewPoints(1)), "{e}");
    let e = prepare(&dir.path().join("missing.unv"), Some(&map), None);
    assert!(
        matches!(&e, RequestError::Read { path, .. } if path.ends_with("missing.unv")),
        "{e}"
    );
}
