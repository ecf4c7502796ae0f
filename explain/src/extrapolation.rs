//! Extrapolation, not only interpolation: each named effect is checked by holding out whole
//! speed levels (the slowest, then the fastest) and whole load ranges (the lightest third of
//! the load levels, then the heaviest), fitting the final model with and without the effect
//! on the rest and comparing the held-out RMSE. A law that only mimics the data inside the
//! tested range predicts the held-out edge worse than the model without it.

use serde::Serialize;

use super::fit::{self, Fit, ModelSpec};
use super::mechanism::Mechanism;
use super::points::TestPoints;

/// Fewest speed levels for a speed hold-out (two must remain to fit speed laws).
const MIN_SPEED_LEVELS: usize = 3;
/// Fewest load levels for a load hold-out.
const MIN_LOAD_LEVELS: usize = 4;
/// Levenberg-Marquardt iterations per round of an edge fit.
const EDGE_ITERATIONS: usize = 12;

/// One held-out edge of the tested range.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOutEdge {
    /// What was held out, e.g. "slowest speed level (4.9 Hz)" or "heaviest third of loads
    /// (2.9-3.7 N m)".
    pub held_out: String,
    /// Rows held out.
    pub rows: usize,
    /// Held-out RMSE of the final model without the effect, mA.
    pub rmse_without_ma: f64,
    /// Held-out RMSE of the final model with it, mA.
    pub rmse_with_ma: f64,
    /// Whether the effect predicts the edge better.
    pub better: bool,
}

/// The extrapolation test of one named effect.
#[derive(Debug, Clone, Serialize)]
pub struct Extrapolation {
    /// Whether the data has the levels for any hold-out.
    pub testable: bool,
    /// Whether the effect predicts the held-out edges better overall (pooled RMSE) and at
    /// no more than one edge worse.
    pub passed: bool,
    /// Each edge.
    pub edges: Vec<HeldOutEdge>,
    /// The result in words.
    pub summary: String,
}

/// The model `spec` without `cand`.
pub(crate) fn without(spec: &ModelSpec, cand: Mechanism) -> ModelSpec {
    let mut s = spec.clone();
    match cand {
        Mechanism::Effect(e) => s.effects.retain(|&x| x != e),
        Mechanism::Term(t) => s.terms.retain(|&x| x != t),
    }
    s
}

/// Held-out RMSE (A) of `spec` fitted on `train` from `start`, on `test`.
fn edge_rmse(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &Fit,
    train: &[usize],
    test: &[usize],
) -> f64 {
    let starts = start.term_starts(points, spec);
    // The final model is the start: a few iterations reach the edge fit (the cost of four
    // edges x two models stays small on large data).
    let f = fit::fit_capped(points, train, spec, &start.model, &starts, EDGE_ITERATIONS);
    let all = f.predict(points);
    let (mut sse, mut n) = (0.0, 0.0);
    for &k in test {
        let e = points.current[k] - all[k];
        sse += points.weight[k] * e * e + points.within_ss[k];
        n += points.weight[k];
    }
    if n > 0.0 { (sse / n).sqrt() } else { f64::NAN }
}

/// The held-out edges of the data: (label, held-out points).
fn edges(points: &TestPoints) -> Vec<(String, Vec<usize>)> {
    let mut out = Vec::new();
    let hz = |w: f64| w / std::f64::consts::TAU;
    let ns = points.speed_centres.len();
    if ns >= MIN_SPEED_LEVELS {
        // Levels are indexed in order of speed.
        let mut order: Vec<usize> = (0..ns).collect();
        order.sort_by(|&a, &b| points.speed_centres[a].total_cmp(&points.speed_centres[b]));
        for (name, level) in [("slowest", order[0]), ("fastest", order[ns - 1])] {
            let test: Vec<usize> = (0..points.len())
                .filter(|&k| points.speed_level[k] == level)
                .collect();
            out.push((
                format!(
                    "{name} speed level ({:.1} Hz)",
                    hz(points.speed_centres[level])
                ),
                test,
            ));
        }
    }
    let nl = points.load_centres.len();
    if nl >= MIN_LOAD_LEVELS {
        let mut order: Vec<usize> = (0..nl).collect();
        order.sort_by(|&a, &b| points.load_centres[a].total_cmp(&points.load_centres[b]));
        let third = nl.div_ceil(3).max(1);
        for (name, levels) in [
            ("lightest", &order[..third]),
            ("heaviest", &order[nl - third..]),
        ] {
            let test: Vec<usize> = (0..points.len())
                .filter(|&k| levels.contains(&points.load_level[k]))
                .collect();
            let lo = levels
                .iter()
                .map(|&l| points.load_centres[l])
                .fold(f64::INFINITY, f64::min);
            let hi = levels
                .iter()
                .map(|&l| points.load_centres[l])
                .fold(f64::NEG_INFINITY, f64::max);
            out.push((
                format!("{name} third of the loads ({lo:.2}-{hi:.2} N m)"),
                test,
            ));
        }
    }
    out
}

/// The extrapolation test of `cand`, an effect of the final model `after`.
pub fn extrapolation(points: &TestPoints, after: &Fit, cand: Mechanism) -> Extrapolation {
    let with = after.spec.clone();
    let less = without(&with, cand);
    let cases: Vec<(String, Vec<usize>, Vec<usize>)> = edges(points)
        .into_iter()
        .filter_map(|(label, test)| {
            let train: Vec<usize> = (0..points.len()).filter(|k| !test.contains(k)).collect();
            (train.len() >= 5 && !test.is_empty()).then_some((label, train, test))
        })
        .collect();
    if cases.is_empty() {
        return Extrapolation {
            testable: false,
            passed: true,
            edges: Vec::new(),
            summary: "not testable: too few speed or load levels to hold a whole one out".into(),
        };
    }
    let results = crate::parallel::par_map(&cases, |(_, train, test)| {
        (
            edge_rmse(points, &less, after, train, test),
            edge_rmse(points, &with, after, train, test),
        )
    });
    let mut edges_out = Vec::new();
    let (mut sse_without, mut sse_with, mut rows_total, mut worse) = (0.0, 0.0, 0.0, 0);
    for ((label, _, test), (r0, r1)) in cases.iter().zip(results) {
        let rows: f64 = test.iter().map(|&k| points.weight[k]).sum();
        sse_without += r0 * r0 * rows;
        sse_with += r1 * r1 * rows;
        rows_total += rows;
        let better = r1 < r0;
        if !better {
            worse += 1;
        }
        edges_out.push(HeldOutEdge {
            held_out: label.clone(),
            rows: rows as usize,
            rmse_without_ma: r0 * 1e3,
            rmse_with_ma: r1 * 1e3,
            better,
        });
    }
    let pooled_without = (sse_without / rows_total).sqrt();
    let pooled_with = (sse_with / rows_total).sqrt();
    let passed = pooled_with < pooled_without && worse <= 1;
    let summary = format!(
        "held-out edges of the tested range: RMSE {:.1} mA without it, {:.1} mA with it; better at {} of {} edges{}",
        pooled_without * 1e3,
        pooled_with * 1e3,
        edges_out.len() - worse,
        edges_out.len(),
        if passed {
            ""
        } else {
            ": the law does not carry beyond the data it was fitted to"
        }
    );
    Extrapolation {
        testable: true,
        passed,
        edges: edges_out,
        summary,
    }
}
