//! The device option `--model FILE` (with `--sim`): the real rig's procedures run on the
//! virtual device whose plant runs a rig file's fitted `[model]`, through the real binary.
//! The current shifts as the model's effect predicts; misuse is refused by name.

use std::path::Path;
use std::time::Duration;

use assert_cmd::Command;
use model::effects::{CurrentModel, OperatingPoint};

/// Virtual seconds per wall-clock second in these tests.
const SPEED: &str = "20";

/// The hidden effect: an extra vibrator loss c_v w_n, N mm s/rad (the size `rig explain
/// --synthetic vibrator-viscous-loss --write-model` fits), about 0.3 A at 15 Hz.
const C_V_N_MM_S_PER_RAD: f64 = 0.2;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(120));
    c
}

/// The board's drive as a fitted model states it (the sweep CSV's `# drive:` line: the
/// G2's braking decay, kappa = -(1 + 0.8 x 0.8) / 2 = -0.82), so the rig file's plant is
/// the `--sim` device's.
const DRIVE: &str =
    "[[model.effects]]\nname = \"inertia-rectification\"\nparams = { kappa = -0.82 }\n";

/// A rig file whose fitted [model] is the paper's (mu) with `effects`.
fn model_file(path: &Path, effects: &str) {
    std::fs::write(path, format!("[model]\nmu = 0.271\n\n{DRIVE}\n{effects}")).unwrap();
}

/// A tiny closed-loop plan: two loads at 15 Hz, one run each, in order.
fn tiny_plan(path: &Path) {
    std::fs::write(
        path,
        "name = \"model test\"\nmode = \"closed-loop\"\nrepeats = 1\norder = \"as-listed\"\n\
         rest_s = 0.5\nwindow_s = 0.5\n\n\
         [[points]]\nload_nm = 0.368\nhz = 15.0\n\n[[points]]\nload_nm = 1.5\nhz = 15.0\n",
    )
    .unwrap();
}

/// The sweep's rows: (omega_n_rad_s, tau_rot_nm, i_in_a).
fn rows(csv: &Path) -> Vec<(f64, f64, f64)> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (w, t, i) = (col("omega_n_rad_s"), col("tau_rot_nm"), col("i_in_a"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let num = |k: usize| f[k].parse::<f64>().unwrap();
            (num(w), num(t), num(i))
        })
        .collect()
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len() as f64
}

/// Runs the tiny plan on the virtual device with `device_args` around the verb; its rows.
fn sweep(dir: &Path, name: &str, before: &[&str], after: &[&str]) -> Vec<(f64, f64, f64)> {
    let plan = dir.join("plan.toml");
    tiny_plan(&plan);
    let csv = dir.join(name);
    rig()
        .args(["--sim", "--speed", SPEED])
        .args(before)
        .args(["experiment", "torque-sweep", "--json", "--plan"])
        .arg(&plan)
        .arg("--csv")
        .arg(&csv)
        .args(after)
        .assert()
        .success();
    let r = rows(&csv);
    assert_eq!(r.len(), 2, "every run of the plan is written: {r:?}");
    r
}

#[test]
fn the_virtual_device_runs_the_fitted_model() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().join("base.toml");
    model_file(&base, "");
    let visc = dir.path().join("visc.toml");
    model_file(
        &visc,
        &format!(
            "[[model.effects]]\nname = \"vibrator-viscous-loss\"\nparams = {{ c_v_n_mm_s_per_rad = {C_V_N_MM_S_PER_RAD} }}\n"
        ),
    );
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let plain = sweep(dir.path(), "plain.csv", &[], &[]);
    // `--model` after the verb, as the other device options.
    let with_base = sweep(dir.path(), "base.csv", &[], &["--model", &s(&base)]);
    let with_visc = sweep(dir.path(), "visc.csv", &["--model", &s(&visc)], &[]);

    // The expectation from the model: the current the effect adds at each run's measured
    // cam speed and load (CurrentModel: (torque - C2) / C1 with c_v w_n in the loss).
    let gear = model::GearSet::paper(model::paper::RIG_Z).unwrap();
    let without = CurrentModel::paper(
        model::CamDrive::paper(gear),
        model::Calibration::PAPER,
        0.271,
    );
    let mut with = without;
    with.effects.viscous_loss = C_V_N_MM_S_PER_RAD * 1e-3;
    let predicted = mean(with_visc.iter().map(|&(w, t, _)| {
        let op = OperatingPoint::new(w, t, 0.0);
        with.current(&op) - without.current(&op)
    }));
    assert!(
        predicted > 0.2,
        "the effect raises the current: {predicted} A"
    );
    let current = |r: &[(f64, f64, f64)]| mean(r.iter().map(|x| x.2));
    let shift = current(&with_visc) - current(&plain);
    // Same seed, plan and closed-loop speed: the effect's share within the run noise and
    // the `paper` preset's small dip of mu_ax at 94 rad/s (a few mA here).
    assert!(
        (shift - predicted).abs() < 0.05,
        "--model raises the mean current by {shift} A; the model predicts {predicted} A"
    );
    // The rig file without the effect is the `--sim` device's rig.
    let same = current(&with_base) - current(&plain);
    assert!(
        same.abs() < 0.03,
        "the effect-free model shifts the current by {same} A"
    );
}

#[test]
fn the_virtual_device_runs_a_user_effect_of_the_model() {
    // A law of the user's own (as `rig explain` proposes one: a `[[user_effects]]` entry
    // and the `[[model.terms]]` entry carrying its value) runs in the virtual device's
    // plant: each run draws the law's current at its speed and load on top of the rig
    // without it, so `rig discover` and `rig compare` can test a proposed law.
    const C: f64 = 0.002; // A per (rad/s N m)
    let dir = tempfile::tempdir().unwrap();
    let user = dir.path().join("user.toml");
    model_file(
        &user,
        &format!(
            "[[model.terms]]\nname = \"brush-float\"\nparams = {{ c = {C} }}\n\n\
             [[user_effects]]\nname = \"brush-float\"\nexpression = \"c * w * tau\"\n\
             params = {{ c = {{ unit = \"A s/(rad N m)\", bounds = [-0.1, 0.1] }} }}\n"
        ),
    );
    let base = dir.path().join("base.toml");
    model_file(&base, "");
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let without = sweep(dir.path(), "base.csv", &["--model", &s(&base)], &[]);
    let with = sweep(dir.path(), "user.csv", &["--model", &s(&user)], &[]);
    for (a, b) in without.iter().zip(&with) {
        let law = C * b.0 * b.1;
        let shift = b.2 - a.2;
        // Same seed, plan and closed-loop speed: the law's current within the run noise.
        assert!(
            (shift - law).abs() < 0.03,
            "at {:.1} rad/s, {:.3} N m: the user effect adds {shift:.4} A, its law {law:.4} A",
            b.0,
            b.1
        );
    }
}

#[test]
fn model_needs_sim_and_a_fitted_rig_file() {
    let dir = tempfile::tempdir().unwrap();
    let said = |c: &mut Command| {
        let out = c.assert().failure().get_output().stderr.clone();
        String::from_utf8(out).unwrap()
    };
    let good = dir.path().join("good.toml");
    model_file(&good, "");
    // Without --sim: refused naming both options, before any port is opened.
    let e = said(rig().arg("--model").arg(&good).args(["info", "--json"]));
    assert!(e.contains("--model") && e.contains("--sim"), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    // A missing file or a file that is not a rig file: each named.
    let missing = dir.path().join("missing.toml");
    let junk = dir.path().join("junk.toml");
    std::fs::write(&junk, "this is not TOML = = =\n").unwrap();
    let plain = dir.path().join("plain.toml");
    std::fs::write(&plain, "[friction]\nmu_s = 0.271\n").unwrap();
    // A plain rig file (no [model]) puts its own rig on the virtual device.
    let out = rig()
        .args(["--sim", "--speed", SPEED, "info", "--json", "--model"])
        .arg(&plain)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    assert!(String::from_utf8_lossy(&out).contains("\"board\": \"virtual\""));
    // The rig file's drive is the virtual device's: braking by default, coast when it says.
    assert!(String::from_utf8_lossy(&out).contains("\"decay\": \"brake\""));
    let coast = dir.path().join("coast.toml");
    std::fs::write(&coast, "[drive]\ndecay = \"coast\"\n").unwrap();
    let out = rig()
        .args(["--sim", "--speed", SPEED, "info", "--json", "--model"])
        .arg(&coast)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8_lossy(&out);
    assert!(text.contains("\"decay\": \"coast\""), "{text}");
    assert!(!text.contains("BRAKING_DECAY"), "{text}");
    for (file, fix) in [(&missing, "--write-model"), (&junk, "--write-model")] {
        let e = said(
            rig()
                .args(["--sim", "--speed", SPEED, "info", "--model"])
                .arg(file),
        );
        assert!(e.contains(&file.display().to_string()), "{e}");
        assert!(e.contains(fix), "{e}");
        assert!(!e.contains("panicked") && !e.contains("RigFile {"), "{e}");
    }
    // An effect the plant cannot run is named.
    let timed = dir.path().join("timed.toml");
    model_file(
        &timed,
        "[[model.effects]]\nname = \"thermal-drift\"\nparams = { k_per_s = 1e-6 }\n",
    );
    let e = said(rig().args(["--sim", "info", "--model"]).arg(&timed));
    assert!(e.contains("cannot run thermal-drift against time"), "{e}");
    // Verbs without a device, and the demo, refuse it with where it goes.
    let e = said(rig().arg("--model").arg(&good).args(["sim", "fig5"]));
    assert!(e.contains("rig sim") && e.contains("own --model"), "{e}");
    let e = said(rig().args(["--sim", "--model"]).arg(&good).arg("demo"));
    assert!(e.contains("--model") && e.contains("rig demo"), "{e}");
}
