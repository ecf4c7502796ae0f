//! User-defined effects (`[[user_effects]]` in the rig file) enter the same selection as the
//! library's: a frame resonance no library law has is named, effect-free data gives no
//! finding with it among the candidates, the written model carries it and explains the data,
//! and a bad expression is refused naming what to fix.

use explain::synth::{self, BenchSchedule, Conditions, SweepPlan};
use explain::{self, Dataset, Options, Verdict};
use model::effects::CurrentModel;
use rigfile::RigFile;

/// A rig file with a frame resonance near 10 Hz: extra current c exp(-((w - w_r) / 15)^2).
const RESONANCE: &str = "[[user_effects]]
name = \"frame-resonance\"
expression = \"c * exp(-((w - w_r) / 15)^2)\"
params = { c = { unit = \"A\", bounds = [-0.5, 0.5] }, w_r = { unit = \"rad/s\", bounds = [20.0, 120.0], start = 60.0, null = 60.0, log = true } }
";

/// Five voltages (5 to 15 Hz in 2.5 Hz steps), the paper's loads, five repeats.
fn plan(noise_a: f64) -> SweepPlan {
    SweepPlan {
        voltages_v: vec![3.6, 4.9, 6.2, 7.5, 8.8],
        repeats: 3,
        noise_a,
        ..SweepPlan::default()
    }
}

fn data(c: f64, noise_a: f64, seed: u64) -> Dataset {
    let rig = RigFile::parse(RESONANCE, "rig.toml").unwrap();
    let truth = rig.current_model().unwrap();
    let extra = move |_: &CurrentModel, k: &Conditions| {
        let z = (k.op.omega_n - 62.8) / 15.0;
        c * (-z * z).exp()
    };
    let rows = synth::generate_session(
        &truth,
        &plan(noise_a),
        &BenchSchedule::default(),
        seed,
        Some(&extra),
    );
    Dataset::from_rows("resonance.csv", rows).unwrap()
}

#[test]
fn a_user_effect_is_named_and_written_into_the_model() {
    let rig = RigFile::parse(RESONANCE, "rig.toml").unwrap();
    for (k, c) in [0.06, -0.08, 0.1].into_iter().enumerate() {
        let d = data(c, 0.02, 10 + k as u64);
        let out = explain::explain(&d, &rig, &Options::default()).unwrap();
        let e = &out.explanation;
        assert_eq!(e.verdict, Verdict::Explained, "{}", e.finding);
        assert_eq!(e.effects[0].name, "frame-resonance", "{}", e.finding);
        let fitted = e.effects[0].params["c"];
        assert!(
            (fitted - c).abs() < 0.3 * c.abs(),
            "c {fitted} vs {c}: {:?} {}",
            e.effects[0].params,
            e.finding
        );
        let w_r = e.effects[0].params["w_r"];
        assert!((w_r - 62.8).abs() < 5.0, "w_r {w_r}");
        assert!(e.holdout_rmse_after_a.unwrap() < e.holdout_rmse_before_a.unwrap());
        assert!(e.effects[0].description.contains("c * exp"));
        // The written model carries the definition and the fitted values, and explains the
        // same data.
        let text = out.augmented_rig().to_toml().unwrap();
        assert!(
            text.contains("[[model.terms]]") && text.contains("frame-resonance"),
            "{text}"
        );
        let back = RigFile::parse(&text, "augmented.toml").unwrap();
        let again = explain::explain(&d, &back, &Options::default())
            .unwrap()
            .explanation;
        assert_eq!(again.verdict, Verdict::NoMissingEffect, "{}", again.finding);
        assert_eq!(again.known_effects, ["frame-resonance"]);
        assert!((again.rmse_before_a - e.rmse_after_a).abs() < 1e-4);
    }
}

#[test]
fn a_user_effect_makes_no_finding_in_effect_free_data() {
    let rig = RigFile::parse(RESONANCE, "rig.toml").unwrap();
    for seed in 0..8u64 {
        let d = data(0.0, [0.005, 0.01, 0.02, 0.04][seed as usize % 4], 50 + seed);
        let e = explain::explain(&d, &rig, &Options::default())
            .unwrap()
            .explanation;
        assert_eq!(
            e.verdict,
            Verdict::NoMissingEffect,
            "seed {seed}: {}",
            e.finding
        );
        assert!(e.candidates.iter().any(|c| c.name == "frame-resonance"));
    }
}

#[test]
fn bad_user_effects_are_refused_naming_the_fix() {
    let d = data(0.0, 0.02, 1);
    // An unknown name: the rig file itself is refused when read (its expression compiles
    // there), naming the effect and the name.
    let unknown = RESONANCE.replace("(w - w_r)", "(speed - w_r)");
    let e = RigFile::parse(&unknown, "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("'speed'") && e.contains("frame-resonance"),
        "{e}"
    );
    // An effect that does not vanish at its null is refused: the model without it must be
    // nested in the model with it.
    let offset = RESONANCE.replace("c * exp", "0.1 + c * exp");
    let rig = RigFile::parse(&offset, "rig.toml").unwrap();
    let e = explain::explain(&d, &rig, &Options::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("vanish") && e.contains("null"), "{e}");
}
