//! `rig explain` on torque sweeps of the simulated rig (`model::plant`): an effect switched on
//! in the plant but not in the model is named.
//!
//! With a braking (regenerating) drive the inertia term of Eq. (9) returns through the
//! gearhead, eta_f eta_b of it (kappa = -(1 + eta_f eta_b) / 2 = -0.82), while Eq. (10)
//! keeps M_hat w^2 e^2 / pi: against the paper's model alone that is itself a finding
//! (`inertia-rectification`, kappa = -0.82; a drive that cannot take power back pays half of
//! it, kappa = -1/2). The model the braking plant is compared with here therefore carries
//! that term as a known effect (a rig file with `[model]`).

use explain::{self, Dataset, MeasuredRow, Options, Verdict};
use model::paper;
use model::plant::{Drive, Load, NoiseSource, Plant, PlantEffects, PlantParams};
use rigfile::{EffectEntry, RigFile};

/// Simulation step, s.
const DT: f64 = 1e-4;

/// The paper's sweep (10 loads x 3 voltages, `repeats` each) in random order on the plant:
/// 1 s to settle (the cam's mechanical time constant is about 60 ms; a window that starts
/// while the cam still slows from the previous test reads a low current), then the 0.5 s means
/// of the logged current and the cam speed, plus 15 mA of test-to-test scatter.
fn plant_sweep(effects: PlantEffects, repeats: usize, seed: u64) -> Vec<MeasuredRow> {
    sweep_with_drive(effects, true, repeats, seed)
}

/// [`plant_sweep`] with a drive that does (`regeneration`) or does not take power back.
fn sweep_with_drive(
    effects: PlantEffects,
    regeneration: bool,
    repeats: usize,
    seed: u64,
) -> Vec<MeasuredRow> {
    let mut params = PlantParams::paper(paper::RIG_GEARS, Load::Torque(paper::TAU_ROT_MIN_TESTED));
    params.effects = effects;
    params.regeneration = regeneration;
    let mut plant = Plant::new(params, seed);
    let mut rng = NoiseSource::new(seed ^ 0xabcd);
    let mut tests = Vec::new();
    for _ in 0..repeats {
        for v in paper::SUPPLY_VOLTAGES {
            for k in 1..=10 {
                tests.push((paper::TAU_ROT_MIN_TESTED * k as f64, v));
            }
        }
    }
    for i in (1..tests.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        tests.swap(i, j);
    }
    tests
        .into_iter()
        .map(|(tau, v)| {
            plant.set_load(Load::Torque(tau));
            plant.reset_output();
            let drive = Drive {
                duty: v / params.supply,
                enabled: true,
            };
            for _ in 0..10_000 {
                plant.step(DT, drive);
            }
            let (mut i_sum, mut w_sum) = (0.0, 0.0);
            let samples = 5000;
            for _ in 0..samples {
                plant.step(DT, drive);
                i_sum += plant.logged_current();
                w_sum += plant.state().cam_speed;
            }
            let s = plant.state();
            MeasuredRow {
                omega_n: w_sum / samples as f64,
                tau_rot: tau,
                i_in: Some(i_sum / samples as f64 + 0.015 * rng.normal()),
                t_s: Some(s.time),
                v_in: Some(v),
                temp_c: Some(s.temperature),
                backdriven: Some(s.output_speed.abs() > 1e-3),
                ..MeasuredRow::default()
            }
        })
        .collect()
}

/// The paper's rig with a braking drive: Eq. (10) with 0.18 of its inertia term.
fn regenerating_model() -> RigFile {
    let mut params = std::collections::BTreeMap::new();
    params.insert("kappa".to_string(), model::effects::KAPPA_BRAKING_DRIVE);
    RigFile::paper().with_model(
        paper::MU_S,
        vec![EffectEntry {
            name: "inertia-rectification".into(),
            params,
        }],
    )
}

fn explain(rows: Vec<MeasuredRow>, rig: &RigFile) -> explain::Explanation {
    let data = Dataset::from_rows("plant sweep", rows).unwrap();
    explain::explain(&data, rig, &Options::default())
        .unwrap()
        .explanation
}

#[test]
fn paper_model_against_the_regenerating_plant_finds_the_inertia_term_averaging_out() {
    let e = explain(
        plant_sweep(PlantEffects::default(), 2, 1),
        &RigFile::paper(),
    );
    assert_eq!(e.verdict, Verdict::Explained, "{}", e.finding);
    assert_eq!(e.effects[0].name, "inertia-rectification");
    // The braking drive's return through the gearhead, from first principles: -0.82,
    // told apart from a lossless return (-1) and from none (-1/2).
    let kappa = e.effects[0].params["kappa"];
    assert!(
        (kappa - model::effects::KAPPA_BRAKING_DRIVE).abs() < 0.08,
        "kappa {kappa}"
    );
}

#[test]
fn a_drive_that_cannot_take_power_back_pays_half_the_inertia_term() {
    let rows = sweep_with_drive(PlantEffects::default(), false, 2, 3);
    let e = explain(rows, &RigFile::paper());
    assert_eq!(e.verdict, Verdict::Explained, "{}", e.finding);
    assert_eq!(e.effects[0].name, "inertia-rectification");
    let kappa = e.effects[0].params["kappa"];
    assert!((kappa + 0.5).abs() < 0.15, "kappa {kappa}");
}

#[test]
fn the_plant_matches_the_regenerating_model() {
    let e = explain(
        plant_sweep(PlantEffects::default(), 2, 2),
        &regenerating_model(),
    );
    assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
}

#[test]
fn an_effect_switched_on_in_the_plant_is_named() {
    let cases: [(&str, PlantEffects); 3] = [
        (
            "vibrator-viscous-loss",
            PlantEffects {
                extra_viscous: 0.15e-3,
                ..Default::default()
            },
        ),
        (
            "current-sensor-offset",
            PlantEffects {
                current_offset: 0.05,
                ..Default::default()
            },
        ),
        (
            "speed-dependent-axial-friction",
            PlantEffects {
                axial_friction_speed: Some((0.4, 25.0)),
                ..Default::default()
            },
        ),
    ];
    for (k, (name, effects)) in cases.into_iter().enumerate() {
        // A sensor offset and load-dependent friction differ only at light load: with two
        // repeats the sweep tells them apart on 3-4 of 12 seeds (the same with kappa -1 or
        // the braking drive's -0.82), with four on 10 of 12 (measured, issue 30).
        let repeats = if name == "current-sensor-offset" {
            4
        } else {
            2
        };
        let e = explain(
            plant_sweep(effects, repeats, 10 + k as u64),
            &regenerating_model(),
        );
        assert_eq!(e.verdict, Verdict::Explained, "{name}: {}", e.finding);
        assert_eq!(e.effects[0].name, name, "{}", e.finding);
        let (before, after) = (
            e.holdout_rmse_before_a.unwrap(),
            e.holdout_rmse_after_a.unwrap(),
        );
        assert!(after < before, "{name}: held-out {before} -> {after}");
    }
}

#[test]
fn the_written_model_runs_in_the_plant() {
    let truth = PlantEffects {
        extra_viscous: 0.12e-3,
        ..Default::default()
    };
    let data = Dataset::from_rows("plant sweep", plant_sweep(truth, 2, 21)).unwrap();
    let outcome = explain::explain(&data, &regenerating_model(), &Options::default()).unwrap();
    assert_eq!(outcome.explanation.verdict, Verdict::Explained);
    let augmented = RigFile::parse(&outcome.augmented_rig().to_toml().unwrap(), "m.toml").unwrap();
    let setup = augmented.plant_effects().unwrap();
    assert!(setup.regeneration == Some(true) && setup.not_in_plant.is_empty());
    let fitted = setup.effects.extra_viscous;
    assert!((fitted / 0.12e-3 - 1.0).abs() < 0.3, "c_v {fitted}");
    // A plant running the augmented model gives data the augmented model explains.
    let e = explain(
        sweep_with_drive(setup.effects, setup.regeneration == Some(true), 2, 22),
        &augmented,
    );
    assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
}
