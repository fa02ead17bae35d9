//! The report page: one self-contained HTML file (inline CSS, inline SVG, no scripts, no external
//! resources) that opens offline.

use std::fmt::Write;

use rfe::display::num;

use crate::document::*;
use crate::{plot, ReportError};

/// HTML-escapes text.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

fn opt(x: Option<f64>) -> String {
    x.map(num).unwrap_or_else(|| "—".into())
}

/// Strips plotters' XML prolog, if any, so the SVG can sit inline.
fn inline(svg: String) -> String {
    match svg.find("<svg") {
        Some(i) => svg[i..].to_string(),
        None => svg,
    }
}

const CSS: &str = "body{font-family:sans-serif;margin:1.5em auto;max-width:1000px;color:#222;line-height:1.4}\
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}\
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}th,td{border:1px solid #ccc;padding:.25em .5em;text-align:right}\
th{background:#f3f3f3}td.l,th.l{text-align:left}.meta{color:#555;font-size:.9em}\
.status{padding:.6em 1em;border-radius:4px;margin:1em 0}.ok{background:#e6f4e6;border:1px solid #7b7}\
.alarm{background:#fff0e0;border:1px solid #e90}.failure{background:#fde8e8;border:1px solid #d55}\
tr.alarm td{background:#fff0e0}tr.accepted td{background:#e8f6e8}figure{margin:.8em 0}svg{max-width:100%;height:auto;display:block}\
.note{color:#555;font-style:italic}";

/// The page of a run that failed before it had results (stand unreachable, disk full, bad
/// config): what went wrong, what was kept, where the log is. `lines` are shown as a list.
pub fn failure_page(title: &str, created_utc: &str, error: &str, lines: &[String]) -> String {
    let e = escape;
    let mut h = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><style>{CSS}</style></head><body>\n\
         <h1>{}</h1>\n<p class=\"meta\">{}</p>\n<div class=\"status failure\" id=\"status\"><strong>outcome: failure</strong><p>{}</p>",
        e(title),
        e(title),
        e(created_utc),
        e(error)
    );
    if !lines.is_empty() {
        h.push_str("<ul>");
        for l in lines {
            let _ = write!(h, "<li>{}</li>", e(l));
        }
        h.push_str("</ul>");
    }
    h.push_str("</div>\n<p class=\"note\">No results: the run stopped before identification. Fix the cause above and run again; a kept session can be analysed with <code>ident replay</code>.</p>\n</body></html>\n");
    h
}

/// Renders the page.
pub fn render(r: &Report) -> Result<String, ReportError> {
    let mut h = String::new();
    header(&mut h, r);
    final_model(&mut h, r);
    // The machining answer right after the final model: after the diagnosis's final table
    // when there is one, else after the identification's table (then the final model).
    let led = r.diagnosis.is_some();
    if led {
        stability(&mut h, r);
    }
    identification_summary(&mut h, r);
    characteristics(&mut h, r)?;
    model_picture(&mut h, r)?;
    parameters(&mut h, r)?;
    if !led {
        stability(&mut h, r);
    }
    diagnosis(&mut h, r);
    sensitivity(&mut h, r)?;
    drift(&mut h, r)?;
    Ok(h)
}

/// The title, provenance and outcome.
fn header(h: &mut String, r: &Report) {
    let e = escape;
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title>\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <meta name=\"generator\" content=\"ident {} ({})\"><style>{CSS}</style></head><body>\n",
        e(&r.title),
        e(&r.source.software),
        e(&r.schema)
    );
    let _ = write!(
        h,
        "<h1>{}</h1>\n<p class=\"meta\">{} · workflow {} · model {} · variables {}",
        e(&r.title),
        e(&r.created_utc),
        e(&r.source.workflow),
        e(&r.source.model),
        e(&r.source.variables)
    );
    if let Some(s) = &r.source.session {
        let _ = write!(h, " · session {}", e(s));
    }
    if let Some(s) = &r.source.stand {
        let _ = write!(h, " · stand {}", e(s));
    }
    let _ = writeln!(h, "<br>measurement: {}</p>", e(&r.source.measurement));
    let o = r.status.outcome.as_str();
    let _ = write!(
        h,
        "<div class=\"status {o}\" id=\"status\"><strong>outcome: {o}</strong>"
    );
    if !r.status.messages.is_empty() {
        h.push_str("<ul>");
        for m in &r.status.messages {
            let _ = write!(h, "<li>{}</li>", e(m));
        }
        h.push_str("</ul>");
    }
    h.push_str("</div>\n");
}

/// The final model first: after diagnosis added an effect, the variables at the final fit with
/// their Cramér-Rao errors there, next to the superseded first fit; otherwise a line saying the
/// identification's table below is final.
fn final_model(h: &mut String, r: &Report) {
    let e = escape;
    let Some(d) = &r.diagnosis else {
        return;
    };
    h.push_str("<h2 id=\"final\">Final model</h2>\n");
    if d.final_parameters.is_empty() {
        let _ = writeln!(
            h,
            "<p>{}: the diagnosis added nothing, the identification below is final.</p>",
            e(&d.final_model)
        );
        return;
    }
    let _ = writeln!(
        h,
        "<p><strong>{}</strong><br><span class=\"note\">Values at the final fit, with their \
         Cramér-Rao standard errors there; the first fit's values (identification, below) are \
         superseded.</span></p>",
        e(&d.final_model)
    );
    if !d.look_alikes.is_empty() {
        h.push_str("<p>The data cannot tell these added effects from the alternatives after \"≡\" (their refits end within a likelihood ratio of 3.84):</p>\n<ul>\n");
        for l in &d.look_alikes {
            let _ = writeln!(h, "<li>{}</li>", e(l));
        }
        h.push_str("</ul>\n");
    }
    h.push_str("<table><tr><th class=\"l\">variable</th><th class=\"l\">SDEs</th><th class=\"l\">unit</th><th>final</th><th>std error</th><th>σ/x</th><th>first fit (superseded)</th><th class=\"l\">note</th></tr>\n");
    for p in &d.final_parameters {
        let _ = writeln!(
            h,
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td></tr>",
            e(&p.variable),
            e(&p.sdes),
            e(&p.unit),
            rfe::display::sig(p.identified, 5),
            p.std_error.map(|s| rfe::display::sig(s, 3)).unwrap_or_else(|| "—".into()),
            p.variability.map(rfe::display::relative).unwrap_or_else(|| "—".into()),
            rfe::display::sig(p.initial, 5),
            p.at_bound.as_deref().map(|b| format!("at {b} bound")).unwrap_or_default()
        );
    }
    h.push_str("</table>\n");
}

/// The chatter stability of the final model for the report's cut: the minimum critical depth
/// with its band, the lobes with their band as a chart, the modes, bodies and joints that set
/// the limit.
fn stability(h: &mut String, r: &Report) {
    let e = escape;
    let Some(s) = &r.stability else {
        return;
    };
    let m = &s.minimum;
    h.push_str("<h2 id=\"stability\">Chatter stability</h2>\n");
    let _ = write!(
        h,
        "<p>{} ({}, {}, {:.0}–{:.0} rpm): <strong>minimum critical depth {} mm</strong> at {:.0} rpm",
        e(s.note.as_deref().unwrap_or(&s.operation)),
        e(&s.operation),
        e(&s.cut),
        s.speed_rpm[0],
        s.speed_rpm[1],
        rfe::display::sig(m.depth_mm, 4),
        m.speed_rpm
    );
    if let Some([lo, hi]) = m.band_mm {
        let _ = write!(
            h,
            " (5–95 %: {}–{} mm)",
            rfe::display::sig(lo, 4),
            rfe::display::sig(hi, 4)
        );
    }
    let _ = writeln!(
        h,
        ", chatter at {:.1} Hz (lobe {}).</p>",
        m.chatter_hz, m.lobe
    );
    if m.band_mm.is_none() {
        h.push_str("<p class=\"note\">No band: the run's covariance was not available.</p>\n");
    }
    for n in &s.band_notes {
        let _ = writeln!(h, "<p class=\"note\">Band: {}.</p>", e(n));
    }
    let _ = writeln!(
        h,
        "<figure>{}<figcaption>Critical axial depth against spindle speed; shaded: the 5–95 % band from the final fit's Cramér-Rao covariance (linear propagation); dot: the minimum.</figcaption></figure>",
        s.svg()
    );
    h.push_str("<table><tr><th>mode (Hz)</th><th>η</th><th>share of the limit</th><th class=\"l\">bodies (kinetic energy)</th><th class=\"l\">joints (strain energy)</th></tr>\n");
    let list = |v: &[::stability::section::Share]| -> String {
        v.iter()
            .take(4)
            .map(|x| format!("{} {:.0} %", e(&x.name), 100.0 * x.share))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for l in &s.limiting {
        let _ = writeln!(
            h,
            "<tr><td>{:.1}</td><td>{:.3}</td><td>{:.0} %</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
            l.freq_hz,
            l.loss_factor,
            100.0 * l.share,
            list(&l.bodies),
            list(&l.joints)
        );
    }
    if s.tool_share.abs() >= 0.05 {
        let _ = writeln!(
            h,
            "<tr><td class=\"l\">tool</td><td></td><td>{:.0} %</td><td></td><td></td></tr>",
            100.0 * s.tool_share
        );
    }
    h.push_str("</table>\n");
}

/// The identification in one paragraph.
fn identification_summary(h: &mut String, r: &Report) {
    let e = escape;
    let id = &r.identification;
    let _ = write!(
        h,
        "<h2 id=\"identification\">Identification</h2>\n<p>{} variables from {} observations; optimizer {}, {} after {} iterations \
         ({}). Criterion J {} → {}; reduced χ² {}.<br><span class=\"meta\">{}</span></p>\n",
        id.parameters.len(),
        id.observations,
        e(&id.optimizer),
        if id.converged { "converged" } else { "<strong>not converged</strong>" },
        id.iterations,
        e(&id.stop),
        num(id.criterion_initial),
        num(id.criterion),
        num(id.reduced_chi2),
        e(&id.noise)
    );
}

/// The characteristics: errors per stage and the amplitude and residual charts.
fn characteristics(h: &mut String, r: &Report) -> Result<(), ReportError> {
    let e = escape;
    h.push_str("<h2 id=\"characteristics\">Amplitude-frequency characteristics</h2>\n");
    h.push_str("<p class=\"note\">Measured points with ± one standard deviation; the model before identification (initial, through the measured lines), after it (identified) and, when diagnosis ran, after the diagnosed effects were added and refitted (diagnosed), as smooth curves on a dense grid; the final model's natural frequencies in the band marked. Residuals in units of σ.</p>\n");
    h.push_str("<table><tr><th class=\"l\">characteristic</th>");
    let stages: Vec<&str> = r
        .characteristics
        .first()
        .map(|c| c.stages.iter().map(|s| s.stage.as_str()).collect())
        .unwrap_or_default();
    for s in &stages {
        let _ = write!(h, "<th>RMS error, {}: dB (relative)</th>", e(s));
    }
    h.push_str("<th>points</th><th class=\"l\">σ from</th></tr>\n");
    for c in &r.characteristics {
        let _ = write!(h, "<tr><td class=\"l\">{}</td>", e(&c.label));
        for s in &c.stages {
            let _ = write!(
                h,
                "<td>{:.2} dB ({})</td>",
                s.rms_db_error,
                rfe::display::relative(s.rms_relative_error)
            );
        }
        let _ = writeln!(
            h,
            "<td>{}</td><td class=\"l\">{}</td></tr>",
            c.freqs_hz.len(),
            e(&c.sigma_kind)
        );
    }
    h.push_str("</table>\n");
    let modes = final_modes(r);
    for c in &r.characteristics {
        let _ = writeln!(
            h,
            "<figure class=\"plot\" data-chart=\"amplitude\">{}</figure>",
            inline(plot::amplitude_chart(c, modes)?)
        );
        if c.measured_phase_rad.is_some() {
            let _ = writeln!(
                h,
                "<figure class=\"plot\" data-chart=\"phase\">{}</figure>",
                inline(plot::phase_chart(c)?)
            );
        }
        let _ = writeln!(
            h,
            "<figure class=\"plot\" data-chart=\"residual\">{}</figure>",
            inline(plot::residual_chart(c)?)
        );
    }
    Ok(())
}

/// The final model as a drawing and its mode shapes in the measured band (`picture`).
fn model_picture(h: &mut String, r: &Report) -> Result<(), ReportError> {
    let e = escape;
    let Some(p) = &r.picture else {
        return Ok(());
    };
    h.push_str("<h2 id=\"model\">Model and mode shapes</h2>\n");
    let clamped: Vec<&str> = p
        .bodies
        .iter()
        .filter(|b| b.clamped)
        .map(|b| b.name.as_str())
        .collect();
    let _ = writeln!(
        h,
        "<p class=\"note\">{}: each body drawn as the uniform box with its mass and principal inertias{}; \
         SDEs at their points, linked to the bodies they join; the exciter and the measured DOFs at the bodies' centres of mass.</p>",
        e(r.diagnosis.as_ref().map_or(&p.model, |d| &d.final_model)),
        if clamped.is_empty() {
            String::new()
        } else {
            format!(
                " (too thin or impossible sides drawn at 5 % of the longest: {})",
                e(&clamped.join(", "))
            )
        }
    );
    let _ = writeln!(
        h,
        "<figure class=\"plot\" data-chart=\"model\">{}</figure>",
        inline(crate::picture::model_svg(p)?)
    );
    let _ = write!(
        h,
        "<p>{} mode{} of the model between {} and {} Hz",
        p.modes.len() + p.modes_omitted,
        if p.modes.len() + p.modes_omitted == 1 {
            ""
        } else {
            "s"
        },
        rfe::display::sig(p.band_hz[0], 4),
        rfe::display::sig(p.band_hz[1], 4)
    );
    if p.modes_omitted > 0 {
        let _ = write!(
            h,
            "; the lowest {} are drawn, {} omitted",
            p.modes.len(),
            p.modes_omitted
        );
    }
    h.push_str(". Undeformed in grey, deformed in colour (the body that moves most in orange), the largest displacement drawn at 8 % of the machine's size.</p>\n<div class=\"modes\" style=\"display:flex;flex-wrap:wrap;gap:0 2%\">\n");
    for i in 0..p.modes.len() {
        let _ = writeln!(
            h,
            "<figure class=\"plot\" data-chart=\"mode\" style=\"width:48%;margin:.4em 0\">{}</figure>",
            inline(crate::picture::mode_svg(p, i)?)
        );
    }
    h.push_str("</div>\n");
    Ok(())
}

/// The final model's natural frequencies in the band: the diagnosed stage's when diagnosis ran,
/// else the identified one's.
fn final_modes(r: &Report) -> &[NaturalMode] {
    let of = |stage: &str| r.natural_frequencies.iter().find(|m| m.stage == stage);
    of("diagnosed")
        .or_else(|| of("identified"))
        .map(|m| m.modes.as_slice())
        .unwrap_or(&[])
}

/// The parameter table (Table-1-like) and the poorly identifiable directions.
fn parameters(h: &mut String, r: &Report) -> Result<(), ReportError> {
    let e = escape;
    let id = &r.identification;
    h.push_str("<h2 id=\"parameters\">Parameters (Table-1-like)</h2>\n<table><tr><th class=\"l\">variable</th><th class=\"l\">SDEs</th><th class=\"l\">parameter</th><th class=\"l\">unit</th><th>initial</th><th>identified</th><th>std error</th><th>σ/x</th><th class=\"l\">note</th></tr>\n");
    for p in &id.parameters {
        let _ = writeln!(
            h,
            "<tr><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td></tr>",
            e(&p.variable),
            e(&p.sdes),
            e(&p.parameter),
            e(&p.unit),
            num(p.initial),
            num(p.identified),
            p.std_error.map(num).unwrap_or_else(|| "undetermined".into()),
            p.variability.map(rfe::display::relative).unwrap_or_else(|| "—".into()),
            p.at_bound.as_ref().map(|b| format!("at {} bound", e(b))).unwrap_or_default()
        );
    }
    h.push_str("</table>\n");
    let _ = writeln!(
        h,
        "<figure class=\"plot\" data-chart=\"parameters\">{}</figure>",
        inline(plot::parameter_chart(&id.parameters)?)
    );
    if !id.weak_directions.is_empty() {
        h.push_str("<p>Poorly identifiable combinations (group these variables or add measurements):</p><ul>");
        for w in &id.weak_directions {
            let _ = write!(
                h,
                "<li>{} ({})</li>",
                e(&w.combination),
                w.relative_std
                    .map(|v| format!("±{:.0} %", 100.0 * v))
                    .unwrap_or_else(|| "no information".into())
            );
        }
        h.push_str("</ul>\n");
    }
    Ok(())
}

/// The diagnosis: before/after, rounds, accepted effects.
fn diagnosis(h: &mut String, r: &Report) {
    let e = escape;
    h.push_str("<h2 id=\"diagnosis\">Diagnosis</h2>\n");
    match &r.diagnosis {
        None => h.push_str("<p class=\"note\">Diagnosis did not run for this report.</p>\n"),
        Some(d) => {
            let _ = writeln!(
                h,
                "<p class=\"verdict\">{}: {}</p>",
                if d.explained {
                    "Explained"
                } else {
                    "Not explained"
                },
                e(&d.verdict)
            );
            candidates(h, &d.candidates);
            h.push_str("<table><tr><th class=\"l\"></th><th>criterion J</th><th>reduced χ²</th><th>χ² p-value</th>");
            for l in &d.before.rms_relative_error {
                let _ = write!(h, "<th>RMS {}</th>", e(&l.label));
            }
            for l in &d.before.rms_db_error {
                let _ = write!(h, "<th>RMS {} (dB)</th>", e(&l.label));
            }
            h.push_str("</tr>\n");
            for (name, q) in [("before", &d.before), ("after", &d.after)] {
                let p = q
                    .chi2_p_value
                    .map(rfe::display::p_value)
                    .unwrap_or_else(|| "— (noise level unknown)".into());
                let _ = write!(
                    h,
                    "<tr><td class=\"l\">{name}</td><td>{}</td><td>{:.3}</td><td>{p}</td>",
                    num(q.criterion),
                    q.reduced_chi2
                );
                for l in &q.rms_relative_error {
                    let _ = write!(h, "<td>{}</td>", rfe::display::relative(l.value));
                }
                for l in &q.rms_db_error {
                    let _ = write!(h, "<td>{:.2} dB</td>", l.value);
                }
                h.push_str("</tr>\n");
            }
            let _ = writeln!(h, "</table>\n<p>Final model: {}</p>", e(&d.final_model));
            if !d.not_tried.is_empty() {
                h.push_str("<p>Tried but not evaluated, or not testable with these data, and why:</p><ul class=\"not-tried\">");
                for n in &d.not_tried {
                    let _ = write!(h, "<li>{}: {}</li>", e(&n.effect), e(&n.reason));
                }
                h.push_str("</ul>\n");
            }
        }
    }
}

/// Candidates shown outside the collapsible rest of the ranking.
pub const TOP_CANDIDATES: usize = 10;

/// The candidates in the compact table: the [`TOP_CANDIDATES`] strongest by score statistic,
/// every accepted one among them, in (round, strongest first) order; then the rest.
pub fn top_candidates(c: &[Candidate]) -> (Vec<&Candidate>, Vec<&Candidate>) {
    let mut order: Vec<usize> = (0..c.len()).collect();
    // Accepted first, then by statistic: the cut keeps every accepted candidate.
    order.sort_by(|&a, &b| {
        c[b].accepted
            .cmp(&c[a].accepted)
            .then(c[b].statistic.total_cmp(&c[a].statistic))
    });
    let mut top: Vec<usize> = order.iter().copied().take(TOP_CANDIDATES).collect();
    let mut rest: Vec<usize> = order.iter().copied().skip(TOP_CANDIDATES).collect();
    top.sort_unstable();
    rest.sort_unstable();
    (
        top.into_iter().map(|i| &c[i]).collect(),
        rest.into_iter().map(|i| &c[i]).collect(),
    )
}

/// The ranking: the top candidates as a compact table, the rest behind a `<details>` element
/// (no script needed).
fn candidates(h: &mut String, all: &[Candidate]) {
    let e = escape;
    let head = "<table class=\"candidates\"><tr><th>round</th><th class=\"l\">candidate effect</th><th class=\"l\">what and where</th><th>score statistic</th><th>p-value</th><th class=\"l\">accepted</th><th>estimate</th><th>std error</th><th class=\"l\">unit</th><th>RMS error when added</th></tr>\n";
    let row = |h: &mut String, c: &Candidate| {
        let gain = match (c.rms_db_before, c.rms_db_after) {
            (Some(a), Some(b)) => format!("{a:.2} → {b:.2} dB"),
            _ => "—".into(),
        };
        let _ = writeln!(
            h,
            "<tr{}><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td><td>{}</td></tr>",
            if c.accepted { " class=\"accepted\"" } else { "" },
            c.round,
            e(&c.name),
            e(&c.location),
            rfe::display::sig(c.statistic, 3),
            rfe::display::p_value(c.p_value),
            if c.accepted { "<strong>yes</strong>" } else { "no" },
            c.estimate.map(|v| rfe::display::sig(v, 4)).unwrap_or_else(|| "—".into()),
            c.std_error.map(|v| rfe::display::sig(v, 2)).unwrap_or_else(|| "—".into()),
            e(&c.unit),
            gain
        );
    };
    let (top, rest) = top_candidates(all);
    let _ = writeln!(
        h,
        "<p>Candidate effects ranked by the score test ({} in all; the {} strongest here, every accepted one among them):</p>",
        all.len(),
        top.len()
    );
    h.push_str(head);
    for c in top {
        row(h, c);
    }
    h.push_str("</table>\n");
    if !rest.is_empty() {
        let _ = writeln!(
            h,
            "<details><summary>the other {} candidates</summary>",
            rest.len()
        );
        h.push_str(head);
        for c in rest {
            row(h, c);
        }
        h.push_str("</table></details>\n");
    }
}

/// The sensitivity maps.
fn sensitivity(h: &mut String, r: &Report) -> Result<(), ReportError> {
    h.push_str("<h2 id=\"sensitivity\">Sensitivity (MI map)</h2>\n");
    match &r.sensitivity {
        None => h.push_str("<p class=\"note\">Not computed for this report.</p>\n"),
        Some(m) => {
            let _ = writeln!(
                h,
                "<figure class=\"plot\" data-chart=\"sensitivity\">{}</figure>",
                inline(plot::sensitivity_chart(m)?)
            );
        }
    }
    Ok(())
}

/// The drift across runs.
fn drift(h: &mut String, r: &Report) -> Result<(), ReportError> {
    let e = escape;
    h.push_str("<h2 id=\"drift\">Drift across runs</h2>\n");
    match &r.drift {
        None => h.push_str("<p class=\"note\">No earlier runs to compare with.</p>\n"),
        Some(d) => {
            let _ = writeln!(
                h,
                "<p>{} runs; baseline {}; alarm when a parameter moves more than {} standard errors of the difference.</p>",
                d.runs.len(),
                e(d.runs.get(d.baseline).map(String::as_str).unwrap_or("?")),
                d.k_sigma
            );
            let _ = writeln!(
                h,
                "<figure class=\"plot\" data-chart=\"drift\">{}</figure>",
                inline(plot::drift_chart(d)?)
            );
            h.push_str("<table><tr><th class=\"l\">variable</th><th class=\"l\">unit</th><th>baseline</th><th>this run</th><th>deviation (σ)</th><th class=\"l\">alarm</th></tr>\n");
            for p in &d.parameters {
                let _ = writeln!(
                    h,
                    "<tr{}><td class=\"l\">{}</td><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"l\">{}</td></tr>",
                    if p.alarm { " class=\"alarm\"" } else { "" },
                    e(&p.variable),
                    e(&p.unit),
                    opt(p.values.get(d.baseline).copied().flatten()),
                    opt(p.values.last().copied().flatten()),
                    p.deviation_sigma.map(|v| format!("{v:+.2}")).unwrap_or_else(|| "—".into()),
                    if p.alarm { "ALARM" } else { "" }
                );
            }
            h.push_str("</table>\n");
        }
    }
    let _ = writeln!(
        h,
        "<p class=\"meta\">Machine-readable copy: report.json ({}).</p>\n</body></html>",
        e(&r.schema)
    );
    Ok(())
}
