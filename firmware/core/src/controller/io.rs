//! What goes into and comes out of the core: the boot facts, one step's sensor readings and
//! bridge command, and the status snapshot.

use protocol::{
    FaultFlags, ParametersStatus, ResetCause, RigParameters, StatusFlags, SupervisorState,
};

/// What the binary knows at boot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BootInfo {
    /// Why the microcontroller last reset (a watchdog reset latches `WATCHDOG_RESET`).
    pub reset_cause: ResetCause,
    /// The firmware's build identifier (short git commit, `-dirty` when the tree had
    /// changes), reported in `Info`; at most [`protocol::FIRMWARE_BUILD_LEN`] bytes are sent.
    pub firmware_build: &'static str,
    /// Rig parameters loaded from flash (the paper's when none or invalid).
    pub parameters: RigParameters,
    /// Where `parameters` came from.
    pub parameters_status: ParametersStatus,
}

impl BootInfo {
    /// The build identifier of a build outside git (or before the binary provides one).
    pub const UNKNOWN_BUILD: &'static str = "unknown";

    /// Whether the last reset was the watchdog's.
    pub fn watchdog_reset(&self) -> bool {
        self.reset_cause == ResetCause::Watchdog
    }
}

impl Default for BootInfo {
    /// A clean power-on with nothing stored: the paper's parameters.
    fn default() -> Self {
        Self {
            reset_cause: ResetCause::PowerOn,
            firmware_build: Self::UNKNOWN_BUILD,
            parameters: RigParameters::paper(),
            parameters_status: ParametersStatus::Defaults,
        }
    }
}

/// One control step's sensor readings.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Now, microseconds since boot.
    pub now_us: u64,
    /// Current ADC samples since the last step, oldest first (normally `samples_per_step`).
    pub current_adc: &'a [u16],
    /// Raw, wrapping 16-bit encoder timer count.
    pub encoder_count: u16,
    /// The physical release input is held.
    pub release_button: bool,
}

/// The board's other measurements, handed over before each step with
/// [`crate::Core::set_board_inputs`] (kept apart from [`Inputs`] so a binary that does not
/// read them yet keeps building). [`Default`] is "nothing measured": no break, NaN for the
/// analog readings, no ECC error.
///
/// What the binary feeds (STM32G474, see the README's pin table):
/// - `hw_break`: TIM1's break flag (SR.BIF) after COMP3 on PA0 tripped; the core latches
///   `HW_OVERCURRENT`. The binary re-arms the break (BDTR.MOE) only while
///   [`crate::Core::break_latched`] is false, i.e. after `ClearFaults`.
/// - `vdda_v`: VDDA from VREFINT (VREFINT_CAL x 3.0 V / reading), V, NaN if not measured.
/// - `bus_voltage_v`: the bridge supply through its divider, V, NaN if not fitted; used by
///   the speed loop's feed-forward and the open-loop volts, reported in Health.
/// - `motor_temp_c`: the motor NTC, deg C, NaN if not fitted; reported in Health.
/// - `flash_ecc_error`: a double-ECC error (NMI, FLASH_ECCR.ECCD) was raised during the last
///   read of the storage region: for [`crate::storage`], the slot being read is corrupt.
///
/// The step's CPU cycles (DWT CYCCNT) go through [`crate::Core::record_step_cycles`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardInputs {
    /// The hardware overcurrent trip (comparator into the timer's break) has fired.
    pub hw_break: bool,
    /// Measured analog supply and ADC reference VDDA, V (NaN: not measured, 3.3 V used).
    pub vdda_v: f32,
    /// Measured bridge supply, V (NaN: not measured, the configured supply is used).
    pub bus_voltage_v: f32,
    /// Motor temperature, deg C (NaN: no thermistor).
    pub motor_temp_c: f32,
    /// A flash ECC error was raised during the last storage read.
    pub flash_ecc_error: bool,
}

impl Default for BoardInputs {
    fn default() -> Self {
        Self {
            hw_break: false,
            vdda_v: f32::NAN,
            bus_voltage_v: f32::NAN,
            motor_temp_c: f32::NAN,
            flash_ecc_error: false,
        }
    }
}

/// One control step's commands to the hardware.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outputs {
    /// PWM duty, -1..=1; the sign is the direction pin.
    pub duty: f32,
    /// Bridge enable; false is the safe state (vibration off).
    pub enable: bool,
    /// Rig parameters to write to flash; report the outcome with
    /// [`crate::Core::persist_result`].
    pub persist: Option<RigParameters>,
    /// A capture is recording (informational: the core records from `current_adc`).
    pub capture: bool,
}

impl Outputs {
    /// Bridge off, nothing to do.
    pub const SAFE: Self = Self {
        duty: 0.0,
        enable: false,
        persist: None,
        capture: false,
    };
}

/// A snapshot of the core for logs, simulation and tests.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Status {
    /// Supervisor state.
    pub state: SupervisorState,
    /// Latched faults (the motor stays off while any is latched).
    pub latched_faults: FaultFlags,
    /// Faults whose condition is present now.
    pub active_faults: FaultFlags,
    /// Telemetry status bits.
    pub flags: StatusFlags,
    /// Cam speed in the drive direction, rad/s.
    pub cam_speed_rad_s: f32,
    /// Cam angle, rad.
    pub cam_angle_rad: f32,
    /// Filtered motor current, A.
    pub current_a: f32,
    /// Commanded duty, -1..=1.
    pub duty: f32,
    /// Bridge enabled.
    pub enabled: bool,
    /// Vibration frequency being driven (possibly raised), Hz.
    pub target_hz: f32,
    /// Ramped speed reference of the loop, rad/s.
    pub speed_reference_rad_s: f32,
    /// Last revolution's mean cam torque, N m (0 before the first).
    pub tau_cam_nm: f32,
    /// Last revolution's load estimate, N m (0 before the first).
    pub tau_rot_nm: f32,
    /// Whether `tau_cam_nm` and `tau_rot_nm` come from a revolution.
    pub estimate_valid: bool,
    /// Revolutions estimated since vibration started.
    pub revolutions: u32,
    /// mu_d * Lambda < 1: the output keeps moving after vibration stops.
    pub keeps_moving_after_stop: bool,
    /// mu_s * Lambda > 1: the gear holds its load without vibration.
    pub holds_at_rest: bool,
    /// A host release (kept alive by accepted requests) is live.
    pub host_release: bool,
    /// The bridge voltage of a live open-loop drive, V.
    pub open_loop_volts: Option<f32>,
    /// The release button is held (and armed).
    pub button_release: bool,
    /// Current-sensor zero, ADC counts.
    pub current_zero_adc: f32,
    /// A zero measurement is running.
    pub zeroing: bool,
    /// The active rig parameters.
    pub parameters: RigParameters,
    /// Where they came from.
    pub parameters_status: ParametersStatus,
    /// Receiver counters (garbled frames included).
    pub deframer: protocol::DeframerStats,
    /// Outgoing frames dropped for lack of queue room.
    pub tx_dropped: u32,
    /// Steps that came late (`CONTROL_OVERRUN` events).
    pub control_overruns: u32,
    /// A capture is recording.
    pub capture_recording: bool,
    /// A capture is uploading.
    pub capture_uploading: bool,
    /// The continuous stream's rate, Hz (0: off).
    pub stream_rate_hz: u16,
    /// ADC samples the stream skipped since it started because the link fell behind
    /// (their stream samples reach the host as lost).
    pub stream_samples_skipped: u32,
}
