//! # acquire — run a vibration test stand and log everything to MCAP
//!
//! Commands a shaker controller, streams an accelerometer DAQ (force channel included), runs
//! excitation sweeps and records every byte, block and event in one MCAP session file. Devices sit
//! behind narrow object-safe traits — [`shaker::Shaker`], [`daq::Daq`], [`transport::Transport`] —
//! with real drivers (SCPI over serial, a COBS/CRC binary stream over serial) and a simulated stand
//! ([`sim`]) that serves the same protocols over pseudo-terminals.
//!
//! ```
//! use acquire::shaker::scpi::{parse_command, Command};
//! // The SCPI parser is I/O free: the simulated controller and firmware benches share it.
//! assert_eq!(parse_command("SOUR:FORC 4 kN").unwrap(), Command::SetForce(4000.0));
//! ```

pub mod can;
pub mod daq;
pub mod device;
pub mod rig;
pub mod session;
pub mod shaker;
pub mod sim;
pub mod stand;
pub mod sweep;
pub mod transport;
pub mod units;

pub use device::DeviceIdentity;
