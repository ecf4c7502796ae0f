//! `rig explain`: find where the model of the vibrator current and the measurement disagree,
//! name the missing effect, add it to the model and show the gap shrink.
//!
//! 0. Screen: rows that cannot be right (beyond the sensors' or the motor's range) or stand
//!    out from the rows at like conditions are set aside and reported; rig-file values are
//!    checked with the firmware's rules ([`robust`]).
//! 1. Gap: fit the paper's model i = (tau_cam_hat(tau_rot, w_n; mu) + C3 w_n + C4 - C2) / C1
//!    (Eqs. 10, 15-17, mu fitted; or a loaded model with its effects refitted) and show where
//!    it disagrees ([`gap`]).
//! 2. Candidates: the effects of [`library`], each fitted jointly with the model ([`fit`]).
//! 3. Selection: forward selection by BIC, guarded by a parametric bootstrap of the best
//!    improvement under the current model, confirmed on held-out blocks of test points and
//!    required to survive leaving out its most influential test point ([`select`]).
//! 4. Confidence: a block bootstrap of the whole selection gives each effect's inclusion
//!    probability, the share of replicates that reach the same finding (`confidence`), and
//!    `ambiguous` when a competitor is selected instead of the leading effect in a fifth or
//!    more of the replicates ([`bootstrap`]); BIC weights of the models tried.
//! 5. Add: the augmented model as a rig file ([`rigfile`]).
//! 6. Show: a report folder with residual plots, the candidate table and the finding
//!    ([`report_files`]).
//!
//! Large data is pooled into points of like conditions ([`points`]): a million rows take
//! about a second.
//!
//! The entry point for plain rows (files, the simulator, tests) is [`explain`].

pub mod bootstrap;
pub mod calibration;
pub mod data;
pub mod design;
pub mod drivers;
pub mod extrapolation;
pub mod fit;
pub mod gap;
pub mod lack_of_fit;
pub mod library;
pub mod mechanism;
pub mod options;
pub mod parallel;
pub mod plausibility;
pub mod points;
pub mod proposed_law;
pub mod report_files;
pub mod residual_shape;
pub mod robust;
pub mod select;
pub mod stats;
pub mod synth;
pub mod terms;

use std::collections::BTreeMap;

use model::effects::{Effect, Param};
use serde::Serialize;

mod error;

pub use data::{Dataset, MeasuredRow};
pub use error::ExplainError;
pub use robust::Outlier;
pub use select::Options;

use fit::{Fit, ModelSpec};
use gap::Gap;
use library::ThermalDriver;
use mechanism::Mechanism;
use points::TestPoints;
use rigfile::{EffectEntry, RigFile, TermEntry};
use terms::{Form, Term, TermParam};

/// What `rig explain` concludes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// One or more effects were found and added; what remains is within the noise.
    Explained,
    /// Named effects shrink the gap, but a significant lack of fit remains.
    PartlyExplained,
    /// A significant lack of fit remains and no named effect explains it.
    Unexplained,
    /// The model agrees with the measurement within its noise (the lack of fit is not
    /// significant).
    NoMissingEffect,
    /// An effect is missing, but the data cannot tell which of several candidates.
    Ambiguous,
}

impl Verdict {
    /// The verdict as printed (`explained`, `partly-explained`, `unexplained`,
    /// `no-missing-effect`, `ambiguous`).
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Explained => "explained",
            Verdict::PartlyExplained => "partly-explained",
            Verdict::Unexplained => "unexplained",
            Verdict::NoMissingEffect => "no-missing-effect",
            Verdict::Ambiguous => "ambiguous",
        }
    }
}

/// An effect found and added.
#[derive(Debug, Clone, Serialize)]
pub struct EffectReport {
    /// The effect's name.
    pub name: String,
    /// The family form of its law, when not the library's own (e.g. `warm-up-in-time`).
    pub form: Option<String>,
    /// Its fitted parameters (see [`library`] for names and units).
    pub params: BTreeMap<String, f64>,
    /// 95 % intervals of the parameters that have one.
    pub intervals: BTreeMap<String, [f64; 2]>,
    /// BIC with the effect minus BIC without it, at the step it was added (negative: better).
    pub delta_bic: f64,
    /// Probability that effect-free data gives an improvement this large (the guard).
    pub p_value: f64,
    /// Held-out RMSE of the model once it was added, A.
    pub holdout_rmse_a: Option<f64>,
    /// What the effect means at the fitted values.
    pub description: String,
    /// The probability that the effect is part of the truth: the finding's `confidence` plus,
    /// for the finding not being right, the calibrated probability that the effect is part
    /// of the truth all the same (from the share of the block-bootstrap replicates that
    /// select it, its driver check and the final model's lack of fit, fitted on generated
    /// batches with truths outside the library; [`calibration::coherent_inclusion`]), so
    /// never below the confidence of the finding that names it; null without a bootstrap.
    pub inclusion_probability: Option<f64>,
    /// Share of the block-bootstrap replicates of the whole selection that select it (null
    /// without a bootstrap).
    pub inclusion_probability_raw: Option<f64>,
    /// BIC weight of the models with it (in any of its laws) among the models of its step
    /// (the model without it and every candidate).
    pub bic_weight: f64,
    /// Whether every physical limit of its parameters holds (the effects table's limits, mu,
    /// the shape's search edges).
    pub plausible: bool,
    /// The limits checked, each with its reason.
    pub limits: Vec<plausibility::LimitCheck>,
    /// Held-out edges of the tested range (whole speed levels and load ranges) predicted
    /// with and without it; null when the effect did not stay in the final model.
    pub extrapolation: Option<extrapolation::Extrapolation>,
    /// Whether the variable its law follows beats a generic shape in another variable
    /// (time, revolutions, temperature, speed, load, current) in the final model (at the
    /// step that named it, when it did not stay); null for a law with no driver (a
    /// constant, a variance, a user effect).
    pub driver_check: Option<drivers::DriverCheck>,
    /// The other named effect without which this one's fit needs values no rig can have
    /// (the two reach physical values only together); null for an effect plausible alone.
    pub only_together_with: Option<String>,
    /// The other effect of a pair named together in place of a step's best candidate
    /// (`select::Decision::AddedInPair`): the two explain more than that candidate with any
    /// partner; null otherwise.
    pub named_in_pair_with: Option<String>,
}

/// A row of a candidate table.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateReport {
    /// The effect's name.
    pub name: String,
    /// The family form of its law, when not the library's own.
    pub form: Option<String>,
    /// Whether the data can show it.
    pub applicable: bool,
    /// Why not, when it cannot.
    pub note: Option<String>,
    /// Its parameters fitted jointly with the model.
    pub params: BTreeMap<String, f64>,
    /// 95 % intervals of the parameters that have one.
    pub intervals: BTreeMap<String, [f64; 2]>,
    /// BIC with the candidate minus BIC without it (negative: better).
    pub delta_bic: Option<f64>,
    /// RMSE of the joint fit, A.
    pub rmse_a: Option<f64>,
    /// Held-out RMSE of the joint fit, A (computed for the leaders only on large data).
    pub holdout_rmse_a: Option<f64>,
    /// BIC weight of the model with it among the models of its step (the current model and
    /// every fitted candidate).
    pub bic_weight: Option<f64>,
    /// Share of the block-bootstrap replicates of the whole selection that select it.
    pub inclusion_probability: Option<f64>,
    /// Whether its fit keeps every physical limit (null when not fitted).
    pub plausible: Option<bool>,
    /// The limits its fit breaks, with their reasons (empty when it keeps them all).
    pub limits_broken: Vec<plausibility::LimitCheck>,
}

/// A candidate of an ambiguous verdict.
#[derive(Debug, Clone, Serialize)]
pub struct AmbiguousCandidate {
    /// The effect.
    pub name: String,
    /// Share of the bootstrap replicates that select it.
    pub probability: f64,
}

/// One model the selection fitted, with its BIC weight among all of them.
#[derive(Debug, Clone, Serialize)]
pub struct ModelWeight {
    /// Its effects beyond the loaded ones, in the order they were added.
    pub effects: Vec<String>,
    /// Its BIC.
    pub bic: f64,
    /// exp(-BIC / 2), normalised over every model fitted.
    pub weight: f64,
}

/// One selection the bootstrap replicates reached, with its share.
#[derive(Debug, Clone, Serialize)]
pub struct BootstrapSet {
    /// The effects selected (beyond the loaded ones), sorted by name.
    pub effects: Vec<String>,
    /// Share of the replicates.
    pub share: f64,
}

/// How the block bootstrap was run, and what it reached.
#[derive(Debug, Clone, Serialize)]
pub struct BootstrapReport {
    /// Replicates.
    pub replicates: usize,
    /// Blocks of consecutive test points.
    pub blocks: usize,
    /// Test points (rows) per block.
    pub block_length: usize,
    /// Seed of the draws.
    pub seed: u64,
    /// The most frequent selections (up to five).
    pub selections: Vec<BootstrapSet>,
}

/// One step of the forward selection.
#[derive(Debug, Clone, Serialize)]
pub struct StepReport {
    /// The best candidate.
    pub best: Option<String>,
    /// Whether it was added.
    pub accepted: bool,
    /// The guard's p-value of the best improvement.
    pub p_value: f64,
    /// Why it was (not) added.
    pub reason: String,
    /// Candidates the data cannot tell from the best: selected instead of it in at least
    /// `Options::ambiguity_share` of the bootstrap replicates (accepted steps only).
    pub ambiguous_with: Vec<String>,
    /// The guard's critical value of the best improvement.
    pub critical_delta_bic: f64,
    /// Every candidate.
    pub candidates: Vec<CandidateReport>,
}

/// The effect hidden in a synthetic sweep, for `--synthetic`.
#[derive(Debug, Clone, Serialize)]
pub struct SyntheticTruth {
    /// The hidden effect, if any.
    pub effect: Option<String>,
    /// Its parameters.
    pub params: BTreeMap<String, f64>,
    /// The sweep's seed.
    pub seed: u64,
    /// Current noise, A.
    pub noise_a: f64,
}

/// What `rig explain` prints with `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Explanation {
    /// The verdict.
    pub verdict: Verdict,
    /// Effects added, strongest first.
    pub effects: Vec<EffectReport>,
    /// Names the data cannot tell apart (the chosen one first), when the verdict is ambiguous.
    pub ambiguous: Vec<String>,
    /// The same with their bootstrap inclusion probabilities.
    pub ambiguous_candidates: Vec<AmbiguousCandidate>,
    /// For `explained`: the probability that the named set of effects is exactly right,
    /// calibrated on generated batches with truths outside the library from
    /// `confidence_raw`, the weakest driver check and the lack of fit
    /// ([`calibration::calibrated`] of [`Explanation::evidence`]). For `partly-explained` and
    /// `ambiguous`: the probability that every effect it names is part of the truth,
    /// calibrated the same way ([`calibration::calibrated_partial`]). For `unexplained` and
    /// `no-missing-effect`: the bootstrap share (`confidence_raw`). Each named effect's
    /// `inclusion_probability` is at least this. Null without a bootstrap.
    pub confidence: Option<f64>,
    /// Share of the block-bootstrap replicates of the whole selection that reach the same set
    /// of effects (none, for `no-missing-effect`); null without a bootstrap.
    pub confidence_raw: Option<f64>,
    /// Every applicable effect's bootstrap inclusion probability.
    pub inclusion_probabilities: BTreeMap<String, f64>,
    /// The models fitted along the selection with their BIC weights, heaviest first (up to
    /// ten).
    pub model_weights: Vec<ModelWeight>,
    /// The block bootstrap, when it ran.
    pub bootstrap: Option<BootstrapReport>,
    /// Rows set aside, in file order: data row, file line, column, value and why.
    pub outliers: Vec<Outlier>,
    /// Things in the data or the rig file worth fixing; they did not stop the analysis.
    pub warnings: Vec<String>,
    /// Robust standard deviation (1.4826 MAD) of the final model's row residuals, A.
    pub robust_sigma_a: f64,
    /// Rows in the data (with or without a current, outliers included).
    pub rows_in_data: usize,
    /// Whether rows at like conditions were pooled into points for the fits.
    pub pooled: bool,
    /// Fitting points (rows, or pools of them).
    pub points: usize,
    /// RMSE of the starting model, A.
    pub rmse_before_a: f64,
    /// RMSE of the final model, A.
    pub rmse_after_a: f64,
    /// Held-out RMSE of the starting model, A (null with too few blocks of test points).
    pub holdout_rmse_before_a: Option<f64>,
    /// Held-out RMSE of the final model, A.
    pub holdout_rmse_after_a: Option<f64>,
    /// BIC of the starting model.
    pub bic_before: f64,
    /// BIC of the final model.
    pub bic_after: f64,
    /// mu fitted in the starting model.
    pub mu_before: f64,
    /// mu fitted in the final model.
    pub mu_after: f64,
    /// Rows with a current that the fits use (outliers excluded).
    pub rows: usize,
    /// Rows whose output did not backdrive.
    pub held_rows: usize,
    /// Effects the loaded model already had (refitted).
    pub known_effects: Vec<String>,
    /// The candidate table of the first step (against the starting model).
    pub candidates: Vec<CandidateReport>,
    /// Every step of the selection.
    pub steps: Vec<StepReport>,
    /// Where the starting model disagrees.
    pub gap_before: Gap,
    /// Where the final model disagrees.
    pub gap_after: Gap,
    /// The final model's lack of fit against the data's own noise, and where it lives.
    pub lack_of_fit: lack_of_fit::LackOfFit,
    /// The shape of what remains, when the verdict is `unexplained` or `partly-explained`:
    /// a sparse description over a generic basis and a ready `[[user_effects]]` entry.
    pub residual_shape: Option<residual_shape::ResidualShape>,
    /// A law proposed for what remains, when the verdict is `unexplained` or
    /// `partly-explained` and a law of the search ([`proposed_law`]: units right by
    /// construction) predicts held-out levels better than the generic shape and survives
    /// the bootstrap; `null` otherwise.
    pub proposed_law: Option<proposed_law::ProposedLaw>,
    /// The finding in words.
    pub finding: String,
    /// The report folder, when one was written.
    pub report_dir: Option<String>,
    /// The augmented model file, when one was written.
    pub model_written: Option<String>,
    /// The hidden truth of a synthetic sweep.
    pub synthetic: Option<SyntheticTruth>,
}

/// Everything an explain run produced: the printed explanation and the fits behind it.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The explanation.
    pub explanation: Explanation,
    /// The test points.
    pub points: TestPoints,
    /// Fit of the starting model.
    pub before: Fit,
    /// Fit of the final model.
    pub after: Fit,
    /// The rig file the run started from.
    pub rig: RigFile,
}

impl Outcome {
    /// The rig file with the final model (mu and every effect, loaded ones first; terms
    /// under `[[model.terms]]`).
    pub fn augmented_rig(&self) -> RigFile {
        let effects = self
            .after
            .spec
            .effects
            .iter()
            .map(|&e| EffectEntry {
                name: e.name().to_string(),
                params: library::report_params(e, &self.after.model.effects, self.points.thermal),
            })
            .collect();
        let terms = self
            .after
            .spec
            .terms
            .iter()
            .zip(&self.after.term_x)
            .map(|(&t, x)| {
                let term = &self.points.terms[t];
                TermEntry {
                    name: term.name.clone(),
                    form: term.form().map(|f| f.name().to_string()),
                    params: term.report(x),
                }
            })
            .collect();
        self.rig
            .with_model_terms(self.after.model.mu, effects, terms)
    }
}

/// The terms a data set may use: every family form and the rig file's user effects.
pub fn term_registry(rig: &RigFile) -> Result<Vec<Term>, ExplainError> {
    let mut out: Vec<Term> = Form::ALL.into_iter().map(Term::family).collect();
    for u in &rig.user_effects {
        let params = u
            .params
            .iter()
            .map(|(k, p)| TermParam {
                key: k.clone(),
                unit: p.unit.clone(),
                bounds: (p.bounds[0], p.bounds[1]),
                null: p.null,
                start: p.start.unwrap_or(p.null),
                log: p.log,
            })
            .collect();
        out.push(
            Term::user(&u.name, &u.expression, params)
                .map(|mut t| {
                    t.note = format!("user effect {} = {}", u.name, u.expression);
                    t
                })
                .map_err(|why| ExplainError::RigFile {
                    file: "(--model)".into(),
                    why: format!("[[user_effects]] {}, field `expression`: {why}", u.name),
                })?,
        );
    }
    Ok(out)
}

/// Every user effect must vanish at its parameters' null values on this data, so the model
/// without it is nested in the model with it.
fn check_user_terms(
    points: &TestPoints,
    start: &model::effects::CurrentModel,
) -> Result<(), ExplainError> {
    for term in points.terms.iter().filter(|t| t.form().is_none()) {
        let mut out = vec![0.0; points.len()];
        term.add(start, &points.inputs(), &term.null_point(), &mut out);
        let worst = out.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if worst.is_nan() || worst > 1e-9 {
            return Err(ExplainError::RigFile {
                file: "(--model)".into(),
                why: format!(
                    "[[user_effects]] {}, field `params`: the effect gives {worst:.3e} A at its null parameters ({}): it must vanish there (0 A), so that the model without it is nested in the model with it; set each parameter's null to the value without the effect",
                    term.name,
                    term.params
                        .iter()
                        .map(|p| format!("{} = {}", p.key, p.null))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            });
        }
    }
    Ok(())
}

/// The rig file's `[[model.terms]]` as registry indices and fit coordinates.
fn known_terms(
    rig: &RigFile,
    registry: &[Term],
) -> Result<(Vec<usize>, Vec<Vec<f64>>), ExplainError> {
    let mut idx = Vec::new();
    let mut coords = Vec::new();
    for entry in rig.term_entries() {
        let bad = |why: String| ExplainError::RigFile {
            file: "(--model)".into(),
            why: format!("[[model.terms]] {}: {why}", entry.name),
        };
        let t = match &entry.form {
            Some(form) => {
                let f = Form::from_name(form).ok_or_else(|| {
                    bad(format!(
                        "unknown form '{form}' (known: {})",
                        Form::ALL
                            .map(|f| format!("{} of {}", f.name(), f.effect().name()))
                            .join(", ")
                    ))
                })?;
                if f.effect().name() != entry.name {
                    return Err(bad(format!(
                        "form {form} belongs to {}, not {}",
                        f.effect().name(),
                        entry.name
                    )));
                }
                registry.iter().position(|t| t.form() == Some(f))
            }
            None => registry
                .iter()
                .position(|t| t.form().is_none() && t.name == entry.name),
        }
        .ok_or_else(|| bad("no such term".into()))?;
        let term = &registry[t];
        let mut x = term.start_point();
        for (k, &v) in &entry.params {
            let c = term
                .params
                .iter()
                .position(|p| &p.key == k)
                .ok_or_else(|| {
                    bad(format!(
                        "no parameter {k} (it takes {})",
                        term.params
                            .iter()
                            .map(|p| p.key.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            let p = &term.params[c];
            if !(v.is_finite() && v >= p.bounds.0 && v <= p.bounds.1) {
                return Err(bad(format!(
                    "{k} = {v} is outside its bounds [{}, {}]",
                    p.bounds.0, p.bounds.1
                )));
            }
            x[c] = p.to_fit(v);
        }
        idx.push(t);
        coords.push(x);
    }
    Ok((idx, coords))
}

/// 95 % intervals of `effect`'s parameters in `fit`, in reported units.
fn intervals(effect: Effect, fit: &Fit, thermal: ThermalDriver) -> BTreeMap<String, [f64; 2]> {
    let mut out = BTreeMap::new();
    let Some(param) = effect.mean_param() else {
        return out;
    };
    let Some(se) = fit.std_error(param) else {
        return out;
    };
    let v = fit.model.params()[param.index()];
    let (lo, hi) = (v - 1.96 * se, v + 1.96 * se);
    let name = library::main_param_name(effect, thermal).to_string();
    let iv = match library::report_scale(param) {
        Some(s) => [lo * s, hi * s],
        None if param == Param::AxialCornerSq => [lo.max(0.0).sqrt(), hi.max(0.0).sqrt()],
        None => return out,
    };
    out.insert(name, iv);
    out
}

/// 95 % interval of a term's first linear coordinate in `fit`.
fn term_intervals(points: &TestPoints, t: usize, fit: &Fit) -> BTreeMap<String, [f64; 2]> {
    let mut out = BTreeMap::new();
    let Some(pos) = fit.spec.terms.iter().position(|&x| x == t) else {
        return out;
    };
    let term = &points.terms[t];
    if let Some(c) = term.params.iter().position(|p| !p.log)
        && let Some(se) = fit.term_std_error(pos, c)
    {
        let v = fit.term_x[pos][c];
        out.insert(term.params[c].key.clone(), [v - 1.96 * se, v + 1.96 * se]);
    }
    out
}

/// The reported parameters of `cand` in `fit`.
pub(crate) fn cand_params(
    points: &TestPoints,
    cand: Mechanism,
    fit: &Fit,
    thermal: ThermalDriver,
) -> BTreeMap<String, f64> {
    match cand {
        Mechanism::Effect(e) => library::report_params(e, &fit.model.effects, thermal),
        Mechanism::Term(t) => fit
            .spec
            .terms
            .iter()
            .position(|&x| x == t)
            .map(|pos| points.terms[t].report(&fit.term_x[pos]))
            .unwrap_or_default(),
    }
}

/// The intervals of `cand`'s parameters in `fit`.
pub(crate) fn cand_intervals(
    points: &TestPoints,
    cand: Mechanism,
    fit: &Fit,
    thermal: ThermalDriver,
) -> BTreeMap<String, [f64; 2]> {
    match cand {
        Mechanism::Effect(e) => intervals(e, fit, thermal),
        Mechanism::Term(t) => term_intervals(points, t, fit),
    }
}

/// What `cand` means in `fit`.
fn cand_description(
    points: &TestPoints,
    cand: Mechanism,
    fit: &Fit,
    thermal: ThermalDriver,
) -> String {
    match cand {
        Mechanism::Effect(e) => library::describe(e, &fit.model.effects, thermal),
        Mechanism::Term(t) => fit
            .spec
            .terms
            .iter()
            .position(|&x| x == t)
            .map(|pos| points.terms[t].describe(&fit.term_x[pos]))
            .unwrap_or_default(),
    }
}

/// One row per effect: an effect's laws (its own and its family forms) are one candidate,
/// shown by its best law (the rows come best first); the row's BIC weight is the family's.
fn merge_by_name(rows: Vec<CandidateReport>) -> Vec<CandidateReport> {
    let mut out: Vec<CandidateReport> = Vec::new();
    for row in rows {
        match out.iter_mut().find(|r| r.name == row.name) {
            Some(kept) => {
                if let (Some(a), Some(b)) = (kept.bic_weight, row.bic_weight) {
                    kept.bic_weight = Some(a + b);
                }
            }
            None => out.push(row),
        }
    }
    out
}

/// A label of `cand` with its form, for lists of models.
fn cand_label(points: &TestPoints, cand: Mechanism) -> String {
    match cand.form(points) {
        Some(f) => format!("{} ({f})", cand.name(points)),
        None => cand.name(points).to_string(),
    }
}

fn candidate_report(
    points: &TestPoints,
    c: &select::Candidate,
    thermal: ThermalDriver,
    weight: Option<f64>,
    inclusion: Option<f64>,
) -> CandidateReport {
    let name = c.cand.name(points).to_string();
    let form = c.cand.form(points).map(str::to_string);
    let plaus = c.fit.as_ref().map(|f| plausibility::check_model(points, f));
    let plausible = plaus.as_ref().map(|p| p.plausible);
    let limits_broken = plaus
        .map(|p| p.checks.into_iter().filter(|c| !c.within).collect())
        .unwrap_or_default();
    match &c.fit {
        Some(f) => CandidateReport {
            name,
            form,
            applicable: true,
            note: None,
            params: cand_params(points, c.cand, f, thermal),
            intervals: cand_intervals(points, c.cand, f, thermal),
            delta_bic: Some(-c.improvement),
            rmse_a: Some(f.rmse()),
            holdout_rmse_a: c.held_out.map(|h| h.rmse),
            bic_weight: weight,
            inclusion_probability: inclusion,
            plausible,
            limits_broken,
        },
        None if c.estimated => CandidateReport {
            name,
            form,
            applicable: true,
            note: Some(
                "not fitted: on large data only the leaders of the score test are; delta_bic is the score-test estimate".into(),
            ),
            params: BTreeMap::new(),
            intervals: BTreeMap::new(),
            delta_bic: Some(-c.improvement),
            rmse_a: None,
            holdout_rmse_a: None,
            bic_weight: None,
            inclusion_probability: inclusion,
            plausible,
            limits_broken,
        },
        None => CandidateReport {
            name,
            form,
            applicable: false,
            note: c.not_applicable.map(str::to_string),
            params: BTreeMap::new(),
            intervals: BTreeMap::new(),
            delta_bic: None,
            rmse_a: None,
            holdout_rmse_a: None,
            bic_weight: None,
            inclusion_probability: None,
            plausible,
            limits_broken,
        },
    }
}

/// BIC weights exp(-BIC/2), normalised, of `bics`.
fn bic_weights(bics: &[f64]) -> Vec<f64> {
    let min = bics.iter().copied().fold(f64::INFINITY, f64::min);
    let w: Vec<f64> = bics.iter().map(|b| (-(b - min) / 2.0).exp()).collect();
    let total: f64 = w.iter().sum();
    w.into_iter().map(|x| x / total).collect()
}

/// BIC weight of each fitted candidate of `step` among the step's models (the current one
/// with BIC `current_bic` and every fitted candidate).
fn step_weights(step: &select::Step, current_bic: f64) -> Vec<Option<f64>> {
    let mut bics = vec![current_bic];
    bics.extend(
        step.candidates
            .iter()
            .filter_map(|c| c.fit.as_ref().map(|f| f.bic)),
    );
    let w = bic_weights(&bics);
    let mut next = 1;
    step.candidates
        .iter()
        .map(|c| {
            c.fit.as_ref().map(|_| {
                next += 1;
                w[next - 1]
            })
        })
        .collect()
}

/// Prepares the test points of `data`: range outliers, then residual outliers under the
/// starting model, set aside. Returns the points, the outliers (file order) and warnings.
fn screened_points(
    data: &Dataset,
    rig: &RigFile,
    spec: &ModelSpec,
    start: &model::effects::CurrentModel,
    options: &Options,
) -> Result<(TestPoints, Vec<Outlier>, Vec<String>), ExplainError> {
    let robust::RangeCheck {
        mut excluded,
        mut outliers,
        mut warnings,
    } = robust::range_check(data)?;
    robust::unit_check(data, &excluded, start)?;
    let too_few = |points: &TestPoints| {
        (points.n_rows < data::MIN_ROWS).then(|| ExplainError::TooFewRows {
            file: data.name.clone(),
            rows: points.n_rows,
            min_rows: data::MIN_ROWS,
        })
    };
    let reference_c = rig.calibration.temperature_c;
    let mut points = TestPoints::new(data, reference_c, options.folds, &excluded, start);
    if let Some(e) = too_few(&points) {
        return Err(e);
    }
    let base = fit::fit(&points, &points.all, spec, start);
    let (more, warning) = robust::residual_outliers(data, &points, &base.model);
    warnings.extend(warning);
    if !more.is_empty() {
        for o in &more {
            excluded[o.row - 1] = true;
        }
        outliers.extend(more);
        outliers.sort_by_key(|o| o.row);
        drop(points);
        points = TestPoints::new(data, reference_c, options.folds, &excluded, start);
        if let Some(e) = too_few(&points) {
            return Err(e);
        }
    }
    Ok((points, outliers, warnings))
}

/// The run's inputs made ready: the starting model, what the rig file loads, the screened
/// test points with the term registry centred on them.
struct Prepared {
    /// The model the selection starts from (loaded effects and terms).
    spec: ModelSpec,
    /// The starting model's parameters.
    start: model::effects::CurrentModel,
    /// The loaded terms' starting coordinates.
    known_x: Vec<Vec<f64>>,
    /// Names of the loaded effects and terms.
    known_names: Vec<String>,
    /// The screened test points.
    points: TestPoints,
    /// Rows set aside.
    outliers: Vec<Outlier>,
    /// Warnings on the rig file and the data.
    warnings: Vec<String>,
}

/// Step 0: the rig file's model and checks, the screened points, the terms centred on them.
fn prepare(data: &Dataset, rig: &RigFile, options: &Options) -> Result<Prepared, ExplainError> {
    let start = rig.current_model()?;
    let (known, _) = rig.effects().map_err(|why| ExplainError::RigFile {
        file: "model".into(),
        why,
    })?;
    let mut warnings = robust::check_rig(rig)?;
    let registry = term_registry(rig)?;
    let (known_terms, known_x) = known_terms(rig, &registry)?;
    let base_spec = ModelSpec {
        effects: known.clone(),
        terms: Vec::new(),
    };
    let (mut points, outliers, data_warnings) =
        screened_points(data, rig, &base_spec, &start, options)?;
    points.terms = registry;
    for term in &mut points.terms {
        term.centre_on(&start, &points.ops);
    }
    check_user_terms(&points, &start)?;
    warnings.extend(data_warnings);
    let known_names = known
        .iter()
        .map(|e| e.name().to_string())
        .chain(known_terms.iter().map(|&t| points.terms[t].name.clone()))
        .collect();
    Ok(Prepared {
        spec: ModelSpec {
            effects: known,
            terms: known_terms,
        },
        start,
        known_x,
        known_names,
        points,
        outliers,
        warnings,
    })
}

/// A warning when the final model's mu is outside the physical range.
fn mu_warning(after: &Fit) -> Option<String> {
    let (mu_lo, mu_hi) = model::effects::MU_PHYSICAL.range(&model::effects::LimitContext {
        max_axial_force_n: 0.0,
        eccentricity_m: 0.0,
    });
    (!(mu_lo..=mu_hi).contains(&after.model.mu)).then(|| {
        format!(
            "the fitted mu = {:.4} is outside the physical range [{mu_lo}, {mu_hi}] ({}): no effect is named on it; check the unit of tau_rot_nm (N m) and the rig file's gear and calibration",
            after.model.mu,
            model::effects::MU_PHYSICAL.why
        )
    })
}

/// The block bootstrap as the report reads it: inclusion by effect name (in any of its
/// laws) and the rivals of a named effect.
struct Resampled<'a> {
    boot: Option<&'a bootstrap::Bootstrap>,
    points: &'a TestPoints,
}

impl Resampled<'_> {
    /// Share of the replicates that select effect `name` (in any of its laws).
    fn inclusion(&self, name: &str) -> Option<f64> {
        self.boot
            .map(|b| b.share(|s| s.iter().any(|c| c.name(self.points) == name)))
    }

    /// The competitors selected instead of `name` in at least `share` of the replicates,
    /// most often first.
    fn rivals(&self, name: &str, competitors: &[String], share: f64) -> Vec<String> {
        let Some(b) = self.boot else {
            return Vec::new();
        };
        let has = |s: &[Mechanism], n: &str| s.iter().any(|c| c.name(self.points) == n);
        let mut r: Vec<(String, f64)> = competitors
            .iter()
            .map(|c| (c.clone(), b.share(|s| has(s, c) && !has(s, name))))
            .filter(|(_, s)| *s >= share)
            .collect();
        r.sort_by(|a, b| b.1.total_cmp(&a.1));
        r.into_iter().map(|(c, _)| c).collect()
    }
}

/// BIC weights of every step's models (per candidate) and of every model fitted along the
/// selection (heaviest first, up to ten).
fn selection_weights(
    points: &TestPoints,
    selection: &select::Selection,
) -> (Vec<Vec<Option<f64>>>, Vec<ModelWeight>) {
    let mut current_bic = selection.start.bic;
    let mut weights_by_step = Vec::new();
    let mut all_models: Vec<(Vec<String>, f64)> = vec![(Vec::new(), selection.start.bic)];
    let mut path: Vec<String> = Vec::new();
    for step in &selection.steps {
        weights_by_step.push(step_weights(step, current_bic));
        for c in &step.candidates {
            if let Some(f) = &c.fit {
                let mut effects = path.clone();
                effects.push(cand_label(points, c.cand));
                all_models.push((effects, f.bic));
            }
        }
        if let (true, Some(b)) = (step.accepted, step.best()) {
            path.push(cand_label(points, b.cand));
            current_bic = b.fit.as_ref().map_or(current_bic, |f| f.bic);
        }
    }
    let w = bic_weights(&all_models.iter().map(|m| m.1).collect::<Vec<_>>());
    let mut model_weights: Vec<ModelWeight> = all_models
        .into_iter()
        .zip(w)
        .map(|((effects, bic), weight)| ModelWeight {
            effects,
            bic,
            weight,
        })
        .collect();
    model_weights.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    model_weights.truncate(10);
    (weights_by_step, model_weights)
}

/// The report of every effect the selection added, in the order added: its fit (in the
/// final model when it stayed), limits, extrapolation, driver check and partner.
fn effect_reports(
    points: &TestPoints,
    selection: &select::Selection,
    weights_by_step: &[Vec<Option<f64>>],
    resampled: &Resampled,
) -> Vec<EffectReport> {
    let after = &selection.end;
    let thermal = points.thermal;
    let mut effects = Vec::new();
    let mut step_start = &selection.start;
    for (k, step) in selection
        .steps
        .iter()
        .enumerate()
        .filter(|(_, s)| s.accepted)
    {
        let best = step.best().expect("an accepted step has a best candidate");
        let f = best.fit.as_ref().expect("fitted");
        let in_final = best.cand.in_spec(&after.spec);
        let source = if in_final { after } else { f };
        let plaus = plausibility::check(points, best.cand, source);
        let name = best.cand.name(points);
        effects.push(EffectReport {
            name: name.to_string(),
            form: best.cand.form(points).map(str::to_string),
            params: cand_params(points, best.cand, source, thermal),
            intervals: cand_intervals(points, best.cand, source, thermal),
            delta_bic: -best.improvement,
            p_value: step.p_value,
            holdout_rmse_a: best.held_out.map(|h| h.rmse),
            description: cand_description(points, best.cand, source, thermal),
            // Calibrated in `judge`, once the final model's lack of fit is known.
            inclusion_probability: None,
            inclusion_probability_raw: resampled.inclusion(name),
            // The effect's weight: all its laws'.
            bic_weight: step
                .candidates
                .iter()
                .zip(&weights_by_step[k])
                .filter(|(c, _)| c.cand.name(points) == name)
                .filter_map(|(_, w)| *w)
                .sum(),
            plausible: plaus.plausible,
            limits: plaus.checks,
            extrapolation: in_final.then(|| extrapolation::extrapolation(points, after, best.cand)),
            driver_check: if in_final {
                drivers::check_in_final(points, after, best.cand)
            } else {
                drivers::check(points, step_start, f, best.cand)
            },
            only_together_with: match &step.decision {
                select::Decision::AddedOnlyTogether { partner, .. } => Some(partner.clone()),
                select::Decision::Added { partner, .. } => partner.clone(),
                _ => None,
            },
            named_in_pair_with: match &step.decision {
                select::Decision::AddedInPair { partner, .. } => Some(partner.clone()),
                _ => selection.steps[..k]
                    .iter()
                    .rev()
                    .find(|s| s.accepted)
                    .and_then(|s| match &s.decision {
                        select::Decision::AddedInPair { best, .. } => Some(best.clone()),
                        _ => None,
                    }),
            },
        });
        step_start = f;
    }
    effects
}

/// Every applicable effect (any law) neither named nor loaded, by name, sorted.
fn competitors(points: &TestPoints, named: &[String], known: &[String]) -> Vec<String> {
    let traits = points.traits();
    let mut out: Vec<String> = select::pending(points, &ModelSpec::base())
        .into_iter()
        .filter(|c| c.not_applicable(points, &traits).is_none())
        .map(|c| c.name(points).to_string())
        .filter(|n| !named.contains(n) && !known.contains(n))
        .collect();
    out.sort();
    out.dedup();
    out
}

/// The candidates of an ambiguous verdict: the leading finding and the competitors selected
/// instead of it often enough; else the first named effect whose driver a generic shape in
/// another variable matches (a named effect that is no explanation either).
fn ambiguous_candidates(
    effects: &[EffectReport],
    competitors: &[String],
    resampled: &Resampled,
    share: f64,
) -> Vec<AmbiguousCandidate> {
    let candidate = |name: &str| AmbiguousCandidate {
        probability: resampled.inclusion(name).unwrap_or(0.0),
        name: name.to_string(),
    };
    // The verdict turns on the leading finding; rivals of later effects are listed with
    // their step.
    if let Some(first) = effects.first() {
        let rivals = resampled.rivals(&first.name, competitors, share);
        if !rivals.is_empty() {
            return std::iter::once(first.name.as_str())
                .chain(rivals.iter().map(String::as_str))
                .map(candidate)
                .collect();
        }
    }
    effects
        .iter()
        .find(|f| f.driver_check.as_ref().is_some_and(|d| !d.separated))
        .map(|f| vec![candidate(&f.name)])
        .unwrap_or_default()
}

impl EffectReport {
    /// What its calibrated inclusion probability reads: its bootstrap share, its driver
    /// check's margin and the final model's lack of fit `lack_of_fit_p` (`None` without a
    /// bootstrap).
    pub fn evidence(&self, lack_of_fit_p: f64) -> Option<calibration::Evidence> {
        Some(calibration::Evidence {
            share: self.inclusion_probability_raw?,
            driver_margin: self
                .driver_check
                .as_ref()
                .map(drivers::DriverCheck::margin_over_best),
            lack_of_fit_p,
        })
    }
}

impl Explanation {
    /// What the calibrated confidence of its finding reads (`None` without a bootstrap).
    pub fn evidence(&self) -> Option<calibration::Evidence> {
        self.confidence_raw
            .map(|s| finding_evidence(s, &self.effects, self.lack_of_fit.p_value))
    }
}

/// The evidence of a finding reached by `share` of the replicates: its weakest driver
/// margin among `effects` and the lack of fit.
fn finding_evidence(
    share: f64,
    effects: &[EffectReport],
    lack_of_fit_p: f64,
) -> calibration::Evidence {
    calibration::Evidence {
        share,
        driver_margin: effects
            .iter()
            .filter_map(|f| f.driver_check.as_ref())
            .map(drivers::DriverCheck::margin_over_best)
            .reduce(f64::min),
        lack_of_fit_p,
    }
}

/// The verdict from what was named, the lack of fit and the ambiguity.
fn verdict_of(named_any: bool, lack_of_fit: &lack_of_fit::LackOfFit, ambiguous: bool) -> Verdict {
    match (named_any, lack_of_fit.significant) {
        (false, false) => Verdict::NoMissingEffect,
        (false, true) => Verdict::Unexplained,
        (true, true) => Verdict::PartlyExplained,
        (true, false) if ambiguous => Verdict::Ambiguous,
        (true, false) => Verdict::Explained,
    }
}

/// The report of every step of the selection.
fn step_reports(
    points: &TestPoints,
    selection: &select::Selection,
    weights_by_step: &[Vec<Option<f64>>],
    competitors: &[String],
    resampled: &Resampled,
    options: &Options,
) -> Vec<StepReport> {
    let thermal = points.thermal;
    selection
        .steps
        .iter()
        .zip(weights_by_step)
        .map(|(s, w)| StepReport {
            best: s.best().map(|c| c.cand.name(points).to_string()),
            accepted: s.accepted,
            p_value: s.p_value,
            reason: s.decision.to_string(),
            ambiguous_with: match s.best() {
                Some(b) if s.accepted => {
                    resampled.rivals(b.cand.name(points), competitors, options.ambiguity_share)
                }
                _ => Vec::new(),
            },
            critical_delta_bic: -s.critical,
            candidates: merge_by_name(
                s.candidates
                    .iter()
                    .zip(w)
                    .map(|(c, &w)| {
                        candidate_report(
                            points,
                            c,
                            thermal,
                            w,
                            resampled.inclusion(c.cand.name(points)),
                        )
                    })
                    .collect(),
            ),
        })
        .collect()
}

/// How the block bootstrap ran and its most frequent selections.
fn bootstrap_report(points: &TestPoints, boot: &bootstrap::Bootstrap) -> BootstrapReport {
    BootstrapReport {
        replicates: boot.replicates,
        blocks: boot.blocks,
        block_length: boot.block_length,
        seed: boot.seed,
        selections: boot
            .sets()
            .into_iter()
            .take(5)
            .map(|(set, share)| BootstrapSet {
                effects: set.iter().map(|c| cand_label(points, *c)).collect(),
                share,
            })
            .collect(),
    }
}

/// What the report concludes from the selection and the resamples.
struct Judgement {
    effects: Vec<EffectReport>,
    named: Vec<Mechanism>,
    named_names: Vec<String>,
    competitors: Vec<String>,
    ambiguous_candidates: Vec<AmbiguousCandidate>,
    gap_before: Gap,
    gap_after: Gap,
    lack_of_fit: lack_of_fit::LackOfFit,
    verdict: Verdict,
    robust_sigma_a: f64,
    /// The product of the weights of the named effects whose driver is not settled.
    driver_weight: f64,
}

/// The effects named, their rivals, the final model's gap and lack of fit, and the verdict.
fn judge(
    points: &TestPoints,
    selection: &select::Selection,
    weights_by_step: &[Vec<Option<f64>>],
    resampled: &Resampled,
    known_names: &[String],
    options: &Options,
) -> Judgement {
    let after = &selection.end;
    let effects = effect_reports(points, selection, weights_by_step, resampled);
    let named = selection.added();
    let named_names: Vec<String> = named.iter().map(|c| c.name(points).to_string()).collect();
    let competitors = competitors(points, &named_names, known_names);
    let ambiguous_candidates =
        ambiguous_candidates(&effects, &competitors, resampled, options.ambiguity_share);
    // The final model predicted once for its gap and its residuals. (The two gaps side by
    // side on two cores would hold 25 MB more at a million rows, beyond the 200 MB budget.)
    let gap_before = gap::gap(points, &selection.start);
    let predicted = after.predict_rows(points);
    let gap_after = gap::gap_of(points, after, &predicted);
    let mut residuals: Vec<f64> = points
        .row_view
        .current
        .iter()
        .zip(&predicted)
        .map(|(y, f)| y - f)
        .collect();
    drop(predicted);
    let lack_of_fit = lack_of_fit::lack_of_fit(
        points,
        after,
        &residuals,
        &gap_after,
        options.stated_noise_a,
    );
    let verdict = verdict_of(
        !effects.is_empty(),
        &lack_of_fit,
        !ambiguous_candidates.is_empty(),
    );
    let driver_weight = effects
        .iter()
        .filter_map(|f| f.driver_check.as_ref())
        .filter(|d| !d.separated)
        .map(drivers::DriverCheck::weight)
        .product();
    Judgement {
        driver_weight,
        effects,
        named,
        named_names,
        competitors,
        ambiguous_candidates,
        gap_before,
        gap_after,
        lack_of_fit,
        verdict,
        robust_sigma_a: robust::robust_scale(&mut residuals),
    }
}

/// Explains `data` against the rig (and model) of `rig`: prepare the points, select, resample
/// the selection, judge, then report.
pub fn explain(data: &Dataset, rig: &RigFile, options: &Options) -> Result<Outcome, ExplainError> {
    let Prepared {
        spec,
        start,
        known_x,
        known_names,
        points,
        outliers,
        mut warnings,
    } = prepare(data, rig, options)?;
    let selection = select::select_from(&points, &spec, &start, &known_x, options);
    let boot = bootstrap::bootstrap(&points, &selection, options);
    let resampled = Resampled {
        boot: boot.as_ref(),
        points: &points,
    };
    warnings.extend(mu_warning(&selection.end));
    let (weights_by_step, model_weights) = selection_weights(&points, &selection);
    let j = judge(
        &points,
        &selection,
        &weights_by_step,
        &resampled,
        &known_names,
        options,
    );
    let mut inclusion_probabilities = BTreeMap::new();
    if boot.is_some() {
        for name in j.competitors.iter().chain(&j.named_names) {
            if let Some(p) = resampled.inclusion(name) {
                inclusion_probabilities.insert(name.clone(), p);
            }
        }
    }
    let steps = step_reports(
        &points,
        &selection,
        &weights_by_step,
        &j.competitors,
        &resampled,
        options,
    );
    let share = boot.as_ref().map(|b| b.set_share(&j.named));
    let (before, after) = (&selection.start, &selection.end);
    let verdict = j.verdict;
    let confidence = share.map(|s| match verdict {
        Verdict::Explained => {
            calibration::calibrated(&finding_evidence(s, &j.effects, j.lack_of_fit.p_value))
        }
        Verdict::PartlyExplained | Verdict::Ambiguous => {
            calibration::calibrated_partial(&finding_evidence(s, &j.effects, j.lack_of_fit.p_value))
        }
        _ => s * j.driver_weight,
    });
    // Each named effect: its finding's confidence plus, when the finding is not right, the
    // calibrated chance that it is part of the truth all the same.
    let mut effects = j.effects;
    for f in &mut effects {
        f.inclusion_probability =
            f.evidence(j.lack_of_fit.p_value)
                .zip(confidence)
                .map(|(e, c)| {
                    calibration::coherent_inclusion(c, calibration::calibrated_inclusion(&e))
                });
    }
    // A named effect's entry is its calibrated probability, as in `effects`.
    for f in &effects {
        if let Some(p) = f.inclusion_probability {
            inclusion_probabilities.insert(f.name.clone(), p);
        }
    }
    let residual_shape = matches!(verdict, Verdict::Unexplained | Verdict::PartlyExplained)
        .then(|| residual_shape::residual_shape(&points, after));
    let proposed_law = residual_shape
        .as_ref()
        .and_then(|shape| proposed_law::propose(&points, after, shape, &j.lack_of_fit));
    let mut explanation = Explanation {
        verdict,
        effects,
        ambiguous: j
            .ambiguous_candidates
            .iter()
            .map(|c| c.name.clone())
            .collect(),
        ambiguous_candidates: j.ambiguous_candidates,
        confidence,
        confidence_raw: share,
        inclusion_probabilities,
        model_weights,
        bootstrap: boot.as_ref().map(|b| bootstrap_report(&points, b)),
        outliers,
        warnings,
        robust_sigma_a: j.robust_sigma_a,
        rows_in_data: data.len(),
        pooled: points.pooled,
        points: points.len(),
        rmse_before_a: before.rmse(),
        rmse_after_a: after.rmse(),
        holdout_rmse_before_a: selection.start_held_out.map(|h| h.rmse),
        holdout_rmse_after_a: selection.end_held_out.map(|h| h.rmse),
        bic_before: before.bic,
        bic_after: after.bic,
        mu_before: before.model.mu,
        mu_after: after.model.mu,
        rows: points.n_rows,
        held_rows: points.traits().held_rows,
        known_effects: known_names,
        candidates: steps
            .first()
            .map(|s| s.candidates.clone())
            .unwrap_or_default(),
        steps,
        gap_before: j.gap_before,
        gap_after: j.gap_after,
        residual_shape,
        proposed_law,
        lack_of_fit: j.lack_of_fit,
        finding: String::new(),
        report_dir: None,
        model_written: None,
        synthetic: None,
    };
    explanation.finding = report_files::finding(&explanation, &selection);
    Ok(Outcome {
        explanation,
        points,
        before: selection.start,
        after: selection.end,
        rig: rig.clone(),
    })
}
