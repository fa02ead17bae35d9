//! The DAQ as a CANopen device (CiA 301): ident is the master of one accelerometer/force node.
//!
//! - [`sdo`]: the SDO client (expedited and segmented upload and download, abort codes as typed
//!   errors, timeouts, toggle errors) and the wire format both ends share.
//! - [`eds`]: the node's EDS/DCF file (INI) read into an [`eds::ObjectDictionary`].
//! - [`CanOpenDaq`]: a [`Daq`](crate::daq::Daq) over NMT, SDO, SYNC, TPDOs, heartbeat and EMCY:
//!   it reads the identity (0x1018), configures the sampling (communication cycle period 0x1006,
//!   the node's own sample-rate object if the stand file names one), maps the requested channels
//!   into TPDOs (0x1A00…, 0x1800…), produces SYNC, watches the heartbeat (a lost node is a device
//!   fault event) and records every EMCY with its error code. A sample counter mapped into every
//!   TPDO detects lost frames, logged as gaps.
//! - [`sim`]: a simulated node with an object dictionary loaded from an EDS shipped in the
//!   repository (`configs/canopen/ident-sim-daq.eds`), answering SDO and NMT, sending SYNC-triggered
//!   TPDOs from a signal, heartbeats, and EMCY on injected faults.
//!
//! Everything runs over a [`CanLink`]: the SocketCAN [`CanBus`] on a stand,
//! the in-memory [`MemoryBus`] in tests. docs/canopen.md describes what is supported.

pub mod eds;
mod master;
pub mod sdo;
pub mod sim;

pub use master::{CanOpenDaq, CanOpenObjects, CanOpenSettings, Emergency};

use async_trait::async_trait;

use crate::can::{BusEvent, CanBus, CanError, CanId, FrameKind, WireFrame};

/// Function code of NMT node control (identifier 0x000).
pub const NMT_ID: u16 = 0x000;
/// Default SYNC identifier.
pub const SYNC_ID: u16 = 0x080;
/// EMCY identifier base (+ node id).
pub const EMCY_BASE: u16 = 0x080;
/// TPDO1 identifier base (+ node id); TPDO n adds `0x100·(n-1)`.
pub const TPDO_BASE: u16 = 0x180;
/// SDO server → client base (+ node id).
pub const SDO_TX_BASE: u16 = 0x580;
/// SDO client → server base (+ node id).
pub const SDO_RX_BASE: u16 = 0x600;
/// Heartbeat / boot-up identifier base (+ node id).
pub const HEARTBEAT_BASE: u16 = 0x700;

/// An NMT node-control command (CiA 301 §7.2.8.3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NmtCommand {
    /// Start remote node: operational (PDOs flow).
    Start,
    /// Stop remote node: stopped (only NMT and heartbeat).
    Stop,
    /// Enter pre-operational (SDO, no PDOs).
    PreOperational,
    /// Reset the application (object dictionary back to its defaults).
    ResetNode,
    /// Reset communication parameters only.
    ResetCommunication,
}

impl NmtCommand {
    /// The command specifier byte.
    pub fn specifier(self) -> u8 {
        match self {
            NmtCommand::Start => 0x01,
            NmtCommand::Stop => 0x02,
            NmtCommand::PreOperational => 0x80,
            NmtCommand::ResetNode => 0x81,
            NmtCommand::ResetCommunication => 0x82,
        }
    }

    /// The command for a specifier byte.
    pub fn from_specifier(cs: u8) -> Option<NmtCommand> {
        Some(match cs {
            0x01 => NmtCommand::Start,
            0x02 => NmtCommand::Stop,
            0x80 => NmtCommand::PreOperational,
            0x81 => NmtCommand::ResetNode,
            0x82 => NmtCommand::ResetCommunication,
            _ => return None,
        })
    }

    /// The NMT frame addressed to `node` (0 = all nodes).
    pub fn frame(self, node: u8) -> WireFrame {
        WireFrame::from_parts(
            CanId::Standard(NMT_ID),
            FrameKind::Classic,
            &[self.specifier(), node],
        )
    }
}

/// A node's NMT state as its heartbeat reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NmtState {
    /// Boot-up message (0x00): the node has just (re)started.
    BootUp,
    /// Stopped (0x04).
    Stopped,
    /// Operational (0x05).
    Operational,
    /// Pre-operational (0x7F).
    PreOperational,
}

impl NmtState {
    /// The heartbeat byte.
    pub fn code(self) -> u8 {
        match self {
            NmtState::BootUp => 0x00,
            NmtState::Stopped => 0x04,
            NmtState::Operational => 0x05,
            NmtState::PreOperational => 0x7F,
        }
    }

    /// The state of a heartbeat byte (the toggle bit 7 of node guarding is ignored).
    pub fn from_code(b: u8) -> Option<NmtState> {
        Some(match b & 0x7F {
            0x00 => NmtState::BootUp,
            0x04 => NmtState::Stopped,
            0x05 => NmtState::Operational,
            0x7F => NmtState::PreOperational,
            _ => return None,
        })
    }
}

/// A CAN connection the CANopen master and the simulated node speak over: the SocketCAN
/// [`CanBus`] or an endpoint of the in-memory [`MemoryBus`]. `recv` must be cancel safe (it is
/// raced against timers).
#[async_trait]
pub trait CanLink: Send {
    /// Interface name, for messages.
    fn interface(&self) -> &str;
    /// Sends one frame.
    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError>;
    /// Receives the next frame or error frame sent by another node.
    async fn recv(&mut self) -> Result<BusEvent, CanError>;
    /// Hands over whatever a recording link still holds (nothing to do for a plain link).
    fn flush(&mut self) {}
}

#[async_trait]
impl CanLink for CanBus {
    fn interface(&self) -> &str {
        CanBus::interface(self)
    }
    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError> {
        CanBus::send(self, frame).await
    }
    async fn recv(&mut self) -> Result<BusEvent, CanError> {
        CanBus::recv(self).await
    }
}

/// An in-memory CAN bus: every endpoint receives the frames every other endpoint sends, in
/// order (a broadcast channel). A reader that falls more than the capacity behind loses the
/// oldest frames, as a CAN controller's overrun does.
#[derive(Debug, Clone)]
pub struct MemoryBus {
    name: String,
    tx: tokio::sync::broadcast::Sender<(u64, WireFrame)>,
    next_endpoint: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl MemoryBus {
    /// A bus named `name` holding up to 65 536 frames per reader.
    pub fn new(name: &str) -> MemoryBus {
        let (tx, _) = tokio::sync::broadcast::channel(1 << 16);
        MemoryBus {
            name: name.to_string(),
            tx,
            next_endpoint: std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0)),
        }
    }

    /// A new node on the bus; it receives the frames sent after this call.
    pub fn endpoint(&self) -> MemoryEndpoint {
        MemoryEndpoint {
            name: self.name.clone(),
            id: self
                .next_endpoint
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            tx: self.tx.clone(),
            rx: self.tx.subscribe(),
        }
    }
}

/// One node's connection to a [`MemoryBus`].
#[derive(Debug)]
pub struct MemoryEndpoint {
    name: String,
    id: u64,
    tx: tokio::sync::broadcast::Sender<(u64, WireFrame)>,
    rx: tokio::sync::broadcast::Receiver<(u64, WireFrame)>,
}

#[async_trait]
impl CanLink for MemoryEndpoint {
    fn interface(&self) -> &str {
        &self.name
    }

    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError> {
        // No receiver is not an error: a frame on a bus nobody listens to is simply lost.
        let _ = self.tx.send((self.id, *frame));
        Ok(())
    }

    async fn recv(&mut self) -> Result<BusEvent, CanError> {
        use tokio::sync::broadcast::error::RecvError;
        loop {
            match self.rx.recv().await {
                Ok((from, f)) if from != self.id => return Ok(BusEvent::Frame(f)),
                Ok(_) | Err(RecvError::Lagged(_)) => continue,
                Err(RecvError::Closed) => {
                    return Err(CanError::Io {
                        interface: self.name.clone(),
                        op: "receive",
                        source: std::io::Error::from(std::io::ErrorKind::UnexpectedEof),
                    })
                }
            }
        }
    }
}

/// A [`CanLink`] whose every frame, sent and received, is copied to a [`ByteTap`](crate::transport::ByteTap) in
/// `cansend`/`candump -L` lines (`605#4018100100000000\n`), as the DAQ-over-CAN driver records its
/// frames into the session. CANopen frames are small and many (SYNC and TPDOs per sample), so
/// consecutive lines of one direction are handed over together, up to 4 KiB: on a change of
/// direction, at [`CanLink::flush`] and when dropped.
pub struct TappedLink {
    inner: Box<dyn CanLink>,
    tap: std::sync::Arc<dyn crate::transport::ByteTap>,
    pending: Vec<u8>,
    direction: crate::transport::Direction,
}

impl TappedLink {
    /// Copies `inner`'s traffic to `tap`.
    pub fn new(
        inner: Box<dyn CanLink>,
        tap: std::sync::Arc<dyn crate::transport::ByteTap>,
    ) -> TappedLink {
        TappedLink {
            inner,
            tap,
            pending: Vec::with_capacity(4096),
            direction: crate::transport::Direction::Tx,
        }
    }

    fn record(&mut self, direction: crate::transport::Direction, f: &WireFrame) {
        if direction != self.direction {
            self.flush();
            self.direction = direction;
        }
        self.pending.extend_from_slice(f.to_cansend().as_bytes());
        self.pending.push(b'\n');
        if self.pending.len() >= 4096 {
            self.flush();
        }
    }
}

impl Drop for TappedLink {
    fn drop(&mut self) {
        self.flush();
    }
}

#[async_trait]
impl CanLink for TappedLink {
    fn interface(&self) -> &str {
        self.inner.interface()
    }

    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError> {
        self.inner.send(frame).await?;
        self.record(crate::transport::Direction::Tx, frame);
        Ok(())
    }

    async fn recv(&mut self) -> Result<BusEvent, CanError> {
        let ev = self.inner.recv().await?;
        if let BusEvent::Frame(f) = &ev {
            self.record(crate::transport::Direction::Rx, f);
        }
        Ok(ev)
    }

    fn flush(&mut self) {
        if !self.pending.is_empty() {
            self.tap
                .bytes(self.inner.interface(), self.direction, &self.pending);
            self.pending.clear();
        }
    }
}

/// The standard 11-bit identifier `base + node`.
pub(crate) fn cob(base: u16, node: u8) -> CanId {
    CanId::Standard(base + node as u16)
}

#[cfg(test)]
mod tests;
