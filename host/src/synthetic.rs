//! Synthetic sweeps: the paper's test plan run on the current model of a rig with one
//! plausible hidden effect (or none), with noise, as `rig explain --synthetic` explains
//! them: the workflow's known-answer test.

use model::effects::{Effect, EffectParams};
use model::plant::NoiseSource;

use crate::RigError;
use explain::data::Dataset;
use explain::synth::{self, SweepPlan};
use explain::{SyntheticTruth, library};
use rigfile::RigFile;

/// A synthetic sweep of `rig` with `hidden`, its data set and truth.
pub fn synthetic_data(
    rig: &RigFile,
    hidden: Option<Effect>,
    seed: u64,
    noise_a: f64,
) -> Result<(Dataset, SyntheticTruth), RigError> {
    synthetic_sweep(rig, hidden, seed, noise_a, 5)
}

/// [`synthetic_data`] with `repeats` repeats of the sweep's test points (tests of 0.5-1.5 s
/// beyond the paper's five repeats, so a long sweep stays within a working day).
pub fn synthetic_sweep(
    rig: &RigFile,
    hidden: Option<Effect>,
    seed: u64,
    noise_a: f64,
    repeats: usize,
) -> Result<(Dataset, SyntheticTruth), RigError> {
    let mut truth = rig.current_model()?;
    truth.effects = EffectParams::default();
    let plan = SweepPlan {
        noise_a,
        repeats,
        test_seconds: if repeats > 5 {
            (0.5, 1.5)
        } else {
            (15.0, 25.0)
        },
        ..SweepPlan::default()
    };
    let mut rng = NoiseSource::new(seed ^ 0x9e37_79b9_7f4a_7c15);
    if let Some(e) = hidden {
        truth.effects = synth::plausible_effect(e, &truth, &plan, &mut rng);
    }
    let rows = synth::generate(&truth, &plan, seed);
    let data = Dataset::from_rows("synthetic", rows)?;
    let params = hidden
        .map(|e| {
            library::report_params(
                e,
                &truth.effects,
                library::ThermalDriver::Temperature {
                    reference_c: plan.ambient_c,
                },
            )
        })
        .unwrap_or_default();
    Ok((
        data,
        SyntheticTruth {
            effect: hidden.map(|e| e.name().to_string()),
            params,
            seed,
            noise_a,
        },
    ))
}
