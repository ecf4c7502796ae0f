//! Library behind the `rig` command-line tool. The verbs in [`cli`] only parse arguments
//! and print; what they do lives here, typed, for the CLI and the Python door alike:
//!
//! - the device: [`client`] (the sans-IO session over a serial port), [`connection`]
//!   (which device a verb talks to), [`virtual_device`] (`--sim`: the firmware core and
//!   the plant on a pseudo-terminal), [`ports`], [`flash`];
//! - procedures on a rig: [`experiment`] (the paper's experiments, through one
//!   [`experiment::Bench`]), [`calibrate`], [`bringup`], [`conformance`], [`demo`];
//! - the discrepancy workflow on the host: [`explanation`] (proposals, report folder,
//!   `rig explain`'s JSON), [`synthetic`] (known-answer sweeps), [`discover`] (the closed
//!   loop), [`compare`] (the replayed gap);
//! - files and views: [`provenance`] (the measured CSV's header), [`monitor`] (staleness
//!   and the log's row schema), [`sweep_report`], [`design`], [`limits`].

pub mod args;
pub mod bringup;
pub mod calibrate;
pub mod cli;
pub mod client;
pub mod compare;
pub mod conformance;
pub mod connection;
pub mod demo;
pub mod design;
pub mod discover;
pub mod error;
pub mod experiment;
pub mod explanation;
pub mod flash;
pub mod limits;
pub mod monitor;
pub mod output_paths;
pub mod ports;
pub mod progress;
pub mod provenance;
pub mod recording;
pub mod row_log;
pub mod signals;
pub mod sweep_report;
pub mod synthetic;
pub mod virtual_device;

pub use error::RigError;

/// The device verbs' `--json` reports for library users (the Python binding
/// `backdrive_rig`): the command line's own definitions, re-exported.
pub mod reports {
    pub use crate::cli::clear::ClearReport;
    pub use crate::cli::faults::FaultsReport;
    pub use crate::cli::info::InfoReport;
}
