//! The `rig` command line: one module per verb, each with its clap arguments and a `run`
//! function that returns the process exit code or a [`crate::RigError`].

use clap::{Parser, Subcommand};

pub mod calibrate;
pub mod calibration;
pub mod capture;
pub mod clear;
pub mod connect;
pub mod demo;
pub mod design;
pub mod explain;
pub mod faults;
pub mod flash;
pub mod info;
pub mod log;
pub mod monitor;
pub mod ports;
pub mod release;
pub mod sim;

/// Tools for the vibration-switched 2K-H planetary gear rig.
#[derive(Debug, Parser)]
#[command(name = "rig", version, about, long_about = None)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub command: Command,
    /// Which device the device verbs talk to.
    #[command(flatten)]
    pub device: connect::DeviceOpts,
}

/// The verbs.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Design calculator: ratio, contact ratios, Lambda, hold verdict and required cam torque.
    Design(design::DesignArgs),
    /// Simulated rig (firmware core + plant): fig5, table1, torque-sweep, faults.
    Sim(sim::SimArgs),
    /// The main job: the whole simulated rig (design, calibration, fig5, table1, sweep, faults) with a report folder.
    Demo(demo::DemoArgs),
    /// Find where the current model and measured data disagree, name the missing effect, add it.
    Explain(crate::cli::explain::ExplainArgs),
    /// List serial ports, marking ST-LINK virtual COM ports (Nucleo boards).
    Ports(ports::PortsArgs),
    /// Device identity: firmware and protocol versions, board, calibration source.
    Info(info::InfoArgs),
    /// Active and latched faults of the device, with what each means.
    Faults(faults::FaultsArgs),
    /// Clear the latched faults whose cause is gone.
    Clear(clear::ClearArgs),
    /// Vibrate (on: the gear becomes backdrivable) while the command runs; Ctrl-C locks.
    Release(release::ReleaseArgs),
    /// Live telemetry: charts of current, cam speed, tau_cam, load estimate and state.
    Monitor(monitor::MonitorArgs),
    /// A 10 kHz burst of raw current and encoder samples from the device's buffer, to CSV.
    Capture(capture::CaptureArgs),
    /// The paper's vibrator calibration (C1-C6): measure, fit, plot, write the device.
    Calibrate(calibrate::CalibrateArgs),
    /// Read (get) or write (set) the device's calibration as a TOML file.
    Calibration(calibration::CalibrationArgs),
    /// Check and flash the firmware through the debug probe (keeps the stored calibration).
    Flash(flash::FlashArgs),
    /// The firmware's defmt log through the debug probe, or decoded from a saved stream.
    Log(log::LogArgs),
}

impl Cli {
    /// Runs the chosen verb.
    pub fn run(self) -> Result<std::process::ExitCode, crate::RigError> {
        match self.command {
            Command::Design(a) => design::run(a),
            Command::Demo(a) => demo::run(a, &self.device),
            Command::Explain(a) => crate::cli::explain::run(a),
            Command::Sim(a) => sim::run(a),
            Command::Ports(a) => ports::run(a),
            Command::Info(a) => info::run(a, &self.device),
            Command::Faults(a) => faults::run(a, &self.device),
            Command::Clear(a) => clear::run(a, &self.device),
            Command::Release(a) => release::run(a, &self.device),
            Command::Monitor(a) => monitor::run(a, &self.device),
            Command::Capture(a) => capture::run(a, &self.device),
            Command::Calibrate(a) => calibrate::run(a, &self.device),
            Command::Calibration(a) => calibration::run(a, &self.device),
            Command::Flash(a) => flash::run(a, &self.device),
            Command::Log(a) => log::run(a, &self.device),
        }
    }
}
