//! Forward selection of missing effects.
//!
//! Each step fits every applicable candidate jointly with the current model and ranks them by
//! the BIC improvement. The best is added only when
//! 1. its BIC improvement is positive,
//! 2. it beats the null distribution of the best improvement over all candidates (a guard
//!    against false discovery: a parametric bootstrap of the score statistics, drawn from the
//!    current model linearised at its fit with Gaussian noise, `Options::null_draws` draws
//!    with a fixed seed) at level `Options::alpha`, and
//! 3. it predicts held-out blocks of test points better (lower RMSE; for the ripple, which
//!    only changes the scatter, a lower negative log predictive density), and
//! 4. it is not carried by a single test point: with the point that contributes most to the
//!    improvement left out, the improvement still clears the guard's critical value at level
//!    [`INFLUENCE_ALPHA`] (so one corrupt row, isolated outliers aside, cannot make a
//!    finding, while a variance effect whose evidence sits in its largest deviations keeps
//!    most of it).
//!
//! Which candidates the data cannot tell apart is judged by the block bootstrap of the whole
//! selection ([`crate::bootstrap`]).

use model::effects::{CurrentModel, Effect, Param};
use model::plant::NoiseSource;

use super::fit::{self, Fit, HeldOut, ModelSpec};
use super::library;
use super::points::TestPoints;
use super::stats;

/// Seed of the null simulation, fixed so the same data always gives the same verdict.
const NULL_SEED: u64 = 0x5eed_0e4f_1a7e_0006;
/// Above this many points only the leading candidates (by the score test) are fitted and
/// scored on held-out points.
const FULL_TABLE_POINTS: usize = 20_000;
/// Candidates fitted per step on large data.
const SCREEN_KEEP: usize = 3;
/// Level of the guard that the best improvement must still clear with its most influential
/// test point left out (at least `Options::alpha`).
pub const INFLUENCE_ALPHA: f64 = 0.05;

/// Settings of the selection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Level of the false-discovery guard (probability that effect-free data passes it).
    pub alpha: f64,
    /// Most effects the model may carry (loaded ones included).
    pub max_effects: usize,
    /// Draws of the null simulation.
    pub null_draws: usize,
    /// Folds of the held-out validation.
    pub folds: usize,
    /// Replicates of the block bootstrap of the selection (0: none; then no inclusion
    /// probabilities and no ambiguity judgement).
    pub replicates: usize,
    /// A competitor is ambiguous with a named effect when at least this share of the
    /// bootstrap replicates select the competitor without the named effect.
    pub ambiguity_share: f64,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            alpha: 0.002,
            max_effects: 4,
            null_draws: 20_000,
            folds: 5,
            replicates: 200,
            ambiguity_share: 0.2,
        }
    }
}

/// One candidate at one step.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The effect.
    pub effect: Effect,
    /// Why it cannot show in this data, if it cannot.
    pub not_applicable: Option<&'static str>,
    /// Its joint fit with the current model.
    pub fit: Option<Fit>,
    /// BIC improvement over the current model (positive: better); a score-test estimate when
    /// `estimated` (large data: only the leading candidates are fitted).
    pub improvement: f64,
    /// Whether `improvement` is a score-test estimate rather than a fit.
    pub estimated: bool,
    /// Held-out score of the current model with it.
    pub held_out: Option<HeldOut>,
}

/// One step of the forward selection.
#[derive(Debug, Clone)]
pub struct Step {
    /// Every candidate, best first (inapplicable ones last).
    pub candidates: Vec<Candidate>,
    /// Probability that effect-free data (under the current model) gives a best improvement
    /// at least this large.
    pub p_value: f64,
    /// The smallest best improvement the guard lets through (its critical value).
    pub critical: f64,
    /// Held-out score of the current model.
    pub held_out_before: Option<HeldOut>,
    /// Whether the best candidate was added.
    pub accepted: bool,
    /// Why the best was or was not added.
    pub reason: String,
}

impl Step {
    /// The best candidate of the step.
    pub fn best(&self) -> Option<&Candidate> {
        self.candidates.first().filter(|c| c.fit.is_some())
    }
}

/// Result of the forward selection.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Fit of the starting model (the paper's, or a loaded one).
    pub start: Fit,
    /// Its held-out score.
    pub start_held_out: Option<HeldOut>,
    /// The steps.
    pub steps: Vec<Step>,
    /// The final model.
    pub end: Fit,
    /// Its held-out score.
    pub end_held_out: Option<HeldOut>,
}

impl Selection {
    /// Effects added, strongest (first added) first.
    pub fn added(&self) -> Vec<Effect> {
        self.steps
            .iter()
            .filter(|s| s.accepted)
            .filter_map(|s| s.best().map(|c| c.effect))
            .collect()
    }
}

/// Fits `effect` jointly with `current`, from a start with the effect at zero.
fn fit_candidate(points: &TestPoints, current: &Fit, effect: Effect) -> Fit {
    let spec = current.spec.with(effect);
    let mut start = current.model;
    library::clear_params(effect, &mut start.effects);
    let first = fit::fit(points, &points.all, &spec, &start);
    // The nonlinear effects get a second start away from zero and the better fit wins; on
    // large data only when the first start stalled at zero or did not converge.
    let stalled = effect
        .mean_param()
        .is_some_and(|q| first.model.params()[q.index()] == 0.0);
    if points.len() > FULL_TABLE_POINTS && first.converged && !stalled {
        return first;
    }
    let alt = match effect {
        Effect::SpeedDependentAxialFriction => {
            let w = points.speed_centres.first().copied().unwrap_or(30.0);
            Some(w * w * 0.5)
        }
        Effect::LoadDependentFriction => Some(0.3),
        _ => None,
    };
    match alt {
        Some(v) => {
            let mut p = start.params();
            let q = effect
                .mean_param()
                .expect("nonlinear effects are mean effects");
            p[q.index()] = v;
            start.set_params(&p);
            let second = fit::fit(points, &points.all, &spec, &start);
            if second.bic < first.bic {
                second
            } else {
                first
            }
        }
        None => first,
    }
}

/// Score tests of the candidates against the current model: the approximate likelihood ratio
/// of each (from the scores projected past the fitted parameters) and their joint null
/// distribution, for screening and for the false-discovery guard.
struct ScoreTests {
    /// Approximate likelihood ratio per mean candidate (`None`: no direction of its own).
    lr: Vec<Option<f64>>,
    /// Approximate likelihood ratio of the ripple variance.
    ripple_lr: f64,
    /// Identifiable mean candidates (indices into the candidate list).
    keep: Vec<usize>,
    /// Cholesky factor of their score correlation.
    chol: Vec<f64>,
}

fn score_tests(points: &TestPoints, current: &Fit, mean: &[Effect]) -> ScoreTests {
    let extra: Vec<Param> = mean.iter().filter_map(|e| e.mean_param()).collect();
    let p = current.free.len();
    let k = extra.len();
    let m = p + k;
    let sc = fit::scores(points, current, &extra);
    let gram = &sc.gram;
    // Schur complement: the candidates' scores after projecting out the fitted parameters.
    let gff: Vec<f64> = (0..p)
        .flat_map(|i| (0..p).map(move |j| (i, j)))
        .map(|(i, j)| {
            gram[i * m + j]
                + if i == j {
                    1e-12 * gram[i * m + i].abs()
                } else {
                    0.0
                }
        })
        .collect();
    let inv = stats::invert_spd(&gff, p).unwrap_or_else(|| vec![0.0; p * p]);
    let mut schur = vec![0.0; k * k];
    let mut projected = vec![0.0; k];
    for a in 0..k {
        let mut u = sc.score[p + a];
        for i in 0..p {
            for j in 0..p {
                u -= gram[(p + a) * m + i] * inv[i * p + j] * sc.score[j];
            }
        }
        projected[a] = u;
        for b in 0..k {
            let mut v = gram[(p + a) * m + p + b];
            for i in 0..p {
                for j in 0..p {
                    v -= gram[(p + a) * m + i] * inv[i * p + j] * gram[j * m + p + b];
                }
            }
            schur[a * k + b] = v;
        }
    }
    let identifiable =
        |a: usize| schur[a * k + a] > 1e-9 * gram[(p + a) * m + p + a].abs().max(1e-300);
    let keep: Vec<usize> = (0..k).filter(|&a| identifiable(a)).collect();
    let lr = (0..k)
        .map(|a| {
            identifiable(a).then(|| {
                let u = projected[a];
                let u = if library::one_sided(mean[a]) {
                    u.max(0.0)
                } else {
                    u
                };
                u * u / schur[a * k + a]
            })
        })
        .collect();
    let q = keep.len();
    let mut cov = vec![0.0; q * q];
    for (x, &a) in keep.iter().enumerate() {
        for (y, &b) in keep.iter().enumerate() {
            let s = (schur[a * k + a] * schur[b * k + b]).sqrt();
            cov[x * q + y] = schur[a * k + b] / s + if x == y { 1e-9 } else { 0.0 };
        }
    }
    let chol = stats::cholesky(&cov, q).unwrap_or_else(|| {
        // Numerically indefinite: treat the scores as independent.
        (0..q * q)
            .map(|i| if i % (q + 1) == 0 { 1.0 } else { 0.0 })
            .collect()
    });
    ScoreTests {
        lr,
        ripple_lr: sc.ripple_z.max(0.0).powi(2),
        keep,
        chol,
    }
}

/// Null distribution of the best BIC improvement over the `mean` candidates (plus the ripple
/// when `ripple`): draws of the linearised score statistics under the current model with
/// Gaussian noise.
fn null_best_improvements(
    tests: &ScoreTests,
    mean: &[Effect],
    ripple: bool,
    n: usize,
    draws: usize,
) -> Vec<f64> {
    let ln_n = (n as f64).ln();
    let q = tests.keep.len();
    let l = &tests.chol;
    let one_sided: Vec<bool> = tests
        .keep
        .iter()
        .map(|&a| library::one_sided(mean[a]))
        .collect();
    let penalty: Vec<f64> = tests
        .keep
        .iter()
        .map(|&a| library::parameter_count(mean[a]) as f64 * ln_n)
        .collect();
    let mut rng = NoiseSource::new(NULL_SEED);
    let mut z = vec![0.0; q];
    (0..draws)
        .map(|_| {
            z.iter_mut().for_each(|v| *v = rng.normal());
            let mut best = f64::NEG_INFINITY;
            for x in 0..q {
                let u: f64 = (0..=x).map(|y| l[x * q + y] * z[y]).sum();
                let lr = if one_sided[x] {
                    u.max(0.0).powi(2)
                } else {
                    u * u
                };
                best = best.max(lr - penalty[x]);
            }
            let zr = rng.normal();
            if ripple {
                best = best.max(zr.max(0.0).powi(2) - ln_n);
            }
            best
        })
        .collect()
}

/// A p-value for messages.
fn p_text(p: f64) -> String {
    if p < 0.001 {
        "p < 0.001".into()
    } else {
        format!("p {p:.3}")
    }
}

/// Whether the held-out validation confirms adding `effect`.
fn confirmed(
    effect: Effect,
    before: Option<HeldOut>,
    after: Option<HeldOut>,
    hold_gain: bool,
) -> (bool, String) {
    match (before, after) {
        (Some(b), Some(a)) => match effect {
            Effect::MeshLoadSharingRipple => (
                a.nlpd < b.nlpd,
                format!("held-out log score {:.3} -> {:.3}", -b.nlpd, -a.nlpd),
            ),
            Effect::LinearBushFriction if hold_gain => (
                a.rmse <= 1.01 * b.rmse,
                format!(
                    "explains non-backdriven points; held-out RMSE {:.1} -> {:.1} mA",
                    b.rmse * 1e3,
                    a.rmse * 1e3
                ),
            ),
            _ => (
                a.rmse < b.rmse,
                format!(
                    "held-out RMSE {:.1} -> {:.1} mA",
                    b.rmse * 1e3,
                    a.rmse * 1e3
                ),
            ),
        },
        _ => (true, "too few blocks of test points to hold any out".into()),
    }
}

/// The candidates of one step fitted against the current model, with the guard's null
/// distribution: what the selection and the bootstrap both start from.
#[derive(Debug, Clone)]
pub struct Explored {
    /// The fitted candidates, best first, then the screened-out ones with their score-test
    /// estimates (inapplicable candidates are not listed).
    pub candidates: Vec<Candidate>,
    /// Draws of the best improvement under the current model (the guard's null).
    pub null: Vec<f64>,
    /// The smallest best improvement the guard lets through at level `alpha`.
    pub critical: f64,
    /// The same at level [`INFLUENCE_ALPHA`], for the improvement without the most
    /// influential point.
    pub critical_influence: f64,
}

/// The critical value of the guard: the improvement a best candidate must exceed so that its
/// p-value, (1 + draws at or above it) / (1 + draws), falls below `alpha`.
fn critical_value(null: &[f64], alpha: f64) -> f64 {
    let allowed = alpha * (1 + null.len()) as f64 - 1.0;
    if allowed <= 0.0 {
        return f64::INFINITY;
    }
    // Up to `allowed` draws (strictly fewer) may reach the improvement.
    let k = (allowed.ceil() as usize).saturating_sub(1);
    if k >= null.len() {
        return f64::NEG_INFINITY;
    }
    let mut sorted = null.to_vec();
    let (_, v, _) = sorted.select_nth_unstable_by(k, |a, b| b.total_cmp(a));
    *v
}

/// Fits the applicable candidates not yet in `current` (on large data the leaders of the score
/// test) and simulates the guard's null; `None` when no candidate is left.
pub fn explore(points: &TestPoints, current: &Fit, opts: &Options) -> Option<Explored> {
    let traits = points.traits();
    let full_table = points.len() <= FULL_TABLE_POINTS;
    let applicable: Vec<Effect> = Effect::ALL
        .into_iter()
        .filter(|e| !current.spec.has(*e))
        .filter(|&e| library::not_applicable(e, &traits).is_none())
        .collect();
    if applicable.is_empty() {
        return None;
    }
    let mean: Vec<Effect> = applicable
        .iter()
        .copied()
        .filter(|e| e.mean_param().is_some())
        .collect();
    let ripple = applicable.contains(&Effect::MeshLoadSharingRipple);
    let tests = score_tests(points, current, &mean);
    let ln_n = (current.n as f64).ln();
    // Score-test estimate of each candidate's BIC improvement, for screening.
    let estimate = |e: Effect| -> f64 {
        let k = library::parameter_count(e) as f64 * ln_n;
        if e == Effect::MeshLoadSharingRipple {
            return tests.ripple_lr - k;
        }
        let a = mean.iter().position(|&m| m == e).expect("a mean candidate");
        let mut lr = tests.lr[a].unwrap_or(0.0);
        if e == Effect::LinearBushFriction && !points.holds.is_empty() {
            let (_, _, errors) = fit::fit_hold(&points.holds);
            let before = current.hold_errors as f64;
            lr += 2.0
                * (before - errors as f64)
                * ((1.0 - fit::HOLD_LABEL_ERROR) / fit::HOLD_LABEL_ERROR).ln();
        }
        lr - k
    };
    let mut ranked: Vec<(Effect, f64)> = applicable.iter().map(|&e| (e, estimate(e))).collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    let to_fit: Vec<Effect> = ranked
        .iter()
        .enumerate()
        .filter(|(i, (e, _))| full_table || *i < SCREEN_KEEP || *e == Effect::LinearBushFriction)
        .map(|(_, (e, _))| *e)
        .collect();
    let fits = fit::par_map(&to_fit, |&e| fit_candidate(points, current, e));
    let mut candidates: Vec<Candidate> = to_fit
        .iter()
        .zip(fits)
        .map(|(&effect, f)| Candidate {
            effect,
            not_applicable: None,
            improvement: current.bic - f.bic,
            estimated: false,
            fit: Some(f),
            held_out: None,
        })
        .collect();
    candidates.sort_by(|a, b| b.improvement.total_cmp(&a.improvement));
    // The screened-out candidates follow with their estimates.
    for &(e, est) in &ranked {
        if !to_fit.contains(&e) {
            candidates.push(Candidate {
                effect: e,
                not_applicable: None,
                fit: None,
                improvement: est,
                estimated: true,
                held_out: None,
            });
        }
    }
    let null = null_best_improvements(&tests, &mean, ripple, current.n, opts.null_draws);
    let critical = critical_value(&null, opts.alpha);
    let critical_influence = critical_value(&null, INFLUENCE_ALPHA.max(opts.alpha));
    Some(Explored {
        candidates,
        null,
        critical,
        critical_influence,
    })
}

/// Per-point parts of a fit's log-likelihood of the currents, for refits without one point:
/// rows, squared residuals scaled by the point's relative noise variance, and the
/// log of that variance times the rows.
struct PointParts {
    rows: Vec<f64>,
    scaled_sse: Vec<f64>,
    log_var: Vec<f64>,
}

impl PointParts {
    fn of(points: &TestPoints, fit: &Fit) -> Self {
        let ev = fit.model.evaluator();
        let s2 = fit.sigma0 * fit.sigma0;
        let r = fit.model.effects.mesh_ripple_rms;
        let rho = if r > 0.0 && s2 > 0.0 { r * r / s2 } else { 0.0 };
        let mut out = PointParts {
            rows: Vec::with_capacity(points.len()),
            scaled_sse: Vec::with_capacity(points.len()),
            log_var: Vec::with_capacity(points.len()),
        };
        for k in 0..points.len() {
            let op = &points.ops[k];
            let e = points.current[k] - ev.current(op);
            let n = points.weight[k];
            let v = if rho > 0.0 {
                let f = ev.friction_current(op);
                1.0 + rho * f * f
            } else {
                1.0
            };
            out.rows.push(n);
            out.scaled_sse.push((n * e * e + points.within_ss[k]) / v);
            out.log_var.push(n * v.ln());
        }
        out
    }

    /// Log-likelihood of the currents without point `skip` (noise level re-profiled, the
    /// ripple's share held).
    fn loglik_without(&self, totals: (f64, f64, f64), skip: usize) -> f64 {
        let n = totals.0 - self.rows[skip];
        let s = (totals.1 - self.scaled_sse[skip]).max(1e-300);
        let l = totals.2 - self.log_var[skip];
        -0.5 * (n * (2.0 * std::f64::consts::PI * s / n).ln() + l + n)
    }

    fn totals(&self) -> (f64, f64, f64) {
        (
            self.rows.iter().sum(),
            self.scaled_sse.iter().sum(),
            self.log_var.iter().sum(),
        )
    }
}

/// The BIC improvement of `with` over `current` when the point that contributes most to it is
/// left out, and that point.
fn improvement_without_top_point(points: &TestPoints, current: &Fit, with: &Fit) -> (f64, usize) {
    let a = PointParts::of(points, current);
    let b = PointParts::of(points, with);
    let (ta, tb) = (a.totals(), b.totals());
    let dk = (with.k as f64 - current.k as f64).max(0.0);
    let mut worst = (f64::INFINITY, 0usize);
    for k in 0..points.len() {
        let n = ta.0 - a.rows[k];
        if n < 3.0 {
            continue;
        }
        let gain = 2.0
            * (b.loglik_without(tb, k) + with.loglik_hold
                - a.loglik_without(ta, k)
                - current.loglik_hold)
            - dk * n.ln();
        if gain < worst.0 {
            worst = (gain, k);
        }
    }
    worst
}

/// Forward selection from the model `spec` started at `start`.
pub fn select(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &CurrentModel,
    opts: &Options,
) -> Selection {
    let traits = points.traits();
    let first = fit::fit(points, &points.all, spec, start);
    // Refit from the first fit so a loaded model and a selected one end at the same optimum.
    let mut current = fit::fit(points, &points.all, spec, &first.model);
    let start_fit = current.clone();
    let start_held_out = fit::held_out(points, spec, &current.model);
    let mut current_held_out = start_held_out;
    let mut steps = Vec::new();
    let full_table = points.len() <= FULL_TABLE_POINTS;

    while current.spec.effects.len() < opts.max_effects {
        let pending: Vec<Effect> = Effect::ALL
            .into_iter()
            .filter(|e| !current.spec.has(*e))
            .collect();
        let Some(Explored {
            mut candidates,
            null,
            critical,
            critical_influence,
        }) = explore(points, &current, opts)
        else {
            break;
        };
        let best_improvement = candidates[0].improvement;
        let exceed = null.iter().filter(|&&v| v >= best_improvement).count();
        let p_value = (1 + exceed) as f64 / (1 + null.len()) as f64;
        // Held-out scores: every fitted candidate on small data; on large data the best,
        // and only when the guard has not already turned it down.
        let guard_passed = best_improvement > 0.0 && p_value < opts.alpha;
        let scored: Vec<usize> = (0..candidates.len())
            .filter(|&i| candidates[i].fit.is_some())
            .filter(|&i| full_table || (guard_passed && i == 0))
            .collect();
        let scores = fit::par_map(&scored, |&i| {
            let c = &candidates[i];
            let f = c.fit.as_ref().expect("filtered to fitted candidates");
            fit::held_out(points, &f.spec, &f.model)
        });
        for (&i, s) in scored.iter().zip(scores) {
            candidates[i].held_out = s;
        }

        let best = &candidates[0];
        let best_fit = best.fit.as_ref().expect("fitted");
        let hold_gain = best_fit.hold_errors + 2 <= current.hold_errors;
        let (ok_held_out, held_note) =
            confirmed(best.effect, current_held_out, best.held_out, hold_gain);
        let (accepted, reason) = if best_improvement <= 0.0 {
            (
                false,
                format!(
                    "no candidate improves the BIC (best: {} by {:.1})",
                    best.effect.name(),
                    best_improvement
                ),
            )
        } else if p_value >= opts.alpha {
            (
                false,
                format!(
                    "{} improves the BIC by {:.1}, but effect-free data does that with probability {:.3} (guard {})",
                    best.effect.name(),
                    best_improvement,
                    p_value,
                    opts.alpha
                ),
            )
        } else if !ok_held_out {
            (
                false,
                format!(
                    "{} improves the BIC by {:.1} ({}) but does not predict held-out points better ({held_note})",
                    best.effect.name(),
                    best_improvement,
                    p_text(p_value)
                ),
            )
        } else {
            let (without, k) = improvement_without_top_point(points, &current, best_fit);
            if without <= critical_influence {
                (
                    false,
                    format!(
                        "{} improves the BIC by {:.1} ({}), but without the single test point at data row {} (the one that contributes most) only by {:.1}, below the {:.1} that effect-free data reaches with probability {}: one point does not make a finding",
                        best.effect.name(),
                        best_improvement,
                        p_text(p_value),
                        points.rows[k] + 1,
                        without,
                        critical_influence,
                        INFLUENCE_ALPHA.max(opts.alpha)
                    ),
                )
            } else {
                (
                    true,
                    format!(
                        "{} improves the BIC by {:.1} ({}); {held_note}",
                        best.effect.name(),
                        best_improvement,
                        p_text(p_value)
                    ),
                )
            }
        };
        // The inapplicable candidates close the table.
        for e in pending {
            if let Some(why) = library::not_applicable(e, &traits) {
                candidates.push(Candidate {
                    effect: e,
                    not_applicable: Some(why),
                    fit: None,
                    improvement: f64::NAN,
                    estimated: false,
                    held_out: None,
                });
            }
        }
        let next = accepted.then(|| (candidates[0].fit.clone(), candidates[0].held_out));
        steps.push(Step {
            candidates,
            p_value,
            critical,
            held_out_before: current_held_out,
            accepted,
            reason,
        });
        match next {
            Some((Some(f), h)) => {
                current = f;
                current_held_out = match h {
                    Some(h) => Some(h),
                    None => fit::held_out(points, &current.spec, &current.model),
                };
            }
            _ => break,
        }
    }
    Selection {
        start: start_fit,
        start_held_out,
        steps,
        end_held_out: current_held_out,
        end: current,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn critical_value_matches_the_p_value_rule() {
        let null: Vec<f64> = (0..999).map(|k| k as f64).collect();
        // alpha 0.01 of 1000: fewer than 9 draws may reach it: above the 9th largest (990).
        let c = critical_value(&null, 0.01);
        assert_eq!(c, 990.0);
        let above = |v: f64| (1 + null.iter().filter(|&&x| x >= v).count()) as f64 / 1000.0;
        assert!(above(c + 0.5) < 0.01);
        assert!(above(c) >= 0.01);
        assert_eq!(critical_value(&null, 0.0005), f64::INFINITY);
    }
}
