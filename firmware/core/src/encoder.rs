//! Cam angle and speed from the quadrature encoder's wrapping 16-bit timer count.
//!
//! The count is unwrapped by its signed 16-bit step difference (at 150 rad/s the cam moves
//! ~200 counts per 1 ms step, far from the +-32768 limit). Speed is position over a moving
//! window: 10 ms when the cam moves briskly, stretched to 100 ms when fewer than
//! [`MIN_WINDOW_COUNTS`] arrive in 10 ms, so that 0.2 rad/s (~26 counts per 100 ms at
//! 8192 counts per turn) still reads within a few per cent.

use core::f32::consts::TAU;

/// History length: 100 steps (100 ms at 1 kHz) plus the current one.
const HISTORY: usize = 101;
/// Short window, steps.
const SHORT_WINDOW: usize = 10;
/// Fewest counts the short window must see to be used.
pub const MIN_WINDOW_COUNTS: i32 = 32;

/// Unwrapped encoder position and speed.
#[derive(Debug, Clone)]
pub struct CamEncoder {
    counts_per_rev: u32,
    last_raw: Option<u16>,
    position: i64,
    /// `position` modulo `counts_per_rev`, kept in step with it in 32-bit arithmetic
    /// (`i64::rem_euclid` would be a 64-bit software division on the target).
    angle_counts: u32,
    // (time us, position) per step, as wrapping 32-bit values: only differences are used.
    history: [(u32, i32); HISTORY],
    head: usize,
    filled: usize,
    speed_rad_s: f32,
}

/// `(a + delta) mod n` for `a < n`, without overflow and without 64-bit arithmetic.
fn wrapping_step(a: u32, delta: i32, n: u32) -> u32 {
    let d = delta.unsigned_abs() % n;
    if delta >= 0 {
        if d >= n - a { d - (n - a) } else { a + d }
    } else if d <= a {
        a - d
    } else {
        n - (d - a)
    }
}

impl CamEncoder {
    /// An encoder with `counts_per_rev` quadrature counts per cam revolution.
    pub fn new(counts_per_rev: u32) -> Self {
        Self {
            counts_per_rev: counts_per_rev.max(1),
            last_raw: None,
            position: 0,
            angle_counts: 0,
            history: [(0, 0); HISTORY],
            head: 0,
            filled: 0,
            speed_rad_s: 0.0,
        }
    }

    /// Takes the raw timer count read at `now_us`; returns the counts moved since the last call.
    pub fn update(&mut self, now_us: u64, raw: u16) -> i32 {
        let delta = match self.last_raw {
            Some(last) => i32::from(raw.wrapping_sub(last).cast_signed()),
            None => 0,
        };
        self.last_raw = Some(raw);
        self.position += i64::from(delta);
        self.angle_counts = wrapping_step(self.angle_counts, delta, self.counts_per_rev);
        self.head = (self.head + 1) % HISTORY;
        #[allow(
            clippy::cast_possible_truncation,
            reason = "kept modulo 2^32: the speed window takes wrapping differences only"
        )]
        let entry = (now_us as u32, self.position as i32);
        self.history[self.head] = entry;
        self.filled = (self.filled + 1).min(HISTORY);
        self.speed_rad_s = self.window_speed();
        delta
    }

    fn window_speed(&self) -> f32 {
        let back = |steps: usize| self.history[(self.head + HISTORY - steps) % HISTORY];
        let (t_now, p_now) = self.history[self.head];
        let available = self.filled.saturating_sub(1);
        if available == 0 {
            return 0.0;
        }
        let mut steps = available.min(SHORT_WINDOW);
        let (_, p_short) = back(steps);
        if p_now.wrapping_sub(p_short).abs() < MIN_WINDOW_COUNTS {
            steps = available;
        }
        let (t_then, p_then) = back(steps);
        let dt_us = t_now.wrapping_sub(t_then);
        if dt_us == 0 {
            return 0.0;
        }
        let counts = p_now.wrapping_sub(p_then) as f32;
        counts / self.counts_per_rev as f32 * TAU / (dt_us as f32 * 1e-6)
    }

    /// Unwrapped position, counts since the first reading.
    pub fn position(&self) -> i64 {
        self.position
    }

    /// Cam angle in [0, 2 pi), rad (zero at the first reading).
    pub fn angle_rad(&self) -> f32 {
        self.angle_counts as f32 / self.counts_per_rev as f32 * TAU
    }

    /// Cam speed (signed), rad/s.
    pub fn speed_rad_s(&self) -> f32 {
        self.speed_rad_s
    }
}

#[cfg(test)]
#[allow(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap,
    reason = "test fixtures: values in range by construction"
)]
mod tests {
    use super::*;

    const CPR: u32 = 8192;

    #[test]
    fn the_angle_is_the_position_modulo_a_turn() {
        // `wrapping_step` against i64::rem_euclid, at the edges of its range.
        for n in [1u32, 2, 3, 7, 100, 8192, 1 << 31, u32::MAX] {
            for a in [0, 1, n / 2, n - 1].into_iter().filter(|&a| a < n) {
                for delta in [0, 1, -1, 5, -5, 32_767, -32_768, i32::MAX, i32::MIN] {
                    let want = (i64::from(a) + i64::from(delta)).rem_euclid(i64::from(n));
                    assert_eq!(
                        i64::from(wrapping_step(a, delta, n)),
                        want,
                        "{a} {delta} {n}"
                    );
                }
            }
        }
        // And through the encoder, back and forth across zero.
        let mut e = CamEncoder::new(100);
        let mut raw = 0u16;
        for (k, step) in [7i16, -30, 250, -999, 3, 32_000, -32_000]
            .iter()
            .cycle()
            .take(50)
            .enumerate()
        {
            raw = raw.wrapping_add(*step as u16);
            e.update(k as u64 * 1000, raw);
            let want = e.position().rem_euclid(100) as f32 / 100.0 * TAU;
            assert!(
                (e.angle_rad() - want).abs() < 1e-6,
                "{} {want}",
                e.angle_rad()
            );
        }
    }

    /// Feeds a cam turning at `speed` rad/s for `steps` 1 ms steps, from raw count `start`.
    fn spin(enc: &mut CamEncoder, start: f64, speed: f64, steps: u64) {
        for k in 0..=steps {
            let t = k as f64 * 1e-3;
            let counts = start + speed * t / core::f64::consts::TAU * CPR as f64;
            enc.update(k * 1000, (libm::floor(counts) as i64) as u16);
        }
    }

    #[test]
    fn unwraps_across_the_16_bit_limit_both_ways() {
        let mut e = CamEncoder::new(CPR);
        e.update(0, 65_530);
        e.update(1000, 10);
        assert_eq!(e.position(), 16);
        e.update(2000, 65_500);
        assert_eq!(e.position(), -30);
    }

    #[test]
    fn speed_is_accurate_from_slow_to_fast() {
        for (speed, tol) in [
            (0.2, 0.05),
            (1.0, 0.02),
            (62.8, 0.01),
            (150.0, 0.01),
            (-40.0, 0.01),
        ] {
            let mut e = CamEncoder::new(CPR);
            spin(&mut e, 65_000.0, speed, 300);
            let got = f64::from(e.speed_rad_s());
            assert!(
                ((got - speed) / speed).abs() < tol,
                "{speed} rad/s read as {got}"
            );
        }
    }

    #[test]
    fn standstill_reads_zero_and_angle_wraps() {
        let mut e = CamEncoder::new(CPR);
        for k in 0..50 {
            e.update(k * 1000, 1234);
        }
        assert_eq!(e.speed_rad_s(), 0.0);
        let mut e = CamEncoder::new(CPR);
        e.update(0, 0);
        e.update(1000, (CPR + CPR / 4) as u16);
        assert!((e.angle_rad() - TAU / 4.0).abs() < 1e-5);
    }
}
