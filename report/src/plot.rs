//! The report's charts as SVG strings, drawn with plotters' SVG backend. Text is emitted as SVG
//! `<text>` (plotters' built-in layout estimate, no font files), so the browser draws it.

use plotters::prelude::*;

use crate::document::{CharacteristicReport, Drift, Parameter, SensitivityMap};
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
pub type DrawError = DrawingAreaErrorKind<std::io::Error>;

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

fn sci(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if (1e-2..1e4).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:.0e}")
    }
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

/// Measured amplitudes (with ±σ bars) and the model at each stage, log-log.
pub fn amplitude_chart(c: &CharacteristicReport) -> Result<String, ReportError> {
    svg("amplitude", (760, 380), |root| {
        let (f0, f1) = log_range(c.freqs_hz.iter().copied());
        let (a0, a1) = log_range(
            c.measured
                .iter()
                .copied()
                .chain(c.stages.iter().flat_map(|s| s.amplitude.iter().copied())),
        );
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!("{} — amplitude-frequency characteristic", c.label),
                (FONT, 16),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d(
                (f0..f1).log_scale().with_key_points(log_ticks(f0, f1)),
                (a0..a1).log_scale(),
            )?;
        chart
            .configure_mesh()
            .x_desc("frequency (Hz)")
            .y_desc(format!("|{}| ({})", c.quantity, c.unit))
            .x_label_formatter(&|v| sci(*v))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((FONT, 12))
            .draw()?;
        for s in &c.stages {
            let col = stage_colour(&s.stage);
            chart
                .draw_series(LineSeries::new(
                    c.freqs_hz
                        .iter()
                        .zip(&s.amplitude)
                        .filter(|(_, a)| **a > 0.0)
                        .map(|(f, a)| (*f, *a)),
                    col.stroke_width(2),
                ))?
                .label(format!("model, {}", s.stage))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], col.stroke_width(2))
                });
        }
        // Error bars (±σ, clipped to the axis) then the points.
        chart.draw_series(
            c.freqs_hz
                .iter()
                .zip(&c.measured)
                .zip(&c.sigma)
                .filter(|((_, a), _)| **a > 0.0)
                .map(|((f, a), s)| {
                    PathElement::new(
                        vec![(*f, (a - s).max(a0)), (*f, (a + s).min(a1))],
                        BLACK.stroke_width(1),
                    )
                }),
        )?;
        chart
            .draw_series(
                c.freqs_hz
                    .iter()
                    .zip(&c.measured)
                    .filter(|(_, a)| **a > 0.0)
                    .map(|(f, a)| Circle::new((*f, *a), 3, BLACK.filled())),
            )?
            .label("measured ± σ")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLACK.filled()));
        legend(&mut chart)
    })
}

/// Standardized residuals (measured − model)/σ of every stage but `initial`, with ±2 lines.
pub fn residual_chart(c: &CharacteristicReport) -> Result<String, ReportError> {
    svg("residual", (760, 260), |root| {
        let (f0, f1) = log_range(c.freqs_hz.iter().copied());
        let shown: Vec<_> = c.stages.iter().filter(|s| s.stage != "initial").collect();
        let m = shown
            .iter()
            .flat_map(|s| s.standardized_residual.iter().copied())
            .filter(|v| v.is_finite())
            .fold(3.0f64, |m, v| m.max(v.abs()))
            .min(1e6)
            * 1.1;
        let mut chart = ChartBuilder::on(root)
            .caption(format!("{} — standardized residuals", c.label), (FONT, 14))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(80)
            .build_cartesian_2d(
                (f0..f1).log_scale().with_key_points(log_ticks(f0, f1)),
                -m..m,
            )?;
        chart
            .configure_mesh()
            .x_desc("frequency (Hz)")
            .y_desc("(measured − model) / σ")
            .x_label_formatter(&|v| sci(*v))
            .label_style((FONT, 12))
            .draw()?;
        for lim in [-2.0, 2.0] {
            chart.draw_series(std::iter::once(PathElement::new(
                vec![(f0, lim), (f1, lim)],
                RGBColor(200, 80, 80).stroke_width(1),
            )))?;
        }
        for s in shown {
            let col = stage_colour(&s.stage);
            chart
                .draw_series(
                    c.freqs_hz
                        .iter()
                        .zip(&s.standardized_residual)
                        .map(|(f, r)| Circle::new((*f, r.clamp(-m, m)), 3, col.filled())),
                )?
                .label(s.stage.clone())
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, col.filled()));
        }
        legend(&mut chart)
    })
}

/// Identified / initial per parameter with ±σ bars (a forest plot of the table).
pub fn parameter_chart(params: &[Parameter]) -> Result<String, ReportError> {
    let n = params.len().max(1);
    svg("parameter", (760, 60 + 22 * n as u32), |root| {
        let ratio = |p: &Parameter| (p.initial != 0.0).then(|| p.identified / p.initial);
        let bar = |p: &Parameter| {
            p.std_error
                .zip(ratio(p))
                .map(|(s, r)| (r, s / p.initial.abs()))
        };
        let hi = params
            .iter()
            .filter_map(bar)
            .map(|(r, s)| r + s)
            .chain(params.iter().filter_map(ratio))
            .filter(|v| v.is_finite())
            .fold(2.0f64, f64::max)
            .min(100.0);
        let lo = params
            .iter()
            .filter_map(bar)
            .map(|(r, s)| r - s)
            .chain(params.iter().filter_map(ratio))
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::min)
            .max(-100.0);
        let names: Vec<String> = params.iter().map(|p| p.variable.clone()).collect();
        let mut chart = ChartBuilder::on(root)
            .caption(
                "identified / initial (bars: ± one standard error)",
                (FONT, 14),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(150)
            .build_cartesian_2d(lo..hi, (0..n as i32).into_segmented())?;
        chart
            .configure_mesh()
            .y_labels(n)
            .y_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) | SegmentValue::Exact(i) => {
                    names.get(*i as usize).cloned().unwrap_or_default()
                }
                SegmentValue::Last => String::new(),
            })
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
            if let Some((r, s)) = bar(p) {
                chart.draw_series(std::iter::once(PathElement::new(
                    vec![((r - s).max(lo), y.clone()), ((r + s).min(hi), y.clone())],
                    blue.stroke_width(2),
                )))?;
            }
            if let Some(r) = ratio(p).filter(|r| r.is_finite()) {
                chart.draw_series(std::iter::once(Circle::new(
                    (r.clamp(lo, hi), y),
                    4,
                    blue.filled(),
                )))?;
            }
        }
        Ok(())
    })
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
