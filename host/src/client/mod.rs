//! The device client: a session with the rig's firmware over any `Read + Write` byte
//! stream (a serial port, the virtual device's pseudo-terminal, an in-memory pipe).
//!
//! The protocol logic is [`protocol::session::Session`], the sans-IO session the
//! simulator's link drives too; this client adds the port and the wall clock:
//!
//! - [`Client::connect`] says `Hello` and refuses a device of another protocol version or
//!   schema with a message that says which side to update ([`protocol::check_peer`]),
//!   also for a v1 device that can only refuse the `Hello` in v1's own layout.
//! - Requests carry a sequence number and every reply names it: replies are matched by
//!   it, stale replies dropped. A request without a reply in
//!   [`ClientOptions::reply_timeout`] is sent again when it is safe to repeat
//!   ([`protocol::Request::retry_safe`]), up to [`ClientOptions::retries`] times.
//! - Telemetry, health, capture chunks and fault events arrive unsolicited; they queue
//!   until [`Client::recv`] (or [`Client::next_telemetry`], [`Client::capture`]) takes them.
//! - While a release or an open-loop drive is live, every wait inside the client sends a
//!   `Heartbeat` each [`protocol::HEARTBEAT_INTERVAL_MS`] (divided by the virtual device's
//!   speed), so the device keeps vibrating exactly as long as the host is waiting on it.
//!   [`Client::tick`] does the same for a caller that is busy elsewhere.
//!
//! The pieces: `options` (options, counters), `requests` (the typed requests), `advice`
//! (what to tell the user), `capture` (raw captures), `transport` (serial port and pipe).

mod advice;
mod capture;
mod options;
mod requests;
mod transport;

use std::collections::{HashMap, VecDeque};
use std::io::{self, Read, Write};
use std::time::{Duration, Instant};

use protocol::session::{Event, Session};
use protocol::{DeviceInfo, DeviceMessage, FaultFlags, PeerIdentity, Reply, Request};

pub use advice::nack_advice;
pub use capture::{
    CAPTURE_RATE_HZ, Capture, CaptureProgress, board_sensors, cam_angle_rad, current_amps,
    output_angle_rad,
};
pub use options::{ClientOptions, FaultStatus, LinkStats};
pub use transport::{PipeEnd, SERIAL_READ_TIMEOUT, SerialTransport, memory_pipe, open_serial};

use crate::RigError;

/// Unsolicited messages kept while nobody takes them.
const MAX_QUEUED: usize = 1 << 16;

/// How a request ended, as the session reported it.
#[derive(Debug)]
enum Outcome {
    Reply(Reply),
    Timeout { tries: u32 },
    Peer(PeerIdentity),
}

/// A session with the rig's firmware over `T`.
pub struct Client<T: Read + Write> {
    io: T,
    opts: ClientOptions,
    session: Session,
    /// The session's time origin.
    epoch: Instant,
    outcomes: HashMap<u16, Outcome>,
    inbox: VecDeque<DeviceMessage>,
    fault_events: Vec<(FaultFlags, u64)>,
    read_buf: Vec<u8>,
}

impl<T: Read + Write> std::fmt::Debug for Client<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("port", &self.opts.port_name)
            .field("keep_alive", &self.session.keeping_alive())
            .field("stats", &self.stats())
            .finish()
    }
}

/// A session id no other process on the port is likely to hold: the standard library's
/// randomly keyed hasher over the time, the process id and a count of sessions opened.
fn new_session_id() -> protocol::SessionId {
    use std::hash::{BuildHasher, Hasher};
    use std::sync::atomic::{AtomicU32, Ordering};
    static OPENED: AtomicU32 = AtomicU32::new(0);
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    let since_epoch = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    h.write_u128(since_epoch.as_nanos());
    h.write_u32(std::process::id());
    h.write_u32(OPENED.fetch_add(1, Ordering::Relaxed));
    // The low half of the hash; never 0 (what a request carries before a session stamps it).
    (h.finish() & 0xFFFF_FFFF) as u32 | 1
}

impl<T: Read + Write> Client<T> {
    /// A client over `io` that has not said `Hello` yet (see [`Client::connect`]).
    pub fn new(io: T, opts: ClientOptions) -> Self {
        Self {
            io,
            session: Session::new(opts.session_config()).with_id(new_session_id()),
            opts,
            epoch: Instant::now(),
            outcomes: HashMap::new(),
            inbox: VecDeque::new(),
            fault_events: Vec::new(),
            read_buf: vec![0; 4096],
        }
    }

    /// Opens a session: resynchronises the peer's deframer, says `Hello` and checks that
    /// the device speaks this tool's protocol version and schema.
    pub fn connect(io: T, opts: ClientOptions) -> Result<(Self, DeviceInfo), RigError> {
        let mut client = Self::new(io, opts);
        client.write_bytes(&Session::OPENING)?;
        let info = client.hello()?;
        Ok((client, info))
    }

    /// The options in use.
    pub fn options(&self) -> &ClientOptions {
        &self.opts
    }

    /// Link counters so far.
    pub fn stats(&self) -> LinkStats {
        self.session.stats().into()
    }

    /// Gives the transport back.
    pub fn into_inner(self) -> T {
        self.io
    }

    /// Sends `req` and returns its accepting reply (`Ack`, or the data it asks for). A
    /// `Nack` becomes [`RigError::Refused`]; no reply after the retries,
    /// [`RigError::NoReply`].
    pub fn request(&mut self, req: &Request) -> Result<Reply, RigError> {
        match self.exchange(req)? {
            Reply::Nack(code @ protocol::NackCode::InFaultHold) => {
                // Name the faults that hold the motor off (one more exchange; without an
                // answer the general advice stands).
                let latched = match self.exchange(&Request::GetFaults) {
                    Ok(Reply::Faults { latched, .. }) => Some(latched),
                    _ => None,
                };
                Err(advice::refused_in_fault_hold(req, code, latched))
            }
            Reply::Nack(code) => Err(advice::refused(req, code)),
            reply if req.is_answered_by(&reply) => Ok(reply),
            other => Err(advice::unexpected(req, &other, &self.opts.port_name)),
        }
    }

    /// Serves the link for `wall` (heartbeats, retries, arriving messages) without a
    /// request of its own: a pause between two tries.
    fn pause(&mut self, wall: Duration) -> Result<(), RigError> {
        let end = crate::limits::deadline_after(wall);
        while Instant::now() < end {
            self.pump()?;
        }
        Ok(())
    }

    /// Sends `req` and requires an `Ack`.
    pub fn ack(&mut self, req: &Request) -> Result<(), RigError> {
        match self.request(req)? {
            Reply::Ack => Ok(()),
            other => Err(advice::unexpected(req, &other, &self.opts.port_name)),
        }
    }

    /// Sends `req` and waits for its reply, whatever it is (a `Nack` included).
    fn exchange(&mut self, req: &Request) -> Result<Reply, RigError> {
        let stats_before = self.session.stats();
        let (seq, bytes) = self.session.send(req.clone(), self.now());
        self.write_bytes(&bytes)?;
        loop {
            self.pump()?;
            let Some(outcome) = self.outcomes.remove(&seq) else {
                continue;
            };
            return match outcome {
                Outcome::Reply(reply) => Ok(reply),
                Outcome::Peer(peer) => Err(advice::peer_error(peer)),
                Outcome::Timeout { tries } => {
                    let stats = self.session.stats();
                    let bytes = stats.bytes_in - stats_before.bytes_in;
                    let bad = stats.frame_errors - stats_before.frame_errors;
                    Err(RigError::NoReply {
                        port: self.opts.port_name.clone(),
                        request: req.name(),
                        waited_ms: self.opts.reply_timeout.as_millis() as u64 * u64::from(tries),
                        tries,
                        hint: advice::silence_hint(bytes, bad),
                    })
                }
            };
        }
    }

    /// The session's clock: wall time since the client was made.
    fn now(&self) -> Duration {
        self.epoch.elapsed()
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), RigError> {
        // No flush: on a tty that is tcdrain, which would wait for the peer to read.
        self.io.write_all(bytes).map_err(|e| self.link_error(e))
    }

    fn link_error(&self, source: io::Error) -> RigError {
        RigError::Link {
            port: self.opts.port_name.clone(),
            source,
        }
    }

    /// Sends what is due (heartbeats, retries), reads once (waiting at most the
    /// transport's read timeout), and sorts the session's events.
    fn pump(&mut self) -> Result<(), RigError> {
        let now = self.now();
        if self.session.keeping_alive() {
            // The virtual device's speed may have changed since the release.
            let every = self.opts.heartbeat_interval();
            self.session.keep_alive(Some(every), now);
        }
        self.flush_session(now)?;
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
        let now = self.now();
        if n > 0 {
            self.session.receive(&self.read_buf[..n], now);
        }
        self.flush_session(now)?;
        while let Some(event) = self.session.poll(now) {
            self.route(event);
        }
        Ok(())
    }

    /// Writes the session's due retries and heartbeats.
    fn flush_session(&mut self, now: Duration) -> Result<(), RigError> {
        while let Some(bytes) = self.session.poll_transmit(now) {
            self.write_bytes(&bytes)?;
        }
        Ok(())
    }

    fn queue(&mut self, msg: DeviceMessage) {
        if self.inbox.len() >= MAX_QUEUED {
            // Nobody is reading: forget the oldest rather than grow without end.
            self.inbox.pop_front();
        }
        self.inbox.push_back(msg);
    }

    fn route(&mut self, event: Event) {
        match event {
            Event::Reply { seq, reply, .. } => {
                self.outcomes.insert(seq, Outcome::Reply(reply));
            }
            Event::Timeout { seq, tries, .. } => {
                self.outcomes.insert(seq, Outcome::Timeout { tries });
            }
            Event::PeerVersion {
                seq: Some(seq),
                peer,
            } => {
                self.outcomes.insert(seq, Outcome::Peer(peer));
            }
            Event::Telemetry(t) => self.queue(DeviceMessage::Telemetry(t)),
            Event::Health(h) => self.queue(DeviceMessage::Health(h)),
            Event::CaptureChunk(c) => self.queue(DeviceMessage::CaptureChunk(c)),
            Event::StreamBlock(b) => self.queue(DeviceMessage::StreamBlock(b)),
            Event::CaptureDone {
                capture_id,
                total_samples,
                sample_rate_hz,
            } => self.queue(DeviceMessage::CaptureDone {
                capture_id,
                total_samples,
                sample_rate_hz,
            }),
            Event::FaultEvent {
                flags,
                device_time_us,
            } => {
                self.fault_events.push((flags, device_time_us));
                self.queue(DeviceMessage::FaultEvent {
                    flags,
                    device_time_us,
                });
            }
            // Counted in the session's stats: a garbled frame, or another version's frame
            // that answers nothing waiting.
            Event::Desync { .. } | Event::PeerVersion { seq: None, .. } => {}
        }
    }
}

impl Client<Box<dyn serialport::SerialPort>> {
    /// Opens serial port `port` at the default rate, connects (see [`Client::connect`])
    /// and agrees on `baud` with the device ([`Client::agree_baud`]).
    pub fn open(port: &str, baud: u32) -> Result<(Self, DeviceInfo), RigError> {
        let io = open_serial(port, protocol::DEFAULT_BAUD_RATE)?;
        let (mut client, info) = Self::connect(io, ClientOptions::new(port))?;
        client.agree_baud(&info, baud)?;
        Ok((client, info))
    }

    /// Switches the link from the default rate to `baud` (protocol v8, `SetBaud`): refused
    /// before anything is sent unless it is the default or the device's `max_baud` (its
    /// `Info`). The device answers at the old rate and switches; this side switches its
    /// port and asks `GetInfo` at the new rate. When no answer comes, both go back to
    /// [`protocol::DEFAULT_BAUD_RATE`] (the device after [`protocol::BAUD_CONFIRM_MS`]) and
    /// the error says so; the link then works at the default rate.
    pub fn agree_baud(&mut self, info: &DeviceInfo, baud: u32) -> Result<(), RigError> {
        let default = protocol::DEFAULT_BAUD_RATE;
        if baud == default {
            return Ok(());
        }
        if baud != info.max_baud {
            return Err(RigError::BadValue {
                what: format!("--baud {baud}"),
                why: format!(
                    "{} switches to {} Bd at most (its Info's max_baud) and runs at {default} Bd otherwise: give --baud {} or leave --baud out",
                    self.opts.port_name, info.max_baud, info.max_baud
                ),
            });
        }
        self.ack(&Request::SetBaud { baud })?;
        // The device switches once its Ack has left the line; a moment for the last bytes.
        std::thread::sleep(Duration::from_millis(5));
        let port_err = |e: serialport::Error| RigError::BadValue {
            what: format!("--baud {baud}"),
            why: format!("the serial port refused the rate: {e}; leave --baud out"),
        };
        self.io.set_baud_rate(baud).map_err(port_err)?;
        if self.info().is_ok() {
            return Ok(());
        }
        // Not heard at the new rate: both sides back to the default.
        self.io.set_baud_rate(default).map_err(port_err)?;
        let back_by = Instant::now()
            + Duration::from_millis(u64::from(protocol::BAUD_CONFIRM_MS) * 2)
                .div_f64(self.opts.time_scale.max(1e-9));
        while Instant::now() < back_by {
            if self.info().is_ok() {
                break;
            }
        }
        Err(RigError::BadValue {
            what: format!("--baud {baud}"),
            why: format!(
                "{} did not answer at {baud} Bd (the cable or the ST-LINK's virtual COM port may not carry it): both went back to {default} Bd; leave --baud out",
                self.opts.port_name
            ),
        })
    }
}

#[cfg(test)]
mod tests;
