//! The stand file's `[broadband]` section: the broadband measurement `ident sweep --broadband`
//! runs (waveform, band, force, averages, settling), checked against the DAQ's sample rate and —
//! on a generator stand — against the generator model's arbitrary-waveform upload and its limits
//! (docs/scpi-generator.md).

use serde::{Deserialize, Serialize};
use serde_spanned::Spanned;

use rfe::source::Quantity as Value;
use rfe::units::Dim;

use super::context::{Ctx, StandError};
use super::generator::{model_of, GeneratorStand};
use crate::record::Waveform;

/// A broadband measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Broadband {
    /// Random, burst random or chirp (a sine is refused).
    pub waveform: Waveform,
    /// Force: RMS for random/burst, peak for chirp (N).
    pub force_n: f64,
    /// Periods averaged.
    pub averages: u32,
    /// Periods discarded first to let the structure settle.
    pub settle_periods: u32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawBroadband {
    waveform: Spanned<String>,
    from: Spanned<Value>,
    to: Spanned<Value>,
    force: Spanned<Value>,
    averages: Option<Spanned<u32>>,
    settle_periods: Option<u32>,
    period: Option<Spanned<Value>>,
    duty: Option<Spanned<f64>>,
}

/// The example the messages show.
const EXAMPLE: &str = "[broadband]\nwaveform = \"random\"   # random | burst_random | chirp\nfrom = \"20 Hz\"\nto = \"400 Hz\"\nforce = \"500 N\"        # RMS (random, burst random); peak for a chirp\naverages = 8\nsettle_periods = 4\n# period = \"1 s\"       # burst_random and chirp (random repeats every 1 s)\n# duty = 0.5           # burst_random";

/// `[broadband]` as a plan, for a stand whose DAQ samples at `fs` (Hz), whose exciter holds at
/// most `max_force_n`, and whose generator (if any) is `generator`.
pub(super) fn broadband_section(
    cx: &Ctx<'_>,
    rb: &Spanned<RawBroadband>,
    fs: f64,
    max_force_n: f64,
    generator: Option<&GeneratorStand>,
) -> Result<Broadband, StandError> {
    let b = rb.get_ref();
    let f_lo_hz = cx.positive(&b.from, Dim::FREQUENCY, "broadband.from")?;
    let f_hi_hz = cx.positive(&b.to, Dim::FREQUENCY, "broadband.to")?;
    if f_hi_hz <= f_lo_hz || f_hi_hz >= 0.5 * fs {
        return Err(cx.at(
            b.to.span(),
            format!("broadband.to must lie above broadband.from ({f_lo_hz} Hz) and below half the DAQ's sample rate ({} Hz)", 0.5 * fs),
        ));
    }
    let force_n = cx.positive(&b.force, Dim::FORCE, "broadband.force")?;
    if force_n > max_force_n {
        return Err(cx.at(
            b.force.span(),
            format!("broadband.force {force_n} N is above the exciter's force limit {max_force_n} N (amplifier.force_limit or shaker.max_force)"),
        ));
    }
    let period = |what: &str| -> Result<f64, StandError> {
        match &b.period {
            Some(p) => cx.positive(p, Dim::TIME, "broadband.period"),
            None => Err(cx.at(
                rb.span(),
                format!("[broadband] waveform = \"{what}\" needs `period` (the time it repeats with), e.g. period = \"1 s\""),
            )),
        }
    };
    let waveform = match b.waveform.get_ref().trim() {
        "random" => Waveform::Random { f_lo_hz, f_hi_hz },
        "burst_random" => {
            let duty = match &b.duty {
                Some(d) if *d.get_ref() > 0.0 && *d.get_ref() <= 1.0 => *d.get_ref(),
                Some(d) => {
                    return Err(cx.at(
                        d.span(),
                        "broadband.duty is the driven fraction of the period, within 0..1",
                    ))
                }
                None => 0.5,
            };
            Waveform::BurstRandom {
                f_lo_hz,
                f_hi_hz,
                duty,
                period_s: period("burst_random")?,
            }
        }
        "chirp" => Waveform::Chirp {
            f_lo_hz,
            f_hi_hz,
            period_s: period("chirp")?,
        },
        other => {
            return Err(cx.at(
                b.waveform.span(),
                format!("broadband.waveform = {other:?}: use \"random\", \"burst_random\" or \"chirp\"; e.g.\n{EXAMPLE}"),
            ))
        }
    };
    let averages = match &b.averages {
        Some(a) if *a.get_ref() == 0 => {
            return Err(cx.at(a.span(), "broadband.averages must be at least 1"))
        }
        Some(a) => *a.get_ref(),
        None => 8,
    };
    let plan = Broadband {
        waveform,
        force_n,
        averages,
        settle_periods: b.settle_periods.unwrap_or(4),
    };
    let period_s = crate::generator::waveform::period_s(&plan.waveform).unwrap_or(1.0);
    let exact = period_s * fs;
    let span = b.period.as_ref().map_or(b.waveform.span(), |p| p.span());
    if (exact - exact.round()).abs() > 1e-6 || exact < 16.0 {
        return Err(cx.at(
            span,
            format!("the broadband period {period_s} s is {exact} samples at daq.sample_rate {fs} Hz; it must be a whole number (≥ 16) so that every period is averaged whole"),
        ));
    }
    if let Some(g) = generator {
        check_generator(cx, rb, span, g, exact.round() as usize, fs, period_s)?;
    }
    Ok(plan)
}

/// The generator's model, when the stand file names it (`dialect`, or `identity` with
/// manufacturer and model): its arbitrary-waveform upload must exist and take the period.
fn check_generator(
    cx: &Ctx<'_>,
    rb: &Spanned<RawBroadband>,
    period_span: std::ops::Range<usize>,
    g: &GeneratorStand,
    points: usize,
    fs: f64,
    period_s: f64,
) -> Result<(), StandError> {
    let Some((entry, from)) = model_of(g) else {
        // Chosen from *IDN? at connection time; the driver checks then.
        return Ok(());
    };
    let Some(a) = &entry.arbitrary else {
        return Err(cx.at(
            rb.span(),
            format!("[broadband] drives an arbitrary waveform, but the generator's command table `{}` ({from}) has no arbitrary-waveform upload; remove [broadband] and measure with a stepped sine, or use a generator model that has one (Keysight 33500B/33600A, Rigol DG800/DG1000Z, Tektronix AFG31000)", entry.name),
        ));
    };
    if fs > a.max_sample_rate_hz {
        return Err(cx.at(
            period_span,
            format!("[broadband] plays the waveform at daq.sample_rate {fs} Hz, above the {}'s {} Sa/s; lower daq.sample_rate", entry.name, a.max_sample_rate_hz),
        ));
    }
    if points > a.max_points || points < a.min_points {
        return Err(cx.at(
            period_span,
            format!("the broadband period {period_s} s at daq.sample_rate {fs} Hz is {points} points; the {} takes {}..{} per upload; shorten broadband.period (random repeats every 1 s) or lower daq.sample_rate", entry.name, a.min_points, a.max_points),
        ));
    }
    Ok(())
}
