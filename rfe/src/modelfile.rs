//! Model files: the human-friendly TOML format (`configs/models/*.toml`, documented key by key in
//! `docs/model-format.md`) and the resolved JSON contract ([`crate::contract`]). Both load into a
//! [`Model`]; every error names the file and the line and column (TOML) or the JSON path, says
//! what is wrong and how to fix it.

use std::ops::Range;
use std::path::Path;

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::Deserialize;
use serde_spanned::Spanned;

use crate::check::{check, rotation_problem, Item, Problem};
use crate::contract::{from_json, json_path, ModelJson};
use crate::model::*;
use crate::source::{Located, SourceText};
use crate::units::{parse_quantities, parse_quantity, Dim};

/// A loaded model and the warnings found while loading it.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The resolved model.
    pub model: Model,
    /// Problems that do not stop computation (e.g. a body connected to nothing), located.
    pub warnings: Vec<String>,
}

/// Why a model file could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The file could not be read.
    #[error("{path}: cannot read the model file: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A problem at a line and column of a TOML file.
    #[error(transparent)]
    Toml(#[from] Located),
    /// A problem at a JSON path of a resolved-JSON file.
    #[error("{origin}: at {path}: {message}")]
    Json {
        /// File name.
        origin: String,
        /// e.g. `$.sdes[3].k`.
        path: String,
        /// What and how to fix.
        message: String,
    },
}

/// A file of the repository, for the crate's unit tests (`rel` from the repository's root).
#[cfg(test)]
pub(crate) fn repo_file(rel: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// The FWD-32J model (`configs/models/fwd32j.toml`), for the crate's unit tests.
#[cfg(test)]
pub(crate) fn fwd32j() -> Model {
    load(&repo_file("configs/models/fwd32j.toml"))
        .expect("configs/models/fwd32j.toml loads")
        .model
}

/// Loads a model file: resolved JSON if the file starts with `{`, TOML otherwise.
pub fn load(path: &Path) -> Result<Loaded, LoadError> {
    let io = |source| LoadError::Io {
        path: path.display().to_string(),
        source,
    };
    crate::source::read_json_or(path, io, parse_json, parse_toml)
}

/// Parses the resolved JSON form.
pub fn parse_json(text: &str, origin: &str) -> Result<Loaded, LoadError> {
    let raw: ModelJson = crate::source::from_json(text).map_err(|e| LoadError::Json {
        origin: origin.into(),
        path: e.path,
        message: e.message,
    })?;
    let model = from_json(&raw).map_err(|p| LoadError::Json {
        origin: origin.into(),
        path: p.path,
        message: p.message,
    })?;
    let (errors, warnings) = check(&model);
    if let Some(p) = errors.first() {
        return Err(LoadError::Json {
            origin: origin.into(),
            path: json_path(p.item),
            message: p.message.clone(),
        });
    }
    Ok(Loaded {
        model,
        warnings: warnings
            .iter()
            .map(|w| format!("{origin}: at {}: {}", json_path(w.item), w.message))
            .collect(),
    })
}

// ---------------------------------------------------------------------------------------------
// TOML

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Value {
    Num(f64),
    Text(String),
    List(Vec<Value>),
}

type Sp<T> = Spanned<T>;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    name: Option<String>,
    #[serde(default, rename = "body")]
    bodies: Vec<RawBody>,
    #[serde(default, rename = "sde")]
    sdes: Vec<RawSde>,
    excitation: Option<RawExcitation>,
    #[serde(default, rename = "reference")]
    references: Vec<RawReference>,
    #[serde(default, rename = "output")]
    outputs: Vec<RawOutput>,
    #[serde(default, rename = "point_mass")]
    point_masses: Vec<RawPointMass>,
}

/// `[[point_mass]]`: a mass added rigidly to a body at a point (sensor, force gauge, fixture).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPointMass {
    name: Sp<String>,
    body: Sp<String>,
    point: Sp<Value>,
    mass: Sp<Value>,
    inertia: Option<Sp<Value>>,
    #[allow(dead_code)]
    note: Option<String>,
}

/// `[[reference]]`: a further, named excitation (forces, pairs, or base motion).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawReference {
    name: Sp<String>,
    #[serde(default)]
    force: Vec<RawForce>,
    #[serde(default)]
    pair: Vec<RawPair>,
    base_motion: Option<Sp<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBody {
    name: Sp<String>,
    mass: Sp<Value>,
    position: Sp<Value>,
    inertia: Option<Sp<Value>>,
    axes: Option<Sp<Value>>,
    inertia_tensor: Option<Sp<Value>>,
    #[allow(dead_code)]
    note: Option<String>,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum Name {
    Int(i64),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSde {
    name: Sp<Name>,
    kind: Sp<String>,
    bodies: Sp<Vec<Sp<String>>>,
    point: Sp<Value>,
    axes: Option<Sp<Value>>,
    axis: Option<Sp<Value>>,
    enabled: Option<bool>,
    #[allow(dead_code)]
    note: Option<String>,
    area: Option<Sp<Value>>,
    moments: Option<Sp<Value>>,
    size: Option<Sp<Value>>,
    inner_radius: Option<Sp<Value>>,
    outer_radius: Option<Sp<Value>>,
    kn: Option<Sp<Value>>,
    kt: Option<Sp<Value>>,
    kn_kt_ratio: Option<Sp<Value>>,
    psi_n: Option<Sp<Value>>,
    psi_t: Option<Sp<Value>>,
    k: Option<Sp<Value>>,
    psi: Option<Sp<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExcitation {
    #[serde(default)]
    force: Vec<RawForce>,
    #[serde(default)]
    pair: Vec<RawPair>,
}

/// A direction given as a vector or by angles.
struct RawDirection {
    direction: Option<Sp<Value>>,
    alpha: Option<Sp<Value>>,
    beta: Option<Sp<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawForce {
    body: Sp<String>,
    point: Option<Sp<Value>>,
    force: Option<Sp<Value>>,
    amplitude: Option<Sp<Value>>,
    moment: Option<Sp<Value>>,
    direction: Option<Sp<Value>>,
    alpha: Option<Sp<Value>>,
    beta: Option<Sp<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPair {
    bodies: Sp<Vec<Sp<String>>>,
    point: Sp<Value>,
    reaction_point: Option<Sp<Value>>,
    amplitude: Sp<Value>,
    direction: Option<Sp<Value>>,
    alpha: Option<Sp<Value>>,
    beta: Option<Sp<Value>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    body: Sp<String>,
    dof: Option<Sp<String>>,
    dofs: Option<Sp<Vec<Sp<String>>>>,
    quantity: Option<Sp<String>>,
    point: Option<Sp<Value>>,
    direction: Option<Sp<Value>>,
    reference: Option<Sp<String>>,
    motion: Option<Sp<String>>,
}

/// Locates errors in the TOML text.
struct Ctx<'a> {
    src: SourceText<'a>,
}

impl Ctx<'_> {
    fn at(&self, span: Range<usize>, message: impl Into<String>) -> LoadError {
        LoadError::Toml(self.src.at(span, message))
    }

    fn scalar(&self, v: &Sp<Value>, dim: Dim, field: &str) -> Result<f64, LoadError> {
        let x = match v.get_ref() {
            Value::Num(x) => *x,
            Value::Text(t) => {
                parse_quantity(t, dim).map_err(|e| self.at(v.span(), format!("{field}: {e}")))?
            }
            Value::List(_) => {
                return Err(self.at(
                    v.span(),
                    format!(
                        "{field}: expected one value, {}, not a list",
                        dim.describe()
                    ),
                ))
            }
        };
        if !x.is_finite() {
            return Err(self.at(v.span(), format!("{field}: {x} is not a finite number")));
        }
        Ok(x)
    }

    /// A list of `n` values with per-entry dimensions: `[1, "2 mm", 3]` or `"1 2 3 mm"`.
    fn vector(&self, v: &Sp<Value>, dims: &[Dim], field: &str) -> Result<Vec<f64>, LoadError> {
        let n = dims.len();
        let values: Vec<f64> = match v.get_ref() {
            Value::Text(t) => {
                if dims.iter().any(|d| *d != dims[0]) {
                    // mixed dimensions cannot share one unit; parse each number as SI + unit check
                    return Err(self.at(v.span(), format!("{field}: give a list of {n} values, each with its own unit")));
                }
                parse_quantities(t, dims[0]).map_err(|e| self.at(v.span(), format!("{field}: {e}")))?
            }
            Value::List(items) => {
                if items.len() != n {
                    return Err(self.at(v.span(), format!("{field}: expected {n} values, found {}", items.len())));
                }
                let mut out = Vec::with_capacity(n);
                for (item, d) in items.iter().zip(dims) {
                    out.push(match item {
                        Value::Num(x) => *x,
                        Value::Text(t) => parse_quantity(t, *d).map_err(|e| self.at(v.span(), format!("{field}: {e}")))?,
                        Value::List(_) => return Err(self.at(v.span(), format!("{field}: expected {n} numbers, found a nested list"))),
                    });
                }
                out
            }
            Value::Num(_) => {
                return Err(self.at(v.span(), format!("{field}: expected a list of {n} values, e.g. [0.0, 0.45, 0.95] or \"0 450 950 mm\"")))
            }
        };
        if values.len() != n {
            return Err(self.at(
                v.span(),
                format!("{field}: expected {n} values, found {}", values.len()),
            ));
        }
        if values.iter().any(|x| !x.is_finite()) {
            return Err(self.at(v.span(), format!("{field}: values must be finite numbers")));
        }
        Ok(values)
    }

    fn vec3(&self, v: &Sp<Value>, dim: Dim, field: &str) -> Result<Vector3<f64>, LoadError> {
        let x = self.vector(v, &[dim; 3], field)?;
        Ok(Vector3::new(x[0], x[1], x[2]))
    }

    fn direction(&self, v: &Sp<Value>, field: &str) -> Result<Vector3<f64>, LoadError> {
        let d = self.vec3(v, Dim::NONE, field)?;
        let n = d.norm();
        if n < 1e-12 {
            return Err(self.at(
                v.span(),
                format!("{field}: the direction has zero length; give a non-zero vector"),
            ));
        }
        Ok(d / n)
    }

    /// Three axes given as rows `[[a1], [a2], [a3]]` → `global_from_local` (axes as columns).
    fn axes(&self, v: &Sp<Value>, field: &str) -> Result<Matrix3<f64>, LoadError> {
        let Value::List(rows) = v.get_ref() else {
            return Err(self.at(
                v.span(),
                format!("{field}: expected three axis vectors, e.g. [[1,0,0],[0,1,0],[0,0,1]]"),
            ));
        };
        if rows.len() != 3 {
            return Err(self.at(
                v.span(),
                format!("{field}: expected three axis vectors, found {}", rows.len()),
            ));
        }
        let mut m = Matrix3::zeros();
        for (j, row) in rows.iter().enumerate() {
            let Value::List(xs) = row else {
                return Err(self.at(
                    v.span(),
                    format!("{field}: axis {} is not a list of three numbers", j + 1),
                ));
            };
            if xs.len() != 3 {
                return Err(self.at(
                    v.span(),
                    format!(
                        "{field}: axis {} has {} components, expected 3",
                        j + 1,
                        xs.len()
                    ),
                ));
            }
            for (i, x) in xs.iter().enumerate() {
                let Value::Num(x) = x else {
                    return Err(self.at(
                        v.span(),
                        format!("{field}: axis components are plain numbers"),
                    ));
                };
                m[(i, j)] = *x;
            }
        }
        // Accept axes written to a few decimals: orthonormal to 1e-4, then made exact.
        for j in 0..3 {
            let n = m.column(j).norm();
            if n < 1e-12 {
                return Err(self.at(v.span(), format!("{field}: axis {} has zero length", j + 1)));
            }
        }
        if let Some(msg) = rotation_problem(&m, 1e-4) {
            return Err(self.at(v.span(), format!("{field}: {msg}")));
        }
        Ok(orthonormalize(&m))
    }
}

/// The nearest rotation (polar decomposition via SVD) to an almost-orthonormal matrix.
fn orthonormalize(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => u * vt,
        _ => *m,
    }
}

/// A right-handed frame whose first axis is `a` (unit): the second is perpendicular to `a` and
/// to the global axis least aligned with it.
pub fn frame_from_axis(a: &Vector3<f64>) -> Matrix3<f64> {
    let e1 = a.normalize();
    let g = [Vector3::x(), Vector3::y(), Vector3::z()]
        .into_iter()
        .min_by(|x, y| e1.dot(x).abs().total_cmp(&e1.dot(y).abs()))
        .unwrap_or(Vector3::x());
    let e2 = e1.cross(&g).normalize();
    let e3 = e1.cross(&e2);
    Matrix3::from_columns(&[e1, e2, e3])
}

/// Parses the TOML model format.
pub fn parse_toml(text: &str, origin: &str) -> Result<Loaded, LoadError> {
    let text = crate::source::strip_bom(text);
    let cx = Ctx {
        src: SourceText::new(origin, text),
    };
    let raw: RawModel = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let msg = e.message().trim().to_string();
        let hint = if msg.contains("unknown field") {
            " (see docs/model-format.md for every key)"
        } else {
            ""
        };
        cx.at(span, format!("{msg}{hint}"))
    })?;
    // Spans of each element's fields, for locating physical problems found after resolution.
    let mut spans: Spans = Vec::new();
    let mut bodies = Vec::new();
    for (i, b) in raw.bodies.iter().enumerate() {
        let body = body(&cx, i, b, &bodies, &mut spans)?;
        bodies.push(body);
    }
    let mut sdes = Vec::new();
    for (i, s) in raw.sdes.iter().enumerate() {
        sdes.push(sde(&cx, i, s, &bodies, &mut spans)?);
    }
    let mut forces = Vec::new();
    if let Some(ex) = &raw.excitation {
        for f in &ex.force {
            forces.push(point_force(&cx, f, &bodies)?);
        }
        for p in &ex.pair {
            forces.extend(force_pair(&cx, p, &bodies)?);
        }
    }
    let mut references: Vec<Reference> = Vec::new();
    for r in &raw.references {
        let name = r.name.get_ref().trim();
        if name.is_empty() || name == "excitation" || references.iter().any(|x| x.name == name) {
            return Err(cx.at(r.name.span(), format!("reference name \"{name}\": give each [[reference]] a unique, non-empty name other than \"excitation\" (the model's own [excitation])")));
        }
        let excitation = match &r.base_motion {
            Some(b) => {
                if let Some(f) = r.force.first() {
                    return Err(cx.at(
                        f.body.span(),
                        "a reference is either forces or a base motion, not both",
                    ));
                }
                if !r.pair.is_empty() {
                    return Err(cx.at(
                        b.span(),
                        "a reference is either forces or a base motion, not both",
                    ));
                }
                let d = cx.direction(b, "base_motion")?;
                Excitation::BaseMotion {
                    direction: d.into(),
                }
            }
            None => {
                let mut f = Vec::new();
                for x in &r.force {
                    f.push(point_force(&cx, x, &bodies)?);
                }
                for p in &r.pair {
                    f.extend(force_pair(&cx, p, &bodies)?);
                }
                if f.is_empty() {
                    return Err(cx.at(r.name.span(), "the reference has no excitation: give [[reference.force]], [[reference.pair]] or base_motion = [x, y, z]"));
                }
                Excitation::Forces(f)
            }
        };
        references.push(Reference {
            name: name.to_string(),
            excitation,
        });
    }
    let mut outputs = Vec::new();
    for o in &raw.outputs {
        let mut cs = output(&cx, o, &bodies)?;
        let reference = match &o.reference {
            None => 0,
            Some(r) => {
                let name = r.get_ref().trim();
                match references.iter().position(|x| x.name == name) {
                    Some(i) => u8::try_from(i + 1)
                        .map_err(|_| cx.at(r.span(), "at most 255 references"))?,
                    None if name == "excitation" => 0,
                    None => {
                        let known: Vec<&str> = references.iter().map(|x| x.name.as_str()).collect();
                        return Err(cx.at(r.span(), format!("reference: the model has no [[reference]] \"{name}\"; its references: excitation{}{}", if known.is_empty() { "" } else { ", " }, known.join(", "))));
                    }
                }
            }
        };
        let relative = match &o.motion {
            None => false,
            Some(m) => {
                let base = reference > 0
                    && matches!(
                        references[reference as usize - 1].excitation,
                        Excitation::BaseMotion { .. }
                    );
                match m.get_ref().as_str() {
                    _ if !base => return Err(cx.at(m.span(), "motion: absolute or relative motion is an output under base motion; name a [[reference]] with base_motion in `reference`")),
                    "absolute" => false,
                    "relative" => true,
                    other => return Err(cx.at(m.span(), format!("motion: \"{other}\" is neither \"absolute\" (transmissibility) nor \"relative\" (response − base)"))),
                }
            }
        };
        for c in &mut cs {
            c.reference = reference;
            c.relative = relative;
        }
        outputs.extend(cs);
    }
    let mut point_masses = Vec::new();
    for (i, p) in raw.point_masses.iter().enumerate() {
        point_masses.push(point_mass(&cx, i, p, &bodies, &point_masses, &mut spans)?);
    }
    let model = Model {
        name: raw.name.unwrap_or_else(|| origin.to_string()),
        bodies,
        sdes,
        forces,
        references,
        outputs,
        point_masses,
    };
    checked(&cx, model, &spans)
}

/// Where each element's fields are in the text, for problems found after resolution.
type Spans = Vec<(Item, Range<usize>)>;

/// Body `i` of the file; `earlier` are the bodies before it (names must be unique).
fn body(
    cx: &Ctx,
    i: usize,
    b: &RawBody,
    earlier: &[Body],
    spans: &mut Spans,
) -> Result<Body, LoadError> {
    let name = b.name.get_ref().trim().to_string();
    if name.is_empty() || name == "ground" {
        return Err(cx.at(
            b.name.span(),
            "body name must be non-empty and not \"ground\" (reserved for the fixed ground)",
        ));
    }
    if let Some(j) = earlier.iter().position(|o: &Body| o.name == name) {
        return Err(cx.at(
            b.name.span(),
            format!(
                "body name \"{name}\" is used twice (bodies {} and {}); names must be unique",
                j + 1,
                i + 1
            ),
        ));
    }
    spans.push((Item::Body(i, "name"), b.name.span()));
    spans.push((Item::Body(i, "mass"), b.mass.span()));
    spans.push((Item::Body(i, "position"), b.position.span()));
    let mass = cx.scalar(&b.mass, Dim::MASS, "mass")?;
    if mass <= 0.0 {
        return Err(cx.at(
            b.mass.span(),
            format!("body \"{name}\": mass must be positive, got {mass} kg"),
        ));
    }
    let position = cx.vec3(&b.position, Dim::LENGTH, "position")?;
    let (inertia, rotation) = match (&b.inertia, &b.inertia_tensor) {
        (Some(_), Some(t)) => {
            return Err(cx.at(t.span(), format!("body \"{name}\": give either `inertia` (principal moments, with `axes`) or `inertia_tensor`, not both")))
        }
        (None, None) => {
            return Err(cx.at(b.name.span(), format!("body \"{name}\" has no inertia: add `inertia = [J1, J2, J3]` (principal central moments, kg m^2) or `inertia_tensor` (3×3, global frame)")))
        }
        (Some(j), None) => {
            spans.push((Item::Body(i, "inertia"), j.span()));
            let j3 = cx.vector(j, &[Dim::INERTIA; 3], "inertia")?;
            if j3.iter().any(|x| *x <= 0.0) {
                return Err(cx.at(j.span(), format!("body \"{name}\": principal moments of inertia must be positive, got {j3:?}")));
            }
            let rotation = match &b.axes {
                Some(a) => {
                    spans.push((Item::Body(i, "rotation"), a.span()));
                    cx.axes(a, "axes")?
                }
                None => Matrix3::identity(),
            };
            ([j3[0], j3[1], j3[2]], rotation)
        }
        (None, Some(t)) => {
            if let Some(a) = &b.axes {
                return Err(cx.at(a.span(), format!("body \"{name}\": `axes` goes with `inertia`; with `inertia_tensor` the principal axes are computed")));
            }
            spans.push((Item::Body(i, "inertia"), t.span()));
            principal_axes(cx, t, &name)?
        }
    };
    Ok(Body {
        name,
        mass,
        inertia,
        position,
        rotation,
    })
}

/// Point mass `i` of the file; `earlier` are the ones before it (names must be unique).
fn point_mass(
    cx: &Ctx,
    i: usize,
    p: &RawPointMass,
    bodies: &[Body],
    earlier: &[PointMass],
    spans: &mut Spans,
) -> Result<PointMass, LoadError> {
    let name = p.name.get_ref().trim().to_string();
    if name.is_empty() {
        return Err(cx.at(p.name.span(), "point mass name must be non-empty"));
    }
    if earlier.iter().any(|o| o.name == name) {
        return Err(cx.at(
            p.name.span(),
            format!("point mass name \"{name}\" is used twice; names must be unique"),
        ));
    }
    let Some(body) = body_ref(cx, bodies, &p.body)? else {
        return Err(cx.at(
            p.body.span(),
            "a point mass on the ground does not move; name the body it sits on",
        ));
    };
    for (field, span) in [
        ("name", p.name.span()),
        ("body", p.body.span()),
        ("point", p.point.span()),
        ("mass", p.mass.span()),
    ] {
        spans.push((Item::PointMass(i, field), span));
    }
    let point = cx.vec3(&p.point, Dim::LENGTH, "point")?;
    let mass = cx.scalar(&p.mass, Dim::MASS, "mass")?;
    if mass <= 0.0 {
        return Err(cx.at(
            p.mass.span(),
            format!("point mass \"{name}\": mass must be positive, got {mass} kg"),
        ));
    }
    let inertia = match &p.inertia {
        None => [0.0; 3],
        Some(j) => {
            spans.push((Item::PointMass(i, "inertia"), j.span()));
            let j3 = match j.get_ref() {
                Value::List(_) => cx.vector(j, &[Dim::INERTIA; 3], "inertia")?,
                _ => vec![cx.scalar(j, Dim::INERTIA, "inertia")?; 3],
            };
            if j3.iter().any(|x| *x < 0.0) {
                return Err(cx.at(j.span(), format!("point mass \"{name}\": its own moments of inertia must be ≥ 0, got {j3:?} kg m^2")));
            }
            [j3[0], j3[1], j3[2]]
        }
    };
    Ok(PointMass {
        name,
        body,
        point,
        mass,
        inertia,
    })
}

/// The body an SDE end, force or output names: `None` for the ground.
fn body_ref(cx: &Ctx, bodies: &[Body], s: &Sp<String>) -> Result<Option<usize>, LoadError> {
    let n = s.get_ref().trim();
    if n == "ground" {
        return Ok(None);
    }
    bodies
        .iter()
        .position(|b| b.name == n)
        .map(Some)
        .ok_or_else(|| {
            let known: Vec<&str> = bodies.iter().map(|b| b.name.as_str()).collect();
            cx.at(
                s.span(),
                format!(
                    "unknown body \"{n}\"; known bodies: {} (or \"ground\")",
                    known.join(", ")
                ),
            )
        })
}

/// SDE `i` of the file.
fn sde(
    cx: &Ctx,
    i: usize,
    s: &RawSde,
    bodies: &[Body],
    spans: &mut Spans,
) -> Result<Sde, LoadError> {
    let name = match s.name.get_ref() {
        Name::Int(n) => n.to_string(),
        Name::Text(t) => t.trim().to_string(),
    };
    if name.is_empty() {
        return Err(cx.at(s.name.span(), "sde name must not be empty"));
    }
    spans.push((Item::Sde(i, "name"), s.name.span()));
    spans.push((Item::Sde(i, "bodies"), s.bodies.span()));
    spans.push((Item::Sde(i, "point"), s.point.span()));
    let kind = match s.kind.get_ref().as_str() {
        "slideway" => SdeKind::Slideway,
        "rotary" => SdeKind::Rotary,
        "screw" => SdeKind::Screw,
        "spring" => SdeKind::Spring,
        "isolator" => SdeKind::Isolator,
        "general" => SdeKind::General,
        other => {
            return Err(cx.at(s.kind.span(), format!("sde {name}: unknown kind \"{other}\"; use slideway, rotary, screw, spring, isolator or general")))
        }
    };
    let ends = s.bodies.get_ref();
    if ends.len() != 2 {
        return Err(cx.at(s.bodies.span(), format!("sde {name}: `bodies` needs two entries [p, r] (a body name or \"ground\"), found {}", ends.len())));
    }
    let pair = [
        body_ref(cx, bodies, &ends[0])?,
        body_ref(cx, bodies, &ends[1])?,
    ];
    if pair[0].is_some() && pair[0] == pair[1] {
        return Err(cx.at(s.bodies.span(), format!("sde {name} joins body \"{}\" to itself; an SDE joins two different bodies, or a body and \"ground\"", ends[0].get_ref())));
    }
    if pair == [None, None] {
        return Err(cx.at(
            s.bodies.span(),
            format!("sde {name} joins the ground to the ground; name at least one body"),
        ));
    }
    let point = cx.vec3(&s.point, Dim::LENGTH, "point")?;
    let rotation = match (&s.axes, &s.axis) {
        (Some(_), Some(a)) => return Err(cx.at(a.span(), format!("sde {name}: give `axes` (all three) or `axis` (axis 1 only), not both"))),
        (Some(a), None) => {
            spans.push((Item::Sde(i, "rotation"), a.span()));
            cx.axes(a, "axes")?
        }
        (None, Some(a)) => {
            spans.push((Item::Sde(i, "rotation"), a.span()));
            frame_from_axis(&cx.direction(a, "axis")?)
        }
        (None, None) => return Err(cx.at(s.name.span(), format!("sde {name}: give its frame, `axes = [[axis1], [axis2], [axis3]]` (axis 1 = normal / screw axis) or `axis = [x, y, z]`"))),
    };
    let law = sde_law(cx, s, kind, &name)?;
    spans.push((Item::Sde(i, "k"), s.name.span()));
    spans.push((Item::Sde(i, "psi"), s.name.span()));
    Ok(Sde {
        name,
        kind,
        bodies: pair,
        point,
        rotation,
        law,
        enabled: s.enabled.unwrap_or(true),
    })
}

/// A force (and moment) at a point of a body, `[[excitation.force]]`.
fn point_force(cx: &Ctx, f: &RawForce, bodies: &[Body]) -> Result<PointForce, LoadError> {
    let Some(body) = body_ref(cx, bodies, &f.body)? else {
        return Err(cx.at(
            f.body.span(),
            "a force cannot act on the ground; name a body",
        ));
    };
    let point = match &f.point {
        Some(p) => cx.vec3(p, Dim::LENGTH, "point")?,
        None => bodies[body].position,
    };
    let dir = RawDirection {
        direction: f.direction.clone(),
        alpha: f.alpha.clone(),
        beta: f.beta.clone(),
    };
    let force = match (&f.force, &f.amplitude) {
        (Some(v), None) => {
            if dir.direction.is_some() || dir.alpha.is_some() || dir.beta.is_some() {
                return Err(cx.at(v.span(), "`force` is a full vector; drop `direction`/`alpha`/`beta` or use `amplitude` with them"));
            }
            cx.vec3(v, Dim::FORCE, "force")?
        }
        (None, Some(a)) => cx.scalar(a, Dim::FORCE, "amplitude")? * direction(cx, &dir, a.span())?,
        (None, None) => Vector3::zeros(),
        (Some(v), Some(_)) => {
            return Err(cx.at(
                v.span(),
                "give either `force` (a vector) or `amplitude` with a direction, not both",
            ))
        }
    };
    let moment = match &f.moment {
        Some(m) => cx.vec3(m, Dim::MOMENT, "moment")?,
        None => Vector3::zeros(),
    };
    if force == Vector3::zeros() && moment == Vector3::zeros() {
        return Err(cx.at(
            f.body.span(),
            "this force has neither `force`, `amplitude` nor `moment`; give at least one",
        ));
    }
    Ok(PointForce {
        body,
        point,
        force,
        moment,
    })
}

/// Equal and opposite forces on two bodies, `[[excitation.pair]]` (an actuator between them).
fn force_pair(cx: &Ctx, p: &RawPair, bodies: &[Body]) -> Result<[PointForce; 2], LoadError> {
    let ends = p.bodies.get_ref();
    if ends.len() != 2 {
        return Err(cx.at(
            p.bodies.span(),
            "a force pair acts between two bodies: bodies = [\"acted on\", \"reacting\"]",
        ));
    }
    let (Some(a), Some(b)) = (
        body_ref(cx, bodies, &ends[0])?,
        body_ref(cx, bodies, &ends[1])?,
    ) else {
        return Err(cx.at(p.bodies.span(), "a force pair acts between two bodies, not the ground; use [[excitation.force]] for a grounded exciter"));
    };
    if a == b {
        return Err(cx.at(
            p.bodies.span(),
            "a force pair between a body and itself does nothing; name two bodies",
        ));
    }
    let point = cx.vec3(&p.point, Dim::LENGTH, "point")?;
    let reaction = match &p.reaction_point {
        Some(r) => cx.vec3(r, Dim::LENGTH, "reaction_point")?,
        None => point,
    };
    let amp = cx.scalar(&p.amplitude, Dim::FORCE, "amplitude")?;
    let dir = RawDirection {
        direction: p.direction.clone(),
        alpha: p.alpha.clone(),
        beta: p.beta.clone(),
    };
    let f = amp * direction(cx, &dir, p.amplitude.span())?;
    Ok([
        PointForce {
            body: a,
            point,
            force: f,
            moment: Vector3::zeros(),
        },
        PointForce {
            body: b,
            point: reaction,
            force: -f,
            moment: Vector3::zeros(),
        },
    ])
}

/// The characteristics one `[[output]]` declares.
fn output(cx: &Ctx, o: &RawOutput, bodies: &[Body]) -> Result<Vec<Characteristic>, LoadError> {
    let Some(body) = body_ref(cx, bodies, &o.body)? else {
        return Err(cx.at(o.body.span(), "the ground does not move; name a body"));
    };
    let quantity = match &o.quantity {
        None => Quantity::Displacement,
        Some(q) => Quantity::parse(q.get_ref()).ok_or_else(|| {
            cx.at(
                q.span(),
                format!(
                    "unknown quantity \"{}\"; use displacement, velocity or acceleration",
                    q.get_ref()
                ),
            )
        })?,
    };
    match (&o.point, &o.direction) {
        (None, None) => {}
        (Some(p), Some(d)) => {
            if let Some(x) = o
                .dof
                .as_ref()
                .map(|d| d.span())
                .or(o.dofs.as_ref().map(|d| d.span()))
            {
                return Err(cx.at(x, "a point output (`point` + `direction`) names no `dof`/`dofs`; drop one or the other"));
            }
            let point = cx.vec3(p, Dim::LENGTH, "point")?;
            let direction = cx.vec3(d, Dim::NONE, "direction")?;
            let Some(at) = PointOutput::new(point, direction) else {
                return Err(cx.at(d.span(), "direction: the zero vector has no direction; give the sensor's axis, e.g. [0, 1, 0] (global)"));
            };
            let (dof, _) = at.nearest_axis(&bodies[body]);
            return Ok(vec![Characteristic {
                body,
                dof,
                quantity,
                at: Some(at),
                reference: 0,
                relative: false,
            }]);
        }
        (Some(p), None) => {
            return Err(cx.at(
                p.span(),
                "a point output needs `direction = [x, y, z]` (global) beside `point`",
            ))
        }
        (None, Some(d)) => {
            return Err(cx.at(
                d.span(),
                "a point output needs `point` (global, e.g. \"100 0 450 mm\") beside `direction`",
            ))
        }
    }
    let names: Vec<&Sp<String>> = match (&o.dof, &o.dofs) {
        (Some(d), None) => vec![d],
        (None, Some(ds)) => ds.get_ref().iter().collect(),
        _ => return Err(cx.at(o.body.span(), "give `dof = \"u1\"` or `dofs = [\"u1\", \"u2\", \"u3\"]` (u1-u3 translations, r1-r3 rotations along the body's principal axes)")),
    };
    names
        .into_iter()
        .map(|d| {
            let dof = DOF_NAMES.iter().position(|n| n == d.get_ref()).ok_or_else(|| cx.at(d.span(), format!("unknown dof \"{}\"; use u1, u2, u3 (translations) or r1, r2, r3 (rotations) along the body's principal axes", d.get_ref())))?;
            Ok(Characteristic::dof(body, dof as u8, quantity))
        })
        .collect()
}

/// The model after the physical checks: the first error located by `spans`, warnings located.
fn checked(cx: &Ctx, model: Model, spans: &Spans) -> Result<Loaded, LoadError> {
    let locate = |p: &Problem| -> Range<usize> {
        spans
            .iter()
            .find(|(it, _)| *it == p.item)
            .map(|(_, s)| s.clone())
            .unwrap_or(0..0)
    };
    let (errors, warnings) = check(&model);
    if let Some(p) = errors.first() {
        return Err(cx.at(locate(p), p.message.clone()));
    }
    let warnings = warnings
        .iter()
        .map(|w| {
            let at = cx.src.at(locate(w), format!("warning: {}", w.message));
            at.to_string()
        })
        .collect();
    Ok(Loaded { model, warnings })
}

/// Unit direction from `direction = [x, y, z]` or from angles: `beta` is the angle from the
/// global +z axis, `alpha` the azimuth of the projection on the x-y plane from +x towards +y:
/// `d = [sin β cos α, sin β sin α, cos β]`.
fn direction(
    cx: &Ctx,
    d: &RawDirection,
    fallback: Range<usize>,
) -> Result<Vector3<f64>, LoadError> {
    match (&d.direction, &d.alpha, &d.beta) {
        (Some(v), None, None) => cx.direction(v, "direction"),
        (None, Some(a), Some(b)) => {
            let (a, b) = (cx.scalar(a, Dim::NONE, "alpha")?, cx.scalar(b, Dim::NONE, "beta")?);
            Ok(Vector3::new(b.sin() * a.cos(), b.sin() * a.sin(), b.cos()))
        }
        (Some(v), _, _) => Err(cx.at(v.span(), "give the direction either as a vector (`direction`) or by angles (`alpha`, `beta`), not both")),
        _ => Err(cx.at(fallback, "the force needs a direction: `direction = [x, y, z]` or both `alpha` and `beta` (e.g. alpha = \"60 deg\", beta = \"81 deg\")")),
    }
}

fn principal_axes(
    cx: &Ctx,
    t: &Sp<Value>,
    name: &str,
) -> Result<([f64; 3], Matrix3<f64>), LoadError> {
    let Value::List(rows) = t.get_ref() else {
        return Err(cx.at(
            t.span(),
            "inertia_tensor: expected three rows of three values (kg m^2, global frame)",
        ));
    };
    if rows.len() != 3 {
        return Err(cx.at(
            t.span(),
            format!("inertia_tensor: expected 3 rows, found {}", rows.len()),
        ));
    }
    let mut m = Matrix3::zeros();
    for (i, row) in rows.iter().enumerate() {
        let r = cx.vector(
            &Spanned::new(t.span(), row.clone()),
            &[Dim::INERTIA; 3],
            "inertia_tensor",
        )?;
        for j in 0..3 {
            m[(i, j)] = r[j];
        }
    }
    let asym = (m - m.transpose()).abs().max();
    if asym > 1e-9 * m.abs().max() {
        return Err(cx.at(t.span(), format!("body \"{name}\": inertia_tensor is not symmetric (largest difference {asym:.3e} kg m^2)")));
    }
    let eig = SymmetricEigen::new(m);
    let mut order = [0usize, 1, 2];
    order.sort_by(|a, b| eig.eigenvalues[*a].total_cmp(&eig.eigenvalues[*b]));
    let j = order.map(|k| eig.eigenvalues[k]);
    if j.iter().any(|x| *x <= 0.0) {
        return Err(cx.at(t.span(), format!("body \"{name}\": inertia_tensor is not positive definite (principal moments {j:?}); check signs of the products of inertia")));
    }
    let mut r = Matrix3::from_columns(&order.map(|k| eig.eigenvectors.column(k).into_owned()));
    if r.determinant() < 0.0 {
        r.set_column(2, &(-r.column(2)));
    }
    Ok((j, r))
}

/// Fields allowed per kind, for error messages about fields that do not apply.
fn allowed(kind: SdeKind) -> &'static [&'static str] {
    match kind {
        SdeKind::Slideway | SdeKind::Rotary => &[
            "area",
            "moments",
            "size",
            "inner_radius",
            "outer_radius",
            "kn",
            "kt",
            "kn_kt_ratio",
            "psi_n",
            "psi_t",
        ],
        SdeKind::Screw | SdeKind::Spring => &["k", "psi"],
        SdeKind::Isolator => &["kn", "kt", "psi", "psi_n", "psi_t"],
        SdeKind::General => &["k", "psi"],
    }
}

fn sde_law(cx: &Ctx, s: &RawSde, kind: SdeKind, name: &str) -> Result<SdeLaw, LoadError> {
    check_law_keys(cx, s, kind, name)?;
    let f = LawFields { cx, s, name };
    Ok(match kind {
        SdeKind::Slideway | SdeKind::Rotary => contact_law(&f)?,
        SdeKind::Screw | SdeKind::Spring => SdeLaw::Axial {
            k: f.need(&s.k, "k", Dim::STIFFNESS)?,
            psi: f.need(&s.psi, "psi", Dim::NONE)?,
        },
        SdeKind::Isolator => isolator_law(&f)?,
        SdeKind::General => general_law(&f)?,
    })
}

/// Every law key given must apply to the SDE's kind.
fn check_law_keys(cx: &Ctx, s: &RawSde, kind: SdeKind, name: &str) -> Result<(), LoadError> {
    let present: [(&str, &Option<Sp<Value>>); 12] = [
        ("area", &s.area),
        ("moments", &s.moments),
        ("size", &s.size),
        ("inner_radius", &s.inner_radius),
        ("outer_radius", &s.outer_radius),
        ("kn", &s.kn),
        ("kt", &s.kt),
        ("kn_kt_ratio", &s.kn_kt_ratio),
        ("psi_n", &s.psi_n),
        ("psi_t", &s.psi_t),
        ("k", &s.k),
        ("psi", &s.psi),
    ];
    for (field, v) in present {
        if let Some(v) = v {
            if !allowed(kind).contains(&field) {
                return Err(cx.at(
                    v.span(),
                    format!(
                        "sde {name}: `{field}` does not apply to a {} (its keys: {})",
                        kind.as_str(),
                        allowed(kind).join(", ")
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// An SDE's law keys being read.
struct LawFields<'a> {
    cx: &'a Ctx<'a>,
    s: &'a RawSde,
    name: &'a str,
}

impl LawFields<'_> {
    /// A required non-negative value of dimension `dim`.
    fn need(&self, v: &Option<Sp<Value>>, field: &str, dim: Dim) -> Result<f64, LoadError> {
        let (cx, name) = (self.cx, self.name);
        match v {
            Some(v) => {
                let x = cx.scalar(v, dim, field)?;
                if x < 0.0 {
                    return Err(cx.at(
                        v.span(),
                        format!("sde {name}: `{field}` must be ≥ 0, got {x}"),
                    ));
                }
                Ok(x)
            }
            None => Err(cx.at(
                self.s.name.span(),
                format!("sde {name}: missing `{field}` ({})", dim.describe()),
            )),
        }
    }
}

/// A slideway's or rotary joint's contact law: area (and moments), kn, kt or kn/kt, ψn, ψt.
fn contact_law(f: &LawFields) -> Result<SdeLaw, LoadError> {
    let (cx, s, name) = (f.cx, f.s, f.name);
    let (area, moments) = contact_area(cx, s, name)?;
    let kn = f.need(&s.kn, "kn", Dim::CONTACT_STIFFNESS)?;
    let kt = match (&s.kt, &s.kn_kt_ratio) {
        (Some(_), None) => Tangential::Value(f.need(&s.kt, "kt", Dim::CONTACT_STIFFNESS)?),
        (None, Some(r)) => {
            let ratio = cx.scalar(r, Dim::NONE, "kn_kt_ratio")?;
            if ratio <= 0.0 {
                return Err(cx.at(r.span(), format!("sde {name}: kn_kt_ratio must be positive, got {ratio}")));
            }
            Tangential::Ratio(ratio)
        }
        (Some(k), Some(_)) => return Err(cx.at(k.span(), format!("sde {name}: give `kt` or `kn_kt_ratio`, not both"))),
        (None, None) => return Err(cx.at(s.name.span(), format!("sde {name}: give the tangential stiffness, `kt = \"0.02 MPa/um\"` or `kn_kt_ratio = 2.5`"))),
    };
    Ok(SdeLaw::Contact {
        area,
        moments,
        kn,
        kt,
        psi_n: f.need(&s.psi_n, "psi_n", Dim::NONE)?,
        psi_t: f.need(&s.psi_t, "psi_t", Dim::NONE)?,
    })
}

/// An isolator: kn, kt and one ψ or ψn and ψt.
fn isolator_law(f: &LawFields) -> Result<SdeLaw, LoadError> {
    let (cx, s, name) = (f.cx, f.s, f.name);
    let (psi_n, psi_t) = match (&s.psi, &s.psi_n, &s.psi_t) {
        (Some(_), None, None) => {
            let p = f.need(&s.psi, "psi", Dim::NONE)?;
            (p, p)
        }
        (None, Some(_), Some(_)) => (
            f.need(&s.psi_n, "psi_n", Dim::NONE)?,
            f.need(&s.psi_t, "psi_t", Dim::NONE)?,
        ),
        _ => {
            return Err(cx.at(
                s.name.span(),
                format!("sde {name}: give `psi` (both directions) or both `psi_n` and `psi_t`"),
            ))
        }
    };
    Ok(SdeLaw::Isolator {
        kn: f.need(&s.kn, "kn", Dim::STIFFNESS)?,
        kt: f.need(&s.kt, "kt", Dim::STIFFNESS)?,
        psi_n,
        psi_t,
    })
}

/// A general SDE: six stiffnesses and one ψ or six.
fn general_law(f: &LawFields) -> Result<SdeLaw, LoadError> {
    let (cx, s, name) = (f.cx, f.s, f.name);
    let Some(kv) = &s.k else {
        return Err(cx.at(
            s.name.span(),
            format!("sde {name}: missing `k`, six stiffnesses [N/m ×3, N·m/rad ×3]"),
        ));
    };
    let dims = [
        Dim::STIFFNESS,
        Dim::STIFFNESS,
        Dim::STIFFNESS,
        Dim::ROTATIONAL_STIFFNESS,
        Dim::ROTATIONAL_STIFFNESS,
        Dim::ROTATIONAL_STIFFNESS,
    ];
    let k = cx.vector(kv, &dims, "k")?;
    if k.iter().any(|x| *x < 0.0) {
        return Err(cx.at(kv.span(), format!("sde {name}: stiffnesses must be ≥ 0")));
    }
    let psi = match &s.psi {
        Some(p) if matches!(p.get_ref(), Value::List(_)) => cx.vector(p, &[Dim::NONE; 6], "psi")?,
        Some(_) => vec![f.need(&s.psi, "psi", Dim::NONE)?; 6],
        None => {
            return Err(cx.at(
                s.name.span(),
                format!("sde {name}: missing `psi` (one value or six)"),
            ))
        }
    };
    if psi.iter().any(|x| *x < 0.0) {
        return Err(cx.at(s.name.span(), format!("sde {name}: ψ must be ≥ 0")));
    }
    Ok(SdeLaw::General {
        k: std::array::from_fn(|i| k[i]),
        psi: std::array::from_fn(|i| psi[i]),
    })
}

/// Working area and its second moments from `area` + `moments`, `size = [a2, a3]` (a rectangle
/// with sides along axes 2 and 3) or `inner_radius` + `outer_radius` (an annulus about axis 1).
fn contact_area(cx: &Ctx, s: &RawSde, name: &str) -> Result<(f64, [f64; 3]), LoadError> {
    let (area, m) = match (&s.area, &s.size, &s.outer_radius) {
        (Some(a), None, None) => {
            let Some(mv) = &s.moments else {
                return Err(cx.at(a.span(), format!("sde {name}: with `area`, give `moments = [J1, J2, J3]` (m^4: polar about the normal, then about axes 2 and 3)")));
            };
            let m = cx.vector(mv, &[Dim::SECOND_MOMENT; 3], "moments")?;
            (cx.scalar(a, Dim::AREA, "area")?, [m[0], m[1], m[2]])
        }
        (None, Some(sz), None) => {
            let v = cx.vector(sz, &[Dim::LENGTH; 2], "size")?;
            let (a2, a3) = (v[0], v[1]);
            let j2 = a2 * a3.powi(3) / 12.0;
            let j3 = a3 * a2.powi(3) / 12.0;
            (a2 * a3, [j2 + j3, j2, j3])
        }
        (None, None, Some(ro)) => {
            let ro = cx.scalar(ro, Dim::LENGTH, "outer_radius")?;
            let ri = match &s.inner_radius {
                Some(r) => cx.scalar(r, Dim::LENGTH, "inner_radius")?,
                None => 0.0,
            };
            if !(0.0..ro).contains(&ri) {
                return Err(cx.at(s.name.span(), format!("sde {name}: need 0 ≤ inner_radius < outer_radius")));
            }
            let pi = std::f64::consts::PI;
            let j = pi * (ro.powi(4) - ri.powi(4)) / 4.0;
            (pi * (ro * ro - ri * ri), [2.0 * j, j, j])
        }
        _ => return Err(cx.at(s.name.span(), format!("sde {name}: give the working area once: `area` + `moments`, `size = [a2, a3]` (rectangle), or `outer_radius` (+ `inner_radius`) for an annulus"))),
    };
    if area <= 0.0 || m.iter().any(|x| *x < 0.0) {
        return Err(cx.at(
            s.name.span(),
            format!("sde {name}: the working area must be positive and its moments ≥ 0"),
        ));
    }
    if s.moments.is_some() && s.area.is_none() {
        return Err(cx.at(
            s.name.span(),
            format!("sde {name}: `moments` goes with `area`"),
        ));
    }
    Ok((area, m))
}
