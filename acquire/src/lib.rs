//! # acquire — run a vibration test stand and log everything to MCAP
//!
//! Commands a shaker controller, streams an accelerometer DAQ (force channel included), runs
//! excitation sweeps and records every byte, block and event in one MCAP session file. Devices sit
//! behind narrow object-safe traits — [`shaker::Shaker`], [`daq::Daq`], [`transport::Transport`] —
//! with real drivers (SCPI over serial, a COBS/CRC binary stream over serial, CAN) and a simulated
//! stand ([`sim`]) that serves the same protocols over pseudo-terminals.
//!
//! Data flow: [`stand::Stand`] (stand file) → [`rig::Rig`] (devices opened, identified,
//! configured; every byte tapped into the [`session`]) → [`sweep`] (stepped sine with closed-loop
//! force control, broadband) → `session.mcap` (docs/mcap-session.md) → [`analysis`] (the
//! session's measured characteristics, recomputed from its raw blocks with the `process` crate).
//! Protocol specs: docs/shaker-scpi.md, docs/scpi-generator.md (a SCPI signal generator and
//! power amplifier, force loop closed by the host, [`generator`]), docs/daq-serial.md,
//! docs/daq-can.md, docs/canopen.md (the DAQ as a CANopen node, ident as master, [`canopen`]).
//!
//! ```
//! use acquire::shaker::scpi::{parse_command, Command};
//! use acquire::daq::frame::{FrameDecoder, Message};
//! // Parsers and decoders are I/O free: host drivers, simulators and firmware benches share them.
//! assert_eq!(parse_command("SOUR:FORC 4 kN").unwrap(), Command::SetForce(4000.0));
//! let mut wire = Vec::new();
//! Message::Start.encode(7, &mut Vec::new(), &mut Vec::new(), &mut wire);
//! let mut seen = Vec::new();
//! FrameDecoder::new().feed(&wire, |f| seen.push(f.map(|f| (f.kind, f.seq))));
//! assert_eq!(seen, vec![Ok((0x03, 7))]);
//! ```

// `expect` is linted here (not workspace-wide yet): nothing read from a file, a device or a
// user may panic; tests may expect (clippy.toml).
#![warn(clippy::expect_used)]

pub mod analysis;
pub mod can;
pub mod canopen;
pub mod daq;
pub mod device;
pub mod faults;
pub mod generator;
pub mod record;
pub mod replay;
pub mod rig;
pub mod scpi;
pub mod session;
pub mod shaker;
pub mod sim;
pub mod stand;
pub mod sweep;
pub mod transport;
pub mod wire;

pub use device::DeviceIdentity;
