//! Stand → session → characteristics, end to end over pseudo-terminals: a full 38-line stepped
//! sine of the simulated FWD-32J stand (truth: the RFE model `configs/models/fwd32j.toml`) into an
//! MCAP session, from which `acquire::analysis::characteristics` recovers the truth model's table
//! characteristics within the noise it states; the recomputation equals the live estimates bit for
//! bit and is deterministic. (The same over CAN runs in the vcan VM: tests/vcan.rs.)

mod util;

use std::collections::BTreeSet;
use std::time::Instant;

use acquire::analysis::{characteristics, AnalysisOptions};
use acquire::rig::Rig;
use acquire::session::{Session, SessionOptions};
use acquire::sim::SimStand;
use acquire::sweep::{self, FrequencyList, NoProgress, SteppedSine, StopSignal};
use util::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn full_stepped_sweep_over_ptys_recovers_the_truth_characteristics() {
    bounded(240, async {
        let dir = tempfile::tempdir().unwrap();
        // The stand file's own pace (truth.speed).
        let stand = model_sim_stand_in(dir.path(), None);
        let plan = SteppedSine { frequencies: FrequencyList::Log { start: 20.0, stop: 400.0, n: 38 }, ..SteppedSine::default() };
        let path = dir.path().join("e2e.mcap");
        let sim = SimStand::start(&stand).unwrap();
        let session = Session::create(&path, SessionOptions::default()).unwrap();
        let h = session.handle();
        sweep::log_session_start(&h, &stand.file, &plan, None, &BTreeSet::new()).unwrap();
        let t0 = Instant::now();
        let mut rig = Rig::connect(&sim.bind(&stand), Some(&h)).await.unwrap();
        let live = sweep::stepped_sine(&mut rig, &plan, &h, &NoProgress, &StopSignal::new(), &BTreeSet::new()).await.unwrap();
        let wall = t0.elapsed().as_secs_f64();
        session.finish().unwrap();
        let simulated: f64 = live.steps.iter().map(|s| s.samples as f64).sum::<f64>() / stand.daq.sample_rate_hz;
        eprintln!("38-line sweep at {}× real time: {wall:.1} s wall clock ({simulated:.1} s of measurement windows)", stand.truth.as_ref().unwrap().speed);
        assert_eq!(live.steps.len(), 38);
        assert_eq!(live.faults, 0);

        let a = characteristics(&path, &AnalysisOptions::default()).unwrap();
        assert_eq!(a.steps.len(), 38, "dropped: {:?}", a.dropped);
        assert!(a.dropped.is_empty() && a.faults.is_empty() && a.truncated.is_none());
        // The table's three translations (the geometry model's declared outputs), in principal axes.
        let dofs: Vec<(String, u8)> = a.measured.characteristics.iter().map(|m| (m.body.clone(), m.dof)).collect();
        assert_eq!(dofs, vec![("table".to_string(), 0), ("table".to_string(), 1), ("table".to_string(), 2)]);
        // Replay = live, bit for bit, for every step and channel.
        for (s, l) in a.steps.iter().zip(&live.steps) {
            assert!(s.matches_live, "step {} differs from its live record", s.step);
            assert_eq!(s.channels, l.channels, "step {}", s.step);
            // Seven sensors on a rigid table: the residual is noise only.
            assert!(s.rigidity[0].residual < 0.05, "{:.1} Hz: rigidity residual {}", s.frequency_hz, s.rigidity[0].residual);
        }
        assert_matches_truth(&a, &dir.path().join("models/fwd32j.toml"));
        // Deterministic.
        let b = characteristics(&path, &AnalysisOptions::default()).unwrap();
        assert_eq!(serde_json::to_string(&a).unwrap(), serde_json::to_string(&b).unwrap());
    })
    .await
}
