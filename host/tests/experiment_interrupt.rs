//! Ctrl-C in every procedure of `rig experiment`, on the virtual rig: while it runs and
//! while a prompt waits for the operator. Each locks the gear and exits 130 (the sweep's
//! Ctrl-C and `--resume`: experiment_cli.rs).

use std::io::Write;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

fn spawn(args: &[&str], stdin: Stdio) -> Child {
    let bin = assert_cmd::cargo::cargo_bin("rig");
    std::process::Command::new(bin)
        .args(["--sim", "--speed", "5", "experiment"])
        .args(args)
        .env_remove("RIG_PORT")
        .stdin(stdin)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

mod support {
    pub mod child;
}
use support::child::{Output, wait_for_handler};

/// When to send SIGINT: once the child said something, or once it handles SIGINT.
enum When<'a> {
    /// Its stderr showed this text this many times.
    Said(&'a str, usize),
    /// Its SIGINT handler is installed (the procedure says nothing while it runs).
    Handles,
}

/// SIGINT to `child` at `when` (its own progress, never a guessed sleep); its exit code
/// and stderr.
fn interrupt(mut child: Child, when: When) -> (Option<i32>, String) {
    let stdout = Output::read(child.stdout.take().unwrap());
    let stderr = Output::read(child.stderr.take().unwrap());
    match when {
        When::Said(text, count) => stderr.wait_for(text, count, &format!("{text:?} x{count}")),
        When::Handles => wait_for_handler(child.id(), 2),
    }
    let sent = std::process::Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let t0 = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "slow to stop");
        std::thread::sleep(Duration::from_millis(20));
    };
    let _ = stdout.all();
    (status.code(), stderr.all())
}

fn assert_locked_130((code, err): (Option<i32>, String)) {
    assert_eq!(code, Some(130), "{err}");
    assert!(
        err.contains("interrupted") && err.contains("locked"),
        "{err}"
    );
}

#[test]
fn ctrl_c_during_a_hold_release_locks() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("h.csv");
    let child = spawn(
        &[
            "hold-release",
            "--hold",
            "60",
            "--csv",
            csv.to_str().unwrap(),
        ],
        Stdio::null(),
    );
    // Mid-hold: its 60 s hold began.
    assert_locked_130(interrupt(child, When::Said("hold: 60 s", 1)));
}

#[test]
fn ctrl_c_during_a_backdrive_test_locks() {
    let child = spawn(&["backdrive", "--hold", "60"], Stdio::null());
    // Wherever the signal lands once the child handles it (before the 60 s hold or in it).
    assert_locked_130(interrupt(child, When::Handles));
}

#[test]
fn ctrl_c_at_an_operator_prompt_locks() {
    let dir = tempfile::tempdir().unwrap();
    let h = dir.path().join("h.csv");
    let s = dir.path().join("s.csv");
    let (h, s) = (h.to_str().unwrap(), s.to_str().unwrap());
    for args in [
        vec![
            "--operator",
            "backdrive",
            "--hold",
            "0.3",
            "--release",
            "0.3",
        ],
        vec!["--operator", "hold-release", "--hold", "0.5", "--csv", h],
        vec!["--operator", "torque-sweep", "--quick", "--csv", s],
    ] {
        let mut child = spawn(&args, Stdio::piped());
        // Stdin stays open and silent: the prompt waits.
        let stdin = child.stdin.take().unwrap();
        let (code, err) = interrupt(child, When::Said("then Enter", 1));
        drop(stdin);
        assert!(
            err.contains("then Enter"),
            "{args:?}: the prompt was shown: {err}"
        );
        assert_locked_130((code, err));
    }
}

#[test]
fn an_answer_then_ctrl_c_at_the_next_prompt_keeps_the_answered_rows() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    let mut child = spawn(
        &[
            "--operator",
            "torque-sweep",
            "--quick",
            "--csv",
            csv.to_str().unwrap(),
        ],
        Stdio::piped(),
    );
    let mut stdin = child.stdin.take().unwrap();
    // Hang the first load, keep the first point; the next prompt waits.
    stdin.write_all(b"\n\n").unwrap();
    let t0 = Instant::now();
    while std::fs::read_to_string(&csv).map_or(true, |b| {
        b.lines().filter(|l| !l.starts_with('#')).count() < 2
    }) {
        assert!(t0.elapsed() < Duration::from_secs(60), "no row written");
        std::thread::sleep(Duration::from_millis(50));
    }
    let result = interrupt(child, When::Said("then Enter", 2));
    drop(stdin);
    assert_locked_130(result);
    let body = std::fs::read_to_string(&csv).unwrap();
    let rows = body
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("point"))
        .count();
    assert!(rows >= 1, "{body}");
}
