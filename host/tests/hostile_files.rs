//! Issue 33's data cases: `--force` keeps the old sweep whole until the new one is
//! complete, and `--resume` drops (and reports) a row cut short by a crash or a full disk
//! instead of keeping it for `explain` to refuse.

use std::time::Duration;

use assert_cmd::Command;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(600));
    c
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// A quick sweep on the virtual rig with an operator whose stdin ends after `answers`
/// Enter presses: the sweep stops there, with the gear locked.
fn stopped_sweep(csv: &std::path::Path, extra: &[&str], answers: usize) -> (bool, String) {
    let out = rig()
        .args([
            "--sim",
            "--speed",
            "10",
            "experiment",
            "torque-sweep",
            "--quick",
            "--operator",
        ])
        .args(extra)
        .arg("--csv")
        .arg(csv)
        .write_stdin("\n".repeat(answers))
        .output()
        .unwrap();
    (out.status.success(), text(&out.stderr))
}

fn data_lines(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("point,"))
        .collect()
}

#[test]
fn force_keeps_the_old_file_whole_until_the_new_sweep_is_complete() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sweep.csv");
    let kept = "# an earlier sweep\npoint,repeat,t_s,v_in_v,target_hz,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c,tau_cam_est_nm,backdriven\n0,0,1.0,3.6,,30.0,0.368,2.5,25,0.05,1\n";
    std::fs::write(&csv, kept).unwrap();
    // Interrupted after a few points: the old file is as it was, the new rows are kept.
    let (ok, err) = stopped_sweep(&csv, &["--force"], 5);
    assert!(!ok, "{err}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), kept, "{err}");
    let new = dir.path().join("sweep.csv.new");
    let partial = std::fs::read_to_string(&new).unwrap();
    let rows = data_lines(&partial).len();
    assert!(rows >= 1, "{partial}");
    assert!(
        err.contains(&format!("{rows} completed rows kept in"))
            && err.contains("sweep.csv.new")
            && err.contains("was left as it was"),
        "{err}"
    );
    // Run to the end: the new sweep replaces the old file in one rename.
    let out = rig()
        .args(["--sim", "--speed", "10", "experiment", "torque-sweep"])
        .args(["--quick", "--force", "--csv"])
        .arg(&csv)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let body = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(data_lines(&body).len(), 30, "{body}");
    assert!(!new.exists());
}

#[test]
fn resume_drops_a_row_cut_short_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sweep.csv");
    let (ok, err) = stopped_sweep(&csv, &[], 5);
    assert!(!ok, "{err}");
    let before = std::fs::read_to_string(&csv).unwrap();
    let rows = data_lines(&before).len();
    assert!(rows >= 1, "{before}");
    // A full disk cut the next row short.
    let half = "7,0,12.5,3.6,,31.2";
    std::fs::write(&csv, before.clone() + half).unwrap();
    let (_, err) = stopped_sweep(&csv, &["--resume"], 3);
    assert!(
        err.contains("dropped an incomplete last row (18 bytes"),
        "{err}"
    );
    let after = std::fs::read_to_string(&csv).unwrap();
    assert!(after.starts_with(&before), "{after}");
    assert!(!after.contains(half), "{after}");
    let columns = before
        .lines()
        .find(|l| l.starts_with("point,"))
        .unwrap()
        .split(',')
        .count();
    for line in data_lines(&after) {
        assert_eq!(line.split(',').count(), columns, "{line}");
    }
}

/// Every text input the tools read is bounded: `/dev/zero`, a FIFO and a file without line
/// ends are refused at once, naming the file, instead of read forever.
#[test]
fn unbounded_inputs_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let lineless = dir.path().join("lineless.csv");
    std::fs::write(&lineless, vec![b'7'; 200_000]).unwrap();
    let fifo = dir.path().join("fifo");
    let fifo_made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    let out = dir.path().join("out");
    let out_csv = dir.path().join("out.csv");
    let cases: Vec<(Vec<String>, &std::path::Path, &str)> = {
        let s = |x: &str| x.to_string();
        let p = |x: &std::path::Path| x.display().to_string();
        let mut cases = Vec::new();
        for file in [std::path::Path::new("/dev/zero"), lineless.as_path()]
            .into_iter()
            .chain(fifo_made.then_some(fifo.as_path()))
        {
            let why = if file == lineless.as_path() {
                "longer than 64 KiB"
            } else {
                "a pipe, socket or device"
            };
            cases.push((
                vec![
                    s("calibrate"),
                    s("--from-points"),
                    p(file),
                    s("--out"),
                    p(&out),
                ],
                file,
                why,
            ));
            cases.push((
                vec![s("--sim"), s("calibration"), s("set"), p(file)],
                file,
                why,
            ));
            cases.push((
                vec![
                    s("--sim"),
                    s("experiment"),
                    s("torque-sweep"),
                    s("--plan"),
                    p(file),
                    s("--csv"),
                    p(&out_csv),
                ],
                file,
                why,
            ));
            cases.push((
                vec![
                    s("--sim"),
                    s("calibrate"),
                    s("--yes"),
                    s("--gauge-csv"),
                    p(file),
                    s("--out"),
                    p(&out),
                ],
                file,
                why,
            ));
        }
        cases.push((
            vec![
                s("--sim"),
                s("experiment"),
                s("torque-sweep"),
                s("--quick"),
                s("--resume"),
                s("--csv"),
                p(&lineless),
            ],
            lineless.as_path(),
            "longer than 64 KiB",
        ));
        cases
    };
    for (args, file, why) in cases {
        let out = rig()
            .args(&args)
            .timeout(Duration::from_secs(60))
            .output()
            .unwrap();
        let err = text(&out.stderr);
        assert!(!out.status.success(), "{args:?}: {err}");
        assert!(
            err.contains(&file.display().to_string()) && err.contains(why),
            "{args:?}: {err}"
        );
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}
