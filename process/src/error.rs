//! Errors of the processing chain: each names the channel, file, field or frequency at fault and
//! says how to fix it.

use std::path::PathBuf;

/// Everything that can go wrong while turning signals into characteristics.
#[derive(Debug, thiserror::Error)]
pub enum ProcessError {
    /// A record holds no samples.
    #[error(
        "channel '{channel}' is empty: record at least one segment ({needed} samples) of data"
    )]
    Empty {
        /// Channel name.
        channel: String,
        /// Samples needed for one segment.
        needed: usize,
    },
    /// A record is shorter than one analysis segment.
    #[error("channel '{channel}' has {samples} samples, fewer than one segment of {needed}: record longer or choose a shorter segment")]
    TooShort {
        /// Channel name.
        channel: String,
        /// Samples present.
        samples: usize,
        /// Samples needed.
        needed: usize,
    },
    /// Channels of one analysis differ in length.
    #[error("channel '{channel}' has {samples} samples but '{first}' has {expected}: all channels of one record must be sampled together")]
    LengthMismatch {
        /// The channel that differs.
        channel: String,
        /// Its length.
        samples: usize,
        /// The first channel's name.
        first: String,
        /// The first channel's length.
        expected: usize,
    },
    /// Channels of one analysis have different sample rates.
    #[error("channel '{channel}' is sampled at {rate_hz} Hz but '{first}' at {expected_hz} Hz: resample or record all channels at one rate")]
    SampleRateMismatch {
        /// The channel that differs.
        channel: String,
        /// Its rate (Hz).
        rate_hz: f64,
        /// The first channel's name.
        first: String,
        /// The first channel's rate (Hz).
        expected_hz: f64,
    },
    /// The number of channels passed does not match what the analysis was set up for.
    #[error("{what}: expected {expected} channels, got {got}")]
    ChannelCount {
        /// Which group of channels (references, responses, calibrations...).
        what: &'static str,
        /// Expected count.
        expected: usize,
        /// Count passed.
        got: usize,
    },
    /// A sample is NaN or infinite.
    #[error("channel '{channel}' sample {index} is {value}: the acquisition produced a non-finite value; check the DAQ channel and cut the record before it")]
    NonFinite {
        /// Channel name.
        channel: String,
        /// Index of the sample in the whole record.
        index: u64,
        /// The value (NaN or ±inf).
        value: f64,
    },
    /// A reference (force) channel carries no signal.
    #[error("reference channel '{channel}' is zero everywhere: the force was not measured (check the force sensor cable and sensitivity)")]
    ZeroForce {
        /// Channel name.
        channel: String,
    },
    /// A setting is out of range.
    #[error("invalid setting {field} = {value}: {reason}")]
    InvalidSetting {
        /// Name of the setting.
        field: &'static str,
        /// Its value as given.
        value: String,
        /// What is allowed.
        reason: String,
    },
    /// An estimator cannot be used with the given channel layout.
    #[error("{estimator} needs exactly one reference channel, got {references}: use H1 for several references")]
    EstimatorNeedsSingleReference {
        /// Estimator name.
        estimator: &'static str,
        /// Number of references.
        references: usize,
    },
    /// The sensor layout cannot observe the solid's motion.
    #[error("sensor layout of body '{body}' is degenerate: {missing}")]
    DegenerateLayout {
        /// Body name.
        body: String,
        /// Which motion is not observed and what to add.
        missing: String,
    },
    /// A conversion between quantities needs a nonzero frequency.
    #[error("cannot convert {from} to {to} at {freq_hz} Hz: division by jω at zero frequency; drop the DC line first")]
    ZeroFrequency {
        /// Source quantity.
        from: &'static str,
        /// Target quantity.
        to: &'static str,
        /// The frequency (Hz).
        freq_hz: f64,
    },
    /// Not enough usable points for a selection.
    #[error("characteristic '{name}': only {usable} frequency lines pass coherence ≥ {min_coherence} in the band, {wanted} wanted; lower the threshold, widen the band or measure again")]
    NotEnoughPoints {
        /// Characteristic name.
        name: String,
        /// Lines that passed.
        usable: usize,
        /// Points requested.
        wanted: usize,
        /// Threshold used.
        min_coherence: f64,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// A file is malformed.
    #[error("{file}: {location}: {message}")]
    Format {
        /// File name (or `<memory>`).
        file: String,
        /// Line, record or field.
        location: String,
        /// What is wrong and how to fix it.
        message: String,
    },
}

/// Result alias of this crate.
pub type Result<T, E = ProcessError> = std::result::Result<T, E>;

pub(crate) fn invalid(
    field: &'static str,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> ProcessError {
    ProcessError::InvalidSetting {
        field,
        value: value.to_string(),
        reason: reason.into(),
    }
}

/// A [`ProcessError::ChannelCount`] of `what` unless `got` is `expected`.
pub(crate) fn check_count(what: &'static str, expected: usize, got: usize) -> Result<()> {
    if got == expected {
        Ok(())
    } else {
        Err(ProcessError::ChannelCount {
            what,
            expected,
            got,
        })
    }
}
