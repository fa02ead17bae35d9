//! From a session file to measured characteristics: what `ident process`, `ident replay`,
//! `ident nightly` and `ident demo` call after a sweep.
//!
//! [`characteristics`] reads a session MCAP (complete or truncated) and uses nothing but what is
//! recorded in it — the stand's channel map and calibration and the geometry of the bodies the
//! sensors are on (`/stand`), the raw sample blocks (`/daq/block`), the steps' measurement windows
//! (`/sweep/step`), faults and retries. For every completed stepped-sine step it
//!
//! 1. re-fits each channel's amplitude and phase from the raw blocks of the step's window with the
//!    same [`StepEstimator`] the live sweep used (so a replay is bit-identical to the live run, and
//!    each step says whether it matched the live record),
//! 2. forms each accelerometer's FRF (m/s² per N) and converts it to the wanted quantity
//!    (receptance by default: `H / (−ω²)`),
//! 3. fits each body's rigid-body motion at its centre of mass in its principal central axes
//!    ([`process::principal::RigidFit`]; translations when the layout cannot observe rotations),
//!    with the rigidity residual, and
//! 4. scales to the model's nominal excitation into [`identify::MeasuredData`]
//!    ([`process::selection::to_measurement`]), with each point's variance.
//!
//! Steps that cannot be used are listed in [`SessionAnalysis::dropped`] with the reason; nothing
//! is dropped silently. The output is deterministic: the same file gives bit-identical results.
//!
//! ```no_run
//! use acquire::analysis::{characteristics, AnalysisOptions};
//!
//! let a = characteristics(std::path::Path::new("session.mcap"), &AnalysisOptions::default())?;
//! for m in &a.measured.characteristics {
//!     println!("{} dof {}: {} points", m.body, m.dof, m.freqs_hz.len());
//! }
//! for d in &a.dropped {
//!     eprintln!("step {} ({:.1} Hz) not used: {}", d.step, d.frequency_hz, d.reason);
//! }
//! # Ok::<(), acquire::analysis::AnalysisError>(())
//! ```

use std::path::{Path, PathBuf};

use identify::{MeasuredData, Quantity};
use nalgebra::Vector3;
use num_complex::Complex;
use process::principal::{Dofs, RigidFit, Sensor};
use process::selection::{to_measurement, CharacteristicSpec};
use serde::Serialize;
use serde_json::Value;

use crate::session::{self, SessionError, Topic};
use crate::stand::{Geometry, Stand};
use crate::sweep::estimate::StepEstimator;
use crate::sweep::ChannelResult;

type C64 = Complex<f64>;

/// Why a session could not be analysed. Each names the file and says what to do.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnalysisError {
    /// The file could not be read.
    #[error(transparent)]
    Session(#[from] SessionError),
    /// Something the analysis needs is not in the file.
    #[error("{path}: {what}; {fix}")]
    Missing {
        /// Session file.
        path: String,
        /// What is missing.
        what: String,
        /// What to do.
        fix: String,
    },
    /// The recorded data contradict each other (e.g. the channel map).
    #[error("{path}: {detail}")]
    Inconsistent {
        /// Session file.
        path: String,
        /// What does not fit.
        detail: String,
    },
    /// The geometry given in the options could not be used.
    #[error("{path}: geometry: {detail}")]
    Geometry {
        /// Session file.
        path: String,
        /// Why.
        detail: String,
    },
    /// Processing failed (degenerate sensor layout, bad values).
    #[error("{path}: {context}: {source}")]
    Process {
        /// Session file.
        path: String,
        /// Which body or characteristic.
        context: String,
        /// Why.
        source: process::ProcessError,
    },
}

/// How to analyse a session.
#[derive(Debug, Clone)]
pub struct AnalysisOptions {
    /// A model file whose bodies replace the geometry recorded in the session (sessions recorded
    /// before geometry was recorded, or a corrected geometry). Never the truth model.
    pub geometry_model: Option<PathBuf>,
    /// Quantity of the characteristics; `None` (default): the geometry model's declared outputs'
    /// quantity, displacement (receptance) where it declares none.
    pub quantity: Option<Quantity>,
    /// Which DOFs to fit per body (default: six if the layout observes them, else translations).
    pub dofs: Dofs,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        AnalysisOptions {
            geometry_model: None,
            quantity: None,
            dofs: Dofs::Auto,
        }
    }
}

/// One step as recomputed from the raw blocks.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepAnalysis {
    /// Step index in the plan.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// First sample of the measurement window (since START).
    pub first_sample: u64,
    /// Samples in the window.
    pub samples: u64,
    /// Measured force amplitude (N).
    pub force_amplitude_n: f64,
    /// Per channel (stream order): amplitude, phase, FRF (per N), noise, FRF variance.
    pub channels: Vec<ChannelResult>,
    /// Per body: rigidity residual `‖y − A q‖/‖y‖` of the principal-axis fit (0 = rigid).
    pub rigidity: Vec<BodyResidual>,
    /// Stream faults recorded since the previous step (while this step was being measured).
    pub faults: u32,
    /// Measurement windows of this step re-measured after a fault.
    pub retries: u32,
    /// True if the recomputation equals the live estimate recorded in `/sweep/step`, bit for bit.
    pub matches_live: bool,
}

/// A body's rigidity residual at a step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BodyResidual {
    /// Body name.
    pub body: String,
    /// `‖y − A q‖/‖y‖`.
    pub residual: f64,
}

/// A recorded step that is not in the characteristics, and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DroppedStep {
    /// Step index.
    pub step: usize,
    /// Frequency (Hz).
    pub frequency_hz: f64,
    /// Why it was not used.
    pub reason: String,
}

/// A stream fault recorded in the session.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecordedFault {
    /// `gap`, `crc`, `duplicate`, ...
    pub kind: String,
    /// Sequence number, if known.
    pub seq: Option<u64>,
    /// Detail.
    pub detail: String,
}

/// Everything [`characteristics`] found in a session.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionAnalysis {
    /// Session file.
    pub session: String,
    /// Stand name.
    pub stand: String,
    /// Sample rate (Hz).
    pub sample_rate_hz: f64,
    /// Geometry used (recorded, or from [`AnalysisOptions::geometry_model`]).
    pub geometry: Geometry,
    /// The measured characteristics (identification input).
    pub measured: MeasuredData,
    /// Every usable step, in frequency order.
    pub steps: Vec<StepAnalysis>,
    /// Steps not used, with reasons.
    pub dropped: Vec<DroppedStep>,
    /// All stream faults recorded.
    pub faults: Vec<RecordedFault>,
    /// Why the file ended early (`None` if complete).
    pub truncated: Option<String>,
    /// Things the operator should know (e.g. a declared output the sensor layout cannot observe).
    pub notes: Vec<String>,
}

struct ChannelDef {
    name: String,
    force: bool,
    sensitivity: f64,
    body: Option<String>,
    position: [f64; 3],
    direction: [f64; 3],
}

fn vec3(v: &Value) -> Option<[f64; 3]> {
    let a = v.as_array()?;
    if a.len() != 3 {
        return None;
    }
    Some([a[0].as_f64()?, a[1].as_f64()?, a[2].as_f64()?])
}

/// Reads a session and computes its measured characteristics (see the module docs).
pub fn characteristics(
    session_path: &Path,
    opts: &AnalysisOptions,
) -> Result<SessionAnalysis, AnalysisError> {
    let path = session_path.display().to_string();
    let missing = |what: &str, fix: &str| AnalysisError::Missing {
        path: path.clone(),
        what: what.into(),
        fix: fix.into(),
    };
    let inconsistent = |detail: String| AnalysisError::Inconsistent {
        path: path.clone(),
        detail,
    };
    let rep = session::read(session_path)?;

    // ---- stand: channel map, calibration, geometry -----------------------------------------
    let stand_rec = rep
        .records
        .iter()
        .find(|r| r.topic == Topic::Stand.name())
        .ok_or_else(|| {
            missing(
                "no /stand record",
                "the session was not written by a sweep (or was cut before the stand was recorded)",
            )
        })?;
    let sv = &stand_rec.value;
    let stand_name = sv["name"].as_str().unwrap_or("").to_string();
    let mut channels = Vec::new();
    for (i, c) in sv["channels"].as_array().into_iter().flatten().enumerate() {
        let bad = |field: &str| {
            inconsistent(format!(
                "/stand channel {i}: field `{field}` missing or malformed"
            ))
        };
        let name = c["name"].as_str().ok_or_else(|| bad("name"))?.to_string();
        let force = match c["kind"].as_str() {
            Some("force") => true,
            Some("acceleration") => false,
            _ => return Err(bad("kind")),
        };
        let sensitivity = c["sensitivity"]
            .as_f64()
            .filter(|s| s.is_finite() && *s > 0.0)
            .ok_or_else(|| bad("sensitivity"))?;
        channels.push(ChannelDef {
            name,
            force,
            sensitivity,
            body: c["body"].as_str().map(str::to_string),
            position: vec3(&c["position_m"]).ok_or_else(|| bad("position_m"))?,
            direction: vec3(&c["direction"]).ok_or_else(|| bad("direction"))?,
        });
    }
    let force_channel = match channels.iter().filter(|c| c.force).count() {
        1 => channels.iter().position(|c| c.force).unwrap_or(0),
        n => {
            return Err(inconsistent(format!(
                "/stand has {n} force channels; exactly one is needed as the FRFs' reference"
            )))
        }
    };
    let geometry = match &opts.geometry_model {
        Some(model) => {
            let text = sv["text"].as_str().ok_or_else(|| missing("the /stand record has no stand-file text", "re-record the session"))?;
            let file = sv["file"].as_str().unwrap_or("recorded stand");
            let mut st = Stand::parse(text, file).map_err(|e| AnalysisError::Geometry { path: path.clone(), detail: e.to_string() })?;
            st.geometry_model = Some(model.clone());
            st.resolve_geometry(crate::stand::SENSOR_MOUNT_TOLERANCE_M).map_err(|e| AnalysisError::Geometry { path: path.clone(), detail: e.to_string() })?;
            st.geometry.ok_or_else(|| AnalysisError::Geometry { path: path.clone(), detail: "no geometry resolved".into() })?
        }
        None => match sv.get("geometry").filter(|g| !g.is_null()) {
            Some(g) => serde_json::from_value::<Geometry>(g.clone()).map_err(|e| inconsistent(format!("/stand geometry: {e}")))?,
            None => {
                return Err(missing(
                    "the session records no body geometry (its stand file has no [geometry] model)",
                    "add `[geometry] model = \"../models/<identification model>.toml\"` to the stand file for future sessions, or pass the model (`ident process --geometry MODEL`)",
                ))
            }
        },
    };

    // ---- stream ------------------------------------------------------------------------------
    let stream = rep
        .records
        .iter()
        .find(|r| r.topic == Topic::DaqStream.name())
        .ok_or_else(|| {
            missing(
                "no /daq/stream record",
                "the DAQ was never configured in this session; nothing was measured",
            )
        })?;
    let fs = stream.value["sample_rate_hz"]
        .as_f64()
        .filter(|f| *f > 0.0)
        .ok_or_else(|| inconsistent("/daq/stream has no sample rate".into()))?;
    if let Some(names) = stream.value["names"].as_array() {
        let got: Vec<&str> = names.iter().filter_map(Value::as_str).collect();
        let want: Vec<&str> = channels.iter().map(|c| c.name.as_str()).collect();
        if got != want {
            return Err(inconsistent(format!(
                "the DAQ stream's channels {got:?} are not the stand's channel map {want:?}"
            )));
        }
    }

    // ---- steps from the raw blocks -----------------------------------------------------------
    let nch = channels.len();
    let sens: Vec<f64> = channels.iter().map(|c| c.sensitivity).collect();
    let names: Vec<String> = channels.iter().map(|c| c.name.clone()).collect();
    let mut estimator = StepEstimator::new(fs, &sens, force_channel);
    // The current stream run (blocks since the last START): (first_sample, samples × channels).
    let mut run: Vec<(u64, Vec<f32>)> = Vec::new();
    let mut faults = Vec::new();
    let mut faults_since_step = 0u32;
    let mut retries: std::collections::BTreeMap<usize, u32> = Default::default();
    let mut steps: Vec<StepAnalysis> = Vec::new();
    let mut dropped = Vec::new();
    let mut row = vec![0f32; nch];
    for r in &rep.records {
        match r.topic.as_str() {
            t if t == Topic::DaqBlock.name() => {
                let first = r.value["first_sample"]
                    .as_u64()
                    .ok_or_else(|| inconsistent("a /daq/block has no first_sample".into()))?;
                let volts = r.value["volts"]
                    .as_array()
                    .filter(|v| v.len() == nch)
                    .ok_or_else(|| {
                        inconsistent(format!(
                            "/daq/block seq {} does not have the stand's {nch} channels",
                            r.value["seq"]
                        ))
                    })?;
                let len = volts[0].as_array().map(Vec::len).unwrap_or(0);
                let mut data = vec![0f32; len * nch];
                for (c, v) in volts.iter().enumerate() {
                    let v = v.as_array().filter(|v| v.len() == len).ok_or_else(|| {
                        inconsistent(format!(
                            "/daq/block seq {}: channels differ in length",
                            r.value["seq"]
                        ))
                    })?;
                    for (i, x) in v.iter().enumerate() {
                        // Blocks are recorded as f32: the JSON number round-trips exactly.
                        data[i * nch + c] = x.as_f64().unwrap_or(f64::NAN) as f32;
                    }
                }
                if run.last().is_some_and(|(f, _)| first <= *f) {
                    run.clear(); // the stream restarted (a new START)
                }
                run.push((first, data));
            }
            t if t == Topic::DaqFault.name() => {
                faults_since_step += 1;
                faults.push(RecordedFault {
                    kind: r.value["kind"].as_str().unwrap_or("").to_string(),
                    seq: r.value["seq"].as_u64(),
                    detail: r.value["detail"].as_str().unwrap_or("").to_string(),
                });
            }
            t if t == Topic::SweepEvent.name() && r.value["kind"] == "retry" => {
                if let Some(s) = r.value["step"].as_u64() {
                    *retries.entry(s as usize).or_default() += 1;
                }
            }
            t if t == Topic::SweepStep.name() => {
                let v = &r.value;
                let step = v["step"].as_u64().unwrap_or(u64::MAX) as usize;
                let f = v["frequency_hz"].as_f64().unwrap_or(f64::NAN);
                let (Some(first), Some(n)) = (v["first_sample"].as_u64(), v["samples"].as_u64())
                else {
                    dropped.push(DroppedStep {
                        step,
                        frequency_hz: f,
                        reason: "the step record has no measurement window".into(),
                    });
                    continue;
                };
                estimator.clear();
                let mut complete = true;
                let mut k =
                    run.partition_point(|(b0, d)| b0 + (d.len() / nch.max(1)) as u64 <= first);
                let mut s = first;
                while s < first + n {
                    let Some((b0, d)) = run.get(k) else {
                        complete = false;
                        break;
                    };
                    let len = (d.len() / nch) as u64;
                    if s < *b0 || s >= b0 + len {
                        complete = false;
                        break;
                    }
                    let i = (s - b0) as usize;
                    row.copy_from_slice(&d[i * nch..(i + 1) * nch]);
                    estimator.push_row(&row);
                    s += 1;
                    if s >= b0 + len {
                        k += 1;
                    }
                }
                let step_faults = std::mem::take(&mut faults_since_step);
                if !complete {
                    dropped.push(DroppedStep {
                        step,
                        frequency_hz: f,
                        reason: format!("samples {s}.. of its window {first}..{} are not in the file (blocks lost or file truncated)", first + n),
                    });
                    continue;
                }
                let est = match estimator.estimate(f) {
                    Ok(e) => e,
                    Err(e) => {
                        dropped.push(DroppedStep {
                            step,
                            frequency_hz: f,
                            reason: format!("sine fit failed: {e}"),
                        });
                        continue;
                    }
                };
                let results = estimator.channel_results(&est, &names);
                let live: Vec<ChannelResult> =
                    serde_json::from_value(v["channels"].clone()).unwrap_or_default();
                let matches_live = live.len() == results.len()
                    && live.iter().zip(&results).all(|(a, b)| {
                        a.name == b.name
                            && a.frf_re.to_bits() == b.frf_re.to_bits()
                            && a.frf_im.to_bits() == b.frf_im.to_bits()
                            && a.amplitude.to_bits() == b.amplitude.to_bits()
                    });
                steps.push(StepAnalysis {
                    step,
                    frequency_hz: f,
                    first_sample: first,
                    samples: n,
                    force_amplitude_n: est.force.amplitude(),
                    channels: results,
                    rigidity: Vec::new(),
                    faults: step_faults,
                    retries: retries.get(&step).copied().unwrap_or(0),
                    matches_live,
                });
            }
            _ => {}
        }
    }
    // Frequency order; a frequency measured twice keeps its first measurement.
    steps.sort_by(|a, b| {
        a.frequency_hz
            .total_cmp(&b.frequency_hz)
            .then(a.step.cmp(&b.step))
    });
    let mut kept: Vec<StepAnalysis> = Vec::with_capacity(steps.len());
    for s in steps {
        match kept.last() {
            Some(p) if s.frequency_hz <= p.frequency_hz => dropped.push(DroppedStep {
                step: s.step,
                frequency_hz: s.frequency_hz,
                reason: format!(
                    "frequency already measured by step {}; the first measurement is used",
                    p.step
                ),
            }),
            _ => kept.push(s),
        }
    }
    let mut steps = kept;
    dropped.sort_by_key(|d| d.step);
    if steps.is_empty() {
        return Err(missing(
            "no usable stepped-sine step in the session",
            if dropped.is_empty() {
                "run a sweep (`ident sweep`) first"
            } else {
                "see why each step was dropped (ident process prints them)"
            },
        ));
    }

    // ---- principal axes per body -------------------------------------------------------------
    let freqs: Vec<f64> = steps.iter().map(|s| s.frequency_hz).collect();
    let order = |q: Quantity| match q {
        Quantity::Displacement => 0,
        Quantity::Velocity => 1,
        Quantity::Acceleration => 2,
    };
    let mut notes = Vec::new();
    let mut measured = Vec::new();
    for g in &geometry.bodies {
        let idx: Vec<usize> = (0..nch)
            .filter(|&c| !channels[c].force && channels[c].body.as_deref() == Some(g.name.as_str()))
            .collect();
        if idx.is_empty() {
            continue;
        }
        let sensors: Vec<Sensor> = idx
            .iter()
            .map(|&c| Sensor {
                name: channels[c].name.clone(),
                position: Vector3::from(channels[c].position),
                direction: Vector3::from(channels[c].direction),
            })
            .collect();
        let body = g.to_body();
        let process_err = |source| AnalysisError::Process {
            path: path.clone(),
            context: format!("body `{}`", g.name),
            source,
        };
        let fit = RigidFit::new(&body, &sensors, opts.dofs).map_err(process_err)?;
        // Rigid-body fit of the accelerances (m/s² or rad/s² per N); linear, so quantities are
        // converted afterwards.
        let mut q_lines = Vec::with_capacity(steps.len());
        let mut var_lines = Vec::with_capacity(steps.len());
        let mut y = vec![C64::default(); idx.len()];
        let mut yv = vec![0.0; idx.len()];
        for s in steps.iter_mut() {
            for (k, &c) in idx.iter().enumerate() {
                let ch = &s.channels[c];
                y[k] = C64::new(ch.frf_re, ch.frf_im);
                yv[k] = ch.frf_variance;
            }
            let mut q = [C64::default(); 6];
            let residual = fit.fit_line(&y, &mut q).map_err(process_err)?;
            s.rigidity.push(BodyResidual {
                body: g.name.clone(),
                residual,
            });
            q_lines.push(q);
            var_lines.push(fit.variance(&yv).map_err(process_err)?);
        }
        let declared: Vec<&crate::stand::GeometryOutput> = geometry
            .outputs
            .iter()
            .filter(|o| o.body == g.name)
            .collect();
        let wanted: Vec<(u8, Quantity)> = if declared.is_empty() {
            (0..fit.dofs() as u8)
                .map(|d| (d, opts.quantity.unwrap_or(Quantity::Displacement)))
                .collect()
        } else {
            declared
                .iter()
                .map(|o| {
                    (
                        o.dof,
                        opts.quantity
                            .or_else(|| Quantity::parse(&o.quantity))
                            .unwrap_or(Quantity::Displacement),
                    )
                })
                .collect()
        };
        let points: Vec<usize> = (0..freqs.len()).collect();
        for (dof, quantity) in wanted {
            if dof as usize >= fit.dofs() {
                notes.push(format!(
                    "{}: body `{}` dof {dof} is declared as an output but its {} accelerometer(s) only observe {} DOFs; add sensors",
                    geometry.source,
                    g.name,
                    idx.len(),
                    fit.dofs()
                ));
                continue;
            }
            let p = 2 - order(quantity);
            let mut h = Vec::with_capacity(freqs.len());
            let mut var = Vec::with_capacity(freqs.len());
            for (k, f) in freqs.iter().enumerate() {
                // Accelerance → quantity: divide by (jω)^(2 − order).
                let factor =
                    C64::new(1.0, 0.0) / C64::new(0.0, 2.0 * std::f64::consts::PI * f).powi(p);
                h.push(q_lines[k][dof as usize] * factor);
                var.push(var_lines[k][dof as usize] * factor.norm_sqr());
            }
            let spec = CharacteristicSpec {
                body: g.name.clone(),
                dof,
                quantity,
                nominal_force: geometry.nominal_force_n,
            };
            let m = to_measurement(&spec, &freqs, &h, None, Some(&var), None, &points).map_err(
                |source| AnalysisError::Process {
                    path: path.clone(),
                    context: format!("body `{}` dof {dof}", g.name),
                    source,
                },
            )?;
            measured.push(m);
        }
    }
    if measured.is_empty() {
        return Err(inconsistent(format!(
            "no accelerometer is on a body of the geometry ({}); check the channels' `body` against [geometry] model",
            geometry.bodies.iter().map(|b| b.name.as_str()).collect::<Vec<_>>().join(", ")
        )));
    }
    let source = format!(
        "session {path} (stand {stand_name:?}): {} stepped-sine steps, {} dropped; response to the model's excitation ({} N), principal axes from {}",
        steps.len(),
        dropped.len(),
        geometry.nominal_force_n,
        geometry.source
    );
    Ok(SessionAnalysis {
        session: path.clone(),
        stand: stand_name,
        sample_rate_hz: fs,
        geometry,
        measured: MeasuredData {
            source,
            characteristics: measured,
        },
        steps,
        dropped,
        faults,
        truncated: rep.truncated,
        notes,
    })
}
