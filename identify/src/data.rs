//! Measured data for identification: reading [`MeasuredData`] from JSON or CSV (format in
//! `docs/identification.md`), and validating it against a model into [`Observations`].
//!
//! Parsing is I/O-free (`parse_json`, `parse_csv` take the text and its origin for messages);
//! [`load`] reads a file and picks the form (JSON when the text starts with `{`).

use std::collections::BTreeMap;
use std::path::Path;

use rfe::frf_units::{self, FrfUnit};
use rfe::measured::{MeasuredData, Measurement, QuantityName};
use rfe::model::{Characteristic, Model, Quantity, DOF_NAMES};

/// Why measured data could not be read or used.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The file could not be read.
    #[error("{path}: cannot read the data file")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// A JSON syntax or structure error.
    #[error("{origin}: at {path}: {message}")]
    Json {
        /// File.
        origin: String,
        /// JSON path, e.g. `$.characteristics[0].amplitude`.
        path: String,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// A CSV error at a line.
    #[error("{origin}:{line}: {message}")]
    Csv {
        /// File.
        origin: String,
        /// 1-based line.
        line: usize,
        /// What is wrong and how to fix it.
        message: String,
    },
    /// A value that cannot be used, located by item (JSON path or characteristic and point).
    #[error("{origin}: {item}: {message}")]
    Invalid {
        /// File.
        origin: String,
        /// e.g. `$.characteristics[1] (table u2 displacement), point 7 (112.5 Hz)`.
        item: String,
        /// What is wrong and how to fix it.
        message: String,
    },
}

/// Reads a data file against the model it will be fitted with: JSON or CSV as [`load`], and a
/// CSV whose header declares a unit (`# unit = g/N`, docs/identification.md) converted exactly
/// to the model's convention (SI, the response to the model's excitation, the model output's
/// quantity: [`frf_units::to_model_convention`]); data in another quantity than the model's
/// output for that body and DOF are converted by (jω)^k. What was assumed and converted is
/// appended to [`MeasuredData::source`], one `; `-separated note each, so reports can state it.
pub fn load_for_model(path: &Path, model: &Model) -> Result<MeasuredData, DataError> {
    let text = std::fs::read_to_string(path).map_err(|source| DataError::Io {
        path: path.display().to_string(),
        source,
    })?;
    let origin = path.display().to_string();
    let mut notes = Vec::new();
    let mut data = if text.trim_start().starts_with('{') {
        notes.push("units: SI, the response to the model's excitation (JSON form)".to_string());
        parse_json(&text, &origin)?
    } else {
        let (mut data, declared) = parse_csv_declared(&text, &origin)?;
        match declared {
            Some(d) => {
                notes.push(format!("unit {} declared in line {}", d.unit.text, d.line));
                for m in &mut data.characteristics {
                    frf_units::to_model_convention(m, &d.unit, model, &mut notes)
                        .map_err(|e| CsvErr { origin: &origin }.at(d.line, e.to_string()))?;
                }
            }
            None => notes.push(
                "units: none declared (no `# unit = ...` line): SI, the response to the model's excitation"
                    .to_string(),
            ),
        }
        data
    };
    for (i, m) in data.characteristics.iter_mut().enumerate() {
        frf_units::convert_quantity(m, model, &mut notes).map_err(|e| DataError::Invalid {
            origin: origin.clone(),
            item: format!("$.characteristics[{i}]"),
            message: e.to_string(),
        })?;
    }
    data.source = std::iter::once(data.source.clone())
        .chain(notes)
        .collect::<Vec<_>>()
        .join("; ");
    Ok(data)
}

/// A unit declared in a CSV comment line before the header.
#[derive(Debug, Clone, PartialEq)]
pub struct DeclaredUnit {
    /// The unit.
    pub unit: FrfUnit,
    /// Its line (1-based).
    pub line: usize,
}

/// The `# unit = ...` and `# quantity = ...` declarations of a CSV file's comment lines before
/// its header (`# quantity = accelerance, unit = g/N`); other comments are ignored.
fn csv_declarations(text: &str, err: &CsvErr) -> Result<Option<DeclaredUnit>, DataError> {
    let mut unit: Option<DeclaredUnit> = None;
    let mut kind: Option<(String, usize)> = None;
    for (i, l) in text.lines().enumerate() {
        let l = l.trim();
        if l.is_empty() {
            continue;
        }
        let Some(c) = l.strip_prefix('#') else { break };
        for part in c.split([',', ';']) {
            let Some((k, v)) = part.split_once('=') else {
                continue;
            };
            match k.trim().to_ascii_lowercase().as_str() {
                "unit" | "units" => {
                    if let Some(u) = &unit {
                        return Err(err.at(
                            i + 1,
                            format!(
                                "a second unit declaration; line {} already declares {}",
                                u.line, u.unit.text
                            ),
                        ));
                    }
                    let u = FrfUnit::parse(v).map_err(|m| err.at(i + 1, format!("unit: {m}")))?;
                    unit = Some(DeclaredUnit {
                        unit: u,
                        line: i + 1,
                    });
                }
                "quantity" => kind = Some((v.trim().to_ascii_lowercase(), i + 1)),
                _ => {}
            }
        }
    }
    if let Some((k, line)) = kind {
        let Some(u) = &unit else {
            return Err(err.at(line, format!("quantity = {k} is declared without a unit; add e.g. `# quantity = {k}, unit = ...` (m/N, (mm/s)/N, g/N, ...)")));
        };
        let kinds = [u.unit.kind(), u.unit.quantity.as_str()];
        if !kinds.contains(&k.as_str()) {
            return Err(err.at(
                line,
                format!(
                    "quantity = {k}, but the unit {} is a {}; fix one of them",
                    u.unit.text,
                    u.unit.kind()
                ),
            ));
        }
    }
    Ok(unit)
}

/// Parses the CSV form with its unit declaration, if any: the amplitudes (and variances) stay in
/// the declared unit (apply [`frf_units::to_model_convention`]), and every characteristic takes
/// the declared quantity (a `quantity` column must agree with it).
pub fn parse_csv_declared(
    text: &str,
    origin: &str,
) -> Result<(MeasuredData, Option<DeclaredUnit>), DataError> {
    let text = rfe::source::strip_bom(text);
    let err = CsvErr { origin };
    let declared = csv_declarations(text, &err)?;
    let (mut data, has_quantity) = parse_csv_rows(text, origin)?;
    if let Some(d) = &declared {
        for m in &mut data.characteristics {
            let q: QuantityName = d.unit.quantity.into();
            // A transmissibility is the same ratio in any like quantity.
            if has_quantity && m.quantity != q && !d.unit.per_base_motion {
                return Err(err.at(d.line, format!(
                    "{} {}: the quantity column says {}, but the declared unit {} is a {}; fix one of them",
                    m.body,
                    DOF_NAMES.get(m.dof as usize).copied().unwrap_or("?"),
                    Quantity::from(m.quantity).as_str(),
                    d.unit.text,
                    d.unit.kind()
                )));
            }
            m.quantity = q;
        }
    }
    Ok((data, declared))
}

/// Reads a data file: JSON ([`MeasuredData`]) when the text starts with `{`, CSV otherwise.
/// A CSV that declares a unit needs the model: use [`load_for_model`].
pub fn load(path: &Path) -> Result<MeasuredData, DataError> {
    let io = |source| DataError::Io {
        path: path.display().to_string(),
        source,
    };
    rfe::source::read_json_or(path, io, parse_json, parse_csv)
}

/// Parses the JSON form (the [`MeasuredData`] serialization).
pub fn parse_json(text: &str, origin: &str) -> Result<MeasuredData, DataError> {
    rfe::source::from_json(text).map_err(|e| DataError::Json {
        origin: origin.into(),
        path: e.path,
        message: format!("{}; see docs/identification.md for the format", e.message),
    })
}

/// Columns of the CSV form, in the order [`to_csv`] writes them.
pub const CSV_COLUMNS: [&str; 11] = [
    "body",
    "dof",
    "quantity",
    "freq_hz",
    "amplitude",
    "phase_rad",
    "variance",
    "coherence",
    "averages",
    "reference",
    "motion",
];

/// What one CSV row's characteristic is: body, DOF, quantity, reference (`None`: the model's
/// excitation) and whether it is relative to a moving base.
type CsvKey = (String, u8, QuantityName, Option<String>, bool);

/// Parses the CSV form: a header naming the columns (any order; `body`, `dof`, `freq_hz`,
/// `amplitude` required; `quantity` defaults to displacement; `phase_rad`, `variance`,
/// `coherence`, `averages` optional), one row per point. Lines starting with `#` and empty
/// lines are skipped. Rows of a characteristic may come in any order; they are sorted by
/// frequency, and a repeated frequency is an error naming both lines.
pub fn parse_csv(text: &str, origin: &str) -> Result<MeasuredData, DataError> {
    let text = rfe::source::strip_bom(text);
    let err = CsvErr { origin };
    if let Some(d) = csv_declarations(text, &err)? {
        return Err(err.at(d.line, format!(
            "the file declares the unit {}; it is converted against a model (identify::data::load_for_model), not read as SI",
            d.unit.text
        )));
    }
    parse_csv_rows(text, origin).map(|(d, _)| d)
}

/// The CSV rows as [`MeasuredData`], and whether the header has a `quantity` column.
fn parse_csv_rows(text: &str, origin: &str) -> Result<(MeasuredData, bool), DataError> {
    let err = CsvErr { origin };
    let rows_read = rfe::csv_text::rows(text).map_err(|e| err.at(e.line, e.message))?;
    let mut lines = rows_read.iter().map(|r| (r.line, &r.cells));
    let Some((hline, header)) = lines.next() else {
        return Err(err.at(
            1,
            "empty file: expected a header line, e.g. `body,dof,quantity,freq_hz,amplitude`".into(),
        ));
    };
    let (col, ncols) = csv_columns(header, hline, &err)?;
    // Characteristics in order of first appearance.
    let mut order: Vec<CsvKey> = Vec::new();
    let mut rows: Vec<Vec<CsvRow>> = Vec::new();
    for (ln, cells) in lines {
        let cells: Vec<&str> = cells.iter().map(String::as_str).collect();
        if cells.len() != ncols {
            return Err(err.at(
                ln,
                format!("{} cells, but the header has {ncols} columns", cells.len()),
            ));
        }
        let (key, row) = csv_row(&cells, &col, ln, &err)?;
        match order.iter().position(|k| *k == key) {
            Some(i) => rows[i].push(row),
            None => {
                order.push(key);
                rows.push(vec![row]);
            }
        }
    }
    if order.is_empty() {
        return Err(err.at(hline, "no data rows after the header".into()));
    }
    let characteristics = order
        .into_iter()
        .zip(rows)
        .map(|(key, pts)| csv_characteristic(key, pts, hline, &err))
        .collect::<Result<_, _>>()?;
    Ok((
        MeasuredData {
            source: origin.to_string(),
            characteristics,
        },
        col.contains_key("quantity"),
    ))
}

/// Errors of a CSV file: its name and a line.
struct CsvErr<'a> {
    origin: &'a str,
}

impl CsvErr<'_> {
    fn at(&self, line: usize, message: String) -> DataError {
        DataError::Csv {
            origin: self.origin.into(),
            line,
            message,
        }
    }
}

/// One data row of the CSV form.
struct CsvRow {
    line: usize,
    freq: f64,
    amp: f64,
    phase: Option<f64>,
    var: Option<f64>,
    coh: Option<f64>,
    avg: Option<u32>,
}

/// The header's columns (name → index; known names, each once, the required ones present)
/// and their count.
fn csv_columns(
    header: &[String],
    hline: usize,
    err: &CsvErr,
) -> Result<(BTreeMap<&'static str, usize>, usize), DataError> {
    let names: Vec<String> = header.iter().map(|s| s.to_ascii_lowercase()).collect();
    let mut col: BTreeMap<&'static str, usize> = BTreeMap::new();
    for (i, n) in names.iter().enumerate() {
        let Some(known) = CSV_COLUMNS.iter().find(|c| **c == n.as_str()) else {
            return Err(err.at(
                hline,
                format!(
                    "unknown column \"{n}\"; known columns: {}",
                    CSV_COLUMNS.join(", ")
                ),
            ));
        };
        if col.insert(known, i).is_some() {
            return Err(err.at(hline, format!("column \"{n}\" appears twice")));
        }
    }
    for required in ["body", "dof", "freq_hz", "amplitude"] {
        if !col.contains_key(required) {
            return Err(err.at(hline, format!("missing column \"{required}\"; the header needs at least body, dof, freq_hz, amplitude")));
        }
    }
    Ok((col, names.len()))
}

/// One data row: the characteristic it belongs to (body, dof, quantity) and its values.
fn csv_row(
    cells: &[&str],
    col: &BTreeMap<&'static str, usize>,
    ln: usize,
    err: &CsvErr,
) -> Result<(CsvKey, CsvRow), DataError> {
    let cell = |name: &str| col.get(name).map(|&i| cells[i]).filter(|c| !c.is_empty());
    let number = |name: &str| -> Result<Option<f64>, DataError> {
        match cell(name) {
            None => Ok(None),
            Some(c) => match c.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(Some(x)),
                Ok(_) => Err(err.at(ln, format!("column {name}: \"{c}\" is not a finite number; drop the line or give the value"))),
                Err(_) => Err(err.at(ln, format!("column {name}: \"{c}\" is not a number"))),
            },
        }
    };
    let body = cell("body")
        .ok_or_else(|| err.at(ln, "empty body name".into()))?
        .to_string();
    let dof_text =
        cell("dof").ok_or_else(|| err.at(ln, "empty dof; use u1, u2, u3, r1, r2, r3".into()))?;
    let dof = parse_dof(dof_text).ok_or_else(|| {
        err.at(ln, format!("unknown dof \"{dof_text}\"; use u1, u2, u3 (translations) or r1, r2, r3 (rotations), or 0-5"))
    })?;
    let quantity = match cell("quantity") {
        None => QuantityName::Displacement,
        Some(q) => Quantity::parse(q).map(QuantityName::from).ok_or_else(|| {
            err.at(
                ln,
                format!("unknown quantity \"{q}\"; use displacement, velocity or acceleration"),
            )
        })?,
    };
    let reference = cell("reference")
        .filter(|r| *r != "excitation")
        .map(str::to_string);
    let relative = match cell("motion") {
        None | Some("absolute") => false,
        Some("relative") => true,
        Some(other) => {
            return Err(err.at(
                ln,
                format!("column motion: \"{other}\" is neither absolute (transmissibility) nor relative (response − base); leave it empty under a force"),
            ))
        }
    };
    let freq = number("freq_hz")?.ok_or_else(|| err.at(ln, "empty freq_hz".into()))?;
    let amp = number("amplitude")?.ok_or_else(|| err.at(ln, "empty amplitude".into()))?;
    let avg = match cell("averages") {
        None => None,
        Some(c) => Some(c.parse::<u32>().map_err(|_| {
            err.at(
                ln,
                format!("column averages: \"{c}\" is not a whole number"),
            )
        })?),
    };
    let row = CsvRow {
        line: ln,
        freq,
        amp,
        phase: number("phase_rad")?,
        var: number("variance")?,
        coh: number("coherence")?,
        avg,
    };
    Ok(((body, dof, quantity, reference, relative), row))
}

/// The characteristic of one key from its rows: sorted by frequency, distinct frequencies, the
/// optional columns given for every point or none, one number of averages.
fn csv_characteristic(
    (body, dof, quantity, reference, relative): CsvKey,
    mut pts: Vec<CsvRow>,
    hline: usize,
    err: &CsvErr,
) -> Result<Measurement, DataError> {
    pts.sort_by(|a, b| a.freq.total_cmp(&b.freq));
    for w in pts.windows(2) {
        if w[0].freq == w[1].freq {
            return Err(err.at(w[1].line, format!(
                "{body} {}: frequency {} Hz repeats line {}; each characteristic needs distinct frequencies (average or drop the repeat)",
                DOF_NAMES[dof as usize], w[1].freq, w[0].line
            )));
        }
    }
    let all_or_none = |what: &str, has: &dyn Fn(&CsvRow) -> bool| -> Result<bool, DataError> {
        let n = pts.iter().filter(|r| has(r)).count();
        if n != 0 && n != pts.len() {
            let missing = pts
                .iter()
                .find(|r| !has(r))
                .map(|r| r.line)
                .unwrap_or(hline);
            return Err(err.at(missing, format!(
                "{body} {}: column {what} is given for some points of this characteristic but not this one; give it for every point or none",
                DOF_NAMES[dof as usize]
            )));
        }
        Ok(n > 0)
    };
    let has_phase = all_or_none("phase_rad", &|r| r.phase.is_some())?;
    let has_var = all_or_none("variance", &|r| r.var.is_some())?;
    let has_coh = all_or_none("coherence", &|r| r.coh.is_some())?;
    let has_avg = all_or_none("averages", &|r| r.avg.is_some())?;
    let averages = if has_avg {
        let a = pts[0].avg;
        if let Some(r) = pts.iter().find(|r| r.avg != a) {
            return Err(err.at(r.line, format!(
                "{body} {}: averages differ between points of one characteristic ({:?} vs {:?}); one number of averages per characteristic",
                DOF_NAMES[dof as usize], r.avg.unwrap_or(0), a.unwrap_or(0)
            )));
        }
        a
    } else {
        None
    };
    Ok(Measurement {
        body,
        dof,
        quantity,
        freqs_hz: pts.iter().map(|r| r.freq).collect(),
        amplitude: pts.iter().map(|r| r.amp).collect(),
        phase_rad: has_phase.then(|| pts.iter().map(|r| r.phase.unwrap_or(f64::NAN)).collect()),
        variance: has_var.then(|| pts.iter().map(|r| r.var.unwrap_or(f64::NAN)).collect()),
        coherence: has_coh.then(|| pts.iter().map(|r| r.coh.unwrap_or(f64::NAN)).collect()),
        averages,
        at: None,
        reference,
        relative,
    })
}

fn parse_dof(s: &str) -> Option<u8> {
    if let Some(i) = DOF_NAMES.iter().position(|n| *n == s) {
        return Some(i as u8);
    }
    s.parse::<u8>().ok().filter(|d| *d < 6)
}

/// Writes the CSV form (every column of [`CSV_COLUMNS`]; empty cells where a value is absent).
/// `parse_csv(&to_csv(d))` gives `d` back (up to the `source` text).
pub fn to_csv(data: &MeasuredData) -> String {
    let mut s = rfe::csv_text::CsvText::new();
    s.row(CSV_COLUMNS);
    let opt = |v: &Option<Vec<f64>>, k: usize| {
        v.as_ref()
            .map(|v| format!("{:?}", v[k]))
            .unwrap_or_default()
    };
    for m in &data.characteristics {
        for k in 0..m.freqs_hz.len() {
            let dof = DOF_NAMES.get(m.dof as usize).copied().unwrap_or("?");
            s.row([
                m.body.clone(),
                dof.to_string(),
                Quantity::from(m.quantity).as_str().to_string(),
                format!("{:?}", m.freqs_hz[k]),
                format!("{:?}", m.amplitude.get(k).copied().unwrap_or(f64::NAN)),
                opt(&m.phase_rad, k),
                opt(&m.variance, k),
                opt(&m.coherence, k),
                m.averages.map(|a| a.to_string()).unwrap_or_default(),
                m.reference.clone().unwrap_or_default(),
                if m.relative { "relative" } else { "" }.to_string(),
            ]);
        }
    }
    s.finish()
}

/// One validated characteristic, ready for fitting.
#[derive(Debug, Clone, PartialEq)]
pub struct Observed {
    /// The characteristic (body index resolved in the model).
    pub characteristic: Characteristic,
    /// Index among the model's output characteristics.
    pub output: usize,
    /// `"table u1 displacement"`.
    pub label: String,
    /// Frequencies (Hz), strictly increasing.
    pub freqs_hz: Vec<f64>,
    /// Measured amplitudes |z| (SI), ≥ 0.
    pub amplitude: Vec<f64>,
    /// Measured phases (rad), if any.
    pub phase_rad: Option<Vec<f64>>,
    /// Complex variances E|z − z_true|² (SI²), if any.
    pub variance: Option<Vec<f64>>,
    /// Coherence γ² per point, if any.
    pub coherence: Option<Vec<f64>>,
    /// Number of averages, if known.
    pub averages: Option<u32>,
}

/// Measured data validated against a model.
#[derive(Debug, Clone, PartialEq)]
pub struct Observations {
    /// Where the data came from (file name), for messages.
    pub origin: String,
    /// The characteristics, in file order.
    pub characteristics: Vec<Observed>,
}

impl Observations {
    /// Number of measured points over all characteristics.
    pub fn points(&self) -> usize {
        self.characteristics.iter().map(|c| c.freqs_hz.len()).sum()
    }

    /// Every frequency measured on any characteristic (Hz), ascending, each once.
    pub fn lines_hz(&self) -> Vec<f64> {
        let mut freqs: Vec<f64> = self
            .characteristics
            .iter()
            .flat_map(|c| c.freqs_hz.iter().copied())
            .collect();
        freqs.sort_by(f64::total_cmp);
        freqs.dedup();
        freqs
    }

    /// The measured band (Hz): the lowest line (at least 1 mHz, so that log-spaced searches
    /// over it are defined) and the highest (at least 1 % above the lowest).
    pub fn band_hz(&self) -> (f64, f64) {
        let freqs = self.lines_hz();
        let f_lo = freqs
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
            .max(1e-3);
        let f_hi = freqs.iter().copied().fold(0.0, f64::max).max(f_lo * 1.01);
        (f_lo, f_hi)
    }
}

/// Validates measured data against a model: every characteristic must be one of the model's
/// outputs (the body known), appear once, and have equally long, finite arrays with strictly
/// increasing non-negative frequencies, non-negative amplitudes, positive variances, coherences
/// in (0, 1] and at least one average. Errors name `origin`, the characteristic and the point.
pub fn validate(
    data: &MeasuredData,
    model: &Model,
    origin: &str,
) -> Result<Observations, DataError> {
    let mut out = Vec::new();
    if data.characteristics.is_empty() {
        return Err(DataError::Invalid {
            origin: origin.into(),
            item: "$.characteristics".into(),
            message: "no characteristics; the data file must hold at least one".into(),
        });
    }
    for (i, m) in data.characteristics.iter().enumerate() {
        let dof_name = DOF_NAMES.get(m.dof as usize).copied().unwrap_or("?");
        let at = DataItem {
            origin,
            item: format!(
                "$.characteristics[{i}] ({} {dof_name} {})",
                m.body,
                Quantity::from(m.quantity).as_str()
            ),
        };
        let (c, output) = resolve_output(m, model, &at)?;
        if out.iter().any(|o: &Observed| o.characteristic == c) {
            return Err(at.bad("this characteristic appears twice; merge the two entries".into()));
        }
        check_points(m, &at)?;
        if m.averages == Some(0) {
            return Err(at.bad("averages is 0; at least one average".into()));
        }
        out.push(Observed {
            characteristic: c,
            output,
            label: model.characteristic_label(c),
            freqs_hz: m.freqs_hz.clone(),
            amplitude: m.amplitude.clone(),
            phase_rad: m.phase_rad.clone(),
            variance: m.variance.clone(),
            coherence: m.coherence.clone(),
            averages: m.averages,
        });
    }
    Ok(Observations {
        origin: origin.into(),
        characteristics: out,
    })
}

/// `model` with the outputs `data` measure added where it does not declare them already: point
/// outputs (sensors anywhere on a body, named by a measurement map), and a declared output's
/// response to another of the model's references (an FRF matrix's other columns) or relative to
/// a moving base. A principal-axis output must be declared by the model under some reference
/// (see [`validate`]); references the model does not have are left to [`validate`] to report.
pub fn with_measured_outputs(model: &Model, data: &MeasuredData) -> Model {
    let mut out = model.clone();
    for m in &data.characteristics {
        let Some(c) = m.resolve(model) else { continue };
        if usize::from(c.reference) > model.references.len() || out.outputs.contains(&c) {
            continue;
        }
        let declared = model
            .outputs
            .iter()
            .any(|o| (o.body, o.dof, o.quantity, o.at) == (c.body, c.dof, c.quantity, c.at));
        if c.at.is_some() || declared {
            out.outputs.push(c);
        }
    }
    out
}

/// A characteristic of a data file, for errors: the file and a JSON-path-like item.
struct DataItem<'a> {
    origin: &'a str,
    item: String,
}

impl DataItem<'_> {
    fn bad(&self, message: String) -> DataError {
        DataError::Invalid {
            origin: self.origin.into(),
            item: self.item.clone(),
            message,
        }
    }

    fn bad_point(&self, m: &Measurement, k: usize, message: String) -> DataError {
        DataError::Invalid {
            origin: self.origin.into(),
            item: format!(
                "{}, point {k} ({} Hz)",
                self.item,
                m.freqs_hz.get(k).copied().unwrap_or(f64::NAN)
            ),
            message,
        }
    }
}

/// The model characteristic `m` is, and its index among the model's outputs.
fn resolve_output(
    m: &Measurement,
    model: &Model,
    at: &DataItem,
) -> Result<(Characteristic, usize), DataError> {
    let bad = |message| at.bad(message);
    if model.body_index(&m.body).is_none() {
        let known: Vec<&str> = model.bodies.iter().map(|b| b.name.as_str()).collect();
        return Err(bad(format!(
            "unknown body \"{}\"; the model's bodies: {}",
            m.body,
            known.join(", ")
        )));
    }
    let Some(c) = m.resolve(model) else {
        return Err(bad(format!(
            "dof {} is out of range; use 0-5 (u1 u2 u3 r1 r2 r3)",
            m.dof
        )));
    };
    if let Some(name) = &m.reference {
        if model.reference_index(name).is_none() {
            let known: Vec<&str> = model.references.iter().map(|r| r.name.as_str()).collect();
            return Err(bad(format!(
                "reference \"{name}\" is not one of the model's (excitation{}{}); declare it as a [[reference]] of the model or fix the name",
                if known.is_empty() { "" } else { ", " },
                known.join(", ")
            )));
        }
    }
    let base = c.reference > 0
        && matches!(
            model.references[usize::from(c.reference) - 1].excitation,
            rfe::model::Excitation::BaseMotion { .. }
        );
    if c.relative && !base {
        return Err(bad(format!(
            "relative: a motion relative to the base is an output under base motion, and the reference \"{}\" is {}; declare a [[reference]] with base_motion in the model and name it, or drop `relative`",
            model.reference_name(c.reference),
            if c.reference == 0 { "the model's force excitation" } else { "a force" }
        )));
    }
    let Some(output) = model.outputs.iter().position(|o| *o == c) else {
        let outs: Vec<String> = model
            .outputs
            .iter()
            .map(|o| model.characteristic_label(*o))
            .collect();
        return Err(bad(format!(
            "this characteristic is not among the model's outputs ({}); add it as an [[output]] of the model or drop it from the data",
            if outs.is_empty() { "none".to_string() } else { outs.join(", ") }
        )));
    };
    Ok((c, output))
}

/// One value per frequency in every column; frequencies finite, non-negative, increasing;
/// amplitudes finite and ≥ 0; phases finite; variances > 0; coherences in (0, 1].
fn check_points(m: &Measurement, at: &DataItem) -> Result<(), DataError> {
    let bad = |message| at.bad(message);
    let bad_point = |k, message| at.bad_point(m, k, message);
    let n = m.freqs_hz.len();
    if n == 0 {
        return Err(bad("no points".into()));
    }
    let lens: [(&str, Option<usize>); 4] = [
        ("amplitude", Some(m.amplitude.len())),
        ("phase_rad", m.phase_rad.as_ref().map(Vec::len)),
        ("variance", m.variance.as_ref().map(Vec::len)),
        ("coherence", m.coherence.as_ref().map(Vec::len)),
    ];
    for (name, len) in lens {
        if let Some(len) = len {
            if len != n {
                return Err(bad(format!(
                    "{name} has {len} values but freqs_hz has {n}; one value per frequency"
                )));
            }
        }
    }
    for k in 0..n {
        let f = m.freqs_hz[k];
        if !f.is_finite() || f < 0.0 {
            return Err(bad_point(
                k,
                format!("frequency {f} is not a finite, non-negative number"),
            ));
        }
        if k > 0 {
            let prev = m.freqs_hz[k - 1];
            if f == prev {
                return Err(bad_point(
                    k,
                    format!(
                        "frequency {f} Hz repeats point {}; frequencies must be distinct",
                        k - 1
                    ),
                ));
            }
            if f < prev {
                return Err(bad_point(k, format!("frequency {f} Hz is below the previous one ({prev} Hz); frequencies must increase")));
            }
        }
        let a = m.amplitude[k];
        if !a.is_finite() {
            return Err(bad_point(
                k,
                format!("amplitude is {a}; every amplitude must be a finite number"),
            ));
        }
        if a < 0.0 {
            return Err(bad_point(k, format!("amplitude {a} is negative; amplitudes are moduli |z| ≥ 0 (put the sign into phase_rad)")));
        }
        if let Some(p) = &m.phase_rad {
            if !p[k].is_finite() {
                return Err(bad_point(
                    k,
                    format!("phase_rad is {}; must be finite", p[k]),
                ));
            }
        }
        if let Some(v) = &m.variance {
            if !(v[k].is_finite() && v[k] > 0.0) {
                return Err(bad_point(
                    k,
                    format!("variance {} must be a finite number > 0", v[k]),
                ));
            }
        }
        if let Some(g) = &m.coherence {
            if !(g[k] > 0.0 && g[k] <= 1.0) {
                return Err(bad_point(
                    k,
                    format!("coherence {} must lie in (0, 1]", g[k]),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_dof_names_and_indices() {
        assert_eq!(parse_dof("u2"), Some(1));
        assert_eq!(parse_dof("5"), Some(5));
        assert_eq!(parse_dof("6"), None);
        assert_eq!(parse_dof("x"), None);
    }
}
