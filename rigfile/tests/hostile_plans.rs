//! Hostile plan files (issue 33): extreme floats and integers in every number a plan
//! gives. Nothing panics; a plan is refused naming the key, or accepted with every value in
//! its stated range, so the runs it makes are few enough to list and every duration
//! converts to a `Duration`.

use std::time::Duration;

use proptest::prelude::*;
use rigfile::plan::{MAX_REPEATS, MAX_RUNS, MAX_SECONDS, Plan};

/// Floats as a careless or hostile user types them.
fn extreme_float() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("1e300".to_string()),
        Just("-1e300".to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("0.0".to_string()),
        Just("-0.0".to_string()),
        Just("5e-324".to_string()),
        Just("1.8e19".to_string()),
        Just("3600.0".to_string()),
        Just("3600.0000001".to_string()),
        (-1e6f64..1e6).prop_map(|x| format!("{x:?}")),
        any::<f64>().prop_map(|x| format!("{x:?}")),
    ]
}

/// Integers as a careless or hostile user types them (some out of `u32`'s range).
fn extreme_int() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("0".to_string()),
        Just("-1".to_string()),
        Just("100000000".to_string()),
        Just("4294967295".to_string()),
        Just("4294967296".to_string()),
        Just("9223372036854775807".to_string()),
        Just("1000".to_string()),
        Just("1001".to_string()),
        (0u32..2000).prop_map(|x| x.to_string()),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn extreme_numbers_are_refused_by_range_or_run_safely(
        repeats in extreme_int(),
        point_repeats in extreme_int(),
        rest in extreme_float(),
        window in extreme_float(),
        duration in extreme_float(),
        load in extreme_float(),
        volts in extreme_float(),
        temp in extreme_float(),
        points in 1usize..4,
    ) {
        let mut text = format!(
            "mode = \"open-loop\"\nrepeats = {repeats}\nrest_s = {rest}\nwindow_s = {window}\n"
        );
        for _ in 0..points {
            text += &format!(
                "[[points]]\nload_nm = {load}\nvolts = {volts}\nrepeats = {point_repeats}\nduration_s = {duration}\ntemp_c = {temp}\n"
            );
        }
        match Plan::parse(&text, "hostile.toml") {
            Err(e) => {
                let msg = e.to_string();
                prop_assert!(msg.contains("hostile.toml"), "{msg}");
            }
            Ok(plan) => {
                prop_assert!((1..=MAX_REPEATS).contains(&plan.repeats));
                prop_assert!((0.0..=MAX_SECONDS).contains(&plan.rest_s));
                prop_assert!(plan.window_s > 0.0 && plan.window_s <= MAX_SECONDS);
                let runs = plan.runs();
                prop_assert!(runs.len() as u64 <= MAX_RUNS);
                for r in runs {
                    let d = r.duration_s.unwrap_or(plan.window_s);
                    prop_assert!(Duration::try_from_secs_f64(d).is_ok());
                    prop_assert!(r.load_nm.is_finite() && r.load_nm >= 0.0);
                }
                prop_assert!(Duration::try_from_secs_f64(plan.rest_s).is_ok());
            }
        }
    }
}

#[test]
fn the_quoted_cases_are_refused_naming_the_key() {
    let base = "[[points]]\nload_nm = 0.1\nvolts = 3.6\n";
    for (text, key) in [
        (format!("rest_s = 1e300\n{base}"), "rest_s"),
        (
            format!("{base}duration_s = 1e300\n"),
            "points[1].duration_s",
        ),
        (format!("repeats = 100000000\n{base}"), "repeats"),
        (format!("{base}repeats = 100000000\n"), "points[1].repeats"),
    ] {
        let e = Plan::parse(&text, "p.toml").unwrap_err().to_string();
        assert!(e.contains(&format!("plan p.toml: {key}")), "{e}");
    }
    // 1000 repeats of 101 points: more runs than a plan may make.
    let many = "repeats = 1000\n".to_string() + &base.repeat(101);
    let e = Plan::parse(&many, "p.toml").unwrap_err().to_string();
    assert!(e.contains("101000 runs"), "{e}");
}
