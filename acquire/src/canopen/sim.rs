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

/// The node's object dictionary with values, and the NMT state its writes depend on.
#[derive(Debug, Clone)]
struct Dictionary {
    values: BTreeMap<Address, Value>,
    state: NmtState,
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
        Dictionary {
            values,
            state: NmtState::PreOperational,
        }
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

    /// The bytes TPDO mapping `map` (0x1A00 + n) carries: each mapped object's value, cut to
    /// its mapped length.
    fn tpdo_payload(&self, map: u16) -> Vec<u8> {
        let mut payload = Vec::with_capacity(8);
        for s in 1..=self.u32(Address::new(map, 0)) as u8 {
            let m = self.u32(Address::new(map, s));
            let bytes = self
                .values
                .get(&Address::new((m >> 16) as u16, (m >> 8) as u8))
                .map(|v| v.bytes.clone())
                .unwrap_or_default();
            payload.extend_from_slice(&bytes[..((m & 0xFF) as usize / 8).min(bytes.len())]);
        }
        payload
    }

    /// Whether TPDO `n` (communication parameter 0x1800 + n) exists: bit 31 of its COB-ID clear.
    fn tpdo_valid(&self, n: u16) -> bool {
        self.u32(Address::new(0x1800 + n, 1)) & 0x8000_0000 == 0
    }

    /// The rules of CiA 301 for writing a TPDO's parameters, and this node's own: its stream is
    /// reconfigured in pre-operational only.
    /// - communication (0x1800 + n) and mapping (0x1A00 + n) parameters while operational:
    ///   0x08000022 (the present device state);
    /// - a mapping while the TPDO exists (COB-ID bit 31 clear), or a mapping entry while
    ///   sub-index 0 is not 0 (§7.5.2.36: invalidate the PDO, set sub-index 0 to 0, write the
    ///   entries, then the count, then validate): 0x06010000 (unsupported access);
    /// - a new COB-ID (bits 0-28) while the TPDO exists (§7.5.2.35): 0x06090030 (invalid value);
    /// - more than 8 entries or 64 bits: 0x06040042; an entry that is not mappable or whose
    ///   length is not its object's: 0x06040041; an entry naming no object: 0x06020000.
    fn check_tpdo_write(&self, a: Address, value: &[u8]) -> Result<(), AbortCode> {
        let (comm, map) = (
            (0x1800..0x1A00).contains(&a.index),
            (0x1A00..0x1C00).contains(&a.index),
        );
        if !(comm || map) {
            return Ok(());
        }
        if self.state == NmtState::Operational {
            return Err(AbortCode::DeviceState);
        }
        let n = a.index & 0x1FF;
        if comm {
            if a.sub == 1 && self.tpdo_valid(n) && value.len() == 4 {
                let new = u32::from_le_bytes([value[0], value[1], value[2], value[3]]);
                let old = self.u32(a);
                if new & 0x8000_0000 == 0 && new & 0x1FFF_FFFF != old & 0x1FFF_FFFF {
                    return Err(AbortCode::InvalidValue);
                }
            }
            return Ok(());
        }
        if self.tpdo_valid(n) {
            return Err(AbortCode::UnsupportedAccess);
        }
        if a.sub == 0 {
            let count = value.first().copied().unwrap_or(0);
            let bits: u32 = (1..=count)
                .map(|s| self.u32(Address::new(a.index, s)) & 0xFF)
                .sum();
            if count > 8 || bits > 64 {
                return Err(AbortCode::PdoTooLong);
            }
            return Ok(());
        }
        if self.u32(Address::new(a.index, 0)) != 0 {
            return Err(AbortCode::UnsupportedAccess);
        }
        let m = u32::from_le_bytes([value[0], value[1], value[2], value[3]]);
        let target = Address::new((m >> 16) as u16, (m >> 8) as u8);
        match self.values.get(&target) {
            _ if m == 0 => Ok(()),
            Some(t)
                if t.pdo_mappable
                    && t.data_type.size().is_some_and(|s| s as u32 * 8 == m & 0xFF) =>
            {
                Ok(())
            }
            Some(_) => Err(AbortCode::NotMappable),
            None => Err(AbortCode::NoObject),
        }
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
        self.check_tpdo_write(a, value)?;
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
    /// boot-up message first, then its heartbeat, and answers NMT, SDO and SYNC.
    pub async fn serve(
        self,
        mut link: Box<dyn CanLink>,
        mut signal: Signal,
        stop: tokio::sync::oneshot::Receiver<()>,
    ) -> Result<SimNodeStats, CanError> {
        let mut run = NodeRun::new(&self);
        run.send(
            &mut *link,
            cob(HEARTBEAT_BASE, self.node_id),
            &[NmtState::BootUp.code()],
        )
        .await?;
        tokio::pin!(stop);
        loop {
            let hb_ms = run.heartbeat_ms();
            let hb_at = (hb_ms > 0 && !run.silent).then_some(run.next_hb);
            let ev = tokio::select! {
                _ = &mut stop => return Ok(run.stats),
                _ = async { match hb_at { Some(t) => tokio::time::sleep_until(t).await, None => std::future::pending().await } } => {
                    run.heartbeat(&mut *link, hb_ms).await?;
                    continue;
                }
                ev = link.recv() => ev?,
            };
            let BusEvent::Frame(f) = ev else { continue };
            if run.silent {
                continue;
            }
            let d = f.data();
            match f.id() {
                CanId::Standard(NMT_ID) if d.len() == 2 && (d[1] == run.node || d[1] == 0) => {
                    run.nmt(&mut *link, d[0]).await?;
                    if hb_ms > 0 {
                        // A state change is announced at once.
                        run.next_hb = Instant::now();
                    }
                }
                CanId::Standard(id) if id == SDO_RX_BASE + run.node as u16 => {
                    run.sdo(&mut *link, d, hb_ms).await?;
                }
                CanId::Standard(id) if id as u32 == run.od.u32(Address::new(0x1005, 0)) & 0x7FF => {
                    run.sync(&mut *link, &mut signal).await?;
                }
                _ => {}
            }
        }
    }
}

/// One run of the simulated node: its dictionary, SDO server, NMT state and counters.
struct NodeRun<'a> {
    node: u8,
    eds: &'a ObjectDictionary,
    faults: &'a SimNodeFaults,
    od: Dictionary,
    server: SdoServer,
    stats: SimNodeStats,
    /// Sample index since the last NMT start.
    sample: u64,
    /// SYNCs received while operational, ever.
    total_syncs: u64,
    tpdo_count: u64,
    silent: bool,
    next_hb: Instant,
}

impl<'a> NodeRun<'a> {
    fn new(node: &'a SimCanOpenNode) -> NodeRun<'a> {
        NodeRun {
            node: node.node_id,
            eds: &node.eds,
            faults: &node.faults,
            od: Dictionary::from_eds(&node.eds),
            server: SdoServer::default(),
            stats: SimNodeStats::default(),
            sample: 0,
            total_syncs: 0,
            tpdo_count: 0,
            silent: false,
            next_hb: Instant::now(),
        }
    }

    async fn send(&self, link: &mut dyn CanLink, id: CanId, d: &[u8]) -> Result<(), CanError> {
        link.send(&WireFrame::from_parts(id, FrameKind::Classic, d))
            .await
    }

    fn heartbeat_ms(&self) -> u64 {
        self.od.u32(Address::new(0x1017, 0)) as u64
    }

    /// The heartbeat (0x700 + node, the NMT state), and when the next one is due.
    async fn heartbeat(&mut self, link: &mut dyn CanLink, hb_ms: u64) -> Result<(), CanError> {
        let state = self.od.state.code();
        self.send(link, cob(HEARTBEAT_BASE, self.node), &[state])
            .await?;
        self.stats.heartbeats += 1;
        self.next_hb = Instant::now().max(self.next_hb + Duration::from_millis(hb_ms));
        Ok(())
    }

    /// An NMT command (CiA 301 §7.2.8.3.2): start, stop, pre-operational, reset node (the
    /// whole dictionary from the EDS) or reset communication (0x1000-0x1FFF), each reset
    /// followed by the boot-up message.
    async fn nmt(&mut self, link: &mut dyn CanLink, specifier: u8) -> Result<(), CanError> {
        match NmtCommand::from_specifier(specifier) {
            Some(NmtCommand::Start) => {
                if self.od.state != NmtState::Operational {
                    self.sample = 0;
                }
                self.od.state = NmtState::Operational;
            }
            Some(NmtCommand::Stop) => self.od.state = NmtState::Stopped,
            Some(NmtCommand::PreOperational) => self.od.state = NmtState::PreOperational,
            Some(command @ (NmtCommand::ResetNode | NmtCommand::ResetCommunication)) => {
                let fresh = Dictionary::from_eds(self.eds);
                if command == NmtCommand::ResetNode {
                    self.od = fresh;
                } else {
                    for (a, v) in fresh
                        .values
                        .into_iter()
                        .filter(|(a, _)| (0x1000..0x2000).contains(&a.index))
                    {
                        self.od.values.insert(a, v);
                    }
                }
                self.server = SdoServer::default();
                self.od.state = NmtState::PreOperational;
                self.send(
                    link,
                    cob(HEARTBEAT_BASE, self.node),
                    &[NmtState::BootUp.code()],
                )
                .await?;
                self.next_hb = Instant::now();
            }
            None => {}
        }
        Ok(())
    }

    /// An SDO request: answered in pre-operational and operational, not in stopped (CiA 301
    /// §7.3.2.2: only NMT and the error control services run there).
    async fn sdo(&mut self, link: &mut dyn CanLink, d: &[u8], hb_ms: u64) -> Result<(), CanError> {
        if self.od.state == NmtState::Stopped {
            return Ok(());
        }
        self.stats.sdo_requests += 1;
        if let Some(answer) = self.server.handle(d, &mut self.od) {
            self.send(link, cob(SDO_TX_BASE, self.node), &answer)
                .await?;
        }
        if self.heartbeat_ms() != hb_ms {
            self.next_hb = Instant::now();
        }
        Ok(())
    }

    /// A SYNC while operational: the injected faults due, then every input sampled and the
    /// enabled synchronous TPDOs sent.
    async fn sync(&mut self, link: &mut dyn CanLink, signal: &mut Signal) -> Result<(), CanError> {
        if self.od.state != NmtState::Operational {
            return Ok(());
        }
        self.total_syncs += 1;
        self.stats.syncs += 1;
        if self
            .faults
            .silent_after_syncs
            .is_some_and(|n| self.total_syncs > n)
        {
            self.silent = true;
            return Ok(());
        }
        if let Some((at, code)) = self.faults.emcy_at_sync {
            if at == self.total_syncs {
                self.od.set(Address::new(0x1001, 0), &[0x01]);
                let c = code.to_le_bytes();
                self.send(
                    link,
                    cob(EMCY_BASE, self.node),
                    &[c[0], c[1], 0x01, 0, 0, 0, 0, 0],
                )
                .await?;
            }
        }
        self.sample_inputs(signal);
        self.send_tpdos(link).await?;
        self.sample += 1;
        Ok(())
    }

    /// Every analog input (0x7100) and the sample counter (0x2100) at this sample.
    fn sample_inputs(&mut self, signal: &mut Signal) {
        let sample = self.sample;
        self.od
            .set(Address::new(0x2100, 0), &(sample as u16).to_le_bytes());
        let inputs: Vec<Address> = self
            .od
            .values
            .range(Address::new(0x7100, 1)..=Address::new(0x7100, 0xFF))
            .map(|(a, _)| *a)
            .collect();
        for a in inputs {
            let n = signal(a.sub as u16 - 1, sample).clamp(i16::MIN as i32, i16::MAX as i32) as i16;
            self.od.set(a, &n.to_le_bytes());
        }
    }

    /// The TPDOs that are valid and synchronous with this SYNC (transmission type 1-240),
    /// each carrying its mapped objects.
    async fn send_tpdos(&mut self, link: &mut dyn CanLink) -> Result<(), CanError> {
        for n in 0..0x200u16 {
            let comm = 0x1800 + n;
            if !self.od.has_index(comm) {
                break;
            }
            let cob_id = self.od.u32(Address::new(comm, 1));
            let tt = self.od.u32(Address::new(comm, 2));
            if cob_id & 0x8000_0000 != 0
                || !(1..=240).contains(&tt)
                || !self.total_syncs.is_multiple_of(tt as u64)
            {
                continue;
            }
            let payload = self.od.tpdo_payload(0x1A00 + n);
            self.tpdo_count += 1;
            if self
                .faults
                .drop_tpdo_every
                .is_some_and(|k| k > 0 && self.tpdo_count.is_multiple_of(k))
            {
                self.stats.dropped += 1;
                continue;
            }
            self.send(link, CanId::Standard((cob_id & 0x7FF) as u16), &payload)
                .await?;
            self.stats.tpdos += 1;
        }
        Ok(())
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
