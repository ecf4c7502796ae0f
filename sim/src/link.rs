//! A host-side session with a [`SimRig`] over the real wire format, in virtual time (the
//! host side of a software-in-the-loop run). It drives the same sans-IO
//! [`protocol::session::Session`] as the serial client, with the rig's clock as its time:
//! requests are framed by the session, fed to the firmware's protocol server, and the
//! device's bytes go back through the session's deframer, reply matching, retries and
//! heartbeats.
//!
//! [`SimLink::set_line_noise`] puts random bytes on the line between frames, in both
//! directions, as a noisy cable would.

use std::collections::BTreeMap;
use std::time::Duration;

use model::plant::NoiseSource;
use protocol::PeerIdentity;
use protocol::session::{Event, Session, SessionConfig, SessionStats};
use protocol::{HealthSample, Reply, Request, TelemetrySample};

use crate::SimError;
use crate::SimRig;

/// Longest a reply may take in virtual time before a retry, s.
const REPLY_TIMEOUT_S: f64 = 0.5;
/// Extra tries of a request that is safe to repeat.
const RETRIES: u32 = 2;
/// Virtual time per polling step while waiting for a reply, s.
const POLL_S: f64 = 0.001;
/// Longest virtual time one step of [`SimLink::wait`] covers, s.
const WAIT_STEP_S: f64 = 0.01;

/// Random bytes on the line between frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineNoise {
    /// Noise bytes per second of virtual time, in each direction.
    pub bytes_per_s: f64,
    /// Seed of the bytes and of their timing.
    pub seed: u64,
}

/// Noise generator state.
struct Noise {
    config: LineNoise,
    rng: NoiseSource,
    /// Bytes owed to each direction (host to device, device to host).
    owed: [f64; 2],
    last_us: u64,
    sent: u64,
}

impl Noise {
    /// The noise bytes due in each direction since the last call.
    fn due(&mut self, now_us: u64) -> [Vec<u8>; 2] {
        let dt = now_us.saturating_sub(self.last_us) as f64 * 1e-6;
        self.last_us = now_us;
        let mut out = [Vec::new(), Vec::new()];
        for (owed, bytes) in self.owed.iter_mut().zip(&mut out) {
            // Poisson-like: a random share of the mean keeps the gaps irregular.
            *owed += dt * self.config.bytes_per_s * 2.0 * self.rng.uniform();
            while *owed >= 1.0 {
                *owed -= 1.0;
                bytes.push((self.rng.next_u64() >> 56) as u8);
            }
        }
        self.sent += (out[0].len() + out[1].len()) as u64;
        out
    }
}

/// How a request ended.
enum Outcome {
    Reply(Reply),
    Timeout { tries: u32 },
    Peer(PeerIdentity),
}

/// A virtual-time host session with a simulated rig.
pub struct SimLink {
    /// The rig.
    pub rig: SimRig,
    session: Session,
    rx: Vec<u8>,
    outcomes: BTreeMap<u16, Outcome>,
    /// The newest telemetry sample seen.
    pub last_telemetry: Option<TelemetrySample>,
    /// The newest health sample seen.
    pub last_health: Option<HealthSample>,
    /// Unsolicited events other than telemetry and health (fault events, capture data),
    /// in arrival order.
    pub events: Vec<Event>,
    noise: Option<Noise>,
}

/// `steps` of `step_s` in seconds as a person writes them: 304 steps of 1 ms are 0.304 s,
/// not the 0.3040000000000002 that adding 0.001 up gives.
fn steps_to_s(steps: u32, step_s: f64) -> f64 {
    let per_s = 1.0 / step_s;
    if (per_s - per_s.round()).abs() < 1e-9 {
        f64::from(steps) / per_s.round()
    } else {
        f64::from(steps) * step_s
    }
}

/// The session id of the simulator's host session.
pub const SIM_SESSION_ID: protocol::SessionId = 0x5133_0001;

impl SimLink {
    /// Opens a session on `rig`.
    pub fn new(rig: SimRig) -> Self {
        let config = SessionConfig {
            reply_timeout: Duration::from_secs_f64(REPLY_TIMEOUT_S),
            retries: RETRIES,
        };
        let mut link = Self {
            rig,
            // One host per virtual rig: a fixed id keeps runs reproducible.
            session: Session::new(config).with_id(SIM_SESSION_ID),
            rx: Vec::new(),
            outcomes: BTreeMap::new(),
            last_telemetry: None,
            last_health: None,
            events: Vec::new(),
            noise: None,
        };
        link.rig.to_device(&Session::OPENING);
        link
    }

    /// The session's clock: the rig's virtual time.
    fn now(&self) -> Duration {
        Duration::from_micros(self.rig.now_us())
    }

    /// Sends `req` and waits (in virtual time, retrying when that is safe) for the reply
    /// with its sequence number. A `Nack` is returned as the reply; no reply is an error.
    pub fn request(&mut self, req: &Request) -> Result<Reply, SimError> {
        let (seq, bytes) = self.session.send(req.clone(), self.now());
        self.rig.to_device(&bytes);
        loop {
            self.rig.advance(POLL_S);
            self.pump();
            match self.outcomes.remove(&seq) {
                None => {}
                Some(Outcome::Reply(reply)) => return Ok(reply),
                Some(Outcome::Timeout { tries }) => {
                    return Err(SimError::Protocol(format!(
                        "the simulated device did not answer {} within {REPLY_TIMEOUT_S} s ({tries} tries)",
                        req.name()
                    )));
                }
                Some(Outcome::Peer(peer)) => {
                    return Err(SimError::Protocol(
                        protocol::session::peer_error(peer).to_string(),
                    ));
                }
            }
        }
    }

    /// Keeps a release alive: a heartbeat every `interval_s` while time passes (`None`
    /// stops sending them, as a host that lost its link).
    pub fn keep_alive(&mut self, interval_s: Option<f64>) {
        let now = self.now();
        self.session
            .keep_alive(interval_s.map(Duration::from_secs_f64), now);
    }

    /// Puts random bytes on the line between frames, both ways (`None`: a clean line).
    pub fn set_line_noise(&mut self, noise: Option<LineNoise>) {
        let last_us = self.rig.now_us();
        self.noise = noise.map(|config| Noise {
            config,
            rng: NoiseSource::new(config.seed),
            owed: [0.0; 2],
            last_us,
            sent: 0,
        });
    }

    /// Noise bytes put on the line so far, both directions.
    pub fn noise_bytes(&self) -> u64 {
        self.noise.as_ref().map_or(0, |n| n.sent)
    }

    /// The session's counters (frames, errors, retries, heartbeats).
    pub fn stats(&self) -> SessionStats {
        self.session.stats()
    }

    /// Lets `seconds` of virtual time pass, collecting telemetry and events and sending
    /// heartbeats when asked to.
    pub fn wait(&mut self, seconds: f64) {
        let mut left = seconds;
        while left > 1e-12 {
            let dt = left.min(WAIT_STEP_S);
            self.rig.advance(dt);
            left -= dt;
            self.pump();
        }
    }

    /// Lets time pass until `done` holds or `limit_s` elapses; returns the time waited.
    pub fn wait_until(
        &mut self,
        limit_s: f64,
        step_s: f64,
        mut done: impl FnMut(&SimLink) -> bool,
    ) -> Option<f64> {
        let mut waited = 0.0;
        let mut steps = 0u32;
        while waited <= limit_s {
            if done(self) {
                return Some(steps_to_s(steps, step_s));
            }
            self.wait(step_s);
            waited += step_s;
            steps += 1;
        }
        None
    }

    /// Moves the line's bytes both ways through the session and sorts its events.
    fn pump(&mut self) {
        let now = self.now();
        let [to_device_noise, to_host_noise] = match &mut self.noise {
            Some(noise) => noise.due(self.rig.now_us()),
            None => [Vec::new(), Vec::new()],
        };
        if !to_device_noise.is_empty() {
            self.rig.to_device(&to_device_noise);
        }
        self.rx.extend_from_slice(&to_host_noise);
        self.rig.from_device(&mut self.rx);
        let bytes = std::mem::take(&mut self.rx);
        self.session.receive(&bytes, now);
        while let Some(bytes) = self.session.poll_transmit(now) {
            self.rig.to_device(&bytes);
        }
        while let Some(event) = self.session.poll(now) {
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
                Event::Telemetry(t) => self.last_telemetry = Some(t),
                Event::Health(h) => self.last_health = Some(h),
                // Counted in the session's stats.
                Event::Desync { .. } | Event::PeerVersion { seq: None, .. } => {}
                other => self.events.push(other),
            }
        }
    }
}
