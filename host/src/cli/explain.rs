//! The `rig explain` command line: arguments and the run behind them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use model::effects::Effect;

use crate::RigError;
use crate::explanation::{ExplainJson, ProposalJson};
pub use crate::explanation::{default_report_dir, proposal_for, write_plan};
pub use crate::synthetic::{synthetic_data, synthetic_sweep};
use explain::data::Dataset;
use explain::design::Proposal;
use explain::{Options, SyntheticTruth, report_files};
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
test points) gives each effect's inclusion_probability_raw and the top-level confidence_raw
(share of replicates reaching the same finding); ambiguous when a competitor is selected
instead of the leading effect in a fifth or more of them. For an explained verdict the
confidence, and for each named effect the inclusion_probability, is that share calibrated to a
probability of being right (with the driver check's margin and the lack of fit, on generated
batches with truths outside the library).

Lack of fit (JSON \"lack_of_fit\"): the final model's cell means (speed level x load level)
against the pure error of the data's repeats (an F-test), or, with drifting repeats, against
successive repeats; without repeats against --stated-noise-ma, else the ACS714's specification
(27 mA per sample); the model's own resolution (2.9 mA) is added to every cell mean. It says
which, and where the discrepancy lives (speed level, load range, time).

Verdicts: explained (named effects, what remains is within the noise), partly-explained (named
effects shrink the gap, a significant lack of fit remains), unexplained (a significant lack of
fit and no named effect explains it), ambiguous (also when a named effect does not beat a
generic shape in another variable: time, revolutions, temperature, speed, load or the current;
JSON \"driver_check\" per effect says which and the test that would separate them),
no-missing-effect (no effect needed and the lack of fit is not significant). Two effects that
reach physical values only together are named together (JSON \"only_together_with\").
Exit code 0 for any verdict, 1 on bad input.";

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
    /// The report's residual plots: printed size, and png or pdf beside the SVGs.
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
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
    #[arg(long, default_value_t = 200, value_parser = parse_replicates)]
    pub replicates: u32,
    /// Level of the false-discovery guard (probability that effect-free data gives a finding).
    #[arg(long, default_value_t = 0.002, value_parser = parse_alpha)]
    pub alpha: f64,
    /// Folds of the held-out validation over blocks of test points.
    #[arg(long, default_value_t = 5, value_parser = parse_folds)]
    pub folds: u8,
    /// Row noise of the current that you know (from repeats elsewhere or the logger), mA: the
    /// lack-of-fit test's reference when the data has too few repeats for a pure error
    /// [default for --synthetic: --noise-ma].
    #[arg(long, value_name = "MA", value_parser = parse_stated_noise_ma)]
    pub stated_noise_ma: Option<f64>,
    /// Write a test plan (docs/plans.md) with the points that best separate the leading
    /// candidates (or pin the finding) for `rig experiment torque-sweep --plan FILE`; JSON
    /// gains `proposal`.
    #[arg(long, value_name = "FILE.toml")]
    pub propose: Option<PathBuf>,
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

// The settings' ranges are the library's ([`explain::options`]), which Python checks too.
fn parse_alpha(s: &str) -> Result<f64, String> {
    crate::args::checked(s, crate::args::finite, Options::check_alpha)
}

fn parse_folds(s: &str) -> Result<u8, String> {
    let folds = crate::args::checked(s, crate::args::whole, Options::check_folds)?;
    // At most 20 folds (the check's range).
    Ok(folds as u8)
}

fn parse_replicates(s: &str) -> Result<u32, String> {
    crate::args::checked(s, crate::args::whole, Options::check_replicates).map(|r| r as u32)
}

/// The noise in mA as given (the options take it in A, [`options`]).
fn parse_stated_noise_ma(s: &str) -> Result<f64, String> {
    let ma = crate::args::finite(s)?;
    Options::check_stated_noise_ma(ma)
        .map(|_| ma)
        .map_err(|why| format!("{ma}: {why}"))
}

/// The data `rig explain` reads or makes: the data set, the synthetic truth, the source's
/// name and the default report folder.
struct Input {
    data: Dataset,
    truth: Option<SyntheticTruth>,
    source: String,
    default_dir: Option<PathBuf>,
    /// What the base model assumed about a drive the data do not state.
    drive_warning: Option<String>,
}

/// Reads `--measured` (its provenance's drive into `rig`) or makes the `--synthetic` sweep
/// (saved with `--write-synthetic`).
fn input(args: &ExplainArgs, rig: &mut RigFile) -> Result<Input, RigError> {
    match (&args.measured, args.synthetic) {
        (Some(path), _) => {
            let data = Dataset::read_csv(path)?;
            if let Some(regenerative) = crate::provenance::Header::read(path).regenerative {
                let measured = rigfile::DecayMode::from_returns_power(regenerative);
                match &args.model {
                    // Never mixed: data of one drive against a rig file of the other.
                    Some(model) if rig.drive.decay != measured => {
                        return Err(RigError::BadValue {
                            what: "--measured".into(),
                            why: format!(
                                "{} was measured on a {} drive (its `# drive:` line) but {} says [drive] decay = \"{}\": the base model's inertia term differs (kappa {} vs {}); set [drive] decay = \"{}\" in the rig file if the data's drive is the rig's, or measure again on the rig's drive",
                                path.display(),
                                measured.name(),
                                model.display(),
                                rig.drive.decay.name(),
                                model::effects::drive_kappa(regenerative),
                                model::effects::drive_kappa(rig.drive.decay.returns_power()),
                                measured.name(),
                            ),
                        });
                    }
                    _ => rig.drive.decay = measured,
                }
            }
            // The stated drive (checked above) or, without a line, the rig's own drive, said.
            let (with_drive, warning) = crate::provenance::with_stated_drive(rig.clone(), path);
            *rig = with_drive;
            Ok(Input {
                data,
                truth: None,
                source: path.display().to_string(),
                default_dir: Some(default_report_dir(path)),
                drive_warning: warning,
            })
        }
        (None, Some(Hidden(hidden))) => {
            let (data, truth) = synthetic_sweep(
                rig,
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
            let source = format!(
                "synthetic sweep ({}, seed {})",
                hidden.map_or("no effect", |e| e.name()),
                args.seed
            );
            Ok(Input {
                data,
                truth: Some(truth),
                source,
                default_dir: None,
                drive_warning: None,
            })
        }
        (None, None) => Err(RigError::BadValue {
            what: "rig explain".into(),
            why: "give --measured FILE.csv (or --synthetic EFFECT)".into(),
        }),
    }
}

/// The explanation's options from the arguments.
fn options(args: &ExplainArgs) -> Options {
    Options {
        alpha: args.alpha,
        folds: args.folds as usize,
        replicates: args.replicates as usize,
        stated_noise_a: args
            .stated_noise_ma
            .or(args.synthetic.map(|_| args.noise_ma))
            .filter(|v| *v > 0.0)
            .map(|v| v * 1e-3),
        ..Options::default()
    }
}

/// Writes the report folder (`--report`, else the default one, where a failure only
/// warns) and names it in the explanation.
fn write_report(
    args: &ExplainArgs,
    outcome: &mut explain::Outcome,
    input: &Input,
) -> Result<(), RigError> {
    let dir = if args.no_report {
        None
    } else {
        args.report.clone().or_else(|| input.default_dir.clone())
    };
    if let Some(d) = &dir {
        outcome.explanation.report_dir = Some(d.display().to_string());
        let written = report_files::write_report(d, outcome, &input.source, args.figures.size())
            .map_err(RigError::from)
            .and_then(|()| args.figures.export_all(&report_files::figures(d)));
        if let Err(e) = written {
            if args.report.is_some() {
                return Err(e);
            }
            // The default folder is a convenience: the analysis still prints.
            eprintln!("warning: no report written ({e}); choose a folder with --report DIR");
            outcome.explanation.report_dir = None;
        }
    }
    Ok(())
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
    let input = input(&args, &mut rig)?;
    let mut outcome = explain::explain(&input.data, &rig, &options(&args))?;
    outcome
        .explanation
        .warnings
        .extend(input.drive_warning.clone());
    if args.json {
        // The text output lists them itself.
        for w in &outcome.explanation.warnings {
            eprintln!("warning: {w}");
        }
    }
    outcome.explanation.synthetic = input.truth.clone();
    // The model file is written last, when everything else worked: a failed run leaves an
    // existing FILE as it was. Named in the report before it exists.
    let model_file = args
        .write_model
        .as_ref()
        .map(|p| (p, outcome.augmented_rig()));
    if let Some((p, _)) = &model_file {
        outcome.explanation.model_written = Some(p.display().to_string());
    }
    write_report(&args, &mut outcome, &input)?;
    let source = &input.source;
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
        let design = explain::design::DesignOptions::default();
        proposal_for(&outcome, &input.data, &rig, &design)
    });
    if let (Some(path), Some(p)) = (&args.propose, &proposal) {
        write_plan(path, p, source)?;
    }
    print(&args, &outcome.explanation, proposal.as_ref(), source)?;
    Ok(ExitCode::SUCCESS)
}

/// Prints the explanation (and the proposal) as JSON or text.
fn print(
    args: &ExplainArgs,
    explanation: &explain::Explanation,
    proposal: Option<&Proposal>,
    source: &str,
) -> Result<(), RigError> {
    let mut out = std::io::stdout().lock();
    if args.json {
        let json = ExplainJson {
            explanation,
            proposal: proposal.map(|proposal| ProposalJson {
                proposal,
                plan_written: args.propose.as_ref().map(|p| p.display().to_string()),
            }),
        };
        serde_json::to_writer_pretty(&mut out, &json)?;
        writeln!(out)?;
    } else {
        write!(out, "{}", report_files::render_text(explanation, source))?;
        if let Some(p) = proposal {
            write!(out, "{}", proposal_text(p, args.propose.as_deref(), source))?;
        }
    }
    Ok(())
}

/// The proposal in words: where it was written, or how to get it.
fn proposal_text(p: &Proposal, written: Option<&Path>, source: &str) -> String {
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
                "Plan written to {}: run `rig experiment torque-sweep --plan {} --csv MORE.csv`, then explain the old and new rows in one file (`--measured` reads one): `(cat {source}; tail -n +2 MORE.csv) > ALL.csv && rig explain --measured ALL.csv`.\n",
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
