//! `SimRig`: the firmware's control core and the simulated plant in closed loop, in
//! virtual time. The ADC samples at 10 kHz, the plant steps at 2 kHz with five samples
//! through each step ([`SimRig::advance`]); the core is stepped at its
//! control rate with the ADC samples of the interval, exactly as the firmware's control
//! task feeds it; host bytes go through the core's real protocol server.
//!
//! The virtual rig also serves `Request::Simulation` commands, the operator's and the
//! bench's actions, so procedures can hang a load through the same link a real rig uses
//! (real firmware refuses them with `SimulationOnly`): `SetLoad` hangs a torque on the
//! plant's output; `SetSupplyVoltage` sets the bridge supply's open-circuit voltage (the
//! bus the firmware measures sags from it through the supply's internal resistance) and
//! `SetSensorSupply` the ACS714's supply (ratiometric: its zero and sensitivity follow);
//! both are also recorded in [`BenchSettings`].

use firmware_core::{BoardInputs, BootInfo, Core, CoreConfig, Inputs};
use model::plant::{Drive, MotorParams, Plant, PlantParams};
use model::{GearSet, plant::Load};
use rigfile::RigFile;

use crate::SimError;
use protocol::{Capabilities, NackCode, ParametersStatus, ResetCause, RigParameters, SimCommand};

/// ADC (current sample) rate, Hz: the plant steps at a fifth of it ([`SimRig::advance`]).
pub const ADC_HZ: u32 = 10_000;

/// ADC samples per plant step where the control rate allows ([`SimRig::advance`]).
pub const SAMPLES_PER_PLANT_STEP: u32 = 5;

/// What to fault on purpose, for the fault scenarios.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Injections {
    /// The encoder cable is cut: the count stops changing.
    pub encoder_frozen: bool,
    /// The ACS714 output is stuck at this ADC code.
    pub current_adc_stuck: Option<u16>,
    /// The encoder counts backwards (A and B swapped, or the motor wired backwards).
    pub encoder_reversed: bool,
}

/// Everything that defines a simulated session.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The physical rig.
    pub plant: PlantParams,
    /// The firmware configuration.
    pub core: CoreConfig,
    /// Rig parameters (calibration) the firmware boots with (as if read from flash).
    pub calibration: RigParameters,
    /// Where they came from.
    pub calibration_status: ParametersStatus,
    /// Whether the firmware boots after a watchdog reset.
    pub watchdog_reset: bool,
    /// Seed of the sensor noise.
    pub seed: u64,
    /// A rig file's user effects the plant runs ([`crate::user_effects`]), or `None`.
    pub user_effects: Option<crate::user_effects::UserEffects>,
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
        let mut calibration = RigParameters::paper();
        calibration.z = z.map(|v| v as u16);
        Ok(Self {
            plant: board_plant(PlantParams::paper(gear, load)),
            core: CoreConfig::default(),
            calibration,
            calibration_status: ParametersStatus::Valid,
            watchdog_reset: false,
            seed: 1,
            user_effects: None,
        })
    }

    /// The rig a rig file describes, with no load, booting with the file's calibration
    /// record stored (what `rig calibration set FILE` would have sent).
    ///
    /// The plant takes the file's gear set, e and M_hat, mu_s and mu_d, a vibrator motor
    /// built around its C1-C4 (C5 and C6 follow from them, Eqs. 16-17) at the calibration
    /// temperature, and, when the file has a fitted `[model]`, its mu as the cam's axial
    /// friction and the effects the plant can represent (`RigFile::plant_effects`; the rest
    /// are left out). The plant's drive is the file's `[drive] decay` (braking by default)
    /// unless the `[model]` fits `inertia-rectification`; the core's estimator follows it.
    pub fn from_rig_file(rig: &RigFile) -> Result<Self, SimError> {
        let bad = |e: rigfile::RigFileError| SimError::BadValue {
            what: "rig file".into(),
            why: e.to_string(),
        };
        let calibration = rig.to_wire().map_err(bad)?;
        let drive = rig.drive().map_err(bad)?;
        let mut plant = board_plant(PlantParams::paper(drive.gear, Load::Torque(0.0)));
        plant.drive = drive;
        plant.mu_s = rig.friction.mu_s;
        plant.mu_d = rig.friction.mu_d;
        plant.mu_ax = rig.friction.mu_s;
        plant.motor = MotorParams::rs735(&rig.calibration());
        plant.motor.ambient_c = rig.calibration.temperature_c;
        // The rig's drive (`[drive] decay`), unless the `[model]` fitted its own below.
        plant.regeneration = rig.drive.decay.returns_power();
        let mut user_effects = None;
        if let Some(m) = &rig.model {
            let setup = rig.plant_effects().map_err(bad)?;
            plant.mu_ax = m.mu;
            plant.effects = setup.effects;
            if let Some(regeneration) = setup.regeneration {
                plant.regeneration = regeneration;
            }
            user_effects = crate::user_effects::UserEffects::of(rig, setup.user_terms)?;
        }
        let mut core = CoreConfig::default();
        // The firmware core's estimator runs on the same drive as the plant.
        core.estimator.carrier_power_returned = plant.regeneration;
        Ok(Self {
            plant,
            core,
            calibration,
            calibration_status: ParametersStatus::Valid,
            watchdog_reset: false,
            seed: 1,
            user_effects,
        })
    }

    /// This configuration with a floor `drop_m` metres below where a load is hung (a rig
    /// file's `[load] drop_m`, [`model::hardware::bench::LOAD_DROP_M`] by default): a load
    /// that falls that far unwinds [`model::hardware::bench::output_travel_rad`] from the
    /// pulley and rests there, its rope slack, as on a bench (the virtual rigs of `rig`).
    pub fn with_floor(mut self, drop_m: f64) -> Self {
        self.plant.output_travel = Some(model::hardware::bench::output_travel_rad(drop_m));
        self
    }

    /// This configuration reporting itself as board [`VIRTUAL_BOARD`], as the host's
    /// virtual rigs do (the firmware core's default names the Nucleo board).
    pub fn virtual_board(mut self) -> Self {
        self.core.board_name = VIRTUAL_BOARD;
        self
    }
}

/// The board name a virtual rig reports in `Info`.
pub const VIRTUAL_BOARD: &str = "virtual";

/// The build the virtual rig reports in `Info`: it runs the firmware core compiled into
/// the host tool, so there is no separate firmware build to name.
pub const VIRTUAL_BUILD: &str = "virtual";

/// The paper's plant on this board: the hardware overcurrent trip (comparator into the
/// timer's break) at [`model::hardware::comparator::TRIP_A`].
fn board_plant(mut plant: PlantParams) -> PlantParams {
    use model::hardware::comparator;
    plant.break_threshold_v = Some(comparator::threshold_v(comparator::TRIP_A));
    plant
}

/// The bench around the virtual rig, as `Request::Simulation` commands set it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BenchSettings {
    /// The supply the last `SetSupplyVoltage` set, V (the plant's open-circuit supply).
    pub supply_v: Option<f32>,
    /// The current sensor's supply the last `SetSensorSupply` set, V.
    pub sensor_supply_v: Option<f32>,
    /// `Simulation` commands served.
    pub commands: u32,
}

/// The device's UART to the host at 8N1 ([`SimRig::set_link_baud`]): the binary's `host_tx`
/// task takes up to [`UART_WRITE`] bytes from [`Core::transmit`] and writes them, then
/// takes the next; the line carries [`protocol::link_bytes_per_s`] of them per second of
/// device time, so the core's transmit queue fills, and the stream skips samples, exactly
/// as on the board when the link cannot carry everything.
#[derive(Debug, Clone)]
struct Uart {
    /// Bytes per second on the line.
    bytes_per_s: u64,
    /// The write in flight and how much of it is on the line.
    write: Vec<u8>,
    sent: usize,
    /// Line capacity not used yet, in bytes times [`ADC_HZ`] (exact integer pacing).
    credit: u64,
    /// Bytes on the line since the link was paced.
    total: u64,
}

/// Bytes per second the Nucleo's USART2 carries at `baud`: never more than the nominal
/// rate's ([`protocol::link_bytes_per_s`]), and no more than its divider gives at 170 MHz
/// (`firmware_core::usart_brr_over8`: 4,000,000 Bd runs at 3,953,488 Bd, 395,348 B/s), so
/// the virtual rig never sends faster than the board.
pub fn board_bytes_per_s(baud: u32) -> u64 {
    let nominal = u64::from(protocol::link_bytes_per_s(baud));
    let board = firmware_core::usart_brr_over8(model::hardware::board::SYSCLK_HZ as u32, baud)
        .map_or(nominal, |(_, actual)| {
            u64::from(protocol::link_bytes_per_s(actual))
        });
    nominal.min(board)
}

/// Bytes the binary's `host_tx` task takes from the core per write.
pub const UART_WRITE: usize = 256;

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
    flash: Option<RigParameters>,
    bench: BenchSettings,
    /// A debug probe halted the core ([`SimRig::debug_halt`]): no control steps run.
    halted: bool,
    /// The paced link, or `None`: every byte leaves at the control step that framed it.
    uart: Option<Uart>,
    /// A rig file's user effects at work in the plant.
    user: Option<crate::user_effects::UserDrive>,
}

impl SimRig {
    /// A rig at rest, firmware just booted.
    pub fn new(config: SimConfig) -> Self {
        let control_hz = config.core.control_hz.clamp(1, ADC_HZ);
        let boot = BootInfo {
            reset_cause: if config.watchdog_reset {
                ResetCause::Watchdog
            } else {
                ResetCause::PowerOn
            },
            firmware_build: VIRTUAL_BUILD,
            parameters: config.calibration,
            parameters_status: config.calibration_status,
        };
        let mut core_config = config.core;
        core_config.capabilities.insert(Capabilities::SIMULATION);
        // The virtual rig measures its bridge supply (`BoardInputs::bus_voltage_v` below),
        // so it says so; health reports it.
        core_config.capabilities.insert(Capabilities::BUS_VOLTAGE);
        // `Info` states the plant's drive (a rig file may set it): braking or coasting.
        core_config
            .capabilities
            .set(Capabilities::BRAKING_DECAY, config.plant.regeneration);
        Self {
            plant: Plant::new(config.plant, config.seed),
            core: Core::new(core_config, boot),
            ticks_per_step: ADC_HZ / control_hz,
            tick: 0,
            adc: Vec::with_capacity(64),
            drive: Drive::default(),
            outbox: Vec::new(),
            button: false,
            injections: Injections::default(),
            frozen_count: 0,
            flash: Some(config.calibration),
            halted: false,
            bench: BenchSettings {
                supply_v: None,
                sensor_supply_v: None,
                commands: 0,
            },
            uart: None,
            user: config.user_effects.map(crate::user_effects::UserDrive::new),
        }
    }

    /// Paces the device's output to a UART at `baud` (8N1, in device time; from then on at
    /// the rate the host agrees with `SetBaud`), as the board sends it: [`SimRig::from_device`] never yields more than
    /// [`protocol::link_bytes_per_s`] bytes per device second (plus the byte in flight),
    /// and what does not fit waits in the core's transmit queue or is skipped there, as on
    /// the board. `None` (the default) hands every byte out at the step that framed it.
    pub fn set_link_baud(&mut self, baud: Option<u32>) {
        self.uart = baud.map(|b| Uart {
            bytes_per_s: board_bytes_per_s(b),
            write: Vec::with_capacity(UART_WRITE),
            sent: 0,
            credit: 0,
            total: 0,
        });
    }

    /// The paced link's rate, bytes per second of device time (`None`: not paced).
    pub fn link_bytes_per_s(&self) -> Option<u64> {
        self.uart.as_ref().map(|u| u.bytes_per_s)
    }

    /// Bytes the paced link carried since [`SimRig::set_link_baud`] (0: not paced).
    pub fn link_bytes_sent(&self) -> u64 {
        self.uart.as_ref().map_or(0, |u| u.total)
    }

    /// `ticks` ADC ticks of the paced UART: the write in flight goes out at the line's
    /// rate, and when it is done the next is taken from the core (an idle line keeps no
    /// credit: the board's task polls again a tick later).
    fn run_uart(&mut self, ticks: u64) {
        let now_us = self.now_us();
        let Self {
            uart, core, outbox, ..
        } = self;
        let Some(uart) = uart else {
            // Unpaced: a rate the host agreed is taken at once (nothing to pace).
            let _ = core.take_baud_switch(now_us);
            return;
        };
        let hz = u64::from(ADC_HZ);
        uart.credit += ticks * uart.bytes_per_s;
        loop {
            if uart.sent == uart.write.len() {
                let mut buf = [0u8; UART_WRITE];
                let n = core.transmit(&mut buf);
                uart.write.clear();
                uart.sent = 0;
                if n == 0 {
                    uart.credit = 0;
                    // The line is quiet: a rate the host agreed takes effect now, as the
                    // binary switches its USART (`Core::take_baud_switch`).
                    if let Some(baud) = core.take_baud_switch(now_us) {
                        uart.bytes_per_s = board_bytes_per_s(baud);
                    }
                    return;
                }
                uart.write.extend_from_slice(&buf[..n]);
            }
            let left = uart.write.len() - uart.sent;
            let k = usize::try_from(uart.credit / hz).map_or(left, |c| c.min(left));
            outbox.extend_from_slice(&uart.write[uart.sent..uart.sent + k]);
            uart.sent += k;
            uart.credit -= k as u64 * hz;
            uart.total += k as u64;
            if uart.sent < uart.write.len() {
                return;
            }
        }
    }

    /// Simulated time since boot, s.
    pub fn time(&self) -> f64 {
        self.tick as f64 / ADC_HZ as f64
    }

    /// Device clock, microseconds since boot.
    pub fn now_us(&self) -> u64 {
        self.tick * 1_000_000 / ADC_HZ as u64
    }

    /// Runs the closed loop for `seconds` of virtual time.
    ///
    /// The plant steps once per `SAMPLES_PER_PLANT_STEP` ADC samples wherever no control
    /// step falls between them (always at the default 1 kHz control rate: 2 kHz plant
    /// steps, five samples each, [`Plant::step_sampled`], exact for the winding within the
    /// step); elsewhere once per sample. The mechanics' semi-implicit step of 0.5 ms turns
    /// the cam by at most 0.05 rad at 15 Hz; the model's own tests hold at that step too.
    pub fn advance(&mut self, seconds: f64) {
        let ticks = (seconds * ADC_HZ as f64).round().max(0.0) as u64;
        let dt = 1.0 / ADC_HZ as f64;
        let group = SAMPLES_PER_PLANT_STEP;
        let grouped = self.ticks_per_step.is_multiple_of(group);
        let mut left = ticks;
        while left > 0 {
            // A group starts on a multiple of its size, so no control step falls inside it.
            let n = if grouped && left >= u64::from(group) && self.tick.is_multiple_of(group.into())
            {
                group
            } else {
                1
            };
            let stuck = self.injections.current_adc_stuck;
            let adc = &mut self.adc;
            self.plant
                .step_sampled(f64::from(n) * dt, self.drive, n, |code| {
                    adc.push(stuck.unwrap_or(code));
                });
            self.tick += u64::from(n);
            left -= u64::from(n);
            if !self.halted {
                if self.tick.is_multiple_of(self.ticks_per_step as u64) {
                    self.control_step();
                }
                self.run_uart(u64::from(n));
            }
        }
    }

    fn control_step(&mut self) {
        if let Some(user) = self.user.as_mut() {
            let dt = f64::from(self.ticks_per_step) / f64::from(ADC_HZ);
            user.update(&mut self.plant, dt, self.tick as f64 / f64::from(ADC_HZ));
        }
        let encoder_count = if self.injections.encoder_frozen {
            self.frozen_count
        } else {
            self.frozen_count = self.plant.encoder_count();
            self.frozen_count
        };
        let encoder_count = if self.injections.encoder_reversed {
            encoder_count.wrapping_neg()
        } else {
            encoder_count
        };
        // The timer's break flag (SR.BIF).
        self.core.set_board_inputs(BoardInputs {
            hw_break: self.plant.break_tripped(),
            // VDDA as the binary measures it through VREFINT.
            vdda_v: self.plant.params().sensors.adc_reference as f32,
            // The bus divider's reading (its 0.9 ms filter averages the PWM ripple).
            bus_voltage_v: self.plant.bus_voltage() as f32,
            ..BoardInputs::default()
        });
        // The optional output encoder reads the plant's output angle at its resolution.
        let output_count = self.core.config().output_encoder.map(|e| {
            let counts = self.plant.state().output_angle / core::f64::consts::TAU
                * f64::from(e.counts_per_rev);
            // The hardware counter is 16 bits and wraps.
            (counts.round() as i64).rem_euclid(1 << 16) as u16
        });
        self.core.set_output_encoder_count(output_count);
        let inputs = Inputs {
            now_us: self.now_us(),
            current_adc: &self.adc,
            encoder_count,
            release_button: self.button,
        };
        let out = self.core.step(&inputs);
        if self.plant.break_tripped()
            && !out.enable
            && self.core.break_latched()
            && self.plant.state().current.abs() < model::hardware::comparator::TRIP_A
        {
            // As the binary (`CamMotor::rearm`): once the core stopped driving and latched
            // HW_OVERCURRENT, and the current is back under the threshold, the break flag is
            // cleared; ClearFaults can then clear the fault (its condition is gone).
            self.plant.rearm_break();
        }
        self.adc.clear();
        self.drive = Drive {
            duty: out.duty as f64,
            enabled: out.enable,
        };
        if let Some(cal) = out.persist {
            self.flash = Some(cal);
            self.core.persist_result(true);
        }
        if self.uart.is_some() {
            // The paced UART takes the bytes at the line's rate (`SimRig::run_uart`).
            return;
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

    /// A debug probe halts the core, leaving the bridge in the board's halt state
    /// ([`SimRig::debug_halt_with`] the firmware's `TIM1_STOPS_IN_DEBUG`).
    pub fn debug_halt(&mut self) {
        self.debug_halt_with(model::hardware::board::TIM1_STOPS_IN_DEBUG);
    }

    /// A debug probe halts the core: no control step runs. With `tim1_stops`
    /// (DBG_TIM1_STOP set) TIM1 puts PA8 at its idle level, low, and the bridge enable, a
    /// GPIO, stays as it was: on the Pololu G2 (braking decay) PWM low with the enable high
    /// shorts the winding through both low sides, so a spinning cam drives its back-EMF over
    /// the winding resistance alone (about 17 A at 15 Hz), modelled as the drive enabled at
    /// duty 0. Without (the firmware's setting), TIM1 keeps switching the last duty.
    pub fn debug_halt_with(&mut self, tim1_stops: bool) {
        self.halted = true;
        if tim1_stops {
            self.drive = Drive {
                duty: 0.0,
                enabled: self.drive.enabled,
            };
        }
    }

    /// The IWDG (not frozen in debug) resets the chip ~250 ms into a halt: the pins float,
    /// the bridge's pull-downs switch it off. The core stays halted (the drill ends here).
    pub fn watchdog_reset_pins(&mut self) {
        self.drive = Drive {
            duty: 0.0,
            enabled: false,
        };
    }

    /// Bytes from the host to the device. `Simulation` commands act on the plant and the
    /// bench; everything else goes to the firmware core's protocol server.
    pub fn to_device(&mut self, bytes: &[u8]) {
        let now = self.now_us();
        let Self {
            core, plant, bench, ..
        } = self;
        core.receive_with(now, bytes, |command| serve(command, plant, bench));
    }

    /// The bench as the `Simulation` commands left it.
    pub fn bench(&self) -> BenchSettings {
        self.bench
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

    /// The host closed the link (`firmware_core::Core::link_closed`): the continuous
    /// stream stops.
    pub fn link_closed(&mut self) {
        self.core.link_closed();
    }

    /// Whether the bridge drives the motor now: the firmware enables it and the hardware
    /// overcurrent trip has not broken it off.
    pub fn bridge_on(&self) -> bool {
        self.drive.enabled && !self.plant.break_tripped()
    }

    /// The H-bridge command the firmware applies now.
    pub fn drive(&self) -> Drive {
        self.drive
    }

    /// The rig parameters in the simulated flash.
    pub fn flash(&self) -> Option<RigParameters> {
        self.flash
    }
}

/// Serves one `Simulation` command on the plant and the bench.
fn serve(
    command: SimCommand,
    plant: &mut Plant,
    bench: &mut BenchSettings,
) -> Result<(), NackCode> {
    let finite = |v: f32| {
        if v.is_finite() {
            Ok(f64::from(v))
        } else {
            Err(NackCode::BadArgument)
        }
    };
    let positive = |v: f32| {
        if v > 0.0 {
            finite(v)
        } else {
            Err(NackCode::BadArgument)
        }
    };
    // Physical bounds, so a typo is refused rather than simulated: twice the teeth's
    // strength (the protections above it can still be exercised), twice the bridge supply.
    let max_load = 2.0 * model::paper::TAU_ROT_MAX;
    let max_supply = 2.0 * model::hardware::board::BRIDGE_SUPPLY_V;
    let within = |v: f64, max: f64| {
        if v.abs() <= max {
            Ok(v)
        } else {
            Err(NackCode::BadArgument)
        }
    };
    match command {
        // The operator hangs the load still (a load still falling from the last run is
        // caught and hung again), where the output is: the encoder sees no jump.
        SimCommand::SetLoad { tau_rot_nm } => {
            plant.set_load(Load::Torque(within(finite(tau_rot_nm)?, max_load)?));
            plant.stop_output();
        }
        SimCommand::SetSupplyVoltage { volts } => {
            plant.set_supply(within(positive(volts)?, max_supply)?);
            bench.supply_v = Some(volts);
        }
        SimCommand::SetSensorSupply { volts } => {
            plant.set_sensor_supply(positive(volts)?);
            bench.sensor_supply_v = Some(volts);
        }
        // A command of a newer protocol this simulator does not model.
        _ => return Err(NackCode::UnknownMessage),
    }
    bench.commands += 1;
    Ok(())
}
