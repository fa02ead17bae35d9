//! Physical validation of a resolved model, shared by every loader. Problems are reported against
//! an [`Item`] (which body/SDE/force/output and which field) so that each file format can point at
//! its own location: a TOML line and column, or a JSON path.

use nalgebra::Matrix3;

use crate::model::{Body, Characteristic, Model, PointForce, PointMass, Sde};

/// A field of an element of the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    /// `bodies[i].field`.
    Body(usize, &'static str),
    /// `sdes[i].field`.
    Sde(usize, &'static str),
    /// `excitation.forces[i].field`.
    Force(usize, &'static str),
    /// `outputs[i].field`.
    Output(usize, &'static str),
    /// `point_masses[i].field`.
    PointMass(usize, &'static str),
    /// The model as a whole.
    Model,
}

/// A problem found in a model.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// Where.
    pub item: Item,
    /// What is wrong and how to fix it.
    pub message: String,
}

/// Checks that `r` is a proper rotation (orthonormal, right-handed) to `tol`.
pub fn rotation_problem(r: &Matrix3<f64>, tol: f64) -> Option<String> {
    if r.iter().any(|v| !v.is_finite()) {
        return Some("the axes contain NaN or infinite values".into());
    }
    let err = (r.transpose() * r - Matrix3::identity()).abs().max();
    if err > tol {
        return Some(format!(
            "the axes are not orthonormal (|RᵀR − I| = {err:.2e}); give three mutually \
             perpendicular unit vectors"
        ));
    }
    if r.determinant() < 0.0 {
        let c = r.column(0).cross(&r.column(1));
        return Some(format!(
            "the axes are left-handed; axis 3 must be axis 1 × axis 2 = [{:.6}, {:.6}, {:.6}]",
            c.x, c.y, c.z
        ));
    }
    None
}

/// Errors (which make the model unusable) and warnings (which do not) of a resolved model.
pub fn check(model: &Model) -> (Vec<Problem>, Vec<Problem>) {
    let mut errors = Vec::new();
    if model.bodies.is_empty() {
        errors.push(Problem {
            item: Item::Model,
            message: "the model has no bodies; add at least one [[body]]".into(),
        });
    }
    for (i, b) in model.bodies.iter().enumerate() {
        check_body(model, i, b, &mut errors);
    }
    for (i, s) in model.sdes.iter().enumerate() {
        check_sde(model, i, s, &mut errors);
    }
    for (i, f) in model.forces.iter().enumerate() {
        check_force(model, i, f, &mut errors);
    }
    for (i, o) in model.outputs.iter().enumerate() {
        check_output(model, i, o, &mut errors);
    }
    for (i, p) in model.point_masses.iter().enumerate() {
        check_point_mass(model, i, p, &mut errors);
    }
    if !errors.is_empty() {
        return (errors, Vec::new());
    }
    (errors, connectivity(model))
}

/// Point mass `i`: an existing body, a finite point, a positive mass, inertias ≥ 0, a unique
/// non-empty name.
fn check_point_mass(model: &Model, i: usize, p: &PointMass, errors: &mut Vec<Problem>) {
    let mut err = |field, message: String| {
        errors.push(Problem {
            item: Item::PointMass(i, field),
            message,
        })
    };
    let name = &p.name;
    if name.trim().is_empty() {
        err("name", "a point mass needs a non-empty name".into());
    } else if model.point_masses[..i].iter().any(|o| &o.name == name) {
        err(
            "name",
            format!("point mass name \"{name}\" is used twice; names must be unique"),
        );
    }
    if p.body >= model.bodies.len() {
        err(
            "body",
            format!(
                "point mass \"{name}\": body index {} does not exist; there are {} bodies",
                p.body,
                model.bodies.len()
            ),
        );
    }
    if p.point.iter().any(|v| !v.is_finite()) {
        err(
            "point",
            format!("point mass \"{name}\": point is not finite"),
        );
    }
    if !(p.mass.is_finite() && p.mass > 0.0) {
        err(
            "mass",
            format!(
                "point mass \"{name}\": mass must be a positive number of kg, got {}",
                p.mass
            ),
        );
    }
    if p.inertia.iter().any(|j| !(j.is_finite() && *j >= 0.0)) {
        err(
            "inertia",
            format!(
                "point mass \"{name}\": its own moments of inertia must be ≥ 0 (kg·m²), got {:?}",
                p.inertia
            ),
        );
    }
}

/// Body `i`: positive mass and inertias, finite position, proper axes, a unique name.
fn check_body(model: &Model, i: usize, b: &Body, errors: &mut Vec<Problem>) {
    let mut err = |item, message: String| errors.push(Problem { item, message });
    if !(b.mass.is_finite() && b.mass > 0.0) {
        err(
            Item::Body(i, "mass"),
            format!(
                "body \"{}\": mass must be a positive number of kg, got {}",
                b.name, b.mass
            ),
        );
    }
    if b.inertia.iter().any(|j| !(j.is_finite() && *j > 0.0)) {
        err(
            Item::Body(i, "inertia"),
            format!(
                "body \"{}\": principal moments of inertia must be positive (kg·m²), got {:?}",
                b.name, b.inertia
            ),
        );
    }
    if b.position.iter().any(|v| !v.is_finite()) {
        err(
            Item::Body(i, "position"),
            format!("body \"{}\": position is not finite", b.name),
        );
    }
    if let Some(m) = rotation_problem(&b.rotation, 1e-9) {
        err(
            Item::Body(i, "rotation"),
            format!("body \"{}\": {m}", b.name),
        );
    }
    if let Some(j) = model.bodies[..i].iter().position(|o| o.name == b.name) {
        err(
            Item::Body(i, "name"),
            format!(
                "body name \"{}\" is used twice (bodies {} and {}); names must be unique",
                b.name,
                j + 1,
                i + 1
            ),
        );
    }
}

/// SDE `i`: existing, different bodies, finite point, proper axes, finite non-negative
/// stiffness and ψ, a unique name.
fn check_sde(model: &Model, i: usize, s: &Sde, errors: &mut Vec<Problem>) {
    let nb = model.bodies.len();
    let mut err = |item, message: String| errors.push(Problem { item, message });
    for (side, b) in s.bodies.iter().enumerate() {
        if let Some(b) = b {
            if *b >= nb {
                err(Item::Sde(i, "bodies"), format!("sde \"{}\": body index {b} (side {side}) does not exist; there are {nb} bodies", s.name));
            }
        }
    }
    match s.bodies {
        [Some(a), Some(b)] if a == b => err(Item::Sde(i, "bodies"), format!(
            "sde \"{}\" joins body {} to itself; an SDE joins two different bodies, or a body and the ground",
            s.name, model.bodies.get(a).map(|b| b.name.as_str()).unwrap_or("?")
        )),
        [None, None] => err(Item::Sde(i, "bodies"), format!("sde \"{}\" joins the ground to the ground; name at least one body", s.name)),
        _ => {}
    }
    if s.point.iter().any(|v| !v.is_finite()) {
        err(
            Item::Sde(i, "point"),
            format!("sde \"{}\": point is not finite", s.name),
        );
    }
    if let Some(m) = rotation_problem(&s.rotation, 1e-9) {
        err(Item::Sde(i, "rotation"), format!("sde \"{}\": {m}", s.name));
    }
    let k = s.law.stiffness();
    let psi = s.law.dissipation();
    if k.iter().chain(&psi).any(|v| !v.is_finite()) {
        err(
            Item::Sde(i, "k"),
            format!(
                "sde \"{}\": stiffness or dissipation is NaN or infinite",
                s.name
            ),
        );
    } else if k.iter().any(|v| *v < 0.0) {
        err(
            Item::Sde(i, "k"),
            format!("sde \"{}\": stiffnesses must be ≥ 0, got {k:?}", s.name),
        );
    } else if psi.iter().any(|v| *v < 0.0) {
        err(
            Item::Sde(i, "psi"),
            format!("sde \"{}\": dissipation ψ must be ≥ 0, got {psi:?}", s.name),
        );
    }
    if let Some(j) = model.sdes[..i].iter().position(|o| o.name == s.name) {
        err(
            Item::Sde(i, "name"),
            format!(
                "sde name \"{}\" is used twice (elements {} and {}); names must be unique",
                s.name,
                j + 1,
                i + 1
            ),
        );
    }
}

/// Force `i`: on an existing body, finite.
fn check_force(model: &Model, i: usize, f: &PointForce, errors: &mut Vec<Problem>) {
    let nb = model.bodies.len();
    let mut err = |item, message: String| errors.push(Problem { item, message });
    if f.body >= nb {
        err(
            Item::Force(i, "body"),
            format!(
                "force {}: body index {} does not exist; there are {nb} bodies",
                i + 1,
                f.body
            ),
        );
    }
    if f.point
        .iter()
        .chain(f.force.iter())
        .chain(f.moment.iter())
        .any(|v| !v.is_finite())
    {
        err(
            Item::Force(i, "force"),
            format!("force {}: point, force or moment is not finite", i + 1),
        );
    }
}

/// Output `i`: on an existing body, a DOF 0-5.
fn check_output(model: &Model, i: usize, o: &Characteristic, errors: &mut Vec<Problem>) {
    let nb = model.bodies.len();
    let mut err = |item, message: String| errors.push(Problem { item, message });
    if o.body >= nb {
        err(
            Item::Output(i, "body"),
            format!(
                "output {}: body index {} does not exist; there are {nb} bodies",
                i + 1,
                o.body
            ),
        );
    }
    if o.dof > 5 {
        err(
            Item::Output(i, "dof"),
            format!(
                "output {}: dof {} is out of range 0-5 (u1 u2 u3 r1 r2 r3)",
                i + 1,
                o.dof
            ),
        );
    }
    let references = model.references.len();
    if usize::from(o.reference) > references {
        err(
            Item::Output(i, "reference"),
            format!(
                "output {}: reference {} does not exist; the model has {references} besides its excitation",
                i + 1,
                o.reference
            ),
        );
    } else if o.relative
        && (o.reference == 0
            || !matches!(
                model.references[usize::from(o.reference) - 1].excitation,
                crate::model::Excitation::BaseMotion { .. }
            ))
    {
        err(
            Item::Output(i, "relative"),
            format!(
                "output {}: a motion relative to the base needs a base-motion reference",
                i + 1
            ),
        );
    }
}

/// Warnings of a model without errors: bodies connected to nothing or held only by SDEs of zero
/// stiffness, and groups with no path to the ground.
fn connectivity(model: &Model) -> Vec<Problem> {
    let nb = model.bodies.len();
    let mut warnings = Vec::new();
    // Bodies touched by no enabled SDE, bodies held only by SDEs of zero stiffness,
    // and groups with no path to the ground (through SDEs with some stiffness).
    let mut touched = vec![false; nb];
    let mut held = vec![false; nb];
    let mut parent: Vec<usize> = (0..=nb).collect(); // index nb = ground
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for s in model.sdes.iter().filter(|s| s.enabled) {
        let stiff = s.law.stiffness().iter().any(|k| *k > 0.0);
        for b in s.bodies.iter().flatten() {
            touched[*b] = true;
            held[*b] |= stiff;
        }
        if stiff {
            let ends = s.bodies.map(|b| b.unwrap_or(nb));
            let (a, b) = (find(&mut parent, ends[0]), find(&mut parent, ends[1]));
            parent[a] = b;
        }
    }
    for (i, b) in model.bodies.iter().enumerate() {
        let why = if !touched[i] {
            "is connected to nothing"
        } else if !held[i] {
            "is held only by SDEs whose stiffnesses are all 0"
        } else {
            continue;
        };
        warnings.push(Problem {
            item: Item::Body(i, "name"),
            message: format!(
                "body \"{}\" {why}: it has six free rigid-body modes and its response is \
                 unbounded at 0 Hz; connect it with an SDE of nonzero stiffness or remove it",
                b.name
            ),
        });
    }
    let ground = find(&mut parent, nb);
    let floating: Vec<&str> = (0..nb)
        .filter(|&i| held[i] && find(&mut parent, i) != ground)
        .map(|i| model.bodies[i].name.as_str())
        .collect();
    if !floating.is_empty() {
        warnings.push(Problem {
            item: Item::Model,
            message: format!(
                "bodies {} have no path to the ground: the model has free rigid-body modes \
                 (response unbounded at 0 Hz); add isolators or supports if that is not intended",
                floating.join(", ")
            ),
        });
    }
    warnings
}
