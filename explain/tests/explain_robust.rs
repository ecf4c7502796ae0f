//! Robustness and confidence of `rig explain`: a corrupt row never makes a finding and is
//! reported with its row and line; rows out of the rig's range are set aside; absurd rig and
//! data values are warned about or refused with the fix; every named effect carries a
//! bootstrap inclusion probability, the explanation a confidence, and data that cannot
//! separate two candidates gives `ambiguous` with both and their probabilities.

use explain::synth::{self, SweepPlan};
use explain::{self, Dataset, Explanation, MeasuredRow, Options, Verdict};
use model::effects::Effect;
use model::plant::NoiseSource;
use rigfile::RigFile;

/// 75 good rows: five loads, three voltages, five repeats, in random order over a session.
fn plan_75(noise_a: f64) -> SweepPlan {
    SweepPlan {
        loads_nm: (1..=5).map(|k| 0.736 * k as f64).collect(),
        noise_a,
        ..SweepPlan::default()
    }
}

fn rows(rig: &RigFile, hidden: Option<Effect>, plan: &SweepPlan, seed: u64) -> Vec<MeasuredRow> {
    let mut truth = rig.current_model().unwrap();
    let mut rng = NoiseSource::new(seed ^ 0x0b5e_55ed);
    if let Some(e) = hidden {
        truth.effects = synth::plausible_effect(e, &truth, plan, &mut rng);
    }
    synth::generate(&truth, plan, seed)
}

fn run(rows: Vec<MeasuredRow>) -> Explanation {
    let data = Dataset::from_rows("measured.csv", rows).unwrap();
    explain::explain(&data, &RigFile::paper(), &Options::default())
        .unwrap()
        .explanation
}

#[test]
fn a_corrupt_row_in_effect_free_data_is_reported_not_explained() {
    // The case: i_in_a = 100 A among 75 good rows gave a confident "explained".
    for seed in 1..=4 {
        let mut r = rows(&RigFile::paper(), None, &plan_75(0.02), seed);
        let k = 17 + seed as usize;
        r.insert(
            k,
            MeasuredRow {
                i_in: Some(100.0),
                ..r[k]
            },
        );
        let e = run(r);
        assert_eq!(
            e.verdict,
            Verdict::NoMissingEffect,
            "seed {seed}: {}",
            e.finding
        );
        assert_eq!(e.outliers.len(), 1, "{:?}", e.outliers);
        let o = &e.outliers[0];
        assert_eq!((o.row, o.line), (k + 1, k as u64 + 2));
        assert_eq!(o.column, "i_in_a");
        assert!(o.reason.contains("current sensor's range"), "{}", o.reason);
        assert_eq!(e.rows, 75);
        assert!(e.finding.contains("set aside as outlier"), "{}", e.finding);
    }
}

#[test]
fn corrupt_rows_within_the_sensor_range_never_make_a_finding() {
    // One row off by 3 to 40 noise standard deviations, anywhere, at 5-40 mA of noise.
    let mut findings = Vec::new();
    let mut flagged = 0;
    let mut cases = 0;
    for seed in 1..=24u64 {
        let noise = [0.005, 0.01, 0.02, 0.04][seed as usize % 4];
        let mut r = rows(&RigFile::paper(), None, &plan_75(noise), 100 + seed);
        let k = (seed as usize * 7) % r.len();
        let z = [3.0, 4.5, 6.0, 10.0, 20.0, 40.0][seed as usize % 6];
        let sign = if seed % 2 == 0 { 1.0 } else { -1.0 };
        r[k].i_in = r[k].i_in.map(|i| i + sign * z * noise);
        let e = run(r);
        cases += 1;
        if e.verdict != Verdict::NoMissingEffect {
            findings.push(format!("seed {seed} z {z}: {}", e.finding));
        }
        if z >= 10.0 {
            assert!(
                e.outliers.iter().any(|o| o.row == k + 1),
                "seed {seed}: {z} sd off not flagged: {:?}",
                e.outliers
            );
            flagged += 1;
        }
    }
    assert!(findings.is_empty(), "{cases} cases: {findings:#?}");
    assert!(flagged > 0);
}

#[test]
fn an_effect_is_still_named_beside_a_corrupt_row() {
    let plan = SweepPlan::default();
    for (k, effect) in [
        Effect::SpeedDependentAxialFriction,
        Effect::ThermalDrift,
        Effect::VibratorViscousLoss,
    ]
    .into_iter()
    .enumerate()
    {
        let mut r = rows(&RigFile::paper(), Some(effect), &plan, 40 + k as u64);
        r[60].i_in = Some(4.9);
        let e = run(r);
        assert_eq!(e.verdict, Verdict::Explained, "{}", e.finding);
        assert_eq!(e.effects[0].name, effect.name());
        assert!(e.outliers.iter().any(|o| o.row == 61), "{:?}", e.outliers);
    }
}

#[test]
fn out_of_range_rows_are_set_aside_and_whole_columns_refused() {
    let mut r = rows(&RigFile::paper(), None, &SweepPlan::default(), 7);
    r[3].omega_n = 2000.0; // rpm, not rad/s
    r[9].temp_c = Some(320.0); // K, not C
    r[12].tau_rot = -r[12].tau_rot;
    let e = run(r.clone());
    assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
    let rows_out: Vec<usize> = e.outliers.iter().map(|o| o.row).collect();
    assert_eq!(rows_out, [4, 10]);
    assert!(e.outliers[0].reason.contains("no-load cam speed"));
    assert!(e.outliers[1].reason.contains("-40..150 C"));
    assert!(
        e.warnings
            .iter()
            .any(|w| w.contains("negative") && w.contains("row 13")),
        "{:?}",
        e.warnings
    );
    // Every temperature in kelvin: the column is wrong, say so.
    for row in &mut r {
        row.temp_c = row.temp_c.map(|c| c + 273.15);
    }
    let data = Dataset::from_rows("measured.csv", r).unwrap();
    let err = explain::explain(&data, &RigFile::paper(), &Options::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("temp_c") && err.contains("not K"), "{err}");
}

#[test]
fn absurd_rig_values_are_warned_about_or_refused() {
    let data = Dataset::from_rows(
        "measured.csv",
        rows(&RigFile::paper(), None, &SweepPlan::default(), 8),
    )
    .unwrap();
    let odd = RigFile::parse("[calibration]\nc1 = 300.0\n", "rig.toml").unwrap();
    let e = explain::explain(&data, &odd, &Options::default()).unwrap();
    assert!(
        e.explanation
            .warnings
            .iter()
            .any(|w| w.contains("c1") && w.contains("plausible range")),
        "{:?}",
        e.explanation.warnings
    );
    // A wrong-sign constant is refused where the rig file is read, naming the field (the
    // rig file applies the same sign rules as the firmware's check).
    let err = RigFile::parse("[calibration]\nc6 = -2.25\n", "rig.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("c6") && err.contains("must be zero or positive"),
        "{err}"
    );
}

#[test]
fn named_effects_carry_inclusion_probabilities_and_a_confidence() {
    let plan = SweepPlan::default();
    for (k, effect) in [
        Effect::SpeedDependentAxialFriction,
        Effect::CurrentSensorOffset,
        Effect::InertiaRectification,
    ]
    .into_iter()
    .enumerate()
    {
        let e = run(rows(&RigFile::paper(), Some(effect), &plan, 70 + k as u64));
        assert_eq!(e.verdict, Verdict::Explained, "{}", e.finding);
        // Nearly every replicate selects it; its inclusion probability is the finding's
        // confidence plus, for a finding not right, that share calibrated with its driver
        // check and the lack of fit: never below the confidence.
        let f = &e.effects[0];
        let raw = f.inclusion_probability_raw.unwrap();
        assert!(raw >= 0.9, "{}: inclusion share {raw}", effect.name());
        let p = f.inclusion_probability.unwrap();
        let ev = f.evidence(e.lack_of_fit.p_value).unwrap();
        assert_eq!(ev.share, raw);
        let c = e.confidence.unwrap();
        assert_eq!(
            p,
            explain::calibration::coherent_inclusion(
                c,
                explain::calibration::calibrated_inclusion(&ev)
            )
        );
        assert!(
            p >= c,
            "{}: inclusion {p} below confidence {c}",
            effect.name()
        );
        // More likely in than not where the final model fits; a near-significant final lack
        // of fit (p < 0.01) is where wrong names sit in the calibration's batch.
        let floor = if e.lack_of_fit.p_value < 0.01 {
            0.2
        } else {
            0.5
        };
        assert!(p > floor, "{}: inclusion {p} from {ev:?}", effect.name());
        // Most replicates reach the same set; the stated confidence is that share, calibrated.
        let share = e.confidence_raw.unwrap();
        assert!(share >= 0.5, "{}", e.finding);
        let evidence = e.evidence().unwrap();
        assert_eq!(evidence.share, share);
        assert_eq!(
            e.confidence,
            Some(explain::calibration::calibrated(&evidence))
        );
        assert!(e.effects[0].bic_weight > 0.9);
        assert_eq!(e.inclusion_probabilities[effect.name()], p);
        assert!(
            e.model_weights
                .iter()
                .any(|m| m.effects == [effect.name()] && m.weight > 0.0),
            "{:?}",
            e.model_weights
        );
        let b = e.bootstrap.as_ref().unwrap();
        assert_eq!((b.replicates, b.blocks), (200, 30));
    }
    // Effect-free data: most replicates find nothing either.
    let e = run(rows(&RigFile::paper(), None, &plan, 80));
    assert_eq!(e.verdict, Verdict::NoMissingEffect);
    assert!(e.confidence.unwrap() >= 0.5, "{}", e.finding);
    assert!(e.inclusion_probabilities.values().all(|&p| p < 0.5));
    // The same data gives the same numbers (fixed seeds).
    let again = run(rows(&RigFile::paper(), None, &plan, 80));
    assert_eq!(again.confidence, e.confidence);
}

#[test]
fn data_that_cannot_separate_two_candidates_is_ambiguous() {
    // A falling load-dependent friction and a tooth compliance both bend the friction term
    // down at high load; at the paper's loads and 30 mA of noise a blend of the two fits
    // either. The verdict names both with their probabilities instead of one confidently.
    let rig = RigFile::paper();
    let plan = SweepPlan {
        noise_a: 0.03,
        ..SweepPlan::default()
    };
    let mut ambiguous = 0;
    let mut confident_wrong = 0;
    for seed in 1..=8u64 {
        let mut truth = rig.current_model().unwrap();
        truth.effects.load_exponent = -0.06;
        let tau_max = 3.68;
        let f_max = truth.drive.friction_force(truth.mu, tau_max);
        truth.effects.tooth_compliance = 0.03 * truth.drive.eccentricity / f_max;
        let e = run(synth::generate(&truth, &plan, 300 + seed));
        match e.verdict {
            Verdict::Ambiguous => {
                ambiguous += 1;
                assert!(e.ambiguous_candidates.len() >= 2);
                assert!(e.ambiguous_candidates.iter().all(|c| c.probability > 0.0));
                assert_eq!(e.ambiguous[0], e.effects[0].name);
                assert!(e.finding.contains("cannot tell"), "{}", e.finding);
            }
            // A blend has no single right name: a confident one is what must be rare.
            Verdict::Explained if e.effects[0].inclusion_probability.unwrap() >= 0.8 => {
                confident_wrong += 1;
            }
            Verdict::Explained
            | Verdict::NoMissingEffect
            | Verdict::PartlyExplained
            | Verdict::Unexplained => {}
        }
    }
    assert!(ambiguous >= 3, "ambiguous {ambiguous} of 8");
    assert!(
        confident_wrong <= 2,
        "{confident_wrong} confident single names"
    );
}
