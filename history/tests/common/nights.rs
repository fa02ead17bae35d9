//! Simulated nights: a per-night truth (joint stiffnesses following a simulated temperature, a
//! slow wear trend in one joint from some night, a step in another from a later night), the
//! model's characteristics at that truth with measurement noise, identified with ident's fit
//! (warm start from the previous night) into history records. Then every night judged by the
//! history's rules and by the old `k_sigma` rule (`report::drift`: |x − x_first| /
//! √(σ² + σ_first²) > k), and the figures the issue asks for. Shared by the CI test and the
//! 90 nights × 20 seeds example.

use history::judge::{judge_series, JudgeConfig, Rule};
use history::record::{model_hash, Covariate, ParameterRecord, RunRecord};
use identify::{self as idn, data, synthetic, variables, Options};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rfe::model::Model;

/// The night-to-night story.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Nights simulated.
    pub nights: usize,
    /// Stiffness change per kelvin (relative, e.g. −0.005/K).
    pub per_kelvin: f64,
    /// Variable index of the wearing joint, first night of wear, relative loss per night.
    pub trend: (usize, usize, f64),
    /// Variable index of the stepping joint, its night, the factor (0.8 = −20 %).
    pub step: (usize, usize, f64),
    /// Relative measurement noise of the amplitudes.
    pub noise: f64,
    /// Start each night's fit from the previous night's estimate (else from the model's values).
    pub warm_start: bool,
}

impl Default for Scenario {
    fn default() -> Self {
        Scenario {
            nights: 90,
            per_kelvin: -0.006,
            trend: (0, 40, 0.001),
            step: (1, 65, 0.8),
            noise: 0.01,
            warm_start: true,
        }
    }
}

/// The simulated stand: a 3-block chain (two slideway joints, four isolators).
pub fn stand() -> (Model, variables::Variables) {
    let model = rfe::textbook::chain(3);
    let vars = variables::parse(
        r#"
[[variable]]
sdes = "joint 1"
parameter = "kn"
initial = "0.05 MPa/um"

[[variable]]
sdes = "joint 2"
parameter = "kn"
initial = "0.05 MPa/um"

[[variable]]
sdes = ["isolator 0", "isolator 1", "isolator 2", "isolator 3"]
parameter = "kn"
initial = "5 N/um"

[[variable]]
sdes = "joint 1"
parameter = "psi_n"
initial = 0.8
"#,
        "nights.toml",
        &model,
    )
    .expect("the nights' variables parse");
    (model, vars)
}

/// One simulated night.
pub struct Night {
    /// The history record of its identification.
    pub record: RunRecord,
    /// Per variable: whether the truth has left normal (trend or step active).
    pub changed: Vec<bool>,
}

/// Simulates and identifies `sc.nights` nights with `seed`.
pub fn simulate(sc: &Scenario, seed: u64) -> Vec<Night> {
    let (model, vars0) = stand();
    let hash = model_hash(format!("{model:?}").as_bytes());
    let lines = synthetic::log_lines(5.0, 600.0, 60);
    let mut rng = StdRng::seed_from_u64(seed);
    let mut normal = || -> f64 { StandardNormal.sample(&mut rng) };
    let x0 = vars0.initial();
    let mut vars = vars0.clone();
    let phase = std::f64::consts::TAU * (seed as f64 * 0.618).fract();
    let opts = Options::default();
    let mut out = Vec::with_capacity(sc.nights);
    for n in 0..sc.nights {
        let temp = 20.0 + 1.5 * (phase + n as f64 * 0.7).sin() + 0.8 * normal();
        let mut x = x0.clone();
        let mut changed = vec![false; x.len()];
        for (i, v) in vars0.vars.iter().enumerate() {
            if !v.dissipation {
                x[i] *= 1.0 + sc.per_kelvin * (temp - 20.0);
            }
        }
        let (ti, t0, rate) = sc.trend;
        if n >= t0 {
            x[ti] *= 1.0 - rate * (n - t0 + 1) as f64;
            changed[ti] = true;
        }
        let (si, s0, factor) = sc.step;
        if n >= s0 {
            x[si] *= factor;
            changed[si] = true;
        }
        let mut truth = model.clone();
        vars0.apply(&mut truth, &x);
        let d = synthetic::amplitude_data(&truth, &lines, sc.noise, &mut normal)
            .expect("the chain solves");
        let obs = data::validate(&d, &model, "night").expect("valid synthetic data");
        let id = idn::identify(&model, &obs, &vars, &opts, &mut |_, _| {})
            .expect("the identification starts");
        // Warm start: tonight's estimate is tomorrow's initial value.
        if sc.warm_start {
            for (v, e) in vars.vars.iter_mut().zip(&id.estimate) {
                v.initial = *e;
            }
        }
        let record = RunRecord {
            run_id: format!("night-{n:03}"),
            time_utc: format!("2026-01-01T{:02}:{:02}:00Z", n / 60, n % 60),
            stand: Some("simulated chain".into()),
            model_hash: hash.clone(),
            session: None,
            outcome: if id.stop.converged() { "ok" } else { "failure" }.into(),
            reduced_chi2: Some(id.uncertainty.reduced_chi2),
            parameters: vars0
                .vars
                .iter()
                .enumerate()
                .map(|(i, v)| ParameterRecord {
                    variable: v.name.clone(),
                    unit: v.unit.symbol.clone(),
                    unit_factor: v.unit.factor,
                    estimate: id.estimate[i],
                    std_error: Some(id.uncertainty.std_error[i]),
                })
                .collect(),
            characteristics: vec![],
            effects: vec![],
            covariates: vec![Covariate {
                name: "temperature".into(),
                unit: "degC".into(),
                value: temp + 0.1 * normal(),
            }],
            correlations: vec![],
            quantities: vec![],
        };
        out.push(Night { record, changed });
    }
    out
}

/// What one series of nights shows under one rule.
#[derive(Debug, Clone, Default)]
pub struct Figures {
    /// Night the step was first flagged (any alarm naming its parameter or T²), if ever.
    pub step_detected: Option<usize>,
    /// Night the trend was first flagged, if ever.
    pub trend_detected: Option<usize>,
    /// Alarms on parameter-nights whose truth was normal (judged nights only).
    pub false_alarms: usize,
    /// Judged parameter-nights whose truth was normal.
    pub normal_parameter_nights: usize,
}

impl Figures {
    /// Adds another series' counts (detections are not summed).
    pub fn add_counts(&mut self, o: &Figures) {
        self.false_alarms += o.false_alarms;
        self.normal_parameter_nights += o.normal_parameter_nights;
    }
}

fn first_flag(
    sc: &Scenario,
    var: usize,
    start: usize,
    flagged: &dyn Fn(usize, usize) -> bool,
) -> Option<usize> {
    (start..sc.nights).find(|&n| flagged(n, var))
}

/// The history's rules over the nights.
pub fn judge_history(sc: &Scenario, nights: &[Night], cfg: &JudgeConfig) -> Figures {
    let records: Vec<RunRecord> = nights.iter().map(|n| n.record.clone()).collect();
    let js = judge_series(&records, cfg);
    let names: Vec<String> = records[0]
        .parameters
        .iter()
        .map(|p| p.variable.clone())
        .collect();
    // A T² alarm names no parameter: it counts for a parameter only when that parameter
    // deviates most in it; otherwise it is a false alarm of the night when nothing changed.
    let flagged = |n: usize, var: usize| -> bool {
        let j = &js[n];
        j.alarms.iter().any(|a| match a.rule {
            Rule::HotellingT2 => j
                .parameters
                .iter()
                .max_by(|a, b| a.standardized.abs().total_cmp(&b.standardized.abs()))
                .is_some_and(|p| p.variable == names[var]),
            _ => a.subject == names[var],
        })
    };
    let mut f = Figures {
        step_detected: first_flag(sc, sc.step.0, sc.step.1, &flagged),
        trend_detected: first_flag(sc, sc.trend.0, sc.trend.1, &flagged),
        ..Figures::default()
    };
    for (n, night) in nights.iter().enumerate() {
        if js[n].verdict != history::judge::Verdict::Judged {
            continue;
        }
        for (v, changed) in night.changed.iter().enumerate() {
            if !changed {
                f.normal_parameter_nights += 1;
                f.false_alarms += usize::from(flagged(n, v));
            }
        }
        // A T² alarm on a night with nothing changed at all is one more false alarm.
        if !night.changed.iter().any(|c| *c)
            && js[n].alarms.iter().any(|a| a.rule == Rule::HotellingT2)
            && !(0..names.len())
                .any(|v| flagged(n, v) && !js[n].alarms.iter().any(|a| a.subject == names[v]))
        {
            f.false_alarms += 1;
        }
    }
    f
}

/// Today's rule: every parameter against the first run, alarm beyond `k` standard errors of the
/// difference; judged from the second night on.
pub fn judge_k_sigma(sc: &Scenario, nights: &[Night], k: f64, from_night: usize) -> Figures {
    let first = &nights[0].record;
    let flagged = |n: usize, var: usize| -> bool {
        let (b, x) = (&first.parameters[var], &nights[n].record.parameters[var]);
        let d = (b.std_error.unwrap_or(0.0).powi(2) + x.std_error.unwrap_or(0.0).powi(2)).sqrt();
        d > 0.0 && ((x.estimate - b.estimate) / d).abs() > k
    };
    let mut f = Figures {
        step_detected: first_flag(sc, sc.step.0, sc.step.1, &flagged),
        trend_detected: first_flag(sc, sc.trend.0, sc.trend.1, &flagged),
        ..Figures::default()
    };
    for (n, night) in nights.iter().enumerate().skip(from_night.max(1)) {
        for (v, changed) in night.changed.iter().enumerate() {
            if !changed {
                f.normal_parameter_nights += 1;
                f.false_alarms += usize::from(flagged(n, v));
            }
        }
    }
    f
}
