//! Proptest strategies for every wire type, shared by the integration tests.
#![allow(dead_code)]

use heapless::{String, Vec};
use proptest::collection::vec;
use proptest::prelude::*;
use protocol::*;

pub fn parameters() -> impl Strategy<Value = RigParameters> {
    (
        proptest::array::uniform6(any::<f32>()),
        proptest::array::uniform4(any::<u16>()),
        proptest::array::uniform9(any::<f32>()),
        proptest::array::uniform4(any::<f32>()),
    )
        .prop_map(|(c, z, g, profile_shift)| RigParameters {
            c1_nmm_per_a: c[0],
            c2_nmm: c[1],
            c3_nmm_s_per_rad: c[2],
            c4_nmm: c[3],
            c5_a_s_per_rad: c[4],
            c6_a: c[5],
            z,
            module_mm: g[0],
            pressure_angle_deg: g[1],
            eccentricity_mm: g[2],
            carrier_mass_kg: g[3],
            mu_s: g[4],
            mu_d: g[5],
            max_release_load_nm: g[6],
            max_current_a: g[7],
            max_freq_hz: g[8],
            profile_shift,
        })
}

pub fn faults() -> impl Strategy<Value = FaultFlags> {
    any::<u32>().prop_map(FaultFlags::from_bits_retain)
}

fn supervisor_state() -> impl Strategy<Value = SupervisorState> {
    prop_oneof![
        Just(SupervisorState::Locked),
        Just(SupervisorState::SpinUp),
        Just(SupervisorState::Vibrating),
        Just(SupervisorState::Stopping),
        Just(SupervisorState::Fault),
    ]
}

fn telemetry() -> impl Strategy<Value = TelemetrySample> {
    (
        any::<u32>(),
        any::<u64>(),
        proptest::array::uniform7(any::<f32>()),
        supervisor_state(),
        faults(),
        any::<u16>(),
    )
        .prop_map(
            |(seq, device_time_us, f, state, faults, status)| TelemetrySample {
                seq,
                device_time_us,
                cam_speed_rad_s: f[0],
                current_a: f[1],
                pwm_duty: f[2],
                tau_cam_nm: f[3],
                tau_rot_nm: f[4],
                state,
                faults,
                status: StatusFlags::from_bits_retain(status),
                output_angle_rad: f[5],
                output_speed_rad_s: f[6],
            },
        )
}

fn health() -> impl Strategy<Value = HealthSample> {
    (any::<u64>(), any::<[f32; 2]>(), any::<[u32; 4]>()).prop_map(|(device_time_us, f, n)| {
        HealthSample {
            device_time_us,
            bus_voltage_v: f[0],
            motor_temp_c: f[1],
            step_cycles_mean: n[0],
            step_cycles_max: n[1],
            rx_frame_errors: n[2],
            tx_frames_dropped: n[3],
        }
    })
}

fn capture_chunk() -> impl Strategy<Value = CaptureChunk> {
    let sample = (any::<u16>(), any::<i32>(), any::<Option<i32>>()).prop_map(
        |(current_adc, encoder_count, output_count)| CaptureSample {
            current_adc,
            encoder_count,
            output_count,
        },
    );
    (
        any::<u16>(),
        any::<u32>(),
        any::<u32>(),
        vec(sample, 0..=CAPTURE_CHUNK_SAMPLES),
    )
        .prop_map(
            |(capture_id, first_sample, total_samples, samples)| CaptureChunk {
                capture_id,
                first_sample,
                total_samples,
                samples: Vec::from_slice(&samples).unwrap(),
            },
        )
}

fn parameter_rejection() -> impl Strategy<Value = ParameterRejection> {
    let reason = prop_oneof![
        Just(RejectReason::NotFinite),
        Just(RejectReason::OutOfRange),
        Just(RejectReason::AboveBoardCap),
        Just(RejectReason::Inconsistent),
        Just(RejectReason::Implausible),
    ];
    (
        proptest::sample::select(ParameterField::ALL.to_vec()),
        reason,
    )
        .prop_map(|(field, reason)| ParameterRejection::new(field, reason))
}

fn nack_code() -> impl Strategy<Value = NackCode> {
    prop_oneof![
        (any::<u16>(), any::<u32>()).prop_map(|(device_protocol, device_schema_hash)| {
            NackCode::VersionMismatch {
                device_protocol,
                device_schema_hash,
            }
        }),
        Just(NackCode::UnknownMessage),
        Just(NackCode::BadArgument),
        Just(NackCode::InFaultHold),
        parameter_rejection().prop_map(NackCode::ParametersRejected),
        Just(NackCode::Busy),
        Just(NackCode::StorageFailed),
        Just(NackCode::SimulationOnly),
        Just(NackCode::CurrentZeroPending),
        any::<u16>().prop_map(|fits_hz| NackCode::StreamRate { fits_hz }),
    ]
}

fn device_info() -> impl Strategy<Value = DeviceInfo> {
    let status = prop_oneof![
        Just(ParametersStatus::Valid),
        Just(ParametersStatus::Defaults),
        Just(ParametersStatus::Invalid),
    ];
    let reset = prop_oneof![
        Just(ResetCause::PowerOn),
        Just(ResetCause::Pin),
        Just(ResetCause::Software),
        Just(ResetCause::Watchdog),
        Just(ResetCause::BrownOut),
        Just(ResetCause::Lockup),
        Just(ResetCause::Other),
    ];
    (
        (any::<[u8; 3]>(), any::<u16>(), any::<u32>()),
        ("[0-9a-f]{0,12}(-dirty)?", "[a-z0-9µ-]{0,8}"),
        (status, reset, any::<u32>(), any::<u16>()),
        (0.001f32..1.0e6, any::<u32>()),
    )
        .prop_map(
            |(
                (v, protocol_version, schema_hash),
                (build, board),
                (parameters_status, reset_cause, uptime_s, capabilities),
                (time_scale, max_baud),
            )| DeviceInfo {
                protocol_version,
                schema_hash,
                firmware_version: FirmwareVersion {
                    major: v[0],
                    minor: v[1],
                    patch: v[2],
                },
                firmware_build: String::try_from(build.as_str()).unwrap(),
                board: String::try_from(board.as_str()).unwrap(),
                parameters_status,
                reset_cause,
                uptime_s,
                capabilities: Capabilities::from_bits_retain(capabilities),
                time_scale,
                max_baud,
            },
        )
}

fn sim_command() -> impl Strategy<Value = SimCommand> {
    prop_oneof![
        any::<f32>().prop_map(|tau_rot_nm| SimCommand::SetLoad { tau_rot_nm }),
        any::<f32>().prop_map(|volts| SimCommand::SetSupplyVoltage { volts }),
        any::<f32>().prop_map(|volts| SimCommand::SetSensorSupply { volts }),
    ]
}

pub fn request() -> impl Strategy<Value = Request> {
    prop_oneof![
        (any::<u16>(), any::<u32>()).prop_map(|(protocol_version, schema_hash)| Request::Hello {
            protocol_version,
            schema_hash
        }),
        Just(Request::GetInfo),
        (any::<bool>(), any::<f32>(), any::<u32>()).prop_map(|(on, target_hz, session)| {
            Request::Release {
                on,
                target_hz,
                session,
            }
        }),
        any::<u32>().prop_map(|session| Request::Heartbeat { session }),
        Just(Request::GetParameters),
        parameters().prop_map(Request::SetParameters),
        any::<u16>().prop_map(|rate_hz| Request::StartTelemetry { rate_hz }),
        Just(Request::StopTelemetry),
        (any::<u16>(), any::<u32>()).prop_map(|(sample_rate_hz, samples)| {
            Request::StartCapture {
                sample_rate_hz,
                samples,
            }
        }),
        Just(Request::GetFaults),
        Just(Request::ClearFaults),
        Just(Request::RezeroCurrent),
        (any::<f32>(), any::<u32>())
            .prop_map(|(volts, session)| Request::OpenLoop { volts, session }),
        sim_command().prop_map(Request::Simulation),
        any::<u16>().prop_map(|rate_hz| Request::StartStream { rate_hz }),
        Just(Request::StopStream),
        any::<u32>().prop_map(|baud| Request::SetBaud { baud }),
    ]
}

pub fn reply() -> impl Strategy<Value = Reply> {
    prop_oneof![
        device_info().prop_map(Reply::Info),
        nack_code().prop_map(Reply::Nack),
        Just(Reply::Ack),
        (faults(), faults()).prop_map(|(active, latched)| Reply::Faults { active, latched }),
        parameters().prop_map(Reply::Parameters),
    ]
}

pub fn device_message() -> impl Strategy<Value = DeviceMessage> {
    prop_oneof![
        (any::<u16>(), reply()).prop_map(|(seq, reply)| DeviceMessage::reply(seq, reply)),
        telemetry().prop_map(DeviceMessage::Telemetry),
        capture_chunk().prop_map(DeviceMessage::CaptureChunk),
        (any::<u16>(), any::<u32>(), any::<u16>()).prop_map(
            |(capture_id, total_samples, sample_rate_hz)| DeviceMessage::CaptureDone {
                capture_id,
                total_samples,
                sample_rate_hz
            }
        ),
        (faults(), any::<u64>()).prop_map(|(flags, device_time_us)| DeviceMessage::FaultEvent {
            flags,
            device_time_us
        }),
        health().prop_map(DeviceMessage::Health),
        (any::<u32>(), stream_samples()).prop_map(|(first_seq, samples)| {
            DeviceMessage::StreamBlock(StreamBlock::pack(first_seq, &samples))
        }),
    ]
}

/// Any stream sample (every field over its whole range).
pub fn stream_sample() -> impl Strategy<Value = StreamSample> {
    (
        any::<u16>(),
        any::<u16>(),
        any::<u16>(),
        any::<i16>(),
        any::<i16>(),
        any::<u16>(),
        any::<u8>(),
    )
        .prop_map(
            |(current_adc, cam_count, output_count, duty, tau_cam, status, state)| StreamSample {
                current_adc,
                cam_count,
                output_count,
                duty,
                tau_cam,
                status,
                state,
            },
        )
}

/// Up to a block of samples: arbitrary ones, or runs where only some fields move (as the
/// device sends them), so both the delta and the held-field paths are exercised.
pub fn stream_samples() -> impl Strategy<Value = std::vec::Vec<StreamSample>> {
    prop_oneof![
        proptest::collection::vec(stream_sample(), 0..=STREAM_BLOCK_SAMPLES),
        (
            stream_sample(),
            proptest::collection::vec(
                (any::<i8>(), any::<i8>(), any::<bool>()),
                0..STREAM_BLOCK_SAMPLES
            ),
        )
            .prop_map(|(first, steps)| {
                let mut out = vec![first];
                let mut s = first;
                for (dc, dk, held) in steps {
                    s.current_adc = s.current_adc.wrapping_add_signed(i16::from(dc));
                    s.cam_count = s.cam_count.wrapping_add_signed(i16::from(dk));
                    if held {
                        s.duty = s.duty.wrapping_add(1);
                        s.state ^= 0x80;
                    }
                    out.push(s);
                }
                out
            }),
    ]
}

/// Encodes into a fresh `MAX_FRAME_SIZE` buffer, as the firmware does.
pub fn frame<M: serde::Serialize>(seq: u16, msg: &M) -> std::vec::Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_SIZE];
    encode_frame(seq, msg, &mut buf).unwrap().to_vec()
}

/// Splits `bytes` at the given cut points (taken modulo the length), in order.
pub fn split<'a>(bytes: &'a [u8], cuts: &[usize]) -> std::vec::Vec<&'a [u8]> {
    let mut points: std::vec::Vec<usize> = cuts.iter().map(|c| c % (bytes.len() + 1)).collect();
    points.sort_unstable();
    let mut parts = std::vec::Vec::new();
    let mut start = 0;
    for p in points {
        parts.push(&bytes[start..p]);
        start = p;
    }
    parts.push(&bytes[start..]);
    parts
}
