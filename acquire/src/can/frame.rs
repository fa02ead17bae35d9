//! CAN frames as the codec and the bus see them: the identifier (standard or extended), the kind
//! (classic or FD) and up to 64 data bytes.

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
