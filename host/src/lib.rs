//! Library behind the `rig` command-line tool: the design calculator, and (in later
//! modules) the device client, the simulator and the reports.

pub mod args;
pub mod cli;
pub mod demo;
pub mod design;
pub mod error;

pub use error::RigError;
