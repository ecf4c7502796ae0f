//! A text description of the wire schema and its hash, so host and device can detect a
//! mismatch at `Hello` even when the version number was not bumped.
//!
//! Keep [`SCHEMA`] in step with the types: the golden-byte tests fail on any layout
//! change, and the fix then includes editing this text (which changes [`SCHEMA_HASH`]).

/// The wire schema: every message type, its variants in discriminant order and its fields
/// in wire order with postcard types (`varint` integers, `f32` little-endian).
pub const SCHEMA: &str = "\
frame = cobs(postcard(seq: u16, msg) ++ crc32_iso_hdlc_le) 0x00
Request = Hello{protocol_version: u16, schema_hash: u32} | GetInfo | Release{on: bool, target_hz: f32} \
| Heartbeat | GetCalibration | SetCalibration(Calibration) | StartTelemetry{rate_hz: u16} | StopTelemetry \
| StartCapture{sample_rate_hz: u16, samples: u32} | GetFaults | ClearFaults | RezeroCurrent \
| OpenLoop{volts: f32}
DeviceMessage = Info(DeviceInfo) | Ack{seq: u16} | Nack{seq: u16, code: NackCode} | Telemetry(TelemetrySample) \
| CaptureChunk(CaptureChunk) | CaptureDone{capture_id: u16, total_samples: u32, sample_rate_hz: u16} \
| FaultEvent{flags: FaultFlags, device_time_us: u64} | Faults{active: FaultFlags, latched: FaultFlags} \
| Calibration(Calibration)
NackCode = UnknownMessage | BadArgument | InFaultHold | VersionMismatch | CalibrationRejected | Busy | StorageFailed
DeviceInfo = {firmware_version: {major: u8, minor: u8, patch: u8}, protocol_version: u16, schema_hash: u32, \
board: string<16>, calibration_status: CalibrationStatus}
CalibrationStatus = Valid | Defaults | Invalid
Calibration = {c1_nmm_per_a: f32, c2_nmm: f32, c3_nmm_s_per_rad: f32, c4_nmm: f32, c5_a_s_per_rad: f32, c6_a: f32, \
z: [u16; 4], module_mm: f32, pressure_angle_deg: f32, eccentricity_mm: f32, carrier_mass_kg: f32, mu_s: f32, mu_d: f32, \
max_release_load_nm: f32, max_current_a: f32, max_freq_hz: f32}
TelemetrySample = {seq: u32, device_time_us: u64, cam_speed_rad_s: f32, current_a: f32, pwm_duty: f32, \
tau_cam_nm: f32, tau_rot_nm: f32, state: SupervisorState, faults: FaultFlags, status: StatusFlags}
SupervisorState = Locked | SpinUp | Vibrating | Stopping | Fault
FaultFlags = u16 {OVERCURRENT STALL ENCODER_LOSS CURRENT_ZERO_RANGE CONTROL_OVERRUN CALIBRATION_INVALID \
WATCHDOG_RESET COMMS_TIMEOUT CANNOT_RELEASE JAM OVERLOAD ESTIMATE_IMPLAUSIBLE}
StatusFlags = u8 {COASTS_AFTER_STOP NOT_SELF_LOCKING HOST_RELEASE BUTTON_RELEASE CAPTURE_RUNNING CALIBRATION_DEFAULTS}
CaptureChunk = {capture_id: u16, first_sample: u32, total_samples: u32, samples: vec<CaptureSample, 32>}
CaptureSample = {current_adc: u16, encoder_count: i32}
";

/// 32-bit FNV-1a hash of `bytes`, usable in constants.
pub const fn fnv1a_32(bytes: &[u8]) -> u32 {
    let mut hash: u32 = 0x811C_9DC5;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u32;
        hash = hash.wrapping_mul(0x0100_0193);
        i += 1;
    }
    hash
}

/// FNV-1a hash of [`SCHEMA`]; exchanged in `Hello` and `Info`.
pub const SCHEMA_HASH: u32 = fnv1a_32(SCHEMA.as_bytes());

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{FaultFlags, StatusFlags};

    #[test]
    fn fnv_reference_values() {
        assert_eq!(fnv1a_32(b""), 0x811C_9DC5);
        assert_eq!(fnv1a_32(b"a"), 0xE40C_292C);
        assert_eq!(fnv1a_32(b"foobar"), 0xBF9C_F968);
    }

    #[test]
    fn flag_names_are_in_the_schema_in_bit_order() {
        let line = |prefix: &str| {
            SCHEMA
                .lines()
                .find(|l| l.starts_with(prefix))
                .unwrap()
                .to_owned()
        };
        let names =
            |named: &[(&str, ())]| named.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(" ");
        let faults: Vec<_> = FaultFlags::NAMED.iter().map(|(n, _)| (*n, ())).collect();
        let status: Vec<_> = StatusFlags::NAMED.iter().map(|(n, _)| (*n, ())).collect();
        assert!(line("FaultFlags").contains(&format!("{{{}}}", names(&faults))));
        assert!(line("StatusFlags").contains(&format!("{{{}}}", names(&status))));
    }
}
