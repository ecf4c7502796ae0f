//! `rig compare` through the real binary: data measured on a virtual rig with a hidden
//! effect, the model `rig explain` writes from it, and the simulation-versus-measurement gap
//! before and after that model runs in the simulator. Also `--model` on the simulator's
//! procedures and `rig explain --propose`'s plan loaded by the experiment's plan parser.

use std::path::Path;
use std::time::Duration;

use assert_cmd::Command;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(600));
    c
}

mod support {
    pub mod cli;
}
use support::cli::json_of as json;

/// A rig file whose [model] hides `effect` with `params` (the paper's rig otherwise).
fn hidden(path: &Path, effect: &str, params: &str) {
    std::fs::write(
        path,
        format!(
            "[model]\nmu = 0.271\n\n[[model.effects]]\nname = \"{effect}\"\nparams = {{ {params} }}\n"
        ),
    )
    .unwrap();
}

#[test]
fn compare_shows_the_gap_shrink_with_the_written_model() {
    let dir = tempfile::tempdir().unwrap();
    let truth = dir.path().join("truth.toml");
    // mu_ax falling at low cam speed (Eq. 40 with a 25 rad/s corner; the plant runs its own
    // law matched to it): less current at 3.6 V than the paper's model, as the paper saw.
    hidden(
        &truth,
        "speed-dependent-axial-friction",
        "omega_c_rad_s = 25.0",
    );
    let measured = dir.path().join("measured.csv");
    rig()
        .args([
            "sim",
            "torque-sweep",
            "--levels",
            "5",
            "--repeats",
            "2",
            "--rest",
            "1",
        ])
        .args(["--seed", "5", "--model"])
        .arg(&truth)
        .arg("--csv")
        .arg(&measured)
        .assert()
        .success();
    let model = dir.path().join("fitted.toml");
    // `rig sim torque-sweep`'s CSV states its drive in a `# drive:` line; the rig file's
    // [model] gives the same inertia term the other documented way (a model that fits the
    // inertia term keeps it over the CSV's line).
    let board = dir.path().join("board.toml");
    hidden(&board, "inertia-rectification", "kappa = -0.5");
    let e = json(
        rig()
            .args([
                "explain",
                "--json",
                "--no-report",
                "--replicates",
                "50",
                "--measured",
            ])
            .arg(&measured)
            .arg("--rig")
            .arg(&board)
            .arg("--write-model")
            .arg(&model),
    );
    assert_eq!(
        e["effects"][0]["name"], "speed-dependent-axial-friction",
        "{e}"
    );
    let svg = dir.path().join("gap.svg");
    let c = json(
        rig()
            .args(["compare", "--json", "--measured"])
            .arg(&measured)
            .arg("--model")
            .arg(&model)
            .arg("--svg")
            .arg(&svg)
            .args(["--format", "pdf"]),
    );
    assert_eq!(c["points"], 30, "{c}");
    // The plot also as a PDF beside the SVG (`--format`, as every verb that draws).
    let pdf = dir.path().join("gap.pdf");
    assert_eq!(c["figure"], pdf.display().to_string(), "{c}");
    assert!(std::fs::read(&pdf).unwrap().starts_with(b"%PDF"));
    assert_eq!(c["rows"].as_array().unwrap().len(), 30);
    let base = c["gap_rmse_base_a"].as_f64().unwrap();
    let with = c["gap_rmse_model_a"].as_f64().unwrap();
    // The base model misses the dip (tens of mA at 5 Hz); with the fitted effect the gap is
    // the two runs' noise and the law's mismatch (a few mA): well under half.
    assert!(base > 0.008, "the hidden loss shows: {base}");
    assert!(
        with < 0.5 * base,
        "gap {with} A with the model vs {base} A without"
    );
    let fitted: Vec<&str> = c["model_effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert!(
        fitted.contains(&"speed-dependent-axial-friction"),
        "{fitted:?}"
    );
    let plot = std::fs::read_to_string(&svg).unwrap();
    assert!(plot.contains("<svg") && plot.contains("base model"));
    // Short legend entries (beside the plot, clear of the points), the numbers in the caption.
    assert!(plot.contains("\nfitted model\n") && plot.contains("mA with the base model"));
    assert!(plot.contains("before and after the fitted effect"));
    // Without a model: the base gap only, and the title promises no more.
    let base_svg = dir.path().join("base.svg");
    let b = json(
        rig()
            .args(["compare", "--json", "--measured"])
            .arg(&measured)
            .arg("--svg")
            .arg(&base_svg),
    );
    assert!(b["gap_rmse_model_a"].is_null());
    let plot = std::fs::read_to_string(&base_svg).unwrap();
    assert!(plot.contains("Simulation versus measurement: the base model"));
    assert!(!plot.contains("before and after") && !plot.contains("fitted model"));
}

#[test]
fn model_runs_in_the_simulators_procedures_or_names_what_it_cannot() {
    let dir = tempfile::tempdir().unwrap();
    let dip = dir.path().join("dip.toml");
    hidden(
        &dip,
        "speed-dependent-axial-friction",
        "omega_c_rad_s = 25.0",
    );
    let csv = |name: &str| dir.path().join(name);
    for (file, model) in [("base.csv", None), ("dip.csv", Some(&dip))] {
        let mut c = rig();
        c.args([
            "sim",
            "torque-sweep",
            "--levels",
            "2",
            "--repeats",
            "1",
            "--rest",
            "0.5",
            "--preset",
            "ideal",
            "--csv",
        ])
        .arg(csv(file));
        if let Some(m) = model {
            c.arg("--model").arg(m);
        }
        c.assert().success();
    }
    let mean_current = |p: &Path| {
        let text = std::fs::read_to_string(p).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let head: Vec<&str> = lines.next().unwrap().split(',').collect();
        let k = head.iter().position(|h| *h == "i_in_a").unwrap();
        let v: Vec<f64> = lines
            .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    // The same seed, runs and noise: only the plant's friction differs. mu_ax at 5 Hz is
    // 0.78 mu (Eq. 40, 25 rad/s corner): the 3.6 V runs draw less current (0.2 A less at
    // 3.68 N m), the 8.8 V ones about the same.
    let shift = mean_current(&csv("dip.csv")) - mean_current(&csv("base.csv"));
    assert!(shift < -0.03, "the fitted dip lowers the current: {shift}");
    // Fig. 5 and Table 1 take it too.
    rig()
        .args(["sim", "fig5", "--json", "--hold", "2", "--model"])
        .arg(&dip)
        .assert()
        .success();
    // An effect the plant cannot run is named.
    let timed = dir.path().join("timed.toml");
    hidden(&timed, "thermal-drift", "k_per_s = 1e-6");
    let out = rig()
        .args(["sim", "table1", "--model"])
        .arg(&timed)
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let err = String::from_utf8_lossy(&out);
    assert!(
        err.contains("cannot run thermal-drift against time"),
        "{err}"
    );
    // A rig file without a fitted model is refused with what to do.
    let plain = dir.path().join("plain.toml");
    std::fs::write(&plain, "[friction]\nmu_s = 0.271\n").unwrap();
    let out = rig()
        .args(["sim", "fig5", "--model"])
        .arg(&plain)
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    assert!(String::from_utf8_lossy(&out).contains("--write-model"));
}

#[test]
fn proposed_plan_loads_in_the_experiments_plan_parser() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("next.toml");
    let v = json(
        rig()
            .args([
                "explain",
                "--synthetic",
                "vibrator-viscous-loss",
                "--seed",
                "2",
                "--json",
                "--replicates",
                "50",
                "--propose",
            ])
            .arg(&plan),
    );
    let p = &v["proposal"];
    assert_eq!(p["plan_written"], plan.display().to_string());
    // The proposal's keys, pinned: readers of `--json` depend on them.
    let mut keys: Vec<&str> = p.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "candidates",
            "goal",
            "mode",
            "plan_written",
            "points",
            "reason",
            "sigma_a"
        ]
    );
    let n = p["points"].as_array().unwrap().len();
    assert!(n >= 1, "{p}");
    // The host's plan loader reads it as written.
    let text = std::fs::read_to_string(&plan).unwrap();
    let parsed = host::experiment::Plan::parse(&text, "next.toml").unwrap();
    assert_eq!(parsed.points.len(), n);
    assert_eq!(parsed.reason, p["reason"].as_str().unwrap());
    let runs: u64 = p["points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| q["repeats"].as_u64().unwrap())
        .sum();
    assert_eq!(parsed.runs().len() as u64, runs);
    for (q, r) in p["points"].as_array().unwrap().iter().zip(&parsed.points) {
        assert_eq!(q["load_nm"].as_f64().unwrap(), r.load_nm);
        assert_eq!(q["volts"].as_f64(), r.volts);
    }
    // And `rig experiment torque-sweep --plan FILE` runs it.
    let csv = dir.path().join("more.csv");
    rig()
        .args([
            "--sim",
            "--speed",
            "20",
            "experiment",
            "torque-sweep",
            "--json",
            "--plan",
        ])
        .arg(&plan)
        .arg("--csv")
        .arg(&csv)
        .assert()
        .success();
}
