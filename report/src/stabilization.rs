//! The stabilization diagram of a modal extraction as an SVG: one marker per pole at (frequency,
//! model order), its symbol the stability class (`o` new, `f` frequency, `v` vector, `d` damping,
//! `s` all stable), the selected poles as vertical lines and a mode indicator curve behind, its
//! dB range in the band scaled to the order axis (`ident modes-from-data` draws the first
//! singular value of the complex mode indicator function, whose peaks mark the modes).

use plotters::prelude::*;

use crate::plot::DrawError;
use crate::ReportError;

/// One pole of the diagram.
#[derive(Debug, Clone, Copy)]
pub struct DiagramPole {
    /// Model order.
    pub order: usize,
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Stability symbol: `o`, `f`, `v`, `d` or `s`.
    pub symbol: char,
}

fn colour(symbol: char) -> RGBColor {
    match symbol {
        's' => RGBColor(44, 160, 44),
        'd' => RGBColor(31, 119, 180),
        'v' => RGBColor(148, 103, 189),
        'f' => RGBColor(255, 127, 14),
        _ => RGBColor(170, 170, 170),
    }
}

/// Draws the diagram over `band_hz`; `indicator` is (frequency, dB) of the mode indicator curve
/// and `selected_hz` the chosen poles.
pub fn stabilization_svg(
    poles: &[DiagramPole],
    band_hz: (f64, f64),
    indicator: &[(f64, f64)],
    selected_hz: &[f64],
) -> Result<String, ReportError> {
    let chart_name = "stabilization";
    let max_order = poles.iter().map(|p| p.order).max().unwrap_or(1).max(1) as f64 + 1.0;
    let (lo, hi) = if band_hz.1 > band_hz.0 {
        band_hz
    } else {
        (0.0, 1.0)
    };
    let (db_lo, db_hi) = indicator
        .iter()
        .filter(|x| x.0 >= lo && x.0 <= hi)
        .map(|x| x.1)
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let to_order = |db: f64| {
        if db_hi > db_lo {
            (db - db_lo) / (db_hi - db_lo) * (max_order - 1.0)
        } else {
            0.0
        }
    };
    let mut out = String::new();
    {
        let draw =
            |root: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>| -> Result<(), DrawError> {
                root.fill(&WHITE)?;
                let mut chart = ChartBuilder::on(root)
                    .caption("Stabilization diagram", ("sans-serif", 18))
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(50)
                    .build_cartesian_2d(lo..hi, 0.0..max_order)?;
                chart
                    .configure_mesh()
                    .x_desc("frequency [Hz]")
                    .y_desc("model order")
                    .label_style(("sans-serif", 12))
                    .draw()?;
                chart.draw_series(LineSeries::new(
                    indicator
                        .iter()
                        .filter(|x| x.0 >= lo && x.0 <= hi && x.1.is_finite())
                        .map(|&(f, db)| (f, to_order(db))),
                    RGBColor(120, 120, 120).stroke_width(1),
                ))?;
                for &f in selected_hz {
                    chart.draw_series(LineSeries::new(
                        [(f, 0.0), (f, max_order)],
                        RED.mix(0.6).stroke_width(1),
                    ))?;
                }
                chart.draw_series(
                    poles
                        .iter()
                        .filter(|p| p.freq_hz >= lo && p.freq_hz <= hi)
                        .map(|p| {
                            Text::new(
                                p.symbol.to_string(),
                                (p.freq_hz, p.order as f64),
                                ("sans-serif", 10).into_font().color(&colour(p.symbol)),
                            )
                        }),
                )?;
                root.present()?;
                Ok(())
            };
        let root = SVGBackend::with_string(&mut out, (1000, 600)).into_drawing_area();
        draw(&root).map_err(|source| ReportError::Plot {
            chart: chart_name.to_string(),
            source,
        })?;
    }
    Ok(out)
}
