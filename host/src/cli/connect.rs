//! The device options (`--port`, `--baud`, `--sim`, `--speed`, `--seed`, `--model`) as the command
//! line takes them: before the verb ([`DeviceArgs`]) or after a device verb
//! ([`VerbDeviceArgs`]; [`DiscoverDeviceArgs`] after `discover`, whose own `--model` is a
//! rig file its explanations start from).
//! Only the verbs that use a device accept them; [`DeviceArgs::refuse_for`] is the error
//! for the others. The resolved options and the session live in [`crate::connection`].

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::Args;

use crate::RigError;
pub use crate::connection::{Connection, DeviceOpts};

/// The verbs that use a device, for messages.
pub const DEVICE_VERBS: &str = "info, faults, clear, release, bringup, monitor, capture, record, calibrate, calibration, experiment, discover, flash and demo";

/// The device options as given on the command line (nothing defaulted), declared twice:
/// before the verb (not global, so a verb without a device does not take them after its
/// name) and on each device verb (global below it, so `rig calibration get --sim` works).
macro_rules! device_args {
    ($(#[$meta:meta])* $name:ident, global = $global:literal, heading = $heading:literal $(, model = $model:ident)? $(, seed = $seed:ident)?) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Default, Args)]
        #[command(next_help_heading = $heading)]
        pub struct $name {
            /// Serial port of the rig, e.g. /dev/ttyACM0 (`rig ports` lists them). Without it:
            /// $RIG_PORT, else the only ST-LINK port plugged in.
            #[arg(long, global = $global, value_name = "PORT", conflicts_with = "sim")]
            pub port: Option<String>,
            /// Link rate to agree on with the device after `Hello`: 921600 (the default, where
            /// every device starts) or the device's fastest (`rig info`: max_baud; 4000000 on
            /// the Nucleo firmware and the virtual rig). When the device is not heard at the
            /// new rate both go back to 921600 and the verb stops, saying so.
            #[arg(long, global = $global, value_name = "BAUD", value_parser = parse_baud)]
            pub baud: Option<u32>,
            /// Use the virtual device: the firmware core and a simulated rig on a pseudo-terminal.
            #[arg(long, global = $global)]
            pub sim: bool,
            /// With --sim: run the virtual device this many times faster than real time [default: 1].
            #[arg(long, global = $global, value_name = "FACTOR", value_parser = parse_speed)]
            pub speed: Option<f64>,
            /// With --sim: the firmware image itself on the emulated STM32G474 (processor in
            /// the loop) instead of the firmware core: `--firmware=ELF`, or alone the release image
            /// `cargo xtask firmware` builds, as `rig sim serve --firmware`.
            #[arg(long, global = $global, value_name = "ELF", num_args = 0..=1, require_equals = true)]
            pub firmware: Option<Option<PathBuf>>,
            $(
            /// With --sim: the virtual rig's sensor-noise seed, as `rig sim serve --seed`
            /// [default: 1]; the same seed gives the same noise draws.
            #[arg(long, global = $global, value_name = "SEED")]
            pub $seed: Option<u64>,
            )?
            $(
            /// With --sim: build the virtual device from this rig file (gear, friction,
            /// calibration), its plant running a fitted [model]'s effects when it has one
            /// (`rig explain --write-model`), as `rig sim serve --model`.
            #[arg(long, global = $global, value_name = "FILE")]
            pub $model: Option<PathBuf>,
            )?
        }

        impl $name {
            /// The options given, by their command-line names.
            pub fn given(&self) -> Vec<&'static str> {
                [
                    ("--port", self.port.is_some()),
                    ("--baud", self.baud.is_some()),
                    ("--sim", self.sim),
                    ("--speed", self.speed.is_some()),
                    ("--firmware", self.firmware.is_some()),
                    $(("--seed", self.$seed.is_some()),)?
                    $(("--model", self.$model.is_some()),)?
                ]
                .into_iter()
                .filter_map(|(name, given)| given.then_some(name))
                .collect()
            }
        }
    };
}

device_args!(
    /// Device options before the verb: `rig --sim info`. Device verbs only.
    DeviceArgs,
    global = false,
    heading = "Device options (for info, faults, clear, release, bringup, monitor, capture, record, calibrate, calibration, experiment, discover, demo; also after the verb)",
    model = model,
    seed = seed
);
device_args!(
    /// Device options after a device verb: `rig info --sim`.
    VerbDeviceArgs,
    global = true,
    heading = "Device options",
    model = model,
    seed = seed
);
device_args!(
    /// Device options after `rig discover`: all but `--model`, which is `discover`'s own
    /// (the rig file its explanations start from), and `--seed`, also its own (the
    /// rounds' order and, with --sim, the virtual rig's noise).
    DiscoverDeviceArgs,
    global = true,
    heading = "Device options"
);
device_args!(
    /// Device options after `rig demo`: all but `--seed`, which is `demo`'s own (the
    /// simulated noise and the test order).
    DemoDeviceArgs,
    global = true,
    heading = "Device options",
    model = model
);

impl From<DiscoverDeviceArgs> for VerbDeviceArgs {
    fn from(d: DiscoverDeviceArgs) -> Self {
        Self {
            port: d.port,
            baud: d.baud,
            sim: d.sim,
            speed: d.speed,
            firmware: d.firmware,
            seed: None,
            model: None,
        }
    }
}

impl From<DemoDeviceArgs> for VerbDeviceArgs {
    fn from(d: DemoDeviceArgs) -> Self {
        Self {
            port: d.port,
            baud: d.baud,
            sim: d.sim,
            speed: d.speed,
            firmware: d.firmware,
            seed: None,
            model: d.model,
        }
    }
}

impl DeviceArgs {
    /// The error for `--seed` before `verb`, which has a `--seed` of its own (`demo`,
    /// `discover`): given there, it would be read as two seeds.
    pub fn refuse_seed_for(&self, verb: &str) -> Result<(), RigError> {
        if self.seed.is_some() {
            return Err(RigError::BadValue {
                what: "--seed".into(),
                why: format!(
                    "`rig {verb}` has a --seed of its own (it seeds the virtual rig's noise too): give it after the verb, `rig {verb} --seed N`"
                ),
            });
        }
        Ok(())
    }
}

impl DeviceArgs {
    /// The error for device options given to `verb`, which uses no device (`Ok` when none
    /// were given). `$RIG_PORT` is not an option: it is read only when a device is opened.
    pub fn refuse_for(&self, verb: &str) -> Result<(), RigError> {
        match self.given().first() {
            None => Ok(()),
            Some(option) => Err(RigError::BadValue {
                what: (*option).into(),
                why: format!(
                    "`rig {verb}` uses no device, so it takes no device options (--port, --baud, --sim, --speed, --firmware, --seed, --model); they go with {DEVICE_VERBS}{}",
                    if *option == "--model" && matches!(verb, "sim" | "compare") {
                        format!(" (`rig {verb}` takes its own --model after its verb)")
                    } else {
                        String::new()
                    }
                ),
            }),
        }
    }

    /// The options of a device verb: those before it and those after it, defaults applied.
    pub fn resolve(&self, after: &VerbDeviceArgs) -> Result<DeviceOpts, RigError> {
        let port = after.port.clone().or_else(|| self.port.clone());
        let sim = self.sim || after.sim;
        if sim && port.is_some() {
            return Err(RigError::BadValue {
                what: "--port".into(),
                why: "cannot be used with --sim (the virtual device opens its own port): give one of them".into(),
            });
        }
        let firmware = after.firmware.clone().or_else(|| self.firmware.clone());
        if firmware.is_some() && !sim {
            return Err(RigError::BadValue {
                what: "--firmware".into(),
                why: "runs the image on the virtual device's emulated board: add --sim (a real rig runs what was flashed: `rig flash`)".into(),
            });
        }
        let defaults = DeviceOpts::default();
        Ok(DeviceOpts {
            port,
            baud: after.baud.or(self.baud).unwrap_or(defaults.baud),
            sim,
            firmware,
            speed: after.speed.or(self.speed).unwrap_or(defaults.speed),
            seed: after.seed.or(self.seed),
            model: after.model.clone().or_else(|| self.model.clone()),
        })
    }
}

/// Parses a baud rate.
pub fn parse_baud(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u64>() {
        Ok(b) if (50..=12_000_000).contains(&b) => Ok(b as u32),
        Ok(b) => Err(format!(
            "{b} baud is not a usable rate: give 50 to 12000000 (the firmware uses {})",
            protocol::DEFAULT_BAUD_RATE
        )),
        Err(_) => Err(format!(
            "'{s}' is not a baud rate: give a whole number such as {}",
            protocol::DEFAULT_BAUD_RATE
        )),
    }
}

/// Parses a simulation speed factor.
pub fn parse_speed(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= crate::virtual_device::MAX_SPEED => Ok(v),
        _ => Err(format!(
            "'{s}' is not a speed the simulation can keep: give a number above 0 and at most {} (1 = real time; faster, the host's heartbeats cannot keep inside the comms timeout)",
            crate::virtual_device::MAX_SPEED
        )),
    }
}

pub use crate::signals::interrupt_flag;

/// Asks `question` on the terminal; false without a terminal (scripts pass `--yes`).
pub fn confirm(question: &str) -> Result<bool, RigError> {
    if !std::io::stdin().is_terminal() {
        return Ok(false);
    }
    eprint!("{question} [y/N] ");
    let mut answer = String::new();
    std::io::stdin().read_line(&mut answer)?;
    Ok(matches!(answer.trim(), "y" | "Y" | "yes" | "Yes" | "YES"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn baud_and_speed_are_checked() {
        assert_eq!(parse_baud("921600"), Ok(921_600));
        assert!(parse_baud("0").unwrap_err().contains("50 to 12000000"));
        assert!(parse_baud("fast").unwrap_err().contains("not a baud rate"));
        assert_eq!(parse_speed("20"), Ok(20.0));
        assert_eq!(parse_speed("100"), Ok(100.0));
        // Issue 33: at 500x every sweep failed with COMMS_TIMEOUT.
        assert!(parse_speed("500").unwrap_err().contains("at most 100"));
        assert!(parse_speed("0").is_err());
        assert!(parse_speed("nan").is_err());
    }

    #[test]
    fn options_before_and_after_the_verb_merge() {
        let before = DeviceArgs {
            sim: true,
            ..Default::default()
        };
        let after = VerbDeviceArgs {
            speed: Some(5.0),
            ..Default::default()
        };
        let d = before.resolve(&after).unwrap();
        assert!(d.sim && d.speed == 5.0 && d.baud == protocol::DEFAULT_BAUD_RATE);
        let after = VerbDeviceArgs {
            port: Some("/dev/ttyACM0".into()),
            ..Default::default()
        };
        let e = before.resolve(&after).unwrap_err().to_string();
        assert!(e.contains("--port") && e.contains("--sim"), "{e}");
        assert!(DeviceArgs::default().refuse_for("design").is_ok());
        let e = DeviceArgs {
            baud: Some(9600),
            ..Default::default()
        }
        .refuse_for("design")
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("--baud") && e.contains("rig design"), "{e}");
        // --model goes before or after the verb like the others (after wins).
        let before = DeviceArgs {
            sim: true,
            model: Some("a.toml".into()),
            ..Default::default()
        };
        assert_eq!(before.given(), ["--sim", "--model"]);
        let d = before.resolve(&VerbDeviceArgs::default()).unwrap();
        assert_eq!(d.model, Some(PathBuf::from("a.toml")));
        let after = VerbDeviceArgs {
            model: Some("b.toml".into()),
            ..Default::default()
        };
        assert_eq!(
            before.resolve(&after).unwrap().model,
            Some(PathBuf::from("b.toml"))
        );
        let e = DeviceArgs {
            model: Some("a.toml".into()),
            ..Default::default()
        }
        .refuse_for("sim")
        .unwrap_err()
        .to_string();
        assert!(e.contains("--model") && e.contains("own --model"), "{e}");
        // After `discover` there is no device --model (its own names its rig file).
        let d = DeviceArgs::default()
            .resolve(
                &DiscoverDeviceArgs {
                    sim: true,
                    ..Default::default()
                }
                .into(),
            )
            .unwrap();
        assert!(d.sim && d.model.is_none());
        // --seed goes before or after the verb (after wins); not given, the virtual rig's own.
        let before = DeviceArgs {
            sim: true,
            seed: Some(7),
            ..Default::default()
        };
        assert_eq!(before.given(), ["--sim", "--seed"]);
        assert_eq!(
            before.resolve(&VerbDeviceArgs::default()).unwrap().seed,
            Some(7)
        );
        let after = VerbDeviceArgs {
            seed: Some(9),
            ..Default::default()
        };
        assert_eq!(before.resolve(&after).unwrap().seed, Some(9));
        assert_eq!(
            DeviceArgs::default().resolve(&after).unwrap().seed,
            Some(9),
            "refused at connect without --sim, naming --seed"
        );
    }
}
