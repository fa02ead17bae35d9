//! Broadband drive through a SCPI signal generator on the simulated stand: the periodic random
//! waveform uploaded as a binary block, played by the simulated generator through the amplifier
//! and shaker into the truth plant, gives the plant's FRF through the one broadband estimator;
//! the force RMS is brought to its target while settling; the waveform (its DAC codes) and every
//! setting are in the session, whose replay is bit-identical; a model without arbitrary waveforms
//! and a waveform too long for the model are refused with the output off.

// Test helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod util;

use std::path::Path;

use acquire::generator::waveform;
use acquire::record::{DriveKind, DriveRecord};
use acquire::session;
use acquire::shaker::Waveform;
use acquire::sim::generator::GeneratorState;
use acquire::sim::{SimSetup, SimStand};
use acquire::stand::{GeneratorAddress, Stand};
use acquire::sweep::{self, Broadband, BroadbandResult, NoProgress, StopSignal};
use util::*;

/// The repository's generator stand on a pty, five times faster than real time.
fn generator_stand() -> Stand {
    let p =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands/fwd32j-generator-sim.toml");
    let mut s = Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
    s.generator.as_mut().unwrap().port = GeneratorAddress::Sim { tcp: false };
    s.truth.as_mut().unwrap().speed = 5.0;
    s
}

fn random_plan() -> Broadband {
    Broadband {
        waveform: Waveform::Random {
            f_lo_hz: 20.0,
            f_hi_hz: 400.0,
        },
        force_n: 500.0,
        averages: 6,
        settle_periods: 4,
    }
}

/// Runs `plan` on `stand`'s simulated generator stand into `path`: the result (as text on
/// error) and the generator's final state.
async fn run(
    stand: &Stand,
    plan: &Broadband,
    path: &Path,
) -> (Result<BroadbandResult, String>, GeneratorState) {
    let sim = SimStand::start(stand).unwrap();
    let bound = sim.bind(stand);
    let r = recorded(stand, &bound, plan, path, async |rig, h| {
        sweep::broadband(rig, plan, h, &NoProgress, &StopSignal::new()).await
    })
    .await;
    (r, sim.generator_state().unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn periodic_random_through_the_generator_gives_the_plants_frf_and_replays_bit_identically() {
    bounded(120, async {
        let stand = generator_stand();
        let plan = random_plan();
        let (_d, path) = temp_file("gen-bb.mcap");
        let (r, state) = run(&stand, &plan, &path).await;
        let r = r.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.averages, plan.averages);
        assert!(!state.output_on, "output left on");

        // The generator played what was uploaded: one period at the DAQ's rate, looping.
        let fs = stand.daq.sample_rate_hz;
        let (name, played) = state.uploaded.clone().unwrap();
        assert_eq!(name, "IDENT");
        assert_eq!(played.samples.len(), fs as usize);
        assert_eq!(played.sample_rate_hz, fs);
        assert!(state.arbitrary && state.selected.as_deref() == Some("IDENT"));

        // The FRF of every accelerometer against the plant's (the truth's response per N of the
        // force delivered, which the force channel measures). The tolerance comes from the
        // simulated noise: white noise of RMS σ over a period of N samples puts √N·σ into each
        // DFT line, against N·a/2 for a line of amplitude a; so the complex error of H1 at a line
        // has an RMS of 2(σ_a + |H|·σ_F)/(a·√N·√n) over n averages. The force's lines follow the
        // shaker's roll-off |g(f)| (flat drive, measured force RMS = the target):
        // a_k = |g_k|·F_rms·√(2/Σ|g|²). A complex Gaussian error exceeds k times its RMS with
        // probability exp(−k²): k = 4.5 makes a false failure among the 2667 values ~4e-6.
        let setup = SimSetup::from_stand(&stand).unwrap();
        let truth = setup.plant.response(&r.freqs_hz).unwrap();
        let t = stand.truth.as_ref().unwrap();
        let (sigma_a, sigma_f) = (t.noise_acceleration, t.noise_force);
        let g: Vec<f64> = r
            .freqs_hz
            .iter()
            .map(|f| setup.interaction.at(*f).norm())
            .collect();
        let g2: f64 = g.iter().map(|x| x * x).sum();
        let n_avg = f64::from(r.averages);
        let samples_per_period = fs;
        let mut checked = 0;
        let mut worst: f64 = 0.0;
        for (j, f) in r.freqs_hz.iter().enumerate() {
            let a = g[j] * plan.force_n * (2.0 / g2).sqrt();
            for (c, want) in truth[j].iter().enumerate() {
                let got = r.h1[c + 1][j];
                let rms = 2.0 * (sigma_a + want.norm() * sigma_f)
                    / (a * samples_per_period.sqrt() * n_avg.sqrt());
                let err = (got - want).norm();
                assert!(
                    err <= 4.5 * rms + 1e-6 * want.norm(),
                    "{f} Hz channel {}: {got} vs the plant's {want} (noise RMS {rms:.3e})",
                    c + 1
                );
                worst = worst.max(err / rms);
                checked += 1;
            }
        }
        assert_eq!(r.freqs_hz.len(), 381, "1 Hz lines 20..400 Hz");
        assert!(checked == 381 * 7, "{checked}");
        println!("largest FRF error {worst:.2} times its noise RMS");
        assert!(worst > 0.5, "the noise is there: {worst}");
        let mean = r.coherence[1].iter().sum::<f64>() / r.coherence[1].len() as f64;
        assert!(mean > 0.95, "mean coherence {mean}");

        // The session holds the waveform exactly as sent, and every setting.
        let rs = records(&path);
        let drive: Vec<DriveRecord> = session::read(&path).unwrap().all().unwrap();
        let w: Vec<&DriveRecord> = drive
            .iter()
            .filter(|d| d.kind == DriveKind::Waveform)
            .collect();
        assert_eq!(w.len(), 1);
        let w = w[0];
        assert_eq!(w.waveform.as_ref(), Some(&plan.waveform));
        assert_eq!(w.sample_rate_hz, Some(fs));
        assert_eq!(w.code_range, Some((-32767, 32767)));
        let codes = w.codes.clone().unwrap();
        let synthesized = waveform::synthesize(&plan.waveform, fs, w.seed.unwrap()).unwrap();
        let expect: Vec<i32> = synthesized
            .samples
            .iter()
            .map(|x| (x * 32767.0).round() as i32)
            .collect();
        assert_eq!(
            codes, expect,
            "the recorded codes are the seeded waveform's"
        );
        assert!(
            played
                .samples
                .iter()
                .zip(&codes)
                .all(|(p, c)| *p == f64::from(*c) / 32767.0),
            "the generator received every code of the binary block"
        );
        // Force: measured every period; within the amplifier's tolerance in every averaged one.
        let tol = stand.generator.as_ref().unwrap().amplifier.tolerance;
        let m: Vec<&DriveRecord> = drive
            .iter()
            .filter(|d| d.kind == DriveKind::Measurement)
            .collect();
        assert!(m.len() >= (plan.settle_periods + plan.averages) as usize);
        for d in &m {
            let (got, target) = (d.force_n.unwrap(), d.target_n.unwrap());
            assert!((target - plan.force_n).abs() < 1e-9);
            if d.step.unwrap() as u32 >= plan.settle_periods {
                assert!(
                    (got / target - 1.0).abs() <= tol,
                    "period {:?}: {got:.1} N RMS against {target} N",
                    d.step
                );
            }
        }
        // The estimate of the first settling period starts from the gain estimate (4 % low,
        // and the shaker's roll-off): it is corrected there, and the drive records say so.
        let first = m[0].force_n.unwrap();
        assert!((first / plan.force_n - 1.0).abs() > tol, "{first}");
        assert!(topic(&rs, "/sweep/event")
            .iter()
            .any(|e| e.value["kind"] == "force_control"));
        let amplitudes = drive
            .iter()
            .filter(|d| d.kind == DriveKind::Amplitude)
            .count();
        let logged = state.log.iter().filter(|a| a.what == "amplitude").count();
        assert_eq!(amplitudes, logged, "every amplitude accepted is recorded");
        assert!(state.log.iter().all(|a| a.what != "amplitude"
            || a.value <= stand.generator.as_ref().unwrap().amplifier.voltage_limit_v));

        // Replay from the file: every line equals the live estimate bit for bit.
        let a = acquire::analysis::characteristics(&path, &Default::default()).unwrap();
        assert_eq!(a.steps.len(), r.freqs_hz.len());
        assert!(a.steps.iter().all(|s| s.matches_live));
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_model_without_arbitrary_waveforms_and_a_too_long_waveform_are_refused_with_the_output_off(
) {
    bounded(120, async {
        // The plain SCPI-99 table has no upload.
        let mut stand = generator_stand();
        stand.generator.as_mut().unwrap().dialect = Some("generic".into());
        let (_d, path) = temp_file("gen-bb-generic.mcap");
        let (r, state) = run(&stand, &random_plan(), &path).await;
        let e = r.unwrap_err();
        assert!(
            e.contains("`generic` has no arbitrary-waveform upload") && e.contains("dialect"),
            "{e}"
        );
        assert!(!state.output_on && state.uploaded.is_none());

        // 20 s at 5120 Hz is 102 400 points; the simulated model takes 65 536.
        let stand = generator_stand();
        let plan = Broadband {
            waveform: Waveform::Chirp {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
                period_s: 20.0,
            },
            ..random_plan()
        };
        let (_d, path) = temp_file("gen-bb-long.mcap");
        let (r, state) = run(&stand, &plan, &path).await;
        let e = r.unwrap_err();
        assert!(
            e.contains("102400 points")
                && e.contains("8..65536")
                && e.contains("IDENT-SIM SIGGEN")
                && e.contains("period_s")
                && e.contains("sample_rate"),
            "{e}"
        );
        assert!(!state.output_on && state.uploaded.is_none());
        // The session is complete and says why it ended.
        let rs = records(&path);
        assert!(topic(&rs, "/sweep/event")
            .iter()
            .any(|e| e.value["kind"] == "error"));
    })
    .await
}
