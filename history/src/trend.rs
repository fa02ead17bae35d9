//! The trend page: per parameter, its series over the runs with the normal centre and the
//! Shewhart limits of each judged run, the baseline window shaded, the runs with an alarm on it
//! marked and the change points estimated; then the operator's table of the newest run: every
//! chart's statistic beside its limit, the open changes and the parameters not judged with why.
//! One self-contained HTML file with inline SVG (plotters; text is SVG `<text>`, the browser
//! draws it). Text is escaped by the report's escaper ([`report::html::escape`]).

use plotters::prelude::*;

use crate::judge::{Judgement, Verdict, VECTOR};
use crate::record::RunRecord;
use report::html::escape;

const FONT: &str = "sans-serif";

/// One parameter's chart as SVG text: `None` when plotters fails (the page says so).
pub fn parameter_chart(
    variable: &str,
    runs: &[RunRecord],
    judgements: &[Judgement],
) -> Option<String> {
    let values: Vec<(usize, f64)> = runs
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.parameter(variable).map(|p| (i, p.in_unit())))
        .collect();
    let unit = runs
        .iter()
        .find_map(|r| r.parameter(variable).map(|p| p.unit.clone()))
        .unwrap_or_default();
    let judged: Vec<(usize, [f64; 3], bool)> = judgements
        .iter()
        .enumerate()
        .filter(|(_, j)| j.verdict == Verdict::Judged)
        .filter_map(|(i, j)| {
            let p = j.parameters.iter().find(|p| p.variable == variable)?;
            let alarm = j.alarms.iter().any(|a| a.subject == variable);
            Some((i, [p.limits[0], p.centre, p.limits[1]], alarm))
        })
        .collect();
    let all = values
        .iter()
        .map(|(_, v)| *v)
        .chain(judged.iter().flat_map(|(_, l, _)| l.iter().copied()))
        .filter(|v| v.is_finite());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return None;
    }
    let pad = ((hi - lo) * 0.08).max(hi.abs() * 1e-6).max(1e-12);
    let n = runs.len().max(1);
    // The baseline window of the newest judged run, as run indices.
    let baseline: Vec<usize> = judgements
        .iter()
        .rev()
        .find(|j| j.verdict == Verdict::Judged)
        .map(|j| {
            runs.iter()
                .enumerate()
                .filter(|(_, r)| j.baseline_runs.contains(&r.run_id))
                .map(|(i, _)| i)
                .collect()
        })
        .unwrap_or_default();
    // Change points of the alarms on this parameter.
    let change_points: Vec<usize> = judgements
        .iter()
        .flat_map(|j| j.alarms.iter())
        .filter(|a| a.subject == variable)
        .filter_map(|a| runs.iter().position(|r| r.run_id == a.since_run))
        .collect();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (760, 300)).into_drawing_area();
        root.fill(&WHITE).ok()?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{variable} ({unit})"), (FONT, 14))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5f64..(n as f64 - 0.5), (lo - pad)..(hi + pad))
            .ok()?;
        chart
            .configure_mesh()
            .x_labels(n.min(12))
            .x_desc("run (oldest first)")
            .y_desc(unit.as_str())
            .label_style((FONT, 11))
            .draw()
            .ok()?;
        if let (Some(a), Some(b)) = (baseline.first(), baseline.last()) {
            chart
                .draw_series(std::iter::once(Rectangle::new(
                    [(*a as f64 - 0.5, lo - pad), (*b as f64 + 0.5, hi + pad)],
                    RGBColor(230, 230, 230).filled(),
                )))
                .ok()?;
        }
        for c in &change_points {
            chart
                .draw_series(LineSeries::new(
                    [(*c as f64 - 0.5, lo - pad), (*c as f64 - 0.5, hi + pad)],
                    RGBColor(255, 127, 14).stroke_width(2),
                ))
                .ok()?;
        }
        let limit_style = RGBColor(214, 39, 40).stroke_width(1);
        for k in [0, 2] {
            chart
                .draw_series(LineSeries::new(
                    judged.iter().map(|(i, l, _)| (*i as f64, l[k])),
                    limit_style,
                ))
                .ok()?;
        }
        chart
            .draw_series(LineSeries::new(
                judged.iter().map(|(i, l, _)| (*i as f64, l[1])),
                RGBColor(127, 127, 127).stroke_width(1),
            ))
            .ok()?;
        let blue = RGBColor(31, 119, 180);
        chart
            .draw_series(LineSeries::new(
                values.iter().map(|(i, v)| (*i as f64, *v)),
                blue.stroke_width(1),
            ))
            .ok()?;
        chart
            .draw_series(
                values
                    .iter()
                    .map(|(i, v)| Circle::new((*i as f64, *v), 3, blue.filled())),
            )
            .ok()?;
        chart
            .draw_series(
                judged
                    .iter()
                    .filter(|(_, _, a)| *a)
                    .filter_map(|(i, _, _)| {
                        let v = values.iter().find(|(j, _)| j == i)?.1;
                        Some(Cross::new(
                            (*i as f64, v),
                            6,
                            RGBColor(214, 39, 40).stroke_width(2),
                        ))
                    }),
            )
            .ok()?;
        root.present().ok()?;
    }
    Some(svg)
}

/// The whole page: a table of the runs with their judgement, then one chart per parameter.
pub fn page(title: &str, runs: &[RunRecord], judgements: &[Judgement]) -> String {
    let mut names: Vec<String> = Vec::new();
    for r in runs {
        // The parameters, then the quantities judged like them (the stable depth).
        for p in r.parameters.iter().chain(&r.quantities) {
            if !names.contains(&p.variable) {
                names.push(p.variable.clone());
            }
        }
    }
    let mut h = format!(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>{t}</title><style>body{{font-family:sans-serif;margin:2em}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 6px;font-size:13px}}.alarm{{color:#d62728;font-weight:bold}}</style></head><body><h1>{t}</h1>\
         <p>Blue: the identified value per run; grey line: normal (the baseline's centre, at the run's covariate when compensated); red: the Shewhart limits; red crosses: runs with an alarm on that parameter; orange line: the change point estimated for an alarm; grey band: the baseline window.</p>",
        t = escape(title)
    );
    h.push_str("<h2>Runs</h2><table><tr><th>#</th><th>run</th><th>time (UTC)</th><th>model</th><th>outcome</th><th>judgement</th></tr>");
    for (i, (r, j)) in runs.iter().zip(judgements).enumerate() {
        let cls = if j.alarm() { " class=\"alarm\"" } else { "" };
        let text = std::iter::once(j.summary())
            .chain(j.alarms.iter().map(|a| a.message.clone()))
            .map(|s| escape(&s))
            .collect::<Vec<_>>()
            .join("<br>");
        h.push_str(&format!(
            "<tr><td>{i}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td{cls}>{text}</td></tr>",
            escape(&r.run_id),
            escape(&r.time_utc),
            escape(&r.model_hash),
            escape(&r.outcome)
        ));
    }
    h.push_str("</table>");
    if let Some(j) = judgements.last() {
        h.push_str(&charts_table(j));
    }
    h.push_str("<h2>Parameters</h2>");
    for v in &names {
        match parameter_chart(v, runs, judgements) {
            Some(svg) => h.push_str(&format!("<div data-chart=\"trend\">{svg}</div>")),
            None => h.push_str(&format!(
                "<p>{}: no chart (no finite values)</p>",
                escape(v)
            )),
        }
    }
    h.push_str("</body></html>\n");
    h
}

/// The operator's table of one judgement: per parameter every chart's statistic and limit (in
/// scatters), the change it is followed as, then T², the parameters not judged and why.
pub fn charts_table(j: &Judgement) -> String {
    let mut h = format!("<h2>Charts of the newest run {}</h2>", escape(&j.run_id));
    if let Verdict::NotJudged(why) = &j.verdict {
        h.push_str(&format!("<p>not judged: {}</p>", escape(why)));
        return h;
    }
    h.push_str("<table data-table=\"charts\"><tr><th>parameter</th><th>value</th><th>normal ± scatter</th><th>deviation / Shewhart limit</th><th>CUSUM + / − / limit</th><th>EWMA / limit</th><th>alarm or change</th></tr>");
    for p in &j.parameters {
        let alarm = j
            .alarms
            .iter()
            .filter(|a| a.subject == p.variable)
            .map(|a| a.message.clone())
            .chain(
                j.changes
                    .iter()
                    .filter(|c| c.subject == p.variable && c.alarm_run != j.run_id)
                    .map(|c| c.message.clone()),
            )
            .map(|m| escape(&m))
            .collect::<Vec<_>>()
            .join("<br>");
        let sig = |v: f64| rfe::display::sig(v, 4);
        h.push_str(&format!(
            "<tr><td>{}</td><td>{} {}</td><td>{} ± {}</td><td>{:+.2} / ±{:.2}</td><td>{:.2} / {:.2} / {:.2}</td><td>{:+.2} / ±{:.2}</td><td>{alarm}</td></tr>",
            escape(&p.variable),
            sig(p.value),
            escape(&p.unit),
            sig(p.centre),
            sig(p.scatter),
            p.standardized,
            p.shewhart_limit,
            p.cusum[0],
            p.cusum[1],
            p.cusum_limit,
            p.ewma,
            p.ewma_limit,
        ));
    }
    h.push_str("</table>");
    match j.t2 {
        Some([t, l]) => h.push_str(&format!(
            "<p>Hotelling T² of the {VECTOR}: {t:.1} / limit {l:.1}</p>"
        )),
        None => h.push_str("<p>Hotelling T²: not computed (see the notes)</p>"),
    }
    for n in &j.not_judged {
        h.push_str(&format!(
            "<p>{}: not judged: {}</p>",
            escape(&n.variable),
            escape(&n.why)
        ));
    }
    for n in &j.notes {
        h.push_str(&format!("<p class=\"note\">{}</p>", escape(n)));
    }
    h
}
