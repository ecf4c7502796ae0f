//! `SimRig`: the firmware's control core and the simulated plant in closed loop, in
//! virtual time. The plant runs at 10 kHz (the ADC rate); the core is stepped at its
//! control rate with the ADC samples of the interval, exactly as the firmware's control
//! task feeds it; host bytes go through the core's real protocol server.

use firmware_core::{BootInfo, Core, CoreConfig, Inputs};
use model::plant::{Drive, Plant, PlantParams};
use model::{GearSet, plant::Load};

/// Plant (and ADC) rate, Hz.
pub const PLANT_HZ: u32 = 10_000;

/// What to fault on purpose, for the fault scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Injections {
    /// The encoder cable is cut: the count stops changing.
    pub encoder_frozen: bool,
    /// The ACS714 output is stuck at this ADC code.
    pub current_adc_stuck: Option<u16>,
}

/// Everything that defines a simulated session.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The physical rig.
    pub plant: PlantParams,
    /// The firmware configuration.
    pub core: CoreConfig,
    /// Calibration the firmware boots with (as if read from flash).
    pub calibration: protocol::Calibration,
    /// Where that calibration came from.
    pub calibration_status: protocol::CalibrationStatus,
    /// Whether the firmware boots after a watchdog reset.
    pub watchdog_reset: bool,
    /// Seed of the sensor noise.
    pub seed: u64,
}

impl SimConfig {
    /// The paper's (Z1, Z4) = (49, 50) rig with no load, booting with Table 2 stored.
    pub fn paper() -> Self {
        Self::for_gear(model::paper::RIG_Z, Load::Torque(0.0))
            .expect("the paper's gear set is valid")
    }

    /// The paper's rig built around gear set `z` with `load`; the stored calibration names `z`.
    pub fn for_gear(z: [u32; 4], load: Load) -> Result<Self, model::GearError> {
        let gear = GearSet::paper(z)?;
        let mut calibration = protocol::Calibration::paper();
        calibration.z = z.map(|v| v as u16);
        Ok(Self {
            plant: PlantParams::paper(gear, load),
            core: CoreConfig::default(),
            calibration,
            calibration_status: protocol::CalibrationStatus::Valid,
            watchdog_reset: false,
            seed: 1,
        })
    }
}

/// The closed-loop simulated rig.
pub struct SimRig {
    plant: Plant,
    core: Core,
    ticks_per_step: u32,
    tick: u64,
    adc: Vec<u16>,
    drive: Drive,
    outbox: Vec<u8>,
    button: bool,
    injections: Injections,
    frozen_count: u16,
    flash: Option<protocol::Calibration>,
}

impl SimRig {
    /// A rig at rest, firmware just booted.
    pub fn new(config: SimConfig) -> Self {
        let control_hz = config.core.control_hz.clamp(1, PLANT_HZ);
        let boot = BootInfo {
            watchdog_reset: config.watchdog_reset,
            calibration: config.calibration,
            calibration_status: config.calibration_status,
        };
        Self {
            plant: Plant::new(config.plant, config.seed),
            core: Core::new(config.core, boot),
            ticks_per_step: PLANT_HZ / control_hz,
            tick: 0,
            adc: Vec::with_capacity(64),
            drive: Drive::default(),
            outbox: Vec::new(),
            button: false,
            injections: Injections::default(),
            frozen_count: 0,
            flash: Some(config.calibration),
        }
    }

    /// Simulated time since boot, s.
    pub fn time(&self) -> f64 {
        self.tick as f64 / PLANT_HZ as f64
    }

    /// Device clock, microseconds since boot.
    pub fn now_us(&self) -> u64 {
        self.tick * 1_000_000 / PLANT_HZ as u64
    }

    /// Runs the closed loop for `seconds` of virtual time.
    pub fn advance(&mut self, seconds: f64) {
        let ticks = (seconds * PLANT_HZ as f64).round().max(0.0) as u64;
        let dt = 1.0 / PLANT_HZ as f64;
        for _ in 0..ticks {
            self.plant.step(dt, self.drive);
            let code = match self.injections.current_adc_stuck {
                Some(code) => code,
                None => self.plant.current_adc(),
            };
            self.adc.push(code);
            self.tick += 1;
            if self.tick.is_multiple_of(self.ticks_per_step as u64) {
                self.control_step();
            }
        }
    }

    fn control_step(&mut self) {
        let encoder_count = if self.injections.encoder_frozen {
            self.frozen_count
        } else {
            self.frozen_count = self.plant.encoder_count();
            self.frozen_count
        };
        let inputs = Inputs {
            now_us: self.now_us(),
            current_adc: &self.adc,
            encoder_count,
            release_button: self.button,
        };
        let out = self.core.step(&inputs);
        self.adc.clear();
        self.drive = Drive {
            duty: out.duty as f64,
            enabled: out.enable,
        };
        if let Some(cal) = out.persist {
            self.flash = Some(cal);
            self.core.persist_result(true);
        }
        let mut buf = [0u8; 256];
        loop {
            let n = self.core.transmit(&mut buf);
            if n == 0 {
                break;
            }
            self.outbox.extend_from_slice(&buf[..n]);
        }
    }

    /// Bytes from the host to the device.
    pub fn to_device(&mut self, bytes: &[u8]) {
        let now = self.now_us();
        self.core.receive(now, bytes);
    }

    /// Moves the bytes the device sent since the last call into `out`.
    pub fn from_device(&mut self, out: &mut Vec<u8>) {
        out.append(&mut self.outbox);
    }

    /// Presses (true) or lets go of (false) the release button.
    pub fn set_button(&mut self, held: bool) {
        self.button = held;
    }

    /// Sets the fault injections.
    pub fn inject(&mut self, injections: Injections) {
        self.injections = injections;
    }

    /// The plant.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The plant, to change the load or the cam setup as an operator would.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.plant
    }

    /// The firmware core.
    pub fn core(&self) -> &Core {
        &self.core
    }

    /// The H-bridge command the firmware applies now.
    pub fn drive(&self) -> Drive {
        self.drive
    }

    /// The calibration in the simulated flash.
    pub fn flash(&self) -> Option<protocol::Calibration> {
        self.flash
    }
}
