//! The simulated rig: vibrator motor and cam, carrier, output shaft with its load, and the
//! sensors, stepped at a fixed time step (`no_std`, so it could run on the target too).
//!
//! Integration: the winding current is advanced exactly over each step for the speed at the
//! step's start (first-order exponential of the R-L circuit, stable at any step), the
//! mechanics with semi-implicit Euler and Coulomb sticking. At the default 10 kHz the cam
//! turns at most 0.01 rad per step; an energy ledger checks the balance.

pub mod bus;
mod effects;
mod motor;
pub mod pwm;
mod rng;
mod sensors;

pub use effects::{MeshRipple, PlantEffects, compliant_stroke};
pub use motor::MotorParams;
pub use pwm::AdcSampling;
pub use rng::NoiseSource;
pub use sensors::{AdcTransfer, SensorParams};

use crate::effects::{
    axial_corner_speed, axial_friction_speed_factor, carrier_inertia_torque,
    carrier_inertia_torque_at_kappa, carrier_inertia_torque_taken, load_dependent_kappa,
    offset_current, viscous_loss_torque,
};
use crate::hardware::{board, rs735};
use crate::math::{cos, sin};
use crate::{CamDrive, GearSet, OutputShaft, paper};

/// Below this speed (rad/s) a shaft counts as standing still.
const STANDSTILL: f64 = 1e-6;

pub use crate::load::Load;

/// How the cam shaft is set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum CamSetup {
    /// The cam drives the carrier (normal operation).
    Coupled,
    /// The vibrator turns alone, nothing on the cam (the paper's no-load current test).
    Uncoupled,
    /// An arm on the vibrator shaft presses on a force gauge (the paper's torque test).
    Blocked,
}

/// Everything that defines a simulated rig.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PlantParams {
    /// The vibrator.
    pub motor: MotorParams,
    /// The hardware overcurrent trip's threshold at the current-sense pin, V
    /// ([`crate::hardware::comparator`]); `None`: no comparator. Once the pin voltage
    /// exceeds it the bridge stays off (the timer's break) until [`Plant::rearm_break`].
    #[cfg_attr(feature = "serde", serde(default))]
    pub break_threshold_v: Option<f64>,
    /// Gear set, eccentricity and carrier mass.
    pub drive: CamDrive,
    /// Static friction coefficient of the teeth.
    pub mu_s: f64,
    /// Dynamic friction coefficient of the teeth.
    pub mu_d: f64,
    /// Axial friction coefficient in the cam torque (Eq. 9); the paper assumes mu_ax ~ mu.
    pub mu_ax: f64,
    /// Equivalent output inertia of the gear (Eq. 7), without the load, kg m^2.
    pub i_hat: f64,
    /// The load.
    pub load: Load,
    /// H-bridge supply, V (open-circuit: the bus sags under load through
    /// `supply_resistance`).
    pub supply: f64,
    /// Internal resistance of the supply and its leads, ohm
    /// ([`crate::hardware::board::SUPPLY_RESISTANCE_OHM`]).
    #[cfg_attr(feature = "serde", serde(default))]
    pub supply_resistance: f64,
    /// Capacitance on the bridge's bus, F ([`crate::hardware::board::BUS_CAPACITANCE_F`]),
    /// fed by a supply that cannot sink: power the bridge returns charges it and the bus
    /// rises ([`bus`]). Zero: a supply that sinks as well as sources (the bus is the supply
    /// less the resistive sag, whichever way the current flows).
    #[cfg_attr(feature = "serde", serde(default))]
    pub bus_capacitance: f64,
    /// Whether the drive can take power back (synchronous H-bridge, backdrivable gearhead).
    /// Without it the current cannot reverse and the carrier's inertial power is lost, so the
    /// inertia term of Eq. (9) no longer averages out (`inertia-rectification`).
    pub regeneration: bool,
    /// Apply Eq. (40): the axial friction share falls as the output speeds up,
    /// mu_ax = mu w_n / sqrt(w_n^2 + (w_t / lambda)^2) with the simulated output speed w_t.
    pub friction_split: bool,
    /// How the cam is set up.
    pub cam: CamSetup,
    /// Sensors.
    pub sensors: SensorParams,
    /// Effects beyond the paper's model.
    pub effects: PlantEffects,
    /// How far the output may turn either way from where the load was hung before the
    /// load rests (a hanging mass on the floor, a brake arm on its end stop), rad; `None`:
    /// no end (the paper's equations alone). Resting, the load's torque is carried by the
    /// floor, not the gear ([`Plant::load_resting`]); hanging it again
    /// ([`Plant::stop_output`]) starts a new travel from where the output is.
    #[cfg_attr(feature = "serde", serde(default))]
    pub output_travel: Option<f64>,
}

impl PlantParams {
    /// The paper's rig with gear set `z`, the load `load` and Table 2's vibrator, on the
    /// board's bridge supply ([`crate::paper`], [`crate::hardware`]).
    pub fn paper(gear: GearSet, load: Load) -> Self {
        Self {
            motor: MotorParams::default(),
            break_threshold_v: None,
            drive: CamDrive::paper(gear),
            mu_s: paper::MU_S,
            mu_d: paper::MU_D,
            mu_ax: paper::MU_S,
            i_hat: paper::I_HAT,
            load,
            supply: board::BRIDGE_SUPPLY_V,
            supply_resistance: board::SUPPLY_RESISTANCE_OHM,
            bus_capacitance: board::BUS_CAPACITANCE_F,
            // The board's decay decides (`board::DECAY`): coasting by default, as the
            // paper's bench supply that cannot take power back; a braking bridge (the G2)
            // returns it into a bus whose supply cannot sink it (`bus_capacitance`).
            regeneration: board::REGENERATIVE_DECAY,
            friction_split: false,
            cam: CamSetup::Coupled,
            sensors: SensorParams::default(),
            effects: PlantEffects::default(),
            output_travel: None,
        }
    }

    /// The output shaft of Eq. (6), load inertia included.
    pub fn output_shaft(&self) -> OutputShaft {
        OutputShaft::new(
            &self.drive.gear,
            self.drive.eccentricity,
            self.i_hat + self.load.inertia(),
            self.mu_s,
            self.mu_d,
        )
    }
}

/// The H-bridge command, as the firmware's PWM timer and pins set it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Drive {
    /// Duty cycle, -1..1 (sign: direction pin).
    pub duty: f64,
    /// Bridge enabled. Disabled, the bridge is open and the current dies out at once.
    pub enabled: bool,
}

/// The plant's physical state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// Simulated time, s.
    pub time: f64,
    /// Winding current, A.
    pub current: f64,
    /// Cam angle, rad (0: carrier at +e).
    pub cam_angle: f64,
    /// Cam speed omega_n, rad/s.
    pub cam_speed: f64,
    /// Output angle, rad (positive: the direction the load drives it).
    pub output_angle: f64,
    /// Output speed omega_t, rad/s.
    pub output_speed: f64,
    /// Winding temperature, deg C.
    pub temperature: f64,
    /// Torque on the gauge arm in the blocked-shaft setup, N m.
    pub gauge_torque: f64,
    /// Voltage across the motor over the last step, V.
    pub motor_voltage: f64,
    /// Bridge supply at the board over the last step (after the supply's internal
    /// resistance), V: what the bus divider measures.
    pub bus_voltage: f64,
}

/// Energy bookkeeping, J, for the balance check.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyLedger {
    /// Delivered by the supply.
    pub electrical_in: f64,
    /// Lost in the winding resistance.
    pub resistive: f64,
    /// Lost in the gearhead (the part of the back-EMF power not reaching the cam shaft).
    pub gearhead: f64,
    /// Lost in the vibrator's own friction.
    pub vibrator_friction: f64,
    /// Lost in tooth (and bush) friction against the axial motion.
    pub axial_friction: f64,
    /// Work done by the load on the output.
    pub load_work: f64,
    /// Lost in the output's friction.
    pub output_friction: f64,
    /// Lost when the load lands on its floor or end stop (its kinetic energy).
    pub end_stop: f64,
    /// Inertial power of the carrier the drive could not take back (no regeneration).
    pub unreturned: f64,
}

/// The true torque the cam delivers to the carrier (tooth and bush friction against the
/// axial motion and the carrier's inertia, Eq. (9)), summed over whole cam revolutions
/// since the start: what the firmware's per-revolution tau_cam estimate stands for. Two
/// readings give the mean over the revolutions between them
/// ([`CamTorqueLedger::mean_since`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CamTorqueLedger {
    /// Whole cam revolutions completed.
    pub revolutions: u64,
    /// Time those revolutions took, s.
    pub seconds: f64,
    /// Integral of the cam torque over that time, N m s.
    pub torque_seconds: f64,
}

impl CamTorqueLedger {
    /// Mean cam torque over the revolutions completed between `earlier` and this reading,
    /// N m; `None` when none completed.
    pub fn mean_since(&self, earlier: &CamTorqueLedger) -> Option<f64> {
        let dt = self.seconds - earlier.seconds;
        (self.revolutions > earlier.revolutions && dt > 0.0)
            .then(|| (self.torque_seconds - earlier.torque_seconds) / dt)
    }
}

/// The simulated rig.
#[derive(Debug, Clone)]
pub struct Plant {
    params: PlantParams,
    state: PlantState,
    rng: NoiseSource,
    energy: EnergyLedger,
    shaft: OutputShaft,
    /// For the (dt, R) they were computed at (R drifts slowly with temperature): the step's
    /// decay exp(-dt R / L), the mean-current factor tau / dt (1 - decay) and 1 / R.
    decay_cache: (f64, u32, f64, [f64; 4]),
    /// sin and cos of the cam angle they were computed at, and steps until a full
    /// evaluation.
    trig_cache: (f64, f64, f64, u32),
    /// The gear's axial force per unit of output torque (Eq. 8), computed once.
    axial_per_torque: f64,
    /// The output mesh's ripple of friction over the mesh angle, computed once.
    mesh: effects::MeshRipple,
    /// Where the output mesh's cycle stood at output angle zero, in mesh cycles, drawn at
    /// every load change ([`Plant::set_load`]): the operator hangs each test's weight with
    /// the output wherever it came to rest, so each test meets the mesh ripple at a phase of
    /// its own (drawn only with the ripple on, so every other plant's noise is unchanged).
    mesh_phase: f64,
    /// 1 / thermal resistance and 1 / heat capacity of the winding.
    thermal: [f64; 2],
    /// The comparator tripped the timer's break: the bridge is off.
    break_tripped: bool,
    /// The PWM ripple at the end of the last step: duty magnitude and the signed
    /// peak-to-peak (negative in reverse; zero with the bridge off).
    ripple: (f64, f64),
    /// The ripple's value at the ADC's sampling instant (signed, A), and the triangle's
    /// shape there per ampere of ripple for the duty it was computed at: (duty, shape).
    ripple_sample: f64,
    ripple_shape: (f64, f64),
    /// The current sensor chain as one affine map (recomputed when the sensor changes).
    adc: AdcTransfer,
    /// The winding's mean-model current within the last step: the start and steady-state
    /// currents and the decay per sample interval (`samples` per step), or `None` when the
    /// bridge was off or clamped (then the step's mean stands for every sample).
    within: Option<(f64, f64, f64)>,
    /// ADC samples per step ([`Plant::step_sampled`]).
    samples: u32,
    /// The current at which the comparator's pin reaches its threshold, A (infinite
    /// without one; recomputed when the sensor changes).
    break_current: f64,
    /// PWM period over the winding inductance, A per volt of ripple factor d (1 - d) V.
    ripple_per_volt: f64,
    /// 1 / the output's inertia (load included).
    inv_i_hat: f64,
    /// The cam torque over whole revolutions, and the revolution under way: its start
    /// angle, seconds and torque integral.
    cam_ledger: CamTorqueLedger,
    cam_rev: (f64, f64, f64),
    /// The output angle where the load was hung ([`PlantParams::output_travel`] counts
    /// from it), and whether it rests on its floor or end stop.
    hung_at: f64,
    resting: bool,
    /// A user effect's extra current ([`Plant::set_user_current`]), A.
    user_current: f64,
}

impl Plant {
    /// A rig at rest at ambient temperature; `seed` fixes the sensor noise.
    pub fn new(params: PlantParams, seed: u64) -> Self {
        Self {
            shaft: params.output_shaft(),
            state: PlantState {
                temperature: params.motor.ambient_c,
                bus_voltage: params.supply,
                ..Default::default()
            },
            rng: NoiseSource::new(seed),
            energy: EnergyLedger::default(),
            decay_cache: (f64::NAN, 0, f64::NAN, [0.0; 4]),
            trig_cache: (0.0, 0.0, 1.0, 0),
            axial_per_torque: params.drive.gear.axial_force_per_torque(),
            mesh: effects::MeshRipple::of(&params.drive.gear),
            mesh_phase: 0.0,
            thermal: [
                1.0 / params.motor.thermal_resistance,
                1.0 / params.motor.thermal_capacity,
            ],
            break_tripped: false,
            ripple: (0.0, 0.0),
            ripple_sample: 0.0,
            ripple_shape: (0.0, 0.0),
            adc: params.sensors.adc_transfer(),
            within: None,
            samples: 1,
            break_current: break_current(&params),
            ripple_per_volt: if params.motor.inductance > 0.0 {
                pwm::PERIOD_S / params.motor.inductance
            } else {
                0.0
            },
            inv_i_hat: 1.0 / params.output_shaft().i_hat,
            cam_ledger: CamTorqueLedger::default(),
            cam_rev: (0.0, 0.0, 0.0),
            hung_at: 0.0,
            resting: false,
            user_current: 0.0,
            params,
        }
    }

    /// Sets the extra current a rig file's user effects draw here (a law in A of the
    /// operating point, evaluated by the caller as it changes): the plant runs it as a drag
    /// on the turning vibrator of the torque that current makes, so at steady speed the
    /// winding draws that much more, warms by it and slows as a real drag would. A negative
    /// current lightens the vibrator's own friction, never below none.
    pub fn set_user_current(&mut self, amps: f64) {
        self.user_current = if amps.is_finite() { amps } else { 0.0 };
    }

    /// The extra current last set by [`Plant::set_user_current`], A.
    pub fn user_current(&self) -> f64 {
        self.user_current
    }

    /// The winding's step response over `dt` at `resistance`: [exp(-dt / tau), the
    /// mean-current factor tau / dt (1 - exp(-dt / tau)), 1 / R, exp(-dt / (n tau))] for
    /// `n` ADC samples per step. Recomputed only when dt, n or R moved (R by more than 1e-4
    /// relative: the error that leaves is below 1e-8 of a step).
    fn winding(&mut self, dt: f64, resistance: f64) -> [f64; 4] {
        let n = self.samples;
        let (cdt, cn, cr, value) = self.decay_cache;
        if cdt == dt && cn == n && (resistance - cr).abs() <= 1e-4 * cr {
            return value;
        }
        let tau = self.params.motor.inductance / resistance;
        let decay = libm::exp(-dt / tau);
        let value = [
            decay,
            tau / dt * (1.0 - decay),
            1.0 / resistance,
            if n > 1 {
                libm::exp(-dt / (f64::from(n) * tau))
            } else {
                decay
            },
        ];
        self.decay_cache = (dt, n, resistance, value);
        value
    }

    /// sin and cos of the cam angle. A step turns the cam by at most a few hundredths of a
    /// radian, so the last pair is rotated by the step's angle (Taylor to the 4th order,
    /// error below 1e-12); a full evaluation every 64 steps keeps rounding from building up.
    fn cam_trig(&mut self) -> (f64, f64) {
        let angle = self.state.cam_angle;
        let (at, s0, c0, left) = self.trig_cache;
        let d = angle - at;
        if d == 0.0 {
            return (s0, c0);
        }
        let (s, c, left) = if d.abs() < 0.05 && left > 0 {
            let d2 = d * d;
            // Multiplications by the reciprocals: no divisions in the step's chain.
            let sd = d * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0)));
            let cd = 1.0 - d2 * 0.5 * (1.0 - d2 * (1.0 / 12.0));
            (s0 * cd + c0 * sd, c0 * cd - s0 * sd, left - 1)
        } else {
            (sin(angle), cos(angle), 64)
        };
        self.trig_cache = (angle, s, c, left);
        (s, c)
    }

    /// The parameters.
    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// Changes the load (the operator hangs another mass).
    pub fn set_load(&mut self, load: Load) {
        self.params.load = load;
        // A new test: the output's mesh meets it at a phase of its own.
        if self.params.effects.mesh_ripple_rms > 0.0 {
            self.mesh_phase = self.rng.uniform();
        }
        self.shaft = self.params.output_shaft();
        self.inv_i_hat = 1.0 / self.shaft.i_hat;
    }

    /// Changes the cam setup (coupled, uncoupled, blocked on the gauge).
    pub fn set_cam(&mut self, cam: CamSetup) {
        self.params.cam = cam;
        if cam == CamSetup::Blocked {
            self.state.cam_speed = 0.0;
        }
    }

    /// Stops the output where it is (the operator steadies the load, or hangs it again):
    /// the load's travel starts again from here.
    pub fn stop_output(&mut self) {
        self.state.output_speed = 0.0;
        self.hung_at = self.state.output_angle;
        self.resting = false;
    }

    /// Stops the output and puts it back at angle zero (the operator resets the load).
    pub fn reset_output(&mut self) {
        self.state.output_angle = 0.0;
        self.stop_output();
    }

    /// The load rests on its floor or end stop ([`PlantParams::output_travel`]): the
    /// output stands still and the gear carries none of the load's torque.
    pub fn load_resting(&self) -> bool {
        self.resting
    }

    /// The physical state.
    pub fn state(&self) -> &PlantState {
        &self.state
    }

    /// The energy ledger since the start.
    pub fn energy(&self) -> &EnergyLedger {
        &self.energy
    }

    /// Energy stored now: winding field, cam and carrier motion, output motion, J.
    pub fn stored_energy(&self) -> f64 {
        let s = &self.state;
        let p = &self.params;
        let e = p.drive.eccentricity;
        let carrier = if p.cam == CamSetup::Coupled {
            let v = e * s.cam_speed * sin(s.cam_angle);
            0.5 * p.drive.carrier_mass * v * v
        } else {
            0.0
        };
        0.5 * p.motor.inductance * s.current * s.current
            + 0.5 * p.motor.inertia * s.cam_speed * s.cam_speed
            + carrier
            + 0.5 * self.shaft.i_hat * s.output_speed * s.output_speed
    }

    /// ADC code of the current sensor now (with noise and quantisation), sampled at the
    /// ADC's instant in the PWM period ([`SensorParams::sampling`]): the mean current plus
    /// the ripple there ([`pwm`]).
    #[inline]
    pub fn current_adc(&mut self) -> u16 {
        let i = self.sampled_current();
        self.adc.code(i, &mut self.rng)
    }

    /// Advances the plant by `dt` seconds under `drive` with the ADC sampling `samples`
    /// times at even intervals through the step (the last at its end, [`Plant::current_adc`]),
    /// handing each code to `sink` in order: a caller whose ADC runs `samples` times faster
    /// than it steps the plant. The winding's response within the step is exact (the R-L
    /// exponential for the step's back-EMF), so each sample is the one a step ending there
    /// would have given; the mechanics take one step of `dt`.
    pub fn step_sampled(&mut self, dt: f64, drive: Drive, samples: u32, mut sink: impl FnMut(u16)) {
        self.samples = samples.max(1);
        self.step(dt, drive);
        if let Some((i0, i_ss, sample_decay)) = self.within {
            let mut left = i0 - i_ss;
            for _ in 1..self.samples {
                left *= sample_decay;
                let i = self.instantaneous(i_ss + left);
                sink(self.adc.code(i, &mut self.rng));
            }
        } else {
            for _ in 1..self.samples {
                let i = self.instantaneous(self.state.current);
                sink(self.adc.code(i, &mut self.rng));
            }
        }
        sink(self.current_adc());
    }

    /// The instantaneous winding current at the ADC's sampling instant, A.
    #[inline]
    pub fn sampled_current(&self) -> f64 {
        self.instantaneous(self.state.current)
    }

    /// The winding current at the ADC's sampling instant for the mean-model current `mean`.
    #[inline]
    fn instantaneous(&self, mean: f64) -> f64 {
        let pp = self.ripple.1;
        if pp == 0.0 {
            return mean;
        }
        let i = mean + self.ripple_sample;
        // Without regeneration the current does not cross zero against the drive (the
        // discontinuous conduction this implies for the mean is not modelled).
        if !self.params.regeneration && (i < 0.0) != (pp < 0.0) && i != 0.0 {
            0.0
        } else {
            i
        }
    }

    /// Peak-to-peak PWM ripple of the winding current now, A (zero with the bridge off).
    pub fn ripple_peak_to_peak(&self) -> f64 {
        self.ripple.1.abs()
    }

    /// The bridge supply at the board now, V (what the firmware's bus divider reads).
    pub fn bus_voltage(&self) -> f64 {
        self.state.bus_voltage
    }

    /// Changes the bridge's supply (open-circuit) voltage, V (the bench turns its knob).
    pub fn set_supply(&mut self, volts: f64) {
        self.params.supply = volts;
        if self.ripple.1 == 0.0 {
            self.state.bus_voltage = volts;
        }
    }

    /// Changes the current sensor's supply, V (the ACS714 is ratiometric: its zero and
    /// sensitivity follow).
    pub fn set_sensor_supply(&mut self, volts: f64) {
        self.params.sensors.acs_supply = volts;
        self.adc = self.params.sensors.adc_transfer();
        self.break_current = break_current(&self.params);
    }

    /// The true cam torque over the whole revolutions completed so far.
    pub fn cam_torque_ledger(&self) -> CamTorqueLedger {
        self.cam_ledger
    }

    /// The current a logger on the sensor reads (the `current-sensor-offset` effect included), A.
    pub fn logged_current(&mut self) -> f64 {
        let noise =
            self.params.sensors.acs_noise / self.params.sensors.acs_sensitivity * self.rng.normal();
        offset_current(self.state.current, self.params.effects.current_offset) + noise
    }

    /// Whether the hardware overcurrent trip has switched the bridge off (the break flag
    /// the firmware reads).
    pub fn break_tripped(&self) -> bool {
        self.break_tripped
    }

    /// Re-arms the break (the firmware sets the timer's main output enable again).
    pub fn rearm_break(&mut self) {
        self.break_tripped = false;
    }

    /// Encoder counter (16-bit, wrapping) now.
    pub fn encoder_count(&self) -> u16 {
        self.params.sensors.encoder_count(self.state.cam_angle)
    }

    /// Advances the plant by `dt` seconds under the bridge command `drive`.
    pub fn step(&mut self, dt: f64, mut drive: Drive) {
        // The timer's break holds the bridge off whatever the firmware commands.
        drive.enabled &= !self.break_tripped;
        let temp = self.state.temperature;
        let resistance = self.params.motor.resistance
            * (1.0 + rs735::COPPER_TEMPCO_PER_K * (temp - self.params.motor.ambient_c));
        let winding = self.winding(dt, resistance);
        let (s, c) = self.cam_trig();
        // Borrowed, not copied: the parameters are a few hundred bytes and this runs at 10 kHz.
        let p = &self.params;
        let m = &p.motor;
        let omega = self.state.cam_speed;

        // Electrical: exact R-L response for this step's back-EMF, on the bus the supply's
        // internal resistance leaves at the last step's supply current d i (sign-magnitude:
        // the supply carries the winding current during the on-time only).
        let duty = drive.duty.clamp(-1.0, 1.0);
        let i0 = self.state.current;
        let bus = if p.bus_capacitance > 0.0 {
            // The bus capacitor's voltage at the step's start ([`bus`]).
            self.state.bus_voltage
        } else if drive.enabled {
            p.supply - p.supply_resistance * duty * i0
        } else {
            p.supply
        };
        let v_bridge = duty * bus;
        let (i1, i_mean, v_motor) = if drive.enabled {
            let [decay, mean_factor, conductance, sample_decay] = winding;
            let i_ss = (v_bridge - m.ke_cam() * omega) * conductance;
            let i1 = i_ss + (i0 - i_ss) * decay;
            let mean = i_ss + (i0 - i_ss) * mean_factor;
            if !p.regeneration && (i1 < 0.0) != (v_bridge < 0.0) && i1 != 0.0 {
                // Diode-clamped bridge: current cannot flow against the applied voltage.
                self.within = None;
                (0.0, 0.5 * i0.max(0.0), m.ke_cam() * omega)
            } else {
                self.within = Some((i0, i_ss, sample_decay));
                (i1, mean, v_bridge)
            }
        } else {
            self.within = None;
            (0.0, 0.0, m.ke_cam() * omega)
        };

        // Mechanical, cam shaft.
        let ktf = p.effects.torque_constant_factor(temp, m.ambient_c);
        let t_motor = m.torque_per_amp * ktf * i_mean;
        // A load resting on its floor pulls on a slack rope: the gear carries none of it
        // until it is hung again or pulls away from the stop.
        let tau_rot = match (self.resting, p.output_travel) {
            (true, Some(_)) if (self.state.output_angle - self.hung_at) * p.load.torque() > 0.0 => {
                0.0
            }
            _ => p.load.torque(),
        };
        let e = p.drive.eccentricity;
        let coupled = p.cam == CamSetup::Coupled;
        let mass = if coupled { p.drive.carrier_mass } else { 0.0 };
        // The teeth's axial friction force, rippling over the mesh angle (seed 003) and
        // sliding over the stroke its tooth compliance leaves (seed 004), and the bush's.
        let t_axial = if coupled {
            let mut mu_ax = p.effects.axial_mu(p.mu_ax, omega, tau_rot);
            if p.friction_split {
                let corner = axial_corner_speed(self.state.output_speed, self.shaft.small_lambda);
                mu_ax *= axial_friction_speed_factor(omega, corner);
            }
            let teeth = mu_ax
                * tau_rot.abs()
                * self.axial_per_torque
                * self.mesh.friction_factor(
                    p.effects.mesh_ripple_rms,
                    self.state.output_angle,
                    self.mesh_phase,
                );
            (teeth * compliant_stroke(e, p.effects.tooth_compliance, teeth)
                + p.effects.bush_friction * e)
                * s.abs()
        } else {
            0.0
        };
        // The vibrator's dry losses, with a user effect's drag (`set_user_current`).
        let kinetic =
            (m.coulomb + m.running_loss + m.torque_per_amp * ktf * self.user_current).max(0.0);
        // The vibrator's viscous loss: C3's and the `vibrator-viscous-loss` effect's.
        let viscous_torque =
            |w: f64| m.viscous * w.abs() + viscous_loss_torque(p.effects.extra_viscous, w);
        let inertia = m.inertia + mass * e * e * s * s;
        let t_carrier_full = carrier_inertia_torque(mass, e, s, c, omega);
        // Without regeneration the drive cannot take back the carrier's inertial power: the
        // part of the cycle where the carrier pushes the cam is lost, not returned.
        // A fitted rectification (`inertia-rectification` in a rig file's [model]) runs as
        // its kappa law; otherwise the drive's own (regenerating or not).
        let t_carrier = match p.effects.inertia_kappa {
            Some((kappa, per_nm)) => carrier_inertia_torque_at_kappa(
                t_carrier_full,
                omega,
                load_dependent_kappa(kappa, per_nm, tau_rot),
            ),
            None => carrier_inertia_torque_taken(t_carrier_full, omega, p.regeneration),
        };
        let new_omega = if p.cam == CamSetup::Blocked {
            self.state.gauge_torque = if t_motor.abs() > m.coulomb {
                t_motor - m.coulomb * t_motor.signum()
            } else {
                0.0
            };
            0.0
        } else if omega.abs() < STANDSTILL {
            let drive_torque = t_motor - t_carrier;
            let resist = m.coulomb + t_axial;
            if drive_torque.abs() <= resist {
                0.0
            } else {
                let net = drive_torque - drive_torque.signum() * (kinetic + t_axial);
                net / inertia * dt
            }
        } else {
            let friction = omega.signum() * (kinetic + viscous_torque(omega) + t_axial);
            let accel = (t_motor - t_carrier - friction) / inertia;
            let w = omega + accel * dt;
            if w.signum() != omega.signum() && (t_motor - t_carrier).abs() <= kinetic + t_axial {
                0.0
            } else {
                w
            }
        };
        let omega_mean = 0.5 * (omega + new_omega);
        let dtheta = new_omega * dt;

        // Output shaft, Eq. (6), with the bush's hold when that effect is on.
        let omega_n = if coupled { new_omega.abs() } else { 0.0 };
        let wt = self.state.output_speed;
        let bush_hold = p.effects.bush_hold_torque(omega_n);
        let out_friction = self.shaft.friction_torque(tau_rot, wt, omega_n);
        let new_wt = if wt.abs() < STANDSTILL && tau_rot.abs() <= bush_hold {
            0.0
        } else {
            // Eq. (6) with the friction computed above (the same as `OutputShaft::acceleration`).
            let a = (tau_rot + out_friction) * self.inv_i_hat;
            let w = wt + a * dt;
            if wt.abs() >= STANDSTILL && w.signum() != wt.signum() {
                0.0
            } else {
                w
            }
        };
        let wt_mean = 0.5 * (wt + new_wt);

        // Thermal.
        let heat = i_mean * i_mean * resistance;
        self.state.temperature +=
            (heat - (temp - m.ambient_c) * self.thermal[0]) * self.thermal[1] * dt;

        // Ledger.
        let led = &mut self.energy;
        led.electrical_in += v_motor * i_mean * dt * if drive.enabled { 1.0 } else { 0.0 };
        led.resistive += resistance * i_mean * i_mean * dt;
        led.gearhead += (m.ke_cam() - m.torque_per_amp * ktf) * i_mean * omega_mean * dt;
        if p.cam != CamSetup::Blocked && new_omega != 0.0 {
            led.vibrator_friction += (kinetic + viscous_torque(omega_mean)) * omega_mean.abs() * dt;
            led.axial_friction += t_axial * omega_mean.abs() * dt;
            led.unreturned += (t_carrier - t_carrier_full) * omega_mean * dt;
        }
        led.load_work += tau_rot * wt_mean * dt;
        led.output_friction += -out_friction * wt_mean * dt;

        // The true cam torque (Eq. 9 on the carrier side, with the carrier's share of the
        // cam's acceleration), over whole revolutions; a cam at rest starts a new one.
        if coupled && new_omega != 0.0 {
            let accel = (new_omega - omega) / dt;
            let tau = t_axial + t_carrier + mass * e * e * s * s * accel;
            let (start, secs, integral) = &mut self.cam_rev;
            *secs += dt;
            *integral += tau * dt;
            let turned = self.state.cam_angle + dtheta - *start;
            if turned.abs() >= core::f64::consts::TAU {
                let led = &mut self.cam_ledger;
                led.revolutions += 1;
                led.seconds += *secs;
                led.torque_seconds += *integral;
                *start += core::f64::consts::TAU * turned.signum();
                *secs = 0.0;
                *integral = 0.0;
            }
        } else {
            self.cam_rev = (self.state.cam_angle + dtheta, 0.0, 0.0);
        }

        self.state.current = i1;
        // The PWM ripple around the mean (the average model's current) for the sampling.
        self.ripple = if drive.enabled && v_motor == v_bridge {
            // pwm::ripple_peak_to_peak, with T / L computed once.
            let d = duty.abs().min(1.0);
            let pp = (bus * d * (1.0 - d) * self.ripple_per_volt).max(0.0);
            (duty.abs(), if duty < 0.0 { -pp } else { pp })
        } else {
            (0.0, 0.0)
        };
        // The triangle's shape at the sampling phase changes with the duty only (once per
        // control step), its height with the bus at every step.
        let (d, pp) = self.ripple;
        if self.ripple_shape.0 != d {
            let phase = self.params.sensors.sampling.phase();
            self.ripple_shape = (d, pwm::ripple_at(phase, d, 1.0));
        }
        self.ripple_sample = pp * self.ripple_shape.1;
        // The comparator watches the pin continuously, the ripple's peaks included: past
        // its threshold the break cuts the bridge within microseconds, modelled as from the
        // end of this step.
        if i1 + 0.5 * self.ripple.1.abs() > self.break_current {
            self.break_tripped = true;
        }
        self.state.cam_speed = new_omega;
        self.state.cam_angle += dtheta;
        self.state.output_speed = new_wt;
        self.state.output_angle += wt_mean * dt;
        if let Some(travel) = p.output_travel {
            let from_hang = self.state.output_angle - self.hung_at;
            if from_hang.abs() >= travel {
                // Landed: the floor (or end stop) takes the load's kinetic energy.
                self.energy.end_stop += 0.5 * self.shaft.i_hat * new_wt * new_wt;
                self.state.output_angle = self.hung_at + travel.copysign(from_hang);
                self.state.output_speed = 0.0;
                self.resting = true;
            } else if self.resting && from_hang.abs() < travel {
                self.resting = false;
            }
        }
        self.state.motor_voltage = v_motor;
        self.state.bus_voltage = if self.params.bus_capacitance > 0.0 {
            // The bridge draws d i from the bus in the on-time (negative: returns it).
            let i_bridge = if drive.enabled && v_motor == v_bridge {
                duty * i_mean
            } else {
                0.0
            };
            let p = &self.params;
            bus::step(
                bus,
                p.supply,
                p.supply_resistance,
                p.bus_capacitance,
                i_bridge,
                dt,
            )
        } else {
            bus
        };
        self.state.time += dt;
    }
}

/// The winding current at which the comparator's input reaches its threshold, A: the
/// sensor's pin voltage is affine in the current ([`SensorParams::pin_voltage`]).
/// Infinite without a comparator.
fn break_current(params: &PlantParams) -> f64 {
    let Some(threshold) = params.break_threshold_v else {
        return f64::INFINITY;
    };
    let s = &params.sensors;
    let at_zero = s.pin_voltage(0.0);
    let per_amp = s.pin_voltage(1.0) - at_zero;
    if per_amp > 0.0 {
        (threshold - at_zero) / per_amp
    } else {
        f64::INFINITY
    }
}

#[cfg(test)]
mod tests;
