//! `rig discover` through the real binary: the closed loop names a hidden effect within 60
//! test points (the paper's sweep has 150) on the in-process virtual rig (`--sim`) and on a
//! served one (`rig sim serve`), gives no finding when none is hidden, appends every round to
//! one CSV, and Ctrl-C locks the gear.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use assert_cmd::Command;
use serde_json::Value;

mod support {
    pub mod child;
    pub mod cli;
    pub mod served;
}
use support::cli::{data_rows, json_of as json};

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(900));
    c
}

/// The points the loop used, within the 60-point budget, each a row of `csv`; the CSV's text.
fn within_budget(v: &Value, csv: &Path) -> (u64, String) {
    let used = v["points_used"].as_u64().unwrap();
    assert!(used <= 60, "{used} test points");
    assert_eq!(data_rows(csv).len() as u64, used);
    (used, std::fs::read_to_string(csv).unwrap())
}

/// The loop's JSON names `effect` first within the 60-point budget.
fn assert_named(v: &Value, effect: &str, csv: &Path) {
    assert_eq!(v["verdict"], "explained", "{}", v["rounds"]);
    assert_eq!(v["effects"][0]["name"], effect, "{}", v["rounds"]);
    let (used, text) = within_budget(v, csv);
    let rounds = v["rounds"].as_array().unwrap();
    assert_eq!(rounds[0]["points"], 30, "the initial quick sweep");
    assert_eq!(rounds[0]["plan"], "initial");
    let total: u64 = rounds.iter().map(|r| r["points"].as_u64().unwrap()).sum();
    assert_eq!(total, used);
    assert_eq!(rounds.last().unwrap()["points_used"], used);
    // The loop's keys beside explain's, and each round's, pinned: readers depend on them.
    for key in ["points_used", "max_points", "settled", "csv", "rounds"] {
        assert!(v.get(key).is_some(), "{key}");
    }
    let mut round_keys: Vec<&str> = rounds[0]
        .as_object()
        .unwrap()
        .keys()
        .map(String::as_str)
        .collect();
    round_keys.sort_unstable();
    assert_eq!(
        round_keys,
        [
            "confidence",
            "leading_effect",
            "plan",
            "points",
            "points_used",
            "round",
            "verdict"
        ]
    );
    // explain's keys are there too.
    for key in [
        "confidence",
        "outliers",
        "inclusion_probabilities",
        "rmse_after_a",
    ] {
        assert!(v.get(key).is_some(), "{key}");
    }
    assert!(
        text.starts_with("# rig experiment torque-sweep"),
        "provenance first"
    );
}

#[test]
fn discover_names_a_hidden_effect_on_the_in_process_virtual_rig() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("loop.csv");
    let v = json(
        rig()
            .args([
                "--sim",
                "discover",
                "--preset",
                "ideal",
                "--effect",
                "speed-dependent-axial-friction",
                "--json",
                "--no-report",
                "--replicates",
                "50",
                "--csv",
            ])
            .arg(&csv),
    );
    assert_named(&v, "speed-dependent-axial-friction", &csv);
}

/// Seed 004's tooth compliance runs in the plant as physics of the teeth (the friction force
/// slides over the stroke its deflection leaves): the loop names it.
#[test]
fn discover_names_the_seeds_tooth_compliance_hidden_in_the_plant() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("loop.csv");
    let v = json(
        rig()
            .args([
                "--sim",
                "discover",
                "--preset",
                "ideal",
                "--effect",
                "tooth-compliance",
                "--json",
                "--no-report",
                "--replicates",
                "50",
                "--csv",
            ])
            .arg(&csv),
    );
    assert_named(&v, "tooth-compliance", &csv);
}

/// The loop's JSON gives no finding: `no-missing-effect`, no effect named, every round
/// without one, within the budget.
fn assert_no_finding(v: &Value, csv: &Path) {
    assert_eq!(v["verdict"], "no-missing-effect", "{}", v["rounds"]);
    assert_eq!(
        v["effects"].as_array().map(Vec::len),
        Some(0),
        "{}",
        v["effects"]
    );
    let (_, text) = within_budget(v, csv);
    assert!(
        text.contains("# window: whole cam revolutions"),
        "every run averages over whole cam revolutions"
    );
}

/// Issue 14 items 4-5: without a hidden effect the loop's proposals (light-load speed
/// sweeps, repeats at a few points) used to turn the model's milliampere lack of fit into a
/// finding (mesh-load-sharing-ripple, load-dependent-friction, vibrator-viscous-loss) on
/// these seeds; it ends `no-missing-effect`.
#[test]
fn discover_gives_no_finding_on_an_effect_free_virtual_rig() {
    for seed in ["1", "3"] {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("none.csv");
        let v = json(
            rig()
                .args([
                    "--sim",
                    "discover",
                    "--preset",
                    "ideal",
                    "--seed",
                    seed,
                    "--json",
                    "--no-report",
                    "--replicates",
                    "50",
                    "--csv",
                ])
                .arg(&csv),
        );
        assert_no_finding(&v, &csv);
    }
}

use support::served::Server;

#[test]
fn discover_names_a_hidden_effect_on_a_served_virtual_rig() {
    // A served rig keeps board time: at the board's own pace a client has the board's
    // 0.5 s comms timeout of wall time between heartbeats, as at a real rig. At 4x (125 ms)
    // a client starved by a busy machine can lose its release; at 20x it had 25 ms.
    let server = Server::start_at(
        "1",
        &[
            "--preset",
            "ideal",
            "--effect",
            "speed-dependent-axial-friction",
        ],
    );
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("served.csv");
    let report = dir.path().join("report");
    let v = json(
        rig()
            .args([
                "--port",
                &server.port,
                "discover",
                "--json",
                "--replicates",
                "50",
                "--report",
            ])
            .arg(&report)
            .arg("--csv")
            .arg(&csv),
    );
    assert_named(&v, "speed-dependent-axial-friction", &csv);
    assert!(report.join("report.md").exists());
}

#[test]
fn discover_refuses_plant_options_without_sim() {
    let out = rig()
        .args([
            "discover",
            "--port",
            "/dev/null-no-such",
            "--effect",
            "thermal-drift",
            "--csv",
            "x.csv",
        ])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let err = String::from_utf8_lossy(&out);
    assert!(err.contains("--sim"), "{err}");
}

#[test]
fn ctrl_c_locks_the_gear_and_keeps_completed_rounds() {
    // A served rig in real time: the first round takes about a minute, so the signal lands
    // mid-run, and the lock goes over the line as on a real rig.
    let server = Server::start_at("1", &["--preset", "ideal"]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("stopped.csv");
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut child = std::process::Command::new(bin)
        .args(["--port", &server.port, "discover", "--no-report", "--csv"])
        .arg(&csv)
        .env_remove("RIG_PORT")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Mid-round, on the child's own progress: its first round began.
    let err = support::child::Output::read(child.stderr.take().unwrap());
    err.wait_for("round 1:", 1, "the first round");
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "discover did not stop"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let err = err.all();
    assert_eq!(status.code(), Some(130), "{err}");
    assert!(err.contains("the gear is locked"), "{err}");
}

/// The served rig without a hidden effect, seeds 1-8 (slow: 264 s for the eight in a debug
/// build on two shared cores, the rig keeping its 5x throughout).
///
/// Served at 5x, the speed the other served tests use: a served rig keeps the board's time
/// whatever the client does, so each request costs the client's round trip through the
/// pseudo-terminal (a millisecond or two of wall time) times the speed in device time; at
/// 50x that was 50-100 ms of the rig's time per request and 10 ms of wall time to the comms
/// timeout, a board no procedure meets. Each seed also checks that the rig kept its speed.
#[test]
#[ignore = "slow batch: 8 served discover loops of 60 test points"]
fn discover_gives_no_finding_on_an_effect_free_served_rig_batch() {
    const SPEED: f64 = 5.0;
    for seed in 1..=8 {
        let seed = seed.to_string();
        let server = Server::start_at(&SPEED.to_string(), &["--preset", "ideal", "--seed", &seed]);
        let started = Instant::now();
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("none.csv");
        let v = json(
            rig()
                .args([
                    "--port",
                    &server.port,
                    "discover",
                    "--seed",
                    &seed,
                    "--json",
                    "--no-report",
                    "--replicates",
                    "50",
                    "--csv",
                ])
                .arg(&csv),
        );
        assert_no_finding(&v, &csv);
        // The rig's own clock against the wall's: it ran at the speed it said.
        let info = json(rig().args(["--port", &server.port, "info", "--json"]));
        assert_eq!(info["time_scale"], SPEED, "{info}");
        let uptime = info["uptime_s"].as_f64().expect("uptime");
        let achieved = uptime / started.elapsed().as_secs_f64();
        assert!(
            achieved >= 0.9 * SPEED,
            "seed {seed}: the served rig ran at {achieved:.1}x, not {SPEED}x: this machine cannot keep it"
        );
    }
}

/// Issue 22: `discover` takes the same virtual rig as every other verb when no preset is
/// given (`paper`), and says why a hidden current-sensor offset cannot show in its rows.
#[test]
fn discover_defaults_to_the_preset_of_every_other_verb_and_explains_an_unseen_offset() {
    let help = |args: &[&str]| {
        let out = rig()
            .args(args)
            .assert()
            .success()
            .get_output()
            .stdout
            .clone();
        String::from_utf8_lossy(&out).into_owned()
    };
    let discover = help(&["discover", "--help"]);
    let serve = help(&["sim", "serve", "--help"]);
    assert!(discover.contains("[default: paper]"), "{discover}");
    assert!(serve.contains("[default: paper]"), "{serve}");
    let note = host::cli::discover::unseen_effect_note("current-sensor-offset:offset_a=0.05")
        .expect("the offset is named");
    assert!(note.contains("zeroes"), "{note}");
    assert!(host::cli::discover::unseen_effect_note("thermal-drift").is_none());
}
