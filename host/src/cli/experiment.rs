//! `rig experiment <procedure>`: the paper's experiments on a rig (a real one with
//! `--port`, the virtual one with `--sim` or a served port): `torque-sweep` (Figs. 8-9),
//! `hold-release` (Fig. 5), `backdrive` (Table 1). On a real rig (or with `--operator`) the
//! operator is prompted on stderr and answers on stdin; Ctrl-C locks the gear.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use clap::{Args, Subcommand};

use super::connect::{DeviceOpts, interrupt_flag};
use crate::RigError;
use crate::experiment::bench::{Bench, DeviceBench, Operator};
use crate::experiment::sweep::{SweepSetup, Window};
use crate::experiment::{Plan, backdrive, hold_release, sweep};

/// Arguments of `rig experiment`.
#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// The procedure.
    #[command(subcommand)]
    pub procedure: Procedure,
    /// Prompt the operator (hang loads, judge the output) even on a virtual rig.
    #[arg(long, global = true)]
    pub operator: bool,
}

/// The procedures.
#[derive(Debug, Subcommand)]
pub enum Procedure {
    /// Figs. 8-9: loads x supply voltages (or frequencies), repeats, random order; writes
    /// `rig explain`'s CSV.
    TorqueSweep(SweepArgs),
    /// Fig. 5: the time history before, during and after a release, to CSV and SVG.
    HoldRelease(HoldArgs),
    /// Table 1: held or backdriven, without and with vibration.
    Backdrive(BackdriveArgs),
}

/// Arguments of `rig experiment torque-sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    /// `paper` (150 runs: Figs. 8-9), `quick` (30 runs) or a plan file (docs/plans.md).
    #[arg(long, default_value = "paper")]
    pub plan: String,
    /// The short plan (same as `--plan quick`).
    #[arg(long)]
    pub quick: bool,
    /// The CSV to write, a new file (an existing one only with --resume or --force); rows
    /// are appended as they complete.
    #[arg(long)]
    pub csv: PathBuf,
    /// Continue an interrupted run in the same CSV with the same plan.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
    /// Replace an existing CSV once the new sweep is complete: until then it is written to
    /// FILE.new and the old file stays whole (without it, or --resume, an existing file is
    /// refused and left unchanged).
    #[arg(long)]
    pub force: bool,
    /// Averaging window: `start` (the paper: window_s from constant rotation) or
    /// `revolutions` (at least window_s, whole cam revolutions).
    #[arg(long, value_enum, default_value_t = Window::Start)]
    pub window: Window,
    /// Also draw Figs. 8-9 (means and spread over repeats, cam speed) to this SVG.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// The --svg plot's printed size, and a png or pdf of it beside it (with --svg).
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `rig experiment hold-release`.
#[derive(Debug, Args)]
pub struct HoldArgs {
    /// The CSV to write (t_s, phase, state, output_angle_rad, cam_speed_rad_s, current_a).
    #[arg(long)]
    pub csv: PathBuf,
    /// The SVG plot to write (default: the CSV's name with .svg).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// The plot's printed size, and a png or pdf of it beside the SVG.
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
    /// Load, N m (Fig. 5: 1.0 kg on 75 mm).
    #[arg(long, default_value_t = model::paper::FIG5_LOAD.torque(), value_parser = hold_load)]
    pub load: f64,
    /// Hold without vibration, s (the paper: 14.5).
    #[arg(long, default_value_t = model::paper::FIG5_HOLD_S, value_parser = hold_s)]
    pub hold: f64,
    /// Vibration frequency, Hz.
    #[arg(long, default_value_t = 5.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// Vibration time, s.
    #[arg(long, default_value_t = 2.0, value_parser = release_s)]
    pub release: f64,
    /// Recorded after the vibration stops, s.
    #[arg(long, default_value_t = 1.5, value_parser = after_s)]
    pub after: f64,
    /// Replace an existing --csv (without it an existing file is refused, unchanged).
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `rig experiment backdrive`.
#[derive(Debug, Args)]
pub struct BackdriveArgs {
    /// Load, N m (Table 1: 3.68).
    #[arg(long, default_value_t = model::paper::TAU_ROT_MAX, value_parser = crate::args::non_negative)]
    pub load: f64,
    /// Hold without vibration, s.
    #[arg(long, default_value_t = 1.0, value_parser = crate::args::positive)]
    pub hold: f64,
    /// Vibration frequency, Hz.
    #[arg(long, default_value_t = 10.0, value_parser = crate::args::positive)]
    pub freq: f64,
    /// Vibration time, s.
    #[arg(long, default_value_t = 1.5, value_parser = crate::args::positive)]
    pub release: f64,
    /// Run Table 1's six gear sets: the operator fits each in turn (real rig).
    #[arg(long)]
    pub all_sets: bool,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

// Hold-release's settings, checked by the procedure's own checks (Python calls them too).
fn hold_load(s: &str) -> Result<f64, String> {
    crate::args::checked(
        s,
        crate::args::finite,
        hold_release::HoldRelease::check_load_nm,
    )
}

fn hold_s(s: &str) -> Result<f64, String> {
    crate::args::checked(
        s,
        crate::args::finite,
        hold_release::HoldRelease::check_hold_s,
    )
}

fn release_s(s: &str) -> Result<f64, String> {
    crate::args::checked(
        s,
        crate::args::finite,
        hold_release::HoldRelease::check_release_s,
    )
}

fn after_s(s: &str) -> Result<f64, String> {
    crate::args::checked(
        s,
        crate::args::finite,
        hold_release::HoldRelease::check_after_s,
    )
}

fn plan_of(a: &SweepArgs) -> Result<Plan, RigError> {
    if a.quick {
        return Ok(Plan::quick());
    }
    match a.plan.as_str() {
        "paper" => Ok(Plan::paper()),
        "quick" => Ok(Plan::quick()),
        file => Ok(Plan::read(std::path::Path::new(file))?),
    }
}

/// Runs `rig experiment`.
pub fn run(a: ExperimentArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let stop = interrupt_flag();
    let mut operator = Operator::stdin(a.operator, Arc::clone(&stop));
    // Check the arguments before the rig moves.
    let plan = match &a.procedure {
        Procedure::TorqueSweep(s) => {
            if s.svg.is_none()
                && let Some(option) = s.figures.given()
            {
                return Err(RigError::BadValue {
                    what: option.into(),
                    why: "it sets the --svg plot's figure: add --svg FILE.svg".into(),
                });
            }
            sweep::check_output(&s.csv, s.resume, s.force)?;
            Some(plan_of(s)?)
        }
        Procedure::HoldRelease(h) => {
            sweep::check_new_output(&h.csv, h.force)?;
            None
        }
        _ => None,
    };
    let mut bench = DeviceBench::new(dev.connect()?).stopped_by(stop);
    let mut out = std::io::stdout().lock();
    // Every error of the procedure, so Ctrl-C anywhere ends with exit 130.
    let result = match a.procedure {
        Procedure::TorqueSweep(s) => torque_sweep(s, plan, &mut bench, &mut operator, &mut out),
        Procedure::HoldRelease(h) => hold_release_run(h, &mut bench, &mut operator, &mut out),
        Procedure::Backdrive(b) => backdrive_run(b, &mut bench, &mut operator, &mut out),
    };
    match result {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(e) if operator.interrupted() => {
            eprintln!("{e}");
            Ok(crate::signals::interrupt_exit_code())
        }
        Err(e) => Err(e),
    }
}

/// Runs the torque sweep on `bench`.
fn torque_sweep(
    s: SweepArgs,
    plan: Option<Plan>,
    bench: &mut DeviceBench,
    operator: &mut Operator,
    out: &mut impl Write,
) -> Result<(), RigError> {
    let setup = SweepSetup {
        plan: plan.unwrap_or_else(Plan::quick),
        window: s.window,
        resume: s.resume,
        force: s.force,
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    let quiet = s.json;
    let r = sweep::run(bench, operator, &setup, &s.csv, &mut |line| {
        if !quiet {
            eprintln!("{line}");
        }
    });
    match r {
        Ok(o) => {
            if let Some(svg) = &s.svg {
                let (rows, _) = sweep::read_rows(&s.csv)?;
                let options = s.figures.options();
                crate::sweep_report::experiment_figure(svg, &rows, options.size)?;
                reporting::figure::export(svg, &options)?;
            }
            if s.json {
                super::print_json(out, &o)?;
            } else {
                writeln!(
                    out,
                    "torque sweep: {} of {} runs written to {} ({} resumed, {} skipped)",
                    o.written + o.resumed,
                    o.planned,
                    s.csv.display(),
                    o.resumed,
                    o.skipped
                )?;
            }
            Ok(())
        }
        Err(e) => {
            // `--force` wrote beside the old file, which stays as it was.
            let new = sweep::forced_path(&s.csv);
            let written = if s.force && new.exists() {
                &new
            } else {
                &s.csv
            };
            let kept = sweep::read_rows(written).map(|r| r.0.len()).unwrap_or(0);
            let old = if written == &new {
                format!("; {} was left as it was", s.csv.display())
            } else {
                String::new()
            };
            eprintln!(
                "stopped: {kept} completed rows kept in {}{old}; continue with `rig experiment torque-sweep --resume --csv {}` and the same plan",
                written.display(),
                written.display()
            );
            Err(e)
        }
    }
}

/// Runs the hold-release time history on `bench`.
fn hold_release_run(
    h: HoldArgs,
    bench: &mut DeviceBench,
    operator: &mut Operator,
    out: &mut impl Write,
) -> Result<(), RigError> {
    // The same ranges as `rig release` and Python's: nothing is silently changed.
    let calibration = bench.calibration()?;
    let opts = hold_release::HoldRelease {
        load_nm: Some(h.load),
        hold_s: h.hold,
        hz: h.freq,
        release_s: h.release,
        after_s: h.after,
    }
    .checked(hold_release::SettingNames::CLI, &calibration)?;
    let samples = hold_release::run(bench, operator, &opts, &mut |l| eprintln!("{l}"))?;
    hold_release::write_csv(&samples, &h.csv)?;
    let svg = h.svg.unwrap_or_else(|| h.csv.with_extension("svg"));
    if !samples.is_empty() {
        let options = h.figures.options();
        hold_release::write_svg(&samples, &svg, options.size)?;
        reporting::figure::export(&svg, &options)?;
    }
    writeln!(
        out,
        "hold-release: {} samples to {} and {}",
        samples.len(),
        h.csv.display(),
        svg.display()
    )?;
    if samples.iter().any(|s| s.output_angle_rad.is_some()) {
        // The verdict of Fig. 5: held? moved? how far?
        let n = hold_release::fig5_numbers(&samples, model::paper::R_OUT);
        writeln!(
            out,
            "verdict: {} during the {} s hold; {}; {} mm of rope paid out on the 75 mm pulley; {}",
            if n.held_without_vibration {
                "held"
            } else {
                "MOVED"
            },
            reporting::human(h.hold),
            match n.release_to_motion_s {
                Some(t) => format!("moved {t:.2} s after the release request"),
                None => "never moved while released".into(),
            },
            reporting::human(reporting::significant(n.load_drop_m * 1e3, 3)),
            if n.output_speed_after_stop_rad_s.abs() > 1e-3 {
                "still moving after the vibration stopped"
            } else {
                "at rest after the vibration stopped"
            }
        )?;
    }
    Ok(())
}

/// Runs the backdrive verdicts on `bench`.
fn backdrive_run(
    b: BackdriveArgs,
    bench: &mut DeviceBench,
    operator: &mut Operator,
    out: &mut impl Write,
) -> Result<(), RigError> {
    let opts = backdrive::Backdrive {
        load_nm: b.load,
        hold_s: b.hold,
        hz: b.freq,
        release_s: b.release,
    };
    let sets: Vec<Option<[u32; 4]>> = if b.all_sets {
        model::TABLE1.iter().copied().map(Some).collect()
    } else {
        vec![None]
    };
    if b.all_sets && !operator.forced && bench.is_virtual() {
        return Err(RigError::BadValue {
        what: "--all-sets".into(),
        why: "a virtual device has one gear set: `rig sim table1` runs all six, or add --operator".into(),
    });
    }
    let mut verdicts = Vec::new();
    for z in sets {
        if let Some(z) = z {
            let q = format!(
                "fit gear set (Z1, Z2, Z3, Z4) = ({})",
                z.map(|v| v.to_string()).join(", ")
            );
            if operator.before(&q)? == crate::experiment::bench::Go::Skip {
                continue;
            }
        }
        if let Some(v) = backdrive::run(bench, operator, &opts, z)? {
            verdicts.push(v);
        }
    }
    if b.json {
        super::print_json(out, &verdicts)?;
    } else {
        for v in &verdicts {
            let word = |m: bool| if m { "backdriven" } else { "held" };
            writeln!(
                out,
                "{}{} N m: without vibration {}, with vibration {} (judged by {})",
                v.z.map(|z| format!("{:?} ", z)).unwrap_or_default(),
                reporting::human(v.load_nm),
                word(v.backdriven_without_vibration),
                word(v.backdriven_with_vibration),
                v.judged_by
            )?;
        }
    }
    Ok(())
}
