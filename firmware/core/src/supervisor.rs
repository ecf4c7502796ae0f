//! The release supervisor: when the cam may vibrate, and what the estimates say about it.
//!
//! | from      | to        | when                                                          |
//! |-----------|-----------|---------------------------------------------------------------|
//! | Locked    | SpinUp    | a release is live, the current zero is measured, no fault     |
//! | SpinUp    | Vibrating | cam speed within 10 % of the target for 100 ms                |
//! | SpinUp    | Stopping  | the release lapsed                                            |
//! | Vibrating | SpinUp    | the target changed (new request, or raised after weak torque) |
//! | Vibrating | Stopping  | the release lapsed                                            |
//! | Stopping  | Locked    | cam below 2 rad/s for 50 ms, or 2 s passed                    |
//! | Stopping  | SpinUp    | a release is live again                                       |
//! | any       | Fault     | a fault is latched                                            |
//! | Fault     | Stopping / Locked | every fault cleared (Stopping while the cam still turns) |
//!
//! Faults the supervisor itself raises: `CANNOT_RELEASE` (spin-up timeout, or tau_cam below
//! Eq. (10) at the highest allowed frequency), `OVERLOAD`, `JAM`, `ESTIMATE_IMPLAUSIBLE`.

use protocol::{FaultFlags, SupervisorState};

use crate::config::SupervisorConfig;

/// How long the cam must stay below the stop speed before `Locked`, us.
const AT_REST_US: u64 = 50_000;

/// What the supervisor looks at each step.
#[derive(Debug, Clone, Copy)]
pub struct SupervisorInputs {
    /// Now, us.
    pub now_us: u64,
    /// A host or button release is live.
    pub release_live: bool,
    /// The requested vibration frequency, Hz (already within the allowed range).
    pub requested_hz: f32,
    /// Any fault latched.
    pub faulted: bool,
    /// The current zero has been measured (no zero measurement running).
    pub zero_ready: bool,
    /// Cam speed in the drive direction, rad/s.
    pub cam_speed_rad_s: f32,
    /// `Some` while an open-loop drive (fixed voltage, `Request::OpenLoop`) is live: whether
    /// its voltage ramp is done and the cam speed has settled. There is no speed target then.
    pub open_loop_settled: Option<bool>,
}

/// A revolution's numbers as the supervisor judges them, N m.
#[derive(Debug, Clone, Copy)]
pub struct RevolutionCheck {
    /// Revolution-mean cam torque.
    pub tau_cam: f32,
    /// Load estimate.
    pub tau_rot: f32,
    /// Eq. (10) at zero load.
    pub required_no_load: f32,
    /// Eq. (10) at the largest release load.
    pub required_max_load: f32,
    /// Largest release load (the calibration's, at most the board's cap).
    pub max_load: f32,
    /// The board's cap on the load while released (the gear's tooth strength) plus the
    /// estimate's tolerance: above it `LOAD_LIMIT` rather than `OVERLOAD`, whatever the
    /// calibration's `max_load`.
    pub load_cap: f32,
}

/// The supervisor's state machine.
#[derive(Debug, Clone)]
pub struct Supervisor {
    config: SupervisorConfig,
    state: SupervisorState,
    entered_us: u64,
    condition_since: Option<u64>,
    requested_hz: f32,
    target_hz: f32,
    max_hz: f32,
    weak_count: u8,
    overload_count: u8,
    load_limit_count: u8,
    settle_left: u8,
    open_loop: bool,
}

impl Supervisor {
    /// Locked, with frequencies capped at `max_hz`.
    pub fn new(config: SupervisorConfig, max_hz: f32) -> Self {
        Self {
            config,
            state: SupervisorState::Locked,
            entered_us: 0,
            condition_since: None,
            requested_hz: config.default_freq_hz,
            target_hz: config.default_freq_hz,
            max_hz,
            weak_count: 0,
            overload_count: 0,
            load_limit_count: 0,
            settle_left: config.settle_revolutions,
            open_loop: false,
        }
    }

    /// Current state.
    pub fn state(&self) -> SupervisorState {
        self.state
    }

    /// Vibration frequency being driven (the request, possibly raised), Hz.
    pub fn target_hz(&self) -> f32 {
        self.target_hz
    }

    /// Highest frequency allowed, Hz.
    pub fn set_max_hz(&mut self, max_hz: f32) {
        self.max_hz = max_hz;
    }

    /// Whether this state drives the motor.
    pub fn drives_motor(&self) -> bool {
        matches!(
            self.state,
            SupervisorState::SpinUp | SupervisorState::Vibrating
        )
    }

    fn enter(&mut self, state: SupervisorState, now_us: u64) {
        self.state = state;
        self.entered_us = now_us;
        self.condition_since = None;
        if state == SupervisorState::Vibrating {
            self.weak_count = 0;
            self.overload_count = 0;
            self.load_limit_count = 0;
            self.settle_left = self.config.settle_revolutions;
        }
    }

    /// True once `condition` has held for `duration_us` (consecutive steps).
    fn held_for(&mut self, condition: bool, now_us: u64, duration_us: u64) -> bool {
        if !condition {
            self.condition_since = None;
            return false;
        }
        let since = *self.condition_since.get_or_insert(now_us);
        now_us.saturating_sub(since) >= duration_us
    }

    /// One step; returns the faults the supervisor raises (state changes are visible
    /// through [`Supervisor::state`]).
    pub fn update(&mut self, i: &SupervisorInputs) -> FaultFlags {
        let now = i.now_us;
        if i.faulted {
            if self.state != SupervisorState::Fault {
                self.enter(SupervisorState::Fault, now);
            }
            return FaultFlags::empty();
        }
        let w = i.cam_speed_rad_s;
        let can_start = i.release_live && i.zero_ready;
        self.open_loop = i.open_loop_settled.is_some();
        if i.release_live && !self.open_loop && i.requested_hz != self.requested_hz {
            // A new request replaces any raised frequency.
            self.requested_hz = i.requested_hz;
            self.target_hz = i.requested_hz.min(self.max_hz);
            if self.state == SupervisorState::Vibrating {
                self.enter(SupervisorState::SpinUp, now);
            }
        }
        match self.state {
            SupervisorState::Fault => {
                let turning = w.abs() >= self.config.stop_speed_rad_s;
                let next = if turning {
                    SupervisorState::Stopping
                } else {
                    SupervisorState::Locked
                };
                self.enter(next, now);
            }
            SupervisorState::Locked => {
                if can_start {
                    self.target_hz = self.requested_hz.min(self.max_hz);
                    self.enter(SupervisorState::SpinUp, now);
                }
            }
            SupervisorState::SpinUp => {
                if !i.release_live {
                    self.enter(SupervisorState::Stopping, now);
                    return FaultFlags::empty();
                }
                let target = core::f32::consts::TAU * self.target_hz;
                let at_speed = match i.open_loop_settled {
                    Some(settled) => settled,
                    None => (w - target).abs() <= self.config.at_speed_tolerance * target,
                };
                if self.held_for(at_speed, now, self.config.at_speed_time_us) {
                    self.enter(SupervisorState::Vibrating, now);
                } else if i.open_loop_settled.is_none()
                    && now.saturating_sub(self.entered_us) >= self.config.spin_up_timeout_us
                {
                    // An open-loop drive has no speed to reach (a shaft held on the force
                    // gauge never turns); heartbeats and the current limit bound it.
                    return FaultFlags::CANNOT_RELEASE;
                }
            }
            SupervisorState::Vibrating => {
                if !i.release_live {
                    self.enter(SupervisorState::Stopping, now);
                }
            }
            SupervisorState::Stopping => {
                if can_start {
                    self.target_hz = self.requested_hz.min(self.max_hz);
                    self.enter(SupervisorState::SpinUp, now);
                } else {
                    let at_rest = w.abs() < self.config.stop_speed_rad_s;
                    let timed_out =
                        now.saturating_sub(self.entered_us) >= self.config.stop_timeout_us;
                    if self.held_for(at_rest, now, AT_REST_US) || timed_out {
                        self.enter(SupervisorState::Locked, now);
                    }
                }
            }
            // `SupervisorState` is non-exhaustive: anything unknown is treated as a fault.
            _ => return FaultFlags::ESTIMATE_IMPLAUSIBLE,
        }
        FaultFlags::empty()
    }

    /// Judges a completed revolution while `Vibrating`; returns the faults it raises. A
    /// persistently weak cam torque raises the target frequency (back to `SpinUp`) until
    /// the highest allowed one, then fails with `CANNOT_RELEASE`.
    pub fn on_revolution(&mut self, r: &RevolutionCheck, now_us: u64) -> FaultFlags {
        if self.state != SupervisorState::Vibrating {
            return FaultFlags::empty();
        }
        if self.settle_left > 0 {
            self.settle_left -= 1;
            return FaultFlags::empty();
        }
        let finite = r.tau_cam.is_finite() && r.tau_rot.is_finite();
        if !finite || r.tau_rot < -r.max_load {
            return FaultFlags::ESTIMATE_IMPLAUSIBLE;
        }
        if r.tau_cam > self.config.jam_ratio * r.required_max_load {
            return FaultFlags::JAM;
        }
        // Above the gear's strength, whatever this release allows: a few revolutions in a
        // row, so one revolution of a transient (a frequency step) does not trip it.
        if r.tau_rot > r.load_cap {
            self.load_limit_count = self.load_limit_count.saturating_add(1);
            if self.load_limit_count >= self.config.load_limit_revolutions {
                return FaultFlags::LOAD_LIMIT;
            }
        } else if r.tau_rot > r.max_load {
            self.load_limit_count = 0;
            self.overload_count = self.overload_count.saturating_add(1);
            if self.overload_count >= self.config.overload_revolutions {
                return FaultFlags::OVERLOAD;
            }
        } else {
            self.load_limit_count = 0;
            self.overload_count = 0;
        }
        // At a fixed voltage there is no frequency to raise.
        if !self.open_loop && r.tau_cam < r.required_no_load - self.config.weak_margin_nm {
            self.weak_count = self.weak_count.saturating_add(1);
            if self.weak_count >= self.config.weak_revolutions {
                self.weak_count = 0;
                let raised = self.target_hz + self.config.freq_step_hz;
                if self.target_hz >= self.max_hz {
                    return FaultFlags::CANNOT_RELEASE;
                }
                self.target_hz = raised.min(self.max_hz);
                self.enter(SupervisorState::SpinUp, now_us);
            }
        } else {
            self.weak_count = 0;
        }
        FaultFlags::empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs(now_us: u64, live: bool, w: f32) -> SupervisorInputs {
        SupervisorInputs {
            now_us,
            release_live: live,
            requested_hz: 10.0,
            faulted: false,
            zero_ready: true,
            cam_speed_rad_s: w,
            open_loop_settled: None,
        }
    }

    fn check(tau_cam: f32, tau_rot: f32) -> RevolutionCheck {
        RevolutionCheck {
            tau_cam,
            tau_rot,
            required_no_load: 0.0,
            required_max_load: 0.0535,
            max_load: 3.68,
            load_cap: 5.0,
        }
    }

    fn vibrating() -> Supervisor {
        let mut s = Supervisor::new(SupervisorConfig::default(), 15.0);
        let w = core::f32::consts::TAU * 10.0;
        for k in 0..=101 {
            s.update(&inputs(k * 1000, true, w));
        }
        assert_eq!(s.state(), SupervisorState::Vibrating);
        s
    }

    #[test]
    fn weak_torque_raises_the_frequency_then_fails() {
        let mut s = vibrating();
        assert!(s.on_revolution(&check(-1.0, 0.0), 0).is_empty()); // settling revolution
        let mut raised = Vec::new();
        for _ in 0..20 {
            let f = s.on_revolution(&check(-0.01, 0.0), 0);
            if !f.is_empty() {
                assert_eq!(f, FaultFlags::CANNOT_RELEASE);
                break;
            }
            if s.state() == SupervisorState::SpinUp {
                raised.push(s.target_hz());
                s.enter(SupervisorState::Vibrating, 0);
                s.settle_left = 0;
            }
        }
        // 10 -> 12 -> 14 -> 15 (the cap), then the fault.
        assert_eq!(raised, [12.0, 14.0, 15.0]);
    }

    #[test]
    fn overload_jam_and_implausible_estimates() {
        let mut s = vibrating();
        s.settle_left = 0;
        assert!(s.on_revolution(&check(0.03, 2.0), 0).is_empty());
        assert_eq!(s.on_revolution(&check(0.06, 3.9), 0), FaultFlags::OVERLOAD);
        // Above the board's cap (the gear's tooth strength) it is LOAD_LIMIT.
        let mut s = vibrating();
        s.settle_left = 0;
        let above_cap = RevolutionCheck {
            load_cap: 3.68,
            ..check(0.06, 3.9)
        };
        for _ in 1..SupervisorConfig::default().load_limit_revolutions {
            assert!(s.on_revolution(&above_cap, 0).is_empty());
        }
        assert_eq!(s.on_revolution(&above_cap, 0), FaultFlags::LOAD_LIMIT);
        assert_eq!(s.on_revolution(&check(0.2, 3.9), 0), FaultFlags::JAM);
        assert_eq!(
            s.on_revolution(&check(f32::NAN, 1.0), 0),
            FaultFlags::ESTIMATE_IMPLAUSIBLE
        );
        assert_eq!(
            s.on_revolution(&check(0.0, -4.0), 0),
            FaultFlags::ESTIMATE_IMPLAUSIBLE
        );
    }
}
