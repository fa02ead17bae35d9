//! The model as a drawing: each body as the uniform box with its mass and principal inertias, the
//! SDEs, the exciter and the measured points in two orthogonal projections (front x–z and side
//! y–z, the views that show a machine tool's column, knee and table best), and the shapes of the
//! modes in the measured band, deformed over undeformed.
//!
//! [`describe`] turns a [`Model`] into a [`ModelPicture`], the data the report carries (JSON field
//! `picture`, `docs/report-json.md`); [`model_svg`] and [`mode_svg`] draw it, so `report.json`
//! alone renders the figures. Drawing uses plotters' SVG backend in pixel coordinates, like the
//! report's charts (text as SVG `<text>`); the projection onto the page is [`Projection`].
//!
//! Units: metres, kilograms, newtons, radians, hertz (SI) in the data; pixels only on the page.

use nalgebra::{Matrix3, Vector3};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use rfe::model::{Body, SdeKind, DOF_NAMES};
use rfe::{modes, Model};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::DrawError;
use crate::ReportError;

/// At most this many modes in the band are drawn (and stored); the rest are counted in
/// [`ModelPicture::modes_omitted`].
pub const MAX_MODES: usize = 8;

/// The largest drawn displacement of a mode shape, as a fraction of the machine's largest extent.
pub const MODE_AMPLITUDE: f64 = 0.08;

/// A derived box side shorter than this fraction of the body's longest side is drawn at it.
pub const MIN_SIDE_FRACTION: f64 = 0.05;

/// The shortest drawn side (m).
pub const MIN_SIDE: f64 = 0.01;

/// What the report needs to draw the model and its modes (SI units, global frame).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModelPicture {
    /// The drawn model's name (the final model: after diagnosis, with the accepted effects).
    pub model: String,
    /// Every body as its equivalent uniform box.
    pub bodies: Vec<BodyBox>,
    /// Every enabled SDE (disabled ones contribute nothing and are not drawn).
    pub sdes: Vec<SdeMark>,
    /// The excitation: one entry per point force.
    pub exciters: Vec<Exciter>,
    /// The output characteristics (measured points).
    pub outputs: Vec<OutputMark>,
    /// The measured band (Hz): lowest and highest line.
    pub band_hz: [f64; 2],
    /// The model's modes in the band, ascending, at most [`MAX_MODES`].
    pub modes: Vec<ModeShape>,
    /// Modes in the band that were not stored (beyond [`MAX_MODES`]).
    pub modes_omitted: usize,
}

/// A body drawn as the uniform box with its mass and principal central inertias.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BodyBox {
    /// Body name.
    pub name: String,
    /// Mass (kg).
    pub mass_kg: f64,
    /// Centre of mass, global (m).
    pub centre_m: [f64; 3],
    /// `axes[i]`: principal axis i+1 as a global unit vector.
    pub axes: [[f64; 3]; 3],
    /// Half sides of the box along the principal axes (m).
    pub half_sizes_m: [f64; 3],
    /// A side was too short (or imaginary) and is drawn at the minimum ([`equivalent_box`]).
    pub clamped: bool,
    /// Not in the identification model: added by an accepted diagnosis effect.
    pub added: bool,
}

/// An SDE's place and connections.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SdeMark {
    /// SDE name.
    pub name: String,
    /// `slideway`, `rotary`, `screw`, `spring`, `isolator`, `general`.
    pub kind: String,
    /// Where it acts, global (m).
    pub point_m: [f64; 3],
    /// Its axis 1 (normal, screw or spring axis), global unit vector.
    pub axis: [f64; 3],
    /// `[p, r]`: indices into `bodies`; `null` is the ground.
    pub bodies: [Option<usize>; 2],
    /// Not in the identification model: added by an accepted diagnosis effect.
    pub added: bool,
}

/// A harmonic point force of the excitation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Exciter {
    /// Index into `bodies`.
    pub body: usize,
    /// Point of application, global (m).
    pub point_m: [f64; 3],
    /// Force amplitude, global (N).
    pub force_n: [f64; 3],
}

/// A measured characteristic: a DOF of a body's centre of mass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OutputMark {
    /// `"table u1 displacement"`.
    pub label: String,
    /// Index into `bodies`.
    pub body: usize,
    /// 0-2 translations u1..u3, 3-5 rotations r1..r3 (principal axes).
    pub dof: u8,
    /// The DOF's principal axis, global unit vector (translation along, rotation about it).
    pub direction: [f64; 3],
}

/// One mode of the model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModeShape {
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Loss factor η (-).
    pub loss_factor: f64,
    /// The body with the largest share of the mode's kinetic energy.
    pub moves_most: String,
    /// Share of the kinetic energy per body (sums to 1), in `bodies` order.
    pub energy: Vec<f64>,
    /// Per body `[u1, u2, u3, r1, r2, r3]` along/about its principal axes (m, rad): the real part
    /// of the complex mode shape scaled so that its largest component is 1 (the scale is
    /// arbitrary; only ratios matter).
    pub shape: Vec<[f64; 6]>,
}

fn arr(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn vec3(a: &[f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

/// Full sides (m) of the uniform box with the body's mass and principal inertias, and whether a
/// side was clamped.
///
/// From `J1 = m(b² + c²)/12` and its cyclic forms, `a² = 6(J2 + J3 − J1)/m`
/// (`diagnose::effects::box_sides`). Inertias no uniform box has (`J1 > J2 + J3`,
/// e.g. a point mass on an arm) make a square negative, and a flat plate makes it zero: such sides,
/// and any side shorter than [`MIN_SIDE_FRACTION`] of the longest, are drawn at that fraction (at
/// least [`MIN_SIDE`]) so the box stays visible; `clamped` is then true. The drawing is a picture,
/// not the mass distribution.
pub fn equivalent_box(body: &Body) -> ([f64; 3], bool) {
    let sides = diagnose::effects::box_sides(body);
    let longest = sides
        .iter()
        .copied()
        .filter(|s| s.is_finite())
        .fold(0.0, f64::max);
    let least = (MIN_SIDE_FRACTION * longest).max(MIN_SIDE);
    let mut clamped = false;
    let sides = sides.map(|s| {
        if s.is_finite() && s >= least {
            s
        } else {
            clamped = true;
            least
        }
    });
    (sides, clamped)
}

/// The drawing data of `model`; SDEs and bodies whose names `identified` lacks are marked as
/// added by diagnosis. Modes are the complex modes of `model` with natural frequencies in
/// `band_hz` (Hz).
pub fn describe(
    model: &Model,
    identified: &Model,
    band_hz: [f64; 2],
) -> Result<ModelPicture, ReportError> {
    let bodies = model
        .bodies
        .iter()
        .map(|b| {
            let (sides, clamped) = equivalent_box(b);
            BodyBox {
                name: b.name.clone(),
                mass_kg: b.mass,
                centre_m: arr(&b.position),
                axes: [0, 1, 2].map(|i| arr(&b.rotation.column(i).into_owned())),
                half_sizes_m: sides.map(|s| s / 2.0),
                clamped,
                added: identified.body_index(&b.name).is_none(),
            }
        })
        .collect();
    let sdes = model
        .sdes
        .iter()
        .filter(|s| s.enabled)
        .map(|s| SdeMark {
            name: s.name.clone(),
            kind: s.kind.as_str().into(),
            point_m: arr(&s.point),
            axis: arr(&s.rotation.column(0).into_owned()),
            bodies: s.bodies,
            added: identified
                .sde_index(&s.name)
                .is_none_or(|i| !identified.sdes[i].enabled),
        })
        .collect();
    let exciters = model
        .forces
        .iter()
        .map(|f| Exciter {
            body: f.body,
            point_m: arr(&f.point),
            force_n: arr(&f.force),
        })
        .collect();
    let outputs = model
        .outputs
        .iter()
        .map(|c| OutputMark {
            label: model.characteristic_label(*c),
            body: c.body,
            dof: c.dof,
            direction: model
                .bodies
                .get(c.body)
                .map(|b| arr(&b.rotation.column(usize::from(c.dof % 3)).into_owned()))
                .unwrap_or([0.0; 3]),
        })
        .collect();
    let all = modes::complex(model).map_err(|source| ReportError::Model {
        stage: "final (mode shapes)".into(),
        source,
    })?;
    let in_band: Vec<&modes::Mode> = all
        .iter()
        .filter(|m| m.freq_hz > 0.0 && m.freq_hz >= band_hz[0] && m.freq_hz <= band_hz[1])
        .collect();
    let modes_omitted = in_band.len().saturating_sub(MAX_MODES);
    let modes = in_band
        .into_iter()
        .take(MAX_MODES)
        .map(|m| mode_shape(model, m))
        .collect();
    Ok(ModelPicture {
        model: model.name.clone(),
        bodies,
        sdes,
        exciters,
        outputs,
        band_hz,
        modes,
        modes_omitted,
    })
}

fn finite(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else {
        0.0
    }
}

fn mode_shape(model: &Model, m: &modes::Mode) -> ModeShape {
    let most = m
        .energy
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i);
    ModeShape {
        freq_hz: finite(m.freq_hz),
        loss_factor: finite(m.loss_factor),
        moves_most: most
            .and_then(|i| model.bodies.get(i))
            .map(|b| b.name.clone())
            .unwrap_or_default(),
        energy: m.energy.iter().copied().map(finite).collect(),
        shape: (0..model.bodies.len())
            .map(|b| std::array::from_fn(|i| finite(m.shape.get(6 * b + i).map_or(0.0, |v| v.re))))
            .collect(),
    }
}

impl BodyBox {
    /// `global_from_body`: columns are the principal axes.
    pub fn global_from_body(&self) -> Matrix3<f64> {
        Matrix3::from_columns(&self.axes.map(|a| vec3(&a)))
    }

    /// The eight corners of the box, global (m).
    pub fn corners(&self) -> [Vector3<f64>; 8] {
        let r = self.global_from_body();
        let c = vec3(&self.centre_m);
        let h = self.half_sizes_m;
        std::array::from_fn(|k| {
            let s = |bit: usize| if k & (1 << bit) == 0 { -1.0 } else { 1.0 };
            c + r * Vector3::new(s(0) * h[0], s(1) * h[1], s(2) * h[2])
        })
    }

    /// Displacement of the global point `p` when the body moves by `q = [u1, u2, u3, r1, r2, r3]`
    /// (its principal axes): `u + θ × (p − c)` with `u`, `θ` turned into the global frame.
    pub fn motion_at(&self, q: &[f64; 6], p: &Vector3<f64>) -> Vector3<f64> {
        let r = self.global_from_body();
        let u = r * Vector3::new(q[0], q[1], q[2]);
        let theta = r * Vector3::new(q[3], q[4], q[5]);
        u + theta.cross(&(p - vec3(&self.centre_m)))
    }
}

/// Each body's corners moved by mode `mode`, scaled so that the largest corner displacement is
/// [`MODE_AMPLITUDE`] of the machine's largest extent; also returns that scale factor (m per unit
/// of the stored shape). Bodies without a shape entry do not move.
pub fn deformed_corners(p: &ModelPicture, mode: &ModeShape) -> (Vec<[Vector3<f64>; 8]>, f64) {
    let zero = [0.0; 6];
    let moves: Vec<[Vector3<f64>; 8]> = p
        .bodies
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let q = mode.shape.get(i).unwrap_or(&zero);
            b.corners().map(|c| b.motion_at(q, &c))
        })
        .collect();
    let largest = moves
        .iter()
        .flat_map(|m| m.iter().map(|d| d.norm()))
        .filter(|d| d.is_finite())
        .fold(0.0, f64::max);
    let scale = if largest > 0.0 {
        MODE_AMPLITUDE * extent(p).size() / largest
    } else {
        0.0
    };
    let corners = p
        .bodies
        .iter()
        .zip(&moves)
        .map(|(b, m)| {
            let c = b.corners();
            std::array::from_fn(|k| c[k] + m[k] * scale)
        })
        .collect();
    (corners, scale)
}

/// The region of space the drawing covers (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Smallest x, y, z.
    pub lo: [f64; 3],
    /// Largest x, y, z.
    pub hi: [f64; 3],
}

impl Extent {
    /// The largest of the three spans (m), at least [`MIN_SIDE`].
    pub fn size(&self) -> f64 {
        (0..3)
            .map(|i| self.hi[i] - self.lo[i])
            .fold(MIN_SIDE, f64::max)
    }
}

/// Everything drawn: body corners, SDE points and exciter points, widened by 5 % of the largest
/// span on every side (room for displaced mode shapes and symbols).
pub fn extent(p: &ModelPicture) -> Extent {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let points = p
        .bodies
        .iter()
        .flat_map(|b| b.corners())
        .chain(p.sdes.iter().map(|s| vec3(&s.point_m)))
        .chain(p.exciters.iter().map(|e| vec3(&e.point_m)));
    for q in points {
        for i in 0..3 {
            if q[i].is_finite() {
                lo[i] = lo[i].min(q[i]);
                hi[i] = hi[i].max(q[i]);
            }
        }
    }
    for i in 0..3 {
        if lo[i] > hi[i] {
            (lo[i], hi[i]) = (-0.5, 0.5);
        }
    }
    let e = Extent { lo, hi };
    let margin = 0.05 * e.size();
    Extent {
        lo: lo.map(|v| v - margin),
        hi: hi.map(|v| v + margin),
    }
}

/// An orthogonal view: which global axes run right and up on the page.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct View {
    /// Title on the page.
    pub name: &'static str,
    /// Global axis (0 x, 1 y, 2 z) running to the right.
    pub right: usize,
    /// Global axis running up.
    pub up: usize,
}

/// Front view: x to the right, z up.
pub const FRONT: View = View {
    name: "front view (x right, z up)",
    right: 0,
    up: 2,
};

/// Side view: y to the right, z up.
pub const SIDE: View = View {
    name: "side view (y right, z up)",
    right: 1,
    up: 2,
};

/// A view placed on the page: global point → SVG pixel (y down).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// The view.
    pub view: View,
    /// Pixels per metre.
    pub scale: f64,
    /// Pixel of the extent's corner (smallest `right`, largest `up`) = the region's top left.
    pub origin: (f64, f64),
    /// Smallest `right` coordinate of the extent (m).
    pub right_lo: f64,
    /// Largest `up` coordinate of the extent (m).
    pub up_hi: f64,
}

impl Projection {
    /// Places `view` of `extent` at `scale` (px/m) centred in the pixel rectangle `region`
    /// (`x, y, width, height`).
    pub fn new(view: View, extent: &Extent, scale: f64, region: (f64, f64, f64, f64)) -> Self {
        let w = (extent.hi[view.right] - extent.lo[view.right]) * scale;
        let h = (extent.hi[view.up] - extent.lo[view.up]) * scale;
        Projection {
            view,
            scale,
            origin: (
                region.0 + (region.2 - w).max(0.0) / 2.0,
                region.1 + (region.3 - h).max(0.0) / 2.0,
            ),
            right_lo: extent.lo[view.right],
            up_hi: extent.hi[view.up],
        }
    }

    /// The pixel of a global point (m), unrounded.
    pub fn at(&self, p: &Vector3<f64>) -> (f64, f64) {
        (
            self.origin.0 + (p[self.view.right] - self.right_lo) * self.scale,
            self.origin.1 + (self.up_hi - p[self.view.up]) * self.scale,
        )
    }

    /// The pixel of a global point (m).
    pub fn px(&self, p: &Vector3<f64>) -> (i32, i32) {
        let (x, y) = self.at(p);
        (x.round() as i32, y.round() as i32)
    }

    /// A global direction on the page: (right, down) components, unit-free.
    pub fn direction(&self, d: &Vector3<f64>) -> (f64, f64) {
        (d[self.view.right], -d[self.view.up])
    }
}

/// The largest scale (px/m) at which every view of `extent` fits a `width` × `height` region.
pub fn fit_scale(views: &[View], extent: &Extent, width: f64, height: f64) -> f64 {
    views
        .iter()
        .map(|v| {
            let w = extent.hi[v.right] - extent.lo[v.right];
            let h = extent.hi[v.up] - extent.lo[v.up];
            (width / w.max(MIN_SIDE)).min(height / h.max(MIN_SIDE))
        })
        .fold(f64::INFINITY, f64::min)
}

/// Convex hull of pixel points (Andrew's monotone chain), counter-clockwise on the page: the
/// outline of a projected box.
pub fn hull(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut lower: Vec<(f64, f64)> = Vec::new();
    for &q in &p {
        while lower.len() >= 2 && cross(lower[lower.len() - 2], lower[lower.len() - 1], q) <= 0.0 {
            lower.pop();
        }
        lower.push(q);
    }
    let mut upper: Vec<(f64, f64)> = Vec::new();
    for &q in p.iter().rev() {
        while upper.len() >= 2 && cross(upper[upper.len() - 2], upper[upper.len() - 1], q) <= 0.0 {
            upper.pop();
        }
        upper.push(q);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

// ------------------------------------------------------------------------------------------------
// Drawing

const FONT: &str = "sans-serif";
const BODY: RGBColor = RGBColor(70, 70, 70);
const LINK: RGBColor = RGBColor(175, 175, 175);
const SDE: RGBColor = RGBColor(90, 90, 90);
const EXCITER: RGBColor = RGBColor(214, 39, 40);
const MEASURED: RGBColor = RGBColor(31, 119, 180);
const ADDED: RGBColor = RGBColor(204, 0, 153);
const UNDEFORMED: RGBColor = RGBColor(185, 185, 185);
const DEFORMED: RGBColor = RGBColor(255, 127, 14);

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;

fn ipt(p: (f64, f64)) -> (i32, i32) {
    (p.0.round() as i32, p.1.round() as i32)
}

fn label(
    area: &Area<'_>,
    s: &str,
    at: (i32, i32),
    size: u32,
    colour: RGBColor,
    h: HPos,
) -> Result<(), DrawError> {
    let style = TextStyle::from((FONT, size).into_font())
        .color(&colour)
        .pos(Pos::new(h, VPos::Center));
    area.draw(&Text::new(s.to_string(), at, style))
}

fn svg(
    chart: &str,
    size: (u32, u32),
    draw: impl FnOnce(&Area<'_>) -> Result<(), DrawError>,
) -> Result<String, ReportError> {
    let err = |source| ReportError::Plot {
        chart: chart.to_string(),
        source,
    };
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        draw(&root).map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(out)
}

/// A box's outline in a view.
fn outline(pr: &Projection, corners: &[Vector3<f64>; 8]) -> Vec<(i32, i32)> {
    let pts: Vec<(f64, f64)> = corners.iter().map(|c| pr.at(c)).collect();
    hull(&pts).into_iter().map(ipt).collect()
}

fn closed(mut p: Vec<(i32, i32)>) -> Vec<(i32, i32)> {
    if let Some(&f) = p.first() {
        p.push(f);
    }
    p
}

/// An arrow from `from` along the page direction `d` (unit-free) for `len` pixels.
fn arrow(
    area: &Area<'_>,
    from: (f64, f64),
    d: (f64, f64),
    len: f64,
    style: ShapeStyle,
) -> Result<(f64, f64), DrawError> {
    let n = (d.0 * d.0 + d.1 * d.1).sqrt();
    if n < 1e-9 {
        return Ok(from);
    }
    let (ux, uy) = (d.0 / n, d.1 / n);
    let tip = (from.0 + ux * len, from.1 + uy * len);
    area.draw(&PathElement::new(vec![ipt(from), ipt(tip)], style))?;
    let (hx, hy) = (tip.0 - ux * 8.0, tip.1 - uy * 8.0);
    let head = vec![
        ipt(tip),
        ipt((hx - uy * 4.0, hy + ux * 4.0)),
        ipt((hx + uy * 4.0, hy - ux * 4.0)),
    ];
    area.draw(&Polygon::new(head, style.color.filled()))?;
    Ok(tip)
}

/// The symbol of an SDE kind at `at`.
fn sde_symbol(
    area: &Area<'_>,
    kind: &str,
    at: (i32, i32),
    colour: RGBColor,
) -> Result<(), DrawError> {
    let (x, y) = at;
    let r = 4;
    let diamond = vec![
        (x, y - r - 1),
        (x + r + 1, y),
        (x, y + r + 1),
        (x - r - 1, y),
    ];
    match kind {
        k if k == SdeKind::Slideway.as_str() => area.draw(&Rectangle::new(
            [(x - r, y - r), (x + r, y + r)],
            colour.filled(),
        )),
        k if k == SdeKind::Rotary.as_str() => {
            area.draw(&Circle::new((x, y), r + 1, colour.stroke_width(2)))
        }
        k if k == SdeKind::Screw.as_str() => area.draw(&Polygon::new(diamond, colour.filled())),
        k if k == SdeKind::Spring.as_str() => {
            area.draw(&PathElement::new(closed(diamond), colour.stroke_width(2)))
        }
        k if k == SdeKind::Isolator.as_str() => area.draw(&Polygon::new(
            vec![(x, y - r - 1), (x + r + 1, y + r), (x - r - 1, y + r)],
            colour.filled(),
        )),
        _ => {
            area.draw(&PathElement::new(
                vec![(x - r, y - r), (x + r, y + r)],
                colour.stroke_width(2),
            ))?;
            area.draw(&PathElement::new(
                vec![(x - r, y + r), (x + r, y - r)],
                colour.stroke_width(2),
            ))
        }
    }
}

/// The ground: a line under `at` with hatching.
fn ground(area: &Area<'_>, at: (i32, i32), colour: RGBColor) -> Result<(), DrawError> {
    let (x, y) = (at.0, at.1 + 7);
    area.draw(&PathElement::new(
        vec![(x - 8, y), (x + 8, y)],
        colour.stroke_width(1),
    ))?;
    for i in 0..4 {
        let x0 = x - 7 + 5 * i;
        area.draw(&PathElement::new(
            vec![(x0, y), (x0 - 4, y + 5)],
            colour.stroke_width(1),
        ))?;
    }
    Ok(())
}

/// `targets` (pixel y of each label's anchor) spread so that labels are at least `gap` apart and
/// within `[top, bottom]`, order kept.
fn spread(targets: &[f64], gap: f64, top: f64, bottom: f64) -> Vec<f64> {
    let mut order: Vec<usize> = (0..targets.len()).collect();
    order.sort_by(|a, b| targets[*a].total_cmp(&targets[*b]));
    let mut y: Vec<f64> = order.iter().map(|&i| targets[i].max(top)).collect();
    for k in 1..y.len() {
        y[k] = y[k].max(y[k - 1] + gap);
    }
    if let Some(&last) = y.last() {
        if last > bottom {
            let shift = last - bottom;
            for v in y.iter_mut() {
                *v -= shift;
            }
            for k in (0..y.len().saturating_sub(1)).rev() {
                y[k] = y[k].min(y[k + 1] - gap);
            }
        }
    }
    let mut out = vec![0.0; targets.len()];
    for (k, &i) in order.iter().enumerate() {
        out[i] = y[k];
    }
    out
}

/// `SDE 34` for the paper's numbered SDEs, the name itself otherwise.
fn sde_label(name: &str) -> String {
    if name.starts_with(|c: char| c.is_ascii_digit()) {
        format!("SDE {name}")
    } else {
        name.to_string()
    }
}

/// A callout label that fits its column: at most 20 characters, cut with an ellipsis.
fn short(name: &str) -> String {
    if name.chars().count() <= 20 {
        name.to_string()
    } else {
        let head: String = name.chars().take(19).collect();
        format!("{head}…")
    }
}

fn force_text(f: f64) -> String {
    if f >= 1000.0 {
        format!("{} kN", rfe::display::sig(f / 1000.0, 3))
    } else {
        format!("{} N", rfe::display::sig(f, 3))
    }
}

/// One view of the model: boxes with callout labels at the right of `region`, SDEs, exciter,
/// measured points, accepted effects.
fn draw_view(
    area: &Area<'_>,
    p: &ModelPicture,
    pr: &Projection,
    labels_x: i32,
    region: (f64, f64, f64, f64),
) -> Result<(), DrawError> {
    let corners: Vec<[Vector3<f64>; 8]> = p.bodies.iter().map(BodyBox::corners).collect();
    // Bodies, largest first so that small ones stay visible on top.
    let mut order: Vec<usize> = (0..p.bodies.len()).collect();
    let volume = |b: &BodyBox| b.half_sizes_m.iter().product::<f64>();
    order.sort_by(|a, b| volume(&p.bodies[*b]).total_cmp(&volume(&p.bodies[*a])));
    for &i in &order {
        let b = &p.bodies[i];
        let colour = if b.added { ADDED } else { BODY };
        let o = outline(pr, &corners[i]);
        area.draw(&Polygon::new(o.clone(), colour.mix(0.07).filled()))?;
        area.draw(&PathElement::new(
            closed(o),
            colour.stroke_width(if b.added { 2 } else { 1 }),
        ))?;
    }
    // SDE links and symbols.
    for s in &p.sdes {
        let at = pr.at(&vec3(&s.point_m));
        let colour = if s.added { ADDED } else { LINK };
        for b in s.bodies.iter().flatten() {
            if let Some(body) = p.bodies.get(*b) {
                area.draw(&PathElement::new(
                    vec![ipt(at), pr.px(&vec3(&body.centre_m))],
                    colour.stroke_width(if s.added { 2 } else { 1 }),
                ))?;
            }
        }
    }
    for s in p.sdes.iter().filter(|s| !s.added) {
        let at = pr.px(&vec3(&s.point_m));
        sde_symbol(area, &s.kind, at, SDE)?;
        if s.bodies.iter().any(Option::is_none) {
            ground(area, at, SDE)?;
        }
    }
    // Exciter.
    let mut labelled = false;
    for e in &p.exciters {
        let f = vec3(&e.force_n);
        let n = f.norm();
        if !(n > 0.0 && n.is_finite()) {
            continue;
        }
        let from = pr.at(&vec3(&e.point_m));
        let d = pr.direction(&(f / n));
        let inplane = (d.0 * d.0 + d.1 * d.1).sqrt();
        let tip = if inplane > 0.15 {
            arrow(
                area,
                from,
                d,
                16.0 + 34.0 * inplane,
                EXCITER.stroke_width(2),
            )?
        } else {
            // Nearly along the line of sight: a ring with a dot.
            area.draw(&Circle::new(ipt(from), 6, EXCITER.stroke_width(2)))?;
            area.draw(&Circle::new(ipt(from), 2, EXCITER.filled()))?;
            (from.0 + 6.0, from.1)
        };
        if !labelled {
            label(
                area,
                &format!("P {}", force_text(n)),
                (tip.0.round() as i32 + 4, tip.1.round() as i32 - 8),
                12,
                EXCITER,
                HPos::Left,
            )?;
            labelled = true;
        }
    }
    // Accepted effects on top, labelled.
    for s in p.sdes.iter().filter(|s| s.added) {
        let at = pr.px(&vec3(&s.point_m));
        sde_symbol(area, &s.kind, at, ADDED)?;
        if s.bodies.iter().any(Option::is_none) {
            ground(area, at, ADDED)?;
        }
        let name = sde_label(&s.name);
        label(area, &name, (at.0 - 9, at.1 - 14), 12, ADDED, HPos::Right)?;
    }
    // Measured points: the body centre and each measured DOF's direction.
    for (k, o) in p.outputs.iter().enumerate() {
        let Some(b) = p.bodies.get(o.body) else {
            continue;
        };
        let c = pr.at(&vec3(&b.centre_m));
        area.draw(&Circle::new(ipt(c), 4, MEASURED.filled()))?;
        let name = DOF_NAMES.get(usize::from(o.dof)).copied().unwrap_or("?");
        let d = pr.direction(&vec3(&o.direction));
        let inplane = (d.0 * d.0 + d.1 * d.1).sqrt();
        if o.dof < 3 && inplane > 0.15 {
            let tip = arrow(area, c, d, 30.0 * inplane, MEASURED.stroke_width(2))?;
            label(
                area,
                name,
                (tip.0.round() as i32 + 3, tip.1.round() as i32 + 7),
                11,
                MEASURED,
                HPos::Left,
            )?;
        } else {
            // Along the line of sight (or a rotation): a ring, named below-left.
            area.draw(&Circle::new(ipt(c), 8, MEASURED.stroke_width(1)))?;
            label(
                area,
                name,
                (
                    c.0.round() as i32 - 10,
                    c.1.round() as i32 + 12 + 10 * (k as i32 % 2),
                ),
                11,
                MEASURED,
                HPos::Right,
            )?;
        }
    }
    // Body callouts at the right of the region.
    let centres: Vec<(f64, f64)> = p.bodies.iter().map(|b| pr.at(&vec3(&b.centre_m))).collect();
    let ys = spread(
        &centres.iter().map(|c| c.1).collect::<Vec<_>>(),
        14.0,
        region.1 + 6.0,
        region.1 + region.3 - 6.0,
    );
    for ((b, c), y) in p.bodies.iter().zip(&centres).zip(ys) {
        let colour = if b.added { ADDED } else { BODY };
        let y = y.round() as i32;
        area.draw(&PathElement::new(
            vec![ipt(*c), (labels_x - 4, y)],
            colour.mix(0.45).stroke_width(1),
        ))?;
        area.draw(&Circle::new(ipt(*c), 2, colour.filled()))?;
        label(area, &short(&b.name), (labels_x, y), 12, colour, HPos::Left)?;
    }
    Ok(())
}

/// The legend: one row of items across the bottom at `y`.
fn legend(area: &Area<'_>, p: &ModelPicture, y: i32, width: i32) -> Result<(), DrawError> {
    let mut x = 12;
    let mut row = y;
    let advance = |x: &mut i32, row: &mut i32, text: &str| {
        let w = 24 + (6.4 * text.chars().count() as f64) as i32 + 16;
        if *x + w > width {
            *x = 12;
            *row += 18;
        }
        let at = (*x, *row);
        *x += w;
        at
    };
    let text = "body (uniform box of its mass and inertias)";
    let (lx, ly) = advance(&mut x, &mut row, text);
    area.draw(&Rectangle::new(
        [(lx, ly - 5), (lx + 16, ly + 5)],
        BODY.stroke_width(1),
    ))?;
    label(area, text, (lx + 22, ly), 11, BODY, HPos::Left)?;
    let mut kinds: Vec<&str> = p.sdes.iter().map(|s| s.kind.as_str()).collect();
    kinds.sort_unstable();
    kinds.dedup();
    for k in kinds {
        let text = format!("{k} SDE");
        let (lx, ly) = advance(&mut x, &mut row, &text);
        sde_symbol(area, k, (lx + 8, ly), SDE)?;
        label(area, &text, (lx + 22, ly), 11, BODY, HPos::Left)?;
    }
    if p.sdes.iter().any(|s| s.bodies.iter().any(Option::is_none)) {
        let text = "to ground";
        let (lx, ly) = advance(&mut x, &mut row, text);
        ground(area, (lx + 8, ly - 7), SDE)?;
        label(area, text, (lx + 22, ly), 11, BODY, HPos::Left)?;
    }
    if !p.exciters.is_empty() {
        let text = "exciter force";
        let (lx, ly) = advance(&mut x, &mut row, text);
        arrow(
            area,
            (f64::from(lx), f64::from(ly)),
            (1.0, 0.0),
            16.0,
            EXCITER.stroke_width(2),
        )?;
        label(area, text, (lx + 22, ly), 11, BODY, HPos::Left)?;
    }
    if !p.outputs.is_empty() {
        let text = "measured DOF (ring: along the line of sight or a rotation)";
        let (lx, ly) = advance(&mut x, &mut row, text);
        area.draw(&Circle::new((lx + 3, ly), 3, MEASURED.filled()))?;
        arrow(
            area,
            (f64::from(lx + 3), f64::from(ly)),
            (1.0, 0.0),
            14.0,
            MEASURED.stroke_width(2),
        )?;
        label(area, text, (lx + 22, ly), 11, BODY, HPos::Left)?;
    }
    if p.sdes.iter().any(|s| s.added) || p.bodies.iter().any(|b| b.added) {
        let text = "added by diagnosis (accepted effect)";
        let (lx, ly) = advance(&mut x, &mut row, text);
        area.draw(&PathElement::new(
            vec![(lx, ly), (lx + 16, ly)],
            ADDED.stroke_width(3),
        ))?;
        label(area, text, (lx + 22, ly), 11, ADDED, HPos::Left)?;
    }
    Ok(())
}

/// Width and height (px) of the model picture.
pub const PICTURE_SIZE: (u32, u32) = (960, 520);

/// Pixel rectangles `(x, y, width, height)` of the two views' drawing regions in the model
/// picture, and the x of each view's label column.
fn picture_regions() -> [((f64, f64, f64, f64), i32); 2] {
    let (w, h) = (f64::from(PICTURE_SIZE.0), f64::from(PICTURE_SIZE.1));
    let half = w / 2.0;
    let labels = 118.0;
    [0.0, half].map(|x0| {
        let region = (x0 + 12.0, 30.0, half - 24.0 - labels, h - 30.0 - 78.0);
        (region, (x0 + half - labels) as i32)
    })
}

/// The model in two projections (front x–z, side y–z) at one scale.
pub fn model_svg(p: &ModelPicture) -> Result<String, ReportError> {
    let ext = extent(p);
    let regions = picture_regions();
    let scale = fit_scale(&[FRONT, SIDE], &ext, regions[0].0 .2, regions[0].0 .3);
    svg("model picture", PICTURE_SIZE, |area| {
        for (view, (region, labels_x)) in [FRONT, SIDE].into_iter().zip(regions) {
            let pr = Projection::new(view, &ext, scale, region);
            label(area, view.name, (region.0 as i32, 14), 13, BODY, HPos::Left)?;
            draw_view(area, p, &pr, labels_x, region)?;
        }
        let bar_m = nice_length(0.2 * ext.size());
        let y = (regions[0].0 .1 + regions[0].0 .3 + 16.0) as i32;
        let x0 = regions[0].0 .0 as i32;
        let x1 = x0 + (bar_m * scale).round() as i32;
        area.draw(&PathElement::new(
            vec![(x0, y - 4), (x0, y), (x1, y), (x1, y - 4)],
            BODY.stroke_width(1),
        ))?;
        label(
            area,
            &format!("{} m", rfe::display::sig(bar_m, 2)),
            (x1 + 6, y - 2),
            11,
            BODY,
            HPos::Left,
        )?;
        legend(area, p, y + 22, PICTURE_SIZE.0 as i32 - 12)
    })
}

/// 1, 2 or 5 times a power of ten, at most `x` (for the scale bar).
fn nice_length(x: f64) -> f64 {
    if !(x > 0.0 && x.is_finite()) {
        return 1.0;
    }
    let d = 10f64.powf(x.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * d)
        .find(|v| *v <= x)
        .unwrap_or(d)
}

/// Width and height (px) of one mode figure.
pub const MODE_SIZE: (u32, u32) = (480, 290);

/// Mode `index` of the picture: the undeformed boxes in grey, the deformed ones in colour, in the
/// two views; titled with its frequency and loss factor and the body that moves most.
pub fn mode_svg(p: &ModelPicture, index: usize) -> Result<String, ReportError> {
    let Some(mode) = p.modes.get(index) else {
        return Err(ReportError::Plot {
            chart: format!("mode {}", index + 1),
            source: DrawingAreaErrorKind::LayoutError,
        });
    };
    let ext = extent(p);
    let (w, h) = (f64::from(MODE_SIZE.0), f64::from(MODE_SIZE.1));
    let half = w / 2.0;
    let regions = [0.0, half].map(|x0| (x0 + 10.0, 50.0, half - 20.0, h - 50.0 - 22.0));
    let scale = fit_scale(&[FRONT, SIDE], &ext, regions[0].2, regions[0].3);
    let (moved, _) = deformed_corners(p, mode);
    let most = p.bodies.iter().position(|b| b.name == mode.moves_most);
    svg(&format!("mode {}", index + 1), MODE_SIZE, |area| {
        label(
            area,
            &format!(
                "Mode {}: {} Hz, loss factor η {}",
                index + 1,
                rfe::display::sig(mode.freq_hz, 4),
                rfe::display::sig(mode.loss_factor, 2)
            ),
            (10, 13),
            13,
            RGBColor(20, 20, 20),
            HPos::Left,
        )?;
        let share = most
            .and_then(|i| mode.energy.get(i))
            .map(|e| format!(" ({:.0} % of the kinetic energy)", 100.0 * e))
            .unwrap_or_default();
        label(
            area,
            &format!("moves most: {}{share}", mode.moves_most),
            (10, 31),
            11,
            BODY,
            HPos::Left,
        )?;
        for (view, region) in [FRONT, SIDE].into_iter().zip(regions) {
            let pr = Projection::new(view, &ext, scale, region);
            for b in &p.bodies {
                let o = outline(&pr, &b.corners());
                area.draw(&PathElement::new(closed(o), UNDEFORMED.stroke_width(1)))?;
            }
            for (i, c) in moved.iter().enumerate() {
                let colour = if Some(i) == most { DEFORMED } else { MEASURED };
                let o = outline(&pr, c);
                area.draw(&Polygon::new(o.clone(), colour.mix(0.18).filled()))?;
                area.draw(&PathElement::new(closed(o), colour.stroke_width(1)))?;
            }
            if let Some(i) = most {
                let c = moved[i].iter().fold(Vector3::zeros(), |s, v| s + v) / 8.0;
                let at = pr.px(&c);
                label(
                    area,
                    &mode.moves_most,
                    (at.0, at.1),
                    10,
                    RGBColor(150, 70, 0),
                    HPos::Center,
                )?;
            }
            label(
                area,
                view.name,
                ((region.0 + region.2 / 2.0) as i32, (h - 10.0) as i32),
                11,
                BODY,
                HPos::Center,
            )?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(name: &str, mass: f64, sides: [f64; 3], at: [f64; 3]) -> Body {
        let [a, b, c] = sides;
        Body {
            name: name.into(),
            mass,
            inertia: [
                mass * (b * b + c * c) / 12.0,
                mass * (c * c + a * a) / 12.0,
                mass * (a * a + b * b) / 12.0,
            ],
            position: vec3(&at),
            rotation: Matrix3::identity(),
        }
    }

    #[test]
    fn equivalent_box_of_a_box_inertia_is_that_box() {
        let (sides, clamped) = equivalent_box(&body("b", 300.0, [1.25, 0.32, 0.12], [0.0; 3]));
        for (s, t) in sides.iter().zip([1.25, 0.32, 0.12]) {
            assert!((s - t).abs() < 1e-12, "{sides:?}");
        }
        assert!(!clamped);
    }

    #[test]
    fn impossible_and_flat_sides_are_clamped_visible() {
        // J1 > J2 + J3: no uniform box has it; the square for a is negative.
        let mut b = body("b", 10.0, [1.0, 1.0, 1.0], [0.0; 3]);
        b.inertia = [5.0, 1.0, 1.0];
        let (sides, clamped) = equivalent_box(&b);
        assert!(clamped);
        let longest = sides.iter().copied().fold(0.0, f64::max);
        assert!(
            (sides[0] - MIN_SIDE_FRACTION * longest).abs() < 1e-12,
            "{sides:?}"
        );
        // A flat plate (c = 0) keeps its two sides and gets a visible thickness.
        let (plate, clamped) = equivalent_box(&body("p", 10.0, [2.0, 1.0, 0.0], [0.0; 3]));
        assert!(clamped);
        assert!((plate[0] - 2.0).abs() < 1e-12 && (plate[1] - 1.0).abs() < 1e-12);
        assert!((plate[2] - 0.1).abs() < 1e-12, "{plate:?}");
    }

    #[test]
    fn projection_maps_points_to_their_pixels() {
        let ext = Extent {
            lo: [-1.0, 0.0, 0.0],
            hi: [1.0, 2.0, 4.0],
        };
        // 100 px/m in a 400 × 400 region at (10, 20): the x–z view is 200 × 400 px, centred
        // horizontally, so the extent's left edge is at 10 + 100 and its top at 20.
        let pr = Projection::new(FRONT, &ext, 100.0, (10.0, 20.0, 400.0, 400.0));
        assert_eq!(pr.px(&Vector3::new(-1.0, 5.0, 4.0)), (110, 20));
        assert_eq!(pr.px(&Vector3::new(0.5, -3.0, 1.0)), (260, 320));
        let side = Projection::new(SIDE, &ext, 100.0, (10.0, 20.0, 400.0, 400.0));
        assert_eq!(side.px(&Vector3::new(9.0, 2.0, 0.0)), (310, 420));
        // z up on the page is y down in SVG.
        assert_eq!(pr.direction(&Vector3::new(0.0, 0.0, 1.0)), (0.0, -1.0));
        assert_eq!(fit_scale(&[FRONT, SIDE], &ext, 400.0, 400.0), 100.0);
    }

    #[test]
    fn hull_of_a_projected_box_is_its_outline() {
        let b = BodyBox {
            name: "b".into(),
            mass_kg: 1.0,
            centre_m: [0.0, 0.0, 1.0],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            half_sizes_m: [0.5, 0.25, 0.1],
            clamped: false,
            added: false,
        };
        let ext = Extent {
            lo: [-1.0, -1.0, 0.0],
            hi: [1.0, 1.0, 2.0],
        };
        let pr = Projection::new(FRONT, &ext, 100.0, (0.0, 0.0, 200.0, 200.0));
        let mut o = outline(&pr, &b.corners());
        o.sort_unstable();
        assert_eq!(o, vec![(50, 90), (50, 110), (150, 90), (150, 110)]);
    }

    fn two_bodies() -> ModelPicture {
        let mk = |name: &str, z: f64| BodyBox {
            name: name.into(),
            mass_kg: 100.0,
            centre_m: [0.0, 0.0, z],
            axes: [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]],
            half_sizes_m: [0.2, 0.3, 0.4],
            clamped: false,
            added: false,
        };
        ModelPicture {
            model: "two".into(),
            bodies: vec![mk("lower", 0.0), mk("upper", 1.0)],
            sdes: Vec::new(),
            exciters: Vec::new(),
            outputs: Vec::new(),
            band_hz: [1.0, 100.0],
            modes: Vec::new(),
            modes_omitted: 0,
        }
    }

    #[test]
    fn a_pure_translation_moves_only_that_body_by_the_scaled_amount() {
        let p = two_bodies();
        // u2 of the upper body: its axis 2 is global z.
        let mode = ModeShape {
            freq_hz: 10.0,
            loss_factor: 0.01,
            moves_most: "upper".into(),
            energy: vec![0.0, 1.0],
            shape: vec![[0.0; 6], [0.0, 1e-3, 0.0, 0.0, 0.0, 0.0]],
        };
        let (moved, scale) = deformed_corners(&p, &mode);
        let amount = MODE_AMPLITUDE * extent(&p).size();
        assert!((scale * 1e-3 - amount).abs() < 1e-12, "{scale}");
        for (k, c) in p.bodies[0].corners().iter().enumerate() {
            assert!((moved[0][k] - c).norm() < 1e-15, "the lower body stays");
        }
        for (k, c) in p.bodies[1].corners().iter().enumerate() {
            let d = moved[1][k] - c;
            assert!((d - Vector3::new(0.0, 0.0, amount)).norm() < 1e-12, "{d:?}");
        }
    }

    #[test]
    fn a_rotation_moves_corners_by_theta_cross_r() {
        let p = two_bodies();
        // r3 of the lower body: about its axis 3 = global x; a corner at +y moves along +z.
        let q = [0.0, 0.0, 0.0, 0.0, 0.0, 0.01];
        let d = p.bodies[0].motion_at(&q, &Vector3::new(0.0, 0.5, 0.0));
        assert!((d - Vector3::new(0.0, 0.0, 0.005)).norm() < 1e-15, "{d:?}");
    }

    #[test]
    fn spread_labels_keep_order_and_distance_inside_the_column() {
        let y = spread(&[50.0, 52.0, 10.0, 98.0], 14.0, 20.0, 100.0);
        assert_eq!(y[2], 20.0);
        assert!(
            y[0] >= 34.0 && y[1] >= y[0] + 14.0 && y[3] >= y[1] + 14.0,
            "{y:?}"
        );
        assert!(y.iter().all(|v| (20.0..=100.0).contains(v)), "{y:?}");
    }
}
