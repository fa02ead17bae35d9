//! The structural changes a model can lack ("effects"), generated from the model's own geometry,
//! each nested: its parameters at their nested values give back the current model exactly.
//!
//! | effect | parameters (SI) | nested at |
//! |---|---|---|
//! | spring-damper between two bodies or a body and the ground, at a point along a direction | k (N/m), ψ | k = 0 |
//! | point mass on a body (accelerometer, fixture, workpiece) | m (kg) | m = 0 |
//! | local resonator (mass on an isotropic spring) at a point | m (kg), f (Hz) | m = 0 |
//! | a body that is not rigid: three RFEs along a principal axis joined by two SDEs | compliance c (m/N) | c = 0 |
//! | a sensor gain error of one characteristic | g (-) | g = 0 |
//! | a separate ψ for one joint of a ψ group | ψ of that joint | the group's ψ |
//! | a direction an SDE's law leaves out (an isolator's rotations, a screw's lateral directions, a general element's zero) given a stiffness | k (N/m or N·m/rad) | k = 0 |
//! | a direction a general element holds stiff (a "rigid" restraint) made compliant | c (m/N or rad/(N·m)) in series | c = 0 |
//! | a body's mass off, its inertias scaled with it | m (kg) | the model's mass |
//!
//! Each effect gives its first-order action on `A(ω) = K + jD − ω²M` as rows and coefficients
//! ([`Effect::rows`], [`Effect::coefficient`]), so that its score needs no new solve; the
//! flexible body, whose DOFs differ, is the exception (one extra solve, see `score`).

use nalgebra::{Matrix3, Vector3};

use identify::variables::{Target, Variables};
use rfe::model::{Body, Model, Param, ParamName, ParamRef, Sde, SdeKind, SdeLaw};
use rfe::modelfile::frame_from_axis;

/// Two-sided 95 % normal quantile: a confidence interval is `estimate ± Z95 σ`.
pub(crate) const Z95: f64 = 1.96;
use rfe::system::generalized_force;
use rfe::C64;

const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

/// A point mass is realized as a small body on a stiff mount whose own resonance sits this many
/// times above the highest measured frequency, so that in the band it acts as a rigid mass.
const MOUNT_ABOVE_BAND: f64 = 30.0;
/// Radius of gyration (m) of an added point mass or resonator body (its rotary inertia is
/// negligible but must be positive).
const POINT_RADIUS: f64 = 0.01;
/// Loss ψ of the stiff mounts and of a flexible body's internal joints (structural steel/cast
/// iron, loss factor ≈ 1 %).
const STRUCTURAL_PSI: f64 = 0.06;
/// Name stem of the bodies of added point masses.
const ADDED_MASS: &str = "diagnosed mass";
/// Name stem of the bodies of added resonators.
const ADDED_RESONATOR: &str = "diagnosed resonator";

/// Why an effect cannot be applied to a model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// The effect names a body the model does not have.
    #[error("no body \"{0}\"")]
    NoBody(String),
    /// The effect names an SDE the model does not have.
    #[error("no SDE \"{0}\"")]
    NoSde(String),
    /// The effect names a characteristic (output) the data does not have.
    #[error("no characteristic number {0}")]
    NoCharacteristic(usize),
    /// The effect names an identification variable that does not exist.
    #[error("no variable number {0}")]
    NoVariable(usize),
    /// Splitting the joints off would leave their ψ group variable with nothing to set.
    #[error("the split would leave the group variable without parameters")]
    EmptyGroup,
    /// A resonator's tuning frequency is not positive.
    #[error("resonator frequency {0} Hz is not > 0")]
    BadFrequency(f64),
    /// A body's principal inertias give it no extent along the axis to split.
    #[error("{body}: its inertias give no length along axis {axis}")]
    NoLength {
        /// The body.
        body: String,
        /// The principal axis, 1-based.
        axis: usize,
    },
    /// The body was split along this axis already.
    #[error("{body} is already split along axis {axis}")]
    AlreadySplit {
        /// The body.
        body: String,
        /// The principal axis, 1-based.
        axis: usize,
    },
}

/// A candidate that cannot be applied at a point of a refit makes that point unevaluable.
impl From<EffectError> for identify::EvalError {
    fn from(e: EffectError) -> Self {
        identify::EvalError::Changed(Box::new(e))
    }
}

/// One candidate effect.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// A spring-damper (axial law) between `bodies` (None = ground) at `point` along `direction`.
    Spring {
        /// Body names `[p, r]`.
        bodies: [Option<String>; 2],
        /// Global point (m).
        point: Vector3<f64>,
        /// Unit direction (global).
        direction: Vector3<f64>,
        /// ψ used for the score (the refit frees it).
        psi: f64,
    },
    /// A spring like [`Effect::Spring`] whose line of action is fitted too: offsets `s1`, `s2`
    /// from `point` across `direction` (along it the place is unobservable). The refinement of an
    /// accepted spring when the true contact lies between the candidate points.
    PlacedSpring {
        /// Body names `[p, r]`.
        bodies: [Option<String>; 2],
        /// Starting point (global, m): the accepted candidate's.
        point: Vector3<f64>,
        /// Unit direction (global).
        direction: Vector3<f64>,
        /// The offsets are bounded to ±`reach` (m).
        reach: f64,
    },
    /// A point mass at `point` on `body`.
    Mass {
        /// Host body.
        body: String,
        /// Global point (m).
        point: Vector3<f64>,
        /// Typical size of the effect (kg), the parameter's scale.
        scale: f64,
    },
    /// A point mass on `body` near `point` whose position is fitted too: the refinement of an
    /// accepted [`Effect::Mass`] when the true place lies between the candidate points.
    PlacedMass {
        /// Host body.
        body: String,
        /// Starting point (global, m): the accepted candidate's.
        point: Vector3<f64>,
        /// Typical size of the mass (kg).
        scale: f64,
        /// The offset from `point` is bounded to ±`reach` (m) along each global axis.
        reach: f64,
    },
    /// A mass on an isotropic spring with natural frequency `freq_hz` at `point` on `body`.
    Resonator {
        /// Host body.
        body: String,
        /// Global point (m).
        point: Vector3<f64>,
        /// Natural frequency of the mass on its spring (Hz), the start of the refit.
        freq_hz: f64,
        /// The tuning frequencies (Hz) this candidate stands for: its score is the best over
        /// them, and `freq_hz` is set there (a resonator is sharply tuned, a fixed grid of
        /// frequencies misses it).
        tuning: [f64; 2],
        /// Typical size of the mass (kg).
        scale: f64,
    },
    /// `body` is three RFEs along its principal axis `axis` (0-2), joined by two SDEs of compliance c.
    Flexible {
        /// The body.
        body: String,
        /// Principal axis index.
        axis: usize,
        /// Typical compliance (m/N): the model's softest SDE's.
        scale: f64,
    },
    /// The amplitude of characteristic `output` is off by a factor `1 + g`.
    Gain {
        /// Characteristic index (data order).
        output: usize,
        /// Its label.
        label: String,
    },
    /// Direction `axis` (0-2 along, 3-5 about the SDE's axes 1-3) of SDE `sde` freed: a
    /// direction its law leaves out (`held` = 0) gets a stiffness k ≥ 0; one a general element
    /// holds at a fixed stiffness `held` > 0 (a "rigid" restraint, no variable sets it) gets a
    /// compliance c ≥ 0 in series, `k = 1/(1/held + c)`.
    Direction {
        /// The SDE's name.
        sde: String,
        /// The direction, 0-5.
        axis: usize,
        /// Its stiffness in the model (N/m or N·m/rad): 0 when the law leaves it out.
        held: f64,
        /// ψ of the freed stiffness (the SDE's own for that direction, or its largest).
        psi: f64,
        /// Typical stiffness of that kind of direction in the model (the parameter's scale when
        /// `held` = 0).
        scale: f64,
    },
    /// Body `body`'s mass is `m` instead of `mass`, its principal inertias scaled by `m/mass`
    /// (the same body, heavier or lighter: a fixture, oil, a casting off its drawing).
    BodyMass {
        /// The body.
        body: String,
        /// Its mass in the model (kg).
        mass: f64,
    },
    /// The SDEs `sdes` (one joint) get their own `parameter` instead of variable `variable`'s.
    Damping {
        /// Index of the group variable.
        variable: usize,
        /// Its name.
        variable_name: String,
        /// The split-off SDE names.
        sdes: Vec<String>,
        /// The ψ parameter.
        parameter: ParamName,
        /// The group's current value (the nested value).
        value: f64,
    },
}

/// One parameter of an effect.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectParam {
    /// Name for reports (`k`, `psi`, `m`, `f`, `c`, `g`).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// The nested value (the current model).
    pub nested: f64,
    /// Start of the refit (replaced by the score step where that is better).
    pub initial: f64,
    /// Bounds.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Scale for the optimizer.
    pub scale: f64,
}

/// The result of applying effects: the model, the variables (a split ψ group loses members) and
/// the sensor gains (per characteristic, 0 = none).
#[derive(Debug, Clone)]
pub struct Realized {
    /// The model with the effects.
    pub model: Model,
    /// The variables of the model.
    pub vars: Variables,
    /// `1 + g` per characteristic.
    pub gains: Vec<f64>,
}

impl Effect {
    /// Short kind name: spring, mass, resonator, flexible body, sensor gain, joint damping.
    pub fn kind(&self) -> &'static str {
        match self {
            Effect::Spring { .. } | Effect::PlacedSpring { .. } => "spring",
            Effect::Mass { .. } | Effect::PlacedMass { .. } => "mass",
            Effect::Resonator { .. } => "resonator",
            Effect::Flexible { .. } => "flexible body",
            Effect::Gain { .. } => "sensor gain",
            Effect::Damping { .. } => "joint damping",
            Effect::Direction { .. } => "SDE direction",
            Effect::BodyMass { .. } => "body mass",
        }
    }

    /// Where the effect acts, without its point: the bodies a spring joins (sorted; ground is
    /// `None`), the body of a mass, resonator, flexibility or body mass, the SDE of a direction,
    /// the SDEs of a damping split, the characteristic of a gain. Two effects of one kind and
    /// site differ only in their point or direction.
    pub fn site(&self) -> Vec<Option<&str>> {
        match self {
            Effect::Spring { bodies, .. } | Effect::PlacedSpring { bodies, .. } => {
                let mut v: Vec<Option<&str>> = bodies.iter().map(|b| b.as_deref()).collect();
                v.sort();
                v
            }
            Effect::Mass { body, .. }
            | Effect::PlacedMass { body, .. }
            | Effect::Resonator { body, .. }
            | Effect::Flexible { body, .. }
            | Effect::BodyMass { body, .. } => vec![Some(body)],
            Effect::Direction { sde, .. } => vec![Some(sde)],
            Effect::Damping { sdes, .. } => sdes.iter().map(|s| Some(s.as_str())).collect(),
            Effect::Gain { label, .. } => vec![Some(label)],
        }
    }

    /// Whether the effect acts on a body the diagnosis added (a point mass's or resonator's).
    pub fn on_added_body(&self) -> bool {
        let added = |b: &str| b.starts_with(ADDED_MASS) || b.starts_with(ADDED_RESONATOR);
        match self {
            Effect::Spring { bodies, .. } | Effect::PlacedSpring { bodies, .. } => {
                bodies.iter().flatten().any(|b| added(b))
            }
            Effect::Mass { body, .. }
            | Effect::PlacedMass { body, .. }
            | Effect::Resonator { body, .. }
            | Effect::Flexible { body, .. }
            | Effect::BodyMass { body, .. } => added(body),
            Effect::Direction { sde, .. } => {
                sde.starts_with(ADDED_MASS) || sde.starts_with(ADDED_RESONATOR)
            }
            Effect::Gain { .. } | Effect::Damping { .. } => false,
        }
    }

    /// Whether the element the effect changes is one of `base`'s (the structure's own): a freed
    /// direction of an SDE, a body's mass. The SDEs and bodies the diagnosis added (springs,
    /// mounts, a split body's thirds and joints) are not candidates themselves.
    pub fn on_structure(&self, base: &Model) -> bool {
        match self {
            Effect::Direction { sde, .. } => base.sde_index(sde).is_some(),
            Effect::BodyMass { body, .. } => base.body_index(body).is_some(),
            _ => !self.on_added_body(),
        }
    }

    /// Where a placed effect was fitted, with its 95 % confidence region, from its parameter
    /// `values` and their standard `errors` (SI): a point mass's point ± per global axis, a
    /// spring's line of action ± across it along the two directions the offsets move it. `None`
    /// for effects whose place is not a parameter.
    pub fn fitted_place(&self, values: &[f64], errors: &[f64]) -> Option<String> {
        let mm =
            |v: &Vector3<f64>| format!("({:.0}, {:.0}, {:.0}) mm", 1e3 * v.x, 1e3 * v.y, 1e3 * v.z);
        let half = |i: usize| 1e3 * Z95 * errors.get(i).copied().unwrap_or(f64::NAN);
        match self {
            Effect::PlacedMass { point, .. } if values.len() >= 4 => {
                let at = point + Vector3::new(values[1], values[2], values[3]);
                Some(format!(
                    "fitted at {}, 95 % region ±({:.0}, {:.0}, {:.0}) mm",
                    mm(&at),
                    half(1),
                    half(2),
                    half(3)
                ))
            }
            Effect::PlacedSpring {
                point, direction, ..
            } if values.len() >= 4 => {
                let frame = frame_from_axis(direction);
                let (e1, e2) = (frame.column(1).into_owned(), frame.column(2).into_owned());
                let at = point + e1 * values[2] + e2 * values[3];
                Some(format!(
                    "line of action fitted through {}, 95 % region ±{:.0} mm along {} and ±{:.0} mm along {}",
                    mm(&at),
                    half(2),
                    unit_vector(&e1),
                    half(3),
                    unit_vector(&e2)
                ))
            }
            _ => None,
        }
    }

    /// What and where, for reports (mm at the edge).
    pub fn describe(&self) -> String {
        let mm =
            |p: &Vector3<f64>| format!("({:.0}, {:.0}, {:.0}) mm", 1e3 * p.x, 1e3 * p.y, 1e3 * p.z);
        let name = |b: &Option<String>| b.clone().unwrap_or_else(|| "ground".into());
        let spring = |bodies: &[Option<String>; 2],
                      at: &str,
                      point: &Vector3<f64>,
                      d: &Vector3<f64>,
                      tail: &str| {
            format!(
                "spring {}–{} {at} {} along {}{tail}",
                name(&bodies[0]),
                name(&bodies[1]),
                mm(point),
                unit_vector(d)
            )
        };
        match self {
            Effect::Spring {
                bodies,
                point,
                direction,
                ..
            } => spring(bodies, "at", point, direction, ""),
            Effect::PlacedSpring {
                bodies,
                point,
                direction,
                ..
            } => spring(
                bodies,
                "near",
                point,
                direction,
                " (line of action fitted: s1, s2 across it)",
            ),
            Effect::Mass { body, point, .. } => format!("point mass on {body} at {}", mm(point)),
            Effect::PlacedMass { body, point, .. } => format!(
                "point mass on {body} near {} (position fitted: dx, dy, dz)",
                mm(point)
            ),
            Effect::Resonator {
                body,
                point,
                freq_hz,
                ..
            } => {
                format!("resonator (≈{freq_hz:.0} Hz) on {body} at {}", mm(point))
            }
            Effect::Flexible { body, axis, .. } => {
                format!(
                    "{body} not rigid: three RFEs along its principal axis {}",
                    axis + 1
                )
            }
            Effect::Gain { label, .. } => format!("gain error of {label}"),
            Effect::Direction {
                sde, axis, held, ..
            } => {
                let (what, unit, f) = direction_units(*axis);
                if *held > 0.0 {
                    format!(
                        "SDE {sde}: {what} axis {} held at {} {unit}, made compliant",
                        axis % 3 + 1,
                        rfe::display::sig(held * f, 3)
                    )
                } else {
                    format!(
                        "SDE {sde}: a stiffness {what} axis {} (its law leaves it out)",
                        axis % 3 + 1
                    )
                }
            }
            Effect::BodyMass { body, mass } => format!(
                "{body}'s mass off (model {} kg; inertias scaled with it)",
                rfe::display::sig(*mass, 4)
            ),
            Effect::Damping {
                variable_name,
                sdes,
                parameter,
                ..
            } => format!(
                "own {} for SDE {} (split from \"{variable_name}\")",
                parameter.as_str(),
                sdes.join(", ")
            ),
        }
    }

    /// How many tuning frequencies the data tell apart where this effect's fit may place it:
    /// for a resonator, one per measured line within its frequency's bounds and one between
    /// (a sharp resonance acts where a line sits); 1 for every other effect. A likelihood ratio
    /// maximised over a tuning frequency does not follow the χ² law of a fixed one (the
    /// nuisance frequency is undefined under the nested model); its p-value times this count
    /// (Bonferroni) bounds the chance of a false add, as the score's does.
    pub fn tunings_searched(&self, lines: &[f64], f_max: f64) -> usize {
        let Effect::Resonator { .. } = self else {
            return 1;
        };
        let params = self.params(f_max);
        let Some(f) = params.iter().find(|p| p.unit == "Hz") else {
            return 1;
        };
        1 + lines
            .iter()
            .filter(|l| (f.lower..=f.upper).contains(*l))
            .count()
    }

    /// The effect's parameters.
    pub fn params(&self, f_max: f64) -> Vec<EffectParam> {
        let p = |name, unit, nested, initial, lower, upper, scale| EffectParam {
            name,
            unit,
            nested,
            initial,
            lower,
            upper,
            scale,
        };
        match self {
            Effect::Spring { psi, .. } => vec![
                p("k", "N/m", 0.0, 0.0, 0.0, f64::INFINITY, 1e6),
                p("psi", "-", *psi, *psi, 0.0, 2.0 * TWO_PI, 0.5),
            ],
            Effect::PlacedSpring { reach, .. } => vec![
                p("k", "N/m", 0.0, 0.0, 0.0, f64::INFINITY, 1e6),
                p("psi", "-", 0.0, 0.0, 0.0, 2.0 * TWO_PI, 0.5),
                p("s1", "m", 0.0, 0.0, -reach, *reach, 0.05),
                p("s2", "m", 0.0, 0.0, -reach, *reach, 0.05),
            ],
            Effect::Mass { scale, .. } => vec![p("m", "kg", 0.0, 0.0, 0.0, f64::INFINITY, *scale)],
            Effect::PlacedMass { scale, reach, .. } => {
                let mut v = vec![p("m", "kg", 0.0, 0.0, 0.0, f64::INFINITY, *scale)];
                for name in ["dx", "dy", "dz"] {
                    v.push(p(name, "m", 0.0, 0.0, -reach, *reach, 0.05));
                }
                v
            }
            Effect::Resonator { freq_hz, scale, .. } => vec![
                p("m", "kg", 0.0, 0.0, 0.0, f64::INFINITY, *scale),
                p(
                    "f",
                    "Hz",
                    *freq_hz,
                    *freq_hz,
                    0.2 * freq_hz,
                    (5.0 * freq_hz).min(MOUNT_ABOVE_BAND * f_max / 3.0),
                    *freq_hz,
                ),
            ],
            Effect::Flexible { scale, .. } => {
                vec![p("c", "m/N", 0.0, 0.0, 0.0, f64::INFINITY, *scale)]
            }
            Effect::Gain { .. } => vec![p("g", "-", 0.0, 0.0, -0.5, 0.5, 0.01)],
            Effect::Direction {
                axis, held, scale, ..
            } => {
                let rot = *axis >= 3;
                if *held > 0.0 {
                    let unit = if rot { "rad/(N·m)" } else { "m/N" };
                    vec![p("c", unit, 0.0, 0.0, 0.0, f64::INFINITY, 1.0 / held)]
                } else {
                    let unit = if rot { "N·m/rad" } else { "N/m" };
                    vec![p("k", unit, 0.0, 0.0, 0.0, f64::INFINITY, *scale)]
                }
            }
            Effect::BodyMass { mass, .. } => vec![p(
                "m",
                "kg",
                *mass,
                *mass,
                BODY_MASS_RANGE.0 * mass,
                BODY_MASS_RANGE.1 * mass,
                0.01 * mass,
            )],
            Effect::Damping { value, .. } => {
                vec![p(
                    "psi",
                    "-",
                    *value,
                    *value,
                    0.0,
                    2.0 * TWO_PI,
                    value.abs().max(0.05),
                )]
            }
        }
    }

    /// The first-order action of the effect's first parameter on `A(ω)`: `∂A/∂γ = c(ω) Σ tᵀt`
    /// over the rows `t` returned here (each over the model's DOFs), with `c` from
    /// [`Effect::coefficient`]. `None` for effects that do not act through `A` (gain, damping:
    /// their scores come from the outputs and the existing Jacobian) or that change the DOFs
    /// (flexible body).
    pub fn rows(&self, model: &Model) -> Option<Vec<Vec<(usize, f64)>>> {
        match self {
            Effect::Spring {
                bodies,
                point,
                direction,
                ..
            } => {
                let mut row = Vec::with_capacity(12);
                for (side, sign) in [(0usize, -1.0), (1, 1.0)] {
                    if let Some(name) = &bodies[side] {
                        let b = model.body_index(name)?;
                        row.extend(
                            point_row(model, b, point, direction).map(|(i, v)| (i, sign * v)),
                        );
                    }
                }
                Some(vec![row])
            }
            Effect::Mass { body, point, .. } | Effect::Resonator { body, point, .. } => {
                // The added body's translation at the point, and its small rotary inertia
                // (m·r², r = POINT_RADIUS) on the host's rotation.
                let b = model.body_index(body)?;
                let rot = model.bodies[b].rotation.transpose();
                let mut rows: Vec<Vec<(usize, f64)>> = axes()
                    .iter()
                    .map(|u| point_row(model, b, point, u).to_vec())
                    .collect();
                for u in axes() {
                    let r = rot * u * POINT_RADIUS;
                    rows.push((0..3).map(|i| (6 * b + 3 + i, r[i])).collect());
                }
                Some(rows)
            }
            Effect::Direction { sde, axis, .. } => {
                let s = model.sde_index(sde)?;
                Some(vec![direction_row(model, &model.sdes[s], *axis)])
            }
            Effect::BodyMass { body, mass } => {
                // ∂M/∂m: the body's diagonal block divided by its mass.
                let b = model.body_index(body)?;
                let j = model.bodies[b].inertia;
                let d = [1.0, 1.0, 1.0, j[0] / mass, j[1] / mass, j[2] / mass];
                Some(
                    (0..6)
                        .map(|i| vec![(6 * b + i, d[i].max(0.0).sqrt())])
                        .collect(),
                )
            }
            _ => None,
        }
    }

    /// The coefficient `c(ω)` of [`Effect::rows`] at `omega` (rad/s).
    pub fn coefficient(&self, omega: f64) -> C64 {
        match self {
            Effect::Spring { psi, .. } => C64::new(1.0, psi / TWO_PI),
            Effect::Mass { .. } => C64::new(-omega * omega, 0.0),
            Effect::Resonator { freq_hz, .. } => resonator_coefficient(omega, *freq_hz),
            // A stiffness k added: ∂A/∂k = (1 + jψ/2π) t tᵀ; a compliance c in series with
            // `held`: ∂k/∂c = −held² at c = 0.
            Effect::Direction { held, psi, .. } => {
                let d = C64::new(1.0, psi / TWO_PI);
                if *held > 0.0 {
                    -d * held * held
                } else {
                    d
                }
            }
            Effect::BodyMass { .. } => C64::new(-omega * omega, 0.0),
            _ => C64::new(0.0, 0.0),
        }
    }

    /// Applies the effect with parameters `gamma` to `r`. At the nested values the model is
    /// unchanged (for the mass-like effects and the flexible body, nothing is added at all).
    pub fn apply(&self, r: &mut Realized, gamma: &[f64], f_max: f64) -> Result<(), EffectError> {
        let model = &mut r.model;
        match self {
            Effect::Spring {
                bodies,
                point,
                direction,
                ..
            } => add_spring(model, bodies, point, direction, gamma[0], gamma[1])?,
            Effect::PlacedSpring {
                bodies,
                point,
                direction,
                ..
            } => {
                let frame = frame_from_axis(direction);
                let at = point + frame.column(1) * gamma[2] + frame.column(2) * gamma[3];
                add_spring(model, bodies, &at, direction, gamma[0], gamma[1])?;
            }
            Effect::Mass { body, point, .. } | Effect::PlacedMass { body, point, .. } => {
                if gamma[0] > 0.0 {
                    // A placed mass's offset from its candidate point is parameters 1-3.
                    let at = match self {
                        Effect::PlacedMass { .. } => {
                            point + Vector3::new(gamma[1], gamma[2], gamma[3])
                        }
                        _ => *point,
                    };
                    attach_mass(
                        model,
                        body,
                        &at,
                        gamma[0],
                        MOUNT_ABOVE_BAND * f_max,
                        STRUCTURAL_PSI,
                        ADDED_MASS,
                    )?;
                }
            }
            Effect::Resonator { body, point, .. } => {
                if gamma[0] > 0.0 {
                    attach_mass(
                        model,
                        body,
                        point,
                        gamma[0],
                        gamma[1],
                        STRUCTURAL_PSI,
                        ADDED_RESONATOR,
                    )?;
                }
            }
            Effect::Flexible { body, axis, .. } => {
                if gamma[0] > 0.0 {
                    split_body(model, body, *axis, gamma[0])?;
                }
            }
            Effect::Direction {
                sde,
                axis,
                held,
                psi,
                ..
            } => free_direction(r, sde, *axis, (*held, *psi), gamma[0])?,
            Effect::BodyMass { body, mass } => {
                let b = body_index(model, body)?;
                let ratio = gamma[0] / mass;
                let body = &mut model.bodies[b];
                body.mass *= ratio;
                body.inertia = body.inertia.map(|j| j * ratio);
            }
            Effect::Gain { output, .. } => {
                let g = r
                    .gains
                    .get_mut(*output)
                    .ok_or(EffectError::NoCharacteristic(*output))?;
                *g *= 1.0 + gamma[0];
            }
            Effect::Damping {
                variable,
                sdes,
                parameter,
                ..
            } => split_damping(r, *variable, sdes, *parameter, gamma[0])?,
        }
        Ok(())
    }
}

/// A body's mass may be fitted within these multiples of its modelled mass.
pub const BODY_MASS_RANGE: (f64, f64) = (0.1, 10.0);

/// Name stem of the SDEs that carry a freed direction of an SDE whose law leaves it out.
pub const FREED_DIRECTION: &str = "freed";

/// "along"/"about", the stiffness unit and its report factor of direction `axis` (0-5).
fn direction_units(axis: usize) -> (&'static str, &'static str, f64) {
    if axis < 3 {
        ("along", "N/µm", 1e-6)
    } else {
        ("about", "N·m/rad", 1.0)
    }
}

/// The relative motion of SDE `sde`'s two ends along (0-2) or about (3-5) its axis as a row over
/// the model's DOFs: row `axis` of its deformation map, `G_r − G_p` (a grounded end contributes
/// nothing).
pub fn direction_row(model: &Model, sde: &Sde, axis: usize) -> Vec<(usize, f64)> {
    let mut row = Vec::with_capacity(12);
    for (side, sign) in [(0usize, -1.0), (1, 1.0)] {
        if let Some(b) = sde.bodies[side] {
            let body = &model.bodies[b];
            let g = rfe::system::sde_from_body(
                &body.position,
                &body.rotation,
                &sde.point,
                &sde.rotation,
            );
            row.extend((0..6).map(|j| (6 * b + j, sign * g[(axis, j)])));
        }
    }
    row
}

/// Frees direction `axis` of SDE `name` with parameter `value`: a general element's own stiffness
/// there is set (`held` = 0: to `value`; `held` > 0: to `1/(1/held + value)`, a compliance in
/// series); any other law, which cannot hold a stiffness in a direction it leaves out, gets a
/// parallel general element with that one stiffness (nothing when `value` is 0). A stiffness the
/// law left out takes the SDE's ψ `psi`; where a variable sets that ψ of the SDE, the freed
/// direction joins its targets, so that its ψ follows the fit rather than staying at the value
/// the candidate was drawn with.
fn free_direction(
    r: &mut Realized,
    name: &str,
    axis: usize,
    (held, psi): (f64, f64),
    value: f64,
) -> Result<(), EffectError> {
    let model = &mut r.model;
    let s = model
        .sde_index(name)
        .ok_or_else(|| EffectError::NoSde(name.into()))?;
    let k = if held > 0.0 {
        1.0 / (1.0 / held + value.max(0.0))
    } else {
        value.max(0.0)
    };
    let source = psi_source(&model.sdes[s].law, axis);
    let freed = if let SdeLaw::General { k: ks, psi: ps } = &mut model.sdes[s].law {
        ks[axis] = k;
        if held > 0.0 {
            return Ok(());
        }
        ps[axis] = psi;
        ParamRef {
            sde: s,
            name: ParamName::PsiI(axis as u8),
        }
    } else {
        if k == 0.0 {
            return Ok(());
        }
        let mut ks = [0.0; 6];
        ks[axis] = k;
        let sde = &model.sdes[s];
        let added = Sde {
            name: fresh_name(model, &format!("{name} {FREED_DIRECTION} k{}", axis + 1)),
            kind: SdeKind::General,
            bodies: sde.bodies,
            point: sde.point,
            rotation: sde.rotation,
            law: SdeLaw::General {
                k: ks,
                psi: [psi; 6],
            },
            enabled: true,
        };
        model.sdes.push(added);
        ParamRef {
            sde: model.sdes.len() - 1,
            name: ParamName::PsiI(axis as u8),
        }
    };
    if let Some(name) = source {
        follow_psi(&mut r.vars, ParamRef { sde: s, name }, freed);
    }
    Ok(())
}

/// The direction whose ψ a stiffness freed in direction `axis` of `law` takes: `axis` itself
/// where the law has a ψ there, else the direction of its largest ψ. The candidate's `psi` is
/// drawn there ([`generate`](super::generate)), and [`free_direction`] follows the parameter
/// that sets it.
pub(super) fn psi_axis(law: &SdeLaw, axis: usize) -> usize {
    let own = law.dissipation();
    if own[axis] > 0.0 {
        axis
    } else {
        (0..6).fold(0, |best, a| if own[a] > own[best] { a } else { best })
    }
}

/// The parameter of `law` that sets the ψ of direction [`psi_axis`]`(law, axis)`.
fn psi_source(law: &SdeLaw, axis: usize) -> Option<ParamName> {
    let axis = psi_axis(law, axis);
    law.params()
        .into_iter()
        .filter(|p| p.is_dissipation())
        .find(|p| {
            law.derivative(*p)
                .is_some_and(|(_, dpsi)| dpsi[axis] != 0.0)
        })
}

/// Adds `freed` to the targets of the variable that sets `source` (with its ratio), if any.
fn follow_psi(vars: &mut Variables, source: ParamRef, freed: ParamRef) {
    for v in &mut vars.vars {
        let ratio = v
            .targets
            .iter()
            .find(|t| t.param.sde() == Some(source))
            .map(|t| t.ratio);
        if let Some(ratio) = ratio {
            if !v.targets.iter().any(|t| t.param.sde() == Some(freed)) {
                v.targets.push(Target {
                    param: Param::Sde(freed),
                    ratio,
                });
            }
            return;
        }
    }
}

/// Dynamic stiffness of a mass on a spring tuned to `freq_hz` (loss ψ of the structure), per
/// unit mass, at `omega` (rad/s): the coefficient of a resonator's first-order action.
pub fn resonator_coefficient(omega: f64, freq_hz: f64) -> C64 {
    let wr2 = C64::new(1.0, STRUCTURAL_PSI / TWO_PI) * (TWO_PI * freq_hz).powi(2);
    -omega * omega * wr2 / (wr2 - omega * omega)
}

/// Relative half-power width of a resonator's peak: its loss factor `ψ / 2π`.
pub const RESONATOR_WIDTH: f64 = STRUCTURAL_PSI / TWO_PI;

/// Gives the SDEs `sdes` of ψ group `variable` their own value `psi` of `parameter`, taking
/// them out of the group.
fn split_damping(
    r: &mut Realized,
    variable: usize,
    sdes: &[String],
    parameter: ParamName,
    psi: f64,
) -> Result<(), EffectError> {
    let model = &mut r.model;
    let var = r
        .vars
        .vars
        .get_mut(variable)
        .ok_or(EffectError::NoVariable(variable))?;
    let mut moved = Vec::new();
    var.targets.retain(|t| {
        let Some(p) = t.param.sde() else { return true };
        let hit = sdes.contains(&model.sdes[p.sde].name);
        if hit {
            moved.push(p);
        }
        !hit
    });
    if var.targets.is_empty() {
        return Err(EffectError::EmptyGroup);
    }
    for p in moved {
        model.set_param(
            ParamRef {
                sde: p.sde,
                name: parameter,
            },
            psi,
        );
    }
    Ok(())
}

fn axes() -> [Vector3<f64>; 3] {
    [Vector3::x(), Vector3::y(), Vector3::z()]
}

/// Displacement of `point` (global) of body `b` along unit `u` as a row over the model's DOFs.
pub fn point_row(
    model: &Model,
    b: usize,
    point: &Vector3<f64>,
    u: &Vector3<f64>,
) -> [(usize, f64); 6] {
    let body = &model.bodies[b];
    let g = generalized_force(&body.position, &body.rotation, point, u, &Vector3::zeros());
    std::array::from_fn(|i| (6 * b + i, g[i]))
}

/// The index of the body called `name`.
pub(crate) fn body_index(model: &Model, name: &str) -> Result<usize, EffectError> {
    model
        .body_index(name)
        .ok_or_else(|| EffectError::NoBody(name.into()))
}

fn fresh_name(model: &Model, stem: &str) -> String {
    let mut i = 1;
    loop {
        let name = format!("{stem} {i}");
        if !model.sdes.iter().any(|s| s.name == name)
            && !model.bodies.iter().any(|b| b.name == name)
        {
            return name;
        }
        i += 1;
    }
}

/// An axial spring-damper `k`, `psi` between `bodies` (None = ground) at `point` along `direction`.
fn add_spring(
    model: &mut Model,
    bodies: &[Option<String>; 2],
    point: &Vector3<f64>,
    direction: &Vector3<f64>,
    k: f64,
    psi: f64,
) -> Result<(), EffectError> {
    let idx = |b: &Option<String>| -> Result<Option<usize>, EffectError> {
        b.as_ref().map(|n| body_index(model, n)).transpose()
    };
    let bodies = [idx(&bodies[0])?, idx(&bodies[1])?];
    let name = fresh_name(model, "diagnosed spring");
    model.sdes.push(Sde {
        name,
        kind: SdeKind::Spring,
        bodies,
        point: *point,
        rotation: frame_from_axis(direction),
        law: SdeLaw::Axial {
            k: k.max(0.0),
            psi: psi.max(0.0),
        },
        enabled: true,
    });
    Ok(())
}

/// A body of mass `m` at `point`, on an isotropic General SDE to `host` tuned to `freq_hz`.
fn attach_mass(
    model: &mut Model,
    host: &str,
    point: &Vector3<f64>,
    m: f64,
    freq_hz: f64,
    psi: f64,
    stem: &str,
) -> Result<(), EffectError> {
    let h = body_index(model, host)?;
    if !(freq_hz.is_finite() && freq_hz > 0.0) {
        return Err(EffectError::BadFrequency(freq_hz));
    }
    let j = m * POINT_RADIUS * POINT_RADIUS;
    let name = fresh_name(model, stem);
    let b = model.bodies.len();
    model.bodies.push(Body {
        name: name.clone(),
        mass: m,
        inertia: [j; 3],
        position: *point,
        rotation: Matrix3::identity(),
    });
    let w2 = (TWO_PI * freq_hz).powi(2);
    let (kt, kr) = (m * w2, j * w2);
    model.sdes.push(Sde {
        name: format!("{name} mount"),
        kind: SdeKind::General,
        bodies: [Some(h), Some(b)],
        point: *point,
        rotation: Matrix3::identity(),
        law: SdeLaw::General {
            k: [kt, kt, kt, kr, kr, kr],
            psi: [psi; 6],
        },
        enabled: true,
    });
    Ok(())
}

/// Full side lengths (m) of the uniform box with the body's mass and principal inertias.
pub fn box_sides(body: &Body) -> [f64; 3] {
    let [j1, j2, j3] = body.inertia;
    let m = body.mass;
    let side = |a: f64, b: f64, c: f64| (6.0 * (b + c - a) / m).max(0.0).sqrt();
    [side(j1, j2, j3), side(j2, j3, j1), side(j3, j1, j2)]
}

/// Splits `name` into three equal thirds along its principal axis `axis`, joined at the two cuts
/// by General SDEs of translational compliance `c` (rotational stiffness: the translational one
/// times the cut section's squared radius of gyration). The centre third keeps the name (and the
/// output characteristics: same centre, same axes); SDEs and forces move to the third they act on.
pub fn split_body(model: &mut Model, name: &str, axis: usize, c: f64) -> Result<(), EffectError> {
    let b = body_index(model, name)?;
    let body = model.bodies[b].clone();
    let sides = box_sides(&body);
    let len = sides[axis];
    if !(len > 0.0) {
        return Err(EffectError::NoLength {
            body: name.into(),
            axis: axis + 1,
        });
    }
    let piece_sides = {
        let mut s = sides;
        s[axis] = len / 3.0;
        s
    };
    let m = body.mass / 3.0;
    let inertia = [0, 1, 2].map(|i| {
        let (a, bb) = (piece_sides[(i + 1) % 3], piece_sides[(i + 2) % 3]);
        m * (a * a + bb * bb) / 12.0
    });
    let u = body.rotation.column(axis).into_owned();
    let ends = [(-1.0, "−"), (1.0, "+")].map(|(s, sign)| {
        let pos = body.position + u * (s * len / 3.0);
        (
            s,
            Body {
                name: format!("{name} ({sign}{} third)", axis + 1),
                mass: m,
                inertia,
                position: pos,
                rotation: body.rotation,
            },
        )
    });
    model.bodies[b].mass = m;
    model.bodies[b].inertia = inertia;
    let first = model.bodies.len();
    for (_, e) in &ends {
        if model.bodies.iter().any(|x| x.name == e.name) {
            return Err(EffectError::AlreadySplit {
                body: name.into(),
                axis: axis + 1,
            });
        }
        model.bodies.push(e.clone());
    }
    // Which third a point belongs to.
    let third = |p: &Vector3<f64>| -> usize {
        let s = (p - body.position).dot(&u);
        if s < -len / 6.0 {
            first
        } else if s > len / 6.0 {
            first + 1
        } else {
            b
        }
    };
    for sde in model.sdes.iter_mut() {
        for side in 0..2 {
            if sde.bodies[side] == Some(b) {
                sde.bodies[side] = Some(third(&sde.point));
            }
        }
    }
    for f in model.forces.iter_mut().filter(|f| f.body == b) {
        f.body = third(&f.point);
    }
    for r in model.references.iter_mut() {
        if let rfe::model::Excitation::Forces(forces) = &mut r.excitation {
            for f in forces.iter_mut().filter(|f| f.body == b) {
                f.body = third(&f.point);
            }
        }
    }
    // The joints: cross-section of the other two sides.
    let (a1, a2) = (sides[(axis + 1) % 3], sides[(axis + 2) % 3]);
    let kt = 1.0 / c;
    let r2 = [(a1 * a1 + a2 * a2) / 12.0, a2 * a2 / 12.0, a1 * a1 / 12.0];
    let frame = Matrix3::from_columns(&[
        u,
        body.rotation.column((axis + 1) % 3).into_owned(),
        body.rotation.column((axis + 2) % 3).into_owned(),
    ]);
    for (k, (s, _)) in ends.iter().enumerate() {
        let point = body.position + u * (s * len / 6.0);
        let jn = format!(
            "{name} joint {}{}",
            if *s < 0.0 { "−" } else { "+" },
            axis + 1
        );
        model.sdes.push(Sde {
            name: jn,
            kind: SdeKind::General,
            bodies: [Some(b), Some(first + k)],
            point,
            rotation: frame,
            law: SdeLaw::General {
                k: [kt, kt, kt, kt * r2[0], kt * r2[1], kt * r2[2]],
                psi: [STRUCTURAL_PSI; 6],
            },
            enabled: true,
        });
    }
    Ok(())
}

/// A unit vector for reports: three components to 0.001, a zero one as `0` (not `0.000` or
/// a `1e-17` left by rounding).
fn unit_vector(d: &Vector3<f64>) -> String {
    let c = |x: f64| rfe::display::sig((x * 1e3).round() / 1e3, 3);
    format!("({}, {}, {})", c(d.x), c(d.y), c(d.z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{fwd32j, repo_file};
    use identify::variables;

    /// FWD-32J with its variables, every gain 1.
    fn fwd32j_realized() -> Realized {
        let model = fwd32j();
        let vars = variables::load(&repo_file("configs/identification/fwd32j.toml"), &model)
            .expect("configs/identification/fwd32j.toml loads");
        let gains = vec![1.0; model.outputs.len()];
        Realized { model, vars, gains }
    }

    /// SDE 34's axis 2, which its axial law leaves out, freed with ψ 0.6 drawn from the fit.
    fn freed_34() -> Effect {
        Effect::Direction {
            sde: "34".into(),
            axis: 1,
            held: 0.0,
            psi: 0.6,
            scale: 1e6,
        }
    }

    /// SDE 34's ψ is the "screw/actuator psi" variable's: the stiffness freed beside it joins
    /// that variable's targets, so a refit that moves the SDE's ψ moves the freed direction's
    /// with it (a freed direction held at the ψ it was drawn with could not fit where the base
    /// fit had pushed the group's ψ far from the truth to absorb misfit).
    #[test]
    fn a_freed_direction_takes_the_psi_the_variable_of_its_sde_sets() {
        let mut r = fwd32j_realized();
        let n = r.model.sdes.len();
        freed_34().apply(&mut r, &[3.0e6], 400.0).expect("applies");
        assert_eq!(r.model.sdes.len(), n + 1, "a parallel general element");
        let freed = ParamRef {
            sde: n,
            name: ParamName::PsiI(1),
        };
        let group = r
            .vars
            .vars
            .iter()
            .position(|v| v.name == "screw/actuator psi")
            .expect("the ψ group");
        assert!(
            r.vars.vars[group]
                .targets
                .iter()
                .any(|t| t.param == Param::Sde(freed)),
            "{:?}",
            r.vars.vars[group].targets
        );
        let mut x = r.vars.initial();
        x[group] = 0.42;
        let vars = r.vars.clone();
        vars.apply(&mut r.model, &x);
        assert_eq!(r.model.param(freed), Some(0.42));
        // The ψ group's joint-damping candidates still list only its joints, not the element.
        let candidates = crate::generate::candidates(&r.model, &r.vars, &x, &[], 1.0, 400.0);
        let listed = candidates.iter().any(|c| {
            matches!(c, Effect::Damping { sdes, .. } if sdes.iter().any(|s| s.contains("freed")))
        });
        assert!(!listed, "a freed direction is no joint of a ψ group");
    }

    /// Where no variable sets the SDE's ψ, the freed direction keeps the ψ it was drawn with.
    #[test]
    fn a_freed_direction_keeps_its_psi_where_no_variable_sets_the_sde_s() {
        let mut r = fwd32j_realized();
        r.vars.vars.retain(|v| v.name != "screw/actuator psi");
        let before = r.vars.clone();
        let n = r.model.sdes.len();
        freed_34().apply(&mut r, &[3.0e6], 400.0).expect("applies");
        let freed = ParamRef {
            sde: n,
            name: ParamName::PsiI(1),
        };
        assert_eq!(r.model.param(freed), Some(0.6));
        assert_eq!(r.vars, before, "no variable gains a target");
    }

    /// The demo's placed spring along (0.494, 0.855, 0.156): the frame across it has a zero
    /// component, printed as `0`, and no component shows rounding noise.
    #[test]
    fn a_fitted_line_of_action_prints_its_directions_without_zeros_to_three_places() {
        let direction = Vector3::new(0.494, 0.855, 0.156).normalize();
        let spring = Effect::PlacedSpring {
            bodies: [Some("spindle head".into()), Some("table".into())],
            point: Vector3::new(0.0, 0.9, 1.15),
            direction,
            reach: 0.1,
        };
        let place = spring
            .fitted_place(&[5e5, 0.8, 0.03, -0.01], &[1e3, 0.01, 0.04, 0.009])
            .expect("a placed spring has a place");
        assert!(place.contains("along (0.866, -0.5"), "{place}");
        assert!(!place.contains("0.000") && !place.contains("e-"), "{place}");
        let described = spring.describe();
        assert!(
            described.contains("along (0.494, 0.855, 0.156)"),
            "{described}"
        );
    }
}
