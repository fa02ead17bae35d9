//! [`CanOpenDaq`]: ident as the CANopen master of one DAQ node, behind the [`Daq`] trait.

use std::collections::VecDeque;
use std::time::Duration;

use async_trait::async_trait;
use tokio::time::Instant;

use crate::can::{BusEvent, CanError, CanId, FrameKind, WireFrame};
use crate::canopen::eds::{DataType, ObjectDictionary};
use crate::canopen::sdo::{Address, SdoClient, SdoError};
use crate::canopen::{
    cob, CanLink, NmtCommand, NmtState, EMCY_BASE, HEARTBEAT_BASE, SYNC_ID, TPDO_BASE,
};
use crate::daq::{
    ChannelInfo, Daq, DaqConfig, DaqError, DaqEvent, FaultKind, SampleBlock, StreamFault,
    StreamInfo,
};
use crate::device::DeviceIdentity;

/// The node's objects ident uses (the stand file's `[daq.canopen.objects]`); defaults are those of
/// `configs/canopen/ident-sim-daq.eds`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CanOpenObjects {
    /// The node's own sample-rate object (Hz, UNSIGNED32), written before streaming; `None` when
    /// the SYNC period alone sets the sampling.
    pub sample_rate: Option<Address>,
    /// The sample counter mapped first into every TPDO (UNSIGNED8/16/32): lost frames show as
    /// jumps.
    pub counter: Address,
    /// Index of the analog inputs' process values (CiA 404 `AI input field value`, 0x7100):
    /// device channel `c` is sub-index `c + 1`.
    pub inputs: u16,
    /// Index of the per-channel scaling in volts per count (REAL32, sub-index `c + 1`); `None`:
    /// [`CanOpenSettings::volts_per_count`] for every channel.
    pub scaling: Option<u16>,
    /// Number of TPDOs the node has (0x1800… / 0x1A00…).
    pub tpdos: u8,
}

impl Default for CanOpenObjects {
    fn default() -> Self {
        CanOpenObjects {
            sample_rate: Some(Address::new(0x2000, 0)),
            counter: Address::new(0x2100, 0),
            inputs: 0x7100,
            scaling: Some(0x6126),
            tpdos: 4,
        }
    }
}

/// How ident talks to the node (the stand file's `[daq.canopen]`).
#[derive(Debug, Clone, PartialEq)]
pub struct CanOpenSettings {
    /// Node id (1–127).
    pub node_id: u8,
    /// Bit rate of the bus (bit/s): set on the interface (`ip link … bitrate`), used here to
    /// check that the requested sample rate fits on the bus.
    pub bit_rate: u32,
    /// The node's object dictionary from its EDS/DCF, if the stand file names one: objects are
    /// checked against it, and its types set the PDO layout.
    pub dictionary: Option<ObjectDictionary>,
    /// Objects used.
    pub objects: CanOpenObjects,
    /// Volts per count when the node has no scaling object.
    pub volts_per_count: f64,
    /// Longest wait for each SDO answer.
    pub sdo_timeout: Duration,
    /// Longest wait for the next TPDO while streaming.
    pub data_timeout: Duration,
    /// Heartbeat period the node is told to produce (0x1017, ms; 0 = none, no heartbeat check).
    pub heartbeat_ms: u16,
    /// A heartbeat missing for this long means the node is lost (a device fault event).
    pub heartbeat_timeout: Duration,
}

impl Default for CanOpenSettings {
    fn default() -> Self {
        CanOpenSettings {
            node_id: 5,
            bit_rate: 1_000_000,
            dictionary: None,
            objects: CanOpenObjects::default(),
            volts_per_count: 10.0 / 32_768.0,
            sdo_timeout: Duration::from_millis(500),
            data_timeout: Duration::from_secs(2),
            heartbeat_ms: 100,
            heartbeat_timeout: Duration::from_millis(350),
        }
    }
}

/// One EMCY message as received.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Emergency {
    /// Emergency error code (0x0000: error reset / no error).
    pub code: u16,
    /// Error register (0x1001) at the time.
    pub register: u8,
    /// Manufacturer-specific bytes.
    pub manufacturer: Vec<u8>,
}

impl Emergency {
    /// The CiA 301 class of the error code (table 21).
    pub fn class(&self) -> &'static str {
        match self.code >> 8 {
            0x00 => "error reset or no error",
            0x10 => "generic error",
            0x20..=0x23 => "current",
            0x30..=0x33 => "voltage",
            0x40..=0x42 => "temperature",
            0x50 => "device hardware",
            0x60..=0x63 => "device software",
            0x70 => "additional modules",
            0x80..=0x82 | 0x90 => "monitoring / communication",
            0xF0 => "additional functions",
            0xFF => "device specific",
            _ => "reserved code",
        }
    }
}

impl std::fmt::Display for Emergency {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "EMCY error code 0x{:04X} ({}), error register 0x{:02X}, manufacturer data {:02X?}",
            self.code,
            self.class(),
            self.register,
            self.manufacturer
        )
    }
}

/// What arrives outside the PDO stream: EMCY, heartbeats, bus errors. Filed as events.
#[derive(Debug)]
struct Monitor {
    node: u8,
    emergencies: Vec<Emergency>,
    pending: VecDeque<DaqEvent>,
    last_heartbeat: Option<(Instant, NmtState)>,
    heartbeat_lost: bool,
    streaming: bool,
    /// An operational heartbeat was seen since start (earlier ones may predate the NMT start).
    seen_operational: bool,
}

impl Monitor {
    /// Files a non-PDO bus event; returns the frame back when it is not one of these.
    fn file(&mut self, ev: BusEvent) -> Option<WireFrame> {
        match ev {
            BusEvent::Frame(f) if f.id() == cob(EMCY_BASE, self.node) => {
                let d = f.data();
                let e = Emergency {
                    code: u16::from_le_bytes([
                        d.first().copied().unwrap_or(0),
                        d.get(1).copied().unwrap_or(0),
                    ]),
                    register: d.get(2).copied().unwrap_or(0),
                    manufacturer: d.get(3..).map(<[u8]>::to_vec).unwrap_or_default(),
                };
                tracing::warn!("CANopen node {}: {e}", self.node);
                self.pending.push_back(DaqEvent::Fault(StreamFault {
                    kind: FaultKind::Device,
                    seq: None,
                    detail: format!("node {}: {e}", self.node),
                }));
                self.emergencies.push(e);
                None
            }
            BusEvent::Frame(f) if f.id() == cob(HEARTBEAT_BASE, self.node) => {
                let state = f.data().first().copied().and_then(NmtState::from_code);
                let now = Instant::now();
                if let Some(state) = state {
                    if self.heartbeat_lost {
                        tracing::info!("CANopen node {}: heartbeat back ({state:?})", self.node);
                        self.heartbeat_lost = false;
                    }
                    if state == NmtState::Operational {
                        self.seen_operational = true;
                    } else if self.streaming && self.seen_operational {
                        self.pending.push_back(DaqEvent::Fault(StreamFault {
                            kind: FaultKind::Device,
                            seq: None,
                            detail: format!("node {}: heartbeat reports {state:?} while streaming (the node left operational: reset or stopped)", self.node),
                        }));
                    }
                    self.last_heartbeat = Some((now, state));
                }
                None
            }
            BusEvent::Frame(f) => Some(f),
            BusEvent::Error(r) => {
                self.pending.push_back(DaqEvent::Fault(StreamFault {
                    kind: FaultKind::Bus,
                    seq: None,
                    detail: r.to_string(),
                }));
                None
            }
            BusEvent::Remote(_) => None,
        }
    }
}

/// The PDO layout after configure.
#[derive(Debug, Clone)]
struct Layout {
    /// Bytes of the counter at the start of every TPDO.
    counter_bytes: usize,
    /// Bits of the counter (its wrap-around).
    counter_bits: u32,
    /// Bytes of each channel value.
    value_bytes: usize,
    /// Per TPDO: the positions (in stream order) of the channels it carries.
    pdos: Vec<Vec<usize>>,
    /// Volts per count, stream order.
    scale: Vec<f64>,
    samples_per_block: usize,
}

/// The TPDO layout a configure request needs, before it is written to the node.
#[derive(Debug)]
struct PdoPlan {
    /// Bytes of the sample counter at the start of every TPDO.
    counter_bytes: usize,
    /// Bytes of each channel value.
    value_bytes: usize,
    /// Per TPDO: the positions (in stream order) of the channels it carries.
    pdos: Vec<Vec<usize>>,
    /// SYNC period (µs).
    period_us: u32,
    /// The sample rate that period gives (Hz).
    rate_hz: f64,
}

/// The sample being assembled from its TPDOs.
#[derive(Debug)]
struct Assembly {
    index: u64,
    mask: u32,
    counts: Vec<i32>,
    done: bool,
}

/// The block being filled.
#[derive(Debug)]
struct Building {
    seq: u64,
    filled: usize,
    volts: Vec<f32>,
}

/// A CANopen DAQ node driven by ident as master: NMT, SDO configuration, SYNC production, TPDO
/// reception, heartbeat consumption and EMCY recording. Lost TPDOs come out of
/// [`Daq::next_event`] as [`FaultKind::Gap`] events, EMCY and a lost heartbeat as
/// [`FaultKind::Device`] events.
pub struct CanOpenDaq {
    link: Box<dyn CanLink>,
    port: String,
    settings: CanOpenSettings,
    sdo: SdoClient,
    monitor: Monitor,
    layout: Option<Layout>,
    info: Option<StreamInfo>,
    sync_period: Duration,
    next_sync: Instant,
    /// SYNCs sent since START: the node takes sample `syncs_sent` at the next one.
    syncs_sent: u64,
    last_data: Instant,
    last_raw: Option<u32>,
    last_index: u64,
    assembly: Option<Assembly>,
    building: Option<Building>,
    next_seq: u64,
}

impl CanOpenDaq {
    /// Opens the SocketCAN interface `interface` for the node of `settings`.
    pub fn open(interface: &str, settings: CanOpenSettings) -> Result<CanOpenDaq, CanError> {
        let bus = crate::can::CanBus::open(interface)?;
        bus.set_receive_buffer(4 << 20)?;
        CanOpenDaq::on_link(Box::new(bus), settings)
    }

    /// The node of `settings` over any [`CanLink`] (the in-memory bus in tests).
    pub fn on_link(
        link: Box<dyn CanLink>,
        settings: CanOpenSettings,
    ) -> Result<CanOpenDaq, CanError> {
        if !(1..=127).contains(&settings.node_id) {
            return Err(CanError::Config {
                detail: format!("CANopen node id {} is out of range: write 1–127 (the node's DIP switches or LSS setting)", settings.node_id),
            });
        }
        let now = Instant::now();
        Ok(CanOpenDaq {
            port: format!("{} node {}", link.interface(), settings.node_id),
            sdo: SdoClient {
                node: settings.node_id,
                timeout: settings.sdo_timeout,
            },
            monitor: Monitor {
                node: settings.node_id,
                emergencies: Vec::new(),
                pending: VecDeque::new(),
                last_heartbeat: None,
                heartbeat_lost: false,
                streaming: false,
                seen_operational: false,
            },
            link,
            settings,
            layout: None,
            info: None,
            sync_period: Duration::from_millis(1),
            next_sync: now,
            syncs_sent: 0,
            last_data: now,
            last_raw: None,
            last_index: 0,
            assembly: None,
            building: None,
            next_seq: 0,
        })
    }

    /// Copies every frame sent and received (NMT, SDO, SYNC, PDO, heartbeat, EMCY) to `tap`, one
    /// line per frame in `cansend` notation.
    pub fn with_tap(mut self, tap: std::sync::Arc<dyn crate::transport::ByteTap>) -> CanOpenDaq {
        let link = std::mem::replace(
            &mut self.link,
            Box::new(crate::canopen::MemoryBus::new("-").endpoint()),
        );
        self.link = Box::new(crate::canopen::TappedLink::new(link, tap));
        self
    }

    /// Every EMCY received so far, in order.
    pub fn emergencies(&self) -> &[Emergency] {
        &self.monitor.emergencies
    }

    /// The node's state from its last heartbeat, if any.
    pub fn node_state(&self) -> Option<NmtState> {
        self.monitor.last_heartbeat.map(|(_, s)| s)
    }

    /// Sends an NMT command to the node.
    pub async fn nmt(&mut self, command: NmtCommand) -> Result<(), DaqError> {
        let f = command.frame(self.settings.node_id);
        self.link.send(&f).await.map_err(|e| self.can_err(e))
    }

    /// Reads an object (SDO upload).
    pub async fn read(&mut self, address: Address) -> Result<Vec<u8>, DaqError> {
        let mon = &mut self.monitor;
        let mut other = |ev: BusEvent| {
            mon.file(ev);
        };
        let r = self
            .sdo
            .upload(self.link.as_mut(), address, &mut other)
            .await;
        r.map_err(|e| self.sdo_err(e))
    }

    /// Writes an object (SDO download).
    pub async fn write(&mut self, address: Address, value: &[u8]) -> Result<(), DaqError> {
        let mon = &mut self.monitor;
        let mut other = |ev: BusEvent| {
            mon.file(ev);
        };
        let r = self
            .sdo
            .download(self.link.as_mut(), address, value, &mut other)
            .await;
        r.map_err(|e| self.sdo_err(e))
    }

    async fn read_u32(&mut self, address: Address) -> Result<u32, DaqError> {
        let v = self.read(address).await?;
        let mut b = [0u8; 4];
        let n = v.len().min(4);
        b[..n].copy_from_slice(&v[..n]);
        Ok(u32::from_le_bytes(b))
    }

    fn name(&self, a: Address) -> String {
        match self.settings.dictionary.as_ref().and_then(|d| d.get(a)) {
            Some(e) => format!("{a} ({})", e.name),
            None => a.to_string(),
        }
    }

    fn sdo_err(&self, e: SdoError) -> DaqError {
        match e {
            SdoError::Abort { op, address, code, by, .. } => DaqError::Rejected {
                port: self.port.clone(),
                command: format!("SDO {op} of {}", self.name(address)),
                code: code.code() as i32,
                message: format!("abort code {code} sent by the {by}; check the object in the stand file's [daq.canopen.objects] against the node's EDS"),
            },
            SdoError::Timeout { op, address, waited, node } => DaqError::Timeout {
                port: self.port.clone(),
                what: format!("SDO answer to the {op} of {} (node {node} answers on 0x{:03X}: check the stand file's node_id, the bit rate and the node's power)", self.name(address), 0x580 + node as u16),
                waited,
            },
            SdoError::Bus { source, .. } => self.can_err(source),
            other => DaqError::Protocol {
                port: self.port.clone(),
                command: "SDO".into(),
                detail: other.to_string(),
            },
        }
    }

    fn can_err(&self, e: CanError) -> DaqError {
        match e {
            CanError::Io { source, .. } => DaqError::from_io(&self.port, source),
            other => DaqError::Bus {
                port: self.port.clone(),
                detail: other.to_string(),
            },
        }
    }

    /// Type of an object from the EDS (`None` without one).
    fn type_of(&self, a: Address) -> Result<Option<DataType>, DaqError> {
        let Some(d) = &self.settings.dictionary else {
            return Ok(None);
        };
        match d.get(a) {
            Some(e) => Ok(Some(e.data_type)),
            None => Err(DaqError::Announcement {
                port: self.port.clone(),
                detail: format!("object {a} named in the stand file is not in the node's EDS ({} {}); fix [daq.canopen.objects]", d.vendor, d.product),
            }),
        }
    }

    /// Number of analog inputs the EDS declares (sub-indices of `inputs` beyond 0).
    fn input_count(&self) -> Option<u16> {
        let d = self.settings.dictionary.as_ref()?;
        let idx = self.settings.objects.inputs;
        Some(
            d.entries
                .range(Address::new(idx, 1)..=Address::new(idx, 0xFF))
                .count() as u16,
        )
    }

    fn tpdo_cob(&self, n: usize) -> u32 {
        (TPDO_BASE as u32 + 0x100 * n as u32) + self.settings.node_id as u32
    }

    /// A configure request this node cannot take, as the error naming the port.
    fn refused(&self, detail: String) -> DaqError {
        DaqError::Announcement {
            port: self.port.clone(),
            detail,
        }
    }

    /// Configure, step 1: the request names channels, a positive rate and a block size, and
    /// only inputs the EDS declares.
    fn check_request(&self, config: &DaqConfig) -> Result<(), DaqError> {
        if config.channels.is_empty()
            || config.samples_per_block == 0
            || !(config.sample_rate_hz > 0.0)
        {
            return Err(self.refused(format!("request {config:?}: needs channels, a positive sample rate and ≥ 1 sample per block")));
        }
        if let Some(n) = self.input_count() {
            if let Some(c) = config.channels.iter().find(|&&c| c >= n) {
                return Err(self.refused(format!("device channel {c} does not exist: the EDS declares {n} inputs at 0x{:04X} (channels 0–{})", self.settings.objects.inputs, n.saturating_sub(1))));
            }
        }
        Ok(())
    }

    /// Configure, step 2: the counter's and the inputs' widths (from the EDS), the channels
    /// split over TPDOs after the counter, the SYNC period, and the bus load checked against
    /// the bit rate.
    fn plan_pdos(&self, config: &DaqConfig) -> Result<PdoPlan, DaqError> {
        let objects = &self.settings.objects;
        let counter_type = self
            .type_of(objects.counter)?
            .unwrap_or(DataType::Unsigned16);
        let counter_bytes = match counter_type {
            DataType::Unsigned8 | DataType::Unsigned16 | DataType::Unsigned32 => {
                counter_type.size().unwrap_or(2)
            }
            t => {
                return Err(self.refused(format!(
                    "sample counter {} is {t:?}: it must be UNSIGNED8/16/32",
                    objects.counter
                )))
            }
        };
        let first_sub = u8::try_from(config.channels[0] + 1).unwrap_or(u8::MAX);
        let input_type = self
            .type_of(Address::new(objects.inputs, first_sub))?
            .unwrap_or(DataType::Integer16);
        let value_bytes = match input_type {
            DataType::Integer8 | DataType::Integer16 | DataType::Integer32 => {
                input_type.size().unwrap_or(2)
            }
            t => {
                return Err(self.refused(format!(
                    "inputs 0x{:04X} are {t:?}: INTEGER8/16/32 are supported",
                    objects.inputs
                )))
            }
        };
        let per_pdo = (8 - counter_bytes) / value_bytes;
        let pdos: Vec<Vec<usize>> = (0..config.channels.len())
            .collect::<Vec<_>>()
            .chunks(per_pdo)
            .map(<[usize]>::to_vec)
            .collect();
        if pdos.len() > objects.tpdos as usize {
            return Err(self.refused(format!("{} channels need {} TPDOs ({per_pdo} channels each after the counter), the node has {}; stream fewer channels", config.channels.len(), pdos.len(), objects.tpdos)));
        }
        let period_us = (1e6 / config.sample_rate_hz).round().max(1.0) as u32;
        let rate = 1e6 / period_us as f64;
        // Bits per second on the bus: SYNC (47 bits + stuffing) and every TPDO (47 + 8·n data bits),
        // with ~20 % bit stuffing. More than the bit rate cannot be delivered.
        let bits_per_sample: f64 = 1.2
            * (47.0
                + pdos
                    .iter()
                    .map(|p| 47.0 + 8.0 * (counter_bytes + p.len() * value_bytes) as f64)
                    .sum::<f64>());
        if rate * bits_per_sample > self.settings.bit_rate as f64 {
            return Err(self.refused(format!("{rate} Hz × {} TPDOs + SYNC needs about {:.0} bit/s, more than the bus's {} bit/s; lower the sample rate to at most {:.0} Hz or stream fewer channels", pdos.len(), rate * bits_per_sample, self.settings.bit_rate, self.settings.bit_rate as f64 / bits_per_sample)));
        }
        Ok(PdoPlan {
            counter_bytes,
            value_bytes,
            pdos,
            period_us,
            rate_hz: rate,
        })
    }

    /// Configure, step 3: in pre-operational, the SYNC period (and the node's sample rate), every
    /// TPDO disabled and the used ones mapped (counter first, then their channels) and enabled
    /// on SYNC, and the heartbeat period, all by SDO.
    async fn write_pdo_mapping(
        &mut self,
        config: &DaqConfig,
        plan: &PdoPlan,
    ) -> Result<(), DaqError> {
        let objects = self.settings.objects.clone();
        self.nmt(NmtCommand::PreOperational).await?;
        self.write(Address::new(0x1006, 0), &plan.period_us.to_le_bytes())
            .await?;
        if let Some(a) = objects.sample_rate {
            self.write(a, &(plan.rate_hz.round() as u32).to_le_bytes())
                .await?;
        }
        let counter_map = (objects.counter.index as u32) << 16
            | (objects.counter.sub as u32) << 8
            | (plan.counter_bytes as u32 * 8);
        for n in 0..objects.tpdos as usize {
            let comm = 0x1800 + n as u16;
            let map = 0x1A00 + n as u16;
            let cob_id = self.tpdo_cob(n);
            self.write(Address::new(comm, 1), &(cob_id | 0x8000_0000).to_le_bytes())
                .await?;
            let Some(chans) = plan.pdos.get(n) else {
                continue;
            };
            self.write(Address::new(map, 0), &[0]).await?;
            self.write(Address::new(map, 1), &counter_map.to_le_bytes())
                .await?;
            for (j, &pos) in chans.iter().enumerate() {
                let sub = config.channels[pos] + 1;
                let Ok(sub) = u8::try_from(sub) else {
                    return Err(self.refused(format!(
                        "device channel {} is beyond sub-index 255",
                        config.channels[pos]
                    )));
                };
                let m = (objects.inputs as u32) << 16
                    | (sub as u32) << 8
                    | (plan.value_bytes as u32 * 8);
                self.write(Address::new(map, 2 + j as u8), &m.to_le_bytes())
                    .await?;
            }
            self.write(Address::new(map, 0), &[1 + chans.len() as u8])
                .await?;
            self.write(Address::new(comm, 2), &[1]).await?;
            self.write(Address::new(comm, 1), &cob_id.to_le_bytes())
                .await?;
        }
        self.write(
            Address::new(0x1017, 0),
            &self.settings.heartbeat_ms.to_le_bytes(),
        )
        .await
    }

    /// Configure, step 4: each channel's volts per count, read from the node's scaling object
    /// (REAL32) when the stand names one, else the stand's value; each must be positive.
    async fn read_scaling(&mut self, config: &DaqConfig) -> Result<Vec<ChannelInfo>, DaqError> {
        let mut channels = Vec::with_capacity(config.channels.len());
        for &c in &config.channels {
            let volts_per_count = match self.settings.objects.scaling {
                Some(idx) => {
                    let v = self.read(Address::new(idx, (c + 1) as u8)).await?;
                    match v.as_slice() {
                        [a, b, cc, d] => f32::from_le_bytes([*a, *b, *cc, *d]) as f64,
                        other => {
                            return Err(self.refused(format!(
                                "scaling 0x{idx:04X}:{:02X} answered {} bytes, REAL32 has 4",
                                c + 1,
                                other.len()
                            )))
                        }
                    }
                }
                None => self.settings.volts_per_count,
            };
            if !(volts_per_count.is_finite() && volts_per_count > 0.0) {
                return Err(self.refused(format!(
                    "channel {c}: volts per count {volts_per_count} is not a positive number"
                )));
            }
            channels.push(ChannelInfo {
                device_channel: c,
                volts_per_count,
            });
        }
        Ok(channels)
    }

    /// Answers the stream's frames and the heartbeat check until an event is ready.
    async fn pump(&mut self) -> Result<(), DaqError> {
        let hb_timeout = self.settings.heartbeat_timeout;
        loop {
            if !self.monitor.pending.is_empty() {
                return Ok(());
            }
            let now = Instant::now();
            if now >= self.next_sync {
                let f = WireFrame::from_parts(CanId::Standard(SYNC_ID), FrameKind::Classic, &[]);
                self.link.send(&f).await.map_err(|e| self.can_err(e))?;
                self.syncs_sent += 1;
                self.next_sync += self.sync_period;
                if now > self.next_sync + self.sync_period * 1000 {
                    // Far behind (the host was busy): resume from now instead of a burst.
                    self.next_sync = now;
                }
                continue;
            }
            let hb_deadline = match (self.settings.heartbeat_ms, self.monitor.last_heartbeat) {
                (0, _) => None,
                (_, Some((t, _))) => Some(t + hb_timeout),
                (_, None) => None,
            };
            if let Some(d) = hb_deadline {
                if now >= d && !self.monitor.heartbeat_lost {
                    self.monitor.heartbeat_lost = true;
                    let since = self
                        .monitor
                        .last_heartbeat
                        .map_or(Duration::ZERO, |(t, _)| now - t);
                    self.monitor.pending.push_back(DaqEvent::Fault(StreamFault {
                        kind: FaultKind::Device,
                        seq: Some(self.next_seq),
                        detail: format!("node {} lost: no heartbeat for {since:?} (consumer time {hb_timeout:?}, producer time {} ms); check the node's power and the bus", self.settings.node_id, self.settings.heartbeat_ms),
                    }));
                    continue;
                }
            }
            let data_deadline = self.last_data + self.settings.data_timeout;
            if now >= data_deadline {
                return Err(DaqError::Timeout {
                    port: self.port.clone(),
                    what: "TPDO (sample data)".into(),
                    waited: self.settings.data_timeout,
                });
            }
            let mut deadline = self.next_sync.min(data_deadline);
            if let Some(d) = hb_deadline.filter(|_| !self.monitor.heartbeat_lost) {
                deadline = deadline.min(d);
            }
            let ev = match tokio::time::timeout_at(deadline, self.link.recv()).await {
                Err(_) => continue,
                Ok(r) => r.map_err(|e| self.can_err(e))?,
            };
            if let Some(f) = self.monitor.file(ev) {
                self.pdo(&f);
            }
        }
    }

    /// Files one TPDO frame.
    fn pdo(&mut self, f: &WireFrame) {
        let Some(layout) = self.layout.clone() else {
            return;
        };
        let raw_id = f.id().raw();
        let Some(k) = (0..layout.pdos.len())
            .find(|&n| matches!(f.id(), CanId::Standard(_)) && self.tpdo_cob(n) == raw_id)
        else {
            return;
        };
        self.last_data = Instant::now();
        let d = f.data();
        let want = layout.counter_bytes + layout.pdos[k].len() * layout.value_bytes;
        if d.len() != want {
            self.monitor.pending.push_back(DaqEvent::Fault(StreamFault {
                kind: FaultKind::Framing,
                seq: None,
                detail: format!(
                    "TPDO{} {} has {} bytes, the mapping makes {want}",
                    k + 1,
                    f.to_cansend(),
                    d.len()
                ),
            }));
            return;
        }
        let mut c = [0u8; 4];
        c[..layout.counter_bytes].copy_from_slice(&d[..layout.counter_bytes]);
        let raw = u32::from_le_bytes(c);
        let index = match self.last_raw {
            None => raw as u64,
            Some(last) => {
                let modulus = 1u64 << layout.counter_bits;
                let delta = (raw as u64 + modulus - last as u64) % modulus;
                if delta > modulus / 2 {
                    self.monitor.pending.push_back(DaqEvent::Fault(StreamFault {
                        kind: FaultKind::OutOfOrder,
                        seq: None,
                        detail: format!(
                            "TPDO{} with sample counter {raw} after {last}: discarded",
                            k + 1
                        ),
                    }));
                    return;
                }
                self.last_index + delta
            }
        };
        self.last_raw = Some(raw);
        self.last_index = index;
        let full: u32 = (1u32 << layout.pdos.len()) - 1;
        if self.assembly.as_ref().is_some_and(|a| a.index != index) {
            if let Some(a) = self.assembly.take() {
                if !a.done {
                    tracing::debug!(
                        "sample {} incomplete (TPDO mask {:b}): lost",
                        a.index,
                        a.mask
                    );
                }
            }
        }
        let nch = layout.scale.len();
        let a = self.assembly.get_or_insert_with(|| Assembly {
            index,
            mask: 0,
            counts: vec![0; nch],
            done: false,
        });
        if a.mask & (1 << k) != 0 {
            self.monitor.pending.push_back(DaqEvent::Fault(StreamFault {
                kind: FaultKind::Duplicate,
                seq: Some(index / layout.samples_per_block as u64),
                detail: format!(
                    "TPDO{} of sample {index} received twice; the copy was discarded",
                    k + 1
                ),
            }));
            return;
        }
        for (j, &pos) in layout.pdos[k].iter().enumerate() {
            let off = layout.counter_bytes + j * layout.value_bytes;
            a.counts[pos] = match layout.value_bytes {
                1 => d[off] as i8 as i32,
                2 => i16::from_le_bytes([d[off], d[off + 1]]) as i32,
                _ => i32::from_le_bytes([d[off], d[off + 1], d[off + 2], d[off + 3]]),
            };
        }
        a.mask |= 1 << k;
        if a.mask == full {
            a.done = true;
            let counts = a.counts.clone();
            self.commit(index, &counts, &layout);
        }
    }

    /// A complete sample into its block; a completed block is delivered.
    fn commit(&mut self, index: u64, counts: &[i32], layout: &Layout) {
        let spb = layout.samples_per_block;
        let nch = counts.len();
        let seq = index / spb as u64;
        let pos = (index % spb as u64) as usize;
        if self.building.as_ref().is_some_and(|b| b.seq != seq) {
            // The previous block misses samples: it is lost; the gap is reported with the next
            // block delivered.
            self.building = None;
        }
        let b = self.building.get_or_insert_with(|| Building {
            seq,
            filled: 0,
            volts: vec![f32::NAN; spb * nch],
        });
        for (c, &n) in counts.iter().enumerate() {
            b.volts[pos * nch + c] = (n as f64 * layout.scale[c]) as f32;
        }
        b.filled += 1;
        if b.filled == spb {
            if let Some(b) = self.building.take() {
                if b.seq > self.next_seq {
                    self.monitor.pending.push_back(DaqEvent::Fault(StreamFault {
                        kind: FaultKind::Gap,
                        seq: Some(self.next_seq),
                        detail: format!(
                            "blocks {}..{} lost: TPDOs missing (sample counter jumped)",
                            self.next_seq,
                            b.seq - 1
                        ),
                    }));
                }
                self.next_seq = b.seq + 1;
                self.monitor.pending.push_back(DaqEvent::Block(SampleBlock {
                    seq: b.seq,
                    first_sample: b.seq * spb as u64,
                    channel_count: nch as u16,
                    volts: b.volts,
                }));
            }
        }
    }
}

#[async_trait]
impl Daq for CanOpenDaq {
    fn port(&self) -> &str {
        &self.port
    }

    async fn identify(&mut self) -> Result<DeviceIdentity, DaqError> {
        let vendor = self.read_u32(Address::new(0x1018, 1)).await?;
        let product = self.read_u32(Address::new(0x1018, 2)).await?;
        let revision = self.read_u32(Address::new(0x1018, 3)).await?;
        let serial = self.read_u32(Address::new(0x1018, 4)).await?;
        let text = |v: Vec<u8>| {
            String::from_utf8_lossy(&v)
                .trim_end_matches('\0')
                .trim()
                .to_string()
        };
        let name = self.read(Address::new(0x1008, 0)).await.map(text).ok();
        let software = self.read(Address::new(0x100A, 0)).await.map(text).ok();
        let mut manufacturer = format!("vendor 0x{vendor:08X}");
        if let Some(d) = &self.settings.dictionary {
            let expect = |sub: u8| {
                d.get(Address::new(0x1018, sub))
                    .and_then(|e| e.value.as_deref())
                    .and_then(|v| DataType::Unsigned32.encode(v).ok())
                    .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            };
            let (ev, ep) = (expect(1), expect(2));
            if ev.is_some_and(|x| x != vendor) || ep.is_some_and(|x| x != product) {
                return Err(DaqError::WrongIdentity {
                    port: self.port.clone(),
                    got: format!("vendor 0x{vendor:08X} product 0x{product:08X}"),
                    expected: format!("vendor 0x{:08X} product 0x{:08X} ({} {} from the EDS; wrong node id or wrong EDS?)", ev.unwrap_or(0), ep.unwrap_or(0), d.vendor, d.product),
                });
            }
            if !d.vendor.is_empty() {
                manufacturer = d.vendor.clone();
            }
        }
        Ok(DeviceIdentity {
            manufacturer,
            model: name.unwrap_or_else(|| format!("product 0x{product:08X}")),
            serial: format!("{serial:08X}"),
            firmware: software.unwrap_or_else(|| format!("revision 0x{revision:08X}")),
        })
    }

    async fn configure(&mut self, config: &DaqConfig) -> Result<StreamInfo, DaqError> {
        self.check_request(config)?;
        let plan = self.plan_pdos(config)?;
        self.write_pdo_mapping(config, &plan).await?;
        let channels = self.read_scaling(config).await?;
        self.sync_period = Duration::from_micros(plan.period_us as u64);
        self.layout = Some(Layout {
            counter_bytes: plan.counter_bytes,
            counter_bits: plan.counter_bytes as u32 * 8,
            value_bytes: plan.value_bytes,
            pdos: plan.pdos,
            scale: channels.iter().map(|c| c.volts_per_count).collect(),
            samples_per_block: config.samples_per_block as usize,
        });
        let info = StreamInfo {
            sample_rate_hz: plan.rate_hz,
            channels,
            samples_per_block: config.samples_per_block,
        };
        self.info = Some(info.clone());
        Ok(info)
    }

    async fn start(&mut self) -> Result<(), DaqError> {
        if self.layout.is_none() {
            return Err(DaqError::State {
                port: self.port.clone(),
                detail: "start before configure".into(),
            });
        }
        self.last_raw = None;
        self.last_index = 0;
        self.assembly = None;
        self.building = None;
        self.next_seq = 0;
        self.nmt(NmtCommand::Start).await?;
        let now = Instant::now();
        self.next_sync = now;
        self.syncs_sent = 0;
        self.last_data = now;
        self.monitor.streaming = true;
        self.monitor.heartbeat_lost = false;
        self.monitor.seen_operational = false;
        if self.settings.heartbeat_ms > 0 {
            let state = self
                .monitor
                .last_heartbeat
                .map_or(NmtState::Operational, |(_, s)| s);
            self.monitor.last_heartbeat = Some((now, state));
        }
        Ok(())
    }

    async fn next_event(&mut self) -> Result<DaqEvent, DaqError> {
        if !self.monitor.streaming {
            return Err(DaqError::State {
                port: self.port.clone(),
                detail: "next_event before start".into(),
            });
        }
        loop {
            if let Some(ev) = self.monitor.pending.pop_front() {
                return Ok(ev);
            }
            self.pump().await?;
        }
    }

    async fn stop(&mut self) -> Result<(), DaqError> {
        self.monitor.streaming = false;
        self.nmt(NmtCommand::PreOperational).await?;
        // Drain what was in flight; EMCY and heartbeats are still filed.
        let until = Instant::now() + Duration::from_millis(20);
        while let Ok(r) = tokio::time::timeout_at(until, self.link.recv()).await {
            let ev = r.map_err(|e| self.can_err(e))?;
            self.monitor.file(ev);
        }
        // Blocks and faults of the stopped stream are discarded; EMCY stay in `emergencies()`.
        self.monitor.pending.clear();
        self.link.flush();
        Ok(())
    }

    /// The node samples on each SYNC this master sends, and only then: while the host is busy
    /// elsewhere no sample is taken, and a host far behind resumes from now (see `pump`), so the
    /// node's sample clock is the SYNC count, not wall-clock time.
    fn sample_clock(&self) -> Option<u64> {
        Some(self.syncs_sent)
    }
}
