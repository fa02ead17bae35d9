//! Every test layout on real data, each checked against sdypy-EMA 0.27.3 (LSCF poles and LSFD
//! residues on the same FRFs): frequencies within 0.5 %, damping within 20 % on the clear modes,
//! shapes MAC ≥ 0.95.
//!
//! - `data/sdypy-beam`: a free-free beam, hammer roved over 6 points, 7 fixed accelerometers
//!   (accelerance, 1 Hz lines): one accelerometer × five hammer points (the roving-hammer case of
//!   issue 42, where a denominator as wide as the references was fitted from one output and found
//!   one mode), seven accelerometers × one hammer point (roving accelerometer), and the full 7 × 6
//!   set (multi-reference).
//! - `data/dtop-three-storey`: the three-storey structure, hammer on each floor, accelerometers on
//!   every floor: one floor's accelerometer × three hammer positions (roving hammer with a driving
//!   point, so shapes scaled to unit modal mass), and a mixed set (a column and a row through the
//!   floor-1 driving point, completed by reciprocity).
#![allow(clippy::unwrap_used, clippy::needless_range_loop, missing_docs)]

mod common;

use common::*;
use process::modal::{
    arrange, layout, lsfd, mac, Channel, FrfKind, LayoutKind, MeasuredFrf, ModalData, ModalModel,
};
use process::uff::Ordinate;
use process::C64;
use std::path::Path;

/// The FRFs of a UFF file in the repository's `data/` folder, with their lines.
fn uff_set(rel: &str) -> (Vec<MeasuredFrf>, Vec<f64>) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../data")
        .join(rel);
    assert!(path.exists(), "real data missing: {}", path.display());
    let file = process::uff::read_file(&path).unwrap();
    let freqs = file.functions[0].x();
    let frfs = file
        .functions
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let Ordinate::Complex(h) = &f.data else {
                panic!("complex FRFs expected")
            };
            MeasuredFrf {
                response: Channel {
                    node: f.response_node,
                    dir: f.response_dir,
                },
                reference: Channel {
                    node: f.reference_node,
                    dir: f.reference_dir,
                },
                h: h.clone(),
                source: format!("dataset {}", i + 1),
            }
        })
        .collect();
    (frfs, freqs)
}

/// The FRFs whose (response node, reference node) pass `keep`.
fn pick(set: &[MeasuredFrf], keep: impl Fn(i64, i64) -> bool) -> Vec<MeasuredFrf> {
    set.iter()
        .filter(|f| keep(f.response.node, f.reference.node))
        .cloned()
        .collect()
}

/// The automatically picked poles' LSFD model.
fn extract(data: &ModalData, band: (f64, f64), order: usize, min_orders: usize) -> ModalModel {
    lsfd(data, &auto_poles(data, band, order, min_orders), Some(band)).unwrap()
}

/// sdypy-EMA on `data` (every FRF a location, in `o · references + r` order): frequencies,
/// damping ratios and residues per mode over the locations, for the poles nearest `approx`.
fn sdypy(
    data: &ModalData,
    band: (f64, f64),
    order: usize,
    approx: &[f64],
) -> (Vec<f64>, Vec<f64>, Vec<Vec<C64>>) {
    let dir = tempfile::tempdir().unwrap();
    let (inp, out) = (dir.path().join("frf.bin"), dir.path().join("modes.bin"));
    let nloc = data.outputs * data.references;
    let mut all = data.freqs_hz.clone();
    for v in &data.h {
        all.extend([v.re, v.im]);
    }
    write_f64(&inp, &all);
    let kind = match data.kind {
        FrfKind::Receptance => "receptance",
        FrfKind::Mobility => "mobility",
        FrfKind::Accelerance => "accelerance",
    };
    let mut args = vec![
        inp.to_str().unwrap().to_string(),
        out.to_str().unwrap().to_string(),
        nloc.to_string(),
        band.0.to_string(),
        band.1.to_string(),
        order.to_string(),
        kind.to_string(),
    ];
    args.extend(approx.iter().map(|f| f.to_string()));
    python(
        "modal_sdypy_shapes.py",
        &args.iter().map(|s| s.as_str()).collect::<Vec<_>>(),
        "numpy, scipy, sdypy.EMA",
    );
    let r = read_f64(&out);
    let n = approx.len();
    assert_eq!(r.len(), 2 * n + 2 * n * nloc, "sdypy output size");
    let res = (0..n)
        .map(|m| {
            (0..nloc)
                .map(|i| C64::new(r[2 * n + 2 * (i * n + m)], r[2 * n + 2 * (i * n + m) + 1]))
                .collect()
        })
        .collect();
    (r[..n].to_vec(), r[n..2 * n].to_vec(), res)
}

/// Each clear mode (nominal frequencies) is found and agrees with sdypy: frequency within
/// 0.5 %, damping within 20 %, residues and shape MAC ≥ 0.95.
fn check_against_sdypy(
    what: &str,
    data: &ModalData,
    model: &ModalModel,
    band: (f64, f64),
    order: usize,
    clear: &[f64],
) {
    let found: Vec<usize> = clear
        .iter()
        .map(|&f| {
            model
                .modes
                .iter()
                .position(|m| (m.pole.freq_hz - f).abs() < 0.02 * f)
                .unwrap_or_else(|| {
                    panic!(
                        "{what}: clear mode near {f} Hz not found: {:?}",
                        model
                            .modes
                            .iter()
                            .map(|m| m.pole.freq_hz)
                            .collect::<Vec<_>>()
                    )
                })
        })
        .collect();
    // sdypy takes the poles nearest all of ours, so that both LSFD models hold the same modes.
    let approx: Vec<f64> = model.modes.iter().map(|m| m.pole.freq_hz).collect();
    let (f, z, res) = sdypy(data, band, order, &approx);
    let l = data.references;
    for &i in &found {
        let k = i;
        let m = &model.modes[i];
        let df = (m.pole.freq_hz - f[k]).abs() / f[k];
        let dz = (m.pole.damping_ratio - z[k]).abs() / z[k];
        let mac_res = mac(
            std::slice::from_ref(&m.residues),
            std::slice::from_ref(&res[k]),
        )[0][0];
        // The shape against sdypy's residues of the reference that excites the mode most.
        let r0 = (0..l)
            .max_by(|&a, &b| {
                m.participation[a]
                    .norm()
                    .total_cmp(&m.participation[b].norm())
            })
            .unwrap();
        let column: Vec<C64> = (0..data.outputs).map(|o| res[k][o * l + r0]).collect();
        let mac_shape = mac(std::slice::from_ref(&m.shape), &[column])[0][0];
        eprintln!(
            "{what}: ident {:.3} Hz ζ {:.5} (σ {:.3} Hz, {:.5}) | sdypy {:.3} Hz ζ {:.5} | Δf/f {:.1e} Δζ/ζ {:.2} MAC residues {:.4} shape {:.4}",
            m.pole.freq_hz,
            m.pole.damping_ratio,
            m.pole.std.map_or(f64::NAN, |s| s.freq_hz),
            m.pole.std.map_or(f64::NAN, |s| s.damping_ratio),
            f[k],
            z[k],
            df,
            dz,
            mac_res,
            mac_shape
        );
        assert!(
            df <= 0.005,
            "{what}: {} Hz vs sdypy {}",
            m.pole.freq_hz,
            f[k]
        );
        assert!(
            dz <= 0.2,
            "{what}: ζ {} vs sdypy {}",
            m.pole.damping_ratio,
            z[k]
        );
        assert!(mac_res >= 0.95, "{what}: residue MAC {mac_res}");
        assert!(mac_shape >= 0.95, "{what}: shape MAC {mac_shape}");
    }
}

const BEAM: &str = "sdypy-beam/beam-hammer.uff";
const BEAM_BAND: (f64, f64) = (10.0, 2000.0);
/// The beam's first four bending modes (Hz).
const BEAM_MODES: [f64; 4] = [177.0, 477.0, 933.0, 1535.0];

/// Issue 42: one accelerometer (node 2) × the hammer on five points (nodes 11-15).
#[test]
fn roving_hammer_one_response_five_references() {
    let (set, freqs) = uff_set(BEAM);
    let (data, lay) = arrange(
        pick(&set, |r, q| r == 2 && q <= 15),
        freqs,
        FrfKind::Accelerance,
    )
    .unwrap();
    assert_eq!(lay.kind, LayoutKind::RovingHammer);
    assert!(lay.transposed, "{}", lay.describe());
    assert_eq!((data.outputs, data.references), (5, 1));
    assert_eq!(lay.points[4], Channel { node: 15, dir: 3 });
    let model = extract(&data, BEAM_BAND, 40, 10);
    check_against_sdypy(
        "roving hammer 1 × 5",
        &data,
        &model,
        BEAM_BAND,
        40,
        &BEAM_MODES,
    );
}

#[test]
fn roving_accelerometer_seven_responses_one_reference() {
    let (set, freqs) = uff_set(BEAM);
    let (data, lay) = arrange(pick(&set, |_, q| q == 11), freqs, FrfKind::Accelerance).unwrap();
    assert_eq!(lay.kind, LayoutKind::RovingAccelerometer);
    assert!(!lay.transposed && lay.reciprocal == 0);
    assert_eq!((data.outputs, data.references), (7, 1));
    let model = extract(&data, BEAM_BAND, 40, 10);
    check_against_sdypy(
        "roving accelerometer 7 × 1",
        &data,
        &model,
        BEAM_BAND,
        40,
        &BEAM_MODES,
    );
}

#[test]
fn multi_reference_seven_responses_six_references() {
    let (set, freqs) = uff_set(BEAM);
    let (data, lay) = arrange(set, freqs, FrfKind::Accelerance).unwrap();
    assert_eq!(lay.kind, LayoutKind::MultiReference);
    assert_eq!((data.outputs, data.references), (7, 6));
    // Orders × 6 references: 20 orders give 120 poles, more than the 1 × 5 set's 40.
    let model = extract(&data, BEAM_BAND, 20, 5);
    check_against_sdypy(
        "multi-reference 7 × 6",
        &data,
        &model,
        BEAM_BAND,
        40,
        &BEAM_MODES,
    );
}

const STOREY: &str = "dtop-three-storey/three-storey-hammer.uff";
const STOREY_BAND: (f64, f64) = (2.0, 40.0);
const STOREY_MODES: [f64; 3] = [6.51, 17.47, 26.51];

/// The accelerometer on floor 1 × the hammer on floors 1-3: a roving hammer with a driving point,
/// so the shapes can be scaled to unit modal mass. The structure's floors weigh about 5.3 kg each
/// (its mass line), so a unit-modal-mass shape of a chain of three equal floors has
/// `Σ |ψ_p|² ≈ 1 / 5.3 kg`.
#[test]
fn roving_hammer_with_driving_point_on_the_three_storey_structure() {
    let (set, freqs) = uff_set(STOREY);
    let (data, lay) = arrange(pick(&set, |r, _| r == 1), freqs, FrfKind::Accelerance).unwrap();
    assert_eq!(lay.kind, LayoutKind::RovingHammer);
    assert_eq!(lay.driving_points, vec![Channel { node: 1, dir: 1 }]);
    let model = extract(&data, STOREY_BAND, 40, 8);
    check_against_sdypy(
        "three-storey roving hammer 1 × 3",
        &data,
        &model,
        STOREY_BAND,
        40,
        &STOREY_MODES,
    );
    for m in &model.modes {
        if !STOREY_MODES
            .iter()
            .any(|f| (m.pole.freq_hz - f).abs() < 0.2)
        {
            continue;
        }
        let psi = layout::mass_normalized(&m.residues, 1, 0, 0, m.pole.lambda);
        let sum: f64 = psi.iter().map(|v| v.norm_sqr()).sum();
        eprintln!(
            "{:.3} Hz: Σ|ψ|² = {sum:.4} 1/kg (1/5.3 kg = {:.4})",
            m.pole.freq_hz,
            1.0 / 5.3
        );
        assert!((sum * 5.3 - 1.0).abs() < 0.25, "Σ|ψ|² = {sum} 1/kg");
    }
}

/// A mixed set: the floor-1 hammer column for floors 1-2 (H11, H21) and the floor-1 accelerometer
/// row for the hammer on floor 3 (H13), completed by reciprocity (H31 read from H13). Its modes and
/// shapes must match the full 3 × 3 set's.
#[test]
fn mixed_set_completed_by_reciprocity() {
    let (set, freqs) = uff_set(STOREY);
    let mixed = pick(&set, |r, q| (q == 1 && r <= 2) || (r == 1 && q == 3));
    let (data, lay) = arrange(mixed, freqs.clone(), FrfKind::Accelerance).unwrap();
    assert_eq!(lay.kind, LayoutKind::Mixed, "{}", lay.describe());
    assert_eq!((data.outputs, data.references, lay.reciprocal), (3, 1, 1));
    let model = extract(&data, STOREY_BAND, 40, 8);
    check_against_sdypy(
        "three-storey mixed",
        &data,
        &model,
        STOREY_BAND,
        40,
        &STOREY_MODES,
    );

    let (full, _) = arrange(set, freqs, FrfKind::Accelerance).unwrap();
    let reference = extract(&full, STOREY_BAND, 40, 8);
    for &f in &STOREY_MODES {
        let near = |m: &ModalModel| {
            m.modes
                .iter()
                .find(|x| (x.pole.freq_hz - f).abs() < 0.2)
                .unwrap()
                .clone()
        };
        let (a, b) = (near(&model), near(&reference));
        let m = mac(
            std::slice::from_ref(&a.shape),
            std::slice::from_ref(&b.shape),
        )[0][0];
        eprintln!(
            "{f} Hz: mixed {:.4} Hz, full {:.4} Hz, MAC {m:.4}",
            a.pole.freq_hz, b.pole.freq_hz
        );
        assert!((a.pole.freq_hz - b.pole.freq_hz).abs() < 0.005 * f);
        assert!(m >= 0.95, "MAC {m}");
    }
}

/// What cannot be used as given is refused, naming what is missing.
#[test]
fn unusable_sets_name_what_is_missing() {
    let (set, freqs) = uff_set(BEAM);
    // Two accelerometers, hammer points 11-13, one FRF left out: no reciprocal FRF can fill it.
    let holes: Vec<MeasuredFrf> = pick(&set, |r, q| r <= 2 && q <= 13 && !(r == 2 && q == 12));
    let err = arrange(holes, freqs.clone(), FrfKind::Accelerance)
        .unwrap_err()
        .to_string();
    assert!(err.contains("2:3 ← 12:3"), "{err}");
    let mut twice = pick(&set, |r, q| r == 1 && q <= 12);
    twice.push(twice[0].clone());
    let err = arrange(twice, freqs, FrfKind::Accelerance)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("1:3") && err.contains("11:3") && err.contains("dataset"),
        "{err}"
    );
}
