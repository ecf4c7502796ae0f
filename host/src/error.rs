//! The host's error type: every message says what went wrong and what to do next.

use thiserror::Error;

/// Everything that can go wrong in the `rig` tool.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RigError {
    /// Gear parameters that do not make a 2K-H gear.
    #[error("invalid gear set {z:?}: {source}")]
    Gear {
        /// The tooth counts given.
        z: [u32; 4],
        /// Why they were rejected.
        source: model::GearError,
    },
    /// A command-line or file value outside its meaningful range.
    #[error("{what}: {why}")]
    BadValue {
        /// Which value.
        what: String,
        /// What is wrong with it and what to give instead.
        why: String,
    },
    /// Writing the output failed.
    #[error("cannot write output: {0}")]
    Output(#[from] std::io::Error),
    /// JSON serialisation failed.
    #[error("cannot format JSON: {0}")]
    Json(#[from] serde_json::Error),
}
