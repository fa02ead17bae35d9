//! The cutting file (`CUT.toml`): where the tool and the workpiece are, the cutting coefficients,
//! the operation (turning or milling: teeth, immersion, up/down milling, feed direction), the
//! spindle-speed range and optionally the tool's own modes. `docs/stability.md` documents every
//! field; `configs/cuts/` holds examples.
//!
//! ```
//! let text = r#"
//! operation = "turning"
//! speed_rpm = [500, 3000]
//! [tool]
//! body = "mass"
//! point = [0.0, 0.0, 0.0]
//! [workpiece]
//! body = "ground"
//! point = [0.0, 0.0, 0.0]
//! [cutting]
//! kt = "1000 MPa"
//! kr = "400 MPa"
//! [turning]
//! thickness = [0.0, 0.0, 1.0]
//! cutting = [1.0, 0.0, 0.0]
//! "#;
//! let cut = stability::cut::parse(text, "cut.toml").unwrap();
//! assert_eq!(cut.kt, 1.0e9);
//! ```

use nalgebra::Vector3;
use serde::Deserialize;

use rfe::source::{strip_bom, Quantity};
use rfe::units::{parse_quantities, Dim};

/// Spindle speeds on the lobe grid when the file does not say.
pub const DEFAULT_SPEEDS: usize = 200;
/// Frequency lines of the oriented FRF when the file does not say: fine enough that a resonance
/// with a loss factor of 1 % spans about ten lines over two decades.
pub const DEFAULT_LINES: usize = 4000;

/// A problem with a cutting file: the file, the field, what is wrong and how to fix it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CutError {
    /// The file is not valid TOML or a field has the wrong type.
    #[error("{file}: {message}")]
    Syntax {
        /// File name.
        file: String,
        /// The parser's message (with line and column).
        message: String,
    },
    /// A field is missing or its value is not usable.
    #[error("{file}: {field}: {problem}; {fix}")]
    Field {
        /// File name.
        file: String,
        /// TOML path of the field (`cutting.kt`).
        field: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },
}

/// Up or down milling (conventional or climb).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Up (conventional) milling: the tooth enters at zero chip thickness.
    Up,
    /// Down (climb) milling: the tooth leaves at zero chip thickness.
    Down,
}

/// Milling: a cutter of `teeth` equally spaced teeth, immersion from `radial_depth`.
#[derive(Debug, Clone, PartialEq)]
pub struct Milling {
    /// Number of teeth.
    pub teeth: usize,
    /// Cutter diameter (m).
    pub diameter: f64,
    /// Radial depth of cut a_e (m), `0 < a_e ≤ diameter`.
    pub radial_depth: f64,
    /// Up or down milling.
    pub direction: Direction,
    /// Feed direction (global, unit): the x axis of the cutting plane.
    pub feed: Vector3<f64>,
    /// Tool axis (global, unit, from the tip towards the spindle): z; y = z × x.
    pub axis: Vector3<f64>,
}

impl Milling {
    /// Entry and exit angles (rad), measured as Altintas does: from the cutting plane's +y
    /// axis, in the cutter's sense of rotation (clockwise seen from the spindle).
    pub fn immersion(&self) -> (f64, f64) {
        let c = (1.0 - 2.0 * self.radial_depth / self.diameter).clamp(-1.0, 1.0);
        match self.direction {
            Direction::Up => (0.0, c.acos()),
            Direction::Down => (std::f64::consts::PI - c.acos(), std::f64::consts::PI),
        }
    }
}

/// Turning (or any single-point cut): the chip thickness is measured along `thickness`.
#[derive(Debug, Clone, PartialEq)]
pub struct Turning {
    /// Unit direction (global) along which a motion of the tool relative to the workpiece thins
    /// the chip; the radial (thrust) force on the tool acts along it.
    pub thickness: Vector3<f64>,
    /// Unit direction (global) of the tangential (main cutting) force on the tool, ⟂ thickness.
    /// Full overlap is assumed: the tool cuts the whole surface the previous revolution left.
    pub cutting: Vector3<f64>,
}

/// The operation.
#[derive(Debug, Clone, PartialEq)]
pub enum Operation {
    /// Turning, boring, single-point cutting (Tlusty/Tobias).
    Turning(Turning),
    /// Milling (Altintas-Budak zeroth-order approximation; semi-discretization).
    Milling(Milling),
}

/// A point on a body of the model, or on the ground.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    /// Body name as in the model, or `ground`.
    pub body: String,
    /// Point, global frame (m).
    pub point: Vector3<f64>,
}

/// One mode of the tool clamped at the spindle nose, seen at its tip along `direction`.
#[derive(Debug, Clone, PartialEq)]
pub struct ToolMode {
    /// Direction (global, unit).
    pub direction: Vector3<f64>,
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Viscous damping ratio ζ (-).
    pub damping_ratio: f64,
    /// Modal stiffness at the tip (N/m).
    pub stiffness: f64,
}

/// A resolved cutting file (SI units).
#[derive(Debug, Clone, PartialEq)]
pub struct Cut {
    /// File name, for messages.
    pub origin: String,
    /// The file's free-text `note`, if any.
    pub note: Option<String>,
    /// The operation.
    pub operation: Operation,
    /// The tool point (the spindle nose, or the tool tip on the spindle's body).
    pub tool: Contact,
    /// The workpiece point.
    pub workpiece: Contact,
    /// Tool modes added in series at the tool point (receptance coupling of a tool given as
    /// modal parameters); empty for none.
    pub tool_modes: Vec<ToolMode>,
    /// Tool receptances read from UFF files (`[[tool.frf]]`), added in series at the tool point
    /// like the modes; empty for none.
    pub tool_frfs: Vec<crate::tool::ToolFrf>,
    /// Tangential cutting coefficient K_t (N/m²).
    pub kt: f64,
    /// Radial (normal) cutting coefficient K_r (N/m²), not the ratio.
    pub kr: f64,
    /// Spindle-speed range (rpm).
    pub speed_rpm: (f64, f64),
    /// Spindle speeds on the grid.
    pub speeds: usize,
    /// Band of the oriented FRF's lines `(lowest, highest)` (Hz); `None`: from the model's modes.
    pub band_hz: Option<(f64, f64)>,
    /// Frequency lines of the oriented FRF.
    pub lines: usize,
}

impl Cut {
    /// The two directions (global, unit) the oriented FRF is taken in: milling x = feed and
    /// y = axis × feed; turning the chip-thickness and the cutting-force directions.
    pub fn directions(&self) -> [Vector3<f64>; 2] {
        match &self.operation {
            Operation::Milling(m) => [m.feed, m.axis.cross(&m.feed)],
            Operation::Turning(t) => [t.thickness, t.cutting],
        }
    }

    /// Cutting periods per revolution: teeth for milling, 1 for turning.
    pub fn periods_per_rev(&self) -> usize {
        match &self.operation {
            Operation::Milling(m) => m.teeth,
            Operation::Turning(_) => 1,
        }
    }

    /// The spindle speeds of the grid (rpm), evenly spaced.
    pub fn speed_grid(&self) -> Vec<f64> {
        let (a, b) = self.speed_rpm;
        let n = self.speeds.max(2);
        (0..n)
            .map(|i| a + (b - a) * i as f64 / (n - 1) as f64)
            .collect()
    }
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RawPoint {
    Numbers(Vec<f64>),
    Text(String),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawContact {
    body: Option<String>,
    point: Option<RawPoint>,
    #[serde(default, rename = "mode")]
    modes: Vec<RawToolMode>,
    #[serde(default, rename = "frf")]
    frfs: Vec<RawToolFrf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawToolFrf {
    uff: Option<String>,
    direction: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawToolMode {
    direction: Option<Vec<f64>>,
    freq: Option<Quantity>,
    damping_ratio: Option<f64>,
    stiffness: Option<Quantity>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCutting {
    kt: Option<Quantity>,
    kr: Option<Quantity>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMilling {
    teeth: Option<usize>,
    diameter: Option<Quantity>,
    radial_depth: Option<Quantity>,
    direction: Option<String>,
    feed: Option<Vec<f64>>,
    axis: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTurning {
    thickness: Option<Vec<f64>>,
    cutting: Option<Vec<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCut {
    note: Option<String>,
    operation: Option<String>,
    speed_rpm: Option<Vec<f64>>,
    speeds: Option<usize>,
    band_hz: Option<Vec<f64>>,
    lines: Option<usize>,
    tool: Option<RawContact>,
    workpiece: Option<RawContact>,
    cutting: Option<RawCutting>,
    milling: Option<RawMilling>,
    turning: Option<RawTurning>,
}

/// Reads a cutting file.
pub fn load(path: &std::path::Path) -> Result<Cut, CutError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| CutError::Syntax {
        file: file.clone(),
        message: format!("cannot read the cutting file: {e}"),
    })?;
    parse(&text, &file)
}

/// Parses the text of a cutting file named `file`.
pub fn parse(text: &str, file: &str) -> Result<Cut, CutError> {
    let raw: RawCut = toml::from_str(strip_bom(text)).map_err(|e| CutError::Syntax {
        file: file.into(),
        message: e.to_string().trim_end().replace('\n', " "),
    })?;
    let f = Fields { file };
    let operation = match raw.operation.as_deref() {
        Some("milling") => Operation::Milling(f.milling(raw.milling)?),
        Some("turning") => Operation::Turning(f.turning(raw.turning)?),
        Some(other) => {
            return Err(f.err(
                "operation",
                format!("\"{other}\" is not an operation"),
                "write operation = \"milling\" or \"turning\"",
            ))
        }
        None => {
            return Err(f.err(
                "operation",
                "missing",
                "add operation = \"milling\" or \"turning\"",
            ))
        }
    };
    let cutting = raw.cutting.ok_or_else(|| {
        f.err(
            "cutting",
            "the cutting coefficients are missing",
            "add a [cutting] table with kt = \"796 MPa\" and kr = \"168 MPa\" (tangential and radial coefficients of the tool and material)",
        )
    })?;
    let kt = f.pressure(cutting.kt.as_ref(), "cutting.kt", "tangential")?;
    let kr = f.pressure(cutting.kr.as_ref(), "cutting.kr", "radial")?;
    if !(kt > 0.0) || kr < 0.0 {
        return Err(f.err(
            "cutting",
            format!("kt = {kt} N/m² must be > 0 and kr = {kr} N/m² ≥ 0"),
            "give the coefficients of the tool and material from a cutting test or a handbook",
        ));
    }
    let speed_rpm = match raw.speed_rpm.as_deref() {
        Some(&[a, b]) if a > 0.0 && b > a && b.is_finite() => (a, b),
        Some(_) => {
            return Err(f.err(
                "speed_rpm",
                "not a range [lowest, highest] with 0 < lowest < highest",
                "write speed_rpm = [1000, 8000]",
            ))
        }
        None => {
            return Err(f.err(
                "speed_rpm",
                "missing",
                "add speed_rpm = [lowest, highest] (spindle speeds of interest, rpm)",
            ))
        }
    };
    let speeds = raw.speeds.unwrap_or(DEFAULT_SPEEDS);
    if speeds < 2 {
        return Err(f.err("speeds", "fewer than 2 speeds", "write speeds = 200"));
    }
    let lines = raw.lines.unwrap_or(DEFAULT_LINES);
    if lines < 100 {
        return Err(f.err(
            "lines",
            format!("{lines} frequency lines cannot resolve the resonances"),
            "leave it out (4000) or give at least 100",
        ));
    }
    let band_hz =
        match raw.band_hz.as_deref() {
            None => None,
            Some(&[a, b]) if a > 0.0 && b > a && b.is_finite() => Some((a, b)),
            Some(_) => return Err(f.err(
                "band_hz",
                "not a band [lowest, highest] with 0 < lowest < highest",
                "leave it out (the band follows the model's modes) or write band_hz = [20, 800]",
            )),
        };
    let tool_raw = raw.tool.ok_or_else(|| {
        f.err(
            "tool",
            "missing",
            "add [tool] with body = \"spindle head\" and point = [x, y, z] (m, global)",
        )
    })?;
    let tool_modes = tool_raw
        .modes
        .iter()
        .enumerate()
        .map(|(i, m)| f.tool_mode(i, m))
        .collect::<Result<_, _>>()?;
    let tool_frfs = tool_raw
        .frfs
        .iter()
        .enumerate()
        .map(|(i, t)| f.tool_frf(i, t))
        .collect::<Result<_, _>>()?;
    let tool = f.contact(tool_raw, "tool")?;
    let workpiece = f.contact(
        raw.workpiece.ok_or_else(|| {
            f.err(
                "workpiece",
                "missing",
                "add [workpiece] with body = \"table\" (or \"ground\") and point = [x, y, z] (m, global)",
            )
        })?,
        "workpiece",
    )?;
    Ok(Cut {
        origin: file.into(),
        note: raw.note,
        operation,
        tool,
        workpiece,
        tool_modes,
        tool_frfs,
        kt,
        kr,
        speed_rpm,
        speeds,
        band_hz,
        lines,
    })
}

/// The pressure units of a cutting coefficient and their value in Pa (N/m²).
pub const PRESSURE_UNITS: [(&str, f64); 9] = [
    ("Pa", 1.0),
    ("kPa", 1e3),
    ("MPa", 1e6),
    ("GPa", 1e9),
    ("N/m^2", 1.0),
    ("N/m²", 1.0),
    ("N/mm^2", 1e6),
    ("N/mm²", 1e6),
    ("N/mm2", 1e6),
];

/// A pressure `"<number> <unit>"` with a unit of [`PRESSURE_UNITS`], to N/m²; the problem in
/// words otherwise.
pub fn parse_pressure(text: &str) -> Result<f64, String> {
    let t = text.trim();
    // The number is the longest prefix that reads as one (`1.8e3 MPa`, `800N/mm^2`).
    let (x, unit) = t
        .char_indices()
        .map(|(i, _)| i)
        .chain([t.len()])
        .rev()
        .find_map(|i| Some((t[..i].trim().parse::<f64>().ok()?, t[i..].trim())))
        .ok_or_else(|| format!("\"{text}\" does not start with a number"))?;
    if unit.is_empty() {
        return Err(format!("\"{text}\" has no unit"));
    }
    let factor = PRESSURE_UNITS
        .iter()
        .find(|(u, _)| *u == unit)
        .map(|(_, f)| *f)
        .ok_or_else(|| format!("\"{unit}\" is not a pressure unit"))?;
    let v = x * factor;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("\"{text}\" is not finite"))
    }
}

struct Fields<'a> {
    file: &'a str,
}

impl Fields<'_> {
    fn err(&self, field: &str, problem: impl Into<String>, fix: impl Into<String>) -> CutError {
        CutError::Field {
            file: self.file.into(),
            field: field.into(),
            problem: problem.into(),
            fix: fix.into(),
        }
    }

    fn quantity(&self, q: &Quantity, dim: Dim, field: &str) -> Result<f64, CutError> {
        q.si(dim)
            .map_err(|e| self.err(field, e.to_string(), format!("write {}", dim.describe())))
    }

    /// A cutting coefficient: a pressure with its unit written out (`"800 MPa"`,
    /// `"800 N/mm^2"`), to N/m². A bare number is refused: handbooks give K_t and K_r in N/mm²
    /// (= MPa) as often as in N/m², and a factor 10⁶ off would pass unnoticed.
    fn pressure(&self, q: Option<&Quantity>, field: &str, what: &str) -> Result<f64, CutError> {
        let key = field.rsplit('.').next().unwrap_or(field);
        let fix = format!(
            "write the {what} cutting coefficient as a pressure with its unit, e.g. {key} = \"800 MPa\" or \"800 N/mm^2\" (units: {})",
            PRESSURE_UNITS.iter().map(|(u, _)| *u).collect::<Vec<_>>().join(", ")
        );
        match q {
            None => Err(self.err(field, "missing", fix)),
            Some(Quantity::Number(x)) => Err(self.err(field, format!("{x} has no unit"), fix)),
            Some(Quantity::Text(t)) => match parse_pressure(t) {
                Ok(v) => Ok(v),
                Err(problem) => Err(self.err(field, problem, fix)),
            },
        }
    }

    fn vector(&self, v: Option<&Vec<f64>>, field: &str) -> Result<Vector3<f64>, CutError> {
        match v.map(|v| v.as_slice()) {
            Some(&[x, y, z]) => {
                let d = Vector3::new(x, y, z);
                let n = d.norm();
                if n > 0.0 && n.is_finite() {
                    Ok(d / n)
                } else {
                    Err(self.err(
                        field,
                        "zero or not finite",
                        "give a direction like [1, 0, 0]",
                    ))
                }
            }
            Some(_) => Err(self.err(
                field,
                "not three numbers",
                "give a direction like [1, 0, 0] (global)",
            )),
            None => Err(self.err(field, "missing", "give a direction like [1, 0, 0] (global)")),
        }
    }

    fn contact(&self, raw: RawContact, table: &str) -> Result<Contact, CutError> {
        let body = raw.body.ok_or_else(|| {
            self.err(
                &format!("{table}.body"),
                "missing",
                "name a body of the model (or \"ground\")",
            )
        })?;
        let field = format!("{table}.point");
        let xyz = match raw.point {
            Some(RawPoint::Numbers(v)) => v,
            Some(RawPoint::Text(t)) => parse_quantities(&t, Dim::LENGTH)
                .map_err(|e| self.err(&field, e.to_string(), "write \"0 900 1150 mm\""))?,
            None => {
                return Err(self.err(
                    &field,
                    "missing",
                    "give point = [x, y, z] (m, global) or \"x y z mm\"",
                ))
            }
        };
        match xyz.as_slice() {
            &[x, y, z] if [x, y, z].iter().all(|v| v.is_finite()) => Ok(Contact {
                body,
                point: Vector3::new(x, y, z),
            }),
            _ => Err(self.err(
                &field,
                "not three finite coordinates",
                "give point = [x, y, z] (m, global)",
            )),
        }
    }

    fn tool_mode(&self, i: usize, m: &RawToolMode) -> Result<ToolMode, CutError> {
        let field = |k: &str| format!("tool.mode[{i}].{k}");
        let direction = self.vector(m.direction.as_ref(), &field("direction"))?;
        let freq_hz = match &m.freq {
            Some(q) => self.quantity(q, Dim::FREQUENCY, &field("freq"))?,
            None => return Err(self.err(&field("freq"), "missing", "write freq = \"1200 Hz\"")),
        };
        let stiffness = match &m.stiffness {
            Some(q) => self.quantity(q, Dim::STIFFNESS, &field("stiffness"))?,
            None => {
                return Err(self.err(
                    &field("stiffness"),
                    "missing",
                    "write stiffness = \"20 N/um\"",
                ))
            }
        };
        let damping_ratio = m.damping_ratio.unwrap_or(f64::NAN);
        if !(freq_hz > 0.0 && stiffness > 0.0 && damping_ratio > 0.0 && damping_ratio < 1.0) {
            return Err(self.err(
                &format!("tool.mode[{i}]"),
                "needs freq > 0, stiffness > 0 and 0 < damping_ratio < 1",
                "give the tool's clamped modes, e.g. freq = \"1200 Hz\", damping_ratio = 0.03, stiffness = \"20 N/um\"",
            ));
        }
        Ok(ToolMode {
            direction,
            freq_hz,
            damping_ratio,
            stiffness,
        })
    }

    /// A `[[tool.frf]]`: the UFF file (relative to the cutting file's folder) and the direction
    /// it was measured in.
    fn tool_frf(&self, i: usize, t: &RawToolFrf) -> Result<crate::tool::ToolFrf, CutError> {
        let field = |k: &str| format!("tool.frf[{i}].{k}");
        let direction = self.vector(t.direction.as_ref(), &field("direction"))?;
        let Some(name) = &t.uff else {
            return Err(self.err(
                &field("uff"),
                "missing",
                "write uff = \"tool-x.uff\" (the tool tip's driving-point FRF, UFF58; relative to the cutting file)",
            ));
        };
        let path = std::path::Path::new(self.file)
            .parent()
            .unwrap_or(std::path::Path::new(""))
            .join(name);
        crate::tool::read(&path, direction).map_err(|problem| {
            self.err(
                &field("uff"),
                format!("{}: {problem}", path.display()),
                "or give the tool by its modes ([[tool.mode]])",
            )
        })
    }

    fn milling(&self, raw: Option<RawMilling>) -> Result<Milling, CutError> {
        let m = raw.ok_or_else(|| {
            self.err(
                "milling",
                "missing for operation = \"milling\"",
                "add [milling] with teeth, diameter, radial_depth, direction = \"up\"|\"down\", feed = [1, 0, 0]",
            )
        })?;
        let teeth = m
            .teeth
            .filter(|&t| t >= 1)
            .ok_or_else(|| self.err("milling.teeth", "missing or 0", "write teeth = 4"))?;
        let diameter = match &m.diameter {
            Some(q) => self.quantity(q, Dim::LENGTH, "milling.diameter")?,
            None => {
                return Err(self.err("milling.diameter", "missing", "write diameter = \"20 mm\""))
            }
        };
        let radial_depth = match &m.radial_depth {
            Some(q) => self.quantity(q, Dim::LENGTH, "milling.radial_depth")?,
            None => {
                return Err(self.err(
                    "milling.radial_depth",
                    "missing",
                    "write radial_depth = \"10 mm\" (a_e; the diameter for slotting)",
                ))
            }
        };
        if !(diameter > 0.0 && radial_depth > 0.0 && radial_depth <= diameter) {
            return Err(self.err(
                "milling.radial_depth",
                format!("a_e = {radial_depth} m with D = {diameter} m"),
                "need 0 < radial_depth ≤ diameter",
            ));
        }
        let direction = match m.direction.as_deref() {
            Some("up") => Direction::Up,
            Some("down") => Direction::Down,
            _ => {
                return Err(self.err(
                    "milling.direction",
                    "missing or not up/down",
                    "write direction = \"down\" (climb) or \"up\" (conventional)",
                ))
            }
        };
        let feed = self.vector(m.feed.as_ref(), "milling.feed")?;
        let axis = match &m.axis {
            Some(_) => self.vector(m.axis.as_ref(), "milling.axis")?,
            None => Vector3::z(),
        };
        if feed.dot(&axis).abs() > 1e-6 {
            return Err(self.err(
                "milling.feed",
                "not perpendicular to the tool axis",
                "give a feed direction in the plane perpendicular to milling.axis (default [0, 0, 1])",
            ));
        }
        Ok(Milling {
            teeth,
            diameter,
            radial_depth,
            direction,
            feed,
            axis,
        })
    }

    fn turning(&self, raw: Option<RawTurning>) -> Result<Turning, CutError> {
        let t = raw.ok_or_else(|| {
            self.err(
                "turning",
                "missing for operation = \"turning\"",
                "add [turning] with thickness = [..] (chip-thickness direction) and cutting = [..] (tangential force direction)",
            )
        })?;
        let thickness = self.vector(t.thickness.as_ref(), "turning.thickness")?;
        let cutting = self.vector(t.cutting.as_ref(), "turning.cutting")?;
        if thickness.dot(&cutting).abs() > 1e-6 {
            return Err(self.err(
                "turning.cutting",
                "not perpendicular to turning.thickness",
                "the tangential force direction is perpendicular to the chip-thickness direction",
            ));
        }
        Ok(Turning { thickness, cutting })
    }
}
