//! `rig`: command-line tool for the vibration-switched planetary gear rig.

use std::process::ExitCode;

use clap::Parser;
use host::cli::Cli;

fn main() -> ExitCode {
    match Cli::parse().run() {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
