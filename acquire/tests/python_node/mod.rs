//! The python-canopen DAQ node (tests/canopen/python_node.py: a `canopen.LocalNode`, a stack nobody
//! on this project wrote) and the scenarios ident's CANopen master runs against it. Shared by
//! `canopen_python.rs` (the bus is a pipe to the python process, on any host) and `vcan.rs` (the
//! bus is vcan0 in the test VM, python-can's socketcan interface on the other side).

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use acquire::canopen::eds::ObjectDictionary;
use acquire::canopen::sdo::Address;
use acquire::canopen::sim::count_pattern;
use acquire::canopen::{CanOpenDaq, CanOpenSettings};
use acquire::daq::{
    events_until_error, Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock, StreamFault,
    StreamInfo,
};

/// One python node at a time: under a loaded machine (CI runs the tests of a binary in parallel
/// on 2 cores) two nodes streaming at once starve each other's PDO loop.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The node id python_node.py is started with.
pub const NODE: u8 = 5;

fn manifest() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

pub fn require_python_canopen() {
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

/// Starts python_node.py with `args`, its stdin and stdout piped: on the pipe bus they carry the
/// frames; with `--bus IFACE` the frames go over CAN and stdin closing tells the node to stop.
pub fn spawn(args: &[&str]) -> Child {
    require_python_canopen();
    Command::new("python3")
        .arg(manifest().join("tests/canopen/python_node.py"))
        .arg(manifest().join("../configs/canopen/ident-sim-daq.eds"))
        .arg(NODE.to_string())
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start python3 tests/canopen/python_node.py")
}

/// `path` (a host path, as python sees it) as this process reads it: in the test VM the host's
/// root is mounted at `$IDENT_HOST_ROOT` (python runs chrooted there; this binary does not).
fn on_this_side(path: &Path) -> std::path::PathBuf {
    match std::env::var_os("IDENT_HOST_ROOT") {
        Some(root) => Path::new(&root).join(path.strip_prefix("/").unwrap_or(path)),
        None => path.to_path_buf(),
    }
}

pub fn settings() -> CanOpenSettings {
    let eds = manifest().join("../configs/canopen/ident-sim-daq.eds");
    CanOpenSettings {
        node_id: NODE,
        dictionary: Some(ObjectDictionary::load(&on_this_side(&eds), NODE).expect("shipped EDS")),
        // Generous: python under a loaded machine (CI shares 2 cores) can take seconds to
        // start its PDO loop; a lost node is still detected by the heartbeat.
        sdo_timeout: Duration::from_secs(5),
        data_timeout: Duration::from_secs(10),
        heartbeat_ms: 50,
        heartbeat_timeout: Duration::from_millis(600),
        ..CanOpenSettings::default()
    }
}

pub fn finish(mut child: Child, daq: CanOpenDaq) {
    drop(daq); // on the pipe bus: closes the pipe, and the python node exits
    drop(child.stdin.take()); // on a CAN bus: its stdin closing tells it the test is over
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

/// Every sample of `b` (streaming `channels`, scaled as `info` says) is the node's count
/// ([`count_pattern`], the formula python_node.py uses too) in volts.
pub fn assert_exact(b: &SampleBlock, channels: &[u16], info: &StreamInfo) {
    for (c, &ch) in channels.iter().enumerate() {
        let vpc = info.channels[c].volts_per_count;
        for (i, v) in b.channel(c).enumerate() {
            let k = b.first_sample + i as u64;
            assert_eq!(
                v,
                (count_pattern(ch, k) as f64 * vpc) as f32,
                "block {} channel {ch} sample {k}",
                b.seq
            );
        }
    }
}

/// python-canopen's node is identified (0x1018 expedited, 0x1008/0x100A segmented), takes a
/// segmented download, aborts a missing object, is configured over SDO (its mapping read back),
/// started by NMT and streams 20 blocks with every sample exact and no fault.
pub async fn identified_configured_over_sdo_and_streams_loss_free(
    child: Child,
    mut daq: CanOpenDaq,
) {
    let _one = ONE_AT_A_TIME.lock().await;
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
        assert_exact(b, &channels, &info);
    }
    finish(child, daq);
}

/// The node started with `--emcy-at 60 8130 --silent-after 300`: its EMCY and then its lost
/// heartbeat are device faults, the stream ends in a timeout, and the 15 blocks before the
/// silence all arrive.
pub async fn emcy_and_heartbeat_loss_are_detected(child: Child, mut daq: CanOpenDaq) {
    let _one = ONE_AT_A_TIME.lock().await;
    daq.identify().await.expect("identify");
    daq.configure(&DaqConfig {
        sample_rate_hz: 500.0,
        channels: vec![2, 6],
        samples_per_block: 20,
    })
    .await
    .expect("configure");
    daq.start().await.expect("start");
    let (events, err) = events_until_error(&mut daq).await;
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
