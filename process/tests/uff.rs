//! UFF dataset 58/58b: round trips (ours and against pyuff), malformed files, fuzzing.
#![allow(clippy::unwrap_used, missing_docs)]

mod common;

use process::uff::{self, Abscissa, Encoding, Function, Ordinate};
use process::C64;
use proptest::prelude::*;
use std::f64::consts::PI;

/// The datasets uff_pyuff.py's reference() builds, computed independently here.
fn reference() -> Vec<Function> {
    let f: Vec<f64> = (1..=200).map(|k| k as f64 * 0.5).collect();
    let h: Vec<C64> = f
        .iter()
        .map(|&f| 1.0 / C64::new(1.0e4 - (2.0 * PI * f).powi(2), 2.0 * PI * f * 3.0))
        .collect();
    let t: Vec<f64> = (0..300).map(|n| n as f64 / 2000.0).collect();
    let x: Vec<f64> = t
        .iter()
        .map(|&t| (2.0 * PI * 50.0 * t).sin() * (-t * 3.0).exp() + 0.1)
        .collect();
    let mut frf = Function::frf("ours", 0.5, 0.5, h);
    frf.response_dir = 3;
    frf.reference_node = 2;
    frf.reference_dir = 3;
    let mut th = Function::time_history("ours", 2000.0, x);
    th.response_dir = 3;
    let mut un = Function::frf(
        "ours",
        0.0,
        0.0,
        vec![
            C64::new(1.0, 2.0),
            C64::new(-3e-7, 1.0),
            C64::new(4.5e10, 0.0),
            C64::new(-1e-300, 1e300),
        ],
    );
    un.abscissa = Abscissa::Uneven(vec![1.0, 2.5, 7.25, 100.0]);
    vec![frf, th, un]
}

fn values(f: &Function) -> Vec<C64> {
    match &f.data {
        Ordinate::Real(v) => v.iter().map(|x| C64::new(*x, 0.0)).collect(),
        Ordinate::Complex(v) => v.clone(),
    }
}

fn assert_close(a: &Function, b: &Function, tol: f64, what: &str) {
    let (xa, xb) = (a.x(), b.x());
    assert_eq!(xa.len(), xb.len(), "{what}: point count");
    for (p, q) in xa.iter().zip(&xb) {
        assert!(
            (p - q).abs() <= 1e-12 * q.abs().max(1e-300),
            "{what}: x {p} vs {q}"
        );
    }
    for (p, q) in values(a).iter().zip(values(b).iter()) {
        assert!((p - q).norm() <= tol * q.norm(), "{what}: {p} vs {q}");
    }
}

#[test]
fn our_files_round_trip_in_every_encoding_and_precision() {
    for enc in [Encoding::Ascii, Encoding::Binary] {
        for double in [true, false] {
            let mut sets = reference();
            if !double {
                sets.truncate(2); // 1e300 does not fit single precision
            }
            sets.iter_mut().for_each(|s| s.double = double);
            let mut real_uneven =
                Function::time_history("uneven real", 1.0, vec![1.5, -2.25, 1e-9]);
            real_uneven.abscissa = Abscissa::Uneven(vec![0.0, 0.5, 3.0]);
            real_uneven.double = double;
            sets.push(real_uneven);
            let bytes = uff::to_bytes(&sets, enc).unwrap();
            let back = uff::parse(&bytes, "mem").unwrap();
            assert_eq!(back.len(), sets.len());
            let tol = match (enc, double) {
                (Encoding::Binary, true) => 0.0,
                (Encoding::Ascii, true) => 1e-12,
                (_, false) => 1e-5, // E13.5 / f32: 6-7 digits
            };
            for (a, b) in back.iter().zip(&sets) {
                assert_close(a, b, tol, &format!("{enc:?} double={double}"));
                assert_eq!(
                    (a.func_type, a.response_dir, a.reference_node, a.double),
                    (b.func_type, b.response_dir, b.reference_node, b.double)
                );
                assert_eq!(a.axes[0], b.axes[0]);
                assert_eq!(a.ids[0], b.ids[0]);
            }
        }
    }
}

#[test]
fn pyuff_reads_what_we_write() {
    let dir = tempfile::tempdir().unwrap();
    for (enc, tol) in [(Encoding::Ascii, 1e-12), (Encoding::Binary, 0.0)] {
        let file = dir.path().join(format!("ours_{enc:?}.uff"));
        let dump = dir.path().join("dump.bin");
        let sets = reference();
        uff::write(&file, &sets, enc).unwrap();
        common::python(
            "uff_pyuff.py",
            &["dump", file.to_str().unwrap(), dump.to_str().unwrap()],
            "numpy, pyuff",
        );
        let d = common::read_f64(&dump);
        let mut o = 0;
        for s in &sets {
            let n = d[o] as usize;
            assert_eq!(n, s.data.len());
            let x = &d[o + 1..o + 1 + n];
            let v: Vec<C64> = (0..n)
                .map(|i| C64::new(d[o + 1 + n + i], d[o + 1 + 2 * n + i]))
                .collect();
            for (p, q) in x.iter().zip(s.x()) {
                assert!(
                    (p - q).abs() <= 1e-12 * q.abs(),
                    "{enc:?}: pyuff x {p} vs {q}"
                );
            }
            for (p, q) in v.iter().zip(values(s)) {
                assert!(
                    (p - q).norm() <= tol * q.norm(),
                    "{enc:?}: pyuff value {p} vs {q}"
                );
            }
            o += 1 + 3 * n;
        }
        assert_eq!(o, d.len());
    }
}

#[test]
fn we_read_what_pyuff_writes() {
    let dir = tempfile::tempdir().unwrap();
    for (binary, tol) in [("0", 1e-11), ("1", 1e-14)] {
        let file = dir.path().join(format!("pyuff_{binary}.uff"));
        common::python(
            "uff_pyuff.py",
            &["write", file.to_str().unwrap(), binary],
            "numpy, pyuff",
        );
        let got = uff::read(&file).unwrap();
        let want = reference();
        assert_eq!(got.len(), 3);
        for (a, b) in got.iter().zip(&want) {
            assert_close(a, b, tol, &format!("pyuff binary={binary}"));
            assert_eq!(a.func_type, b.func_type);
            assert_eq!(a.ids[0], "pyuff");
            assert_eq!(
                (
                    a.response_entity.as_str(),
                    a.reference_node,
                    a.reference_dir
                ),
                ("NODE", 2, 3)
            );
        }
    }
}

fn ascii_reference() -> String {
    String::from_utf8(uff::to_bytes(&reference(), Encoding::Ascii).unwrap()).unwrap()
}

#[test]
fn time_histories_become_signals_for_welch() {
    let x: Vec<f64> = (0..1000).map(|i| (i as f64 * 0.1).sin()).collect();
    let f = Function::time_history("hammer", 25600.0, x.clone());
    let back = uff::parse(&uff::to_bytes(&[f], Encoding::Binary).unwrap(), "m").unwrap();
    let s = back[0].to_signal("ch1").unwrap();
    assert_eq!(
        (s.name.as_str(), s.samples.as_slice()),
        ("hammer", x.as_slice())
    );
    assert!((s.sample_rate_hz - 25600.0).abs() < 1e-9);
    let frf = Function::frf("h", 0.0, 1.0, vec![C64::new(1.0, 0.0)]);
    assert!(frf
        .to_signal("x")
        .unwrap_err()
        .to_string()
        .contains("not a time response"));
}

#[test]
fn real_world_quirks_crlf_fortran_d_and_other_datasets_are_read() {
    let text = ascii_reference();
    let want = uff::parse(text.as_bytes(), "lf").unwrap();
    let crlf = text.replace('\n', "\r\n");
    assert_eq!(uff::parse(crlf.as_bytes(), "crlf").unwrap(), want);
    // Fortran D exponents in data lines and record 7.
    let d = text.replace("E+", "D+").replace("E-", "D-");
    let got = uff::parse(d.as_bytes(), "d").unwrap();
    for (a, b) in got.iter().zip(&want) {
        assert_close(a, b, 0.0, "D exponents");
    }
    // A dataset 15 (nodes) before ours is skipped.
    let other = format!("    -1\n    15\n         1         0         0         0 0.0000000E+00 0.0000000E+00 0.0000000E+00\n    -1\n{text}");
    assert_eq!(uff::parse(other.as_bytes(), "mixed").unwrap(), want);
}

#[test]
fn non_ascii_headers_are_read_by_character_in_utf8_and_latin1() {
    // A response entity "Prüfstand" and a units label "m/s²" before the node, direction and
    // exponent fields: read by byte, the extra UTF-8 byte (or a lossy Latin-1 replacement) shifts
    // every field after it.
    let mut f = Function::frf("Prüfstand FRF", 1.0, 1.0, vec![C64::new(1.0, -2.0); 3]);
    f.response_entity = "Prüfstand".into();
    f.response_node = 1234;
    f.response_dir = -3;
    f.reference_entity = "Kraft-µ".into();
    f.reference_node = 77;
    f.reference_dir = 2;
    f.axes[1] = uff::Axis {
        spec_data_type: 12,
        length_exp: 1,
        force_exp: 0,
        temperature_exp: 0,
        label: "Beschleunigung²".into(),
        units: "m/s²".into(),
    };
    f.axes[2].units = "N".into();
    let utf8 = uff::to_bytes(std::slice::from_ref(&f), Encoding::Ascii).unwrap();
    let text = String::from_utf8(utf8.clone()).unwrap();
    assert!(text.contains("Prüfstand") && text.contains("m/s²"));
    let latin1: Vec<u8> = text
        .chars()
        .map(|c| u8::try_from(u32::from(c)).unwrap())
        .collect();
    assert_ne!(latin1.len(), utf8.len(), "the Latin-1 file is shorter");
    for (bytes, what) in [(&utf8, "UTF-8"), (&latin1, "Latin-1")] {
        let back = uff::parse(bytes, what).unwrap();
        let g = &back[0];
        assert_eq!(
            (
                g.response_entity.as_str(),
                g.response_node,
                g.response_dir,
                g.reference_entity.as_str(),
                g.reference_node,
                g.reference_dir
            ),
            ("Prüfstand", 1234, -3, "Kraft-µ", 77, 2),
            "{what}"
        );
        assert_eq!(g.axes[1], f.axes[1], "{what}");
        assert_eq!(g.axes[2].units, "N", "{what}");
        assert_eq!(g.ids[0], "Prüfstand FRF", "{what}");
        assert_close(g, &f, 1e-12, what);
        // The channel keeps its node and direction, and "m/s²" per "N" reads as accelerance.
        let file = uff::parse_file(bytes, what).unwrap();
        let (channels, _) = uff::measured_channels(&file, what).unwrap();
        let unit = channels[0].unit.as_ref().unwrap();
        assert_eq!(
            (unit.kind(), unit.to_si, channels[0].name.to_string()),
            ("accelerance", 1.0, "node 1234 -Z".to_string()),
            "{what}"
        );
    }
}

#[test]
fn other_datasets_are_skipped_and_listed() {
    let text = ascii_reference();
    let other =
        format!("    -1\n   164\n         1SI\n    -1\n{text}    -1\n  2414\n         1\n    -1\n");
    assert!(uff::looks_like_uff(other.as_bytes()));
    assert!(!uff::looks_like_uff(b"body,dof,freq_hz,amplitude\n"));
    let u = uff::parse_file(other.as_bytes(), "mixed.unv").unwrap();
    assert_eq!(u.functions.len(), 3);
    let kinds: Vec<(usize, &str, usize)> = u
        .skipped
        .iter()
        .map(|s| (s.dataset, s.kind.as_str(), s.line))
        .collect();
    let last_line = 4 + text.lines().count() + 2;
    assert_eq!(kinds, vec![(1, "164", 2), (5, "2414", last_line)]);
    assert!(u.skipped[1].to_string().contains("type 2414"));
}

#[test]
fn malformed_files_give_clear_errors() {
    let text = ascii_reference();
    // Truncated in the data of the first dataset.
    let cut = &text[..text.len() / 5];
    let e = uff::parse(cut.as_bytes(), "cut.uff")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cut.uff") && e.contains("dataset 1") && e.contains("truncated"),
        "{e}"
    );
    // Wrong point count in record 7.
    let wrong = text.replacen("       200         1", "       201         1", 1);
    let e = uff::parse(wrong.as_bytes(), "n.uff")
        .unwrap_err()
        .to_string();
    assert!(e.contains("record 7") && e.contains("402"), "{e}");
    let fewer = text.replacen("       200         1", "       190         1", 1);
    let e = uff::parse(fewer.as_bytes(), "n.uff")
        .unwrap_err()
        .to_string();
    assert!(e.contains("wrong record length"), "{e}");
    // Bad number.
    let bad = text.replacen("E-", "X-", 30);
    assert!(uff::parse(bad.as_bytes(), "x.uff")
        .unwrap_err()
        .to_string()
        .contains("not a number"));
    // Binary: truncated block and byte count disagreeing with record 7.
    let bin = uff::to_bytes(&reference(), Encoding::Binary).unwrap();
    let e = uff::parse(&bin[..2000], "b.uff").unwrap_err().to_string();
    assert!(e.contains("truncated"), "{e}");
    let s = String::from_utf8_lossy(&bin).into_owned();
    let hdr = s.find("58b").unwrap();
    let mut wrong = bin.clone();
    let line_end = hdr + s[hdr..].find('\n').unwrap();
    let new_hdr = s[hdr..line_end].replacen("3200", "3208", 1);
    wrong.splice(hdr..line_end, new_hdr.bytes());
    // The header count alone is not trusted (pyuff writes half of it for complex data) ...
    assert_eq!(
        uff::parse(&wrong, "b.uff").unwrap(),
        uff::parse(&bin, "b.uff").unwrap()
    );
    // ... but a record 7 that disagrees with the block is an error.
    let r7 = s.find("       200         1").unwrap();
    let mut wrong = bin.clone();
    wrong.splice(r7..r7 + 20, "       199         1".bytes());
    let e = uff::parse(&wrong, "b.uff").unwrap_err().to_string();
    assert!(
        e.contains("199 points") && e.contains("record 7") && e.contains("wrong record length"),
        "{e}"
    );
    // Not UFF at all.
    assert!(uff::parse(b"hello\nworld\n", "t.txt")
        .unwrap_err()
        .to_string()
        .contains("delimiter"));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, rng_seed: proptest::test_runner::RngSeed::Fixed(58), ..ProptestConfig::default() })]

    #[test]
    fn reader_never_panics_on_garbage(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let _ = uff::parse(&bytes, "fuzz");
    }

    #[test]
    fn reader_never_panics_on_damaged_files(
        binary in any::<bool>(),
        cut in 0.0f64..1.0,
        edits in proptest::collection::vec((0.0f64..1.0, any::<u8>()), 0..8),
    ) {
        let mut sets = reference();
        sets.truncate(1);
        let mut b = uff::to_bytes(&sets, if binary { Encoding::Binary } else { Encoding::Ascii }).unwrap();
        for (pos, byte) in edits {
            let i = ((b.len() - 1) as f64 * pos) as usize;
            b[i] = byte;
        }
        b.truncate((b.len() as f64 * cut) as usize + 1);
        if let Ok(sets) = uff::parse(&b, "fuzz") {
            for s in sets {
                prop_assert_eq!(s.x().len(), s.data.len());
            }
        }
    }
}
