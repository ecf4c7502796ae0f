//! The Nucleo-G474RE on the rig: the emulated MCU wired to the simulated plant (the
//! bridge, the ACS714, the bus and NTC dividers, both encoders, the user button) and to a
//! host link of bytes.

use std::any::Any;
use std::path::{Path, PathBuf};

use model::hardware::{amt102, bus_divider, ntc};
use model::plant::{Drive, Plant, PlantParams};

use crate::EmuError;
use crate::elf::Image;
use crate::machine::{Machine, SYSCLK_HZ};
use crate::periph::{Analog, Bridge, Env};

/// Longest plant step, s (the plant's own tests hold at 0.5 ms).
const MAX_PLANT_STEP_S: f64 = 0.5e-3;
/// Longest stretch of CPU time run at once, cycles (100 us: the host's bytes and the
/// plant's catch-up are handled in between).
const SLICE_CYCLES: u64 = SYSCLK_HZ / 10_000;

/// What to build the board from.
#[derive(Debug, Clone)]
pub struct BoardConfig {
    /// The firmware ELF.
    pub elf: PathBuf,
    /// The rig around it.
    pub plant: PlantParams,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// Device seconds per wall-clock second the board will be paced at, written into the
    /// image's `RIG_TIME_SCALE` so that `Info` reports it (`None`: the image's own, 1.0).
    pub time_scale: Option<f32>,
}

impl BoardConfig {
    /// `elf` on the paper's (49, 50) rig with no load, noise seed 1, the image's own pace.
    pub fn paper(elf: impl Into<PathBuf>) -> Self {
        let gear =
            model::GearSet::paper(model::paper::RIG_Z).expect("the paper's gear set is valid");
        Self {
            elf: elf.into(),
            plant: PlantParams::paper(gear, model::plant::Load::Torque(0.0)),
            seed: 1,
            time_scale: None,
        }
    }
}

/// The image's symbol for its reported time scale (an `f32` in flash).
pub const TIME_SCALE_SYMBOL: &str = "RIG_TIME_SCALE";

/// The plant as the board's surroundings.
pub struct PlantEnv {
    /// The simulated rig.
    pub plant: Plant,
    t: f64,
    code: u16,
    /// The user button B1 held.
    pub button: bool,
}

impl PlantEnv {
    fn drive(bridge: Bridge) -> Drive {
        let magnitude = bridge.duty.unwrap_or(0.0);
        Drive {
            duty: if bridge.reverse {
                -magnitude
            } else {
                magnitude
            },
            enabled: bridge.enable,
        }
    }

    /// Steps the plant to `t_s` with `bridge` held.
    pub fn catch_up(&mut self, t_s: f64, bridge: Bridge) {
        let drive = Self::drive(bridge);
        while t_s - self.t > 1e-9 {
            let dt = (t_s - self.t).min(MAX_PLANT_STEP_S);
            let mut code = self.code;
            self.plant.step_sampled(dt, drive, 1, |c| code = c);
            self.code = code;
            self.t += dt;
        }
    }
}

impl Env for PlantEnv {
    fn sample(&mut self, t_s: f64, bridge: Bridge) -> Analog {
        self.catch_up(t_s, bridge);
        let vdda = self.plant.params().sensors.adc_reference;
        let temp_k = self.plant.state().temperature + 273.15;
        let r_ntc = ntc::R25_OHM * ((ntc::BETA_K * (1.0 / temp_k - 1.0 / ntc::T25_K)).exp());
        Analog {
            current_code: self.code,
            bus_pin_v: self.plant.bus_voltage() * bus_divider::RATIO,
            ntc_pin_v: vdda * r_ntc / (r_ntc + ntc::PULL_UP_OHM),
            vdda_v: vdda,
        }
    }

    fn encoder_counts(&self) -> (u16, u16) {
        let out = self.plant.state().output_angle / std::f64::consts::TAU
            * f64::from(amt102::COUNTS_PER_REV);
        (
            self.plant.encoder_count(),
            (out.round() as i64).rem_euclid(1 << 16) as u16,
        )
    }

    fn inputs(&self, port: usize) -> u32 {
        // B1 on PC13 pulls it high when pressed.
        if port == 2 && self.button { 1 << 13 } else { 0 }
    }

    fn comparator_in_v(&self) -> f64 {
        self.plant
            .params()
            .sensors
            .pin_voltage(self.plant.state().current)
    }

    fn as_any(&mut self) -> &mut dyn Any {
        self
    }
}

/// The board: MCU, plant, host link.
pub struct Board {
    machine: Box<Machine>,
    elf: PathBuf,
}

impl std::fmt::Debug for Board {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Board").field("elf", &self.elf).finish()
    }
}

impl Board {
    /// Loads the ELF, wires the plant and powers the board on.
    pub fn new(config: BoardConfig) -> Result<Self, EmuError> {
        let image = Image::load(&config.elf)?;
        let mut params = config.plant;
        // The break comes from COMP3 and DAC3 as the image programs them, not from the
        // plant's own comparator.
        params.break_threshold_v = None;
        let env = PlantEnv {
            plant: Plant::new(params, config.seed),
            t: 0.0,
            code: 0,
            button: false,
        };
        let scale_at = image.symbols.get(TIME_SCALE_SYMBOL).copied();
        let mut machine = Machine::new(image, Box::new(env))?;
        if let Some(scale) = config.time_scale {
            let Some(at) = scale_at else {
                return Err(EmuError::Image {
                    path: config.elf.display().to_string(),
                    why: format!(
                        "no `{TIME_SCALE_SYMBOL}` symbol: the image cannot report the emulated board's pace; build it from this tree (cargo xtask firmware)"
                    ),
                });
            };
            machine.patch_flash(at, &scale.to_le_bytes())?;
        }
        machine.power_on();
        Ok(Self {
            machine,
            elf: config.elf,
        })
    }

    /// The image's path.
    pub fn elf(&self) -> &Path {
        &self.elf
    }

    /// Device time since power-on, s.
    pub fn time(&self) -> f64 {
        self.machine.cycles() as f64 / SYSCLK_HZ as f64
    }

    /// Runs the board for `seconds` of device time.
    pub fn advance(&mut self, seconds: f64) -> Result<(), EmuError> {
        let end = self.machine.cycles() + (seconds.max(0.0) * SYSCLK_HZ as f64).round() as u64;
        while self.machine.cycles() < end {
            let until = (self.machine.cycles() + SLICE_CYCLES).min(end);
            self.machine.run_until(until)?;
            // No ADC trigger (a board before its scans start, or stopped): the plant still
            // moves with the bridge as it is.
            let t = self.time();
            let bridge = self.machine.bus.bridge();
            self.env().catch_up(t - 1e-3, bridge);
        }
        Ok(())
    }

    fn env(&mut self) -> &mut PlantEnv {
        self.machine
            .bus
            .env
            .as_any()
            .downcast_mut::<PlantEnv>()
            .expect("the board's surroundings are its plant")
    }

    /// The plant, as an operator's hand at the rig.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.env().plant
    }

    /// Presses (or releases) the user button B1.
    pub fn set_button(&mut self, held: bool) {
        self.env().button = held;
    }

    /// Host bytes onto the UART's receive line.
    pub fn to_device(&mut self, bytes: &[u8]) {
        let now = self.machine.cycles();
        self.machine.bus.usart.receive(bytes, now);
    }

    /// Bytes the board sent to the host since the last call, appended to `out`.
    pub fn from_device(&mut self, out: &mut Vec<u8>) {
        out.append(&mut self.machine.bus.usart.out);
    }

    /// The bridge as the pins drive it now.
    pub fn bridge(&self) -> Bridge {
        self.machine.bus.bridge()
    }

    /// The emulated MCU (registers, peripherals, what the image touched).
    pub fn machine(&self) -> &Machine {
        &self.machine
    }

    /// The emulated MCU, mutable (tests inject faults here).
    pub fn machine_mut(&mut self) -> &mut Machine {
        &mut self.machine
    }
}
