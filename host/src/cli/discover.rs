//! `rig discover`: the closed discovery loop on a rig. Runs a short initial plan (the
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
//! bootstrap), or with its leading effect's inclusion probability at least that, or `no-missing-effect` with that confidence once at least
//! [`MIN_POINTS_FOR_NONE`] test points are in (a short sweep's silence is weak evidence).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args;
use serde::Serialize;

use super::connect::{DeviceOpts, interrupt_flag};
use crate::RigError;
use crate::experiment::SimBench;
use crate::experiment::bench::{Bench, DeviceBench, Operator};
use crate::experiment::plan::{Mode, Order, Plan, PlanPoint};
use crate::experiment::sweep::{self, Row, SweepSetup, Window};
use explain::design::{DesignOptions, DriveMode, Proposal};
use explain::{Dataset, MeasuredRow, Options, Verdict, report_files};
use rigfile::RigFile;

/// Confidence at which a verdict is settled.
pub const SETTLED_CONFIDENCE: f64 = 0.8;
/// Test points before `no-missing-effect` settles the loop.
pub const MIN_POINTS_FOR_NONE: usize = 36;
/// Test points a round proposes at most.
pub const ROUND_POINTS: usize = 12;

/// The virtual rig's preset without --preset: the same as every other verb's (`rig sim`,
/// `rig sim serve`).
pub const DEFAULT_PRESET: &str = "paper";

/// Why a hidden effect cannot show in the rows `rig discover` logs, if it cannot.
pub fn unseen_effect_note(spec: &str) -> Option<String> {
    let name = spec.split(':').next().unwrap_or(spec).trim();
    (name == model::effects::Effect::CurrentSensorOffset.name()).then(|| {
        format!(
            "--effect {name}: the virtual rig adds the offset to the sensor's reading, but the firmware zeroes its current reading with the motor off (as on the board), so the offset cancels in the rows `rig discover` logs through the firmware; it cannot be found this way. A separate logger on the sensor (as the paper's) would see it: try `rig explain --synthetic {name}`"
        )
    })
}

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
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u32).range(12..=10_000))]
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
    /// Write the final augmented model (rig file with its fitted [model]) to FILE.
    #[arg(long, value_name = "FILE")]
    pub write_model: Option<PathBuf>,
    /// Replicates of each explanation's block bootstrap.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(20..=10_000))]
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

/// One round of the loop.
#[derive(Debug, Clone, Serialize)]
pub struct Round {
    /// 1-based.
    pub round: usize,
    /// Test points run in this round.
    pub points: usize,
    /// Test points run so far.
    pub points_used: usize,
    /// What this round ran: `initial` (the quick sweep), `separate`, `pin` or `seek`.
    pub plan: String,
    /// The verdict on every row so far.
    pub verdict: Verdict,
    /// The leading effect (the first named, or the first ambiguous candidate).
    pub leading_effect: Option<String>,
    /// The explanation's confidence.
    pub confidence: Option<f64>,
}

/// The bench of the options: the in-process virtual rig (virtual time) with --sim, else
/// the device (a real rig or a served virtual one).
fn bench_for(a: &DiscoverArgs, dev: &DeviceOpts) -> Result<Box<dyn Bench>, RigError> {
    if dev.sim {
        let preset = sim::Preset::by_name(a.preset.as_deref().unwrap_or(DEFAULT_PRESET))?;
        // The simulator's own rig (`rig sim torque-sweep`'s): backdrive is read from the
        // plant's output, as the in-process bench does.
        let mut config = sim::SimConfig::paper();
        config.core.board_name = "virtual";
        preset.apply(&mut config.plant);
        for e in &a.effects {
            sim::EffectSpec::parse(e)?.apply(&mut config.plant)?;
        }
        config.seed = a.seed;
        return Ok(Box::new(SimBench::new(config)?));
    }
    if !a.effects.is_empty() || a.preset.is_some() {
        return Err(RigError::BadValue {
            what: "--effect / --preset".into(),
            why: "they configure the in-process virtual rig: add --sim, or give them to `rig sim serve`".into(),
        });
    }
    Ok(Box::new(DeviceBench::new(dev.connect()?)))
}

/// The plan of a proposal.
pub fn plan_of(p: &Proposal, seed: u64) -> Plan {
    Plan {
        name: format!("rig discover: {}", p.reason),
        mode: match p.mode {
            DriveMode::OpenLoop => Mode::OpenLoop,
            DriveMode::ClosedLoop => Mode::ClosedLoop,
        },
        repeats: 1,
        order: Order::Random,
        seed,
        rest_s: 2.0,
        window_s: model::paper::CURRENT_AVERAGING_S,
        reason: p.reason.clone(),
        points: p
            .points
            .iter()
            .map(|q| PlanPoint {
                load_nm: q.load_nm,
                volts: q.volts,
                hz: q.hz,
                repeats: Some(q.repeats),
                duration_s: None,
                temp_c: None,
            })
            .collect(),
    }
}

fn measured(r: &Row) -> MeasuredRow {
    MeasuredRow {
        omega_n: r.omega_n_rad_s,
        tau_rot: r.tau_rot_nm,
        i_in: Some(r.i_in_a),
        t_s: Some(r.t_s),
        v_in: r.v_in_v,
        temp_c: r.temp_c,
        backdriven: r.backdriven.map(|b| b == 1),
    }
}

/// Appends `rows` to `path` (creating it with `head` first: an existing file only with
/// `force`), synced.
fn append(path: &Path, head: Option<&str>, rows: &[Row], force: bool) -> Result<(), RigError> {
    let fail = |source| RigError::File {
        action: "write",
        path: path.display().to_string(),
        source,
    };
    let mut file = if head.is_some() {
        sweep::create_new(path, force)?
    } else {
        std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(fail)?
    };
    let mut w = csv::WriterBuilder::new()
        .has_headers(head.is_some())
        .from_writer(Vec::new());
    for r in rows {
        w.serialize(r.for_people())
            .map_err(|e| RigError::BadValue {
                what: "a sweep row".into(),
                why: e.to_string(),
            })?;
    }
    let body = w.into_inner().map_err(|e| RigError::BadValue {
        what: "a sweep row".into(),
        why: e.to_string(),
    })?;
    if let Some(h) = head {
        file.write_all(h.as_bytes()).map_err(fail)?;
    }
    file.write_all(&body).map_err(fail)?;
    file.sync_data().map_err(fail)
}

/// Faults a virtual rig's round recovers from (clear, resume) before giving up.
pub const VIRTUAL_FAULT_RETRIES: usize = 3;

/// Runs one round's plan through the sweep procedure into a sidecar CSV (so every completed
/// row survives an error) and returns its rows (with the error, the rows it completed). On a virtual rig a latched fault (a load
/// running away at release, say) is cleared and the round resumed, at most
/// [`VIRTUAL_FAULT_RETRIES`] times; on a real rig it ends the loop (the gear is locked;
/// the operator looks at the rig).
fn run_round(
    bench: &mut dyn Bench,
    operator: &mut Operator,
    mut setup: SweepSetup,
    csv: &Path,
    round: usize,
    say: &dyn Fn(&str),
) -> Result<Vec<Row>, (Vec<Row>, RigError)> {
    let side = csv.with_extension(format!("round{round}.csv"));
    let _ = std::fs::remove_file(&side);
    let mut retries = 0;
    let result = loop {
        let r = sweep::run(bench, operator, &setup, &side, &mut |l| {
            say(&format!("  {l}"))
        });
        match r {
            Ok(_) => break Ok(()),
            Err(e)
                if bench.is_virtual()
                    && !operator.interrupted()
                    && retries < VIRTUAL_FAULT_RETRIES
                    && matches!(e, RigError::DeviceFault { .. } | RigError::Refused { .. }) =>
            {
                retries += 1;
                say(&format!(
                    "  {e}: the virtual rig's fault is cleared and the round resumed"
                ));
                // Let the output come to rest (the gear is locked) so the fault's cause is
                // gone, then clear.
                let cleared = bench
                    .wait(2.0)
                    .and_then(|()| bench.request(&protocol::Request::ClearFaults));
                if let Err(e) = cleared {
                    break Err(e);
                }
                setup.resume = true;
            }
            Err(e) => break Err(e),
        }
    };
    let rows = sweep::read_rows(&side).map(|r| r.0).unwrap_or_default();
    let _ = std::fs::remove_file(&side);
    match result {
        Ok(()) => Ok(rows),
        Err(e) => Err((rows, e)),
    }
}

fn settled(e: &explain::Explanation, used: usize) -> bool {
    let sure = e.confidence.is_none_or(|c| c >= SETTLED_CONFIDENCE);
    match e.verdict {
        // The leading finding is what the loop looks for: settled when it is selected in
        // enough of the resamples, whatever the smaller effects beside it.
        Verdict::Explained => {
            sure || e
                .effects
                .first()
                .and_then(|f| f.inclusion_probability)
                .is_some_and(|p| p >= SETTLED_CONFIDENCE)
        }
        Verdict::NoMissingEffect => sure && used >= MIN_POINTS_FOR_NONE,
        // A discrepancy remains: the loop spends its budget resolving its shape.
        Verdict::Ambiguous | Verdict::Unexplained | Verdict::PartlyExplained => false,
    }
}

fn leading(e: &explain::Explanation) -> Option<String> {
    match e.verdict {
        Verdict::Ambiguous => e.ambiguous.first().cloned(),
        _ => e.effects.first().map(|f| f.name.clone()),
    }
}

/// Runs `rig discover`.
pub fn run(a: DiscoverArgs, dev: &DeviceOpts) -> Result<ExitCode, RigError> {
    // The rows come from this project's firmware (real or virtual): its drive's decay mode
    // is known, as the CSV's provenance says (`rig explain` reads it from there).
    let rig = match &a.model {
        Some(p) => RigFile::load(p)?,
        None => RigFile::paper(),
    }
    .with_drive_decay(model::hardware::board::REGENERATIVE_DECAY);
    // An existing CSV is refused before the rig moves, and never truncated.
    sweep::check_output(&a.csv, false, a.force)?;
    let stop = interrupt_flag();
    let mut operator = Operator::stdin(false, stop);
    let mut bench = bench_for(&a, dev)?;
    let budget = a.max_points as usize;
    let options = Options {
        replicates: a.replicates as usize,
        ..Options::default()
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

    let mut plan = Plan::quick();
    plan.name =
        "rig discover: initial quick sweep (5 loads x 3 supply voltages x 2 repeats)".into();
    plan.seed = a.seed;
    let mut kind = "initial".to_string();
    let mut all: Vec<Row> = Vec::new();
    let mut rounds: Vec<Round> = Vec::new();
    let mut outcome = None;
    let result: Result<(), RigError> = (|| {
        loop {
            let setup = SweepSetup {
                plan: plan.clone(),
                // Whole cam revolutions: the paper's fixed 0.5 s window ends at a random
                // phase of the cam's torque ripple (2.5 turns at 3.6 V), a scatter of up to
                // 5 mA at heavy load and low speed that `rig explain` reads as
                // mesh-load-sharing-ripple once proposals repeat points there.
                window: Window::Revolutions,
                resume: false,
                force: false,
                command: std::env::args().collect::<Vec<_>>().join(" "),
            };
            let head = if all.is_empty() {
                Some(
                    sweep::provenance(bench.as_mut(), &setup)?
                        + "# rig discover: later rounds append the points `rig explain --propose` chose; `point` counts on across rounds\n",
                )
            } else {
                None
            };
            let round = rounds.len() + 1;
            say(&format!(
                "round {round}: {} test points ({kind})",
                plan.runs().len()
            ));
            let offset = all.len();
            let (mut rows, failed) =
                match run_round(bench.as_mut(), &mut operator, setup, &a.csv, round, &say) {
                    Ok(rows) => (rows, None),
                    Err((rows, e)) => (rows, Some(e)),
                };
            for r in &mut rows {
                r.point += offset;
            }
            append(&a.csv, head.as_deref(), &rows, a.force)?;
            all.extend(rows);
            if let Some(e) = failed {
                return Err(e);
            }
            let data = Dataset::from_rows(&source, all.iter().map(measured).collect())?;
            let o = explain::explain(&data, &rig, &options)?;
            let e = &o.explanation;
            let used = all.len();
            rounds.push(Round {
                round,
                points: used - offset,
                points_used: used,
                plan: kind.clone(),
                verdict: e.verdict,
                leading_effect: leading(e),
                confidence: e.confidence,
            });
            say(&format!(
                "  {} test points: {}{}{}",
                used,
                e.verdict.as_str(),
                leading(e).map(|l| format!(", {l}")).unwrap_or_default(),
                e.confidence
                    .map(|c| format!(" (confidence {c:.2})"))
                    .unwrap_or_default()
            ));
            let left = budget.saturating_sub(used);
            if settled(e, used) || left == 0 {
                outcome = Some((o, data));
                return Ok(());
            }
            let design = DesignOptions {
                max_test_points: left.min(ROUND_POINTS),
                ..DesignOptions::default()
            };
            let proposal = super::explain::proposal_for(&o, &data, &rig, &design);
            outcome = Some((o, data));
            if proposal.points.is_empty() {
                say("  nothing left to propose within the rig's limits");
                return Ok(());
            }
            kind = format!("{:?}", proposal.goal).to_lowercase();
            plan = plan_of(&proposal, a.seed + round as u64);
        }
    })();
    if let Err(e) = result {
        if operator.interrupted() {
            eprintln!("{e}; {} completed rows kept in {source}", all.len());
            return Ok(crate::signals::interrupt_exit_code());
        }
        return Err(e);
    }
    let Some((mut outcome, _data)) = outcome else {
        return Err(RigError::BadValue {
            what: "rig discover".into(),
            why: "no round completed".into(),
        });
    };
    let used = all.len();
    outcome.explanation.warnings.extend(notes);
    let model_file = a.write_model.as_ref().map(|p| (p, outcome.augmented_rig()));
    if let Some((p, _)) = &model_file {
        outcome.explanation.model_written = Some(p.display().to_string());
    }
    let dir = if a.no_report {
        None
    } else {
        a.report
            .clone()
            .or_else(|| Some(super::explain::default_report_dir(&a.csv)))
    };
    if let Some(d) = &dir {
        outcome.explanation.report_dir = Some(d.display().to_string());
        report_files::write_report(d, &outcome, &source)?;
    }
    if let Some((p, r)) = &model_file {
        r.save_with_comment(
            p,
            &format!("Written by `rig discover --write-model` from {source}."),
        )?;
    }
    let settled_now = settled(&outcome.explanation, used);
    let mut out = std::io::stdout().lock();
    if a.json {
        let mut value = serde_json::to_value(&outcome.explanation)?;
        if let Some(map) = value.as_object_mut() {
            map.insert("points_used".into(), used.into());
            map.insert("max_points".into(), budget.into());
            map.insert("settled".into(), settled_now.into());
            map.insert("csv".into(), source.clone().into());
            map.insert("rounds".into(), serde_json::to_value(&rounds)?);
        }
        serde_json::to_writer_pretty(&mut out, &value)?;
        writeln!(out)?;
    } else {
        write!(
            out,
            "{}",
            report_files::render_text(&outcome.explanation, &source)
        )?;
        writeln!(
            out,
            "\nrig discover: {} rounds, {used} of {budget} test points; {}",
            rounds.len(),
            if settled_now {
                "the verdict is settled"
            } else {
                "the budget ran out before the verdict settled (raise --max-points)"
            }
        )?;
    }
    Ok(ExitCode::SUCCESS)
}
