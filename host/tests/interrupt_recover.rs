//! A bench day's interruptions and recoveries on a served virtual rig: Ctrl-C in the
//! middle of a released capture locks the gear at once, keeps the samples and leaves no
//! fault; a load left falling by a released rig lands on the floor, so `rig clear` clears
//! what its fall latched and the rig is usable again.

use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::time::Duration;

use assert_cmd::Command;
use serde_json::Value;

mod support {
    pub mod served;
}
use support::served::Server;

fn rig(port: &str) -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT")
        .args(["--port", port])
        .timeout(Duration::from_secs(120));
    c
}

fn json(port: &str, args: &[&str]) -> Value {
    let out = rig(port).args(args).output().unwrap();
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn latched(port: &str) -> Vec<String> {
    json(port, &["faults", "--json"])["latched"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn ctrl_c_in_a_released_capture_locks_at_once_and_keeps_the_samples() {
    // Real time: the burst lasts a second of device time, the signal lands inside it.
    let server = Server::start_at("1", &[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("burst.csv");
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut child = std::process::Command::new(bin)
        .env_remove("RIG_PORT")
        .args([
            "--port",
            &server.port,
            "capture",
            "--seconds",
            "1",
            "--release",
            "10",
        ])
        .arg("--csv")
        .arg(&csv)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the device to start recording (said on stderr), not for a wall-clock time.
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut said = String::new();
    loop {
        let mut line = String::new();
        assert!(
            err.read_line(&mut line).unwrap() > 0,
            "no recording line: {said}"
        );
        said += &line;
        if line.starts_with("recording ") {
            break;
        }
    }
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let status = child.wait().unwrap();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    assert_eq!(status.code(), Some(130), "{said}{rest}");
    assert!(
        rest.contains("stopped by Ctrl-C") && rest.contains("locked"),
        "{rest}"
    );
    // What the device recorded is in the CSV.
    let text = std::fs::read_to_string(&csv).expect("the CSV was written");
    let rows = text.lines().filter(|l| !l.starts_with('#')).count() - 1;
    assert!(rows > 0, "{text}");
    // The gear was locked by the client, not by the comms timeout: nothing latched.
    let faults = latched(&server.port);
    assert!(faults.is_empty(), "{faults:?}");
}

#[test]
fn a_load_left_falling_lands_and_the_rig_recovers() {
    let server = Server::start_at("20", &[]);
    let port = server.port.as_str();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("fig5.csv");
    // Fig. 5's load (0.736 N m) released for 2 s: it falls, and keeps falling after the
    // lock on the (49, 51, 50, 50) rig (mu_d Lambda < 1) until it reaches the floor.
    rig(port)
        .args([
            "experiment",
            "hold-release",
            "--hold",
            "1",
            "--after",
            "1",
            "--csv",
        ])
        .arg(&csv)
        .assert()
        .success();
    // Clear what the fall latched and watch the output for a device second, until it
    // stands still (the monitor refuses to start while a fault is latched).
    let mut still = false;
    for _ in 0..120 {
        rig(port).arg("clear").output().unwrap();
        let out = rig(port)
            .args(["monitor", "--json", "--seconds", "1"])
            .output()
            .unwrap();
        let rows: Vec<Value> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| serde_json::from_str::<Value>(l).ok())
            .collect();
        let speeds: Vec<f64> = rows
            .iter()
            .filter_map(|r| r["output_rad_s"].as_f64())
            .collect();
        if speeds.len() > 10 && speeds.iter().all(|w| w.abs() < 0.01) {
            // It rests where its 2 m of rope ends: 26.7 rad below where it was hung.
            let angle = rows.last().unwrap()["output_rad"].as_f64().unwrap();
            assert!((25.0..30.0).contains(&angle.abs()), "rests at {angle} rad");
            still = true;
            break;
        }
    }
    assert!(still, "the load never came to rest");
    // Its cause gone, a clear clears for good.
    rig(port).arg("clear").output().unwrap();
    let faults = latched(port);
    assert!(faults.is_empty(), "{faults:?}");
}
