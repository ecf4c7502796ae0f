//! The global device options (`--port`, `--baud`, `--sim`, `--speed`) and the session the
//! device verbs open with them.

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use clap::Args;
use protocol::DeviceInfo;

use crate::RigError;
use crate::client::{Client, ClientOptions, SerialTransport, open_serial};
use crate::device::VirtualDevice;
use crate::ports;

/// Which device to talk to; global, so they go before or after the verb.
#[derive(Debug, Clone, Args)]
pub struct DeviceOpts {
    /// Serial port of the rig, e.g. /dev/ttyACM0 (`rig ports` lists them). Without it:
    /// $RIG_PORT, else the only ST-LINK port plugged in.
    #[arg(long, global = true, value_name = "PORT", conflicts_with = "sim")]
    pub port: Option<String>,
    /// Baud rate of the serial port (the firmware's UART runs at 921600).
    #[arg(long, global = true, value_name = "BAUD", default_value_t = protocol::DEFAULT_BAUD_RATE, value_parser = parse_baud)]
    pub baud: u32,
    /// Use the virtual device: the firmware core and a simulated rig on a pseudo-terminal.
    #[arg(long, global = true)]
    pub sim: bool,
    /// With --sim: run the virtual device this many times faster than real time.
    #[arg(long, global = true, value_name = "FACTOR", default_value_t = 1.0, value_parser = parse_speed)]
    pub speed: f64,
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
        Ok(v) if v.is_finite() && v > 0.0 && v <= 1000.0 => Ok(v),
        _ => Err(format!(
            "'{s}' is not a speed factor: give a number above 0 and at most 1000 (1 = real time)"
        )),
    }
}

/// An open session with the device, and the virtual device when `--sim` made one.
pub struct Session {
    /// The client, connected and version-checked.
    pub client: Client<SerialTransport>,
    /// What the device said at `Hello`.
    pub info: DeviceInfo,
    /// The virtual device (dropped after the client: fields drop in order).
    pub device: Option<VirtualDevice>,
}

impl Session {
    /// The port's name.
    pub fn port(&self) -> &str {
        &self.client.options().port_name
    }

    /// Device seconds per wall-clock second.
    pub fn time_scale(&self) -> f64 {
        self.client.options().time_scale
    }
}

impl DeviceOpts {
    /// The port to open (none for `--sim`).
    pub fn resolve_port(&self) -> Result<String, RigError> {
        if let Some(p) = &self.port {
            return Ok(p.clone());
        }
        if let Ok(p) = std::env::var("RIG_PORT")
            && !p.trim().is_empty()
        {
            return Ok(p.trim().to_owned());
        }
        let stlinks: Vec<_> = ports::list().into_iter().filter(|p| p.stlink).collect();
        match stlinks.as_slice() {
            [one] => Ok(one.port.clone()),
            [] => Err(RigError::NoDevice),
            many => Err(RigError::BadValue {
                what: "--port".into(),
                why: format!(
                    "several ST-LINK ports are plugged in ({}): choose one with --port",
                    many.iter()
                        .map(|p| p.port.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }),
        }
    }

    /// Opens the device (starting the virtual one for `--sim`) and says `Hello`.
    pub fn connect(&self) -> Result<Session, RigError> {
        if !self.sim && self.speed != 1.0 {
            return Err(RigError::BadValue {
                what: format!("--speed {}", self.speed),
                why: "only the virtual device can run faster: add --sim".into(),
            });
        }
        let (device, port, name) = if self.sim {
            let dev = VirtualDevice::paper(self.speed)?;
            let port = dev.port_name().to_owned();
            let name = format!("the virtual device ({port})");
            (Some(dev), port, name)
        } else {
            let port = self.resolve_port()?;
            (None, port.clone(), port)
        };
        let io = open_serial(&port, self.baud)?;
        let mut opts = ClientOptions::new(name);
        if self.sim {
            opts.time_scale = self.speed;
            // Pseudo-terminal bytes wait for a kernel worker: on a busy machine, long.
            opts.reply_timeout = std::time::Duration::from_secs(1);
        }
        let (client, info) = Client::connect(io, opts)?;
        Ok(Session {
            client,
            info,
            device,
        })
    }
}

/// A flag raised by Ctrl-C (SIGINT) or SIGTERM; a second Ctrl-C ends the process at once.
pub fn interrupt_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // Registration only fails for forbidden signals; without it Ctrl-C still ends the
        // process, and the device stops at its comms timeout (the safe state).
        let _ = signal_hook::flag::register_conditional_shutdown(signal, 130, Arc::clone(&flag));
        let _ = signal_hook::flag::register(signal, Arc::clone(&flag));
    }
    flag
}

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
        assert!(parse_speed("0").is_err());
        assert!(parse_speed("nan").is_err());
    }
}
