//! Decision variables: which SDE parameters an identification estimates, read from a variables
//! TOML file (`configs/identification/*.toml`, documented in `docs/identification.md`).
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

use crate::model::{Model, ParamName, ParamRef, SdeLaw};
use crate::source::{Located, Quantity, SourceText};
use crate::units::{parse_quantity, Dim};

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
    /// The SDE parameter.
    pub param: ParamRef,
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
    /// The SDE names, compressed (`"2-10, 13-17"`), for the report table.
    pub sdes: String,
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

/// The decision variables of one identification.
#[derive(Debug, Clone, PartialEq)]
pub struct Variables {
    /// File name (for messages).
    pub origin: String,
    /// The variables, in file order.
    pub vars: Vec<Variable>,
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

    /// Writes values `x` (SI) into the model's parameters.
    pub fn apply(&self, model: &mut Model, x: &[f64]) {
        for (v, &xi) in self.vars.iter().zip(x) {
            for t in &v.targets {
                model.set_param(t.param, t.ratio * xi);
            }
        }
    }

    /// Every parameter any variable sets, without repeats, in variable order.
    pub fn params(&self) -> Vec<ParamRef> {
        let mut ps: Vec<ParamRef> = Vec::new();
        for v in &self.vars {
            for t in &v.targets {
                if !ps.contains(&t.param) {
                    ps.push(t.param);
                }
            }
        }
        ps
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
    sdes: Spanned<SdeList>,
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
    let text = crate::source::strip_bom(text);
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
    let mut owner: Vec<(ParamRef, String)> = Vec::new();
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
    owner: &[(ParamRef, String)],
) -> Result<Variable, VarsError> {
    let names = expand(rv.sdes.get_ref()).map_err(|m| cx.at(rv.sdes.span(), m))?;
    let pname = rv.parameter.get_ref().trim();
    let Some(param) = ParamName::parse(pname) else {
        return Err(cx.at(rv.parameter.span(), format!(
            "unknown parameter \"{pname}\"; parameters are kn, kt, psi_n, psi_t (slideway, rotary, isolator), k, psi (screw, spring), k1-k6, psi1-psi6 (general)"
        )));
    };
    let tie = match rv.tie.as_ref().map(|t| t.get_ref().as_str()) {
        None | Some("equal") => Tie::Equal,
        Some("scale") => Tie::Scale,
        Some(other) => {
            let span = rv.tie.as_ref().map(|t| t.span()).unwrap_or(0..0);
            return Err(cx.at(span, format!("unknown tie \"{other}\"; use \"equal\" (one shared value, optionally with ratios) or \"scale\" (a factor on the model's values)")));
        }
    };
    let Targets {
        mut targets,
        dim,
        model_values,
    } = targets(cx, rv, model, &names, param, owner)?;
    let name = match &rv.name {
        Some(n) => n.get_ref().trim().to_string(),
        None if names.len() == 1 => format!("{pname} {}", names[0]),
        None => format!("{pname} {}", compress(&names)),
    };
    if earlier.iter().any(|v| v.name == name) {
        let span = rv.name.as_ref().map(|n| n.span()).unwrap_or(rv.sdes.span());
        return Err(cx.at(
            span,
            format!("a variable named \"{name}\" already exists; give it another `name`"),
        ));
    }
    let vdim = if tie == Tie::Scale { Dim::NONE } else { dim };
    // Ratios.
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
            for (t, &v) in targets.iter_mut().zip(&model_values) {
                t.ratio = v;
            }
        }
        (None, Tie::Equal) => {}
    }
    let unit = display_unit(cx, rv, vdim)?;
    let Values {
        initial,
        lower,
        upper,
        scale,
    } = values(cx, rv, tie, vdim, &unit, &targets, &model_values)?;
    Ok(Variable {
        name,
        sdes: compress(&names),
        parameter: pname.to_string(),
        targets,
        tie,
        initial,
        lower,
        upper,
        scale,
        unit,
        dissipation: param.is_dissipation(),
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
    tie: Tie,
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
                    return Err(cx.at(rv.sdes.span(), format!(
                        "the model's {pname} values of these SDEs differ ({}); give `initial` for the shared value",
                        implied.iter().map(|v| format!("{:.6}", v / unit.factor)).collect::<Vec<_>>().join(", ")
                    )));
                }
                first
            }
        },
    };
    let lower = match &rv.lower {
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
        let span = rv
            .initial
            .as_ref()
            .map(|v| v.span())
            .unwrap_or(rv.sdes.span());
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
            let span = rv
                .initial
                .as_ref()
                .map(|v| v.span())
                .unwrap_or(rv.sdes.span());
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
    owner: &[(ParamRef, String)],
) -> Result<Targets, VarsError> {
    let pname = rv.parameter.get_ref().trim();
    let mut targets = Vec::new();
    let mut dim: Option<Dim> = None;
    let mut model_values = Vec::new();
    for n in names {
        let Some(s) = model.sde_index(n) else {
            let known: Vec<&str> = model.sdes.iter().map(|s| s.name.as_str()).collect();
            return Err(cx.at(
                rv.sdes.span(),
                format!(
                    "unknown SDE \"{n}\"; the model's SDEs: {}",
                    known.join(", ")
                ),
            ));
        };
        let sde = &model.sdes[s];
        if !sde.enabled {
            return Err(cx.at(rv.sdes.span(), format!("SDE \"{n}\" is disabled in the model (enabled = false); enable it or leave it out")));
        }
        let pr = ParamRef {
            sde: s,
            name: param,
        };
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
                return Err(cx.at(rv.sdes.span(), format!(
                    "SDE \"{n}\"'s {pname} is {} but the variable's first SDE's is {}; one variable sets parameters of one dimension (use tie = \"scale\" for a factor)",
                    d.describe(), d0.describe()
                )));
            }
        }
        dim = Some(d);
        if let Some((_, other)) = owner.iter().find(|(p, _)| *p == pr) {
            return Err(cx.at(rv.sdes.span(), format!("SDE \"{n}\" {pname} is already set by variable \"{other}\"; each parameter belongs to one variable")));
        }
        if targets.iter().any(|t: &Target| t.param == pr) {
            return Err(cx.at(rv.sdes.span(), format!("SDE \"{n}\" is listed twice")));
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
