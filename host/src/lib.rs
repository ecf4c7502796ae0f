//! Library behind the `rig` command-line tool: the design calculator, and (in later
//! modules) the device client, the simulator and the reports.

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
pub mod provenance;
pub mod scenario;
pub mod signals;
pub mod sweep_report;
pub mod synthetic;
pub mod virtual_device;

pub use error::RigError;
