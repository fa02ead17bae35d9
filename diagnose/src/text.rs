//! The diagnosis as text, in the paper's units: the verdict first, then each round.

use super::*;

/// The diagnosis as text: verdict before, ranking, refits, accepted effects, error before/after.
pub fn text(d: &Diagnosis) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "Diagnosis");
    let _ = writeln!(s, "  before: {}", d.before.verdict);
    for (i, r) in d.rounds.iter().enumerate() {
        round_text(&mut s, i, r);
    }
    let _ = writeln!(s);
    if d.accepted.is_empty() {
        let indicated = d.rounds.iter().any(|r| !r.not_identifiable.is_empty());
        let _ = writeln!(
            s,
            "  no effect added: {}",
            if indicated {
                "the significant ones were not physical, not identifiable or only partial fixes"
            } else {
                "nothing significant at the chosen level"
            }
        );
    }
    for a in &d.accepted {
        let ps: Vec<String> = a.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(s, "  added: {} ({})", a.effect, ps.join(", "));
        let _ = writeln!(s, "         {}", gain_text(a));
        if !a.equivalent.is_empty() {
            let alike: Vec<String> = a.equivalent.iter().map(Effect::describe).collect();
            let _ = writeln!(
                s,
                "         ≡ the data cannot tell it from: {}",
                first_three(&alike)
            );
        }
        if let Some(place) = &a.place {
            let _ = writeln!(s, "         {place}");
        }
    }
    before_after_text(&mut s, d);
    let _ = writeln!(s, "  after: {}", d.after.verdict);
    if let Some(v) = &d.outside_library {
        let _ = writeln!(s, "  {v}");
    }
    let skipped: Vec<&NotTried> = d.not_tried.iter().collect();
    if !skipped.is_empty() {
        let _ = writeln!(s, "\n  not tried ({}):", skipped.len());
        for n in skipped.iter().take(12) {
            let _ = writeln!(s, "    - {}: {}", n.effect, n.reason);
        }
        if skipped.len() > 12 {
            let _ = writeln!(
                s,
                "    … and {} more (see the JSON report)",
                skipped.len() - 12
            );
        }
    }
    s
}

/// The final model in one block, to be read first: after an accepted effect, every variable's
/// value at the final fit in its report unit with its Cramér-Rao error (bounds hit flagged) and
/// each added effect's parameters; when nothing was accepted, that the first fit stands.
pub fn final_text(id: &Identification, d: &Diagnosis) -> String {
    use rfe::display::{relative, sig};
    use std::fmt::Write;
    let mut s = String::new();
    // The diagnosis continued the identification (and tried more starts) until it converged;
    // say so when even that did not converge.
    let converged = if d.base.converged || (d.base.stop.is_empty() && id.stop.converged()) {
        String::new()
    } else {
        let stop = if d.base.stop.is_empty() {
            id.stop.describe()
        } else {
            d.base.stop.clone()
        };
        format!(" — the fit did NOT converge ({stop})")
    };
    if d.accepted.is_empty() {
        let _ = writeln!(
            s,
            "FINAL MODEL = the first fit above: the diagnosis added nothing{converged}"
        );
        if let Some(v) = &d.outside_library {
            let _ = writeln!(s, "  {v}");
        }
        return s;
    }
    let _ = writeln!(
        s,
        "FINAL MODEL: the first fit above is superseded; {} effect(s) added{converged}",
        d.accepted.len()
    );
    if let Some(v) = &d.outside_library {
        let _ = writeln!(s, "  {v}");
    }
    let _ = writeln!(
        s,
        "  {:<20} {:<8} {:>12} {:>12} {:>9}",
        "variable", "unit", "value", "std error", "σ/x"
    );
    for (i, v) in id.variables.vars.iter().enumerate() {
        let x = d.estimate[i];
        let se = d.std_error.get(i).copied().unwrap_or(f64::NAN);
        let f = v.unit.factor;
        let tol = 1e-9 * v.scale;
        let bound = if x <= v.lower + tol {
            "  at lower bound"
        } else if x >= v.upper - tol {
            "  at upper bound"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "  {:<20} {:<8} {:>12} {:>12} {:>9}{bound}",
            v.name,
            v.unit.symbol,
            sig(x / f, 5),
            sig(se / f, 3),
            if x != 0.0 {
                relative(se / x)
            } else {
                "-".into()
            }
        );
    }
    for a in &d.accepted {
        let ps: Vec<String> = a.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(s, "  + {} ({})", a.effect, ps.join(", "));
        let _ = writeln!(s, "    {}", gain_text(a));
        if let Some(place) = &a.place {
            let _ = writeln!(s, "    {place}");
        }
    }
    s
}

/// The first three of `items`, then how many more.
fn first_three(items: &[String]) -> String {
    let more = items.len().saturating_sub(3);
    let tail = if more > 0 {
        format!(" and {more} more")
    } else {
        String::new()
    };
    format!("{}{tail}", items[..items.len().min(3)].join("; "))
}

/// What an accepted effect gained when it was added: the RMS amplitude error in dB over every
/// fitted point, and the criterion.
pub fn gain_text(a: &Refit) -> String {
    format!(
        "gain when added: RMS error {:.2} → {:.2} dB, criterion J {:.1} → {:.1}",
        a.rms_db_before, a.rms_db_after, a.criterion_before, a.criterion_after
    )
}

/// Round `i` of a diagnosis: the ranking, the refits, the placement and the removals.
pub(super) fn round_text(s: &mut String, i: usize, r: &Round) {
    use std::fmt::Write;
    let _ = writeln!(s, "\n  round {}: {} candidates scored (score test at the current fit); LR threshold p < {:.1e}", i + 1, r.candidates, r.threshold);
    let _ = writeln!(
        s,
        "    {:>4}  {:<14} {:>10} {:>9}  effect",
        "rank", "kind", "LM", "p"
    );
    for c in r.ranked.iter().take(10) {
        let _ = writeln!(
            s,
            "    {:>4}  {:<14} {:>10.1} {:>9.1e}  {}",
            c.rank, c.kind, c.statistic, c.p_value, c.effect
        );
        if !c.equivalent.is_empty() {
            let _ = writeln!(s, "          ≡ {}", first_three(&c.equivalent));
        }
    }
    for (k, f) in r.refits.iter().enumerate() {
        let mark = if r.accepted == Some(k) {
            "ACCEPTED"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "    refit: {}: J {:.1} → {:.1}, RMS {:.2} → {:.2} dB, LR {:.1} ({} dof), p {:.1e}, ΔBIC {:.1} {mark}",
            f.effect,
            f.criterion_before,
            f.criterion_after,
            f.rms_db_before,
            f.rms_db_after,
            f.lr,
            f.dof,
            f.p_value,
            f.bic_change
        );
    }
    for f in &r.pairs {
        let _ = writeln!(
            s,
            "    pair: {}: J {:.1} → {:.1}, LR {:.1} ({} dof), p {:.1e}",
            f.effect, f.criterion_before, f.criterion_after, f.lr, f.dof, f.p_value
        );
    }
    for m in &r.relocated {
        let _ = writeln!(
            s,
            "    moved: {} (J {:.1} there, the best of the same effect refitted at its other places)",
            m.effect, m.criterion_after
        );
    }
    for x in &r.replaced {
        let _ = writeln!(
            s,
            "    replaced: {} → {} (J {:.1} there, an effect of another kind on the same bodies)",
            x.effect, x.by.effect, x.by.criterion_after
        );
    }
    if let Some(p) = &r.placed {
        let ps: Vec<String> = p.params.iter().map(ParamEstimate::describe).collect();
        let _ = writeln!(
            s,
            "    placed: {} ({}): its place fitted, LR {:.1} against the model without it",
            p.effect,
            ps.join(", "),
            p.lr
        );
    }
    for x in &r.not_identifiable {
        let _ = writeln!(
            s,
            "    indicated but not added: {} ({})",
            x.effect, x.reason
        );
    }
    for x in &r.removed {
        let _ = writeln!(
            s,
            "    removed: {} (not needed once this round's effect is in: LR {:.1}, p {:.2e})",
            x.effect, x.lr, x.p_value
        );
    }
}

/// The error before and after the diagnosis, one line per figure.
pub(super) fn before_after_text(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let _ = writeln!(s, "\n  error before → after:");
    let _ = writeln!(
        s,
        "    criterion J     {:.1} → {:.1}",
        d.before.criterion, d.after.criterion
    );
    let _ = writeln!(
        s,
        "    reduced χ²      {:.2} → {:.2}",
        d.before.reduced_chi2, d.after.reduced_chi2
    );
    let _ = writeln!(
        s,
        "    RMS error       {:.2} dB → {:.2} dB",
        d.before.rms_db, d.after.rms_db
    );
    if let (Some(a), Some(b)) = (d.before.chi2_p, d.after.chi2_p) {
        let _ = writeln!(
            s,
            "    χ² p-value      {} → {}",
            rfe::display::p_value(a),
            rfe::display::p_value(b)
        );
    }
    for (a, b) in d
        .before
        .characteristics
        .iter()
        .zip(&d.after.characteristics)
    {
        let _ = writeln!(
            s,
            "    RMS error       {:<28} {:.2} dB → {:.2} dB ({} → {})",
            a.label,
            a.rms_db,
            b.rms_db,
            rfe::display::relative(a.rms_relative),
            rfe::display::relative(b.rms_relative)
        );
    }
}
