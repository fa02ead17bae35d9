//! The report's charts as SVG strings, drawn with plotters' SVG backend. Text is emitted as SVG
//! `<text>` (plotters' built-in layout estimate, no font files), so the browser draws it.

use plotters::prelude::*;

use plotters::coord::ranged1d::{SegmentedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordi32;

use crate::document::{CharacteristicReport, Drift, NaturalMode, Parameter, SensitivityMap};
use crate::drift::deviation;
use crate::ReportError;

/// Colour of a stage's curve.
pub fn stage_colour(stage: &str) -> RGBColor {
    match stage {
        "initial" => RGBColor(150, 150, 150),
        "identified" => RGBColor(31, 119, 180),
        "diagnosed" => RGBColor(44, 160, 44),
        _ => RGBColor(214, 39, 40),
    }
}

const SERIES: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

const FONT: &str = "sans-serif";

/// What drawing on the SVG canvas can fail with.
pub use crate::DrawError;

fn err(chart: &str) -> impl Fn(DrawError) -> ReportError + '_ {
    move |source| ReportError::Plot {
        chart: chart.to_string(),
        source,
    }
}

/// Runs a drawing closure on a fresh SVG canvas and returns the SVG text.
fn svg(
    chart: &str,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, plotters::coord::Shift>) -> Result<(), DrawError>,
) -> Result<String, ReportError> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        root.fill(&WHITE).map_err(err(chart))?;
        draw(&root).map_err(err(chart))?;
        root.present().map_err(err(chart))?;
    }
    Ok(out)
}

/// Positive finite range of `values` widened to whole decades-ish margins for a log axis.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || hi <= 0.0 {
        return (1e-12, 1.0);
    }
    if hi <= lo {
        return (lo / 2.0, hi * 2.0);
    }
    (lo / 1.5, hi * 1.5)
}

/// The series legend, upper right, on a translucent box.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 12))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
}

/// Frequency ticks 1-2-5 per decade within `[lo, hi]` (plotters' own log ticks are decades only,
/// which leaves a 20-400 Hz axis one label below 100 Hz).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut out = Vec::new();
    if !(lo > 0.0 && hi > lo) {
        return out;
    }
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        for m in [1.0, 2.0, 5.0] {
            let v = m * decade;
            if v >= lo && v <= hi {
                out.push(v);
            }
        }
        decade *= 10.0;
    }
    out
}

/// The range of one chart axis and whether it is logarithmic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Lower end (same unit as the data).
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
    /// Logarithmic.
    pub log: bool,
}

impl Axis {
    /// The axis for `values`: logarithmic (with a margin of ×1.5) when the positive finite values
    /// span at least a decade, linear (with a 5 % margin) otherwise.
    pub fn for_values(values: impl Iterator<Item = f64>) -> Axis {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if !lo.is_finite() || !hi.is_finite() {
            return Axis {
                lo: 0.0,
                hi: 1.0,
                log: false,
            };
        }
        if lo > 0.0 && hi >= 10.0 * lo {
            let (lo, hi) = log_range([lo, hi].into_iter());
            return Axis { lo, hi, log: true };
        }
        let pad = if hi > lo {
            0.05 * (hi - lo)
        } else {
            0.05 * hi.abs().max(1e-300)
        };
        Axis {
            lo: lo - pad,
            hi: hi + pad,
            log: false,
        }
    }

    /// The value a fraction `t` (0 bottom/left, 1 top/right) along the axis.
    pub fn at(&self, t: f64) -> f64 {
        if self.log {
            self.lo * (self.hi / self.lo).powf(t)
        } else {
            self.lo + t * (self.hi - self.lo)
        }
    }

    /// Where `v` lies along the axis (0 at `lo`, 1 at `hi`): the inverse of [`Axis::at`].
    pub fn fraction(&self, v: f64) -> f64 {
        if self.log {
            (v / self.lo).ln() / (self.hi / self.lo).ln()
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }

    /// `v` clamped into the axis.
    fn clamp(&self, v: f64) -> f64 {
        v.clamp(self.lo, self.hi)
    }

    /// Whether `v` can be drawn on the axis (positive on a log axis).
    fn shows(&self, v: f64) -> bool {
        v.is_finite() && (!self.log || v > 0.0)
    }
}

/// Builds a 2-D chart with `x` and `y` linear or logarithmic as each says (log frequency axes
/// get 1-2-5 ticks) and runs the generic drawing function `$draw(&mut chart, args...)` on it.
macro_rules! on_axes {
    ($builder:expr, $x:expr, $y:expr, $draw:ident ( $($arg:expr),* )) => {{
        let (x, y): (Axis, Axis) = ($x, $y);
        let b = &mut $builder;
        match (x.log, y.log) {
            (true, true) => $draw(
                &mut b.build_cartesian_2d(
                    (x.lo..x.hi).log_scale().with_key_points(log_ticks(x.lo, x.hi)),
                    (y.lo..y.hi).log_scale(),
                )?,
                $($arg),*
            ),
            (true, false) => $draw(
                &mut b.build_cartesian_2d(
                    (x.lo..x.hi).log_scale().with_key_points(log_ticks(x.lo, x.hi)),
                    y.lo..y.hi,
                )?,
                $($arg),*
            ),
            (false, true) => $draw(
                &mut b.build_cartesian_2d(x.lo..x.hi, (y.lo..y.hi).log_scale())?,
                $($arg),*
            ),
            (false, false) => $draw(&mut b.build_cartesian_2d(x.lo..x.hi, y.lo..y.hi)?, $($arg),*),
        }
    }};
}

/// A chart on the SVG canvas with f64 axes of either kind.
type Chart<'a, 'b, X, Y> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<X, Y>>;

/// Label of a tick on a frequency or ratio axis: three significant digits, no float noise.
fn tick(v: f64) -> String {
    rfe::display::sig(v, 3)
}

/// Draws the mesh of a chart over frequency: the x axis in Hz with [`tick`] labels, `y_desc` and
/// `y_label` on the y axis.
fn frequency_mesh<'a, 'b: 'a, X, Y>(
    chart: &mut Chart<'a, 'b, X, Y>,
    y_desc: &str,
    y_label: &dyn Fn(&f64) -> String,
) -> Result<(), DrawError>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc(y_desc)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(y_label)
        .label_style((FONT, 12))
        .draw()
}

/// The builder of a chart over frequency: its caption, margins and label areas.
fn frequency_chart<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    caption: String,
    caption_size: u32,
    x_label_area: u32,
) -> ChartBuilder<'a, 'b, SVGBackend<'b>> {
    let mut b = ChartBuilder::on(root);
    b.caption(caption, (FONT, caption_size))
        .margin(10)
        .x_label_area_size(x_label_area)
        .y_label_area_size(80);
    b
}

/// The frequency axis of a characteristic's charts.
fn frequency_axis(c: &CharacteristicReport) -> Axis {
    Axis::for_values(c.freqs_hz.iter().copied().filter(|f| *f > 0.0))
}

/// Measured amplitudes (with ±σ bars), the model at each stage — smooth curves on the dense grid
/// for the identified and diagnosed models, a thin polyline through the measured lines for the
/// initial one — and the final model's natural frequencies as labelled vertical markers.
/// Frequency and amplitude axes are logarithmic where the data span a decade or more.
pub fn amplitude_chart(
    c: &CharacteristicReport,
    modes: &[NaturalMode],
) -> Result<String, ReportError> {
    svg("amplitude", (760, 380), |root| {
        let x = frequency_axis(c);
        let y = Axis::for_values(
            c.measured
                .iter()
                .copied()
                .chain(c.stages.iter().flat_map(|s| {
                    let dense = s.dense.iter().flat_map(|d| d.amplitude.iter().copied());
                    s.amplitude.iter().copied().chain(dense)
                })),
        );
        let caption = format!("{} — amplitude-frequency characteristic", c.label);
        let mut b = frequency_chart(root, caption, 16, 40);
        on_axes!(b, x, y, draw_amplitude(c, modes, x, y))
    })
}

fn draw_amplitude<'a, 'b: 'a, X, Y>(
    chart: &mut Chart<'a, 'b, X, Y>,
    c: &CharacteristicReport,
    modes: &[NaturalMode],
    x: Axis,
    y: Axis,
) -> Result<(), DrawError>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let y_label = |v: &f64| {
        if y.log {
            format!("{v:.0e}")
        } else {
            format!("{v:.2e}")
        }
    };
    frequency_mesh(chart, &format!("|{}| ({})", c.quantity, c.unit), &y_label)?;
    // The final model's natural frequencies: thin vertical markers, labelled along them.
    let grey = RGBColor(120, 120, 120);
    let in_view: Vec<&NaturalMode> = modes
        .iter()
        .filter(|m| m.freq_hz >= x.lo && m.freq_hz <= x.hi && x.shows(m.freq_hz))
        .collect();
    chart.draw_series(in_view.iter().map(|m| {
        PathElement::new(
            vec![(m.freq_hz, y.lo), (m.freq_hz, y.hi)],
            grey.mix(0.6).stroke_width(1),
        )
    }))?;
    let label = (FONT, 10)
        .into_font()
        .transform(FontTransform::Rotate270)
        .color(&grey);
    // Labels where they do not overlap the previous one (2 % of the width apart).
    let mut last = f64::NEG_INFINITY;
    let labelled: Vec<&&NaturalMode> = in_view
        .iter()
        .filter(|m| {
            let t = x.fraction(m.freq_hz);
            let free = t - last >= 0.02;
            if free {
                last = t;
            }
            free
        })
        .collect();
    chart.draw_series(labelled.iter().map(|m| {
        Text::new(
            format!("mode {} · {} Hz", m.number, rfe::display::sig(m.freq_hz, 3)),
            (m.freq_hz, y.at(0.03)),
            label.clone(),
        )
    }))?;
    for s in &c.stages {
        let col = stage_colour(&s.stage);
        let (points, style): (Vec<(f64, f64)>, ShapeStyle) = match &s.dense {
            Some(d) => (
                d.freqs_hz
                    .iter()
                    .zip(&d.amplitude)
                    .map(|(f, a)| (*f, *a))
                    .collect(),
                col.stroke_width(2),
            ),
            None => (
                c.freqs_hz
                    .iter()
                    .zip(&s.amplitude)
                    .map(|(f, a)| (*f, *a))
                    .collect(),
                col.stroke_width(1),
            ),
        };
        let width = style.stroke_width;
        chart
            .draw_series(LineSeries::new(
                points
                    .into_iter()
                    .filter(|(f, a)| x.shows(*f) && y.shows(*a))
                    .map(|(f, a)| (f, y.clamp(a))),
                style,
            ))?
            .label(format!("model, {}", s.stage))
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(width))
            });
    }
    let measured = || {
        c.freqs_hz
            .iter()
            .zip(&c.measured)
            .zip(&c.sigma)
            .filter(|((f, a), _)| x.shows(**f) && y.shows(**a))
    };
    // Error bars (±σ, clipped to the axis) then the points.
    chart.draw_series(measured().map(|((f, a), s)| {
        let low = if y.log && a - s <= 0.0 {
            y.lo
        } else {
            y.clamp(a - s)
        };
        PathElement::new(vec![(*f, low), (*f, y.clamp(a + s))], BLACK.stroke_width(1))
    }))?;
    chart
        .draw_series(
            measured().map(|((f, a), _)| Circle::new((*f, y.clamp(*a)), 3, BLACK.filled())),
        )?
        .label("measured ± σ")
        .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
    legend(chart)
}

/// Measured and model phase (degrees) where the data have phase: the dense model curves of the
/// identified and diagnosed stages (broken where they wrap at ±180°) over the measured points.
pub fn phase_chart(c: &CharacteristicReport) -> Result<String, ReportError> {
    svg("phase", (760, 260), |root| {
        let x = frequency_axis(c);
        let y = Axis {
            lo: -180.0,
            hi: 180.0,
            log: false,
        };
        let mut b = frequency_chart(root, format!("{} — phase", c.label), 14, 35);
        on_axes!(b, x, y, draw_phase(c, x))
    })
}

fn draw_phase<'a, 'b: 'a, X, Y>(
    chart: &mut Chart<'a, 'b, X, Y>,
    c: &CharacteristicReport,
    x: Axis,
) -> Result<(), DrawError>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    frequency_mesh(chart, "phase (°)", &|v| format!("{v:.0}"))?;
    let deg = |r: f64| r.to_degrees().clamp(-180.0, 180.0);
    for s in &c.stages {
        let Some((d, phase)) = s
            .dense
            .as_ref()
            .and_then(|d| Some((d, d.phase_rad.as_ref()?)))
        else {
            continue;
        };
        let col = stage_colour(&s.stage);
        // One polyline per stretch between wraps.
        let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for (f, p) in d.freqs_hz.iter().zip(phase).filter(|(f, _)| x.shows(**f)) {
            let v = deg(*p);
            let wrap = pieces
                .last()
                .and_then(|l| l.last())
                .is_some_and(|(_, last)| (v - last).abs() > 180.0);
            if wrap {
                pieces.push(Vec::new());
            }
            if let Some(l) = pieces.last_mut() {
                l.push((*f, v));
            }
        }
        for (i, piece) in pieces.into_iter().enumerate() {
            let series = chart.draw_series(LineSeries::new(piece, col.stroke_width(2)))?;
            if i == 0 {
                series
                    .label(format!("model, {}", s.stage))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2))
                    });
            }
        }
    }
    if let Some(p) = &c.measured_phase_rad {
        chart
            .draw_series(
                c.freqs_hz
                    .iter()
                    .zip(p)
                    .filter(|(f, _)| x.shows(**f))
                    .map(|(f, p)| Circle::new((*f, deg(*p)), 3, BLACK.filled())),
            )?
            .label("measured")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
    }
    legend(chart)
}

/// Standardized residuals (measured − model)/σ, in units of σ, of every stage but `initial`, with
/// the ±2σ guides.
pub fn residual_chart(c: &CharacteristicReport) -> Result<String, ReportError> {
    svg("residual", (760, 260), |root| {
        let x = frequency_axis(c);
        let m = c
            .stages
            .iter()
            .filter(|s| s.stage != "initial")
            .flat_map(|s| s.standardized_residual.iter().copied())
            .filter(|v| v.is_finite())
            .fold(3.0f64, |m, v| m.max(v.abs()))
            .min(1e6)
            * 1.1;
        let y = Axis {
            lo: -m,
            hi: m,
            log: false,
        };
        let caption = format!("{} — standardized residuals (units of σ)", c.label);
        let mut b = frequency_chart(root, caption, 14, 35);
        on_axes!(b, x, y, draw_residuals(c, x, m))
    })
}

fn draw_residuals<'a, 'b: 'a, X, Y>(
    chart: &mut Chart<'a, 'b, X, Y>,
    c: &CharacteristicReport,
    x: Axis,
    m: f64,
) -> Result<(), DrawError>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    frequency_mesh(chart, "(measured − model) / σ", &|v| {
        format!("{}σ", rfe::display::sig(*v, 2))
    })?;
    let red = RGBColor(200, 80, 80);
    for lim in [-2.0, 2.0] {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(x.lo, lim), (x.hi, lim)],
            red.stroke_width(1),
        )))?;
        chart.draw_series(std::iter::once(Text::new(
            format!("{lim:+}σ"),
            (x.at(0.005), lim),
            (FONT, 10).into_font().color(&red),
        )))?;
    }
    for s in c.stages.iter().filter(|s| s.stage != "initial") {
        let col = stage_colour(&s.stage);
        chart
            .draw_series(
                c.freqs_hz
                    .iter()
                    .zip(&s.standardized_residual)
                    .filter(|(f, _)| x.shows(**f))
                    .map(|(f, r)| Circle::new((*f, r.clamp(-m, m)), 3, col.filled())),
            )?
            .label(s.stage.clone())
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, col.filled()));
    }
    legend(chart)
}

/// Identified / initial per parameter with ±σ bars (a forest plot of the table). The ratio axis
/// is logarithmic when the ratios span a decade or more (a first fit far from its start is drawn,
/// not clipped); a ratio that cannot be drawn there (zero or negative) is an open circle at the
/// left edge.
pub fn parameter_chart(params: &[Parameter]) -> Result<String, ReportError> {
    let n = params.len().max(1);
    svg("parameter", (760, 60 + 22 * n as u32), |root| {
        let ratio = |p: &Parameter| (p.initial != 0.0).then(|| p.identified / p.initial);
        let ratios: Vec<f64> = params
            .iter()
            .filter_map(ratio)
            .filter(|r| r.is_finite())
            .collect();
        let positive = ratios.iter().copied().filter(|r| *r > 0.0);
        let spans = {
            let lo = positive.clone().fold(f64::INFINITY, f64::min);
            let hi = positive.clone().fold(0.0f64, f64::max);
            lo.is_finite() && hi >= 10.0 * lo
        };
        let x = if spans {
            let (lo, hi) = log_range(positive.chain([1.0]));
            Axis { lo, hi, log: true }
        } else {
            let bars = params.iter().filter_map(|p| {
                let r = ratio(p)?;
                let s = p.std_error? / p.initial.abs();
                Some([r - s, r + s])
            });
            let v: Vec<f64> = ratios
                .iter()
                .copied()
                .chain(bars.flatten())
                .chain([0.0, 2.0])
                .filter(|v| v.is_finite())
                .collect();
            Axis {
                lo: v.iter().copied().fold(0.0, f64::min),
                hi: v.iter().copied().fold(2.0, f64::max),
                log: false,
            }
        };
        let names: Vec<String> = params.iter().map(|p| p.variable.clone()).collect();
        let mut b = ChartBuilder::on(root);
        b.caption(
            if x.log {
                "identified / initial, log scale (bars: ± one standard error)"
            } else {
                "identified / initial (bars: ± one standard error)"
            },
            (FONT, 14),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(150);
        let y = (0..n as i32).into_segmented();
        match x.log {
            true => draw_parameters(
                &mut b.build_cartesian_2d((x.lo..x.hi).log_scale(), y)?,
                params,
                &names,
                x,
            ),
            false => draw_parameters(&mut b.build_cartesian_2d(x.lo..x.hi, y)?, params, &names, x),
        }
    })
}

fn draw_parameters<'a, 'b: 'a, X>(
    chart: &mut Chart<'a, 'b, X, SegmentedCoord<RangedCoordi32>>,
    params: &[Parameter],
    names: &[String],
    x: Axis,
) -> Result<(), DrawError>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let n = params.len().max(1);
    chart
        .configure_mesh()
        .y_labels(n)
        .y_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                names.get(*i as usize).cloned().unwrap_or_default()
            }
            SegmentValue::Last => String::new(),
        })
        .x_label_formatter(&|v| tick(*v))
        .x_desc("identified / initial")
        .label_style((FONT, 11))
        .draw()?;
    chart.draw_series(std::iter::once(PathElement::new(
        vec![(1.0, SegmentValue::Exact(0)), (1.0, SegmentValue::Last)],
        RGBColor(150, 150, 150).stroke_width(1),
    )))?;
    let blue = stage_colour("identified");
    for (i, p) in params.iter().enumerate() {
        let y = SegmentValue::CenterOf(i as i32);
        let Some(r) = (p.initial != 0.0)
            .then(|| p.identified / p.initial)
            .filter(|r| r.is_finite())
        else {
            continue;
        };
        if let Some(s) = p.std_error.map(|s| s / p.initial.abs()) {
            let low = if x.log && r - s <= 0.0 {
                x.lo
            } else {
                x.clamp(r - s)
            };
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(low, y.clone()), (x.clamp(r + s), y.clone())],
                blue.stroke_width(2),
            )))?;
        }
        if x.shows(r) {
            chart.draw_series(std::iter::once(Circle::new(
                (x.clamp(r), y),
                4,
                blue.filled(),
            )))?;
        } else {
            chart.draw_series(std::iter::once(Circle::new(
                (x.lo, y),
                4,
                blue.stroke_width(1),
            )))?;
        }
    }
    Ok(())
}

/// Relative MI per parameter (rows) and characteristic (columns), log colour scale.
pub fn sensitivity_chart(map: &SensitivityMap) -> Result<String, ReportError> {
    let (nr, nc) = (
        map.parameters.len().max(1),
        map.characteristics.len().max(1),
    );
    svg("sensitivity", (760, 80 + 16 * nr as u32), |root| {
        let max = map
            .relative
            .iter()
            .flatten()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let floor = max * 1e-4;
        let rows = map.parameters.clone();
        let cols = map.characteristics.clone();
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!("relative band sensitivity MIr, {:.0}-{:.0} Hz (dark = sensitive; log scale over 4 decades)", map.band_hz[0], map.band_hz[1]),
                (FONT, 14),
            )
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(120)
            .build_cartesian_2d((0..nc as i32).into_segmented(), (0..nr as i32).into_segmented())?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(nc)
            .y_labels(nr)
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                    cols.get(*i as usize).cloned().unwrap_or_default()
                }
                SegmentValue::Last => String::new(),
            })
            .y_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                    rows.get(*i as usize).cloned().unwrap_or_default()
                }
                SegmentValue::Last => String::new(),
            })
            .label_style((FONT, 10))
            .draw()?;
        let cells = map.relative.iter().enumerate().flat_map(|(r, row)| {
            row.iter().enumerate().map(move |(c, v)| {
                let t = if max > 0.0 && *v > floor {
                    ((v / floor).log10() / (max / floor).log10()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let shade = (255.0 * (1.0 - t)) as u8;
                let colour = RGBColor(shade, shade, 255);
                Rectangle::new(
                    [
                        (SegmentValue::Exact(c as i32), SegmentValue::Exact(r as i32)),
                        (
                            SegmentValue::Exact(c as i32 + 1),
                            SegmentValue::Exact(r as i32 + 1),
                        ),
                    ],
                    colour.filled(),
                )
            })
        });
        chart.draw_series(cells)?;
        Ok(())
    })
}

/// Deviation of every parameter from the baseline run, in standard errors, run by run, with the
/// ±k alarm band.
pub fn drift_chart(d: &Drift) -> Result<String, ReportError> {
    svg("drift", (760, 360), |root| {
        let n = d.runs.len();
        let devs: Vec<Vec<(usize, f64)>> = d
            .parameters
            .iter()
            .map(|p| {
                (0..n)
                    .filter_map(|j| deviation(p, d.baseline, j).map(|v| (j, v)))
                    .collect()
            })
            .collect();
        let m = devs
            .iter()
            .flatten()
            .map(|(_, v)| v.abs())
            .filter(|v| v.is_finite())
            .fold(d.k_sigma * 1.5, f64::max)
            .min(1e6);
        let runs = d.runs.clone();
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "drift from the baseline run (alarm beyond ±{} σ)",
                    d.k_sigma
                ),
                (FONT, 14),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5).max(0.5), -m..m)?;
        chart
            .configure_mesh()
            .x_labels(n.min(12))
            .x_label_formatter(&|v| {
                let i = v.round();
                if (v - i).abs() < 1e-6 && i >= 0.0 {
                    runs.get(i as usize)
                        .map(|s| s.chars().take(10).collect())
                        .unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .x_desc("run")
            .y_desc("(x − x_baseline) / σ")
            .label_style((FONT, 11))
            .draw()?;
        for lim in [-d.k_sigma, d.k_sigma] {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(-0.5, lim), (n as f64 - 0.5, lim)],
                RGBColor(214, 39, 40).stroke_width(1),
            )))?;
        }
        for (i, (p, pts)) in d.parameters.iter().zip(&devs).enumerate() {
            let col = SERIES[i % SERIES.len()];
            let pts: Vec<(f64, f64)> = pts
                .iter()
                .map(|(j, v)| (*j as f64, v.clamp(-m, m)))
                .collect();
            chart.draw_series(LineSeries::new(
                pts.iter().copied(),
                col.stroke_width(if p.alarm { 3 } else { 1 }),
            ))?;
            chart.draw_series(pts.iter().map(|xy| Circle::new(*xy, 3, col.filled())))?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_are_logarithmic_where_the_data_span_a_decade() {
        let a = Axis::for_values([20.0, 55.0, 400.0].into_iter());
        assert!(a.log && a.lo < 20.0 && a.hi > 400.0, "{a:?}");
        let a = Axis::for_values([2e-7, 9e-7].into_iter());
        assert!(!a.log && a.lo < 2e-7 && a.hi > 9e-7, "{a:?}");
        // Zero or negative values keep an axis linear.
        assert!(!Axis::for_values([0.0, 1.0, 500.0].into_iter()).log);
        let a = Axis::for_values(std::iter::empty());
        assert!(!a.log && a.hi > a.lo);
        assert!((Axis::for_values([1.0, 100.0].into_iter()).at(0.5) - 10.0).abs() < 1e-9);
    }

    fn param(initial: f64, identified: f64) -> Parameter {
        Parameter {
            variable: format!("k{identified}"),
            sdes: "1".into(),
            parameter: "k".into(),
            unit: "N/um".into(),
            initial,
            identified,
            std_error: Some(0.1 * identified.abs().max(1.0)),
            variability: None,
            at_bound: None,
        }
    }

    #[test]
    fn a_fit_far_from_its_start_is_drawn_on_a_log_axis_not_clipped() {
        // 1919 / 10: the demo's first fit of k22 (the old linear axis stopped at 100).
        let far =
            parameter_chart(&[param(10.0, 1919.0), param(9.0, 0.0), param(5.0, 5.5)]).unwrap();
        assert!(far.contains("log scale"), "a log ratio axis");
        assert!(
            far.contains(">\n100\n</text>"),
            "the axis reaches beyond 100"
        );
        let near = parameter_chart(&[param(10.0, 12.0), param(5.0, 4.0)]).unwrap();
        assert!(!near.contains("log scale"));
    }

    #[test]
    fn frequency_ticks_are_1_2_5_per_decade_inside_the_range() {
        assert_eq!(
            super::log_ticks(18.0, 450.0),
            vec![20.0, 50.0, 100.0, 200.0]
        );
        assert_eq!(super::log_ticks(1.0, 10.0), vec![1.0, 2.0, 5.0, 10.0]);
        assert!(super::log_ticks(0.0, 10.0).is_empty());
    }
}
