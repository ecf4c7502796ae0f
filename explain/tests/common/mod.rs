//! What the open-world batches share: issue 19's rule for a confident name and the
//! reliability table's bins, written once so every batch measures the same thing.

use explain::{Explanation, Verdict};

/// Issue 19's threshold: a name is confident at a confidence or a first inclusion probability
/// of this or more.
pub const CONFIDENT: f64 = 0.8;

/// `explained` with a confidence or a first inclusion probability of [`CONFIDENT`] or more
/// (on an out-of-library or effect-free truth any such name is a confident wrong name).
pub fn confident(e: &Explanation) -> bool {
    e.verdict == Verdict::Explained
        && (e.confidence.unwrap_or(0.0) >= CONFIDENT
            || e.effects
                .first()
                .and_then(|f| f.inclusion_probability)
                .unwrap_or(0.0)
                >= CONFIDENT)
}

/// The reliability table of `stated` (confidence, right) pairs: per bin of stated
/// confidence, the verdicts, their mean stated confidence and the share right.
pub fn reliability_table(stated: &[(f64, bool)]) -> String {
    let mut out = String::from(
        "| stated confidence | explained verdicts | mean stated | share right |\n|---|---|---|---|\n",
    );
    for (lo, hi) in [
        (0.0, 0.5),
        (0.5, 0.7),
        (0.7, 0.8),
        (0.8, 0.9),
        (0.9, 0.95),
        (0.95, 1.01),
    ] {
        let bin: Vec<&(f64, bool)> = stated.iter().filter(|(c, _)| *c >= lo && *c < hi).collect();
        if bin.is_empty() {
            out += &format!("| {lo:.2}-{:.2} | 0 | - | - |\n", hi.min(1.0));
            continue;
        }
        let right = bin.iter().filter(|(_, r)| *r).count();
        let mean = bin.iter().map(|(c, _)| c).sum::<f64>() / bin.len() as f64;
        out += &format!(
            "| {lo:.2}-{:.2} | {} | {mean:.2} | {:.0} % ({right}) |\n",
            hi.min(1.0),
            bin.len(),
            100.0 * right as f64 / bin.len() as f64
        );
    }
    out
}

/// One row of a batch's case table for studying the calibration: written to the file named by
/// `EXPLAIN_BATCH_DUMP` (appended; nothing when it is unset). Columns: batch, truth, class
/// (`out`, `library`, `pair`, `none`), right (an `explained` verdict naming exactly the
/// truth), verdict, bootstrap share, confidence, first inclusion, effects, first effect,
/// whether its extrapolation passed (empty: not tested), its driver check's margin (its
/// chi-square less the best alternative's; empty: none), the lack of fit's p and reference.
#[allow(dead_code)] // each batch binary uses what it needs
pub fn dump_case(batch: &str, truth: &str, class: &str, right: bool, e: &Explanation) {
    let Ok(path) = std::env::var("EXPLAIN_BATCH_DUMP") else {
        return;
    };
    use std::io::Write;
    let first = e.effects.first();
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
    let line = format!(
        "{batch},\"{truth}\",{class},{},{},{},{},{},{},{},{},{},{},{}\n",
        right as u8,
        e.verdict.as_str(),
        opt(e.confidence_raw),
        opt(e.confidence),
        opt(first.and_then(|f| f.inclusion_probability)),
        e.effects.len(),
        first.map_or("", |f| f.name.as_str()),
        first
            .and_then(|f| f.extrapolation.as_ref())
            .filter(|x| x.testable)
            .map_or(String::new(), |x| (x.passed as u8).to_string()),
        opt(first
            .and_then(|f| f.driver_check.as_ref())
            .map(explain::drivers::DriverCheck::margin_over_best)),
        e.lack_of_fit.p_value,
        e.lack_of_fit.against,
    );
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .expect("EXPLAIN_BATCH_DUMP names a writable file");
    f.write_all(line.as_bytes()).expect("the dump is written");
}
