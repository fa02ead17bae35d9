//! The SocketCAN transport: one raw CAN socket (classic and FD frames) on a named interface, with
//! identifier filters, error frames decoded into reports, and errors that say what to check.

use std::time::Duration;

use socketcan::{
    CanAnyFrame, CanDataFrame, CanFdFrame, CanFilter, EmbeddedFrame, ErrorCause, ExtendedId, Id,
    SocketOptions, StandardId,
};

use crate::can::{CanError, CanId, FrameKind, WireFrame};

const CAN_EFF_FLAG: u32 = 0x8000_0000;
const CAN_RTR_FLAG: u32 = 0x4000_0000;
const CAN_SFF_MASK: u32 = 0x7FF;
const CAN_EFF_MASK: u32 = 0x1FFF_FFFF;
const SOL_SOCKET: i32 = 1;
const SO_RCVBUF: i32 = 8;
const SO_RCVBUFFORCE: i32 = 33;
const ENODEV: i32 = 19;
const ENXIO: i32 = 6;
const EINVAL: i32 = 22;
const EAFNOSUPPORT: i32 = 97;
const EPROTONOSUPPORT: i32 = 93;
const ENETDOWN: i32 = 100;
const ENOBUFS: i32 = 105;

/// How long a send keeps retrying while the interface's transmit queue is full (ENOBUFS).
const SEND_BACKPRESSURE_LIMIT: Duration = Duration::from_secs(2);

/// A decoded CAN error frame (`CAN_ERR_FLAG`): what the controller or driver reported.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct BusErrorReport {
    /// Interface it came from.
    pub interface: String,
    /// The controller went bus-off: it no longer takes part in the bus until restarted.
    pub bus_off: bool,
    /// The controller is error-passive (TX or RX error counter ≥ 128).
    pub error_passive: bool,
    /// Error class bits of the frame's identifier (`CAN_ERR_*`).
    pub class_bits: u32,
    /// The causes in words (`bus off`, `controller problem: rx-warning`, …).
    pub causes: Vec<String>,
}

impl std::fmt::Display for BusErrorReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "CAN interface `{}`: error frame: {}",
            self.interface,
            self.causes.join("; ")
        )?;
        if self.bus_off {
            write!(
                f,
                "; the controller is bus-off: check termination (120 Ω at both ends), that every node uses the same bitrate, and the wiring; restart with `ip link set {} type can restart-ms 100`",
                self.interface
            )?;
        } else if self.error_passive {
            f.write_str(
                "; error-passive: frames are being corrupted (check termination, bitrate, wiring)",
            )?;
        }
        Ok(())
    }
}

/// What the bus delivered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BusEvent {
    /// A data frame (classic or FD).
    Frame(WireFrame),
    /// An error frame.
    Error(BusErrorReport),
    /// A remote-transmission-request frame (not used by the protocol).
    Remote(CanId),
}

/// An open raw CAN socket on one interface, able to send and receive classic and FD frames.
#[derive(Debug)]
pub struct CanBus {
    interface: String,
    sock: socketcan::tokio::CanFdSocket,
}

impl CanBus {
    /// Opens `interface` (e.g. `can0`, `vcan0`), receiving every frame and every error frame.
    pub fn open(interface: &str) -> Result<CanBus, CanError> {
        let sock =
            socketcan::tokio::CanFdSocket::open(interface).map_err(|e| open_error(interface, e))?;
        let bus = CanBus {
            interface: interface.to_string(),
            sock,
        };
        bus.sock
            .set_error_filter_accept_all()
            .map_err(|e| bus.io("set error filter", e))?;
        Ok(bus)
    }

    /// Opens `interface` receiving only frames with the given identifiers (plus error frames).
    pub fn open_filtered(interface: &str, ids: &[CanId]) -> Result<CanBus, CanError> {
        let bus = CanBus::open(interface)?;
        let filters: Vec<CanFilter> = ids
            .iter()
            .map(|id| match *id {
                CanId::Standard(x) => {
                    CanFilter::new(x as u32, CAN_SFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG)
                }
                CanId::Extended(x) => {
                    CanFilter::new(x | CAN_EFF_FLAG, CAN_EFF_MASK | CAN_EFF_FLAG | CAN_RTR_FLAG)
                }
            })
            .collect();
        bus.sock
            .set_filters(&filters)
            .map_err(|e| bus.io("set filters", e))?;
        Ok(bus)
    }

    /// Interface name.
    pub fn interface(&self) -> &str {
        &self.interface
    }

    /// Asks for a receive buffer of `bytes` (frames arriving faster than they are read queue
    /// there; beyond it the kernel drops them, which the protocol's frame counter then reports).
    /// Returns the request; privileged processes may exceed `net.core.rmem_max`.
    pub fn set_receive_buffer(&self, bytes: usize) -> Result<(), CanError> {
        let b = i32::try_from(bytes).unwrap_or(i32::MAX);
        self.sock
            .set_socket_option_int(SOL_SOCKET, SO_RCVBUFFORCE, b)
            .or_else(|_| self.sock.set_socket_option_int(SOL_SOCKET, SO_RCVBUF, b))
            .map_err(|e| self.io("set receive buffer", e))
    }

    /// Sends one frame. Waits (up to 2 s) while the transmit queue is full.
    pub async fn send(&self, frame: &WireFrame) -> Result<(), CanError> {
        let id = to_socketcan_id(frame.id()).ok_or_else(|| CanError::Config {
            detail: format!(
                "identifier {:?} is out of range (standard ≤ 0x7FF, extended ≤ 0x1FFFFFFF)",
                frame.id()
            ),
        })?;
        let deadline = tokio::time::Instant::now() + SEND_BACKPRESSURE_LIMIT;
        loop {
            let r = match frame.kind() {
                FrameKind::Classic => match CanDataFrame::new(id, frame.data()) {
                    Some(f) => self.sock.write_frame(&f).await,
                    None => return Err(self.bad_frame(frame)),
                },
                FrameKind::Fd => match CanFdFrame::new(id, frame.data()) {
                    Some(f) => self.sock.write_frame(&f).await,
                    None => return Err(self.bad_frame(frame)),
                },
            };
            match r {
                Ok(()) => return Ok(()),
                Err(e)
                    if e.raw_os_error() == Some(ENOBUFS)
                        && tokio::time::Instant::now() < deadline =>
                {
                    tokio::time::sleep(Duration::from_micros(200)).await;
                }
                Err(e) => return Err(self.send_error(frame, e)),
            }
        }
    }

    /// Receives the next frame or error frame.
    pub async fn recv(&self) -> Result<BusEvent, CanError> {
        let f = self
            .sock
            .read_frame()
            .await
            .map_err(|e| match e.raw_os_error() {
                Some(ENETDOWN) => CanError::InterfaceDown {
                    interface: self.interface.clone(),
                },
                _ => self.io("receive", e),
            })?;
        Ok(match f {
            CanAnyFrame::Normal(f) => BusEvent::Frame(WireFrame::from_parts(
                from_socketcan_id(f.id()),
                FrameKind::Classic,
                f.data(),
            )),
            CanAnyFrame::Fd(f) => BusEvent::Frame(WireFrame::from_parts(
                from_socketcan_id(f.id()),
                FrameKind::Fd,
                f.data(),
            )),
            CanAnyFrame::Remote(f) => BusEvent::Remote(from_socketcan_id(f.id())),
            CanAnyFrame::Error(f) => {
                let class_bits = f.error_bits();
                let err = f.into_error();
                let mut bus_off = false;
                let mut error_passive = false;
                let mut causes = Vec::new();
                for c in err.causes() {
                    match c {
                        ErrorCause::BusOff => bus_off = true,
                        ErrorCause::Controller(p) => {
                            error_passive |= p.intersects(
                                socketcan::errors::ControllerProblems::RX_PASSIVE
                                    | socketcan::errors::ControllerProblems::TX_PASSIVE,
                            )
                        }
                        _ => {}
                    }
                    causes.push(c.to_string());
                }
                BusEvent::Error(BusErrorReport {
                    interface: self.interface.clone(),
                    bus_off,
                    error_passive,
                    class_bits,
                    causes,
                })
            }
        })
    }

    fn io(&self, op: &'static str, source: std::io::Error) -> CanError {
        CanError::Io {
            interface: self.interface.clone(),
            op,
            source,
        }
    }

    fn bad_frame(&self, frame: &WireFrame) -> CanError {
        CanError::Config {
            detail: format!(
                "frame {frame:?} for `{}` cannot be built (length or identifier)",
                self.interface
            ),
        }
    }

    fn send_error(&self, frame: &WireFrame, e: std::io::Error) -> CanError {
        match e.raw_os_error() {
            Some(ENETDOWN) => CanError::InterfaceDown {
                interface: self.interface.clone(),
            },
            Some(EINVAL) if frame.is_fd() => CanError::FdNotSupported {
                interface: self.interface.clone(),
            },
            _ => self.io("send", e),
        }
    }
}

fn open_error(interface: &str, e: std::io::Error) -> CanError {
    match e.raw_os_error() {
        Some(EAFNOSUPPORT) | Some(EPROTONOSUPPORT) => CanError::NoKernelSupport {
            interface: interface.to_string(),
            source: e,
        },
        Some(ENODEV) | Some(ENXIO) => CanError::UnknownInterface {
            interface: interface.to_string(),
            source: e,
        },
        _ if e.kind() == std::io::ErrorKind::NotFound => CanError::UnknownInterface {
            interface: interface.to_string(),
            source: e,
        },
        Some(ENETDOWN) => CanError::InterfaceDown {
            interface: interface.to_string(),
        },
        _ => CanError::Io {
            interface: interface.to_string(),
            op: "open",
            source: e,
        },
    }
}

/// The socketcan identifier of `id`; `None` when it is out of its format's range.
fn to_socketcan_id(id: CanId) -> Option<Id> {
    match id {
        CanId::Standard(x) => StandardId::new(x).map(Id::Standard),
        CanId::Extended(x) => ExtendedId::new(x).map(Id::Extended),
    }
}

fn from_socketcan_id(id: Id) -> CanId {
    match id {
        Id::Standard(s) => CanId::Standard(s.as_raw()),
        Id::Extended(e) => CanId::Extended(e.as_raw()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn open_errors_name_the_interface_and_say_what_to_check() {
        let e = open_error("can7", std::io::Error::from_raw_os_error(ENODEV));
        let msg = e.to_string();
        assert!(matches!(e, CanError::UnknownInterface { .. }), "{e:?}");
        assert!(
            msg.contains("`can7`") && msg.contains("ip link show can7"),
            "{msg}"
        );
        let e = open_error("can7", std::io::Error::from_raw_os_error(EAFNOSUPPORT));
        assert!(
            matches!(e, CanError::NoKernelSupport { .. })
                && e.to_string().contains("modprobe can-raw"),
            "{e}"
        );
        let e = open_error("can7", std::io::Error::from_raw_os_error(ENETDOWN));
        assert!(e.to_string().contains("ip link set can7 up"), "{e}");
        let e = open_error("can7", std::io::Error::from_raw_os_error(13));
        assert!(
            matches!(e, CanError::Io { op: "open", .. }) && e.to_string().contains("can7"),
            "{e}"
        );
    }

    #[test]
    fn identifiers_convert_both_ways_and_out_of_range_ones_are_refused() {
        for id in [
            CanId::Standard(0),
            CanId::Standard(0x7FF),
            CanId::Extended(0x1FFF_FFFF),
        ] {
            assert_eq!(to_socketcan_id(id).map(from_socketcan_id), Some(id));
        }
        assert!(to_socketcan_id(CanId::Standard(0x800)).is_none());
        assert!(to_socketcan_id(CanId::Extended(0x2000_0000)).is_none());
        assert!(CanId::Standard(0x800)
            .validate("data")
            .is_err_and(|e| e.to_string().contains("data identifier 800")));
    }
}
