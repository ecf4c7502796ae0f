//! The closed discovery loop behind `rig discover`: runs a short initial plan (the quick
//! sweep), explains the rows, runs the test points `rig explain --propose` would propose
//! ([`explain::design`]) through the same torque-sweep procedure as `rig experiment`, and
//! repeats until the verdict is settled or the budget of test points (a test point = one
//! plan point x repeat) is spent. Every round's rows are appended to one CSV (provenance
//! first). Every run averages over whole cam revolutions (`# window:` in the provenance),
//! so the cam's torque ripple does not scatter the rows. An interruption or a lost link
//! locks the gear (the procedure's path) and keeps the completed rounds' rows.
//!
//! Settled: `explained` with a confidence of at least [`SETTLED_CONFIDENCE`] (or no
//! bootstrap), or with its leading effect selected in at least that share of the bootstrap
//! replicates (`inclusion_probability_raw`), or
//! `no-missing-effect` with that confidence once at least [`MIN_POINTS_FOR_NONE`] test
//! points are in (a short sweep's silence is weak evidence).

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::RigError;
use crate::experiment::bench::{Bench, Operator};
use crate::experiment::plan::Plan;
use crate::experiment::sweep::{self, Row, SweepSetup, Window};
use explain::design::{DesignOptions, Proposal};
use explain::{Dataset, Options, Verdict};
use rigfile::RigFile;

/// Confidence at which a verdict is settled.
pub const SETTLED_CONFIDENCE: f64 = 0.8;
/// Test points before `no-missing-effect` settles the loop.
pub const MIN_POINTS_FOR_NONE: usize = 36;
/// Test points a round proposes at most.
pub const ROUND_POINTS: usize = 12;

/// Why a hidden effect cannot show in the rows `rig discover` logs, if it cannot
/// ([`sim::EffectSpec::unseen_through_firmware`]; a spec that does not parse: `None`, its
/// error comes when it is applied).
pub fn unseen_effect_note(spec: &str) -> Option<String> {
    sim::EffectSpec::parse(spec).ok()?.unseen_through_firmware()
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

/// The plan of a proposal ([`Proposal::to_plan`]), named for `rig discover`.
pub fn plan_of(p: &Proposal, seed: u64) -> Plan {
    p.to_plan(&format!("rig discover: {}", p.reason), seed)
}

/// Appends `rows` to `path` (creating it with `head` first: an existing file only with
/// `force`), synced.
pub fn append(path: &Path, head: Option<&str>, rows: &[Row], force: bool) -> Result<(), RigError> {
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
    let body = sweep::csv_text(rows, head.is_some())?;
    if let Some(h) = head {
        file.write_all(h.as_bytes()).map_err(fail)?;
    }
    file.write_all(body.as_bytes()).map_err(fail)?;
    file.sync_data().map_err(fail)
}

/// Faults a virtual rig's round recovers from (clear, resume) before giving up.
pub const VIRTUAL_FAULT_RETRIES: usize = 3;

/// Runs one round's plan through the sweep procedure into a sidecar CSV (so every completed
/// row survives an error) and returns its rows (with the error, the rows it completed). On a virtual rig a latched fault (a load
/// running away at release, say) is cleared and the round resumed, at most
/// [`VIRTUAL_FAULT_RETRIES`] times; on a real rig it ends the loop (the gear is locked;
/// the operator looks at the rig).
pub fn run_round(
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

/// Whether the verdict `e` on `used` test points is settled (the module's rule).
pub fn settled(e: &explain::Explanation, used: usize) -> bool {
    let sure = e.confidence.is_none_or(|c| c >= SETTLED_CONFIDENCE);
    match e.verdict {
        // The leading finding is what the loop looks for: settled when it is selected in
        // enough of the resamples (its bootstrap share, not its calibrated probability:
        // more points do not make a law more likely to be the truth once the selection is
        // stable), whatever the smaller effects beside it.
        Verdict::Explained => {
            sure || e
                .effects
                .first()
                .and_then(|f| f.inclusion_probability_raw)
                .is_some_and(|p| p >= SETTLED_CONFIDENCE)
        }
        Verdict::NoMissingEffect => sure && used >= MIN_POINTS_FOR_NONE,
        // A discrepancy remains: the loop spends its budget resolving its shape.
        Verdict::Ambiguous | Verdict::Unexplained | Verdict::PartlyExplained => false,
    }
}

/// The leading effect of `e`: the first named, or the first ambiguous candidate.
pub fn leading(e: &explain::Explanation) -> Option<String> {
    match e.verdict {
        Verdict::Ambiguous => e.ambiguous.first().cloned(),
        _ => e.effects.first().map(|f| f.name.clone()),
    }
}

/// What a discovery runs with.
#[derive(Debug, Clone)]
pub struct DiscoverySetup {
    /// The CSV every round's rows are appended to (a new file; an existing one only with
    /// `force`).
    pub csv: PathBuf,
    /// Replace an existing `csv`.
    pub force: bool,
    /// Budget of test points.
    pub max_points: usize,
    /// Seed of the rounds' run orders.
    pub seed: u64,
    /// The explanations' options.
    pub options: Options,
    /// The command line, for the CSV's provenance.
    pub command: String,
}

// One check per setting a user gives, which the CLI's value parsers and Python's
// `Rig.discover` both call; the reason says what to give, the caller names the setting.
impl DiscoverySetup {
    /// The budget of test points, 12 to 10,000.
    pub fn check_max_points(points: u32) -> Result<usize, String> {
        if (12..=10_000).contains(&points) {
            Ok(points as usize)
        } else {
            Err("give 12 to 10000 test points".into())
        }
    }

    /// Each explanation's bootstrap replicates, 20 to 10,000 (a round settles on the
    /// bootstrap's confidence).
    pub fn check_replicates(replicates: u32) -> Result<usize, String> {
        if (20..=10_000).contains(&replicates) {
            Ok(replicates as usize)
        } else {
            Err("give 20 to 10000 bootstrap replicates".into())
        }
    }
}

/// What a finished discovery found.
#[derive(Debug)]
pub struct Discovery {
    /// The last explanation (of every row).
    pub outcome: explain::Outcome,
    /// Every row, as explained.
    pub data: Dataset,
    /// The rounds run.
    pub rounds: Vec<Round>,
    /// Test points run.
    pub points_used: usize,
    /// Whether the verdict settled ([`settled`]) before the budget ran out.
    pub settled: bool,
}

/// A discovery that ended early: why, and how many completed rows the CSV keeps.
#[derive(Debug)]
pub struct Stopped {
    /// Why.
    pub error: RigError,
    /// Rows written to the CSV before it stopped.
    pub rows_kept: usize,
}

impl From<RigError> for Stopped {
    fn from(error: RigError) -> Self {
        Self {
            error,
            rows_kept: 0,
        }
    }
}

/// Runs the discovery loop on `bench` from the rig file `rig` (whose drive decay the rows'
/// provenance states), appending every round's rows to `setup.csv`; `say` reports
/// progress in lines.
pub fn discover(
    bench: &mut dyn Bench,
    operator: &mut Operator,
    rig: &RigFile,
    setup: &DiscoverySetup,
    say: &dyn Fn(&str),
) -> Result<Discovery, Stopped> {
    let source = setup.csv.display().to_string();
    let mut plan = Plan::quick();
    plan.name =
        "rig discover: initial quick sweep (5 loads x 3 supply voltages x 2 repeats)".into();
    plan.seed = setup.seed;
    let mut kind = "initial".to_string();
    let mut all: Vec<Row> = Vec::new();
    let mut rounds: Vec<Round> = Vec::new();
    let mut outcome = None;
    let result: Result<(), RigError> = (|| {
        loop {
            let sweep_setup = SweepSetup {
                plan: plan.clone(),
                // Whole cam revolutions: the paper's fixed 0.5 s window ends at a random
                // phase of the cam's torque ripple (2.5 turns at 3.6 V), a scatter of up to
                // 5 mA at heavy load and low speed that `rig explain` reads as
                // mesh-load-sharing-ripple once proposals repeat points there.
                window: Window::Revolutions,
                resume: false,
                force: false,
                command: setup.command.clone(),
            };
            let head = if all.is_empty() {
                Some(
                    sweep::provenance(bench, &sweep_setup)?
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
                match run_round(bench, operator, sweep_setup, &setup.csv, round, say) {
                    Ok(rows) => (rows, None),
                    Err((rows, e)) => (rows, Some(e)),
                };
            for r in &mut rows {
                r.point = r.point.map(|p| p + offset);
            }
            append(&setup.csv, head.as_deref(), &rows, setup.force)?;
            all.extend(rows);
            if let Some(e) = failed {
                return Err(e);
            }
            let data = Dataset::from_rows(&source, all.clone())?;
            let o = explain::explain(&data, rig, &setup.options)?;
            let e = &o.explanation;
            let used = all.len();
            let r = Round {
                round,
                points: used - offset,
                points_used: used,
                plan: kind.clone(),
                verdict: e.verdict,
                leading_effect: leading(e),
                confidence: e.confidence,
            };
            say(&format!("  {}", r.summary()));
            rounds.push(r);
            let left = setup.max_points.saturating_sub(used);
            if settled(e, used) || left == 0 {
                outcome = Some((o, data));
                return Ok(());
            }
            let design = DesignOptions {
                max_test_points: left.min(ROUND_POINTS),
                ..DesignOptions::default()
            };
            let proposal = crate::explanation::proposal_for(&o, &data, rig, &design);
            outcome = Some((o, data));
            if proposal.points.is_empty() {
                say("  nothing left to propose within the rig's limits");
                return Ok(());
            }
            kind = format!("{:?}", proposal.goal).to_lowercase();
            plan = plan_of(&proposal, setup.seed + round as u64);
        }
    })();
    if let Err(error) = result {
        return Err(Stopped {
            error,
            rows_kept: all.len(),
        });
    }
    let Some((outcome, data)) = outcome else {
        return Err(RigError::BadValue {
            what: "rig discover".into(),
            why: "no round completed".into(),
        }
        .into());
    };
    let points_used = all.len();
    Ok(Discovery {
        settled: settled(&outcome.explanation, points_used),
        outcome,
        data,
        rounds,
        points_used,
    })
}

impl Round {
    /// The round's result in words: `30 test points: explained, NAME (confidence 0.93)`.
    pub fn summary(&self) -> String {
        format!(
            "{} test points: {}{}{}",
            self.points_used,
            self.verdict.as_str(),
            self.leading_effect
                .as_ref()
                .map(|l| format!(", {l}"))
                .unwrap_or_default(),
            self.confidence
                .map(|c| format!(" (confidence {c:.2})"))
                .unwrap_or_default()
        )
    }
}

/// What `rig discover --json` prints: `rig explain`'s keys plus the loop's.
#[derive(Debug, Clone, Serialize)]
pub struct DiscoverJson<'a> {
    /// The final explanation.
    #[serde(flatten)]
    pub explanation: &'a explain::Explanation,
    /// Test points run.
    pub points_used: usize,
    /// The budget of test points.
    pub max_points: usize,
    /// Whether the verdict settled.
    pub settled: bool,
    /// The CSV written.
    pub csv: String,
    /// Every round.
    pub rounds: &'a [Round],
}

impl Discovery {
    /// What `rig discover --json` prints for this discovery, with the budget and the CSV
    /// it was run with.
    pub fn json<'a>(&'a self, setup: &DiscoverySetup) -> DiscoverJson<'a> {
        DiscoverJson {
            explanation: &self.outcome.explanation,
            points_used: self.points_used,
            max_points: setup.max_points,
            settled: self.settled,
            csv: setup.csv.display().to_string(),
            rounds: &self.rounds,
        }
    }
}

/// The rig file a discovery's explanations start from: `model` or the paper's rig, with
/// this project's firmware's drive decay (the rows come from it, real or virtual, as the
/// CSV's provenance says).
pub fn starting_rig(model: Option<&Path>) -> Result<RigFile, RigError> {
    let rig = match model {
        Some(p) => RigFile::load(p)?,
        None => RigFile::paper(),
    };
    // The rig file's drive (`[drive] decay`, the board's braking drive by default).
    let returned = rig.drive.decay.returns_power();
    Ok(rig.with_drive_decay(returned))
}
