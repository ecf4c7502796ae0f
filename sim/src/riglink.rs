//! Rig scenarios written once against [`RigLink`], a host session with a rig: the
//! simulated rig in virtual time ([`SimLink`]) or a real rig over its serial port (the
//! host's device link). `hil-tests` runs them on either.

use protocol::{FaultFlags, NackCode, Reply, Request, SupervisorState};
use serde::Serialize;

use crate::{SimError, SimLink};

/// Heartbeat interval the scenarios keep while a release is live, s.
pub const HEARTBEAT_S: f64 = protocol::HEARTBEAT_INTERVAL_MS as f64 / 1000.0;

/// Telemetry rate the scenarios watch the state at, Hz.
const TELEMETRY_HZ: u16 = 50;

/// A host session with a rig, simulated or real.
pub trait RigLink {
    /// The session's error; scenario failures convert into it.
    type Error: From<SimError>;
    /// Sends `req` and returns its reply, matched by its sequence number (a `Nack` is an
    /// error).
    fn request(&mut self, req: &Request) -> Result<Reply, Self::Error>;
    /// Keeps a release alive with heartbeats (true) or lets it lapse (false).
    fn keep_alive(&mut self, on: bool);
    /// Lets `seconds` pass (virtual or wall-clock), heartbeats going on when kept alive.
    fn wait(&mut self, seconds: f64) -> Result<(), Self::Error>;
    /// The device's reason when `error` is a refusal (a `Nack`), `None` for any other error.
    fn refusal(&self, error: &Self::Error) -> Option<NackCode>;
    /// The supervisor state of the newest telemetry sample (a link may wait for a fresh
    /// one).
    fn state(&mut self) -> Result<SupervisorState, Self::Error>;
    /// The rig's own clock, s: virtual time on the simulated rig, the device time of the
    /// newest telemetry on a device (never the host's clock, which a device need not keep
    /// pace with).
    fn clock_s(&mut self) -> f64;

    /// Waits until `done(state)` or `limit_s` passes; returns the time waited, by
    /// [`RigLink::clock_s`]: the waits and whatever reading the state took.
    fn wait_for_state(
        &mut self,
        limit_s: f64,
        done: &dyn Fn(SupervisorState) -> bool,
    ) -> Result<Option<f64>, Self::Error> {
        let step = 0.01;
        let start = self.clock_s();
        loop {
            let state = self.state()?;
            let waited = self.clock_s() - start;
            if done(state) {
                return Ok(Some(waited));
            }
            if waited > limit_s {
                return Ok(None);
            }
            self.wait(step)?;
        }
    }

    /// Latched faults.
    fn latched_faults(&mut self) -> Result<FaultFlags, Self::Error> {
        match self.request(&Request::GetFaults)? {
            Reply::Faults { latched, .. } => Ok(latched),
            other => Err(unexpected(&Request::GetFaults, &other).into()),
        }
    }
}

/// The error for a request answered with something else than its reply: a refusal
/// (naming the device's reason) or a reply of another kind.
pub fn unexpected(req: &Request, reply: &Reply) -> SimError {
    match reply {
        Reply::Nack(code) => SimError::Refused {
            request: req.name(),
            code: *code,
        },
        other => SimError::Protocol(format!(
            "{} was answered with {} instead of {}",
            req.name(),
            other.name(),
            req.reply_kind().name()
        )),
    }
}

impl RigLink for SimLink {
    type Error = SimError;

    fn request(&mut self, req: &Request) -> Result<Reply, SimError> {
        match SimLink::request(self, req)? {
            nack @ Reply::Nack(_) => Err(unexpected(req, &nack)),
            reply => Ok(reply),
        }
    }

    fn keep_alive(&mut self, on: bool) {
        SimLink::keep_alive(self, on.then_some(HEARTBEAT_S));
    }

    fn wait(&mut self, seconds: f64) -> Result<(), SimError> {
        SimLink::wait(self, seconds);
        Ok(())
    }

    fn refusal(&self, error: &SimError) -> Option<NackCode> {
        match error {
            SimError::Refused { code, .. } => Some(*code),
            _ => None,
        }
    }

    fn state(&mut self) -> Result<SupervisorState, SimError> {
        self.last_telemetry
            .map(|t| t.state)
            .ok_or_else(|| SimError::Protocol("no telemetry from the simulated rig yet".into()))
    }

    fn clock_s(&mut self) -> f64 {
        self.rig.time()
    }
}

/// How long a drive request waits for the rig's current-sensor zero, rig seconds (ten times
/// the firmware's 100 ms measurement); the host's client waits as long.
pub const ZERO_WAIT_S: f64 = 1.0;
/// How often a drive request refused with `CurrentZeroPending` is asked again, rig seconds.
pub const ZERO_RETRY_S: f64 = 0.01;

/// Requests a release at `hz` and keeps it alive with heartbeats (waiting for the current
/// zero as [`drive`] does).
pub fn release<L: RigLink + ?Sized>(link: &mut L, hz: f32) -> Result<(), L::Error> {
    drive(
        link,
        &Request::Release {
            on: true,
            target_hz: hz,
            session: 0,
        },
    )
}

/// Whether `req` starts (or keeps) a host drive that needs heartbeats: a release on, an
/// open-loop voltage other than 0.
pub fn starts_drive(req: &Request) -> bool {
    match req {
        Request::Release { on, .. } => *on,
        Request::OpenLoop { volts, .. } => *volts != 0.0,
        _ => false,
    }
}

/// Sends a drive request (`Release`, `OpenLoop`) and requires an `Ack`. A rig still
/// measuring its current sensor's zero (just booted, or re-zeroing) refuses a drive with
/// `CurrentZeroPending`: asked again every [`ZERO_RETRY_S`] for at most [`ZERO_WAIT_S`] of
/// the rig's clock, then that refusal stands.
/// Heartbeats as [`heartbeated`] sends them.
pub fn drive<L: RigLink + ?Sized>(link: &mut L, req: &Request) -> Result<(), L::Error> {
    heartbeated(link, req, |l, on| l.keep_alive(on), |l| drive_once(l, req))
}

/// Runs `send` (drive request `req` and the wait for its `Ack`) on `s` with the heartbeats
/// `keep_alive` turns on and off. A drive that starts is kept alive from the moment it is
/// sent, not from its `Ack`: the rig drives as soon as it reads the request, so an `Ack`
/// lost on a noisy line (its retry comes a reply timeout later, as long as the rig's comms
/// timeout) must not leave the drive without heartbeats. Accepted, the heartbeats go on
/// while the drive does and stop when it stops; refused or unanswered, they stop (a drive
/// the rig took anyway lapses at its comms timeout, the safe end). The scenarios' links and
/// the host's client both drive through here.
pub fn heartbeated<S: ?Sized, E>(
    s: &mut S,
    req: &Request,
    keep_alive: impl Fn(&mut S, bool),
    send: impl FnOnce(&mut S) -> Result<(), E>,
) -> Result<(), E> {
    let on = starts_drive(req);
    if on {
        keep_alive(s, true);
    }
    let answer = send(s);
    if answer.is_ok() || on {
        keep_alive(s, answer.is_ok() && on);
    }
    answer
}

fn drive_once<L: RigLink + ?Sized>(link: &mut L, req: &Request) -> Result<(), L::Error> {
    // Waits of ZERO_RETRY_S each (the link's own clock), so no reading of the clock is needed.
    let mut waits = 0;
    loop {
        match link.request(req) {
            Ok(Reply::Ack) => return Ok(()),
            Ok(other) => return Err(unexpected(req, &other).into()),
            Err(e)
                if link.refusal(&e) == Some(NackCode::CurrentZeroPending)
                    && f64::from(waits) * ZERO_RETRY_S < ZERO_WAIT_S =>
            {
                link.wait(ZERO_RETRY_S)?;
                waits += 1;
            }
            Err(e) => return Err(e),
        }
    }
}

/// Ends the release and stops the heartbeats.
pub fn lock<L: RigLink + ?Sized>(link: &mut L) -> Result<(), L::Error> {
    let req = Request::Release {
        on: false,
        target_hz: 0.0,
        session: 0,
    };
    match link.request(&req)? {
        Reply::Ack => {
            link.keep_alive(false);
            Ok(())
        }
        other => Err(unexpected(&req, &other).into()),
    }
}

fn start_telemetry<L: RigLink + ?Sized>(link: &mut L) -> Result<(), L::Error> {
    link.request(&Request::StartTelemetry {
        rate_hz: TELEMETRY_HZ,
    })?;
    link.wait(0.1)
}

/// Outcome of [`release_cycle`].
#[derive(Debug, Clone, Serialize)]
pub struct ReleaseCycle {
    /// From the release request to `Vibrating`, s.
    pub to_vibrating_s: Option<f64>,
    /// From the end of the release to `Locked`, s.
    pub to_locked_s: Option<f64>,
    /// Faults latched at the end.
    pub latched: String,
}

/// Release at `hz` for `hold_s`, then lock: the supervisor must reach `Vibrating`, then
/// `Locked`, with no fault.
pub fn release_cycle<L: RigLink + ?Sized>(
    link: &mut L,
    hz: f32,
    hold_s: f64,
) -> Result<ReleaseCycle, L::Error> {
    start_telemetry(link)?;
    release(link, hz)?;
    let to_vibrating_s = link.wait_for_state(6.0, &|s| s == SupervisorState::Vibrating)?;
    link.wait(hold_s)?;
    lock(link)?;
    let to_locked_s = link.wait_for_state(4.0, &|s| s == SupervisorState::Locked)?;
    let latched = link.latched_faults()?;
    link.request(&Request::StopTelemetry)?;
    Ok(ReleaseCycle {
        to_vibrating_s,
        to_locked_s,
        latched: latched.to_string(),
    })
}

/// Outcome of [`comms_loss_drill`].
#[derive(Debug, Clone, Serialize)]
pub struct CommsLoss {
    /// From the last heartbeat opportunity to the motor-off state, s.
    pub to_safe_s: Option<f64>,
    /// `COMMS_TIMEOUT` was latched.
    pub comms_timeout_latched: bool,
    /// The fault cleared once the cause was gone.
    pub cleared: bool,
}

/// Release, then stop the heartbeats as a host that vanished: the rig must stop the motor
/// and latch `COMMS_TIMEOUT`; a clear afterwards succeeds.
pub fn comms_loss_drill<L: RigLink + ?Sized>(link: &mut L, hz: f32) -> Result<CommsLoss, L::Error> {
    start_telemetry(link)?;
    release(link, hz)?;
    link.wait_for_state(6.0, &|s| s == SupervisorState::Vibrating)?;
    link.keep_alive(false);
    let to_safe_s = link.wait_for_state(3.0, &|s| {
        matches!(
            s,
            SupervisorState::Fault | SupervisorState::Locked | SupervisorState::Stopping
        )
    })?;
    let comms_timeout_latched = link.latched_faults()?.contains(FaultFlags::COMMS_TIMEOUT);
    // Outside the 500 ms fault hold, and with the cam at rest, the clear succeeds.
    link.wait(2.5)?;
    let cleared = match link.request(&Request::ClearFaults)? {
        Reply::Faults { latched, .. } => latched.is_empty(),
        _ => false,
    };
    link.request(&Request::StopTelemetry)?;
    Ok(CommsLoss {
        to_safe_s,
        comms_timeout_latched,
        cleared,
    })
}
