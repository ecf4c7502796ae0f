//! The once-a-second health sample: quantities that change slowly or are summaries over a
//! second, kept out of the 1 kHz telemetry stream.

use serde::{Deserialize, Serialize};

use crate::sizes::{F32, U32, U64};

/// Sent unsolicited once per second while telemetry runs (`StartTelemetry`), as
/// [`crate::DeviceMessage::Health`]. SI units; a quantity the board does not sense is NaN
/// (see [`crate::Capabilities`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HealthSample {
    /// Device clock at the sample, microseconds since boot (the uptime).
    pub device_time_us: u64,
    /// Motor supply (bridge bus) voltage, V; NaN when not sensed.
    pub bus_voltage_v: f32,
    /// Motor temperature, degrees C; NaN without a thermistor.
    pub motor_temp_c: f32,
    /// Mean CPU cycles (DWT CYCCNT) of one control step over the last full second; 0 until
    /// a second has passed, or where not measured (the virtual rig).
    pub step_cycles_mean: u32,
    /// Largest CPU cycle count of one control step over the last full second (0 as above).
    pub step_cycles_max: u32,
    /// Host frames the device dropped since boot (CRC, framing, overflow, unknown layout):
    /// line noise, or a host at another baud rate.
    pub rx_frame_errors: u32,
    /// Device frames dropped since boot for lack of transmit-queue room (the host sees
    /// them as gaps in the device's frame numbers).
    pub tx_frames_dropped: u32,
}

impl HealthSample {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = U64 + 2 * F32 + 4 * U32;

    /// How often the device sends one while telemetry runs, ms.
    pub const PERIOD_MS: u32 = 1000;
}
