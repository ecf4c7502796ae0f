//! The device-contract conformance suite (`rig conformance --port PORT`): checks, over the
//! wire alone, what `protocol/LAYOUT.md` promises of any device (a board, the served
//! virtual rig, another implementation): handshake and version refusal, refusal codes for
//! out-of-range and malformed requests, values used exactly or refused, one reply per
//! request within the request window under 1 kHz telemetry and a capture, `Busy` beyond
//! it, hostile frames and noise, and, when motion is allowed, the heartbeat timeout in
//! wall time, fault latch, hold and clear, with the safe state after each.
//!
//! It talks through its own minimal client ([`RawLink`]: frames, sequence numbers, nothing
//! else), not the host session, so it sees exactly what the device sends and can send what
//! a well-behaved host never would. Checks that can move a load (a release) run only when
//! the device is a simulation or the caller allows motion (`RIG_ALLOW_MOTION=1`).

use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use protocol::{
    DeviceDeframer, DeviceInfo, DeviceMessage, FaultFlags, NackCode, PROTOCOL_VERSION,
    REQUEST_WINDOW, Reply, Request, SCHEMA_HASH, SupervisorState, TelemetrySample,
};
use serde::Serialize;

use crate::RigError;

/// One check's result.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    /// The check's name (stable: scripts key on it).
    pub name: &'static str,
    /// `pass`, `fail` or `skip`.
    pub status: &'static str,
    /// What was seen, with the numbers.
    pub detail: String,
}

/// What `rig conformance --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The port.
    pub port: String,
    /// The device's protocol version (null when the handshake failed).
    pub protocol_version: Option<u16>,
    /// The device's board name.
    pub board: Option<String>,
    /// Device seconds per wall-clock second, as the device reported it.
    pub time_scale: Option<f64>,
    /// Whether checks that vibrate the carrier ran.
    pub motion: bool,
    /// Every check passed (skipped ones aside).
    pub passed: bool,
    /// Each check, in the order run.
    pub checks: Vec<Check>,
}

/// How the suite runs.
#[derive(Debug, Clone)]
pub struct Options {
    /// The port's name, for the report.
    pub port: String,
    /// Run the checks that vibrate the carrier on a device that is not a simulation.
    pub allow_motion: bool,
    /// Requests sent in the window check.
    pub window_requests: usize,
}

/// A bare client: numbered frames out, device messages in, replies matched by seq.
pub struct RawLink<T: Read + Write> {
    io: T,
    deframer: DeviceDeframer,
    next_seq: u16,
    replies: HashMap<u16, Reply>,
    /// Unsolicited messages with their wall-clock arrival.
    unsolicited: VecDeque<(Instant, DeviceMessage)>,
    buf: Vec<u8>,
    /// Device frames that failed to decode (should stay 0 on a clean line).
    pub desyncs: u32,
}

/// A postcard body written as raw bytes (a tuple of `u8`s has no length prefix).
struct RawBody<'a>(&'a [u8]);

impl Serialize for RawBody<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(self.0.len())?;
        for b in self.0 {
            t.serialize_element(b)?;
        }
        t.end()
    }
}

impl<T: Read + Write> RawLink<T> {
    /// A link over `io`; writes the opening delimiter.
    pub fn new(mut io: T) -> Result<Self, RigError> {
        io.write_all(&[protocol::FRAME_DELIMITER])?;
        Ok(Self {
            io,
            deframer: DeviceDeframer::new(),
            next_seq: 0x4000,
            replies: HashMap::new(),
            unsolicited: VecDeque::new(),
            buf: vec![0; 4096],
            desyncs: 0,
        })
    }

    fn take_seq(&mut self) -> u16 {
        let s = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        s
    }

    /// Writes raw bytes.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), RigError> {
        self.io.write_all(bytes)?;
        self.io.flush()?;
        Ok(())
    }

    /// The frame of `req` under a new seq (not written).
    pub fn frame(&mut self, req: &Request) -> (u16, Vec<u8>) {
        let seq = self.take_seq();
        (
            seq,
            protocol::encode_frame_vec(seq, req).unwrap_or_default(),
        )
    }

    /// Sends `req`; returns its seq.
    pub fn send(&mut self, req: &Request) -> Result<u16, RigError> {
        let (seq, bytes) = self.frame(req);
        self.write(&bytes)?;
        Ok(seq)
    }

    /// Sends a frame whose message is the raw postcard bytes `message`; returns its seq.
    pub fn send_body(&mut self, message: &[u8]) -> Result<u16, RigError> {
        let seq = self.take_seq();
        let bytes = protocol::encode_frame_vec(seq, &RawBody(message)).unwrap_or_default();
        self.write(&bytes)?;
        Ok(seq)
    }

    /// Reads what arrives for up to `wait`.
    pub fn pump(&mut self, wait: Duration) -> Result<(), RigError> {
        let end = Instant::now() + wait;
        loop {
            match self.io.read(&mut self.buf) {
                Ok(n) if n > 0 => {
                    let now = Instant::now();
                    for &b in &self.buf[..n] {
                        match self.deframer.push_byte(b) {
                            Some(Ok(frame)) => match frame.msg {
                                DeviceMessage::Reply { request_seq, reply } => {
                                    self.replies.insert(request_seq, reply);
                                }
                                other => {
                                    if self.unsolicited.len() > 1 << 16 {
                                        self.unsolicited.pop_front();
                                    }
                                    self.unsolicited.push_back((now, other));
                                }
                            },
                            Some(Err(_)) => self.desyncs += 1,
                            None => {}
                        }
                    }
                }
                Ok(_) => {}
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock
                    ) => {}
                Err(e) => return Err(e.into()),
            }
            if Instant::now() >= end {
                return Ok(());
            }
        }
    }

    /// The reply to `seq`, waiting up to `timeout`.
    pub fn reply(&mut self, seq: u16, timeout: Duration) -> Result<Option<Reply>, RigError> {
        let end = Instant::now() + timeout;
        loop {
            if let Some(r) = self.replies.remove(&seq) {
                return Ok(Some(r));
            }
            if Instant::now() >= end {
                return Ok(None);
            }
            self.pump(Duration::from_millis(1))?;
        }
    }

    /// Sends `req` and waits up to `timeout` for its reply.
    pub fn request(&mut self, req: &Request, timeout: Duration) -> Result<Option<Reply>, RigError> {
        let seq = self.send(req)?;
        self.reply(seq, timeout)
    }

    /// Takes the unsolicited messages received so far.
    pub fn take_unsolicited(&mut self) -> Vec<(Instant, DeviceMessage)> {
        self.unsolicited.drain(..).collect()
    }

    /// Forgets replies nobody asked for yet.
    pub fn clear_replies(&mut self) {
        self.replies.clear();
    }
}

/// The suite's state while it runs.
struct Suite<T: Read + Write> {
    link: RawLink<T>,
    checks: Vec<Check>,
    /// Wall time of a reply, generous: device time scaled, plus the link.
    reply_wait: Duration,
    scale: f64,
}

fn describe(r: &Option<Reply>) -> String {
    match r {
        None => "no reply".into(),
        Some(Reply::Nack(code)) => format!("Nack({})", code.name()),
        Some(other) => other.name().into(),
    }
}

impl<T: Read + Write> Suite<T> {
    fn record(&mut self, name: &'static str, ok: bool, detail: String) {
        self.checks.push(Check {
            name,
            status: if ok { "pass" } else { "fail" },
            detail,
        });
    }

    fn skip(&mut self, name: &'static str, why: &str) {
        self.checks.push(Check {
            name,
            status: "skip",
            detail: why.into(),
        });
    }

    /// Wall time for `device_s` of device time.
    fn wall(&self, device_s: f64) -> Duration {
        crate::limits::wall_duration(device_s, self.scale)
    }

    fn request(&mut self, req: &Request) -> Result<Option<Reply>, RigError> {
        let wait = self.reply_wait;
        self.link.request(req, wait)
    }

    /// Each request must be refused with `code`; an accepted release is undone at once.
    fn expect_refusals(
        &mut self,
        name: &'static str,
        cases: &[(Request, NackCode)],
    ) -> Result<(), RigError> {
        let mut bad = Vec::new();
        for (req, code) in cases {
            let got = self.request(req)?;
            if got != Some(Reply::Nack(*code)) {
                bad.push(format!(
                    "{req:?}: {} (want Nack({}))",
                    describe(&got),
                    code.name()
                ));
                if matches!(
                    req,
                    Request::Release { on: true, .. } | Request::OpenLoop { .. }
                ) {
                    self.request(&Request::Release {
                        on: false,
                        target_hz: 0.0,
                        session: 0,
                    })?;
                }
            }
        }
        let ok = bad.is_empty();
        let detail = if ok {
            format!("{} requests refused with the documented code", cases.len())
        } else {
            bad.join("; ")
        };
        self.record(name, ok, detail);
        Ok(())
    }

    /// A telemetry sample, waiting up to `device_s` of device time.
    fn telemetry(&mut self, device_s: f64) -> Result<Option<(Instant, TelemetrySample)>, RigError> {
        let end = Instant::now() + self.wall(device_s) + Duration::from_millis(200);
        loop {
            let got = self.link.take_unsolicited();
            if let Some((at, t)) = got.into_iter().rev().find_map(|(at, m)| match m {
                DeviceMessage::Telemetry(t) => Some((at, t)),
                _ => None,
            }) {
                return Ok(Some((at, t)));
            }
            if Instant::now() >= end {
                return Ok(None);
            }
            self.link.pump(Duration::from_millis(2))?;
        }
    }

    /// The device is in its safe state: locked (or faulted), motor off.
    fn safe_state(&mut self, name: &'static str) -> Result<(), RigError> {
        let _ = self.request(&Request::StartTelemetry { rate_hz: 100 })?;
        // Let the cam stop (the supervisor brakes it) before judging.
        let end = Instant::now() + self.wall(3.0) + Duration::from_millis(500);
        let mut last = None;
        while Instant::now() < end {
            if let Some((_, t)) = self.telemetry(0.1)? {
                let safe = matches!(t.state, SupervisorState::Locked | SupervisorState::Fault)
                    && t.pwm_duty == 0.0;
                last = Some(t);
                if safe {
                    break;
                }
            }
        }
        let _ = self.request(&Request::StopTelemetry)?;
        match last {
            Some(t) => {
                let ok = matches!(t.state, SupervisorState::Locked | SupervisorState::Fault)
                    && t.pwm_duty == 0.0;
                self.record(
                    name,
                    ok,
                    format!("state {}, duty {}", t.state.name(), t.pwm_duty),
                );
            }
            None => self.record(name, false, "no telemetry".into()),
        }
        Ok(())
    }
}

/// Runs the suite over `io` (an open port to the device).
pub fn run<T: Read + Write>(io: T, opts: &Options) -> Result<Report, RigError> {
    let mut s = Suite {
        link: RawLink::new(io)?,
        checks: Vec::new(),
        reply_wait: Duration::from_secs(1),
        scale: 1.0,
    };
    let hello = Request::Hello {
        protocol_version: PROTOCOL_VERSION,
        schema_hash: SCHEMA_HASH,
    };
    let info: Option<DeviceInfo> = match s.request(&hello)? {
        Some(Reply::Info(info)) => Some(info),
        other => {
            s.record(
                "handshake",
                false,
                format!(
                    "Hello (protocol {PROTOCOL_VERSION}) got {}: {}",
                    describe(&other),
                    match other {
                        Some(Reply::Nack(NackCode::VersionMismatch {
                            device_protocol,
                            device_schema_hash,
                        })) => protocol::check_peer(device_protocol, Some(device_schema_hash))
                            .err()
                            .map_or_else(String::new, |e| e.to_string()),
                        _ => "check the port, the baud rate and that the firmware runs".into(),
                    }
                ),
            );
            None
        }
    };
    let Some(info) = info else {
        return Ok(report(opts, None, s.checks, false));
    };
    let scale_ok = info.time_scale.is_finite() && info.time_scale > 0.0;
    s.scale = if scale_ok {
        f64::from(info.time_scale)
    } else {
        1.0
    };
    s.record(
        "handshake",
        info.protocol_version == PROTOCOL_VERSION && info.schema_hash == SCHEMA_HASH && scale_ok,
        format!(
            "protocol {}, schema {:#010x}, board {}, time scale {}",
            info.protocol_version, info.schema_hash, info.board, info.time_scale
        ),
    );
    let simulation = info
        .capabilities
        .contains(protocol::Capabilities::SIMULATION);
    let motion = simulation || opts.allow_motion;

    // Version refusal: a host of another version is told the device's.
    let got = s.request(&Request::Hello {
        protocol_version: PROTOCOL_VERSION + 100,
        schema_hash: SCHEMA_HASH,
    })?;
    let want = Reply::Nack(NackCode::VersionMismatch {
        device_protocol: PROTOCOL_VERSION,
        device_schema_hash: SCHEMA_HASH,
    });
    s.record(
        "version-refusal",
        got.as_ref() == Some(&want),
        format!(
            "Hello of protocol {} got {}",
            PROTOCOL_VERSION + 100,
            describe(&got)
        ),
    );

    // Start from no faults (a previous client may have left one).
    let _ = s.request(&Request::ClearFaults)?;
    s.link.pump(s.wall(0.6))?;
    let parameters = match s.request(&Request::GetParameters)? {
        Some(Reply::Parameters(p)) => Some(p),
        _ => None,
    };

    // Out-of-range values: refused, never replaced.
    let mut cases = vec![
        (
            Request::StartTelemetry { rate_hz: 0 },
            NackCode::BadArgument,
        ),
        (
            Request::StartTelemetry { rate_hz: 300 },
            NackCode::BadArgument,
        ),
        (
            Request::StartTelemetry { rate_hz: 1001 },
            NackCode::BadArgument,
        ),
        (
            Request::StartTelemetry { rate_hz: u16::MAX },
            NackCode::BadArgument,
        ),
        (
            Request::StartCapture {
                sample_rate_hz: 3000,
                samples: 100,
            },
            NackCode::BadArgument,
        ),
        (
            Request::StartCapture {
                sample_rate_hz: 10_000,
                samples: 0,
            },
            NackCode::BadArgument,
        ),
        (
            Request::StartCapture {
                sample_rate_hz: 10_000,
                samples: u32::MAX,
            },
            NackCode::BadArgument,
        ),
        (
            Request::OpenLoop {
                volts: f32::NAN,
                session: 0,
            },
            NackCode::BadArgument,
        ),
        (
            Request::OpenLoop {
                volts: 1e6,
                session: 0,
            },
            NackCode::BadArgument,
        ),
    ];
    if motion {
        cases.push((
            Request::Release {
                on: true,
                target_hz: f32::NAN,
                session: 0,
            },
            NackCode::BadArgument,
        ));
        cases.push((
            Request::Release {
                on: true,
                target_hz: 1e6,
                session: 0,
            },
            NackCode::BadArgument,
        ));
        if let Some(p) = parameters {
            cases.push((
                Request::Release {
                    on: true,
                    target_hz: p.max_freq_hz + 0.5,
                    session: 0,
                },
                NackCode::BadArgument,
            ));
        }
    }
    s.expect_refusals("out-of-range-refused", &cases)?;

    // Malformed requests with a good CRC.
    let mut bad = Vec::new();
    let malformed: [(&[u8], NackCode, &str); 4] = [
        (&[200], NackCode::UnknownMessage, "unknown request tag 200"),
        (
            &[13, 9],
            NackCode::UnknownMessage,
            "unknown simulation command 9",
        ),
        (
            &[2, 2, 0, 0, 0x20, 0x41],
            NackCode::BadArgument,
            "Release with a bool of 2",
        ),
        (
            &[3, 0x01, 0x55],
            NackCode::BadArgument,
            "Heartbeat with a trailing byte",
        ),
    ];
    for (body, code, what) in malformed {
        let seq = s.link.send_body(body)?;
        let got = s.link.reply(seq, s.reply_wait)?;
        if got != Some(Reply::Nack(code)) {
            bad.push(format!(
                "{what}: {} (want Nack({}))",
                describe(&got),
                code.name()
            ));
        }
    }
    let ok = bad.is_empty();
    s.record(
        "malformed-refused",
        ok,
        if ok {
            "unknown requests get UnknownMessage, bad fields BadArgument".into()
        } else {
            bad.join("; ")
        },
    );

    hostile(&mut s)?;
    exact_values(&mut s)?;
    window_under_load(&mut s, opts.window_requests)?;
    busy_beyond_window(&mut s)?;
    s.safe_state("safe-state-after-load")?;
    if motion {
        if simulation {
            // The motion checks' precondition, an unloaded output (a load left falling by
            // an earlier client would latch OUTPUT_OVERSPEED in them): a virtual rig's
            // operator unhooks it; a real rig's operator was asked to (RIG_ALLOW_MOTION).
            let _ = s.request(&Request::Simulation(protocol::SimCommand::SetLoad {
                tau_rot_nm: 0.0,
            }))?;
        }
        let hz = parameters.map_or(10.0, |p| p.max_freq_hz.min(10.0));
        release_before_zero(&mut s, hz)?;
        heartbeat_and_faults(&mut s, hz)?;
    } else {
        for name in [
            "release-before-zero",
            "heartbeat-timeout",
            "release-owner",
            "fault-latch-hold-clear",
            "safe-state-after-faults",
        ] {
            s.skip(
                name,
                "vibrates the carrier: set RIG_ALLOW_MOTION=1 with the rig unloaded and clear",
            );
        }
    }
    let desyncs = s.link.desyncs;
    s.record(
        "device-frames-decode",
        desyncs == 0,
        format!("{desyncs} device frames failed to decode"),
    );
    Ok(report(opts, Some(&info), s.checks, motion))
}

fn report(opts: &Options, info: Option<&DeviceInfo>, checks: Vec<Check>, motion: bool) -> Report {
    Report {
        port: opts.port.clone(),
        protocol_version: info.map(|i| i.protocol_version),
        board: info.map(|i| i.board.to_string()),
        time_scale: info.map(|i| f64::from(i.time_scale)),
        motion,
        passed: !checks.is_empty() && checks.iter().all(|c| c.status != "fail"),
        checks,
    }
}

/// Noise, a corrupted frame and an overlong one: no reply to any, and the device answers
/// the next request.
fn hostile<T: Read + Write>(s: &mut Suite<T>) -> Result<(), RigError> {
    let mut rng = 0x9E37_79B9_7F4A_7C15u64;
    let mut noise = Vec::with_capacity(600);
    for _ in 0..600 {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        noise.push((rng >> 56) as u8);
    }
    s.link.write(&noise)?;
    // A GetInfo with one byte flipped: its CRC fails.
    let (corrupt_seq, mut frame) = s.link.frame(&Request::GetInfo);
    let mid = frame.len() / 2;
    frame[mid] ^= if frame[mid] == 0x01 { 0x03 } else { 0x01 };
    if frame[mid] == 0 {
        frame[mid] = 0x7F;
    }
    s.link.write(&frame)?;
    // A frame longer than any request.
    let mut long = vec![0x00];
    long.extend(std::iter::repeat_n(0x5Au8, 2000));
    long.push(0x00);
    s.link.write(&long)?;
    let got = s.request(&Request::GetFaults)?;
    let answered = matches!(got, Some(Reply::Faults { .. }));
    let phantom = s.link.reply(corrupt_seq, Duration::from_millis(50))?;
    s.record(
        "hostile-frames-and-noise",
        answered && phantom.is_none(),
        format!(
            "after 600 noise bytes, a corrupted frame and a 2000-byte frame: GetFaults got {}; the corrupted frame got {}",
            describe(&got),
            describe(&phantom)
        ),
    );
    Ok(())
}

/// Values the device accepts are used exactly: telemetry at 250 Hz comes every 4 ms of
/// device time; a capture at 2.5 kHz of 50 samples reports that rate and count.
fn exact_values<T: Read + Write>(s: &mut Suite<T>) -> Result<(), RigError> {
    let ack = s.request(&Request::StartTelemetry { rate_hz: 250 })?;
    let mut times = Vec::new();
    let end = Instant::now() + s.wall(0.2) + Duration::from_millis(500);
    while times.len() < 20 && Instant::now() < end {
        s.link.pump(Duration::from_millis(2))?;
        for (_, m) in s.link.take_unsolicited() {
            if let DeviceMessage::Telemetry(t) = m {
                times.push(t.device_time_us);
            }
        }
    }
    let _ = s.request(&Request::StopTelemetry)?;
    let steps: Vec<u64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    let ok = ack == Some(Reply::Ack) && steps.len() >= 5 && steps.iter().all(|&d| d == 4000);
    s.record(
        "telemetry-rate-exact",
        ok,
        format!(
            "StartTelemetry 250 got {}; sample spacing {:?} us (want 4000)",
            describe(&ack),
            steps.iter().take(8).collect::<Vec<_>>()
        ),
    );
    let ack = s.request(&Request::StartCapture {
        sample_rate_hz: 2500,
        samples: 50,
    })?;
    let mut done = None;
    let mut received = 0usize;
    let end = Instant::now() + s.wall(0.5) + Duration::from_secs(2);
    while done.is_none() && Instant::now() < end {
        s.link.pump(Duration::from_millis(2))?;
        for (_, m) in s.link.take_unsolicited() {
            match m {
                DeviceMessage::CaptureChunk(c) => received += c.samples.len(),
                DeviceMessage::CaptureDone {
                    total_samples,
                    sample_rate_hz,
                    ..
                } => done = Some((total_samples, sample_rate_hz)),
                _ => {}
            }
        }
    }
    s.record(
        "capture-values-exact",
        ack == Some(Reply::Ack) && done == Some((50, 2500)) && received == 50,
        format!(
            "StartCapture 2500 Hz x 50 got {}; CaptureDone {:?} (total, rate); {received} samples received",
            describe(&ack),
            done
        ),
    );
    Ok(())
}

/// `n` requests in windows of [`REQUEST_WINDOW`] with 1 kHz telemetry and a capture
/// running: every one answered, with its own kind of reply.
fn window_under_load<T: Read + Write>(s: &mut Suite<T>, n: usize) -> Result<(), RigError> {
    let tele = s.request(&Request::StartTelemetry { rate_hz: 1000 })?;
    let cap = s.request(&Request::StartCapture {
        sample_rate_hz: 10_000,
        samples: 10_000,
    })?;
    let mut outstanding: VecDeque<(u16, bool)> = VecDeque::new();
    let (mut sent, mut right, mut wrong, mut lost) = (0usize, 0usize, Vec::new(), 0usize);
    let (mut telemetry, mut chunks) = (0usize, 0usize);
    let mut last_reply = Instant::now();
    while right + wrong.len() + lost < n {
        while sent < n && outstanding.len() < REQUEST_WINDOW {
            let info = sent % 2 == 1;
            let req = if info {
                Request::GetInfo
            } else {
                Request::GetFaults
            };
            outstanding.push_back((s.link.send(&req)?, info));
            sent += 1;
        }
        s.link.pump(Duration::from_millis(1))?;
        for (_, m) in s.link.take_unsolicited() {
            match m {
                DeviceMessage::Telemetry(_) => telemetry += 1,
                DeviceMessage::CaptureChunk(_) => chunks += 1,
                _ => {}
            }
        }
        let mut k = 0;
        while k < outstanding.len() {
            let (seq, info) = outstanding[k];
            if let Some(r) = s.link.replies.remove(&seq) {
                outstanding.remove(k);
                last_reply = Instant::now();
                match (&r, info) {
                    (Reply::Info(_), true) | (Reply::Faults { .. }, false) => right += 1,
                    _ => wrong.push(format!("seq {seq}: {}", describe(&Some(r)))),
                }
            } else {
                k += 1;
            }
        }
        if last_reply.elapsed() > s.reply_wait {
            lost += outstanding.len();
            outstanding.clear();
            last_reply = Instant::now();
        }
    }
    let _ = s.request(&Request::StopTelemetry)?;
    // Let the capture finish uploading so later checks start clean.
    let end = Instant::now() + s.wall(1.2) + Duration::from_secs(3);
    let mut done = false;
    while !done && Instant::now() < end {
        s.link.pump(Duration::from_millis(2))?;
        for (_, m) in s.link.take_unsolicited() {
            match m {
                DeviceMessage::CaptureChunk(_) => chunks += 1,
                DeviceMessage::CaptureDone { .. } => done = true,
                _ => {}
            }
        }
    }
    s.record(
        "one-reply-per-request-under-load",
        tele == Some(Reply::Ack) && cap == Some(Reply::Ack) && right == n,
        format!(
            "{right} of {n} requests answered in windows of {REQUEST_WINDOW} (telemetry 1 kHz: {}, capture 10 kHz x 10000: {}); {telemetry} telemetry samples and {chunks} capture chunks meanwhile; {} unanswered; wrong replies: {}",
            describe(&tele),
            describe(&cap),
            lost,
            if wrong.is_empty() { "none".into() } else { wrong.join(", ") }
        ),
    );
    Ok(())
}

/// Four windows' worth of requests in one write: every reply is the request's own or
/// `Busy`, at least a window's worth are answered, and nothing else happens.
fn busy_beyond_window<T: Read + Write>(s: &mut Suite<T>) -> Result<(), RigError> {
    s.link.pump(Duration::from_millis(20))?;
    s.link.clear_replies();
    let mut bytes = Vec::new();
    let mut seqs = Vec::new();
    for _ in 0..4 * REQUEST_WINDOW {
        let (seq, frame) = s.link.frame(&Request::GetFaults);
        seqs.push(seq);
        bytes.extend(frame);
    }
    s.link.write(&bytes)?;
    s.link.pump(s.wall(0.05) + Duration::from_millis(300))?;
    let (mut answered, mut busy, mut other) = (0, 0, Vec::new());
    for seq in &seqs {
        match s.link.replies.remove(seq) {
            Some(Reply::Faults { .. }) => answered += 1,
            Some(Reply::Nack(NackCode::Busy)) => busy += 1,
            Some(r) => other.push(describe(&Some(r))),
            None => {}
        }
    }
    s.record(
        "busy-beyond-window",
        answered >= REQUEST_WINDOW && other.is_empty(),
        format!(
            "{} requests at once: {answered} answered, {busy} Busy, other replies: {}",
            seqs.len(),
            if other.is_empty() {
                "none".into()
            } else {
                other.join(", ")
            }
        ),
    );
    Ok(())
}

/// A drive before the current sensor's zero is measured is refused with the reason: a
/// `RezeroCurrent` and a `Release` in one write, so the release reaches the device well
/// inside the zero's 100 ms. The zero's own reply must be `Ack`, the release's
/// `Nack(CurrentZeroPending)`; whatever came back, the gear is locked again and the zero
/// given time to end.
fn release_before_zero<T: Read + Write>(s: &mut Suite<T>, hz: f32) -> Result<(), RigError> {
    let (zero_seq, mut bytes) = s.link.frame(&Request::RezeroCurrent);
    let (release_seq, release) = s.link.frame(&Request::Release {
        on: true,
        target_hz: hz,
        session: 0,
    });
    bytes.extend_from_slice(&release);
    s.link.write(&bytes)?;
    let wait = s.reply_wait;
    let zero = s.link.reply(zero_seq, wait)?;
    let got = s.link.reply(release_seq, wait)?;
    let lock = s.request(&Request::Release {
        on: false,
        target_hz: 0.0,
        session: 0,
    })?;
    // The zero takes 100 ms of device time; a margin for the link.
    s.link.pump(s.wall(0.3))?;
    let ok = zero == Some(Reply::Ack)
        && got == Some(Reply::Nack(NackCode::CurrentZeroPending))
        && lock == Some(Reply::Ack);
    s.record(
        "release-before-zero",
        ok,
        format!(
            "RezeroCurrent got {}; a Release in the same write got {} (want Nack(CurrentZeroPending)); Release(off) got {}",
            describe(&zero),
            describe(&got),
            describe(&lock)
        ),
    );
    Ok(())
}

/// A second host session on the same port: its requests are answered but keep no release
/// alive, and its release is refused while another session's is live.
const STRANGER_SESSION: protocol::SessionId = 0x0BAD_0BAD;

/// A release whose heartbeats stop: vibration stops after the comms timeout (device and
/// wall time) although a second session keeps sending heartbeats and status requests and
/// cannot take the release over (`release-owner`), `COMMS_TIMEOUT` latches, a release is refused in the hold and while the
/// fault is latched, a lock never is, `ClearFaults` clears it, and the device ends in its
/// safe state.
fn heartbeat_and_faults<T: Read + Write>(s: &mut Suite<T>, hz: f32) -> Result<(), RigError> {
    let _ = s.request(&Request::ClearFaults)?;
    s.link.pump(s.wall(0.6))?;
    let _ = s.request(&Request::StartTelemetry { rate_hz: 100 })?;
    let ack = s.request(&Request::Release {
        on: true,
        target_hz: hz,
        session: 0,
    })?;
    if ack != Some(Reply::Ack) {
        // Say which precondition failed: a fault that would not clear (its cause is
        // still there: a load still moving, a blocked cam) or another refusal.
        let latched = match s.request(&Request::GetFaults)? {
            Some(Reply::Faults { latched, .. }) if !latched.is_empty() => format!(
                " with {} latched after ClearFaults: its cause is still there (the output must be unloaded and still, the cam free); fix it, `rig clear`, and run conformance again",
                latched.names().collect::<Vec<_>>().join(", ")
            ),
            _ => String::new(),
        };
        s.record(
            "heartbeat-timeout",
            false,
            format!("Release at {hz} Hz got {}{latched}", describe(&ack)),
        );
        let _ = s.request(&Request::StopTelemetry)?;
        return Ok(());
    }
    // Heartbeats for a second of device time.
    let every = s.wall(f64::from(protocol::HEARTBEAT_INTERVAL_MS) / 1000.0);
    let until = Instant::now() + s.wall(1.0);
    let mut last_device_us = 0u64;
    let mut heartbeats_ok = true;
    while Instant::now() < until {
        let seq = s.link.send(&Request::Heartbeat { session: 0 })?;
        let step_end = Instant::now() + every;
        while Instant::now() < step_end {
            s.link.pump(Duration::from_millis(1))?;
        }
        if let Some(r) = s.link.replies.remove(&seq) {
            heartbeats_ok &= r == Reply::Ack;
        }
    }
    // The last heartbeat: its acceptance is after the last sample seen before it.
    s.link.pump(Duration::ZERO)?;
    for (_, m) in s.link.take_unsolicited() {
        if let DeviceMessage::Telemetry(t) = m {
            last_device_us = t.device_time_us;
        }
    }
    let seq = s.link.send(&Request::Heartbeat { session: 0 })?;
    let silent_from = Instant::now();
    // The owner falls silent; a second session talks on, and asks to take over.
    let takeover = s.link.send(&Request::Release {
        on: true,
        target_hz: hz,
        session: STRANGER_SESSION,
    })?;
    let mut stranger_at = silent_from;
    let mut stopped_wall = None;
    let mut fault_us = None;
    let end = silent_from + s.wall(1.5) + Duration::from_millis(500);
    while Instant::now() < end && (stopped_wall.is_none() || fault_us.is_none()) {
        if stopped_wall.is_none() && Instant::now() >= stranger_at {
            s.link.send(&Request::Heartbeat {
                session: STRANGER_SESSION,
            })?;
            s.link.send(&Request::GetFaults)?;
            stranger_at += every;
        }
        s.link.pump(Duration::from_millis(1))?;
        for (at, m) in s.link.take_unsolicited() {
            match m {
                DeviceMessage::Telemetry(t)
                    if stopped_wall.is_none()
                        && !matches!(
                            t.state,
                            SupervisorState::SpinUp | SupervisorState::Vibrating
                        ) =>
                {
                    stopped_wall = Some(at.duration_since(silent_from));
                }
                DeviceMessage::FaultEvent {
                    flags,
                    device_time_us,
                } if flags.contains(FaultFlags::COMMS_TIMEOUT) => fault_us = Some(device_time_us),
                _ => {}
            }
        }
    }
    let _ = s.link.replies.remove(&seq);
    let takeover = s.link.replies.remove(&takeover);
    let timeout_s = f64::from(protocol::COMMS_TIMEOUT_MS) / 1000.0;
    let period_s = 0.001;
    // The device-time bound: after the last heartbeat's acceptance, at most the timeout
    // and a control period (the sample before it is up to a telemetry period earlier).
    let device_s = fault_us.map(|f| f.saturating_sub(last_device_us) as f64 * 1e-6);
    let device_ok = device_s.is_some_and(|d| d <= timeout_s + period_s + 0.01 + 0.02 * s.scale);
    // The wall-time bound, with 100 ms for the link and this machine.
    let wall_bound = s.wall(timeout_s + period_s) + Duration::from_millis(100);
    let wall_ok = stopped_wall.is_some_and(|w| w <= wall_bound);
    s.record(
        "heartbeat-timeout",
        heartbeats_ok && device_ok && wall_ok,
        format!(
            "heartbeats accepted: {heartbeats_ok}; vibration stopped {} after the last heartbeat (bound {:.3} s wall); COMMS_TIMEOUT rose {} of device time after the last sample before it (bound {:.3} s)",
            stopped_wall.map_or("never".into(), |w| format!("{:.3} s wall", w.as_secs_f64())),
            wall_bound.as_secs_f64(),
            device_s.map_or("never".into(), |d| format!("{d:.3} s")),
            timeout_s + period_s + 0.01 + 0.02 * s.scale
        ),
    );
    s.record(
        "release-owner",
        takeover == Some(Reply::Nack(NackCode::Busy)) && device_ok && wall_ok,
        format!(
            "a second session's Release(on) during the first's release got {}; its heartbeats and GetFaults every {:.3} s wall kept nothing alive: vibration stopped {} after the owner's last heartbeat",
            describe(&takeover),
            every.as_secs_f64(),
            stopped_wall.map_or("never".into(), |w| format!("{:.3} s wall", w.as_secs_f64())),
        ),
    );
    s.link.clear_replies();
    let _ = s.request(&Request::StopTelemetry)?;

    // Latch, hold, clear.
    let mut bad = Vec::new();
    match s.request(&Request::GetFaults)? {
        Some(Reply::Faults { latched, .. }) if latched.contains(FaultFlags::COMMS_TIMEOUT) => {}
        other => bad.push(format!("GetFaults after the timeout: {}", describe(&other))),
    }
    let release = Request::Release {
        on: true,
        target_hz: hz,
        session: 0,
    };
    let got = s.request(&release)?;
    if got != Some(Reply::Nack(NackCode::InFaultHold)) {
        bad.push(format!("Release with a fault latched: {}", describe(&got)));
    }
    // A lock is never held off.
    let got = s.request(&Request::Release {
        on: false,
        target_hz: 0.0,
        session: 0,
    })?;
    if got != Some(Reply::Ack) {
        bad.push(format!("Release(off) in the hold: {}", describe(&got)));
    }
    // Wait out the fault hold: a latched fault still refuses a release.
    s.link
        .pump(s.wall(f64::from(protocol::FAULT_HOLD_MS) / 1000.0 + 0.1))?;
    let got = s.request(&release)?;
    if got != Some(Reply::Nack(NackCode::InFaultHold)) {
        bad.push(format!(
            "Release after the hold, fault latched: {}",
            describe(&got)
        ));
    }
    match s.request(&Request::ClearFaults)? {
        Some(Reply::Faults { latched, .. }) if latched.is_empty() => {}
        other => bad.push(format!("ClearFaults: {}", describe(&other))),
    }
    // Cleared and past the hold: accepted again.
    let got = s.request(&Request::Heartbeat { session: 0 })?;
    if got != Some(Reply::Ack) {
        bad.push(format!("Heartbeat after the clear: {}", describe(&got)));
    }
    let got = s.request(&Request::Release {
        on: false,
        target_hz: 0.0,
        session: 0,
    })?;
    if got != Some(Reply::Ack) {
        bad.push(format!("Release(off) after the clear: {}", describe(&got)));
    }
    let ok = bad.is_empty();
    s.record(
        "fault-latch-hold-clear",
        ok,
        if ok {
            "COMMS_TIMEOUT latched; a release refused in the hold and while latched after it; cleared; requests accepted again".into()
        } else {
            bad.join("; ")
        },
    );
    s.safe_state("safe-state-after-faults")
}
