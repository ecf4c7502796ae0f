//! The device client: a session with the rig's firmware over any `Read + Write` byte
//! stream (a serial port, the virtual device's pseudo-terminal, an in-memory pipe).
//!
//! - [`Client::connect`] says `Hello` and refuses a device of another protocol version or
//!   schema with a message that names the side to update.
//! - Requests carry a sequence number; replies are matched to it, stale replies dropped.
//!   A request without a reply in [`ClientOptions::reply_timeout`] is sent again when it
//!   is safe to repeat ([`is_idempotent`]), up to [`ClientOptions::retries`] times.
//! - Telemetry, capture chunks and fault events arrive unsolicited; they queue until
//!   [`Client::recv`] (or [`Client::next_telemetry`], [`Client::capture`]) takes them.
//! - While a release or an open-loop drive is live, every wait inside the client sends a
//!   `Heartbeat` each [`protocol::HEARTBEAT_INTERVAL_MS`] (divided by the virtual device's
//!   speed), so the device keeps vibrating exactly as long as the host is waiting on it.
//!   [`Client::tick`] does the same for a caller that is busy elsewhere.

mod capture;
mod transport;

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use protocol::{
    Calibration, DeviceDeframer, DeviceInfo, DeviceMessage, FaultFlags, Frame, NackCode,
    PROTOCOL_VERSION, Request, SCHEMA_HASH, SeqTracker, TelemetrySample,
};

pub use capture::{
    CAPTURE_RATE_HZ, Capture, CaptureProgress, board_sensors, cam_angle_rad, current_amps,
};
pub use transport::{PipeEnd, SERIAL_READ_TIMEOUT, SerialTransport, memory_pipe, open_serial};

use crate::RigError;

/// Unsolicited messages kept while nobody takes them.
const MAX_QUEUED: usize = 1 << 16;

/// How the client talks to the device.
#[derive(Debug, Clone)]
pub struct ClientOptions {
    /// The port's name, for messages (`/dev/ttyACM0`, `virtual device on /dev/pts/3`).
    pub port_name: String,
    /// How long to wait for a reply before trying again, wall clock.
    pub reply_timeout: Duration,
    /// Extra tries of a request that is safe to repeat.
    pub retries: u32,
    /// Device seconds per wall-clock second: 1 for hardware, the `--speed` of the virtual
    /// device. Heartbeats are sent this much more often.
    pub time_scale: f64,
}

impl ClientOptions {
    /// Defaults for a hardware port called `port_name`: 500 ms replies, 2 retries.
    pub fn new(port_name: impl Into<String>) -> Self {
        Self {
            port_name: port_name.into(),
            reply_timeout: Duration::from_millis(500),
            retries: 2,
            time_scale: 1.0,
        }
    }
}

/// Faults as the device reports them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultStatus {
    /// Faults whose condition is present now.
    pub active: FaultFlags,
    /// Faults latched since the last clear (the motor stays off while any is latched).
    pub latched: FaultFlags,
}

/// Counters of the link since the client was made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct LinkStats {
    /// Frames decoded.
    pub frames_ok: u32,
    /// Frames dropped by the deframer (CRC, framing, overflow, unknown layout).
    pub frame_errors: u32,
    /// Device frames that never arrived (gaps in the device's frame numbers: its queue was
    /// full, or the line lost them).
    pub frames_lost: u32,
    /// Replies that matched no pending request (late answers to a timed-out try).
    pub stale_replies: u32,
    /// Requests sent again after a timeout.
    pub retries: u32,
    /// Heartbeats sent.
    pub heartbeats: u32,
    /// Telemetry samples missing from the stream (gaps in the sample counter).
    pub telemetry_lost: u64,
}

/// What a request expects as its answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    Ack,
    Info,
    Faults,
    Calibration,
}

impl Expect {
    fn of(req: &Request) -> Self {
        match req {
            Request::Hello { .. } | Request::GetInfo => Self::Info,
            Request::GetFaults | Request::ClearFaults => Self::Faults,
            Request::GetCalibration => Self::Calibration,
            _ => Self::Ack,
        }
    }

    fn matches(self, msg: &DeviceMessage) -> bool {
        matches!(
            (self, msg),
            (Self::Info, DeviceMessage::Info(_))
                | (Self::Faults, DeviceMessage::Faults { .. })
                | (Self::Calibration, DeviceMessage::Calibration(_))
        )
    }
}

/// Whether `req` may be sent twice without a different outcome (so it is retried after a
/// timeout). A capture or a re-zero started twice would not be the same.
pub fn is_idempotent(req: &Request) -> bool {
    !matches!(req, Request::StartCapture { .. } | Request::RezeroCurrent)
}

/// Short name of a request for messages.
pub fn request_name(req: &Request) -> &'static str {
    match req {
        Request::Hello { .. } => "Hello",
        Request::GetInfo => "GetInfo",
        Request::Release { on: true, .. } => "Release(on)",
        Request::Release { on: false, .. } => "Release(off)",
        Request::Heartbeat => "Heartbeat",
        Request::GetCalibration => "GetCalibration",
        Request::SetCalibration(_) => "SetCalibration",
        Request::StartTelemetry { .. } => "StartTelemetry",
        Request::StopTelemetry => "StopTelemetry",
        Request::StartCapture { .. } => "StartCapture",
        Request::GetFaults => "GetFaults",
        Request::ClearFaults => "ClearFaults",
        Request::RezeroCurrent => "RezeroCurrent",
        Request::OpenLoop { .. } => "OpenLoop",
        _ => "request",
    }
}

/// What to do about a refusal, by its code.
pub fn nack_advice(code: NackCode) -> &'static str {
    match code {
        NackCode::UnknownMessage => {
            "the firmware does not know this request: flash the firmware that matches this tool (cargo fw-flash)"
        }
        NackCode::BadArgument => {
            "an argument is out of the device's range (frequency above the calibration's max_freq_hz, telemetry rate, sample count or voltage): use a smaller value"
        }
        NackCode::InFaultHold => {
            "a fault is latched and holds the motor off: `rig faults` shows it, `rig clear` clears it once its cause is gone"
        }
        NackCode::VersionMismatch => {
            "host and firmware speak different protocol versions: update one of them"
        }
        NackCode::CalibrationRejected => {
            "the firmware's checks refused the calibration: fix the values (`rig calibration get` shows the active ones)"
        }
        NackCode::Busy => {
            "the device is busy (a capture is recording, or the motor is running): wait, or `rig release off`, then try again"
        }
        NackCode::StorageFailed => {
            "writing to the device's flash failed: try again; if it keeps failing the calibration page may be worn"
        }
        _ => "the firmware refused it for a reason this tool does not know: update the host tool",
    }
}

/// A session with the rig's firmware over `T`.
pub struct Client<T: Read + Write> {
    io: T,
    opts: ClientOptions,
    deframer: DeviceDeframer,
    seq: u16,
    inbox: VecDeque<DeviceMessage>,
    fault_events: Vec<(FaultFlags, u64)>,
    keep_alive: bool,
    heartbeat_seqs: VecDeque<u16>,
    last_sent: Instant,
    read_buf: Vec<u8>,
    stats: LinkStats,
    device_seq: SeqTracker,
    last_telemetry_seq: Option<u32>,
    bytes_in: u64,
}

impl<T: Read + Write> std::fmt::Debug for Client<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("port", &self.opts.port_name)
            .field("seq", &self.seq)
            .field("keep_alive", &self.keep_alive)
            .field("stats", &self.stats)
            .finish()
    }
}

impl<T: Read + Write> Client<T> {
    /// A client over `io` that has not said `Hello` yet (see [`Client::connect`]).
    pub fn new(io: T, opts: ClientOptions) -> Self {
        Self {
            io,
            opts,
            deframer: DeviceDeframer::new(),
            seq: 0,
            inbox: VecDeque::new(),
            fault_events: Vec::new(),
            keep_alive: false,
            heartbeat_seqs: VecDeque::new(),
            last_sent: Instant::now(),
            read_buf: vec![0; 4096],
            stats: LinkStats::default(),
            device_seq: SeqTracker::new(),
            last_telemetry_seq: None,
            bytes_in: 0,
        }
    }

    /// Opens a session: resynchronises the peer's deframer, says `Hello` and checks that
    /// the device speaks this tool's protocol version and schema.
    pub fn connect(io: T, opts: ClientOptions) -> Result<(Self, DeviceInfo), RigError> {
        let mut client = Self::new(io, opts);
        // A lone delimiter ends any half frame the device holds from before.
        client.write_bytes(&[protocol::FRAME_DELIMITER])?;
        let info = client.hello()?;
        Ok((client, info))
    }

    /// Says `Hello` and checks the versions.
    pub fn hello(&mut self) -> Result<DeviceInfo, RigError> {
        let hello = Request::Hello {
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
        };
        match self.request(&hello) {
            Ok(DeviceMessage::Info(info)) => {
                check_versions(&info)?;
                Ok(info)
            }
            Ok(other) => Err(self.unexpected(&hello, &other)),
            Err(RigError::Refused {
                code: NackCode::VersionMismatch,
                ..
            }) => {
                // Ask who it is, to say which side to update; an old device may refuse this too.
                if let Ok(DeviceMessage::Info(info)) = self.request(&Request::GetInfo) {
                    check_versions(&info)?;
                }
                Err(RigError::VersionMismatch {
                    device: None,
                    host: PROTOCOL_VERSION,
                    advice: "flash the firmware and install the rig tool from the same checkout (cargo fw-flash; cargo install --path host --locked)".into(),
                })
            }
            Err(e) => Err(e),
        }
    }

    /// The options in use.
    pub fn options(&self) -> &ClientOptions {
        &self.opts
    }

    /// Link counters so far.
    pub fn stats(&self) -> LinkStats {
        let d = self.deframer.stats();
        LinkStats {
            frames_ok: d.frames_ok,
            frame_errors: d.errors(),
            frames_lost: self.device_seq.lost,
            ..self.stats
        }
    }

    /// Gives the transport back.
    pub fn into_inner(self) -> T {
        self.io
    }

    /// Device identity and versions.
    pub fn info(&mut self) -> Result<DeviceInfo, RigError> {
        match self.request(&Request::GetInfo)? {
            DeviceMessage::Info(info) => Ok(info),
            other => Err(self.unexpected(&Request::GetInfo, &other)),
        }
    }

    /// Active and latched faults.
    pub fn faults(&mut self) -> Result<FaultStatus, RigError> {
        self.faults_request(&Request::GetFaults)
    }

    /// Clears the latched faults whose condition is gone; returns what remains.
    pub fn clear_faults(&mut self) -> Result<FaultStatus, RigError> {
        self.faults_request(&Request::ClearFaults)
    }

    fn faults_request(&mut self, req: &Request) -> Result<FaultStatus, RigError> {
        match self.request(req)? {
            DeviceMessage::Faults { active, latched } => Ok(FaultStatus { active, latched }),
            other => Err(self.unexpected(req, &other)),
        }
    }

    /// Starts (`on`) vibration at `target_hz`, or stops it. While on, the client keeps the
    /// release alive with heartbeats during every wait.
    pub fn release(&mut self, on: bool, target_hz: f32) -> Result<(), RigError> {
        self.ack(&Request::Release { on, target_hz })?;
        self.keep_alive = on;
        Ok(())
    }

    /// Drives the vibrator with a fixed voltage `volts` (open loop, for calibration); 0
    /// stops it. Kept alive by heartbeats like a release.
    pub fn open_loop(&mut self, volts: f32) -> Result<(), RigError> {
        self.ack(&Request::OpenLoop { volts })?;
        self.keep_alive = volts != 0.0;
        Ok(())
    }

    /// Sends one heartbeat and waits for its `Ack`.
    pub fn heartbeat(&mut self) -> Result<(), RigError> {
        self.ack(&Request::Heartbeat)
    }

    /// Whether the client is keeping a release (or open-loop drive) alive.
    pub fn keeping_alive(&self) -> bool {
        self.keep_alive
    }

    /// Starts sending heartbeats during every wait (after a release sent with
    /// [`Client::request`]).
    pub fn start_keep_alive(&mut self) {
        self.keep_alive = true;
    }

    /// Stops sending heartbeats (the device stops at its comms timeout).
    pub fn stop_keep_alive(&mut self) {
        self.keep_alive = false;
    }

    /// The calibration the device uses.
    pub fn calibration(&mut self) -> Result<Calibration, RigError> {
        match self.request(&Request::GetCalibration)? {
            DeviceMessage::Calibration(c) => Ok(c),
            other => Err(self.unexpected(&Request::GetCalibration, &other)),
        }
    }

    /// Validates `cal` here, then has the device validate, store and activate it.
    pub fn set_calibration(&mut self, cal: &Calibration) -> Result<(), RigError> {
        cal.validate().map_err(|e| RigError::BadValue {
            what: "calibration".into(),
            why: e.to_string(),
        })?;
        self.ack(&Request::SetCalibration(*cal))
    }

    /// Starts the telemetry stream at `rate_hz` samples per device second.
    pub fn start_telemetry(&mut self, rate_hz: u16) -> Result<(), RigError> {
        self.last_telemetry_seq = None;
        self.ack(&Request::StartTelemetry { rate_hz })
    }

    /// Stops the telemetry stream and drops queued samples.
    pub fn stop_telemetry(&mut self) -> Result<(), RigError> {
        self.ack(&Request::StopTelemetry)?;
        self.discard_telemetry();
        Ok(())
    }

    /// Drops the telemetry samples received but not yet taken (after a change, to read
    /// only what follows it).
    pub fn discard_telemetry(&mut self) {
        self.inbox
            .retain(|m| !matches!(m, DeviceMessage::Telemetry(_)));
    }

    /// Fault events received so far (flags that rose, device time in µs); taking them
    /// empties the list.
    pub fn take_fault_events(&mut self) -> Vec<(FaultFlags, u64)> {
        std::mem::take(&mut self.fault_events)
    }

    /// The next unsolicited message (telemetry, capture data, fault event), waiting up to
    /// `timeout`; heartbeats continue meanwhile.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<DeviceMessage>, RigError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(msg) = self.inbox.pop_front() {
                return Ok(Some(msg));
            }
            self.pump(None)?;
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// The next telemetry sample, waiting up to `timeout`. Other unsolicited messages are
    /// dropped (fault events stay in [`Client::take_fault_events`]).
    pub fn next_telemetry(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<TelemetrySample>, RigError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv(left)? {
                Some(DeviceMessage::Telemetry(t)) => return Ok(Some(t)),
                Some(_) => continue,
                None => return Ok(None),
            }
        }
    }

    /// Reads what has arrived and sends a heartbeat if one is due, without waiting.
    pub fn tick(&mut self) -> Result<(), RigError> {
        self.pump(None).map(|_| ())
    }

    /// Sends `req` and returns its reply: `Ack`, or the data message it asks for. A `Nack`
    /// becomes [`RigError::Refused`]; no reply after the retries, [`RigError::NoReply`].
    pub fn request(&mut self, req: &Request) -> Result<DeviceMessage, RigError> {
        let expect = Expect::of(req);
        let tries = if is_idempotent(req) {
            1 + self.opts.retries
        } else {
            1
        };
        let bytes_before = self.bytes_in;
        let errors_before = self.deframer.stats().errors();
        for attempt in 0..tries {
            if attempt > 0 {
                self.stats.retries += 1;
            }
            let seq = self.send(req)?;
            let deadline = Instant::now() + self.opts.reply_timeout;
            loop {
                if let Some(reply) = self.pump(Some((seq, expect)))? {
                    return match reply {
                        DeviceMessage::Nack { code, .. } => Err(RigError::Refused {
                            request: request_name(req),
                            code,
                            advice: nack_advice(code).into(),
                        }),
                        msg => Ok(msg),
                    };
                }
                if Instant::now() >= deadline {
                    break;
                }
            }
        }
        let bytes = self.bytes_in - bytes_before;
        let bad = self.deframer.stats().errors() - errors_before;
        Err(RigError::NoReply {
            port: self.opts.port_name.clone(),
            request: request_name(req),
            waited_ms: self.opts.reply_timeout.as_millis() as u64 * u64::from(tries),
            tries,
            hint: silence_hint(bytes, bad),
        })
    }

    /// Sends `req` and requires an `Ack`.
    pub fn ack(&mut self, req: &Request) -> Result<(), RigError> {
        match self.request(req)? {
            DeviceMessage::Ack { .. } => Ok(()),
            other => Err(self.unexpected(req, &other)),
        }
    }

    /// Sends `req` with the next sequence number; returns that number.
    pub fn send(&mut self, req: &Request) -> Result<u16, RigError> {
        self.seq = self.seq.wrapping_add(1);
        let frame = protocol::encode_frame_vec(self.seq, req)
            .map_err(|e| RigError::Protocol(format!("cannot encode {}: {e}", request_name(req))))?;
        self.write_bytes(&frame)?;
        Ok(self.seq)
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), RigError> {
        // No flush: on a tty that is tcdrain, which would wait for the peer to read.
        self.io.write_all(bytes).map_err(|e| self.link_error(e))?;
        self.last_sent = Instant::now();
        Ok(())
    }

    fn link_error(&self, source: io::Error) -> RigError {
        RigError::Link {
            port: self.opts.port_name.clone(),
            source,
        }
    }

    fn unexpected(&self, req: &Request, msg: &DeviceMessage) -> RigError {
        RigError::Protocol(format!(
            "the device answered {} with {msg:?} on {}; update host tool and firmware to the same version",
            request_name(req),
            self.opts.port_name
        ))
    }

    fn heartbeat_due(&self) -> bool {
        let every =
            protocol::HEARTBEAT_INTERVAL_MS as f64 / 1000.0 / self.opts.time_scale.max(1e-3);
        self.keep_alive && self.last_sent.elapsed().as_secs_f64() >= every
    }

    /// Reads once (waiting at most the transport's read timeout), routes every frame, and
    /// returns the reply to `want` if it came. Sends a due heartbeat first.
    fn pump(&mut self, want: Option<(u16, Expect)>) -> Result<Option<DeviceMessage>, RigError> {
        if self.heartbeat_due() {
            let seq = self.send(&Request::Heartbeat)?;
            self.heartbeat_seqs.push_back(seq);
            if self.heartbeat_seqs.len() > 16 {
                self.heartbeat_seqs.pop_front();
            }
            self.stats.heartbeats += 1;
        }
        let n = match self.io.read(&mut self.read_buf) {
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut
                        | io::ErrorKind::WouldBlock
                        | io::ErrorKind::Interrupted
                ) =>
            {
                0
            }
            Err(e) => return Err(self.link_error(e)),
        };
        if n == 0 {
            return Ok(None);
        }
        self.bytes_in += n as u64;
        let mut frames = Vec::new();
        self.deframer.push(&self.read_buf[..n], |f| frames.push(f));
        let mut reply = None;
        for frame in frames.into_iter().flatten() {
            if let Some(msg) = self.route(frame, want) {
                reply.get_or_insert(msg);
            }
        }
        Ok(reply)
    }

    /// Queues unsolicited messages; returns the frame's message if it answers `want`.
    fn route(
        &mut self,
        frame: Frame<DeviceMessage>,
        want: Option<(u16, Expect)>,
    ) -> Option<DeviceMessage> {
        self.device_seq.observe(frame.seq);
        match frame.msg {
            DeviceMessage::Telemetry(t) => {
                if let Some(last) = self.last_telemetry_seq
                    && t.seq > last.wrapping_add(1)
                {
                    self.stats.telemetry_lost += u64::from(t.seq - last - 1);
                }
                self.last_telemetry_seq = Some(t.seq);
                if self.inbox.len() >= MAX_QUEUED {
                    // Nobody is reading: forget the oldest rather than grow without end.
                    self.inbox.pop_front();
                }
                self.inbox.push_back(DeviceMessage::Telemetry(t));
                None
            }
            DeviceMessage::FaultEvent {
                flags,
                device_time_us,
            } => {
                self.fault_events.push((flags, device_time_us));
                self.inbox.push_back(DeviceMessage::FaultEvent {
                    flags,
                    device_time_us,
                });
                None
            }
            msg @ (DeviceMessage::CaptureChunk(_) | DeviceMessage::CaptureDone { .. }) => {
                self.inbox.push_back(msg);
                None
            }
            DeviceMessage::Ack { seq } | DeviceMessage::Nack { seq, .. }
                if want.is_some_and(|(s, _)| s == seq) =>
            {
                Some(frame.msg)
            }
            // Heartbeats are not waited for; their answers end here.
            DeviceMessage::Ack { seq } | DeviceMessage::Nack { seq, .. }
                if self.heartbeat_seqs.contains(&seq) =>
            {
                None
            }
            // Data replies carry no request number (the device numbers its frames with its
            // own counter): the first of the expected kind answers. Requests go one at a
            // time, so only a late answer to a timed-out try can come first, and tries of
            // the same request have the same answer.
            msg if want.is_some_and(|(_, e)| e.matches(&msg)) => Some(msg),
            _ => {
                self.stats.stale_replies += 1;
                None
            }
        }
    }
}

impl Client<Box<dyn serialport::SerialPort>> {
    /// Opens serial port `port` at `baud` and connects (see [`Client::connect`]).
    pub fn open(port: &str, baud: u32) -> Result<(Self, DeviceInfo), RigError> {
        let io = open_serial(port, baud)?;
        Self::connect(io, ClientOptions::new(port))
    }
}

/// Refuses a device of another protocol version or schema, naming the side to update.
pub fn check_versions(info: &DeviceInfo) -> Result<(), RigError> {
    let device = info.protocol_version;
    if device > PROTOCOL_VERSION {
        return Err(RigError::VersionMismatch {
            device: Some(device),
            host: PROTOCOL_VERSION,
            advice: "update the host tool (cargo install --path host --locked, from the checkout that built the firmware)".into(),
        });
    }
    if device < PROTOCOL_VERSION {
        return Err(RigError::VersionMismatch {
            device: Some(device),
            host: PROTOCOL_VERSION,
            advice: "flash the firmware that matches this tool (cargo fw-flash)".into(),
        });
    }
    if info.schema_hash != SCHEMA_HASH {
        return Err(RigError::SchemaMismatch {
            version: device,
            device_hash: info.schema_hash,
            host_hash: SCHEMA_HASH,
        });
    }
    Ok(())
}

/// Why the device may be silent, from what arrived instead of a reply.
fn silence_hint(bytes: u64, bad_frames: u32) -> String {
    if bytes == 0 {
        "nothing came back: check that the rig is powered, the firmware flashed (cargo fw-flash) and this is its port (`rig ports` lists them)".into()
    } else if bad_frames > 0 {
        format!(
            "{bytes} bytes came back but {bad_frames} frame(s) were garbled: the baud rate probably differs from the firmware's ({} by default; set it with --baud)",
            protocol::DEFAULT_BAUD_RATE
        )
    } else {
        format!(
            "{bytes} bytes came back but no answer to this request: the device may be busy; try again"
        )
    }
}

#[cfg(test)]
mod tests;
