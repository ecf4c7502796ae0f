//! The `rig` command line: one module per verb, each with its clap arguments and a `run`
//! function that returns the process exit code or a [`crate::RigError`].

use clap::{Parser, Subcommand};

pub mod demo;
pub mod design;

/// Tools for the vibration-switched 2K-H planetary gear rig.
#[derive(Debug, Parser)]
#[command(name = "rig", version, about, long_about = None)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub command: Command,
}

/// The verbs.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Design calculator: ratio, contact ratios, Lambda, hold verdict and required cam torque.
    Design(design::DesignArgs),
    /// The main job: runs the design check on the paper's Table 1 and summarises it.
    Demo(demo::DemoArgs),
}

impl Cli {
    /// Runs the chosen verb.
    pub fn run(self) -> Result<std::process::ExitCode, crate::RigError> {
        match self.command {
            Command::Design(a) => design::run(a),
            Command::Demo(a) => demo::run(a),
        }
    }
}
