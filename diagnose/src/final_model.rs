//! The final model as a model file: the identified values written back into the model's own TOML
//! (comments and layout kept), every effect `ident diagnose` accepted appended as a real element of
//! the model format with a comment saying where it came from, and the identification variables
//! file for the next run, whose initial values are the final estimates.
//!
//! Pure text in, text out: the caller reads and writes the files. The written model is loaded back
//! here and compared with the final model before it is returned, so a file this module returns
//! reproduces the final model (to the 12 significant digits it writes).
//!
//! | accepted effect | written as |
//! |---|---|
//! | spring (placed or not) | `[[sde]]` of kind `spring` (`k`, `psi`, `axis`) |
//! | point mass (placed or not), resonator | `[[body]]` and its `general` mount `[[sde]]` |
//! | flexible body | the body's new mass and inertia, its two new thirds (`[[body]]`), their two `general` joints, the SDEs and forces moved to the thirds |
//! | joint damping | the split SDEs' own ψ, and a variable of its own in the next variables file |
//! | sensor gain | not a model element: [`FinalModelError::NotExpressible`] |
//!
//! ```
//! use rfe::textbook;
//! use diagnose::final_model;
//! let model = textbook::single_body(100.0, 1.0e6, 0.2);
//! let text = final_model::resolved_toml(&model);
//! let back = rfe::modelfile::parse_toml(&text, "single.toml").unwrap().model;
//! assert_eq!(back.bodies[0].mass, 100.0);
//! ```

use std::fmt::Write as _;

use nalgebra::{Matrix3, Vector3};
use toml_edit::{DocumentMut, Item, Value};

use crate::{Diagnosis, Effect, Refit};
use identify::variables::{self, On, Tie, Variable};
use identify::Identification;
use rfe::display::{p_value, sig};
use rfe::model::{
    Body, Characteristic, Model, Param, ParamName, PointForce, PointMass, Sde, SdeLaw, Tangential,
    DOF_NAMES,
};
use rfe::write_back::{
    axes_rows, exact_list, float, inertia_list, length_list, prepend_comment, quantity, quoted,
    raw_item, sde_table, write_back_bodies, write_params, WriteBackError,
};

/// Relative tolerance of the load-back check.
const RELOAD_TOLERANCE: f64 = 1e-9;

/// Why the final model or the next variables file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FinalModelError {
    /// The original text is not valid TOML (it loaded before, so this means it changed).
    #[error("{origin}: cannot re-read the model TOML to write the final model: {message}")]
    Parse {
        /// File.
        origin: String,
        /// Parser message.
        message: String,
    },
    /// The values could not be written into the model's TOML text.
    #[error(transparent)]
    WriteBack(#[from] WriteBackError),
    /// An accepted effect has no element in the model format.
    #[error("the accepted effect \"{effect}\" cannot be written into a model file: {why}")]
    NotExpressible {
        /// What and where.
        effect: String,
        /// Why, and what to do instead.
        why: String,
    },
    /// The final model does not extend the identification's model as the effects say.
    #[error(
        "the final model does not follow from the identified model and the accepted effects: {0}"
    )]
    Inconsistent(String),
    /// The written text does not load back into the final model.
    #[error("the written final model does not load back to the final model: {0}")]
    Reload(String),
}

/// Where the model came from: its file name (for messages and the header) and, for a TOML
/// model, its text (whose comments and layout are kept). Without text (a resolved JSON model)
/// the whole final model is written from the resolved form.
#[derive(Debug, Clone, Copy)]
pub struct Source<'a> {
    /// The model file as given.
    pub origin: &'a str,
    /// Its TOML text, `None` for a resolved JSON model.
    pub text: Option<&'a str>,
}

/// The final model: the diagnosis's when one ran, else the identification's.
fn final_of<'a>(id: &'a Identification, diagnosis: Option<&'a Diagnosis>) -> &'a Model {
    diagnosis.map(|d| &d.model).unwrap_or(&id.model)
}

/// The final model, once the diagnosis's accepted effects (if one ran) are known to be
/// expressible in the model file.
fn writable_final<'a>(
    id: &'a Identification,
    diagnosis: Option<&'a Diagnosis>,
) -> Result<&'a Model, FinalModelError> {
    if let Some(d) = diagnosis {
        expressible(d)?;
    }
    Ok(final_of(id, diagnosis))
}

/// The final model as TOML text in the project's model format (`docs/model-format.md`): for a
/// TOML source its text with the final values written back in each key's own unit and the
/// accepted effects appended; for a JSON source the resolved final model written whole. A header
/// comment says which fit is final (the first fit when nothing was accepted or no diagnosis ran).
pub fn model_toml(
    source: Source<'_>,
    id: &Identification,
    diagnosis: Option<&Diagnosis>,
) -> Result<String, FinalModelError> {
    let fin = writable_final(id, diagnosis)?;
    let mut out = header(source, id, diagnosis);
    match source.text {
        Some(text) => out.push_str(&edited(text, source.origin, id, diagnosis)?),
        None => {
            out.push_str(
                "# Written from the resolved model (the source was JSON: there were no comments to keep).\n\n",
            );
            out.push_str(&resolved_toml(fin));
        }
    }
    reload_check(&out, source.origin, fin)?;
    Ok(out)
}

/// Every accepted effect must have a model element.
fn expressible(d: &Diagnosis) -> Result<(), FinalModelError> {
    for e in &d.effects {
        if let Effect::Gain { .. } = e {
            return Err(FinalModelError::NotExpressible {
                effect: e.describe(),
                why: "a sensor gain error corrects the measured characteristic, not the structure, and the model format has no gain per output; correct the sensor's calibration in the stand file and measure again, or identify without that characteristic".into(),
            });
        }
    }
    Ok(())
}

/// The header comment: where the file came from and which fit it holds.
fn header(source: Source<'_>, id: &Identification, diagnosis: Option<&Diagnosis>) -> String {
    let converged = if id.stop.converged() {
        String::new()
    } else {
        format!(
            "\n# NOTE: the identification did not converge ({}); the values here start from its best point.",
            id.stop.describe()
        )
    };
    let what = match diagnosis {
        Some(d) if !d.accepted.is_empty() => format!(
            "the estimates of the final fit written back, after `ident diagnose` added {} effect(s):\n# each is appended at the end as a model element, with where it came from. The first fit is\n# superseded.",
            d.accepted.len()
        ),
        Some(_) => "the estimates of the first fit written back: `ident diagnose` accepted no effect,\n# so the first fit is final.".into(),
        None => "the estimates of the identification written back (no diagnosis ran: the first fit\n# is final).".into(),
    };
    format!(
        "# Final model written by ident from {}:\n# {what}{converged}\n# Variables for the next run: the matching final variables file.\n\n",
        file_name(source.origin)
    )
}

/// The file name of a path, for headers that do not depend on where the files were.
fn file_name(path: &str) -> &str {
    std::path::Path::new(path)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or(path)
}

/// The original text with the final values, the changed elements and the added ones.
fn edited(
    text: &str,
    origin: &str,
    id: &Identification,
    diagnosis: Option<&Diagnosis>,
) -> Result<String, FinalModelError> {
    let base = &id.model;
    let fin = final_of(id, diagnosis);
    extends(base, fin)?;
    let mut doc: DocumentMut =
        text.parse()
            .map_err(|e: toml_edit::TomlError| FinalModelError::Parse {
                origin: origin.into(),
                message: e.to_string(),
            })?;
    let notes = diagnosis.map(modified_notes).unwrap_or_default();
    write_back_sdes(&mut doc, origin, id, fin, &notes)?;
    let by_vars = id.variables.model_params();
    write_back_bodies(&mut doc, origin, (base, fin), &by_vars, &notes)?;
    let forces_moved = base.forces != fin.forces;
    if forces_moved {
        doc.remove("excitation");
    }
    let mut out = doc.to_string();
    if !out.ends_with('\n') {
        out.push('\n');
    }
    if forces_moved {
        out.push_str("\n# The excitation, rewritten by `ident diagnose`: the bodies it acts on were split (see below).\n");
        out.push_str(&excitation_toml(fin));
    }
    // Outputs the measured data added to the model (point outputs, other references:
    // `identify::data::with_measured_outputs`) follow the file's own.
    let declared = rfe::modelfile::parse_toml(text, origin)
        .map(|l| l.model.outputs.len())
        .unwrap_or(fin.outputs.len());
    if fin.outputs.len() > declared {
        let mut measured = fin.clone();
        measured.outputs = fin.outputs[declared..].to_vec();
        out.push_str(
            "\n# Outputs the measured data added (point outputs, responses to other references).\n",
        );
        out.push_str(&outputs_toml(&measured));
    }
    if let Some(d) = diagnosis {
        out.push_str(&added_toml(base, d)?);
    }
    Ok(out)
}

/// The final model keeps every element of the identified model, in order, and its outputs.
fn extends(base: &Model, fin: &Model) -> Result<(), FinalModelError> {
    let bodies_kept = fin.bodies.len() >= base.bodies.len()
        && base
            .bodies
            .iter()
            .zip(&fin.bodies)
            .all(|(a, b)| a.name == b.name);
    let sdes_kept = fin.sdes.len() >= base.sdes.len()
        && base
            .sdes
            .iter()
            .zip(&fin.sdes)
            .all(|(a, b)| a.name == b.name && a.kind == b.kind);
    if !(bodies_kept && sdes_kept) {
        return Err(FinalModelError::Inconsistent(
            "an element of the identified model is missing or renamed".into(),
        ));
    }
    if base.outputs != fin.outputs {
        return Err(FinalModelError::Inconsistent(
            "the output characteristics changed".into(),
        ));
    }
    Ok(())
}

/// Comments for existing elements an effect changed: (`body`/`sde`, name, comment).
fn modified_notes(d: &Diagnosis) -> Vec<(&'static str, String, String)> {
    let mut notes = Vec::new();
    for (e, a) in d.effects.iter().zip(&d.accepted) {
        match e {
            Effect::Damping { sdes, .. } => {
                for s in sdes {
                    notes.push((
                        "sde",
                        s.clone(),
                        format!(
                            "# {} — by `ident diagnose`: {}\n",
                            a.effect,
                            estimates_text(a)
                        ),
                    ));
                }
            }
            Effect::Flexible { body, axis, .. } => notes.push((
                "body",
                body.clone(),
                format!(
                    "# Split by `ident diagnose` into three RFEs along its principal axis {} (this is the centre third; the others and their joints are at the end): {}\n",
                    axis + 1,
                    estimates_text(a)
                ),
            )),
            _ => {}
        }
    }
    notes
}

/// Writes into the `[[sde]]` tables every parameter a variable sets and every one the diagnosis
/// changed, and the ends of SDEs moved to another body.
fn write_back_sdes(
    doc: &mut DocumentMut,
    origin: &str,
    id: &Identification,
    fin: &Model,
    notes: &[(&'static str, String, String)],
) -> Result<(), FinalModelError> {
    let base = &id.model;
    let by_vars = id.variables.params();
    for (i, (b, f)) in base.sdes.iter().zip(&fin.sdes).enumerate() {
        let params: Vec<ParamName> = f
            .law
            .params()
            .into_iter()
            .filter(|p| {
                by_vars.iter().any(|r| r.sde == i && r.name == *p) || b.law.get(*p) != f.law.get(*p)
            })
            .collect();
        let moved = b.bodies != f.bodies;
        let geometry = b.point != f.point || b.rotation != f.rotation;
        let note = notes.iter().find(|n| n.0 == "sde" && n.1 == f.name);
        if params.is_empty() && !moved && !geometry && note.is_none() {
            continue;
        }
        let missing = || WriteBackError::Missing {
            origin: origin.into(),
            table: "sde",
            name: f.name.clone(),
        };
        let table = doc
            .get_mut("sde")
            .and_then(Item::as_array_of_tables_mut)
            .and_then(|t| sde_table(t, &f.name))
            .ok_or_else(missing)?;
        write_params(table, &f.law, &params);
        if moved {
            let ends: toml_edit::Array = f.bodies.iter().map(|e| body_name(fin, *e)).collect();
            table.insert("bodies", Item::Value(Value::Array(ends)));
        }
        if geometry {
            table.insert("point", raw_item(&length_list(&f.point))?);
            table.remove("axis");
            table.insert("axes", raw_item(&axes_rows(&f.rotation))?);
        }
        if let Some(n) = note {
            prepend_comment(table, &n.2);
        }
    }
    Ok(())
}

/// How many bodies and SDEs each effect appended, in order.
fn appended_counts(d: &Diagnosis) -> Vec<(usize, usize)> {
    d.effects
        .iter()
        .zip(&d.accepted)
        .map(|(e, a)| {
            let first = a.params.first().map(|p| p.value).unwrap_or(0.0);
            match e {
                Effect::Spring { .. } | Effect::PlacedSpring { .. } => (0, 1),
                Effect::Mass { .. } | Effect::PlacedMass { .. } | Effect::Resonator { .. } => {
                    if first > 0.0 {
                        (1, 1)
                    } else {
                        (0, 0)
                    }
                }
                Effect::Flexible { .. } => {
                    if first > 0.0 {
                        (2, 2)
                    } else {
                        (0, 0)
                    }
                }
                // A law that leaves the direction out gets a parallel general element; a
                // general element's own stiffness is written into its table.
                Effect::Direction { sde, .. } => {
                    let general = d.model.sde_index(sde).is_some_and(|i| {
                        matches!(d.model.sdes[i].law, rfe::model::SdeLaw::General { .. })
                    });
                    if general || first <= 0.0 {
                        (0, 0)
                    } else {
                        (0, 1)
                    }
                }
                Effect::Gain { .. } | Effect::Damping { .. } | Effect::BodyMass { .. } => (0, 0),
            }
        })
        .collect()
}

/// The elements the accepted effects added, each group under a comment saying where it came from.
fn added_toml(base: &Model, d: &Diagnosis) -> Result<String, FinalModelError> {
    let fin = &d.model;
    let counts = appended_counts(d);
    let (nb, ns): (usize, usize) = counts.iter().fold((0, 0), |(a, b), (x, y)| (a + x, b + y));
    if base.bodies.len() + nb != fin.bodies.len() || base.sdes.len() + ns != fin.sdes.len() {
        return Err(FinalModelError::Inconsistent(format!(
            "the effects add {nb} bodies and {ns} SDEs, the final model has {} and {} more",
            fin.bodies.len() - base.bodies.len(),
            fin.sdes.len() - base.sdes.len()
        )));
    }
    let mut out = String::new();
    let (mut bi, mut si) = (base.bodies.len(), base.sdes.len());
    for ((e, a), (nb, ns)) in d.effects.iter().zip(&d.accepted).zip(counts) {
        let _ = write!(out, "\n{}", provenance(d, a));
        match e {
            Effect::Damping { sdes, .. } => {
                let _ = writeln!(
                    out,
                    "# (written into SDE {} above: its own ψ)",
                    sdes.join(", ")
                );
            }
            _ if nb + ns == 0 => {
                let _ = writeln!(
                    out,
                    "# (its estimate is at the nested value: no element to add)"
                );
            }
            _ => {}
        }
        for b in &fin.bodies[bi..bi + nb] {
            out.push('\n');
            out.push_str(&body_toml(b));
        }
        for s in &fin.sdes[si..si + ns] {
            out.push('\n');
            out.push_str(&sde_toml(s, fin));
        }
        bi += nb;
        si += ns;
    }
    Ok(out)
}

/// Where an accepted effect came from: the round, the score and likelihood-ratio tests, and its
/// estimates at the final fit with their Cramér-Rao errors. Date-free, so it is reproducible.
fn provenance(d: &Diagnosis, a: &Refit) -> String {
    let mut s = String::from(
        "# ---------------------------------------------------------------------------------------\n",
    );
    let round = d.rounds.iter().enumerate().find(|(_, r)| {
        r.placed.as_ref().is_some_and(|p| p.effect == a.effect)
            || r.accepted
                .and_then(|k| r.refits.get(k))
                .is_some_and(|f| f.effect == a.effect)
    });
    let _ = writeln!(
        s,
        "# Added by `ident diagnose`{}: {}",
        round
            .map(|(i, _)| format!(", round {}", i + 1))
            .unwrap_or_default(),
        a.effect
    );
    if let Some((_, r)) = round {
        let candidate = r.accepted.and_then(|k| r.refits.get(k));
        let ranked = candidate.and_then(|c| {
            r.ranked
                .iter()
                .find(|k| k.effect == c.effect || k.equivalent.contains(&c.effect))
        });
        if let Some(k) = ranked {
            let _ = writeln!(
                s,
                "# score test: statistic {} (p {}), rank {} of {} candidates",
                sig(k.statistic, 4),
                p_value(k.p_value),
                k.rank,
                r.candidates
            );
        }
        let _ = writeln!(
            s,
            "# likelihood-ratio test: LR {} on {} parameter(s), p {} (threshold {})",
            sig(a.lr, 4),
            a.dof,
            p_value(a.p_value),
            sig(r.threshold, 2)
        );
    }
    let _ = writeln!(s, "# estimates at the final fit: {}", estimates_text(a));
    for e in &a.equivalent {
        let _ = writeln!(s, "# the data cannot tell it from: {}", e.describe());
    }
    s
}

/// `k = 0.5635 ± 5.00e-4 N/µm, psi = …` (± the Cramér-Rao standard error).
fn estimates_text(a: &Refit) -> String {
    a.params
        .iter()
        .map(|p| {
            let (v, e, u) = p.display();
            let u = if u == "-" {
                String::new()
            } else {
                format!(" {u}")
            };
            format!("{} = {} ± {}{u}", p.name, sig(v, 6), sig(e, 2))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

// ---------------------------------------------------------------------------------------------
// The resolved model as TOML elements

/// The whole resolved model as TOML in the model format: every body, SDE, force (a force pair is
/// written as its two forces) and output, in readable units (kg, mm, N/um, MPa/um), numbers to
/// 12 significant digits.
pub fn resolved_toml(model: &Model) -> String {
    let mut s = format!("name = {}\n", quoted(&model.name));
    for b in &model.bodies {
        s.push('\n');
        s.push_str(&body_toml(b));
    }
    for sde in &model.sdes {
        s.push('\n');
        s.push_str(&sde_toml(sde, model));
    }
    if !model.forces.is_empty() {
        s.push('\n');
        s.push_str(&excitation_toml(model));
    }
    for r in &model.references {
        let _ = write!(s, "\n[[reference]]\nname = {}\n", quoted(&r.name));
        match &r.excitation {
            rfe::model::Excitation::BaseMotion { direction } => {
                let _ = writeln!(s, "base_motion = {}", exact_list(direction));
            }
            rfe::model::Excitation::Forces(forces) => {
                for f in forces {
                    s.push_str(
                        &force_toml(f, model)
                            .replace("[[excitation.force]]", "[[reference.force]]"),
                    );
                }
            }
        }
    }
    s.push_str(&outputs_toml(model));
    for p in &model.point_masses {
        s.push('\n');
        s.push_str(&point_mass_toml(p, model));
    }
    s
}

/// One `[[point_mass]]`.
fn point_mass_toml(p: &PointMass, model: &Model) -> String {
    let mut s = String::from("[[point_mass]]\n");
    let _ = writeln!(s, "name = {}", quoted(&p.name));
    let _ = writeln!(s, "body = {}", quoted(&body_name(model, Some(p.body))));
    let _ = writeln!(s, "point = {}", length_list(&p.point));
    let _ = writeln!(s, "mass = {}", quantity(p.mass, 1.0, "kg"));
    if p.inertia != [0.0; 3] {
        let _ = writeln!(s, "inertia = {}", inertia_list(&p.inertia));
    }
    s
}

fn body_name(model: &Model, b: Option<usize>) -> String {
    b.and_then(|i| model.bodies.get(i))
        .map(|b| b.name.clone())
        .unwrap_or_else(|| "ground".into())
}

/// One `[[body]]`.
fn body_toml(b: &Body) -> String {
    let mut s = String::from("[[body]]\n");
    let _ = writeln!(s, "name = {}", quoted(&b.name));
    let _ = writeln!(s, "mass = {}", quantity(b.mass, 1.0, "kg"));
    let _ = writeln!(s, "position = {}", length_list(&b.position));
    let _ = writeln!(s, "inertia = {}", inertia_list(&b.inertia));
    if b.rotation != Matrix3::identity() {
        let _ = writeln!(s, "axes = {}", axes_rows(&b.rotation));
    }
    s
}

/// An SDE name: an integer when it is one (the paper's SDE numbers), else a string.
fn sde_name(name: &str) -> String {
    match name.parse::<i64>() {
        Ok(n) if n.to_string() == name => n.to_string(),
        _ => quoted(name),
    }
}

/// One `[[sde]]`.
fn sde_toml(sde: &Sde, model: &Model) -> String {
    let mut s = String::from("[[sde]]\n");
    let _ = writeln!(s, "name = {}", sde_name(&sde.name));
    let _ = writeln!(s, "kind = \"{}\"", sde.kind.as_str());
    let _ = writeln!(
        s,
        "bodies = [{}, {}]",
        quoted(&body_name(model, sde.bodies[0])),
        quoted(&body_name(model, sde.bodies[1]))
    );
    let _ = writeln!(s, "point = {}", length_list(&sde.point));
    let axial = matches!(sde.law, SdeLaw::Axial { .. });
    if axial {
        // Only axis 1 acts; the loader completes the frame.
        let a = sde.rotation.column(0);
        let _ = writeln!(s, "axis = [{}, {}, {}]", float(a.x), float(a.y), float(a.z));
    } else {
        let _ = writeln!(s, "axes = {}", axes_rows(&sde.rotation));
    }
    if !sde.enabled {
        let _ = writeln!(s, "enabled = false");
    }
    match sde.law {
        SdeLaw::Contact {
            area,
            moments,
            kn,
            kt,
            psi_n,
            psi_t,
        } => {
            let _ = writeln!(s, "area = {}", quantity(area, 1.0, "m^2"));
            let m: Vec<String> = moments.iter().map(|v| quantity(*v, 1.0, "m^4")).collect();
            let _ = writeln!(s, "moments = [{}]", m.join(", "));
            let _ = writeln!(s, "kn = {}", quantity(kn, 1e12, "MPa/um"));
            match kt {
                Tangential::Value(v) => {
                    let _ = writeln!(s, "kt = {}", quantity(v, 1e12, "MPa/um"));
                }
                Tangential::Ratio(r) => {
                    let _ = writeln!(s, "kn_kt_ratio = {}", float(r));
                }
            }
            let _ = writeln!(s, "psi_n = {}\npsi_t = {}", float(psi_n), float(psi_t));
        }
        SdeLaw::Axial { k, psi } => {
            let _ = writeln!(s, "k = {}", quantity(k, 1e6, "N/um"));
            let _ = writeln!(s, "psi = {}", float(psi));
        }
        SdeLaw::Isolator {
            kn,
            kt,
            psi_n,
            psi_t,
        } => {
            let _ = writeln!(s, "kn = {}", quantity(kn, 1e6, "N/um"));
            let _ = writeln!(s, "kt = {}", quantity(kt, 1e6, "N/um"));
            let _ = writeln!(s, "psi_n = {}\npsi_t = {}", float(psi_n), float(psi_t));
        }
        SdeLaw::General { k, psi } => {
            let ks: Vec<String> = k
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    if i < 3 {
                        quantity(*v, 1e6, "N/um")
                    } else {
                        quantity(*v, 1.0, "N*m/rad")
                    }
                })
                .collect();
            let _ = writeln!(s, "k = [{}]", ks.join(", "));
            if psi.iter().all(|p| *p == psi[0]) {
                let _ = writeln!(s, "psi = {}", float(psi[0]));
            } else {
                let ps: Vec<String> = psi.iter().map(|p| float(*p)).collect();
                let _ = writeln!(s, "psi = [{}]", ps.join(", "));
            }
        }
    }
    s
}

/// The excitation as `[[excitation.force]]` tables (a pair as its two forces).
fn excitation_toml(model: &Model) -> String {
    let mut s = String::new();
    for (k, f) in model.forces.iter().enumerate() {
        if k > 0 {
            s.push('\n');
        }
        s.push_str(&force_toml(f, model));
    }
    s
}

fn force_toml(f: &PointForce, model: &Model) -> String {
    let mut s = String::from("[[excitation.force]]\n");
    let _ = writeln!(s, "body = {}", quoted(&body_name(model, Some(f.body))));
    let _ = writeln!(s, "point = {}", length_list(&f.point));
    let vec = |v: &Vector3<f64>, unit: &str| {
        format!(
            "[{}, {}, {}]",
            quantity(v.x, 1.0, unit),
            quantity(v.y, 1.0, unit),
            quantity(v.z, 1.0, unit)
        )
    };
    if f.force != Vector3::zeros() || f.moment == Vector3::zeros() {
        let _ = writeln!(s, "force = {}", vec(&f.force, "N"));
    }
    if f.moment != Vector3::zeros() {
        let _ = writeln!(s, "moment = {}", vec(&f.moment, "N*m"));
    }
    s
}

/// The outputs, consecutive characteristics of one body and quantity as one `[[output]]`.
fn outputs_toml(model: &Model) -> String {
    // In model order: consecutive principal-axis outputs of one body and quantity share a table;
    // a point output, or one under another reference, has its own.
    let mut groups: Vec<(usize, rfe::model::Quantity, Vec<u8>, Option<String>)> = Vec::new();
    for &Characteristic {
        body,
        dof,
        quantity,
        at,
        reference,
        relative,
    } in &model.outputs
    {
        let simple = at.is_none() && reference == 0 && !relative;
        if !simple {
            let table = format!(
                "\n[[output]]\nbody = {}\n{}quantity = \"{}\"\n{}{}",
                quoted(&body_name(model, Some(body))),
                match at {
                    Some(at) => format!(
                        "point = {}\ndirection = {}\n",
                        exact_list(&at.point),
                        exact_list(&at.direction)
                    ),
                    None => format!(
                        "dof = {}\n",
                        quoted(DOF_NAMES.get(dof as usize).copied().unwrap_or("u1"))
                    ),
                },
                quantity.as_str(),
                if reference != 0 {
                    format!("reference = {}\n", quoted(model.reference_name(reference)))
                } else {
                    String::new()
                },
                if relative {
                    "motion = \"relative\"\n"
                } else {
                    ""
                }
            );
            groups.push((body, quantity, Vec::new(), Some(table)));
            continue;
        }
        match groups.last_mut() {
            Some((b, q, dofs, None)) if *b == body && *q == quantity && !dofs.contains(&dof) => {
                dofs.push(dof)
            }
            _ => groups.push((body, quantity, vec![dof], None)),
        }
    }
    let mut s = String::new();
    for (body, q, dofs, table) in groups {
        if let Some(t) = table {
            s.push_str(&t);
            continue;
        }
        let names: Vec<String> = dofs
            .iter()
            .map(|d| quoted(DOF_NAMES.get(*d as usize).copied().unwrap_or("u1")))
            .collect();
        let _ = write!(
            s,
            "\n[[output]]\nbody = {}\ndofs = [{}]\nquantity = \"{}\"\n",
            quoted(&body_name(model, Some(body))),
            names.join(", "),
            q.as_str()
        );
    }
    s
}

// ---------------------------------------------------------------------------------------------
// Load-back check

/// Loads `text` and compares it with `fin`.
fn reload_check(text: &str, origin: &str, fin: &Model) -> Result<(), FinalModelError> {
    let back = rfe::modelfile::parse_toml(text, origin)
        .map_err(|e| FinalModelError::Reload(e.to_string()))?
        .model;
    match differences(&back, fin, RELOAD_TOLERANCE).first() {
        Some(d) => Err(FinalModelError::Reload(d.clone())),
        None => Ok(()),
    }
}

/// `|a − b| ≤ tol · scale` elementwise, `scale` the largest magnitude of both (at least 1e-300).
fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    let scale = a
        .iter()
        .chain(b)
        .fold(0.0_f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol * scale)
}

/// What differs between two models beyond the relative tolerance `tol` (positions to `tol` m,
/// directions to `tol`): names, bodies, SDE ends, stiffness and dissipation, forces, outputs.
pub fn differences(a: &Model, b: &Model, tol: f64) -> Vec<String> {
    let mut out = Vec::new();
    if a.bodies.len() != b.bodies.len() || a.sdes.len() != b.sdes.len() {
        out.push(format!(
            "{} bodies and {} SDEs against {} and {}",
            a.bodies.len(),
            a.sdes.len(),
            b.bodies.len(),
            b.sdes.len()
        ));
        return out;
    }
    let abs = |x: &[f64], y: &[f64]| x.iter().zip(y).all(|(p, q)| (p - q).abs() <= tol);
    for (x, y) in a.bodies.iter().zip(&b.bodies) {
        let same = x.name == y.name
            && close(&[x.mass], &[y.mass], tol)
            && close(&x.inertia, &y.inertia, tol)
            && abs(x.position.as_slice(), y.position.as_slice())
            && abs(x.rotation.as_slice(), y.rotation.as_slice());
        if !same {
            out.push(format!("body \"{}\" differs from \"{}\"", x.name, y.name));
        }
    }
    for (x, y) in a.sdes.iter().zip(&b.sdes) {
        let axial = matches!(x.law, SdeLaw::Axial { .. });
        let frame = if axial {
            abs(
                x.rotation.column(0).as_slice(),
                y.rotation.column(0).as_slice(),
            )
        } else {
            abs(x.rotation.as_slice(), y.rotation.as_slice())
        };
        let same = x.name == y.name
            && x.kind == y.kind
            && x.bodies == y.bodies
            && x.enabled == y.enabled
            && abs(x.point.as_slice(), y.point.as_slice())
            && frame
            && close(&x.law.stiffness(), &y.law.stiffness(), tol)
            && close(&x.law.dissipation(), &y.law.dissipation(), tol);
        if !same {
            out.push(format!("SDE \"{}\" differs from \"{}\"", x.name, y.name));
        }
    }
    let points_same = a.point_masses.len() == b.point_masses.len()
        && a.point_masses.iter().zip(&b.point_masses).all(|(x, y)| {
            x.name == y.name
                && x.body == y.body
                && abs(x.point.as_slice(), y.point.as_slice())
                && close(&[x.mass], &[y.mass], tol)
                && close(&x.inertia, &y.inertia, tol)
        });
    if !points_same {
        out.push("the point masses differ".into());
    }
    let load = |m: &Model| -> Vec<(usize, Vec<f64>)> {
        let mut v: Vec<(usize, Vec<f64>)> = m
            .forces
            .iter()
            .map(|f| {
                let mut xs = f.point.as_slice().to_vec();
                xs.extend(f.force.iter().chain(f.moment.iter()));
                (f.body, xs)
            })
            .collect();
        v.sort_by_key(|p| p.0);
        v
    };
    let (fa, fb) = (load(a), load(b));
    // Points to `tol` m, force and moment relative.
    let forces_same = fa.len() == fb.len()
        && fa.iter().zip(&fb).all(|(p, q)| {
            p.0 == q.0 && abs(&p.1[..3], &q.1[..3]) && close(&p.1[3..], &q.1[3..], tol)
        });
    if !forces_same {
        out.push("the excitation differs".into());
    }
    if a.outputs != b.outputs {
        let first = a
            .outputs
            .iter()
            .zip(&b.outputs)
            .find(|(x, y)| x != y)
            .map(|(x, y)| {
                format!(
                    " (first: {} against {})",
                    a.characteristic_label(*x),
                    b.characteristic_label(*y)
                )
            })
            .unwrap_or_else(|| format!(" ({} against {})", a.outputs.len(), b.outputs.len()));
        out.push(format!("the output characteristics differ{first}"));
    }
    out
}

// ---------------------------------------------------------------------------------------------
// The variables file for the next run

/// The identification variables file for the next run, against the final model written by
/// [`model_toml`] (`model_file` names it in the header): the same variables with `initial` = the
/// final estimates (bounds, scale and unit kept; a `tie = "scale"` variable starts at 1, the
/// final values being the model's now), the SDEs a joint-damping effect split off in a variable of
/// their own, and each added spring's `k` and `psi` as variables. Effects whose parameters are not
/// SDE parameters (a mass, a resonator, a flexible body's compliance, a place) are listed in
/// comments: their values are in the model file.
pub fn variables_toml(
    model_file: &str,
    id: &Identification,
    diagnosis: Option<&Diagnosis>,
) -> Result<String, FinalModelError> {
    let fin = writable_final(id, diagnosis)?;
    let estimate = diagnosis.map(|d| &d.estimate).unwrap_or(&id.estimate);
    let stage = match diagnosis {
        Some(d) if !d.accepted.is_empty() => "final fit (after the diagnosis)",
        _ => "first fit (final: nothing was added)",
    };
    let mut s = format!(
        "# Identification variables for the next run, against {}: those of {}\n# with `initial` = the estimates of the {stage}.\nnote = {}\n",
        file_name(model_file),
        file_name(&id.variables.origin),
        quoted(&format!("next run after {}", file_name(&id.variables.origin)))
    );
    // The SDEs a joint-damping effect took out of a ψ group variable: (variable, SDE name).
    let split: Vec<(usize, &String)> = diagnosis
        .map(|d| {
            d.effects
                .iter()
                .flat_map(|e| match e {
                    Effect::Damping { variable, sdes, .. } => {
                        sdes.iter().map(|s| (*variable, s)).collect()
                    }
                    _ => Vec::new(),
                })
                .collect()
        })
        .unwrap_or_default();
    for (i, (v, &x)) in id.variables.vars.iter().zip(estimate).enumerate() {
        let gone: Vec<&String> = split
            .iter()
            .filter(|(k, _)| *k == i)
            .map(|(_, s)| *s)
            .collect();
        s.push('\n');
        s.push_str(&variable_toml(v, x, fin, &gone)?);
    }
    if let Some(d) = diagnosis {
        let mut si = id.model.sdes.len();
        for ((e, a), (_, ns)) in d.effects.iter().zip(&d.accepted).zip(appended_counts(d)) {
            let _ = write!(s, "\n# From `ident diagnose`: {}\n", a.effect);
            s.push_str(&effect_variables(e, a, &fin.sdes[si..si + ns]));
            si += ns;
        }
    }
    Ok(s)
}

/// One `[[variable]]` at the final estimate `x` (SI). The SDEs in `split` left its group.
fn variable_toml(
    v: &Variable,
    x: f64,
    fin: &Model,
    split: &[&String],
) -> Result<String, FinalModelError> {
    let targets: Vec<_> = v
        .targets
        .iter()
        .filter(|t| {
            t.param
                .sde()
                .is_none_or(|p| !split.contains(&&fin.sdes[p.sde].name))
        })
        .collect();
    if targets.is_empty() {
        return Err(FinalModelError::Inconsistent(format!(
            "variable \"{}\" lost every SDE",
            v.name
        )));
    }
    let mut names: Vec<String> = Vec::new();
    for t in &targets {
        let name = match t.param {
            Param::Sde(p) => fin.sdes[p.sde].name.clone(),
            Param::Mass { body } | Param::Inertia { body, .. } => fin.bodies[body].name.clone(),
            Param::PointMass { index } => fin.point_masses[index].name.clone(),
            Param::Gain { body, dof } => format!(
                "{} {}",
                fin.bodies[body].name,
                DOF_NAMES.get(dof as usize).copied().unwrap_or("?")
            ),
        };
        if !names.contains(&name) {
            names.push(name);
        }
    }
    let f = v.unit.factor;
    let u = &v.unit.symbol;
    let value = |si: f64| {
        if u == "-" {
            float(si)
        } else {
            quantity(si, f, u)
        }
    };
    let mut s = String::from("[[variable]]\n");
    let _ = writeln!(s, "name = {}", quoted(&v.name));
    let list: Vec<String> = names.iter().map(|n| quoted(n)).collect();
    let _ = writeln!(s, "{} = [{}]", v.on.key(), list.join(", "));
    let _ = writeln!(s, "parameter = {}", quoted(&v.parameter));
    let _ = writeln!(s, "unit = {}", quoted(u));
    // A scale tie's factor is now in the model's values: start again from 1.
    // (A gain is not in the model: its estimate stays the start.)
    let (initial, lower, upper, scale) = match v.tie {
        Tie::Scale if x > 0.0 && v.on != On::Characteristics => {
            (1.0, v.lower / x, v.upper / x, v.scale / x)
        }
        _ => (x, v.lower, v.upper, v.scale),
    };
    let initial = initial.max(lower).min(upper);
    let _ = writeln!(s, "initial = {}", value(initial));
    if lower != 0.0 {
        let _ = writeln!(s, "lower = {}", value(lower));
    }
    if upper.is_finite() {
        let _ = writeln!(s, "upper = {}", value(upper));
    }
    let _ = writeln!(s, "scale = {}", value(scale));
    match v.tie {
        Tie::Scale => {
            let _ = writeln!(s, "tie = \"scale\"");
        }
        Tie::Equal if targets.iter().any(|t| t.ratio != 1.0) => {
            let r: Vec<String> = targets.iter().map(|t| float(t.ratio)).collect();
            let _ = writeln!(s, "ratios = [{}]", r.join(", "));
        }
        Tie::Equal => {}
    }
    Ok(s)
}

/// The variables an accepted effect brings (its SDE parameters), or a comment saying why none.
fn effect_variables(e: &Effect, a: &Refit, added: &[Sde]) -> String {
    let value = |name: &str| a.params.iter().find(|p| p.name == name).map(|p| p.value);
    let var = |name: String, sdes: &str, parameter: &str, initial: String, scale: String| {
        format!("[[variable]]\nname = {}\nsdes = {sdes}\nparameter = \"{parameter}\"\ninitial = {initial}\nscale = {scale}\n",
            quoted(&name))
    };
    match e {
        Effect::Spring { .. } | Effect::PlacedSpring { .. } => {
            let Some(sde) = added.first() else {
                return "# (no element added)\n".into();
            };
            let list = format!("[{}]", quoted(&sde.name));
            let k = value("k").unwrap_or(0.0);
            let psi = value("psi").unwrap_or(0.0);
            let mut s = var(
                format!("k {}", sde.name),
                &list,
                "k",
                quantity(k, 1e6, "N/um"),
                quantity(if k > 0.0 { k } else { 1e6 }, 1e6, "N/um"),
            );
            s.push('\n');
            s.push_str(&var(
                format!("psi {}", sde.name),
                &list,
                "psi",
                float(psi),
                float(if psi > 0.0 { psi } else { 0.5 }),
            ));
            if matches!(e, Effect::PlacedSpring { .. }) {
                s.push_str("# (its line of action was fitted; it is fixed in the model file)\n");
            }
            s
        }
        Effect::Damping {
            sdes, parameter, ..
        } => {
            let psi = value("psi").unwrap_or(0.0);
            let list: Vec<String> = sdes.iter().map(|n| quoted(n)).collect();
            var(
                format!("{} {}", parameter.as_str(), variables::compress(sdes)),
                &format!("[{}]", list.join(", ")),
                &parameter.as_str(),
                float(psi),
                float(psi.abs().max(0.05)),
            )
        }
        Effect::Mass { .. } | Effect::PlacedMass { .. } | Effect::Resonator { .. } => {
            "# (a mass is not an SDE parameter: its value and place are fixed in the model file)\n"
                .into()
        }
        Effect::Flexible { .. } => {
            "# (the compliance sets all six springs of both joints: fixed in the model file)\n"
                .into()
        }
        Effect::Direction { sde, axis, .. } => {
            // The freed stiffness is a parameter of the element that carries it: the SDE
            // itself (a general element) or the parallel one added.
            let name = added.first().map_or(sde.as_str(), |s| s.name.as_str());
            let k = fin_direction_stiffness(added.first(), a, e);
            let (unit, factor) = if *axis < 3 {
                ("N/um", 1e6)
            } else {
                ("N*m/rad", 1.0)
            };
            var(
                format!("k{} {name}", axis + 1),
                &format!("[{}]", quoted(name)),
                &format!("k{}", axis + 1),
                quantity(k, factor, unit),
                quantity(if k > 0.0 { k } else { factor }, factor, unit),
            )
        }
        Effect::BodyMass { body, .. } => format!(
            "[[variable]]\nname = {}\nbodies = [{}]\nparameter = \"mJ\"\ninitial = 1.0\n",
            quoted(&format!("mJ {body}")),
            quoted(body)
        ),
        Effect::Gain { .. } => String::new(),
    }
}

/// The stiffness (SI) of a freed direction at the final fit: the added element's, or the one the
/// estimate gives (`k` itself, or `1/(1/held + c)`).
fn fin_direction_stiffness(added: Option<&Sde>, a: &Refit, e: &Effect) -> f64 {
    let Effect::Direction { axis, held, .. } = e else {
        return 0.0;
    };
    if let Some(s) = added {
        return s.law.stiffness()[*axis];
    }
    let v = a.params.first().map_or(0.0, |p| p.value);
    if *held > 0.0 {
        1.0 / (1.0 / held + v.max(0.0))
    } else {
        v.max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfe::textbook;

    #[test]
    fn numbers_are_written_to_twelve_digits_and_load_back() {
        assert_eq!(float(4.0), "4.0");
        assert_eq!(float(3999.9999999999995), "4000.0");
        assert_eq!(quantity(9.7e6, 1e6, "N/um"), "\"9.7 N/um\"");
        assert_eq!(sde_name("34"), "34");
        assert_eq!(sde_name("034"), "\"034\"");
        assert_eq!(sde_name("diagnosed spring 1"), "\"diagnosed spring 1\"");
    }

    #[test]
    fn a_resolved_model_is_written_whole_and_loads_back() {
        let model = textbook::single_body(100.0, 1.0e6, 0.2);
        let text = resolved_toml(&model);
        let back = rfe::modelfile::parse_toml(&text, "single.toml")
            .unwrap()
            .model;
        assert!(differences(&back, &model, 1e-9).is_empty(), "{text}");
        let mut other = model.clone();
        other.bodies[0].mass *= 1.0 + 1e-6;
        assert!(!differences(&back, &other, 1e-9).is_empty());
    }
}
