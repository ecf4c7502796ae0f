//! The fault latch, the post-fault request hold, and the detectors that need memory
//! (overcurrent duration, stall window).
//!
//! A fault latches when it rises and stays latched until `ClearFaults`, which clears only
//! the faults whose condition is gone. While anything is latched the motor is off.

use protocol::FaultFlags;

/// Latched faults and the detectors' state.
#[derive(Debug, Clone)]
pub struct FaultMonitor {
    latched: FaultFlags,
    unreported: FaultFlags,
    hold_until_us: u64,
    hold_us: u64,
    overcurrent_since: Option<u64>,
    stall_start: Option<(u64, i64)>,
    reversed_since: Option<u64>,
}

impl FaultMonitor {
    /// Nothing latched; a fault refuses requests for `hold_us` after it rises.
    pub fn new(hold_us: u64) -> Self {
        Self {
            latched: FaultFlags::empty(),
            unreported: FaultFlags::empty(),
            hold_until_us: 0,
            hold_us,
            overcurrent_since: None,
            stall_start: None,
            reversed_since: None,
        }
    }

    /// Latches `flags` at `now_us`; the new ones start the request hold and are reported.
    pub fn raise(&mut self, flags: FaultFlags, now_us: u64) {
        let new = flags.difference(self.latched);
        if !new.is_empty() {
            self.latched.insert(new);
            self.unreported.insert(new);
            self.hold_until_us = now_us.saturating_add(self.hold_us);
        }
    }

    /// Faults that rose since the last call (for a `FaultEvent`).
    pub fn take_unreported(&mut self) -> FaultFlags {
        core::mem::take(&mut self.unreported)
    }

    /// Latched faults.
    pub fn latched(&self) -> FaultFlags {
        self.latched
    }

    /// Whether requests other than status and clear are refused at `now_us`.
    pub fn in_hold(&self, now_us: u64) -> bool {
        now_us < self.hold_until_us
    }

    /// Clears the latched faults that are not in `active`; returns what stays latched.
    pub fn clear(&mut self, active: FaultFlags) -> FaultFlags {
        self.latched = self.latched & active;
        self.latched
    }

    /// Overcurrent detector: true once `current_a` has exceeded `limit_a` for `duration_us`.
    pub fn overcurrent(
        &mut self,
        now_us: u64,
        current_a: f32,
        limit_a: f32,
        duration_us: u64,
    ) -> bool {
        if current_a.abs() <= limit_a {
            self.overcurrent_since = None;
            return false;
        }
        let since = *self.overcurrent_since.get_or_insert(now_us);
        now_us.saturating_sub(since) >= duration_us
    }

    /// Reversed-encoder detector: true once the encoder's speed `speed_rad_s` has run
    /// against the driven duty's sign (faster than `min_speed_rad_s`) for `duration_us`
    /// while the bridge is `driven`: swapped A/B channels, or a motor wired backwards.
    pub fn reversed(
        &mut self,
        now_us: u64,
        driven: bool,
        duty: f32,
        speed_rad_s: f32,
        min_speed_rad_s: f32,
        duration_us: u64,
    ) -> bool {
        let against = driven && duty * speed_rad_s < 0.0 && speed_rad_s.abs() > min_speed_rad_s;
        if !against {
            self.reversed_since = None;
            return false;
        }
        let since = *self.reversed_since.get_or_insert(now_us);
        now_us.saturating_sub(since) >= duration_us
    }

    /// Stall detector: true when the cam moved fewer than `min_counts` during a whole
    /// `window_us` in which the drive stayed above its stall level (`driven`).
    pub fn no_motion(
        &mut self,
        now_us: u64,
        driven: bool,
        position: i64,
        min_counts: u32,
        window_us: u64,
    ) -> bool {
        if !driven {
            self.stall_start = None;
            return false;
        }
        let (t0, p0) = *self.stall_start.get_or_insert((now_us, position));
        if position.abs_diff(p0) >= u64::from(min_counts) {
            self.stall_start = Some((now_us, position));
            return false;
        }
        now_us.saturating_sub(t0) >= window_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latch_hold_and_selective_clear() {
        let mut f = FaultMonitor::new(500_000);
        f.raise(FaultFlags::STALL | FaultFlags::OVERCURRENT, 1_000);
        assert!(f.in_hold(400_000) && !f.in_hold(501_000));
        assert_eq!(
            f.take_unreported(),
            FaultFlags::STALL | FaultFlags::OVERCURRENT
        );
        assert!(f.take_unreported().is_empty());
        // Re-raising a latched fault neither restarts the hold nor reports again.
        f.raise(FaultFlags::STALL, 600_000);
        assert!(!f.in_hold(600_000) && f.take_unreported().is_empty());
        assert_eq!(f.clear(FaultFlags::OVERCURRENT), FaultFlags::OVERCURRENT);
        assert_eq!(f.clear(FaultFlags::empty()), FaultFlags::empty());
    }

    #[test]
    fn overcurrent_needs_its_duration() {
        let mut f = FaultMonitor::new(0);
        assert!(!f.overcurrent(0, 6.0, 4.5, 10_000));
        assert!(!f.overcurrent(9_000, -6.0, 4.5, 10_000));
        assert!(f.overcurrent(10_000, 6.0, 4.5, 10_000));
        // A dip below the limit restarts the timer.
        assert!(!f.overcurrent(11_000, 1.0, 4.5, 10_000));
        assert!(!f.overcurrent(12_000, 6.0, 4.5, 10_000));
        assert!(!f.overcurrent(21_000, 6.0, 4.5, 10_000));
        assert!(f.overcurrent(22_000, 6.0, 4.5, 10_000));
    }

    #[test]
    fn reversed_needs_opposite_sign_speed_and_time() {
        let mut f = FaultMonitor::new(0);
        assert!(!f.reversed(0, true, 0.3, -10.0, 2.0, 100_000));
        assert!(!f.reversed(50_000, true, 0.3, -10.0, 2.0, 100_000));
        // Too slow to tell (the cam just starting or stopping) restarts the timer.
        assert!(!f.reversed(60_000, true, 0.3, -1.0, 2.0, 100_000));
        assert!(!f.reversed(100_000, true, 0.3, -10.0, 2.0, 100_000));
        assert!(f.reversed(200_000, true, -0.3, 10.0, 2.0, 100_000));
        // The same sign, or the bridge off (a coasting cam), is fine.
        assert!(!f.reversed(300_000, true, 0.3, 10.0, 2.0, 100_000));
        assert!(!f.reversed(400_000, false, 0.3, -10.0, 2.0, 0));
    }

    #[test]
    fn no_motion_window_slides_with_progress() {
        let mut f = FaultMonitor::new(0);
        assert!(!f.no_motion(0, true, 0, 64, 200_000));
        assert!(!f.no_motion(150_000, true, 100, 64, 200_000));
        assert!(!f.no_motion(300_000, true, 120, 64, 200_000));
        assert!(f.no_motion(350_000, true, 120, 64, 200_000));
        assert!(!f.no_motion(360_000, false, 120, 64, 200_000));
    }
}
