//! `ident history DB ACTION`: the nightly run history (`docs/nightly.md`): list the runs, show
//! one parameter's series, export CSV, import dated report folders, and write the HTML trend page
//! (per parameter: the series, its normal and control limits, the alarms marked).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use history::judge::{judge_series, BaselineWindow, JudgeConfig, Judgement, Verdict};
use history::store::Store;
use rfe::csv_text::CsvText;

/// Arguments of `ident history`.
#[derive(clap::Args)]
pub struct HistoryArgs {
    /// The history database (`[history] database` of the nightly job).
    pub database: PathBuf,
    #[command(subcommand)]
    action: Action,
}

/// How runs are judged for `series` and `html` (the nightly job's `[history]` settings).
#[derive(clap::Args, Clone)]
struct Judging {
    /// Runs in the baseline window.
    #[arg(long, default_value_t = 20)]
    baseline_runs: usize,
    /// The first runs (`first`) or those just before each run (`rolling`).
    #[arg(long, default_value = "first")]
    window: String,
    /// Covariate to compensate (e.g. `temperature`).
    #[arg(long)]
    covariate: Option<String>,
}

impl Judging {
    fn config(&self) -> anyhow::Result<JudgeConfig> {
        let n = self.baseline_runs;
        anyhow::ensure!(n >= 3, "--baseline-runs {n}: give at least 3");
        Ok(JudgeConfig {
            baseline: match self.window.as_str() {
                "first" => BaselineWindow::First(n),
                "rolling" => BaselineWindow::Rolling(n),
                w => anyhow::bail!("--window {w}: give `first` or `rolling`"),
            },
            covariate: self.covariate.clone(),
            ..JudgeConfig::default()
        })
    }
}

#[derive(clap::Subcommand)]
enum Action {
    /// One line per run: id, time, model hash, outcome, parameters, reduced χ², effects.
    List,
    /// One parameter over the runs: value, standard error, normal, scatter, every chart's
    /// statistic and limit, alarms, the change followed, and why a run was not judged.
    Series {
        /// Variable name (as in the report's table).
        variable: String,
        #[command(flatten)]
        judging: Judging,
    },
    /// Every parameter of every run as CSV (display units) to stdout or `--out`.
    Csv {
        /// Output file (written atomically); stdout without it.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Import the dated report folders of earlier runs (each `*/report.json`); repeatable.
    Import {
        /// The nightly's `reports` folder.
        reports: PathBuf,
    },
    /// The HTML trend page: per parameter the series, its limits and the alarms.
    Html {
        /// Output file.
        out: PathBuf,
        #[command(flatten)]
        judging: Judging,
    },
}

/// Runs `ident history`.
pub fn run(a: HistoryArgs) -> anyhow::Result<ExitCode> {
    let db = &a.database;
    match a.action {
        Action::Import { reports } => {
            let mut store = Store::open(db)?;
            let s = history::import::import_reports(&mut store, &reports)?;
            for m in s.skipped.iter().chain(&s.warnings) {
                eprintln!("warning: {m}");
            }
            println!(
                "{} runs imported, {} already in {}, {} left out",
                s.imported,
                s.already_stored,
                db.display(),
                s.skipped.len()
            );
        }
        Action::List => {
            let runs = Store::open_read_only(db)?.runs()?;
            println!("run\ttime_utc\tmodel_hash\toutcome\tparameters\treduced_chi2\teffects");
            for r in &runs {
                println!(
                    "{}\t{}\t{}\t{}\t{}\t{}\t{}",
                    r.run_id,
                    r.time_utc,
                    r.model_hash,
                    r.outcome,
                    r.parameters.len(),
                    r.reduced_chi2
                        .map(|c| rfe::display::sig(c, 4))
                        .unwrap_or_default(),
                    r.effects.join("; ")
                );
            }
        }
        Action::Series { variable, judging } => {
            let runs = Store::open_read_only(db)?.runs()?;
            anyhow::ensure!(
                runs.iter().any(|r| r.parameter(&variable).is_some()),
                "no run in {} has a parameter or quantity \"{variable}\"; `ident history {} list` and the reports name them (the stable depth: \"stable depth <from>–<to> rpm (<cut>)\")",
                db.display(),
                db.display()
            );
            let js = judge_series(&runs, &judging.config()?);
            println!("run\ttime_utc\tvalue\tstd_error\tunit\tnormal\tscatter\tdeviation_scatters\tshewhart_limit\tcusum_up\tcusum_down\tcusum_limit\tewma\tewma_limit\tt2\tt2_limit\talarms\tchange\tnot_judged");
            for (r, j) in runs.iter().zip(&js) {
                let Some(p) = r.parameter(&variable) else {
                    continue;
                };
                println!("{}", series_line(r, p, j, &variable));
            }
        }
        Action::Csv { out } => {
            let runs = Store::open_read_only(db)?.runs()?;
            let mut csv = CsvText::new();
            csv.row([
                "run_id",
                "time_utc",
                "model_hash",
                "outcome",
                "variable",
                "unit",
                "value",
                "std_error",
            ]);
            for r in &runs {
                for p in r.parameters.iter().chain(&r.quantities) {
                    csv.row([
                        r.run_id.clone(),
                        r.time_utc.clone(),
                        r.model_hash.clone(),
                        r.outcome.clone(),
                        p.variable.clone(),
                        p.unit.clone(),
                        p.in_unit().to_string(),
                        p.std_error
                            .map(|s| (s / p.unit_factor).to_string())
                            .unwrap_or_default(),
                    ]);
                }
            }
            let t = csv.finish();
            match out {
                Some(o) => report::write_atomic(&o, t.as_bytes())?,
                None => print!("{t}"),
            }
        }
        Action::Html { out, judging } => {
            let runs = Store::open_read_only(db)?.runs()?;
            let js = judge_series(&runs, &judging.config()?);
            let page = history::trend::page(&format!("Run history {}", db.display()), &runs, &js);
            report::write_atomic(&out, page.as_bytes())
                .with_context(|| format!("cannot write {}", out.display()))?;
            println!(
                "{} runs, {} with alarms: {}",
                runs.len(),
                js.iter().filter(|j| j.alarm()).count(),
                out.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// One run of a parameter's series: its value, every chart's statistic beside its limit, the
/// alarms and open change naming it, or why it was not judged.
fn series_line(
    r: &history::record::RunRecord,
    p: &history::record::ParameterRecord,
    j: &Judgement,
    variable: &str,
) -> String {
    let sig = |v: f64| rfe::display::sig(v, 5);
    let f2 = |v: f64| format!("{v:.2}");
    let pj = j.parameters.iter().find(|q| q.variable == variable);
    let alarms: Vec<&str> = j
        .alarms
        .iter()
        .filter(|x| x.subject == variable || x.subject == history::judge::VECTOR)
        .map(|x| x.rule.as_str())
        .collect();
    let change = j
        .changes
        .iter()
        .find(|c| c.subject == variable)
        .map(|c| {
            format!(
                "since {} ({}; level {:+.1}×)",
                c.change_point_run,
                match c.persists {
                    Some(true) => "persists",
                    Some(false) => "not confirmed",
                    None => "new",
                },
                c.level
            )
        })
        .unwrap_or_default();
    let why = match &j.verdict {
        Verdict::NotJudged(why) => why.clone(),
        Verdict::Judged => j
            .not_judged
            .iter()
            .find(|n| n.variable == variable)
            .map(|n| n.why.clone())
            .unwrap_or_default(),
    };
    let col =
        |g: &dyn Fn(&history::judge::ParameterJudgement) -> String| pj.map(g).unwrap_or_default();
    [
        r.run_id.clone(),
        r.time_utc.clone(),
        sig(p.in_unit()),
        p.std_error
            .map(|s| sig(s / p.unit_factor))
            .unwrap_or_default(),
        p.unit.clone(),
        col(&|q| sig(q.centre)),
        col(&|q| sig(q.scatter)),
        col(&|q| format!("{:+.2}", q.standardized)),
        col(&|q| f2(q.shewhart_limit)),
        col(&|q| f2(q.cusum[0])),
        col(&|q| f2(q.cusum[1])),
        col(&|q| f2(q.cusum_limit)),
        col(&|q| format!("{:+.2}", q.ewma)),
        col(&|q| f2(q.ewma_limit)),
        j.t2.map(|[t, _]| format!("{t:.1}")).unwrap_or_default(),
        j.t2.map(|[_, l]| format!("{l:.1}")).unwrap_or_default(),
        alarms.join(","),
        change,
        why,
    ]
    .join("\t")
}
