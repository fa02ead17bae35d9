//! A tool's own receptance read from a UFF file (`[[tool.frf]]` in the cutting file): the
//! driving-point FRF at the tool tip, measured with the tool clamped in a stiff holder (an impact
//! test on the tool alone, or a beam model exported as UFF58), coupled in series at the spindle
//! nose like the modal tool (`[[tool.mode]]`).
//!
//! The file is read by `process::uff` (datasets 58/58b, the units from records 8-10): the FRF must
//! be a driving point (response node and direction = reference node and direction) with complex
//! values per unit force. Receptance is used as it is, mobility is divided by jω and accelerance
//! by −ω². Between lines the FRF is interpolated linearly (real and imaginary parts). Below the
//! first line it is held at the first line's value, the tool's quasi-static compliance. Above the
//! last line there is no data, so the lobes refuse a frequency grid that reaches past it.

use nalgebra::Vector3;
use num_complex::Complex64 as C64;
use rfe::model::Quantity;

/// A tool's driving-point receptance along `direction` (SI: m/N).
#[derive(Debug, Clone, PartialEq)]
pub struct ToolFrf {
    /// The UFF file, for messages.
    pub origin: String,
    /// Direction it was measured in (global, unit).
    pub direction: Vector3<f64>,
    /// Lines (Hz), increasing.
    pub freqs_hz: Vec<f64>,
    /// Receptance (m/N) at the lines.
    pub h: Vec<C64>,
}

impl ToolFrf {
    /// The receptance at `freq_hz`: linear between lines, the first line's value below them. The
    /// caller checks that `freq_hz` is not above the last line ([`ToolFrf::highest_hz`]).
    pub fn at(&self, freq_hz: f64) -> C64 {
        let f = &self.freqs_hz;
        let k = f.partition_point(|&x| x <= freq_hz);
        if k == 0 {
            return self.h[0];
        }
        if k == f.len() {
            return self.h[f.len() - 1];
        }
        let t = (freq_hz - f[k - 1]) / (f[k] - f[k - 1]);
        self.h[k - 1] * (1.0 - t) + self.h[k] * t
    }

    /// The last line (Hz).
    pub fn highest_hz(&self) -> f64 {
        self.freqs_hz.last().copied().unwrap_or(0.0)
    }
}

/// Reads the tool FRF in `path` (measured along `direction`); the problem in words otherwise
/// (what is wrong and how to fix it; the caller names the file and the field).
pub fn read(path: &std::path::Path, direction: Vector3<f64>) -> Result<ToolFrf, String> {
    let origin = path.display().to_string();
    let file = process::uff::read_file(path).map_err(|e| format!("cannot read it: {e}"))?;
    let (channels, _) = process::uff::measured_channels(&file, &origin)
        .map_err(|e| format!("no usable FRF: {e}"))?;
    let fix = "give the tool tip's driving-point receptance: one UFF58 FRF with its response and reference at the same node and direction (the tool clamped in a stiff holder, excited and measured at the tip), complex values in m/N, (m/s)/N or (m/s^2)/N";
    if channels.len() != 1 {
        return Err(format!(
            "{} FRFs in the file; one tool FRF per [[tool.frf]] is read: {fix}",
            channels.len()
        ));
    }
    let c = &channels[0];
    let response = match c.name {
        rfe::channel::ChannelName::Node { node, dir } => Some((node, dir)),
        _ => None,
    };
    if response.is_none() || c.reference != response {
        let (node, dir) = response.unwrap_or((0, 0));
        let (rn, rd) = c.reference.unwrap_or((0, 0));
        return Err(format!(
            "{}: response node {node} direction {dir}, reference node {rn} direction {rd}: not a driving-point FRF (a cross FRF is not the tool's own receptance); {fix}",
            c.item
        ));
    }
    let unit = c
        .unit
        .as_ref()
        .map_err(|e| format!("{}: {e}; {fix}", c.item))?;
    if !unit.per_force {
        return Err(format!(
            "{}: its unit \"{}\" is not a response per force; {fix}",
            c.item, unit.text
        ));
    }
    let Some(phase) = &c.phase_rad else {
        return Err(format!("{}: real values without phase; {fix}", c.item));
    };
    let mut freqs = Vec::with_capacity(c.freqs_hz.len());
    let mut h = Vec::with_capacity(c.freqs_hz.len());
    for ((&f, &a), &p) in c.freqs_hz.iter().zip(&c.amplitude).zip(phase) {
        let v = C64::from_polar(a * unit.to_si, p);
        let jw = C64::new(0.0, std::f64::consts::TAU * f);
        let r = match unit.quantity {
            Quantity::Displacement => v,
            // At 0 Hz a mobility or accelerance says nothing about the compliance.
            _ if f <= 0.0 => continue,
            Quantity::Velocity => v / jw,
            Quantity::Acceleration => v / (jw * jw),
        };
        if !(r.re.is_finite() && r.im.is_finite()) {
            return Err(format!("{}: a value at {f} Hz is not finite", c.item));
        }
        freqs.push(f);
        h.push(r);
    }
    if freqs.len() < 2 || freqs.windows(2).any(|w| w[1] <= w[0]) {
        return Err(format!(
            "{}: needs at least two lines at increasing frequencies",
            c.item
        ));
    }
    Ok(ToolFrf {
        origin,
        direction,
        freqs_hz: freqs,
        h,
    })
}
