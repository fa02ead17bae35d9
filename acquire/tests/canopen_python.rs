//! The independent check of ident's CANopen master: python-canopen (`canopen` on PyPI, a stack
//! nobody on this project wrote) plays the DAQ node — a `LocalNode` with the object dictionary of
//! `configs/canopen/ident-sim-daq.eds`, its own SDO server, NMT slave, heartbeat producer, EMCY
//! producer and PDO packing — and ident configures it over SDO, runs NMT, produces SYNC, receives
//! its TPDO stream, and detects its EMCY and its lost heartbeat.
//!
//! Here, on any host, the bus between the two stacks is a pipe to the python process
//! (tests/canopen/python_node.py): one frame per line in `cansend` notation, carried on the python
//! side by a python-can bus class and on this side by a [`CanLink`]. The same scenarios
//! (`python_node/mod.rs`) run over a real CAN interface, vcan0 in the test VM, in `vcan.rs`.
//!
//! Without python3 and the `canopen` package (`.ci/requirements.txt`) these tests fail: they never
//! pass without having run.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin};

use async_trait::async_trait;

mod python_node;

use acquire::can::{BusEvent, CanError, CanId, FrameKind, WireFrame};
use acquire::canopen::{CanLink, CanOpenDaq};

/// The python node's end of the pipe as a CAN link.
struct PipeLink {
    stdin: ChildStdin,
    rx: tokio::sync::mpsc::UnboundedReceiver<WireFrame>,
}

fn parse_cansend(line: &str) -> Option<WireFrame> {
    let (id, data) = line.trim().split_once('#')?;
    let raw = u32::from_str_radix(id, 16).ok()?;
    let id = if id.len() > 3 {
        CanId::Extended(raw)
    } else {
        CanId::Standard(u16::try_from(raw).ok()?)
    };
    let bytes: Option<Vec<u8>> = (0..data.len())
        .step_by(2)
        .map(|i| {
            data.get(i..i + 2)
                .and_then(|h| u8::from_str_radix(h, 16).ok())
        })
        .collect();
    Some(WireFrame::from_parts(id, FrameKind::Classic, &bytes?))
}

#[async_trait]
impl CanLink for PipeLink {
    fn interface(&self) -> &str {
        "python-canopen pipe"
    }
    async fn send(&mut self, frame: &WireFrame) -> Result<(), CanError> {
        let io = |source| CanError::Io {
            interface: "python-canopen pipe".into(),
            op: "send",
            source,
        };
        writeln!(self.stdin, "{}", frame.to_cansend()).map_err(io)?;
        self.stdin.flush().map_err(io)
    }
    async fn recv(&mut self) -> Result<BusEvent, CanError> {
        match self.rx.recv().await {
            Some(f) => Ok(BusEvent::Frame(f)),
            None => Err(CanError::Io {
                interface: "python-canopen pipe".into(),
                op: "receive",
                source: std::io::Error::from(std::io::ErrorKind::UnexpectedEof),
            }),
        }
    }
}

/// Starts python_node.py with `args`; returns the child and the link to it.
fn python_node(args: &[&str]) -> (Child, PipeLink) {
    let mut child = python_node::spawn(args);
    let stdout = child.stdout.take().expect("piped stdout");
    let stdin = child.stdin.take().expect("piped stdin");
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            match parse_cansend(&line) {
                Some(f) => {
                    if tx.send(f).is_err() {
                        break;
                    }
                }
                None => eprintln!("python node wrote a line that is not a frame: {line}"),
            }
        }
    });
    (child, PipeLink { stdin, rx })
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_canopen_node_is_identified_configured_over_sdo_and_streams_loss_free() {
    let (child, link) = python_node(&[]);
    let daq = CanOpenDaq::on_link(Box::new(link), python_node::settings()).expect("settings");
    python_node::identified_configured_over_sdo_and_streams_loss_free(child, daq).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_canopen_emcy_and_heartbeat_loss_are_detected() {
    let (child, link) = python_node(&["--emcy-at", "60", "8130", "--silent-after", "300"]);
    let daq = CanOpenDaq::on_link(Box::new(link), python_node::settings()).expect("settings");
    python_node::emcy_and_heartbeat_loss_are_detected(child, daq).await;
}
