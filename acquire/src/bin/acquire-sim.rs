//! `acquire-sim`: serves a stand file's simulated shaker controller and DAQ on pseudo-terminals
//! and, with `--record`, runs stepped-sine sweeps against them into an MCAP session (the
//! crash-recovery test kills it with SIGKILL mid-sweep).
//!
//! ```text
//! acquire-sim <stand.toml> [--record out.mcap] [--steps N] [--speed X] [--forever] [--flush-ms M]
//! ```

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::Duration;

use acquire::rig::Rig;
use acquire::session::{Session, SessionOptions};
use acquire::sim::SimStand;
use acquire::stand::Stand;
use acquire::sweep::{self, FrequencyList, NoProgress, SteppedSine, StopSignal};

struct Args {
    stand: PathBuf,
    record: Option<PathBuf>,
    steps: usize,
    speed: Option<f64>,
    forever: bool,
    flush_ms: u64,
}

fn parse_args() -> Result<Args, String> {
    let mut it = std::env::args().skip(1);
    let mut a = Args {
        stand: PathBuf::new(),
        record: None,
        steps: 12,
        speed: None,
        forever: false,
        flush_ms: 500,
    };
    let mut stand = None;
    while let Some(x) = it.next() {
        let mut val = |name: &str| it.next().ok_or_else(|| format!("{name} needs a value"));
        match x.as_str() {
            "--record" => a.record = Some(PathBuf::from(val("--record")?)),
            "--steps" => {
                a.steps = val("--steps")?
                    .parse()
                    .map_err(|e| format!("--steps: {e}"))?
            }
            "--speed" => {
                a.speed = Some(
                    val("--speed")?
                        .parse()
                        .map_err(|e| format!("--speed: {e}"))?,
                )
            }
            "--flush-ms" => {
                a.flush_ms = val("--flush-ms")?
                    .parse()
                    .map_err(|e| format!("--flush-ms: {e}"))?
            }
            "--forever" => a.forever = true,
            "-h" | "--help" => return Err(String::new()),
            s if s.starts_with('-') => return Err(format!("unknown option {s}")),
            s => stand = Some(PathBuf::from(s)),
        }
    }
    a.stand = stand.ok_or("missing <stand.toml>")?;
    Ok(a)
}

#[tokio::main]
async fn main() -> std::process::ExitCode {
    match run().await {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("acquire-sim: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

async fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args = parse_args().map_err(|e| {
        format!("{e}\nusage: acquire-sim <stand.toml> [--record out.mcap] [--steps N] [--speed X] [--forever] [--flush-ms M]")
    })?;
    let mut stand = Stand::load(&args.stand)?;
    if let (Some(s), Some(t)) = (args.speed, stand.truth.as_mut()) {
        t.speed = s;
    }
    let sim = SimStand::start(&stand)?;
    println!("shaker {}\ndaq {}", sim.shaker_port, sim.daq_port);
    let stop = StopSignal::on_ctrl_c();
    let Some(out) = args.record else {
        while !stop.is_set() {
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        return Ok(());
    };
    let bound = sim.bind(&stand);
    let session = Session::create(
        &out,
        SessionOptions {
            flush_interval: Duration::from_millis(args.flush_ms),
            ..Default::default()
        },
    )?;
    let h = session.handle();
    let plan = SteppedSine {
        frequencies: FrequencyList::Log {
            start: 30.0,
            stop: 300.0,
            n: args.steps,
        },
        settle_s: 0.05,
        cycles: 10.0,
        min_window_s: 0.1,
        ..SteppedSine::default()
    };
    let result = async {
        sweep::log_session_start(&h, &stand.file, &plan, None, &BTreeSet::new())?;
        let mut rig = sim.clock_rig(Rig::connect(&bound, Some(&h)).await?);
        loop {
            let o = sweep::stepped_sine(&mut rig, &plan, &h, &NoProgress, &stop, &BTreeSet::new())
                .await?;
            eprintln!("acquire-sim: sweep of {} steps done", o.steps.len());
            if !args.forever || o.stopped {
                return Ok::<(), Box<dyn std::error::Error>>(());
            }
        }
    }
    .await;
    let summary = session.finish();
    result?;
    let s = summary?;
    eprintln!("acquire-sim: {} messages in {}", s.total(), s.path);
    Ok(())
}
