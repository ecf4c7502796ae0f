//! `rig monitor` from the operator's side: flags explained, stale estimates cleared.

use std::time::Duration;

use assert_cmd::Command;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

fn stdout(c: &mut Command) -> String {
    String::from_utf8(c.assert().success().get_output().stdout.clone()).unwrap()
}

#[test]
fn explain_names_every_status_flag_and_the_stale_rule() {
    let text = stdout(rig().args(["monitor", "--explain"]));
    for flag in [
        "COASTS_AFTER_STOP",
        "NOT_SELF_LOCKING",
        "HOST_RELEASE",
        "BUTTON_RELEASE",
        "CAPTURE_RUNNING",
        "CALIBRATION_DEFAULTS",
        "OUTPUT_MOVING",
        "OPEN_LOOP",
    ] {
        assert!(text.contains(flag), "{flag} missing:\n{text}");
    }
    assert!(text.contains("stale") && text.contains("`-`"), "{text}");
    assert!(text.lines().all(|l| l.chars().count() <= 160), "{text}");
}

#[test]
fn estimates_show_a_dash_while_locked_and_values_while_vibrating() {
    let text = stdout(rig().args([
        "--sim",
        "--speed",
        "5",
        "monitor",
        "--plain",
        "--seconds",
        "3",
        "--rate",
        "20",
        "--release",
        "10",
    ]));
    // Columns under the header: time_s state cam_hz current_a tau_cam_nm bus_v output_rad faults.
    let head = text.lines().next().unwrap();
    assert!(head.contains("current_a tau_cam_nm bus_v"), "{head}");
    let cols = |l: &str| l.split_whitespace().map(str::to_owned).collect::<Vec<_>>();
    let locked: Vec<&str> = text.lines().filter(|l| l.contains(" locked ")).collect();
    assert!(!locked.is_empty(), "{text}");
    assert!(
        locked
            .iter()
            .all(|l| cols(l)[4] == "-" && cols(l)[5].parse::<f64>().is_ok()),
        "{text}"
    );
    let vibrating: Vec<&str> = text.lines().filter(|l| l.contains("vibrating")).collect();
    let last = vibrating.last().expect("it vibrated");
    assert!(
        cols(last)[4] != "-" && cols(last)[4].parse::<f64>().is_ok(),
        "a current estimate while vibrating: {last}"
    );
    assert!(text.lines().all(|l| l.len() <= 80), "{text}");
}

/// Issue 33: `rig monitor --csv` killed with SIGKILL (nothing of it runs after the
/// signal) leaves its header and whole rows in the file itself; `--resume` continues it,
/// dropping and reporting a row cut short, so every row stays whole.
#[test]
fn sigkill_leaves_whole_rows_and_resume_drops_a_row_cut_short() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mon.csv");
    let header = "device_time_s,state,cam_speed_rad_s,cam_hz,current_a,pwm_duty,tau_cam_nm,tau_rot_nm,faults,status,output_rad,output_rad_s,bus_v,motor_temp_c,step_cycles_mean,step_cycles_max";
    let data_rows = |text: &str| text.lines().skip(1).count();
    let bin = assert_cmd::cargo::cargo_bin("rig");
    let mut said_dropped = 0;
    // Killed three times, each run continuing the last one's log, at growing sizes.
    for (k, want) in [40usize, 400, 1500].into_iter().enumerate() {
        let mut cmd = std::process::Command::new(&bin);
        cmd.env_remove("RIG_PORT")
            .args(["--sim", "monitor", "--plain", "--rate", "1000", "--csv"])
            .arg(&csv)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        if k > 0 {
            cmd.arg("--resume");
        }
        let mut child = cmd.spawn().unwrap();
        // Wait on the file's contents (the rows the monitor logged), not on the clock.
        let deadline = std::time::Instant::now() + Duration::from_secs(300);
        loop {
            let text = std::fs::read_to_string(&csv).unwrap_or_default();
            if data_rows(&text) >= want {
                break;
            }
            if let Some(status) = child.try_wait().unwrap() {
                let mut err = String::new();
                std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
                panic!("the monitor ended by itself ({status}): {err}");
            }
            assert!(
                std::time::Instant::now() < deadline,
                "no {want} rows logged"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        child.kill().unwrap(); // SIGKILL
        let status = child.wait().unwrap();
        assert!(!status.success());
        let mut err = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
        said_dropped += err.matches("dropped an incomplete last row").count();
        let text = std::fs::read_to_string(&csv).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], header);
        assert!(lines.len() > want, "{} lines", lines.len());
        // Every row whole, but for the last one if the kill landed inside its write
        // (then the next run drops it and says so).
        let whole = if text.ends_with('\n') {
            &lines[1..]
        } else {
            &lines[1..lines.len() - 1]
        };
        for row in whole {
            let fields: Vec<&str> = row.split(',').collect();
            assert_eq!(fields.len(), 16, "{row}");
            assert!(fields[0].parse::<f64>().is_ok(), "{row}");
            assert!(
                !fields[1].is_empty() && fields[1] != "device_time_s",
                "{row}"
            );
        }
    }
    // A row cut short for certain (as a full disk or a kill inside a write leaves it): the
    // next run drops it, says so with its size, and appends whole rows after it.
    let mut text = std::fs::read_to_string(&csv).unwrap();
    if !text.ends_with('\n') {
        text.truncate(text.rfind('\n').unwrap() + 1);
    }
    let before = data_rows(&text);
    text.push_str("12.345678,vibr");
    std::fs::write(&csv, &text).unwrap();
    let out = Command::cargo_bin("rig")
        .unwrap()
        .env_remove("RIG_PORT")
        .timeout(Duration::from_secs(120))
        .args([
            "--sim",
            "monitor",
            "--plain",
            "--rate",
            "100",
            "--seconds",
            "0.2",
            "--resume",
            "--csv",
        ])
        .arg(&csv)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("dropped an incomplete last row (14 bytes"),
        "{err}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.ends_with('\n') && !text.contains("vibr\n"));
    assert_eq!(text.matches("device_time_s").count(), 1, "one header");
    assert!(data_rows(&text) >= before + 19, "{} rows", data_rows(&text));
    assert!(
        text.lines()
            .skip(1)
            .all(|l| l.split(',').count() == 16
                && l.split(',').next().unwrap().parse::<f64>().is_ok()),
        "a row not whole"
    );
    // Without --resume or --force an existing log is refused and left as it was.
    let out = Command::cargo_bin("rig")
        .unwrap()
        .env_remove("RIG_PORT")
        .args(["--sim", "monitor", "--plain", "--seconds", "0.1", "--csv"])
        .arg(&csv)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--resume") && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), text);
    eprintln!("{said_dropped} kills landed inside a row's write");
}

/// `--force` logs to FILE.new and replaces FILE only when the monitor ends normally; a
/// leftover FILE.new (an interrupted --force run's rows) is never overwritten.
#[test]
fn force_keeps_the_old_log_until_the_monitor_ends() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mon.csv");
    std::fs::write(&csv, "old log\n").unwrap();
    let run = |extra: &[&str]| {
        Command::cargo_bin("rig")
            .unwrap()
            .env_remove("RIG_PORT")
            .timeout(Duration::from_secs(120))
            .args([
                "--sim",
                "monitor",
                "--plain",
                "--rate",
                "50",
                "--seconds",
                "0.2",
            ])
            .args(extra)
            .arg("--csv")
            .arg(&csv)
            .output()
            .unwrap()
    };
    let new = dir.path().join("mon.csv.new");
    std::fs::write(&new, "rows of a killed run\n").unwrap();
    let out = run(&["--force"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("mon.csv.new"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(&new).unwrap(),
        "rows of a killed run\n"
    );
    std::fs::remove_file(&new).unwrap();
    let out = run(&["--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.starts_with("device_time_s,") && text.lines().count() >= 10,
        "{text}"
    );
    assert!(!new.exists());
    // Not a monitor's log: --resume refuses it and leaves it alone.
    std::fs::write(&csv, "t_s,i_in_a\n1,2\n").unwrap();
    let out = run(&["--resume"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("not a `rig monitor --csv` log"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), "t_s,i_in_a\n1,2\n");
}
