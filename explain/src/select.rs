//! Forward selection of missing effects.
//!
//! Each step fits every applicable candidate (a library effect in its own law, a family form
//! of one, or a user effect: [`Mechanism`]) jointly with the current model and ranks them by the
//! BIC improvement. The best is added only when
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

use model::effects::{CurrentModel, Effect};
use model::plant::NoiseSource;

use super::fit::{self, Column, Fit, HeldOut, ModelSpec};
use super::library;
use super::mechanism::Mechanism;
use super::points::TestPoints;
use super::stats;

/// Seed of the null simulation, fixed so the same data always gives the same verdict.
const NULL_SEED: u64 = 0x5eed_0e4f_1a7e_0006;
/// Above this many points only the leading candidates (by the score test) are fitted and
/// scored on held-out points.
const FULL_TABLE_POINTS: usize = 20_000;
/// Candidates fitted per step on large data.
const SCREEN_KEEP: usize = 3;
/// On pooled data a family form or user effect is fitted only when this many times its
/// score-test estimate of the BIC improvement, plus [`TERM_SCREEN_SLACK`], reaches the guard's
/// critical value (a fit gains up to about 2.2 times the estimate of a large effect, about the
/// estimate of a small one).
const TERM_SCREEN_FACTOR: f64 = 2.0;
/// See [`TERM_SCREEN_FACTOR`].
const TERM_SCREEN_SLACK: f64 = 10.0;
/// A step's pairs of candidates fitted jointly start from this many of its best fitted
/// candidates ([`pair_fits`])...
pub const PAIR_FIRSTS: usize = 4;
/// ... each with this many partners, those the score test from its fit ranks highest.
pub const PAIR_PARTNERS: usize = 2;
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
    /// Row noise of the current the user states, A (the lack-of-fit test's reference when
    /// the data has too few repeats for a pure error).
    pub stated_noise_a: Option<f64>,
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
            stated_noise_a: None,
        }
    }
}

/// Whether `spec` already carries library effect `e` in some law (its own or a form).
fn carries(points: &TestPoints, spec: &ModelSpec, e: Effect) -> bool {
    spec.has(e)
        || spec
            .terms
            .iter()
            .any(|&t| points.terms[t].effect() == Some(e))
}

/// The candidates `spec` does not carry yet (applicable or not): every library effect not in
/// it in any law, every family form of those, every user effect not in it.
pub fn pending(points: &TestPoints, spec: &ModelSpec) -> Vec<Mechanism> {
    let mut out: Vec<Mechanism> = Effect::ALL
        .into_iter()
        .filter(|&e| !carries(points, spec, e))
        .map(Mechanism::Effect)
        .collect();
    for (t, term) in points.terms.iter().enumerate() {
        let free = match term.effect() {
            Some(e) => !carries(points, spec, e),
            None => !spec.terms.contains(&t),
        };
        if free {
            out.push(Mechanism::Term(t));
        }
    }
    out
}

/// One candidate at one step.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The candidate.
    pub cand: Mechanism,
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
    pub decision: Decision,
    /// Pairs of the leading candidates fitted jointly with the current model (computed
    /// where the guard passed; see [`choose_pair`]), for the bootstrap to compare too.
    pub pairs: Vec<PairFit>,
}

/// Two candidates of one step fitted jointly with the current model.
#[derive(Debug, Clone)]
pub struct PairFit {
    /// The one that improves the current model more alone.
    pub first: Mechanism,
    /// The other.
    pub second: Mechanism,
    /// Their joint fit.
    pub fit: Fit,
    /// Whether every value of the joint fit is within its physical limits.
    pub plausible: bool,
}

/// A model compared by [`choose_pair`]: its BIC and whether every value in it is physical.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scored {
    /// Its BIC.
    pub bic: f64,
    /// Whether every value is within its physical limits.
    pub plausible: bool,
}

/// What a step decided about its best candidate, by the first rule that turned it down (in
/// the order they are tried), or that it was added. Printed as the step's `reason`.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// No candidate improves the BIC.
    NoImprovement {
        /// The best candidate's name.
        best: String,
        /// Its BIC improvement (not positive).
        improvement: f64,
    },
    /// Effect-free data reaches the improvement too often (the false-discovery guard).
    BelowGuard {
        /// The best candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The guard's level.
        alpha: f64,
    },
    /// It does not predict held-out points better.
    NotConfirmed {
        /// The best candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The held-out scores before and after, in words.
        held_out: String,
    },
    /// Its fit needs values no rig can have.
    Implausible {
        /// The best candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The limits broken, each with its reason.
        limits: String,
    },
    /// The improvement rests on a single test point.
    CarriedByOnePoint {
        /// The best candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The data row (1-based) of the point that contributes most.
        row: usize,
        /// The improvement without that point.
        without: f64,
        /// The guard's critical value at `level`.
        critical: f64,
        /// The level of that guard.
        level: f64,
    },
    /// A later effect (one was named before it) whose law its own driver does not tell from a
    /// generic shape in another variable: stacked without grounds, it is not named, and what
    /// it would explain is left to the lack of fit and the residual's shape.
    NotSeparated {
        /// The candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The driver check, in words.
        check: String,
    },
    /// Added to the model.
    Added {
        /// The candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The held-out scores before and after, in words.
        held_out: String,
        /// The effect of the step before, when that one needed this one to be plausible.
        partner: Option<String>,
    },
    /// Added with the next step's candidate as a pair in place of the step's best candidate:
    /// the two fitted together explain more than the best with any partner, each of the two
    /// improving on the other alone by more than the guard's critical value.
    AddedInPair {
        /// The candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value at its improvement.
        p_value: f64,
        /// The held-out scores before and after, in words.
        held_out: String,
        /// The step's best candidate alone, passed over (a family form named by its form).
        instead: String,
        /// Its BIC improvement alone.
        instead_improvement: f64,
        /// Whether its fit alone has every value within its limits.
        instead_plausible: bool,
        /// The next step's candidate, named with it.
        partner: String,
        /// The pair's BIC improvement over the model before the step.
        pair_improvement: f64,
    },
    /// Added although its fit alone needs values no rig can have, because the next step's
    /// effect, fitted jointly with it, brings every value within its limits.
    AddedOnlyTogether {
        /// The candidate's name.
        best: String,
        /// Its BIC improvement.
        improvement: f64,
        /// The guard's p-value.
        p_value: f64,
        /// The limits its fit alone breaks, each with its reason.
        limits: String,
        /// The next step's effect.
        partner: String,
    },
}

impl Decision {
    /// Whether the best candidate was added.
    pub fn accepted(&self) -> bool {
        matches!(
            self,
            Decision::Added { .. }
                | Decision::AddedOnlyTogether { .. }
                | Decision::AddedInPair { .. }
        )
    }
}

impl std::fmt::Display for Decision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Decision::NoImprovement { best, improvement } => write!(
                f,
                "no candidate improves the BIC (best: {best} by {improvement:.1})"
            ),
            Decision::BelowGuard {
                best,
                improvement,
                p_value,
                alpha,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1}, but effect-free data does that with probability {p_value:.3} (guard {alpha})"
            ),
            Decision::NotConfirmed {
                best,
                improvement,
                p_value,
                held_out,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}) but does not predict held-out points better ({held_out})",
                p_text(*p_value)
            ),
            Decision::Implausible {
                best,
                improvement,
                p_value,
                limits,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}), but only with values no rig can have: {limits}; it is not named",
                p_text(*p_value)
            ),
            Decision::CarriedByOnePoint {
                best,
                improvement,
                p_value,
                row,
                without,
                critical,
                level,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}), but without the single test point at data row {row} (the one that contributes most) only by {without:.1}, below the {critical:.1} that effect-free data reaches with probability {level}: one point does not make a finding",
                p_text(*p_value)
            ),
            Decision::NotSeparated {
                best,
                improvement,
                p_value,
                check,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}), but {check}; an effect added to one already named must follow its own variable: it is not named",
                p_text(*p_value)
            ),
            Decision::Added {
                best,
                improvement,
                p_value,
                held_out,
                partner,
            } => {
                write!(
                    f,
                    "{best} improves the BIC by {improvement:.1} ({}); {held_out}",
                    p_text(*p_value)
                )?;
                match partner {
                    Some(p) => write!(
                        f,
                        "; with it every value of {p} is physical: the two are plausible only together"
                    ),
                    None => Ok(()),
                }
            }
            Decision::AddedInPair {
                best,
                improvement,
                p_value,
                held_out,
                instead,
                instead_improvement,
                instead_plausible,
                partner,
                pair_improvement,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}); {held_out}; {instead} alone improves it more (by {instead_improvement:.1}{}), but {best} with {partner} (the next step) improves it by {pair_improvement:.1}, more than {instead} with any partner, and each of the two adds more than effect-free data would: the two are named together",
                p_text(*p_value),
                if *instead_plausible {
                    ""
                } else {
                    ", with values no rig can have"
                }
            ),
            Decision::AddedOnlyTogether {
                best,
                improvement,
                p_value,
                limits,
                partner,
            } => write!(
                f,
                "{best} improves the BIC by {improvement:.1} ({}); alone only with values no rig can have ({limits}), but with {partner} (the next step) every value is physical: the two are named together",
                p_text(*p_value)
            ),
        }
    }
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
    /// Candidates added, strongest (first added) first.
    pub fn added(&self) -> Vec<Mechanism> {
        self.steps
            .iter()
            .filter(|s| s.accepted)
            .filter_map(|s| s.best().map(|c| c.cand))
            .collect()
    }
}

/// Fits library effect `effect` jointly with `current`, from a start with the effect at zero.
fn fit_effect(points: &TestPoints, current: &Fit, effect: Effect) -> Fit {
    let spec = current.spec.with(effect);
    let mut start = current.model;
    library::clear_params(effect, &mut start.effects);
    let first = fit::fit_from(points, &points.all, &spec, &start, &current.term_x);
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
            let second = fit::fit_from(points, &points.all, &spec, &start, &current.term_x);
            if second.bic < first.bic {
                second
            } else {
                first
            }
        }
        None => first,
    }
}

/// The shape values a term's fit starts from and its score test looks along: its start, a
/// third of it and three times it (for a term with one shape parameter, fitted in ln).
fn shape_grid(points: &TestPoints, t: usize) -> Vec<Vec<f64>> {
    let term = &points.terms[t];
    let start = term.start_point();
    let shapes: Vec<usize> = (0..term.params.len())
        .filter(|&c| term.params[c].log)
        .collect();
    if shapes.len() != 1 {
        return vec![start];
    }
    let c = shapes[0];
    let (lo, hi) = term.params[c].fit_bounds();
    [0.0, -3f64.ln(), 3f64.ln()]
        .iter()
        .map(|d| {
            let mut x = start.clone();
            x[c] = (x[c] + d).clamp(lo, hi);
            x
        })
        .collect()
}

/// Fits term `t` jointly with `current` from each start of its shape grid; the best fit wins.
fn fit_term(points: &TestPoints, current: &Fit, t: usize) -> Fit {
    let spec = current.spec.with_term(t);
    let grid = shape_grid(points, t);
    let starts = |x: Vec<f64>| {
        let mut starts = current.term_x.clone();
        starts.push(x);
        starts
    };
    if grid.len() == 1 {
        let x = grid.into_iter().next().expect("one start");
        return fit::fit_from(points, &points.all, &spec, &current.model, &starts(x));
    }
    // A few iterations from each start show which basin is best; the fit finishes there.
    let best = grid
        .into_iter()
        .map(|x| {
            fit::fit_capped(
                points,
                &points.all,
                &spec,
                &current.model,
                &starts(x),
                SHAPE_LOOK_ITERATIONS,
            )
        })
        .min_by(|a, b| a.bic.total_cmp(&b.bic))
        .expect("a shape grid has a start");
    if best.converged {
        return best;
    }
    fit::fit_from(points, &points.all, &spec, &best.model, &best.term_x)
}

/// Levenberg-Marquardt iterations from each start of a term's shape grid before the best
/// one is followed to the end.
const SHAPE_LOOK_ITERATIONS: usize = 4;

/// Fits `cand` jointly with `current`.
pub(crate) fn fit_candidate(points: &TestPoints, current: &Fit, cand: Mechanism) -> Fit {
    match cand {
        Mechanism::Effect(e) => fit_effect(points, current, e),
        Mechanism::Term(t) => fit_term(points, current, t),
    }
}

/// A subspace of score columns a candidate's effect can move along (one per shape of a term).
#[derive(Debug, Clone)]
struct Block {
    /// Indices into the kept columns.
    cols: Vec<usize>,
    /// Inverse of their score covariance.
    inv: Vec<f64>,
    /// A single column whose null sits on its bound: only positive scores count.
    one_sided: bool,
}

impl Block {
    /// The approximate likelihood ratio of scores `u` (all kept columns).
    fn lr(&self, u: &[f64]) -> f64 {
        let b = self.cols.len();
        if self.one_sided && b == 1 {
            let v = u[self.cols[0]].max(0.0);
            return v * v * self.inv[0];
        }
        let mut q = 0.0;
        for x in 0..b {
            for y in 0..b {
                q += u[self.cols[x]] * self.inv[x * b + y] * u[self.cols[y]];
            }
        }
        q.max(0.0)
    }
}

/// Score tests of the candidates against the current model: the approximate likelihood ratio
/// of each (from the scores projected past the fitted unknowns, the largest over its
/// blocks) and their joint null distribution, for screening and for the false-discovery
/// guard.
struct ScoreTests {
    /// Approximate likelihood ratio per mean candidate (`None`: no direction of its own).
    lr: Vec<Option<f64>>,
    /// Approximate likelihood ratio of the ripple variance.
    ripple_lr: f64,
    /// The candidates' blocks.
    blocks: Vec<Vec<Block>>,
    /// Kept columns and the Cholesky factor of their score covariance.
    q: usize,
    chol: Vec<f64>,
}

/// The score columns of a mean candidate: blocks of (column, one-sided) lists.
fn columns_of(points: &TestPoints, cand: Mechanism) -> Vec<Vec<(Column, bool)>> {
    match cand {
        Mechanism::Effect(e) => match e.mean_param() {
            Some(q) => vec![vec![(Column::Param(q), library::one_sided(e))]],
            None => Vec::new(),
        },
        Mechanism::Term(t) => {
            let term = &points.terms[t];
            let linear: Vec<usize> = (0..term.params.len())
                .filter(|&c| !term.params[c].log)
                .collect();
            let single_one_sided = linear.len() == 1 && {
                let p = &term.params[linear[0]];
                p.null <= p.bounds.0
            };
            shape_grid(points, t)
                .into_iter()
                .map(|mut at| {
                    for &c in &linear {
                        at[c] = term.params[c].to_fit(term.params[c].null);
                    }
                    linear
                        .iter()
                        .map(|&c| {
                            (
                                Column::Term {
                                    term: t,
                                    coord: c,
                                    at: at.clone(),
                                },
                                single_one_sided,
                            )
                        })
                        .collect()
                })
                .collect()
        }
    }
}

fn score_tests(points: &TestPoints, current: &Fit, mean: &[Mechanism]) -> ScoreTests {
    let layout: Vec<Vec<Vec<(Column, bool)>>> =
        mean.iter().map(|&c| columns_of(points, c)).collect();
    let mut extra: Vec<Column> = Vec::new();
    let mut where_: Vec<Vec<(Vec<usize>, bool)>> = Vec::new();
    for blocks in &layout {
        let mut out = Vec::new();
        for block in blocks {
            let mut idx = Vec::new();
            let mut one = false;
            for (col, one_sided) in block {
                idx.push(extra.len());
                extra.push(col.clone());
                one = *one_sided;
            }
            out.push((idx, one));
        }
        where_.push(out);
    }
    let sc = fit::scores(points, current, &extra);
    let p = sc.own;
    let k = extra.len();
    let m = p + k;
    let gram = &sc.gram;
    // Schur complement: the candidates' scores after projecting out the fitted unknowns.
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
    // G_eo G_oo^-1, k x p.
    let mut proj = vec![0.0; k * p];
    for a in 0..k {
        for j in 0..p {
            proj[a * p + j] = (0..p).map(|i| gram[(p + a) * m + i] * inv[i * p + j]).sum();
        }
    }
    let mut schur = vec![0.0; k * k];
    let mut projected = vec![0.0; k];
    for a in 0..k {
        projected[a] = sc.score[p + a] - (0..p).map(|j| proj[a * p + j] * sc.score[j]).sum::<f64>();
        for b in 0..k {
            schur[a * k + b] = gram[(p + a) * m + p + b]
                - (0..p)
                    .map(|j| proj[a * p + j] * gram[j * m + p + b])
                    .sum::<f64>();
        }
    }
    let identifiable =
        |a: usize| schur[a * k + a] > 1e-9 * gram[(p + a) * m + p + a].abs().max(1e-300);
    let keep: Vec<usize> = (0..k).filter(|&a| identifiable(a)).collect();
    let position = |a: usize| keep.iter().position(|&x| x == a);
    let q = keep.len();
    let u: Vec<f64> = keep.iter().map(|&a| projected[a]).collect();
    let mut blocks = Vec::new();
    let mut lr = Vec::new();
    for cand_blocks in &where_ {
        let mut bs = Vec::new();
        for (idx, one_sided) in cand_blocks {
            let cols: Vec<usize> = idx.iter().filter_map(|&a| position(a)).collect();
            if cols.is_empty() {
                continue;
            }
            let b = cols.len();
            let sub: Vec<f64> = cols
                .iter()
                .flat_map(|&x| cols.iter().map(move |&y| (x, y)))
                .map(|(x, y)| {
                    schur[keep[x] * k + keep[y]]
                        + if x == y {
                            1e-9 * schur[keep[x] * k + keep[x]]
                        } else {
                            0.0
                        }
                })
                .collect();
            if let Some(inv) = stats::invert_spd(&sub, b) {
                bs.push(Block {
                    cols,
                    inv,
                    one_sided: *one_sided,
                });
            }
        }
        lr.push(
            bs.iter()
                .map(|b| b.lr(&u))
                .fold(None, |m: Option<f64>, v| Some(m.map_or(v, |m| m.max(v)))),
        );
        blocks.push(bs);
    }
    let mut cov = vec![0.0; q * q];
    for (x, &a) in keep.iter().enumerate() {
        for (y, &b) in keep.iter().enumerate() {
            cov[x * q + y] = schur[a * k + b] + if x == y { 1e-9 * schur[a * k + a] } else { 0.0 };
        }
    }
    let chol = stats::cholesky(&cov, q).unwrap_or_else(|| {
        // Numerically indefinite: treat the scores as independent.
        (0..q * q)
            .map(|i| {
                if i % (q + 1) == 0 {
                    cov[i].max(0.0).sqrt()
                } else {
                    0.0
                }
            })
            .collect()
    });
    ScoreTests {
        lr,
        ripple_lr: sc.ripple_z.max(0.0).powi(2),
        blocks,
        q,
        chol,
    }
}

/// Null distribution of the best BIC improvement over the `mean` candidates (plus the ripple
/// when `ripple`): draws of the linearised score statistics under the current model with
/// Gaussian noise.
fn null_best_improvements(
    points: &TestPoints,
    tests: &ScoreTests,
    mean: &[Mechanism],
    ripple: bool,
    n: usize,
    draws: usize,
) -> Vec<f64> {
    let ln_n = (n as f64).ln();
    let q = tests.q;
    let l = &tests.chol;
    let penalty: Vec<f64> = mean.iter().map(|c| c.penalty(points, n as f64)).collect();
    let mut rng = NoiseSource::new(NULL_SEED);
    let mut z = vec![0.0; q];
    let mut u = vec![0.0; q];
    (0..draws)
        .map(|_| {
            z.iter_mut().for_each(|v| *v = rng.normal());
            for x in 0..q {
                u[x] = (0..=x).map(|y| l[x * q + y] * z[y]).sum();
            }
            let mut best = f64::NEG_INFINITY;
            for (blocks, pen) in tests.blocks.iter().zip(&penalty) {
                for b in blocks {
                    best = best.max(b.lr(&u) - pen);
                }
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

/// Whether the held-out validation confirms adding `effect` (a library effect's law or a
/// term, `None`).
fn confirmed(
    effect: Option<Effect>,
    before: Option<HeldOut>,
    after: Option<HeldOut>,
    hold_gain: bool,
) -> (bool, String) {
    match (before, after) {
        (Some(b), Some(a)) => match effect {
            Some(Effect::MeshLoadSharingRipple) => (
                a.nlpd < b.nlpd,
                format!("held-out log score {:.3} -> {:.3}", -b.nlpd, -a.nlpd),
            ),
            Some(Effect::LinearBushFriction) if hold_gain => (
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

/// Score-test estimates of the BIC improvement of each of `cands` (applicable, not in
/// `current`) added to `current`, for screening; with the score tests and the mean
/// candidates they were taken over (for the guard's null).
fn estimate_improvements(
    points: &TestPoints,
    current: &Fit,
    cands: &[Mechanism],
) -> (ScoreTests, Vec<Mechanism>, Vec<f64>) {
    let ripple_cand = Mechanism::Effect(Effect::MeshLoadSharingRipple);
    let mean: Vec<Mechanism> = cands
        .iter()
        .copied()
        .filter(|c| *c != ripple_cand)
        .collect();
    let tests = score_tests(points, current, &mean);
    let estimate = |c: Mechanism| -> f64 {
        let k = c.penalty(points, current.n as f64);
        if c == ripple_cand {
            return tests.ripple_lr - k;
        }
        let a = mean.iter().position(|&m| m == c).expect("a mean candidate");
        let mut lr = tests.lr[a].unwrap_or(0.0);
        if c == Mechanism::Effect(Effect::LinearBushFriction) && !points.holds.is_empty() {
            let (_, _, errors) = fit::fit_hold(&points.holds);
            let before = current.hold_errors as f64;
            lr += 2.0
                * (before - errors as f64)
                * ((1.0 - fit::HOLD_LABEL_ERROR) / fit::HOLD_LABEL_ERROR).ln();
        }
        lr - k
    };
    let estimates = cands.iter().map(|&c| estimate(c)).collect();
    (tests, mean, estimates)
}

/// Fits the applicable candidates not yet in `current` (on large data the leaders of the score
/// test) and simulates the guard's null; `None` when no candidate is left.
pub fn explore(points: &TestPoints, current: &Fit, opts: &Options) -> Option<Explored> {
    let traits = points.traits();
    let full_table = points.len() <= FULL_TABLE_POINTS;
    let applicable: Vec<Mechanism> = pending(points, &current.spec)
        .into_iter()
        .filter(|c| c.not_applicable(points, &traits).is_none())
        .collect();
    if applicable.is_empty() {
        return None;
    }
    let ripple = applicable.contains(&Mechanism::Effect(Effect::MeshLoadSharingRipple));
    let (tests, mean, estimates) = estimate_improvements(points, current, &applicable);
    let mut ranked: Vec<(Mechanism, f64)> = applicable.iter().copied().zip(estimates).collect();
    ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
    let null = null_best_improvements(points, &tests, &mean, ripple, current.n, opts.null_draws);
    let critical = critical_value(&null, opts.alpha);
    let critical_influence = critical_value(&null, INFLUENCE_ALPHA.max(opts.alpha));
    // On pooled data a family form or user effect is fitted only when its score test could
    // reach the guard's critical value (its fit improving the BIC by up to
    // `TERM_SCREEN_FACTOR` times the estimate plus `TERM_SCREEN_SLACK`); the others keep
    // their estimates.
    let could_pass = |c: Mechanism, est: f64| {
        !points.pooled
            || matches!(c, Mechanism::Effect(_))
            || TERM_SCREEN_FACTOR * est + TERM_SCREEN_SLACK >= critical
    };
    let to_fit: Vec<Mechanism> = ranked
        .iter()
        .enumerate()
        .filter(|(i, (c, _))| {
            full_table || *i < SCREEN_KEEP || *c == Mechanism::Effect(Effect::LinearBushFriction)
        })
        .filter(|(_, (c, est))| could_pass(*c, *est))
        .map(|(_, (c, _))| *c)
        .collect();
    let fits = crate::parallel::par_map(&to_fit, |&c| fit_candidate(points, current, c));
    let mut candidates: Vec<Candidate> = to_fit
        .iter()
        .zip(fits)
        .map(|(&cand, f)| Candidate {
            cand,
            not_applicable: None,
            improvement: current.bic - f.bic,
            estimated: false,
            fit: Some(f),
            held_out: None,
        })
        .collect();
    candidates.sort_by(|a, b| b.improvement.total_cmp(&a.improvement));
    // The screened-out candidates follow with their estimates.
    for &(c, est) in &ranked {
        if !to_fit.contains(&c) {
            candidates.push(Candidate {
                cand: c,
                not_applicable: None,
                fit: None,
                improvement: est,
                estimated: true,
                held_out: None,
            });
        }
    }
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
        let predicted = fit.predict(points);
        let s2 = fit.sigma0 * fit.sigma0;
        let r = fit.model.effects.mesh_ripple_rms;
        let rho = if r > 0.0 && s2 > 0.0 { r * r / s2 } else { 0.0 };
        let mut out = PointParts {
            rows: Vec::with_capacity(points.len()),
            scaled_sse: Vec::with_capacity(points.len()),
            log_var: Vec::with_capacity(points.len()),
        };
        for (k, (op, pred)) in points.ops.iter().zip(predicted.iter()).enumerate() {
            let e = points.current[k] - pred;
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
    let dshapes = (with.shapes as f64 - current.shapes as f64).max(0.0);
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
            - (dk - dshapes) * n.ln()
            - dshapes * crate::terms::SHAPE_PENALTY;
        if gain < worst.0 {
            worst = (gain, k);
        }
    }
    worst
}

/// Forward selection from the model `spec` started at `start` (its terms at their first
/// starts).
pub fn select(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &CurrentModel,
    opts: &Options,
) -> Selection {
    let starts: Vec<Vec<f64>> = spec
        .terms
        .iter()
        .map(|&t| points.terms[t].start_point())
        .collect();
    select_from(points, spec, start, &starts, opts)
}

/// Forward selection from the model `spec` started at `start` and its terms at
/// `start_terms`: fit the starting model, then take steps until one adds nothing. A step
/// whose best candidate needs values no rig can have may still add it when the next step's
/// best candidate, fitted jointly with it, brings every value back within its limits: the
/// two are named together ([`Decision::AddedOnlyTogether`]), each having passed the same
/// tests as any other.
pub fn select_from(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &CurrentModel,
    start_terms: &[Vec<f64>],
    opts: &Options,
) -> Selection {
    let (mut current, start_held_out) = start_fit(points, spec, start, start_terms);
    let start_fit = current.clone();
    let mut current_held_out = start_held_out;
    let mut steps = Vec::new();
    while current.spec.effects.len() < opts.max_effects {
        let Some((mut step, null, critical_influence)) =
            take_step_with_null(points, &current, current_held_out, opts)
        else {
            break;
        };
        if let Some(second) = pair_steps(
            points,
            &current,
            current_held_out,
            &mut step,
            &null,
            critical_influence,
            opts,
        ) {
            steps.push(step);
            (current, current_held_out) = advance(points, &second);
            steps.push(second);
            continue;
        }
        if !step.accepted {
            let partner = matches!(step.decision, Decision::Implausible { .. })
                .then(|| complete_plausibility(points, &current, &step, opts))
                .flatten();
            let Some(mut next) = partner else {
                steps.push(step);
                break;
            };
            step.decision = only_together(&step.decision, &next, points);
            step.accepted = true;
            steps.push(step);
            (current, current_held_out) = advance(points, &next);
            if let Decision::Added { partner, .. } = &mut next.decision {
                *partner = steps
                    .last()
                    .and_then(Step::best)
                    .map(|b| b.cand.name(points).to_string());
            }
            steps.push(next);
            continue;
        }
        if !steps.is_empty()
            && let Some(refused) = not_separated(points, &current, &step)
        {
            step.decision = refused;
            step.accepted = false;
            steps.push(step);
            break;
        }
        (current, current_held_out) = advance(points, &step);
        steps.push(step);
    }
    Selection {
        start: start_fit,
        start_held_out,
        steps,
        end_held_out: current_held_out,
        end: current,
    }
}

/// The pairs of `candidates` (a step's, best first, fitted on one model) fitted jointly: each
/// of the [`PAIR_FIRSTS`] best fitted ones with the [`PAIR_PARTNERS`] fitted ones after it
/// that the score test from its fit ranks highest (a partner may add little alone and much
/// with it), the better one alone first.
pub fn pair_fits(points: &TestPoints, candidates: &[Candidate]) -> Vec<PairFit> {
    let pool: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.fit.is_some() && !c.estimated)
        .collect();
    let mut jobs: Vec<(usize, usize)> = Vec::new();
    for i in 0..pool.len().min(PAIR_FIRSTS) {
        let with = pool[i].fit.as_ref().expect("fitted");
        let carried = pending(points, &with.spec);
        let others: Vec<usize> = (i + 1..pool.len())
            .filter(|&j| carried.contains(&pool[j].cand))
            .collect();
        // The partners the score test from the first's fit ranks highest.
        let cands: Vec<Mechanism> = others.iter().map(|&j| pool[j].cand).collect();
        let (_, _, estimates) = estimate_improvements(points, with, &cands);
        let mut ranked: Vec<(usize, f64)> = others.into_iter().zip(estimates).collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        jobs.extend(ranked.iter().take(PAIR_PARTNERS).map(|&(j, _)| (i, j)));
    }
    crate::parallel::par_map(&jobs, |&(i, j)| {
        let with = pool[i].fit.as_ref().expect("fitted");
        let fit = fit_candidate(points, with, pool[j].cand);
        PairFit {
            first: pool[i].cand,
            second: pool[j].cand,
            plausible: crate::plausibility::check_model(points, &fit).plausible,
            fit,
        }
    })
}

/// The rule that takes two candidates at once in place of the step's best (the selection
/// and the bootstrap apply it alike): among the pairs whose joint model is physical, beats
/// every physical single candidate and needs both members (each improves on the other alone
/// by more than `critical`, the guard's critical value, and the first, as the step's own
/// candidate, clears it over the model before, `here`), the one with the lowest BIC; taken
/// when the best single candidate clears `critical` over the model before (`here`) and
/// needs values no rig can have, or is not in that pair and falls short of it by more than
/// `critical`. Returns the pair's index.
pub fn choose_pair(
    here: f64,
    singles: &[(Mechanism, Scored)],
    pairs: &[(Mechanism, Mechanism, Scored)],
    critical: f64,
) -> Option<usize> {
    let (best, best_score) = singles.iter().min_by(|a, b| a.1.bic.total_cmp(&b.1.bic))?;
    if here - best_score.bic <= critical.max(0.0) {
        return None;
    }
    let best_physical = singles
        .iter()
        .filter(|s| s.1.plausible)
        .map(|s| s.1.bic)
        .fold(f64::INFINITY, f64::min);
    let alone = |m: Mechanism| singles.iter().find(|s| s.0 == m).map(|s| s.1.bic);
    let (k, (a, b, _)) = pairs
        .iter()
        .enumerate()
        .filter(|(_, (a, b, s))| {
            s.plausible
                && s.bic < best_physical
                && alone(*a).is_some_and(|x| x - s.bic > critical && here - x > critical)
                && alone(*b).is_some_and(|x| x - s.bic > critical)
        })
        .min_by(|x, y| x.1.2.bic.total_cmp(&y.1.2.bic))?;
    let pair = pairs[k].2;
    // In place of a physical best, the pair must beat it by what effect-free data gives.
    let replaces =
        !best_score.plausible || (a != best && b != best && best_score.bic - pair.bic > critical);
    replaces.then_some(k)
}

/// A candidate's name in a reason, its form added for a family form (whose name is its
/// library effect's).
fn label(points: &TestPoints, m: Mechanism) -> String {
    match m.form(points) {
        Some(form) => format!("{} ({form} form)", m.name(points)),
        None => m.name(points).to_string(),
    }
}

/// A pair taken in place of `step`'s best ([`choose_pair`]): `step` turned into the first
/// member's step and the next step, the second member's, returned. Each member has passed
/// the tests of a step of its own (the first: every test but the physical limits, which only
/// the pair must meet; the second: every test, from the first's fit, and the driver check of
/// a later effect). `None`, and `step` as it was but for its `pairs` (filled where the guard
/// passed), when no pair is chosen or a member fails.
fn pair_steps(
    points: &TestPoints,
    current: &Fit,
    current_held_out: Option<HeldOut>,
    step: &mut Step,
    null: &[f64],
    critical_influence: f64,
    opts: &Options,
) -> Option<Step> {
    if step.p_value >= opts.alpha || current.spec.effects.len() + 2 > opts.max_effects {
        return None;
    }
    step.pairs = pair_fits(points, &step.candidates);
    let singles: Vec<(Mechanism, Scored)> = step
        .candidates
        .iter()
        .filter_map(|c| {
            let f = c.fit.as_ref()?;
            Some((
                c.cand,
                Scored {
                    bic: f.bic,
                    plausible: crate::plausibility::check_model(points, f).plausible,
                },
            ))
        })
        .collect();
    let scored: Vec<(Mechanism, Mechanism, Scored)> = step
        .pairs
        .iter()
        .map(|p| {
            (
                p.first,
                p.second,
                Scored {
                    bic: p.fit.bic,
                    plausible: p.plausible,
                },
            )
        })
        .collect();
    let pair = &step.pairs[choose_pair(current.bic, &singles, &scored, step.critical)?];
    let pair_held_out = fit::held_out(points, &pair.fit.spec, &pair.fit.model, &pair.fit.term_x);
    if !confirmed(None, current_held_out, pair_held_out, false).0 {
        return None;
    }
    let (first_cand, second_cand, pair_bic) = (pair.first, pair.second, pair.fit.bic);
    // The first member, judged as a step of its own.
    let i = step.candidates.iter().position(|c| c.cand == first_cand)?;
    let (first, d, p_first) = judged_alone(
        points,
        current,
        current_held_out,
        &step.candidates[i],
        null,
        critical_influence,
        opts,
    )?;
    let first_fit = first.fit.as_ref()?;
    // The second member: the next step from the first's fit, with it on top.
    let (mut next, next_null, next_influence) =
        take_step_with_null(points, first_fit, first.held_out, opts)?;
    let j = next.candidates.iter().position(|c| c.cand == second_cand)?;
    let (second, d2, p_second) = judged_alone(
        points,
        first_fit,
        first.held_out,
        &next.candidates[j],
        &next_null,
        next_influence,
        opts,
    )?;
    if !d2.accepted() {
        return None;
    }
    next.promote(j, second, d2, p_second);
    if not_separated(points, first_fit, &next).is_some() {
        return None;
    }
    let best = step.best()?;
    let decision = match d {
        Decision::Implausible { .. } => only_together(&d, &next, points),
        Decision::Added {
            best: name,
            improvement,
            p_value,
            held_out,
            ..
        } if best.cand != first_cand => Decision::AddedInPair {
            best: name,
            improvement,
            p_value,
            held_out,
            instead: label(points, best.cand),
            instead_improvement: best.improvement,
            instead_plausible: singles.iter().any(|(m, s)| *m == best.cand && s.plausible),
            partner: second_cand.name(points).to_string(),
            pair_improvement: current.bic - pair_bic,
        },
        _ => return None,
    };
    if let Decision::Added { partner, .. } = &mut next.decision
        && matches!(decision, Decision::AddedOnlyTogether { .. })
    {
        *partner = Some(first_cand.name(points).to_string());
    }
    step.promote(i, first, decision, p_first);
    Some(next)
}

/// A later step's best, accepted on every other test, whose own driver a generic shape in
/// another variable matches ([`crate::drivers::check`]): the decision that turns it down.
/// The first effect named is judged on the same check after the selection (the verdict is
/// then `ambiguous`); a later one would only stack a guess on a finding.
fn not_separated(points: &TestPoints, current: &Fit, step: &Step) -> Option<Decision> {
    let best = step.best()?;
    let with = best.fit.as_ref()?;
    let check = crate::drivers::check(points, current, with, best.cand)?;
    if check.separated {
        return None;
    }
    let name = best.cand.name(points);
    Some(Decision::NotSeparated {
        best: name.to_string(),
        improvement: best.improvement,
        p_value: step.p_value,
        check: check.summary(name),
    })
}

/// The starting model fitted (twice, so a loaded model and a selected one end at the same
/// optimum) and its held-out score.
fn start_fit(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &CurrentModel,
    start_terms: &[Vec<f64>],
) -> (Fit, Option<HeldOut>) {
    let first = fit::fit_from(points, &points.all, spec, start, start_terms);
    let current = fit::fit_from(points, &points.all, spec, &first.model, &first.term_x);
    let held_out = fit::held_out(points, spec, &current.model, &current.term_x);
    (current, held_out)
}

/// The model after an accepted step, with its held-out score.
fn advance(points: &TestPoints, step: &Step) -> (Fit, Option<HeldOut>) {
    let best = &step.candidates[0];
    let f = best
        .fit
        .clone()
        .expect("an accepted step has a fitted best");
    let held_out = match best.held_out {
        Some(h) => Some(h),
        None => fit::held_out(points, &f.spec, &f.model, &f.term_x),
    };
    (f, held_out)
}

/// The guard's p-value of `improvement`: the share of the null draws (plus one) at or above it.
fn p_value_at(null: &[f64], improvement: f64) -> f64 {
    let exceed = null.iter().filter(|&&v| v >= improvement).count();
    (1 + exceed) as f64 / (1 + null.len()) as f64
}

/// Candidate `c` of a step from `current` judged as if it were the step's best: its held-out
/// score filled in, the guard's p-value at its own improvement (the null is of the best of
/// all candidates, so this is no easier) and the step's decision on it.
fn judged_alone(
    points: &TestPoints,
    current: &Fit,
    current_held_out: Option<HeldOut>,
    c: &Candidate,
    null: &[f64],
    critical_influence: f64,
    opts: &Options,
) -> Option<(Candidate, Decision, f64)> {
    let f = c.fit.as_ref()?;
    let mut c = c.clone();
    if c.held_out.is_none() {
        c.held_out = fit::held_out(points, &f.spec, &f.model, &f.term_x);
    }
    let p_value = p_value_at(null, c.improvement);
    let d = decide(
        points,
        current,
        current_held_out,
        &c,
        p_value,
        critical_influence,
        opts,
    );
    Some((c, d, p_value))
}

impl Step {
    /// Puts candidate `i`, as judged (`c`, decision `d` at guard p-value `p_value`), at the
    /// top of the step as its best.
    fn promote(&mut self, i: usize, c: Candidate, d: Decision, p_value: f64) {
        self.candidates.remove(i);
        self.candidates.insert(0, c);
        self.accepted = d.accepted();
        self.decision = d;
        self.p_value = p_value;
    }
}

/// One step of the selection from `current`: every candidate explored, the best scored and
/// judged; `None` when no candidate is left. With the guard's null draws and its critical
/// value at [`INFLUENCE_ALPHA`].
fn take_step_with_null(
    points: &TestPoints,
    current: &Fit,
    current_held_out: Option<HeldOut>,
    opts: &Options,
) -> Option<(Step, Vec<f64>, f64)> {
    let pending = pending(points, &current.spec);
    let Explored {
        mut candidates,
        null,
        critical,
        critical_influence,
    } = explore(points, current, opts)?;
    let best_improvement = candidates[0].improvement;
    let p_value = p_value_at(&null, best_improvement);
    let guard_passed = best_improvement > 0.0 && p_value < opts.alpha;
    score_held_out(points, &mut candidates, guard_passed);
    let decision = decide(
        points,
        current,
        current_held_out,
        &candidates[0],
        p_value,
        critical_influence,
        opts,
    );
    close_table(points, pending, &mut candidates);
    let step = Step {
        candidates,
        p_value,
        critical,
        held_out_before: current_held_out,
        accepted: decision.accepted(),
        decision,
        pairs: Vec::new(),
    };
    Some((step, null, critical_influence))
}

/// Held-out scores: every fitted candidate on small data; on large data the best, and only
/// when the guard has not already turned it down.
fn score_held_out(points: &TestPoints, candidates: &mut [Candidate], guard_passed: bool) {
    let full_table = points.len() <= FULL_TABLE_POINTS;
    let scored: Vec<usize> = (0..candidates.len())
        .filter(|&i| candidates[i].fit.is_some())
        .filter(|&i| full_table || (guard_passed && i == 0))
        .collect();
    let scores = crate::parallel::par_map(&scored, |&i| {
        let f = candidates[i]
            .fit
            .as_ref()
            .expect("filtered to fitted candidates");
        fit::held_out(points, &f.spec, &f.model, &f.term_x)
    });
    for (&i, s) in scored.iter().zip(scores) {
        candidates[i].held_out = s;
    }
}

/// The step's decision on its best candidate: the first rule that turns it down (no
/// improvement, the guard, the held-out points, the physical limits, a single point), or
/// added.
fn decide(
    points: &TestPoints,
    current: &Fit,
    current_held_out: Option<HeldOut>,
    best: &Candidate,
    p_value: f64,
    critical_influence: f64,
    opts: &Options,
) -> Decision {
    let best_fit = best.fit.as_ref().expect("fitted");
    let improvement = best.improvement;
    let hold_gain = best_fit.hold_errors + 2 <= current.hold_errors;
    let (ok_held_out, held_note) = confirmed(
        match best.cand {
            Mechanism::Effect(e) => Some(e),
            Mechanism::Term(_) => None,
        },
        current_held_out,
        best.held_out,
        hold_gain,
    );
    let best_name = best.cand.name(points).to_string();
    if improvement <= 0.0 {
        return Decision::NoImprovement {
            best: best_name,
            improvement,
        };
    }
    if p_value >= opts.alpha {
        return Decision::BelowGuard {
            best: best_name,
            improvement,
            p_value,
            alpha: opts.alpha,
        };
    }
    if !ok_held_out {
        return Decision::NotConfirmed {
            best: best_name,
            improvement,
            p_value,
            held_out: held_note,
        };
    }
    let plausibility = crate::plausibility::check_model(points, best_fit);
    if !plausibility.plausible {
        return Decision::Implausible {
            best: best_name,
            improvement,
            p_value,
            limits: plausibility.failures(),
        };
    }
    let (without, k) = improvement_without_top_point(points, current, best_fit);
    if without <= critical_influence {
        return Decision::CarriedByOnePoint {
            best: best_name,
            improvement,
            p_value,
            row: points.rows[k] + 1,
            without,
            critical: critical_influence,
            level: INFLUENCE_ALPHA.max(opts.alpha),
        };
    }
    Decision::Added {
        best: best_name,
        improvement,
        p_value,
        held_out: held_note,
        partner: None,
    }
}

/// The inapplicable candidates close the step's table.
fn close_table(points: &TestPoints, pending: Vec<Mechanism>, candidates: &mut Vec<Candidate>) {
    let traits = points.traits();
    for c in pending {
        if let Some(why) = c.not_applicable(points, &traits) {
            candidates.push(Candidate {
                cand: c,
                not_applicable: Some(why),
                fit: None,
                improvement: f64::NAN,
                estimated: false,
                held_out: None,
            });
        }
    }
}

/// When `step`'s best candidate passed every test but the physical limits (not a shape on
/// the edge of its search), the next step taken from its (implausible) fit: returned when that step adds its best candidate with
/// every value of the joint model within its limits (the pair is then plausible together),
/// `None` otherwise.
fn complete_plausibility(
    points: &TestPoints,
    current: &Fit,
    step: &Step,
    opts: &Options,
) -> Option<Step> {
    if current.spec.effects.len() + 2 > opts.max_effects {
        return None;
    }
    let best = step.best()?;
    let with = best.fit.as_ref()?;
    // A shape on the edge of its search only mimics the data: no partner makes it a law.
    if !crate::plausibility::check_model(points, with).only_physical_limits_broken() {
        return None;
    }
    let held_out = match best.held_out {
        Some(h) => Some(h),
        None => fit::held_out(points, &with.spec, &with.model, &with.term_x),
    };
    let (mut next, null, critical_influence) = take_step_with_null(points, with, held_out, opts)?;
    if !next.accepted {
        // The best partner is the best candidate that passes every test, the guard at its
        // own improvement included.
        let found = (1..next.candidates.len()).find_map(|i| {
            let (c, d, p_value) = judged_alone(
                points,
                with,
                held_out,
                &next.candidates[i],
                &null,
                critical_influence,
                opts,
            )?;
            d.accepted().then_some((i, c, d, p_value))
        });
        let (i, c, d, p_value) = found?;
        next.promote(i, c, d, p_value);
    }
    // The partner must also improve on the model without the first candidate: together
    // they beat it by more than the first did alone.
    let joint = next.best()?.fit.as_ref()?;
    (joint.bic < with.bic && joint.bic < current.bic).then_some(next)
}

/// The decision of a step whose best candidate is plausible only together with the next
/// step's.
fn only_together(decision: &Decision, next: &Step, points: &TestPoints) -> Decision {
    let Decision::Implausible {
        best,
        improvement,
        p_value,
        limits,
    } = decision.clone()
    else {
        return decision.clone();
    };
    Decision::AddedOnlyTogether {
        best,
        improvement,
        p_value,
        limits,
        partner: next
            .best()
            .map(|b| b.cand.name(points).to_string())
            .unwrap_or_default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_decision_reads_as_the_reason_text_of_before() {
        let name = || "thermal-drift".to_string();
        let cases = [
            (
                Decision::NoImprovement {
                    best: name(),
                    improvement: -1.25,
                },
                "no candidate improves the BIC (best: thermal-drift by -1.2)",
            ),
            (
                Decision::BelowGuard {
                    best: name(),
                    improvement: 12.345,
                    p_value: 0.0123,
                    alpha: 0.002,
                },
                "thermal-drift improves the BIC by 12.3, but effect-free data does that with probability 0.012 (guard 0.002)",
            ),
            (
                Decision::NotConfirmed {
                    best: name(),
                    improvement: 40.0,
                    p_value: 0.0004,
                    held_out: "held-out RMSE 10.0 -> 10.2 mA".into(),
                },
                "thermal-drift improves the BIC by 40.0 (p < 0.001) but does not predict held-out points better (held-out RMSE 10.0 -> 10.2 mA)",
            ),
            (
                Decision::Implausible {
                    best: name(),
                    improvement: 40.0,
                    p_value: 0.0015,
                    limits: "k_per_c = -0.01 /K beyond 0..0.005".into(),
                },
                "thermal-drift improves the BIC by 40.0 (p 0.002), but only with values no rig can have: k_per_c = -0.01 /K beyond 0..0.005; it is not named",
            ),
            (
                Decision::CarriedByOnePoint {
                    best: name(),
                    improvement: 40.0,
                    p_value: 0.0001,
                    row: 17,
                    without: 3.21,
                    critical: 7.89,
                    level: 0.05,
                },
                "thermal-drift improves the BIC by 40.0 (p < 0.001), but without the single test point at data row 17 (the one that contributes most) only by 3.2, below the 7.9 that effect-free data reaches with probability 0.05: one point does not make a finding",
            ),
            (
                Decision::Added {
                    best: name(),
                    improvement: 40.0,
                    p_value: 0.0001,
                    held_out: "held-out RMSE 12.0 -> 10.0 mA".into(),
                    partner: None,
                },
                "thermal-drift improves the BIC by 40.0 (p < 0.001); held-out RMSE 12.0 -> 10.0 mA",
            ),
        ];
        for (decision, text) in cases {
            assert_eq!(decision.to_string(), text);
            assert_eq!(
                decision.accepted(),
                matches!(decision, Decision::Added { .. })
            );
        }
    }

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

    #[test]
    fn a_pair_replaces_the_best_only_when_both_members_are_needed_and_it_wins_by_the_guard() {
        let e = |x| Mechanism::Effect(x);
        let (ir, visc, off, ldf) = (
            e(Effect::InertiaRectification),
            e(Effect::VibratorViscousLoss),
            e(Effect::CurrentSensorOffset),
            e(Effect::LoadDependentFriction),
        );
        let sc = |bic, plausible| Scored { bic, plausible };
        let critical = 8.0;
        let here = 0.0;
        // The best alone (-200) is physical; viscous loss (-150) and the offset (-60) together
        // reach -230: each adds more than 8 to the other, and the pair beats
        // the best alone by 30, more than the guard lets through.
        let singles = [
            (ir, sc(-200.0, true)),
            (visc, sc(-150.0, true)),
            (off, sc(-60.0, true)),
            (ldf, sc(-40.0, true)),
        ];
        let pairs = [
            (ir, visc, sc(-203.0, true)),
            (ir, off, sc(-205.0, true)),
            (visc, off, sc(-230.0, true)),
            (visc, ldf, sc(-160.0, true)),
        ];
        assert_eq!(choose_pair(here, &singles, &pairs, critical), Some(2));
        // Not when the pair wins by less than the guard's critical value.
        let mut close = pairs;
        close[2].2.bic = -206.0;
        assert_eq!(choose_pair(here, &singles, &close, critical), None);
        // Not when one member adds too little to the other: the offset adds 7 to viscous loss.
        let mut weak = singles;
        weak[1].1.bic = -223.0;
        assert_eq!(choose_pair(here, &weak, &pairs, critical), None);
        // Not when the joint model needs values no rig can have.
        let mut beyond = pairs;
        beyond[2].2.plausible = false;
        assert_eq!(choose_pair(here, &singles, &beyond, critical), None);
        // Not when the best alone does not clear the guard over the model before.
        assert_eq!(choose_pair(-195.0, &singles, &pairs, critical), None);
        // An implausible best is replaced by the best physical pair, its own pairs included.
        let mut implausible = singles;
        implausible[0].1.plausible = false;
        let mut with_best = pairs;
        with_best[2].2.bic = -150.0;
        with_best[1].2.bic = -210.0;
        assert_eq!(
            choose_pair(here, &implausible, &with_best, critical),
            Some(1)
        );
        // A physical best already in the best pair: the forward step is kept.
        assert_eq!(choose_pair(here, &singles, &with_best, critical), None);
    }
}
