//! `rig discover`: the closed discovery loop on a rig ([`crate::discover`] runs it; this
//! module picks the rig, parses and prints). Runs a short initial plan (the
//! quick sweep), explains the rows, runs the test points `rig explain --propose` would
//! propose ([`explain::design`]) through the same torque-sweep procedure as
//! `rig experiment`, and repeats until the verdict is settled or the budget of test points
//! (`--max-points`, a test point = one plan point x repeat) is spent. Every round's rows are
//! appended to one CSV (provenance first). Every run averages over whole cam revolutions
//! (`# window:` in the provenance), so the cam's torque ripple does not scatter the rows.
//! Ctrl-C or a lost link locks the gear (the procedure's path) and keeps the completed
//! rounds' rows.
//!
//! Settled: `explained` with a confidence of at least [`SETTLED_CONFIDENCE`] (or no
//! bootstrap), or with its leading effect selected in at least that share of the bootstrap
//! replicates (`inclusion_probability_raw`), or `no-missing-effect` with that confidence
//! once at least [`MIN_POINTS_FOR_NONE`] test points are in (a short sweep's silence is weak
//! evidence).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use super::connect::{DeviceOpts, interrupt_flag};
use crate::RigError;
use crate::discover::{Discovery, DiscoverySetup, Stopped, discover, starting_rig};
pub use crate::discover::{
    MIN_POINTS_FOR_NONE, ROUND_POINTS, Round, SETTLED_CONFIDENCE, VIRTUAL_FAULT_RETRIES, plan_of,
    unseen_effect_note,
};
use crate::experiment::InProcessBench;
use crate::experiment::bench::{Bench, DeviceBench, Operator};
use crate::experiment::sweep;
use crate::explanation::default_report_dir;
use explain::{Options, report_files};

/// The virtual rig's preset without --preset: the same as every other verb's (`rig sim`,
/// `rig sim serve`).
pub const DEFAULT_PRESET: &str = "paper";

/// Arguments of `rig discover`.
#[derive(Debug, Args)]
pub struct DiscoverArgs {
    /// The CSV to write, a new file (an existing one is refused unless --force): every
    /// round's rows are appended to it as they complete (`rig explain`'s columns, provenance
    /// first).
    #[arg(long, value_name = "FILE.csv")]
    pub csv: PathBuf,
    /// Replace an existing --csv (without it an existing file is refused and left
    /// unchanged).
    #[arg(long)]
    pub force: bool,
    /// Budget of test points (plan points x repeats; the paper's sweep has 150).
    #[arg(long, default_value_t = 60, value_parser = parse_max_points)]
    pub max_points: u32,
    /// Rig file (TOML) the explanations start from [default: the paper's rig].
    #[arg(long, visible_alias = "rig", value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Print one JSON object on stdout: `rig explain`'s keys plus `points_used` and `rounds`.
    #[arg(long)]
    pub json: bool,
    /// Report folder of the final explanation [default: NAME-explain beside the CSV].
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,
    /// Write no report folder.
    #[arg(long, conflicts_with = "report")]
    pub no_report: bool,
    /// The report's residual plots: printed size, and png or pdf beside the SVGs.
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
    /// Write the final augmented model (rig file with its fitted [model]) to FILE.
    #[arg(long, value_name = "FILE")]
    pub write_model: Option<PathBuf>,
    /// Replicates of each explanation's block bootstrap.
    #[arg(long, default_value_t = 200, value_parser = parse_replicates)]
    pub replicates: u32,
    /// With --sim: the virtual rig's plant (`paper`: with the paper's speed-dependent axial
    /// friction, as every other verb; `ideal`: the paper's equations only) [default: paper].
    #[arg(long, value_parser = clap::builder::PossibleValuesParser::new(sim::preset::PRESETS))]
    pub preset: Option<String>,
    /// With --sim: hide an effect in the plant, NAME[:k=v,...] as `rig sim serve --effect`.
    #[arg(long = "effect", value_name = "NAME[:k=v,...]")]
    pub effects: Vec<String>,
    /// Seed of the virtual rig's noise (--sim) and of the rounds' run orders.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// The bench of the options: the in-process virtual rig (virtual time) with --sim, else
/// the device (a real rig or a served virtual one), whose rests `stop` (a signal's flag)
/// ends.
fn bench_for(
    a: &DiscoverArgs,
    dev: &DeviceOpts,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> Result<Box<dyn Bench>, RigError> {
    if dev.sim {
        let preset = sim::Preset::by_name(a.preset.as_deref().unwrap_or(DEFAULT_PRESET))?;
        // The simulator's own rig (`rig sim torque-sweep`'s): backdrive is read from the
        // plant's output, as the in-process bench does.
        let mut config = sim::SimConfig::paper().virtual_board();
        preset.apply(&mut config.plant);
        for e in &a.effects {
            sim::EffectSpec::parse(e)?.apply(&mut config.plant)?;
        }
        config.seed = a.seed;
        return Ok(Box::new(InProcessBench::new(config)?));
    }
    if !a.effects.is_empty() || a.preset.is_some() {
        return Err(RigError::BadValue {
            what: "--effect / --preset".into(),
            why: "they configure the in-process virtual rig: add --sim, or give them to `rig sim serve`".into(),
        });
    }
    Ok(Box::new(DeviceBench::new(dev.connect()?).stopped_by(stop)))
}

// The library's ranges ([`DiscoverySetup::check_max_points`], `check_replicates`), which
// Python checks too.
fn parse_max_points(s: &str) -> Result<u32, String> {
    crate::args::checked(s, crate::args::whole, DiscoverySetup::check_max_points).map(|n| n as u32)
}

fn parse_replicates(s: &str) -> Result<u32, String> {
    crate::args::checked(s, crate::args::whole, DiscoverySetup::check_replicates).map(|n| n as u32)
}

/// Runs `rig discover`.
pub fn run(a: DiscoverArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    let rig = starting_rig(a.model.as_deref())?;
    // An existing CSV is refused before the rig moves, and never truncated.
    sweep::check_output(&a.csv, false, a.force)?;
    let stop = interrupt_flag();
    let mut operator = Operator::stdin(false, std::sync::Arc::clone(&stop));
    let mut bench = bench_for(&a, dev, stop)?;
    let setup = DiscoverySetup {
        csv: a.csv.clone(),
        force: a.force,
        max_points: a.max_points as usize,
        seed: a.seed,
        options: Options {
            replicates: a.replicates as usize,
            ..Options::default()
        },
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    let source = a.csv.display().to_string();
    let quiet = a.json;
    let say = |line: &str| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    let notes: Vec<String> = a
        .effects
        .iter()
        .filter_map(|e| unseen_effect_note(e))
        .collect();
    for n in &notes {
        eprintln!("note: {n}");
    }
    let mut found = match discover(bench.as_mut(), &mut operator, &rig, &setup, &say) {
        Ok(found) => found,
        Err(Stopped { error, rows_kept }) if operator.interrupted() => {
            eprintln!("{error}; {rows_kept} completed rows kept in {source}");
            return Ok(crate::signals::interrupt_exit_code());
        }
        Err(stopped) => return Err(stopped.error),
    };
    found.outcome.explanation.warnings.extend(notes);
    write_outputs(&a, &mut found.outcome, &source)?;
    print(&a, &found, &setup, &source)?;
    Ok(ExitCode::SUCCESS)
}

/// Writes the report folder and the augmented model (last), naming both in the explanation.
fn write_outputs(
    a: &DiscoverArgs,
    outcome: &mut explain::Outcome,
    source: &str,
) -> Result<(), RigError> {
    let model_file = a.write_model.as_ref().map(|p| (p, outcome.augmented_rig()));
    if let Some((p, _)) = &model_file {
        outcome.explanation.model_written = Some(p.display().to_string());
    }
    let dir = if a.no_report {
        None
    } else {
        a.report
            .clone()
            .or_else(|| Some(default_report_dir(&a.csv)))
    };
    if let Some(d) = &dir {
        outcome.explanation.report_dir = Some(d.display().to_string());
        report_files::write_report(d, outcome, source, a.figures.size())?;
        a.figures.export_all(&report_files::figures(d))?;
    }
    if let Some((p, r)) = &model_file {
        r.save_with_comment(
            p,
            &format!("Written by `rig discover --write-model` from {source}."),
        )?;
    }
    Ok(())
}

/// Prints the final explanation and the loop's summary, as JSON or text.
fn print(
    a: &DiscoverArgs,
    found: &Discovery,
    setup: &DiscoverySetup,
    source: &str,
) -> Result<(), RigError> {
    let mut out = std::io::stdout().lock();
    let explanation = &found.outcome.explanation;
    let (used, budget) = (found.points_used, a.max_points as usize);
    if a.json {
        serde_json::to_writer_pretty(&mut out, &found.json(setup))?;
        writeln!(out)?;
    } else {
        write!(out, "{}", report_files::render_text(explanation, source))?;
        writeln!(
            out,
            "\nrig discover: {} rounds, {used} of {budget} test points; {}",
            found.rounds.len(),
            if found.settled {
                "the verdict is settled"
            } else {
                "the budget ran out before the verdict settled (raise --max-points)"
            }
        )?;
    }
    Ok(())
}
