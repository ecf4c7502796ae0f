//! The host's side of a session, sans-IO: requests in, frame bytes out; device bytes in,
//! events out; time passed in. The serial client (wall-clock time) and the simulator's link
//! (virtual time) both drive this one state machine, so they match replies, retry, keep a
//! release alive and recognise a peer of another version in the same way.
//!
//! It lives here (feature `std`), not in a crate of its own, because it is nothing but this
//! protocol's rules put together: the request facts ([`Request::retry_safe`]), reply
//! matching ([`DeviceMessage::reply_to`]), the deframer, lost-frame counting ([`SeqTracker`])
//! and peer identification ([`identify_peer`]). It does no I/O and reads no clock, so it
//! needs nothing the crate does not already depend on.
//!
//! # Driving it
//! ```
//! use std::time::Duration;
//! use protocol::session::{Event, Session, SessionConfig};
//! use protocol::{DeviceMessage, Reply, Request, encode_frame_vec};
//!
//! let mut session = Session::new(SessionConfig::default());
//! let t0 = Duration::ZERO;
//! let (seq, bytes) = session.send(Request::GetFaults, t0);
//! // ... write `bytes` to the port; later, bytes arrive from the device:
//! # let _ = bytes;
//! let answer = DeviceMessage::reply(seq, Reply::Ack);
//! session.receive(&encode_frame_vec(1, &answer)?, Duration::from_millis(3));
//! while let Some(bytes) = session.poll_transmit(Duration::from_millis(3)) {
//!     // ... write retries and heartbeats
//! #   let _ = bytes;
//! }
//! match session.poll(Duration::from_millis(3)) {
//!     Some(Event::Reply { seq: s, reply, .. }) => assert_eq!((s, reply), (seq, Reply::Ack)),
//!     other => panic!("{other:?}"),
//! }
//! # Ok::<(), protocol::Error>(())
//! ```
//!
//! * [`Session::send`] numbers the request and returns its frame. Its reply comes back as
//!   [`Event::Reply`] with the same `seq`, matched by [`DeviceMessage::reply_to`] and never
//!   by kind; a reply nobody waits for (the late answer to a retried try) is counted in
//!   [`SessionStats::stale_replies`] and dropped.
//! * Without a reply within [`SessionConfig::reply_timeout`], a request that is
//!   [`Request::retry_safe`] is sent again with the same `seq` (up to
//!   [`SessionConfig::retries`] times; the bytes come out of [`Session::poll_transmit`]);
//!   then, or at once for the others, [`Event::Timeout`].
//! * At most [`REQUEST_WINDOW`] requests are outstanding at once (heartbeats included), the
//!   device's window: [`Session::send`] of a request beyond it returns empty bytes and
//!   keeps the frame until a reply (or a timeout) frees a place; it then comes out of
//!   [`Session::poll_transmit`]. While heartbeats go out, one place in the window is kept
//!   for them (other requests use the rest), so a heartbeat never waits behind queries.
//! * Every `Release`, `OpenLoop` and `Heartbeat` carries the session's id
//!   ([`Session::with_id`]): the device keeps a release alive only on its owner's.
//! * [`Session::keep_alive`] sends a `Heartbeat` every interval (through
//!   [`Session::poll_transmit`]) while a release or an open-loop drive is live. Their
//!   replies are consumed here; refusals are counted.
//! * Unsolicited messages become [`Event::Telemetry`], [`Event::Health`],
//!   [`Event::CaptureChunk`], [`Event::CaptureDone`] and [`Event::FaultEvent`].
//! * A frame that passes its CRC but is not a message of this version is read with
//!   [`identify_peer`]: an older or newer device's answer to `Hello` becomes
//!   [`Event::PeerVersion`] (pass it to [`peer_error`] for what to do). Other garbled
//!   frames become [`Event::Desync`]; the next frame decodes regardless.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::compat::{PeerIdentity, check_peer, identify_peer};
use crate::{
    CaptureChunk, DeviceDeframer, DeviceInfo, DeviceMessage, Error, FRAME_DELIMITER, FaultFlags,
    HealthSample, NackCode, PROTOCOL_VERSION, REQUEST_WINDOW, Reply, Request, SCHEMA_HASH,
    SeqTracker, SessionId, TelemetrySample, encode_frame_vec,
};

/// Events kept while the driver does not poll; beyond this the oldest are dropped.
const MAX_EVENTS: usize = 1 << 16;

/// How a session waits and retries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionConfig {
    /// How long to wait for a reply before a retry or a timeout (in the driver's time).
    pub reply_timeout: Duration,
    /// Extra tries of a request that is [`Request::retry_safe`].
    pub retries: u32,
}

impl Default for SessionConfig {
    /// 500 ms replies (the comms timeout: a device that cannot answer in that time has
    /// dropped its release anyway), 2 retries.
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(u64::from(crate::COMMS_TIMEOUT_MS)),
            retries: 2,
        }
    }
}

/// What the session has to tell its driver.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// The device's answer to request `seq` (an accepting reply or a `Nack`). Check its
    /// kind with [`Request::is_answered_by`] before reading it as the expected reply.
    Reply {
        /// The request's sequence number, as [`Session::send`] returned it.
        seq: u16,
        /// The request.
        request: Request,
        /// The answer.
        reply: Reply,
    },
    /// A telemetry sample.
    Telemetry(TelemetrySample),
    /// A health sample (once a second while telemetry runs).
    Health(HealthSample),
    /// Part of a capture upload.
    CaptureChunk(CaptureChunk),
    /// A capture upload is complete.
    CaptureDone {
        /// The capture's id.
        capture_id: u16,
        /// Samples sent in all chunks.
        total_samples: u32,
        /// Actual sample rate, Hz.
        sample_rate_hz: u16,
    },
    /// New faults became active on the device.
    FaultEvent {
        /// The faults that rose.
        flags: FaultFlags,
        /// Device clock when they rose, microseconds since boot.
        device_time_us: u64,
    },
    /// Request `seq` got no reply after `tries` tries; it is forgotten.
    Timeout {
        /// The request's sequence number.
        seq: u16,
        /// The request.
        request: Request,
        /// How often it was sent.
        tries: u32,
    },
    /// A device of another protocol version answered: its frame did not decode as this
    /// version's, but [`identify_peer`] read its version. `seq` is the `Hello` it answers
    /// when one was waiting (that request is then finished).
    PeerVersion {
        /// The waiting `Hello`, if any.
        seq: Option<u16>,
        /// The device's version.
        peer: PeerIdentity,
    },
    /// A frame was lost to noise, a wrong baud rate or an unknown layout (the deframer's
    /// error); the session resynchronises at the next frame.
    Desync {
        /// What went wrong.
        error: Error,
    },
    /// A block of the continuous stream (feed it to a [`crate::StreamDecoder`]).
    StreamBlock(crate::StreamBlock),
}

/// Counters of a session since it was made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SessionStats {
    /// Frames decoded.
    pub frames_ok: u32,
    /// Frames dropped by the deframer (CRC, framing, overflow, unknown layout).
    pub frame_errors: u32,
    /// Device frames that never arrived (gaps in the device's frame numbers).
    pub frames_lost: u32,
    /// Replies that matched no waiting request (late answers to a retried or abandoned
    /// request).
    pub stale_replies: u32,
    /// Requests sent again after a timeout.
    pub retries: u32,
    /// Heartbeats sent.
    pub heartbeats: u32,
    /// Heartbeats the device refused (a fault hold, for example).
    pub heartbeats_refused: u32,
    /// Telemetry samples missing from the stream (gaps in the sample counter).
    pub telemetry_lost: u64,
    /// Bytes received.
    pub bytes_in: u64,
    /// Events dropped because the driver did not poll.
    pub events_dropped: u32,
}

/// A request waiting for its reply.
#[derive(Debug, Clone)]
struct Pending {
    request: Request,
    sent_at: Duration,
    tries: u32,
    /// Sent by the session's keep-alive, not by the driver: its reply is consumed here.
    heartbeat: bool,
}

/// The host's session state machine. See the module documentation.
#[derive(Debug)]
pub struct Session {
    config: SessionConfig,
    next_seq: u16,
    deframer: DeviceDeframer,
    pending: BTreeMap<u16, Pending>,
    /// Requests numbered but not yet sent: the window was full.
    waiting: VecDeque<(u16, Request)>,
    events: VecDeque<Event>,
    transmit: VecDeque<Vec<u8>>,
    /// Heartbeat interval and when the last one went out.
    keep_alive: Option<(Duration, Duration)>,
    /// This session's id, stamped on every drive request it sends.
    id: SessionId,
    device_seq: SeqTracker,
    last_telemetry_seq: Option<u32>,
    stats: SessionStats,
}

impl Default for Session {
    fn default() -> Self {
        Self::new(SessionConfig::default())
    }
}

impl Session {
    /// A session that has sent nothing yet. Write [`Session::OPENING`] to the port first.
    pub fn new(config: SessionConfig) -> Self {
        Self {
            config,
            next_seq: 0,
            deframer: DeviceDeframer::new(),
            pending: BTreeMap::new(),
            waiting: VecDeque::new(),
            events: VecDeque::new(),
            transmit: VecDeque::new(),
            keep_alive: None,
            id: 0,
            device_seq: SeqTracker::new(),
            last_telemetry_seq: None,
            stats: SessionStats::default(),
        }
    }

    /// The session with `id` as its [`SessionId`] (0 until set): every `Release`,
    /// `OpenLoop` and `Heartbeat` it sends carries it, whatever the caller put there. A host
    /// picks it at random when it opens a port, so two processes on one port differ and
    /// only the one that released keeps the release alive.
    #[must_use]
    pub fn with_id(mut self, id: SessionId) -> Self {
        self.id = id;
        self
    }

    /// This session's id.
    pub fn id(&self) -> SessionId {
        self.id
    }

    /// Bytes to write once after opening a port: a lone delimiter ends any half frame the
    /// device holds from before.
    pub const OPENING: [u8; 1] = [FRAME_DELIMITER];

    /// The `Hello` this host opens a session with (this protocol version and schema).
    pub const fn hello() -> Request {
        Request::Hello {
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SessionConfig {
        &self.config
    }

    /// Changes how later requests wait and retry.
    pub fn set_config(&mut self, config: SessionConfig) {
        self.config = config;
    }

    /// Numbers `request`, remembers it until its reply, and returns its sequence number
    /// and frame (write the bytes to the port). With [`REQUEST_WINDOW`] requests already
    /// outstanding the bytes are empty: the frame waits for a free place and then comes
    /// out of [`Session::poll_transmit`].
    pub fn send(&mut self, request: Request, now: Duration) -> (u16, Vec<u8>) {
        let request = request.with_session(self.id);
        let seq = self.take_seq();
        if !self.has_room() || !self.waiting.is_empty() {
            self.waiting.push_back((seq, request));
            return (seq, Vec::new());
        }
        (seq, self.start(seq, request, now))
    }

    /// Requests sent and not yet answered (at most [`REQUEST_WINDOW`]).
    pub fn outstanding(&self) -> usize {
        self.pending.len()
    }

    /// Sends `request` as `seq` now: remembered until its reply.
    fn start(&mut self, seq: u16, request: Request, now: Duration) -> Vec<u8> {
        let bytes = frame(seq, &request);
        self.pending.insert(
            seq,
            Pending {
                request,
                sent_at: now,
                tries: 1,
                heartbeat: false,
            },
        );
        bytes
    }

    /// Whether the window has room for a request: while heartbeats go out one place is kept
    /// for them, since only the owner's drive requests keep a release alive and a heartbeat
    /// must not wait behind a full window of queries.
    fn has_room(&self) -> bool {
        let reserved = usize::from(self.keep_alive.is_some());
        let requests = self.pending.values().filter(|p| !p.heartbeat).count();
        self.pending.len() < REQUEST_WINDOW && requests < REQUEST_WINDOW - reserved
    }

    /// Sends waiting requests while the window has room.
    fn release_waiting(&mut self, now: Duration) {
        while self.has_room() {
            let Some((seq, request)) = self.waiting.pop_front() else {
                break;
            };
            let bytes = self.start(seq, request, now);
            self.transmit.push_back(bytes);
        }
    }

    /// Feeds bytes from the device, in chunks of any size.
    pub fn receive(&mut self, bytes: &[u8], now: Duration) {
        self.stats.bytes_in += bytes.len() as u64;
        for &byte in bytes {
            let Some(result) = self.deframer.push_byte(byte) else {
                continue;
            };
            match result {
                Ok(frame) => {
                    self.device_seq.observe(frame.seq);
                    self.route(frame.msg);
                }
                Err(error @ Error::Decode { .. }) => {
                    let peer = self.deframer.last_body().and_then(identify_peer);
                    match peer {
                        Some(peer) => {
                            let seq = self.finish_hello();
                            self.push_event(Event::PeerVersion { seq, peer });
                        }
                        None => self.push_event(Event::Desync { error }),
                    }
                }
                Err(error) => self.push_event(Event::Desync { error }),
            }
        }
        self.handle_timers(now);
    }

    /// The next event, after retrying or timing out the requests whose reply is overdue at
    /// `now`.
    pub fn poll(&mut self, now: Duration) -> Option<Event> {
        self.handle_timers(now);
        self.events.pop_front()
    }

    /// The next bytes to write (a retry or a heartbeat) due at `now`.
    pub fn poll_transmit(&mut self, now: Duration) -> Option<Vec<u8>> {
        self.handle_timers(now);
        self.transmit.pop_front()
    }

    /// When the session next needs [`Session::poll`] or [`Session::poll_transmit`]
    /// without new bytes: the earliest reply deadline or heartbeat.
    pub fn poll_timeout(&self) -> Option<Duration> {
        let replies = self
            .pending
            .values()
            .map(|p| p.sent_at + self.config.reply_timeout);
        let heartbeat = self.keep_alive.map(|(every, last)| last + every);
        replies.chain(heartbeat).min()
    }

    /// Sends a `Heartbeat` every `interval` from `now` on (`None` stops them, as a host
    /// that lets a release lapse). While heartbeats already go out, a new interval applies
    /// from the last one sent.
    pub fn keep_alive(&mut self, interval: Option<Duration>, now: Duration) {
        self.keep_alive = match (interval, self.keep_alive) {
            (None, _) => None,
            (Some(every), Some((_, last))) => Some((every, last)),
            (Some(every), None) => Some((every, now)),
        };
    }

    /// Whether heartbeats are being sent.
    pub fn keeping_alive(&self) -> bool {
        self.keep_alive.is_some()
    }

    /// Whether request `seq` still waits for its reply (or for its place in the window).
    pub fn is_pending(&self, seq: u16) -> bool {
        self.pending.contains_key(&seq) || self.waiting.iter().any(|(s, _)| *s == seq)
    }

    /// Stops waiting for request `seq` (a late reply then counts as stale; one not sent
    /// yet is never sent).
    pub fn forget(&mut self, seq: u16) {
        self.pending.remove(&seq);
        self.waiting.retain(|(s, _)| *s != seq);
    }

    /// Counters so far.
    pub fn stats(&self) -> SessionStats {
        let d = self.deframer.stats();
        SessionStats {
            frames_ok: d.frames_ok,
            frame_errors: d.errors(),
            frames_lost: self.device_seq.lost,
            ..self.stats
        }
    }

    /// Drops the half frame received so far and forgets the device's frame numbering
    /// (after reopening the port); keeps the counters and the waiting requests.
    pub fn resync(&mut self) {
        self.deframer.clear();
        self.device_seq.resync();
        self.last_telemetry_seq = None;
    }

    /// Forgets the telemetry sample counter, so the next sample starts a new count (after
    /// `StartTelemetry`).
    pub fn restart_telemetry_count(&mut self) {
        self.last_telemetry_seq = None;
    }

    fn take_seq(&mut self) -> u16 {
        let seq = self.next_seq;
        self.next_seq = self.next_seq.wrapping_add(1);
        seq
    }

    fn push_event(&mut self, event: Event) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
            self.stats.events_dropped = self.stats.events_dropped.saturating_add(1);
        }
        self.events.push_back(event);
    }

    /// Finishes the oldest waiting `Hello`, if any; returns its seq.
    fn finish_hello(&mut self) -> Option<u16> {
        let seq = self
            .pending
            .iter()
            .find(|(_, p)| matches!(p.request, Request::Hello { .. }))
            .map(|(seq, _)| *seq)?;
        self.pending.remove(&seq);
        Some(seq)
    }

    fn route(&mut self, msg: DeviceMessage) {
        match msg {
            DeviceMessage::Reply { request_seq, reply } => {
                match self.pending.remove(&request_seq) {
                    Some(p) if p.heartbeat => {
                        if matches!(reply, Reply::Nack(_)) {
                            self.stats.heartbeats_refused += 1;
                        }
                    }
                    Some(p) => self.push_event(Event::Reply {
                        seq: request_seq,
                        request: p.request,
                        reply,
                    }),
                    None => self.stats.stale_replies += 1,
                }
            }
            DeviceMessage::Telemetry(t) => {
                if let Some(last) = self.last_telemetry_seq
                    && t.seq > last.wrapping_add(1)
                {
                    self.stats.telemetry_lost += u64::from(t.seq - last - 1);
                }
                self.last_telemetry_seq = Some(t.seq);
                self.push_event(Event::Telemetry(t));
            }
            DeviceMessage::Health(h) => self.push_event(Event::Health(h)),
            DeviceMessage::StreamBlock(b) => self.push_event(Event::StreamBlock(b)),
            DeviceMessage::CaptureChunk(c) => self.push_event(Event::CaptureChunk(c)),
            DeviceMessage::CaptureDone {
                capture_id,
                total_samples,
                sample_rate_hz,
            } => self.push_event(Event::CaptureDone {
                capture_id,
                total_samples,
                sample_rate_hz,
            }),
            DeviceMessage::FaultEvent {
                flags,
                device_time_us,
            } => self.push_event(Event::FaultEvent {
                flags,
                device_time_us,
            }),
        }
    }

    /// Retries or times out overdue requests and sends a due heartbeat.
    fn handle_timers(&mut self, now: Duration) {
        let timeout = self.config.reply_timeout;
        let overdue: Vec<u16> = self
            .pending
            .iter()
            .filter(|(_, p)| now.saturating_sub(p.sent_at) >= timeout)
            .map(|(seq, _)| *seq)
            .collect();
        for seq in overdue {
            let Some(p) = self.pending.get_mut(&seq) else {
                continue;
            };
            if !p.heartbeat && p.request.retry_safe() && p.tries <= self.config.retries {
                p.tries += 1;
                p.sent_at = now;
                let bytes = frame(seq, &p.request);
                self.transmit.push_back(bytes);
                self.stats.retries += 1;
            } else if let Some(p) = self.pending.remove(&seq)
                && !p.heartbeat
            {
                self.push_event(Event::Timeout {
                    seq,
                    request: p.request,
                    tries: p.tries,
                });
            }
        }
        self.release_waiting(now);
        if let Some((every, last)) = self.keep_alive
            && now.saturating_sub(last) >= every
        {
            // A new heartbeat supersedes one still unanswered: the device's comms timeout
            // counts the requests it receives, not the replies this side has read, so a
            // reply late behind a busy link (a 10 kHz stream read by a starved host) must
            // not hold the next heartbeat back. Its late reply counts as stale.
            self.pending.retain(|_, p| !p.heartbeat);
        }
        if let Some((every, last)) = self.keep_alive
            && now.saturating_sub(last) >= every
            && self.pending.len() < REQUEST_WINDOW
        {
            self.keep_alive = Some((every, now));
            let seq = self.take_seq();
            let heartbeat = Request::Heartbeat { session: self.id };
            self.transmit.push_back(frame(seq, &heartbeat));
            self.pending.insert(
                seq,
                Pending {
                    request: heartbeat,
                    sent_at: now,
                    tries: 1,
                    heartbeat: true,
                },
            );
            self.stats.heartbeats += 1;
        }
    }
}

/// The frame of `request` (requests always fit their frame, so encoding cannot fail).
fn frame(seq: u16, request: &Request) -> Vec<u8> {
    encode_frame_vec(seq, request).unwrap_or_default()
}

/// What an answer to `Hello` says about the device: its identity when it speaks this
/// version and schema; an [`Error::VersionMismatch`] that says which side to update when
/// it does not (an `Info` of another version, or `Nack(VersionMismatch)`); `None` for any
/// other reply.
pub fn hello_outcome(reply: &Reply) -> Option<Result<&DeviceInfo, Error>> {
    match reply {
        Reply::Info(info) => {
            Some(check_peer(info.protocol_version, Some(info.schema_hash)).map(|()| info))
        }
        Reply::Nack(NackCode::VersionMismatch {
            device_protocol,
            device_schema_hash,
        }) => Some(Err(mismatch(*device_protocol, Some(*device_schema_hash)))),
        _ => None,
    }
}

/// The error for a device identified by [`Event::PeerVersion`]: which side to update.
pub fn peer_error(peer: PeerIdentity) -> Error {
    mismatch(peer.protocol_version, peer.schema_hash)
}

/// [`check_peer`]'s error, also when the device refused a version it reports as its own.
fn mismatch(device_protocol: u16, device_schema_hash: Option<u32>) -> Error {
    match check_peer(device_protocol, device_schema_hash) {
        Err(e) => e,
        Ok(()) => Error::VersionMismatch {
            device_protocol,
            device_schema_hash: None,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Frame, LegacyV1Nack, RequestDeframer, StatusFlags, SupervisorState};

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// A scripted device: decodes the host's frames and encodes its answers.
    #[derive(Default)]
    struct Device {
        deframer: RequestDeframer,
        seq: u16,
    }

    impl Device {
        fn requests(&mut self, bytes: &[u8]) -> Vec<Frame<Request>> {
            let mut out = Vec::new();
            self.deframer.push(bytes, |f| out.push(f.unwrap()));
            out
        }

        fn say<M: serde::Serialize>(&mut self, msg: &M) -> Vec<u8> {
            self.seq = self.seq.wrapping_add(1);
            encode_frame_vec(self.seq, msg).unwrap()
        }
    }

    fn events(s: &mut Session, now: Duration) -> Vec<Event> {
        std::iter::from_fn(|| s.poll(now)).collect()
    }

    fn telemetry(seq: u32) -> DeviceMessage {
        DeviceMessage::Telemetry(TelemetrySample {
            seq,
            device_time_us: u64::from(seq) * 1000,
            cam_speed_rad_s: 0.0,
            current_a: 0.0,
            pwm_duty: 0.0,
            tau_cam_nm: 0.0,
            tau_rot_nm: 0.0,
            state: SupervisorState::Locked,
            faults: FaultFlags::empty(),
            status: StatusFlags::empty(),
            output_angle_rad: f32::NAN,
            output_speed_rad_s: f32::NAN,
        })
    }

    #[test]
    fn no_more_than_the_window_is_ever_outstanding() {
        let mut s = Session::default();
        let mut dev = Device::default();
        let mut on_wire = Vec::new();
        let mut seqs = Vec::new();
        for _ in 0..3 * REQUEST_WINDOW {
            let (seq, bytes) = s.send(Request::GetFaults, ms(0));
            seqs.push(seq);
            on_wire.extend(dev.requests(&bytes));
        }
        assert_eq!(on_wire.len(), REQUEST_WINDOW);
        assert_eq!(s.outstanding(), REQUEST_WINDOW);
        assert!(seqs.iter().all(|&q| s.is_pending(q)));
        // A heartbeat due while the window is full waits.
        s.keep_alive(Some(ms(10)), ms(0));
        assert!(s.poll_transmit(ms(20)).is_none());
        let mut answered = 0;
        let mut t = 20;
        while answered < seqs.len() {
            // The device answers everything it has; the session sends as places free.
            let mut wire = Vec::new();
            for f in on_wire.drain(..) {
                wire.extend(dev.say(&DeviceMessage::ack(f.seq)));
            }
            t += 1;
            s.receive(&wire, ms(t));
            assert!(s.outstanding() <= REQUEST_WINDOW);
            answered += events(&mut s, ms(t))
                .iter()
                .filter(|e| matches!(e, Event::Reply { .. }))
                .count();
            while let Some(bytes) = s.poll_transmit(ms(t)) {
                on_wire.extend(dev.requests(&bytes));
            }
            assert!(on_wire.len() <= REQUEST_WINDOW, "{}", on_wire.len());
            assert!(t < 100, "stuck after {answered} replies");
        }
        // In order, each exactly once.
        assert_eq!(answered, seqs.len());
        // A forgotten waiting request is never sent.
        for _ in 0..REQUEST_WINDOW {
            s.send(Request::GetInfo, ms(t));
        }
        let (late, bytes) = s.send(Request::GetInfo, ms(t));
        assert!(bytes.is_empty());
        s.forget(late);
        assert!(!s.is_pending(late));
    }

    #[test]
    fn replies_are_matched_by_seq_not_by_kind() {
        let mut s = Session::default();
        let mut dev = Device::default();
        let (a, bytes_a) = s.send(Request::GetFaults, ms(0));
        let (b, bytes_b) = s.send(Request::GetInfo, ms(0));
        assert_ne!(a, b);
        assert_eq!(dev.requests(&bytes_a)[0].seq, a);
        assert_eq!(dev.requests(&bytes_b)[0].seq, b);
        // Answers in the other order, a stale one and telemetry in between.
        let mut wire = dev.say(&DeviceMessage::ack(b.wrapping_add(100)));
        wire.extend(dev.say(&DeviceMessage::nack(b, NackCode::Busy)));
        wire.extend(dev.say(&telemetry(1)));
        let faults = Reply::Faults {
            active: FaultFlags::empty(),
            latched: FaultFlags::STALL,
        };
        wire.extend(dev.say(&DeviceMessage::reply(a, faults.clone())));
        s.receive(&wire, ms(1));
        let got = events(&mut s, ms(1));
        assert_eq!(
            got[0],
            Event::Reply {
                seq: b,
                request: Request::GetInfo,
                reply: Reply::Nack(NackCode::Busy)
            }
        );
        assert!(matches!(got[1], Event::Telemetry(_)));
        assert_eq!(
            got[2],
            Event::Reply {
                seq: a,
                request: Request::GetFaults,
                reply: faults
            }
        );
        assert_eq!(got.len(), 3);
        assert_eq!(s.stats().stale_replies, 1);
        assert!(!s.is_pending(a) && !s.is_pending(b));
    }

    #[test]
    fn only_retry_safe_requests_are_sent_again() {
        let config = SessionConfig {
            reply_timeout: ms(100),
            retries: 2,
        };
        let mut s = Session::new(config);
        let (info, _) = s.send(Request::GetInfo, ms(0));
        let capture = Request::StartCapture {
            sample_rate_hz: 10_000,
            samples: 10,
        };
        let (cap, _) = s.send(capture.clone(), ms(0));
        assert_eq!(s.poll_timeout(), Some(ms(100)));
        assert!(s.poll_transmit(ms(99)).is_none());
        // At the timeout: GetInfo again with its own seq, StartCapture given up.
        let retry = s.poll_transmit(ms(100)).unwrap();
        assert_eq!(Device::default().requests(&retry)[0].seq, info);
        assert_eq!(
            s.poll(ms(100)),
            Some(Event::Timeout {
                seq: cap,
                request: capture,
                tries: 1
            })
        );
        s.poll_transmit(ms(200)).unwrap();
        assert!(s.poll(ms(250)).is_none());
        assert_eq!(
            s.poll(ms(300)),
            Some(Event::Timeout {
                seq: info,
                request: Request::GetInfo,
                tries: 3
            })
        );
        assert_eq!(s.stats().retries, 2);
        // A late answer to a finished request is stale.
        let mut dev = Device::default();
        s.receive(&dev.say(&DeviceMessage::ack(info)), ms(301));
        assert!(s.poll(ms(301)).is_none());
        assert_eq!(s.stats().stale_replies, 1);
    }

    #[test]
    fn a_heartbeat_never_waits_behind_a_full_window_of_queries() {
        let mut s = Session::default().with_id(5);
        let mut dev = Device::default();
        s.keep_alive(Some(ms(150)), ms(0));
        let on_wire = (0..REQUEST_WINDOW)
            .filter(|_| !s.send(Request::GetFaults, ms(0)).1.is_empty())
            .count();
        assert_eq!(on_wire, REQUEST_WINDOW - 1, "one place kept for heartbeats");
        // No reply yet: the heartbeat still goes out when due.
        let mut beats = 0;
        while let Some(bytes) = s.poll_transmit(ms(150)) {
            for f in dev.requests(&bytes) {
                beats += usize::from(f.msg == Request::Heartbeat { session: 5 });
            }
        }
        assert_eq!(beats, 1);
    }

    #[test]
    fn heartbeats_keep_their_interval_when_no_reply_comes_back() {
        // Replies stuck behind a busy link: three queries and every heartbeat unanswered
        // for two seconds; the device must still receive a heartbeat every interval.
        let mut s = Session::default().with_id(7);
        let mut dev = Device::default();
        s.keep_alive(Some(ms(150)), ms(0));
        for _ in 0..REQUEST_WINDOW - 1 {
            s.send(Request::GetFaults, ms(0));
        }
        let mut beats = Vec::new();
        for t in (0..=2000).step_by(10) {
            while let Some(bytes) = s.poll_transmit(ms(t)) {
                for f in dev.requests(&bytes) {
                    if f.msg == (Request::Heartbeat { session: 7 }) {
                        beats.push((t, f.seq));
                    }
                }
            }
            while s.poll(ms(t)).is_some() {}
        }
        let times: Vec<u64> = beats.iter().map(|b| b.0).collect();
        assert_eq!(times, (1..=13).map(|k| 150 * k).collect::<Vec<_>>());
        // The late reply to a superseded heartbeat is stale, not an error.
        s.receive(&dev.say(&DeviceMessage::ack(beats[0].1)), ms(2000));
        assert!(s.poll(ms(2000)).is_none());
        assert_eq!(s.stats().stale_replies, 1);
    }

    #[test]
    fn heartbeats_go_out_while_kept_alive_and_their_replies_stay_inside() {
        let mut s = Session::default().with_id(0xA11CE);
        let mut dev = Device::default();
        s.keep_alive(Some(ms(150)), ms(0));
        let mut beats = Vec::new();
        for t in (0..=1000).step_by(10) {
            while let Some(bytes) = s.poll_transmit(ms(t)) {
                for f in dev.requests(&bytes) {
                    assert_eq!(f.msg, Request::Heartbeat { session: 0xA11CE });
                    beats.push(t);
                    // The device refuses every other one.
                    let reply = if beats.len() % 2 == 0 {
                        DeviceMessage::nack(f.seq, NackCode::InFaultHold)
                    } else {
                        DeviceMessage::ack(f.seq)
                    };
                    s.receive(&dev.say(&reply), ms(t));
                }
            }
            assert!(s.poll(ms(t)).is_none(), "heartbeat replies are no events");
        }
        assert_eq!(beats, [150, 300, 450, 600, 750, 900]);
        let stats = s.stats();
        assert_eq!((stats.heartbeats, stats.heartbeats_refused), (6, 3));
        assert_eq!(stats.stale_replies, 0);
        // A shorter interval applies from the last heartbeat.
        s.keep_alive(Some(ms(50)), ms(1000));
        assert!(s.poll_transmit(ms(949)).is_none());
        assert!(s.poll_transmit(ms(950)).is_some());
        s.keep_alive(None, ms(1000));
        assert!(s.poll_transmit(ms(5000)).is_none());
    }

    #[test]
    fn a_v1_device_is_identified_and_its_hello_finished() {
        let mut s = Session::default();
        let mut dev = Device::default();
        let (hello, _) = s.send(Session::hello(), ms(0));
        s.receive(&dev.say(&LegacyV1Nack { hello_seq: hello }), ms(2));
        let peer = PeerIdentity {
            protocol_version: 1,
            schema_hash: None,
        };
        assert_eq!(
            s.poll(ms(2)),
            Some(Event::PeerVersion {
                seq: Some(hello),
                peer
            })
        );
        assert!(!s.is_pending(hello));
        let text = peer_error(peer).to_string();
        assert!(
            text.contains("run `rig flash` to update the firmware"),
            "{text}"
        );
        // No retry, no timeout later.
        assert!(s.poll_transmit(ms(10_000)).is_none());
        assert!(s.poll(ms(10_000)).is_none());
    }

    #[test]
    fn hello_outcome_says_which_side_to_update() {
        let newer = Reply::Nack(NackCode::VersionMismatch {
            device_protocol: PROTOCOL_VERSION + 1,
            device_schema_hash: 5,
        });
        let text = hello_outcome(&newer).unwrap().unwrap_err().to_string();
        assert!(text.contains("update the rig tool"), "{text}");
        assert!(hello_outcome(&Reply::Ack).is_none());
        // The same version refused (a schema mismatch the device could not tell apart).
        let same = Reply::Nack(NackCode::VersionMismatch {
            device_protocol: PROTOCOL_VERSION,
            device_schema_hash: SCHEMA_HASH,
        });
        assert!(hello_outcome(&same).unwrap().is_err());
    }

    #[test]
    fn noise_between_frames_costs_no_frame_and_is_reported() {
        let mut s = Session::default();
        let mut dev = Device::default();
        let (seq, _) = s.send(Request::Heartbeat { session: 0 }, ms(0));
        let mut wire = vec![0x37, 0x99];
        wire.extend(dev.say(&telemetry(1)));
        wire.extend([0x12, 0x00, 0x55]);
        wire.extend(dev.say(&telemetry(3)));
        wire.push(0x42);
        wire.extend(dev.say(&DeviceMessage::ack(seq)));
        // Any chunking.
        for chunk in wire.chunks(5) {
            s.receive(chunk, ms(1));
        }
        let got = events(&mut s, ms(1));
        let desyncs = got
            .iter()
            .filter(|e| matches!(e, Event::Desync { .. }))
            .count();
        // Four runs of noise (the 0x00 in the middle splits one).
        assert_eq!(desyncs, 4, "{got:?}");
        assert!(got.contains(&Event::Reply {
            seq,
            request: Request::Heartbeat { session: 0 },
            reply: Reply::Ack
        }));
        let stats = s.stats();
        assert_eq!((stats.frames_ok, stats.frame_errors), (3, 4));
        assert_eq!(stats.telemetry_lost, 1);
        assert_eq!(stats.frames_lost, 0);
    }

    #[test]
    fn the_same_script_runs_in_any_time_base() {
        // Virtual time in microsecond steps or wall-clock-like jumps: the same outcome.
        for step in [Duration::from_micros(250), ms(40)] {
            let mut s = Session::new(SessionConfig {
                reply_timeout: ms(200),
                retries: 1,
            });
            let (seq, _) = s.send(Request::GetFaults, Duration::ZERO);
            let mut now = Duration::ZERO;
            let mut sent = 1;
            let mut outcome = None;
            while outcome.is_none() {
                now += step;
                sent += std::iter::from_fn(|| s.poll_transmit(now)).count();
                outcome = s.poll(now);
            }
            assert_eq!(sent, 2);
            assert!(matches!(outcome, Some(Event::Timeout { seq: s, tries: 2, .. }) if s == seq));
            assert!(now >= ms(400) && now < ms(400) + step + step);
        }
    }
}
