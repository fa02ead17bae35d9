//! SDO (service data object) transfers of CiA 301 §7.2.4: the client ident runs against the
//! node's SDO server (requests on 0x600 + node id, answers on 0x580 + node id), expedited (≤ 4
//! bytes in the initiate frame) and segmented (7 bytes per segment, alternating toggle bit) in
//! both directions, with the abort codes of §7.2.4.3.17 as a typed [`AbortCode`].
//!
//! Frames that arrive while a transfer waits for its answer (heartbeats, EMCY, PDOs) are handed
//! to the caller's `other` sink, never dropped.

use std::time::Duration;

use crate::can::{BusEvent, CanError, FrameKind, WireFrame};
use crate::canopen::{cob, CanLink, SDO_RX_BASE, SDO_TX_BASE};

/// An SDO abort code (CiA 301 table 22), named where the standard names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum AbortCode {
    /// 0x05030000: toggle bit not alternated.
    ToggleNotAlternated,
    /// 0x05040000: SDO protocol timed out.
    Timeout,
    /// 0x05040001: client/server command specifier not valid or unknown.
    UnknownCommand,
    /// 0x06010000: unsupported access to an object.
    UnsupportedAccess,
    /// 0x06010001: attempt to read a write-only object.
    WriteOnly,
    /// 0x06010002: attempt to write a read-only object.
    ReadOnly,
    /// 0x06020000: object does not exist in the object dictionary.
    NoObject,
    /// 0x06040041: object cannot be mapped to the PDO.
    NotMappable,
    /// 0x06040042: the mapped objects would exceed the PDO length.
    PdoTooLong,
    /// 0x06070010: data type does not match, length of service parameter does not match.
    LengthMismatch,
    /// 0x06090011: sub-index does not exist.
    NoSubIndex,
    /// 0x06090030: invalid value for parameter.
    InvalidValue,
    /// 0x06090031: value of parameter written too high.
    ValueTooHigh,
    /// 0x06090032: value of parameter written too low.
    ValueTooLow,
    /// 0x08000000: general error.
    General,
    /// 0x08000020: data cannot be transferred or stored to the application.
    CannotStore,
    /// 0x08000022: data cannot be transferred or stored because of the present device state.
    DeviceState,
    /// Any other code.
    Other(u32),
}

const CODES: [(AbortCode, u32, &str); 17] = [
    (
        AbortCode::ToggleNotAlternated,
        0x0503_0000,
        "toggle bit not alternated",
    ),
    (AbortCode::Timeout, 0x0504_0000, "SDO protocol timed out"),
    (
        AbortCode::UnknownCommand,
        0x0504_0001,
        "command specifier not valid or unknown",
    ),
    (
        AbortCode::UnsupportedAccess,
        0x0601_0000,
        "unsupported access to an object",
    ),
    (
        AbortCode::WriteOnly,
        0x0601_0001,
        "attempt to read a write-only object",
    ),
    (
        AbortCode::ReadOnly,
        0x0601_0002,
        "attempt to write a read-only object",
    ),
    (
        AbortCode::NoObject,
        0x0602_0000,
        "object does not exist in the object dictionary",
    ),
    (
        AbortCode::NotMappable,
        0x0604_0041,
        "object cannot be mapped to the PDO",
    ),
    (
        AbortCode::PdoTooLong,
        0x0604_0042,
        "the mapped objects would exceed the PDO length",
    ),
    (
        AbortCode::LengthMismatch,
        0x0607_0010,
        "data type does not match, length of service parameter does not match",
    ),
    (
        AbortCode::NoSubIndex,
        0x0609_0011,
        "sub-index does not exist",
    ),
    (
        AbortCode::InvalidValue,
        0x0609_0030,
        "invalid value for parameter",
    ),
    (
        AbortCode::ValueTooHigh,
        0x0609_0031,
        "value of parameter written too high",
    ),
    (
        AbortCode::ValueTooLow,
        0x0609_0032,
        "value of parameter written too low",
    ),
    (AbortCode::General, 0x0800_0000, "general error"),
    (
        AbortCode::CannotStore,
        0x0800_0020,
        "data cannot be transferred or stored to the application",
    ),
    (
        AbortCode::DeviceState,
        0x0800_0022,
        "data cannot be transferred or stored because of the present device state",
    ),
];

impl AbortCode {
    /// The code of the 32-bit value on the wire.
    pub fn from_u32(code: u32) -> AbortCode {
        CODES
            .iter()
            .find(|(_, c, _)| *c == code)
            .map_or(AbortCode::Other(code), |(a, _, _)| *a)
    }

    /// The 32-bit value on the wire.
    pub fn code(self) -> u32 {
        match self {
            AbortCode::Other(c) => c,
            a => CODES
                .iter()
                .find(|(x, _, _)| *x == a)
                .map_or(0, |(_, c, _)| *c),
        }
    }

    /// What the standard says it means.
    pub fn meaning(self) -> &'static str {
        CODES.iter().find(|(x, _, _)| *x == self).map_or(
            "code not defined by CiA 301 (see the device manual)",
            |(_, _, m)| m,
        )
    }
}

impl std::fmt::Display for AbortCode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "0x{:08X} ({})", self.code(), self.meaning())
    }
}

/// An object dictionary address: index and sub-index.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize,
)]
pub struct Address {
    /// Index (0x1000–0xFFFF).
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
}

impl Address {
    /// `index:sub`.
    pub fn new(index: u16, sub: u8) -> Address {
        Address { index, sub }
    }

    fn mux(self) -> [u8; 3] {
        let i = self.index.to_le_bytes();
        [i[0], i[1], self.sub]
    }

    fn from_mux(d: &[u8]) -> Address {
        Address {
            index: u16::from_le_bytes([d[1], d[2]]),
            sub: d[3],
        }
    }
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "0x{:04X}:{:02X}", self.index, self.sub)
    }
}

/// Why an SDO transfer failed. Each names the node, the object and whether it was a read or a
/// write.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SdoError {
    /// The server (or ident, on a protocol error) aborted the transfer.
    #[error("node {node}: SDO {op} of {address} aborted by the {by}: {code}")]
    Abort {
        /// Node id.
        node: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Object.
        address: Address,
        /// The abort code.
        code: AbortCode,
        /// `node` or `client` (ident aborted after a protocol error).
        by: &'static str,
    },
    /// No answer in time.
    #[error("node {node}: no SDO answer to the {op} of {address} within {waited:?}; check the node id (the node answers on 0x{:03X}), the bit rate, and that the node is powered and not stopped", SDO_TX_BASE + *node as u16)]
    Timeout {
        /// Node id.
        node: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Object.
        address: Address,
        /// How long ident waited.
        waited: Duration,
    },
    /// A segment came back with the wrong toggle bit (ident aborted with 0x05030000).
    #[error("node {node}: SDO {op} of {address}: segment {segment} has the wrong toggle bit; transfer aborted (0x05030000)")]
    Toggle {
        /// Node id.
        node: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Object.
        address: Address,
        /// Segment number (0-based).
        segment: usize,
    },
    /// An answer that is not the protocol (wrong command specifier, wrong object, wrong size).
    #[error(
        "node {node}: SDO {op} of {address}: malformed answer {frame}: {detail}; transfer aborted"
    )]
    Malformed {
        /// Node id.
        node: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Object.
        address: Address,
        /// The frame, `cansend` notation.
        frame: String,
        /// What is wrong with it.
        detail: String,
    },
    /// The bus failed.
    #[error("node {node}: SDO {op} of {address}: {source}")]
    Bus {
        /// Node id.
        node: u8,
        /// `read` or `write`.
        op: &'static str,
        /// Object.
        address: Address,
        /// The bus error.
        source: CanError,
    },
}

/// Command specifiers and flags of the SDO protocol.
pub mod cs {
    /// Client: initiate download (write).
    pub const INITIATE_DOWNLOAD: u8 = 0x20;
    /// Client: initiate upload (read).
    pub const INITIATE_UPLOAD: u8 = 0x40;
    /// Client: upload segment request.
    pub const UPLOAD_SEGMENT: u8 = 0x60;
    /// Client: download segment (ccs 0).
    pub const DOWNLOAD_SEGMENT: u8 = 0x00;
    /// Server: initiate download response.
    pub const DOWNLOAD_RESPONSE: u8 = 0x60;
    /// Server: download segment response (scs 1).
    pub const SEGMENT_DOWNLOAD_RESPONSE: u8 = 0x20;
    /// Either side: abort.
    pub const ABORT: u8 = 0x80;
    /// Expedited flag (e).
    pub const EXPEDITED: u8 = 0x02;
    /// Size indicated flag (s).
    pub const SIZE: u8 = 0x01;
    /// Toggle bit in segment frames.
    pub const TOGGLE: u8 = 0x10;
    /// Last segment flag (c).
    pub const LAST: u8 = 0x01;
}

/// An abort frame for `address` with `code`, as either side sends it.
pub fn abort_frame(id: crate::can::CanId, address: Address, code: AbortCode) -> WireFrame {
    let m = address.mux();
    let c = code.code().to_le_bytes();
    WireFrame::from_parts(
        id,
        FrameKind::Classic,
        &[cs::ABORT, m[0], m[1], m[2], c[0], c[1], c[2], c[3]],
    )
}

/// The SDO client of one node.
#[derive(Debug, Clone, Copy)]
pub struct SdoClient {
    /// Node id (1–127).
    pub node: u8,
    /// Longest wait for each answer.
    pub timeout: Duration,
}

struct Transfer<'a> {
    link: &'a mut dyn CanLink,
    other: &'a mut (dyn FnMut(BusEvent) + Send),
    node: u8,
    op: &'static str,
    address: Address,
    timeout: Duration,
}

impl Transfer<'_> {
    /// Aborts the transfer (unknown command specifier) and returns the error for an answer `f`
    /// that is not the `expected` kind.
    async fn unexpected(&mut self, f: &[u8; 8], expected: &str) -> SdoError {
        self.abort(AbortCode::UnknownCommand).await;
        self.malformed(
            f,
            format!("command specifier 0x{:02X}, expected {expected}", f[0]),
        )
    }

    /// Aborts the transfer (toggle bit not alternated) and returns the error for segment
    /// `segment`, whose toggle bit is wrong.
    async fn toggle_error(&mut self, segment: usize) -> SdoError {
        self.abort(AbortCode::ToggleNotAlternated).await;
        SdoError::Toggle {
            node: self.node,
            op: self.op,
            address: self.address,
            segment,
        }
    }

    fn malformed(&self, f: &[u8; 8], detail: impl Into<String>) -> SdoError {
        SdoError::Malformed {
            node: self.node,
            op: self.op,
            address: self.address,
            frame: WireFrame::from_parts(cob(SDO_TX_BASE, self.node), FrameKind::Classic, f)
                .to_cansend(),
            detail: detail.into(),
        }
    }

    fn bus(&self, source: CanError) -> SdoError {
        SdoError::Bus {
            node: self.node,
            op: self.op,
            address: self.address,
            source,
        }
    }

    /// Tells the server the transfer is over (best effort: the error that caused it wins).
    async fn abort(&mut self, code: AbortCode) {
        let f = abort_frame(cob(SDO_RX_BASE, self.node), self.address, code);
        let _ = self.link.send(&f).await;
    }

    /// Sends `req` and waits for the server's answer; an abort from the server is an error.
    async fn exchange(&mut self, req: [u8; 8]) -> Result<[u8; 8], SdoError> {
        let f = WireFrame::from_parts(cob(SDO_RX_BASE, self.node), FrameKind::Classic, &req);
        self.link.send(&f).await.map_err(|e| self.bus(e))?;
        let answer_id = cob(SDO_TX_BASE, self.node);
        let deadline = tokio::time::Instant::now() + self.timeout;
        loop {
            let ev = match tokio::time::timeout_at(deadline, self.link.recv()).await {
                Err(_) => {
                    self.abort(AbortCode::Timeout).await;
                    return Err(SdoError::Timeout {
                        node: self.node,
                        op: self.op,
                        address: self.address,
                        waited: self.timeout,
                    });
                }
                Ok(r) => r.map_err(|e| self.bus(e))?,
            };
            match ev {
                BusEvent::Frame(f) if f.id() == answer_id => {
                    let mut d = [0u8; 8];
                    if f.data().len() != 8 {
                        d[..f.data().len()].copy_from_slice(f.data());
                        self.abort(AbortCode::General).await;
                        return Err(self.malformed(
                            &d,
                            format!("{} data bytes, SDO frames have 8", f.data().len()),
                        ));
                    }
                    d.copy_from_slice(f.data());
                    if d[0] == cs::ABORT {
                        let address = Address::from_mux(&d);
                        if address != self.address {
                            return Err(self.malformed(
                                &d,
                                format!("abort for {address}, not for the object in transfer"),
                            ));
                        }
                        return Err(SdoError::Abort {
                            node: self.node,
                            op: self.op,
                            address,
                            code: AbortCode::from_u32(u32::from_le_bytes([d[4], d[5], d[6], d[7]])),
                            by: "node",
                        });
                    }
                    return Ok(d);
                }
                other => (self.other)(other),
            }
        }
    }

    fn check_mux(&self, d: &[u8; 8]) -> Result<(), SdoError> {
        let a = Address::from_mux(d);
        if a != self.address {
            return Err(self.malformed(d, format!("answer is for {a}")));
        }
        Ok(())
    }

    async fn upload(&mut self) -> Result<Vec<u8>, SdoError> {
        let m = self.address.mux();
        let d = self
            .exchange([cs::INITIATE_UPLOAD, m[0], m[1], m[2], 0, 0, 0, 0])
            .await?;
        if d[0] & 0xE0 != 0x40 {
            return Err(self
                .unexpected(&d, "an initiate upload response (0x4_)")
                .await);
        }
        if let Err(e) = self.check_mux(&d) {
            self.abort(AbortCode::General).await;
            return Err(e);
        }
        if d[0] & cs::EXPEDITED != 0 {
            let n = if d[0] & cs::SIZE != 0 {
                4 - ((d[0] >> 2) & 3) as usize
            } else {
                4
            };
            return Ok(d[4..4 + n].to_vec());
        }
        let size =
            (d[0] & cs::SIZE != 0).then(|| u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize);
        let mut data = Vec::with_capacity(size.unwrap_or(0).min(1 << 16));
        let mut toggle = 0u8;
        for segment in 0.. {
            let s = self
                .exchange([cs::UPLOAD_SEGMENT | toggle, 0, 0, 0, 0, 0, 0, 0])
                .await?;
            if s[0] & 0xE0 != 0x00 {
                return Err(self.unexpected(&s, "an upload segment (0x0_/0x1_)").await);
            }
            if s[0] & cs::TOGGLE != toggle {
                return Err(self.toggle_error(segment).await);
            }
            let n = 7 - ((s[0] >> 1) & 7) as usize;
            data.extend_from_slice(&s[1..1 + n]);
            if s[0] & cs::LAST != 0 {
                break;
            }
            if size.is_some_and(|z| data.len() > z) || data.len() > 1 << 24 {
                self.abort(AbortCode::LengthMismatch).await;
                return Err(
                    self.malformed(&s, format!("more data than the {size:?} bytes announced"))
                );
            }
            toggle ^= cs::TOGGLE;
        }
        if let Some(z) = size {
            if z != data.len() {
                return Err(SdoError::Malformed {
                    node: self.node,
                    op: self.op,
                    address: self.address,
                    frame: String::new(),
                    detail: format!("{z} bytes announced, {} received", data.len()),
                });
            }
        }
        Ok(data)
    }

    async fn download(&mut self, value: &[u8]) -> Result<(), SdoError> {
        let m = self.address.mux();
        if value.len() <= 4 {
            let mut req = [
                cs::INITIATE_DOWNLOAD | cs::EXPEDITED | cs::SIZE | (((4 - value.len()) as u8) << 2),
                m[0],
                m[1],
                m[2],
                0,
                0,
                0,
                0,
            ];
            req[4..4 + value.len()].copy_from_slice(value);
            let d = self.exchange(req).await?;
            return self.download_response(&d).await;
        }
        let len = u32::try_from(value.len()).map_err(|_| SdoError::Malformed {
            node: self.node,
            op: self.op,
            address: self.address,
            frame: String::new(),
            detail: format!("{} bytes is more than an SDO transfer carries", value.len()),
        })?;
        let z = len.to_le_bytes();
        let d = self
            .exchange([
                cs::INITIATE_DOWNLOAD | cs::SIZE,
                m[0],
                m[1],
                m[2],
                z[0],
                z[1],
                z[2],
                z[3],
            ])
            .await?;
        self.download_response(&d).await?;
        let mut toggle = 0u8;
        let chunks: Vec<&[u8]> = value.chunks(7).collect();
        for (segment, chunk) in chunks.iter().enumerate() {
            let last = segment + 1 == chunks.len();
            let mut req = [
                cs::DOWNLOAD_SEGMENT
                    | toggle
                    | (((7 - chunk.len()) as u8) << 1)
                    | if last { cs::LAST } else { 0 },
                0,
                0,
                0,
                0,
                0,
                0,
                0,
            ];
            req[1..1 + chunk.len()].copy_from_slice(chunk);
            let s = self.exchange(req).await?;
            if s[0] & 0xE0 != cs::SEGMENT_DOWNLOAD_RESPONSE {
                return Err(self
                    .unexpected(&s, "a download segment response (0x20/0x30)")
                    .await);
            }
            if s[0] & cs::TOGGLE != toggle {
                return Err(self.toggle_error(segment).await);
            }
            toggle ^= cs::TOGGLE;
        }
        Ok(())
    }

    async fn download_response(&mut self, d: &[u8; 8]) -> Result<(), SdoError> {
        if d[0] != cs::DOWNLOAD_RESPONSE {
            return Err(self
                .unexpected(d, "an initiate download response (0x60)")
                .await);
        }
        if let Err(e) = self.check_mux(d) {
            self.abort(AbortCode::General).await;
            return Err(e);
        }
        Ok(())
    }
}

impl SdoClient {
    /// Reads `address` (expedited or segmented, as the server chooses). Frames of other services
    /// that arrive meanwhile go to `other`.
    pub async fn upload(
        &self,
        link: &mut dyn CanLink,
        address: Address,
        other: &mut (dyn FnMut(BusEvent) + Send),
    ) -> Result<Vec<u8>, SdoError> {
        Transfer {
            link,
            other,
            node: self.node,
            op: "read",
            address,
            timeout: self.timeout,
        }
        .upload()
        .await
    }

    /// Writes `value` to `address`: expedited up to 4 bytes, segmented beyond. Frames of other
    /// services that arrive meanwhile go to `other`.
    pub async fn download(
        &self,
        link: &mut dyn CanLink,
        address: Address,
        value: &[u8],
        other: &mut (dyn FnMut(BusEvent) + Send),
    ) -> Result<(), SdoError> {
        Transfer {
            link,
            other,
            node: self.node,
            op: "write",
            address,
            timeout: self.timeout,
        }
        .download(value)
        .await
    }
}

/// The server side of the SDO protocol, I/O free: feed it the client's frames, send what it
/// returns. Used by the simulated node.
#[derive(Debug, Default)]
pub struct SdoServer {
    state: ServerState,
}

#[derive(Debug, Default)]
enum ServerState {
    #[default]
    Idle,
    Uploading {
        address: Address,
        data: Vec<u8>,
        pos: usize,
        toggle: u8,
    },
    Downloading {
        address: Address,
        size: Option<usize>,
        data: Vec<u8>,
        toggle: u8,
    },
}

/// What the server's object dictionary does for it.
pub trait ServerDictionary {
    /// The value of `address`, or the abort code that refuses the read.
    fn read(&mut self, address: Address) -> Result<Vec<u8>, AbortCode>;
    /// Stores `value` at `address`, or the abort code that refuses the write.
    fn write(&mut self, address: Address, value: &[u8]) -> Result<(), AbortCode>;
}

impl SdoServer {
    /// Handles one client request (8 data bytes); returns the answer's 8 data bytes, or `None`
    /// when the request was an abort (no answer).
    pub fn handle(&mut self, req: &[u8], od: &mut dyn ServerDictionary) -> Option<[u8; 8]> {
        let mut d = [0u8; 8];
        let n = req.len().min(8);
        d[..n].copy_from_slice(&req[..n]);
        let abort = |a: Address, code: AbortCode| {
            let m = a.mux();
            let c = code.code().to_le_bytes();
            [cs::ABORT, m[0], m[1], m[2], c[0], c[1], c[2], c[3]]
        };
        if req.len() != 8 {
            self.state = ServerState::Idle;
            return Some(abort(Address::from_mux(&d), AbortCode::UnknownCommand));
        }
        let ccs = d[0] & 0xE0;
        match (ccs, std::mem::take(&mut self.state)) {
            (cs::ABORT, _) => None,
            (cs::INITIATE_UPLOAD, _) => {
                let a = Address::from_mux(&d);
                let m = a.mux();
                match od.read(a) {
                    Err(code) => Some(abort(a, code)),
                    Ok(v) if v.len() <= 4 => {
                        let mut r = [
                            0x40 | cs::EXPEDITED | cs::SIZE | (((4 - v.len()) as u8) << 2),
                            m[0],
                            m[1],
                            m[2],
                            0,
                            0,
                            0,
                            0,
                        ];
                        r[4..4 + v.len()].copy_from_slice(&v);
                        Some(r)
                    }
                    Ok(v) => {
                        let z = (v.len() as u32).to_le_bytes();
                        self.state = ServerState::Uploading {
                            address: a,
                            data: v,
                            pos: 0,
                            toggle: 0,
                        };
                        Some([0x40 | cs::SIZE, m[0], m[1], m[2], z[0], z[1], z[2], z[3]])
                    }
                }
            }
            (
                cs::UPLOAD_SEGMENT,
                ServerState::Uploading {
                    address,
                    data,
                    pos,
                    toggle,
                },
            ) => {
                if d[0] & cs::TOGGLE != toggle {
                    return Some(abort(address, AbortCode::ToggleNotAlternated));
                }
                let end = (pos + 7).min(data.len());
                let chunk = &data[pos..end];
                let last = end == data.len();
                let mut r = [
                    toggle | (((7 - chunk.len()) as u8) << 1) | if last { cs::LAST } else { 0 },
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                ];
                r[1..1 + chunk.len()].copy_from_slice(chunk);
                if !last {
                    self.state = ServerState::Uploading {
                        address,
                        data,
                        pos: end,
                        toggle: toggle ^ cs::TOGGLE,
                    };
                }
                Some(r)
            }
            (cs::INITIATE_DOWNLOAD, _) => {
                let a = Address::from_mux(&d);
                let m = a.mux();
                if d[0] & cs::EXPEDITED != 0 {
                    let n = if d[0] & cs::SIZE != 0 {
                        4 - ((d[0] >> 2) & 3) as usize
                    } else {
                        4
                    };
                    return Some(match od.write(a, &d[4..4 + n]) {
                        Ok(()) => [cs::DOWNLOAD_RESPONSE, m[0], m[1], m[2], 0, 0, 0, 0],
                        Err(code) => abort(a, code),
                    });
                }
                let size = (d[0] & cs::SIZE != 0)
                    .then(|| u32::from_le_bytes([d[4], d[5], d[6], d[7]]) as usize);
                self.state = ServerState::Downloading {
                    address: a,
                    size,
                    data: Vec::new(),
                    toggle: 0,
                };
                Some([cs::DOWNLOAD_RESPONSE, m[0], m[1], m[2], 0, 0, 0, 0])
            }
            (
                cs::DOWNLOAD_SEGMENT,
                ServerState::Downloading {
                    address,
                    size,
                    mut data,
                    toggle,
                },
            ) => {
                if d[0] & cs::TOGGLE != toggle {
                    return Some(abort(address, AbortCode::ToggleNotAlternated));
                }
                let n = 7 - ((d[0] >> 1) & 7) as usize;
                data.extend_from_slice(&d[1..1 + n]);
                let r = [cs::SEGMENT_DOWNLOAD_RESPONSE | toggle, 0, 0, 0, 0, 0, 0, 0];
                if d[0] & cs::LAST == 0 {
                    self.state = ServerState::Downloading {
                        address,
                        size,
                        data,
                        toggle: toggle ^ cs::TOGGLE,
                    };
                    return Some(r);
                }
                if size.is_some_and(|z| z != data.len()) {
                    return Some(abort(address, AbortCode::LengthMismatch));
                }
                Some(match od.write(address, &data) {
                    Ok(()) => r,
                    Err(code) => abort(address, code),
                })
            }
            (_, _) => Some(abort(Address::from_mux(&d), AbortCode::UnknownCommand)),
        }
    }
}
