//! Is the measured data plausible for this model before fitting? Two checks against the initial
//! model: the **band** (data lines more than a decade away from every natural frequency of the
//! model — frequencies in kHz under a `freq_hz` column, or the wrong model — are an error), and
//! the **level** (the median of log10 |data/model|; a level 9.81× or 1000× off — g read as m/s²,
//! mm as m, kN as N — is warned about, naming the likely mistake). The level is judged first on
//! the lines above the model's resonances (the mass line, fixed by the masses, which drawings
//! give well), then below them (the static compliance), then over the whole band: misplaced
//! resonances blur the band's level but not the asymptotes. Nothing is ever rescaled: the user
//! fixes the unit.

use nalgebra::DMatrix;

use super::data::{DataError, Observations};
use rfe::display::sig;
use rfe::frf::{response, Method, Response};
use rfe::model::Model;
use rfe::system::{MassScaling, System};
use rfe::units::STANDARD_GRAVITY;

/// A band further than this factor below the first (above the last) natural frequency is an
/// error.
pub const BAND_FACTOR: f64 = 10.0;
/// A median level within this many decades of a suspicious factor is reported as that factor.
const LEVEL_TOLERANCE_DECADES: f64 = 0.12;

/// The band check: an error when every measured line lies more than [`BAND_FACTOR`] below the
/// model's first natural frequency or above its last (rigid-body modes aside).
pub fn check_band(model: &Model, obs: &Observations) -> Result<(), DataError> {
    band_within(resonance_range(model), obs)
}

/// Both checks with the model's resonance range found once: the band's error, else every
/// characteristic's level ([`check_band`], [`check_level`]).
pub fn check(model: &Model, obs: &Observations) -> Result<Vec<Level>, DataError> {
    let range = resonance_range(model);
    band_within(range, obs)?;
    Ok(levels_within(model, range, obs))
}

/// [`check_band`] against the resonance range `range` (none: nothing to check).
fn band_within(range: Option<(f64, f64)>, obs: &Observations) -> Result<(), DataError> {
    let Some((first, last)) = range else {
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
    levels_within(model, resonance_range(model), obs)
}

/// The model's response to every characteristic, each at its own lines (`None` where the model
/// cannot be evaluated): one solve for all when they share their lines, as measured
/// characteristics mostly do, else one each.
fn responses(model: &Model, obs: &Observations) -> Vec<Option<Vec<rfe::C64>>> {
    let chars = &obs.characteristics;
    let shared = chars.windows(2).all(|w| w[0].freqs_hz == w[1].freqs_hz);
    if shared && chars.len() > 1 {
        let mut all = model.clone();
        all.outputs = chars.iter().map(|c| c.characteristic).collect();
        if let Ok(r) = response(&all, &chars[0].freqs_hz, &[], Method::Auto) {
            return (0..chars.len())
                .map(|o| Some(r.output(o).to_vec()))
                .collect();
        }
    }
    chars
        .iter()
        .map(|c| {
            let mut single = model.clone();
            single.outputs = vec![c.characteristic];
            response(&single, &c.freqs_hz, &[], Method::Auto)
                .ok()
                .map(|r: Response| r.values)
        })
        .collect()
}

/// [`check_level`] with the model's resonance range `range` (`None`: unknown).
fn levels_within(model: &Model, range: Option<(f64, f64)>, obs: &Observations) -> Vec<Level> {
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
    // The model's resonance range: lines well above it follow the mass line, lines well below
    // the static compliance; both are far less sensitive to misplaced resonances than the
    // level across the band, and the mass line depends only on masses, which the drawings give.
    let (first, last) = range.unwrap_or((f64::NAN, f64::NAN));
    let mut out = Vec::new();
    for (c, q) in obs.characteristics.iter().zip(responses(model, obs)) {
        let Some(q) = q else {
            continue;
        };
        let ratios: Vec<(f64, f64)> = q
            .iter()
            .zip(&c.amplitude)
            .zip(&c.freqs_hz)
            .filter(|((z, a), _)| z.norm() > 0.0 && **a > 0.0)
            .map(|((z, a), f)| (*f, (a / z.norm()).log10()))
            .filter(|(_, x)| x.is_finite())
            .collect();
        let Some(median) = median_of(ratios.iter().map(|(_, x)| *x), 1) else {
            continue;
        };
        let regions = [
            (
                "above the model's resonances (the mass line)",
                median_of(
                    ratios
                        .iter()
                        .filter(|(f, _)| *f > 2.0 * last)
                        .map(|(_, x)| *x),
                    3,
                ),
            ),
            (
                "below the model's resonances (the static compliance)",
                median_of(
                    ratios
                        .iter()
                        .filter(|(f, _)| *f < 0.5 * first)
                        .map(|(_, x)| *x),
                    3,
                ),
            ),
            ("over the band", Some(median)),
        ];
        let suspect = regions.iter().find_map(|(region, m)| {
            let m = (*m)?;
            suspects
                .iter()
                .find(|(f, _)| (m - f.log10()).abs() < LEVEL_TOLERANCE_DECADES)
                .map(|(_, why)| (region, m, why))
        });
        let warning = suspect
            .map(|(region, m, why)| {
                format!(
                    "{}: the data lie {}x the initial model's level {region} (median over {} lines in all) — that looks like {why}. Check the unit; nothing was rescaled",
                    c.label,
                    sig(10f64.powf(m), 3),
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

/// The model's lowest and highest natural frequency (Hz), rigid-body modes aside: from the
/// eigenvalues `ω²` of `M^-½ K M^-½`, those of [`rfe::modes::undamped`] without its shapes
/// (only the frequencies are needed here).
fn resonance_range(model: &Model) -> Option<(f64, f64)> {
    let s = System::assemble(model);
    let n = s.n;
    let scale = MassScaling::new(&s)?;
    let a = DMatrix::from_fn(n, n, |i, j| scale.congruence(i, j, |k, l| s.k[k * n + l]));
    if !a.iter().all(|v| v.is_finite()) {
        return None;
    }
    let omega2 = a.symmetric_eigenvalues();
    let f = omega2
        .iter()
        .map(|w2| w2.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
        .filter(|f| f.is_finite() && *f > 0.0);
    let first = f.clone().reduce(f64::min)?;
    Some((first, f.reduce(f64::max)?))
}

/// The median of at least `min` values, `None` with fewer.
fn median_of(values: impl Iterator<Item = f64>, min: usize) -> Option<f64> {
    let mut v: Vec<f64> = values.collect();
    if v.len() < min.max(1) {
        return None;
    }
    v.sort_by(f64::total_cmp);
    Some(v[v.len() / 2])
}
