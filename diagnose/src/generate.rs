//! The candidate list, generated from the model's geometry: hundreds of placements for a
//! machine-tool model.
//!
//! - springs: between every pair of bodies and between every body and the ground, at the points
//!   where something already acts on them (SDE attachment points, excitation points, the bodies'
//!   centres, the midpoint between two centres; to the ground also the centres of the body's
//!   equivalent-box faces) along the global axes and the excitation directions;
//! - point masses and resonators: at each body's centre, the corners of its equivalent box and
//!   the excitation points on it (resonators at log-spaced frequencies across the band);
//! - flexible bodies: every body along each principal axis;
//! - sensor gains: every characteristic;
//! - joint damping: for each ψ group, each joint (the group's SDEs between one pair of bodies);
//! - freed SDE directions: every direction an enabled SDE's law leaves out (an isolator's
//!   rotations, a screw's or spring's lateral directions, a general element's zeros), and every
//!   direction a general element holds at a stiffness no variable sets;
//! - body masses: every body whose mass and inertias no variable sets.

use nalgebra::Vector3;

use super::effects::{box_sides, Effect};
use identify::variables::Tie;
use identify::Variables;
use rfe::model::{Body, Model, Param, ParamName, ParamRef, SdeLaw};

/// Resonator frequencies per decade of the band.
const RESONATORS_PER_DECADE: f64 = 6.0;

fn push_unique(points: &mut Vec<Vector3<f64>>, p: Vector3<f64>) {
    if !points.iter().any(|q| (q - p).norm() < 1e-3) {
        points.push(p);
    }
}

/// Candidates for `model` (identified values `x` of `vars`), measured characteristics labelled
/// `labels`, band `f_lo..f_hi` (Hz).
pub fn candidates(
    model: &Model,
    vars: &Variables,
    x: &[f64],
    labels: &[String],
    f_lo: f64,
    f_hi: f64,
) -> Vec<Effect> {
    let mut out = springs(model, typical_psi(model));
    let n_res = ((f_hi / f_lo).log10() * RESONATORS_PER_DECADE)
        .ceil()
        .max(1.0) as usize;
    // Each resonator candidate stands for a cell of tuning frequencies (its score is the best
    // within it): the cells tile the band.
    let edge = |i: usize| f_lo * (f_hi / f_lo).powf(i as f64 / n_res as f64);
    let res_freqs: Vec<[f64; 2]> = (0..n_res).map(|i| [edge(i), edge(i + 1)]).collect();
    for b in 0..model.bodies.len() {
        masses_and_flexibility(model, b, &res_freqs, &mut out);
    }
    for (o, label) in labels.iter().enumerate() {
        out.push(Effect::Gain {
            output: o,
            label: label.clone(),
        });
    }
    damping_splits(model, vars, x, &mut out);
    freed_directions(model, vars, &mut out);
    body_masses(model, vars, &mut out);
    out
}

/// Every direction of an enabled SDE that its law leaves out ([`SdeLaw::leaves_out`]), and
/// every direction of a general element held at a stiffness no variable sets, as a candidate
/// to free. An SDE with no stiffness at all is no connection unless a variable sets one of its
/// stiffnesses: a fit can drive that one to 0 (a table actuator whose fitted axial stiffness went
/// to 0 to mimic its missing lateral stiffness), and the candidates follow the law's form, not
/// the fit's values, so that the missing lateral one stays a candidate.
fn freed_directions(model: &Model, vars: &Variables, out: &mut Vec<Effect>) {
    let by_vars = vars.params();
    let typical = [0..3, 3..6].map(|r| typical_stiffness(model, r));
    for (i, sde) in model.sdes.iter().enumerate().filter(|(_, s)| s.enabled) {
        let k = sde.law.stiffness();
        let fitted = by_vars
            .iter()
            .any(|r| r.sde == i && !r.name.is_dissipation());
        if k.iter().all(|v| *v == 0.0) && !fitted {
            continue;
        }
        let psi = sde.law.dissipation();
        let general = matches!(sde.law, SdeLaw::General { .. });
        for axis in 0..6 {
            let set_by_var = by_vars
                .iter()
                .any(|r| r.sde == i && r.name == ParamName::Ki(axis as u8));
            let candidate = if general {
                !set_by_var
            } else {
                sde.law.leaves_out(axis)
            };
            if !candidate {
                continue;
            }
            out.push(Effect::Direction {
                sde: sde.name.clone(),
                axis,
                held: k[axis],
                psi: psi[super::effects::psi_axis(&sde.law, axis)],
                scale: typical[axis / 3],
            });
        }
    }
}

/// The median nonzero stiffness of the enabled SDEs' directions `range` (0..3 translations,
/// 3..6 rotations); 1 when there is none.
fn typical_stiffness(model: &Model, range: std::ops::Range<usize>) -> f64 {
    let mut v: Vec<f64> = model
        .sdes
        .iter()
        .filter(|s| s.enabled)
        .flat_map(|s| s.law.stiffness()[range.clone()].to_vec())
        .filter(|k| *k > 0.0)
        .collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(1.0)
}

/// Every body whose mass and inertias no variable sets, as a candidate for a mass that is off.
fn body_masses(model: &Model, vars: &Variables, out: &mut Vec<Effect>) {
    let by_vars = vars.model_params();
    for (b, body) in model.bodies.iter().enumerate() {
        let fitted = by_vars
            .iter()
            .any(|p| matches!(p, Param::Mass { body } | Param::Inertia { body, .. } if *body == b));
        if !fitted && body.mass > 0.0 {
            out.push(Effect::BodyMass {
                body: body.name.clone(),
                mass: body.mass,
            });
        }
    }
}

/// The candidates of other kinds than `effect`'s that act on a body it acts on (the bodies a
/// spring joins, the body of a mass, resonator, flexibility or body mass, the two bodies of an
/// SDE's direction): point masses at the bodies' attachment points, the bodies'
/// flexibilities and masses, and the freed directions of every SDE attached to them. A
/// look-alike of another kind accepted in place of the effect the model lacks acts on the same
/// bodies (an SDE's missing stiffness along one of its axes, between two bodies, taken for a
/// spring between the same two bodies). None for a sensor's gain or a
/// joint-damping split.
pub(super) fn alternatives(model: &Model, vars: &Variables, effect: &Effect) -> Vec<Effect> {
    let touched = bodies_of(model, effect);
    let on_touched = |b: &Option<usize>| b.is_some_and(|b| touched.contains(&b));
    let mut out = Vec::new();
    for &b in &touched {
        masses_and_flexibility(model, b, &[], &mut out);
    }
    let mut directions = Vec::new();
    freed_directions(model, vars, &mut directions);
    out.extend(directions.into_iter().filter(|d| {
        match d {
            Effect::Direction { sde, .. } => model
                .sde_index(sde)
                .is_some_and(|i| model.sdes[i].bodies.iter().any(on_touched)),
            _ => false,
        }
    }));
    let mut masses = Vec::new();
    body_masses(model, vars, &mut masses);
    out.extend(masses.into_iter().filter(|m| match m {
        Effect::BodyMass { body, .. } => on_touched(&model.body_index(body)),
        _ => false,
    }));
    out.retain(|c| c.kind() != effect.kind());
    out
}

/// The bodies `effect` acts on (indices into `model.bodies`; the ground is left out).
fn bodies_of(model: &Model, effect: &Effect) -> Vec<usize> {
    match effect {
        Effect::Spring { bodies, .. } | Effect::PlacedSpring { bodies, .. } => bodies
            .iter()
            .flatten()
            .filter_map(|b| model.body_index(b))
            .collect(),
        Effect::Mass { body, .. }
        | Effect::PlacedMass { body, .. }
        | Effect::Resonator { body, .. }
        | Effect::Flexible { body, .. }
        | Effect::BodyMass { body, .. } => model.body_index(body).into_iter().collect(),
        Effect::Direction { sde, .. } => model
            .sde_index(sde)
            .map(|i| model.sdes[i].bodies.iter().flatten().copied().collect())
            .unwrap_or_default(),
        Effect::Gain { .. } | Effect::Damping { .. } => Vec::new(),
    }
}

/// Every spring candidate (ψ `psi` for the score): between each pair of bodies
/// ([`springs_between`]) and from each body to the ground ([`springs_to_ground`]).
pub(super) fn springs(model: &Model, psi: f64) -> Vec<Effect> {
    let directions = spring_directions(model);
    let mut out = Vec::new();
    for a in 0..model.bodies.len() {
        for b in (a + 1)..model.bodies.len() {
            springs_between(model, (a, b), &directions, psi, &mut out);
        }
        springs_to_ground(model, a, &directions, psi, &mut out);
    }
    out
}

/// Spring directions: the global axes and every excitation force's direction.
fn spring_directions(model: &Model) -> Vec<Vector3<f64>> {
    let mut directions = vec![Vector3::x(), Vector3::y(), Vector3::z()];
    for f in &model.forces {
        if f.force.norm() > 0.0 {
            let d = f.force.normalize();
            if !directions.iter().any(|e| e.dot(&d).abs() > 0.999) {
                directions.push(d);
            }
        }
    }
    directions
}

/// Where the forces on body `b` act.
fn force_points(model: &Model, b: usize) -> impl Iterator<Item = Vector3<f64>> + '_ {
    model
        .forces
        .iter()
        .filter(move |f| f.body == b)
        .map(|f| f.point)
}

/// Springs between bodies `a` and `b`: at their joints' points, the forces' points on one that
/// the other reaches ([`reaches`]) or where an excitation pair joins them ([`paired`]), and
/// midway between their centres, along every direction.
fn springs_between(
    model: &Model,
    (a, b): (usize, usize),
    directions: &[Vector3<f64>],
    psi: f64,
    out: &mut Vec<Effect>,
) {
    let mut points = Vec::new();
    for s in model.sdes.iter().filter(|s| s.enabled) {
        if (s.bodies == [Some(a), Some(b)]) || (s.bodies == [Some(b), Some(a)]) {
            push_unique(&mut points, s.point);
        }
    }
    let joined = paired(model, a, b);
    force_points(model, a)
        .filter(|p| joined || reaches(&model.bodies[b], p))
        .chain(force_points(model, b).filter(|p| joined || reaches(&model.bodies[a], p)))
        .for_each(|p| push_unique(&mut points, p));
    push_unique(
        &mut points,
        0.5 * (model.bodies[a].position + model.bodies[b].position),
    );
    for p in points {
        for d in directions {
            out.push(Effect::Spring {
                bodies: [
                    Some(model.bodies[a].name.clone()),
                    Some(model.bodies[b].name.clone()),
                ],
                point: p,
                direction: *d,
                psi,
            });
        }
    }
}

/// How far beyond its equivalent box a body reaches, as a share of the box's longest side.
const REACH: f64 = 0.1;

/// Whether `body` reaches point `p` (m): `p` lies within its equivalent box grown by [`REACH`]
/// of its longest side. An unmodelled connection between two bodies (a cover, a hose, a chip, a
/// contact) joins them where both are: a spring from the knee to the exciter's bracket on top
/// of the table would be a strut through the saddles. Such springs at the exciter's two points
/// were look-alikes of what acts through the exciter: on 200 blind cases they were added 13
/// times (10 times as the first effect), each time wrongly.
fn reaches(body: &Body, p: &Vector3<f64>) -> bool {
    let sides = box_sides(body);
    let grow = REACH * sides.iter().copied().fold(0.0, f64::max);
    let local = body.rotation.transpose() * (p - body.position);
    (0..3).all(|i| local[i].abs() <= 0.5 * sides[i] + grow)
}

/// Whether an excitation pair joins bodies `a` and `b`: equal and opposite forces on the two,
/// an exciter between them attached at the pair's points (where the demo's missing actuator is
/// found, its own SDE left out of the model).
fn paired(model: &Model, a: usize, b: usize) -> bool {
    let on = |body: usize| model.forces.iter().filter(move |f| f.body == body);
    on(a).any(|fa| {
        on(b).any(|fb| {
            let scale = fa.force.norm() + fa.moment.norm();
            scale > 0.0
                && (fa.force + fb.force).norm() + (fa.moment + fb.moment).norm() <= 1e-9 * scale
        })
    })
}

/// Springs from body `a` to the ground: at its grounded joints, its centre, its forces' points
/// and the centres of its equivalent box's faces (a support or contact from outside acts on a
/// face), along every direction.
fn springs_to_ground(
    model: &Model,
    a: usize,
    directions: &[Vector3<f64>],
    psi: f64,
    out: &mut Vec<Effect>,
) {
    let mut points = Vec::new();
    for s in model.sdes.iter().filter(|s| s.enabled) {
        if s.bodies.contains(&Some(a)) && s.bodies.contains(&None) {
            push_unique(&mut points, s.point);
        }
    }
    push_unique(&mut points, model.bodies[a].position);
    force_points(model, a).for_each(|p| push_unique(&mut points, p));
    // A support or contact from outside (a jack, a hose, a cover) acts on a face: the centres
    // of the equivalent box's faces.
    let body = &model.bodies[a];
    let sides = box_sides(body);
    for (axis, side) in sides.iter().enumerate() {
        for sign in [-1.0, 1.0] {
            push_unique(
                &mut points,
                body.position + body.rotation.column(axis) * (sign * 0.5 * side),
            );
        }
    }
    for p in points {
        for d in directions {
            out.push(Effect::Spring {
                bodies: [None, Some(model.bodies[a].name.clone())],
                point: p,
                direction: *d,
                psi,
            });
        }
    }
}

/// Where a point mass or resonator can sit on body `b`: its centre, its box's corners and the
/// points where the characteristics' forces act on it (global, m; no point twice).
pub(super) fn attachment_points(model: &Model, b: usize) -> Vec<Vector3<f64>> {
    let body = &model.bodies[b];
    let mut points = vec![body.position];
    let sides = box_sides(body);
    for corner in 0..8 {
        let s = |i: usize| if corner >> i & 1 == 1 { 0.5 } else { -0.5 };
        let local = Vector3::new(s(0) * sides[0], s(1) * sides[1], s(2) * sides[2]);
        push_unique(&mut points, body.position + body.rotation * local);
    }
    force_points(model, b).for_each(|p| push_unique(&mut points, p));
    points
}

/// Point masses and resonators (tuned across the band) at body `b`'s centre, box corners and
/// force points, and the body split along each principal axis.
fn masses_and_flexibility(model: &Model, b: usize, res_freqs: &[[f64; 2]], out: &mut Vec<Effect>) {
    let body = &model.bodies[b];
    let sides = box_sides(body);
    let scale = 0.01 * body.mass;
    for p in &attachment_points(model, b) {
        out.push(Effect::Mass {
            body: body.name.clone(),
            point: *p,
            scale,
        });
        for &[lo, hi] in res_freqs {
            out.push(Effect::Resonator {
                body: body.name.clone(),
                point: *p,
                freq_hz: (lo * hi).sqrt(),
                tuning: [lo, hi],
                scale,
            });
        }
    }
    let stiff = model
        .sdes
        .iter()
        .filter(|s| s.enabled)
        .flat_map(|s| s.law.stiffness()[..3].to_vec())
        .fold(0.0, f64::max);
    if stiff > 0.0 {
        for (axis, side) in sides.iter().enumerate() {
            if *side > 0.0 {
                out.push(Effect::Flexible {
                    body: body.name.clone(),
                    axis,
                    scale: 1.0 / stiff,
                });
            }
        }
    }
}

/// Joint damping: each ψ group split by the pair of bodies its SDEs join.
fn damping_splits(model: &Model, vars: &Variables, x: &[f64], out: &mut Vec<Effect>) {
    for (vi, v) in vars
        .vars
        .iter()
        .enumerate()
        .filter(|(_, v)| v.dissipation && v.tie == Tie::Equal && v.targets.len() > 1)
    {
        let refs: Vec<ParamRef> = v.targets.iter().filter_map(|t| t.param.sde()).collect();
        let Some(first) = refs.first() else { continue };
        let mut joints: Vec<([Option<usize>; 2], Vec<String>)> = Vec::new();
        // A direction the diagnosis freed follows its SDE's ψ as a target of another name
        // (`psi1`..`psi6`): it is not a joint of the group.
        for r in refs.iter().filter(|r| r.name == first.name) {
            let sde = &model.sdes[r.sde];
            let mut key = sde.bodies;
            key.sort();
            match joints.iter_mut().find(|(k, _)| *k == key) {
                Some((_, names)) => names.push(sde.name.clone()),
                None => joints.push((key, vec![sde.name.clone()])),
            }
        }
        if joints.len() < 2 {
            continue;
        }
        for (_, sdes) in joints {
            out.push(Effect::Damping {
                variable: vi,
                variable_name: v.name.clone(),
                sdes,
                parameter: first.name,
                value: x[vi],
            });
        }
    }
}

/// The median ψ of the model's enabled SDEs (ψ of a spring candidate in its score).
fn typical_psi(model: &Model) -> f64 {
    let mut v: Vec<f64> = model
        .sdes
        .iter()
        .filter(|s| s.enabled)
        .flat_map(|s| {
            let k = s.law.stiffness();
            let p = s.law.dissipation();
            (0..6).filter(move |&i| k[i] > 0.0).map(move |i| p[i])
        })
        .collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.3)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The table actuator (SDE 34, an axial spring) whose fitted stiffness went to 0 keeps its
    /// five other directions as candidates to free; with no variable setting its stiffness it
    /// is no connection and has none.
    #[test]
    fn an_sde_whose_fitted_stiffness_is_0_keeps_the_directions_its_law_leaves_out() {
        let mut model = crate::test_support::fwd32j();
        let vars_file = crate::test_support::repo_file("configs/identification/fwd32j.toml");
        let vars = identify::variables::load(&vars_file, &model).unwrap();
        let s = model.sde_index("34").unwrap();
        model.sdes[s].law = SdeLaw::Axial { k: 0.0, psi: 0.3 };
        let freed = |vars: &Variables| -> Vec<usize> {
            let x: Vec<f64> = vars.vars.iter().map(|v| v.initial).collect();
            candidates(&model, vars, &x, &["u1".to_string()], 20.0, 400.0)
                .iter()
                .filter_map(|e| match e {
                    Effect::Direction { sde, axis, .. } if sde == "34" => Some(*axis),
                    _ => None,
                })
                .collect()
        };
        assert_eq!(freed(&vars), [1, 2, 3, 4, 5]);
        let none = Variables {
            origin: "none".into(),
            vars: Vec::new(),
            extra_starts: Vec::new(),
        };
        assert!(freed(&none).is_empty());
    }

    /// FWD-32J's springs between two bodies stand where both reach: the exciter joins the
    /// spindle head to the table at its ball and its bracket, the bracket on top of the table is
    /// out of the knee's, the saddles' and the column's reach, and the knee–lower saddle ways keep
    /// theirs.
    #[test]
    fn springs_between_two_bodies_stand_where_both_reach() {
        let model = crate::test_support::fwd32j();
        let vars_file = crate::test_support::repo_file("configs/identification/fwd32j.toml");
        let vars = identify::variables::load(&vars_file, &model).unwrap();
        let x: Vec<f64> = vars.vars.iter().map(|v| v.initial).collect();
        let labels = ["u1".to_string(), "u2".into(), "u3".into()];
        let library = candidates(&model, &vars, &x, &labels, 20.0, 400.0);
        let springs_at = |a: &str, b: &str, p: [f64; 3]| {
            library
                .iter()
                .filter(|e| match e {
                    Effect::Spring { bodies, point, .. } => {
                        bodies == &[Some(a.to_string()), Some(b.to_string())]
                            && (point - Vector3::from(p)).norm() < 1e-6
                    }
                    _ => false,
                })
                .count()
        };
        let ball = [0.0, 0.9, 1.15];
        let bracket = [-0.098769, 0.728927, 1.118713];
        assert!(springs_at("spindle head", "table", ball) > 0);
        // The exciter joins the spindle head and the table at both its points.
        assert!(springs_at("spindle head", "table", bracket) > 0);
        for body in ["knee", "lower saddle", "upper saddle", "column"] {
            assert_eq!(springs_at(body, "table", bracket), 0, "{body}–table");
        }
        let way = model.sdes.iter().find(|s| s.name == "23").unwrap().point;
        assert!(springs_at("knee", "lower saddle", way.into()) > 0);
        assert!(reaches(&model.bodies[0], &model.bodies[0].position));
    }

    /// A spring between the column and the knee has, among its alternatives, SDE 12's missing
    /// stiffness along its axis 2 (the SDE those two bodies share), the two bodies' flexibilities
    /// and point masses, and no spring and nothing on a body it does not touch; a sensor's gain
    /// has none.
    #[test]
    fn a_springs_alternatives_are_the_other_kinds_on_the_bodies_it_joins() {
        let model = crate::test_support::fwd32j();
        let vars_file = crate::test_support::repo_file("configs/identification/fwd32j.toml");
        let vars = identify::variables::load(&vars_file, &model).unwrap();
        let spring = Effect::Spring {
            bodies: [Some("column".into()), Some("knee".into())],
            point: Vector3::new(0.0, 0.75, 0.1),
            direction: Vector3::y(),
            psi: 0.3,
        };
        let found = alternatives(&model, &vars, &spring);
        let has = |kind: &str, site: &str| {
            found
                .iter()
                .any(|e| e.kind() == kind && e.site() == [Some(site)])
        };
        assert!(found
            .iter()
            .any(|e| matches!(e, Effect::Direction { sde, axis: 1, .. } if sde == "12")));
        for body in ["column", "knee"] {
            assert!(has("flexible body", body), "{body}'s flexibility");
            assert!(has("mass", body), "point masses on the {body}");
        }
        assert!(!found.iter().any(|e| e.kind() == "spring"));
        let joins = |sde: &str, body: &str| {
            let (s, b) = (model.sde_index(sde).unwrap(), model.body_index(body));
            model.sdes[s].bodies.contains(&b)
        };
        for e in &found {
            let on_touched = match e {
                Effect::Direction { sde, .. } => joins(sde, "column") || joins(sde, "knee"),
                _ => e.site() == [Some("column")] || e.site() == [Some("knee")],
            };
            assert!(on_touched, "{} acts on neither body", e.describe());
        }
        let gain = Effect::Gain {
            output: 0,
            label: "u1".into(),
        };
        assert!(alternatives(&model, &vars, &gain).is_empty());
    }
}
