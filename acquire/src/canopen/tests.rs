//! Tests of the CANopen master against the simulated node on the in-memory bus: NMT, SDO
//! (expedited, segmented both ways, aborts, toggle errors, malformed answers, wrong node id), the
//! TPDO stream (loss-free, lost frames as gaps), heartbeat loss and EMCY.

use std::time::Duration;

use crate::can::sim::Signal;
use crate::can::{BusEvent, CanId, FrameKind, WireFrame};
use crate::canopen::eds::{Access, DataType, ObjectDictionary};
use crate::canopen::sdo::{AbortCode, Address, SdoClient, SdoError};
use crate::canopen::sim::{
    count_pattern, serve_fixed_sdo_answer, SimCanOpenNode, SimNodeFaults, SimNodeStats, SIM_EDS,
};
use crate::canopen::{CanLink, CanOpenDaq, CanOpenSettings, MemoryBus, NmtCommand, NmtState};
use crate::daq::{events_until_error, Daq, DaqConfig, DaqError, DaqEvent, FaultKind};

type Node = (
    tokio::sync::oneshot::Sender<()>,
    tokio::task::JoinHandle<Result<SimNodeStats, crate::can::CanError>>,
);

fn signal() -> Signal {
    Box::new(count_pattern)
}

fn start_node(bus: &MemoryBus, node: u8, faults: SimNodeFaults) -> Node {
    let sim = SimCanOpenNode::new(node)
        .expect("shipped EDS parses")
        .with_faults(faults);
    let (tx, rx) = tokio::sync::oneshot::channel();
    let link = Box::new(bus.endpoint());
    (tx, tokio::spawn(sim.serve(link, signal(), rx)))
}

fn dictionary(node: u8) -> ObjectDictionary {
    ObjectDictionary::parse(SIM_EDS, "ident-sim-daq.eds", node).expect("shipped EDS parses")
}

fn settings(node: u8) -> CanOpenSettings {
    CanOpenSettings {
        node_id: node,
        dictionary: Some(dictionary(node)),
        sdo_timeout: Duration::from_millis(200),
        data_timeout: Duration::from_millis(1500),
        heartbeat_ms: 20,
        // Generous: a test runner under load must not see a live node as lost.
        heartbeat_timeout: Duration::from_millis(500),
        ..CanOpenSettings::default()
    }
}

fn master(bus: &MemoryBus, s: CanOpenSettings) -> CanOpenDaq {
    CanOpenDaq::on_link(Box::new(bus.endpoint()), s).expect("valid settings")
}

fn config(channels: Vec<u16>) -> DaqConfig {
    DaqConfig {
        sample_rate_hz: 2000.0,
        channels,
        samples_per_block: 16,
    }
}

/// Node 5 on `bus` with `faults`, and a master streaming its `channels`.
async fn streaming(
    bus: &MemoryBus,
    faults: SimNodeFaults,
    channels: Vec<u16>,
) -> (Node, CanOpenDaq) {
    let node = start_node(bus, 5, faults);
    let mut daq = master(bus, settings(5));
    daq.configure(&config(channels)).await.expect("configure");
    daq.start().await.expect("start");
    (node, daq)
}

async fn stop_node(n: Node) -> SimNodeStats {
    let _ = n.0.send(());
    n.1.await.expect("node task").expect("node ran")
}

#[test]
fn the_shipped_eds_parses_with_types_access_mapping_and_node_id() {
    let od = dictionary(5);
    assert_eq!(
        (od.vendor.as_str(), od.product.as_str()),
        ("IDENT-SIM", "CANOPEN-DAQ-8")
    );
    let tpdo1 = od.get(Address::new(0x1800, 1)).expect("TPDO1 COB-ID");
    assert_eq!(
        tpdo1.value.as_deref(),
        Some("0x80000185"),
        "$NODEID+0x80000180 for node 5"
    );
    assert_eq!(
        dictionary(0x11)
            .get(Address::new(0x1014, 0))
            .and_then(|e| e.value.clone())
            .as_deref(),
        Some("0x91")
    );
    let ai = od.get(Address::new(0x7100, 8)).expect("8th input");
    assert_eq!(
        (ai.data_type, ai.access, ai.pdo_mappable),
        (DataType::Integer16, Access::ReadOnly, true)
    );
    let name = od.get(Address::new(0x1008, 0)).expect("device name");
    assert_eq!(
        (name.data_type, name.access),
        (DataType::VisibleString, Access::ReadOnly)
    );
    assert!(od.get(Address::new(0x7100, 9)).is_none());
    assert_eq!(
        DataType::Real32.encode("0.5").ok(),
        Some(0.5f32.to_le_bytes().to_vec())
    );
    assert!(DataType::Unsigned8.encode("300").is_err());
}

#[test]
fn eds_errors_name_the_file_line_and_fix() {
    let text = "[DeviceInfo]\nVendorName=X\n\n[1000]\nParameterName=Device type\nDataType=0x0099\nAccessType=ro\n";
    let e = ObjectDictionary::parse(text, "bad.eds", 1).expect_err("unknown type");
    assert_eq!((e.file.as_str(), e.line), ("bad.eds", 6), "{e}");
    assert!(e.to_string().contains("0x0099"), "{e}");
    let e = ObjectDictionary::parse("[1000\n", "x.eds", 1).expect_err("bad header");
    assert!(
        e.to_string().contains("x.eds:1") && e.to_string().contains("`]`"),
        "{e}"
    );
    let e = ObjectDictionary::parse("[1000]\nDataType=0x0007\nAccessType=xx\n", "x.eds", 1)
        .expect_err("bad access");
    assert!(e.to_string().contains("AccessType `xx`"), "{e}");
    let e =
        ObjectDictionary::parse("[FileInfo]\nFileName=a\n", "x.eds", 1).expect_err("no objects");
    assert!(e.to_string().contains("is this an EDS"), "{e}");
}

#[test]
fn nmt_frames_and_abort_codes_match_cia_301() {
    assert_eq!(NmtCommand::Start.frame(5).to_cansend(), "000#0105");
    assert_eq!(NmtCommand::PreOperational.frame(5).to_cansend(), "000#8005");
    assert_eq!(
        NmtCommand::ResetCommunication.frame(0).to_cansend(),
        "000#8200"
    );
    assert_eq!(NmtState::from_code(0x7F), Some(NmtState::PreOperational));
    assert_eq!(
        NmtState::from_code(0x85),
        Some(NmtState::Operational),
        "toggle bit ignored"
    );
    assert_eq!(AbortCode::from_u32(0x0602_0000), AbortCode::NoObject);
    assert_eq!(AbortCode::ToggleNotAlternated.code(), 0x0503_0000);
    assert_eq!(
        AbortCode::from_u32(0x1234_5678),
        AbortCode::Other(0x1234_5678)
    );
    assert!(AbortCode::ReadOnly
        .to_string()
        .contains("0x06010002 (attempt to write a read-only object)"));
}

#[tokio::test]
async fn identity_and_segmented_transfers_both_ways() {
    let bus = MemoryBus::new("mem0");
    let node = start_node(&bus, 5, SimNodeFaults::default());
    let mut daq = master(&bus, settings(5));
    let id = daq.identify().await.expect("identify");
    assert_eq!(id.manufacturer, "IDENT-SIM");
    assert_eq!(
        id.model, "IDENT-SIM CANopen accelerometer and force DAQ, 8 channels",
        "0x1008 by segmented upload"
    );
    assert_eq!(id.serial, "00002A17");
    assert!(id.firmware.starts_with("2.3.0"), "{id:?}");
    // Segmented download (> 4 bytes, several segments, last one partial) and read back.
    let label = "accelerometer A3 on the spindle head, +Y direction (12 segments)".as_bytes();
    daq.write(Address::new(0x2010, 0), label)
        .await
        .expect("segmented download");
    assert_eq!(
        daq.read(Address::new(0x2010, 0))
            .await
            .expect("segmented upload"),
        label
    );
    // Exactly 7 and 8 bytes: segment boundaries.
    for text in ["1234567", "12345678"] {
        daq.write(Address::new(0x2010, 0), text.as_bytes())
            .await
            .expect("download");
        assert_eq!(
            daq.read(Address::new(0x2010, 0)).await.expect("upload"),
            text.as_bytes()
        );
    }
    // Expedited both ways.
    daq.write(Address::new(0x1017, 0), &250u16.to_le_bytes())
        .await
        .expect("expedited download");
    assert_eq!(
        daq.read(Address::new(0x1017, 0))
            .await
            .expect("expedited upload"),
        250u16.to_le_bytes()
    );
    let stats = stop_node(node).await;
    assert!(stats.sdo_requests > 20, "{stats:?}");
}

#[tokio::test]
async fn sdo_aborts_are_typed_errors_naming_the_object_and_code() {
    let bus = MemoryBus::new("mem0");
    let node = start_node(&bus, 5, SimNodeFaults::default());
    let mut daq = master(&bus, settings(5));
    let cases: [(Address, Option<&[u8]>, u32); 4] = [
        (Address::new(0x5000, 0), None, 0x0602_0000),
        (Address::new(0x1018, 9), None, 0x0609_0011),
        (Address::new(0x1018, 1), Some(&[1, 2, 3, 4]), 0x0601_0002),
        (Address::new(0x1006, 0), Some(&[1, 2]), 0x0607_0010),
    ];
    for (a, value, code) in cases {
        let r = match value {
            None => daq.read(a).await.map(|_| ()),
            Some(v) => daq.write(a, v).await,
        };
        match r {
            Err(DaqError::Rejected {
                code: c,
                command,
                message,
                ..
            }) => {
                assert_eq!(c as u32, code, "{command}: {message}");
                assert!(command.contains(&a.to_string()), "{command}");
                assert!(message.contains(&format!("0x{code:08X}")), "{message}");
            }
            other => panic!("{a}: expected an abort, got {other:?}"),
        }
    }
    // The PDO mapping as CiA 301 §7.5.2.36 has it changed: not while the TPDO exists, not an
    // entry while sub-index 0 is not 0, and only objects that can be mapped; a TPDO that
    // exists keeps its COB-ID (§7.5.2.35).
    let abort = |r: Result<(), DaqError>| match r {
        Err(DaqError::Rejected { code, .. }) => code as u32,
        other => panic!("expected an abort, got {other:?}"),
    };
    let map =
        |index: u16, sub: u8, bits: u32| (u32::from(index) << 16) | (u32::from(sub) << 8) | bits;
    let entry = map(0x7100, 1, 16).to_le_bytes();
    let cob = u32::from_le_bytes(
        daq.read(Address::new(0x1800, 1))
            .await
            .unwrap()
            .try_into()
            .unwrap(),
    );
    if cob & 0x8000_0000 == 0 {
        let moved = (cob + 1).to_le_bytes();
        assert_eq!(
            abort(daq.write(Address::new(0x1800, 1), &moved).await),
            0x0609_0030
        );
        assert_eq!(
            abort(daq.write(Address::new(0x1A00, 1), &entry).await),
            0x0601_0000
        );
    }
    daq.write(Address::new(0x1800, 1), &(cob | 0x8000_0000).to_le_bytes())
        .await
        .unwrap();
    let count = daq.read(Address::new(0x1A00, 0)).await.unwrap()[0];
    if count != 0 {
        assert_eq!(
            abort(daq.write(Address::new(0x1A00, 1), &entry).await),
            0x0601_0000
        );
    }
    daq.write(Address::new(0x1A00, 0), &[0]).await.unwrap();
    let not_mappable = map(0x1008, 0, 8).to_le_bytes();
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 1), &not_mappable).await),
        0x0604_0041
    );
    let wrong_length = map(0x7100, 1, 32).to_le_bytes();
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 1), &wrong_length).await),
        0x0604_0041
    );
    let missing = map(0x7100, 0x7F, 16).to_le_bytes();
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 1), &missing).await),
        0x0602_0000
    );
    for s in 1..=5 {
        daq.write(Address::new(0x1A00, s), &entry).await.unwrap();
    }
    // Five 16-bit entries are 80 bits, more than a CAN frame's 64.
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 0), &[5]).await),
        0x0604_0042
    );
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 0), &[9]).await),
        0x0604_0042
    );
    daq.write(Address::new(0x1A00, 0), &[4]).await.unwrap();
    // Operational: the node's stream is reconfigured in pre-operational only (0x08000022).
    daq.nmt(crate::canopen::NmtCommand::Start).await.unwrap();
    assert_eq!(
        abort(daq.write(Address::new(0x1A00, 0), &[0]).await),
        0x0800_0022
    );
    assert_eq!(
        abort(daq.write(Address::new(0x1800, 2), &[1]).await),
        0x0800_0022
    );
    daq.nmt(crate::canopen::NmtCommand::PreOperational)
        .await
        .unwrap();
    daq.write(Address::new(0x1A00, 0), &[0]).await.unwrap();
    // The session goes on: the next transfer works.
    assert_eq!(
        daq.read(Address::new(0x1018, 4))
            .await
            .expect("read after aborts"),
        0x2A17u32.to_le_bytes()
    );
    stop_node(node).await;
}

#[tokio::test]
async fn a_wrong_node_id_is_a_timeout_that_says_what_to_check() {
    let bus = MemoryBus::new("mem0");
    let node = start_node(&bus, 5, SimNodeFaults::default());
    let mut daq = master(&bus, settings(6));
    let e = daq.identify().await.expect_err("nobody is node 6");
    let msg = e.to_string();
    assert!(matches!(e, DaqError::Timeout { .. }), "{e:?}");
    assert!(
        msg.contains("node 6") && msg.contains("0x586") && msg.contains("node_id"),
        "{msg}"
    );
    assert!(CanOpenDaq::on_link(
        Box::new(bus.endpoint()),
        CanOpenSettings {
            node_id: 0,
            ..settings(5)
        }
    )
    .is_err());
    stop_node(node).await;
}

/// A server that answers an upload as segmented, then sends segments whose toggle bit is wrong.
#[tokio::test]
async fn a_wrong_toggle_bit_aborts_the_transfer() {
    let bus = MemoryBus::new("mem0");
    let mut server = bus.endpoint();
    let mut watcher = bus.endpoint();
    let mut client_link = bus.endpoint();
    let task = tokio::spawn(async move {
        let answers = [
            [0x41u8, 0x08, 0x10, 0x00, 20, 0, 0, 0],
            [0x10, b'a', b'b', b'c', b'd', b'e', b'f', b'g'],
        ];
        for a in answers {
            loop {
                if let Ok(BusEvent::Frame(f)) = server.recv().await {
                    if f.id() == CanId::Standard(0x605) {
                        break;
                    }
                }
            }
            server
                .send(&WireFrame::from_parts(
                    CanId::Standard(0x585),
                    FrameKind::Classic,
                    &a,
                ))
                .await
                .expect("send");
        }
    });
    let client = SdoClient {
        node: 5,
        timeout: Duration::from_millis(300),
    };
    let r = client
        .upload(&mut client_link, Address::new(0x1008, 0), &mut |_| {})
        .await;
    assert!(
        matches!(r, Err(SdoError::Toggle { segment: 0, .. })),
        "{r:?}"
    );
    task.await.expect("server");
    // ident told the node: abort 0x05030000 for 0x1008:00.
    let mut seen = Vec::new();
    while let Ok(Ok(BusEvent::Frame(f))) =
        tokio::time::timeout(Duration::from_millis(50), watcher.recv()).await
    {
        seen.push(f.to_cansend());
    }
    assert!(
        seen.contains(&"605#8008100000000305".to_string()),
        "{seen:?}"
    );
}

#[tokio::test]
async fn malformed_sdo_answers_are_clear_errors() {
    for (answer, needle) in [
        ([0xE0u8, 0, 0, 0, 0, 0, 0, 0], "command specifier 0xE0"),
        (
            [0x4F, 0x19, 0x10, 0x01, 1, 0, 0, 0],
            "answer is for 0x1019:01",
        ),
    ] {
        let bus = MemoryBus::new("mem0");
        let (tx, rx) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(serve_fixed_sdo_answer(
            Box::new(bus.endpoint()),
            5,
            answer,
            rx,
        ));
        let mut daq = master(&bus, settings(5));
        let e = daq
            .read(Address::new(0x1018, 1))
            .await
            .expect_err("malformed");
        assert!(matches!(e, DaqError::Protocol { .. }), "{e:?}");
        assert!(
            e.to_string().contains(needle) && e.to_string().contains("0x1018:01"),
            "{e}"
        );
        let _ = tx.send(());
        task.await.expect("task").expect("server");
    }
}

async fn collect(
    daq: &mut CanOpenDaq,
    blocks: usize,
) -> (Vec<crate::daq::SampleBlock>, Vec<crate::daq::StreamFault>) {
    let (mut b, mut f) = (Vec::new(), Vec::new());
    while b.len() < blocks {
        match daq.next_event().await.expect("stream") {
            DaqEvent::Block(x) => b.push(x),
            DaqEvent::Fault(x) => f.push(x),
        }
    }
    (b, f)
}

fn assert_block_matches_signal(b: &crate::daq::SampleBlock, channels: &[u16], vpc: f64) {
    for (c, &ch) in channels.iter().enumerate() {
        for (i, v) in b.channel(c).enumerate() {
            let k = b.first_sample + i as u64;
            let want = (count_pattern(ch, k) as f64 * vpc) as f32;
            assert_eq!(v, want, "block {} channel {ch} sample {k}", b.seq);
        }
    }
}

#[tokio::test]
async fn the_stream_arrives_loss_free_in_several_tpdos_with_the_node_scaling() {
    let bus = MemoryBus::new("mem0");
    let node = start_node(&bus, 5, SimNodeFaults::default());
    let mut daq = master(&bus, settings(5));
    let channels = vec![7, 0, 3, 5, 1];
    let info = daq
        .configure(&config(channels.clone()))
        .await
        .expect("configure");
    assert_eq!(info.sample_rate_hz, 2000.0);
    assert_eq!(info.device_channels(), channels);
    let vpc = 0.000_305_175_781_25;
    assert!(
        info.channels.iter().all(|c| c.volts_per_count == vpc),
        "{info:?}"
    );
    daq.start().await.expect("start");
    assert_eq!(daq.sample_clock(), Some(0), "no SYNC sent yet");
    let (blocks, faults) = collect(&mut daq, 12).await;
    // The node samples on each SYNC: the clock is past every delivered sample.
    let clock = daq.sample_clock().expect("the master paces the sampling");
    assert!(clock >= 12 * 16, "{clock}");
    assert_eq!(
        daq.node_state(),
        Some(NmtState::Operational),
        "heartbeat seen while streaming"
    );
    daq.stop().await.expect("stop");
    assert!(faults.is_empty(), "{faults:?}");
    for (i, b) in blocks.iter().enumerate() {
        assert_eq!(
            (b.seq, b.first_sample, b.len()),
            (i as u64, 16 * i as u64, 16)
        );
        assert_block_matches_signal(b, &channels, vpc);
    }
    let stats = stop_node(node).await;
    assert_eq!(stats.dropped, 0);
    assert_eq!(
        Some(stats.syncs),
        daq.sample_clock(),
        "one sample per SYNC sent"
    );
    assert!(
        stats.tpdos >= 2 * 12 * 16,
        "5 channels = 2 TPDOs per SYNC: {stats:?}"
    );
    // A second run restarts the counters.
    let bus2 = MemoryBus::new("mem1");
    let node = start_node(&bus2, 5, SimNodeFaults::default());
    let mut daq = master(&bus2, settings(5));
    daq.configure(&config(vec![2])).await.expect("configure");
    for _ in 0..2 {
        daq.start().await.expect("start");
        assert_eq!(daq.sample_clock(), Some(0), "the SYNC count restarts");
        let (blocks, faults) = collect(&mut daq, 3).await;
        daq.stop().await.expect("stop");
        assert!(faults.is_empty() && blocks[0].seq == 0, "{faults:?}");
        assert_block_matches_signal(&blocks[0], &[2], vpc);
    }
    stop_node(node).await;
}

#[tokio::test]
async fn lost_tpdo_frames_become_gaps_and_the_delivered_blocks_stay_exact() {
    let bus = MemoryBus::new("mem0");
    let faults = SimNodeFaults {
        drop_tpdo_every: Some(97),
        ..SimNodeFaults::default()
    };
    let channels = vec![0, 1, 2, 3];
    let (node, mut daq) = streaming(&bus, faults, channels.clone()).await;
    let (blocks, faults) = collect(&mut daq, 20).await;
    daq.stop().await.expect("stop");
    let stats = stop_node(node).await;
    assert!(stats.dropped > 0, "{stats:?}");
    let gaps: Vec<_> = faults.iter().filter(|f| f.kind == FaultKind::Gap).collect();
    assert!(!gaps.is_empty(), "{faults:?}");
    // Every missing block number is covered by a gap, and every delivered block is exact.
    let mut expected = 0;
    for b in &blocks {
        if b.seq != expected {
            assert!(
                gaps.iter().any(|g| g.seq == Some(expected)),
                "blocks {expected}..{} missing without a gap: {faults:?}",
                b.seq
            );
        }
        assert_block_matches_signal(b, &channels, 0.000_305_175_781_25);
        expected = b.seq + 1;
    }
    assert!(
        blocks
            .last()
            .is_some_and(|b| b.seq as usize >= blocks.len()),
        "some blocks were lost"
    );
}

#[tokio::test]
async fn a_lost_heartbeat_is_a_device_fault_then_the_stream_times_out() {
    let bus = MemoryBus::new("mem0");
    let faults = SimNodeFaults {
        silent_after_syncs: Some(100),
        ..SimNodeFaults::default()
    };
    let (node, mut daq) = streaming(&bus, faults, vec![0, 1]).await;
    let (events, err) = events_until_error(&mut daq).await;
    let lost: Vec<&str> = events.iter().filter_map(DaqEvent::device_fault).collect();
    assert_eq!(lost.len(), 1, "{lost:?}");
    assert!(lost[0].contains("node 5 lost: no heartbeat"), "{lost:?}");
    assert!(matches!(err, DaqError::Timeout { .. }), "{err:?}");
    let blocks = events
        .iter()
        .filter(|e| matches!(e, DaqEvent::Block(_)))
        .count();
    assert_eq!(blocks, 100 / 16, "the blocks before the node fell silent");
    stop_node(node).await;
}

#[tokio::test]
async fn an_emcy_is_recorded_with_its_error_code_and_the_stream_goes_on() {
    let bus = MemoryBus::new("mem0");
    let faults = SimNodeFaults {
        emcy_at_sync: Some((40, 0x5030)),
        ..SimNodeFaults::default()
    };
    let (node, mut daq) = streaming(&bus, faults, vec![4]).await;
    let (blocks, faults) = collect(&mut daq, 6).await;
    daq.stop().await.expect("stop");
    assert_eq!(faults.len(), 1, "{faults:?}");
    assert_eq!(faults[0].kind, FaultKind::Device);
    assert!(
        faults[0].detail.contains("0x5030 (device hardware)")
            && faults[0].detail.contains("register 0x01"),
        "{faults:?}"
    );
    assert_eq!(daq.emergencies().len(), 1);
    assert_eq!(
        (daq.emergencies()[0].code, daq.emergencies()[0].register),
        (0x5030, 0x01)
    );
    assert_eq!(
        blocks.iter().map(|b| b.seq).collect::<Vec<_>>(),
        (0..6).collect::<Vec<_>>()
    );
    // The node's error register says so too.
    assert_eq!(
        daq.read(Address::new(0x1001, 0))
            .await
            .expect("error register"),
        vec![0x01]
    );
    stop_node(node).await;
}

#[tokio::test]
async fn requests_beyond_the_node_or_the_bus_are_refused_before_any_frame() {
    let bus = MemoryBus::new("mem0");
    let mut daq = master(&bus, settings(5));
    let e = daq
        .configure(&config(vec![0, 8]))
        .await
        .expect_err("channel 8");
    assert!(
        e.to_string().contains("device channel 8 does not exist") && e.to_string().contains("0–7"),
        "{e}"
    );
    let e = daq
        .configure(&DaqConfig {
            sample_rate_hz: 10_000.0,
            channels: (0..8).collect(),
            samples_per_block: 16,
        })
        .await
        .expect_err("too fast for 1 Mbit/s");
    assert!(
        e.to_string().contains("bit/s") && e.to_string().contains("lower the sample rate"),
        "{e}"
    );
    let e = daq.start().await.expect_err("not configured");
    assert!(e.to_string().contains("start before configure"), "{e}");
}

#[derive(Default)]
struct Lines(std::sync::Mutex<Vec<(crate::transport::Direction, String)>>);

impl crate::transport::ByteTap for Lines {
    fn bytes(&self, port: &str, direction: crate::transport::Direction, data: &[u8]) {
        assert_eq!(port, "mem0");
        let text = String::from_utf8_lossy(data).to_string();
        assert!(text.ends_with('\n'), "whole lines only: {text:?}");
        let mut v = self.0.lock().expect("lock");
        v.extend(text.lines().map(|l| (direction, l.to_string())));
    }
}

#[tokio::test]
async fn the_tap_records_every_frame_both_ways_in_cansend_notation() {
    use crate::transport::Direction;
    let bus = MemoryBus::new("mem0");
    let node = start_node(&bus, 5, SimNodeFaults::default());
    let tap = std::sync::Arc::new(Lines::default());
    let mut daq = master(&bus, settings(5)).with_tap(tap.clone());
    daq.configure(&config(vec![0])).await.expect("configure");
    daq.start().await.expect("start");
    collect(&mut daq, 1).await;
    daq.stop().await.expect("stop");
    stop_node(node).await;
    let lines = tap.0.lock().expect("lock").clone();
    let has = |d: Direction, l: &str| lines.iter().any(|(x, y)| *x == d && y == l);
    assert!(has(Direction::Tx, "000#8005"), "NMT pre-operational");
    assert!(
        has(Direction::Tx, "605#23061000F4010000"),
        "0x1006 = 500 µs: {lines:?}"
    );
    assert!(has(Direction::Rx, "585#6006100000000000"), "its answer");
    assert!(has(Direction::Tx, "000#0105"), "NMT start");
    assert!(has(Direction::Tx, "080#"), "SYNC");
    let tpdo = lines
        .iter()
        .any(|(d, l)| *d == Direction::Rx && l.starts_with("185#0000"));
    assert!(tpdo, "TPDO1 of sample 0 (counter 0000 first)");
}
