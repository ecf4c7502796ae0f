//! `rig explain`: find where the model of the vibrator current and the measurement disagree,
//! name the missing effect, add it to the model and show the gap shrink.
//!
//! 1. Gap: fit the paper's model i = (tau_cam_hat(tau_rot, w_n; mu) + C3 w_n + C4 - C2) / C1
//!    (Eqs. 10, 15-17, mu fitted; or a loaded model with its effects refitted) and show where
//!    it disagrees ([`gap`]).
//! 2. Candidates: the effects of [`library`], each fitted jointly with the model ([`fit`]).
//! 3. Selection: forward selection by BIC, guarded by a parametric bootstrap of the best
//!    improvement under the current model and confirmed on held-out blocks of test points
//!    ([`select`]); candidates within 2 of the best BIC are `ambiguous`.
//! 4. Add: the augmented model as a rig file ([`rigfile`]).
//! 5. Show: a report folder with residual plots, the candidate table and the finding
//!    ([`report_files`]).
//!
//! The entry point for plain rows (files, the simulator, tests) is [`explain`].

pub mod data;
pub mod fit;
pub mod gap;
pub mod library;

pub mod points;
pub mod report_files;
pub mod select;
pub mod stats;
pub mod synth;

use std::collections::BTreeMap;

use model::effects::{Effect, Param};
use serde::Serialize;

mod error;

pub use data::{Dataset, MeasuredRow};
pub use error::ExplainError;
pub use select::Options;

use fit::{Fit, ModelSpec};
use gap::Gap;
use library::ThermalDriver;
use points::TestPoints;
use rigfile::{EffectEntry, RigFile};

/// What `rig explain` concludes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// One or more effects were found and added; the gap shrank.
    Explained,
    /// The model agrees with the measurement within its noise.
    NoMissingEffect,
    /// An effect is missing, but the data cannot tell which of several candidates.
    Ambiguous,
}

impl Verdict {
    /// The verdict as printed (`explained`, `no-missing-effect`, `ambiguous`).
    pub fn as_str(self) -> &'static str {
        match self {
            Verdict::Explained => "explained",
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
}

/// A row of a candidate table.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateReport {
    /// The effect's name.
    pub name: String,
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
    /// Candidates the data cannot tell from the best.
    pub ambiguous_with: Vec<String>,
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
    /// Rows with a current.
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
    /// The rig file with the final model (mu and every effect, loaded ones first).
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
        self.rig.with_model(self.after.model.mu, effects)
    }
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

fn candidate_report(c: &select::Candidate, thermal: ThermalDriver) -> CandidateReport {
    match &c.fit {
        Some(f) => CandidateReport {
            name: c.effect.name().to_string(),
            applicable: true,
            note: None,
            params: library::report_params(c.effect, &f.model.effects, thermal),
            intervals: intervals(c.effect, f, thermal),
            delta_bic: Some(-c.improvement),
            rmse_a: Some(f.rmse()),
            holdout_rmse_a: c.held_out.map(|h| h.rmse),
        },
        None if c.estimated => CandidateReport {
            name: c.effect.name().to_string(),
            applicable: true,
            note: Some(
                "not fitted: on large data only the leaders of the score test are; delta_bic is the score-test estimate".into(),
            ),
            params: BTreeMap::new(),
            intervals: BTreeMap::new(),
            delta_bic: Some(-c.improvement),
            rmse_a: None,
            holdout_rmse_a: None,
        },
        None => CandidateReport {
            name: c.effect.name().to_string(),
            applicable: false,
            note: c.not_applicable.map(str::to_string),
            params: BTreeMap::new(),
            intervals: BTreeMap::new(),
            delta_bic: None,
            rmse_a: None,
            holdout_rmse_a: None,
        },
    }
}

/// Explains `data` against the rig (and model) of `rig`.
pub fn explain(data: &Dataset, rig: &RigFile, options: &Options) -> Result<Outcome, ExplainError> {
    let start = rig.current_model()?;
    let (known, _) = rig.effects().map_err(|why| ExplainError::RigFile {
        file: "model".into(),
        why,
    })?;
    let points = TestPoints::new(data, rig.calibration.temperature_c, options.folds);
    let spec = ModelSpec {
        effects: known.clone(),
    };
    let selection = select::select(&points, &spec, &start, options);
    let thermal = points.thermal;
    let before = selection.start.clone();
    let after = selection.end.clone();

    let mut effects = Vec::new();
    let mut ambiguous = Vec::new();
    for step in selection.steps.iter().filter(|s| s.accepted) {
        let best = step.best().expect("an accepted step has a best candidate");
        let f = best.fit.as_ref().expect("fitted");
        effects.push(EffectReport {
            name: best.effect.name().to_string(),
            params: library::report_params(best.effect, &after.model.effects, thermal),
            intervals: if after.spec.has(best.effect) {
                intervals(best.effect, &after, thermal)
            } else {
                intervals(best.effect, f, thermal)
            },
            delta_bic: -best.improvement,
            p_value: step.p_value,
            holdout_rmse_a: best.held_out.map(|h| h.rmse),
            description: library::describe(best.effect, &after.model.effects, thermal),
        });
        if !step.ambiguous_with.is_empty() && ambiguous.is_empty() {
            ambiguous.push(best.effect.name().to_string());
            ambiguous.extend(step.ambiguous_with.iter().map(|e| e.name().to_string()));
        }
    }
    let verdict = if effects.is_empty() {
        Verdict::NoMissingEffect
    } else if !ambiguous.is_empty() {
        Verdict::Ambiguous
    } else {
        Verdict::Explained
    };
    let steps: Vec<StepReport> = selection
        .steps
        .iter()
        .map(|s| StepReport {
            best: s.best().map(|c| c.effect.name().to_string()),
            accepted: s.accepted,
            p_value: s.p_value,
            reason: s.reason.clone(),
            ambiguous_with: s
                .ambiguous_with
                .iter()
                .map(|e| e.name().to_string())
                .collect(),
            candidates: s
                .candidates
                .iter()
                .map(|c| candidate_report(c, thermal))
                .collect(),
        })
        .collect();
    let gap_before = gap::gap(&points, &before);
    let gap_after = gap::gap(&points, &after);
    let mut explanation = Explanation {
        verdict,
        effects,
        ambiguous,
        rmse_before_a: before.rmse(),
        rmse_after_a: after.rmse(),
        holdout_rmse_before_a: selection.start_held_out.map(|h| h.rmse),
        holdout_rmse_after_a: selection.end_held_out.map(|h| h.rmse),
        bic_before: before.bic,
        bic_after: after.bic,
        mu_before: before.model.mu,
        mu_after: after.model.mu,
        rows: points.len(),
        held_rows: points.traits().held_rows,
        known_effects: known.iter().map(|e| e.name().to_string()).collect(),
        candidates: steps
            .first()
            .map(|s| s.candidates.clone())
            .unwrap_or_default(),
        steps,
        gap_before,
        gap_after,
        finding: String::new(),
        report_dir: None,
        model_written: None,
        synthetic: None,
    };
    explanation.finding = report_files::finding(&explanation, &selection);
    Ok(Outcome {
        explanation,
        points,
        before,
        after,
        rig: rig.clone(),
    })
}
