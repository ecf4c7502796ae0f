//! The host's side of an explanation (`rig explain`, `rig discover`): the test points that
//! would settle it, the plan file they are written to, the default report folder, and the
//! JSON `rig explain --json` prints, from typed structs.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::RigError;
use explain::data::Dataset;
use explain::design::Proposal;
use rigfile::RigFile;

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

/// The default report folder for measured data `path`: `<stem>-explain` beside it.
pub fn default_report_dir(path: &Path) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "measured".into());
    path.with_file_name(format!("{stem}-explain"))
}

/// A proposal as `rig explain --json` prints it: the proposal's keys and where its plan
/// was written (`null`: not written).
#[derive(Debug, Clone, Serialize)]
pub struct ProposalJson<'a> {
    /// The proposal.
    #[serde(flatten)]
    pub proposal: &'a Proposal,
    /// The plan file written (`--propose`), if any.
    pub plan_written: Option<String>,
}

/// What `rig explain --json` prints: the explanation's keys and, when one was made, the
/// proposal of next test points.
#[derive(Debug, Clone, Serialize)]
pub struct ExplainJson<'a> {
    /// The explanation.
    #[serde(flatten)]
    pub explanation: &'a explain::Explanation,
    /// The next test points, when proposed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub proposal: Option<ProposalJson<'a>>,
}
