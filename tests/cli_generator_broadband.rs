//! `ident sweep --broadband` on the generator stand (simulated SCPI signal generator + power
//! amplifier, the periodic random uploaded as an arbitrary waveform) and `ident process` of its
//! session: every accelerometer's FRF equals the truth plant's within the noise, recomputed from
//! the raw blocks bit for bit; a `[broadband]` the generator model cannot play is refused naming
//! the stand file's field, the model and the fix.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::path::Path;

use acquire::sim::SimSetup;
use acquire::stand::Stand;
use common::{ident, p, root, text};

const STAND: &str = "configs/stands/fwd32j-generator-sim.toml";

/// `ident sweep --broadband` of the stand file `stand` into `out`.
fn broadband_sweep(stand: &Path, out: &Path) -> std::process::Output {
    ident(&["sweep", "--stand", p(stand), "--broadband", "--out", p(out)])
}

#[test]
fn broadband_sweep_through_the_generator_and_process_give_the_truth_frf() {
    let dir = tempfile::tempdir().unwrap();
    let stand_path = root().join(STAND);
    let o = broadband_sweep(&stand_path, dir.path());
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    assert!(
        out.contains("8 averages of 381 lines (20.0 to 400.0 Hz)"),
        "{out}"
    );
    let session = dir
        .path()
        .join(
            out.lines()
                .find_map(|l| l.strip_prefix("session: "))
                .unwrap_or_else(|| panic!("no session path: {out}")),
        )
        .canonicalize()
        .unwrap();

    let processed = dir.path().join("processed");
    let o = ident(&["process", p(&session), "--out", p(&processed)]);
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    assert!(
        out.contains("381 of 381 steps equal the live estimate bit for bit"),
        "{out}"
    );
    let stem = session.file_stem().unwrap().to_string_lossy().into_owned();
    let csv = std::fs::read_to_string(processed.join(format!("{stem}.steps.csv"))).unwrap();

    // The truth: the plant's response per N of delivered force. Tolerance from the simulated
    // noise (as in acquire/tests/generator_broadband.rs): a line's H1 error has an RMS of
    // 2(σ_a + |H|σ_F)/(a√N√n), a = the force's line amplitude under the shaker roll-off, N =
    // samples per period, n = averages; 4.5 times it.
    let stand = Stand::load(&stand_path).unwrap();
    let plan = stand.broadband.clone().unwrap();
    let setup = SimSetup::from_stand(&stand).unwrap();
    let truth = stand.truth.as_ref().unwrap();
    let freqs: Vec<f64> = (20..=400).map(f64::from).collect();
    let response = setup.plant.response(&freqs).unwrap();
    let g: Vec<f64> = freqs
        .iter()
        .map(|f| setup.interaction.at(*f).norm())
        .collect();
    let g2: f64 = g.iter().map(|x| x * x).sum();
    let per_line = 2.0 / (stand.daq.sample_rate_hz.sqrt() * f64::from(plan.averages).sqrt());
    let names: Vec<&str> = stand.channels.iter().map(|c| c.name.as_str()).collect();
    let mut rows = 0;
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (hz, channel) = (f[1].parse::<f64>().unwrap(), f[3]);
        assert_eq!(f[13], "true", "{line}");
        let c = names.iter().position(|n| *n == channel).unwrap();
        if c == 0 {
            continue; // the force against itself
        }
        let k = (hz - 20.0).round() as usize;
        assert_eq!(freqs[k], hz);
        let want = response[k][c - 1];
        let got = acquire::sim::plant::C64::new(f[6].parse().unwrap(), f[7].parse().unwrap());
        let a = g[k] * plan.force_n * (2.0 / g2).sqrt();
        let rms = per_line * (truth.noise_acceleration + want.norm() * truth.noise_force) / a;
        assert!(
            (got - want).norm() <= 4.5 * rms,
            "{hz} Hz {channel}: {got} vs the truth's {want} (noise RMS {rms:.2e})"
        );
        rows += 1;
    }
    assert_eq!(rows, 381 * 7);
}

#[test]
fn a_broadband_section_the_generator_cannot_play_names_the_field_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(root().join(STAND)).unwrap();
    let write = |name: &str, text: &str| {
        let path = dir.path().join(name);
        // Relative paths of the repository's stand stay valid next to it.
        std::fs::write(
            &path,
            text.replace(
                "../models/",
                &format!("{}/configs/models/", root().display()),
            ),
        )
        .unwrap();
        path
    };
    let cases = [
        // A 100 s chirp at 5120 Hz is 512 000 points; the simulated model takes 65 536.
        (
            "long.toml",
            good.replace(
                "waveform = \"random\"",
                "waveform = \"chirp\"\nperiod = \"100 s\"",
            ),
            &[
                "512000 points",
                "IDENT-SIM SIGGEN",
                "65536",
                "shorten broadband.period",
            ][..],
        ),
        // A model without uploads.
        (
            "generic.toml",
            good.replace("retries = 2\n", "retries = 2\ndialect = \"generic\"\n"),
            &[
                "`generic` (generator.dialect) has no arbitrary-waveform upload",
                "stepped sine",
            ],
        ),
        // No [broadband] at all.
        (
            "none.toml",
            good[..good.find("\n# `ident sweep --broadband`").unwrap()].to_string(),
            &["has no [broadband] section"],
        ),
    ];
    for (name, stand, says) in cases {
        let stand = write(name, &stand);
        let o = broadband_sweep(&stand, dir.path());
        let out = text(&o);
        assert!(!o.status.success(), "{out}");
        for want in says {
            assert!(out.contains(want), "{out}");
        }
    }
}
