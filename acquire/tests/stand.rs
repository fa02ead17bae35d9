//! End-to-end checks of the acquisition over pseudo-terminals against the simulated stand:
//! a stepped-sine sweep recovers the truth FRF from the session file, injected faults are all
//! detected and recorded, device failures end the sweep cleanly, stop/resume, bad input.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod util;

use std::collections::BTreeSet;

use acquire::daq::{Daq, DaqError, DaqOptions, SerialDaq};
use acquire::rig::{Rig, RigError};
use acquire::session::{Session, SessionOptions};
use acquire::shaker::{ScpiShaker, Shaker, ShakerError, ShakerOptions};
use acquire::sim::plant::{Interaction, SdofPlant, C64};
use acquire::sim::{SimSetup, SimStand};
use acquire::stand::{Stand, TruthModel};
use acquire::sweep::estimate::StepEstimator;
use acquire::sweep::{
    self, FrequencyList, NoProgress, SteppedSine, StopSignal, SweepError, SweepProgress,
};
use acquire::transport::{open_serial, pty_pair, SerialSettings, TransportError};
use serde_json::Value;
use util::*;

fn quick_plan(n: usize) -> SteppedSine {
    SteppedSine {
        frequencies: FrequencyList::Log {
            start: 40.0,
            stop: 250.0,
            n,
        },
        settle_s: 0.05,
        cycles: 10.0,
        min_window_s: 0.15,
        max_retries: 8,
        ..SteppedSine::default()
    }
}

/// The truth accelerance of each acceleration channel (stand order) at `f`.
fn truth(stand: &Stand, f: f64) -> Vec<C64> {
    let t = stand.truth.as_ref().unwrap();
    let TruthModel::Sdof {
        mass,
        stiffness,
        loss_factor,
        direction,
        ..
    } = &t.model
    else {
        panic!("sdof truth expected")
    };
    let p = SdofPlant {
        mass: *mass,
        stiffness: *stiffness,
        loss_factor: *loss_factor,
        gains: vec![],
    };
    stand
        .channels
        .iter()
        .filter(|c| c.kind == acquire::stand::ChannelKind::Acceleration)
        .map(|c| {
            p.accelerance(f)
                * c.direction
                    .iter()
                    .zip(direction)
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
        })
        .collect()
}

async fn run_sweep(
    stand: &Stand,
    plan: &SteppedSine,
    path: &std::path::Path,
    stop: &StopSignal,
    skip: &BTreeSet<usize>,
    progress: &dyn SweepProgress,
) -> (Result<sweep::SweepOutcome, SweepError>, SimStand) {
    let sim = SimStand::start(stand).unwrap();
    let bound = sim.bind(stand);
    let session = Session::create(path, SessionOptions::default()).unwrap();
    let h = session.handle();
    sweep::log_session_start(&h, &stand.file, plan, None, skip).unwrap();
    let r = async {
        let mut rig = Rig::connect(&bound, Some(&h))
            .await
            .map_err(|e| SweepError::Plan(e.to_string()))?;
        sweep::stepped_sine(&mut rig, plan, &h, progress, stop, skip).await
    }
    .await;
    session.finish().unwrap();
    (r, sim)
}

/// [`run_sweep`] with nothing skipped, no stop and no progress display.
async fn sweep_to_the_end(
    stand: &Stand,
    plan: &SteppedSine,
    path: &std::path::Path,
) -> (Result<sweep::SweepOutcome, SweepError>, SimStand) {
    let none = BTreeSet::new();
    run_sweep(stand, plan, path, &StopSignal::new(), &none, &NoProgress).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stepped_sine_over_ptys_recovers_the_truth_frf_from_the_session_file() {
    bounded(120, async {
        let stand = sim_stand(8.0);
        let plan = SteppedSine {
            frequencies: FrequencyList::AroundResonances {
                resonances: vec![95.1],
                relative_span: 0.5,
                per_resonance: 9,
            },
            // At 8× real time the blocks queued during a shaker command exchange amount to
            // ~10 ms × 8; settle well beyond that.
            settle_s: 0.25,
            ..quick_plan(0)
        };
        let (_d, path) = temp_file("e2e.mcap");
        let (r, _sim) = sweep_to_the_end(&stand, &plan, &path).await;
        let outcome = r.unwrap();
        assert_eq!(outcome.steps.len(), 9);
        assert_eq!(stand.force_channel(), 0);
        assert_eq!(outcome.faults, 0);

        let rs = records(&path);
        let stream = topic(&rs, "/daq/stream")[0].value.clone();
        let fs = stream["sample_rate_hz"].as_f64().unwrap();
        let blocks = topic(&rs, "/daq/block");
        let steps = topic(&rs, "/sweep/step");
        assert_eq!(steps.len(), 9);
        assert_eq!(topic(&rs, "/device/identity").len(), 2);
        assert!(!topic(&rs, "/raw").is_empty());
        let nch = stand.channels.len();
        let t = stand.truth.as_ref().unwrap();
        for s in steps {
            let v = &s.value;
            let f = v["frequency_hz"].as_f64().unwrap();
            let first = v["first_sample"].as_u64().unwrap();
            let n = v["samples"].as_u64().unwrap();
            // Closed loop held the target force.
            let famp = v["force_amplitude_n"].as_f64().unwrap();
            assert!(
                (famp - 4000.0).abs() <= 0.03 * 4000.0 + 1.0,
                "{f} Hz: force {famp}"
            );
            // Recompute the step from the recorded blocks alone (an independent walk over the
            // blocks; acquire::analysis is checked against this in tests/pipeline.rs).
            let sens: Vec<f64> = stand.channels.iter().map(|c| c.sensitivity).collect();
            let mut est = StepEstimator::new(fs, &sens, stand.force_channel());
            for b in &blocks {
                let b0 = b.value["first_sample"].as_u64().unwrap();
                let volts = b.value["volts"].as_array().unwrap();
                let len = volts[0].as_array().unwrap().len() as u64;
                for i in 0..len {
                    let k = b0 + i;
                    if k >= first && k < first + n {
                        let row: Vec<f32> = (0..nch)
                            .map(|c| volts[c][i as usize].as_f64().unwrap() as f32)
                            .collect();
                        est.push_row(&row);
                    }
                }
            }
            assert_eq!(
                est.len() as u64,
                n,
                "window of step at {f} Hz not fully in the file"
            );
            let fit = est.estimate(f).unwrap();
            let force = fit.force.fundamental;
            let want = truth(&stand, f);
            for (c, w) in want.iter().enumerate() {
                let ch = c + 1;
                let h = fit.frf[c];
                // Noise bound: σ(H)/|F| ≈ sqrt(2/N)(σ_a + |H| σ_F)/|F|; 6 σ plus 0.2 % for
                // quantisation and f32 rounding.
                let sigma = (2.0 / n as f64).sqrt()
                    * (t.noise_acceleration + w.norm() * t.noise_force)
                    / force.norm();
                let tol = 6.0 * sigma + 2e-3 * w.norm();
                assert!(
                    (h - w).norm() < tol,
                    "{f:.2} Hz channel {}: H = {h}, truth {w}, tol {tol:e}",
                    stand.channels[ch].name
                );
                // The live estimate recorded by the sweep is the recomputation, bit for bit.
                let live = C64::new(
                    v["channels"][ch]["frf_re"].as_f64().unwrap(),
                    v["channels"][ch]["frf_im"].as_f64().unwrap(),
                );
                assert_eq!(
                    (live.re.to_bits(), live.im.to_bits()),
                    (h.re.to_bits(), h.im.to_bits()),
                    "{live} vs {h}"
                );
            }
        }
        // The Python reader decodes every channel.
        let (n, topics) = python_read(&path);
        assert_eq!(n, rs.len() as u64);
        assert!(topics.contains(&"/sweep/step".to_string()));
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_injected_stream_fault_is_detected_and_recorded() {
    bounded(120, async {
        let mut stand = sim_stand(10.0);
        stand.faults.drop = 0.01;
        stand.faults.corrupt = 0.01;
        stand.faults.duplicate = 0.01;
        stand.faults.seed = 42;
        let plan = quick_plan(5);
        let (_d, path) = temp_file("faults.mcap");
        let (r, sim) = sweep_to_the_end(&stand, &plan, &path).await;
        let outcome = r.unwrap();
        assert_eq!(
            outcome.steps.len(),
            5,
            "the sweep re-measures windows hit by faults"
        );
        let rs = records(&path);
        // Stream order: faults and blocks are recorded in the order they were decoded.
        let last_block = rs.iter().rposition(|r| r.topic == "/daq/block").unwrap();
        let last_seq = rs[last_block].value["seq"].as_u64().unwrap();
        let injected = sim.injected();
        let count = |k: &str| {
            injected
                .iter()
                .filter(|f| f.kind == k && f.seq < last_seq)
                .count() as u64
        };
        let (drops, corrupts, dups) = (count("drop"), count("corrupt"), count("duplicate"));
        assert!(
            drops + corrupts + dups >= 3,
            "seeded faults should fire: {injected:?}"
        );
        let faults: Vec<&Value> = rs[..last_block]
            .iter()
            .filter(|r| r.topic == "/daq/fault")
            .map(|r| &r.value)
            .collect();
        let kind = |k: &str| faults.iter().filter(|f| f["kind"] == k).count() as u64;
        assert_eq!(
            kind("crc") + kind("framing"),
            corrupts,
            "every corrupted frame is a CRC/framing fault: {faults:?}"
        );
        assert_eq!(kind("duplicate"), dups, "every duplicate is reported");
        let missing: u64 = faults
            .iter()
            .filter(|f| f["kind"] == "gap")
            .map(|f| {
                f["detail"]
                    .as_str()
                    .unwrap()
                    .split('(')
                    .nth(1)
                    .unwrap()
                    .split(' ')
                    .next()
                    .unwrap()
                    .parse::<u64>()
                    .unwrap()
            })
            .sum();
        assert_eq!(
            missing,
            drops + corrupts,
            "every dropped or corrupted block shows up in a gap"
        );
        // No block is accepted twice or out of order.
        let seqs: Vec<u64> = topic(&rs, "/daq/block")
            .iter()
            .map(|b| b.value["seq"].as_u64().unwrap())
            .collect();
        assert!(seqs.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(
            seqs.len() as u64 + missing,
            last_seq + 1,
            "blocks + missing account for every sequence number"
        );
        // Windows hit by faults were re-measured, and that is recorded.
        assert!(topic(&rs, "/sweep/event")
            .iter()
            .any(|e| e.value["kind"] == "retry"));
    })
    .await
}

async fn expect_sweep_error(
    mut stand: Stand,
    set: impl FnOnce(&mut acquire::stand::Faults),
) -> (SweepError, Vec<acquire::session::Record>) {
    set(&mut stand.faults);
    let (_d, path) = temp_file("fail.mcap");
    let (r, _sim) = sweep_to_the_end(&stand, &quick_plan(6), &path).await;
    let e = r.expect_err("the sweep must fail");
    let rs = records(&path); // the file is still complete
    assert!(
        topic(&rs, "/sweep/event")
            .iter()
            .any(|x| x.value["kind"] == "error"
                && x.value["detail"].as_str().unwrap() == e.to_string()),
        "error recorded"
    );
    (e, rs)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silent_daq_is_a_timeout_naming_the_port() {
    bounded(60, async {
        let (e, _) =
            expect_sweep_error(sim_stand(10.0), |f| f.daq_silent_after_blocks = Some(60)).await;
        let SweepError::Daq(DaqError::Timeout { port, .. }) = &e else {
            panic!("{e}")
        };
        assert!(port.starts_with("/dev/pts/"), "{e}");
        assert!(
            e.to_string().contains("check that the device is powered"),
            "{e}"
        );
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pulled_cable_mid_sweep_ends_the_sweep_cleanly() {
    bounded(60, async {
        let (e, rs) =
            expect_sweep_error(sim_stand(10.0), |f| f.cable_pull_after_blocks = Some(60)).await;
        assert!(
            matches!(
                e,
                SweepError::Daq(DaqError::Disconnected { .. } | DaqError::Timeout { .. })
                    | SweepError::Shaker(
                        ShakerError::Disconnected { .. } | ShakerError::Timeout { .. }
                    )
            ),
            "{e}"
        );
        assert!(e.to_string().contains("/dev/pts/"), "{e}");
        // Blocks before the pull are in the file, in order and without holes (blocks still in
        // the port's buffer when the cable goes are lost with it, as on real hardware).
        let seqs: Vec<u64> = topic(&rs, "/daq/block")
            .iter()
            .map(|b| b.value["seq"].as_u64().unwrap())
            .collect();
        assert!(
            seqs.len() >= 20 && seqs.len() <= 61,
            "{} blocks",
            seqs.len()
        );
        assert!(seqs.iter().enumerate().all(|(i, s)| *s == i as u64));
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn silent_shaker_controller_is_a_timeout_naming_the_command() {
    bounded(60, async {
        let (e, _) = expect_sweep_error(sim_stand(10.0), |f| {
            f.shaker_silent_after_commands = Some(14)
        })
        .await;
        let SweepError::Shaker(ShakerError::Timeout {
            command, attempts, ..
        }) = &e
        else {
            panic!("{e}")
        };
        assert_eq!(*attempts, 3);
        assert!(!command.is_empty());
    })
    .await
}

struct StopAfter(usize, StopSignal);
impl SweepProgress for StopAfter {
    fn start(&self, _: u64, _: u64) {}
    fn step(&self, step: usize, _: f64, _: f64, _: f64) {
        if step + 1 >= self.0 {
            self.1.set();
        }
    }
    fn finish(&self, _: &str) {}
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stop_leaves_a_complete_file_and_the_sweep_resumes_from_it() {
    bounded(120, async {
        let stand = sim_stand(10.0);
        let plan = quick_plan(6);
        let (_d, first) = temp_file("first.mcap");
        let stop = StopSignal::new();
        let (r, _sim) = run_sweep(
            &stand,
            &plan,
            &first,
            &stop,
            &BTreeSet::new(),
            &StopAfter(2, stop.clone()),
        )
        .await;
        let o = r.unwrap();
        assert!(o.stopped);
        assert_eq!(o.steps.len(), 2);
        let rs = records(&first);
        assert!(topic(&rs, "/sweep/event")
            .iter()
            .any(|e| e.value["kind"] == "stopped"));

        let done = sweep::completed_steps(&first, &plan).unwrap();
        assert_eq!(done, [0, 1].into_iter().collect());
        let other = quick_plan(7);
        assert!(matches!(
            sweep::completed_steps(&first, &other),
            Err(SweepError::Resume { .. })
        ));

        let second = first.with_file_name("second.mcap");
        let (r, _sim) = run_sweep(
            &stand,
            &plan,
            &second,
            &StopSignal::new(),
            &done,
            &NoProgress,
        )
        .await;
        let o = r.unwrap();
        assert!(!o.stopped);
        let measured: Vec<usize> = o.steps.iter().map(|s| s.step).collect();
        assert_eq!(measured, vec![2, 3, 4, 5]);
        assert_eq!(o.skipped, vec![0, 1]);
        // Chained resume sees all six as done.
        assert_eq!(sweep::completed_steps(&second, &plan).unwrap().len(), 6);
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_ports_give_errors_that_name_the_port() {
    bounded(30, async {
        let e = open_serial("/dev/ttyDOESNOTEXIST9", &SerialSettings::default()).unwrap_err();
        assert!(matches!(e, TransportError::NotFound { .. }), "{e}");
        assert!(
            e.to_string().contains("/dev/ttyDOESNOTEXIST9") && e.to_string().contains("plugged in"),
            "{e}"
        );

        let e = open_serial("/dev/null", &SerialSettings::default()).unwrap_err();
        assert!(matches!(e, TransportError::NotSerial { .. }), "{e}");
        let e = open_serial("/tmp", &SerialSettings::default()).unwrap_err();
        assert!(matches!(e, TransportError::NotSerial { .. }), "{e}");

        // A port already opened by another program is refused (flock), even for root.
        let pty = pty_pair("daq").unwrap();
        let first = open_serial(&pty.path, &SerialSettings::default()).unwrap();
        let e = open_serial(&pty.path, &SerialSettings::default()).unwrap_err();
        assert!(matches!(e, TransportError::Busy { .. }), "{e}");
        assert!(
            e.to_string().contains(&pty.path) && e.to_string().contains("already in use"),
            "{e}"
        );
        drop(first);
        open_serial(&pty.path, &SerialSettings::default()).expect("free again after close");
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_identities_are_refused() {
    bounded(30, async {
        let stand = sim_stand(10.0);
        let mut setup = SimSetup::from_stand(&stand).unwrap();
        setup.identities.shaker.manufacturer = "ACME".into();
        let sim = SimStand::start_with(setup).unwrap();
        let e = Rig::connect(&sim.bind(&stand), None).await.err().unwrap();
        assert!(
            matches!(e, RigError::Shaker(ShakerError::WrongIdentity { .. })),
            "{e}"
        );
        assert!(
            e.to_string().contains("ACME,SHAKER-4K") && e.to_string().contains(&sim.shaker_port),
            "{e}"
        );

        let mut setup = SimSetup::from_stand(&stand).unwrap();
        setup.identities.daq.model = "SCOPE".into();
        let sim = SimStand::start_with(setup).unwrap();
        let e = Rig::connect(&sim.bind(&stand), None).await.err().unwrap();
        assert!(
            matches!(e, RigError::Daq(DaqError::WrongIdentity { .. }))
                || e.to_string().contains("identifies as `IDENT-SIM,SCOPE"),
            "{e}"
        );
    })
    .await
}

/// The path of a pseudo-terminal for `role` whose "device" answers every line with `junk`.
fn garbage_port(role: &str, junk: &'static [u8]) -> String {
    let pty = pty_pair(role).unwrap();
    tokio::spawn(garbage_device(pty.device, junk));
    pty.path
}

/// What a shaker controller answering every line with `junk` makes of `*IDN?`.
async fn garbage_shaker_identity(junk: &'static [u8], opts: ShakerOptions) -> ShakerError {
    let path = garbage_port("shaker", junk);
    let mut sh = ScpiShaker::new(
        open_serial(&path, &SerialSettings::default()).unwrap(),
        opts,
    );
    sh.identify().await.unwrap_err()
}

/// A "device" that answers every line with noise.
async fn garbage_device(mut io: acquire::transport::SerialTransport, junk: &'static [u8]) {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut buf = [0u8; 256];
    let deadline = tokio::time::Instant::now() + std::time::Duration::from_secs(20);
    while tokio::time::Instant::now() < deadline {
        match tokio::time::timeout(std::time::Duration::from_millis(50), io.read(&mut buf)).await {
            Ok(Ok(n)) if n > 0 => {
                let _ = io.write_all(junk).await;
            }
            // EIO until the host opens the port.
            Ok(_) => tokio::time::sleep(std::time::Duration::from_millis(10)).await,
            Err(_) => {}
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn devices_answering_garbage_are_reported() {
    bounded(30, async {
        let opts = ShakerOptions {
            timeout: std::time::Duration::from_millis(150),
            retries: 1,
        };
        // Text without line ends (wrong baud rate): timeout with a hint.
        let e = garbage_shaker_identity(b"\xfe\x13\x88garbage", opts.clone()).await;
        assert!(matches!(e, ShakerError::Timeout { .. }), "{e}");
        assert!(e.to_string().contains("without a line end"), "{e}");
        // A line that is not an identity.
        let e = garbage_shaker_identity(b"hello world\n", opts).await;
        assert!(matches!(e, ShakerError::Garbled { .. }), "{e}");
        assert!(e.to_string().contains("hello world"), "{e}");
        // A DAQ port with a text device on it.
        let path = garbage_port("daq", b"OK\r\n>");
        let mut daq = SerialDaq::new(
            open_serial(&path, &SerialSettings::default()).unwrap(),
            DaqOptions {
                command_timeout: std::time::Duration::from_millis(150),
                retries: 1,
                ..Default::default()
            },
        );
        let e = daq.identify().await.unwrap_err();
        assert!(matches!(e, DaqError::Timeout { .. }), "{e}");
        assert!(
            e.to_string().contains("not DAQ frames") && e.to_string().contains(&path),
            "{e}"
        );
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn controller_errors_reach_the_operator() {
    bounded(30, async {
        let stand = sim_stand(10.0);
        let sim = SimStand::start(&stand).unwrap();
        let mut sh = ScpiShaker::new(
            open_serial(&sim.shaker_port, &SerialSettings::default()).unwrap(),
            ShakerOptions::default(),
        );
        sh.reset().await.unwrap();
        let e = sh.set_force(99_000.0).await.unwrap_err();
        let ShakerError::Device { code, message, .. } = &e else {
            panic!("{e}")
        };
        assert_eq!(*code, -222);
        assert!(message.contains("force"), "{e}");
        // The queue is drained: the next command succeeds.
        sh.set_force(100.0).await.unwrap();
        let e = sh
            .query(&acquire::shaker::scpi::Command::QueryForce)
            .await
            .unwrap();
        assert_eq!(e.trim(), "100");
        assert!(matches!(
            sh.set_frequency(f64::NAN).await,
            Err(ShakerError::InvalidValue { .. })
        ));
        let st = sh.status().await.unwrap();
        assert!(!st.output_on);
        let _ = Interaction {
            gain: 1.0,
            cutoff_hz: 1.0,
        };
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broadband_random_and_chirp_recover_the_truth_frf() {
    bounded(120, async {
        let stand = sim_stand(10.0);
        for waveform in [
            acquire::shaker::Waveform::Random {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
            },
            acquire::shaker::Waveform::Chirp {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
                period_s: 0.5,
            },
            acquire::shaker::Waveform::BurstRandom {
                f_lo_hz: 20.0,
                f_hi_hz: 400.0,
                duty: 0.5,
                period_s: 0.5,
            },
        ] {
            let sim = SimStand::start(&stand).unwrap();
            let (_d, path) = temp_file("bb.mcap");
            let session = Session::create(&path, SessionOptions::default()).unwrap();
            let h = session.handle();
            let plan = sweep::Broadband {
                waveform: waveform.clone(),
                force_n: 1000.0,
                averages: 4,
                settle_periods: 1,
            };
            sweep::log_session_start(&h, &stand.file, &plan, None, &BTreeSet::new()).unwrap();
            let mut rig = Rig::connect(&sim.bind(&stand), Some(&h)).await.unwrap();
            let r = sweep::broadband(&mut rig, &plan, &h, &NoProgress, &StopSignal::new())
                .await
                .unwrap();
            session.finish().unwrap();
            assert_eq!(r.averages, 4);
            let mut checked = 0;
            for (j, &f) in r.freqs_hz.iter().enumerate() {
                let want = truth(&stand, f);
                for (c, w) in want.iter().enumerate() {
                    let got = r.h1[c + 1][j];
                    // Noise is small against the periodic excitation: 2 % (chirp ends are weak).
                    assert!(
                        (got - w).norm() < 0.02 * w.norm() + 1e-3,
                        "{waveform:?} {f} Hz ch {c}: {got} vs {w}"
                    );
                    checked += 1;
                }
                // Low-frequency bins carry little acceleration against the sensor noise.
                assert!(
                    r.coherence[1][j] > 0.8,
                    "{waveform:?} {f} Hz coherence {}",
                    r.coherence[1][j]
                );
            }
            let mean = r.coherence[1].iter().sum::<f64>() / r.coherence[1].len() as f64;
            assert!(mean > 0.98, "{waveform:?}: mean coherence {mean}");
            assert!(checked > 100);
            let rs = records(&path);
            assert_eq!(
                topic(&rs, "/sweep/event")
                    .iter()
                    .filter(|e| e.value["kind"] == "average")
                    .count(),
                4
            );
            // The H1 estimates are in the session, exactly as returned.
            let bb = topic(&rs, "/sweep/broadband");
            assert_eq!(bb.len(), 1);
            let ch1 = &bb[0].value["channels"][1];
            assert_eq!(ch1["name"], stand.channels[1].name.as_str());
            let re: Vec<f64> = ch1["h1_re"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            assert_eq!(re, r.h1[1].iter().map(|h| h.re).collect::<Vec<_>>());
            // Processing the file replays the blocks through the same averager: every line equals
            // the live estimate bit for bit, and the table's characteristics come out of it.
            let a = acquire::analysis::characteristics(&path, &Default::default()).unwrap();
            assert_eq!(a.steps.len(), r.freqs_hz.len(), "{waveform:?}");
            assert!(
                a.steps.iter().all(|s| s.matches_live),
                "{waveform:?}: a replayed line differs from the live estimate"
            );
            assert!(!a.measured.characteristics.is_empty());
            assert!(a
                .measured
                .source
                .contains(&format!("{} broadband lines (H1)", r.freqs_hz.len())));
        }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rfe_model_truth_is_recovered_by_a_stepped_sine() {
    bounded(120, async {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../configs/stands/fwd32j-model-sim.toml");
        let mut stand = Stand::load(&p).unwrap_or_else(|e| panic!("{e}"));
        stand.truth.as_mut().unwrap().speed = 10.0;
        let plan = SteppedSine {
            frequencies: FrequencyList::Explicit {
                freqs: vec![25.0, 60.0, 140.0],
            },
            settle_s: 0.25,
            ..quick_plan(0)
        };
        let (_d, path) = temp_file("rfe.mcap");
        let (r, _sim) = sweep_to_the_end(&stand, &plan, &path).await;
        let o = r.unwrap();
        let t = stand.truth.as_ref().unwrap();
        let plant = acquire::sim::plant::plant_for(t, &stand.channels).unwrap();
        for s in &o.steps {
            let want = plant.response(&[s.frequency_hz]).unwrap().remove(0);
            for (c, w) in want.iter().enumerate() {
                let ch = &stand.channels[c + 1];
                let got = s.frf(&ch.name).unwrap();
                let sigma = (2.0 / s.samples as f64).sqrt()
                    * (t.noise_acceleration + w.norm() * t.noise_force)
                    / s.force_amplitude_n;
                assert!(
                    (got - w).norm() < 6.0 * sigma + 2e-3 * w.norm(),
                    "{} Hz {}: {got} vs {w}",
                    s.frequency_hz,
                    ch.name
                );
            }
        }
    })
    .await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn in_memory_stand_runs_the_same_sweep_without_any_device() {
    use acquire::transport::MemoryTransport;
    bounded(60, async {
        let stand = sim_stand(10.0);
        let (s_host, s_dev) = MemoryTransport::pair("shaker", "shaker-sim", 1 << 16);
        let (d_host, d_dev) = MemoryTransport::pair("daq", "daq-sim", 1 << 20);
        let _sim = SimStand::serve(
            SimSetup::from_stand(&stand).unwrap(),
            s_dev,
            d_dev,
            "mem:shaker".into(),
            "mem:daq".into(),
        );
        let (_d, path) = temp_file("mem.mcap");
        let session = Session::create(&path, SessionOptions::default()).unwrap();
        let h = session.handle();
        let shaker: Box<dyn Shaker> = Box::new(ScpiShaker::new(s_host, ShakerOptions::default()));
        let daq: Box<dyn Daq> = Box::new(SerialDaq::new(d_host, DaqOptions::default()));
        let mut rig = Rig::from_devices(&stand, shaker, daq, Some(&h))
            .await
            .unwrap();
        assert_eq!(rig.daq_identity.model, "DAQ-8");
        let plan = SteppedSine {
            settle_s: 0.25,
            ..quick_plan(3)
        };
        let o = sweep::stepped_sine(
            &mut rig,
            &plan,
            &h,
            &NoProgress,
            &StopSignal::new(),
            &BTreeSet::new(),
        )
        .await
        .unwrap();
        session.finish().unwrap();
        assert_eq!(o.steps.len(), 3);
        for s in &o.steps {
            let w = truth(&stand, s.frequency_hz)[0];
            let got = s.frf("table-a-x").unwrap();
            assert!(
                (got - w).norm() < 0.01 * w.norm(),
                "{} Hz: {got} vs {w}",
                s.frequency_hz
            );
        }
    })
    .await
}

/// A DAQ whose every block reaches the host `latency` after the device sent it: a buffering
/// link, or a host too busy to read at once (the vcan VM on a loaded machine, where the host
/// fell 0.6 s behind the stream). A block read right after a drive change was taken before it.
struct LateDaq {
    inner: Box<dyn Daq>,
    latency: std::time::Duration,
    arrived: std::collections::VecDeque<(tokio::time::Instant, acquire::daq::DaqEvent)>,
}

#[async_trait::async_trait]
impl Daq for LateDaq {
    fn port(&self) -> &str {
        self.inner.port()
    }
    async fn identify(&mut self) -> Result<acquire::device::DeviceIdentity, DaqError> {
        self.inner.identify().await
    }
    async fn configure(
        &mut self,
        config: &acquire::daq::DaqConfig,
    ) -> Result<acquire::daq::StreamInfo, DaqError> {
        self.inner.configure(config).await
    }
    async fn start(&mut self) -> Result<(), DaqError> {
        self.arrived.clear();
        self.inner.start().await
    }
    async fn next_event(&mut self) -> Result<acquire::daq::DaqEvent, DaqError> {
        loop {
            let due = self.arrived.front().map(|(t, _)| *t + self.latency);
            if due.is_some_and(|d| d <= tokio::time::Instant::now()) {
                return Ok(self.arrived.pop_front().unwrap().1);
            }
            let hold = tokio::time::sleep_until(due.unwrap_or_else(tokio::time::Instant::now));
            tokio::select! {
                e = self.inner.next_event() => self.arrived.push_back((tokio::time::Instant::now(), e?)),
                _ = hold, if due.is_some() => {}
            }
        }
    }
    async fn stop(&mut self) -> Result<(), DaqError> {
        self.arrived.clear();
        self.inner.stop().await
    }
    fn sample_clock(&self) -> Option<u64> {
        self.inner.sample_clock()
    }
}

/// A stepped sine on `stand` whose DAQ is replaced by `daq(rig's DAQ)`, recorded to `path`.
async fn sweep_with_daq(
    stand: &Stand,
    plan: &SteppedSine,
    path: &std::path::Path,
    daq: impl FnOnce(Box<dyn Daq>) -> Box<dyn Daq>,
) -> (Result<sweep::SweepOutcome, SweepError>, SimStand) {
    let sim = SimStand::start(stand).unwrap();
    let bound = sim.bind(stand);
    let session = Session::create(path, SessionOptions::default()).unwrap();
    let h = session.handle();
    let none = BTreeSet::new();
    sweep::log_session_start(&h, &stand.file, plan, None, &none).unwrap();
    let mut rig = Rig::connect(&bound, Some(&h)).await.unwrap();
    rig.daq = daq(rig.daq);
    let r = sweep::stepped_sine(&mut rig, plan, &h, &NoProgress, &StopSignal::new(), &none).await;
    drop(rig);
    session.finish().unwrap();
    (r, sim)
}

/// Checks that each line's window was taken at the line's own drive — its force is what the
/// truth's shaker delivers for that drive — within the tolerance of the target, and that the
/// recomputation from the recorded blocks equals the live estimates.
fn assert_lines_at_their_drive(stand: &Stand, plan: &SteppedSine, path: &std::path::Path) {
    let t = stand.truth.as_ref().unwrap();
    let shaker = Interaction {
        gain: t.shaker_gain,
        cutoff_hz: t.shaker_cutoff_hz,
    };
    let a = acquire::analysis::characteristics(path, &Default::default()).unwrap();
    assert!(a.steps.iter().all(|s| s.matches_live), "replay differs");
    let steps: Vec<sweep::StepResult> = records(path)
        .iter()
        .filter(|r| r.topic == "/sweep/step")
        .map(|r| serde_json::from_value(r.value.clone()).unwrap())
        .collect();
    assert_eq!(steps.len(), a.steps.len());
    for s in &steps {
        let delivered = s.drive_n * shaker.at(s.frequency_hz).norm();
        let f = s.force_amplitude_n;
        assert!(
            (f - delivered).abs() < 0.005 * delivered,
            "{} Hz: measured {f:.1} N, but drive {:.1} N delivers {delivered:.1} N: the window holds data of another drive",
            s.frequency_hz,
            s.drive_n
        );
        let target = plan.target_force_n;
        assert!(
            (f - target).abs() <= plan.force_tolerance * target,
            "{} Hz: {f:.1} N",
            s.frequency_hz
        );
    }
}

/// The cause of the vcan VM's clipped sweeps under load: blocks that reach the host late (here
/// every one 0.4 s, longer than a settle and a window) hold data taken before the last drive
/// change. Settling counted from what the host had read made the loop learn the old force as
/// the new drive's, raise the drive twice over and clip the force channel (4 kN target, 4.44 kN
/// full scale); settling counted from the DAQ's sample clock measures every line at its drive.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn blocks_arriving_late_never_feed_the_force_loop_stale_data() {
    bounded(120, async {
        let stand = sim_stand(2.0);
        let plan = SteppedSine {
            frequencies: FrequencyList::Log {
                start: 40.0,
                stop: 160.0,
                n: 3,
            },
            settle_s: 0.05,
            cycles: 10.0,
            min_window_s: 0.1,
            ..SteppedSine::default()
        };
        let (_d, path) = temp_file("late.mcap");
        let late = |inner| -> Box<dyn Daq> {
            Box::new(LateDaq {
                inner,
                latency: std::time::Duration::from_millis(400),
                arrived: Default::default(),
            })
        };
        let (r, _sim) = sweep_with_daq(&stand, &plan, &path, late).await;
        let o = r.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(o.steps.len(), 3);
        assert_lines_at_their_drive(&stand, &plan, &path);
    })
    .await
}

/// The loop's first drive assumes a path gain of 1; this shaker delivers 1.15 times its command,
/// so the first reading clips the force channel (4.6 kN on a 4.44 kN full scale). The target
/// lies within the range, so the loop drives less (the force estimated from the share of clipped
/// samples) and measures every line unclipped; no clipped window is kept. A clipped force beyond
/// the exciter's limit (a shaker delivering twice its command: 8 kN on a 6 kN exciter) still
/// stops the sweep, with the output off and no line kept.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clipped_settling_reading_drives_less_and_an_over_force_still_stops() {
    bounded(120, async {
        let mut stand = sim_stand(10.0);
        stand.truth.as_mut().unwrap().shaker_gain = 1.15;
        let plan = quick_plan(3);
        let (_d, path) = temp_file("clipped.mcap");
        let (r, _sim) = sweep_to_the_end(&stand, &plan, &path).await;
        let o = r.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(o.steps.len(), 3);
        let rs = records(&path);
        let controls: Vec<&str> = topic(&rs, "/sweep/event")
            .iter()
            .filter(|r| r.value["kind"] == "force_control")
            .filter_map(|r| r.value["detail"].as_str())
            .collect();
        // The clipped force, estimated from the share of samples at the rails, is what the
        // shaker delivered: 4000 N × 1.15 × |1 / (1 + j 40/350)| = 4570 N.
        let estimated: f64 = controls[0]
            .strip_prefix("force clipped at the input range (≈ ")
            .and_then(|d| d.split(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("{controls:?}"));
        let t = stand.truth.as_ref().unwrap();
        let delivered = 4000.0 * 1.15 / (1.0 + (40.0 / t.shaker_cutoff_hz).powi(2)).sqrt();
        assert!(
            (estimated - delivered).abs() < 0.02 * delivered,
            "{estimated} vs {delivered}"
        );
        assert_lines_at_their_drive(&stand, &plan, &path);
        for s in &o.steps {
            let peak = window_force_peak_volts(&rs, s);
            assert!(
                peak < 0.999 * stand.daq.input_range_v,
                "{} Hz: {peak} V",
                s.frequency_hz
            );
        }

        stand.truth.as_mut().unwrap().shaker_gain = 2.0;
        let (_d, path) = temp_file("over.mcap");
        let (r, sim) = sweep_to_the_end(&stand, &plan, &path).await;
        let e = r.unwrap_err();
        assert!(matches!(e, SweepError::ForceClipped { step: 0, .. }), "{e}");
        assert!(!sim.excitation().output_on, "output left on");
        assert!(
            topic(&records(&path), "/sweep/step").is_empty(),
            "a clipped line was kept"
        );
    })
    .await
}

/// The largest force-channel sample (V) of a step's measurement window in the recorded blocks.
fn window_force_peak_volts(rs: &[acquire::session::Record], s: &sweep::StepResult) -> f64 {
    let window = s.first_sample..s.first_sample + s.samples;
    let mut peak = 0.0f64;
    for b in topic(rs, "/daq/block") {
        let first = b.value["first_sample"].as_u64().unwrap();
        for (i, v) in b.value["volts"][0].as_array().unwrap().iter().enumerate() {
            if window.contains(&(first + i as u64)) {
                peak = peak.max(v.as_f64().unwrap().abs());
            }
        }
    }
    peak
}

/// The simulator's end of a link, starved of CPU: every write first waits `pause`, as a
/// simulator thread that runs a fraction of the time on a busy machine.
struct Starved<T> {
    inner: T,
    pause: std::time::Duration,
    sleep: Option<std::pin::Pin<Box<tokio::time::Sleep>>>,
}

impl<T: acquire::transport::Transport> acquire::transport::Transport for Starved<T> {
    fn port(&self) -> &str {
        self.inner.port()
    }
}

impl<T: tokio::io::AsyncRead + Unpin> tokio::io::AsyncRead for Starved<T> {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: tokio::io::AsyncWrite + Unpin> tokio::io::AsyncWrite for Starved<T> {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        let pause = self.pause;
        let sleep = self
            .sleep
            .get_or_insert_with(|| Box::pin(tokio::time::sleep(pause)));
        if std::future::Future::poll(sleep.as_mut(), cx).is_pending() {
            return std::task::Poll::Pending;
        }
        self.sleep = None;
        std::pin::Pin::new(&mut self.inner).poll_write(cx, buf)
    }
    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_flush(cx)
    }
    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// The simulated stand on a busy machine: its DAQ, starved, streams at an eighth of its speed
/// (10 ms per block where 10× real time needs 1.25 ms). Settling reckoned from wall-clock time
/// waited for up to 2 s of wall-clock stream per drive change (20 s of simulated stream here,
/// minutes of starved stream per line) and the devices' timeouts ran out. With the simulator's
/// own clock (the samples it has produced) every line is measured at its drive, and the stream
/// read is what the windows need: settling, windows and at most a link's worth per window.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_starved_simulator_is_measured_by_its_own_clock() {
    use acquire::transport::MemoryTransport;
    bounded(60, async {
        let stand = sim_stand(10.0);
        let link = 1 << 16;
        let (s_host, s_dev) = MemoryTransport::pair("shaker", "shaker-sim", link);
        let (d_host, d_dev) = MemoryTransport::pair("daq", "daq-sim", link);
        let starved = Starved {
            inner: d_dev,
            pause: std::time::Duration::from_millis(10),
            sleep: None,
        };
        let sim = SimStand::serve(
            SimSetup::from_stand(&stand).unwrap(),
            s_dev,
            starved,
            "mem:shaker".into(),
            "mem:daq".into(),
        );
        let (_d, path) = temp_file("starved.mcap");
        let session = Session::create(&path, SessionOptions::default()).unwrap();
        let h = session.handle();
        let plan = quick_plan(3);
        sweep::log_session_start(&h, &stand.file, &plan, None, &BTreeSet::new()).unwrap();
        let shaker: Box<dyn Shaker> = Box::new(ScpiShaker::new(s_host, ShakerOptions::default()));
        let daq: Box<dyn Daq> = Box::new(SerialDaq::new(d_host, DaqOptions::default()));
        let rig = Rig::from_devices(&stand, shaker, daq, Some(&h))
            .await
            .unwrap();
        let mut rig = sim.clock_rig(rig);
        assert_eq!(rig.daq.sample_clock(), Some(0), "nothing streamed yet");
        let o = sweep::stepped_sine(
            &mut rig,
            &plan,
            &h,
            &NoProgress,
            &StopSignal::new(),
            &BTreeSet::new(),
        )
        .await
        .unwrap_or_else(|e| panic!("{e}"));
        drop(rig);
        session.finish().unwrap();
        assert_eq!(o.steps.len(), 3);
        assert_eq!(o.faults, 0);
        assert_lines_at_their_drive(&stand, &plan, &path);
        let fs = stand.daq.sample_rate_hz;
        let frame = 4 * stand.channels.len() as u64 * stand.daq.samples_per_block as u64;
        let link_samples = (link as u64 / frame + 1) * stand.daq.samples_per_block as u64;
        let settle = (plan.settle_s * fs).ceil() as u64;
        let needed: u64 = o
            .steps
            .iter()
            .map(|s| 2 * (s.iterations as u64 + 1) * (settle + s.samples + link_samples))
            .sum();
        let last = o.steps.last().unwrap();
        let read = last.first_sample + last.samples;
        assert!(
            read <= needed,
            "the sweep read {read} samples where its windows need at most {needed}: it waited for stream the simulator had not produced"
        );
    })
    .await
}
