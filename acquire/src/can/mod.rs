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
mod frame;
pub mod sim;

pub use bus::{BusErrorReport, BusEvent, CanBus};
pub use daq::{CanDaq, CanDaqSettings};
pub use frame::{CanId, FrameKind, WireFrame};

// Defined here rather than with the identifier so that the frame types depend on nothing above them.
impl CanId {
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
