//! The release requests: what may make the motor run (the safety policy in the crate
//! documentation). A host `Release` or an open-loop drive, kept alive by the heartbeat of
//! its owner's accepted drive requests, or the held button, let go once since boot or the
//! last fault. A host drive belongs to the session that started it: another session's
//! requests cannot refresh it, and its `Release { on: true }` is refused while it is live.
//!
//! [`Release`] holds that state; the requests that change it ([`release`], [`open_loop`])
//! are plain functions of the state and what they are checked against ([`DriveLimits`]), as
//! the other request handlers in `crate::server` are.

use protocol::{NackCode, Reply, SessionId};

/// Why a drive request was refused, or `Ok` with what it did.
pub(crate) type DriveAnswer = Result<Reply, NackCode>;

/// The release requests and their heartbeat.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Release {
    /// A host `Release` is live.
    pub host: bool,
    /// The frequency the host asked for, Hz (the default until it asks).
    pub host_target_hz: f32,
    /// A live open-loop drive (`Request::OpenLoop`): the bridge voltage asked for, V.
    pub open_loop_volts: Option<f32>,
    /// Whether the open-loop drive has settled ([`OpenLoopSettle`]).
    pub open_loop: OpenLoopSettle,
    /// The session whose request started the host drive (meaningful while one is live).
    pub owner: SessionId,
    /// When the owner's last accepted drive request arrived: the heartbeat, us.
    pub last_request_us: u64,
    /// The button releases now: held, and let go once since boot or the last fault.
    pub button_held: bool,
    /// The button was seen let go since boot or the last fault.
    button_armed: bool,
}

impl Release {
    /// Nothing released; a host release would run at `default_hz`.
    pub fn new(default_hz: f32) -> Self {
        Self {
            host: false,
            host_target_hz: default_hz,
            open_loop_volts: None,
            open_loop: OpenLoopSettle::default(),
            owner: 0,
            last_request_us: 0,
            button_held: false,
            button_armed: false,
        }
    }

    /// Drops every request (a fault): the host must ask again, a held button must be let go
    /// once.
    pub fn drop_all(&mut self) {
        self.host = false;
        self.open_loop_volts = None;
        self.button_armed = false;
        self.button_held = false;
    }

    /// Stops the host's drives, a release and an open-loop drive (`Release { on: false }`).
    pub fn stop_host(&mut self) {
        self.host = false;
        self.open_loop_volts = None;
    }

    /// Whether a host drive (a release or an open-loop drive) is live.
    pub fn host_drive(&self) -> bool {
        self.host || self.open_loop_volts.is_some()
    }

    /// Whether a request from `session` may refresh the heartbeat: it owns the live host
    /// drive, or none is live (then the heartbeat matters to nobody).
    pub fn refreshed_by(&self, session: SessionId) -> bool {
        !self.host_drive() || self.owner == session
    }

    /// A drive request (`Release`, `OpenLoop`, `Heartbeat`) from `session` at `now`,
    /// `accepted` or refused: the owner's accepted ones are the heartbeat.
    pub fn beat(&mut self, now: u64, session: SessionId, accepted: bool) {
        if accepted && self.refreshed_by(session) {
            self.last_request_us = now;
        }
    }

    /// One step's update at `now` with the button's level. Returns whether a host drive
    /// lapsed for want of an accepted request within `comms_timeout_us` (it is dropped; the
    /// caller raises `COMMS_TIMEOUT`).
    pub fn update(&mut self, now: u64, button: bool, comms_timeout_us: u64) -> bool {
        let lapsed = now.saturating_sub(self.last_request_us) > comms_timeout_us
            && (self.host || self.open_loop_volts.is_some());
        if lapsed {
            self.stop_host();
        }
        // A button already held (at boot, or through a fault) must be let go once first.
        if !button {
            self.button_armed = true;
        }
        self.button_held = button && self.button_armed;
        lapsed
    }

    /// The frequency a release runs at: the host's when the host released, else `default_hz`
    /// (the button's).
    pub fn requested_hz(&self, default_hz: f32) -> f32 {
        if self.host {
            self.host_target_hz
        } else {
            default_hz
        }
    }
}

/// What a drive request is checked against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DriveLimits {
    /// Lowest release frequency, Hz.
    pub min_hz: f32,
    /// Highest release frequency: the parameters' own limit, at most the board's, Hz.
    pub max_hz: f32,
    /// Largest open-loop voltage magnitude: the supply at the largest duty, V.
    pub max_volts: f32,
    /// A fault is latched or the parameter record is invalid: nothing may start.
    pub locked: bool,
    /// The current sensor's zero is not measured yet (boot, or a `RezeroCurrent` running):
    /// the overcurrent trip has no measured zero to be centred on, so nothing may start.
    pub zero_pending: bool,
}

/// `Release { on, target_hz, session }`: off (from any session) stops every host drive; on
/// starts a release at exactly `target_hz` (refused, never clamped, outside the limits)
/// owned by `session`, unless something is locked, the current sensor's zero is not
/// measured yet, an open-loop drive runs or another session's release is live.
pub(crate) fn release(
    r: &mut Release,
    limits: &DriveLimits,
    on: bool,
    target_hz: f32,
    session: SessionId,
) -> DriveAnswer {
    if !on {
        r.stop_host();
        return Ok(Reply::Ack);
    }
    if !(target_hz.is_finite() && (limits.min_hz..=limits.max_hz).contains(&target_hz)) {
        Err(NackCode::BadArgument)
    } else if limits.locked {
        Err(NackCode::InFaultHold)
    } else if limits.zero_pending {
        Err(NackCode::CurrentZeroPending)
    } else if r.open_loop_volts.is_some() || (r.host && r.owner != session) {
        Err(NackCode::Busy)
    } else {
        r.host = true;
        r.owner = session;
        r.host_target_hz = target_hz;
        Ok(Reply::Ack)
    }
}

/// `OpenLoop { volts, session }`: 0 (from any session) stops an open-loop drive; otherwise
/// a fixed bridge voltage of at most [`DriveLimits::max_volts`] owned by `session`, unless
/// something is locked, the current sensor's zero is not measured yet, a release is live
/// or another session's open-loop drive runs.
pub(crate) fn open_loop(
    r: &mut Release,
    limits: &DriveLimits,
    volts: f32,
    session: SessionId,
) -> DriveAnswer {
    if volts == 0.0 {
        r.open_loop_volts = None;
        Ok(Reply::Ack)
    } else if !(volts.is_finite() && volts.abs() <= limits.max_volts) {
        Err(NackCode::BadArgument)
    } else if limits.locked {
        Err(NackCode::InFaultHold)
    } else if limits.zero_pending {
        Err(NackCode::CurrentZeroPending)
    } else if r.host || r.button_held || (r.open_loop_volts.is_some() && r.owner != session) {
        Err(NackCode::Busy)
    } else {
        r.open_loop_volts = Some(volts);
        r.owner = session;
        Ok(Reply::Ack)
    }
}

/// The start of the current cam revolution of an open-loop drive, and the period of the
/// one before it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct OpenLoopRevolution {
    /// Unwrapped encoder position at the revolution's start, counts.
    pub start_position: i64,
    /// Time of the revolution's start, us.
    pub start_us: u64,
    /// Period of the revolution before, us (0: none yet).
    pub last_period_us: u64,
}

/// The open-loop settle check: the voltage ramp is done and two consecutive cam
/// revolutions took the same time within 2 % (a revolution's mean: the cam's speed ripples
/// within a turn).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct OpenLoopSettle {
    /// The revolution being timed.
    pub revolution: OpenLoopRevolution,
    /// The last two whole revolutions agreed.
    pub steady: bool,
}

impl OpenLoopSettle {
    /// One step at `now` and unwrapped `position`, with `counts_per_rev` a turn and
    /// `ramp_done` whether the duty has reached its goal. Returns whether the drive is
    /// settled.
    pub fn update(
        &mut self,
        now: u64,
        position: i64,
        counts_per_rev: i64,
        ramp_done: bool,
    ) -> bool {
        let rev = self.revolution;
        if !ramp_done {
            self.revolution = OpenLoopRevolution {
                start_position: position,
                start_us: now,
                last_period_us: 0,
            };
            self.steady = false;
        } else if (position - rev.start_position).abs() >= counts_per_rev {
            let period = now.saturating_sub(rev.start_us);
            let diff = period.abs_diff(rev.last_period_us);
            self.steady = rev.last_period_us > 0 && diff * 50 <= rev.last_period_us;
            self.revolution = OpenLoopRevolution {
                start_position: position,
                start_us: now,
                last_period_us: period,
            };
        }
        self.steady
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: DriveLimits = DriveLimits {
        min_hz: 1.0,
        max_hz: 20.0,
        max_volts: 11.4,
        locked: false,
        zero_pending: false,
    };

    #[test]
    fn a_release_runs_at_exactly_the_asked_frequency_or_is_refused() {
        let mut r = Release::new(10.0);
        assert_eq!(r.requested_hz(10.0), 10.0);
        assert_eq!(
            release(&mut r, &LIMITS, true, 20.5, 7),
            Err(NackCode::BadArgument)
        );
        assert_eq!(
            release(&mut r, &LIMITS, true, f32::NAN, 7),
            Err(NackCode::BadArgument)
        );
        assert!(!r.host);
        assert_eq!(release(&mut r, &LIMITS, true, 12.5, 7), Ok(Reply::Ack));
        assert!(r.host && r.requested_hz(10.0) == 12.5);
        let locked = DriveLimits {
            locked: true,
            ..LIMITS
        };
        let mut l = Release::new(10.0);
        assert_eq!(
            release(&mut l, &locked, true, 12.5, 7),
            Err(NackCode::InFaultHold)
        );
        // Off is always accepted, locked or not, and stops an open-loop drive too.
        l.open_loop_volts = Some(3.0);
        assert_eq!(release(&mut l, &locked, false, f32::NAN, 7), Ok(Reply::Ack));
        assert_eq!(l.open_loop_volts, None);
    }

    #[test]
    fn no_drive_starts_before_the_current_zero_is_measured() {
        let pending = DriveLimits {
            zero_pending: true,
            ..LIMITS
        };
        let mut r = Release::new(10.0);
        assert_eq!(
            release(&mut r, &pending, true, 10.0, 7),
            Err(NackCode::CurrentZeroPending)
        );
        assert_eq!(
            open_loop(&mut r, &pending, 3.0, 7),
            Err(NackCode::CurrentZeroPending)
        );
        assert!(!r.host_drive(), "a refused request has no effect");
        // A bad argument is named first; stopping is always accepted.
        assert_eq!(
            release(&mut r, &pending, true, 99.0, 7),
            Err(NackCode::BadArgument)
        );
        assert_eq!(release(&mut r, &pending, false, 0.0, 7), Ok(Reply::Ack));
        assert_eq!(open_loop(&mut r, &pending, 0.0, 7), Ok(Reply::Ack));
        // A latched fault is the reason given before the zero.
        let both = DriveLimits {
            locked: true,
            ..pending
        };
        assert_eq!(
            release(&mut r, &both, true, 10.0, 7),
            Err(NackCode::InFaultHold)
        );
    }

    #[test]
    fn open_loop_and_release_exclude_each_other() {
        let mut r = Release::new(10.0);
        assert_eq!(
            open_loop(&mut r, &LIMITS, 11.5, 7),
            Err(NackCode::BadArgument)
        );
        assert_eq!(open_loop(&mut r, &LIMITS, -6.2, 7), Ok(Reply::Ack));
        assert_eq!(r.open_loop_volts, Some(-6.2));
        assert_eq!(release(&mut r, &LIMITS, true, 10.0, 7), Err(NackCode::Busy));
        assert_eq!(open_loop(&mut r, &LIMITS, 0.0, 7), Ok(Reply::Ack));
        assert_eq!(release(&mut r, &LIMITS, true, 10.0, 7), Ok(Reply::Ack));
        assert_eq!(open_loop(&mut r, &LIMITS, 3.6, 7), Err(NackCode::Busy));
    }

    #[test]
    fn a_drive_belongs_to_the_session_that_started_it() {
        let mut r = Release::new(10.0);
        assert!(r.refreshed_by(1) && r.refreshed_by(2), "nothing live");
        assert_eq!(release(&mut r, &LIMITS, true, 10.0, 1), Ok(Reply::Ack));
        assert!(r.refreshed_by(1) && !r.refreshed_by(2));
        // A second session can neither take it over nor start an open-loop drive.
        assert_eq!(release(&mut r, &LIMITS, true, 12.0, 2), Err(NackCode::Busy));
        assert_eq!(r.requested_hz(10.0), 10.0);
        // The owner may change its frequency.
        assert_eq!(release(&mut r, &LIMITS, true, 12.0, 1), Ok(Reply::Ack));
        // Anyone may lock.
        assert_eq!(release(&mut r, &LIMITS, false, 0.0, 2), Ok(Reply::Ack));
        assert!(!r.host_drive());
        assert_eq!(open_loop(&mut r, &LIMITS, 3.0, 2), Ok(Reply::Ack));
        assert!(!r.refreshed_by(1));
        assert_eq!(open_loop(&mut r, &LIMITS, 4.0, 1), Err(NackCode::Busy));
        assert_eq!(open_loop(&mut r, &LIMITS, 0.0, 1), Ok(Reply::Ack));
        // Once lapsed, another session may release.
        assert_eq!(release(&mut r, &LIMITS, true, 10.0, 3), Ok(Reply::Ack));
        r.last_request_us = 0;
        assert!(r.update(600_000, false, 500_000));
        assert_eq!(release(&mut r, &LIMITS, true, 10.0, 4), Ok(Reply::Ack));
    }

    #[test]
    fn host_drives_lapse_without_a_heartbeat_and_the_button_must_be_let_go_once() {
        let mut r = Release::new(10.0);
        // Held at boot: not a release until let go once.
        assert!(!r.update(0, true, 500_000));
        assert!(!r.button_held);
        assert!(!r.update(1_000, false, 500_000));
        assert!(!r.update(2_000, true, 500_000));
        assert!(r.button_held);
        r.host = true;
        r.last_request_us = 2_000;
        assert!(
            !r.update(502_000, true, 500_000),
            "exactly the timeout is still live"
        );
        assert!(r.update(502_001, true, 500_000));
        assert!(!r.host && r.button_held, "the button is not the host's");
        // A fault drops everything; the button must be let go again.
        r.drop_all();
        assert!(!r.update(503_000, true, 500_000));
        assert!(!r.button_held);
    }

    #[test]
    fn open_loop_settles_on_two_revolutions_within_two_percent() {
        let per_rev = 8192;
        let mut s = OpenLoopSettle::default();
        // Ramping: the revolution restarts at every step.
        assert!(!s.update(0, 0, per_rev, false));
        assert_eq!(s.revolution.start_us, 0);
        // First whole turn: 100 ms, no previous period.
        assert!(!s.update(100_000, per_rev, per_rev, true));
        assert_eq!(s.revolution.last_period_us, 100_000);
        // 102 ms: within 2 % of 100 ms.
        assert!(s.update(202_000, 2 * per_rev, per_rev, true));
        // 105 ms against 102 ms: 2.9 %, not steady.
        assert!(!s.update(307_000, 3 * per_rev, per_rev, true));
        // Within a turn nothing changes.
        assert!(!s.update(350_000, 3 * per_rev + 10, per_rev, true));
        // Backwards counts as well (a reversed drive).
        let mut b = OpenLoopSettle::default();
        b.update(0, 0, per_rev, false);
        b.update(100_000, -per_rev, per_rev, true);
        assert!(b.update(200_000, -2 * per_rev, per_rev, true));
        // The ramp starting again clears it.
        assert!(!b.update(210_000, -2 * per_rev, per_rev, false));
    }
}
