//! The nightly's status for monitoring systems: a Prometheus textfile (the text exposition format
//! that node_exporter's textfile collector reads), written atomically (a temporary file renamed
//! over the old one, so the collector never reads half a file).

use std::fmt::Write as _;
use std::path::Path;

use history::judge::{Judgement, Verdict};
use history::record::RunRecord;

/// What one run reports.
pub struct RunStatus<'a> {
    /// The job's name (label `job_name`).
    pub job: &'a str,
    /// `ok`, `alarm` or `failure`.
    pub outcome: &'a str,
    /// The exit status (0, 1, 2).
    pub exit_code: u8,
    /// When the run ended (Unix seconds).
    pub end_unix: i64,
    /// The drift judgement from the history, when made.
    pub judgement: Option<&'a Judgement>,
    /// The run as recorded, when identified.
    pub record: Option<&'a RunRecord>,
}

fn label(v: &str) -> String {
    v.replace('\\', "\\\\")
        .replace('"', "\\\"")
        .replace('\n', "\\n")
}

/// The textfile's text.
pub fn textfile(s: &RunStatus<'_>) -> String {
    let job = label(s.job);
    let mut t = String::new();
    let mut metric = |name: &str, help: &str, rows: &[(String, f64)]| {
        let _ = writeln!(t, "# HELP {name} {help}\n# TYPE {name} gauge");
        for (labels, v) in rows {
            let _ = writeln!(t, "{name}{{job_name=\"{job}\"{labels}}} {v}");
        }
    };
    metric(
        "ident_nightly_exit_code",
        "Exit status of the last run: 0 ok, 1 drift alarm, 2 failure.",
        &[(String::new(), s.exit_code as f64)],
    );
    metric(
        "ident_nightly_outcome",
        "1 for the last run's outcome (ok, alarm, failure).",
        &["ok", "alarm", "failure"].map(|o| {
            (
                format!(",outcome=\"{o}\""),
                if o == s.outcome { 1.0 } else { 0.0 },
            )
        }),
    );
    metric(
        "ident_nightly_last_run_timestamp_seconds",
        "When the last run ended (Unix time).",
        &[(String::new(), s.end_unix as f64)],
    );
    if let Some(j) = s.judgement {
        metric(
            "ident_nightly_drift_judged",
            "1 when the last run was judged against the history's baseline, 0 when not (too few runs, another model).",
            &[(String::new(), f64::from(u8::from(j.verdict == Verdict::Judged)))],
        );
        metric(
            "ident_nightly_drift_alarms",
            "New drift alarms of the last run (all rules; a change is alarmed once).",
            &[(String::new(), j.alarms.len() as f64)],
        );
        metric(
            "ident_nightly_drift_open_changes",
            "Changes followed after an earlier alarm (parameters, the parameter vector, new effects).",
            &[(String::new(), j.changes.len() as f64)],
        );
        if let Some([t2, limit]) = j.t2 {
            metric(
                "ident_nightly_hotelling_t2_ratio",
                "Hotelling T² of the parameter vector over its limit (> 1 is an alarm).",
                &[(String::new(), t2 / limit)],
            );
        }
        let rows: Vec<(String, f64)> = j
            .parameters
            .iter()
            .map(|p| {
                (
                    format!(",variable=\"{}\"", label(&p.variable)),
                    p.standardized,
                )
            })
            .collect();
        metric(
            "ident_nightly_parameter_deviation_scatters",
            "Deviation of each parameter (and the stable depth) from normal in multiples of its normal run-to-run scatter.",
            &rows,
        );
    }
    if let Some(r) = s.record {
        if let Some(chi2) = r.reduced_chi2 {
            metric(
                "ident_nightly_reduced_chi2",
                "Reduced chi-square of the last run's final fit (about 1 at the noise level).",
                &[(String::new(), chi2)],
            );
        }
        let rows: Vec<(String, f64)> = r
            .parameters
            .iter()
            .map(|p| {
                (
                    format!(
                        ",variable=\"{}\",unit=\"{}\"",
                        label(&p.variable),
                        label(&p.unit)
                    ),
                    p.in_unit(),
                )
            })
            .collect();
        metric(
            "ident_nightly_parameter",
            "Identified value of each parameter in its display unit (label unit).",
            &rows,
        );
        if !r.quantities.is_empty() {
            let rows = |f: &dyn Fn(&history::record::ParameterRecord) -> Option<f64>| {
                r.quantities
                    .iter()
                    .filter_map(|q| Some((format!(",quantity=\"{}\"", label(&q.variable)), f(q)?)))
                    .collect::<Vec<_>>()
            };
            metric(
                "ident_nightly_stable_depth_mm",
                "Minimum critical (chatter-free) axial depth of cut of the final model over the cut's speed range (mm; label quantity names the range and the cut).",
                &rows(&|q| Some(q.estimate / q.unit_factor)),
            );
            metric(
                "ident_nightly_stable_depth_sigma_mm",
                "Standard deviation of that depth from the final fit's Cramér-Rao covariance (mm).",
                &rows(&|q| q.std_error.map(|s| s / q.unit_factor)),
            );
        }
    }
    t
}

/// Writes the textfile atomically (`PATH.partial`, then renamed over `PATH`).
pub fn write(path: &Path, s: &RunStatus<'_>) -> Result<(), report::ReportError> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        let _ = std::fs::create_dir_all(parent);
    }
    report::write_atomic(path, textfile(s).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textfile_has_one_sample_per_outcome_and_escapes_labels() {
        let t = textfile(&RunStatus {
            job: "FWD \"32J\"",
            outcome: "alarm",
            exit_code: 1,
            end_unix: 1_700_000_000,
            judgement: None,
            record: None,
        });
        assert!(
            t.contains("ident_nightly_exit_code{job_name=\"FWD \\\"32J\\\"\"} 1\n"),
            "{t}"
        );
        assert!(
            t.contains("outcome=\"alarm\"} 1\n") && t.contains("outcome=\"ok\"} 0\n"),
            "{t}"
        );
        assert!(t.contains(
            "ident_nightly_last_run_timestamp_seconds{job_name=\"FWD \\\"32J\\\"\"} 1700000000\n"
        ));
        // Every sample line names a metric declared by a TYPE line before it.
        let mut declared = Vec::new();
        for l in t.lines() {
            if let Some(rest) = l.strip_prefix("# TYPE ") {
                declared.push(rest.split(' ').next().unwrap_or("").to_string());
            } else if !l.starts_with('#') {
                let name = l.split('{').next().unwrap_or("");
                assert!(declared.iter().any(|d| d == name), "{l}");
            }
        }
    }
}
