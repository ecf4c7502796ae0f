//! Calibrated confidence: the share of bootstrap replicates that reach a finding is not the
//! probability that the finding is right (on batches with truths outside the library, a
//! share of 0.9-0.95 was right in 74 % of the `explained` verdicts). A monotone map, fitted
//! by isotonic regression on a generated batch and checked on another, turns the share into
//! that probability ([`calibrated`]); the share itself stays in the JSON as `confidence_raw`.
//!
//! The map was fitted on `explain/tests/explain_open_world.rs`'s `fit_confidence_map`
//! batch (its own seeds and a third rig) and is checked on `full_open_world_batch` (other
//! seeds and rigs), whose reliability table docs/explain-validation.md gives.

/// One step of a confidence map: bootstrap shares from `from` (inclusive) up to the next
/// step's `from` were right with probability `probability`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationStep {
    /// Lowest bootstrap share of the step.
    pub from: f64,
    /// Probability that an `explained` verdict with such a share names exactly the truth.
    pub probability: f64,
    /// Verdicts of the fitting batch in the step.
    pub verdicts: usize,
}

/// The map from the bootstrap share of an `explained` verdict's set of effects to the
/// probability that the set is exactly the truth, fitted by [`isotonic`] on the
/// `fit_confidence_map` batch: 544 data sets (the paper's rig and one with gears (50, 50,
/// 51, 49), a 1.2 mm stroke and a 4.2 kg carrier; two plans; 3-40 mA; out-of-library
/// truths, library effects, pairs and effect-free sets; seeds 80 000 and up), 225 of them
/// `explained` (refitted after the driver check and the pairs plausible only together,
/// session 7).
pub const CONFIDENCE_MAP: &[CalibrationStep] = &[
    CalibrationStep {
        from: 0.0,
        probability: 0.421,
        verdicts: 17,
    },
    CalibrationStep {
        from: 0.5,
        probability: 0.6,
        verdicts: 18,
    },
    CalibrationStep {
        from: 0.7,
        probability: 0.741,
        verdicts: 25,
    },
    CalibrationStep {
        from: 0.8,
        probability: 0.85,
        verdicts: 18,
    },
    CalibrationStep {
        from: 0.85,
        probability: 0.862,
        verdicts: 27,
    },
    CalibrationStep {
        from: 0.9,
        probability: 0.913,
        verdicts: 21,
    },
    CalibrationStep {
        from: 0.95,
        probability: 0.95,
        verdicts: 99,
    },
];

/// The probability that an `explained` verdict whose set of effects `share` of the bootstrap
/// replicates reach is right, by [`CONFIDENCE_MAP`].
pub fn calibrated(share: f64) -> f64 {
    calibrated_by(CONFIDENCE_MAP, share)
}

/// [`calibrated`] by the map `map` (steps in rising `from`).
pub fn calibrated_by(map: &[CalibrationStep], share: f64) -> f64 {
    map.iter()
        .take_while(|s| s.from <= share)
        .last()
        .or(map.first())
        .map_or(share, |s| s.probability)
}

/// Lower edges of the bins [`isotonic`] starts from: a step per bin is all a batch of a few
/// hundred verdicts can support (a step per distinct share would follow its noise).
pub const BIN_EDGES: [f64; 8] = [0.0, 0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.99];

/// Isotonic regression of `right` on the bootstrap share, as a step map: pairs
/// `(share, right)` in any order are counted in the bins of [`BIN_EDGES`], each bin's
/// probability is its share of right verdicts with one right and one wrong added (Laplace's
/// rule: 40 right of 40 says 0.976, not certainty), and neighbouring bins whose
/// probabilities fall are pooled until they rise (pool adjacent violators). Empty bins join
/// the step below them.
pub fn isotonic(pairs: &[(f64, bool)]) -> Vec<CalibrationStep> {
    // (lowest share, right, count) per bin with verdicts.
    let mut blocks: Vec<(f64, f64, f64)> = Vec::new();
    for (k, &from) in BIN_EDGES.iter().enumerate() {
        let to = BIN_EDGES.get(k + 1).copied().unwrap_or(f64::INFINITY);
        let bin: Vec<bool> = pairs
            .iter()
            .filter(|(c, _)| c.is_finite() && *c >= from && *c < to)
            .map(|p| p.1)
            .collect();
        if !bin.is_empty() {
            let right = bin.iter().filter(|&&r| r).count() as f64;
            blocks.push((from, right, bin.len() as f64));
        }
    }
    let rate = |b: &(f64, f64, f64)| (b.1 + 1.0) / (b.2 + 2.0);
    // Pool until no step falls.
    while let Some(k) = (1..blocks.len()).find(|&k| rate(&blocks[k]) < rate(&blocks[k - 1])) {
        let b = blocks.remove(k);
        let a = &mut blocks[k - 1];
        a.1 += b.1;
        a.2 += b.2;
    }
    blocks
        .iter()
        .enumerate()
        .map(|(k, b)| CalibrationStep {
            from: if k == 0 { 0.0 } else { b.0 },
            probability: rate(b),
            verdicts: b.2 as usize,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotonic_pools_a_violation_and_keeps_the_order() {
        // 0.8-0.85 right 9 of 10, 0.9-0.95 right 6 of 10, 0.95-0.99 right 19 of 20, below
        // 0.5 right 2 of 10: the 0.9 bin falls below the 0.8 bin and pools with it.
        let mut pairs = Vec::new();
        for k in 0..10 {
            pairs.push((0.82, k < 9));
            pairs.push((0.92, k < 6));
            pairs.push((0.3, k < 2));
        }
        for k in 0..20 {
            pairs.push((0.97, k < 19));
        }
        let map = isotonic(&pairs);
        assert_eq!(map.len(), 3, "{map:?}");
        assert_eq!(map[0].from, 0.0);
        assert!((map[0].probability - 3.0 / 12.0).abs() < 1e-12, "{map:?}");
        assert_eq!(map[1].from, 0.8);
        assert!((map[1].probability - 16.0 / 22.0).abs() < 1e-12, "{map:?}");
        assert_eq!(map[2].from, 0.95);
        assert_eq!(map[2].verdicts, 20);
        assert!(map.windows(2).all(|w| w[0].probability <= w[1].probability));
        // Shares between steps take the step below; below the first, the first.
        assert_eq!(calibrated_by(&map, 0.9), map[1].probability);
        assert_eq!(calibrated_by(&map, 1.0), map[2].probability);
        assert_eq!(calibrated_by(&map, 0.0), map[0].probability);
    }

    #[test]
    fn the_shipped_map_is_a_monotone_probability() {
        assert_eq!(CONFIDENCE_MAP[0].from, 0.0);
        assert!(
            CONFIDENCE_MAP
                .windows(2)
                .all(|w| w[0].from < w[1].from && w[0].probability <= w[1].probability)
        );
        assert!(
            CONFIDENCE_MAP
                .iter()
                .all(|s| s.probability > 0.0 && s.probability < 1.0)
        );
        for share in [0.0, 0.5, 0.9, 1.0] {
            let p = calibrated(share);
            assert!((0.0..=1.0).contains(&p));
        }
    }
}
