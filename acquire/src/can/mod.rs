//! The DAQ over CAN: a SocketCAN transport (classic and CAN FD frames, error frames decoded), the
//! DAQ-over-CAN wire format of `docs/daq-can.md` (pure codec), a [`Daq`](crate::daq::Daq) backed by
//! it, and a simulated CAN DAQ that serves the protocol for tests.
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! use acquire::can::{CanDaq, CanDaqSettings};
//! use acquire::daq::{Daq, DaqConfig, DaqEvent};
//!
//! let mut daq = CanDaq::open("can0", CanDaqSettings::default())?;
//! let identity = daq.identify().await?;
//! let info = daq
//!     .configure(&DaqConfig { sample_rate_hz: 25_600.0, channels: vec![0, 1, 2, 3], samples_per_block: 64 })
//!     .await?;
//! daq.start().await?;
//! while let DaqEvent::Block(block) = daq.next_event().await? {
//!     println!("{identity:?} block {} at {} Hz: {} samples", block.seq, info.sample_rate_hz, block.len());
//!     break;
//! }
//! daq.stop().await?;
//! # Ok(()) }
//! ```

mod bus;
pub mod codec;
mod daq;
pub mod sim;

pub use bus::{BusErrorReport, BusEvent, CanBus};
pub use daq::{CanDaq, CanDaqSettings};

/// A CAN identifier: 11-bit standard or 29-bit extended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CanId {
    /// 11-bit identifier (0–0x7FF).
    Standard(u16),
    /// 29-bit identifier (0–0x1FFF_FFFF).
    Extended(u32),
}

impl CanId {
    /// The numeric identifier.
    pub fn raw(self) -> u32 {
        match self {
            CanId::Standard(id) => id as u32,
            CanId::Extended(id) => id,
        }
    }

    /// Checks the range of the identifier; `what` names it in the error.
    pub fn validate(self, what: &str) -> Result<(), CanError> {
        let ok = match self {
            CanId::Standard(id) => id <= 0x7FF,
            CanId::Extended(id) => id <= 0x1FFF_FFFF,
        };
        if ok {
            Ok(())
        } else {
            Err(CanError::Config {
                detail: format!("{what} identifier {self} out of range (standard ≤ 0x7FF, extended ≤ 0x1FFFFFFF)"),
            })
        }
    }
}

impl std::fmt::Display for CanId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CanId::Standard(id) => write!(f, "{id:03X}"),
            CanId::Extended(id) => write!(f, "{id:08X}"),
        }
    }
}

/// Classic CAN (≤ 8 data bytes) or CAN FD (≤ 64 data bytes) frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameKind {
    /// Classic CAN 2.0 frames, 8 data bytes.
    Classic,
    /// CAN FD frames, 64 data bytes.
    Fd,
}

impl FrameKind {
    /// Largest data length (bytes).
    pub fn max_data(self) -> usize {
        match self {
            FrameKind::Classic => 8,
            FrameKind::Fd => 64,
        }
    }
}

/// One data frame as the codec sees it: identifier, kind and up to 64 data bytes.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct WireFrame {
    id: CanId,
    kind: FrameKind,
    len: u8,
    data: [u8; 64],
}

impl WireFrame {
    /// A frame with `data` (truncated to the kind's maximum: 8 or 64 bytes).
    pub fn from_parts(id: CanId, kind: FrameKind, data: &[u8]) -> WireFrame {
        let len = data.len().min(kind.max_data());
        let mut d = [0u8; 64];
        d[..len].copy_from_slice(&data[..len]);
        WireFrame {
            id,
            kind,
            len: len as u8,
            data: d,
        }
    }

    /// Identifier.
    pub fn id(&self) -> CanId {
        self.id
    }

    /// Data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..self.len as usize]
    }

    /// True for a CAN FD frame.
    pub fn is_fd(&self) -> bool {
        self.kind == FrameKind::Fd
    }

    /// Frame kind.
    pub fn kind(&self) -> FrameKind {
        self.kind
    }

    /// The frame in `candump -L` / `cansend` notation: `102#80010003A1B2`, FD frames `102##0…`.
    pub fn to_cansend(&self) -> String {
        let mut s = format!("{}#", self.id);
        if self.is_fd() {
            s.push_str("#0");
        }
        for b in self.data() {
            s.push_str(&format!("{b:02X}"));
        }
        s
    }
}

impl std::fmt::Debug for WireFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.to_cansend())
    }
}

/// Errors of the CAN transport. Each names the interface and says what to check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CanError {
    /// The interface does not exist or is not a CAN device.
    #[error("CAN interface `{interface}` does not exist or is not a CAN device ({source}); check `ip link show {interface}` and the stand file's interface name (a virtual bus: `ip link add dev {interface} type vcan && ip link set {interface} up`)")]
    UnknownInterface {
        /// Interface name.
        interface: String,
        /// What the kernel said.
        source: std::io::Error,
    },
    /// The kernel has no SocketCAN support.
    #[error("CAN interface `{interface}`: this kernel has no CAN support ({source}); load it with `modprobe can-raw` (and `vcan` for a virtual bus), or run the tests through .ci/vcan/run-in-vm.sh")]
    NoKernelSupport {
        /// Interface name.
        interface: String,
        /// What the kernel said.
        source: std::io::Error,
    },
    /// The interface exists but is down.
    #[error("CAN interface `{interface}` is down; bring it up with `ip link set {interface} up` (hardware: set the bitrate first, `ip link set {interface} type can bitrate 1000000`)")]
    InterfaceDown {
        /// Interface name.
        interface: String,
    },
    /// The interface does not accept CAN FD frames.
    #[error("CAN interface `{interface}` does not accept CAN FD frames (MTU 16); enable FD (`ip link set {interface} mtu 72` for vcan, `type can ... fd on dbitrate ...` for hardware) or configure classic frames")]
    FdNotSupported {
        /// Interface name.
        interface: String,
    },
    /// Reading or writing failed.
    #[error("CAN interface `{interface}`: {op} failed: {source}; check `ip -details -statistics link show {interface}` (state, bus errors, tx queue)")]
    Io {
        /// Interface name.
        interface: String,
        /// Operation (`send`, `receive`, `open`).
        op: &'static str,
        /// Underlying error.
        source: std::io::Error,
    },
    /// A message does not fit the wire format.
    #[error("CAN interface `{interface}`: cannot encode {message}: {source}")]
    Encode {
        /// Interface name.
        interface: String,
        /// Message name.
        message: &'static str,
        /// Why.
        source: codec::EncodeError,
    },
    /// Bad settings (identifiers out of range, clashing identifiers).
    #[error("CAN settings: {detail}")]
    Config {
        /// What is wrong.
        detail: String,
    },
}
