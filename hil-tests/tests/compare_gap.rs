//! `rig compare`'s gap against `rig explain`'s on the same simulated sweep (issue 21): the
//! model `rig explain` fits on a torque sweep, run in the virtual rig by compare's replay,
//! leaves no more than 1.5 times the residual explain reports.
//!
//! Before, the sweep's window opened while the cam was still accelerating after the
//! firmware reported constant rotation: +3 mA of J dw/dt at 8.8 V that no steady-state model
//! holds. Explain's fit took it into kappa (-0.475 on data made with -0.5) and compare's
//! replay, which accelerates in the same way, counted it a second time; each replay also
//! added its own boot zero error (about 1 mA) and its own draw of the 0.5 s window's
//! friction-ripple phase (several mA at 3.6 V and heavy loads). The clean rig's ratio was
//! 4.2; the test pins both the cause (kappa comes back as made) and the ratio.

use std::collections::BTreeMap;
use std::path::Path;

use explain::{Dataset, Options};
use model::plant::PlantEffects;
use rigfile::{EffectEntry, RigFile};
use sim::scenarios::sweep;

/// The simulated drive is the board's: the G2 brakes and returns the carrier's power
/// through the gearhead (kappa = -(1 + eta_f eta_b) / 2 = -0.82; a coasting build: -1/2).
/// That is part of the rig, so the starting model says so.
const BOARD_KAPPA: f64 = model::effects::drive_kappa(model::hardware::board::REGENERATIVE_DECAY);

fn rig_model() -> RigFile {
    let mut params = BTreeMap::new();
    params.insert("kappa".to_string(), BOARD_KAPPA);
    RigFile::paper().with_model(
        model::paper::MU_S,
        vec![EffectEntry {
            name: "inertia-rectification".into(),
            params,
        }],
    )
}

/// What one sweep gave: explain's residual and kappa, compare's gap with the fitted model.
#[derive(Debug)]
struct Gaps {
    explain_rmse_a: f64,
    kappa: Option<f64>,
    compare_rmse_a: f64,
    compare_points: usize,
}

/// A torque sweep of 5 loads x 3 voltages x 2 repeats on a virtual rig with `effects`
/// (`seed`), explained from the board's model, and that fitted model compared.
fn gaps(effects: PlantEffects, seed: u64, dir: &Path) -> Gaps {
    let opts = sweep::SweepOptions {
        loads: host::sweep_report::sweep_loads(5),
        repeats: 2,
        rest_s: 1.0,
        seed,
        effects,
        ..Default::default()
    };
    let points = host::experiment::paper::torque_sweep(&opts).expect("the sweep runs");
    let path = dir.join(format!("sweep-{seed}.csv"));
    sweep::write_csv(&points, std::fs::File::create(&path).unwrap()).unwrap();
    let data = Dataset::read_csv(&path).expect("explain reads the sweep");
    let options = Options {
        replicates: 0,
        null_draws: 2000,
        ..Options::default()
    };
    let outcome = explain::explain(&data, &rig_model(), &options).expect("explain runs");
    let fitted = outcome.augmented_rig();
    let kappa = fitted.model.as_ref().and_then(|m| {
        m.effects
            .iter()
            .find(|e| e.name == "inertia-rectification")
            .and_then(|e| e.params.get("kappa").copied())
    });
    let c = host::cli::compare::compare(&path, &fitted, Some(&fitted), 1).expect("compare runs");
    Gaps {
        explain_rmse_a: outcome.explanation.rmse_after_a,
        kappa,
        compare_rmse_a: c.gap_rmse_model_a.expect("a model was compared"),
        compare_points: c.points,
    }
}

/// A folder of its own for one test's files, removed when dropped.
struct Scratch(std::path::PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let dir =
            std::env::temp_dir().join(format!("rig-compare-gap-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn compare_leaves_at_most_one_and_a_half_times_explains_gap() {
    let dir = Scratch::new("fast");
    let g = gaps(PlantEffects::default(), 5, dir.path());
    // The cause: data made with a known kappa give it back (was -0.475).
    let kappa = g.kappa.expect("kappa stays in the model");
    assert!((kappa - BOARD_KAPPA).abs() < 0.01, "{g:?}");
    assert_eq!(g.compare_points, 30, "{g:?}");
    // The gap: the two runs' noise and what the law cannot hold (was 4.2 times).
    assert!(
        g.compare_rmse_a <= 1.5 * g.explain_rmse_a,
        "compare {:.2} mA against explain {:.2} mA: {g:?}",
        g.compare_rmse_a * 1e3,
        g.explain_rmse_a * 1e3
    );
}

/// The same on other seeds and rigs with an effect to find (minutes).
#[test]
#[ignore]
fn compare_leaves_at_most_one_and_a_half_times_explains_gap_batch() {
    let dir = Scratch::new("batch");
    let cases = [
        ("clean", PlantEffects::default()),
        ("paper preset", sim::Preset::paper().effects),
        (
            "vibrator-viscous-loss",
            PlantEffects {
                extra_viscous: 2e-4,
                ..PlantEffects::default()
            },
        ),
        (
            "speed-dependent-axial-friction",
            PlantEffects {
                axial_friction_speed: Some((0.4, 25.0)),
                ..PlantEffects::default()
            },
        ),
    ];
    let mut worst: Vec<String> = Vec::new();
    for (name, effects) in cases {
        for seed in [7, 11, 13] {
            let g = gaps(effects, seed, dir.path());
            let ratio = g.compare_rmse_a / g.explain_rmse_a;
            eprintln!(
                "{name} seed {seed}: explain {:.2} mA, compare {:.2} mA, ratio {ratio:.2}, kappa {:?}",
                g.explain_rmse_a * 1e3,
                g.compare_rmse_a * 1e3,
                g.kappa
            );
            if ratio > 1.5 {
                worst.push(format!("{name} seed {seed}: {ratio:.2}"));
            }
        }
    }
    assert!(worst.is_empty(), "over 1.5 times: {worst:?}");
}
