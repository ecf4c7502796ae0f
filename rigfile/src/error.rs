//! The rig file's error type.

use thiserror::Error;

/// A rig file that cannot be read, used or written.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RigFileError {
    /// Gear parameters that do not make a 2K-H gear.
    #[error("invalid gear set {z:?}: {source}")]
    Gear {
        /// The tooth counts given.
        z: [u32; 4],
        /// Why they were rejected.
        source: model::GearError,
    },
    /// A value outside its meaningful range.
    #[error("{what}: {why}")]
    BadValue {
        /// Which value.
        what: String,
        /// What is wrong with it and what to give instead.
        why: String,
    },
    /// A rig file whose content cannot be used.
    #[error("rig file {file}: {why}")]
    RigFile {
        /// The rig file.
        file: String,
        /// What is wrong and what to write instead.
        why: String,
    },
    /// A file that cannot be read or written.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// What was tried ("read", "write").
        action: &'static str,
        /// The path.
        path: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// Writing the file failed (nothing was replaced).
    #[error(transparent)]
    Report(#[from] reporting::ReportError),
}
