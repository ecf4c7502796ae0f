//! The finding in words, the text summary and the report folder of `rig explain`: residual
//! plots before and after, the candidate table, every step and the gap in detail.

use std::fmt::Write as _;
use std::path::Path;

use super::gap::{Bin, Gap};
use super::select::Selection;
use super::{CandidateReport, Explanation, Outcome, Verdict};
use crate::ExplainError;
use reporting::plot::{self, Panel};

fn ma(a: f64) -> String {
    format!("{:.1} mA", a * 1e3)
}

fn opt_ma(a: Option<f64>) -> String {
    a.map(ma).unwrap_or_else(|| "n/a".into())
}

fn opt_pct(p: Option<f64>) -> String {
    p.map(|p| format!("{:.0} %", 100.0 * p))
        .unwrap_or_else(|| "n/a".into())
}

fn p_text(p: f64) -> String {
    if p < 0.001 {
        "p < 0.001".into()
    } else {
        format!("p {p:.3}")
    }
}

/// The residuals' whiteness in words that follow the Ljung-Box p-value: "white" only when
/// nothing suggests otherwise (p >= 0.1).
fn whiteness_words(p: f64) -> &'static str {
    if p < 0.01 {
        "not white (correlated in time)"
    } else if p < 0.1 {
        "not clearly white (weakly correlated in time)"
    } else {
        "consistent with white noise"
    }
}

/// The lack of fit and where it lives, as a sentence.
fn lack_of_fit_text(e: &Explanation) -> String {
    let l = &e.lack_of_fit;
    let mut s = format!(" {}", capitalised(&l.text()));
    if !l.testable {
        s.push('.');
        return s;
    }
    s.push_str(if l.significant {
        ": a significant discrepancy remains"
    } else {
        ": what remains is within that noise"
    });
    let at = l.locations_text();
    if !at.is_empty() {
        let _ = write!(s, " (it stands out {at})");
    }
    s.push('.');
    if let Some(shape) = &e.residual_shape {
        let _ = write!(s, " Its shape: {}.", shape.description);
        if !shape.user_effect.is_empty() {
            s.push_str(" A ready [[user_effects]] entry is in the JSON (`residual_shape.user_effect`) and the report: name it, paste it into the rig file and refit.");
        }
    }
    if let Some(law) = &e.proposed_law {
        let _ = write!(
            s,
            " A proposed law (units checked: the expression is in A): {} = {}; held out by {} it predicts to {:.1} mA RMSE{}, where the generic shape gets {:.1} mA; in {:.0} % of the resamples. Its [[user_effects]] entry is in the JSON (`proposed_law.user_effect`): paste it into the rig file and refit, or add it with a [[model.terms]] entry of its name to the model `--write-model` writes and the virtual rig runs it (`rig sim serve --model FILE`, then `rig discover`).",
            law.expression,
            law.words,
            law.held_out,
            law.holdout_rmse_a * 1e3,
            law.pure_error_a
                .map(|p| format!(" against a pure error of {:.1} mA", p * 1e3))
                .unwrap_or_default(),
            law.generic_holdout_rmse_a * 1e3,
            100.0 * law.bootstrap_share
        );
    }
    s
}

fn capitalised(text: &str) -> String {
    let mut c = text.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

/// The bin of `gap` that stands out most (largest |mean| / standard error).
fn worst_bin(gap: &Gap) -> Option<(&'static str, &Bin)> {
    let mut best: Option<(&'static str, &Bin, f64)> = None;
    for (axis, bins) in [
        ("cam speed", &gap.by_speed),
        ("load", &gap.by_load),
        ("temperature/time", &gap.by_thermal),
    ] {
        for b in bins {
            let z = b.mean_residual_ma.abs() / b.std_error_ma.max(1e-9);
            if best.is_none_or(|(_, _, zb)| z > zb) {
                best = Some((axis, b, z));
            }
        }
    }
    best.map(|(a, b, _)| (a, b))
}

fn params_text(
    p: &std::collections::BTreeMap<String, f64>,
    iv: &std::collections::BTreeMap<String, [f64; 2]>,
) -> String {
    p.iter()
        .map(|(k, v)| match iv.get(k) {
            Some([lo, hi]) => format!("{k} = {v:.4} [{lo:.4}, {hi:.4}]"),
            None => format!("{k} = {v:.4}"),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The outliers in a sentence (empty without any).
fn outliers_text(e: &Explanation) -> String {
    let n = e.outliers.len();
    if n == 0 {
        return String::new();
    }
    let first = &e.outliers[0];
    format!(
        " {n} row{} set aside as outlier{} (first: row {}, line {}: {}).",
        if n == 1 { " was" } else { "s were" },
        if n == 1 { "" } else { "s" },
        first.row,
        first.line,
        first.reason
    )
}

/// The bootstrap's confidence in a sentence (empty without a bootstrap).
fn confidence_text(e: &Explanation) -> String {
    match (e.confidence, &e.bootstrap) {
        (Some(c), Some(b)) if e.verdict == Verdict::Explained => format!(
            " Confidence {:.0} %: the probability that this finding is right, calibrated on generated batches with truths outside the library ({:.0} % of {} resamples of {} blocks of consecutive test points reach it).",
            100.0 * c,
            100.0 * e.confidence_raw.unwrap_or(c),
            b.replicates,
            b.blocks
        ),
        (Some(c), Some(b)) if !e.effects.is_empty() => format!(
            " Confidence {:.0} %: the probability that every effect named is part of the truth, calibrated on generated batches with truths outside the library ({:.0} % of {} resamples of {} blocks of consecutive test points reach the same finding).",
            100.0 * c,
            100.0 * e.confidence_raw.unwrap_or(c),
            b.replicates,
            b.blocks
        ),
        (Some(c), Some(b)) => format!(
            " Confidence {:.0} %: the share of {} resamples of {} blocks of consecutive test points that reach the same finding.",
            100.0 * c,
            b.replicates,
            b.blocks
        ),
        _ => String::new(),
    }
}

/// Effects that change only the friction torque, as a function of the load: a friction
/// coefficient that changes with load and a sliding stroke that shortens under load (any
/// law). For any deflection d(F) the coefficient mu (1 - d(F) / e) draws the same current.
const FRICTION_TORQUE_OF_LOAD: [&str; 2] = ["load-dependent-friction", "tooth-compliance"];

/// What further tests would separate the candidates of an ambiguous verdict (first
/// principles, see docs/explain-validation.md): a constant offset stays at zero load, where
/// an effect on the friction torque draws nothing; two effects on the friction torque as a
/// function of load are the same current unless the axial force depends on the speed (the
/// speed-dependent axial friction, which `carried` tells), whatever the loads and speeds
/// tested.
fn what_separates(ambiguous: &[String], carried: impl Fn(&str) -> bool) -> String {
    let has = |n: &str| ambiguous.iter().any(|a| a == n);
    let friction_pair = FRICTION_TORQUE_OF_LOAD.iter().all(|n| has(n));
    let axial_with_speed = carried("speed-dependent-axial-friction");
    let mut out = Vec::new();
    if has("current-sensor-offset") && FRICTION_TORQUE_OF_LOAD.iter().any(|n| has(n)) {
        out.push(
            "an offset stays at zero load, where friction that changes with load or a shortened stroke draws nothing: tests with no load hung (the vibrator running free) separate them",
        );
    }
    if friction_pair && !axial_with_speed {
        out.push(
            "load-dependent friction and tooth compliance both change only the friction torque, as a function of the load, and here the axial force does not depend on the speed: no further test of the current at other loads or speeds separates those two (a measured tooth deflection or friction coefficient would)",
        );
    }
    if out.is_empty() {
        "more tests at other loads, speeds or temperatures would separate them".to_string()
    } else {
        out.join("; ")
    }
}

/// The finding in words.
pub fn finding(e: &Explanation, selection: &Selection) -> String {
    let s = finding_core(e, selection);
    format!("{s}{}{}", confidence_text(e), outliers_text(e))
}

fn finding_core(e: &Explanation, selection: &Selection) -> String {
    let mut s = String::new();
    let model = if e.known_effects.is_empty() {
        format!(
            "The paper's model (Eq. 10 with mu fitted = {:.3})",
            e.mu_before
        )
    } else {
        format!(
            "The loaded model (mu = {:.3}, with {})",
            e.mu_before,
            e.known_effects.join(", ")
        )
    };
    match e.verdict {
        Verdict::NoMissingEffect | Verdict::Unexplained => {
            if e.verdict == Verdict::NoMissingEffect {
                let _ = write!(
                    s,
                    "{model} agrees with the measurement to {} RMS (held-out {}): no candidate effect is needed.",
                    ma(e.rmse_before_a),
                    opt_ma(e.holdout_rmse_before_a)
                );
            } else {
                let _ = write!(
                    s,
                    "{model} misses the measurement by {} RMS (held-out {}) and none of the named effects explains it: a discrepancy remains whose cause is not in the library.",
                    ma(e.rmse_before_a),
                    opt_ma(e.holdout_rmse_before_a)
                );
            }
            if let Some(step) = selection.steps.first() {
                let _ = write!(s, " Closest candidate: {}.", step.decision);
            }
            let w = &e.gap_after.whiteness;
            let _ = write!(
                s,
                " The residuals are {} in time order (Ljung-Box {}).",
                whiteness_words(w.p_value),
                p_text(w.p_value)
            );
            s.push_str(&lack_of_fit_text(e));
        }
        Verdict::Explained | Verdict::Ambiguous | Verdict::PartlyExplained => {
            let _ = write!(
                s,
                "{model} misses the measured current by {} RMS",
                ma(e.rmse_before_a)
            );
            if let Some((axis, b)) = worst_bin(&e.gap_before) {
                let _ = write!(
                    s,
                    "; the residuals stand out by {} (mean {:+.1} mA at {}, {} rows)",
                    axis, b.mean_residual_ma, b.label, b.rows
                );
            }
            s.push_str(". ");
            let accepted: Vec<&super::StepReport> = e.steps.iter().filter(|s| s.accepted).collect();
            for (k, eff) in e.effects.iter().enumerate() {
                let _ = write!(
                    s,
                    "{} {}: {}. It lowers the BIC by {:.1} ({}), held-out RMSE {}",
                    if k == 0 { "Missing:" } else { "Also:" },
                    eff.name,
                    eff.description,
                    -eff.delta_bic,
                    p_text(eff.p_value),
                    opt_ma(eff.holdout_rmse_a)
                );
                if let Some(p) = eff.inclusion_probability_raw {
                    let _ = write!(s, ", selected in {:.0} % of the resamples", 100.0 * p);
                }
                if let Some(p) = eff.inclusion_probability {
                    let _ = write!(
                        s,
                        " (probability {:.0} % that it is part of the truth, calibrated)",
                        100.0 * p
                    );
                }
                s.push_str(". ");
                if let Some(x) = eff.extrapolation.as_ref().filter(|x| x.testable) {
                    let _ = write!(s, "Extrapolation: {}. ", x.summary);
                }
                let rivals = accepted.get(k).map_or(&[][..], |st| &st.ambiguous_with[..]);
                if let Some(p) = &eff.only_together_with {
                    let _ = write!(
                        s,
                        "It and {p} reach physical values only together (fitted without the other, one of them needs values no rig can have). "
                    );
                }
                if let Some(p) = &eff.named_in_pair_with {
                    let _ = write!(
                        s,
                        "It and {p} are named as a pair: together they explain more than the best single candidate with any partner. "
                    );
                }
                if let Some(d) = eff.driver_check.as_ref().filter(|d| !d.separated) {
                    let _ = write!(s, "But {}. ", d.summary(&eff.name));
                }
                if k > 0 && !rivals.is_empty() {
                    let _ = write!(
                        s,
                        "(The data cannot tell it from {}: a fifth or more of the resamples select that instead.) ",
                        rivals.join(", ")
                    );
                }
            }
            if e.verdict == Verdict::Ambiguous && e.ambiguous.len() >= 2 {
                let shares = e
                    .ambiguous_candidates
                    .iter()
                    .map(|c| format!("{} {:.0} %", c.name, 100.0 * c.probability))
                    .collect::<Vec<_>>()
                    .join(", ");
                let _ = write!(
                    s,
                    "The data cannot tell {} apart: resampling blocks of consecutive test points selects them in {shares} of the replicates; the model takes {}, {}. ",
                    e.ambiguous.join(", "),
                    e.ambiguous[0],
                    what_separates(&e.ambiguous, |n| {
                        e.effects.iter().any(|f| f.name == n)
                            || e.known_effects.iter().any(|k| k == n)
                    })
                );
            }
            let w = &e.gap_after.whiteness;
            let _ = write!(
                s,
                "With it the gap shrinks from {} to {} RMS (held-out {} -> {}); the residuals are {} in time order (Ljung-Box {}).",
                ma(e.rmse_before_a),
                ma(e.rmse_after_a),
                opt_ma(e.holdout_rmse_before_a),
                opt_ma(e.holdout_rmse_after_a),
                whiteness_words(w.p_value),
                p_text(w.p_value)
            );
            s.push_str(&lack_of_fit_text(e));
            if e.verdict == Verdict::PartlyExplained {
                s.push_str(" The named effects shrink the gap but do not close it: part of the discrepancy has a cause the library does not name.");
            }
        }
    }
    s
}

/// The text `rig explain` prints without `--json`.
pub fn render_text(e: &Explanation, source: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "rig explain: {source} ({} rows with a current)", e.rows);
    let _ = writeln!(
        s,
        "verdict: {}{}",
        e.verdict.as_str(),
        e.confidence
            .map(|c| format!(" (confidence {:.0} %)", 100.0 * c))
            .unwrap_or_default()
    );
    let _ = writeln!(
        s,
        "  before: RMSE {}  held-out {}  mu {:.4}",
        ma(e.rmse_before_a),
        opt_ma(e.holdout_rmse_before_a),
        e.mu_before
    );
    let _ = writeln!(
        s,
        "  after:  RMSE {}  held-out {}  mu {:.4}",
        ma(e.rmse_after_a),
        opt_ma(e.holdout_rmse_after_a),
        e.mu_after
    );
    let _ = writeln!(s, "  {}", e.lack_of_fit.text());
    let at = e.lack_of_fit.locations_text();
    if !at.is_empty() {
        let _ = writeln!(s, "  the discrepancy lives {at}");
    }
    if !e.effects.is_empty() {
        let _ = writeln!(s, "effects, strongest first:");
        for eff in &e.effects {
            let _ = writeln!(
                s,
                "  {:<32} delta-BIC {:>8.1}  {}  held-out {}  inclusion {}",
                eff.name,
                eff.delta_bic,
                p_text(eff.p_value),
                opt_ma(eff.holdout_rmse_a),
                opt_pct(eff.inclusion_probability)
            );
            let _ = writeln!(s, "    {}", params_text(&eff.params, &eff.intervals));
            if let Some(p) = &eff.only_together_with {
                let _ = writeln!(s, "    plausible only together with {p}");
            }
            if let Some(p) = &eff.named_in_pair_with {
                let _ = writeln!(s, "    named as a pair with {p}");
            }
            for c in eff.limits.iter().filter(|c| c.within && c.at_limit) {
                let _ = writeln!(s, "    {}", c.at_limit_text());
            }
            if let Some(d) = eff.driver_check.as_ref().filter(|d| !d.separated) {
                let _ = writeln!(s, "    driver not settled: {}", d.summary(&eff.name));
            }
        }
    }
    if !e.ambiguous.is_empty() {
        let _ = writeln!(
            s,
            "ambiguous: {}",
            e.ambiguous_candidates
                .iter()
                .map(|c| format!("{} ({:.0} %)", c.name, 100.0 * c.probability))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if !e.outliers.is_empty() {
        let _ = writeln!(s, "outliers set aside ({}):", e.outliers.len());
        for o in e.outliers.iter().take(10) {
            let _ = writeln!(s, "  row {} (line {}): {}", o.row, o.line, o.reason);
        }
        if e.outliers.len() > 10 {
            let _ = writeln!(s, "  ... and {} more (see --json)", e.outliers.len() - 10);
        }
    }
    for w in &e.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    let _ = writeln!(s, "candidates (first step):");
    for c in &e.candidates {
        let _ = writeln!(s, "  {}", candidate_line(c));
    }
    let _ = writeln!(s, "finding: {}", e.finding);
    if let Some(d) = &e.report_dir {
        let _ = writeln!(s, "report: {d}");
    }
    if let Some(m) = &e.model_written {
        let _ = writeln!(s, "model written: {m}");
    }
    s
}

fn candidate_line(c: &CandidateReport) -> String {
    if c.applicable && c.rmse_a.is_none() {
        return format!(
            "{:<32} delta-BIC {:>8.1}  (score-test estimate, not fitted)",
            c.name,
            c.delta_bic.unwrap_or(f64::NAN)
        );
    }
    match c.delta_bic {
        Some(d) => format!(
            "{:<32} delta-BIC {:>8.1}  RMSE {:>9}  held-out {:>9}  inclusion {:>5}  {}",
            c.name,
            d,
            opt_ma(c.rmse_a),
            opt_ma(c.holdout_rmse_a),
            opt_pct(c.inclusion_probability),
            params_text(&c.params, &c.intervals)
        ),
        None => format!(
            "{:<32} not applicable: {}",
            c.name,
            c.note.as_deref().unwrap_or("")
        ),
    }
}

fn gap_markdown(title: &str, g: &Gap) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "### {title}\n");
    let _ = writeln!(
        s,
        "RMSE {} over {} rows, mean residual {:+.1} mA.\n",
        ma(g.rmse_a),
        g.rows,
        g.mean_residual_a * 1e3
    );
    for (axis, bins) in [
        ("cam speed", &g.by_speed),
        ("load", &g.by_load),
        (g.thermal_axis.as_deref().unwrap_or("time"), &g.by_thermal),
    ] {
        if bins.is_empty() {
            continue;
        }
        let _ = writeln!(
            s,
            "| {axis} | rows | mean residual, mA | std. error, mA |\n|---|---|---|---|"
        );
        for b in bins {
            let _ = writeln!(
                s,
                "| {} | {} | {:+.1} | {:.1} |",
                b.label, b.rows, b.mean_residual_ma, b.std_error_ma
            );
        }
        s.push('\n');
    }
    let w = &g.whiteness;
    let _ = writeln!(
        s,
        "Whiteness (order: {}): Ljung-Box Q = {:.1} over {} lags, {}; Durbin-Watson {:.2}.\n",
        w.order,
        w.ljung_box_q,
        w.lags,
        p_text(w.p_value),
        w.durbin_watson
    );
    let _ = writeln!(s, "| residual correlated with | r | p |\n|---|---|---|");
    for c in &g.correlations {
        let _ = writeln!(s, "| {} | {:+.3} | {:.2e} |", c.with, c.r, c.p_value);
    }
    s.push('\n');
    s
}

/// The report as Markdown.
pub fn markdown(e: &Explanation, source: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# rig explain: {source}\n");
    let _ = writeln!(s, "**Verdict: {}**\n", e.verdict.as_str());
    let _ = writeln!(s, "{}\n", e.finding);
    let _ = writeln!(
        s,
        "## Lack of fit\n\n{}.\n",
        capitalised(&e.lack_of_fit.text())
    );
    if let Some(shape) = &e.residual_shape {
        let _ = writeln!(
            s,
            "## The shape of what remains\n\n{} (residual RMSE {:.1} -> {:.1} mA).\n",
            capitalised(&shape.description),
            shape.rmse_ma[0],
            shape.rmse_ma[1]
        );
        if !shape.user_effect.is_empty() {
            let _ = writeln!(
                s,
                "As a user effect for the rig file (name it, paste it, refit with `rig explain --model`):\n\n```toml\n{}```\n",
                shape.user_effect
            );
        }
    }
    if let Some(law) = &e.proposed_law {
        let units = law
            .units
            .iter()
            .map(|(k, u)| format!("`{k}` {u}"))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            s,
            "## A proposed law\n\n`{}` (A), with {units}: {}.\n\nHeld out by {}: RMSE {:.1} mA with the law, {:.1} mA with the generic shape, {:.1} mA with neither{}; BIC gain {:.1}; the same law wins in {:.0} % of the block-bootstrap resamples.\n\n```toml\n{}```\n",
            law.expression,
            law.words,
            law.held_out,
            law.holdout_rmse_a * 1e3,
            law.generic_holdout_rmse_a * 1e3,
            law.residual_holdout_rmse_a * 1e3,
            law.pure_error_a
                .map(|p| format!("; pure error {:.1} mA", p * 1e3))
                .unwrap_or_default(),
            law.bic_gain,
            100.0 * law.bootstrap_share,
            law.user_effect
        );
    }
    if !e.lack_of_fit.locations.is_empty() {
        let _ = writeln!(
            s,
            "| where | bin | rows | mean residual, mA | z |\n|---|---|---|---|---|"
        );
        for l in &e.lack_of_fit.locations {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:+.1} | {:+.1} |",
                l.axis, l.label, l.rows, l.mean_residual_ma, l.z
            );
        }
        s.push('\n');
    }
    if !e.warnings.is_empty() {
        let _ = writeln!(s, "## Warnings\n");
        for w in &e.warnings {
            let _ = writeln!(s, "- {w}");
        }
        s.push('\n');
    }
    if !e.outliers.is_empty() {
        let _ = writeln!(
            s,
            "## Outliers set aside ({})\n\nThese rows are excluded from every fit.\n\n| row | line | column | value | reason |\n|---|---|---|---|---|",
            e.outliers.len()
        );
        for o in e.outliers.iter().take(200) {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} |",
                o.row, o.line, o.column, o.value, o.reason
            );
        }
        s.push('\n');
    }
    if let Some(b) = &e.bootstrap {
        let _ = writeln!(
            s,
            "## Confidence\n\nBlock bootstrap of the whole selection: {} replicates, {} blocks of {} consecutive test points (seed {:#x}). Confidence (same finding): {}.\n\n| selection | share |\n|---|---|",
            b.replicates,
            b.blocks,
            b.block_length,
            b.seed,
            opt_pct(e.confidence)
        );
        for set in &b.selections {
            let name = if set.effects.is_empty() {
                "(none)".to_string()
            } else {
                set.effects.join(" + ")
            };
            let _ = writeln!(s, "| {name} | {:.0} % |", 100.0 * set.share);
        }
        let _ = writeln!(s, "\n| effect | inclusion probability |\n|---|---|");
        for (name, p) in &e.inclusion_probabilities {
            let _ = writeln!(s, "| {name} | {:.0} % |", 100.0 * p);
        }
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "| | RMSE | held-out RMSE | BIC | mu |\n|---|---|---|---|---|\n| before | {} | {} | {:.1} | {:.4} |\n| after | {} | {} | {:.1} | {:.4} |\n",
        ma(e.rmse_before_a),
        opt_ma(e.holdout_rmse_before_a),
        e.bic_before,
        e.mu_before,
        ma(e.rmse_after_a),
        opt_ma(e.holdout_rmse_after_a),
        e.bic_after,
        e.mu_after
    );
    let _ = writeln!(
        s,
        "![residuals before](residuals_before.svg)\n\n![residuals after](residuals_after.svg)\n"
    );
    if !e.effects.is_empty() {
        let _ = writeln!(s, "## Effects added, strongest first\n");
        let _ = writeln!(
            s,
            "| effect | parameters [95 % interval] | delta-BIC | guard | held-out RMSE |\n|---|---|---|---|---|"
        );
        for eff in &e.effects {
            let _ = writeln!(
                s,
                "| {} | {} | {:.1} | {} | {} |",
                eff.name,
                params_text(&eff.params, &eff.intervals),
                eff.delta_bic,
                p_text(eff.p_value),
                opt_ma(eff.holdout_rmse_a)
            );
        }
        s.push('\n');
        for eff in &e.effects {
            if let Some(p) = &eff.only_together_with {
                let _ = writeln!(
                    s,
                    "- {} and {p} reach physical values only together (fitted without the other, one of them needs values no rig can have).",
                    eff.name
                );
            }
            if let Some(p) = eff.named_in_pair_with.as_ref().filter(|p| **p > eff.name) {
                let _ = writeln!(
                    s,
                    "- {} and {p} are named as a pair: together they explain more than the best single candidate of their step with any partner, each adding more than effect-free data would.",
                    eff.name
                );
            }
            if let Some(d) = &eff.driver_check {
                let _ = writeln!(s, "- Driver: {}.", d.summary(&eff.name));
            }
        }
        s.push('\n');
    }
    for (k, step) in e.steps.iter().enumerate() {
        let _ = writeln!(s, "## Step {}: {}\n", k + 1, step.reason);
        let _ = writeln!(
            s,
            "| candidate | parameters [95 % interval] | delta-BIC | BIC weight | RMSE | held-out RMSE | inclusion |\n|---|---|---|---|---|---|---|"
        );
        for c in &step.candidates {
            match c.delta_bic {
                Some(d) => {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {:.1} | {} | {} | {} | {} |",
                        c.name,
                        params_text(&c.params, &c.intervals),
                        d,
                        c.bic_weight.map(|w| format!("{w:.3}")).unwrap_or_default(),
                        opt_ma(c.rmse_a),
                        opt_ma(c.holdout_rmse_a),
                        opt_pct(c.inclusion_probability)
                    );
                }
                None => {
                    let _ = writeln!(
                        s,
                        "| {} | not applicable: {} | | | | | |",
                        c.name,
                        c.note.as_deref().unwrap_or("")
                    );
                }
            }
        }
        s.push('\n');
    }
    let _ = writeln!(s, "## The gap in detail\n");
    s.push_str(&gap_markdown("Before", &e.gap_before));
    s.push_str(&gap_markdown("After", &e.gap_after));
    s
}

fn candidates_csv(e: &Explanation) -> String {
    let mut s = String::from(
        "step,name,applicable,delta_bic,rmse_a,holdout_rmse_a,params,intervals,note,bic_weight,inclusion_probability\n",
    );
    for (k, step) in e.steps.iter().enumerate() {
        for c in &step.candidates {
            let f = |v: Option<f64>| v.map(|x| format!("{x:.6}")).unwrap_or_default();
            let params = c
                .params
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect::<Vec<_>>()
                .join(";");
            let iv = c
                .intervals
                .iter()
                .map(|(k, [lo, hi])| format!("{k}=[{lo};{hi}]"))
                .collect::<Vec<_>>()
                .join(";");
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},\"{}\",\"{}\",\"{}\",{},{}",
                k + 1,
                c.name,
                c.applicable,
                f(c.delta_bic),
                f(c.rmse_a),
                f(c.holdout_rmse_a),
                params,
                iv,
                c.note.as_deref().unwrap_or(""),
                f(c.bic_weight),
                f(c.inclusion_probability)
            );
        }
    }
    s
}

fn write(path: &Path, text: &str) -> Result<(), ExplainError> {
    reporting::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// The figures [`write_report`] writes into `dir`.
pub fn figures(dir: &Path) -> Vec<std::path::PathBuf> {
    ["residuals_before.svg", "residuals_after.svg"]
        .iter()
        .map(|f| dir.join(f))
        .collect()
}

/// Writes the report folder `dir`: `report.md`, `candidates.csv`, `explanation.json`,
/// `residuals_before.svg` and `residuals_after.svg` (printed at `size`).
pub fn write_report(
    dir: &Path,
    outcome: &Outcome,
    source: &str,
    size: reporting::figure::FigureSize,
) -> Result<(), ExplainError> {
    std::fs::create_dir_all(dir).map_err(|source| ExplainError::File {
        action: "create folder",
        path: dir.display().to_string(),
        source,
    })?;
    let e = &outcome.explanation;
    write(&dir.join("report.md"), &markdown(e, source))?;
    write(&dir.join("candidates.csv"), &candidates_csv(e))?;
    write(
        &dir.join("explanation.json"),
        &(serde_json::to_string_pretty(e)? + "\n"),
    )?;
    let pts = &outcome.points;
    let axes = |res: &[f64]| {
        let r: Vec<f64> = res.iter().map(|v| v * 1e3).collect();
        let mut panels = vec![
            Panel {
                x_label: plot::axis_label("cam speed ω_n", "rad/s"),
                x: pts.ops.iter().map(|o| o.omega_n).collect(),
                residual_ma: r.clone(),
            },
            Panel {
                x_label: plot::axis_label("load τ_rot", "N m"),
                x: pts.ops.iter().map(|o| o.tau_rot).collect(),
                residual_ma: r.clone(),
            },
        ];
        match pts.thermal {
            super::library::ThermalDriver::Temperature { reference_c } => panels.push(Panel {
                x_label: plot::axis_label("motor temperature", "°C"),
                x: pts.ops.iter().map(|o| o.thermal + reference_c).collect(),
                residual_ma: r,
            }),
            super::library::ThermalDriver::Time => panels.push(Panel {
                x_label: plot::axis_label("time", "s"),
                x: pts.ops.iter().map(|o| o.thermal).collect(),
                residual_ma: r,
            }),
            super::library::ThermalDriver::Unavailable => {}
        }
        panels
    };
    let y_max = outcome
        .before
        .residuals
        .iter()
        .chain(&outcome.after.residuals)
        .fold(0.0f64, |m, v| m.max(v.abs()))
        * 1.1e3;
    plot::residual_figure(
        &dir.join("residuals_before.svg"),
        size,
        &format!("before: RMSE {}", ma(e.rmse_before_a)),
        &axes(&outcome.before.residuals),
        y_max,
    )?;
    let title = if e.effects.is_empty() {
        format!("after (no effect added): RMSE {}", ma(e.rmse_after_a))
    } else {
        format!(
            "after adding {}: RMSE {}",
            e.effects
                .iter()
                .map(|f| f.name.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            ma(e.rmse_after_a)
        )
    };
    plot::residual_figure(
        &dir.join("residuals_after.svg"),
        size,
        &title,
        &axes(&outcome.after.residuals),
        y_max,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whiteness_words_follow_the_p_value() {
        // The issue's case: p = 0.017 is not "white".
        assert!(!whiteness_words(0.017).starts_with("consistent"));
        assert!(whiteness_words(0.017).contains("not clearly white"));
        assert!(whiteness_words(0.004).starts_with("not white"));
        assert_eq!(whiteness_words(0.5), "consistent with white noise");
    }

    #[test]
    fn an_ambiguous_verdict_says_what_would_separate_its_candidates() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let none = |_: &str| false;
        // The offset against an effect on the friction torque: tests at zero load.
        let t = what_separates(
            &names(&["current-sensor-offset", "load-dependent-friction"]),
            none,
        );
        assert!(
            t.contains("no load hung") && !t.contains("no further test"),
            "{t}"
        );
        // Friction that changes with load against a shortened stroke: no test of the current.
        let pair = names(&["tooth-compliance", "load-dependent-friction"]);
        let t = what_separates(&pair, none);
        assert!(
            t.contains("no further test") && !t.contains("no load hung"),
            "{t}"
        );
        // ... unless the axial force depends on the speed.
        let t = what_separates(&pair, |n| n == "speed-dependent-axial-friction");
        assert!(t.contains("other loads, speeds or temperatures"), "{t}");
        // All three: both sentences.
        let t = what_separates(
            &names(&[
                "current-sensor-offset",
                "tooth-compliance",
                "load-dependent-friction",
            ]),
            none,
        );
        assert!(
            t.contains("no load hung") && t.contains("no further test"),
            "{t}"
        );
        // Anything else: the general advice.
        let t = what_separates(&names(&["thermal-drift", "vibrator-viscous-loss"]), none);
        assert!(t.contains("other loads, speeds or temperatures"), "{t}");
    }
}
