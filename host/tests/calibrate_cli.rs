//! `rig calibrate` from the operator's side, on the virtual rig with `--operator` and
//! scripted stdin: set-up prompts, a reading redone (`r`), force-and-arm readings, points
//! written as they are taken and kept on Ctrl-C, `--from-points` refits, and a fit that is
//! implausible for the motor is not written without `--force`.

use std::io::Write;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use assert_cmd::Command;
use serde_json::Value;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

/// `rig --sim --speed 20 calibrate --operator --out DIR ...`.
fn operator(dir: &Path, extra: &[&str]) -> Command {
    let mut c = rig();
    c.args(["--sim", "--speed", "20", "calibrate", "--operator", "--out"])
        .arg(dir)
        .args(extra);
    c
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The torque rows of a points.csv: their gauge readings, N mm.
fn torque_readings(path: &Path) -> Vec<f64> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| l.starts_with("torque,"))
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect()
}

/// Readings that rise with the current as a gauge's would (C1 about 44 N mm/A: plausible).
const GOOD: &str = "10\n20\n30\n40\n50\n60\n70\n80\n90\n";

#[test]
fn operator_prompts_redo_and_force_at_arm_readings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    // Two set-up prompts (Enter), step 1, step 2 redone, step 3 as a force on an arm.
    let input = "\n\n10\nr\n20\n3 N @ 0.01 m\n40\n50\n60\n70\n80\n90\n";
    let got = operator(&out, &["--yes", "--json"])
        .write_stdin(input)
        .assert()
        .success()
        .get_output()
        .clone();
    let err = text(&got.stderr);
    assert!(err.contains("uncouple the cam") && err.contains("Press Enter when ready"));
    assert!(err.contains("r: redo the step"), "{err}");
    assert_eq!(err.matches("step 2: ").count(), 2, "step 2 redone: {err}");
    let v: Value = serde_json::from_slice(&got.stdout).unwrap();
    assert_eq!(v["written_to_device"], true, "{v}");
    let readings = torque_readings(&out.join("points.csv"));
    assert_eq!(
        readings,
        [10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0]
    );
    assert!(out.join("calibration.toml").exists());
}

#[test]
fn force_gauge_on_an_arm() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let got = operator(
        &out,
        &["--gauge", "force", "--arm-m", "0.01", "--dry-run", "--json"],
    )
    .write_stdin("\n\n1\n2\n3\n4\n5\n6\n7\n8\n9\n")
    .assert()
    .success()
    .get_output()
    .clone();
    assert!(text(&got.stderr).contains("Gauge force (N, on the 0.01 m arm"));
    let v: Value = serde_json::from_slice(&got.stdout).unwrap();
    let torque = v["measurements"]["torque"].as_array().unwrap();
    for (k, p) in torque.iter().enumerate() {
        let want = 10.0 * (k + 1) as f64;
        assert!(
            (p["gauge_nmm"].as_f64().unwrap() - want).abs() < 1e-9,
            "{p}"
        );
    }
    // A dry run writes nothing.
    assert!(!out.exists());
    // --arm-m belongs to a force gauge.
    let e = rig()
        .args(["--sim", "calibrate", "--arm-m", "0.01"])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    assert!(text(&e).contains("--gauge force"), "{}", text(&e));
}

#[test]
fn a_reading_that_is_not_a_number_is_asked_again() {
    let dir = tempfile::tempdir().unwrap();
    let got = operator(&dir.path().join("cal"), &["--dry-run"])
        .write_stdin(format!("\n\nabc\n12 N\n{GOOD}"))
        .assert()
        .success()
        .get_output()
        .clone();
    let err = text(&got.stderr);
    assert!(err.contains("'abc' is not a number"), "{err}");
    assert!(err.contains("'12 N' is a force without its arm"), "{err}");
}

#[test]
fn an_implausible_fit_is_not_written_without_force_and_refits_from_points() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let got = operator(&out, &["--yes"])
        .write_stdin("\n\n1000\n2000\n3000\n4000\n5000\n6000\n7000\n8000\n9000\n")
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = text(&got.stderr);
    assert!(
        err.contains("c1 = ") && err.contains("plausible range") && err.contains("--force"),
        "{err}"
    );
    assert!(err.contains("model::Calibration::check"), "{err}");
    assert!(!out.join("calibration.toml").exists());
    let points = out.join("points.csv");
    assert_eq!(torque_readings(&points).len(), 9, "the points are kept");

    // --force writes the rig file (never the device: its firmware refuses the fit).
    let v: Value = serde_json::from_slice(
        &rig()
            .args([
                "--sim",
                "calibrate",
                "--yes",
                "--json",
                "--force",
                "--from-points",
            ])
            .arg(&points)
            .arg("--out")
            .arg(&out)
            .args(["--format", "png"])
            .assert()
            .success()
            .get_output()
            .stdout,
    )
    .unwrap();
    assert_eq!(v["written_to_device"], false, "{v}");
    assert!(out.join("calibration.toml").exists());
    // The fit plots also as PNG (`--format`), the SVGs kept.
    let figures = v["files"]["figures"].as_array().unwrap();
    assert_eq!(figures.len(), 2, "{v}");
    for f in figures {
        let png = std::fs::read(f.as_str().unwrap()).unwrap();
        assert!(png.starts_with(b"\x89PNG"), "{f}");
    }
    assert!(out.join("torque_current.svg").exists() && out.join("no_load.svg").exists());

    // A dry run refits offline, without a device.
    let good = dir.path().join("good.csv");
    let body = std::fs::read_to_string(&points).unwrap();
    let mut k = 0;
    let lines: Vec<String> = body
        .lines()
        .map(|l| {
            if let Some(rest) = l.strip_prefix("torque,") {
                k += 1;
                let head = rest.rsplit_once(',').unwrap().0;
                format!("torque,{head},{}", 10 * k)
            } else {
                l.to_string()
            }
        })
        .collect();
    std::fs::write(&good, lines.join("\n") + "\n").unwrap();
    let v: Value = serde_json::from_slice(
        &rig()
            .args(["calibrate", "--dry-run", "--json", "--from-points"])
            .arg(&good)
            .assert()
            .success()
            .get_output()
            .stdout,
    )
    .unwrap();
    let c1 = v["c1"].as_f64().unwrap();
    assert!((40.0..50.0).contains(&c1), "{v}");
    let e = rig()
        .args(["calibrate", "--dry-run", "--from-points"])
        .arg(dir.path().join("missing.csv"))
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    assert!(text(&e).contains("missing.csv"), "{}", text(&e));
}

#[test]
fn stdin_ending_keeps_the_points_taken() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let got = operator(&out, &["--yes"])
        .write_stdin("\n\n10\n20\n")
        .assert()
        .failure()
        .get_output()
        .clone();
    let err = text(&got.stderr);
    assert!(err.contains("standard input ended"), "{err}");
    assert_eq!(torque_readings(&out.join("points.csv")), [10.0, 20.0]);
    assert!(!out.join("calibration.toml").exists());
}

#[test]
fn ctrl_c_locks_and_keeps_the_points_written_as_taken() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cal");
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut child = std::process::Command::new(bin)
        .args([
            "--sim",
            "--speed",
            "20",
            "calibrate",
            "--operator",
            "--yes",
            "--out",
        ])
        .arg(&out)
        .env_remove("RIG_PORT")
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Stdin stays open: the third reading never comes.
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(b"\n\n10\n20\n").unwrap();
    let points = out.join("points.csv");
    let t0 = Instant::now();
    while std::fs::read_to_string(&points).map_or(true, |b| b.matches("torque,").count() < 2) {
        assert!(t0.elapsed() < Duration::from_secs(60), "no points written");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The points file is whole at every moment (written atomically).
    let no_load = std::fs::read_to_string(&points)
        .unwrap()
        .matches("no_load,")
        .count();
    assert_eq!(no_load, 10);
    std::thread::sleep(Duration::from_millis(300));
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let got = child.wait_with_output().unwrap();
    drop(stdin);
    assert_eq!(got.status.code(), Some(130));
    let err = text(&got.stderr);
    assert!(
        err.contains("interrupted") && err.contains("gear locked"),
        "{err}"
    );
    assert!(err.contains("--from-points"), "{err}");
    assert_eq!(torque_readings(&points), [10.0, 20.0]);
    assert!(!out.join("calibration.toml").exists());
}
