//! One identification problem as a library call: a [`Request`] (model file, data file, measurement
//! map, line choice, decimation, variables file, start, options) becomes a [`Problem`] — the model
//! with the measured outputs, the validated observations, the variables at their start and the fit
//! options — ready for [`crate::identify()`] and the diagnosis. The command line, the workflows
//! and the tests call this instead of repeating the preparation:
//!
//! ```text
//! model file ─┐
//! data file ──┼─ read (ident JSON/CSV, or UFF58 + map) ─ units to the model's convention
//! map ────────┘   ─ line choice ─ decimation ─ outputs ─ validation ─ band and level checks
//! variables ──── read ─ start (the file's, or moved by the modal pre-fit) ─ fit kind
//! ```
//!
//! What was assumed, converted, dropped or warned about is handed to the caller as [`Note`]s,
//! in the order it happened (so a caller can print them before a later step fails).
//!
//! ```no_run
//! use identify::line_choice::LineChoice;
//! use identify::request::{prepare, DataRequest, Request, Start};
//! use std::path::Path;
//! let lines = LineChoice { band_hz: (Some(20.0), None), ..LineChoice::default() };
//! let req = Request {
//!     model: Path::new("configs/models/textbook-two-mass.toml"),
//!     data: DataRequest {
//!         data: Path::new("run.unv"),
//!         map: Some(Path::new("map.toml")),
//!         lines: &lines,
//!         points: Some(200),
//!     },
//!     vars: Path::new("configs/identification/textbook-two-mass.toml"),
//!     start: Start::Auto,
//!     fit: None,
//!     options: identify::Options::default(),
//! };
//! let problem = prepare(&req, &mut |note| eprintln!("{note}"))?;
//! let id = problem.identify(&mut |_, _| {})?;
//! println!("{}", identify::report::text(&id));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;
use std::path::Path;

use rfe::{MeasuredData, Measurement, Model};

use crate::data::{self, DataError, Observations};
use crate::line_choice::{self, LineChoice, LineChoiceError};
use crate::measurement_map::{self, MapError};
use crate::modal_start::{self, ModalStartError};
use crate::variables::{self, Variables, VarsError};
use crate::{FitKind, Identification, IdentifyError, Options, Progress};

/// Where the measured data come from and which of their lines enter the fit.
#[derive(Debug, Clone, Copy)]
pub struct DataRequest<'a> {
    /// ident's JSON or CSV (a CSV may declare its unit), or a UFF58/58b file (detected by
    /// content), which needs `map`.
    pub data: &'a Path,
    /// The measurement map (TOML) of a UFF file: which node and direction is which body and DOF.
    pub map: Option<&'a Path>,
    /// Band, excluded lines, mains harmonics, coherence.
    pub lines: &'a LineChoice,
    /// Decimate each characteristic to at most this many lines (log-uniform, denser at the
    /// resonance peaks).
    pub points: Option<usize>,
}

/// Where the fit starts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Start {
    /// For data without variances or coherence (the log-amplitude fit), the variables file's
    /// start and the modal pre-fit's both, the better fit kept; otherwise the variables file's.
    #[default]
    Auto,
    /// The variables file's initial values.
    Variables,
    /// Moved by the modal pre-fit to the measured modes ([`crate::modal_start`]).
    Modal,
}

/// An identification to prepare.
#[derive(Debug, Clone, Copy)]
pub struct Request<'a> {
    /// The model file (TOML or resolved JSON).
    pub model: &'a Path,
    /// The measured data.
    pub data: DataRequest<'a>,
    /// The decision variables file (TOML).
    pub vars: &'a Path,
    /// Where the fit starts.
    pub start: Start,
    /// What is fitted; `None`: log-amplitude for data without variances or coherence,
    /// amplitude otherwise ([`FitKind::for_data`]).
    pub fit: Option<FitKind>,
    /// The fit options (`fit` is set from the request's).
    pub options: Options,
}

/// An identification problem, prepared.
#[derive(Debug, Clone)]
pub struct Problem {
    /// The model, with an output for every measured characteristic.
    pub model: Model,
    /// The measured characteristics, validated against it.
    pub observations: Observations,
    /// The decision variables at their start.
    pub variables: Variables,
    /// The fit options, with the fit kind chosen.
    pub options: Options,
}

impl Problem {
    /// The identification of this problem ([`crate::identify()`]); `progress` gets every
    /// iteration of every start.
    pub fn identify(
        &self,
        progress: &mut dyn FnMut(usize, &Progress),
    ) -> Result<Identification, IdentifyError> {
        crate::identify(
            &self.model,
            &self.observations,
            &self.variables,
            &self.options,
            progress,
        )
    }
}

/// What a preparation step did that the user should know.
#[derive(Debug, Clone, PartialEq)]
pub enum Note {
    /// A warning of the model file (an unknown key, a default taken).
    Model(String),
    /// What was taken from the data file, assumed or converted.
    Data(String),
    /// Lines dropped by the line choice or the decimation.
    Lines(String),
    /// The data look off against the model (a level 9.81× or 1000× off).
    Warning(String),
    /// Where the fit starts (the modal pre-fit's pairs and values).
    Start(String),
}

impl fmt::Display for Note {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Note::Model(s) => write!(f, "{s}"),
            Note::Data(s) => write!(f, "data: {s}"),
            Note::Lines(s) => write!(f, "lines: {s}"),
            Note::Warning(s) => write!(f, "warning: {s}"),
            Note::Start(s) => write!(f, "start: {s}"),
        }
    }
}

/// Why a request cannot be prepared. Each names the file (and line or field) and the fix.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// The model file.
    #[error(transparent)]
    Model(#[from] rfe::modelfile::LoadError),
    /// The data file cannot be read.
    #[error("{path}: cannot read the data file")]
    Read {
        /// The data file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A UFF file given without a measurement map.
    #[error("{origin} is a UFF file of {channels} FRF(s): give --map FILE saying which node and direction is which body of the model (docs/identification.md, measurement map)")]
    UffWithoutMap {
        /// The data file.
        origin: String,
        /// Its FRFs.
        channels: usize,
    },
    /// A measurement map given for ident's own JSON/CSV.
    #[error("--map applies to UFF files (node and direction → body); {origin} is ident's JSON/CSV, which names bodies and DOFs itself")]
    MapWithoutUff {
        /// The data file.
        origin: String,
    },
    /// The UFF file, or the decimation of a characteristic.
    #[error(transparent)]
    Process(#[from] process::ProcessError),
    /// The measurement map.
    #[error(transparent)]
    Map(#[from] MapError),
    /// The data (JSON/CSV, units, validation against the model, band).
    #[error(transparent)]
    Data(#[from] DataError),
    /// The line choice.
    #[error(transparent)]
    Lines(#[from] LineChoiceError),
    /// Too few lines asked for by the decimation.
    #[error("--points {0}: give at least 2 lines per characteristic")]
    TooFewPoints(usize),
    /// The variables file.
    #[error(transparent)]
    Variables(#[from] VarsError),
    /// The modal start (`Start::Modal`).
    #[error(transparent)]
    ModalStart(#[from] ModalStartError),
}

/// Prepares the identification `req` asks for (see the module docs); `note` receives what was
/// assumed, converted, dropped or warned about, as it happens.
pub fn prepare(req: &Request<'_>, note: &mut dyn FnMut(Note)) -> Result<Problem, RequestError> {
    let loaded = rfe::modelfile::load(req.model)?;
    for w in &loaded.warnings {
        note(Note::Model(w.to_string()));
    }
    let (model, observations) = observations(&req.data, &loaded.model, note)?;
    let variables = variables::load(req.vars, &model)?;
    let fit = req
        .fit
        .unwrap_or_else(|| FitKind::for_data(&observations, req.options.noise));
    let options = Options { fit, ..req.options };
    let variables = start(req.start, &model, &observations, variables, fit, note)?;
    Ok(Problem {
        model,
        observations,
        variables,
        options,
    })
}

/// The measured data of `req` in `model`'s convention, their lines chosen, validated against
/// `model` extended by an output per measured characteristic (returned with them), with the
/// band checked (an error when data and model do not overlap) and the level (a warning).
pub fn observations(
    req: &DataRequest<'_>,
    model: &Model,
    note: &mut dyn FnMut(Note),
) -> Result<(Model, Observations), RequestError> {
    let measured = load(req.data, req.map, model)?;
    // What was taken from the file, assumed or converted; the plain statement that ident's own
    // JSON/CSV is SI (its documented convention) stays in `source` only.
    for n in measured.source.split("; ").skip(1) {
        if !n.starts_with("units: ") {
            note(Note::Data(n.to_string()));
        }
    }
    let measured = choose_lines(&measured, req.lines, req.points, req.data, note)?;
    let model = data::with_measured_outputs(model, &measured);
    let obs = data::validate(&measured, &model, &req.data.display().to_string())?;
    for level in crate::plausibility::check(&model, &obs)? {
        if let Some(w) = level.warning {
            note(Note::Warning(w));
        }
    }
    Ok((model, obs))
}

/// Loads `path` in the model's convention: a UFF file through the measurement map `map`, else
/// ident's JSON/CSV.
pub fn load(path: &Path, map: Option<&Path>, model: &Model) -> Result<MeasuredData, RequestError> {
    let origin = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| RequestError::Read {
        path: origin.clone(),
        source,
    })?;
    if !process::uff::looks_like_uff(&bytes) {
        if map.is_some() {
            return Err(RequestError::MapWithoutUff { origin });
        }
        return Ok(data::load_for_model(path, model)?);
    }
    let file = process::uff::parse_file(&bytes, &origin)?;
    let (channels, notes) = process::uff::measured_channels(&file, &origin)?;
    let Some(map) = map else {
        return Err(RequestError::UffWithoutMap {
            origin,
            channels: channels.len(),
        });
    };
    let map = measurement_map::load(map, model)?;
    let mut m = map.apply(&channels, &origin, model)?;
    for n in notes {
        m.source.push_str("; ");
        m.source.push_str(&n);
    }
    Ok(m)
}

/// Keeps the lines `choice` keeps and, with `points`, decimates each characteristic to at most
/// that many (log-uniform plus resonance peaks, `process::selection`); what was dropped is a
/// [`Note::Lines`] per characteristic.
pub fn choose_lines(
    measured: &MeasuredData,
    choice: &LineChoice,
    points: Option<usize>,
    path: &Path,
    note: &mut dyn FnMut(Note),
) -> Result<MeasuredData, RequestError> {
    let origin = path.display().to_string();
    let mut out = measured.clone();
    if !choice.is_all() {
        let (chosen, accounts) = choice.apply(measured, &origin)?;
        for a in accounts {
            note(Note::Lines(format!(
                "{} ({})",
                a.describe(),
                choice.describe()
            )));
        }
        out = chosen;
    }
    if let Some(n) = points {
        if n < 2 {
            return Err(RequestError::TooFewPoints(n));
        }
        for m in &mut out.characteristics {
            decimate(m, n, &origin, note)?;
        }
    }
    Ok(out)
}

/// Decimates one characteristic to at most `n` lines (`process::selection::select_points`).
fn decimate(
    m: &mut Measurement,
    n: usize,
    origin: &str,
    note: &mut dyn FnMut(Note),
) -> Result<(), RequestError> {
    let before = m.freqs_hz.len();
    if before <= n {
        return Ok(());
    }
    let config = process::selection::SelectionConfig {
        count: n,
        min_coherence: 0.0,
        ..Default::default()
    };
    let label = format!("{origin}: {}", m.label());
    let chosen =
        process::selection::select_points(&label, &m.freqs_hz, &m.amplitude, None, &config)?;
    let mut keep = vec![false; before];
    for k in chosen {
        keep[k] = true;
    }
    line_choice::retain(m, &keep);
    note(Note::Lines(format!(
        "{}: decimated from {before} to {} lines (log-uniform, denser at the resonance peaks)",
        m.label(),
        m.freqs_hz.len()
    )));
    Ok(())
}

/// The variables with the start `how` asks for. `Auto`, for data without variances or coherence
/// (`fit` log-amplitude: vendor files, a first model): the modal pre-fit's start is added as a
/// second start (the better fit is kept), or, when the data allow no modal extraction, the
/// variables file's start alone, saying why.
fn start(
    how: Start,
    model: &Model,
    obs: &Observations,
    vars: Variables,
    fit: FitKind,
    note: &mut dyn FnMut(Note),
) -> Result<Variables, RequestError> {
    let mut say = |s: String| note(Note::Start(s));
    match how {
        Start::Variables => Ok(vars),
        Start::Modal => Ok(modal_start::modal_start(model, obs, &vars, &mut say)?),
        Start::Auto if fit != FitKind::LogAmplitude => Ok(vars),
        Start::Auto => match modal_start::modal_start(model, obs, &vars, &mut say) {
            Ok(modal) => {
                say("auto: from the variables file's values and from the modal pre-fit's; the better fit is kept (--start model or modal for one)".into());
                let mut vars = vars;
                vars.extra_starts.push(modal.initial());
                Ok(vars)
            }
            Err(e) => {
                say(format!(
                    "auto: no modal pre-fit ({}); from the variables file's values",
                    chain(&e)
                ));
                Ok(vars)
            }
        },
    }
}

/// An error with its causes, `: `-separated (as `{:#}` prints an error chain).
fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cause = c.source();
    }
    s
}
