//! From `identify`'s results to a [`Report`]: model curves per stage at the measured lines and on
//! a dense log grid across the band (with the model's resonances on it), the natural frequencies
//! in the band, standardized residuals, the parameter table and the sensitivity map.

use identify::data::{Observations, Observed};
use identify::{report as table, Identification};
use rfe::{frf, modes, sensitivity, Model, Quantity};

use crate::document::*;
use crate::ReportError;

/// Relative σ used for standardized residuals when the data carry neither variances nor
/// coherence (the identification's own relative-error default).
pub const RELATIVE_SIGMA: f64 = 0.01;

/// Log-spaced lines of the dense model curves across the measured band (the measured lines and
/// the model's resonances are added to them).
pub const DENSE_LINES: usize = 400;

/// Everything a report is built from.
pub struct Inputs<'a> {
    /// Headline.
    pub title: String,
    /// UTC time stamp (ISO 8601); empty = now.
    pub created_utc: String,
    /// Provenance.
    pub source: Source,
    /// The validated measurement.
    pub observations: &'a Observations,
    /// The identification.
    pub identification: &'a Identification,
    /// The diagnosis section and the final (diagnosed and refitted) model.
    pub diagnosis: Option<(Diagnosis, &'a Model)>,
    /// Parameter history, when there is one (the comparison with earlier runs).
    pub drift: Option<Drift>,
    /// Compute the sensitivity map (one FRF solve with derivatives).
    pub sensitivity: bool,
    /// Messages for the status block (warnings, lost data).
    pub messages: Vec<String>,
}

impl<'a> Inputs<'a> {
    /// Inputs with defaults: now, no diagnosis, no drift, sensitivity on.
    pub fn new(
        title: &str,
        observations: &'a Observations,
        identification: &'a Identification,
    ) -> Inputs<'a> {
        Inputs {
            title: title.into(),
            created_utc: String::new(),
            source: Source {
                software: env!("CARGO_PKG_VERSION").into(),
                ..Source::default()
            },
            observations,
            identification,
            diagnosis: None,
            drift: None,
            sensitivity: true,
            messages: Vec::new(),
        }
    }
}

/// Current UTC time as `YYYY-MM-DDTHH:MM:SSZ` (whole seconds).
pub fn now_utc() -> String {
    utc_from_unix(jiff::Timestamp::now().as_second())
}

/// `YYYY-MM-DDTHH:MM:SSZ` of a Unix time (s); times jiff cannot represent (beyond the years
/// -9999..9999) print as the raw number of seconds.
pub fn utc_from_unix(secs: i64) -> String {
    jiff::Timestamp::from_second(secs)
        .map(|t| t.to_string())
        .unwrap_or_else(|_| format!("{secs} s after 1970-01-01T00:00:00Z"))
}

fn unit_of(dof: u8, q: Quantity) -> String {
    let base = if dof < 3 { "m" } else { "rad" };
    match q {
        Quantity::Displacement => base.into(),
        Quantity::Velocity => format!("{base}/s"),
        Quantity::Acceleration => format!("{base}/s2"),
    }
}

/// σ of each measured amplitude and where it came from.
fn sigmas(c: &Observed) -> (Vec<f64>, &'static str) {
    if let Some(v) = &c.variance {
        // Complex variance E|z − z_true|² = 2σ² (σ per real component, = σ of the amplitude).
        return (v.iter().map(|v| (v / 2.0).sqrt()).collect(), "variance");
    }
    if let (Some(g), Some(n)) = (&c.coherence, c.averages) {
        let n = f64::from(n.max(1));
        return (
            g.iter()
                .zip(&c.amplitude)
                .map(|(g, a)| ((1.0 - g) / (2.0 * n * g)).sqrt() * a)
                .collect(),
            "coherence",
        );
    }
    (
        c.amplitude.iter().map(|a| RELATIVE_SIGMA * a).collect(),
        "relative",
    )
}

/// The sensor gain of characteristic `c` at values `x` (1 without a gain variable): the model
/// curve the fit compares with the data is the model's output times it.
fn gain_of(id: &Identification, c: &Observed, x: &[f64]) -> f64 {
    match id
        .variables
        .gain(c.characteristic.body, c.characteristic.dof)
    {
        Some((v, ratio)) => x.get(v).map_or(1.0, |x| ratio * x),
        None => 1.0,
    }
}

fn stage_curve(
    stage: &str,
    (model, gain): (&Model, f64),
    c: &Observed,
    sigma: &[f64],
) -> Result<StageCurve, ReportError> {
    let r = frf::response(model, &c.freqs_hz, &[], frf::Method::Auto).map_err(|source| {
        ReportError::Model {
            stage: stage.into(),
            source,
        }
    })?;
    let q: Vec<f64> = r.output(c.output).iter().map(|v| v.norm() * gain).collect();
    let mut s2 = 0.0;
    let mut n = 0usize;
    let mut db2 = 0.0;
    let mut ndb = 0usize;
    let residual = c
        .amplitude
        .iter()
        .zip(&q)
        .zip(sigma)
        .map(|((z, q), s)| {
            if *z > 0.0 {
                s2 += ((q - z) / z).powi(2);
                n += 1;
            }
            if *z > 0.0 && *q > 0.0 {
                db2 += (20.0 * (q / z).log10()).powi(2);
                ndb += 1;
            }
            if *s > 0.0 {
                (z - q) / s
            } else {
                0.0
            }
        })
        .map(finite)
        .collect();
    Ok(StageCurve {
        stage: stage.into(),
        amplitude: q.into_iter().map(finite).collect(),
        standardized_residual: residual,
        rms_relative_error: finite(if n > 0 { (s2 / n as f64).sqrt() } else { 0.0 }),
        rms_db_error: finite(if ndb > 0 {
            (db2 / ndb as f64).sqrt()
        } else {
            0.0
        }),
        dense: None,
    })
}

/// The band of the measured lines over every characteristic (Hz): the lowest positive and the
/// highest line; `None` without a positive line.
pub fn measured_band(obs: &Observations) -> Option<(f64, f64)> {
    let lines = || {
        obs.characteristics
            .iter()
            .flat_map(|c| c.freqs_hz.iter().copied())
            .filter(|f| f.is_finite() && *f > 0.0)
    };
    let lo = lines().min_by(f64::total_cmp)?;
    let hi = lines().max_by(f64::total_cmp)?;
    Some((lo, hi))
}

/// The modes of `model` (`rfe::modes::complex`, with their loss factors) whose natural
/// frequency lies in `band` (Hz), numbered as `ident modes` numbers them.
pub fn modes_in_band(
    model: &Model,
    (lo, hi): (f64, f64),
) -> Result<Vec<NaturalMode>, frf::SolveError> {
    Ok(modes::complex(model)?
        .into_iter()
        .enumerate()
        .filter(|(_, m)| m.freq_hz >= lo && m.freq_hz <= hi)
        .map(|(i, m)| NaturalMode {
            number: i + 1,
            freq_hz: m.freq_hz,
            loss_factor: finite(m.loss_factor),
        })
        .collect())
}

/// The dense frequency grid (Hz, strictly increasing) of a model curve over `band`: `lines`
/// log-spaced lines from end to end, every `measured` line inside the band, and each mode's
/// natural frequency with the points where a single hysteretic mode's response falls to 1/√2
/// and to 1/√(5/4) of its peak (`f_n √(1 ± η)`, `f_n √(1 ± η/2)`), so no peak is cut between
/// grid lines.
pub fn dense_grid(
    (lo, hi): (f64, f64),
    lines: usize,
    measured: &[f64],
    modes: &[NaturalMode],
) -> Vec<f64> {
    let mut grid: Vec<f64> = Vec::with_capacity(lines + measured.len() + 5 * modes.len());
    if lo > 0.0 && hi > lo && lines >= 2 {
        let ratio = (hi / lo).ln();
        grid.extend((0..lines).map(|i| lo * (ratio * i as f64 / (lines - 1) as f64).exp()));
        // The end points exactly.
        grid[0] = lo;
        grid[lines - 1] = hi;
    } else if lo > 0.0 {
        grid.push(lo);
        grid.push(hi);
    }
    grid.extend(measured.iter().copied());
    for m in modes {
        let eta = m.loss_factor.max(0.0);
        grid.push(m.freq_hz);
        for s in [-1.0, -0.5, 0.5, 1.0] {
            let x = 1.0 + s * eta;
            if x > 0.0 {
                grid.push(m.freq_hz * x.sqrt());
            }
        }
    }
    grid.retain(|f| f.is_finite() && *f > 0.0 && *f >= lo && *f <= hi);
    grid.sort_by(f64::total_cmp);
    grid.dedup_by(|b, a| (*b - *a).abs() <= 1e-12 * a.abs());
    grid
}

/// One stage's model on its dense grid over `band`: the grid, the response of every output on
/// it, and the model's modes in the band.
struct DenseStage {
    grid: Vec<f64>,
    response: frf::Response,
    modes: Vec<NaturalMode>,
}

fn dense_stage(
    stage: &str,
    model: &Model,
    obs: &Observations,
    band: (f64, f64),
) -> Result<DenseStage, ReportError> {
    let err = |source| ReportError::Model {
        stage: stage.into(),
        source,
    };
    let modes = modes_in_band(model, band).map_err(err)?;
    let measured: Vec<f64> = obs
        .characteristics
        .iter()
        .flat_map(|c| c.freqs_hz.iter().copied())
        .collect();
    let grid = dense_grid(band, DENSE_LINES, &measured, &modes);
    let response = frf::response(model, &grid, &[], frf::Method::Auto).map_err(err)?;
    Ok(DenseStage {
        grid,
        response,
        modes,
    })
}

/// The part of a stage's dense curve inside characteristic `c`'s own band.
fn dense_curve(d: &DenseStage, c: &Observed, gain: f64) -> DenseCurve {
    let (lo, hi) = (
        c.freqs_hz.first().copied().unwrap_or(0.0),
        c.freqs_hz.last().copied().unwrap_or(0.0),
    );
    let values = d.response.output(c.output);
    let inside: Vec<usize> = (0..d.grid.len())
        .filter(|&k| d.grid[k] >= lo && d.grid[k] <= hi)
        .collect();
    DenseCurve {
        freqs_hz: inside.iter().map(|&k| d.grid[k]).collect(),
        amplitude: inside
            .iter()
            .map(|&k| finite(values[k].norm() * gain))
            .collect(),
        phase_rad: c
            .phase_rad
            .as_ref()
            .map(|_| inside.iter().map(|&k| finite(values[k].arg())).collect()),
    }
}

/// JSON has no infinities: clamp them (a report must still be written when a model explodes).
fn finite(x: f64) -> f64 {
    if x.is_finite() {
        x
    } else if x.is_nan() {
        0.0
    } else {
        x.signum() * f64::MAX
    }
}

fn opt(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

/// The variables at the diagnosis' final fit (empty when it added nothing), in report units, the
/// first fit's value as `initial`.
fn final_parameters(d: &diagnose::Diagnosis, id: &Identification) -> Vec<Parameter> {
    if d.accepted.is_empty() {
        return Vec::new();
    }
    table::rows(id)
        .into_iter()
        .zip(&id.variables.vars)
        .enumerate()
        .map(|(i, (r, v))| {
            let f = v.unit.factor;
            let x = d.estimate[i];
            let se = d.std_error.get(i).copied().unwrap_or(f64::NAN);
            let tol = 1e-9 * v.scale;
            let at_bound = if x <= v.lower + tol {
                Some("lower".to_string())
            } else if x >= v.upper - tol {
                Some("upper".to_string())
            } else {
                None
            };
            Parameter {
                initial: finite(r.identified),
                identified: finite(x / f),
                std_error: opt(se / f),
                variability: if x != 0.0 { opt(se / x.abs()) } else { None },
                at_bound,
                ..r
            }
        })
        .collect()
}

/// The identification summary and table.
pub fn summary(id: &Identification) -> IdentificationSummary {
    let n = id.variables.len();
    let c = &id.uncertainty.correlation;
    IdentificationSummary {
        optimizer: id.optimizer.as_str().into(),
        converged: id.stop.converged(),
        stop: id.stop.describe(),
        iterations: id.iterations,
        observations: id.observations,
        noise: id.noise.describe(),
        criterion_initial: finite(id.criterion_initial),
        criterion: finite(id.criterion),
        reduced_chi2: finite(id.uncertainty.reduced_chi2),
        parameters: table::rows(id)
            .into_iter()
            .map(|r| Parameter {
                initial: finite(r.initial),
                identified: finite(r.identified),
                std_error: r.std_error.and_then(opt),
                variability: r.variability.and_then(opt),
                ..r
            })
            .collect(),
        correlation: (0..n)
            .map(|a| (0..n).map(|b| opt(c[(a, b)])).collect())
            .collect(),
        weak_directions: id
            .uncertainty
            .weak
            .iter()
            .map(|d| WeakDirection {
                combination: d.combination(),
                relative_std: opt(d.relative_std),
            })
            .collect(),
    }
}

/// The relative band sensitivity of the measured characteristics to the identified parameters,
/// over the measured band.
pub fn sensitivity_map(
    model: &Model,
    id: &Identification,
    obs: &Observations,
) -> Result<SensitivityMap, ReportError> {
    let freqs = obs.lines_hz();
    let params = id.variables.model_params();
    let (_, relative) =
        sensitivity::band_mi(model, &freqs, &params, frf::Method::Auto).map_err(|source| {
            ReportError::Model {
                stage: "identified".into(),
                source,
            }
        })?;
    let outputs = model.outputs.len();
    let label = |p: &rfe::Param| match p {
        rfe::Param::Sde(r) => format!("SDE {} {}", model.sdes[r.sde].name, r.name.as_str()),
        other => model.label(*other),
    };
    Ok(SensitivityMap {
        band_hz: [
            freqs.first().copied().unwrap_or(0.0),
            freqs.last().copied().unwrap_or(0.0),
        ],
        parameters: params.iter().map(label).collect(),
        characteristics: obs
            .characteristics
            .iter()
            .map(|c| c.label.clone())
            .collect(),
        relative: (0..params.len())
            .map(|p| {
                obs.characteristics
                    .iter()
                    .map(|c| finite(relative[p * outputs + c.output]))
                    .collect()
            })
            .collect(),
    })
}

/// The diagnosis section from `diagnose::diagnose`'s result: every round's ranked candidates
/// (strongest first), the accepted ones with their principal parameter in report units, the fit
/// before and after, and what was not tried. `base` names the identified model.
pub fn diagnosis(d: &diagnose::Diagnosis, base: &str, id: &Identification) -> Diagnosis {
    let mut candidates = Vec::new();
    let removed_in = |effect: &str| {
        d.rounds
            .iter()
            .position(|r| r.removed.iter().any(|x| x.effect == effect))
    };
    for (i, round) in d.rounds.iter().enumerate() {
        let accepted = round.accepted.and_then(|k| round.refits.get(k));
        for c in &round.ranked {
            // The accepted refit stands for its family: the leader, or a member refitted in its
            // place (see `diagnose`'s family refits).
            let refit = accepted.filter(|a| {
                a.effect == c.effect
                    || a.equivalent.iter().any(|e| e.describe() == c.effect)
                    || a.family.contains(&c.effect)
            });
            let effect = refit.map_or(&c.effect, |a| &a.effect);
            // Values at the final fit; none for an effect a later round removed.
            // An accepted mass whose position was then fitted is in the final model as placed.
            let final_effect = refit.map(|a| {
                round
                    .placed
                    .as_ref()
                    .map_or(a.effect.as_str(), |p| p.effect.as_str())
            });
            let final_refit = final_effect.and_then(|e| d.accepted.iter().find(|f| f.effect == e));
            let principal = final_refit
                .and_then(|a| a.params.first())
                .map(|p| p.display());
            candidates.push(Candidate {
                round: i + 1,
                name: c.kind.clone(),
                location: match removed_in(effect).filter(|_| refit.is_some()) {
                    Some(k) => format!(
                        "{effect} (removed in round {}: not needed once later effects were added)",
                        k + 1
                    ),
                    None => effect.clone(),
                },
                statistic: finite(c.statistic),
                p_value: c.p_value.clamp(0.0, 1.0),
                accepted: refit.is_some(),
                estimate: principal.map(|(v, _, _)| finite(v)),
                std_error: principal.map(|(_, s, _)| finite(s)),
                unit: principal.map(|(_, _, u)| u.to_string()).unwrap_or_default(),
                rms_db_before: refit.map(|a| finite(a.rms_db_before)),
                rms_db_after: refit.map(|a| finite(a.rms_db_after)),
            });
        }
    }
    let fit = |r: &diagnose::residuals::ResidualAnalysis| FitQuality {
        criterion: finite(r.criterion),
        chi2_p_value: r.chi2_p.map(finite),
        reduced_chi2: finite(r.reduced_chi2),
        rms_relative_error: r
            .characteristics
            .iter()
            .map(|c| LabelledValue {
                label: c.label.clone(),
                value: finite(c.rms_relative),
            })
            .collect(),
        rms_db_error: r
            .characteristics
            .iter()
            .map(|c| LabelledValue {
                label: c.label.clone(),
                value: finite(c.rms_db),
            })
            .collect(),
    };
    let added: Vec<String> = d
        .accepted
        .iter()
        .map(|a| {
            format!(
                "{} ({})",
                a.effect,
                a.params
                    .iter()
                    .map(diagnose::ParamEstimate::describe)
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
        .collect();
    let look_alikes: Vec<String> = d
        .accepted
        .iter()
        .filter(|a| !a.equivalent.is_empty())
        .map(|a| {
            let alike: Vec<String> = a.equivalent.iter().map(|e| e.describe()).collect();
            format!("{} ≡ {}", a.effect, alike.join("; "))
        })
        .collect();
    let final_model = if added.is_empty() {
        format!("{base} (no effect added)")
    } else {
        format!("{base} + {}", added.join(" + "))
    };
    Diagnosis {
        candidates,
        before: fit(&d.before),
        after: fit(&d.after),
        final_model,
        look_alikes,
        final_parameters: final_parameters(d, id),
        final_correlation: if d.accepted.is_empty() {
            Vec::new()
        } else {
            d.correlation
                .iter()
                .map(|row| row.iter().map(|&r| opt(r)).collect())
                .collect()
        },
        explained: d.after.explained,
        verdict: match &d.outside_library {
            Some(v) => format!("{} {v}", d.after.verdict),
            None => d.after.verdict.clone(),
        },
        not_tried: d
            .not_tried
            .iter()
            .map(|n| NotTried {
                effect: n.effect.clone(),
                reason: n.reason.clone(),
            })
            .collect(),
    }
}

/// Builds the report.
pub fn build(inputs: Inputs<'_>) -> Result<Report, ReportError> {
    let id = inputs.identification;
    let mut initial = id.model.clone();
    id.variables.apply(&mut initial, &id.initial);
    let mut stages: Vec<(&str, &Model)> = vec![("initial", &initial), ("identified", &id.model)];
    // Each stage's values, for the sensor gains (not part of the model).
    let mut values: Vec<Vec<f64>> = vec![id.initial.clone(), id.estimate.clone()];
    if let Some((d, m)) = &inputs.diagnosis {
        stages.push(("diagnosed", m));
        values.push(if d.final_parameters.len() == id.variables.len() {
            d.final_parameters
                .iter()
                .zip(&id.variables.vars)
                .map(|(p, v)| p.identified * v.unit.factor)
                .collect()
        } else {
            id.estimate.clone()
        });
    }
    // The first fit and the final model on dense grids (the initial model only at the lines).
    let band = measured_band(inputs.observations);
    let dense: Vec<Option<DenseStage>> = stages
        .iter()
        .map(|(s, m)| match band {
            Some(b) if *s != "initial" => dense_stage(s, m, inputs.observations, b).map(Some),
            _ => Ok(None),
        })
        .collect::<Result<_, _>>()?;
    let mut characteristics = Vec::new();
    for c in &inputs.observations.characteristics {
        let (sigma, kind) = sigmas(c);
        let curves = stages
            .iter()
            .zip(&dense)
            .zip(&values)
            .map(|(((s, m), d), x)| {
                let gain = gain_of(id, c, x);
                let mut curve = stage_curve(s, (m, gain), c, &sigma)?;
                curve.dense = d.as_ref().map(|d| dense_curve(d, c, gain));
                Ok(curve)
            })
            .collect::<Result<Vec<_>, ReportError>>()?;
        characteristics.push(CharacteristicReport {
            label: c.label.clone(),
            body: id
                .model
                .bodies
                .get(c.characteristic.body)
                .map(|b| b.name.clone())
                .unwrap_or_default(),
            dof: c.characteristic.dof,
            quantity: c.characteristic.quantity.as_str().into(),
            unit: unit_of(c.characteristic.dof, c.characteristic.quantity),
            freqs_hz: c.freqs_hz.clone(),
            measured: c.amplitude.clone(),
            sigma: sigma.into_iter().map(finite).collect(),
            sigma_kind: kind.into(),
            measured_phase_rad: c.phase_rad.clone(),
            stages: curves,
        });
    }
    let sensitivity = if inputs.sensitivity {
        let final_model = inputs
            .diagnosis
            .as_ref()
            .map(|(_, m)| *m)
            .unwrap_or(&id.model);
        Some(sensitivity_map(final_model, id, inputs.observations)?)
    } else {
        None
    };
    // The final model as a drawing, its accepted effects marked against the identified model.
    let picture = {
        let final_model = inputs.diagnosis.as_ref().map_or(&id.model, |(_, m)| *m);
        Some(crate::picture::describe(
            final_model,
            &id.model,
            band.map_or([0.0, 0.0], |(lo, hi)| [lo, hi]),
        )?)
    };
    let mut messages = inputs.messages;
    // The misfit headline first, unless a diagnosis went on to add effects (its verdict then
    // speaks for the final model).
    let diagnosed = inputs
        .diagnosis
        .as_ref()
        .is_some_and(|(d, _)| !d.final_parameters.is_empty());
    if let Some(m) = identify::misfit::misfit(id).filter(|_| !diagnosed) {
        messages.insert(0, m.message);
    }
    if !id.stop.converged() {
        messages.push(format!(
            "the identification did not converge: {}",
            id.stop.describe()
        ));
    }
    Ok(Report {
        schema: SCHEMA.into(),
        title: inputs.title,
        created_utc: if inputs.created_utc.is_empty() {
            now_utc()
        } else {
            inputs.created_utc
        },
        source: inputs.source,
        status: Status {
            outcome: Outcome::Ok,
            messages,
        },
        characteristics,
        identification: summary(id),
        diagnosis: inputs.diagnosis.map(|(d, _)| d),
        sensitivity,
        picture,
        drift: None,
        stability: None,
        natural_frequencies: stages
            .iter()
            .zip(dense)
            .filter_map(|((s, _), d)| {
                Some(StageModes {
                    stage: (*s).into(),
                    band_hz: band.map(|(lo, hi)| [lo, hi])?,
                    modes: d?.modes,
                })
            })
            .collect(),
    })
    .map(|mut r| {
        if let Some(d) = inputs.drift {
            crate::drift::attach(&mut r, d);
        }
        r
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_grid_is_log_spaced_across_the_band_with_lines_and_resonances() {
        let measured = [20.0, 31.7, 55.5, 400.0, 401.0, 10.0];
        let modes = [NaturalMode {
            number: 7,
            freq_hz: 47.3,
            loss_factor: 0.1,
        }];
        let g = dense_grid((20.0, 400.0), 400, &measured, &modes);
        assert_eq!(g.first(), Some(&20.0));
        assert_eq!(g.last(), Some(&400.0));
        assert!(g.windows(2).all(|w| w[1] > w[0]), "strictly increasing");
        // 400 log lines + 31.7, 55.5 + the mode and its four neighbours (20 and 400 are grid ends;
        // lines outside the band are left out).
        assert_eq!(g.len(), 400 + 2 + 5, "{}", g.len());
        for f in [
            31.7,
            55.5,
            47.3,
            47.3 * 1.1f64.sqrt(),
            47.3 * 0.95f64.sqrt(),
        ] {
            assert!(
                g.iter().any(|x| (x - f).abs() < 1e-12 * f),
                "{f} on the grid"
            );
        }
        // Log-spaced: the ratio between neighbours never exceeds the log step (20^(1/399)).
        let step = (400.0f64 / 20.0).powf(1.0 / 399.0);
        let worst = g.windows(2).map(|w| w[1] / w[0]).fold(0.0, f64::max);
        assert!(worst <= step * (1.0 + 1e-12), "{worst} vs {step}");
        // A degenerate band gives its one line.
        assert_eq!(dense_grid((50.0, 50.0), 400, &[50.0], &[]), vec![50.0]);
        assert!(dense_grid((0.0, 0.0), 400, &[0.0], &[]).is_empty());
    }

    #[test]
    fn modes_in_band_number_like_ident_modes() {
        let m = rfe::textbook::two_in_series(400.0, 120.0, 2.0e7, 5.0e6, 0.5);
        let all = modes::complex(&m).unwrap();
        let elastic: Vec<f64> = all.iter().map(|x| x.freq_hz).filter(|f| *f > 1.0).collect();
        assert!(elastic.len() >= 2, "{elastic:?}");
        let (lo, hi) = (elastic[0] * 0.99, elastic[1] * 1.01);
        let inside = modes_in_band(&m, (lo, hi)).unwrap();
        let expected = all
            .iter()
            .filter(|x| x.freq_hz >= lo && x.freq_hz <= hi)
            .count();
        assert!(inside.len() >= 2 && inside.len() == expected, "{inside:?}");
        assert!(inside.windows(2).all(|w| w[1].number > w[0].number));
        for x in &inside {
            assert!((all[x.number - 1].freq_hz - x.freq_hz).abs() < 1e-12);
            assert!(
                x.loss_factor > 0.0,
                "hysteretic damping gives a loss factor"
            );
        }
        assert!(modes_in_band(&m, (elastic[0] * 0.5, elastic[0] * 0.9))
            .unwrap()
            .is_empty());
    }

    #[test]
    fn utc_dates_match_known_instants() {
        assert_eq!(utc_from_unix(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_from_unix(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_from_unix(1_700_000_000), "2023-11-14T22:13:20Z");
    }
}
