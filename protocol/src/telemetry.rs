//! The periodic telemetry sample and the supervisor state it reports.

use serde::{Deserialize, Serialize};

use crate::FaultFlags;
use crate::flags::flag_set;
use crate::sizes::{F32, TAG, U16, U32, U64};

/// State of the firmware's release supervisor. Only `SpinUp` and `Vibrating` shake the
/// carrier; every other state holds the motor off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum SupervisorState {
    /// Vibrator off: the gear holds its load (when mu_s * Lambda > 1).
    Locked,
    /// Release requested: ramping the cam to the target frequency.
    SpinUp,
    /// Cam at speed: the gear is backdrivable.
    Vibrating,
    /// Release ended: braking the cam to rest.
    Stopping,
    /// A fault is latched: motor off until the fault is cleared.
    Fault,
}

impl SupervisorState {
    /// Every state, in variant order: `ALL[i]` is the state whose index (`state as u8`, as
    /// [`crate::StreamSample::state`] carries it) is `i`.
    pub const ALL: [Self; 5] = [
        Self::Locked,
        Self::SpinUp,
        Self::Vibrating,
        Self::Stopping,
        Self::Fault,
    ];

    /// The state whose variant index is `index` (`None` for one this build does not know).
    pub fn from_index(index: u8) -> Option<Self> {
        Self::ALL.get(usize::from(index)).copied()
    }

    /// Lower-case name for logs and CSV columns.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Locked => "locked",
            Self::SpinUp => "spin_up",
            Self::Vibrating => "vibrating",
            Self::Stopping => "stopping",
            Self::Fault => "fault",
        }
    }
}

flag_set! {
    /// Status bits of a telemetry sample, a `u16` varint on the wire.
    pub struct StatusFlags(u16) {
        /// mu_d * Lambda < 1: once moving, the output keeps moving after vibration stops.
        const COASTS_AFTER_STOP = 0
            => "mu_d Lambda < 1: once moving, the load keeps moving after vibration stops";
        /// mu_s * Lambda <= 1: the gear does not hold its load even without vibration.
        const NOT_SELF_LOCKING = 1
            => "mu_s Lambda <= 1: this gear set does not hold its load even locked";
        /// A release request (host, refreshed by heartbeat) is live.
        const HOST_RELEASE = 2
            => "a host's release is live (kept by heartbeats)";
        /// The physical release input is held.
        const BUTTON_RELEASE = 3
            => "the release button is held";
        /// A capture is recording.
        const CAPTURE_RUNNING = 4
            => "a capture is recording";
        /// The paper's default calibration is in use (none stored, or stored one invalid).
        const CALIBRATION_DEFAULTS = 5
            => "the paper's calibration is in use (none stored, or it failed its check)";
        /// The output shaft turns (output encoder fitted); while the gear is locked this is
        /// backdrive.
        const OUTPUT_MOVING = 6
            => "the output shaft turns; while locked, that is backdrive";
        /// An open-loop drive (`Request::OpenLoop`) is running.
        const OPEN_LOOP = 7
            => "an open-loop drive is running";
    }
}

/// One telemetry sample, sent at the rate set by `StartTelemetry`. SI units.
///
/// It carries what changes within a control period; the slow quantities (supply,
/// temperature, timing, link counters) come once a second in [`crate::HealthSample`], so a
/// 1 kHz stream leaves room on the link for capture uploads. A quantity the board does not
/// sense (no output encoder: see [`crate::Capabilities`]) is NaN, never a made-up 0.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TelemetrySample {
    /// Sample counter since boot; a gap means samples were lost.
    pub seq: u32,
    /// Device clock at the sample, microseconds since boot.
    pub device_time_us: u64,
    /// Cam (vibrator shaft) speed w_n, rad/s.
    pub cam_speed_rad_s: f32,
    /// Motor current i_in, A.
    pub current_a: f32,
    /// PWM duty applied to the motor, -1..=1 (sign is direction).
    pub pwm_duty: f32,
    /// Estimated torque reaching the carrier, tau_cam, N m.
    pub tau_cam_nm: f32,
    /// Estimated output load torque tau_rot (from Eq. 10 inverted), N m.
    pub tau_rot_nm: f32,
    /// Supervisor state at the sample.
    pub state: SupervisorState,
    /// Active faults.
    pub faults: FaultFlags,
    /// Status bits.
    pub status: StatusFlags,
    /// Output shaft angle since boot, rad (not wrapped); NaN without an output encoder.
    pub output_angle_rad: f32,
    /// Output shaft speed, rad/s; NaN without an output encoder.
    pub output_speed_rad_s: f32,
}

impl TelemetrySample {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = U32 + U64 + 7 * F32 + TAG + U32 + U16;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_state_is_found_by_its_variant_index() {
        for (i, s) in (0u8..).zip(SupervisorState::ALL) {
            assert_eq!(s as u8, i);
            assert_eq!(SupervisorState::from_index(i), Some(s));
        }
        assert_eq!(SupervisorState::from_index(5), None);
    }
}
