//! A simulated CANopen DAQ node: its object dictionary is loaded from an EDS (by default
//! `configs/canopen/ident-sim-daq.eds`, compiled in), it answers SDO (expedited and segmented, with
//! abort codes) and NMT, produces its heartbeat (0x1017), and on each SYNC while operational
//! samples every analog input from a [`Signal`] and sends the TPDOs its mapping (0x1A00…)
//! describes. Injected faults: dropped TPDOs, a node that falls silent (lost heartbeat), an EMCY.

use std::collections::BTreeMap;
use std::time::Duration;

use tokio::time::Instant;

use crate::can::sim::Signal;
use crate::can::{BusEvent, CanError, CanId, FrameKind, WireFrame};
use crate::canopen::eds::{Access, DataType, EdsError, ObjectDictionary};
use crate::canopen::sdo::{AbortCode, Address, SdoServer, ServerDictionary};
use crate::canopen::{
    cob, CanLink, NmtCommand, NmtState, EMCY_BASE, HEARTBEAT_BASE, NMT_ID, SDO_RX_BASE, SDO_TX_BASE,
};

/// The EDS of the simulated node, as shipped in `configs/canopen/`.
pub const SIM_EDS: &str = include_str!("../../../configs/canopen/ident-sim-daq.eds");

/// A deterministic ADC count of input `ch` at sample `k`, distinct per channel and sample, so
/// that a stream can be checked sample by sample: the [`Signal`] the tests serve from the
/// simulated node (and `tests/canopen/python_node.py` from python-canopen's).
pub fn count_pattern(ch: u16, k: u64) -> i32 {
    ((k as i32 * 37 + ch as i32 * 4001) % 30_000) - 15_000
}

/// Faults the simulated node injects.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimNodeFaults {
    /// Skip every n-th TPDO frame.
    pub drop_tpdo_every: Option<u64>,
    /// After this many SYNCs the node sends nothing more (no heartbeat, PDO or SDO answer).
    pub silent_after_syncs: Option<u64>,
    /// At this SYNC count, send an EMCY with this error code (error register: generic error).
    pub emcy_at_sync: Option<(u64, u16)>,
}

/// What the simulated node did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SimNodeStats {
    /// SYNCs received while operational.
    pub syncs: u64,
    /// TPDO frames sent.
    pub tpdos: u64,
    /// TPDO frames dropped by the fault injection.
    pub dropped: u64,
    /// SDO requests answered.
    pub sdo_requests: u64,
    /// Heartbeats sent.
    pub heartbeats: u64,
}

#[derive(Debug, Clone)]
struct Value {
    data_type: DataType,
    access: Access,
    pdo_mappable: bool,
    bytes: Vec<u8>,
}

/// The node's object dictionary with values.
#[derive(Debug, Clone)]
struct Dictionary {
    values: BTreeMap<Address, Value>,
}

impl Dictionary {
    fn from_eds(od: &ObjectDictionary) -> Dictionary {
        let values = od
            .entries
            .iter()
            .map(|(a, e)| {
                let bytes = e
                    .value
                    .as_deref()
                    .and_then(|v| e.data_type.encode(v).ok())
                    .unwrap_or_else(|| vec![0; e.data_type.size().unwrap_or(0)]);
                (
                    *a,
                    Value {
                        data_type: e.data_type,
                        access: e.access,
                        pdo_mappable: e.pdo_mappable,
                        bytes,
                    },
                )
            })
            .collect();
        Dictionary { values }
    }

    fn u32(&self, a: Address) -> u32 {
        self.values.get(&a).map_or(0, |v| {
            let mut b = [0u8; 4];
            let n = v.bytes.len().min(4);
            b[..n].copy_from_slice(&v.bytes[..n]);
            u32::from_le_bytes(b)
        })
    }

    fn set(&mut self, a: Address, bytes: &[u8]) {
        if let Some(v) = self.values.get_mut(&a) {
            v.bytes = bytes.to_vec();
        }
    }

    fn has_index(&self, index: u16) -> bool {
        self.values
            .range(Address::new(index, 0)..=Address::new(index, 0xFF))
            .next()
            .is_some()
    }
}

impl ServerDictionary for Dictionary {
    fn read(&mut self, a: Address) -> Result<Vec<u8>, AbortCode> {
        match self.values.get(&a) {
            Some(v) if !v.access.readable() => Err(AbortCode::WriteOnly),
            Some(v) => Ok(v.bytes.clone()),
            None if self.has_index(a.index) => Err(AbortCode::NoSubIndex),
            None => Err(AbortCode::NoObject),
        }
    }

    fn write(&mut self, a: Address, value: &[u8]) -> Result<(), AbortCode> {
        let v = match self.values.get(&a) {
            Some(v) if !v.access.writable() => return Err(AbortCode::ReadOnly),
            Some(v) => v,
            None if self.has_index(a.index) => return Err(AbortCode::NoSubIndex),
            None => return Err(AbortCode::NoObject),
        };
        if v.data_type.size().is_some_and(|n| n != value.len()) {
            return Err(AbortCode::LengthMismatch);
        }
        if (0x1A00..0x1C00).contains(&a.index) {
            if a.sub == 0 {
                let n = value.first().copied().unwrap_or(0);
                let mut bits = 0u32;
                for s in 1..=n {
                    let m = self.u32(Address::new(a.index, s));
                    bits += m & 0xFF;
                }
                if n > 8 || bits > 64 {
                    return Err(AbortCode::PdoTooLong);
                }
            } else {
                let m = u32::from_le_bytes([value[0], value[1], value[2], value[3]]);
                let target = Address::new((m >> 16) as u16, (m >> 8) as u8);
                match self.values.get(&target) {
                    _ if m == 0 => {}
                    Some(t)
                        if t.pdo_mappable
                            && t.data_type.size().is_some_and(|s| s as u32 * 8 == m & 0xFF) => {}
                    Some(_) => return Err(AbortCode::NotMappable),
                    None => return Err(AbortCode::NoObject),
                }
            }
        }
        self.set(a, value);
        Ok(())
    }
}

/// A simulated CANopen DAQ node.
pub struct SimCanOpenNode {
    node_id: u8,
    eds: ObjectDictionary,
    faults: SimNodeFaults,
}

impl SimCanOpenNode {
    /// The node `node_id` with the object dictionary of the shipped EDS.
    pub fn new(node_id: u8) -> Result<SimCanOpenNode, EdsError> {
        Ok(SimCanOpenNode::with_dictionary(
            node_id,
            ObjectDictionary::parse(SIM_EDS, "configs/canopen/ident-sim-daq.eds", node_id)?,
        ))
    }

    /// The node `node_id` with the object dictionary `eds`.
    pub fn with_dictionary(node_id: u8, eds: ObjectDictionary) -> SimCanOpenNode {
        SimCanOpenNode {
            node_id,
            eds,
            faults: SimNodeFaults::default(),
        }
    }

    /// Injects `faults`.
    pub fn with_faults(mut self, faults: SimNodeFaults) -> SimCanOpenNode {
        self.faults = faults;
        self
    }

    /// Serves the node on `link` until `stop` resolves; `signal` gives the ADC count of each
    /// device channel (0-based) at each sample index (SYNC count since NMT start). Sends its
    /// boot-up message first.
    pub async fn serve(
        self,
        mut link: Box<dyn CanLink>,
        mut signal: Signal,
        stop: tokio::sync::oneshot::Receiver<()>,
    ) -> Result<SimNodeStats, CanError> {
        let node = self.node_id;
        let mut od = Dictionary::from_eds(&self.eds);
        let mut server = SdoServer::default();
        let mut state = NmtState::PreOperational;
        let mut stats = SimNodeStats::default();
        let mut sample: u64 = 0;
        let mut total_syncs: u64 = 0;
        let mut tpdo_count: u64 = 0;
        let mut silent = false;
        let frame = |id: CanId, d: &[u8]| WireFrame::from_parts(id, FrameKind::Classic, d);
        link.send(&frame(
            cob(HEARTBEAT_BASE, node),
            &[NmtState::BootUp.code()],
        ))
        .await?;
        let mut next_hb = Instant::now();
        tokio::pin!(stop);
        loop {
            let hb_ms = od.u32(Address::new(0x1017, 0)) as u64;
            let hb_at = (hb_ms > 0 && !silent).then_some(next_hb);
            let ev = tokio::select! {
                _ = &mut stop => return Ok(stats),
                _ = async { match hb_at { Some(t) => tokio::time::sleep_until(t).await, None => std::future::pending().await } } => {
                    link.send(&frame(cob(HEARTBEAT_BASE, node), &[state.code()])).await?;
                    stats.heartbeats += 1;
                    next_hb = Instant::now().max(next_hb + Duration::from_millis(hb_ms));
                    continue;
                }
                ev = link.recv() => ev?,
            };
            let BusEvent::Frame(f) = ev else { continue };
            if silent {
                continue;
            }
            let d = f.data();
            match f.id() {
                CanId::Standard(NMT_ID) if d.len() == 2 && (d[1] == node || d[1] == 0) => {
                    match NmtCommand::from_specifier(d[0]) {
                        Some(NmtCommand::Start) => {
                            if state != NmtState::Operational {
                                sample = 0;
                            }
                            state = NmtState::Operational;
                        }
                        Some(NmtCommand::Stop) => state = NmtState::Stopped,
                        Some(NmtCommand::PreOperational) => state = NmtState::PreOperational,
                        Some(NmtCommand::ResetNode) | Some(NmtCommand::ResetCommunication) => {
                            let fresh = Dictionary::from_eds(&self.eds);
                            if d[0] == NmtCommand::ResetNode.specifier() {
                                od = fresh;
                            } else {
                                for (a, v) in fresh
                                    .values
                                    .into_iter()
                                    .filter(|(a, _)| (0x1000..0x2000).contains(&a.index))
                                {
                                    od.values.insert(a, v);
                                }
                            }
                            server = SdoServer::default();
                            state = NmtState::PreOperational;
                            link.send(&frame(
                                cob(HEARTBEAT_BASE, node),
                                &[NmtState::BootUp.code()],
                            ))
                            .await?;
                            next_hb = Instant::now();
                        }
                        None => {}
                    }
                    if hb_ms > 0 {
                        // A state change is announced at once.
                        next_hb = Instant::now();
                    }
                }
                CanId::Standard(id) if id == SDO_RX_BASE + node as u16 => {
                    if state == NmtState::Stopped {
                        continue;
                    }
                    stats.sdo_requests += 1;
                    if let Some(answer) = server.handle(d, &mut od) {
                        link.send(&frame(cob(SDO_TX_BASE, node), &answer)).await?;
                    }
                    if od.u32(Address::new(0x1017, 0)) as u64 != hb_ms {
                        next_hb = Instant::now();
                    }
                }
                CanId::Standard(id) if id as u32 == od.u32(Address::new(0x1005, 0)) & 0x7FF => {
                    if state != NmtState::Operational {
                        continue;
                    }
                    total_syncs += 1;
                    stats.syncs += 1;
                    if self
                        .faults
                        .silent_after_syncs
                        .is_some_and(|n| total_syncs > n)
                    {
                        silent = true;
                        continue;
                    }
                    if let Some((at, code)) = self.faults.emcy_at_sync {
                        if at == total_syncs {
                            od.set(Address::new(0x1001, 0), &[0x01]);
                            let c = code.to_le_bytes();
                            link.send(&frame(
                                cob(EMCY_BASE, node),
                                &[c[0], c[1], 0x01, 0, 0, 0, 0, 0],
                            ))
                            .await?;
                        }
                    }
                    // Sample every input, then send the enabled synchronous TPDOs.
                    od.set(Address::new(0x2100, 0), &(sample as u16).to_le_bytes());
                    let inputs: Vec<Address> = od
                        .values
                        .range(Address::new(0x7100, 1)..=Address::new(0x7100, 0xFF))
                        .map(|(a, _)| *a)
                        .collect();
                    for a in inputs {
                        let n = signal(a.sub as u16 - 1, sample)
                            .clamp(i16::MIN as i32, i16::MAX as i32)
                            as i16;
                        od.set(a, &n.to_le_bytes());
                    }
                    for n in 0..0x200u16 {
                        let comm = 0x1800 + n;
                        if !od.has_index(comm) {
                            break;
                        }
                        let cob_id = od.u32(Address::new(comm, 1));
                        let tt = od.u32(Address::new(comm, 2));
                        if cob_id & 0x8000_0000 != 0
                            || !(1..=240).contains(&tt)
                            || !total_syncs.is_multiple_of(tt as u64)
                        {
                            continue;
                        }
                        let mut payload = Vec::with_capacity(8);
                        for s in 1..=od.u32(Address::new(0x1A00 + n, 0)) as u8 {
                            let m = od.u32(Address::new(0x1A00 + n, s));
                            let bytes = od
                                .values
                                .get(&Address::new((m >> 16) as u16, (m >> 8) as u8))
                                .map(|v| v.bytes.clone())
                                .unwrap_or_default();
                            payload.extend_from_slice(
                                &bytes[..((m & 0xFF) as usize / 8).min(bytes.len())],
                            );
                        }
                        tpdo_count += 1;
                        if self
                            .faults
                            .drop_tpdo_every
                            .is_some_and(|k| k > 0 && tpdo_count.is_multiple_of(k))
                        {
                            stats.dropped += 1;
                            continue;
                        }
                        link.send(&frame(CanId::Standard((cob_id & 0x7FF) as u16), &payload))
                            .await?;
                        stats.tpdos += 1;
                    }
                    sample += 1;
                }
                _ => {}
            }
        }
    }
}

/// A node that answers every SDO request with `answer` (for malformed-answer tests).
pub async fn serve_fixed_sdo_answer(
    mut link: Box<dyn CanLink>,
    node: u8,
    answer: [u8; 8],
    stop: tokio::sync::oneshot::Receiver<()>,
) -> Result<(), CanError> {
    tokio::pin!(stop);
    loop {
        let ev = tokio::select! {
            _ = &mut stop => return Ok(()),
            ev = link.recv() => ev?,
        };
        if let BusEvent::Frame(f) = ev {
            if f.id() == cob(SDO_RX_BASE, node)
                && f.data().first().is_some_and(|&c| c & 0xE0 != 0x80)
            {
                link.send(&WireFrame::from_parts(
                    cob(SDO_TX_BASE, node),
                    FrameKind::Classic,
                    &answer,
                ))
                .await?;
            }
        }
    }
}
