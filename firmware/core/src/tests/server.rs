//! The protocol server: every request answered, arguments checked, streams paced,
//! garbage counted.

use protocol::{
    CaptureSample, DeviceMessage, FaultFlags, MAX_FRAME_SIZE, NackCode, PROTOCOL_VERSION,
    ParameterField, ParameterRejection, ParametersStatus, RejectReason, Reply, Request, ResetCause,
    RigParameters, SCHEMA_HASH, SimCommand, SupervisorState, encode_frame,
};

use super::Rig;

/// What a reply must look like.
type Expect = Box<dyn Fn(&DeviceMessage) -> bool>;

fn hello() -> Request {
    Request::Hello {
        protocol_version: PROTOCOL_VERSION,
        schema_hash: SCHEMA_HASH,
    }
}

#[test]
fn every_request_is_answered() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    let info = |m: &DeviceMessage| matches!(m, DeviceMessage::Reply { reply: Reply::Info(i), .. } if i.board == "nucleo-g474re" && i.protocol_version == PROTOCOL_VERSION && i.parameters_status == ParametersStatus::Defaults);
    let cases: Vec<(Request, Expect)> = vec![
        (hello(), Box::new(info)),
        (Request::GetInfo, Box::new(info)),
        (
            Request::Heartbeat { session: 0 },
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
        (
            Request::GetParameters,
            Box::new(
                |m| matches!(m, DeviceMessage::Reply { reply: Reply::Parameters(c), .. } if *c == RigParameters::paper()),
            ),
        ),
        (
            Request::StartTelemetry { rate_hz: 50 },
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
        (
            Request::StopTelemetry,
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
        (
            Request::GetFaults,
            Box::new(
                |m| matches!(m, DeviceMessage::Reply { reply: Reply::Faults { active, latched }, .. } if active.is_empty() && latched.is_empty()),
            ),
        ),
        (
            Request::ClearFaults,
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Faults { .. },
                        ..
                    }
                )
            }),
        ),
        (
            Request::RezeroCurrent,
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
        (
            Request::StartCapture {
                sample_rate_hz: 1000,
                samples: 10,
            },
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
        (
            Request::Release {
                on: false,
                target_hz: 0.0,
                session: 0,
            },
            Box::new(|m| {
                matches!(
                    m,
                    DeviceMessage::Reply {
                        reply: Reply::Ack,
                        ..
                    }
                )
            }),
        ),
    ];
    for (request, expect) in cases {
        let replies = rig.request(&request);
        assert_eq!(replies.len(), 1, "{request:?}: {replies:?}");
        assert!(expect(&replies[0]), "{request:?}: {replies:?}");
        // Every reply names the request's sequence number (sent just before).
        assert_eq!(
            replies[0].reply_to(),
            Some(rig_last_seq(&rig)),
            "{request:?}"
        );
        rig.run_ms(120);
    }
}

/// The seq of the request sent last (the rig counts from 0).
fn rig_last_seq(rig: &Rig) -> u16 {
    rig.sent_count().wrapping_sub(1)
}

#[test]
fn hello_with_another_version_is_refused() {
    let mut rig = Rig::new(0.0);
    for (v, h) in [
        (PROTOCOL_VERSION + 1, SCHEMA_HASH),
        (PROTOCOL_VERSION, SCHEMA_HASH ^ 1),
    ] {
        // The refusal carries the device's own version, so the host can say what to do.
        assert_eq!(
            rig.ack(&Request::Hello {
                protocol_version: v,
                schema_hash: h
            }),
            Err(NackCode::VersionMismatch {
                device_protocol: PROTOCOL_VERSION,
                device_schema_hash: SCHEMA_HASH
            })
        );
    }
}

#[test]
fn release_arguments_are_checked_never_clamped() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    for hz in [0.5, 20.5, f32::NAN, f32::INFINITY, -10.0] {
        assert_eq!(
            rig.ack(&Request::Release {
                on: true,
                target_hz: hz,
                session: 0
            }),
            Err(NackCode::BadArgument),
            "{hz}"
        );
    }
    // 18 Hz is within the board's cap but above the calibration's 15 Hz limit: refused,
    // never run at 15 Hz instead.
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 18.0,
            session: 0
        }),
        Err(NackCode::BadArgument)
    );
    rig.step();
    assert!(
        !rig.core
            .status()
            .flags
            .contains(protocol::StatusFlags::HOST_RELEASE)
    );
    // The limit itself is used as asked.
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 15.0,
            session: 0
        }),
        Ok(())
    );
    rig.step();
    assert_eq!(rig.core.status().target_hz, 15.0);
}

#[test]
fn set_calibration_persists_then_activates() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    let new = RigParameters {
        // C1 changed alone stays within C4 = C1 C6 + C2's tolerance (model's check).
        c1_nmm_per_a: 62.0,
        max_freq_hz: 18.0,
        ..RigParameters::paper()
    };
    let seq = rig.send(&Request::SetParameters(new));
    // Not acknowledged before the flash write.
    assert!(!rig.answered(seq, |r| *r == Reply::Ack));
    rig.step();
    assert_eq!(rig.persisted, [new]);
    assert!(rig.answered(seq, |r| *r == Reply::Ack));
    assert_eq!(rig.reply(&Request::GetParameters), Reply::Parameters(new));
    let s = rig.core.status();
    assert_eq!(s.parameters_status, ParametersStatus::Valid);

    // Invalid values are rejected without touching flash, naming the field.
    let rejected = |field, reason| {
        Err(NackCode::ParametersRejected(ParameterRejection::new(
            field, reason,
        )))
    };
    let bad = RigParameters {
        z: [49, 51, 50, 49], // unequal centre distances
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::Z, RejectReason::Inconsistent)
    );
    let bad = RigParameters {
        mu_s: f32::NAN,
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::MuS, RejectReason::NotFinite)
    );
    // Limits the board cannot honour are refused, not silently lowered.
    let bad = RigParameters {
        max_current_a: 6.0, // the board trips at 4.8 A
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::MaxCurrent, RejectReason::AboveBoardCap)
    );
    let bad = RigParameters {
        max_freq_hz: 25.0, // the supervisor drives at most 20 Hz
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::MaxFreq, RejectReason::AboveBoardCap)
    );
    rig.step();
    assert_eq!(rig.persisted.len(), 1);
}

#[test]
fn a_shifted_gear_with_unequal_tooth_sums_is_stored_with_its_own_lambda() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    // The paper's gear coasts after the cam stops (mu_d Lambda 0.86).
    assert!(rig.core.status().keeps_moving_after_stop);
    // A design of `rig design search`: Z1 + Z2 = 104, Z3 + Z4 = 105, one working centre
    // distance through the shifts; the model gives mu_d Lambda 1.97: it stops.
    let new = RigParameters {
        z: [54, 50, 50, 55],
        profile_shift: [-0.1, -0.1, -0.4, -0.265_678_2],
        ..RigParameters::paper()
    };
    let g = model::GearSet::shifted(
        new.z.map(u32::from),
        new.profile_shift.map(f64::from),
        1e-3,
        20f64.to_radians(),
    )
    .unwrap();
    assert!(f64::from(new.mu_d) * g.big_lambda() > 1.9);
    let seq = rig.send(&Request::SetParameters(new));
    rig.step();
    assert_eq!(rig.persisted, [new]);
    assert!(rig.answered(seq, |r| *r == Reply::Ack));
    assert_eq!(rig.reply(&Request::GetParameters), Reply::Parameters(new));
    assert!(!rig.core.status().keeps_moving_after_stop);

    let rejected = |field| {
        Err(NackCode::ParametersRejected(ParameterRejection::new(
            field,
            RejectReason::Inconsistent,
        )))
    };
    // x4 0.03 off: the working centre distances differ by about 0.03 module.
    let mut off = new;
    off.profile_shift[3] += 0.03;
    assert_eq!(
        rig.ack(&Request::SetParameters(off)),
        rejected(ParameterField::ProfileShift)
    );
    // The same teeth without the shifts: unequal sums, refused naming the teeth.
    let unshifted = RigParameters {
        profile_shift: [0.0; 4],
        ..new
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(unshifted)),
        rejected(ParameterField::Z)
    );
    rig.step();
    assert_eq!(rig.persisted.len(), 1);
}

#[test]
fn limits_and_constants_the_host_cannot_lift() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    let rejected = |field, reason| {
        Err(NackCode::ParametersRejected(ParameterRejection::new(
            field, reason,
        )))
    };
    // 3.4e38 would switch OVERLOAD off; the gear's teeth hold 3.68 N m.
    for load in [1e30, 3.4e38, 3.7] {
        let bad = RigParameters {
            max_release_load_nm: load,
            ..RigParameters::paper()
        };
        assert_eq!(
            rig.ack(&Request::SetParameters(bad)),
            rejected(ParameterField::MaxReleaseLoad, RejectReason::AboveBoardCap),
            "{load}"
        );
    }
    // A fit 36 times off Table 2 is implausible for the RS-735.
    let bad = RigParameters {
        c1_nmm_per_a: 2258.0,
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::C1, RejectReason::Implausible)
    );
    // C3 = C1 C5 (0.235 N mm s/rad) within 10 %.
    let bad = RigParameters {
        c3_nmm_s_per_rad: 0.5,
        ..RigParameters::paper()
    };
    assert_eq!(
        rig.ack(&Request::SetParameters(bad)),
        rejected(ParameterField::C3, RejectReason::Inconsistent)
    );
    rig.step();
    assert!(rig.persisted.is_empty());
    // The same rule, the model's, is what the host runs before sending.
    let bad = RigParameters {
        max_release_load_nm: 1e30,
        ..RigParameters::paper()
    };
    let config = crate::CoreConfig::default();
    assert_eq!(
        crate::check_rules(&bad, &config.board_limits(), config.motor.constants())
            .map_err(|r| r.field),
        Err(ParameterField::MaxReleaseLoad)
    );
    // At the caps is fine.
    let ok = RigParameters {
        max_release_load_nm: 3.68,
        max_current_a: 4.8,
        max_freq_hz: 20.0,
        ..RigParameters::paper()
    };
    let seq = rig.send(&Request::SetParameters(ok));
    rig.step();
    assert!(rig.answered(seq, |r| *r == Reply::Ack));
    assert_eq!(rig.persisted, [ok]);
}

#[test]
fn release_off_stops_an_open_loop_drive() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(1200);
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 6.2,
            session: 0
        }),
        Ok(())
    );
    rig.run_ms_alive(800);
    assert!(rig.core.status().enabled);
    assert_eq!(
        rig.ack(&Request::Release {
            on: false,
            target_hz: 10.0,
            session: 0
        }),
        Ok(())
    );
    let s = rig.core.status();
    assert_eq!(s.open_loop_volts, None);
    assert!(!rig.step().enable, "the bridge is off at the next step");
    assert!(rig.core.status().latched_faults.is_empty());
}

#[test]
fn failed_flash_write_keeps_the_old_calibration() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.persist_answer = Some(false);
    let new = RigParameters {
        c1_nmm_per_a: 62.0,
        ..RigParameters::paper()
    };
    let seq = rig.send(&Request::SetParameters(new));
    rig.step();
    let storage_failed = |r: &Reply| *r == Reply::Nack(NackCode::StorageFailed);
    assert!(rig.answered(seq, storage_failed));
    assert_eq!(rig.core.status().parameters, RigParameters::paper());

    // A binary that never answers: refused after 5 s; meanwhile another write is Busy.
    rig.persist_answer = None;
    let seq = rig.send(&Request::SetParameters(new));
    rig.step();
    assert_eq!(rig.ack(&Request::SetParameters(new)), Err(NackCode::Busy));
    rig.run_ms(5001);
    assert!(rig.answered(seq, storage_failed));
}

#[test]
fn calibration_and_rezero_are_busy_while_the_motor_runs() {
    let mut rig = Rig::new(0.5);
    rig.vibrate(10.0);
    assert_eq!(
        rig.ack(&Request::SetParameters(RigParameters::paper())),
        Err(NackCode::Busy)
    );
    assert_eq!(rig.ack(&Request::RezeroCurrent), Err(NackCode::Busy));
    assert_eq!(rig.state(), SupervisorState::Vibrating);
}

#[test]
fn telemetry_streams_at_the_rate_asked_or_refuses() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    let telemetry = |rig: &Rig| rig.count(|m| matches!(m, DeviceMessage::Telemetry(_)));
    assert_eq!(
        rig.ack(&Request::StartTelemetry { rate_hz: 0 }),
        Err(NackCode::BadArgument)
    );
    rig.ack(&Request::StartTelemetry { rate_hz: 100 }).unwrap();
    rig.run_ms(1000);
    assert_eq!(telemetry(&rig), 100);
    // Rates it cannot keep exactly are refused (the stream goes on at 100 Hz).
    for rate_hz in [300, 1001, 60_000, u16::MAX] {
        assert_eq!(
            rig.ack(&Request::StartTelemetry { rate_hz }),
            Err(NackCode::BadArgument),
            "{rate_hz}"
        );
    }
    let before = telemetry(&rig);
    rig.run_ms(500);
    assert_eq!(telemetry(&rig) - before, 50);
    rig.ack(&Request::StartTelemetry { rate_hz: 1000 }).unwrap();
    let before = telemetry(&rig);
    rig.run_ms(500);
    assert_eq!(telemetry(&rig) - before, 500);
    rig.ack(&Request::StopTelemetry).unwrap();
    let before = telemetry(&rig);
    rig.run_ms(100);
    assert_eq!(telemetry(&rig), before);
    // Samples count up without gaps and carry the state.
    let seqs: Vec<u32> = rig
        .received
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::Telemetry(t) => Some(t.seq),
            _ => None,
        })
        .collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1));
}

#[test]
fn capture_uploads_while_telemetry_and_replies_continue() {
    let mut rig = Rig::new(1.0);
    rig.vibrate(10.0);
    rig.ack(&Request::StartTelemetry { rate_hz: 1000 }).unwrap();
    assert_eq!(
        rig.ack(&Request::StartCapture {
            sample_rate_hz: 10_000,
            samples: 50_000,
        }),
        Err(NackCode::BadArgument),
        "more than the buffer: refused, not capped"
    );
    rig.ack(&Request::StartCapture {
        sample_rate_hz: 10_000,
        samples: 10_000,
    })
    .unwrap();
    assert_eq!(
        rig.ack(&Request::StartCapture {
            sample_rate_hz: 10_000,
            samples: 10
        }),
        Err(NackCode::Busy)
    );
    let start = rig.received.len();
    // Simulate a 921 600 Bd link: ~92 bytes per ms leave the device.
    rig.link_budget = Some(92);
    let mut done_at = None;
    for ms in 0..3000 {
        if ms % 150 == 0 {
            rig.send(&protocol::Request::Heartbeat { session: 0 });
        }
        rig.step();
        if rig.received[start..]
            .iter()
            .any(|m| matches!(m, DeviceMessage::CaptureDone { .. }))
        {
            done_at = Some(ms);
            break;
        }
    }
    let done_at = done_at.expect("capture completes");
    let mut samples: Vec<CaptureSample> = Vec::new();
    let mut telemetry_during = 0;
    for m in &rig.received[start..] {
        match m {
            DeviceMessage::CaptureChunk(c) => {
                assert_eq!(c.first_sample as usize, samples.len());
                assert_eq!(c.total_samples, 10_000);
                samples.extend(c.samples.iter().copied());
            }
            DeviceMessage::Telemetry(_) if !samples.is_empty() => telemetry_during += 1,
            DeviceMessage::CaptureDone {
                total_samples,
                sample_rate_hz,
                ..
            } => {
                assert_eq!((*total_samples, *sample_rate_hz), (10_000, 10_000));
            }
            _ => {}
        }
    }
    assert_eq!(samples.len(), 10_000);
    // This core has no output encoder: the samples say so rather than carry a made-up 0.
    assert!(samples.iter().all(|s| s.output_count.is_none()));
    // One second of recording plus the upload (~80 kB: v4's output field is one byte
    // without an output encoder) sharing the link with telemetry.
    assert!(done_at < 2700, "{done_at} ms");
    assert!(
        telemetry_during > 500,
        "{telemetry_during} telemetry samples during upload"
    );
    // At 10 Hz the cam turns 8192 counts per 100 ms: ~8192 counts per 1000 samples.
    let turned = samples[9999].encoder_count - samples[0].encoder_count;
    assert!((80_000..84_000).contains(&turned), "{turned}");
    // The current is the plant's (1 N m at 10 Hz: about 2.6 A, i.e. ~2068 + 400 counts).
    let mean = samples
        .iter()
        .map(|s| f64::from(s.current_adc))
        .sum::<f64>()
        / 10_000.0;
    assert!((2350.0..2600.0).contains(&mean), "{mean}");
    assert_eq!(rig.state(), SupervisorState::Vibrating);
    assert_eq!(rig.core.status().tx_dropped, 0);
}

#[test]
fn garbage_is_counted_and_never_stops_the_server() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    // Line noise, an over-long run, a corrupted frame, stray delimiters.
    let mut noise: Vec<u8> = (0..500u32).map(|i| (i * 7919 % 251) as u8).collect();
    noise.push(0);
    noise.extend(std::iter::repeat_n(0x55, 300));
    noise.push(0);
    let mut buf = [0u8; MAX_FRAME_SIZE];
    let mut frame = encode_frame(77, &Request::GetInfo, &mut buf)
        .unwrap()
        .to_vec();
    frame[2] ^= 0x40;
    noise.extend(&frame);
    noise.extend([0, 0, 0]);
    for chunk in noise.chunks(13) {
        rig.core.receive(rig.now_us, chunk);
    }
    let stats = rig.core.status().deframer;
    // Two runs of noise and the 0x55 run overflow the 82-byte request buffer; the
    // corrupted frame fails its CRC or its COBS.
    assert_eq!(stats.overflow_errors, 3, "{stats:?}");
    assert_eq!(stats.crc_errors + stats.framing_errors, 1, "{stats:?}");
    assert_eq!(stats.frames_ok, 0);
    rig.pump();
    assert!(
        rig.received.is_empty()
            || rig
                .received
                .iter()
                .all(|m| matches!(m.as_reply(), Some(Reply::Nack(_))))
    );
    // Still serving.
    assert!(matches!(
        rig.request(&Request::GetInfo)[..],
        [DeviceMessage::Reply {
            reply: Reply::Info(_),
            ..
        }]
    ));
    assert!(rig.latched().is_empty());
}

#[test]
fn unknown_message_is_refused_with_its_seq() {
    let mut rig = Rig::new(0.0);
    // A frame with a good CRC whose message tag no firmware knows.
    let mut buf = [0u8; MAX_FRAME_SIZE];
    let frame = encode_frame(4321, &200u8, &mut buf).unwrap().to_vec();
    rig.core.receive(0, &frame);
    rig.pump();
    assert_eq!(
        rig.received,
        [DeviceMessage::nack(4321, NackCode::UnknownMessage)]
    );
    assert_eq!(rig.core.status().deframer.decode_errors, 1);
}

#[test]
fn faults_report_active_and_latched() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.adc_offset = 5 * 153;
    rig.run_ms(20);
    let replies = rig.request(&Request::GetFaults);
    assert_eq!(
        replies,
        [DeviceMessage::reply(
            rig_last_seq(&rig),
            Reply::Faults {
                active: FaultFlags::OVERCURRENT,
                latched: FaultFlags::OVERCURRENT
            }
        )]
    );
}

#[test]
fn open_loop_drives_a_fixed_voltage_while_kept_alive() {
    let mut rig = Rig::new(2.0);
    rig.run_ms(1200);
    for volts in [f32::NAN, 30.0, -30.0] {
        assert_eq!(
            rig.ack(&Request::OpenLoop { volts, session: 0 }),
            Err(NackCode::BadArgument)
        );
    }
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 6.2,
            session: 0
        }),
        Ok(())
    );
    // Exclusive with a speed-controlled release.
    assert_eq!(
        rig.ack(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        }),
        Err(NackCode::Busy)
    );
    let t = rig.run_until(4000, true, |s| s.state == SupervisorState::Vibrating);
    assert!(t.is_some(), "{:?}", rig.core.status());
    let s = rig.core.status();
    assert!((s.duty - 6.2 / 12.0).abs() < 1e-3, "{}", s.duty);
    assert_eq!(s.open_loop_volts, Some(6.2));
    // The paper's 6.2 V gives about 10 Hz.
    let hz = s.cam_speed_rad_s / core::f32::consts::TAU;
    assert!((hz - 10.0).abs() < 1.5, "{hz} Hz");
    rig.run_ms_alive(1500);
    let s = rig.core.status();
    assert!(s.estimate_valid);
    // The per-revolution load estimate sees the 2 N m load.
    assert!((s.tau_rot_nm - 2.0).abs() < 0.15, "{}", s.tau_rot_nm);
    // 0 V ends it; the cam coasts to rest and the core locks.
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 0.0,
            session: 0
        }),
        Ok(())
    );
    let t = rig.run_until(3000, false, |s| s.state == SupervisorState::Locked);
    assert!(t.is_some());
    assert!(rig.core.status().latched_faults.is_empty());
}

#[test]
fn open_loop_without_heartbeat_times_out_to_safe() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(1200);
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 3.6,
            session: 0
        }),
        Ok(())
    );
    let t = rig.run_until(2000, false, |s| !s.enabled && !s.latched_faults.is_empty());
    assert!(t.is_some());
    let s = rig.core.status();
    assert!(
        s.latched_faults.contains(FaultFlags::COMMS_TIMEOUT),
        "{:?}",
        s.latched_faults
    );
    assert_eq!(s.open_loop_volts, None);
}

#[test]
fn refused_requests_do_not_keep_a_release_alive() {
    // A release, then only refused requests (a host retrying a bad record, another
    // version's hello) and undecodable frames: the release lapses within the comms
    // timeout as if the host had gone.
    let mut rig = Rig::new(0.3);
    rig.vibrate(10.0);
    assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
    let last_accepted = rig.now_us;
    let bad = RigParameters {
        mu_d: 0.5,
        ..RigParameters::paper()
    };
    let mut buf = [0u8; MAX_FRAME_SIZE];
    let unknown = encode_frame(999, &200u8, &mut buf).unwrap().to_vec();
    let mut refused = 0;
    let lapsed_at = loop {
        match (rig.now_us / 1000) % 3 {
            0 => {
                // Busy while the motor runs, and a bad record in any case.
                if rig.ack(&Request::SetParameters(bad)).is_err() {
                    refused += 1;
                }
            }
            1 => {
                let hello = Request::Hello {
                    protocol_version: PROTOCOL_VERSION + 1,
                    schema_hash: 0,
                };
                if rig.ack(&hello).is_err() {
                    refused += 1;
                }
            }
            _ => rig.core.receive(rig.now_us, &unknown),
        }
        rig.step();
        if rig.latched().contains(FaultFlags::COMMS_TIMEOUT) {
            break rig.now_us;
        }
        assert!(
            rig.now_us - last_accepted < 2_000_000,
            "the release never lapsed"
        );
    };
    assert!(refused > 250, "{refused} refused requests");
    let after_us = lapsed_at - last_accepted;
    assert!((500_000..=502_000).contains(&after_us), "{after_us} us");
    assert!(!rig.step().enable);
}

#[test]
fn the_owners_heartbeats_keep_a_release_alive_not_other_requests() {
    let mut rig = Rig::new(0.3);
    rig.vibrate(10.0);
    for k in 0..1500 {
        if k % 150 == 0 {
            assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
        }
        rig.step();
    }
    assert_eq!(rig.state(), SupervisorState::Vibrating);
    assert!(rig.latched().is_empty());
    // Accepted but not a drive request: a status query keeps nothing alive.
    let last_beat = rig.now_us;
    assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
    let lapsed = (0..1500).find(|k| {
        if k % 100 == 0 {
            assert!(matches!(
                rig.reply(&Request::GetFaults),
                Reply::Faults { .. }
            ));
        }
        rig.step();
        rig.latched().contains(FaultFlags::COMMS_TIMEOUT)
    });
    let after_us = lapsed.map(|_| rig.now_us - last_beat);
    assert!(
        after_us.is_some_and(|us| (500_000..=502_000).contains(&us)),
        "{after_us:?}"
    );
}

#[test]
fn a_second_session_cannot_keep_a_dead_hosts_release_alive_or_take_it_over() {
    // Issue 33's case: `rig release on` (session 0) is killed; a second process on the
    // port (session 77) sends GetFaults and heartbeats every 0.3 s and asks to release.
    let mut rig = Rig::new(0.3);
    rig.vibrate(10.0);
    assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
    let owner_gone = rig.now_us;
    let stranger = Request::Release {
        on: true,
        target_hz: 12.0,
        session: 77,
    };
    assert_eq!(rig.ack(&stranger), Err(NackCode::Busy), "no take-over");
    let mut lapsed_at = None;
    for k in 0..3000 {
        if k % 300 == 0 {
            assert!(matches!(
                rig.reply(&Request::GetFaults),
                Reply::Faults { .. }
            ));
            // Answered, but it keeps nothing alive.
            let _ = rig.ack(&Request::Heartbeat { session: 77 });
        }
        if !rig.step().enable && lapsed_at.is_none() {
            lapsed_at = Some(rig.now_us);
        }
    }
    assert!(rig.latched().contains(FaultFlags::COMMS_TIMEOUT));
    let after_us = lapsed_at.expect("the release lapsed") - owner_gone;
    assert!((500_000..=502_000).contains(&after_us), "{after_us} us");
    assert_ne!(rig.state(), SupervisorState::Vibrating);
    // Any session may lock, and after the lapse (faults cleared) the stranger may release.
    assert_eq!(
        rig.ack(&Request::Release {
            on: false,
            target_hz: 0.0,
            session: 77
        }),
        Ok(())
    );
}

#[test]
fn simulation_commands_are_refused_by_real_firmware() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    let load = Request::Simulation(SimCommand::SetLoad { tau_rot_nm: 1.0 });
    assert_eq!(rig.ack(&load), Err(NackCode::SimulationOnly));
    // A simulator serves them through `receive_with`, in order with the other replies.
    let mut buf = [0u8; MAX_FRAME_SIZE];
    let frame = encode_frame(70, &load, &mut buf).unwrap().to_vec();
    let mut seen = Vec::new();
    rig.core.receive_with(rig.now_us, &frame, |c| {
        seen.push(c);
        Ok(())
    });
    rig.pump();
    assert_eq!(seen, [SimCommand::SetLoad { tau_rot_nm: 1.0 }]);
    assert_eq!(rig.received.last(), Some(&DeviceMessage::ack(70)));
}

#[test]
fn a_v1_host_gets_v1s_refusal() {
    let mut rig = Rig::new(0.0);
    let hello = Request::Hello {
        protocol_version: 1,
        schema_hash: 0xDEAD_BEEF,
    };
    let mut buf = [0u8; MAX_FRAME_SIZE];
    let frame = encode_frame(301, &hello, &mut buf).unwrap().to_vec();
    rig.core.receive(0, &frame);
    let mut out = [0u8; 64];
    let n = rig.core.transmit(&mut out);
    // Not a v2 message: the v1 layout of `Nack { seq: 301, VersionMismatch }`, which
    // identifies the device to a v1 tool (and to this one) as protocol 1.
    let mut bytes = out[..n].to_vec();
    assert!(protocol::decode_frame::<DeviceMessage>(&mut bytes.clone()).is_err());
    let body = protocol::frame_body(&mut bytes).unwrap();
    let peer = protocol::identify_peer(body).unwrap();
    assert_eq!(peer.protocol_version, 1);
    // Refused: it does not refresh the heartbeat.
    assert_eq!(rig.core.status().deframer.frames_ok, 1);
}

#[test]
fn info_reports_build_reset_uptime_and_capabilities() {
    let boot = crate::BootInfo {
        reset_cause: ResetCause::Pin,
        firmware_build: "0123456789abcdef0123-dirty",
        ..crate::BootInfo::default()
    };
    let config = crate::CoreConfig {
        capabilities: protocol::Capabilities::SIMULATION,
        ..crate::CoreConfig::default()
    };
    let mut rig = super::Rig::with_config(config, boot, 0.0, |_| {});
    rig.run_ms(2500);
    let Reply::Info(info) = rig.reply(&Request::GetInfo) else {
        panic!("GetInfo answered otherwise");
    };
    // Cut to the wire's 20 bytes.
    assert_eq!(info.firmware_build, "0123456789abcdef0123");
    assert_eq!(info.reset_cause, ResetCause::Pin);
    assert_eq!(info.uptime_s, 2);
    assert_eq!(info.capabilities, protocol::Capabilities::SIMULATION);
    assert_eq!(info.firmware_version, crate::FIRMWARE_VERSION);
}

#[test]
fn health_comes_once_a_second_while_telemetry_runs() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.ack(&Request::StartTelemetry { rate_hz: 1000 }).unwrap();
    // Some noise for the link counters.
    rig.core.receive(rig.now_us, &[0x12, 0x34, 0x00]);
    for k in 0..3000u32 {
        rig.step();
        rig.core.record_step_cycles(20_000 + k % 2 * 1000);
    }
    let health: Vec<_> = rig
        .received
        .iter()
        .filter_map(|m| match m {
            DeviceMessage::Health(h) => Some(*h),
            _ => None,
        })
        .collect();
    // At the start, then every second.
    assert_eq!(health.len(), 3, "{health:?}");
    assert_eq!(
        health[1].device_time_us - health[0].device_time_us,
        1_000_000
    );
    let h = health[2];
    assert!(h.bus_voltage_v.is_nan() && h.motor_temp_c.is_nan());
    assert_eq!((h.step_cycles_mean, h.step_cycles_max), (20_500, 21_000));
    assert_eq!(h.rx_frame_errors, 1);
    assert_eq!(h.tx_frames_dropped, 0);
    // The telemetry has no output encoder to read.
    let t = rig
        .received
        .iter()
        .rev()
        .find_map(|m| match m {
            DeviceMessage::Telemetry(t) => Some(*t),
            _ => None,
        })
        .unwrap();
    assert!(t.output_angle_rad.is_nan() && t.output_speed_rad_s.is_nan());
    rig.ack(&Request::StopTelemetry).unwrap();
    let before = rig.received.len();
    rig.run_ms(1500);
    assert!(
        !rig.received[before..]
            .iter()
            .any(|m| matches!(m, DeviceMessage::Health(_)))
    );
}

#[test]
fn measured_bus_voltage_sets_the_open_loop_duty_and_is_reported() {
    let config = crate::CoreConfig {
        capabilities: protocol::Capabilities::BUS_VOLTAGE | protocol::Capabilities::MOTOR_TEMP,
        ..crate::CoreConfig::default()
    };
    let mut rig = Rig::with_config(config, crate::BootInfo::default(), 0.0, |_| {});
    rig.core.set_board_inputs(crate::BoardInputs {
        bus_voltage_v: 10.0,
        motor_temp_c: 31.5,
        ..Default::default()
    });
    rig.run_ms(1200);
    assert_eq!(
        rig.ack(&Request::OpenLoop {
            volts: 6.2,
            session: 0
        }),
        Ok(())
    );
    rig.run_ms_alive(2500);
    // duty = volts / Vbus: 0.62 on a 10 V bus, not 6.2 / 12.
    let s = rig.core.status();
    assert!((s.duty - 0.62).abs() < 1e-3, "{}", s.duty);
    assert_eq!(rig.ack(&Request::StartTelemetry { rate_hz: 10 }), Ok(()));
    rig.run_ms_alive(20);
    let health = rig
        .received
        .iter()
        .find_map(|m| match m {
            DeviceMessage::Health(h) => Some(*h),
            _ => None,
        })
        .expect("a health sample");
    assert_eq!((health.bus_voltage_v, health.motor_temp_c), (10.0, 31.5));
}

#[test]
fn a_thousand_requests_in_windows_get_a_thousand_replies_under_telemetry_and_capture() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.ack(&Request::StartTelemetry { rate_hz: 1000 }).unwrap();
    // A 921 600 Bd link: ~92 bytes per ms leave the device.
    rig.link_budget = Some(92);
    // 0.2 s of recording, then its upload shares the link with the requests.
    let capture = rig.send(&Request::StartCapture {
        sample_rate_hz: 10_000,
        samples: 2_000,
    });
    // Its reply counts in the window until it arrives.
    while !rig.received.iter().any(|m| m.reply_to() == Some(capture)) {
        rig.step();
    }
    let mut outstanding: std::collections::VecDeque<(u16, bool)> = Default::default();
    let (mut sent, mut right, mut seen) = (0, 0, rig.received.len());
    let mut chunks = 0;
    let mut ms = 0;
    while right < 1000 {
        while sent < 1000 && outstanding.len() < protocol::REQUEST_WINDOW {
            let info = sent % 2 == 1;
            let req = if info {
                Request::GetInfo
            } else {
                Request::GetFaults
            };
            outstanding.push_back((rig.send(&req), info));
            sent += 1;
        }
        rig.step();
        ms += 1;
        for m in &rig.received[seen..] {
            if matches!(m, DeviceMessage::CaptureChunk(_)) {
                chunks += 1;
            }
            if let Some((seq, reply)) = m.clone().into_reply()
                && let Some(k) = outstanding.iter().position(|(s, _)| *s == seq)
            {
                let (_, info) = outstanding.remove(k).unwrap();
                match (reply, info) {
                    (Reply::Info(_), true) | (Reply::Faults { .. }, false) => right += 1,
                    (other, _) => panic!("request {seq}: {other:?}"),
                }
            }
        }
        seen = rig.received.len();
        assert!(ms < 20_000, "{right} of 1000 answered after {ms} ms");
    }
    assert_eq!(right, 1000);
    assert!(chunks > 0, "the capture uploaded meanwhile");
    let telemetry = rig.count(|m| matches!(m, DeviceMessage::Telemetry(_)));
    assert!(telemetry > 100, "{telemetry}");
}

#[test]
fn requests_beyond_the_window_are_refused_busy_and_have_no_effect() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    // Nothing drains until the next step: requests pile up.
    rig.link_budget = Some(92);
    let w = protocol::REQUEST_WINDOW;
    let first: Vec<u16> = (0..w).map(|_| rig.send(&Request::GetFaults)).collect();
    let beyond = rig.send(&Request::StartTelemetry { rate_hz: 100 });
    rig.run_ms(20);
    let reply_to = |rig: &Rig, seq: u16| {
        rig.received
            .iter()
            .filter(|m| m.reply_to() == Some(seq))
            .filter_map(DeviceMessage::as_reply)
            .cloned()
            .collect::<Vec<_>>()
    };
    for seq in first {
        assert!(matches!(reply_to(&rig, seq)[..], [Reply::Faults { .. }]));
    }
    assert_eq!(reply_to(&rig, beyond), [Reply::Nack(NackCode::Busy)]);
    // Refused: no telemetry started.
    assert_eq!(rig.count(|m| matches!(m, DeviceMessage::Telemetry(_))), 0);
    // With the replies sent, the window is open again.
    rig.link_budget = None;
    assert_eq!(rig.ack(&Request::Heartbeat { session: 0 }), Ok(()));
}

#[test]
fn a_known_request_with_a_bad_field_is_a_bad_argument() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    /// A message written as raw postcard bytes (a tuple of `u8`s has no length prefix).
    struct RawBody<'a>(&'a [u8]);
    impl serde::Serialize for RawBody<'_> {
        fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            use serde::ser::SerializeTuple;
            let mut t = s.serialize_tuple(self.0.len())?;
            for b in self.0 {
                t.serialize_element(b)?;
            }
            t.end()
        }
    }
    let send_body = |rig: &mut Rig, seq: u16, body: &[u8]| {
        let mut buf = [0u8; MAX_FRAME_SIZE];
        let frame = protocol::encode_frame(seq, &RawBody(body), &mut buf).unwrap();
        let before = rig.received.len();
        rig.core.receive(rig.now_us, frame);
        rig.pump();
        rig.received[before..]
            .iter()
            .filter(|m| m.reply_to() == Some(seq))
            .filter_map(DeviceMessage::as_reply)
            .cloned()
            .collect::<Vec<_>>()
    };
    // `Release { on: 2, .. }`: the request is known, its bool is not.
    assert_eq!(
        send_body(&mut rig, 40, &[2, 2, 0, 0, 0x20, 0x41]),
        [Reply::Nack(NackCode::BadArgument)]
    );
    // A trailing byte after a `Heartbeat`.
    assert_eq!(
        send_body(&mut rig, 41, &[3, 0x01, 0x55]),
        [Reply::Nack(NackCode::BadArgument)]
    );
    // An unknown request and an unknown simulation command.
    assert_eq!(
        send_body(&mut rig, 42, &[200, 1]),
        [Reply::Nack(NackCode::UnknownMessage)]
    );
    assert_eq!(
        send_body(&mut rig, 43, &[13, 9]),
        [Reply::Nack(NackCode::UnknownMessage)]
    );
}

#[test]
fn info_reports_the_time_scale() {
    let mut rig = Rig::new(0.0);
    let Reply::Info(info) = rig.reply(&Request::GetInfo) else {
        panic!("no Info");
    };
    assert_eq!(info.time_scale, 1.0, "a board runs in real time");
    let config = crate::CoreConfig {
        time_scale: 20.0,
        ..crate::CoreConfig::default()
    };
    let mut rig = Rig::with_config(config, crate::BootInfo::default(), 0.0, |_| {});
    let Reply::Info(info) = rig.reply(&Request::GetInfo) else {
        panic!("no Info");
    };
    assert_eq!(info.time_scale, 20.0);
}

#[test]
fn health_reports_nan_for_a_bus_voltage_the_board_does_not_declare() {
    let mut rig = Rig::new(0.0);
    // The default board declares its decay mode only (braking: the G2), no measured bus.
    assert!(
        !rig.core
            .config()
            .capabilities
            .contains(protocol::Capabilities::BUS_VOLTAGE)
    );
    assert_eq!(
        rig.core.config().capabilities,
        if model::hardware::board::DECAY.returns_power() {
            protocol::Capabilities::BRAKING_DECAY
        } else {
            protocol::Capabilities::empty()
        }
    );
    rig.core.set_board_inputs(crate::BoardInputs {
        bus_voltage_v: 12.0,
        motor_temp_c: 30.0,
        ..Default::default()
    });
    rig.run_ms(10);
    assert_eq!(rig.ack(&Request::StartTelemetry { rate_hz: 10 }), Ok(()));
    rig.run_ms(20);
    let health = rig
        .received
        .iter()
        .find_map(|m| match m {
            DeviceMessage::Health(h) => Some(*h),
            _ => None,
        })
        .expect("a health sample");
    assert!(health.bus_voltage_v.is_nan());
}
