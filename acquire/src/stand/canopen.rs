//! The stand file's `[daq.canopen]` section: the DAQ is a CANopen node on the interface of
//! `daq.port = "can:IFACE"` (docs/canopen.md). It names the node (id, bit rate, EDS/DCF file) and
//! the objects ident uses (`[daq.canopen.objects]`).

use std::ops::Range;
use std::path::PathBuf;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use rfe::source::Quantity as Value;
use rfe::units::Dim;

use super::context::{Ctx, StandError};
use crate::canopen::eds::{EdsError, ObjectDictionary};
use crate::canopen::sdo::Address;
use crate::canopen::{CanOpenObjects, CanOpenSettings};

/// A CANopen DAQ node as the stand file describes it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CanOpenPort {
    /// Node id (1–127).
    pub node_id: u8,
    /// Bit rate of the bus (bit/s).
    pub bit_rate: u32,
    /// The node's EDS or DCF file (relative paths are relative to the stand file once loaded).
    pub eds: Option<PathBuf>,
    /// Objects used.
    pub objects: CanOpenObjects,
    /// Heartbeat period the node is told to produce (ms; 0 = none).
    pub heartbeat_ms: u16,
    /// A heartbeat missing for this long is a lost node.
    pub heartbeat_timeout: Duration,
    /// Longest wait for each SDO answer.
    pub sdo_timeout: Duration,
    /// Longest wait for the next TPDO while streaming.
    pub data_timeout: Duration,
}

impl CanOpenPort {
    /// The master's settings, with the EDS read (if one is named).
    pub fn settings(&self) -> Result<CanOpenSettings, EdsError> {
        let dictionary = match &self.eds {
            Some(p) => Some(ObjectDictionary::load(p, self.node_id)?),
            None => None,
        };
        Ok(CanOpenSettings {
            node_id: self.node_id,
            bit_rate: self.bit_rate,
            dictionary,
            objects: self.objects.clone(),
            sdo_timeout: self.sdo_timeout,
            data_timeout: self.data_timeout,
            heartbeat_ms: self.heartbeat_ms,
            heartbeat_timeout: self.heartbeat_timeout,
            ..CanOpenSettings::default()
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawCanOpen {
    node_id: Spanned<u32>,
    bit_rate: Option<Spanned<u32>>,
    eds: Option<String>,
    heartbeat: Option<Spanned<Value>>,
    heartbeat_timeout: Option<Spanned<Value>>,
    sdo_timeout: Option<Spanned<Value>>,
    data_timeout: Option<Spanned<Value>>,
    objects: Option<RawObjects>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObjects {
    sample_rate: Option<Spanned<String>>,
    counter: Option<Spanned<String>>,
    inputs: Option<Spanned<String>>,
    scaling: Option<Spanned<String>>,
    tpdos: Option<Spanned<u8>>,
}

const BIT_RATES: [u32; 9] = [
    10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000, 2_000_000,
];

/// `"0x2100:00"` (index:sub-index, hex) or `"0x7100"` (sub-index 0); `"none"` for no object.
fn address(cx: &Ctx<'_>, v: &Spanned<String>, what: &str) -> Result<Option<Address>, StandError> {
    let t = v.get_ref().trim();
    if t.eq_ignore_ascii_case("none") {
        return Ok(None);
    }
    let bad = || {
        cx.at(v.span(), format!("daq.canopen.objects.{what} = {t:?}: write an object as \"0x2100:00\" (hex index:sub-index) or \"0x7100\", or \"none\""))
    };
    let (i, s) = t.split_once(':').unwrap_or((t, "0"));
    let i = i.trim().trim_start_matches("0x").trim_start_matches("0X");
    let s = s.trim().trim_start_matches("0x").trim_start_matches("0X");
    let index = u16::from_str_radix(i, 16).map_err(|_| bad())?;
    let sub = u8::from_str_radix(s, 16).map_err(|_| bad())?;
    if index < 0x1000 {
        return Err(bad());
    }
    Ok(Some(Address::new(index, sub)))
}

fn millis(
    cx: &Ctx<'_>,
    v: &Option<Spanned<Value>>,
    what: &str,
    dflt: Duration,
) -> Result<Duration, StandError> {
    match v {
        Some(t) => Ok(Duration::from_secs_f64(cx.positive(t, Dim::TIME, what)?)),
        None => Ok(dflt),
    }
}

pub(super) fn canopen_port(
    cx: &Ctx<'_>,
    raw: &Spanned<RawCanOpen>,
    port_span: Range<usize>,
    is_can: bool,
) -> Result<CanOpenPort, StandError> {
    let r = raw.get_ref();
    if !is_can {
        return Err(cx.at(port_span, "[daq.canopen] needs the DAQ on CAN: daq.port = \"can:can0\" (or \"sim\" for the simulated node)"));
    }
    let node_id = *r.node_id.get_ref();
    let node_id = u8::try_from(node_id).ok().filter(|n| (1..=127).contains(n)).ok_or_else(|| {
        cx.at(r.node_id.span(), format!("daq.canopen.node_id = {node_id}: a CANopen node id is 1–127 (set on the node by DIP switches, LSS or its configuration tool)"))
    })?;
    let bit_rate = match &r.bit_rate {
        None => 1_000_000,
        Some(b) if BIT_RATES.contains(b.get_ref()) => *b.get_ref(),
        Some(b) => {
            return Err(cx.at(
                b.span(),
                format!(
                    "daq.canopen.bit_rate = {}: CiA 301 bit rates are {BIT_RATES:?} bit/s",
                    b.get_ref()
                ),
            ))
        }
    };
    let d = CanOpenSettings::default();
    let heartbeat = millis(
        cx,
        &r.heartbeat,
        "daq.canopen.heartbeat",
        Duration::from_millis(d.heartbeat_ms as u64),
    )?;
    let heartbeat_ms = u16::try_from(heartbeat.as_millis()).map_err(|_| {
        cx.at(
            r.heartbeat.as_ref().map_or(0..0, |h| h.span()),
            "daq.canopen.heartbeat: at most 65535 ms (0x1017 is UNSIGNED16)",
        )
    })?;
    let heartbeat_timeout = millis(
        cx,
        &r.heartbeat_timeout,
        "daq.canopen.heartbeat_timeout",
        (heartbeat * 7 / 2).max(Duration::from_millis(50)),
    )?;
    if heartbeat_timeout <= heartbeat {
        return Err(cx.at(
            r.heartbeat_timeout.as_ref().map_or(0..0, |h| h.span()),
            format!("daq.canopen.heartbeat_timeout ({heartbeat_timeout:?}) must exceed the heartbeat period ({heartbeat:?}); about 3× the period is usual"),
        ));
    }
    let mut objects = CanOpenObjects::default();
    if let Some(o) = &r.objects {
        if let Some(v) = &o.sample_rate {
            objects.sample_rate = address(cx, v, "sample_rate")?;
        }
        if let Some(v) = &o.counter {
            objects.counter = address(cx, v, "counter")?.ok_or_else(|| cx.at(v.span(), "daq.canopen.objects.counter cannot be \"none\": lost frames are detected by it"))?;
        }
        if let Some(v) = &o.inputs {
            objects.inputs = address(cx, v, "inputs")?
                .ok_or_else(|| cx.at(v.span(), "daq.canopen.objects.inputs cannot be \"none\""))?
                .index;
        }
        if let Some(v) = &o.scaling {
            objects.scaling = address(cx, v, "scaling")?.map(|a| a.index);
        }
        if let Some(t) = &o.tpdos {
            if *t.get_ref() == 0 {
                return Err(cx.at(
                    t.span(),
                    "daq.canopen.objects.tpdos must be ≥ 1 (the number of TPDOs the node has)",
                ));
            }
            objects.tpdos = *t.get_ref();
        }
    }
    Ok(CanOpenPort {
        node_id,
        bit_rate,
        eds: r.eds.as_ref().map(PathBuf::from),
        objects,
        heartbeat_ms,
        heartbeat_timeout,
        sdo_timeout: millis(cx, &r.sdo_timeout, "daq.canopen.sdo_timeout", d.sdo_timeout)?,
        data_timeout: millis(
            cx,
            &r.data_timeout,
            "daq.canopen.data_timeout",
            d.data_timeout,
        )?,
    })
}

#[cfg(test)]
mod tests {
    use crate::stand::{PortSpec, Stand};

    const STAND: &str = concat!(
        r#"
name = "canopen stand"
[shaker]
port = "/dev/ttyUSB0"
max_force = "6 kN"
[daq]
port = "can:can0"
sample_rate = "2000 Hz"
[daq.canopen]
NODE
"#,
        test_stand_channels!()
    );

    fn parse(node: &str) -> Result<Stand, crate::stand::StandError> {
        Stand::parse(&STAND.replace("NODE", node), "canopen.toml")
    }

    #[test]
    fn the_canopen_section_is_read_with_defaults_and_objects() {
        let s = parse("node_id = 12\nheartbeat = \"50 ms\"\n[daq.canopen.objects]\nsample_rate = \"none\"\ncounter = \"0x2200:01\"\nscaling = \"0x6126\"")
            .expect("valid");
        assert_eq!(s.daq.port, PortSpec::Can("can0".into()));
        let c = s.daq.canopen.expect("canopen section");
        assert_eq!((c.node_id, c.bit_rate, c.heartbeat_ms), (12, 1_000_000, 50));
        assert_eq!(
            c.heartbeat_timeout,
            std::time::Duration::from_millis(175),
            "3.5 × the heartbeat by default"
        );
        assert_eq!(c.objects.sample_rate, None);
        assert_eq!(
            c.objects.counter,
            crate::canopen::sdo::Address::new(0x2200, 1)
        );
        assert_eq!(
            (c.objects.inputs, c.objects.scaling, c.objects.tpdos),
            (0x7100, Some(0x6126), 4)
        );
        assert!(c.eds.is_none());
        let settings = c.settings().expect("no EDS to read");
        assert_eq!(settings.node_id, 12);
    }

    #[test]
    fn bad_canopen_settings_name_the_key_and_the_fix() {
        for (node, needle) in [
            ("node_id = 0", "node id is 1–127"),
            ("node_id = 200", "node id is 1–127"),
            ("node_id = 5\nbit_rate = 300000", "CiA 301 bit rates"),
            (
                "node_id = 5\nheartbeat = \"100 ms\"\nheartbeat_timeout = \"80 ms\"",
                "must exceed the heartbeat period",
            ),
            (
                "node_id = 5\n[daq.canopen.objects]\ncounter = \"none\"",
                "lost frames are detected by it",
            ),
            (
                "node_id = 5\n[daq.canopen.objects]\ninputs = \"7100h\"",
                "write an object as",
            ),
            (
                "node_id = 5\n[daq.canopen.objects]\ntpdos = 0",
                "tpdos must be ≥ 1",
            ),
            ("node_id = 5\nbogus = 1", "bogus"),
        ] {
            let e = parse(node).expect_err(node);
            assert!(e.to_string().contains(needle), "{node}: {e}");
        }
        let serial = STAND
            .replace("NODE", "node_id = 5")
            .replace("port = \"can:can0\"", "port = \"/dev/ttyUSB1\"");
        let e = Stand::parse(&serial, "x.toml").expect_err("CANopen on a serial port");
        assert!(e.to_string().contains("needs the DAQ on CAN"), "{e}");
    }

    #[test]
    fn the_shipped_canopen_stand_loads_its_eds() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/stands");
        let s = Stand::load(&dir.join("fwd32j-canopen-sim.toml")).expect("shipped stand file");
        let c = s.daq.canopen.expect("canopen");
        let settings = c.settings().expect("EDS readable");
        let od = settings.dictionary.expect("EDS named");
        assert_eq!(od.product, "CANOPEN-DAQ-8");
        assert_eq!(s.daq.sample_rate_hz, 2000.0);
        // A missing EDS is refused when the stand file is loaded, not at the sweep.
        let tmp = tempfile::tempdir().expect("temp dir");
        let text = std::fs::read_to_string(dir.join("fwd32j-canopen-sim.toml")).expect("read");
        let moved = tmp.path().join("stand.toml");
        std::fs::write(
            &moved,
            text.replace("../models/", &format!("{}/../models/", dir.display())),
        )
        .expect("write");
        let e = Stand::load(&moved).expect_err("EDS not beside the copy");
        assert!(
            e.to_string().contains("daq.canopen.eds")
                && e.to_string().contains("ident-sim-daq.eds"),
            "{e}"
        );
    }
}
