//! Values written back into a model's TOML text, its comments and layout kept (`toml_edit`):
//! an SDE's parameters in the convention of the key they replace (the same unit if it had one),
//! bodies' masses, inertias, positions and axes, point masses. The fit's updated model and the
//! diagnosis's final model are both written with these, so a value reads back the same way.

use nalgebra::{Matrix3, Vector3};
use toml_edit::{DocumentMut, Item, Value};

use crate::display::sig;
use crate::model::{Model, Param, ParamName, SdeLaw};
use crate::units::{parse_quantity, Dim};

/// Significant digits of every number written: loads back within 5e-12 relative.
pub const DIGITS: usize = 12;

/// Why values could not be written back into a model file.
#[derive(Debug, thiserror::Error)]
pub enum WriteBackError {
    /// An element of the model is not found in the TOML text.
    #[error(
        "{origin}: no [[{table}]] named \"{name}\" in the file; write the resolved JSON instead"
    )]
    Missing {
        /// File.
        origin: String,
        /// `body`, `sde` or `point_mass`.
        table: &'static str,
        /// Element name.
        name: String,
    },
    /// A value's text is not a TOML value (a bug in the writer, not in the file).
    #[error("cannot form the TOML value {text}: {message}")]
    Value {
        /// The text.
        text: String,
        /// The parser's message.
        message: String,
    },
}

/// Rounds to 12 significant digits so that written values read cleanly (and load back within
/// 5e-12 relative).
pub fn round_sig(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

/// `"0.05 MPa/um"` → `Some("MPa/um")`.
fn unit_of(text: &str) -> Option<String> {
    let t = text.trim();
    let end = t
        .char_indices()
        .find(|(_, c)| !(c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E')))
        .map(|(i, _)| i)
        .unwrap_or(t.len());
    let unit = t[end..].trim();
    (!unit.is_empty()).then(|| unit.to_string())
}

fn param_dim(law: &SdeLaw, p: ParamName) -> Dim {
    match (law, p) {
        (_, p) if p.is_dissipation() => Dim::NONE,
        (SdeLaw::Contact { .. }, _) => Dim::CONTACT_STIFFNESS,
        _ => Dim::STIFFNESS,
    }
}

/// The new value for a key, in the convention of the old one: the same unit if it was a string
/// with a unit, SI otherwise; decoration (comments) kept.
fn set_value(item: &mut Item, si: f64, dim: Dim) {
    let old = item.as_value().cloned();
    let mut new: Value = match old.as_ref().and_then(|v| v.as_str()).and_then(unit_of) {
        Some(unit) => match parse_quantity(&format!("1 {unit}"), dim) {
            Ok(f) => Value::from(format!("{} {unit}", round_sig(si / f))),
            Err(_) => Value::from(round_sig(si)),
        },
        None => Value::from(round_sig(si)),
    };
    if let Some(old) = old {
        *new.decor_mut() = old.decor().clone();
    }
    *item = Item::Value(new);
}

/// The `[[sde]]` table named `name` (an integer or a string name).
pub fn sde_table<'a>(
    sdes: &'a mut toml_edit::ArrayOfTables,
    name: &str,
) -> Option<&'a mut toml_edit::Table> {
    sdes.iter_mut()
        .find(|t| match t.get("name").and_then(Item::as_value) {
            Some(Value::Integer(i)) => i.value().to_string() == name,
            Some(Value::String(s)) => s.value().trim() == name,
            _ => false,
        })
}

/// Writes the parameters `params` of `law` into an `[[sde]]` table, each in the convention of
/// the key it replaces (as `identify::report::update_toml` writes an identification).
pub fn write_params(table: &mut toml_edit::Table, law: &SdeLaw, params: &[ParamName]) {
    for &p in params {
        let value = law.get(p).unwrap_or(0.0);
        match (law, p) {
            (SdeLaw::General { k, psi }, ParamName::Ki(_) | ParamName::PsiI(_)) => {
                let (key, vals) = if matches!(p, ParamName::Ki(_)) {
                    ("k", k)
                } else {
                    ("psi", psi)
                };
                let arr: toml_edit::Array = vals.iter().map(|v| round_sig(*v)).collect();
                table.insert(key, Item::Value(Value::Array(arr)));
            }
            (SdeLaw::Isolator { psi_n, psi_t, .. }, ParamName::PsiN | ParamName::PsiT)
                if table.contains_key("psi") =>
            {
                let mut old = table.remove("psi").unwrap_or(Item::None);
                let mut other = old.clone();
                set_value(&mut old, *psi_n, Dim::NONE);
                set_value(&mut other, *psi_t, Dim::NONE);
                table.insert("psi_n", old);
                table.insert("psi_t", other);
            }
            _ => {
                let key = p.as_str();
                let dim = param_dim(law, p);
                match table.get_mut(&key) {
                    Some(item) => set_value(item, value, dim),
                    None => {
                        table.insert(&key, Item::Value(Value::from(round_sig(value))));
                    }
                }
            }
        }
    }
}

/// Adds `comment` lines before a table's header.
pub fn prepend_comment(table: &mut toml_edit::Table, comment: &str) {
    let old = table
        .decor()
        .prefix()
        .and_then(|r| r.as_str())
        .unwrap_or("")
        .to_string();
    let gap = if old.starts_with('\n') { "" } else { "\n" };
    table.decor_mut().set_prefix(format!("{gap}{old}{comment}"));
}

/// Rewrites the mass, inertia, axes and position of bodies the diagnosis changed (a split) or
/// whose mass or inertias are variables (`by_vars`).
pub fn write_back_bodies(
    doc: &mut DocumentMut,
    origin: &str,
    (base, fin): (&Model, &Model),
    by_vars: &[Param],
    notes: &[(&'static str, String, String)],
) -> Result<(), WriteBackError> {
    for (i, (b, f)) in base.bodies.iter().zip(&fin.bodies).enumerate() {
        let fitted = by_vars
            .iter()
            .any(|p| matches!(p, Param::Mass { body } | Param::Inertia { body, .. } if *body == i));
        if b == f && !fitted {
            continue;
        }
        let table = doc
            .get_mut("body")
            .and_then(Item::as_array_of_tables_mut)
            .and_then(|ts| {
                ts.iter_mut().find(|t| {
                    t.get("name")
                        .and_then(Item::as_str)
                        .is_some_and(|n| n.trim() == f.name)
                })
            })
            .ok_or_else(|| WriteBackError::Missing {
                origin: origin.into(),
                table: "body",
                name: f.name.clone(),
            })?;
        table.insert("mass", raw_item(&quantity(f.mass, 1.0, "kg"))?);
        table.insert("position", raw_item(&length_list(&f.position))?);
        table.remove("inertia_tensor");
        table.insert("inertia", raw_item(&inertia_list(&f.inertia))?);
        table.insert("axes", raw_item(&axes_rows(&f.rotation))?);
        if let Some(n) = notes.iter().find(|n| n.0 == "body" && n.1 == f.name) {
            prepend_comment(table, &n.2);
        }
    }
    write_back_point_masses(doc, origin, fin, by_vars)
}

/// Rewrites the `mass` of the `[[point_mass]]` tables whose mass is a variable.
pub fn write_back_point_masses(
    doc: &mut DocumentMut,
    origin: &str,
    fin: &Model,
    by_vars: &[Param],
) -> Result<(), WriteBackError> {
    for p in by_vars {
        let Param::PointMass { index } = *p else {
            continue;
        };
        let Some(pm) = fin.point_masses.get(index) else {
            continue;
        };
        let table = doc
            .get_mut("point_mass")
            .and_then(Item::as_array_of_tables_mut)
            .and_then(|ts| {
                ts.iter_mut().find(|t| {
                    t.get("name")
                        .and_then(Item::as_str)
                        .is_some_and(|n| n.trim() == pm.name)
                })
            })
            .ok_or_else(|| WriteBackError::Missing {
                origin: origin.into(),
                table: "point_mass",
                name: pm.name.clone(),
            })?;
        table.insert("mass", raw_item(&quantity(pm.mass, 1.0, "kg"))?);
    }
    Ok(())
}

/// A TOML value item from its text.
pub fn raw_item(text: &str) -> Result<Item, WriteBackError> {
    let mut v = text.parse::<Value>().map_err(|e| WriteBackError::Value {
        text: text.into(),
        message: e.to_string(),
    })?;
    v.decor_mut().clear();
    Ok(Item::Value(v))
}

/// A TOML basic string.
pub fn quoted(text: &str) -> String {
    Value::from(text).to_string().trim().to_string()
}

/// A number as written: 12 significant digits, no float noise.
pub fn number(x: f64) -> String {
    sig(x, DIGITS)
}

/// A bare TOML float (always with a point or an exponent).
pub fn float(x: f64) -> String {
    let n = number(x);
    if n.contains(['.', 'e', 'E']) {
        n
    } else {
        format!("{n}.0")
    }
}

/// `"12.5 N/um"`: SI value `x` in `unit`, `factor` SI per unit.
pub fn quantity(x: f64, factor: f64, unit: &str) -> String {
    quoted(&format!("{} {unit}", number(x / factor)))
}

/// `["10 mm", "20 mm", "30 mm"]`: a point in millimetres.
pub fn length_list(p: &Vector3<f64>) -> String {
    format!(
        "[{}, {}, {}]",
        quantity(p.x, 1e-3, "mm"),
        quantity(p.y, 1e-3, "mm"),
        quantity(p.z, 1e-3, "mm")
    )
}

/// `[x, y, z]` in the shortest form that reads back to the same bits (a point output's geometry
/// is its identity: SI metres for a point, a unit vector for a direction).
pub fn exact_list(v: &[f64; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", v[0], v[1], v[2])
}

/// `["1 kg m^2", ...]`: principal moments of inertia.
pub fn inertia_list(j: &[f64; 3]) -> String {
    let j: Vec<String> = j.iter().map(|v| quantity(*v, 1.0, "kg m^2")).collect();
    format!("[{}]", j.join(", "))
}

/// Axes as rows: the columns of a `global_from_local` rotation.
pub fn axes_rows(r: &Matrix3<f64>) -> String {
    let rows: Vec<String> = (0..3)
        .map(|j| {
            format!(
                "[{}, {}, {}]",
                float(r[(0, j)]),
                float(r[(1, j)]),
                float(r[(2, j)])
            )
        })
        .collect();
    format!("[{}]", rows.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_split_from_values() {
        assert_eq!(unit_of("0.05 MPa/um").as_deref(), Some("MPa/um"));
        assert_eq!(unit_of("1e-3"), None);
        assert_eq!(unit_of("10N/um").as_deref(), Some("N/um"));
    }
}
