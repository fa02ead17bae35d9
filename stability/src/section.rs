//! The lobes as data: the one serde type written by `ident stability --json` and held by the
//! identification report's stability section (`report::Report::stability`), with its JSON Schema
//! generated from it ([`json_schema`], `docs/stability.schema.json`), and the SVG chart drawn from
//! it by both the command and the report.
//!
//! Units are the ones an operator reads: depths in mm, speeds in rpm, frequencies in Hz, shares
//! and loss factors dimensionless. Every number is finite; a depth no lobe reaches (the cut is
//! stable at any depth there) is `null`.

use std::fmt::Write as _;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::bands::Band;
use crate::cut::{Cut, Operation};
use crate::Lobes;

/// Schema identifier of the `--json` document.
pub const SCHEMA: &str = "ident.stability/1";

/// z of the 5–95 % band: the band is `depth ∓ Z95 σ`.
pub const Z95: f64 = 1.6448536269514722;

/// Chatter stability of a model for one cut.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Stability {
    /// Always [`SCHEMA`].
    #[schemars(extend("const" = "ident.stability/1"))]
    pub schema: String,
    /// The cutting file.
    pub cut: String,
    /// Its `note`, when it has one.
    pub note: Option<String>,
    /// `turning` or `milling`.
    #[schemars(extend("enum" = ["turning", "milling"]))]
    pub operation: String,
    /// The spindle-speed range of interest (rpm).
    pub speed_rpm: [f64; 2],
    /// The lowest critical depth over the range: the depth the machine can cut at every speed.
    pub minimum: Minimum,
    /// The modes that set the limit at the minimum, largest share first (shares ≥ 5 %).
    pub limiting: Vec<LimitingMode>,
    /// The tool's own modes' share of the limit at the minimum (0 without tool modes).
    pub tool_share: f64,
    /// Where the band's covariance came from, and what it assumes; empty without a band.
    pub band_notes: Vec<String>,
    /// The boundary at each speed of the grid.
    pub points: Vec<Point>,
}

/// The lowest critical depth over the speed range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Minimum {
    /// Spindle speed (rpm).
    pub speed_rpm: f64,
    /// Critical axial depth (mm).
    pub depth_mm: f64,
    /// 5 % and 95 % quantiles of the depth there (mm, linear band), `null` without a covariance.
    pub band_mm: Option<[f64; 2]>,
    /// Standard deviation of the depth there (mm, linear propagation), `null` without a
    /// covariance.
    pub sigma_mm: Option<f64>,
    /// Chatter frequency (Hz).
    pub chatter_hz: f64,
    /// Lobe number (0 = the rightmost lobe).
    pub lobe: usize,
}

/// A mode that sets the limit, and where its energy is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LimitingMode {
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Loss factor η.
    pub loss_factor: f64,
    /// Share of the limit (of `Re G` at the chatter frequency; all modes and the tool sum to 1).
    pub share: f64,
    /// Bodies by kinetic-energy share, largest first (≥ 5 %).
    pub bodies: Vec<Share>,
    /// Joints (SDEs) by strain-energy share, largest first (≥ 5 %).
    pub joints: Vec<Share>,
}

/// A name and its share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Share {
    /// Body or SDE name.
    pub name: String,
    /// Share (0–1).
    pub share: f64,
}

/// The boundary at one spindle speed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// Spindle speed (rpm).
    pub speed_rpm: f64,
    /// Critical axial depth (mm); `null` where no lobe reaches this speed.
    pub depth_mm: Option<f64>,
    /// Linear 5–95 % band (mm), when there is a covariance.
    pub band_mm: Option<[f64; 2]>,
    /// Monte Carlo 5–95 % band (mm), when asked for.
    pub monte_carlo_mm: Option<[f64; 2]>,
    /// Chatter frequency (Hz), `null` where no lobe reaches this speed.
    pub chatter_hz: Option<f64>,
    /// Lobe number.
    pub lobe: usize,
    /// Natural frequency (Hz) of the mode with the largest share here.
    pub dominant_mode_hz: Option<f64>,
}

fn mm(x: f64) -> Option<f64> {
    x.is_finite().then_some(x * 1e3)
}

fn band_at(b: &Band, i: usize) -> Option<[f64; 2]> {
    Some([mm(b.lower[i])?, mm(b.upper[i])?])
}

fn shares(v: &[(String, f64)]) -> Vec<Share> {
    v.iter()
        .map(|(name, share)| Share {
            name: name.clone(),
            share: *share,
        })
        .collect()
}

impl Stability {
    /// The section of `lobes` of `cut`, with the Monte Carlo band when computed and the notes on
    /// the covariance the linear band used.
    pub fn new(
        cut: &Cut,
        lobes: &Lobes,
        monte_carlo: Option<&Band>,
        band_notes: &[String],
    ) -> Self {
        let m = &lobes.points[lobes.minimum];
        let points = lobes
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| Point {
                speed_rpm: p.speed_rpm,
                depth_mm: mm(p.depth),
                band_mm: lobes.band.as_ref().and_then(|b| band_at(b, i)),
                monte_carlo_mm: monte_carlo.and_then(|b| band_at(b, i)),
                chatter_hz: p.depth.is_finite().then_some(p.chatter_hz),
                lobe: p.lobe,
                dominant_mode_hz: lobes.dominant_hz.get(i).copied().filter(|f| f.is_finite()),
            })
            .collect();
        Stability {
            schema: SCHEMA.into(),
            cut: cut.origin.clone(),
            note: cut.note.clone(),
            operation: match cut.operation {
                Operation::Turning(_) => "turning",
                Operation::Milling(_) => "milling",
            }
            .into(),
            speed_rpm: [cut.speed_rpm.0, cut.speed_rpm.1],
            minimum: Minimum {
                speed_rpm: m.speed_rpm,
                // `lobes()` refuses a range no lobe reaches, so the minimum is finite.
                depth_mm: m.depth * 1e3,
                band_mm: lobes.band.as_ref().and_then(|b| band_at(b, lobes.minimum)),
                sigma_mm: lobes.band.as_ref().and_then(|b| mm(b.sigma[lobes.minimum])),
                chatter_hz: m.chatter_hz,
                lobe: m.lobe,
            },
            limiting: lobes
                .limiting
                .iter()
                .map(|l| LimitingMode {
                    freq_hz: l.freq_hz,
                    loss_factor: l.loss_factor,
                    share: l.share,
                    bodies: shares(&l.bodies),
                    joints: shares(&l.joints),
                })
                .collect(),
            tool_share: lobes.tool_share,
            band_notes: if lobes.band.is_some() {
                band_notes.to_vec()
            } else {
                Vec::new()
            },
            points,
        }
    }

    /// The name of the judged quantity in a run history: the minimum critical depth over this
    /// cut's speed range, e.g. `"stable depth 200–2000 rpm (fwd32j-face-milling)"`.
    pub fn quantity_name(&self) -> String {
        let stem = std::path::Path::new(&self.cut)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.cut.clone());
        format!(
            "stable depth {:.0}–{:.0} rpm ({stem})",
            self.speed_rpm[0], self.speed_rpm[1]
        )
    }

    /// One paragraph: the minimum with its band, then the limiting modes with their bodies and
    /// joints.
    pub fn summary(&self) -> String {
        let m = &self.minimum;
        let mut s = format!(
            "minimum critical depth {:.4} mm at {:.0} rpm (chatter {:.1} Hz, lobe {})",
            m.depth_mm, m.speed_rpm, m.chatter_hz, m.lobe
        );
        if let Some([lo, hi]) = m.band_mm {
            let _ = write!(s, ", 5–95 %: {lo:.4}–{hi:.4} mm");
        }
        s.push('\n');
        for l in &self.limiting {
            let named = |v: &[Share], n: usize, prefix: &str| -> String {
                v.iter()
                    .take(n)
                    .map(|x| format!("{prefix}{} {:.0}%", x.name, 100.0 * x.share))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let _ = writeln!(
                s,
                "  mode {:.1} Hz (η {:.3}): {:.0}% of the limit; bodies {}; joints {}",
                l.freq_hz,
                l.loss_factor,
                100.0 * l.share,
                named(&l.bodies, 3, ""),
                named(&l.joints, 4, "SDE ")
            );
        }
        if self.tool_share.abs() >= 0.05 {
            let _ = writeln!(
                s,
                "  tool modes: {:.0}% of the limit",
                100.0 * self.tool_share
            );
        }
        s
    }

    /// A self-contained SVG chart: critical depth (mm) against spindle speed, the linear band
    /// shaded, the Monte Carlo band dashed, the minimum marked.
    pub fn svg(&self) -> String {
        let (w, h, left, bottom, top, right) = (720.0, 420.0, 64.0, 48.0, 24.0, 16.0);
        let [s0, s1] = self.speed_rpm;
        let ymax = self
            .points
            .iter()
            .flat_map(|p| {
                p.depth_mm
                    .into_iter()
                    .chain(p.band_mm.map(|b| b[1]))
                    .chain(p.monte_carlo_mm.map(|b| b[1]))
            })
            .fold(0.0, f64::max)
            .max(1e-9)
            * 1.1;
        let x = |s: f64| left + (s - s0) / (s1 - s0).max(f64::MIN_POSITIVE) * (w - left - right);
        let y = |d: f64| h - bottom - d.clamp(0.0, ymax) / ymax * (h - bottom - top);
        let line = |f: &dyn Fn(&Point) -> Option<f64>| -> Vec<String> {
            self.points
                .iter()
                .filter_map(|p| Some(format!("{:.1},{:.1}", x(p.speed_rpm), y(f(p)?))))
                .collect()
        };
        let mut s = format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n"
        );
        if self.points.iter().any(|p| p.band_mm.is_some()) {
            let mut outline = line(&|p| p.band_mm.map(|b| b[1]));
            outline.extend(line(&|p| p.band_mm.map(|b| b[0])).into_iter().rev());
            let _ = writeln!(
                s,
                "<polygon points=\"{}\" fill=\"#9ecae1\" fill-opacity=\"0.6\" stroke=\"none\"><title>5–95 % band (linear)</title></polygon>",
                outline.join(" ")
            );
        }
        if self.points.iter().any(|p| p.monte_carlo_mm.is_some()) {
            for k in 0..2 {
                let _ = writeln!(
                    s,
                    "<polyline points=\"{}\" fill=\"none\" stroke=\"#e6550d\" stroke-dasharray=\"4 3\"><title>5–95 % band (Monte Carlo)</title></polyline>",
                    line(&|p| p.monte_carlo_mm.map(|b| b[k])).join(" ")
                );
            }
        }
        let _ = writeln!(
            s,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"#08519c\" stroke-width=\"1.5\"><title>critical depth</title></polyline>",
            line(&|p| p.depth_mm).join(" ")
        );
        let m = &self.minimum;
        let _ = writeln!(
            s,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"#cb181d\"><title>minimum {:.4} mm at {:.0} rpm</title></circle>",
            x(m.speed_rpm),
            y(m.depth_mm),
            m.depth_mm,
            m.speed_rpm
        );
        let (x0, y0, x1, y1) = (left, h - bottom, w - right, top);
        let _ = writeln!(
            s,
            "<path d=\"M{x0},{y1} L{x0},{y0} L{x1},{y0}\" fill=\"none\" stroke=\"black\"/>"
        );
        for i in 0..=5 {
            let sp = s0 + (s1 - s0) * i as f64 / 5.0;
            let d = ymax * i as f64 / 5.0;
            let _ = writeln!(
                s,
                "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{:.0}</text>\n<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{:.3}</text>",
                x(sp),
                y0 + 18.0,
                sp,
                x0 - 6.0,
                y(d) + 4.0,
                d
            );
        }
        let _ = writeln!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">spindle speed (rpm)</text>\n<text transform=\"translate(16,{:.1}) rotate(-90)\" text-anchor=\"middle\">critical axial depth (mm)</text>\n</svg>",
            (x0 + x1) / 2.0,
            h - 8.0,
            (y0 + y1) / 2.0
        );
        s
    }
}

/// The JSON Schema of [`Stability`] (`docs/stability.schema.json` is this, pretty-printed;
/// `IDENT_BLESS=1 cargo test --workspace --test schema` rewrites it).
pub fn json_schema() -> serde_json::Value {
    let mut s = serde_json::Value::from(schemars::schema_for!(Stability));
    if let Some(o) = s.as_object_mut() {
        o.insert("$id".into(), SCHEMA.into());
        o.insert("title".into(), SCHEMA.into());
        o.insert(
            "description".into(),
            "Chatter stability lobes of a model for one cut (docs/stability.md), generated from stability::section::Stability: `ident stability --json` and the report's `stability` section. Depths in mm, speeds in rpm, frequencies in Hz.".into(),
        );
    }
    s
}
