//! The HTML report in a real browser: headless Chromium (Debian's `chromium`, installed by
//! `.ci/setup`) loads a full report from disk with networking disabled and a probe script that
//! records errors, rendered plots (with the mode markers and the dense model curves) and resource
//! loads into the DOM; the test reads the DOM back.

// Test and benchmark helpers unwrap: a panic with its message is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use std::process::Command;

use serde_json::Value;

const PROBE: &str = r#"<script>
window.__errors = [];
window.addEventListener('error', e => { window.__errors.push('error: ' + (e.message || (e.target && (e.target.src || e.target.href)) || 'resource')); }, true);
window.addEventListener('unhandledrejection', e => { window.__errors.push('rejection: ' + e.reason); });
for (const k of ['error', 'warn']) { const f = console[k]; console[k] = (...a) => { window.__errors.push(k + ': ' + a.join(' ')); f.apply(console, a); }; }
window.addEventListener('load', () => {
  const svgs = [...document.querySelectorAll('figure.plot svg')];
  const drawn = svgs.filter(s => { const b = s.getBBox(); return b.width > 50 && b.height > 50 && s.querySelectorAll('text').length > 2; });
  const out = {
    title: document.title,
    plots: svgs.length,
    drawn: drawn.length,
    charts: svgs.map(s => s.closest('figure').dataset.chart),
    texts: document.querySelectorAll('svg text').length,
    marks: [...document.querySelectorAll('figure[data-chart=amplitude] svg text')]
      .filter(t => t.textContent.trim().startsWith('mode '))
      .map(t => { const b = t.getBBox(); return b.width > 0 && b.height > 0; }),
    curves: [...document.querySelectorAll('figure[data-chart=amplitude] svg polyline')]
      .filter(p => p.points.numberOfItems >= 400).length,
    rows: document.querySelectorAll('#parameters ~ table tr').length,
    resources: performance.getEntriesByType('resource').map(r => r.name),
    errors: window.__errors,
  };
  const pre = document.createElement('pre');
  pre.id = 'probe';
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"#;

fn chromium() -> String {
    for c in ["chromium", "chromium-browser"] {
        if Command::new(c)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
        {
            return c.to_string();
        }
    }
    panic!("chromium is not installed: run .ci/setup (it installs Debian's chromium from .ci/apt-packages.txt)");
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&#39;", "'")
        .replace("&amp;", "&")
}

#[test]
fn report_renders_in_headless_chromium_with_its_plots_and_no_errors() {
    let browser = chromium();
    let f = common::fixture(11);
    let r = common::full_report(&f, 5.0);
    let dir = tempfile::tempdir().unwrap();
    let w = report::write(&r, dir.path()).unwrap();
    let html = std::fs::read_to_string(&w.html).unwrap();
    let probed = html.replacen("<head>", &format!("<head>{PROBE}"), 1);
    assert_ne!(probed, html, "the report has a <head>");
    let page = dir.path().join("probed.html");
    std::fs::write(&page, probed).unwrap();
    let profile = dir.path().join("profile");
    let out = Command::new(&browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--proxy-server=127.0.0.1:9", // offline: any network request fails
            "--enable-logging=stderr",
            "--v=0",
            "--virtual-time-budget=10000",
            "--dump-dom",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("file://{}", page.display()))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "chromium failed: {stderr}");
    let probe = stdout
        .split("<pre id=\"probe\">")
        .nth(1)
        .and_then(|s| s.split("</pre>").next())
        .unwrap_or_else(|| {
            panic!("the page did not finish loading (no probe output); stderr: {stderr}")
        });
    let v: Value = serde_json::from_str(&unescape(probe)).unwrap();
    eprintln!("{v}");
    assert_eq!(v["title"], r.title);
    // Amplitude, phase and residuals per characteristic; parameters, sensitivity, drift; the
    // model picture and one figure per mode in the band.
    let n = r.characteristics.len();
    let shapes = r.picture.as_ref().map_or(0, |p| p.modes.len());
    assert!(shapes > 0, "the fixture has modes in its band");
    let expected = 3 * n + 3 + 1 + shapes;
    assert_eq!(v["plots"], expected as u64, "{v}");
    let charts = v["charts"].as_array().unwrap();
    for chart in ["amplitude", "phase", "residual"] {
        assert_eq!(charts.iter().filter(|c| *c == chart).count(), n, "{v}");
    }
    assert_eq!(charts.iter().filter(|c| *c == "model").count(), 1, "{v}");
    assert_eq!(
        charts.iter().filter(|c| *c == "mode").count(),
        shapes,
        "{v}"
    );
    // The final model's modes marked on every amplitude chart, each label drawn.
    let modes = r.natural_frequencies.last().unwrap().modes.len();
    assert!(modes > 0);
    let marks = v["marks"].as_array().unwrap();
    assert!(
        marks.len() >= n && marks.len() <= modes * n && marks.iter().all(|m| m == true),
        "{v}"
    );
    // Two smooth model curves (identified, diagnosed) of at least 400 points per chart.
    assert_eq!(v["curves"], (2 * n) as u64, "{v}");
    assert_eq!(
        v["drawn"], expected as u64,
        "every plot is drawn with its labels: {v}"
    );
    assert!(v["texts"].as_u64().unwrap() > 50, "{v}");
    assert!(
        v["rows"].as_u64().unwrap() > r.identification.parameters.len() as u64,
        "{v}"
    );
    assert_eq!(
        v["resources"],
        Value::Array(vec![]),
        "the page must load nothing: {v}"
    );
    assert_eq!(v["errors"], Value::Array(vec![]), "{v}");
    // Console messages Chromium itself logs (CSP, blocked loads, uncaught errors).
    let console: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("CONSOLE") || l.contains("Uncaught"))
        .collect();
    assert!(console.is_empty(), "console messages: {console:?}");
}
