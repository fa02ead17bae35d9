//! The DAQ over CAN on a real SocketCAN interface (vcan0): acquisition against the simulated CAN
//! DAQ (classic and FD), fault injection, error frames and bus-off, can-utils (`cansend`,
//! `candump`) as an independent peer, bad-interface errors, and a throughput benchmark.
//!
//! This host kernel may have no CAN support. `vcan_suite` (the one test that runs by default)
//! therefore runs the `#[ignore]`d tests below either directly, when vcan0 exists here, or inside a
//! qemu VM through `.ci/vcan/run-in-vm.sh`, and fails if any of them fails — or if neither vcan0
//! nor the VM prerequisites are present (install them with `.ci/setup`).

mod python_node;
mod util;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use acquire::can::codec::{Message, Reassembler, SampleFormat, Segmenter, WireBlock};
use acquire::can::sim::{SimCanDaq, SimCanDaqSettings, SimFaults, SimStats};
use acquire::can::{
    BusEvent, CanBus, CanDaq, CanDaqSettings, CanError, CanId, FrameKind, WireFrame,
};
use acquire::daq::{Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock};
use acquire::transport::{ByteTap, Direction};

const IFACE: &str = "vcan0";
const INSIDE: &str = "IDENT_VCAN_INSIDE";

// ---------------------------------------------------------------------------------------------
// Host side: run the CAN tests where vcan0 exists.

fn vcan0_is_up() -> bool {
    let dev = Path::new("/sys/class/net").join(IFACE);
    let ty = std::fs::read_to_string(dev.join("type")).unwrap_or_default();
    let flags = std::fs::read_to_string(dev.join("flags")).unwrap_or_default();
    let up =
        u32::from_str_radix(flags.trim().trim_start_matches("0x"), 16).is_ok_and(|f| f & 1 == 1);
    ty.trim() == "280" && up
}

#[test]
fn vcan_suite() {
    let exe = std::env::current_exe().expect("path of this test binary");
    let test_args = ["--ignored", "--test-threads=1", "--nocapture"];
    // IDENT_VCAN_FORCE_VM=1 uses the VM even where vcan0 exists (e.g. when not root: one test
    // creates and deletes its own interface).
    let status = if vcan0_is_up() && std::env::var_os("IDENT_VCAN_FORCE_VM").is_none() {
        eprintln!("vcan_suite: {IFACE} is up on this host; running the CAN tests directly");
        Command::new(&exe)
            .args(test_args)
            .env(INSIDE, "host")
            .status()
            .expect("run this test binary")
    } else {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.ci/vcan/run-in-vm.sh");
        eprintln!(
            "vcan_suite: no {IFACE} on this host; running the CAN tests in a qemu VM ({})",
            script.display()
        );
        let started = Instant::now();
        let status = Command::new("bash")
            .arg(&script)
            .args([
                "--env",
                &format!("{INSIDE}=vm"),
                "--env",
                "RUST_BACKTRACE=1",
                "--timeout",
                "300",
                // python-canopen, from this host's python3, plays a DAQ node on vcan0.
                "--host-root",
            ])
            .arg(&exe)
            .args(test_args)
            .status()
            .expect("run .ci/vcan/run-in-vm.sh");
        eprintln!(
            "vcan_suite: VM run took {:.1} s",
            started.elapsed().as_secs_f64()
        );
        if status.code() == Some(3) {
            panic!(
                "the vcan VM's prerequisites are missing (qemu-system-x86, busybox-static, can-utils, cpio and the Debian kernel); \
                 run `.ci/setup` as root, then re-run the tests"
            );
        }
        status
    };
    assert!(
        status.success(),
        "CAN tests over {IFACE} failed (see their output above); exit status {status}"
    );
}

// ---------------------------------------------------------------------------------------------
// Inside (VM or a host with vcan0): the real tests.

/// Collects what a [`ByteTap`] receives, one entry per frame line.
#[derive(Default)]
struct LineTap(std::sync::Mutex<Vec<(Direction, String)>>);

impl ByteTap for LineTap {
    fn bytes(&self, port: &str, direction: Direction, data: &[u8]) {
        assert_eq!(port, IFACE);
        let line = String::from_utf8(data.to_vec()).expect("tap lines are text");
        self.0
            .lock()
            .expect("tap lock")
            .push((direction, line.trim_end().to_string()));
    }
}

fn require_vcan() {
    assert!(
        vcan0_is_up(),
        "{IFACE} is not up here: these tests are run by `vcan_suite` (in the qemu VM when the host has no CAN; `.ci/vcan/run-in-vm.sh`)"
    );
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("tokio runtime")
}

/// Runs a CAN test's body on a fresh runtime, once vcan0 is known to be up.
fn on_vcan<T>(test: impl std::future::Future<Output = T>) -> T {
    require_vcan();
    runtime().block_on(test)
}

/// The simulated DAQ's signal: a deterministic pattern per channel and sample, so that every
/// received value can be checked exactly.
fn pattern(channel: u16, index: u64) -> i32 {
    let x = (index.wrapping_mul(7919) ^ (channel as u64).wrapping_mul(104_729)) % 16_000_000;
    x as i32 - 8_000_000
}

fn settings_pair(base: u16, frames: FrameKind) -> (CanDaqSettings, SimCanDaqSettings) {
    let host = CanDaqSettings {
        command_id: CanId::Standard(base),
        status_id: CanId::Standard(base + 1),
        data_id: CanId::Standard(base + 2),
        frames,
        ..CanDaqSettings::default()
    };
    let dev = SimCanDaqSettings {
        command_id: host.command_id,
        status_id: host.status_id,
        data_id: host.data_id,
        frames,
        ..SimCanDaqSettings::default()
    };
    (host, dev)
}

type SimTask = (
    tokio::task::JoinHandle<Result<SimStats, CanError>>,
    tokio::sync::oneshot::Sender<()>,
);

fn spawn_sim(dev: SimCanDaqSettings) -> SimTask {
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel();
    // Bound before returning: the host's first command cannot race the simulator's socket.
    let sim = SimCanDaq::bind(IFACE, dev).expect("simulated DAQ binds to vcan0");
    let task = tokio::spawn(sim.serve(Box::new(pattern), None, stop_rx));
    (task, stop_tx)
}

async fn stop_sim(sim: SimTask) -> SimStats {
    let (task, stop) = sim;
    let _ = stop.send(());
    tokio::time::timeout(Duration::from_secs(5), task)
        .await
        .expect("simulated DAQ stops within 5 s")
        .expect("simulated DAQ task")
        .expect("simulated DAQ ran without error")
}

fn check_block(b: &SampleBlock, channels: &[u16], spb: u16, vpc: f64) {
    assert_eq!(b.first_sample, b.seq * spb as u64);
    assert_eq!(b.len(), spb as usize);
    for i in 0..spb as usize {
        for (c, &ch) in channels.iter().enumerate() {
            let want = (pattern(ch, b.first_sample + i as u64) as f64 * vpc) as f32;
            let got = b.volts[i * channels.len() + c];
            assert_eq!(got, want, "block {} sample {i} channel {ch}", b.seq);
        }
    }
}

/// Identify, configure, start, read `blocks` blocks (asserting no fault and exact values), stop.
async fn acquire_clean(
    base: u16,
    frames: FrameKind,
    channels: Vec<u16>,
    spb: u16,
    rate: f64,
    blocks: u64,
) {
    let (host, dev) = settings_pair(base, frames);
    let vpc = dev.volts_per_count as f64;
    let identity = dev.identity.clone();
    let sim = spawn_sim(dev);
    let tap = std::sync::Arc::new(LineTap::default());
    let command_prefix = format!("{}#", host.command_id);
    let data_prefix = format!("{}#", host.data_id);
    let mut daq = CanDaq::open(IFACE, host)
        .expect("open CAN DAQ on vcan0")
        .with_tap(tap.clone());
    assert_eq!(daq.identify().await.expect("identify"), identity);
    let config = DaqConfig {
        sample_rate_hz: rate,
        channels: channels.clone(),
        samples_per_block: spb,
    };
    let info = daq.configure(&config).await.expect("configure");
    assert_eq!(info.sample_rate_hz, rate);
    assert_eq!(info.device_channels(), channels);
    daq.start().await.expect("start");
    for want in 0..blocks {
        match daq.next_event().await.expect("next event") {
            DaqEvent::Block(b) => {
                assert_eq!(b.seq, want);
                check_block(&b, &channels, spb, vpc);
            }
            DaqEvent::Fault(f) => panic!("unexpected fault on a clean stream: {f:?}"),
        }
    }
    daq.stop().await.expect("stop");
    let stats = stop_sim(sim).await;
    assert!(stats.blocks >= blocks);
    // The tap saw every frame: our 4 commands out, and at least the data frames of the blocks in.
    let lines = tap.0.lock().expect("tap lock");
    let tx: Vec<&String> = lines
        .iter()
        .filter(|(d, _)| *d == Direction::Tx)
        .map(|(_, l)| l)
        .collect();
    assert!(
        tx.len() >= 4 && tx.iter().all(|l| l.starts_with(&command_prefix)),
        "{tx:?}"
    );
    let rx_data = lines
        .iter()
        .filter(|(d, l)| *d == Direction::Rx && l.starts_with(&data_prefix))
        .count() as u64;
    assert!(
        rx_data >= blocks,
        "{rx_data} data frames recorded for {blocks} blocks"
    );
    assert_eq!(
        (stats.dropped, stats.duplicated, stats.corrupted),
        (0, 0, 0)
    );
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn classic_frames_acquisition_against_simulated_daq() {
    on_vcan(async {
        tokio::time::timeout(
            Duration::from_secs(30),
            acquire_clean(0x110, FrameKind::Classic, vec![0, 2, 5], 16, 2000.0, 25),
        )
        .await
        .expect("classic acquisition finishes within 30 s");
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn fd_frames_acquisition_against_simulated_daq() {
    on_vcan(async {
        tokio::time::timeout(
            Duration::from_secs(30),
            acquire_clean(0x120, FrameKind::Fd, vec![7, 1, 3, 0], 64, 25_600.0, 50),
        )
        .await
        .expect("FD acquisition finishes within 30 s");
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn injected_faults_are_all_reported_and_no_damaged_block_is_delivered() {
    on_vcan(async {
        tokio::time::timeout(Duration::from_secs(40), async {
            let (host, mut dev) = settings_pair(0x130, FrameKind::Classic);
            dev.faults = SimFaults {
                drop_every: Some(97),
                duplicate_every: Some(61),
                corrupt_every: Some(89),
                ..SimFaults::default()
            };
            let vpc = dev.volts_per_count as f64;
            let sim = spawn_sim(dev);
            let mut daq = CanDaq::open(IFACE, host).expect("open");
            let channels = vec![0u16, 1, 2, 3];
            daq.configure(&DaqConfig {
                sample_rate_hz: 8000.0,
                channels: channels.clone(),
                samples_per_block: 16,
            })
            .await
            .expect("configure");
            daq.start().await.expect("start");
            let mut delivered = Vec::new();
            let mut faults = Vec::new();
            while delivered.last().is_none_or(|&s| s < 60) {
                match daq.next_event().await.expect("next event") {
                    DaqEvent::Block(b) => {
                        check_block(&b, &channels, 16, vpc);
                        delivered.push(b.seq);
                    }
                    DaqEvent::Fault(f) => faults.push(f),
                }
            }
            daq.stop().await.expect("stop");
            let stats = stop_sim(sim).await;
            let kinds: Vec<FaultKind> = faults.iter().map(|f| f.kind).collect();
            eprintln!(
                "sim: {stats:?}; delivered {} blocks; faults {kinds:?}",
                delivered.len()
            );
            assert!(
                stats.dropped > 0 && stats.duplicated > 0 && stats.corrupted > 0,
                "every fault kind was injected: {stats:?}"
            );
            for k in [FaultKind::Gap, FaultKind::Duplicate, FaultKind::Crc] {
                assert!(
                    kinds.contains(&k),
                    "{k:?} injected but not reported; faults: {faults:?}"
                );
            }
            // Every missing block is covered by a block-level gap report.
            let missing = (0..=*delivered.last().expect("blocks"))
                .filter(|s| !delivered.contains(s))
                .count() as u64;
            let gap_blocks: u64 = faults
                .iter()
                .filter(|f| f.kind == FaultKind::Gap && f.detail.contains("block(s) missing"))
                .map(|f| {
                    f.detail
                        .split_whitespace()
                        .next()
                        .and_then(|n| n.parse::<u64>().ok())
                        .expect("gap count")
                })
                .sum();
            assert!(missing > 0, "faults should have cost some blocks");
            assert_eq!(
                gap_blocks, missing,
                "missing blocks {missing} vs reported {gap_blocks}"
            );
            assert!(
                delivered.windows(2).all(|w| w[0] < w[1]),
                "blocks in order, no duplicates"
            );
        })
        .await
        .expect("fault-injection run finishes within 40 s");
    });
}

fn block_frames(
    id: CanId,
    kind: FrameKind,
    seq: u32,
    channels: u8,
    spb: usize,
) -> (WireBlock, Vec<WireFrame>) {
    let counts: Vec<i32> = (0..spb as u64)
        .flat_map(|i| (0..channels as u16).map(move |c| pattern(c, i)))
        .collect();
    let block = WireBlock {
        seq,
        format: SampleFormat::I24,
        channel_count: channels,
        counts,
    };
    let mut body = Vec::new();
    Message::Block(block.clone())
        .encode(&mut body)
        .expect("encode block");
    let mut frames = Vec::new();
    Segmenter::new(id, kind)
        .segment(&body, &mut frames)
        .expect("segment");
    (block, frames)
}

/// Asserts that the data of `frames` reassemble without a fault into one message: `block`.
fn assert_frames_carry<'a>(frames: impl IntoIterator<Item = &'a [u8]>, block: WireBlock) {
    let mut r = Reassembler::new();
    let mut out = Vec::new();
    for f in frames {
        let p = r.push(f);
        assert!(p.fault.is_none(), "fault {:?}", p.fault);
        if let Some(m) = p.message {
            out.push(Message::decode(m).expect("valid message"));
        }
    }
    assert_eq!(out, vec![Message::Block(block)]);
}

fn cansend(frame: &str) {
    let out = Command::new("cansend")
        .args([IFACE, frame])
        .output()
        .expect("run cansend (can-utils)");
    assert!(
        out.status.success(),
        "cansend {IFACE} {frame}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn frames_injected_by_cansend_are_decoded() {
    on_vcan(async {
        for (kind, id) in [
            (FrameKind::Classic, CanId::Standard(0x142)),
            (FrameKind::Fd, CanId::Extended(0x18FF_0142)),
        ] {
            let (block, frames) = block_frames(id, kind, 41, 3, 6);
            let bus = CanBus::open_filtered(IFACE, &[id]).expect("open");
            let lines: Vec<String> = frames.iter().map(WireFrame::to_cansend).collect();
            let sender = tokio::task::spawn_blocking(move || lines.iter().for_each(|l| cansend(l)));
            let mut got = Vec::new();
            while got.len() < frames.len() {
                match tokio::time::timeout(Duration::from_secs(10), bus.recv())
                    .await
                    .expect("frame within 10 s")
                    .expect("recv")
                {
                    BusEvent::Frame(f) => got.push(f),
                    other => panic!("unexpected {other:?}"),
                }
            }
            sender.await.expect("cansend task");
            assert_eq!(got, frames, "{kind:?}: frames as cansend sent them");
            assert_frames_carry(got.iter().map(WireFrame::data), block);
        }
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn candump_sees_the_frames_our_sender_emits() {
    on_vcan(async {
        for (kind, id) in [
            (FrameKind::Classic, CanId::Standard(0x152)),
            (FrameKind::Fd, CanId::Standard(0x153)),
        ] {
            let (block, frames) = block_frames(id, kind, 7, 4, 10);
            // -T: candump gives up after 10 s without frames, so this can never hang.
            let dump = Command::new("candump")
                .args([
                    "-L",
                    "-T",
                    "10000",
                    "-n",
                    &frames.len().to_string(),
                    &format!("{IFACE},{:03X}:7FF", id.raw()),
                ])
                .stdout(std::process::Stdio::piped())
                .spawn()
                .expect("run candump (can-utils)");
            tokio::time::sleep(Duration::from_millis(500)).await; // candump binds its socket
            let bus = CanBus::open(IFACE).expect("open");
            for f in &frames {
                bus.send(f).await.expect("send");
            }
            let out = tokio::task::spawn_blocking(move || dump.wait_with_output())
                .await
                .expect("candump task")
                .expect("candump output");
            let text = String::from_utf8_lossy(&out.stdout);
            // `(1700000000.123456) vcan0 152#80...` — the third field is the frame. FD frames are
            // `153##F…` with F the FD flags nibble (kernels ≥ 6.x set CANFD_FDF = 4; BRS = 1 and
            // ESI = 2 must be clear): normalise it to our `##0`.
            let seen: Vec<String> = text
                .lines()
                .filter_map(|l| l.split_whitespace().nth(2))
                .map(|f| match f.split_once("##") {
                    Some((id, rest)) => {
                        let flags = u8::from_str_radix(&rest[..1], 16).expect("FD flags nibble");
                        assert_eq!(flags & 0x3, 0, "no BRS/ESI in {f}");
                        format!("{id}##0{}", &rest[1..])
                    }
                    None => f.to_string(),
                })
                .collect();
            let sent: Vec<String> = frames.iter().map(WireFrame::to_cansend).collect();
            assert_eq!(seen, sent, "{kind:?}: candump -L output:\n{text}");
            // Decode what candump printed, independently of our receive path.
            let bytes: Vec<Vec<u8>> = seen
                .iter()
                .map(|s| {
                    let hex = s.split('#').next_back().expect("data");
                    let hex = if s.contains("##") { &hex[1..] } else { hex };
                    (0..hex.len())
                        .step_by(2)
                        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex"))
                        .collect()
                })
                .collect();
            assert_frames_carry(bytes.iter().map(Vec::as_slice), block);
        }
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn error_frames_are_reported_and_bus_off_ends_the_stream() {
    on_vcan(async {
        tokio::time::timeout(Duration::from_secs(30), async {
            let (host, dev) = settings_pair(0x160, FrameKind::Fd);
            let sim = spawn_sim(dev);
            let mut daq = CanDaq::open(IFACE, host).expect("open");
            daq.configure(&DaqConfig {
                sample_rate_hz: 1000.0,
                channels: vec![0],
                samples_per_block: 50,
            })
            .await
            .expect("configure");
            daq.start().await.expect("start");
            // Controller problem: RX error-passive (CAN_ERR_CRTL, data[1] = CAN_ERR_CRTL_RX_PASSIVE).
            tokio::task::spawn_blocking(|| cansend("20000004#0010000000000000"))
                .await
                .expect("cansend");
            let fault = loop {
                match daq.next_event().await.expect("event") {
                    DaqEvent::Fault(f) => break f,
                    DaqEvent::Block(_) => {}
                }
            };
            assert_eq!(fault.kind, FaultKind::Bus);
            assert!(
                fault.detail.contains("error-passive") && fault.detail.contains(IFACE),
                "{}",
                fault.detail
            );
            // Bus-off (CAN_ERR_BUSOFF).
            tokio::task::spawn_blocking(|| cansend("20000040#0000000000000000"))
                .await
                .expect("cansend");
            let err = loop {
                match daq.next_event().await {
                    Ok(DaqEvent::Block(_)) => {}
                    Ok(DaqEvent::Fault(f)) => panic!("unexpected fault {f:?}"),
                    Err(e) => break e,
                }
            };
            assert!(matches!(err, DaqError::Bus { .. }), "{err:?}");
            let msg = err.to_string();
            assert!(
                msg.contains("bus off") && msg.contains("termination") && msg.contains(IFACE),
                "{msg}"
            );
            stop_sim(sim).await;
        })
        .await
        .expect("finishes within 30 s");
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn bad_interfaces_give_errors_naming_them() {
    on_vcan(async {
        let e = CanBus::open("nocan7").expect_err("no such interface");
        let msg = e.to_string();
        assert!(
            matches!(e, CanError::UnknownInterface { .. })
                && msg.contains("nocan7")
                && msg.contains("ip link"),
            "{msg}"
        );
        assert!(matches!(
            CanDaq::open("nocan7", CanDaqSettings::default()),
            Err(CanError::UnknownInterface { .. })
        ));
        // A network interface that is not CAN.
        assert!(matches!(
            CanBus::open("lo"),
            Err(CanError::UnknownInterface { .. })
        ));
        // Clashing identifiers are refused before touching the bus.
        let clash = CanDaqSettings {
            data_id: CanId::Standard(0x100),
            ..CanDaqSettings::default()
        };
        assert!(matches!(
            CanDaq::open(IFACE, clash),
            Err(CanError::Config { .. })
        ));

        let ip = |args: &str| {
            let st = Command::new("ip")
                .args(args.split_whitespace())
                .status()
                .expect("run ip");
            assert!(
                st.success(),
                "ip {args} failed: this test creates vcan9 and needs root (in the VM it is); run with IDENT_VCAN_FORCE_VM=1 to use the VM"
            );
        };
        // Classic-only interface (MTU 16): FD frames are refused with advice.
        ip("link add dev vcan9 type vcan");
        ip("link set vcan9 mtu 16");
        ip("link set vcan9 up");
        let bus = CanBus::open("vcan9").expect("open vcan9");
        let fd = WireFrame::from_parts(CanId::Standard(1), FrameKind::Fd, &[1; 12]);
        let e = bus.send(&fd).await.expect_err("FD on a classic interface");
        assert!(
            matches!(e, CanError::FdNotSupported { .. }) && e.to_string().contains("mtu 72"),
            "{e}"
        );
        let classic = WireFrame::from_parts(CanId::Standard(1), FrameKind::Classic, &[1; 8]);
        bus.send(&classic).await.expect("classic frame on vcan9");
        // Interface down.
        ip("link set vcan9 down");
        let e = bus
            .send(&classic)
            .await
            .expect_err("send on a down interface");
        assert!(
            matches!(e, CanError::InterfaceDown { .. })
                && e.to_string().contains("ip link set vcan9 up"),
            "{e}"
        );
        ip("link del dev vcan9");
        // A device that never answers: timeout naming the interface and identifiers.
        let quiet = CanDaqSettings {
            command_id: CanId::Standard(0x170),
            status_id: CanId::Standard(0x171),
            data_id: CanId::Standard(0x172),
            ..CanDaqSettings::default()
        };
        let mut daq = CanDaq::open(IFACE, quiet).expect("open");
        let e = daq.identify().await.expect_err("nobody answers");
        assert!(
            matches!(e, DaqError::Timeout { .. })
                && e.to_string().contains(IFACE)
                && e.to_string().contains("171"),
            "{e}"
        );
    });
}

#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn device_refusals_and_misuse_are_clear_errors() {
    on_vcan(async {
        tokio::time::timeout(Duration::from_secs(30), async {
            let (host, dev) = settings_pair(0x180, FrameKind::Classic);
            let sim = spawn_sim(dev);
            let mut daq = CanDaq::open(IFACE, host).expect("open");
            let e = daq.start().await.expect_err("start before configure");
            assert!(
                matches!(e, DaqError::State { .. }) && e.to_string().contains("configure"),
                "{e}"
            );
            let e = daq.next_event().await.expect_err("next_event before start");
            assert!(matches!(e, DaqError::State { .. }), "{e}");
            // The simulated DAQ has channels 0–7: it refuses channel 9 with a NAK.
            let bad = DaqConfig {
                sample_rate_hz: 1000.0,
                channels: vec![0, 9],
                samples_per_block: 8,
            };
            let e = daq.configure(&bad).await.expect_err("channel 9 refused");
            let msg = e.to_string();
            assert!(
                matches!(e, DaqError::Rejected { code: 2, .. })
                    && msg.contains("no channel 9")
                    && msg.contains(IFACE),
                "{msg}"
            );
            // Refused locally, before the bus: a rate DAQ-over-CAN cannot carry.
            let e = daq
                .configure(&DaqConfig {
                    sample_rate_hz: 1.0e7,
                    ..bad.clone()
                })
                .await
                .expect_err("rate too high for u32 mHz");
            assert!(e.to_string().contains("sample rate"), "{e}");
            // And the device still works afterwards.
            daq.configure(&DaqConfig {
                channels: vec![0, 7],
                ..bad
            })
            .await
            .expect("configure");
            stop_sim(sim).await;
        })
        .await
        .expect("finishes within 30 s");
    });
}

/// A device whose answers get lost: CONFIGURE is sent again; a START whose ACK was lost (so
/// the device is already streaming) is re-sent after a STOP, and the stream that follows is clean
/// and exact from block 0.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn lost_answers_are_asked_again_and_the_stream_starts_clean() {
    use acquire::can::codec::kind;
    on_vcan(async {
        tokio::time::timeout(Duration::from_secs(60), async {
            let (host, mut dev) = settings_pair(0x190, FrameKind::Classic);
            dev.faults.lose_answers = vec![kind::CONFIGURE, kind::START];
            let vpc = dev.volts_per_count as f64;
            let sim = spawn_sim(dev);
            let tap = std::sync::Arc::new(LineTap::default());
            let mut daq = CanDaq::open(IFACE, host)
                .expect("open")
                .with_tap(tap.clone());
            daq.identify().await.expect("identify");
            let channels = vec![1, 4];
            let config = DaqConfig {
                sample_rate_hz: 2000.0,
                channels: channels.clone(),
                samples_per_block: 16,
            };
            daq.configure(&config)
                .await
                .expect("configure, answered the second time");
            daq.start()
                .await
                .expect("start, acknowledged after STOP and START again");
            for want in 0..20 {
                match daq.next_event().await.expect("next event") {
                    DaqEvent::Block(b) => {
                        assert_eq!(b.seq, want);
                        check_block(&b, &channels, 16, vpc);
                    }
                    DaqEvent::Fault(f) => {
                        panic!("the re-sent START left a fault on the new stream: {f:?}")
                    }
                }
            }
            daq.stop().await.expect("stop");
            let stats = stop_sim(sim).await;
            // The device received IDENTIFY, CONFIGURE twice, START, STOP, START and STOP.
            assert_eq!((stats.answers_lost, stats.commands), (2, 7), "{stats:?}");
            assert!(
                tap.0
                    .lock()
                    .expect("tap lock")
                    .iter()
                    .any(|(d, _)| *d == Direction::Tx),
                "the tap saw the commands"
            );
        })
        .await
        .expect("finishes within 60 s");
    });
}

/// The simulated FWD-32J stand (written into `dir`) with its DAQ on CAN: a small stream (2560 Hz,
/// 32 samples per block, since the VM is emulated), identifiers `base`, `base + 1`, `base + 2`.
fn can_stand(dir: &Path, speed: f64, base: u16, frames: FrameKind) -> acquire::stand::Stand {
    let mut stand = util::model_sim_stand_in(dir, Some(speed));
    stand.daq.sample_rate_hz = 2560.0;
    stand.daq.samples_per_block = 32;
    stand.daq.can.frames = frames;
    stand.daq.can.command_id = CanId::Standard(base);
    stand.daq.can.status_id = CanId::Standard(base + 1);
    stand.daq.can.data_id = CanId::Standard(base + 2);
    stand
}

/// The stand file's `[faults]` reach a DAQ simulated on CAN: per block, a drop loses one CAN
/// frame, a corruption flips a bit in one, a duplicate repeats one, a delay holds the block back;
/// then the DAQ falls silent. The host reports each, delivers none of the damaged blocks and no
/// block twice, and ends with a timeout naming the data identifier.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn stand_file_faults_reach_the_simulated_can_daq() {
    use acquire::sim::SimStand;
    require_vcan();
    let dir = tempfile::tempdir().expect("temp dir");
    let mut stand = can_stand(dir.path(), 1.0, 0x320, FrameKind::Classic);
    let sent = 150;
    stand.faults = acquire::stand::Faults {
        seed: 5,
        drop: 0.04,
        corrupt: 0.04,
        duplicate: 0.04,
        delay: 0.04,
        delay_time: Duration::from_millis(5),
        daq_silent_after_blocks: Some(sent),
        ..Default::default()
    };
    runtime().block_on(async {
        tokio::time::timeout(Duration::from_secs(90), async {
            let sim = SimStand::start_can(&stand, IFACE).expect("simulated stand with its DAQ on vcan0");
            let mut daq = CanDaq::open(IFACE, stand.daq.can.clone()).expect("open");
            daq.identify().await.expect("identify");
            daq.configure(&stand.daq_config()).await.expect("configure");
            daq.start().await.expect("start");
            let (mut delivered, mut faults) = (Vec::new(), Vec::new());
            let end = loop {
                match daq.next_event().await {
                    Ok(DaqEvent::Block(b)) => delivered.push(b.seq),
                    Ok(DaqEvent::Fault(f)) => faults.push(f.kind),
                    Err(e) => break e,
                }
            };
            assert!(matches!(end, DaqError::Timeout { .. }) && end.to_string().contains("322"), "{end}");
            let injected = sim.injected();
            sim.shutdown();
            let of = |k: &str| injected.iter().filter(|f| f.kind == k).map(|f| f.seq).collect::<Vec<u64>>();
            let (drops, corrupt, dups) = (of("drop"), of("corrupt"), of("duplicate"));
            eprintln!(
                "stand faults on CAN: {} blocks delivered; injected drop {drops:?} corrupt {corrupt:?} duplicate {dups:?} delay {:?}; host faults {faults:?}",
                delivered.len(),
                of("delay")
            );
            for k in ["drop", "corrupt", "duplicate", "delay"] {
                assert!(!of(k).is_empty(), "no {k} injected in {sent} blocks (seed 5)");
            }
            assert_eq!(of("daq_silent"), [sent], "silent after {sent} blocks");
            // Exactly the undamaged blocks, each once, in order.
            let want: Vec<u64> = (0..sent).filter(|s| !drops.contains(s) && !corrupt.contains(s)).collect();
            assert_eq!(delivered, want);
            let count = |k: FaultKind| faults.iter().filter(|f| **f == k).count();
            assert!(count(FaultKind::Crc) >= corrupt.len(), "{faults:?}");
            assert!(count(FaultKind::Gap) >= drops.len(), "{faults:?}");
            assert!(count(FaultKind::Duplicate) >= dups.len(), "{faults:?}");
        })
        .await
        .expect("finishes within 90 s");
    });
}

/// Reads this thread's CPU time (user + system) from /proc (clock ticks of 10 ms).
fn thread_cpu() -> Duration {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").expect("/proc/thread-self/stat");
    let after = &stat[stat.rfind(')').expect("stat format") + 2..];
    let f: Vec<u64> = after
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0))
        .collect();
    // Fields 14 and 15 of stat (utime, stime) are 12 and 13 after the command name.
    Duration::from_millis((f[11] + f[12]) * 10)
}

/// Throughput benchmark (figures, not assertions on speed): the simulated DAQ streams FD or
/// classic frames at a target rate; the host receives for a fixed time on its own thread. Prints
/// frames/s, faults and the receiving thread's CPU; asserts only that every delivered block is
/// exact and every loss reported.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn throughput_benchmark() {
    require_vcan();
    let secs: f64 = std::env::var("IDENT_VCAN_BENCH_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2.0);
    let rt = runtime();
    // (frame kind, target frames/s); `None` = the simulator sends as fast as it can (no pacing).
    let steps = [
        (FrameKind::Fd, Some(10_000.0)),
        (FrameKind::Fd, Some(20_000.0)),
        (FrameKind::Classic, Some(20_000.0)),
        (FrameKind::Fd, None),
        (FrameKind::Classic, None),
    ];
    for (n, (kind, target)) in steps.into_iter().enumerate() {
        let base = 0x200 + 0x10 * n as u16;
        let (host, mut dev) = settings_pair(base, kind);
        dev.real_time = target.is_some();
        let target_fps = target.unwrap_or(50_000.0);
        let vpc = dev.volts_per_count as f64;
        let channels = vec![0u16, 1, 2, 3];
        let spb = 64u16;
        // Frames per block: 9-byte header + 4 × 64 × 3 bytes, +4 bytes length/CRC.
        let bytes: usize = 9 + 4 * 64 * 3 + 4;
        let per_frame = kind.max_data() - 1;
        let frames_per_block = bytes.div_ceil(per_frame);
        let rate = target_fps / frames_per_block as f64 * spb as f64;
        let sim = rt.block_on(async { spawn_sim(dev) });
        let ch = channels.clone();
        let receiver = std::thread::spawn(move || {
            let local = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .expect("runtime");
            local.block_on(async move {
                let mut daq = CanDaq::open(IFACE, host).expect("open");
                daq.configure(&DaqConfig {
                    sample_rate_hz: rate,
                    channels: ch.clone(),
                    samples_per_block: spb,
                })
                .await
                .expect("configure");
                daq.start().await.expect("start");
                let cpu0 = thread_cpu();
                let t0 = Instant::now();
                let (mut blocks, mut faults, mut last) = (0u64, Vec::new(), None);
                while t0.elapsed().as_secs_f64() < secs {
                    match daq.next_event().await.expect("event") {
                        DaqEvent::Block(b) => {
                            check_block(&b, &ch, spb, vpc);
                            blocks += 1;
                            last = Some(b.seq);
                        }
                        DaqEvent::Fault(f) => faults.push(f),
                    }
                }
                let wall = t0.elapsed();
                let cpu = thread_cpu() - cpu0;
                daq.stop().await.expect("stop");
                (blocks, faults, last, wall, cpu)
            })
        });
        let (blocks, faults, last, wall, cpu) = receiver.join().expect("receiver thread");
        let stats = rt.block_on(stop_sim(sim));
        let fps = (blocks * frames_per_block as u64) as f64 / wall.as_secs_f64();
        println!(
            "VCAN-BENCH: {kind:?} {} ({frames_per_block} frames/block, 4 ch × 64 samples i24): received {fps:.0} frames/s ({blocks} blocks in {:.2} s), faults {}, receiver CPU {:.1} % of a core",
            match target {
                Some(t) => format!("paced at {t:.0} frames/s ({rate:.0} Hz)"),
                None => "unpaced (sender flat out)".to_string(),
            },
            wall.as_secs_f64(),
            faults.len(),
            100.0 * cpu.as_secs_f64() / wall.as_secs_f64()
        );
        if !faults.is_empty() {
            println!("VCAN-BENCH:   first fault: {:?}", faults[0]);
        }
        // Integrity, not speed: no fault injected, so any loss must have been reported as a fault.
        let last = last.expect("some blocks received");
        if blocks < last + 1 {
            assert!(
                !faults.is_empty(),
                "{} blocks lost without a fault report",
                last + 1 - blocks
            );
        }
        assert_eq!(
            (stats.dropped, stats.duplicated, stats.corrupted),
            (0, 0, 0)
        );
    }
}

/// Stand → session → characteristics with the DAQ on CAN FD over vcan0 and the shaker controller
/// on a pseudo-terminal: a short stepped sine of the simulated FWD-32J stand (truth: the RFE model)
/// recovers the truth model's table characteristics within the noise the analysis states, and
/// the recomputation from the recorded blocks equals the live estimates bit for bit. Kept short
/// (6 lines, 2560 Hz) because the VM is emulated.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn stepped_sine_over_vcan_recovers_the_truth_characteristics() {
    require_vcan();
    let dir = tempfile::tempdir().expect("temp dir");
    let stand = can_stand(dir.path(), 2.0, 0x300, FrameKind::Fd);
    let plan = log_stepped_sine(20.0, 400.0, 6);
    let path = dir.path().join("vcan.mcap");
    let live = sweep_over_vcan(&stand, &plan, &path, IFACE, 90);
    assert_eq!(live.steps.len(), 6);
    let a = assert_replay_equals_live(&path, &live);
    // The CAN frames themselves are in the session (every byte received and sent).
    let raw = acquire::session::read(&path)
        .expect("read")
        .records
        .iter()
        .filter(|r| r.topic == "/raw")
        .count();
    assert!(raw > 100, "{raw} /raw records");
    util::assert_matches_truth(&a, &dir.path().join("models/fwd32j.toml"));
}

// ---------------------------------------------------------------------------------------------
// CANopen (docs/canopen.md): ident as master of the simulated CANopen node over vcan0.

fn canopen_settings(node: u8) -> acquire::canopen::CanOpenSettings {
    // Compiled in: the VM has only this test binary.
    let eds = acquire::canopen::sim::SIM_EDS;
    acquire::canopen::CanOpenSettings {
        node_id: node,
        dictionary: Some(
            acquire::canopen::eds::ObjectDictionary::parse(eds, "ident-sim-daq.eds", node)
                .expect("shipped EDS"),
        ),
        sdo_timeout: Duration::from_secs(1),
        data_timeout: Duration::from_secs(3),
        heartbeat_ms: 50,
        heartbeat_timeout: Duration::from_millis(600),
        ..acquire::canopen::CanOpenSettings::default()
    }
}

type NodeTask = (
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<Result<acquire::canopen::sim::SimNodeStats, CanError>>,
);

fn spawn_canopen_node(node: u8, faults: acquire::canopen::sim::SimNodeFaults) -> NodeTask {
    use acquire::canopen::sim::{count_pattern, SimCanOpenNode};
    let sim = SimCanOpenNode::new(node).expect("EDS").with_faults(faults);
    let bus = CanBus::open(IFACE).expect("open vcan0 for the node");
    let (tx, rx) = tokio::sync::oneshot::channel();
    (
        tx,
        tokio::spawn(sim.serve(Box::new(bus), Box::new(count_pattern), rx)),
    )
}

/// Over SocketCAN: identity (segmented SDO), configuration over SDO, NMT, SYNC and a 4-channel
/// stream at 2 kHz received loss-free and sample-exact; then a node that sends an EMCY and falls
/// silent: the EMCY with its code and the lost heartbeat are device faults, the stream ends with
/// a timeout; a wrong node id is a timeout naming the node.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn canopen_node_over_vcan_streams_loss_free_and_reports_emcy_and_lost_heartbeat() {
    use acquire::canopen::sim::SimNodeFaults;
    use acquire::canopen::CanOpenDaq;
    require_vcan();
    runtime().block_on(util::bounded(90, async {
        let node = spawn_canopen_node(5, SimNodeFaults::default());
        let mut daq = CanOpenDaq::open(IFACE, canopen_settings(5)).expect("open vcan0");
        let id = daq.identify().await.expect("identify");
        assert_eq!(id.serial, "00002A17");
        let channels = vec![0, 3, 6, 7];
        let cfg = DaqConfig {
            sample_rate_hz: 2000.0,
            channels: channels.clone(),
            samples_per_block: 32,
        };
        let info = daq.configure(&cfg).await.expect("configure");
        daq.start().await.expect("start");
        let started = Instant::now();
        let mut blocks = Vec::new();
        while blocks.len() < 40 {
            match daq.next_event().await.expect("stream") {
                DaqEvent::Block(b) => blocks.push(b),
                DaqEvent::Fault(f) => panic!("loss-free stream expected: {f:?}"),
            }
        }
        let secs = started.elapsed().as_secs_f64();
        daq.stop().await.expect("stop");
        eprintln!(
            "canopen over {IFACE}: 40 blocks × 32 samples × 4 channels at 2 kHz in {secs:.2} s"
        );
        for (i, b) in blocks.iter().enumerate() {
            assert_eq!(b.seq, i as u64);
            python_node::assert_exact(b, &channels, &info);
        }
        let _ = node.0.send(());
        node.1.await.expect("node task").expect("node");

        // Wrong node id.
        let node = spawn_canopen_node(5, SimNodeFaults::default());
        let mut wrong = CanOpenDaq::open(IFACE, canopen_settings(9)).expect("open");
        let e = wrong.identify().await.expect_err("no node 9");
        assert!(
            e.to_string().contains("node 9") && e.to_string().contains("0x589"),
            "{e}"
        );
        let _ = node.0.send(());
        node.1.await.expect("node task").expect("node");

        // EMCY, then silence.
        let faults = SimNodeFaults {
            emcy_at_sync: Some((100, 0x4210)),
            silent_after_syncs: Some(640),
            ..SimNodeFaults::default()
        };
        let node = spawn_canopen_node(5, faults);
        let mut daq = CanOpenDaq::open(IFACE, canopen_settings(5)).expect("open vcan0");
        daq.configure(&cfg).await.expect("configure");
        daq.start().await.expect("start");
        let (events, err) = acquire::daq::events_until_error(&mut daq).await;
        let device: Vec<&str> = events.iter().filter_map(DaqEvent::device_fault).collect();
        assert_eq!(device.len(), 2, "{device:?}");
        assert!(device[0].contains("0x4210 (temperature)"), "{device:?}");
        assert!(
            device[1].contains("node 5 lost: no heartbeat"),
            "{device:?}"
        );
        assert!(matches!(err, DaqError::Timeout { .. }), "{err:?}");
        let n = events
            .iter()
            .filter(|e| matches!(e, DaqEvent::Block(_)))
            .count();
        assert_eq!(n, 640 / 32, "every block before the silence");
        let _ = node.0.send(());
        node.1.await.expect("node task").expect("node");
    }));
}

/// The whole pipeline through CANopen: the shipped CANopen stand file (simulated node on vcan0,
/// shaker on a pty), a short stepped sine via the rig; every step recorded and the recomputation
/// from the recorded blocks equal to the live estimates.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn stepped_sine_through_the_canopen_stand_file() {
    require_vcan();
    let dir = tempfile::tempdir().expect("temp dir");
    let stand = canopen_stand_in(dir.path());
    let plan = log_stepped_sine(40.0, 300.0, 4);
    let path = dir.path().join("canopen.mcap");
    let live = sweep_over_vcan(&stand, &plan, &path, &format!("{IFACE} node 5"), 120);
    assert_eq!(live.steps.len(), 4);
    let _ = assert_replay_equals_live(&path, &live);
    // Every CANopen frame (SDO configuration, SYNC, TPDOs, heartbeats) is in the session, and so
    // is every stream fault the emulated VM's load may cause.
    let records = acquire::session::read(&path).expect("read").records;
    for r in records.iter().filter(|r| r.topic == "/daq/fault") {
        eprintln!("stream fault: {}", r.value);
    }
    let raw = records.iter().filter(|r| r.topic == "/raw").count();
    assert!(raw > 100, "{raw} /raw records");
}

/// The shipped CANopen stand file, its EDS and its geometry model written into `dir` (the VM has
/// only this test binary), loaded.
fn canopen_stand_in(dir: &Path) -> acquire::stand::Stand {
    for (rel, text) in [
        (
            "stands/fwd32j-canopen-sim.toml",
            include_str!("../../configs/stands/fwd32j-canopen-sim.toml"),
        ),
        (
            "canopen/ident-sim-daq.eds",
            include_str!("../../configs/canopen/ident-sim-daq.eds"),
        ),
        (
            "models/fwd32j-no-actuator.toml",
            include_str!("../../configs/models/fwd32j-no-actuator.toml"),
        ),
    ] {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().expect("parent")).expect("dir");
        std::fs::write(&p, text).expect("write");
    }
    let p = dir.join("stands/fwd32j-canopen-sim.toml");
    acquire::stand::Stand::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

/// A CANopen node lost mid-sweep (the stand's `daq_silent_after_blocks`): the lost heartbeat is
/// recorded as a device fault, the sweep ends with a timeout naming the node, and the session
/// file is complete with the error in it.
#[test]
#[ignore = "needs vcan0: run by vcan_suite (in the qemu VM when the host has no CAN)"]
fn a_canopen_node_lost_mid_sweep_ends_it_with_the_session_intact() {
    use acquire::session::{Session, SessionOptions};
    use acquire::sim::SimStand;
    use acquire::sweep::{self, NoProgress, StopSignal};
    require_vcan();
    let dir = tempfile::tempdir().expect("temp dir");
    let mut stand = canopen_stand_in(dir.path());
    stand.faults.daq_silent_after_blocks = Some(40);
    let plan = log_stepped_sine(40.0, 300.0, 6);
    let path = dir.path().join("lost.mcap");
    let err = runtime().block_on(async {
        tokio::time::timeout(Duration::from_secs(120), async {
            let sim = SimStand::start_can(&stand, IFACE).expect("simulated CANopen stand");
            let bound = sim.bind(&stand);
            let session = Session::create(&path, SessionOptions::default()).expect("session");
            let h = session.handle();
            sweep::log_session_start(&h, &stand.file, &plan, None, &Default::default())
                .expect("log");
            let mut rig = acquire::rig::Rig::connect(&bound, Some(&h))
                .await
                .expect("connect");
            let r = sweep::stepped_sine(
                &mut rig,
                &plan,
                &h,
                &NoProgress,
                &StopSignal::new(),
                &Default::default(),
            )
            .await;
            drop(rig);
            session.finish().expect("finish");
            sim.shutdown();
            r.expect_err("the node falls silent")
        })
        .await
        .expect("the sweep ends within 120 s")
    });
    let msg = err.to_string();
    assert!(
        msg.contains("vcan0 node 5") && msg.contains("TPDO"),
        "{msg}"
    );
    let records = util::records(&path); // complete file
    let faults: Vec<String> = records
        .iter()
        .filter(|r| r.topic == "/daq/fault")
        .map(|r| r.value.to_string())
        .collect();
    assert!(
        faults
            .iter()
            .any(|f| f.contains("node 5 lost: no heartbeat")),
        "{faults:?}"
    );
    assert!(
        records.iter().any(|r| r.topic == "/sweep/event"
            && r.value["kind"] == "error"
            && r.value["detail"].as_str() == Some(msg.as_str())),
        "the error is in the session"
    );
}

/// The short stepped sines of the tests over vcan0: `n` log-spaced lines from `start` to `stop`
/// (Hz), the rest as default (the VM is emulated, so they are kept short).
fn log_stepped_sine(start: f64, stop: f64, n: usize) -> acquire::sweep::SteppedSine {
    acquire::sweep::SteppedSine {
        frequencies: acquire::sweep::FrequencyList::Log { start, stop, n },
        ..acquire::sweep::SteppedSine::default()
    }
}

/// A stepped sine over the simulated stand whose DAQ is on vcan0 (the rig's DAQ must report
/// `daq_port`), recorded to `path`, within `limit_s` seconds; prints its steps, time and stream
/// faults.
fn sweep_over_vcan(
    stand: &acquire::stand::Stand,
    plan: &acquire::sweep::SteppedSine,
    path: &Path,
    daq_port: &str,
    limit_s: u64,
) -> acquire::sweep::SweepOutcome {
    use acquire::session::{Session, SessionOptions};
    use acquire::sim::SimStand;
    use acquire::sweep::{self, NoProgress, StopSignal};
    let started = Instant::now();
    let live = runtime().block_on(async {
        tokio::time::timeout(Duration::from_secs(limit_s), async {
            let sim =
                SimStand::start_can(stand, IFACE).expect("simulated stand with its DAQ on vcan0");
            let bound = sim.bind(stand);
            let session = Session::create(path, SessionOptions::default()).expect("session");
            let h = session.handle();
            sweep::log_session_start(&h, &stand.file, plan, None, &Default::default())
                .expect("log");
            let mut rig = acquire::rig::Rig::connect(&bound, Some(&h))
                .await
                .expect("connect shaker (pty) and DAQ (vcan0)");
            assert_eq!(rig.daq.port(), daq_port);
            let o = sweep::stepped_sine(
                &mut rig,
                plan,
                &h,
                &NoProgress,
                &StopSignal::new(),
                &Default::default(),
            )
            .await;
            drop(rig);
            session.finish().expect("finish");
            sim.shutdown();
            o.unwrap_or_else(|e| panic!("sweep: {e}\n{}", sweep_events(path)))
        })
        .await
        .unwrap_or_else(|_| panic!("sweep over vcan0 finishes within {limit_s} s"))
    });
    eprintln!(
        "sweep over {daq_port}: {} steps in {:.1} s, {} stream faults",
        live.steps.len(),
        started.elapsed().as_secs_f64(),
        live.faults
    );
    live
}

/// The sweep's events recorded in the session at `path`, one a line: the force loop's trail
/// (drives, corrections, retries) for a failure message.
fn sweep_events(path: &Path) -> String {
    util::records(path)
        .iter()
        .filter(|r| r.topic == "/sweep/event")
        .map(|r| r.value.to_string())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The session's steps recomputed from its raw blocks equal the live estimates, bit for bit;
/// returns the recomputation.
fn assert_replay_equals_live(
    path: &Path,
    live: &acquire::sweep::SweepOutcome,
) -> acquire::analysis::SessionAnalysis {
    use acquire::analysis::{characteristics, AnalysisOptions};
    let a = characteristics(path, &AnalysisOptions::default()).expect("characteristics");
    assert_eq!(a.steps.len(), live.steps.len(), "dropped: {:?}", a.dropped);
    for (s, l) in a.steps.iter().zip(&live.steps) {
        assert!(
            s.matches_live && s.channels == l.channels,
            "step {}: replay differs from live",
            s.step
        );
    }
    a
}

/// python-canopen's `LocalNode` (a stack nobody on this project wrote) as the DAQ node on vcan0,
/// through python-can's socketcan interface: ident identifies it, configures it over SDO, starts
/// it by NMT and receives its TPDO stream loss-free (the scenario of `canopen_python.rs`, over CAN).
#[test]
#[ignore = "needs vcan0 and python3 with canopen: run by vcan_suite (in the qemu VM, the host's python shared)"]
fn python_canopen_node_on_vcan_is_configured_and_streams_loss_free() {
    on_vcan(async {
        let mut child = python_node::spawn(&["--bus", IFACE]);
        let daq = open_python_node(&mut child);
        python_node::identified_configured_over_sdo_and_streams_loss_free(child, daq).await;
    });
}

/// The python-canopen node on vcan0 sends an EMCY and then falls silent: both are device faults.
#[test]
#[ignore = "needs vcan0 and python3 with canopen: run by vcan_suite (in the qemu VM, the host's python shared)"]
fn python_canopen_node_on_vcan_emcy_and_heartbeat_loss_are_detected() {
    on_vcan(async {
        let mut child = python_node::spawn(&[
            "--bus",
            IFACE,
            "--emcy-at",
            "60",
            "8130",
            "--silent-after",
            "300",
        ]);
        let daq = open_python_node(&mut child);
        python_node::emcy_and_heartbeat_loss_are_detected(child, daq).await;
    });
}

/// ident's master on vcan0 for the python node, once the node listens (it says `ready` on stdout
/// after its boot-up message; python takes seconds to start in the VM, and frames sent before it
/// listens are lost).
fn open_python_node(child: &mut std::process::Child) -> acquire::canopen::CanOpenDaq {
    use std::io::BufRead;
    let stdout = child.stdout.take().expect("piped stdout");
    let mut line = String::new();
    std::io::BufReader::new(stdout)
        .read_line(&mut line)
        .expect("read the python node's stdout");
    assert_eq!(
        line.trim(),
        "ready",
        "the python node did not start (see its stderr above)"
    );
    acquire::canopen::CanOpenDaq::open(IFACE, python_node::settings()).expect("open vcan0")
}
