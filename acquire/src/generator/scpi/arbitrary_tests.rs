//! The arbitrary-waveform upload against recorded transcripts of two vendors' manuals.
