//! One example of every variant of every wire enum, named for the snapshot.
//!
//! The `*_index` functions match exhaustively on purpose (no `_` arm): a new variant fails
//! to compile here until it gets an example, a snapshot line and a layout-table row.
//! Example values differ from field to field, so swapping two fields changes the bytes.

use heapless::{String, Vec};

use crate::*;

/// A named example.
pub(crate) type Named<T> = (&'static str, T);

pub(crate) fn telemetry() -> TelemetrySample {
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
        output_angle_rad: -0.75,
        output_speed_rad_s: f32::NAN,
    }
}

pub(crate) fn health() -> HealthSample {
    HealthSample {
        device_time_us: 6_000_000,
        bus_voltage_v: 12.25,
        motor_temp_c: f32::NAN,
        step_cycles_mean: 21_000,
        step_cycles_max: 34_567,
        rx_frame_errors: 3,
        tx_frames_dropped: 130,
    }
}

pub(crate) fn worst_case_chunk() -> CaptureChunk {
    let sample = CaptureSample {
        current_adc: u16::MAX,
        encoder_count: i32::MIN,
        output_count: Some(i32::MIN),
    };
    CaptureChunk {
        capture_id: u16::MAX,
        first_sample: u32::MAX,
        total_samples: u32::MAX,
        samples: Vec::from_slice(&[sample; CAPTURE_CHUNK_SAMPLES]).unwrap(),
    }
}

pub(crate) fn device_info() -> DeviceInfo {
    DeviceInfo {
        protocol_version: 8,
        schema_hash: 0xDEAD_BEEF,
        firmware_version: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 2,
        },
        firmware_build: String::try_from("1a2b3c4d5e6f-dirty").unwrap(),
        board: String::try_from("nucleo-g474re").unwrap(),
        parameters_status: ParametersStatus::Defaults,
        reset_cause: ResetCause::Watchdog,
        uptime_s: 3_600,
        capabilities: Capabilities::OUTPUT_ENCODER | Capabilities::BUS_VOLTAGE,
        time_scale: 1.0,
        max_baud: crate::FAST_BAUD_RATE,
    }
}

/// One example of each request, in variant order.
pub(crate) fn requests() -> std::vec::Vec<Named<Request>> {
    use Request::*;
    vec![
        (
            "Request::Hello",
            Hello {
                protocol_version: 2,
                schema_hash: 0xDEAD_BEEF,
            },
        ),
        ("Request::GetInfo", GetInfo),
        (
            "Request::Release",
            Release {
                on: true,
                target_hz: 10.0,
                session: 0x5EED_0001,
            },
        ),
        (
            "Request::Heartbeat",
            Heartbeat {
                session: 0x5EED_0001,
            },
        ),
        ("Request::GetParameters", GetParameters),
        (
            "Request::SetParameters",
            // A profile-shifted design (Z1 + Z2 = 100, Z3 + Z4 = 101, one working centre
            // distance): the record's last field carries the shifts.
            SetParameters(RigParameters {
                z: [49, 51, 51, 50],
                profile_shift: [0.2, 0.3, 0.0, -0.017],
                ..RigParameters::paper()
            }),
        ),
        ("Request::StartTelemetry", StartTelemetry { rate_hz: 200 }),
        ("Request::StopTelemetry", StopTelemetry),
        (
            "Request::StartCapture",
            StartCapture {
                sample_rate_hz: 10_000,
                samples: 5_000,
            },
        ),
        ("Request::GetFaults", GetFaults),
        ("Request::ClearFaults", ClearFaults),
        ("Request::RezeroCurrent", RezeroCurrent),
        (
            "Request::OpenLoop",
            OpenLoop {
                volts: 3.6,
                session: 0x5EED_0001,
            },
        ),
        (
            "Request::Simulation(SimCommand::SetLoad)",
            Simulation(SimCommand::SetLoad { tau_rot_nm: 0.368 }),
        ),
        (
            "Request::Simulation(SimCommand::SetSupplyVoltage)",
            Simulation(SimCommand::SetSupplyVoltage { volts: 6.2 }),
        ),
        (
            "Request::Simulation(SimCommand::SetSensorSupply)",
            Simulation(SimCommand::SetSensorSupply { volts: 4.75 }),
        ),
        ("Request::StartStream", StartStream { rate_hz: 10_000 }),
        ("Request::StopStream", StopStream),
        ("Request::SetBaud", SetBaud { baud: 4_000_000 }),
    ]
}

/// Exhaustive on purpose: the position of `r`'s example in [`requests`].
pub(crate) fn request_index(r: &Request) -> usize {
    use Request::*;
    match r {
        Hello { .. } => 0,
        GetInfo => 1,
        Release { .. } => 2,
        Heartbeat { .. } => 3,
        GetParameters => 4,
        SetParameters(_) => 5,
        StartTelemetry { .. } => 6,
        StopTelemetry => 7,
        StartCapture { .. } => 8,
        GetFaults => 9,
        ClearFaults => 10,
        RezeroCurrent => 11,
        OpenLoop { .. } => 12,
        Simulation(SimCommand::SetLoad { .. }) => 13,
        Simulation(SimCommand::SetSupplyVoltage { .. }) => 14,
        Simulation(SimCommand::SetSensorSupply { .. }) => 15,
        StartStream { .. } => 16,
        StopStream => 17,
        SetBaud { .. } => 18,
    }
}

/// One example of each refusal code, in variant order.
pub(crate) fn nack_codes() -> std::vec::Vec<Named<NackCode>> {
    use NackCode::*;
    vec![
        (
            "VersionMismatch",
            VersionMismatch {
                device_protocol: 2,
                device_schema_hash: 0xDEAD_BEEF,
            },
        ),
        ("UnknownMessage", UnknownMessage),
        ("BadArgument", BadArgument),
        ("InFaultHold", InFaultHold),
        (
            "ParametersRejected",
            ParametersRejected(ParameterRejection::new(
                ParameterField::MaxReleaseLoad,
                RejectReason::AboveBoardCap,
            )),
        ),
        ("Busy", Busy),
        ("StorageFailed", StorageFailed),
        ("SimulationOnly", SimulationOnly),
        ("CurrentZeroPending", CurrentZeroPending),
        ("StreamRate", StreamRate { fits_hz: 2_500 }),
    ]
}

/// Exhaustive on purpose, as [`request_index`].
pub(crate) fn nack_index(c: &NackCode) -> usize {
    use NackCode::*;
    match c {
        VersionMismatch { .. } => 0,
        UnknownMessage => 1,
        BadArgument => 2,
        InFaultHold => 3,
        ParametersRejected(_) => 4,
        Busy => 5,
        StorageFailed => 6,
        SimulationOnly => 7,
        CurrentZeroPending => 8,
        StreamRate { .. } => 9,
    }
}

/// One example of each reply, in variant order, with one `Nack` per refusal code.
pub(crate) fn replies() -> std::vec::Vec<(std::string::String, Reply)> {
    let mut out = vec![("Reply::Info".to_owned(), Reply::Info(device_info()))];
    for (name, code) in nack_codes() {
        out.push((format!("Reply::Nack(NackCode::{name})"), Reply::Nack(code)));
    }
    out.push(("Reply::Ack".to_owned(), Reply::Ack));
    out.push((
        "Reply::Faults".to_owned(),
        Reply::Faults {
            active: FaultFlags::empty(),
            latched: FaultFlags::COMMS_TIMEOUT | FaultFlags::HW_OVERCURRENT,
        },
    ));
    out.push((
        "Reply::Parameters".to_owned(),
        Reply::Parameters(RigParameters::paper()),
    ));
    out
}

/// Exhaustive on purpose: the variant index of `r`.
pub(crate) fn reply_index(r: &Reply) -> usize {
    match r {
        Reply::Info(_) => 0,
        Reply::Nack(_) => 1,
        Reply::Ack => 2,
        Reply::Faults { .. } => 3,
        Reply::Parameters(_) => 4,
    }
}

/// A stream block as the device sends it at 10 kHz: one control step of a vibrating cam
/// (the current and cam count move every sample, the step's fields are held).
pub(crate) fn stream_block() -> crate::StreamBlock {
    let samples: std::vec::Vec<_> = (0..STREAM_BLOCK_SAMPLES)
        .map(|k| {
            let k16 = u16::try_from(k).unwrap();
            crate::StreamSample {
                current_adc: [2300, 2303, 2301, 2306, 2304, 2309, 2307, 2310, 2312, 2311][k],
                cam_count: 40_000 + 16 * k16,
                output_count: 1_200,
                duty: 4_150,
                tau_cam: 312,
                status: (StatusFlags::HOST_RELEASE | StatusFlags::NOT_SELF_LOCKING).bits(),
                state: 2,
            }
        })
        .collect();
    crate::StreamBlock::pack(123_450, &samples)
}

/// A stream block at its largest: every field jumps by its largest difference at every
/// sample.
pub(crate) fn worst_case_stream_block() -> (std::vec::Vec<crate::StreamSample>, crate::StreamBlock)
{
    let samples: std::vec::Vec<_> = (0..STREAM_BLOCK_SAMPLES)
        .map(|k| {
            let odd = k % 2 == 1;
            crate::StreamSample {
                current_adc: if odd { 0 } else { 0x8000 },
                cam_count: if odd { 0 } else { 0x8000 },
                output_count: if odd { 0 } else { 0x8000 },
                duty: if odd { i16::MAX } else { i16::MIN },
                tau_cam: if odd { i16::MAX } else { i16::MIN },
                // The first sample's status takes 3 bytes, its state 1.
                status: if odd { u16::MAX } else { 0xFFFE },
                state: if odd { 0xFF } else { 0 },
            }
        })
        .collect();
    let block = crate::StreamBlock::pack(u32::MAX, &samples);
    (samples, block)
}

/// One example of each device message (every reply inside `Reply`), in variant order.
pub(crate) fn device_messages() -> std::vec::Vec<(std::string::String, DeviceMessage)> {
    use DeviceMessage::*;
    let sample = |current_adc, encoder_count, output_count| CaptureSample {
        current_adc,
        encoder_count,
        output_count,
    };
    let mut out: std::vec::Vec<_> = replies()
        .into_iter()
        .map(|(name, reply)| {
            (
                format!("DeviceMessage::Reply({name})"),
                DeviceMessage::reply(300, reply),
            )
        })
        .collect();
    let unsolicited = [
        ("DeviceMessage::Telemetry", Telemetry(telemetry())),
        (
            "DeviceMessage::CaptureChunk",
            CaptureChunk(crate::CaptureChunk {
                capture_id: 3,
                first_sample: 64,
                total_samples: 100,
                samples: Vec::from_slice(&[
                    sample(2048, 0, Some(0)),
                    sample(2100, -1, Some(-3)),
                    sample(2090, -2, Some(70_000)),
                ])
                .unwrap(),
            }),
        ),
        (
            "DeviceMessage::CaptureDone",
            CaptureDone {
                capture_id: 3,
                total_samples: 100,
                sample_rate_hz: 10_000,
            },
        ),
        (
            "DeviceMessage::FaultEvent",
            FaultEvent {
                flags: FaultFlags::OVERCURRENT | FaultFlags::STALL,
                device_time_us: 1_000,
            },
        ),
        ("DeviceMessage::Health", Health(health())),
        ("DeviceMessage::StreamBlock", StreamBlock(stream_block())),
    ];
    out.extend(unsolicited.map(|(n, m)| (n.to_owned(), m)));
    out
}

/// Exhaustive on purpose: the variant index of `m`.
pub(crate) fn device_index(m: &DeviceMessage) -> usize {
    use DeviceMessage::*;
    match m {
        Reply { .. } => 0,
        Telemetry(_) => 1,
        CaptureChunk(_) => 2,
        CaptureDone { .. } => 3,
        FaultEvent { .. } => 4,
        Health(_) => 5,
        StreamBlock(_) => 6,
    }
}

/// A value of one of the enums inside messages, for the snapshot's value lines.
pub(crate) enum Leaf {
    State(SupervisorState),
    Status(ParametersStatus),
    Reset(ResetCause),
    Field(ParameterField),
    Reason(RejectReason),
}

impl serde::Serialize for Leaf {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::State(v) => v.serialize(s),
            Self::Status(v) => v.serialize(s),
            Self::Reset(v) => v.serialize(s),
            Self::Field(v) => v.serialize(s),
            Self::Reason(v) => v.serialize(s),
        }
    }
}

/// Every variant of the enums inside messages, with its variant index (the wire tag).
pub(crate) fn leaves() -> std::vec::Vec<(std::string::String, usize, Leaf)> {
    let mut out = std::vec::Vec::new();
    let mut add = |name: std::string::String, leaf: Leaf| {
        let index = leaf_index(&leaf);
        out.push((name, index, leaf));
    };
    use SupervisorState as S;
    for v in [S::Locked, S::SpinUp, S::Vibrating, S::Stopping, S::Fault] {
        add(format!("SupervisorState::{v:?}"), Leaf::State(v));
    }
    use ParametersStatus as P;
    for v in [P::Valid, P::Defaults, P::Invalid] {
        add(format!("ParametersStatus::{v:?}"), Leaf::Status(v));
    }
    use ResetCause as R;
    let causes = [
        R::PowerOn,
        R::Pin,
        R::Software,
        R::Watchdog,
        R::BrownOut,
        R::Lockup,
        R::Other,
    ];
    for v in causes {
        add(format!("ResetCause::{v:?}"), Leaf::Reset(v));
    }
    for v in ParameterField::ALL {
        add(format!("ParameterField::{v:?}"), Leaf::Field(v));
    }
    use RejectReason as J;
    let reasons = [
        J::NotFinite,
        J::OutOfRange,
        J::AboveBoardCap,
        J::Inconsistent,
        J::Implausible,
    ];
    for v in reasons {
        add(format!("RejectReason::{v:?}"), Leaf::Reason(v));
    }
    out
}

/// Exhaustive on purpose: the variant index of a leaf value.
fn leaf_index(leaf: &Leaf) -> usize {
    match leaf {
        Leaf::State(v) => match v {
            SupervisorState::Locked => 0,
            SupervisorState::SpinUp => 1,
            SupervisorState::Vibrating => 2,
            SupervisorState::Stopping => 3,
            SupervisorState::Fault => 4,
        },
        Leaf::Status(v) => match v {
            ParametersStatus::Valid => 0,
            ParametersStatus::Defaults => 1,
            ParametersStatus::Invalid => 2,
        },
        Leaf::Reset(v) => match v {
            ResetCause::PowerOn => 0,
            ResetCause::Pin => 1,
            ResetCause::Software => 2,
            ResetCause::Watchdog => 3,
            ResetCause::BrownOut => 4,
            ResetCause::Lockup => 5,
            ResetCause::Other => 6,
        },
        Leaf::Field(v) => match v {
            ParameterField::C1 => 0,
            ParameterField::C2 => 1,
            ParameterField::C3 => 2,
            ParameterField::C4 => 3,
            ParameterField::C5 => 4,
            ParameterField::C6 => 5,
            ParameterField::Z => 6,
            ParameterField::Module => 7,
            ParameterField::PressureAngle => 8,
            ParameterField::Eccentricity => 9,
            ParameterField::CarrierMass => 10,
            ParameterField::MuS => 11,
            ParameterField::MuD => 12,
            ParameterField::MaxReleaseLoad => 13,
            ParameterField::MaxCurrent => 14,
            ParameterField::MaxFreq => 15,
            ParameterField::ProfileShift => 16,
        },
        Leaf::Reason(v) => match v {
            RejectReason::NotFinite => 0,
            RejectReason::OutOfRange => 1,
            RejectReason::AboveBoardCap => 2,
            RejectReason::Inconsistent => 3,
            RejectReason::Implausible => 4,
        },
    }
}

/// Every named bit of every flag set: (set name, flag name, bits).
pub(crate) fn flags() -> std::vec::Vec<(&'static str, &'static str, u64)> {
    let mut out = std::vec::Vec::new();
    for (name, f) in FaultFlags::NAMED {
        out.push(("FaultFlags", *name, u64::from(f.bits())));
    }
    for (name, f) in StatusFlags::NAMED {
        out.push(("StatusFlags", *name, u64::from(f.bits())));
    }
    for (name, f) in Capabilities::NAMED {
        out.push(("Capabilities", *name, u64::from(f.bits())));
    }
    out
}
