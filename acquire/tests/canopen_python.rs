//! The independent check of ident's CANopen master: python-canopen (`canopen` on PyPI, a stack
//! nobody on this project wrote) plays the DAQ node — a `LocalNode` with the object dictionary of
//! `configs/canopen/ident-sim-daq.eds`, its own SDO server, NMT slave, heartbeat producer, EMCY
//! producer and PDO packing — and ident configures it over SDO, runs NMT, produces SYNC, receives
//! its TPDO stream, and detects its EMCY and its lost heartbeat.
//!
//! This host's kernel has no CAN, so the bus between the two stacks is a pipe to the python
//! process (tests/canopen/python_node.py): one frame per line in `cansend` notation, carried on
//! the python side by a python-can bus class and on this side by a [`CanLink`]. The frames
//! themselves are CAN frames as both stacks build them; only the wire is not CAN.
//!
//! Without python3 and the `canopen` package (`.ci/requirements.txt`) these tests fail: they never
//! pass without having run.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

use async_trait::async_trait;

use acquire::can::{BusEvent, CanError, CanId, FrameKind, WireFrame};
use acquire::canopen::eds::ObjectDictionary;
use acquire::canopen::sdo::Address;
use acquire::canopen::{CanLink, CanOpenDaq, CanOpenSettings};
use acquire::daq::{Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock, StreamFault};

const NODE: u8 = 5;

/// The python node's signal (same formula in python_node.py).
fn count(ch: u16, k: u64) -> i32 {
    ((k as i32 * 37 + ch as i32 * 4001) % 30_000) - 15_000
}

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn require_python_canopen() {
    let out = Command::new("python3")
        .args([
            "-c",
            "import canopen, can; print(canopen.__version__, can.__version__)",
        ])
        .output();
    match out {
        Ok(o) if o.status.success() => {
            eprintln!("python-canopen, python-can: {}", String::from_utf8_lossy(&o.stdout).trim())
        }
        Ok(o) => panic!(
            "python-canopen is not installed ({}); install the cross-check's packages with `python3 -m pip install -r .ci/requirements.txt` (or `.ci/setup`); this test must not pass without it",
            String::from_utf8_lossy(&o.stderr).trim()
        ),
        Err(e) => panic!("python3 is not available ({e}); install it and `.ci/requirements.txt`; this test must not pass without it"),
    }
}

/// The python node's end of the pipe as a CAN link.
struct PipeLink {
    stdin: ChildStdin,
    rx: tokio::sync::mpsc::UnboundedReceiver<WireFrame>,
}

fn parse_cansend(line: &str) -> Option<WireFrame> {
    let (id, data) = line.trim().split_once('#')?;
    let raw = u32::from_str_radix(id, 16).ok()?;
    let id = if id.len() > 3 {
        CanId::Extended(raw)
    } else {
        CanId::Standard(u16::try_from(raw).ok()?)
    };
    let bytes: Option<Vec<u8>> = (0..data.len())
        .step_by(2)
        .map(|i| {
            data.get(i..i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        })
        .collect();
    Some(WireFrame::from_parts(id, FrameKind::Classic, &bytes?))
}

#[async_trait]
impl CanLink for PipeLink {
    fn interface(&self) -> &str {
        "python-canopen pipe"
    }
    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError> {
        let io = |source| CanError::Io {
            interface: "python-canopen pipe".into(),
            op: "send",
            source,
        };
        writeln!(self.stdin, "{}", frame.to_cansend()).map_err(io)?;
        self.stdin.flush().map_err(io)
    }
    async fn recv(&mut self) -> Result<BusEvent, CanError> {
        match self.rx.recv().await {
            Some(f) => Ok(BusEvent::Frame(f)),
            None => Err(CanError::Io {
                interface: "python-canopen pipe".into(),
                op: "receive",
                source: std::io::Error::from(std::io::ErrorKind::UnexpectedEof),
            }),
        }
    }
}

/// Starts python_node.py with `args`; returns the child and the link to it.
fn python_node(args: &[&str]) -> (Child, PipeLink) {
    require_python_canopen();
    let mut child = Command::new("python3")
        .arg(manifest().join("tests/canopen/python_node.py"))
        .arg(manifest().join("../configs/canopen/ident-sim-daq.eds"))
        .arg(NODE.to_string())
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start python3 tests/canopen/python_node.py");
    let stdout = child.stdout.take().expect("piped stdout");
    let stdin = child.stdin.take().expect("piped stdin");
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            match parse_cansend(&line) {
                Some(f) => {
                    if tx.send(f).is_err() {
                        break;
                    }
                }
                None => eprintln!("python node wrote a line that is not a frame: {line}"),
            }
        }
    });
    (child, PipeLink { stdin, rx })
}

fn settings() -> CanOpenSettings {
    let eds = manifest().join("../configs/canopen/ident-sim-daq.eds");
    CanOpenSettings {
        node_id: NODE,
        dictionary: Some(ObjectDictionary::load(&eds, NODE).expect("shipped EDS")),
        // Generous: python under a loaded machine (CI shares 2 cores) can take seconds to
        // start its PDO loop; a lost node is still detected by the heartbeat.
        sdo_timeout: Duration::from_secs(5),
        data_timeout: Duration::from_secs(10),
        heartbeat_ms: 50,
        heartbeat_timeout: Duration::from_millis(600),
        ..CanOpenSettings::default()
    }
}

fn finish(mut child: Child, daq: CanOpenDaq) {
    drop(daq); // closes the pipe: the python node exits
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match child.try_wait() {
            Ok(Some(status)) => {
                assert!(status.success(), "python node exited with {status}");
                return;
            }
            Ok(None) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(20)),
            _ => {
                let _ = child.kill();
                panic!("python node did not exit after its pipe closed");
            }
        }
    }
}

fn assert_exact(b: &SampleBlock, channels: &[u16], vpc: f64) {
    for (c, &ch) in channels.iter().enumerate() {
        for (i, v) in b.channel(c).enumerate() {
            let k = b.first_sample + i as u64;
            assert_eq!(
                v,
                (count(ch, k) as f64 * vpc) as f32,
                "block {} channel {ch} sample {k}",
                b.seq
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_canopen_node_is_identified_configured_over_sdo_and_streams_loss_free() {
    let (child, link) = python_node(&[]);
    let mut daq = CanOpenDaq::on_link(Box::new(link), settings()).expect("settings");
    // Identity: python-canopen's SDO server answers 0x1018 expedited and 0x1008/0x100A segmented.
    let id = daq.identify().await.expect("identify the python node");
    assert_eq!(id.manufacturer, "IDENT-SIM");
    assert_eq!(
        id.model,
        "IDENT-SIM CANopen accelerometer and force DAQ, 8 channels"
    );
    assert_eq!(id.serial, "00002A17");
    // A segmented download python-canopen must reassemble, read back by segmented upload.
    let label = "triaxial accelerometer, spindle nose, +Z (python-canopen check)".as_bytes();
    daq.write(Address::new(0x2010, 0), label)
        .await
        .expect("segmented download to python-canopen");
    assert_eq!(
        daq.read(Address::new(0x2010, 0))
            .await
            .expect("segmented upload"),
        label
    );
    // python-canopen's abort for a missing object arrives as ident's typed error.
    let e = daq
        .read(Address::new(0x5555, 0))
        .await
        .expect_err("no such object");
    assert!(
        matches!(e, DaqError::Rejected { code, .. } if code as u32 == 0x0602_0000),
        "{e:?}"
    );

    let channels = vec![7, 0, 3, 5, 1];
    let info = daq
        .configure(&DaqConfig {
            sample_rate_hz: 500.0,
            channels: channels.clone(),
            samples_per_block: 25,
        })
        .await
        .expect("configure the python node over SDO");
    assert_eq!(info.sample_rate_hz, 500.0);
    // What ident wrote, as python-canopen stored it.
    let map = daq
        .read(Address::new(0x1A01, 0))
        .await
        .expect("mapping count");
    assert_eq!(map, vec![3], "TPDO2: counter + channels 5 and 1");
    assert_eq!(
        daq.read(Address::new(0x1006, 0))
            .await
            .expect("cycle period"),
        2000u32.to_le_bytes()
    );
    daq.start().await.expect("NMT start");
    let started = Instant::now();
    let (mut blocks, mut faults) = (Vec::new(), Vec::<StreamFault>::new());
    while blocks.len() < 20 {
        match daq.next_event().await.expect("stream") {
            DaqEvent::Block(b) => blocks.push(b),
            DaqEvent::Fault(f) => faults.push(f),
        }
    }
    let secs = started.elapsed().as_secs_f64();
    daq.stop().await.expect("stop");
    eprintln!("python-canopen node: 20 blocks × 25 samples × 5 channels (2 TPDOs per SYNC) at 500 Hz in {secs:.2} s");
    assert!(faults.is_empty(), "loss-free: {faults:?}");
    for (i, b) in blocks.iter().enumerate() {
        assert_eq!(b.seq, i as u64);
        assert_exact(b, &channels, info.channels[0].volts_per_count);
    }
    finish(child, daq);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_canopen_emcy_and_heartbeat_loss_are_detected() {
    let (child, link) = python_node(&["--emcy-at", "60", "8130", "--silent-after", "300"]);
    let mut daq = CanOpenDaq::on_link(Box::new(link), settings()).expect("settings");
    daq.identify().await.expect("identify");
    daq.configure(&DaqConfig {
        sample_rate_hz: 500.0,
        channels: vec![2, 6],
        samples_per_block: 20,
    })
    .await
    .expect("configure");
    daq.start().await.expect("start");
    let mut events = Vec::new();
    let err = loop {
        match daq.next_event().await {
            Ok(ev) => events.push(ev),
            Err(e) => break e,
        }
    };
    let device: Vec<&str> = events.iter().filter_map(DaqEvent::device_fault).collect();
    assert_eq!(device.len(), 2, "{device:?}");
    assert!(
        device[0]
            .contains("EMCY error code 0x8130 (monitoring / communication), error register 0x01"),
        "{device:?}"
    );
    assert!(
        device[1].contains("node 5 lost: no heartbeat"),
        "{device:?}"
    );
    assert_eq!(daq.emergencies().len(), 1);
    assert!(matches!(err, DaqError::Timeout { .. }), "{err:?}");
    let blocks: Vec<u64> = events
        .iter()
        .filter_map(|e| match e {
            DaqEvent::Block(b) => Some(b.seq),
            _ => None,
        })
        .collect();
    assert_eq!(
        blocks,
        (0..15).collect::<Vec<_>>(),
        "300 samples before silence = 15 blocks, none lost"
    );
    assert!(events
        .iter()
        .all(|e| !matches!(e, DaqEvent::Fault(f) if f.kind == FaultKind::Gap)));
    finish(child, daq);
}
