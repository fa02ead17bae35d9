//! The node's electronic data sheet (EDS, CiA 306) or device configuration file (DCF): an INI
//! file with one section per object (`[1018]`) and sub-object (`[1018sub1]`), read into an
//! [`ObjectDictionary`] of the entries' names, data types, access and default (or, in a DCF,
//! parameter) values. `$NODEID` in a value is replaced by the node id.

use std::collections::BTreeMap;

use crate::canopen::sdo::Address;

/// A CiA 301 data type (the EDS `DataType` code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum DataType {
    /// 0x0001.
    Boolean,
    /// 0x0002.
    Integer8,
    /// 0x0003.
    Integer16,
    /// 0x0004.
    Integer32,
    /// 0x0005.
    Unsigned8,
    /// 0x0006.
    Unsigned16,
    /// 0x0007.
    Unsigned32,
    /// 0x0008.
    Real32,
    /// 0x0009.
    VisibleString,
    /// 0x000A.
    OctetString,
    /// 0x000F.
    Domain,
    /// 0x0011.
    Real64,
    /// 0x0015.
    Integer64,
    /// 0x001B.
    Unsigned64,
}

impl DataType {
    /// The type of an EDS code.
    pub fn from_code(code: u16) -> Option<DataType> {
        Some(match code {
            0x01 => DataType::Boolean,
            0x02 => DataType::Integer8,
            0x03 => DataType::Integer16,
            0x04 => DataType::Integer32,
            0x05 => DataType::Unsigned8,
            0x06 => DataType::Unsigned16,
            0x07 => DataType::Unsigned32,
            0x08 => DataType::Real32,
            0x09 => DataType::VisibleString,
            0x0A => DataType::OctetString,
            0x0F => DataType::Domain,
            0x11 => DataType::Real64,
            0x15 => DataType::Integer64,
            0x1B => DataType::Unsigned64,
            _ => return None,
        })
    }

    /// Size in bytes of a fixed-size type (`None` for strings and domains).
    pub fn size(self) -> Option<usize> {
        Some(match self {
            DataType::Boolean | DataType::Integer8 | DataType::Unsigned8 => 1,
            DataType::Integer16 | DataType::Unsigned16 => 2,
            DataType::Integer32 | DataType::Unsigned32 | DataType::Real32 => 4,
            DataType::Real64 | DataType::Integer64 | DataType::Unsigned64 => 8,
            DataType::VisibleString | DataType::OctetString | DataType::Domain => return None,
        })
    }

    /// The little-endian bytes of a value written as in an EDS (`0x1A`, `-3`, `2.5e-4`, text).
    pub fn encode(self, text: &str) -> Result<Vec<u8>, EncodeError> {
        let t = text.trim();
        let int = || -> Result<i128, EncodeError> {
            let (neg, body) = match t.strip_prefix('-') {
                Some(b) => (true, b),
                None => (false, t),
            };
            let v = match body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
                Some(h) => i128::from_str_radix(h, 16),
                None => body.parse::<i128>(),
            }
            .map_err(|e| EncodeError::NotInteger {
                text: t.to_string(),
                detail: e.to_string(),
            })?;
            Ok(if neg { -v } else { v })
        };
        let fit = |v: i128, lo: i128, hi: i128| {
            if (lo..=hi).contains(&v) {
                Ok(v)
            } else {
                Err(EncodeError::DoesNotFit {
                    value: v,
                    data_type: self,
                })
            }
        };
        Ok(match self {
            DataType::Boolean | DataType::Unsigned8 => vec![fit(int()?, 0, 0xFF)? as u8],
            DataType::Integer8 => (fit(int()?, -128, 127)? as i8).to_le_bytes().to_vec(),
            DataType::Integer16 => (fit(int()?, i16::MIN as i128, i16::MAX as i128)? as i16)
                .to_le_bytes()
                .to_vec(),
            DataType::Unsigned16 => (fit(int()?, 0, 0xFFFF)? as u16).to_le_bytes().to_vec(),
            DataType::Integer32 => (fit(int()?, i32::MIN as i128, i32::MAX as i128)? as i32)
                .to_le_bytes()
                .to_vec(),
            DataType::Unsigned32 => (fit(int()?, 0, u32::MAX as i128)? as u32)
                .to_le_bytes()
                .to_vec(),
            DataType::Integer64 => (fit(int()?, i64::MIN as i128, i64::MAX as i128)? as i64)
                .to_le_bytes()
                .to_vec(),
            DataType::Unsigned64 => (fit(int()?, 0, u64::MAX as i128)? as u64)
                .to_le_bytes()
                .to_vec(),
            DataType::Real32 => t
                .parse::<f32>()
                .map_err(|e| EncodeError::NotNumber {
                    text: t.to_string(),
                    detail: e.to_string(),
                })?
                .to_le_bytes()
                .to_vec(),
            DataType::Real64 => t
                .parse::<f64>()
                .map_err(|e| EncodeError::NotNumber {
                    text: t.to_string(),
                    detail: e.to_string(),
                })?
                .to_le_bytes()
                .to_vec(),
            DataType::VisibleString | DataType::OctetString | DataType::Domain => {
                t.as_bytes().to_vec()
            }
        })
    }
}

/// A value written as in an EDS that its data type cannot hold.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// Not an integer (decimal or `0x` hexadecimal).
    #[error("`{text}` is not an integer: {detail}")]
    NotInteger {
        /// The text.
        text: String,
        /// What the parser said.
        detail: String,
    },
    /// Outside the type's range.
    #[error("{value} does not fit {data_type:?}")]
    DoesNotFit {
        /// The value.
        value: i128,
        /// The type.
        data_type: DataType,
    },
    /// Not a floating-point number.
    #[error("`{text}` is not a number: {detail}")]
    NotNumber {
        /// The text.
        text: String,
        /// What the parser said.
        detail: String,
    },
}

/// Read/write access of an entry (`AccessType`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// `ro` or `const`.
    ReadOnly,
    /// `wo`.
    WriteOnly,
    /// `rw`, `rwr`, `rww`.
    ReadWrite,
}

impl Access {
    /// Whether the master may read it.
    pub fn readable(self) -> bool {
        self != Access::WriteOnly
    }
    /// Whether the master may write it.
    pub fn writable(self) -> bool {
        self != Access::ReadOnly
    }
}

/// One readable/writable entry (a VAR object or one sub-index of an array or record).
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// `ParameterName`.
    pub name: String,
    /// `DataType`.
    pub data_type: DataType,
    /// `AccessType`.
    pub access: Access,
    /// `ParameterValue` (DCF) or `DefaultValue`, `$NODEID` replaced; `None` if absent.
    pub value: Option<String>,
    /// `PDOMapping=1`.
    pub pdo_mappable: bool,
}

/// The object dictionary an EDS or DCF describes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ObjectDictionary {
    /// `[DeviceInfo] VendorName`.
    pub vendor: String,
    /// `[DeviceInfo] ProductName`.
    pub product: String,
    /// Entries by address.
    pub entries: BTreeMap<Address, Entry>,
}

/// Why an EDS could not be read: the file, line and what to fix.
#[derive(Debug, thiserror::Error)]
#[error("EDS {file}:{line}: {detail}")]
pub struct EdsError {
    /// File name (as given).
    pub file: String,
    /// 1-based line (0: the whole file).
    pub line: usize,
    /// What is wrong.
    pub detail: String,
}

impl ObjectDictionary {
    /// Reads an EDS/DCF file for node `node_id`.
    pub fn load(path: &std::path::Path, node_id: u8) -> Result<ObjectDictionary, EdsError> {
        let text = std::fs::read_to_string(path).map_err(|e| EdsError {
            file: path.display().to_string(),
            line: 0,
            detail: format!("cannot read it: {e}; check the stand file's `eds` path (relative to the stand file)"),
        })?;
        ObjectDictionary::parse(&text, &path.display().to_string(), node_id)
    }

    /// Parses EDS/DCF text; `file` names it in errors.
    pub fn parse(text: &str, file: &str, node_id: u8) -> Result<ObjectDictionary, EdsError> {
        let err = |line: usize, detail: String| EdsError {
            file: file.to_string(),
            line,
            detail,
        };
        // Sections in order, each with its key → (value, line).
        let mut sections: Vec<Section> = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.trim();
            if line.is_empty() || line.starts_with(';') || line.starts_with('#') {
                continue;
            }
            if let Some(rest) = line.strip_prefix('[') {
                let name = rest.strip_suffix(']').ok_or_else(|| {
                    err(i + 1, format!("section header `{line}` has no closing `]`"))
                })?;
                sections.push((name.trim().to_ascii_lowercase(), i + 1, BTreeMap::new()));
                continue;
            }
            let (k, v) = line.split_once('=').ok_or_else(|| {
                err(
                    i + 1,
                    format!("`{line}` is neither `[section]` nor `key=value`"),
                )
            })?;
            let Some(sec) = sections.last_mut() else {
                return Err(err(
                    i + 1,
                    format!("`{line}` comes before the first [section]"),
                ));
            };
            sec.2
                .insert(k.trim().to_ascii_lowercase(), (v.trim().to_string(), i + 1));
        }
        let mut od = ObjectDictionary::default();
        let node = node_id.to_string();
        for (name, line, keys) in &sections {
            if name == "deviceinfo" {
                od.vendor = keys
                    .get("vendorname")
                    .map(|v| v.0.clone())
                    .unwrap_or_default();
                od.product = keys
                    .get("productname")
                    .map(|v| v.0.clone())
                    .unwrap_or_default();
                continue;
            }
            let (idx, sub) = match name.split_once("sub") {
                Some((i, s)) => (i, Some(s)),
                None => (name.as_str(), None),
            };
            if idx.len() != 4 || !idx.bytes().all(|b| b.is_ascii_hexdigit()) {
                continue; // [FileInfo], [MandatoryObjects], [Comments], …
            }
            let index = u16::from_str_radix(idx, 16)
                .map_err(|e| err(*line, format!("section [{name}]: {e}")))?;
            let sub = match sub {
                Some(s) => u8::from_str_radix(s, 16)
                    .map_err(|e| err(*line, format!("section [{name}]: sub-index `{s}`: {e}")))?,
                None => 0,
            };
            let Some((dt, dt_line)) = keys.get("datatype") else {
                continue; // an ARRAY/RECORD header: its entries are the sub sections
            };
            let code = parse_u32(dt)
                .ok_or_else(|| err(*dt_line, format!("DataType `{dt}` is not a number")))?;
            let data_type = u16::try_from(code)
                .ok()
                .and_then(DataType::from_code)
                .ok_or_else(|| {
                    err(
                        *dt_line,
                        format!("DataType 0x{code:04X} is not supported (basic types only)"),
                    )
                })?;
            let access = match keys
                .get("accesstype")
                .map(|v| v.0.to_ascii_lowercase())
                .as_deref()
            {
                Some("ro") | Some("const") => Access::ReadOnly,
                Some("wo") => Access::WriteOnly,
                Some("rw") | Some("rwr") | Some("rww") => Access::ReadWrite,
                Some(other) => {
                    return Err(err(
                        *line,
                        format!(
                            "[{name}] AccessType `{other}`: write ro, wo, rw, rwr, rww or const"
                        ),
                    ))
                }
                None => return Err(err(*line, format!("[{name}] has no AccessType"))),
            };
            let value = keys
                .get("parametervalue")
                .or_else(|| keys.get("defaultvalue"))
                .map(|(v, _)| substitute_node_id(v, &node));
            if let (Some(v), Some((_, l))) = (&value, keys.get("defaultvalue")) {
                data_type
                    .encode(v)
                    .map_err(|e| err(*l, format!("[{name}] value: {e}")))?;
            }
            od.entries.insert(
                Address::new(index, sub),
                Entry {
                    name: keys
                        .get("parametername")
                        .map(|v| v.0.clone())
                        .unwrap_or_default(),
                    data_type,
                    access,
                    value,
                    pdo_mappable: keys.get("pdomapping").is_some_and(|v| v.0 == "1"),
                },
            );
        }
        if od.entries.is_empty() {
            return Err(err(
                0,
                "no object dictionary entries ([1000], [1018sub1], …): is this an EDS file?".into(),
            ));
        }
        Ok(od)
    }

    /// The entry at `address`.
    pub fn get(&self, address: Address) -> Option<&Entry> {
        self.entries.get(&address)
    }
}

/// One `[section]`: lower-case name, line, and its keys (lower case) → (value, line).
type Section = (String, usize, BTreeMap<String, (String, usize)>);

/// `$NODEID+0x180` → `5+0x180` → evaluated when it is a sum of integers.
fn substitute_node_id(v: &str, node: &str) -> String {
    let lower = v.to_ascii_lowercase();
    if !lower.contains("$nodeid") {
        return v.to_string();
    }
    let replaced = lower.replace("$nodeid", node);
    let sum: Option<u64> = replaced
        .split('+')
        .map(|t| parse_u32(t.trim()).map(u64::from))
        .sum();
    match sum {
        Some(s) => format!("0x{s:X}"),
        None => replaced,
    }
}

fn parse_u32(t: &str) -> Option<u32> {
    let t = t.trim();
    match t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        Some(h) => u32::from_str_radix(h, 16).ok(),
        None => t.parse().ok(),
    }
}
