//! The measurement map (`--map FILE`, TOML): which measured channel — a UFF response node and
//! direction, or a named sensor — is which body of the model and which output of it (a
//! principal-axis DOF, or a point and a direction on the body); which file reference is which
//! of the model's excitations; the unit when a file gives none. [`MeasurementMap::apply`] turns
//! the channels of a vendor file into [`MeasuredData`] in the model's convention (SI, the
//! response to the model's excitation or reference, the output's quantity).
//!
//! ```toml
//! unit = "g/N"                 # optional: when the file's records give no units
//! [[reference]]                # optional: one per file reference to use ([reference]: one)
//! node = 1
//! dir = "+Z"                   # no name: the model's own excitation
//! [[reference]]
//! node = 2
//! dir = "+Y"
//! name = "hammer"              # a [[reference]] of the model (motion = "relative": base motion)
//! [[channel]]
//! node = 3                     # UFF response node ...
//! dir = "+Z"                   # ... and direction (±X/Y/Z or ±1..3, global axes)
//! body = "table"
//! point = "120 0 450 mm"       # optional: where the sensor is (global); see below
//! [[channel]]
//! sensor = "acc2"              # a named sensor (CSV `body` column or a UFF response entity)
//! body = "column"
//! direction = [0, 1, 0]        # global direction of its axis, or `dof = "u2"` / `"-u2"`
//! ```
//!
//! A channel is an output of its body (`docs/identification.md`, measurement map):
//! - `dof = "u2"` (or `"-u2"`): that principal-axis DOF at the centre of mass. A UFF `dir` beside
//!   it must lie within 1° of that axis; a `point` is not allowed with it.
//! - a direction (`direction = [x, y, z]`, or the UFF `dir`) and an optional `point` (global; the
//!   centre of mass when omitted): where the point lies within 1 mm of the line through the centre
//!   of mass along a principal axis and the direction within 1° of that axis, the channel is that
//!   principal-axis DOF (a negative axis flips the sign), as before; anywhere else it is a **point
//!   output**, `dᵀ(u + θ × (p − c))` ([`rfe::model::PointOutput`]), which the model need not
//!   declare ([`super::data::with_measured_outputs`]).
//!
//! With several `[[reference]]`s every channel is mapped once per reference. Errors name the
//! map's file, line and field.

use std::collections::BTreeSet;
use std::f64::consts::PI;
use std::path::Path;

use nalgebra::Vector3;
use serde::Deserialize;
use serde_spanned::Spanned;

use super::data::DataError;
use rfe::channel::{dir_text, ChannelName, MeasuredChannel};
use rfe::frf_units::{self, FrfUnit};
use rfe::measured::{MeasuredData, Measurement};
use rfe::model::{Body, Excitation, Model, PointOutput, DOF_NAMES};
use rfe::source::{Located, SourceText};
use rfe::units::{parse_quantities, Dim};

/// Largest angle (degrees) between a channel's direction and the principal axis it maps to (as
/// that DOF; farther off it is a point output, except where the map declares `dof`).
pub const MAX_AXIS_ANGLE_DEG: f64 = 1.0;
/// Largest distance (m) of a sensor's point from the line through the centre of mass along its
/// direction for it to read a principal-axis DOF (farther off it is a point output).
pub const MAX_LEVER_ARM_M: f64 = 1e-3;

/// Why a map could not be read or applied.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The file could not be read.
    #[error("{path}: cannot read the measurement map")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A problem at a place in the map.
    #[error(transparent)]
    Map(#[from] Located),
    /// A problem with the measured data the map is applied to.
    #[error(transparent)]
    Data(#[from] DataError),
}

/// One `[[channel]]` of the map, resolved against the model.
#[derive(Debug, Clone, PartialEq)]
struct Entry {
    line: usize,
    name: ChannelName,
    body: usize,
    dof: u8,
    negative: bool,
    /// A point output (sensor off the principal-axis lines); `None`: the DOF `dof`.
    at: Option<PointOutput>,
    unit: Option<FrfUnit>,
}

impl Entry {
    /// `u2`, or `at (100, 0, 450) mm along (0, 1, 0)`.
    fn output_name(&self) -> String {
        match &self.at {
            Some(at) => at.label(),
            None => DOF_NAMES[self.dof as usize].to_string(),
        }
    }
}

/// One `[reference]` / `[[reference]]` of the map: which excitation of the file is which of the
/// model.
#[derive(Debug, Clone, PartialEq)]
struct MapReference {
    line: usize,
    /// The file's reference node and direction.
    node_dir: (i64, i64),
    /// The model's reference (`None`: its own excitation).
    name: Option<String>,
    /// Under base motion: the channels are relative to the base.
    relative: bool,
}

/// A measurement map resolved against a model.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasurementMap {
    file: String,
    references: Vec<MapReference>,
    unit: Option<FrfUnit>,
    entries: Vec<Entry>,
}

type Sp<T> = Spanned<T>;

#[derive(Deserialize)]
#[serde(untagged)]
enum Dir {
    Int(i64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Point {
    Numbers(Vec<f64>),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMap {
    unit: Option<Sp<String>>,
    reference: Option<RawReferences>,
    #[serde(default, rename = "channel")]
    channels: Vec<RawChannel>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReference {
    node: Sp<i64>,
    dir: Sp<Dir>,
    name: Option<Sp<String>>,
    motion: Option<Sp<String>>,
}

/// `[reference]` (one table) or `[[reference]]` (several), read without buffering so that every
/// field keeps its place in the file.
struct RawReferences(Vec<RawReference>);

impl<'de> Deserialize<'de> for RawReferences {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct OneOrMany;
        impl<'de> serde::de::Visitor<'de> for OneOrMany {
            type Value = RawReferences;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a [reference] table or [[reference]] tables")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> Result<RawReferences, A::Error> {
                RawReference::deserialize(serde::de::value::MapAccessDeserializer::new(map))
                    .map(|r| RawReferences(vec![r]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                seq: A,
            ) -> Result<RawReferences, A::Error> {
                Vec::<RawReference>::deserialize(serde::de::value::SeqAccessDeserializer::new(seq))
                    .map(RawReferences)
            }
        }
        d.deserialize_any(OneOrMany)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannel {
    node: Option<Sp<i64>>,
    dir: Option<Sp<Dir>>,
    sensor: Option<Sp<String>>,
    body: Sp<String>,
    dof: Option<Sp<String>>,
    direction: Option<Sp<Vec<f64>>>,
    point: Option<Sp<Point>>,
    unit: Option<Sp<String>>,
    #[allow(dead_code)]
    note: Option<String>,
}

/// Reads a map file and resolves it against `model`.
pub fn load(path: &Path, model: &Model) -> Result<MeasurementMap, MapError> {
    let text = std::fs::read_to_string(path).map_err(|source| MapError::Io {
        path: path.display().to_string(),
        source,
    })?;
    Ok(parse(&text, &path.display().to_string(), model)?)
}

/// A UFF direction code from `+Z`, `Z-`, `y`, `3`, `-1`; `None` if it is none.
fn parse_dir(d: &Dir) -> Option<i64> {
    match d {
        Dir::Int(i) => (1..=6).contains(&i.abs()).then_some(*i),
        Dir::Text(t) => {
            let t = t.trim().to_ascii_uppercase();
            if let Ok(i) = t.parse::<i64>() {
                return (1..=6).contains(&i.abs()).then_some(i);
            }
            let (sign, axis) = if let Some(a) = t.strip_prefix('-').or(t.strip_suffix('-')) {
                (-1, a)
            } else {
                (1, t.strip_prefix('+').or(t.strip_suffix('+')).unwrap_or(&t))
            };
            let k = ["X", "Y", "Z", "RX", "RY", "RZ"]
                .iter()
                .position(|a| *a == axis)?;
            Some(sign * (k as i64 + 1))
        }
    }
}

/// Parses a map's text (`origin` names it in errors) and resolves it against `model`.
pub fn parse(text: &str, origin: &str, model: &Model) -> Result<MeasurementMap, Located> {
    let text = rfe::source::strip_bom(text);
    let src = SourceText::new(origin, text);
    let raw: RawMap = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        src.at(
            span,
            format!(
                "{} (see docs/identification.md, measurement map)",
                e.message().trim()
            ),
        )
    })?;
    let unit = raw.unit.as_ref().map(|u| unit_of(&src, u)).transpose()?;
    let mut references: Vec<MapReference> = Vec::new();
    for r in raw.reference.iter().flat_map(|r| &r.0) {
        let resolved = reference(&src, r, model, &references)?;
        references.push(resolved);
    }
    if raw.channels.is_empty() {
        return Err(src.at(
            0..0,
            "no [[channel]]: the map must say which measured channel is which body and direction",
        ));
    }
    Ok(MeasurementMap {
        file: origin.to_string(),
        references,
        unit,
        entries: entries(&src, &raw.channels, model)?,
    })
}

/// One `[[reference]]` of the map resolved against the model and the references before it
/// (`earlier`): no file reference or model reference twice.
fn reference(
    src: &SourceText,
    r: &RawReference,
    model: &Model,
    earlier: &[MapReference],
) -> Result<MapReference, Located> {
    let node_dir = (
        *r.node.get_ref(),
        parse_dir(r.dir.get_ref())
            .ok_or_else(|| src.at(r.dir.span(), "reference.dir: use +X, -Y, Z, ... or ±1..6"))?,
    );
    let line = src.at(r.node.span(), "").line;
    if let Some(o) = earlier.iter().find(|o| o.node_dir == node_dir) {
        return Err(src.at(
            r.node.span(),
            format!(
                "reference node {} {} is mapped twice (line {} too)",
                node_dir.0,
                dir_text(node_dir.1),
                o.line
            ),
        ));
    }
    let name = match &r.name {
        None => None,
        Some(n) if n.get_ref() == "excitation" => None,
        Some(n) => {
            if model.reference_index(n.get_ref()).is_none() {
                let known: Vec<&str> = model.references.iter().map(|x| x.name.as_str()).collect();
                return Err(src.at(
                    n.span(),
                    format!(
                        "reference.name: the model has no [[reference]] \"{}\"; its references: excitation{}{}",
                        n.get_ref(),
                        if known.is_empty() { "" } else { ", " },
                        known.join(", ")
                    ),
                ));
            }
            Some(n.get_ref().clone())
        }
    };
    if earlier.iter().any(|o| o.name == name) {
        return Err(src.at(
            r.name.as_ref().map(|n| n.span()).unwrap_or(r.node.span()),
            format!(
                "reference.name: two file references map to the model's {}; name a different [[reference]] of the model for each",
                name.as_deref().unwrap_or("excitation")
            ),
        ));
    }
    let relative = relative_motion(src, r, model, name.as_deref())?;
    Ok(MapReference {
        line,
        node_dir,
        name,
        relative,
    })
}

/// Whether a reference's outputs are relative motions (`motion = "relative"`: response − base)
/// or absolute ones; only a base-motion reference (`name`, `None` for the excitation) has either.
fn relative_motion(
    src: &SourceText,
    r: &RawReference,
    model: &Model,
    name: Option<&str>,
) -> Result<bool, Located> {
    Ok(match &r.motion {
        None => false,
        Some(m) => {
            let base = name
                .and_then(|n| model.references.iter().find(|x| x.name == n))
                .is_some_and(|x| matches!(x.excitation, Excitation::BaseMotion { .. }));
            if !base {
                return Err(src.at(
                    m.span(),
                    format!(
                        "reference.motion: absolute or relative motion is an output under base motion, and the model's {} is not one; name a [[reference]] of the model with base_motion",
                        name.map(|n| format!("reference \"{n}\"")).unwrap_or("excitation".into())
                    ),
                ));
            }
            match m.get_ref().as_str() {
                "absolute" => false,
                "relative" => true,
                other => {
                    return Err(src.at(
                        m.span(),
                        format!("reference.motion: \"{other}\" is neither \"absolute\" (transmissibility) nor \"relative\" (response − base)"),
                    ))
                }
            }
        }
    })
}

/// The map's `[[channel]]`s resolved: no channel, and no body and DOF, mapped twice.
fn entries(
    src: &SourceText,
    channels: &[RawChannel],
    model: &Model,
) -> Result<Vec<Entry>, Located> {
    let mut entries: Vec<Entry> = Vec::new();
    for c in channels {
        let e = entry(src, c, model)?;
        if let Some(o) = entries.iter().find(|o| o.name == e.name) {
            return Err(src.at(
                c.body.span(),
                format!("{} is mapped twice (line {} too)", e.name, o.line),
            ));
        }
        if let Some(o) = entries
            .iter()
            .find(|o| (o.body, o.dof, o.at) == (e.body, e.dof, e.at))
        {
            return Err(src.at(
                c.body.span(),
                format!(
                    "{} {} is already measured by {} (line {}); one channel per body and DOF",
                    model.bodies[e.body].name,
                    e.output_name(),
                    o.name,
                    o.line
                ),
            ));
        }
        entries.push(e);
    }
    Ok(entries)
}

/// A `unit = "..."` of the map, read as an FRF unit.
fn unit_of(src: &SourceText, u: &Sp<String>) -> Result<FrfUnit, Located> {
    FrfUnit::parse(u.get_ref()).map_err(|m| src.at(u.span(), format!("unit: {m}")))
}

/// One `[[channel]]` resolved: its name, body, DOF and sign.
fn entry(src: &SourceText, c: &RawChannel, model: &Model) -> Result<Entry, Located> {
    let line = src.at(c.body.span(), "").line;
    let name = channel_name(src, c)?;
    let body = body_of(src, c, model)?;
    let b = &model.bodies[body];
    let (dof, negative, at) = match (&c.dof, &c.direction) {
        (Some(_), Some(d)) => {
            return Err(src.at(d.span(), "give `dof` or `direction`, not both"));
        }
        (Some(d), None) => along_dof(src, c, d, &name, b)?,
        (None, given) => along_direction(src, c, given.as_ref(), &name, b)?,
    };
    let unit = c.unit.as_ref().map(|u| unit_of(src, u)).transpose()?;
    Ok(Entry {
        line,
        name,
        body,
        dof,
        negative,
        at,
        unit,
    })
}

/// The channel's name in the file: UFF node and direction, or a sensor name.
fn channel_name(src: &SourceText, c: &RawChannel) -> Result<ChannelName, Located> {
    Ok(match (&c.node, &c.dir, &c.sensor) {
        (Some(n), Some(d), None) => ChannelName::Node {
            node: *n.get_ref(),
            dir: parse_dir(d.get_ref()).ok_or_else(|| {
                src.at(d.span(), "dir: use +X, -Y, Z, ... (global axes) or ±1..6")
            })?,
        },
        (None, None, Some(s)) => ChannelName::Sensor(s.get_ref().clone()),
        (Some(n), None, None) => {
            return Err(src.at(
                n.span(),
                "node without dir: give the response direction too, e.g. dir = \"+Z\"",
            ))
        }
        _ => return Err(src.at(
            c.body.span(),
            "a channel is either `node` + `dir` (UFF) or `sensor` (a name), not both or neither",
        )),
    })
}

/// The index of the model body the channel names.
fn body_of(src: &SourceText, c: &RawChannel, model: &Model) -> Result<usize, Located> {
    let body_name = c.body.get_ref();
    model.body_index(body_name).ok_or_else(|| {
        let known: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
        src.at(
            c.body.span(),
            format!(
                "body: the model has no body \"{body_name}\"; its bodies: {}",
                known.join(", ")
            ),
        )
    })
}

/// A channel declared as a principal-axis DOF (`dof = "-u2"`): the DOF and its sign; a UFF
/// direction beside it must agree.
fn along_dof(
    src: &SourceText,
    c: &RawChannel,
    d: &Sp<String>,
    name: &ChannelName,
    b: &Body,
) -> Result<(u8, bool, Option<PointOutput>), Located> {
    let t = d.get_ref().trim();
    let (neg, t) = match t.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, t.strip_prefix('+').unwrap_or(t)),
    };
    let k = DOF_NAMES[..3].iter().position(|n| *n == t).ok_or_else(|| {
        src.at(
            d.span(),
            format!("dof: \"{t}\" is not u1, u2 or u3 (optionally with a sign: \"-u2\"); rotations are not mapped from sensors"),
        )
    })?;
    if let Some(p) = &c.point {
        return Err(src.at(
            p.span(),
            "`point` goes with a direction (`direction = [x, y, z]` or the UFF `dir`), not with `dof`: a channel declared as a principal-axis DOF reads it at the centre of mass",
        ));
    }
    // A UFF direction beside `dof` must agree with it: within 1° of that principal axis.
    if let (Some(dspan), ChannelName::Node { dir, .. }) = (&c.dir, name) {
        if (1..=3).contains(&dir.abs()) {
            let mut g = Vector3::zeros();
            g[(dir.unsigned_abs() - 1) as usize] = dir.signum() as f64;
            let cos = g.dot(&b.rotation.column(k));
            let angle = cos.abs().min(1.0).acos() * 180.0 / PI;
            if angle > MAX_AXIS_ANGLE_DEG {
                return Err(src.at(
                    dspan.span(),
                    format!(
                        "dir: {} is {angle:.2}° from {} of body \"{}\" (dof = \"{}\"); a channel declared as a principal-axis DOF must lie within {MAX_AXIS_ANGLE_DEG}° of it — drop `dof` to map it as a point output along its direction",
                        dir_text(*dir), DOF_NAMES[k], b.name, d.get_ref()
                    ),
                ));
            }
        }
    }
    Ok((k as u8, neg, None))
}

/// A channel along a direction (`direction = [x, y, z]`, or its UFF direction), optionally at a
/// point: a principal-axis DOF when it lies along one through the centre of mass, else a point
/// output.
fn along_direction(
    src: &SourceText,
    c: &RawChannel,
    given: Option<&Sp<Vec<f64>>>,
    name: &ChannelName,
    b: &Body,
) -> Result<(u8, bool, Option<PointOutput>), Located> {
    let (d, span) = match (given, name) {
        (Some(v), _) => {
            let x = v.get_ref();
            if x.len() != 3 || !x.iter().all(|c| c.is_finite()) {
                return Err(src.at(
                    v.span(),
                    "direction: three finite numbers [x, y, z] (global axes)",
                ));
            }
            (Vector3::new(x[0], x[1], x[2]), v.span())
        }
        (None, ChannelName::Node { dir, .. }) if (1..=3).contains(&dir.abs()) => {
            let mut d = Vector3::zeros();
            d[(dir.unsigned_abs() - 1) as usize] = dir.signum() as f64;
            (d, c.dir.as_ref().map(|d| d.span()).unwrap_or(c.body.span()))
        }
        (None, ChannelName::Node { dir, .. }) => {
            return Err(src.at(
                c.dir.as_ref().map(|d| d.span()).unwrap_or(c.body.span()),
                format!(
                    "dir: {} is a rotation; map translations (±X, ±Y, ±Z), or give `dof`",
                    dir_text(*dir)
                ),
            ))
        }
        (None, ChannelName::Sensor(_)) => {
            return Err(src.at(
                c.body.span(),
                "a sensor needs `direction = [x, y, z]` (global) or `dof = \"u1\"`",
            ))
        }
    };
    let n = d.norm();
    if n == 0.0 {
        return Err(src.at(span, "direction: the zero vector has no direction"));
    }
    let d = d / n;
    let point = point_of(src, c)?;
    // The sensor reads dᵀ(u + θ × (p − c)); where p lies on the line through the centre
    // of mass along a principal axis it reads that DOF alone, and the channel keeps the
    // principal-axis characteristic; anywhere else it is a point output.
    let (k, cos) = (0..3)
        .map(|k| (k, d.dot(&b.rotation.column(k))))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap_or((0, 0.0));
    let angle = cos.abs().min(1.0).acos() * 180.0 / PI;
    let on_axis_line = point.is_none_or(|p| (p - b.position).cross(&d).norm() <= MAX_LEVER_ARM_M);
    if angle <= MAX_AXIS_ANGLE_DEG && on_axis_line {
        Ok((k as u8, cos < 0.0, None))
    } else {
        let p = point.unwrap_or(b.position);
        let Some(at) = PointOutput::new(p, d) else {
            return Err(src.at(span, "direction: not a finite direction"));
        };
        Ok((k as u8, false, Some(at)))
    }
}

/// The channel's `point`, when given (m).
fn point_of(src: &SourceText, c: &RawChannel) -> Result<Option<Vector3<f64>>, Located> {
    Ok(match &c.point {
        None => None,
        Some(p) => {
            let xs = match p.get_ref() {
                Point::Numbers(v) => v.clone(),
                Point::Text(t) => parse_quantities(t, Dim::LENGTH)
                    .map_err(|e| src.at(p.span(), format!("point: {e}")))?,
            };
            if xs.len() != 3 || !xs.iter().all(|x| x.is_finite()) {
                return Err(src.at(
                    p.span(),
                    "point: three coordinates, e.g. \"0 0 450 mm\" or [0, 0, 0.45] (m)",
                ));
            }
            Some(Vector3::new(xs[0], xs[1], xs[2]))
        }
    })
}

impl MeasurementMap {
    /// The channels of a data file (`origin`) mapped onto the model: every map entry must find
    /// its channel (for the chosen reference), channels the map does not name are left out
    /// with a note, units come from the map's entry, the map, or the file (else an error), and
    /// everything is converted to the model's convention. The notes end up in `source`.
    pub fn apply(
        &self,
        channels: &[MeasuredChannel],
        origin: &str,
        model: &Model,
    ) -> Result<MeasuredData, MapError> {
        let bad = |item: &str, message: String| {
            MapError::Data(DataError::Invalid {
                origin: origin.to_string(),
                item: item.to_string(),
                message,
            })
        };
        let mut notes = vec![format!("channels mapped by {}", self.file)];
        let targets = self.targets(channels, origin, &mut notes)?;
        let of_any = |c: &MeasuredChannel| {
            targets.is_empty()
                || c.reference.is_none()
                || targets.iter().any(|t| c.reference == Some(t.node_dir))
        };
        let mut characteristics = Vec::new();
        let no_target = [None];
        let each: Vec<Option<&MapReference>> = if targets.is_empty() {
            no_target.to_vec()
        } else {
            targets.iter().map(Some).collect()
        };
        for (t, e) in each
            .iter()
            .flat_map(|t| self.entries.iter().map(move |e| (t, e)))
        {
            let c = self.channel_of(channels, e, t.map(|t| t.node_dir), origin, &bad)?;
            let (unit, from) = self.unit_for(e, c, &bad)?;
            check_lines(c, &bad)?;
            let mut m = measurement(e, c, *t, &unit, model);
            notes.push(format!(
                "{} ({}) is {} {}{}, unit from {from}",
                e.name,
                c.item,
                m.body,
                if e.negative { "-" } else { "" },
                e.output_name()
            ));
            frf_units::to_model_convention(&mut m, &unit, model, &mut notes)
                .map_err(|e| bad(&c.item, e.to_string()))?;
            characteristics.push(m);
        }
        notes.extend(self.unused(channels, of_any));
        Ok(MeasuredData {
            source: std::iter::once(origin.to_string())
                .chain(notes)
                .collect::<Vec<_>>()
                .join("; "),
            characteristics,
        })
    }

    /// The references the map's channels are read for (the map's, else the file's one), each
    /// checked against the file's and noted.
    fn targets(
        &self,
        channels: &[MeasuredChannel],
        origin: &str,
        notes: &mut Vec<String>,
    ) -> Result<Vec<MapReference>, MapError> {
        let targets: Vec<MapReference> = if self.references.is_empty() {
            match self.reference(channels, origin)? {
                Some(node_dir) => vec![MapReference {
                    line: 0,
                    node_dir,
                    name: None,
                    relative: false,
                }],
                None => Vec::new(),
            }
        } else {
            self.references.clone()
        };
        let held: BTreeSet<(i64, i64)> = channels.iter().filter_map(|c| c.reference).collect();
        for t in &targets {
            let (n, d) = t.node_dir;
            if t.line > 0 && !held.contains(&t.node_dir) && !held.is_empty() {
                return Err(MapError::Map(Located {
                    file: self.file.clone(),
                    line: t.line,
                    column: 1,
                    message: format!(
                        "reference: {origin} holds no FRFs of reference node {n} {}; its references: {}",
                        dir_text(d),
                        held.iter()
                            .map(|(n, d)| format!("node {n} {}", dir_text(*d)))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                }));
            }
            notes.push(format!(
                "reference node {n} {} is the model's {}{}",
                dir_text(d),
                t.name.as_deref().unwrap_or("excitation"),
                if t.relative { " (relative motion)" } else { "" }
            ));
        }
        Ok(targets)
    }

    /// The one channel of the file an entry names (for `reference`, when there is one).
    fn channel_of<'c>(
        &self,
        channels: &'c [MeasuredChannel],
        e: &Entry,
        reference: Option<(i64, i64)>,
        origin: &str,
        bad: &dyn Fn(&str, String) -> MapError,
    ) -> Result<&'c MeasuredChannel, MapError> {
        let of_reference = |c: &&MeasuredChannel| {
            reference.is_none() || c.reference.is_none() || c.reference == reference
        };
        let found: Vec<&MeasuredChannel> = channels
            .iter()
            .filter(of_reference)
            .filter(|c| c.name == e.name)
            .collect();
        match found.as_slice() {
            [c] => Ok(*c),
            [] => {
                let names: BTreeSet<String> = channels
                    .iter()
                    .filter(of_reference)
                    .map(|c| c.name.to_string())
                    .collect();
                Err(MapError::Map(Located {
                    file: self.file.clone(),
                    line: e.line,
                    column: 1,
                    message: format!(
                        "{} is not in {origin}{}; its channels: {}",
                        e.name,
                        reference
                            .map(|(n, d)| format!(" for reference node {n} {}", dir_text(d)))
                            .unwrap_or_default(),
                        names.into_iter().collect::<Vec<_>>().join(", ")
                    ),
                }))
            }
            [a, b, ..] => Err(bad(
                &b.item,
                format!("{} appears twice (also {}); keep one", e.name, a.item),
            )),
        }
    }

    /// The unit of a channel's values and where it came from: the entry's, the map's, or the
    /// file's (else an error asking the map for one).
    fn unit_for(
        &self,
        e: &Entry,
        c: &MeasuredChannel,
        bad: &dyn Fn(&str, String) -> MapError,
    ) -> Result<(FrfUnit, String), MapError> {
        match (&e.unit, &self.unit, &c.unit) {
            (Some(u), _, _) => Ok((u.clone(), format!("{} line {}", self.file, e.line))),
            (None, Some(u), _) => Ok((u.clone(), format!("{} (top-level unit)", self.file))),
            (None, None, Ok(u)) => Ok((u.clone(), c.unit_source.clone())),
            (None, None, Err(why)) => Err(bad(
                &c.item,
                format!("{why}; the file does not say what unit {} is in: give it in the map, e.g. unit = \"g/N\" (top level, or in this [[channel]])", e.name),
            )),
        }
    }

    /// The note on the channels left out: not in the map, or of another reference.
    fn unused(
        &self,
        channels: &[MeasuredChannel],
        of_any: impl Fn(&MeasuredChannel) -> bool,
    ) -> Option<String> {
        let unused: Vec<String> = channels
            .iter()
            .filter(|c| !self.entries.iter().any(|e| e.name == c.name) || !of_any(c))
            .map(|c| format!("{} ({})", c.name, c.item))
            .collect();
        (!unused.is_empty()).then(|| {
            format!(
                "{} channel(s) not in the map or of another reference, not used: {}{}",
                unused.len(),
                unused
                    .iter()
                    .take(5)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", "),
                if unused.len() > 5 { ", ..." } else { "" }
            )
        })
    }

    /// The reference to use: the map's, or the one reference of the channels the map names.
    fn reference(
        &self,
        channels: &[MeasuredChannel],
        origin: &str,
    ) -> Result<Option<(i64, i64)>, MapError> {
        let refs: BTreeSet<(i64, i64)> = channels
            .iter()
            .filter(|c| self.entries.iter().any(|e| e.name == c.name))
            .filter_map(|c| c.reference)
            .collect();
        if refs.len() > 1 {
            let list: Vec<String> = refs
                .iter()
                .map(|(n, d)| format!("node {n} {}", dir_text(*d)))
                .collect();
            return Err(MapError::Data(DataError::Invalid {
                origin: origin.to_string(),
                item: "references".into(),
                message: format!(
                    "the file holds FRFs of {} references ({}); say in the map which is which of the model: [[reference]] node = ..., dir = \"...\", name = \"...\" (a [[reference]] of the model; without name, the model's excitation), one per reference to use",
                    refs.len(),
                    list.join(", ")
                ),
            }));
        }
        Ok(refs.into_iter().next())
    }
}

/// A channel as a measurement of the entry's body and DOF (for reference `t`), still in the
/// channel's `unit`; a negative direction turns the phase by π.
fn measurement(
    e: &Entry,
    c: &MeasuredChannel,
    t: Option<&MapReference>,
    unit: &FrfUnit,
    model: &Model,
) -> Measurement {
    let mut phase = c.phase_rad.clone();
    if e.negative {
        if let Some(p) = &mut phase {
            for x in p.iter_mut() {
                *x = (*x + 2.0 * PI).rem_euclid(2.0 * PI) - PI;
            }
        }
    }
    Measurement {
        body: model.bodies[e.body].name.clone(),
        dof: e.dof,
        quantity: unit.quantity.into(),
        freqs_hz: c.freqs_hz.clone(),
        amplitude: c.amplitude.clone(),
        phase_rad: phase,
        variance: None,
        coherence: c.coherence.clone(),
        averages: None,
        at: e.at,
        reference: t.and_then(|t| t.name.clone()),
        relative: t.is_some_and(|t| t.relative),
    }
}

/// Finite, non-negative, strictly increasing frequencies; finite amplitudes and phases.
fn check_lines(
    c: &MeasuredChannel,
    bad: &dyn Fn(&str, String) -> MapError,
) -> Result<(), MapError> {
    let n = c.freqs_hz.len();
    if n == 0 || c.amplitude.len() != n {
        return Err(bad(
            &c.item,
            format!("{} frequencies, {} values", n, c.amplitude.len()),
        ));
    }
    for k in 0..n {
        let f = c.freqs_hz[k];
        let at = format!("{}, line {k} of the function ({f} Hz)", c.item);
        if !(f.is_finite() && f >= 0.0) {
            return Err(bad(
                &at,
                format!("abscissa {f} is not a finite frequency ≥ 0"),
            ));
        }
        if k > 0 && f <= c.freqs_hz[k - 1] {
            let what = if f == c.freqs_hz[k - 1] {
                "repeats"
            } else {
                "is below"
            };
            return Err(bad(
                &at,
                format!(
                    "frequency {f} Hz {what} the previous one ({} Hz); frequencies must increase",
                    c.freqs_hz[k - 1]
                ),
            ));
        }
        let phase_ok = c.phase_rad.as_ref().is_none_or(|p| p[k].is_finite());
        if !c.amplitude[k].is_finite() || !phase_ok {
            return Err(bad(
                &at,
                "value is NaN or infinite; drop the line or fix the file".into(),
            ));
        }
    }
    Ok(())
}
