//! Calibrated confidence: the share of bootstrap replicates that reach a finding is not the
//! probability that the finding is right (on batches with truths outside the library, a
//! share of 0.9-0.95 was right in 74 % of the `explained` verdicts, and on an independent
//! batch a stated 0.95 in 65 %). What else the report knows says how far the share can be
//! trusted: a law that a generic shape in another variable nearly matches (a small
//! [`drivers`](crate::drivers) margin), or a final model whose lack of fit is close to
//! significant, is wrong more often at the same share. Logistic models of those three
//! readings ([`Evidence`]), fitted by [`fit_logistic`] on a generated batch and checked on
//! others, turn them into probabilities, one per claim, defined so they cannot contradict:
//! - the finding's confidence `c`: for an `explained` verdict the probability that its set
//!   of effects is exactly the truth ([`CONFIDENCE_MODEL`]); for a `partly-explained` or
//!   `ambiguous` verdict the probability that every effect it names is part of the truth
//!   ([`PARTIAL_MODEL`]);
//! - a named effect's inclusion probability, by the law of total probability over the
//!   finding being right or not: `c + (1 - c) q` ([`coherent_inclusion`]), with `q` the
//!   probability that the effect is part of the truth when the finding is not right
//!   ([`INCLUSION_MODEL`], fitted on the named effects of the findings that were not right).
//!   A right finding holds every effect it names, so each inclusion is at least the
//!   finding's confidence, by construction and not by a cap.
//!
//! The shares themselves stay in the JSON (`confidence_raw`, each effect's
//! `inclusion_probability_raw`).

use serde::Serialize;

/// Readings of the evidence a probability is calibrated from.
pub const FEATURES: usize = 5;

/// The driver margin (chi-square) at which its reading saturates: beyond, a law is as well
/// separated as it gets.
const MARGIN_FULL: f64 = 100.0;
/// Decades of the lack of fit's p-value at which its reading saturates.
const P_DECADES: f64 = 6.0;

/// What a calibrated probability reads of a finding or of one named effect.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Evidence {
    /// The share of bootstrap replicates that reach the finding (that include the effect).
    pub share: f64,
    /// The smallest driver-check margin among its effects: the chi-square its law explains
    /// less that of the best generic shape in another variable (`None`: no effect has a law
    /// with a driver, e.g. a sensor offset).
    pub driver_margin: Option<f64>,
    /// The final model's lack-of-fit p-value.
    pub lack_of_fit_p: f64,
}

impl Evidence {
    /// The readings the model weighs: 1, the share's log-odds (within 0.005-0.995), the
    /// margin (ln(1 + m) / ln(1 + 100), 0 below zero and without a driver), whether no law
    /// has a driver, and the lack of fit's -log10 p in thirds of its six decades.
    pub fn features(&self) -> [f64; FEATURES] {
        let s = if self.share.is_finite() {
            self.share.clamp(0.005, 0.995)
        } else {
            0.005
        };
        let margin = self
            .driver_margin
            .filter(|m| m.is_finite())
            .map_or(0.0, |m| {
                m.clamp(0.0, MARGIN_FULL).ln_1p() / MARGIN_FULL.ln_1p()
            });
        let p = if self.lack_of_fit_p.is_finite() {
            self.lack_of_fit_p.clamp(1e-300, 1.0)
        } else {
            1.0
        };
        [
            1.0,
            (s / (1.0 - s)).ln(),
            margin,
            if self.driver_margin.is_none() {
                1.0
            } else {
                0.0
            },
            (-p.log10()).min(P_DECADES) / 3.0,
        ]
    }
}

/// A logistic model: probability = 1 / (1 + exp(-w . features)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CalibrationModel {
    /// Weight of each reading of [`Evidence::features`].
    pub weights: [f64; FEATURES],
    /// Cases of the batch it was fitted on.
    pub cases: usize,
}

impl CalibrationModel {
    /// The probability this model gives `evidence`.
    pub fn probability(&self, evidence: &Evidence) -> f64 {
        logistic(&self.weights, &evidence.features())
    }
}

/// 1 / (1 + exp(-w . x)).
fn logistic(w: &[f64; FEATURES], x: &[f64; FEATURES]) -> f64 {
    let z: f64 = w.iter().zip(x).map(|(a, b)| a * b).sum();
    1.0 / (1.0 + (-z).exp())
}

/// The probability that an `explained` verdict is exactly right, fitted by [`fit_logistic`]
/// on `explain/tests/explain_open_world.rs`'s `fit_confidence_map` batch: 544 data sets (the
/// paper's rig and one with gears (50, 50, 51, 49), a 1.2 mm stroke and a 4.2 kg carrier;
/// two plans; 3-40 mA; out-of-library truths, library effects, pairs and effect-free sets;
/// seeds 80 000 and up), its `explained` verdicts (refitted in session 10 with the limits
/// judged by their intervals).
pub const CONFIDENCE_MODEL: CalibrationModel = CalibrationModel {
    weights: [-0.07, 0.64, 1.54, 1.11, -2.96],
    cases: 247,
};

/// The probability that every effect a `partly-explained` or `ambiguous` verdict names is
/// part of the truth, fitted by [`fit_logistic`] on the same batch's such verdicts.
pub const PARTIAL_MODEL: CalibrationModel = CalibrationModel {
    weights: [-1.63, 0.25, 0.37, 0.74, -1.97],
    cases: 168,
};

/// The probability that a named effect is part of the truth when the finding that names it
/// is not right, fitted by [`fit_logistic`] on the same batch: every effect named by a
/// finding that was not right ([`coherent_inclusion`] adds the finding's confidence).
pub const INCLUSION_MODEL: CalibrationModel = CalibrationModel {
    weights: [-4.34, 0.05, 0.86, -0.48, -1.08],
    cases: 377,
};

/// The probability that an `explained` verdict with this evidence is right
/// ([`CONFIDENCE_MODEL`]).
pub fn calibrated(evidence: &Evidence) -> f64 {
    CONFIDENCE_MODEL.probability(evidence)
}

/// The probability that every effect of a `partly-explained` or `ambiguous` verdict with
/// this evidence is part of the truth ([`PARTIAL_MODEL`]).
pub fn calibrated_partial(evidence: &Evidence) -> f64 {
    PARTIAL_MODEL.probability(evidence)
}

/// The probability that a named effect with this evidence is part of the truth when the
/// finding naming it is not right ([`INCLUSION_MODEL`]).
pub fn calibrated_inclusion(evidence: &Evidence) -> f64 {
    INCLUSION_MODEL.probability(evidence)
}

/// A named effect's inclusion probability from its finding's confidence `confidence` and
/// `given_wrong`, the probability that it is part of the truth when the finding is not
/// right: P(in) = P(right) + P(not right) P(in | not right), since a right finding holds
/// every effect it names. Never below `confidence`.
pub fn coherent_inclusion(confidence: f64, given_wrong: f64) -> f64 {
    let c = confidence.clamp(0.0, 1.0);
    c + (1.0 - c) * given_wrong.clamp(0.0, 1.0)
}

/// Ridge on the weights other than the intercept: a batch of a few hundred verdicts
/// supports five weights, not their noise.
pub const RIDGE: f64 = 1.0;

/// The logistic model of `right` on the readings of each case, by maximum likelihood with
/// [`RIDGE`] (Newton's method; `None` when the cases cannot fix the weights).
pub fn fit_logistic(cases: &[(Evidence, bool)]) -> Option<CalibrationModel> {
    const N: usize = FEATURES;
    if cases.is_empty() {
        return None;
    }
    let x: Vec<[f64; N]> = cases.iter().map(|(e, _)| e.features()).collect();
    let y: Vec<f64> = cases.iter().map(|&(_, r)| f64::from(u8::from(r))).collect();
    let mut w = [0.0; N];
    for _ in 0..100 {
        let mut grad = [0.0; N];
        let mut hess = [0.0; N * N];
        for (xi, yi) in x.iter().zip(&y) {
            let p = logistic(&w, xi);
            for a in 0..N {
                grad[a] += (p - yi) * xi[a];
                for b in 0..N {
                    hess[a * N + b] += p * (1.0 - p) * xi[a] * xi[b];
                }
            }
        }
        for a in 1..N {
            grad[a] += RIDGE * w[a];
            hess[a * N + a] += RIDGE;
        }
        hess[0] += 1e-9;
        let l = crate::stats::cholesky(&hess, N)?;
        let step = crate::stats::cholesky_solve(&l, N, &grad);
        let mut largest = 0.0f64;
        for a in 0..N {
            w[a] -= step[a];
            largest = largest.max(step[a].abs());
        }
        if !largest.is_finite() {
            return None;
        }
        if largest < 1e-10 {
            break;
        }
    }
    Some(CalibrationModel {
        weights: w,
        cases: cases.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(share: f64, margin: Option<f64>, p: f64) -> Evidence {
        Evidence {
            share,
            driver_margin: margin,
            lack_of_fit_p: p,
        }
    }

    #[test]
    fn the_fit_recovers_the_weights_that_drew_the_cases() {
        // Cases drawn from a known model: the fit finds its weights back (within the ridge's
        // pull and the draw's noise).
        let truth = CalibrationModel {
            weights: [0.5, 1.0, 1.5, 0.5, -2.0],
            cases: 0,
        };
        let mut rng = model::plant::NoiseSource::new(7);
        let mut cases = Vec::new();
        for _ in 0..20_000 {
            let e = ev(
                rng.uniform(),
                (rng.uniform() < 0.8).then(|| 150.0 * rng.uniform()),
                rng.uniform().powi(3),
            );
            let right = rng.uniform() < truth.probability(&e);
            cases.push((e, right));
        }
        let fitted = fit_logistic(&cases).unwrap();
        for (a, b) in fitted.weights.iter().zip(truth.weights) {
            assert!((a - b).abs() < 0.2, "{fitted:?}");
        }
    }

    #[test]
    fn an_effect_is_named_at_least_as_surely_as_the_finding_that_names_it() {
        for c in [0.0, 0.1, 0.5, 0.93, 1.0] {
            for q in [0.0, 0.25, 0.9, 1.0] {
                let p = coherent_inclusion(c, q);
                assert!(p >= c && p <= 1.0, "{c} {q} {p}");
            }
        }
        // The contradiction: a finding right at 0.93 cannot name an effect at 0.25.
        assert!((coherent_inclusion(0.93, 0.25) - (0.93 + 0.07 * 0.25)).abs() < 1e-12);
        assert_eq!(coherent_inclusion(0.0, 0.4), 0.4);
    }

    #[test]
    fn the_shipped_models_rise_with_the_share_and_fall_with_the_lack_of_fit() {
        for m in [CONFIDENCE_MODEL, PARTIAL_MODEL, INCLUSION_MODEL] {
            let at = |s, p| m.probability(&ev(s, Some(50.0), p));
            assert!(at(0.99, 0.5) > at(0.6, 0.5));
            assert!(at(0.99, 0.5) > at(0.99, 0.002));
            for s in [0.0, 0.5, 1.0, f64::NAN] {
                let p = m.probability(&ev(s, None, 0.3));
                assert!((0.0..=1.0).contains(&p), "{p}");
            }
        }
    }
}
