//! Which measured lines enter the fit: a frequency band, excluded lines (mains harmonics, a
//! known disturbance), and a coherence floor, applied to measured data before validation, with a
//! per-characteristic account of what was kept and why the rest was dropped.
//!
//! Real spectra carry lines that only mislead a fit: below the shaker's usable range, above the
//! model's validity, at 50/60 Hz and their harmonics, where the coherence says the FRF is noise.
//! A choice that leaves a characteristic without lines is an error naming it, never a silent
//! empty fit.
//!
//! ```
//! use identify::line_choice::LineChoice;
//! let choice = LineChoice { band_hz: (Some(20.0), Some(400.0)), ..LineChoice::default() };
//! assert!(choice.keeps(50.0, None) && !choice.keeps(10.0, None));
//! ```

use rfe::measured::{MeasuredData, Measurement};

/// What to keep. The default keeps every line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LineChoice {
    /// Band (Hz), inclusive; `None` = open on that side.
    pub band_hz: (Option<f64>, Option<f64>),
    /// Frequencies (Hz) whose neighbourhood ± `exclude_width_hz` is dropped.
    pub exclude_hz: Vec<f64>,
    /// Mains frequency (Hz): every harmonic of it is excluded like `exclude_hz`.
    pub mains_hz: Option<f64>,
    /// Half-width (Hz) of an excluded neighbourhood.
    pub exclude_width_hz: f64,
    /// Lines whose coherence is below this are dropped (where the data have coherence).
    pub min_coherence: Option<f64>,
}

/// A choice that cannot be applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LineChoiceError {
    /// A setting is out of range.
    #[error("{option} {value}: {fix}")]
    Setting {
        /// The option (`--band`, ...).
        option: &'static str,
        /// Its value as given.
        value: String,
        /// What is allowed.
        fix: String,
    },
    /// Nothing of a characteristic is left.
    #[error("{origin}: {label}: none of its {lines} lines ({lo}-{hi} Hz) is left after {what}; widen the band or relax the choice")]
    Empty {
        /// Data file.
        origin: String,
        /// Characteristic (`body dof`).
        label: String,
        /// Lines it had.
        lines: usize,
        /// Its lowest line (Hz).
        lo: f64,
        /// Its highest line (Hz).
        hi: f64,
        /// The choice, in words.
        what: String,
    },
}

/// What the choice did to one characteristic.
#[derive(Debug, Clone, PartialEq)]
pub struct Account {
    /// Characteristic (`body dof`).
    pub label: String,
    /// Lines measured.
    pub measured: usize,
    /// Dropped outside the band.
    pub outside_band: usize,
    /// Dropped near an excluded line or mains harmonic.
    pub excluded: usize,
    /// Dropped for low coherence.
    pub low_coherence: usize,
    /// Lines kept.
    pub kept: usize,
}

impl Account {
    /// One line for the terminal.
    pub fn describe(&self) -> String {
        let mut why = Vec::new();
        if self.outside_band > 0 {
            why.push(format!("{} outside the band", self.outside_band));
        }
        if self.excluded > 0 {
            why.push(format!("{} near excluded lines", self.excluded));
        }
        if self.low_coherence > 0 {
            why.push(format!("{} below the coherence floor", self.low_coherence));
        }
        let dropped = if why.is_empty() {
            "none dropped".to_string()
        } else {
            format!("dropped {}", why.join(", "))
        };
        format!(
            "{}: {} of {} lines kept ({dropped})",
            self.label, self.kept, self.measured
        )
    }
}

impl LineChoice {
    /// True when the choice keeps everything (nothing to apply or report).
    pub fn is_all(&self) -> bool {
        self.band_hz == (None, None)
            && self.exclude_hz.is_empty()
            && self.mains_hz.is_none()
            && self.min_coherence.is_none()
    }

    /// Checks the settings.
    pub fn check(&self) -> Result<(), LineChoiceError> {
        let bad = |option, value: String, fix: &str| {
            Err(LineChoiceError::Setting {
                option,
                value,
                fix: fix.into(),
            })
        };
        let (lo, hi) = self.band_hz;
        for f in [lo, hi].into_iter().flatten() {
            if !(f.is_finite() && f >= 0.0) {
                return bad("--band", f.to_string(), "band edges are frequencies ≥ 0 Hz");
            }
        }
        if let (Some(l), Some(h)) = (lo, hi) {
            if l >= h {
                return bad(
                    "--band",
                    format!("{l}:{h}"),
                    "the lower edge must be below the upper one (LO:HI in Hz)",
                );
            }
        }
        if let Some(f) = self
            .exclude_hz
            .iter()
            .find(|f| !(f.is_finite() && **f > 0.0))
        {
            return bad(
                "--exclude",
                f.to_string(),
                "excluded lines are frequencies > 0 Hz",
            );
        }
        if let Some(m) = self.mains_hz.filter(|m| !(m.is_finite() && *m > 0.0)) {
            return bad(
                "--mains",
                m.to_string(),
                "the mains frequency, e.g. 50 or 60 (Hz)",
            );
        }
        let w = self.exclude_width_hz;
        if !(w.is_finite() && w >= 0.0) {
            return bad("--exclude-width", w.to_string(), "a half-width ≥ 0 Hz");
        }
        if let Some(g) = self.min_coherence.filter(|g| !(0.0..1.0).contains(g)) {
            return bad(
                "--min-coherence",
                g.to_string(),
                "a coherence from 0 to below 1",
            );
        }
        Ok(())
    }

    /// Why line `f` (with its coherence) is dropped, or `None` when it is kept.
    fn reason(&self, f: f64, coherence: Option<f64>) -> Option<Reason> {
        let (lo, hi) = self.band_hz;
        if lo.is_some_and(|l| f < l) || hi.is_some_and(|h| f > h) {
            return Some(Reason::Band);
        }
        let w = self.exclude_width_hz;
        let near_listed = self.exclude_hz.iter().any(|x| (f - x).abs() <= w);
        let near_mains = self.mains_hz.is_some_and(|m| {
            let k = (f / m).round();
            k >= 1.0 && (f - k * m).abs() <= w
        });
        if near_listed || near_mains {
            return Some(Reason::Excluded);
        }
        if let (Some(min), Some(g)) = (self.min_coherence, coherence) {
            if g < min {
                return Some(Reason::Coherence);
            }
        }
        None
    }

    /// True when line `f` (with its coherence, if known) is kept.
    pub fn keeps(&self, f: f64, coherence: Option<f64>) -> bool {
        self.reason(f, coherence).is_none()
    }

    /// The choice in words, for messages.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        match self.band_hz {
            (None, None) => {}
            (lo, hi) => parts.push(format!(
                "the band {}-{} Hz",
                lo.map_or("0".into(), |l| l.to_string()),
                hi.map_or("∞".into(), |h| h.to_string())
            )),
        }
        if !self.exclude_hz.is_empty() || self.mains_hz.is_some() {
            parts.push(format!(
                "excluding ±{} Hz around the given lines",
                self.exclude_width_hz
            ));
        }
        if let Some(g) = self.min_coherence {
            parts.push(format!("coherence ≥ {g}"));
        }
        parts.join(", ")
    }

    /// Applies the choice to every characteristic of `data` (from the file `origin`).
    pub fn apply(
        &self,
        data: &MeasuredData,
        origin: &str,
    ) -> Result<(MeasuredData, Vec<Account>), LineChoiceError> {
        self.check()?;
        let mut out = data.clone();
        let mut accounts = Vec::new();
        for m in &mut out.characteristics {
            let label = m.label();
            let mut account = Account {
                label: label.clone(),
                measured: m.freqs_hz.len(),
                outside_band: 0,
                excluded: 0,
                low_coherence: 0,
                kept: 0,
            };
            let keep: Vec<bool> = (0..m.freqs_hz.len())
                .map(|k| {
                    let g = m.coherence.as_ref().and_then(|c| c.get(k).copied());
                    match self.reason(m.freqs_hz[k], g) {
                        None => true,
                        Some(Reason::Band) => {
                            account.outside_band += 1;
                            false
                        }
                        Some(Reason::Excluded) => {
                            account.excluded += 1;
                            false
                        }
                        Some(Reason::Coherence) => {
                            account.low_coherence += 1;
                            false
                        }
                    }
                })
                .collect();
            account.kept = keep.iter().filter(|k| **k).count();
            if account.kept == 0 && account.measured > 0 {
                return Err(LineChoiceError::Empty {
                    origin: origin.into(),
                    label,
                    lines: account.measured,
                    lo: m.freqs_hz.first().copied().unwrap_or(0.0),
                    hi: m.freqs_hz.last().copied().unwrap_or(0.0),
                    what: self.describe(),
                });
            }
            retain(m, &keep);
            accounts.push(account);
        }
        Ok((out, accounts))
    }
}

/// Why a line is dropped.
enum Reason {
    Band,
    Excluded,
    Coherence,
}

/// Keeps the points of `m` where `keep` is true, in every per-point column (frequencies,
/// amplitudes, phases, variances, coherences).
pub fn retain(m: &mut Measurement, keep: &[bool]) {
    fn filter(v: &mut Vec<f64>, keep: &[bool]) {
        let mut k = keep.iter();
        v.retain(|_| k.next().copied().unwrap_or(true));
    }
    filter(&mut m.freqs_hz, keep);
    filter(&mut m.amplitude, keep);
    for column in [&mut m.phase_rad, &mut m.variance, &mut m.coherence]
        .into_iter()
        .flatten()
    {
        filter(column, keep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rfe::measured::QuantityName;

    fn data() -> MeasuredData {
        let f: Vec<f64> = (1..=200).map(|i| i as f64).collect();
        MeasuredData {
            source: "test".into(),
            characteristics: vec![Measurement {
                body: "table".into(),
                dof: 2,
                quantity: QuantityName::Acceleration,
                amplitude: f.iter().map(|f| 1.0 / f).collect(),
                phase_rad: Some(f.iter().map(|f| -f / 100.0).collect()),
                variance: None,
                coherence: Some(
                    f.iter()
                        .map(|f| if *f > 150.0 { 0.5 } else { 0.99 })
                        .collect(),
                ),
                averages: Some(8),
                at: None,
                reference: None,
                relative: false,
                freqs_hz: f,
            }],
        }
    }

    #[test]
    fn band_mains_and_coherence_drop_exactly_their_lines_and_keep_the_columns_aligned() {
        let choice = LineChoice {
            band_hz: (Some(20.0), Some(180.0)),
            mains_hz: Some(50.0),
            exclude_hz: vec![77.0],
            exclude_width_hz: 1.0,
            min_coherence: Some(0.8),
        };
        let (out, acc) = choice.apply(&data(), "d.csv").unwrap();
        let c = &out.characteristics[0];
        // 1-19 and 181-200 outside: 39; around 50, 100, 150 and 77: 3 lines each (12), 150's
        // neighbourhood is also below the floor but counted as excluded; 151-180 below: 30.
        assert_eq!(acc[0].outside_band, 39);
        assert_eq!(acc[0].excluded, 12);
        assert_eq!(acc[0].low_coherence, 29);
        assert_eq!(acc[0].kept, 200 - 39 - 12 - 29);
        assert_eq!(c.freqs_hz.len(), acc[0].kept);
        for (k, f) in c.freqs_hz.iter().enumerate() {
            assert!(choice.keeps(*f, Some(c.coherence.as_ref().unwrap()[k])));
            assert_eq!(c.amplitude[k], 1.0 / f);
            assert_eq!(c.phase_rad.as_ref().unwrap()[k], -f / 100.0);
        }
        assert!(!c.freqs_hz.contains(&100.0) && c.freqs_hz.contains(&102.0));
        assert!(
            acc[0].describe().contains("120 of 200 lines kept"),
            "{}",
            acc[0].describe()
        );
    }

    #[test]
    fn a_choice_that_empties_a_characteristic_or_makes_no_sense_is_an_error() {
        let e = LineChoice {
            band_hz: (Some(500.0), None),
            ..LineChoice::default()
        }
        .apply(&data(), "d.csv")
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("d.csv: table u3: none of its 200 lines (1-200 Hz)"),
            "{e}"
        );
        for (choice, want) in [
            (
                LineChoice {
                    band_hz: (Some(90.0), Some(10.0)),
                    ..LineChoice::default()
                },
                "--band 90:10",
            ),
            (
                LineChoice {
                    mains_hz: Some(0.0),
                    ..LineChoice::default()
                },
                "--mains 0",
            ),
            (
                LineChoice {
                    min_coherence: Some(1.5),
                    ..LineChoice::default()
                },
                "--min-coherence 1.5",
            ),
            (
                LineChoice {
                    exclude_hz: vec![-3.0],
                    ..LineChoice::default()
                },
                "--exclude -3",
            ),
        ] {
            let e = choice.apply(&data(), "d.csv").unwrap_err().to_string();
            assert!(e.starts_with(want), "{e}");
        }
        assert!(LineChoice::default().is_all());
        assert_eq!(
            LineChoice::default().apply(&data(), "d.csv").unwrap().0,
            data()
        );
    }
}
