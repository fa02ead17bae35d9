//! Decision variables: which SDE parameters, body masses and inertias, and sensor gains an
//! identification estimates, read from a variables TOML file (`configs/identification/*.toml`,
//! documented in `docs/identification.md`).
//!
//! A variable `x` (SI) sets one or more parameters `p_j = ratio_j · x`: a single parameter, a
//! group sharing one value (ratio 1), parameters tied by fixed ratios, or (`tie = "scale"`) a
//! dimensionless factor on the model's current values. Each has an initial value, bounds and an
//! internal scale `x_scale` (the optimizers work on `x / x_scale`, so variables of different
//! units converge alike).

use std::ops::Range;
use std::path::Path;

use serde::Deserialize;
use serde_spanned::Spanned;

use rfe::model::{Model, Param, ParamName, ParamRef, SdeLaw, DOF_NAMES};
use rfe::source::{Located, Quantity, SourceText};
use rfe::units::{parse_quantity, Dim};

/// Why a variables file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum VarsError {
    /// The file could not be read.
    #[error("{path}: cannot read the variables file")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A problem at a line and column.
    #[error(transparent)]
    At(#[from] Located),
}

/// One parameter a variable sets: `param = ratio · x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// The parameter: an SDE's, a body's mass or inertia, or a characteristic's gain.
    pub param: Param,
    /// Fixed ratio (1 for a shared value).
    pub ratio: f64,
}

/// How a value is shown in reports: `shown = x / factor`, with `symbol` as its unit.
#[derive(Debug, Clone, PartialEq)]
pub struct DisplayUnit {
    /// e.g. `MPa/um`, `N/um`, `-`.
    pub symbol: String,
    /// SI per displayed unit (1e12 for MPa/µm).
    pub factor: f64,
}

/// How a variable's parameters relate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tie {
    /// Every parameter equals `ratio · x` (ratio 1 unless given): the variable has the
    /// parameters' unit.
    Equal,
    /// `x` is a dimensionless factor on the model's values (`ratio_j` = the model's value).
    Scale,
}

/// A decision variable.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Name used in reports and identifiability messages.
    pub name: String,
    /// What it acts on, for the report table: the SDE names, compressed (`"2-10, 13-17"`), or
    /// `"body table, carriage"`, or the characteristics (`"table u1"`).
    pub sdes: String,
    /// Which kind of element the targets belong to (the key the file named them with).
    pub on: On,
    /// The parameter name (as written in files) of the targets.
    pub parameter: String,
    /// The parameters it sets.
    pub targets: Vec<Target>,
    /// How they relate.
    pub tie: Tie,
    /// Initial value (SI, or the factor for [`Tie::Scale`]).
    pub initial: f64,
    /// Lower bound (same unit), ≥ 0 for stiffnesses and ψ.
    pub lower: f64,
    /// Upper bound, `f64::INFINITY` when none.
    pub upper: f64,
    /// Internal scale: optimizers see `x / scale`.
    pub scale: f64,
    /// Unit for reports.
    pub unit: DisplayUnit,
    /// True for dissipation (ψ) variables.
    pub dissipation: bool,
}

/// The kind of element a variable's parameters belong to: the key that names them in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum On {
    /// `sdes = …`: SDE law parameters.
    Sdes,
    /// `bodies = …`: masses and principal inertias.
    Bodies,
    /// `characteristics = …`: sensor gains.
    Characteristics,
    /// `point_masses = …`: masses added to bodies at points (`[[point_mass]]`).
    PointMasses,
}

impl On {
    /// The key in variables files.
    pub fn key(&self) -> &'static str {
        match self {
            On::Sdes => "sdes",
            On::Bodies => "bodies",
            On::Characteristics => "characteristics",
            On::PointMasses => "point_masses",
        }
    }
}

/// The decision variables of one identification.
#[derive(Debug, Clone, PartialEq)]
pub struct Variables {
    /// File name (for messages).
    pub origin: String,
    /// The variables, in file order.
    pub vars: Vec<Variable>,
    /// Further starting points (SI, one value per variable) tried after the initial values
    /// and before any Latin-hypercube starts: e.g. a modal pre-fit's (`ident identify --start
    /// auto`). The best fit of all is kept.
    pub extra_starts: Vec<Vec<f64>>,
}

impl Variables {
    /// Number of variables.
    pub fn len(&self) -> usize {
        self.vars.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.vars.is_empty()
    }

    /// Initial values (SI).
    pub fn initial(&self) -> Vec<f64> {
        self.vars.iter().map(|v| v.initial).collect()
    }

    /// Writes values `x` (SI) into the model's parameters (SDE parameters, masses, inertias;
    /// gains are not part of the model: see [`Variables::gain`]).
    pub fn apply(&self, model: &mut Model, x: &[f64]) {
        for (v, &xi) in self.vars.iter().zip(x) {
            for t in &v.targets {
                model.set_value(t.param, t.ratio * xi);
            }
        }
    }

    /// Every SDE parameter any variable sets, without repeats, in variable order.
    pub fn params(&self) -> Vec<ParamRef> {
        let mut ps: Vec<ParamRef> = Vec::new();
        for p in self.model_params() {
            if let Param::Sde(r) = p {
                ps.push(r);
            }
        }
        ps
    }

    /// Every parameter of the model any variable sets (SDE parameters, masses, inertias; not
    /// gains), without repeats, in variable order.
    pub fn model_params(&self) -> Vec<Param> {
        let mut ps: Vec<Param> = Vec::new();
        for v in &self.vars {
            for t in &v.targets {
                if !matches!(t.param, Param::Gain { .. }) && !ps.contains(&t.param) {
                    ps.push(t.param);
                }
            }
        }
        ps
    }

    /// The variable that sets the gain of the characteristics of `body`, DOF `dof`, and its
    /// ratio (`gain = ratio · x[variable]`); `None` when no variable does (the gain is 1).
    pub fn gain(&self, body: usize, dof: u8) -> Option<(usize, f64)> {
        self.vars.iter().enumerate().find_map(|(i, v)| {
            v.targets
                .iter()
                .find(|t| t.param == Param::Gain { body, dof })
                .map(|t| (i, t.ratio))
        })
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default, rename = "variable")]
    variables: Vec<RawVariable>,
    #[allow(dead_code)]
    note: Option<String>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum Value {
    Num(f64),
    Text(String),
}

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum SdeList {
    One(Value),
    Many(Vec<Value>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVariable {
    name: Option<Spanned<String>>,
    #[serde(alias = "sde")]
    sdes: Option<Spanned<SdeList>>,
    #[serde(alias = "body")]
    bodies: Option<Spanned<SdeList>>,
    #[serde(alias = "characteristic")]
    characteristics: Option<Spanned<SdeList>>,
    #[serde(alias = "point_mass")]
    point_masses: Option<Spanned<SdeList>>,
    parameter: Spanned<String>,
    initial: Option<Spanned<Quantity>>,
    lower: Option<Spanned<Quantity>>,
    upper: Option<Spanned<Quantity>>,
    scale: Option<Spanned<Quantity>>,
    unit: Option<Spanned<String>>,
    tie: Option<Spanned<String>>,
    ratios: Option<Spanned<Vec<f64>>>,
    #[allow(dead_code)]
    note: Option<String>,
}

impl RawVariable {
    /// The one key that names the elements (`sdes`, `bodies` or `characteristics`), if exactly one.
    fn elements(&self) -> Result<(On, &Spanned<SdeList>), usize> {
        let given: Vec<(On, &Spanned<SdeList>)> = [
            (On::Sdes, &self.sdes),
            (On::Bodies, &self.bodies),
            (On::Characteristics, &self.characteristics),
            (On::PointMasses, &self.point_masses),
        ]
        .into_iter()
        .filter_map(|(on, l)| l.as_ref().map(|l| (on, l)))
        .collect();
        match given.as_slice() {
            [one] => Ok(*one),
            _ => Err(given.len()),
        }
    }

    /// Where the elements are named, for messages.
    fn names_span(&self) -> Range<usize> {
        match self.elements() {
            Ok((_, l)) => l.span(),
            Err(_) => self.parameter.span(),
        }
    }

    /// Where `key` is written, or the element names when it is not.
    fn span_or_names<T>(&self, key: &Option<Spanned<T>>) -> Range<usize> {
        key.as_ref()
            .map(|k| k.span())
            .unwrap_or_else(|| self.names_span())
    }
}

struct Ctx<'a> {
    src: SourceText<'a>,
}

impl Ctx<'_> {
    fn at(&self, span: Range<usize>, message: impl Into<String>) -> VarsError {
        VarsError::At(self.src.at(span, message))
    }

    fn value(&self, v: &Spanned<Quantity>, dim: Dim, field: &str) -> Result<f64, VarsError> {
        Ok(self.src.quantity(v, dim, field)?)
    }
}

/// Dimension of a parameter of a law.
fn param_dim(law: &SdeLaw, p: ParamName) -> Dim {
    match (law, p) {
        (_, p) if p.is_dissipation() => Dim::NONE,
        (SdeLaw::Contact { .. }, _) => Dim::CONTACT_STIFFNESS,
        (SdeLaw::General { .. }, ParamName::Ki(i)) if i >= 3 => Dim::ROTATIONAL_STIFFNESS,
        _ => Dim::STIFFNESS,
    }
}

/// The report unit the paper uses for a dimension.
fn default_unit(dim: Dim) -> DisplayUnit {
    let (symbol, factor) = match dim {
        Dim::CONTACT_STIFFNESS => ("MPa/um", 1e12),
        Dim::STIFFNESS => ("N/um", 1e6),
        Dim::ROTATIONAL_STIFFNESS => ("N*m/rad", 1.0),
        Dim::MASS => ("kg", 1.0),
        Dim::INERTIA => ("kg·m²", 1.0),
        _ => ("-", 1.0),
    };
    DisplayUnit {
        symbol: symbol.into(),
        factor,
    }
}

/// Expands `"2-10, 13-17, 19-21"`, `"30"`, `[2, "5-7"]` into SDE names.
fn expand(list: &SdeList) -> Result<Vec<String>, String> {
    let items: Vec<Value> = match list {
        SdeList::One(v) => vec![v.clone()],
        SdeList::Many(vs) => vs.clone(),
    };
    let mut names = Vec::new();
    for it in items {
        match it {
            Value::Num(x) => {
                if x.fract() != 0.0 {
                    return Err(format!(
                        "SDE name {x} is not a whole number; write names as strings"
                    ));
                }
                names.push(format!("{}", x as i64));
            }
            Value::Text(t) => {
                for part in t.split(',').map(str::trim).filter(|p| !p.is_empty()) {
                    let range = part.split_once('-').and_then(|(a, b)| {
                        Some((a.trim().parse::<i64>().ok()?, b.trim().parse::<i64>().ok()?))
                    });
                    match range {
                        Some((a, b)) if a <= b => names.extend((a..=b).map(|i| i.to_string())),
                        Some((a, b)) => {
                            return Err(format!("range \"{part}\" runs backwards; write {b}-{a}"))
                        }
                        None => names.push(part.to_string()),
                    }
                }
            }
        }
    }
    if names.is_empty() {
        return Err(
            "no SDE named; give `sdes = \"2\"`, a list, or ranges like \"2-10, 13-17\"".into(),
        );
    }
    Ok(names)
}

/// Compresses integer names into ranges for display: `["2","3","4","7"]` → `"2-4, 7"`.
pub fn compress(names: &[String]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < names.len() {
        let Ok(a) = names[i].parse::<i64>() else {
            parts.push(names[i].clone());
            i += 1;
            continue;
        };
        let mut j = i;
        while j + 1 < names.len()
            && names[j + 1].parse::<i64>().ok() == Some(a + (j + 1 - i) as i64)
        {
            j += 1;
        }
        if j > i {
            parts.push(format!("{a}-{}", a + (j - i) as i64));
        } else {
            parts.push(a.to_string());
        }
        i = j + 1;
    }
    parts.join(", ")
}

/// Reads a variables file against a model.
pub fn load(path: &Path, model: &Model) -> Result<Variables, VarsError> {
    let text = std::fs::read_to_string(path).map_err(|source| VarsError::Io {
        path: path.display().to_string(),
        source,
    })?;
    parse(&text, &path.display().to_string(), model)
}

/// Parses a variables file against a model. Errors (with line and column): unknown SDE or
/// parameter names, disabled SDEs, parameters of different dimensions in one variable, a
/// parameter set by two variables, bounds outside the physical range (stiffness and ψ ≥ 0),
/// `lower > upper`, an initial value outside its bounds, groups whose model values differ with
/// no `initial` given, ratios that do not match the SDE list.
pub fn parse(text: &str, origin: &str, model: &Model) -> Result<Variables, VarsError> {
    let text = rfe::source::strip_bom(text);
    let cx = Ctx {
        src: SourceText::new(origin, text),
    };
    let raw: RawFile = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        let msg = e.message().trim().to_string();
        let hint = if msg.contains("unknown field") {
            " (see docs/identification.md for every key)"
        } else {
            ""
        };
        cx.at(span, format!("{msg}{hint}"))
    })?;
    if raw.variables.is_empty() {
        return Err(cx.at(
            0..0,
            "no [[variable]] tables; declare at least one decision variable",
        ));
    }
    let mut vars: Vec<Variable> = Vec::new();
    let mut owner: Vec<(Param, String)> = Vec::new();
    for rv in &raw.variables {
        let v = variable(&cx, rv, model, &vars, &owner)?;
        for t in &v.targets {
            owner.push((t.param, v.name.clone()));
        }
        vars.push(v);
    }
    Ok(Variables {
        origin: origin.into(),
        vars,
        extra_starts: Vec::new(),
    })
}

/// The parameters one variable sets, before ratios: every SDE's `param`, its dimension, and
/// the model's current values.
struct Targets {
    targets: Vec<Target>,
    dim: Dim,
    model_values: Vec<f64>,
}

/// One `[[variable]]`, checked against the model and the variables before it (`earlier`, and
/// `owner`: which variable already sets which parameter).
fn variable(
    cx: &Ctx,
    rv: &RawVariable,
    model: &Model,
    earlier: &[Variable],
    owner: &[(Param, String)],
) -> Result<Variable, VarsError> {
    let (on, list) = rv.elements().map_err(|given| {
        cx.at(
            rv.parameter.span(),
            if given == 0 {
                "no `sdes`, `bodies`, `characteristics` or `point_masses`: name what the variable sets (e.g. sdes = \"2-10\", bodies = \"table\", characteristics = \"table u1\", point_masses = \"force gauge\")"
            } else {
                "more than one of `sdes`, `bodies`, `characteristics`, `point_masses`: a variable sets parameters of one kind; split it into several [[variable]] tables"
            },
        )
    })?;
    let names = expand(list.get_ref()).map_err(|m| cx.at(list.span(), m))?;
    let pname = rv.parameter.get_ref().trim();
    let kind = kind_of(cx, rv, on, pname)?;
    let tie = tie_of(cx, rv, &kind, pname)?;
    let Targets {
        mut targets,
        dim,
        model_values,
    } = match kind {
        Kind::Sde(param) => targets(cx, rv, model, &names, param, owner)?,
        _ => element_targets(cx, rv, model, &names, &kind, owner)?,
    };
    let name = match &rv.name {
        Some(n) => n.get_ref().trim().to_string(),
        None if names.len() == 1 => format!("{pname} {}", names[0]),
        None => format!("{pname} {}", compress(&names)),
    };
    if earlier.iter().any(|v| v.name == name) {
        let span = rv.span_or_names(&rv.name);
        return Err(cx.at(
            span,
            format!("a variable named \"{name}\" already exists; give it another `name`"),
        ));
    }
    let vdim = if tie == Tie::Scale { Dim::NONE } else { dim };
    set_ratios(cx, rv, tie, &mut targets, &model_values)?;
    let unit = display_unit(cx, rv, vdim)?;
    let positive = !matches!(kind, Kind::Sde(_));
    let Values {
        initial,
        lower,
        upper,
        scale,
    } = values(
        cx,
        rv,
        (tie, positive),
        vdim,
        &unit,
        &targets,
        &model_values,
    )?;
    Ok(Variable {
        name,
        sdes: match on {
            On::Sdes | On::Characteristics => compress(&names),
            On::Bodies => format!("body {}", names.join(", ")),
            On::PointMasses => format!("point mass {}", names.join(", ")),
        },
        on,
        parameter: pname.to_string(),
        targets,
        tie,
        initial,
        lower,
        upper,
        scale,
        unit,
        dissipation: matches!(kind, Kind::Sde(p) if p.is_dissipation()),
    })
}

/// What a variable's `parameter` sets on the elements it names (`on`).
fn kind_of(cx: &Ctx, rv: &RawVariable, on: On, pname: &str) -> Result<Kind, VarsError> {
    Ok(match on {
        On::Sdes => match ParamName::parse(pname) {
            Some(p) => Kind::Sde(p),
            None => return Err(cx.at(rv.parameter.span(), format!(
                "unknown parameter \"{pname}\"; parameters are kn, kt, psi_n, psi_t (slideway, rotary, isolator), k, psi (screw, spring), k1-k6, psi1-psi6 (general); masses and inertias go with `bodies`, gains with `characteristics`"
            ))),
        },
        On::Bodies => body_kind(cx, rv, pname)?,
        On::Characteristics if pname == "gain" => Kind::Gain,
        On::Characteristics => return Err(cx.at(rv.parameter.span(), format!(
            "unknown parameter \"{pname}\" of a characteristic; the one there is is parameter = \"gain\""
        ))),
        On::PointMasses if pname == "m" => Kind::PointMass,
        On::PointMasses => return Err(cx.at(rv.parameter.span(), format!(
            "unknown parameter \"{pname}\" of a point mass; the one there is is parameter = \"m\" (its mass, kg)"
        ))),
    })
}

/// The variable's tie: one shared value (`equal`, optionally with ratios) or a factor on the
/// model's values (`scale`, the only one for a parameter that sets several values per element).
fn tie_of(cx: &Ctx, rv: &RawVariable, kind: &Kind, pname: &str) -> Result<Tie, VarsError> {
    Ok(match rv.tie.as_ref().map(|t| t.get_ref().as_str()) {
        None if kind.several() => Tie::Scale,
        Some("equal") if kind.several() => {
            let span = rv.tie.as_ref().map(|t| t.span()).unwrap_or(0..0);
            return Err(cx.at(span, format!("parameter \"{pname}\" sets several inertias of each body, so it is a factor on the model's values: use tie = \"scale\" (or leave tie out)")));
        }
        None | Some("equal") => Tie::Equal,
        Some("scale") => Tie::Scale,
        Some(other) => {
            let span = rv.tie.as_ref().map(|t| t.span()).unwrap_or(0..0);
            return Err(cx.at(span, format!("unknown tie \"{other}\"; use \"equal\" (one shared value, optionally with ratios) or \"scale\" (a factor on the model's values)")));
        }
    })
}

/// Each target's ratio: the given `ratios` (tie = "equal"), or the model's values (tie = "scale").
fn set_ratios(
    cx: &Ctx,
    rv: &RawVariable,
    tie: Tie,
    targets: &mut [Target],
    model_values: &[f64],
) -> Result<(), VarsError> {
    match (&rv.ratios, tie) {
        (Some(r), Tie::Scale) => return Err(cx.at(r.span(), "`ratios` go with tie = \"equal\"; with tie = \"scale\" the model's values are the ratios")),
        (Some(r), Tie::Equal) => {
            let rs = r.get_ref();
            if rs.len() != targets.len() {
                return Err(cx.at(r.span(), format!("{} ratios for {} SDEs; one ratio per SDE, in the order of `sdes`", rs.len(), targets.len())));
            }
            if let Some(bad) = rs.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
                return Err(cx.at(r.span(), format!("ratio {bad} must be a finite number > 0")));
            }
            for (t, &x) in targets.iter_mut().zip(rs) {
                t.ratio = x;
            }
        }
        (None, Tie::Scale) => {
            for (t, &v) in targets.iter_mut().zip(model_values) {
                t.ratio = v;
            }
        }
        (None, Tie::Equal) => {}
    }
    Ok(())
}

/// What a variable's parameter is, per element it names.
enum Kind {
    /// An SDE law parameter.
    Sde(ParamName),
    /// Inertia entries of each body: `None` the mass, `Some(a)` the principal inertia `J[a]`.
    Body(Vec<Option<u8>>),
    /// The gain of each characteristic.
    Gain,
    /// The mass of each point mass.
    PointMass,
}

impl Kind {
    /// True when each element gets several parameters (of possibly different values and units):
    /// only a factor on the model's values makes sense.
    fn several(&self) -> bool {
        matches!(self, Kind::Body(ps) if ps.len() > 1)
    }
}

/// The parameter of `bodies = …`: `m`, `J1`-`J3`, `J` (J1-J3 together) or `mJ` (m and J1-J3).
fn body_kind(cx: &Ctx, rv: &RawVariable, pname: &str) -> Result<Kind, VarsError> {
    Ok(Kind::Body(match pname {
        "m" => vec![None],
        "J1" => vec![Some(0)],
        "J2" => vec![Some(1)],
        "J3" => vec![Some(2)],
        "J" => vec![Some(0), Some(1), Some(2)],
        "mJ" => vec![None, Some(0), Some(1), Some(2)],
        _ if pname.starts_with('J') => {
            return Err(cx.at(rv.parameter.span(), format!(
                "\"{pname}\": a body has three principal inertias, J1, J2, J3 (about its principal axes 1-3); write one of them, or \"J\" for all three scaled together"
            )))
        }
        _ => {
            return Err(cx.at(rv.parameter.span(), format!(
                "unknown body parameter \"{pname}\"; a body's are m (mass, kg), J1, J2, J3 (principal inertias, kg·m²), J (J1-J3 scaled together) and mJ (mass and inertias scaled together)"
            )))
        }
    }))
}

/// The masses/inertias of the bodies, or the gains of the characteristics, in `names`: every one
/// must exist and not be set by another variable (`owner`); a body's parameters share one
/// dimension unless the variable is a factor.
fn element_targets(
    cx: &Ctx,
    rv: &RawVariable,
    model: &Model,
    names: &[String],
    kind: &Kind,
    owner: &[(Param, String)],
) -> Result<Targets, VarsError> {
    let pname = rv.parameter.get_ref().trim();
    let span = rv.names_span();
    let bodies = || {
        model
            .bodies
            .iter()
            .map(|b| b.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut params = Vec::new();
    for n in names {
        match kind {
            Kind::Body(entries) => {
                let Some(b) = model.body_index(n) else {
                    return Err(cx.at(
                        span,
                        format!(
                            "bodies: unknown body \"{n}\"; the model's bodies: {}",
                            bodies()
                        ),
                    ));
                };
                params.extend(entries.iter().map(|e| match e {
                    None => Param::Mass { body: b },
                    Some(axis) => Param::Inertia {
                        body: b,
                        axis: *axis,
                    },
                }));
            }
            Kind::Gain => {
                let (body, dof) = n.rsplit_once(char::is_whitespace).unwrap_or(("", n));
                let Some(d) = DOF_NAMES.iter().position(|x| *x == dof.trim()) else {
                    return Err(cx.at(span, format!("characteristics: \"{n}\" is not a characteristic; write the body and the DOF, e.g. \"table u1\" (DOFs u1 u2 u3 r1 r2 r3)")));
                };
                let Some(b) = model.body_index(body.trim()) else {
                    return Err(cx.at(span, format!("characteristics: \"{n}\" names an unknown body \"{}\"; the model's bodies: {}", body.trim(), bodies())));
                };
                params.push(Param::Gain {
                    body: b,
                    dof: d as u8,
                });
            }
            Kind::PointMass => {
                let Some(index) = model.point_mass_index(n) else {
                    let known: Vec<&str> =
                        model.point_masses.iter().map(|p| p.name.as_str()).collect();
                    return Err(cx.at(
                        span,
                        format!(
                            "point_masses: unknown point mass \"{n}\"; the model's [[point_mass]] names: {}",
                            if known.is_empty() { "none (declare it in the model file)".to_string() } else { known.join(", ") }
                        ),
                    ));
                };
                params.push(Param::PointMass { index });
            }
            Kind::Sde(_) => {}
        }
    }
    let mut targets: Vec<Target> = Vec::new();
    let mut model_values = Vec::new();
    let mut dim: Option<Dim> = None;
    for p in params {
        let d = match p {
            Param::Mass { .. } | Param::PointMass { .. } => Dim::MASS,
            Param::Inertia { .. } => Dim::INERTIA,
            _ => Dim::NONE,
        };
        if dim.is_some_and(|d0| d0 != d) && !kind.several() {
            return Err(cx.at(span, "one variable sets parameters of one dimension"));
        }
        dim = Some(d);
        let label = model.label(p);
        if let Some((_, other)) = owner.iter().find(|(q, _)| *q == p) {
            return Err(cx.at(span, format!("{label} is already set by variable \"{other}\"; each parameter belongs to one variable")));
        }
        if targets.iter().any(|t| t.param == p) {
            return Err(cx.at(span, format!("{label} ({pname}) is listed twice")));
        }
        targets.push(Target {
            param: p,
            ratio: 1.0,
        });
        model_values.push(model.value(p).unwrap_or(1.0));
    }
    Ok(Targets {
        targets,
        dim: dim.unwrap_or(Dim::NONE),
        model_values,
    })
}

/// A variable's initial value, bounds and scale (SI, or the factor for a scale tie).
struct Values {
    initial: f64,
    lower: f64,
    upper: f64,
    scale: f64,
}

/// The initial value (given, or implied by the model's values of a group), the bounds (within
/// the physical range) and the scale (given, else from the initial value or the bounds).
fn values(
    cx: &Ctx,
    rv: &RawVariable,
    (tie, positive): (Tie, bool),
    vdim: Dim,
    unit: &DisplayUnit,
    targets: &[Target],
    model_values: &[f64],
) -> Result<Values, VarsError> {
    let pname = rv.parameter.get_ref().trim();
    let initial = match &rv.initial {
        Some(v) => cx.value(v, vdim, "initial")?,
        None => match tie {
            Tie::Scale => 1.0,
            Tie::Equal => {
                let implied: Vec<f64> = targets
                    .iter()
                    .zip(model_values)
                    .map(|(t, v)| v / t.ratio)
                    .collect();
                let first = implied[0];
                if implied
                    .iter()
                    .any(|v| (v - first).abs() > 1e-9 * first.abs().max(f64::MIN_POSITIVE))
                {
                    return Err(cx.at(rv.names_span(), format!(
                        "the model's {pname} values of these SDEs differ ({}); give `initial` for the shared value",
                        implied.iter().map(|v| format!("{:.6}", v / unit.factor)).collect::<Vec<_>>().join(", ")
                    )));
                }
                first
            }
        },
    };
    if positive && !(initial > 0.0 && initial.is_finite()) {
        let span = rv.span_or_names(&rv.initial);
        return Err(cx.at(
            span,
            format!(
                "initial value {} {}: a mass, inertia or gain must be > 0",
                initial / unit.factor,
                unit.symbol
            ),
        ));
    }
    let lower = match &rv.lower {
        Some(v) if positive => {
            let l = cx.value(v, vdim, "lower")?;
            if l <= 0.0 {
                return Err(cx.at(v.span(), format!(
                    "lower bound {} {}: a mass, inertia or gain must stay > 0; give lower > 0 (e.g. a tenth of the initial value, {} {}) or leave it out (default: a hundredth of the initial value)",
                    l / unit.factor, unit.symbol, initial / 10.0 / unit.factor, unit.symbol
                )));
            }
            l
        }
        None if positive => initial / 100.0,
        Some(v) => {
            let l = cx.value(v, vdim, "lower")?;
            if l < 0.0 {
                return Err(cx.at(v.span(), format!(
                    "lower bound {} {} is outside the physical range: stiffness and ψ are ≥ 0; use lower = 0 or more",
                    l / unit.factor, unit.symbol
                )));
            }
            l
        }
        None => 0.0,
    };
    let upper = match &rv.upper {
        Some(v) => {
            let u = cx.value(v, vdim, "upper")?;
            if u <= lower {
                return Err(cx.at(
                    v.span(),
                    format!(
                        "upper bound {} {} is not above the lower bound {} {}",
                        u / unit.factor,
                        unit.symbol,
                        lower / unit.factor,
                        unit.symbol
                    ),
                ));
            }
            u
        }
        None => f64::INFINITY,
    };
    if initial < lower || initial > upper {
        let span = rv.span_or_names(&rv.initial);
        return Err(cx.at(span, format!(
            "initial value {} {} is outside the bounds [{}, {}] {}; move it inside or widen the bounds",
            initial / unit.factor, unit.symbol, lower / unit.factor, upper / unit.factor, unit.symbol
        )));
    }
    let scale = natural_scale(cx, rv, (vdim, unit), initial, (lower, upper))?;
    Ok(Values {
        initial,
        lower,
        upper,
        scale,
    })
}

/// The variable's scale: `scale` if given, else |initial|, else the width of the bounds.
fn natural_scale(
    cx: &Ctx,
    rv: &RawVariable,
    (vdim, unit): (Dim, &DisplayUnit),
    initial: f64,
    (lower, upper): (f64, f64),
) -> Result<f64, VarsError> {
    Ok(match &rv.scale {
        Some(v) => {
            let s = cx.value(v, vdim, "scale")?;
            if s <= 0.0 {
                return Err(cx.at(v.span(), "scale must be > 0"));
            }
            s
        }
        None if initial.abs() > 0.0 => initial.abs(),
        None if upper.is_finite() => upper - lower,
        None => {
            let span = rv.span_or_names(&rv.initial);
            return Err(cx.at(span, format!(
                "initial value is 0 and there is no upper bound, so the variable has no natural scale; give `scale` (e.g. scale = \"1 {}\") or an `upper` bound",
                unit.symbol
            )));
        }
    })
}

/// The parameter `param` of every SDE in `names`, which must exist, be enabled, have it, share
/// one dimension, and not be set by another variable (`owner`).
fn targets(
    cx: &Ctx,
    rv: &RawVariable,
    model: &Model,
    names: &[String],
    param: ParamName,
    owner: &[(Param, String)],
) -> Result<Targets, VarsError> {
    let pname = rv.parameter.get_ref().trim();
    let mut targets = Vec::new();
    let mut dim: Option<Dim> = None;
    let mut model_values = Vec::new();
    for n in names {
        let Some(s) = model.sde_index(n) else {
            let known: Vec<&str> = model.sdes.iter().map(|s| s.name.as_str()).collect();
            return Err(cx.at(
                rv.names_span(),
                format!(
                    "unknown SDE \"{n}\"; the model's SDEs: {}",
                    known.join(", ")
                ),
            ));
        };
        let sde = &model.sdes[s];
        if !sde.enabled {
            return Err(cx.at(rv.names_span(), format!("SDE \"{n}\" is disabled in the model (enabled = false); enable it or leave it out")));
        }
        let pr = Param::Sde(ParamRef {
            sde: s,
            name: param,
        });
        let Some(value) = sde.law.get(param) else {
            let has: Vec<String> = sde.law.params().iter().map(|p| p.as_str()).collect();
            return Err(cx.at(
                rv.parameter.span(),
                format!(
                    "SDE \"{n}\" ({}) has no parameter \"{pname}\"; its parameters: {}",
                    sde.kind.as_str(),
                    has.join(", ")
                ),
            ));
        };
        let d = param_dim(&sde.law, param);
        if let Some(d0) = dim {
            if d0 != d {
                return Err(cx.at(rv.names_span(), format!(
                    "SDE \"{n}\"'s {pname} is {} but the variable's first SDE's is {}; one variable sets parameters of one dimension (use tie = \"scale\" for a factor)",
                    d.describe(), d0.describe()
                )));
            }
        }
        dim = Some(d);
        if let Some((_, other)) = owner.iter().find(|(p, _)| *p == pr) {
            return Err(cx.at(rv.names_span(), format!("SDE \"{n}\" {pname} is already set by variable \"{other}\"; each parameter belongs to one variable")));
        }
        if targets.iter().any(|t: &Target| t.param == pr) {
            return Err(cx.at(rv.names_span(), format!("SDE \"{n}\" is listed twice")));
        }
        targets.push(Target {
            param: pr,
            ratio: 1.0,
        });
        model_values.push(value);
    }
    Ok(Targets {
        targets,
        dim: dim.unwrap_or(Dim::NONE),
        model_values,
    })
}

/// The unit the variable is shown in (`unit`, default the paper's for its dimension).
fn display_unit(cx: &Ctx, rv: &RawVariable, vdim: Dim) -> Result<DisplayUnit, VarsError> {
    Ok(match &rv.unit {
        None => default_unit(vdim),
        Some(u) => {
            let sym = u.get_ref().trim();
            if sym == "-" || sym.is_empty() {
                if vdim != Dim::NONE {
                    return Err(cx.at(
                        u.span(),
                        format!(
                            "unit \"-\" is for plain numbers; this variable is {}",
                            vdim.describe()
                        ),
                    ));
                }
                DisplayUnit {
                    symbol: "-".into(),
                    factor: 1.0,
                }
            } else {
                let factor = parse_quantity(&format!("1 {sym}"), vdim)
                    .map_err(|e| cx.at(u.span(), format!("unit: {e}")))?;
                DisplayUnit {
                    symbol: sym.into(),
                    factor,
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_expand_and_compress() {
        let l = SdeList::One(Value::Text("2-4, 7, 9-10".into()));
        let n = expand(&l).unwrap();
        assert_eq!(n, ["2", "3", "4", "7", "9", "10"]);
        assert_eq!(compress(&n), "2-4, 7, 9-10");
        assert!(expand(&SdeList::One(Value::Text("5-3".into()))).is_err());
    }
}
