//! Which device a device verb talks to ([`DeviceOpts`], resolved from the command line)
//! and the session it opens with it ([`Connection`]). Below the command line: `demo` and the
//! verbs both use it.

use std::path::PathBuf;

use protocol::DeviceInfo;

use crate::RigError;
use crate::client::{Client, ClientOptions, SerialTransport, open_serial};
use crate::ports;
use crate::virtual_device::{FirmwareDevice, VirtualDevice};

/// The device to talk to, with every default applied.
#[derive(Debug, Clone, PartialEq)]
pub struct DeviceOpts {
    /// Serial port of the rig; `None`: $RIG_PORT, else the only ST-LINK port plugged in.
    pub port: Option<String>,
    /// Baud rate of the serial port.
    pub baud: u32,
    /// Use the virtual device.
    pub sim: bool,
    /// With `sim`: virtual seconds per wall-clock second.
    pub speed: f64,
    /// With `sim`: run the firmware image on the emulated board ([`FirmwareDevice`]): the
    /// ELF given, or (`Some(None)`) the default release image.
    pub firmware: Option<Option<PathBuf>>,
    /// With `sim`: the virtual rig's sensor-noise seed (`None`: its default, 1).
    pub seed: Option<u64>,
    /// With `sim`: a rig file (a fitted `[model]`, or a plain rig); the virtual device is
    /// built from it and its plant runs the model's effects ([`VirtualDevice::fitted_config`]).
    pub model: Option<PathBuf>,
}

impl Default for DeviceOpts {
    /// No port named, the firmware's baud rate, real time.
    fn default() -> Self {
        Self {
            port: None,
            baud: protocol::DEFAULT_BAUD_RATE,
            sim: false,
            speed: 1.0,
            firmware: None,
            seed: None,
            model: None,
        }
    }
}

/// An open session with the device, and the virtual device when `--sim` made one.
pub struct Connection {
    /// The client, connected and version-checked.
    pub client: Client<SerialTransport>,
    /// What the device said at `Hello`.
    pub info: DeviceInfo,
    /// The virtual device (dropped after the client: fields drop in order).
    pub device: Option<VirtualDevice>,
    /// The emulated board running the firmware image (`--sim --firmware`).
    pub board: Option<FirmwareDevice>,
}

impl Connection {
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
    pub fn connect(&self) -> Result<Connection, RigError> {
        if !self.sim && self.speed != 1.0 {
            return Err(RigError::BadValue {
                what: format!("--speed {}", self.speed),
                why: "only the virtual device can run faster: add --sim".into(),
            });
        }
        if let (false, Some(model)) = (self.sim, &self.model) {
            return Err(RigError::BadValue {
                what: format!("--model {}", model.display()),
                why: "only the virtual device runs a fitted model (a real rig runs its own physics): add --sim, or leave --model out".into(),
            });
        }
        if let (false, Some(seed)) = (self.sim, self.seed) {
            return Err(RigError::BadValue {
                what: format!("--seed {seed}"),
                why: "only the virtual device has a noise seed (a real rig's noise is its own): add --sim, or leave --seed out".into(),
            });
        }
        let mut board = None;
        let (device, port, name) = if let (true, Some(elf)) = (self.sim, &self.firmware) {
            let mut config = match &self.model {
                Some(path) => VirtualDevice::fitted_config(path)?,
                None => VirtualDevice::paper_config(&sim::Preset::paper()),
            };
            if let Some(seed) = self.seed {
                config.seed = seed;
            }
            let dev =
                FirmwareDevice::start(elf.as_deref(), &config, config.seed, self.speed, None)?;
            let port = dev.port_name().to_owned();
            let name = format!("the firmware image on the emulated board ({port})");
            board = Some(dev);
            (None, port, name)
        } else if self.sim {
            let mut config = match &self.model {
                Some(path) => VirtualDevice::fitted_config(path)?,
                None => VirtualDevice::paper_config(&sim::Preset::paper()),
            };
            if let Some(seed) = self.seed {
                config.seed = seed;
            }
            let dev = VirtualDevice::start(config, self.speed)?;
            let port = dev.port_name().to_owned();
            let name = format!("the virtual device ({port})");
            (Some(dev), port, name)
        } else {
            let port = self.resolve_port()?;
            (None, port.clone(), port)
        };
        // Every device starts at the default rate; a faster one is agreed after `Hello`.
        let io = open_serial(&port, protocol::DEFAULT_BAUD_RATE)?;
        let mut opts = ClientOptions::new(name);
        if board.is_some() {
            // The image reports the board's pace in `Info`; the client takes it from there.
            // The emulation keeps that pace only while the machine has the cores it was
            // measured with; on a busy one the board's clock falls behind the wall clock, and
            // a reply it is still working on must not time out.
            opts.reply_timeout = std::time::Duration::from_secs(5);
        } else if self.sim {
            opts.time_scale = self.speed;
            // Pseudo-terminal bytes wait for a kernel worker: on a busy machine, long.
            opts.reply_timeout = std::time::Duration::from_secs(1);
        }
        let (mut client, info) = Client::connect(io, opts)?;
        client.agree_baud(&info, self.baud)?;
        Ok(Connection {
            client,
            info,
            device,
            board,
        })
    }
}
