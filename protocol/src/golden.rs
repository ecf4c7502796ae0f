//! Golden wire bytes: one hard-coded frame per message variant, and worst-case sizes.
//!
//! If a test here fails, the wire layout changed. If that was intended: regenerate with
//! `cargo test -p protocol golden::print -- --ignored --nocapture`, paste the bytes,
//! update `schema::SCHEMA` and bump `PROTOCOL_VERSION`.

use heapless::{String, Vec};

use crate::*;

pub(crate) fn sample_telemetry() -> TelemetrySample {
    TelemetrySample {
        seq: 1234,
        device_time_us: 5_000_000,
        cam_speed_rad_s: 62.8,
        current_a: 2.5,
        pwm_duty: -0.25,
        tau_cam_nm: 0.0201,
        tau_rot_nm: 1.5,
        state: SupervisorState::Vibrating,
        faults: FaultFlags::empty(),
        status: StatusFlags::HOST_RELEASE | StatusFlags::CAPTURE_RUNNING,
    }
}

pub(crate) fn worst_case_chunk() -> CaptureChunk {
    let sample = CaptureSample {
        current_adc: u16::MAX,
        encoder_count: i32::MIN,
    };
    CaptureChunk {
        capture_id: u16::MAX,
        first_sample: u32::MAX,
        total_samples: u32::MAX,
        samples: Vec::from_slice(&[sample; CAPTURE_CHUNK_SAMPLES]).unwrap(),
    }
}

/// One example of each request, indexed by [`request_index`].
fn requests() -> std::vec::Vec<Request> {
    use Request::*;
    vec![
        Hello {
            protocol_version: 1,
            schema_hash: 0xDEAD_BEEF,
        },
        GetInfo,
        Release {
            on: true,
            target_hz: 10.0,
        },
        Heartbeat,
        GetCalibration,
        SetCalibration(Calibration::paper()),
        StartTelemetry { rate_hz: 200 },
        StopTelemetry,
        StartCapture {
            sample_rate_hz: 10_000,
            samples: 5_000,
        },
        GetFaults,
        ClearFaults,
        RezeroCurrent,
        OpenLoop { volts: 3.6 },
    ]
}

/// Exhaustive on purpose (no `_` arm): a new variant fails to compile here until it
/// gets an example and golden bytes.
fn request_index(r: &Request) -> usize {
    use Request::*;
    match r {
        Hello { .. } => 0,
        GetInfo => 1,
        Release { .. } => 2,
        Heartbeat => 3,
        GetCalibration => 4,
        SetCalibration(_) => 5,
        StartTelemetry { .. } => 6,
        StopTelemetry => 7,
        StartCapture { .. } => 8,
        GetFaults => 9,
        ClearFaults => 10,
        RezeroCurrent => 11,
        OpenLoop { .. } => 12,
    }
}

/// One example of each device message, indexed by [`device_index`].
fn device_messages() -> std::vec::Vec<DeviceMessage> {
    use DeviceMessage::*;
    let sample = |current_adc, encoder_count| CaptureSample {
        current_adc,
        encoder_count,
    };
    vec![
        Info(DeviceInfo {
            firmware_version: FirmwareVersion {
                major: 0,
                minor: 1,
                patch: 2,
            },
            protocol_version: 1,
            schema_hash: 0xDEAD_BEEF,
            board: String::try_from("nucleo-g474re").unwrap(),
            calibration_status: CalibrationStatus::Defaults,
        }),
        Ack { seq: 300 },
        Nack {
            seq: 301,
            code: NackCode::InFaultHold,
        },
        Telemetry(sample_telemetry()),
        CaptureChunk(crate::CaptureChunk {
            capture_id: 3,
            first_sample: 64,
            total_samples: 100,
            samples: Vec::from_slice(&[sample(2048, 0), sample(2100, -1)]).unwrap(),
        }),
        CaptureDone {
            capture_id: 3,
            total_samples: 100,
            sample_rate_hz: 10_000,
        },
        FaultEvent {
            flags: FaultFlags::OVERCURRENT | FaultFlags::STALL,
            device_time_us: 1_000,
        },
        Faults {
            active: FaultFlags::empty(),
            latched: FaultFlags::COMMS_TIMEOUT,
        },
        Calibration(crate::Calibration::paper()),
    ]
}

/// Exhaustive on purpose, as [`request_index`].
fn device_index(m: &DeviceMessage) -> usize {
    use DeviceMessage::*;
    match m {
        Info(_) => 0,
        Ack { .. } => 1,
        Nack { .. } => 2,
        Telemetry(_) => 3,
        CaptureChunk(_) => 4,
        CaptureDone { .. } => 5,
        FaultEvent { .. } => 6,
        Faults { .. } => 7,
        Calibration(_) => 8,
    }
}

const REQUEST_FRAMES: [&[u8]; 13] = [
    // Hello
    &[
        0x03, 0xb4, 0x24, 0x0b, 0x01, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, 0xa5, 0x4f, 0xc0, 0x4d, 0x00,
    ],
    // GetInfo
    &[0x08, 0xb4, 0x24, 0x01, 0xee, 0x5e, 0xf9, 0xbb, 0x00],
    // Release
    &[
        0x05, 0xb4, 0x24, 0x02, 0x01, 0x01, 0x07, 0x20, 0x41, 0xa4, 0xc7, 0x9b, 0xe8, 0x00,
    ],
    // Heartbeat
    &[0x08, 0xb4, 0x24, 0x03, 0xc2, 0x3f, 0xf7, 0x55, 0x00],
    // GetCalibration
    &[0x08, 0xb4, 0x24, 0x04, 0x61, 0xaa, 0x93, 0xcb, 0x00],
    // SetCalibration
    &[
        0x08, 0xb4, 0x24, 0x05, 0x66, 0x66, 0x78, 0x42, 0x01, 0x0f, 0x0a, 0xc3, 0xd7, 0xa3, 0x70,
        0x3e, 0xec, 0x51, 0xd8, 0x3f, 0xe0, 0xb9, 0x77, 0x3b, 0x01, 0x07, 0x10, 0x40, 0x31, 0x33,
        0x32, 0x32, 0x01, 0x03, 0x80, 0x3f, 0x01, 0x03, 0xa0, 0x41, 0x01, 0x13, 0x80, 0x3f, 0xe1,
        0x7a, 0x74, 0x40, 0x83, 0xc0, 0x8a, 0x3e, 0x0e, 0x2d, 0x32, 0x3e, 0x1f, 0x85, 0x6b, 0x40,
        0x01, 0x03, 0x90, 0x40, 0x01, 0x07, 0x70, 0x41, 0xa6, 0x7d, 0x32, 0xdc, 0x00,
    ],
    // StartTelemetry
    &[
        0x0a, 0xb4, 0x24, 0x06, 0xc8, 0x01, 0xc2, 0x70, 0x9c, 0x7c, 0x00,
    ],
    // StopTelemetry
    &[0x08, 0xb4, 0x24, 0x07, 0xdb, 0xfb, 0x9a, 0x52, 0x00],
    // StartCapture
    &[
        0x0c, 0xb4, 0x24, 0x08, 0x90, 0x4e, 0x88, 0x27, 0x6a, 0x5e, 0x0f, 0x74, 0x00,
    ],
    // GetFaults
    &[0x08, 0xb4, 0x24, 0x09, 0xdc, 0xd6, 0x22, 0xb5, 0x00],
    // ClearFaults
    &[0x08, 0xb4, 0x24, 0x0a, 0x66, 0x87, 0x2b, 0x2c, 0x00],
    // RezeroCurrent
    &[0x08, 0xb4, 0x24, 0x0b, 0xf0, 0xb7, 0x2c, 0x5b, 0x00],
    // OpenLoop
    &[
        0x0c, 0xb4, 0x24, 0x0c, 0x66, 0x66, 0x66, 0x40, 0x10, 0x8c, 0xf7, 0x07, 0x00,
    ],
];
const DEVICE_FRAMES: [&[u8]; 9] = [
    // Info
    &[
        0x02, 0x07, 0x01, 0x1c, 0x01, 0x02, 0x01, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, 0x0d, 0x6e, 0x75,
        0x63, 0x6c, 0x65, 0x6f, 0x2d, 0x67, 0x34, 0x37, 0x34, 0x72, 0x65, 0x01, 0xfc, 0x5d, 0xda,
        0x0a, 0x00,
    ],
    // Ack
    &[0x09, 0x07, 0x01, 0xac, 0x02, 0x5b, 0x1f, 0xed, 0x51, 0x00],
    // Nack
    &[
        0x0a, 0x07, 0x02, 0xad, 0x02, 0x02, 0x1b, 0x2e, 0x93, 0xd3, 0x00,
    ],
    // Telemetry
    &[
        0x0d, 0x07, 0x03, 0xd2, 0x09, 0xc0, 0x96, 0xb1, 0x02, 0x33, 0x33, 0x7b, 0x42, 0x01, 0x03,
        0x20, 0x40, 0x01, 0x07, 0x80, 0xbe, 0xc1, 0xa8, 0xa4, 0x3c, 0x01, 0x04, 0xc0, 0x3f, 0x02,
        0x06, 0x14, 0x9a, 0x6d, 0xf2, 0x20, 0x00,
    ],
    // CaptureChunk
    &[
        0x09, 0x07, 0x04, 0x03, 0x40, 0x64, 0x02, 0x80, 0x10, 0x08, 0xb4, 0x10, 0x01, 0x5f, 0xac,
        0xcd, 0xc8, 0x00,
    ],
    // CaptureDone
    &[
        0x0b, 0x07, 0x05, 0x03, 0x64, 0x90, 0x4e, 0xf4, 0x34, 0x69, 0xd9, 0x00,
    ],
    // FaultEvent
    &[
        0x0a, 0x07, 0x06, 0x03, 0xe8, 0x07, 0xcf, 0x26, 0xec, 0x5b, 0x00,
    ],
    // Faults
    &[
        0x03, 0x07, 0x07, 0x07, 0x80, 0x01, 0x69, 0xbb, 0x51, 0xa5, 0x00,
    ],
    // Calibration
    &[
        0x07, 0x07, 0x08, 0x66, 0x66, 0x78, 0x42, 0x01, 0x0f, 0x0a, 0xc3, 0xd7, 0xa3, 0x70, 0x3e,
        0xec, 0x51, 0xd8, 0x3f, 0xe0, 0xb9, 0x77, 0x3b, 0x01, 0x07, 0x10, 0x40, 0x31, 0x33, 0x32,
        0x32, 0x01, 0x03, 0x80, 0x3f, 0x01, 0x03, 0xa0, 0x41, 0x01, 0x13, 0x80, 0x3f, 0xe1, 0x7a,
        0x74, 0x40, 0x83, 0xc0, 0x8a, 0x3e, 0x0e, 0x2d, 0x32, 0x3e, 0x1f, 0x85, 0x6b, 0x40, 0x01,
        0x03, 0x90, 0x40, 0x01, 0x07, 0x70, 0x41, 0x23, 0xa3, 0x19, 0x20, 0x00,
    ],
];

#[test]
fn every_variant_has_an_example() {
    let idx: std::vec::Vec<_> = requests().iter().map(request_index).collect();
    assert_eq!(idx, (0..REQUEST_FRAMES.len()).collect::<std::vec::Vec<_>>());
    let idx: std::vec::Vec<_> = device_messages().iter().map(device_index).collect();
    assert_eq!(idx, (0..DEVICE_FRAMES.len()).collect::<std::vec::Vec<_>>());
}

#[test]
fn request_frames_match_golden_bytes() {
    for (msg, golden) in requests().into_iter().zip(REQUEST_FRAMES) {
        assert_eq!(
            encode_frame_vec(REQUEST_SEQ, &msg).unwrap(),
            golden,
            "{msg:?}"
        );
        let decoded: Frame<Request> = decode_frame(&mut golden.to_vec()).unwrap();
        assert_eq!(
            decoded,
            Frame {
                seq: REQUEST_SEQ,
                msg
            }
        );
    }
}

#[test]
fn device_frames_match_golden_bytes() {
    for (msg, golden) in device_messages().into_iter().zip(DEVICE_FRAMES) {
        assert_eq!(
            encode_frame_vec(DEVICE_SEQ, &msg).unwrap(),
            golden,
            "{msg:?}"
        );
        let decoded: Frame<DeviceMessage> = decode_frame(&mut golden.to_vec()).unwrap();
        assert_eq!(
            decoded,
            Frame {
                seq: DEVICE_SEQ,
                msg
            }
        );
    }
}

#[test]
fn schema_identity_is_pinned() {
    assert_eq!(PROTOCOL_VERSION, 1);
    // Changing schema::SCHEMA changes this value: bump PROTOCOL_VERSION with it.
    assert_eq!(SCHEMA_HASH, 0xBCD3_DE6D);
}

fn wire_len<T: serde::Serialize>(value: &T) -> usize {
    let mut buf = [0u8; 1024];
    postcard::to_slice(value, &mut buf).unwrap().len()
}

#[test]
fn worst_case_sizes_are_exact() {
    let cal = Calibration {
        z: [u16::MAX; 4],
        ..Calibration::paper()
    };
    assert_eq!(wire_len(&cal), Calibration::MAX_WIRE_SIZE);
    let telemetry = TelemetrySample {
        seq: u32::MAX,
        device_time_us: u64::MAX,
        faults: FaultFlags::from_bits_retain(u16::MAX),
        status: StatusFlags::from_bits_retain(u8::MAX),
        ..sample_telemetry()
    };
    assert_eq!(wire_len(&telemetry), TelemetrySample::MAX_WIRE_SIZE);
    let info = DeviceInfo {
        firmware_version: FirmwareVersion {
            major: 255,
            minor: 255,
            patch: 255,
        },
        protocol_version: u16::MAX,
        schema_hash: u32::MAX,
        board: String::try_from("0123456789abcdef").unwrap(),
        calibration_status: CalibrationStatus::Invalid,
    };
    assert_eq!(wire_len(&info), DeviceInfo::MAX_WIRE_SIZE);
    let chunk = worst_case_chunk();
    assert_eq!(wire_len(&chunk.samples[0]), CaptureSample::MAX_WIRE_SIZE);
    assert_eq!(wire_len(&chunk), CaptureChunk::MAX_WIRE_SIZE);
    let set = Request::SetCalibration(cal);
    assert_eq!(wire_len(&set), Request::MAX_WIRE_SIZE);
    assert_eq!(
        wire_len(&DeviceMessage::CaptureChunk(chunk)),
        DeviceMessage::MAX_WIRE_SIZE
    );
    assert_eq!(wire_len(&(u16::MAX, set)), REQUEST_MESSAGE_SIZE);
}

/// Sequence number plus the largest request.
const REQUEST_MESSAGE_SIZE: usize = 3 + Request::MAX_WIRE_SIZE;

#[test]
fn other_variants_fit_the_budget() {
    let requests = [
        Request::Hello {
            protocol_version: u16::MAX,
            schema_hash: u32::MAX,
        },
        Request::Release {
            on: true,
            target_hz: f32::MAX,
        },
        Request::StartTelemetry { rate_hz: u16::MAX },
        Request::StartCapture {
            sample_rate_hz: u16::MAX,
            samples: u32::MAX,
        },
    ];
    for r in requests {
        assert!(wire_len(&r) <= Request::MAX_WIRE_SIZE, "{r:?}");
    }
    let faults = FaultFlags::from_bits_retain(u16::MAX);
    let messages = [
        DeviceMessage::Ack { seq: u16::MAX },
        DeviceMessage::Nack {
            seq: u16::MAX,
            code: NackCode::StorageFailed,
        },
        DeviceMessage::CaptureDone {
            capture_id: u16::MAX,
            total_samples: u32::MAX,
            sample_rate_hz: u16::MAX,
        },
        DeviceMessage::FaultEvent {
            flags: faults,
            device_time_us: u64::MAX,
        },
        DeviceMessage::Faults {
            active: faults,
            latched: faults,
        },
    ];
    for m in messages {
        assert!(wire_len(&m) <= DeviceMessage::MAX_WIRE_SIZE, "{m:?}");
    }
}

const REQUEST_SEQ: u16 = 0x1234;
const DEVICE_SEQ: u16 = 7;

fn hex(bytes: &[u8]) -> std::string::String {
    let items: std::vec::Vec<_> = bytes.iter().map(|b| format!("0x{b:02x}")).collect();
    format!("&[{}]", items.join(", "))
}

#[test]
#[ignore = "prints the golden bytes; run by hand after an intended layout change"]
fn print() {
    println!("const REQUEST_FRAMES: [&[u8]; {}] = [", requests().len());
    for r in requests() {
        println!(
            "    // {r:?}\n    {},",
            hex(&encode_frame_vec(REQUEST_SEQ, &r).unwrap())
        );
    }
    println!(
        "];\nconst DEVICE_FRAMES: [&[u8]; {}] = [",
        device_messages().len()
    );
    for m in device_messages() {
        println!(
            "    // {m:?}\n    {},",
            hex(&encode_frame_vec(DEVICE_SEQ, &m).unwrap())
        );
    }
    println!("];");
}
