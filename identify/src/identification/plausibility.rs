//! Is the measured data plausible for this model before fitting? Two checks against the initial
//! model: the **band** (data lines more than a decade away from every natural frequency of the
//! model — frequencies in kHz under a `freq_hz` column, or the wrong model — are an error), and
//! the **level** (the median of log10 |data/model| over each characteristic's lines; a level
//! 9.81× or 1000× off — g read as m/s², mm as m, kN as N — is warned about, naming the likely
//! mistake). Nothing is ever rescaled: the user fixes the unit.

use super::data::{DataError, Observations};
use crate::display::sig;
use crate::frf::{response, Method};
use crate::model::Model;
use crate::units::STANDARD_GRAVITY;

/// A band further than this factor below the first (above the last) natural frequency is an
/// error.
pub const BAND_FACTOR: f64 = 10.0;
/// A median level within this many decades of a suspicious factor is reported as that factor.
const LEVEL_TOLERANCE_DECADES: f64 = 0.12;

/// The band check: an error when every measured line lies more than [`BAND_FACTOR`] below the
/// model's first natural frequency or above its last (rigid-body modes aside).
pub fn check_band(model: &Model, obs: &Observations) -> Result<(), DataError> {
    let Ok(modes) = crate::modes::undamped(model) else {
        return Ok(());
    };
    let f: Vec<f64> = modes
        .iter()
        .map(|m| m.freq_hz)
        .filter(|f| f.is_finite() && *f > 0.0)
        .collect();
    let (Some(first), Some(last)) = (
        f.iter().copied().reduce(f64::min),
        f.iter().copied().reduce(f64::max),
    ) else {
        return Ok(());
    };
    let lines = obs
        .characteristics
        .iter()
        .flat_map(|c| c.freqs_hz.iter().copied());
    let (lo, hi) = lines.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
    let problem = if hi < first / BAND_FACTOR {
        Some(format!(
            "every line ({} to {} Hz) lies more than {BAND_FACTOR}x below the model's first natural frequency ({} Hz): the data and the model's band do not overlap. Are the frequencies in kHz under a freq_hz column (× 1000), or is it the wrong model?",
            sig(lo, 4), sig(hi, 4), sig(first, 4)
        ))
    } else if lo > last * BAND_FACTOR {
        Some(format!(
            "every line ({} to {} Hz) lies more than {BAND_FACTOR}x above the model's last natural frequency ({} Hz): the data and the model's band do not overlap. Are the frequencies in rad/s or cycles per minute rather than Hz, or is it the wrong model?",
            sig(lo, 4), sig(hi, 4), sig(last, 4)
        ))
    } else {
        None
    };
    match problem {
        Some(message) => Err(DataError::Invalid {
            origin: obs.origin.clone(),
            item: "frequencies".into(),
            message,
        }),
        None => Ok(()),
    }
}

/// The level of one characteristic against the initial model.
#[derive(Debug, Clone, PartialEq)]
pub struct Level {
    /// `"table u1 displacement"`.
    pub label: String,
    /// Median over the lines of log10 |data / model|.
    pub median_log10: f64,
    /// The likely mistake when the level is suspicious.
    pub warning: Option<String>,
}

/// The level check of every characteristic (empty when the model cannot be evaluated).
pub fn check_level(model: &Model, obs: &Observations) -> Vec<Level> {
    let suspects: [(f64, &str); 6] = [
        (
            STANDARD_GRAVITY,
            "g read as m/s² (acceleration in g but declared or taken as m/s²)",
        ),
        (1.0 / STANDARD_GRAVITY, "m/s² read as g"),
        (
            1e3,
            "mm read as m, or per kN read as per N (or the data per N of a 1 kN excitation)",
        ),
        (1e-3, "m read as mm, or per N read as per kN"),
        (1e6, "µm read as m"),
        (1e-6, "m read as µm"),
    ];
    let mut out = Vec::new();
    for c in &obs.characteristics {
        let mut single = model.clone();
        single.outputs = vec![c.characteristic];
        let Ok(r) = response(&single, &c.freqs_hz, &[], Method::Auto) else {
            continue;
        };
        let mut ratios: Vec<f64> = r
            .output(0)
            .iter()
            .zip(&c.amplitude)
            .filter(|(z, a)| z.norm() > 0.0 && **a > 0.0)
            .map(|(z, a)| (a / z.norm()).log10())
            .filter(|x| x.is_finite())
            .collect();
        if ratios.is_empty() {
            continue;
        }
        ratios.sort_by(f64::total_cmp);
        let median = ratios[ratios.len() / 2];
        let warning = suspects
            .iter()
            .find(|(f, _)| (median - f.log10()).abs() < LEVEL_TOLERANCE_DECADES)
            .map(|(_, why)| {
                format!(
                    "{}: the data lie {}x the initial model's level (median over {} lines) — that looks like {why}. Check the unit; nothing was rescaled",
                    c.label,
                    sig(10f64.powf(median), 3),
                    ratios.len(),
                )
            })
            .or_else(|| {
                (median.abs() > 1.0).then(|| {
                    format!(
                        "{}: the data lie {}x the initial model's level (median over {} lines): check the unit and the excitation scaling, or the initial values",
                        c.label,
                        sig(10f64.powf(median), 3),
                        ratios.len()
                    )
                })
            });
        out.push(Level {
            label: c.label.clone(),
            median_log10: median,
            warning,
        });
    }
    out
}
