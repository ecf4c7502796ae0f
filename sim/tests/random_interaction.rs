//! Random interaction between the host's sans-IO session and the virtual rig's device side,
//! in the style of quinn-proto's proptests: a random script of requests, heartbeats, frames
//! dropped, duplicated, reordered or corrupted on the line, noise, a second client that
//! ignores the request window, fault injections on the plant and time advanced in steps,
//! with the device contract checked after every millisecond of virtual time.
//!
//! The checks use only what crosses the wire (the device's own output, before the line
//! spoils it, and the bytes the device really received), not the core's reasoning:
//!
//! * exactly one reply per request frame the device received intact (or intact but with
//!   a bad field), every one within the control period; the request that finds
//!   [`REQUEST_WINDOW`] replies still queued is answered `Busy`, one inside the window never
//!   `Busy` unless its own rules allow it; a reply's kind is its request's;
//! * the bridge drives the motor only while a release (or open-loop drive) that the device
//!   accepted is live: no lock, no fault and no comms lapse since, and the device's release
//!   state is what the wire says it is;
//! * without an accepted drive request (`Release`, `OpenLoop`, `Heartbeat`: every client
//!   here is one session) for the comms timeout (+ one control period) a live release
//!   ends in the safe state with `COMMS_TIMEOUT` latched, and never earlier;
//! * latched faults only grow while time passes and drop only at an accepted `ClearFaults`;
//!   every fault that rises is announced by a `FaultEvent` in the same control period;
//! * the session keeps at most the window outstanding, ends every request it sent exactly
//!   once (a reply the device really sent for that `seq`, or a timeout), and, once the
//!   line is clean again, gets every reply.
//!
//! `cargo test -p sim --test random_interaction` runs a fixed number of short scripts (a
//! few seconds); the `#[ignore]`d batch runs many more, longer ones.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use proptest::prelude::*;
use protocol::session::{Event, Session, SessionConfig};
use protocol::{
    COMMS_TIMEOUT_MS, DeviceDeframer, DeviceMessage, Error, FaultFlags, Frame, NackCode,
    REQUEST_WINDOW, Reply, Request, RequestDeframer, SimCommand, encode_frame_vec,
};
use sim::{Injections, SimConfig, SimRig};

/// The virtual rig's control period, us (1 kHz: `CoreConfig::default`).
const PERIOD_US: u64 = 1000;
const COMMS_TIMEOUT_US: u64 = COMMS_TIMEOUT_MS as u64 * 1000;
/// Sequence numbers of the second client's frames (the session's start at 0).
const ROGUE_SEQ: u16 = 0x8000;

/// A frame the second client writes: a request, or an intact frame (valid CRC) whose body
/// is not a request of this version.
#[derive(Debug, Clone)]
enum Rogue {
    Request(Request),
    /// `Release` with a bool of 2: a known request with a bad field.
    BadBool,
    /// A `Release` cut after its tag.
    Truncated,
    /// A request tag past the last.
    UnknownTag,
}

/// Where a fault is injected on the plant side.
#[derive(Debug, Clone, Copy)]
enum Inject {
    Nothing,
    EncoderFrozen,
    EncoderReversed,
    CurrentStuck(u16),
}

/// One step of a script.
#[derive(Debug, Clone)]
enum Op {
    /// The session sends a request.
    Send(Request),
    /// The second client writes frames in one go, ignoring the window.
    Burst(Vec<Rogue>),
    /// Virtual time passes in 1 ms steps; the line carries frames each way or holds them.
    Advance { ms: u16, up: bool, down: bool },
    /// The session keeps a release alive, or stops (a host that goes quiet).
    KeepAlive(bool),
    /// The frames waiting host to device are written now.
    Deliver,
    /// A frame on the line is lost.
    Drop { down: bool, at: usize },
    /// A frame on the line arrives twice.
    Duplicate { down: bool, at: usize },
    /// Two frames on the line swap places.
    Swap { down: bool, a: usize, b: usize },
    /// One bit of a frame on the line flips.
    Corrupt {
        down: bool,
        at: usize,
        byte: usize,
        bit: u8,
    },
    /// Noise bytes on the line.
    Noise { down: bool, bytes: Vec<u8> },
    /// A fault on the plant side (or none).
    Inject(Inject),
}

/// What the reply to one delivered frame must be.
#[derive(Debug, Clone)]
struct Delivery {
    at_us: u64,
    /// The request, when the frame decoded.
    request: Option<Request>,
    /// Beyond the window: `Busy`.
    beyond_window: bool,
    /// The refusal an intact frame that is not a request gets.
    refusal: Option<NackCode>,
}

/// The session's requests and how each ended.
#[derive(Debug, Default)]
struct SessionLedger {
    sent: BTreeMap<u16, (Request, u32)>,
}

/// The virtual rig, the session, the line between them and the oracle.
struct World {
    rig: SimRig,
    session: Session,
    /// Frames (or noise) on the line, host to device and device to host.
    up: VecDeque<Vec<u8>>,
    down: VecDeque<Vec<u8>>,
    /// What the device received, decoded as the device decodes it.
    mirror: RequestDeframer,
    /// What the device sent, before the line.
    device_out: DeviceDeframer,
    /// What the session wrote, before the line, and how often it wrote each `seq`.
    host_out: RequestDeframer,
    tries: BTreeMap<u16, u32>,
    /// Delivered frames waiting for their reply, per `seq`, oldest first.
    waiting: BTreeMap<u16, VecDeque<Delivery>>,
    /// Every reply the device sent, per `seq`.
    replies: BTreeMap<u16, Vec<Reply>>,
    /// The control period the last frames were delivered in, and the replies queued in it.
    period: u64,
    queued_in_period: usize,
    /// The release as the wire says it is.
    host_release: bool,
    open_loop: bool,
    last_accepted_us: u64,
    latched: FaultFlags,
    /// Fault events seen in the current period.
    announced: FaultFlags,
    ledger: SessionLedger,
    rogue_seq: u16,
    /// Counters, to see that a batch exercised what it claims to.
    stats: Stats,
}

/// What a script did.
#[derive(Debug, Default, Clone, Copy)]
struct Stats {
    busy_beyond_window: u32,
    driven_ms: u32,
    comms_timeouts: u32,
    clears: u32,
}

fn now_of(rig: &SimRig) -> Duration {
    Duration::from_micros(rig.now_us())
}

/// Hand-made frame of `body` (CRC-32 and COBS as `protocol` frames it): for bodies no
/// encoder of this version writes.
fn seal(body: &[u8]) -> Vec<u8> {
    let mut raw = body.to_vec();
    raw.extend(protocol::crc32::checksum(body).to_le_bytes());
    // COBS: each block's length code replaces the zero that ends it.
    let mut out = vec![0u8, 0];
    let mut code_at = 1;
    for &b in &raw {
        if b != 0 {
            out.push(b);
        }
        let code = out.len() - code_at;
        if b == 0 || code == 0xFF {
            out[code_at] = code as u8;
            code_at = out.len();
            out.push(0);
        }
    }
    out[code_at] = (out.len() - code_at) as u8;
    out.push(0);
    out
}

/// The same message, NaN fields included (compared by their wire bytes).
fn same<M: serde::Serialize>(a: &M, b: &M) -> bool {
    encode_frame_vec(0, a).ok() == encode_frame_vec(0, b).ok()
}

fn rogue_frame(seq: u16, rogue: &Rogue) -> Vec<u8> {
    // postcard: the seq as a varint, then the variant tag as a varint.
    let mut body = Vec::new();
    let mut s = u32::from(seq);
    loop {
        let b = (s & 0x7F) as u8;
        s >>= 7;
        if s == 0 {
            body.push(b);
            break;
        }
        body.push(b | 0x80);
    }
    const RELEASE_TAG: u8 = 2;
    match rogue {
        Rogue::Request(r) => return encode_frame_vec(seq, r).expect("a request encodes"),
        Rogue::BadBool => body.extend([RELEASE_TAG, 2, 0, 0, 0x20, 0x41]),
        Rogue::Truncated => body.push(RELEASE_TAG),
        Rogue::UnknownTag => body.push(100),
    }
    seal(&body)
}

/// Whether `request` may be refused with `Busy` by its own rules (a drive running, a
/// capture or measurement in progress), not only beyond the window.
fn may_be_busy(request: &Request) -> bool {
    matches!(
        request,
        Request::Release { on: true, .. }
            | Request::OpenLoop { .. }
            | Request::StartCapture { .. }
            | Request::RezeroCurrent
            | Request::SetParameters(_)
    )
}

impl World {
    fn new() -> Self {
        let mut rig = SimRig::new(SimConfig::paper());
        let mut mirror = RequestDeframer::new();
        rig.to_device(&Session::OPENING);
        mirror.push(&Session::OPENING, |_| {});
        Self {
            rig,
            session: Session::new(SessionConfig::default()),
            up: VecDeque::new(),
            down: VecDeque::new(),
            mirror,
            device_out: DeviceDeframer::new(),
            host_out: RequestDeframer::new(),
            tries: BTreeMap::new(),
            waiting: BTreeMap::new(),
            replies: BTreeMap::new(),
            period: 0,
            queued_in_period: 0,
            host_release: false,
            open_loop: false,
            last_accepted_us: 0,
            latched: FaultFlags::empty(),
            announced: FaultFlags::empty(),
            ledger: SessionLedger::default(),
            rogue_seq: ROGUE_SEQ,
            stats: Stats::default(),
        }
    }

    fn line(&mut self, down: bool) -> &mut VecDeque<Vec<u8>> {
        if down { &mut self.down } else { &mut self.up }
    }

    fn run(&mut self, op: &Op) -> Result<(), TestCaseError> {
        match op {
            Op::Send(request) => {
                let (seq, bytes) = self.session.send(request.clone(), now_of(&self.rig));
                prop_assert!(
                    self.ledger.sent.insert(seq, (request.clone(), 0)).is_none(),
                    "the session reused seq {seq}"
                );
                self.host_wrote(bytes)?;
                prop_assert!(self.session.outstanding() <= REQUEST_WINDOW);
            }
            Op::Burst(frames) => {
                let mut wire = Vec::new();
                for rogue in frames {
                    wire.extend(rogue_frame(self.rogue_seq, rogue));
                    self.rogue_seq = self.rogue_seq.wrapping_add(1) | ROGUE_SEQ;
                }
                self.deliver(&wire)?;
            }
            Op::Advance { ms, up, down } => {
                for _ in 0..*ms {
                    self.tick(*up, *down)?;
                }
            }
            Op::KeepAlive(on) => {
                let interval =
                    on.then(|| Duration::from_millis(u64::from(protocol::HEARTBEAT_INTERVAL_MS)));
                self.session.keep_alive(interval, now_of(&self.rig));
            }
            Op::Deliver => self.deliver_up()?,
            Op::Drop { down, at } => {
                let line = self.line(*down);
                if !line.is_empty() {
                    let at = at % line.len();
                    line.remove(at);
                }
            }
            Op::Duplicate { down, at } => {
                let line = self.line(*down);
                if !line.is_empty() {
                    let at = at % line.len();
                    let copy = line[at].clone();
                    line.insert(at + 1, copy);
                }
            }
            Op::Swap { down, a, b } => {
                let line = self.line(*down);
                if !line.is_empty() {
                    let n = line.len();
                    line.swap(a % n, b % n);
                }
            }
            Op::Corrupt {
                down,
                at,
                byte,
                bit,
            } => {
                let line = self.line(*down);
                if !line.is_empty() {
                    let at = at % line.len();
                    let frame = &mut line[at];
                    let byte = byte % frame.len();
                    frame[byte] ^= 1 << (bit % 8);
                }
            }
            Op::Noise { down, bytes } => self.line(*down).push_back(bytes.clone()),
            Op::Inject(inject) => self.rig.inject(match *inject {
                Inject::Nothing => Injections::default(),
                Inject::EncoderFrozen => Injections {
                    encoder_frozen: true,
                    ..Injections::default()
                },
                Inject::EncoderReversed => Injections {
                    encoder_reversed: true,
                    ..Injections::default()
                },
                Inject::CurrentStuck(code) => Injections {
                    current_adc_stuck: Some(code),
                    ..Injections::default()
                },
            }),
        }
        Ok(())
    }

    /// One millisecond: the session's due frames onto the line, the line's frames to the
    /// device (when `up`), one control period, the device's output checked and put on the
    /// line, and to the session (when `down`).
    fn tick(&mut self, up: bool, down: bool) -> Result<(), TestCaseError> {
        let now = now_of(&self.rig);
        while let Some(bytes) = self.session.poll_transmit(now) {
            self.host_wrote(bytes)?;
        }
        if up {
            self.deliver_up()?;
        }
        self.rig.advance(1e-3);
        self.device_output()?;
        self.check_release_and_faults()?;
        if down {
            self.deliver_down()?;
        }
        prop_assert!(self.session.outstanding() <= REQUEST_WINDOW);
        Ok(())
    }

    /// The session wrote `bytes`: onto the line. A request goes out again only when it is
    /// safe to repeat, and no more often than the retries allow.
    fn host_wrote(&mut self, bytes: Vec<u8>) -> Result<(), TestCaseError> {
        if bytes.is_empty() {
            return Ok(());
        }
        let mut frames = Vec::new();
        self.host_out.push(&bytes, |f| frames.push(f));
        prop_assert_eq!(frames.len(), 1, "one frame per write");
        let Ok(Frame { seq, msg }) = frames.remove(0) else {
            return Err(TestCaseError::fail("the session wrote a bad frame"));
        };
        let tries = self.tries.entry(seq).or_default();
        *tries += 1;
        let allowed = if msg.retry_safe() {
            1 + self.session.config().retries
        } else {
            1
        };
        prop_assert!(
            *tries <= allowed,
            "{} (seq {seq}) written {tries} times",
            msg.name()
        );
        self.up.push_back(bytes);
        Ok(())
    }

    fn deliver_up(&mut self) -> Result<(), TestCaseError> {
        while let Some(bytes) = self.up.pop_front() {
            self.deliver(&bytes)?;
        }
        Ok(())
    }

    /// Writes `bytes` to the device, noting what each frame in them must be answered with,
    /// and checks that latched faults drop only at an accepted `ClearFaults`.
    fn deliver(&mut self, bytes: &[u8]) -> Result<(), TestCaseError> {
        let now = self.rig.now_us();
        let period = now / PERIOD_US;
        if period != self.period {
            // The control step between drained the transmit queue.
            self.period = period;
            self.queued_in_period = 0;
        }
        let mut clears = false;
        for &byte in bytes {
            let (seq, request, refusal) = match self.mirror.push_byte(byte) {
                None => continue,
                Some(Ok(Frame { seq, msg })) => (seq, Some(msg), None),
                Some(Err(Error::Decode { seq: Some(seq) })) => {
                    // Read now: the body of this frame, as the device reads it.
                    let known = self
                        .mirror
                        .last_body()
                        .is_some_and(Request::names_known_request);
                    let code = if known {
                        NackCode::BadArgument
                    } else {
                        NackCode::UnknownMessage
                    };
                    (seq, None, Some(code))
                }
                // Garbled: no reply.
                Some(Err(_)) => continue,
            };
            let beyond_window = self.queued_in_period >= REQUEST_WINDOW;
            clears |= !beyond_window && request == Some(Request::ClearFaults);
            self.queued_in_period += 1;
            self.waiting.entry(seq).or_default().push_back(Delivery {
                at_us: now,
                request,
                beyond_window,
                refusal,
            });
        }
        let status = self.rig.core().status();
        let (before, active) = (status.latched_faults, status.active_faults);
        self.rig.to_device(bytes);
        let after = self.rig.core().status().latched_faults;
        prop_assert!(
            after.difference(before).is_empty(),
            "faults rose on receiving bytes: {after:?} from {before:?}"
        );
        if after != before {
            prop_assert!(
                clears,
                "latched faults {before:?} became {after:?} without an accepted ClearFaults"
            );
            prop_assert!(
                !before.difference(after).intersects(active),
                "ClearFaults cleared a fault whose condition is present: {before:?} -> {after:?} with {active:?} active"
            );
            self.stats.clears += 1;
        }
        self.latched = after;
        Ok(())
    }

    /// Reads what the device sent in the last period: every reply matched to the frame it
    /// answers, fault events noted; then onto the line, frame by frame.
    fn device_output(&mut self) -> Result<(), TestCaseError> {
        let mut out = Vec::new();
        self.rig.from_device(&mut out);
        let mut messages = Vec::new();
        self.device_out.push(&out, |frame| messages.push(frame));
        self.announced = FaultFlags::empty();
        for message in messages {
            let frame = message.map_err(|e| TestCaseError::fail(format!("device sent {e}")))?;
            match frame.msg {
                DeviceMessage::Reply { request_seq, reply } => self.reply(request_seq, reply)?,
                DeviceMessage::FaultEvent { flags, .. } => self.announced.insert(flags),
                _ => {}
            }
        }
        for (seq, left) in &self.waiting {
            prop_assert!(
                left.is_empty(),
                "request seq {seq} got no reply within a control period: {left:?}"
            );
        }
        // Whole frames (the queue takes them whole), each `0x00 COBS 0x00`.
        for body in out.split(|&b| b == 0).filter(|b| !b.is_empty()) {
            let mut frame = vec![0];
            frame.extend_from_slice(body);
            frame.push(0);
            self.down.push_back(frame);
        }
        Ok(())
    }

    fn reply(&mut self, seq: u16, reply: Reply) -> Result<(), TestCaseError> {
        let delivery = self.waiting.get_mut(&seq).and_then(VecDeque::pop_front);
        let Some(d) = delivery else {
            return Err(TestCaseError::fail(format!(
                "reply {} to seq {seq}, which has no delivered frame left to answer",
                reply.name()
            )));
        };
        let busy = reply == Reply::Nack(NackCode::Busy);
        if d.beyond_window {
            prop_assert!(busy, "seq {seq} beyond the window got {reply:?}");
            self.stats.busy_beyond_window += 1;
        } else if let Some(code) = d.refusal {
            prop_assert_eq!(&reply, &Reply::Nack(code), "seq {}", seq);
        } else if let Some(request) = &d.request {
            prop_assert!(
                !busy || may_be_busy(request),
                "{} (seq {seq}) within the window got Busy",
                request.name()
            );
            prop_assert!(
                request.is_answered_by(&reply),
                "{} answered by {}",
                request.name(),
                reply.name()
            );
        }
        let accepted = !matches!(reply, Reply::Nack(_));
        // Only drive requests refresh a release (the owner's: every client here is session 0).
        let drive = d.request.as_ref().and_then(Request::session).is_some();
        if accepted && drive {
            self.last_accepted_us = self.last_accepted_us.max(d.at_us);
        }
        if accepted {
            match d.request {
                Some(Request::Release { on: true, .. }) => self.host_release = true,
                Some(Request::Release { on: false, .. }) => {
                    self.host_release = false;
                    self.open_loop = false;
                }
                Some(Request::OpenLoop { volts, .. }) => self.open_loop = volts != 0.0,
                _ => {}
            }
        }
        self.replies.entry(seq).or_default().push(reply);
        Ok(())
    }

    /// The release and fault rules, after a control period.
    fn check_release_and_faults(&mut self) -> Result<(), TestCaseError> {
        let t = self.rig.now_us();
        let status = self.rig.core().status();
        let latched = status.latched_faults;
        let risen = latched.difference(self.latched);
        let dropped = self.latched.difference(latched);
        prop_assert!(
            dropped.is_empty(),
            "{dropped:?} unlatched with no request at {t} us"
        );
        prop_assert!(
            self.announced.contains(risen),
            "{risen:?} rose at {t} us but the device announced {:?}",
            self.announced
        );
        let live = self.host_release || self.open_loop;
        let quiet_us = t.saturating_sub(self.last_accepted_us);
        if risen.contains(FaultFlags::COMMS_TIMEOUT) {
            prop_assert!(live, "COMMS_TIMEOUT at {t} us with no live release");
            prop_assert!(
                quiet_us > COMMS_TIMEOUT_US,
                "COMMS_TIMEOUT at {t} us, {quiet_us} us after an accepted request"
            );
            self.stats.comms_timeouts += 1;
        } else if live {
            prop_assert!(
                quiet_us <= COMMS_TIMEOUT_US + PERIOD_US,
                "a release live {quiet_us} us after the last accepted request, no COMMS_TIMEOUT: {risen:?}"
            );
        }
        if !risen.is_empty() {
            // Any fault drops every release.
            self.host_release = false;
            self.open_loop = false;
        }
        self.latched = latched;
        prop_assert_eq!(
            (status.host_release, status.open_loop_volts.is_some()),
            (self.host_release, self.open_loop),
            "device release state (host, open loop) against the wire's at {} us",
            t
        );
        if status.enabled {
            prop_assert!(
                self.host_release || self.open_loop,
                "the bridge drives with no live release at {t} us"
            );
            prop_assert!(latched.is_empty(), "the bridge drives with {latched:?}");
            self.stats.driven_ms += 1;
        }
        Ok(())
    }

    /// The line's frames to the session; every event it makes checked against the device.
    fn deliver_down(&mut self) -> Result<(), TestCaseError> {
        let now = now_of(&self.rig);
        while let Some(bytes) = self.down.pop_front() {
            self.session.receive(&bytes, now);
        }
        while let Some(event) = self.session.poll(now) {
            match event {
                Event::Reply {
                    seq,
                    request,
                    reply,
                } => {
                    let entry = self.ledger.sent.get_mut(&seq);
                    let Some((sent, ends)) = entry else {
                        return Err(TestCaseError::fail(format!("reply to unsent seq {seq}")));
                    };
                    prop_assert!(
                        same(&request, sent),
                        "seq {seq}: {request:?} sent as {sent:?}"
                    );
                    *ends += 1;
                    prop_assert_eq!(*ends, 1, "seq {} ended twice", seq);
                    let sent_replies = self.replies.get(&seq).map_or(&[][..], Vec::as_slice);
                    prop_assert!(
                        sent_replies.iter().any(|r| same(r, &reply)),
                        "the session reports {reply:?} for seq {seq}; the device sent {sent_replies:?}"
                    );
                }
                Event::Timeout { seq, .. } => {
                    let entry = self.ledger.sent.get_mut(&seq);
                    let Some((_, ends)) = entry else {
                        return Err(TestCaseError::fail(format!("timeout of unsent seq {seq}")));
                    };
                    *ends += 1;
                    prop_assert_eq!(*ends, 1, "seq {} ended twice", seq);
                }
                Event::PeerVersion { .. } => {
                    return Err(TestCaseError::fail(
                        "a device of this version was taken for another".to_string(),
                    ));
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// A clean line from now on: everything the session sent ends, and a full window of
    /// requests gets its replies.
    fn settle(&mut self) -> Result<(), TestCaseError> {
        self.session.keep_alive(None, now_of(&self.rig));
        let config = self.session.config();
        let every_try = config.reply_timeout * (config.retries + 1);
        let ms = every_try.as_millis() as u64 + 20;
        for _ in 0..ms {
            self.tick(true, true)?;
        }
        for (seq, (request, ends)) in &self.ledger.sent {
            prop_assert_eq!(*ends, 1, "{} (seq {}) never ended", request.name(), seq);
        }
        let mut seqs = Vec::new();
        for _ in 0..REQUEST_WINDOW {
            let (seq, bytes) = self.session.send(Request::GetInfo, now_of(&self.rig));
            self.ledger.sent.insert(seq, (Request::GetInfo, 0));
            self.host_wrote(bytes)?;
            seqs.push(seq);
        }
        self.tick(true, true)?;
        self.tick(true, true)?;
        for seq in seqs {
            let replies = self.replies.get(&seq).map_or(&[][..], Vec::as_slice);
            prop_assert!(
                matches!(replies, [Reply::Info(_)]),
                "GetInfo within the window on a clean line: {replies:?}"
            );
            prop_assert_eq!(self.ledger.sent[&seq].1, 1);
        }
        Ok(())
    }
}

fn request() -> impl Strategy<Value = Request> {
    let hz = prop_oneof![
        Just(5.0f32),
        Just(10.0),
        Just(15.0),
        Just(0.5),
        Just(1e3),
        Just(f32::NAN)
    ];
    let volts = prop_oneof![
        Just(0.0f32),
        Just(3.6),
        Just(-3.6),
        Just(6.2),
        Just(100.0),
        Just(f32::NAN)
    ];
    let load = prop_oneof![Just(0.0f32), Just(0.5), Just(1.84), Just(3.68), Just(-5.0)];
    prop_oneof![
        6 => Just(Request::Heartbeat { session: 0 }),
        1 => Just(Request::GetInfo),
        2 => Just(Request::GetFaults),
        3 => Just(Request::ClearFaults),
        1 => Just(Session::hello()),
        1 => Just(Request::Hello { protocol_version: protocol::PROTOCOL_VERSION + 1, schema_hash: 7 }),
        6 => (any::<bool>(), hz).prop_map(|(on, target_hz)| Request::Release { on, target_hz, session: 0 }),
        2 => volts.prop_map(|volts| Request::OpenLoop { volts, session: 0 }),
        1 => prop_oneof![Just(1u16), Just(100), Just(1000), Just(300), Just(0)]
            .prop_map(|rate_hz| Request::StartTelemetry { rate_hz }),
        1 => Just(Request::StopTelemetry),
        1 => prop_oneof![Just((10_000u16, 500u32)), Just((1000, 50)), Just((333, 10)), Just((10_000, 20_000))]
            .prop_map(|(sample_rate_hz, samples)| Request::StartCapture { sample_rate_hz, samples }),
        1 => Just(Request::RezeroCurrent),
        1 => Just(Request::GetParameters),
        1 => load.prop_map(|tau_rot_nm| Request::Simulation(SimCommand::SetLoad { tau_rot_nm })),
    ]
}

fn rogue() -> impl Strategy<Value = Rogue> {
    prop_oneof![
        6 => request().prop_map(Rogue::Request),
        1 => Just(Rogue::BadBool),
        1 => Just(Rogue::Truncated),
        1 => Just(Rogue::UnknownTag),
    ]
}

fn op() -> impl Strategy<Value = Op> {
    let line = prop_oneof![Just(false), Just(true)];
    prop_oneof![
        10 => request().prop_map(Op::Send),
        2 => prop::collection::vec(rogue(), 1..=2 * REQUEST_WINDOW + 2).prop_map(Op::Burst),
        12 => (prop_oneof![1u16..20, 20u16..200, 200u16..700], prop::bool::weighted(0.85), prop::bool::weighted(0.85))
            .prop_map(|(ms, up, down)| Op::Advance { ms, up, down }),
        4 => any::<bool>().prop_map(Op::KeepAlive),
        2 => Just(Op::Deliver),
        2 => (line.clone(), any::<usize>()).prop_map(|(down, at)| Op::Drop { down, at }),
        2 => (line.clone(), any::<usize>()).prop_map(|(down, at)| Op::Duplicate { down, at }),
        2 => (line.clone(), any::<usize>(), any::<usize>()).prop_map(|(down, a, b)| Op::Swap { down, a, b }),
        2 => (line.clone(), any::<usize>(), any::<usize>(), any::<u8>())
            .prop_map(|(down, at, byte, bit)| Op::Corrupt { down, at, byte, bit }),
        1 => (line, prop::collection::vec(any::<u8>(), 1..12)).prop_map(|(down, bytes)| Op::Noise { down, bytes }),
        1 => prop_oneof![
            3 => Just(Inject::Nothing),
            1 => Just(Inject::EncoderFrozen),
            1 => Just(Inject::EncoderReversed),
            1 => prop_oneof![Just(0u16), Just(4095)].prop_map(Inject::CurrentStuck),
        ].prop_map(Op::Inject),
    ]
}

/// Runs `script` and settles; returns what it exercised.
fn play(script: &[Op]) -> Result<Stats, TestCaseError> {
    let mut world = World::new();
    // Let the current zero settle so releases can start.
    world.run(&Op::Advance {
        ms: 300,
        up: true,
        down: true,
    })?;
    for op in script {
        world.run(op)?;
    }
    world.run(&Op::Inject(Inject::Nothing))?;
    world.settle()?;
    Ok(world.stats)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn the_device_contract_holds_under_random_interaction(
        script in prop::collection::vec(op(), 1..60)
    ) {
        play(&script)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    /// Many more and longer scripts (minutes).
    #[test]
    #[ignore]
    fn the_device_contract_holds_under_random_interaction_batch(
        script in prop::collection::vec(op(), 1..200)
    ) {
        play(&script)?;
    }
}

/// A script that drives every invariant's both sides: released with heartbeats (driven),
/// a window overrun, a stalled host (comms timeout), the latch and its clearing.
#[test]
fn a_known_script_exercises_every_rule() {
    let release = Request::Release {
        on: true,
        target_hz: 10.0,
        session: 0,
    };
    let script = [
        Op::Send(release.clone()),
        Op::KeepAlive(true),
        Op::Advance {
            ms: 1500,
            up: true,
            down: true,
        },
        Op::Burst(vec![Rogue::Request(Request::GetFaults); 2 * REQUEST_WINDOW]),
        Op::Burst(vec![Rogue::BadBool, Rogue::UnknownTag, Rogue::Truncated]),
        // The host stalls: its heartbeats pile up on the line.
        Op::Advance {
            ms: 800,
            up: false,
            down: true,
        },
        Op::Deliver,
        Op::KeepAlive(false),
        Op::Advance {
            ms: 600,
            up: true,
            down: true,
        },
        Op::Send(Request::ClearFaults),
        Op::Advance {
            ms: 5,
            up: true,
            down: true,
        },
    ];
    let stats = play(&script).unwrap_or_else(|e| panic!("{e}"));
    assert!(stats.driven_ms > 500, "{stats:?}");
    assert!(
        stats.busy_beyond_window >= REQUEST_WINDOW as u32,
        "{stats:?}"
    );
    assert_eq!(stats.comms_timeouts, 1, "{stats:?}");
    assert!(stats.clears >= 1, "{stats:?}");
}
