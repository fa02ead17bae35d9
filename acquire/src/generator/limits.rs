//! What each generator model accepts, from its data sheet (the `[model.limits]` entries of
//! `models.toml`, data rather than code): sine amplitude by load, frequency, offset, and the
//! resolution its settings are kept at. The driver chooses every amplitude inside them and
//! compares each read-back within the resolution.

use serde::{Deserialize, Serialize};

/// The load the generator is told its output drives (`OUTPut:LOAD`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Load {
    /// 50 Ω (every generator's default after `*RST`).
    FiftyOhm,
    /// A high impedance (`INFinity`): a power amplifier's input; what the driver always sets.
    HighImpedance,
}

impl Load {
    /// The `[model.limits]` field holding the amplitude range at this load.
    pub fn amplitude_field(self) -> &'static str {
        match self {
            Load::FiftyOhm => "amplitude_50_ohm_vpp",
            Load::HighImpedance => "amplitude_high_z_vpp",
        }
    }

    /// As the instrument's data sheet says it.
    pub fn describe(self) -> &'static str {
        match self {
            Load::FiftyOhm => "into 50 Ω",
            Load::HighImpedance => "into a high impedance",
        }
    }
}

/// One model's ranges (Vpp, V, Hz, as the data sheets state them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModelLimits {
    /// The document the ranges are from.
    pub source: String,
    /// Smallest and largest sine amplitude into 50 Ω (Vpp).
    pub amplitude_50_ohm_vpp: Option<[f64; 2]>,
    /// Smallest and largest sine amplitude into a high impedance (Vpp): twice the 50 Ω range,
    /// the same output voltage.
    pub amplitude_high_z_vpp: Option<[f64; 2]>,
    /// Lowest and highest sine frequency (Hz).
    pub frequency_hz: [f64; 2],
    /// Largest |offset| + peak voltage into 50 Ω (V).
    pub offset_50_ohm_v: f64,
    /// Largest |offset| + peak voltage into a high impedance (V).
    pub offset_high_z_v: f64,
    /// Smallest amplitude step (Vpp): amplitudes are sent on this grid.
    pub amplitude_step_vpp: f64,
    /// Significant digits the instrument keeps of an amplitude.
    pub amplitude_digits: u32,
    /// Frequency resolution (Hz).
    pub frequency_resolution_hz: f64,
}

/// A model's ranges do not cover what is asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitError {
    /// The table has no amplitude range for the load.
    #[error("its [model.limits] in acquire/src/generator/models.toml has no `{field}` (the sine amplitude range {load}); add the range from the instrument's data sheet, or name a table that has it in `dialect` of [generator]")]
    NoRange {
        /// The missing field.
        field: &'static str,
        /// The load, as the data sheet says it.
        load: &'static str,
    },
    /// A value outside the model's range.
    #[error("{what} {value} is outside the model's {lo}..{hi} {unit} {load} ({source_doc})")]
    OutOfRange {
        /// Which quantity.
        what: &'static str,
        /// The value.
        value: f64,
        /// Lowest accepted.
        lo: f64,
        /// Highest accepted.
        hi: f64,
        /// Its unit.
        unit: &'static str,
        /// The load, as the data sheet says it (empty for a frequency).
        load: &'static str,
        /// The data sheet.
        source_doc: String,
    },
}

impl ModelLimits {
    /// The amplitude range at `load` (Vpp).
    pub fn amplitude_vpp(&self, load: Load) -> Result<[f64; 2], LimitError> {
        let r = match load {
            Load::FiftyOhm => self.amplitude_50_ohm_vpp,
            Load::HighImpedance => self.amplitude_high_z_vpp,
        };
        r.ok_or(LimitError::NoRange {
            field: load.amplitude_field(),
            load: load.describe(),
        })
    }

    /// The amplitude range at `load` as the sine's peak voltage (V).
    pub fn amplitude_peak(&self, load: Load) -> Result<[f64; 2], LimitError> {
        let [lo, hi] = self.amplitude_vpp(load)?;
        Ok([0.5 * lo, 0.5 * hi])
    }

    /// The amplitude the output idles at (V peak): the smallest the model accepts at `load`.
    pub fn idle_peak(&self, load: Load) -> Result<f64, LimitError> {
        Ok(self.amplitude_peak(load)?[0])
    }

    /// `volts_peak` on the model's amplitude grid (V peak), checked against its range at `load`.
    pub fn amplitude_to_send(&self, volts_peak: f64, load: Load) -> Result<f64, LimitError> {
        let [lo, hi] = self.amplitude_vpp(load)?;
        let vpp = self.on_grid(2.0 * volts_peak);
        if vpp < lo - 1e-12 || vpp > hi + 1e-12 {
            return Err(LimitError::OutOfRange {
                what: "amplitude (Vpp)",
                value: 2.0 * volts_peak,
                lo,
                hi,
                unit: "Vpp",
                load: load.describe(),
                source_doc: self.source.clone(),
            });
        }
        Ok(0.5 * vpp)
    }

    /// A frequency (Hz) checked against the model's sine range.
    pub fn frequency(&self, hz: f64) -> Result<f64, LimitError> {
        let [lo, hi] = self.frequency_hz;
        if !(lo..=hi).contains(&hz) {
            return Err(LimitError::OutOfRange {
                what: "frequency (Hz)",
                value: hz,
                lo,
                hi,
                unit: "Hz",
                load: "",
                source_doc: self.source.clone(),
            });
        }
        Ok(hz)
    }

    /// A value in Vpp rounded to the amplitude step.
    fn on_grid(&self, vpp: f64) -> f64 {
        let step = self.amplitude_step_vpp;
        if step > 0.0 {
            // Rounded twice: to the grid, then to 12 digits so the decimal has no float noise.
            let g = (vpp / step).round() * step;
            (g * 1e12).round() / 1e12
        } else {
            vpp
        }
    }

    /// How far a read-back amplitude may lie from the one sent (same unit): one step, or the
    /// last of the digits the instrument keeps (a 4-digit instrument rounds 1.2345 to 1.235).
    pub fn amplitude_tolerance(&self, value: f64) -> f64 {
        let digits = self.amplitude_digits.max(1) as i32;
        let relative = value.abs() * 10f64.powi(1 - digits);
        self.amplitude_step_vpp.max(relative) + 1e-12
    }

    /// How far a read-back frequency may lie from the one sent (Hz): the resolution, or the
    /// 1e-6 Hz the driver writes numbers to, or 12 significant digits of it.
    pub fn frequency_tolerance(&self, hz: f64) -> f64 {
        self.frequency_resolution_hz.max(1e-6).max(hz.abs() * 1e-12) + 1e-12
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keysight() -> ModelLimits {
        super::super::dialect::by_name("Keysight 33500B/33600A")
            .unwrap()
            .unwrap()
            .limits
            .unwrap()
    }

    #[test]
    fn the_33500b_idles_at_2_mvpp_into_a_high_impedance_and_1_mvpp_into_50_ohm() {
        let k = keysight();
        assert_eq!(k.idle_peak(Load::HighImpedance).unwrap(), 0.001);
        assert_eq!(k.idle_peak(Load::FiftyOhm).unwrap(), 0.0005);
        // The old idle amplitude (1 mVpp) is refused at a high impedance, as the instrument does.
        let e = k
            .amplitude_to_send(0.0005, Load::HighImpedance)
            .unwrap_err();
        assert!(
            e.to_string()
                .contains("0.002..20 Vpp into a high impedance"),
            "{e}"
        );
        assert!(k.amplitude_to_send(0.0005, Load::FiftyOhm).is_ok());
        assert!(k.amplitude_to_send(10.0, Load::HighImpedance).is_ok());
        assert!(k.amplitude_to_send(10.01, Load::HighImpedance).is_err());
        assert!(k.amplitude_to_send(5.01, Load::FiftyOhm).is_err());
    }

    #[test]
    fn amplitudes_are_sent_on_the_step_grid_and_read_back_within_the_digits() {
        let k = keysight();
        // 0.1 mVpp steps: 1.23456 V peak = 2.46912 Vpp → 2.4691 Vpp.
        let v = k.amplitude_to_send(1.23456, Load::HighImpedance).unwrap();
        assert_eq!(v, 1.23455);
        // Four digits: 2.4691 Vpp may read back as 2.469.
        assert!((2.4691f64 - 2.469).abs() <= k.amplitude_tolerance(2.4691));
        assert!((2.4691f64 - 2.466).abs() > k.amplitude_tolerance(2.4691));
        assert!(k.frequency(20e6).is_ok() && k.frequency(20.1e6).is_err());
        assert!(k.frequency(0.0).is_err());
    }

    #[test]
    fn a_table_without_the_high_impedance_range_says_which_field_to_add() {
        let mut k = keysight();
        k.amplitude_high_z_vpp = None;
        let e = k.idle_peak(Load::HighImpedance).unwrap_err().to_string();
        assert!(
            e.contains("no `amplitude_high_z_vpp`") && e.contains("data sheet"),
            "{e}"
        );
    }
}
