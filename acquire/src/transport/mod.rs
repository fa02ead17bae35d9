//! Byte-stream transports (serial ports, pseudo-terminals, raw TCP sockets, USBTMC devices, in-memory pipes) behind one narrow
//! trait, plus a tap that copies every byte to the session log.

/// Implements [`Transport`], `AsyncRead` and `AsyncWrite` for a transport struct that holds its
/// port name in `name` and its byte stream in `inner`: every read and write goes to `inner`.
macro_rules! stream_transport {
    ($t:ty) => {
        impl $crate::transport::Transport for $t {
            fn port(&self) -> &str {
                &self.name
            }
        }

        impl tokio::io::AsyncRead for $t {
            fn poll_read(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
                buf: &mut tokio::io::ReadBuf<'_>,
            ) -> std::task::Poll<std::io::Result<()>> {
                std::pin::Pin::new(&mut self.inner).poll_read(cx, buf)
            }
        }

        impl tokio::io::AsyncWrite for $t {
            fn poll_write(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
                buf: &[u8],
            ) -> std::task::Poll<std::io::Result<usize>> {
                std::pin::Pin::new(&mut self.inner).poll_write(cx, buf)
            }
            fn poll_flush(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
            ) -> std::task::Poll<std::io::Result<()>> {
                std::pin::Pin::new(&mut self.inner).poll_flush(cx)
            }
            fn poll_shutdown(
                mut self: std::pin::Pin<&mut Self>,
                cx: &mut std::task::Context<'_>,
            ) -> std::task::Poll<std::io::Result<()>> {
                std::pin::Pin::new(&mut self.inner).poll_shutdown(cx)
            }
        }
    };
}

mod line;
mod serial;
mod tap;
mod tcp;
mod usbtmc;

pub use line::{Answer, Line, LineBuffer, LineLink, LinkError, LinkFailure, MAX_LINE};
pub use serial::{open_serial, pty_pair, PtyDevice, SerialSettings, SerialTransport};
pub use tap::{ByteTap, Direction, Tapped};
pub use tcp::{connect_tcp, SocketAddress, TcpTransport, SCPI_RAW_PORT};
pub use usbtmc::{open_usbtmc, UsbtmcTransport};

use tokio::io::{AsyncRead, AsyncWrite};

/// A bidirectional byte stream to one device.
///
/// Object safe: drivers hold a `Box<dyn Transport>` and do not care whether the bytes go over a
/// USB serial adapter, a pseudo-terminal served by the simulated stand, or an in-memory pipe.
pub trait Transport: AsyncRead + AsyncWrite + Send + Unpin {
    /// Where the bytes go, for messages and session records (`/dev/ttyUSB0`, `/dev/pts/7`, `mem:daq`).
    fn port(&self) -> &str;
}

impl Transport for Box<dyn Transport> {
    fn port(&self) -> &str {
        (**self).port()
    }
}

/// An in-memory transport (one end of a [`tokio::io::duplex`] pipe), for tests of drivers and
/// device simulators without any operating-system device.
pub struct MemoryTransport {
    name: String,
    inner: tokio::io::DuplexStream,
}

impl MemoryTransport {
    /// Two connected ends named `a` and `b`, buffering up to `capacity` bytes each way.
    pub fn pair(a: &str, b: &str, capacity: usize) -> (MemoryTransport, MemoryTransport) {
        let (x, y) = tokio::io::duplex(capacity);
        (
            MemoryTransport {
                name: format!("mem:{a}"),
                inner: x,
            },
            MemoryTransport {
                name: format!("mem:{b}"),
                inner: y,
            },
        )
    }
}

stream_transport!(MemoryTransport);

/// Why a transport could not be opened or used. Every variant names the port and says what to check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TransportError {
    /// The device path does not exist.
    #[error("serial port {port}: no such device; check the `port` in the stand file and that the adapter is plugged in (ls /dev/ttyUSB* /dev/ttyACM* /dev/serial/by-id/)")]
    NotFound {
        /// Port path as configured.
        port: String,
    },
    /// The operating system refused access.
    #[error("serial port {port}: permission denied; add your user to the `dialout` group (then log in again) or check the device node's mode")]
    PermissionDenied {
        /// Port path.
        port: String,
    },
    /// Another process holds the port (exclusive lock).
    #[error("serial port {port}: already in use by another program; close it (another `ident` run, minicom, screen; see `fuser {port}`)")]
    Busy {
        /// Port path.
        port: String,
    },
    /// The path exists but is not a terminal device.
    #[error(
        "serial port {port}: not a serial device ({detail}); check the `port` in the stand file"
    )]
    NotSerial {
        /// Port path.
        port: String,
        /// What the operating system said.
        detail: String,
    },
    /// Any other failure while opening or configuring the port.
    #[error("serial port {port}: cannot open: {detail}")]
    Open {
        /// Port path.
        port: String,
        /// What the operating system said.
        detail: String,
    },
    /// A network socket (raw SCPI over TCP) could not be connected or configured.
    #[error("instrument socket {port}: cannot connect: {detail}; check the address and port in the stand file, that the instrument is on and on the network (LAN settings: SCPI raw socket enabled, port 5025)")]
    Socket {
        /// `tcp:host:port`.
        port: String,
        /// What the operating system said.
        detail: String,
    },
    /// The `usbtmc` driver's device does not exist.
    #[error("USBTMC device {port}: no such device; check that the generator is connected by USB and switched on, that its USB interface is set to USBTMC (not a virtual serial port), that the kernel module is loaded (`modprobe usbtmc`), and the device number (ls /dev/usbtmc*)")]
    UsbtmcNotFound {
        /// `usbtmc:PATH`.
        port: String,
    },
    /// The operating system refused access to the `usbtmc` device.
    #[error("USBTMC device {port}: permission denied; install a udev rule such as `SUBSYSTEM==\"usbmisc\", KERNEL==\"usbtmc*\", GROUP=\"plugdev\", MODE=\"0660\"` (e.g. /etc/udev/rules.d/60-usbtmc.rules, then `udevadm control --reload` and re-plug), add your user to that group and log in again (docs/scpi-generator.md)")]
    UsbtmcPermission {
        /// `usbtmc:PATH`.
        port: String,
    },
    /// The path exists but is not the driver's character device.
    #[error("USBTMC device {port}: not a USBTMC device ({detail}); give the `usbtmc` driver's device, e.g. \"usbtmc:/dev/usbtmc0\"")]
    NotUsbtmc {
        /// `usbtmc:PATH`.
        port: String,
        /// What it is instead.
        detail: String,
    },
    /// Creating a pseudo-terminal pair failed.
    #[error("cannot create a pseudo-terminal for the simulated {role}: {detail}")]
    Pty {
        /// Which simulated device wanted it.
        role: String,
        /// What the operating system said.
        detail: String,
    },
}
