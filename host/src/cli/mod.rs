//! The `rig` command line: one module per verb, each with its clap arguments and a `run`
//! function that returns the process exit code or a [`crate::RigError`].
//!
//! Device options (`--port`, `--baud`, `--sim`, `--speed`, `--model`) go before the verb or
//! after a verb that uses a device; any other verb refuses them, naming the option.

use std::io::Write;

use clap::{Parser, Subcommand};
use serde::Serialize;

pub mod bringup;
pub mod calibrate;
pub mod calibration;
pub mod capture;
pub mod clear;
pub mod compare;
pub mod conformance;
pub mod connect;
pub mod demo;
pub mod design;
pub mod discover;
pub mod experiment;
pub mod explain;
pub mod faults;
pub mod figures;
pub mod flash;
pub mod info;
pub mod log;
pub mod monitor;
pub mod ports;
pub mod record;
pub mod release;
pub mod serve;
pub mod sim;

use connect::{DemoDeviceArgs, DeviceArgs, DiscoverDeviceArgs, VerbDeviceArgs};

/// Tools for the vibration-switched 2K-H planetary gear rig.
#[derive(Debug, Parser)]
#[command(name = "rig", version, about, long_about = None)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub command: Command,
    /// Which device the device verbs talk to (also accepted after a device verb).
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// The verbs. Those that use a device carry the device options given after their name.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Design calculator: ratio, contact ratios, Lambda, hold verdict and required cam torque.
    Design(design::DesignArgs),
    /// Simulated rig (firmware core + plant): fig5, table1, torque-sweep, faults, serve.
    Sim(sim::SimArgs),
    /// The main job: the whole simulated rig (design, calibration, fig5, table1, sweep, faults) with a report folder.
    Demo {
        /// The verb's arguments.
        #[command(flatten)]
        args: demo::DemoArgs,
        /// Device options after the verb (its own `--seed` seeds the simulated rig).
        #[command(flatten)]
        device: DemoDeviceArgs,
    },
    /// The paper's experiments on a rig: torque-sweep (Figs. 8-9), hold-release (Fig. 5), backdrive (Table 1).
    Experiment {
        /// The verb's arguments.
        #[command(flatten)]
        args: experiment::ExperimentArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Find where the current model and measured data disagree, name the missing effect, add it.
    Explain(explain::ExplainArgs),
    /// The closed loop on a rig: sweep, explain, run the proposed points, until the verdict settles.
    Discover {
        /// The verb's arguments.
        #[command(flatten)]
        args: discover::DiscoverArgs,
        /// Device options after the verb (its own `--model` is the starting rig file).
        #[command(flatten)]
        device: DiscoverDeviceArgs,
    },
    /// Replay a measured sweep on the virtual rig with the base and a fitted model: the gap before and after.
    Compare(compare::CompareArgs),
    /// List serial ports, marking ST-LINK virtual COM ports (Nucleo boards).
    Ports(ports::PortsArgs),
    /// Device identity: firmware and protocol versions, board, calibration source.
    Info {
        /// The verb's arguments.
        #[command(flatten)]
        args: info::InfoArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Active and latched faults of the device, with what each means.
    Faults {
        /// The verb's arguments.
        #[command(flatten)]
        args: faults::FaultsArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Check a device against the protocol's contract (LAYOUT.md): every check, pass or fail.
    Conformance {
        /// The verb's arguments.
        #[command(flatten)]
        args: conformance::ConformanceArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Clear the latched faults whose cause is gone.
    Clear {
        /// The verb's arguments.
        #[command(flatten)]
        args: clear::ClearArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Vibrate (on: the gear becomes backdrivable) while the command runs; Ctrl-C locks.
    Release {
        /// The verb's arguments.
        #[command(flatten)]
        args: release::ReleaseArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Guided first power-up: identity, faults, bus voltage, current zero, encoders,
    /// overcurrent trip, first release; pass/fail and what to check for each.
    Bringup {
        /// The verb's arguments.
        #[command(flatten)]
        args: bringup::BringupArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Live telemetry: charts of current, cam speed, tau_cam, load estimate and state.
    Monitor {
        /// The verb's arguments.
        #[command(flatten)]
        args: monitor::MonitorArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// A 10 kHz burst of raw current and encoder samples from the device's buffer, to CSV.
    Capture {
        /// The verb's arguments.
        #[command(flatten)]
        args: capture::CaptureArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// The continuous stream (every sample, up to 10 kHz) to a CSV or binary file, for --seconds or until Ctrl-C.
    Record {
        /// The verb's arguments.
        #[command(flatten)]
        args: record::RecordArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// The paper's vibrator calibration (C1-C6): measure, fit, plot, write the device.
    Calibrate {
        /// The verb's arguments.
        #[command(flatten)]
        args: calibrate::CalibrateArgs,
        /// Device options after the verb.
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Read (get) or write (set) the device's calibration as a TOML file.
    Calibration {
        /// The verb's arguments.
        #[command(flatten)]
        args: calibration::CalibrationArgs,
        /// Device options after the verb (or after `get` / `set`).
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// Check and flash the firmware through the debug probe (keeps the stored calibration).
    Flash {
        /// The verb's arguments.
        #[command(flatten)]
        args: flash::FlashArgs,
        /// Device options after the verb (the serial port of the rig to lock first).
        #[command(flatten)]
        device: VerbDeviceArgs,
    },
    /// The firmware's defmt log through the debug probe, or decoded from a saved stream.
    Log(log::LogArgs),
}

/// A verb that uses no device whose reader went away (`rig design --table1 | head`) ends
/// normally: its output was read as far as the reader wanted.
fn reader_gone_is_normal(
    result: Result<std::process::ExitCode, crate::RigError>,
) -> Result<std::process::ExitCode, crate::RigError> {
    match result {
        Err(crate::RigError::Output(e)) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            Ok(std::process::ExitCode::SUCCESS)
        }
        other => other,
    }
}

impl Cli {
    /// Runs the chosen verb.
    pub fn run(self) -> Result<std::process::ExitCode, crate::RigError> {
        let before = self.device;
        match self.command {
            Command::Design(a) => {
                before.refuse_for("design")?;
                reader_gone_is_normal(design::run(a))
            }
            Command::Sim(a) => {
                before.refuse_for("sim")?;
                reader_gone_is_normal(sim::run(a))
            }
            Command::Explain(a) => {
                before.refuse_for("explain")?;
                explain::run(a)
            }
            Command::Compare(a) => {
                before.refuse_for("compare")?;
                compare::run(a)
            }
            Command::Discover { args, device } => {
                if let Some(m) = &before.model {
                    return Err(crate::RigError::BadValue {
                        what: format!("--model {}", m.display()),
                        why: "`rig discover` takes --model after its name, as the rig file its explanations start from; its virtual rig (--sim) is set with --preset and --effect".into(),
                    });
                }
                before.refuse_seed_for("discover")?;
                discover::run(args, &before.resolve(&device.into())?)
            }
            Command::Ports(a) => {
                before.refuse_for("ports")?;
                ports::run(a)
            }
            Command::Demo { args, device } => {
                before.refuse_seed_for("demo")?;
                let mut given = before.given();
                given.extend(device.given());
                let device: VerbDeviceArgs = device.into();
                if given.contains(&"--model") {
                    return Err(crate::RigError::BadValue {
                        what: "--model".into(),
                        why: "`rig demo` runs the paper's rig: leave --model out (`rig sim fig5|table1|torque-sweep --model FILE` run a fitted model)".into(),
                    });
                }
                demo::run(args, &before.resolve(&device)?, &given)
            }
            Command::Experiment { args, device } => {
                experiment::run(args, &before.resolve(&device)?)
            }
            Command::Info { args, device } => info::run(args, &before.resolve(&device)?),
            Command::Faults { args, device } => faults::run(args, &before.resolve(&device)?),
            Command::Clear { args, device } => clear::run(args, &before.resolve(&device)?),
            Command::Conformance { args, device } => {
                conformance::run(args, &before.resolve(&device)?)
            }
            Command::Release { args, device } => release::run(args, &before.resolve(&device)?),
            Command::Bringup { args, device } => bringup::run(args, &before.resolve(&device)?),
            Command::Monitor { args, device } => monitor::run(args, &before.resolve(&device)?),
            Command::Capture { args, device } => capture::run(args, &before.resolve(&device)?),
            Command::Record { args, device } => record::run(args, &before.resolve(&device)?),
            Command::Calibrate { args, device } => calibrate::run(args, &before.resolve(&device)?),
            Command::Calibration { args, device } => {
                calibration::run(args, &before.resolve(&device)?)
            }
            Command::Flash { args, device } => flash::run(args, &before.resolve(&device)?),
            Command::Log(a) => log::run(a, &before.resolve(&VerbDeviceArgs::default())?),
        }
    }
}

/// Prints `value` as pretty JSON, numbers as a person writes them (62.1, not
/// 62.099998474121094: see [`reporting::human_json`]), and a newline. Every verb's `--json`
/// goes through here.
pub fn print_json<T: Serialize + ?Sized>(
    out: &mut impl Write,
    value: &T,
) -> Result<(), crate::RigError> {
    writeln!(out, "{}", reporting::json_pretty(value)?)?;
    Ok(())
}

/// Prints `value` as one line of JSON (JSON lines), numbers as a person writes them.
pub fn print_json_line<T: Serialize + ?Sized>(
    out: &mut impl Write,
    value: &T,
) -> Result<(), crate::RigError> {
    writeln!(out, "{}", reporting::json_line(value)?)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    /// clap's own checks of the whole command tree (unique argument names per verb,
    /// including the device options flattened into each device verb, valid defaults and
    /// conflicts): a clash such as a verb's own `--seed` beside the device options' fails
    /// here rather than as a panic when a user runs that verb.
    #[test]
    fn the_command_tree_passes_claps_checks() {
        super::Cli::command().debug_assert();
    }
}
