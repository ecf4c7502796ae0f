//! The discrepancy workflow's error type: every message says what went wrong and what to do.

use thiserror::Error;

/// What can go wrong while explaining measured data.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ExplainError {
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
    /// A row of the measured data that cannot be used.
    #[error("{file} row {row} (line {line}): {why}")]
    MeasuredRow {
        /// The data file.
        file: String,
        /// Data row, 1-based (the header is not counted).
        row: usize,
        /// Line in the file, 1-based.
        line: u64,
        /// What is wrong and what the row needs.
        why: String,
    },
    /// A required column is missing from the measured data.
    #[error(
        "{file}: missing required column {column} (found: {found}); the header needs omega_n_rad_s, tau_rot_nm and i_in_a"
    )]
    MissingColumn {
        /// The data file.
        file: String,
        /// The missing column.
        column: String,
        /// The columns the header has.
        found: String,
    },
    /// Measured data without a single data row.
    #[error("{file} is empty: it needs a header and at least {min_rows} rows")]
    EmptyData {
        /// The data file.
        file: String,
        /// Rows the analysis needs.
        min_rows: usize,
    },
    /// Measured data with too few usable rows.
    #[error("{file} has only {rows} rows with a current: explain needs at least {min_rows}")]
    TooFewRows {
        /// The data file.
        file: String,
        /// Rows with a measured current.
        rows: usize,
        /// Rows the analysis needs.
        min_rows: usize,
    },
    /// Measured data that is not readable as CSV with a header.
    #[error("{file}: {why}")]
    MeasuredFile {
        /// The data file.
        file: String,
        /// What is wrong and what to do.
        why: String,
    },
    /// A rig (model) file that cannot be used.
    #[error("rig file {file}: {why}")]
    RigFile {
        /// The rig file.
        file: String,
        /// What is wrong and what to write instead.
        why: String,
    },
    /// A file or folder that cannot be read or written.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// What was tried ("read", "write", "create folder").
        action: &'static str,
        /// The path.
        path: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// JSON serialisation failed.
    #[error("cannot format JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// The rig file (given or written) cannot be used.
    #[error(transparent)]
    Rig(#[from] rigfile::RigFileError),
    /// A report file or plot that cannot be written.
    #[error(transparent)]
    Report(#[from] reporting::ReportError),
}
