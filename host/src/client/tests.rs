//! The client against scripted fake devices over an in-memory pipe.

use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::{AtomicU32, Ordering};
use std::thread;
use std::time::Duration;

use protocol::{
    CAPTURE_CHUNK_SAMPLES, Capabilities, CaptureChunk, CaptureSample, DeviceInfo, DeviceMessage,
    FaultFlags, FirmwareVersion, Frame, LegacyV1Nack, NackCode, PROTOCOL_VERSION, ParametersStatus,
    Reply, Request, RequestDeframer, ResetCause, SCHEMA_HASH,
};

use super::*;

fn device_info(protocol_version: u16, schema_hash: u32) -> DeviceInfo {
    DeviceInfo {
        firmware_version: FirmwareVersion {
            major: 0,
            minor: 1,
            patch: 0,
        },
        protocol_version,
        schema_hash,
        firmware_build: "1a2b3c4d5e6f".try_into().unwrap(),
        board: "fake".try_into().unwrap(),
        parameters_status: ParametersStatus::Defaults,
        reset_cause: ResetCause::PowerOn,
        uptime_s: 12,
        capabilities: Capabilities::empty(),
        time_scale: 1.0,
        max_baud: protocol::DEFAULT_BAUD_RATE,
    }
}

/// Runs a fake device on the far end of a pipe: `answer` maps each request (with its
/// sequence number) to the frames to send back, as `(frame seq, message)`.
fn fake_device(
    answer: impl FnMut(u16, Request) -> Vec<(u16, DeviceMessage)> + Send + 'static,
) -> Client<PipeEnd> {
    fake_device_of(answer)
}

/// As [`fake_device`], with messages of any layout (an older protocol's, for example).
fn fake_device_of<M: serde::Serialize + Send + 'static>(
    answer: impl FnMut(u16, Request) -> Vec<(u16, M)> + Send + 'static,
) -> Client<PipeEnd> {
    // A fake device answers at once, but a loaded machine may run its thread late: a
    // reply that is coming never times out.
    fake_device_timing_out(answer, ANSWERED)
}

/// As [`fake_device_of`], waiting `reply_timeout` for each reply (a test of silence).
fn fake_device_timing_out<M: serde::Serialize + Send + 'static>(
    mut answer: impl FnMut(u16, Request) -> Vec<(u16, M)> + Send + 'static,
    reply_timeout: Duration,
) -> Client<PipeEnd> {
    let (host, mut dev) = memory_pipe(Duration::from_millis(2));
    thread::spawn(move || {
        let mut deframer = RequestDeframer::new();
        let mut buf = [0u8; 512];
        loop {
            let n = match dev.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
                Err(_) => return,
            };
            let mut requests = Vec::new();
            deframer.push(&buf[..n], |f| requests.push(f));
            for Frame { seq, msg } in requests.into_iter().flatten() {
                for (out_seq, reply) in answer(seq, msg) {
                    let frame = protocol::encode_frame_vec(out_seq, &reply).unwrap();
                    if dev.write_all(&frame).is_err() {
                        return;
                    }
                }
            }
        }
    });
    let mut opts = ClientOptions::new("test pipe");
    opts.reply_timeout = reply_timeout;
    Client::new(host, opts)
}

/// Reply timeout of the fake devices: only a fake device that stopped trips it.
const ANSWERED: Duration = Duration::from_secs(10);

/// Reply timeout of the tests whose fake device stays silent on purpose.
const TIMES_OUT: Duration = Duration::from_millis(50);

/// A well-behaved device: Info for hello, Ack for the rest.
fn good_answer(seq: u16, req: Request) -> Vec<(u16, DeviceMessage)> {
    let reply = match req {
        Request::Hello { .. } | Request::GetInfo => {
            Reply::Info(device_info(PROTOCOL_VERSION, SCHEMA_HASH))
        }
        Request::GetFaults => Reply::Faults {
            active: FaultFlags::empty(),
            latched: FaultFlags::COMMS_TIMEOUT,
        },
        Request::GetParameters => Reply::Parameters(protocol::RigParameters::paper()),
        _ => Reply::Ack,
    };
    vec![(seq, DeviceMessage::reply(seq, reply))]
}

/// An `Info` reply to request `seq` from a device of `version` and `hash`.
fn info_reply(seq: u16, version: u16, hash: u32) -> Vec<(u16, DeviceMessage)> {
    vec![(
        seq,
        DeviceMessage::reply(seq, Reply::Info(device_info(version, hash))),
    )]
}

#[test]
fn hello_and_requests_are_matched_by_seq() {
    let mut c = fake_device(good_answer);
    let info = c.hello().unwrap();
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    let f = c.faults().unwrap();
    assert_eq!(f.latched, FaultFlags::COMMS_TIMEOUT);
    assert_eq!(c.calibration().unwrap(), protocol::RigParameters::paper());
    c.release(true, 10.0).unwrap();
    assert!(c.keeping_alive());
    c.release(false, 0.0).unwrap();
    assert!(!c.keeping_alive());
    assert_eq!(c.stats().retries, 0);
}

#[test]
fn newer_device_says_update_the_host() {
    let mut c = fake_device(|seq, _| info_reply(seq, PROTOCOL_VERSION + 1, 7));
    let e = c.hello().unwrap_err().to_string();
    assert!(
        e.contains(&format!("protocol {}", PROTOCOL_VERSION + 1)),
        "{e}"
    );
    assert!(e.contains("update the rig tool"), "{e}");
}

#[test]
fn older_device_says_flash_the_firmware() {
    let mut c = fake_device(|seq, _| info_reply(seq, PROTOCOL_VERSION - 1, 7));
    let e = c.hello().unwrap_err().to_string();
    assert!(e.contains("run `rig flash` to update the firmware"), "{e}");
}

#[test]
fn same_version_other_schema_is_refused() {
    let mut c = fake_device(|seq, _| info_reply(seq, PROTOCOL_VERSION, SCHEMA_HASH ^ 1));
    let e = c.hello().unwrap_err().to_string();
    assert!(e.contains("schema"), "{e}");
}

#[test]
fn version_nack_is_explained() {
    // A newer device refuses this tool's hello, naming its own version.
    let mut c = fake_device(|seq, _| {
        let code = NackCode::VersionMismatch {
            device_protocol: PROTOCOL_VERSION + 3,
            device_schema_hash: 1,
        };
        vec![(seq, DeviceMessage::nack(seq, code))]
    });
    let e = c.hello().unwrap_err().to_string();
    assert!(e.contains("update the rig tool"), "{e}");
    assert_eq!(c.stats().retries, 0);
}

#[test]
fn a_v1_device_says_flash_the_firmware() {
    // Protocol v1 firmware answers a v2 hello with v1's own refusal layout (the only one
    // it has), which this tool cannot decode but recognises.
    let mut c = fake_device_of(|seq, req| match req {
        Request::Hello { .. } => vec![(900, LegacyV1Nack { hello_seq: seq })],
        _ => vec![],
    });
    let e = c.hello().unwrap_err().to_string();
    assert_eq!(
        e,
        format!(
            "the firmware speaks protocol 1, this rig tool speaks {PROTOCOL_VERSION}: run `rig flash` to update the firmware"
        )
    );
    // Recognised at once: not retried, not timed out.
    assert_eq!(c.stats().retries, 0);
}

#[test]
fn lost_replies_are_retried_for_idempotent_requests_only() {
    let calls = Arc::new(AtomicU32::new(0));
    let seen = Arc::clone(&calls);
    // Each try waits 1 s: the unanswered one times out, the answered one (on a loaded
    // machine, late) does not.
    let mut c = fake_device_timing_out(
        move |seq, req| {
            // The first try of every request goes unanswered.
            if seen.fetch_add(1, Ordering::SeqCst).is_multiple_of(2) {
                return vec![];
            }
            good_answer(seq, req)
        },
        Duration::from_secs(1),
    );
    c.info().unwrap();
    assert_eq!(c.stats().retries, 1);
    calls.store(0, Ordering::SeqCst);
    let e = c
        .ack(&Request::StartCapture {
            sample_rate_hz: 10_000,
            samples: 10,
        })
        .unwrap_err();
    assert!(matches!(e, RigError::NoReply { tries: 1, .. }), "{e}");
}

#[test]
fn silent_device_is_a_clear_error() {
    let mut c = fake_device_timing_out(|_, _| Vec::<(u16, DeviceMessage)>::new(), TIMES_OUT);
    let e = c.hello().unwrap_err().to_string();
    assert!(e.contains("no reply"), "{e}");
    assert!(e.contains("test pipe"), "{e}");
    assert!(e.contains("nothing came back"), "{e}");
}

#[test]
fn garbage_suggests_the_baud_rate() {
    let (host, mut dev) = memory_pipe(Duration::from_millis(2));
    thread::spawn(move || {
        let mut buf = [0u8; 64];
        loop {
            match dev.read(&mut buf) {
                // What a device at another baud rate looks like: bytes, but never a frame.
                Ok(_) => {
                    if dev
                        .write_all(&[0x55, 0x13, 0xF0, 0x00, 0x7E, 0x00])
                        .is_err()
                    {
                        return;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => continue,
                Err(_) => return,
            }
        }
    });
    let mut opts = ClientOptions::new("test pipe");
    opts.reply_timeout = Duration::from_millis(30);
    let mut c = Client::new(host, opts);
    let e = c.hello().unwrap_err().to_string();
    assert!(e.contains("--baud"), "{e}");
}

#[test]
fn nack_names_the_request_and_the_fix() {
    let mut c = fake_device(|seq, _| vec![(seq, DeviceMessage::nack(seq, NackCode::InFaultHold))]);
    let e = c.release(true, 10.0).unwrap_err().to_string();
    assert!(e.contains("Release(on)"), "{e}");
    assert!(e.contains("rig clear"), "{e}");
    assert!(!c.keeping_alive());
}

#[test]
fn a_fault_hold_refusal_names_the_latched_faults() {
    let mut c = fake_device(|seq, req| {
        let reply = match req {
            Request::GetFaults => Reply::Faults {
                active: FaultFlags::empty(),
                latched: FaultFlags::OVERCURRENT,
            },
            _ => return vec![(seq, DeviceMessage::nack(seq, NackCode::InFaultHold))],
        };
        vec![(seq, DeviceMessage::reply(seq, reply))]
    });
    let e = c.release(false, 0.0).unwrap_err().to_string();
    assert!(
        e.contains("Release(off)") && e.contains("OVERCURRENT"),
        "{e}"
    );
    assert!(e.contains("rig clear"), "{e}");
}

#[test]
fn stale_and_unsolicited_frames_do_not_answer_requests() {
    let mut c = fake_device(|seq, req| {
        let mut out = vec![
            // A late answer to an older request, and a telemetry sample in between.
            (seq.wrapping_sub(1), DeviceMessage::ack(seq.wrapping_sub(1))),
            (
                900,
                DeviceMessage::FaultEvent {
                    flags: FaultFlags::STALL,
                    device_time_us: 5,
                },
            ),
        ];
        out.extend(good_answer(seq, req));
        out
    });
    c.heartbeat().unwrap();
    c.info().unwrap();
    assert!(c.stats().stale_replies >= 2);
    assert_eq!(c.take_fault_events(), vec![(FaultFlags::STALL, 5); 2]);
}

#[test]
fn heartbeats_keep_a_release_alive_while_waiting() {
    // The fake device counts the heartbeats it reads before the lock, and those it reads
    // after a marker request the host sends once the lock has returned. Requests reach it
    // in the order they were sent, so the counts do not race a reply in flight: a heartbeat
    // sent while the lock's reply was on its way is read before the marker, and only a
    // client that went on heartbeating after the lock is counted after it.
    let beats = Arc::new(AtomicU32::new(0));
    let after_marker = Arc::new(AtomicU32::new(0));
    let (counter, late) = (Arc::clone(&beats), Arc::clone(&after_marker));
    let (mut locked, mut marked) = (false, false);
    let mut c = fake_device(move |seq, req| {
        match req {
            Request::Heartbeat { .. } if marked => {
                late.fetch_add(1, Ordering::SeqCst);
            }
            Request::Heartbeat { .. } if !locked => {
                counter.fetch_add(1, Ordering::SeqCst);
            }
            Request::Release { on: false, .. } => locked = true,
            Request::GetFaults if locked => marked = true,
            _ => {}
        }
        good_answer(seq, req)
    });
    c.release(true, 10.0).unwrap();
    // 0.5 s of waiting at 10x speed: one heartbeat every 15 ms is due, about 33. The client
    // never sends more than are due; a loaded machine may starve it of a few, so only an
    // upper bound is tight.
    c.opts.time_scale = 10.0;
    let waited = std::time::Instant::now();
    // Waiting inside the client (it heartbeats meanwhile): 0.5 s, and on until the device
    // counted three heartbeats (a starved client sends them late, never fewer than due).
    while waited.elapsed() < Duration::from_millis(500) || beats.load(Ordering::SeqCst) < 3 {
        assert!(c.recv(Duration::from_millis(100)).unwrap().is_none());
        assert!(
            waited.elapsed() < ANSWERED,
            "{} heartbeats in {ANSWERED:?}",
            beats.load(Ordering::SeqCst)
        );
    }
    let due = waited.elapsed().as_secs_f64() / c.opts.heartbeat_interval().as_secs_f64();
    assert_eq!(c.stats().stale_replies, 0, "heartbeat acks are expected");
    c.release(false, 0.0).unwrap();
    // The lock's reply came back, so every heartbeat sent before the lock has been read.
    let n = beats.load(Ordering::SeqCst);
    assert!(
        n >= 3 && f64::from(n) <= due + 2.0,
        "{n} heartbeats, {due:.1} due"
    );
    c.faults().unwrap(); // the marker
    c.recv(Duration::from_millis(100)).unwrap();
    c.faults().unwrap(); // read after every request sent in the wait
    assert_eq!(
        after_marker.load(Ordering::SeqCst),
        0,
        "heartbeats after the lock"
    );
}

#[test]
fn a_drive_is_heartbeated_while_its_lost_ack_is_retried() {
    // The device drives as soon as it reads a release; its Ack is lost on the line. The
    // retry comes a reply timeout later (the device's own comms timeout, 500 ms), so the
    // client must heartbeat from the moment it sends the release, not from its Ack: the
    // device counts the heartbeats read between the first release and its retry. Requests
    // reach it in the order they were sent, so the count does not race the retry.
    let between = Arc::new(AtomicU32::new(0));
    let counter = Arc::clone(&between);
    let mut releases = 0;
    let mut c = fake_device_timing_out(
        move |seq, req| {
            match req {
                Request::Release { on: true, .. } => {
                    releases += 1;
                    if releases == 1 {
                        return Vec::new(); // the Ack lost
                    }
                }
                Request::Heartbeat { .. } if releases == 1 => {
                    counter.fetch_add(1, Ordering::SeqCst);
                }
                _ => {}
            }
            good_answer(seq, req)
        },
        Duration::from_millis(u64::from(protocol::COMMS_TIMEOUT_MS)),
    );
    c.release(true, 10.0).unwrap();
    assert!(c.keeping_alive());
    let n = between.load(Ordering::SeqCst);
    // 500 ms at one heartbeat every 150 ms: 3 due; a starved client sends at least one.
    assert!(n >= 1, "{n} heartbeats while the release's Ack was retried");
}

#[test]
fn telemetry_gaps_are_counted() {
    let mut c = fake_device(|seq, req| {
        let mut out = good_answer(seq, req.clone());
        if matches!(req, Request::StartTelemetry { .. }) {
            for s in [1u32, 2, 5, 6] {
                let t = protocol::TelemetrySample {
                    seq: s,
                    device_time_us: u64::from(s) * 1000,
                    cam_speed_rad_s: 0.0,
                    current_a: 0.0,
                    pwm_duty: 0.0,
                    tau_cam_nm: 0.0,
                    tau_rot_nm: 0.0,
                    state: protocol::SupervisorState::Locked,
                    faults: FaultFlags::empty(),
                    status: protocol::StatusFlags::empty(),
                    output_angle_rad: f32::NAN,
                    output_speed_rad_s: f32::NAN,
                };
                out.push((1000 + s as u16, DeviceMessage::Telemetry(t)));
            }
        }
        out
    });
    c.start_telemetry(100).unwrap();
    let mut got = Vec::new();
    // Up to the last sample sent (however late a loaded machine runs the fake device),
    // then nothing more.
    while got.last() != Some(&6) {
        match c.next_telemetry(ANSWERED).unwrap() {
            Some(t) => got.push(t.seq),
            None => panic!("the telemetry stopped after {got:?}"),
        }
    }
    assert!(c.next_telemetry(TIMES_OUT).unwrap().is_none());
    assert_eq!(got, vec![1, 2, 5, 6]);
    assert_eq!(c.stats().telemetry_lost, 2);
}

#[test]
fn capture_is_assembled_and_drops_reported() {
    let mut c = fake_device(|seq, req| {
        let mut out = good_answer(seq, req.clone());
        if let Request::StartCapture { samples, .. } = req {
            let chunk = |first: u32| {
                DeviceMessage::CaptureChunk(CaptureChunk {
                    capture_id: 9,
                    first_sample: first,
                    total_samples: samples,
                    samples: (first..first + CAPTURE_CHUNK_SAMPLES as u32)
                        .map(|i| CaptureSample {
                            current_adc: 2068 + 28,
                            encoder_count: i as i32,
                            output_count: Some(-(i as i32)),
                        })
                        .collect(),
                })
            };
            out.push((2, chunk(0)));
            // Chunk 10..20 is lost on the way.
            out.push((4, chunk(20)));
            out.push((
                5,
                DeviceMessage::CaptureDone {
                    capture_id: 9,
                    total_samples: samples,
                    sample_rate_hz: 10_000,
                },
            ));
        }
        out
    });
    let mut updates = 0;
    let cap = c.capture(10_000, 30, |_| updates += 1).unwrap();
    assert_eq!(updates, 2);
    assert!(cap.completed);
    assert_eq!(cap.samples.len(), 20);
    assert_eq!(cap.dropped, 10);
    assert_eq!(cap.gaps, 1);
    // 28 LSB of 6.5 mA above the zero: about 0.18 A.
    let i = cap.mean_current_a().unwrap();
    assert!((i - 0.18).abs() < 0.01, "{i}");
}

#[test]
fn broken_link_is_an_error_not_a_panic() {
    let (host, dev) = memory_pipe(Duration::from_millis(2));
    drop(dev);
    let mut c = Client::new(host, ClientOptions::new("test pipe"));
    let e = c.info().unwrap_err().to_string();
    assert!(e.contains("test pipe"), "{e}");
}

#[test]
fn a_drive_waits_for_the_current_zero_and_then_names_it() {
    // The device refuses the first three drives (its zero is being measured), then accepts.
    let refused = Arc::new(AtomicU32::new(0));
    let count = refused.clone();
    let mut c = fake_device(move |seq, req| match req {
        Request::Release { on: true, .. } | Request::OpenLoop { .. }
            if count.fetch_add(1, Ordering::SeqCst) < 3 =>
        {
            let nack = Reply::Nack(NackCode::CurrentZeroPending);
            vec![(seq, DeviceMessage::reply(seq, nack))]
        }
        other => good_answer(seq, other),
    });
    c.release(true, 10.0).unwrap();
    assert_eq!(
        refused.load(Ordering::SeqCst),
        4,
        "asked again until accepted"
    );
    assert!(c.keeping_alive());
    c.release(false, 0.0).unwrap();

    // A zero that never ends: the refusal stands after the wait, with its reason.
    let mut c = fake_device(|seq, req| match req {
        Request::OpenLoop { volts, .. } if volts != 0.0 => {
            let nack = Reply::Nack(NackCode::CurrentZeroPending);
            vec![(seq, DeviceMessage::reply(seq, nack))]
        }
        other => good_answer(seq, other),
    });
    // A virtual rig served 100x faster: 1 s of device time is 10 ms here.
    c.opts.time_scale = 100.0;
    let e = c.open_loop(3.0).unwrap_err();
    assert_eq!(e.refusal(), Some(NackCode::CurrentZeroPending));
    assert!(!c.keeping_alive(), "a refused drive is not heartbeated");
    let text = e.to_string();
    assert!(
        text.contains("zero") && text.contains("rig faults"),
        "{text}"
    );
    assert!(!c.keeping_alive(), "a refused drive keeps nothing alive");
}
