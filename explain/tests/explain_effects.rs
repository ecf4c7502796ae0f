//! `rig explain` on synthetic sweeps with one hidden effect each (random parameters over
//! plausible ranges, several seeds, 10-30 mA noise, tests in random order over a warming
//! session) and on effect-free sweeps: the right effect is named, the gap shrinks on held-out
//! points, effect-free data gives `no-missing-effect`. Hit and false-positive rates over a
//! larger batch: `explain_batch.rs` (ignored by default).

use explain::synth::{self, SweepPlan};
use explain::{self, Dataset, Explanation, Options, Verdict};
use model::effects::Effect;
use model::plant::NoiseSource;
use rigfile::RigFile;

/// A sweep of `rig` with `hidden` drawn over its plausible range.
fn sweep(rig: &RigFile, hidden: Option<Effect>, plan: &SweepPlan, seed: u64) -> Dataset {
    let mut truth = rig.current_model().unwrap();
    let mut rng = NoiseSource::new(seed.wrapping_mul(0x9e37_79b9) ^ 0x5eed);
    if let Some(e) = hidden {
        truth.effects = synth::plausible_effect(e, &truth, plan, &mut rng);
    }
    Dataset::from_rows("synthetic", synth::generate(&truth, plan, seed)).unwrap()
}

fn run(data: &Dataset, rig: &RigFile) -> Explanation {
    explain::explain(data, rig, &Options::default())
        .unwrap()
        .explanation
}

fn assert_named(e: &Explanation, effect: Effect, context: &str) {
    assert_eq!(e.verdict, Verdict::Explained, "{context}: {}", e.finding);
    assert_eq!(e.effects[0].name, effect.name(), "{context}: {}", e.finding);
    if effect != Effect::MeshLoadSharingRipple {
        // The ripple only scatters the current: its evidence is the held-out likelihood.
        let (before, after) = (
            e.holdout_rmse_before_a.unwrap(),
            e.holdout_rmse_after_a.unwrap(),
        );
        assert!(
            after < before,
            "{context}: held-out RMSE {before} -> {after}"
        );
        assert!(e.rmse_after_a < e.rmse_before_a);
    }
}

#[test]
fn each_hidden_effect_is_named_and_the_held_out_gap_shrinks() {
    let rig = RigFile::paper();
    for effect in Effect::ALL {
        for seed in 1..=3 {
            let plan = SweepPlan {
                noise_a: [0.010, 0.020, 0.030][seed as usize - 1],
                ..SweepPlan::default()
            };
            let data = sweep(&rig, Some(effect), &plan, seed);
            let e = run(&data, &rig);
            assert_named(&e, effect, &format!("{} seed {seed}", effect.name()));
        }
    }
}

#[test]
fn effect_free_sweeps_give_no_missing_effect() {
    let rig = RigFile::paper();
    for seed in 100..112 {
        let plan = SweepPlan {
            noise_a: 0.010 + 0.002 * (seed - 100) as f64,
            ..SweepPlan::default()
        };
        let e = run(&sweep(&rig, None, &plan, seed), &rig);
        assert_eq!(
            e.verdict,
            Verdict::NoMissingEffect,
            "seed {seed}: {}",
            e.finding
        );
        assert!(e.effects.is_empty());
        assert_eq!(e.rmse_before_a, e.rmse_after_a);
    }
}

#[test]
fn other_gear_sets_through_the_rig_file() {
    let rig = RigFile::parse(
        "[gear]\nz = [52, 48, 50, 50]\n[cam]\neccentricity_mm = 0.6\ncarrier_mass_kg = 2.5\n[calibration]\nc1 = 55.0\nc2 = -120.0\n",
        "rig.toml",
    )
    .unwrap();
    let plan = SweepPlan::default();
    for (k, effect) in [
        Effect::SpeedDependentAxialFriction,
        Effect::ThermalDrift,
        Effect::InertiaRectification,
        Effect::CurrentSensorOffset,
    ]
    .into_iter()
    .enumerate()
    {
        let e = run(&sweep(&rig, Some(effect), &plan, 20 + k as u64), &rig);
        assert_named(&e, effect, effect.name());
    }
    let e = run(&sweep(&rig, None, &plan, 30), &rig);
    assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
}

#[test]
fn thermal_drift_shows_against_time_when_no_temperature_was_logged() {
    let rig = RigFile::paper();
    let plan = SweepPlan {
        with_temperature: false,
        ..SweepPlan::default()
    };
    let e = run(&sweep(&rig, Some(Effect::ThermalDrift), &plan, 41), &rig);
    assert_named(&e, Effect::ThermalDrift, "time only");
    assert!(
        e.effects[0].params.contains_key("k_per_s"),
        "{:?}",
        e.effects[0].params
    );
}

#[test]
fn without_optional_columns_only_what_the_data_can_show_is_tried() {
    let rig = RigFile::paper();
    let plan = SweepPlan {
        with_time: false,
        with_temperature: false,
        with_voltage: false,
        with_backdriven: false,
        ..SweepPlan::default()
    };
    let e = run(
        &sweep(&rig, Some(Effect::VibratorViscousLoss), &plan, 51),
        &rig,
    );
    assert_named(&e, Effect::VibratorViscousLoss, "no optional columns");
    let not_applicable: Vec<&str> = e
        .candidates
        .iter()
        .filter(|c| !c.applicable)
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(not_applicable, ["thermal-drift", "linear-bush-friction"]);
}

#[test]
fn the_augmented_model_explains_the_same_data() {
    let rig = RigFile::paper();
    for (k, effect) in [
        Effect::SpeedDependentAxialFriction,
        Effect::LinearBushFriction,
        Effect::MeshLoadSharingRipple,
    ]
    .into_iter()
    .enumerate()
    {
        let data = sweep(&rig, Some(effect), &SweepPlan::default(), 60 + k as u64);
        let first = explain::explain(&data, &rig, &Options::default()).unwrap();
        assert_named(&first.explanation, effect, effect.name());
        let text = first.augmented_rig().to_toml().unwrap();
        let augmented = RigFile::parse(&text, "augmented.toml").unwrap();
        let second = run(&data, &augmented);
        assert_eq!(
            second.verdict,
            Verdict::NoMissingEffect,
            "{}",
            second.finding
        );
        assert_eq!(second.known_effects, [effect.name()]);
        assert!((second.rmse_before_a - first.explanation.rmse_after_a).abs() < 1e-6);
    }
}

#[test]
fn candidate_table_has_parameters_intervals_and_held_out_scores() {
    let rig = RigFile::paper();
    let data = sweep(
        &rig,
        Some(Effect::VibratorViscousLoss),
        &SweepPlan::default(),
        71,
    );
    let e = run(&data, &rig);
    let best = &e.candidates[0];
    assert_eq!(best.name, "vibrator-viscous-loss");
    let [lo, hi] = best.intervals["c_v_n_mm_s_per_rad"];
    let v = best.params["c_v_n_mm_s_per_rad"];
    assert!(lo < v && v < hi && lo > 0.0, "{lo} {v} {hi}");
    assert!(best.delta_bic.unwrap() < -10.0);
    assert!(best.holdout_rmse_a.is_some());
    assert_eq!(e.candidates.len(), Effect::ALL.len());
    // The gap tables bin the residuals by speed, load and temperature.
    assert_eq!(e.gap_before.by_speed.len(), 3);
    assert_eq!(e.gap_before.by_load.len(), 10);
    assert!(!e.gap_before.by_thermal.is_empty());
    assert!(
        e.gap_before
            .correlations
            .iter()
            .any(|c| c.with == "omega_n_rad_s" && c.p_value < 1e-3)
    );
    assert!(e.gap_after.rmse_a < e.gap_before.rmse_a);
}
