//! The `rig explain` command line: arguments and the run behind them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use model::effects::{Effect, EffectParams};
use model::plant::NoiseSource;

use crate::RigError;
use explain::data::Dataset;
use explain::synth::{self, SweepPlan};
use explain::{Options, SyntheticTruth, library, report_files};
use rigfile::RigFile;

const AFTER_HELP: &str = "\
Measured data: CSV with a header in SI units, one row per test point. Required columns
omega_n_rad_s, tau_rot_nm, i_in_a; optional t_s, v_in_v, temp_c, backdriven (0/1); other
columns are ignored. A row with backdriven = 0 may leave i_in_a empty.

Rig file (--model, alias --rig): TOML, every key optional (the paper's rig otherwise); the
same file `rig calibrate` and `rig calibration get` write (docs/rig-file.md lists every key):
  [gear]         z = [49, 51, 50, 50], module_mm = 1.0, pressure_angle_deg = 20.0
  [cam]          eccentricity_mm = 1.0, carrier_mass_kg = 3.82
  [friction]     mu_s = 0.271, mu_d = 0.174
  [calibration]  c1 = 62.1, c2 = -138.0, c3 = 0.235, c4 = 1.69, c5 = 0.00378, c6 = 2.25
                 (Table 2, N mm, A and s), temperature_c = 25.0
  [limits]       max_release_load_nm = 3.68, max_current_a = 4.5, max_freq_hz = 15.0
  [model]        mu = ..., [[model.effects]] name = \"...\", params = { ... }
                 (written by --write-model; loaded effects are refitted, not searched for)
Other sections are kept as they are by --write-model. The older flat calibration file
(c1_nmm_per_a = ...) loads too.

Effects searched for: speed-dependent-axial-friction, load-dependent-friction,
current-sensor-offset, thermal-drift, vibrator-viscous-loss, inertia-rectification,
linear-bush-friction (needs backdriven = 0 rows), tooth-compliance, mesh-load-sharing-ripple.

Rows that cannot be right (a current beyond the sensor's +-5 A, a cam speed beyond the
motor's no-load speed, a temperature outside -40..150 C) or that stand out from the rows at
like conditions by more than 5.5 robust standard deviations are set aside and listed
(JSON \"outliers\": row, file line, column, value, reason). Warnings (negative loads,
implausible rig values by the firmware's calibration rules) go to stderr and JSON
\"warnings\".

Confidence: a block bootstrap of the whole selection (--replicates, blocks of consecutive
test points) gives each effect's inclusion_probability and the top-level confidence (share of
replicates reaching the same finding); ambiguous when a competitor is selected instead of
the leading effect in a fifth or more of them.

Lack of fit (JSON \"lack_of_fit\"): the final model's cell means (speed level x load level)
against the pure error of the data's repeats (an F-test), or, with drifting repeats, against
successive repeats; without repeats against --stated-noise-ma, else the ACS714's specification
(27 mA per sample); the model's own resolution (2.9 mA) is added to every cell mean. It says
which, and where the discrepancy lives (speed level, load range, time).

Verdicts: explained (named effects, what remains is within the noise), partly-explained (named
effects shrink the gap, a significant lack of fit remains), unexplained (a significant lack of
fit and no named effect explains it), ambiguous, no-missing-effect (no effect needed and the
lack of fit is not significant). Exit code 0 for any verdict, 1 on bad input.";

/// Arguments of `rig explain`.
#[derive(Debug, Clone, Args)]
#[command(after_long_help = AFTER_HELP)]
pub struct ExplainArgs {
    /// Measured steady-state data (CSV, see below).
    #[arg(long, value_name = "FILE.csv", required_unless_present = "synthetic")]
    pub measured: Option<PathBuf>,
    /// Rig file (TOML) with the rig and, written by --write-model, a fitted model [default: the paper's (49, 51, 50, 50) rig].
    #[arg(long, visible_alias = "rig", value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Print one JSON object on stdout instead of text.
    #[arg(long)]
    pub json: bool,
    /// Report folder (residual plots before and after, candidate table, finding) [default: NAME-explain (NAME: the data file's stem) beside the measured file; none for --synthetic].
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Write no report folder.
    #[arg(long, conflicts_with = "report")]
    pub no_report: bool,
    /// Write the augmented model (the rig file with its fitted [model]) to FILE, atomically and only when the whole run succeeded.
    #[arg(long, value_name = "FILE")]
    pub write_model: Option<PathBuf>,
    /// Explain a synthetic sweep of the paper's test plan with this hidden effect ("none": effect-free) instead of --measured.
    #[arg(long, value_name = "EFFECT", conflicts_with = "measured", value_parser = parse_hidden)]
    pub synthetic: Option<Hidden>,
    /// Seed of the synthetic sweep (test order, noise, effect size).
    #[arg(long, default_value_t = 1, requires = "synthetic")]
    pub seed: u64,
    /// Current noise of the synthetic sweep, mA.
    #[arg(long, default_value_t = 20.0, requires = "synthetic", value_parser = crate::args::non_negative)]
    pub noise_ma: f64,
    /// Also save the synthetic sweep as CSV.
    #[arg(
        long,
        value_name = "FILE.csv",
        requires = "synthetic",
        visible_alias = "save-data"
    )]
    pub write_synthetic: Option<PathBuf>,
    /// Repeats of the synthetic sweep's 30 test points (5: the paper's 150 rows; 33334: a million rows).
    #[arg(long, default_value_t = 5, requires = "synthetic", value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    pub repeats: u32,
    /// Replicates of the block bootstrap of the selection (0: no bootstrap, no confidence).
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(0..=10_000))]
    pub replicates: u32,
    /// Level of the false-discovery guard (probability that effect-free data gives a finding).
    #[arg(long, default_value_t = 0.002, value_parser = parse_alpha)]
    pub alpha: f64,
    /// Folds of the held-out validation over blocks of test points.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u8).range(2..=20))]
    pub folds: u8,
    /// Row noise of the current that you know (from repeats elsewhere or the logger), mA: the
    /// lack-of-fit test's reference when the data has too few repeats for a pure error
    /// [default for --synthetic: --noise-ma].
    #[arg(long, value_name = "MA", value_parser = crate::args::non_negative)]
    pub stated_noise_ma: Option<f64>,
    /// Write a test plan (docs/plans.md) with the points that best separate the leading
    /// candidates (or pin the finding) for `rig experiment torque-sweep --plan FILE`; JSON
    /// gains `proposal`.
    #[arg(long, value_name = "FILE.toml")]
    pub propose: Option<PathBuf>,
}

/// The test points that best separate `outcome`'s leading candidates (or pin its finding)
/// on the rig of `rig`, for data like `data` ([`explain::design`]).
pub fn proposal_for(
    outcome: &explain::Outcome,
    data: &Dataset,
    rig: &RigFile,
    options: &explain::design::DesignOptions,
) -> explain::design::Proposal {
    let space = explain::design::Space::for_rig(rig, data);
    explain::design::propose(outcome, &space, options)
}

/// Writes `proposal` as a plan file (atomically).
pub fn write_plan(
    path: &Path,
    proposal: &explain::design::Proposal,
    source: &str,
) -> Result<(), RigError> {
    let text = proposal.to_plan_toml(&format!("proposed by rig explain for {source}"), 1);
    reporting::write_atomic(path, text.as_bytes())?;
    Ok(())
}

/// The hidden effect of `--synthetic`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hidden(pub Option<Effect>);

fn parse_hidden(s: &str) -> Result<Hidden, String> {
    if s == "none" {
        return Ok(Hidden(None));
    }
    Effect::from_name(s)
        .map(|e| Hidden(Some(e)))
        .ok_or_else(|| {
            format!(
                "unknown effect '{s}': give none or one of {}",
                Effect::ALL.map(|e| e.name()).join(", ")
            )
        })
}

fn parse_alpha(s: &str) -> Result<f64, String> {
    let v = crate::args::finite(s)?;
    if v > 0.0 && v < 0.5 {
        Ok(v)
    } else {
        Err(format!(
            "{v}: the guard level must lie in (0, 0.5), e.g. 0.01"
        ))
    }
}

/// The default report folder for measured data `path`: `<stem>-explain` beside it.
pub fn default_report_dir(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "measured".into());
    path.with_file_name(format!("{stem}-explain"))
}

/// A synthetic sweep of `rig` with `hidden`, its data set and truth.
pub fn synthetic_data(
    rig: &RigFile,
    hidden: Option<Effect>,
    seed: u64,
    noise_a: f64,
) -> Result<(Dataset, SyntheticTruth), RigError> {
    synthetic_sweep(rig, hidden, seed, noise_a, 5)
}

/// [`synthetic_data`] with `repeats` repeats of the sweep's test points (tests of 0.5-1.5 s
/// beyond the paper's five repeats, so a long sweep stays within a working day).
pub fn synthetic_sweep(
    rig: &RigFile,
    hidden: Option<Effect>,
    seed: u64,
    noise_a: f64,
    repeats: usize,
) -> Result<(Dataset, SyntheticTruth), RigError> {
    let mut truth = rig.current_model()?;
    truth.effects = EffectParams::default();
    let plan = SweepPlan {
        noise_a,
        repeats,
        test_seconds: if repeats > 5 {
            (0.5, 1.5)
        } else {
            (15.0, 25.0)
        },
        ..SweepPlan::default()
    };
    let mut rng = NoiseSource::new(seed ^ 0x9e37_79b9_7f4a_7c15);
    if let Some(e) = hidden {
        truth.effects = synth::plausible_effect(e, &truth, &plan, &mut rng);
    }
    let rows = synth::generate(&truth, &plan, seed);
    let data = Dataset::from_rows("synthetic", rows)?;
    let params = hidden
        .map(|e| {
            library::report_params(
                e,
                &truth.effects,
                library::ThermalDriver::Temperature {
                    reference_c: plan.ambient_c,
                },
            )
        })
        .unwrap_or_default();
    Ok((
        data,
        SyntheticTruth {
            effect: hidden.map(|e| e.name().to_string()),
            params,
            seed,
            noise_a,
        },
    ))
}

/// Runs `rig explain`.
pub fn run(args: ExplainArgs) -> Result<ExitCode, RigError> {
    // An output over an input would destroy the measurement: refused before anything runs.
    crate::output_paths::refuse_outputs_over_inputs(
        &[
            ("--measured", args.measured.as_deref()),
            ("--model", args.model.as_deref()),
        ],
        &[
            ("--write-model", args.write_model.as_deref()),
            ("--propose", args.propose.as_deref()),
            ("--write-synthetic", args.write_synthetic.as_deref()),
        ],
    )?;
    let mut rig = match &args.model {
        Some(p) => RigFile::load(p)?,
        None => RigFile::paper(),
    };
    let (data, truth, source, default_dir) = match (&args.measured, args.synthetic) {
        (Some(path), _) => {
            let data = Dataset::read_csv(path)?;
            if let Some(regenerative) = crate::experiment::sweep::read_drive(path) {
                rig = rig.with_drive_decay(regenerative);
            }
            (
                data,
                None,
                path.display().to_string(),
                Some(default_report_dir(path)),
            )
        }
        (None, Some(Hidden(hidden))) => {
            let (data, truth) = synthetic_sweep(
                &rig,
                hidden,
                args.seed,
                args.noise_ma * 1e-3,
                args.repeats as usize,
            )?;
            if let Some(p) = &args.write_synthetic {
                reporting::write_atomic_with(p, |tmp| -> Result<(), RigError> {
                    let file = std::fs::File::create(tmp).map_err(|source| RigError::File {
                        action: "write",
                        path: p.display().to_string(),
                        source,
                    })?;
                    data.write_csv(file)?;
                    Ok(())
                })?;
            }
            let name = format!(
                "synthetic sweep ({}, seed {})",
                hidden.map_or("no effect", |e| e.name()),
                args.seed
            );
            (data, Some(truth), name, None)
        }
        (None, None) => {
            return Err(RigError::BadValue {
                what: "rig explain".into(),
                why: "give --measured FILE.csv (or --synthetic EFFECT)".into(),
            });
        }
    };
    let options = Options {
        alpha: args.alpha,
        folds: args.folds as usize,
        replicates: args.replicates as usize,
        stated_noise_a: args
            .stated_noise_ma
            .or(args.synthetic.map(|_| args.noise_ma))
            .filter(|v| *v > 0.0)
            .map(|v| v * 1e-3),
        ..Options::default()
    };
    let mut outcome = explain::explain(&data, &rig, &options)?;
    if args.json {
        // The text output lists them itself.
        for w in &outcome.explanation.warnings {
            eprintln!("warning: {w}");
        }
    }
    outcome.explanation.synthetic = truth;
    // The model file is written last, when everything else worked: a failed run leaves an
    // existing FILE as it was. Named in the report before it exists.
    let model_file = args
        .write_model
        .as_ref()
        .map(|p| (p, outcome.augmented_rig()));
    if let Some((p, _)) = &model_file {
        outcome.explanation.model_written = Some(p.display().to_string());
    }
    let dir = if args.no_report {
        None
    } else {
        args.report.clone().or(default_dir)
    };
    if let Some(d) = &dir {
        outcome.explanation.report_dir = Some(d.display().to_string());
        if let Err(e) = report_files::write_report(d, &outcome, &source) {
            if args.report.is_some() {
                return Err(e.into());
            }
            // The default folder is a convenience: the analysis still prints.
            eprintln!("warning: no report written ({e}); choose a folder with --report DIR");
            outcome.explanation.report_dir = None;
        }
    }
    if let Some((p, rig)) = &model_file {
        rig.save_with_comment(
            p,
            &format!("Written by `rig explain --write-model` from {source}."),
        )?;
    }
    // A proposal on request, and offered when the data cannot separate the leaders or a
    // discrepancy remains that no named effect explains (points that resolve its shape).
    let offered = matches!(
        outcome.explanation.verdict,
        explain::Verdict::Ambiguous | explain::Verdict::Unexplained
    );
    let proposal = (args.propose.is_some() || offered).then(|| {
        proposal_for(
            &outcome,
            &data,
            &rig,
            &explain::design::DesignOptions::default(),
        )
    });
    if let (Some(path), Some(p)) = (&args.propose, &proposal) {
        write_plan(path, p, &source)?;
    }
    let mut out = std::io::stdout().lock();
    if args.json {
        let mut value = serde_json::to_value(&outcome.explanation)?;
        if let (Some(p), Some(map)) = (&proposal, value.as_object_mut()) {
            let mut v = serde_json::to_value(p)?;
            if let Some(m) = v.as_object_mut() {
                m.insert(
                    "plan_written".into(),
                    args.propose
                        .as_ref()
                        .map(|p| p.display().to_string())
                        .into(),
                );
            }
            map.insert("proposal".into(), v);
        }
        serde_json::to_writer_pretty(&mut out, &value)?;
        writeln!(out)?;
    } else {
        write!(
            out,
            "{}",
            report_files::render_text(&outcome.explanation, &source)
        )?;
        if let Some(p) = &proposal {
            write!(
                out,
                "{}",
                proposal_text(p, args.propose.as_deref(), &source)
            )?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The proposal in words: where it was written, or how to get it.
fn proposal_text(p: &explain::design::Proposal, written: Option<&Path>, source: &str) -> String {
    let mut t = format!(
        "\nNext test points ({} points, {} test points): {}\n",
        p.points.len(),
        p.test_points(),
        p.reason
    );
    for q in &p.points {
        let drive = match (q.volts, q.hz) {
            (Some(v), _) => format!("{} V", reporting::human(v)),
            (_, Some(hz)) => format!("{} Hz", reporting::human(hz)),
            _ => String::new(),
        };
        t += &format!(
            "  {} N m at {drive} x {} ({:.1} noise sd per test)\n",
            reporting::human(q.load_nm),
            q.repeats,
            q.separation_sigma
        );
    }
    match written {
        Some(path) => {
            t += &format!(
                "Plan written to {}: run `rig experiment torque-sweep --plan {} --csv MORE.csv`, then explain {source} and MORE.csv together.\n",
                path.display(),
                path.display()
            );
        }
        None => {
            t += "Write them as a plan with `--propose FILE.toml` and run it with `rig experiment torque-sweep --plan FILE.toml`.\n";
        }
    }
    t
}
