//! A setting outside its range is refused by the CLI with the library's own reason (the one
//! check per setting that Python's door calls too): `rig explain`'s alpha, folds,
//! replicates and stated noise, `rig experiment hold-release`'s load and seconds, and
//! `rig discover`'s budget and replicates. Each is refused before anything runs.

use std::time::Duration;

use assert_cmd::Command;
use explain::Options;
use host::discover::DiscoverySetup;
use host::experiment::hold_release::{HoldRelease, SettingNames};

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(60));
    c
}

/// Runs `args`, requires failure, and returns stderr.
fn fails(args: &[&str]) -> String {
    let out = rig().args(args).assert().failure().get_output().clone();
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!text.contains("panicked"), "panic:\n{text}");
    text
}

/// The CLI's message for `flag value` names the flag and gives the library's reason.
fn refuses(args: &[&str], flag: &str, value: &str, why: String) {
    let text = fails(args);
    for want in [format!("'{flag}"), format!("{value}: {why}")] {
        assert!(text.contains(&want), "expected {want:?} in:\n{text}");
    }
}

#[test]
fn explain_settings_are_refused_with_the_librarys_reasons() {
    let measured = ["explain", "--measured", "no-such.csv", "--json"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        measured
            .iter()
            .copied()
            .chain(extra.iter().copied())
            .collect()
    };
    refuses(
        &with(&["--alpha", "0.7"]),
        "--alpha",
        "0.7",
        Options::check_alpha(0.7).unwrap_err(),
    );
    refuses(
        &with(&["--folds", "30"]),
        "--folds",
        "30",
        Options::check_folds(30).unwrap_err(),
    );
    refuses(
        &with(&["--replicates", "20000"]),
        "--replicates",
        "20000",
        Options::check_replicates(20_000).unwrap_err(),
    );
    refuses(
        &with(&["--stated-noise-ma=-2"]),
        "--stated-noise-ma",
        "-2",
        Options::check_stated_noise_ma(-2.0).unwrap_err(),
    );
    // Not a count at all: said so.
    let text = fails(&with(&["--folds", "many"]));
    assert!(text.contains("'many' is not a whole number"), "{text}");
    // The bounds themselves are accepted (the run then fails on the missing file, not
    // on the setting).
    let text = fails(&with(&[
        "--folds",
        "20",
        "--replicates",
        "0",
        "--alpha",
        "0.49",
    ]));
    assert!(text.contains("no-such.csv"), "{text}");
}

#[test]
fn hold_release_settings_are_refused_before_the_rig_is_touched() {
    let base = ["--sim", "experiment", "hold-release", "--csv", "never.csv"];
    let with = |extra: &[&'static str]| -> Vec<&'static str> {
        base.iter().copied().chain(extra.iter().copied()).collect()
    };
    refuses(
        &with(&["--load", "9"]),
        "--load",
        "9",
        HoldRelease::check_load_nm(9.0).unwrap_err(),
    );
    refuses(
        &with(&["--hold=-1"]),
        "--hold",
        "-1",
        HoldRelease::check_hold_s(-1.0).unwrap_err(),
    );
    refuses(
        &with(&["--release", "0"]),
        "--release",
        "0",
        HoldRelease::check_release_s(0.0).unwrap_err(),
    );
    refuses(
        &with(&["--after=-0.5"]),
        "--after",
        "-0.5",
        HoldRelease::check_after_s(-0.5).unwrap_err(),
    );
    assert!(!std::path::Path::new("never.csv").exists());
}

#[test]
fn hold_release_checks_name_each_setting_as_its_caller_spells_it() {
    let cal = protocol::RigParameters::paper();
    let ok = HoldRelease::default();
    assert_eq!(
        ok.checked(SettingNames::PYTHON, &cal).unwrap().hz,
        ok.hz,
        "a frequency the device drives is kept as given"
    );
    let e = HoldRelease {
        load_nm: Some(9.0),
        ..ok
    }
    .checked(SettingNames::PYTHON, &cal)
    .unwrap_err()
    .to_string();
    assert!(
        e.starts_with("load_nm 9: outside 0 to 3.68 N m (the gear's tooth strength"),
        "{e}"
    );
    let e = HoldRelease {
        release_s: -1.0,
        ..ok
    }
    .checked(SettingNames::CLI, &cal)
    .unwrap_err()
    .to_string();
    assert_eq!(e, "--release -1: give a positive number of seconds");
    let e = HoldRelease { hz: 30.0, ..ok }
        .checked(SettingNames::PYTHON, &cal)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("freq_hz 30: the device drives"), "{e}");
    // No load to hang (the one on the rig): nothing to check there.
    assert!(
        HoldRelease {
            load_nm: None,
            ..ok
        }
        .checked(SettingNames::CLI, &cal)
        .is_ok()
    );
}

#[test]
fn discover_settings_are_refused_with_the_librarys_reasons() {
    refuses(
        &["discover", "--csv", "never.csv", "--max-points", "5"],
        "--max-points",
        "5",
        DiscoverySetup::check_max_points(5).unwrap_err(),
    );
    refuses(
        &["discover", "--csv", "never.csv", "--replicates", "10"],
        "--replicates",
        "10",
        DiscoverySetup::check_replicates(10).unwrap_err(),
    );
    assert_eq!(DiscoverySetup::check_max_points(12), Ok(12));
    assert_eq!(DiscoverySetup::check_replicates(10_000), Ok(10_000));
    assert!(DiscoverySetup::check_max_points(10_001).is_err());
    assert!(!std::path::Path::new("never.csv").exists());
}
