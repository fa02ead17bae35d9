//! A tool's receptance read from a UFF file (`[[tool.frf]]`): the same tool given by its mode
//! (`[[tool.mode]]`) and as a measured driving-point FRF (receptance, and accelerance) gives the
//! same lobes; a cross FRF, an FRF without phase, and a measurement that ends below the lobes'
//! band are refused, naming the file and the fix.

#![allow(clippy::unwrap_used)]

use std::path::Path;

use num_complex::Complex64 as C64;
use process::uff::{self, Encoding, Function};

/// The tool: one mode along x at 80 Hz, ζ = 0.03, 20 N/µm at the tip.
const F_TOOL: f64 = 80.0;
const ZETA: f64 = 0.03;
const K_TOOL: f64 = 2.0e7;

fn tool_receptance(f: f64) -> C64 {
    let r = f / F_TOOL;
    C64::new(1.0 - r * r, 2.0 * ZETA * r).inv() / K_TOOL
}

/// A turning cut on a 100 kg body on springs (a 50 Hz mode), the chip thickness along x, the
/// tool given by `tool` (TOML lines in `[tool]`).
fn cut_text(tool: &str) -> String {
    format!(
        r#"
operation = "turning"
speed_rpm = [600, 3000]
speeds = 80
band_hz = [20, 300]
lines = 3000
[tool]
body = "mass"
point = [0.0, 0.0, 0.0]
{tool}
[workpiece]
body = "ground"
point = [0.0, 0.0, 0.0]
[cutting]
kt = "1000 MPa"
kr = "400 MPa"
[turning]
thickness = [1.0, 0.0, 0.0]
cutting = [0.0, 0.0, 1.0]
"#
    )
}

/// Writes an FRF on 0.1 Hz lines up to `top` Hz in the given units (the tool's half-power
/// bandwidth, 2ζf = 4.8 Hz, spans 48 lines: linear interpolation between them is the only
/// difference to the modal tool).
fn write_uff(path: &Path, top: f64, (num, den): (&str, &str), response: (i64, i64), accel: bool) {
    let freqs: Vec<f64> = (0..=(top * 10.0).round() as usize)
        .map(|i| 0.1 * i as f64)
        .collect();
    let h: Vec<C64> = freqs
        .iter()
        .map(|&f| {
            let w = std::f64::consts::TAU * f;
            if accel {
                -w * w * tool_receptance(f)
            } else {
                tool_receptance(f)
            }
        })
        .collect();
    let mut f = Function::frf_between("tool tip", freqs, h, response, (1, 1));
    f.axes[1].spec_data_type = if accel { 12 } else { 8 };
    f.axes[1].units = num.into();
    f.axes[2].spec_data_type = 13;
    f.axes[2].units = den.into();
    uff::write(path, &[f], Encoding::Ascii).unwrap();
}

fn lobes(text: &str, file: &Path) -> Vec<f64> {
    let model = rfe::textbook::single_body(100.0, 1.0e7, 0.2);
    let cut = stability::cut::parse(text, &file.display().to_string()).unwrap();
    let l = stability::lobes(&stability::Request::new(&model, &cut)).unwrap();
    l.points.iter().map(|p| p.depth).collect()
}

#[test]
fn a_tool_frf_from_uff_couples_like_its_modes() {
    let dir = tempfile::tempdir().unwrap();
    let cut_file = dir.path().join("cut.toml");
    let modal = lobes(
        &cut_text(&format!(
            "[[tool.mode]]\ndirection = [1.0, 0.0, 0.0]\nfreq = \"{F_TOOL} Hz\"\ndamping_ratio = {ZETA}\nstiffness = \"{} N/um\"",
            K_TOOL / 1e6
        )),
        &cut_file,
    );
    let without = lobes(&cut_text(""), &cut_file);
    for (name, units, accel) in [
        ("receptance.uff", ("m", "N"), false),
        ("accelerance.uff", ("m/s^2", "N"), true),
    ] {
        write_uff(&dir.path().join(name), 400.0, units, (1, 1), accel);
        let measured = lobes(
            &cut_text(&format!(
                "[[tool.frf]]\nuff = \"{name}\"\ndirection = [1.0, 0.0, 0.0]"
            )),
            &cut_file,
        );
        let mut worst: f64 = 0.0;
        for (a, b) in modal.iter().zip(&measured) {
            worst = worst.max(((a - b) / a).abs());
        }
        println!("{name}: largest relative depth difference to the modal tool {worst:.2e}");
        assert!(worst < 2e-3, "{name}: {worst}");
        // The tool matters here: the lobes without it differ by far more.
        let moved = without
            .iter()
            .zip(&modal)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0, f64::max);
        assert!(moved > 0.05, "the tool changes the lobes: {moved}");
    }
}

#[test]
fn a_uff_that_is_not_the_tools_receptance_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cut_file = dir.path().join("cut.toml");
    let model = rfe::textbook::single_body(100.0, 1.0e7, 0.2);
    let frf = |name: &str| {
        cut_text(&format!(
            "[[tool.frf]]\nuff = \"{name}\"\ndirection = [1.0, 0.0, 0.0]"
        ))
    };
    let origin = cut_file.display().to_string();

    // A cross FRF: response at node 2, reference at node 1.
    write_uff(
        &dir.path().join("cross.uff"),
        400.0,
        ("m", "N"),
        (2, 1),
        false,
    );
    let e = stability::cut::parse(&frf("cross.uff"), &origin)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with(&format!("{origin}: tool.frf[0].uff: "))
            && e.contains("cross.uff")
            && e.contains("not a driving-point FRF")
            && e.contains("same node and direction"),
        "{e}"
    );

    // A missing file names it.
    let e = stability::cut::parse(&frf("nowhere.uff"), &origin)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("tool.frf[0].uff") && e.contains("nowhere.uff"),
        "{e}"
    );

    // A measurement that stops below the lobes' band.
    write_uff(
        &dir.path().join("short.uff"),
        150.0,
        ("m", "N"),
        (1, 1),
        false,
    );
    let cut = stability::cut::parse(&frf("short.uff"), &origin).unwrap();
    let e = stability::lobes(&stability::Request::new(&model, &cut))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("tool.frf") && e.contains("short.uff") && e.contains("ends at 150.0 Hz"),
        "{e}"
    );
}
