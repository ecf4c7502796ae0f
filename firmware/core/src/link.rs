//! The host link's rate (protocol v8, issue 35): both sides start at
//! [`protocol::DEFAULT_BAUD_RATE`]; a host's `SetBaud` switches to the device's
//! [`crate::CoreConfig::max_baud`] once its `Ack` has left the line, and a device that
//! accepts no request at the new rate within [`protocol::BAUD_CONFIRM_MS`] goes back to the
//! default. The binary (and the virtual rig's UART model) asks [`crate::Core::take_baud_switch`]
//! when its UART is idle and sets the rate it returns.

use protocol::{BAUD_CONFIRM_MS, DEFAULT_BAUD_RATE};

/// The agreed rate and a switch waiting for the line to go quiet.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LinkRate {
    /// The rate the UART runs at now, Bd.
    pub(crate) baud: u32,
    /// The rate to switch to once the transmit queue is empty.
    pub(crate) pending: Option<u32>,
    /// Device time by which a request must arrive at the new rate, us.
    pub(crate) confirm_by_us: Option<u64>,
}

impl Default for LinkRate {
    fn default() -> Self {
        Self {
            baud: DEFAULT_BAUD_RATE,
            pending: None,
            confirm_by_us: None,
        }
    }
}

impl LinkRate {
    /// A request was accepted: the rate in use is confirmed.
    pub(crate) fn confirmed(&mut self) {
        self.confirm_by_us = None;
    }

    /// The switch due at `now_us` with the transmit queue empty (`idle`): a pending one,
    /// or back to the default when the new rate was not confirmed in time.
    pub(crate) fn take_switch(&mut self, now_us: u64, idle: bool) -> Option<u32> {
        if self.confirm_by_us.is_some_and(|by| now_us >= by) {
            self.confirm_by_us = None;
            self.pending = Some(DEFAULT_BAUD_RATE);
        }
        if !idle {
            return None;
        }
        let baud = self.pending.take()?;
        if baud == self.baud {
            return None;
        }
        self.baud = baud;
        self.confirm_by_us =
            (baud != DEFAULT_BAUD_RATE).then(|| now_us + u64::from(BAUD_CONFIRM_MS) * 1000);
        Some(baud)
    }
}

/// The BRR value of an STM32 USART at `kernel_hz` nearest to `baud` with 8x oversampling
/// (CR1.OVER8 = 1), with the rate it gives, by RM0440's rule (section 37.5.7): `BRR[15:4] =
/// USARTDIV[15:4]`, `BRR[3] = 0`, `BRR[2:0] = USARTDIV[3:0] >> 1`, so the divider the USART
/// uses is even and the rate is 2 x f_ck / USARTDIV. `None` when that rate is more than
/// [`MAX_BAUD_ERROR_PERMILLE`] off `baud` (beyond what the far end's receiver takes) or the
/// divider is out of the register's range (16..=0xFFFF).
///
/// 4,000,000 Bd at 170 MHz is not exact: USARTDIV 85 would be, but its low bit is not
/// stored; the nearest even dividers give 4,047,619 Bd (84, +1.19 %) and 3,953,488 Bd (86,
/// -1.16 %, BRR 0x53, the one taken). (The emulated board's USART runs at what the register
/// gives, which showed it.)
pub const fn usart_brr_over8(kernel_hz: u32, baud: u32) -> Option<(u16, u32)> {
    if baud == 0 {
        return None;
    }
    let twice = 2 * kernel_hz as u64;
    // The nearest even divider.
    let div = (twice + baud as u64) / (2 * baud as u64) * 2;
    if div < 16 || div > 0xFFFF {
        return None;
    }
    let actual = twice / div;
    let error = actual.abs_diff(baud as u64);
    if error * 1000 > MAX_BAUD_ERROR_PERMILLE as u64 * baud as u64 {
        return None;
    }
    #[allow(
        clippy::cast_possible_truncation,
        reason = "at most 0xFFFF and the rate below the kernel clock, checked above"
    )]
    Some((((div & !0xF) | ((div & 0xF) >> 1)) as u16, actual as u32))
}

/// Largest difference between the rate asked and the rate a USART divider gives that the
/// link accepts, per mille: a receiver at 8x or 16x oversampling takes about 3 % in all
/// (RM0440 table 386), shared between the two ends.
pub const MAX_BAUD_ERROR_PERMILLE: u32 = 15;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_mbaud_at_170_mhz_is_3_953_488_bd_with_8x_oversampling() {
        // USARTDIV would be 2 x 170 MHz / 4 Mbaud = 85, but BRR keeps USARTDIV[3:1] only: of
        // the even dividers 84 (+1.19 %) and 86 (-1.16 %), 86: BRR = 0x50 | (0x6 >> 1) =
        // 0x53, and the USART runs at 2 x 170 MHz / 86 = 3,953,488 Bd, inside the link's 1.5 %.
        assert_eq!(
            usart_brr_over8(170_000_000, protocol::FAST_BAUD_RATE),
            Some((0x53, 3_953_488))
        );
        // Back from the register: USARTDIV = BRR[15:4] << 4 | BRR[2:0] << 1 = 86.
        assert_eq!((0x53 & 0xFFF0) | ((0x53 & 7) << 1), 86);
        // 921,600 Bd: USARTDIV 368.9 -> 368, 923,913 Bd (+0.25 %).
        assert_eq!(
            usart_brr_over8(170_000_000, protocol::DEFAULT_BAUD_RATE),
            Some((0x170, 923_913))
        );
        // A rate no even divider reaches within 1.5 %: 170 MHz / 5.5 (USARTDIV 11 is
        // below 16 anyway) and 13 Mbaud (USARTDIV 26.15 -> 26: 13.08 Mbaud, +0.6 %, fine).
        assert_eq!(usart_brr_over8(170_000_000, 30_000_000), None);
        assert!(usart_brr_over8(170_000_000, 13_000_000).is_some());
        // Beyond the divider: 170 MHz with OVER8 reaches 2 x 170 / 16 = 21.25 Mbaud.
        assert_eq!(usart_brr_over8(170_000_000, 34_000_000), None);
        assert_eq!(usart_brr_over8(170_000_000, 0), None);
    }

    #[test]
    fn a_switch_waits_for_the_ack_and_falls_back_unconfirmed() {
        let mut link = LinkRate {
            pending: Some(protocol::FAST_BAUD_RATE),
            ..LinkRate::default()
        };
        // The Ack is still queued: no switch yet.
        assert_eq!(link.take_switch(1_000, false), None);
        assert_eq!(
            link.take_switch(2_000, true),
            Some(protocol::FAST_BAUD_RATE)
        );
        assert_eq!(link.baud, protocol::FAST_BAUD_RATE);
        // No request at the new rate for BAUD_CONFIRM_MS: back to the default.
        let by = 2_000 + u64::from(BAUD_CONFIRM_MS) * 1000;
        assert_eq!(link.take_switch(by - 1, true), None);
        assert_eq!(link.take_switch(by, true), Some(DEFAULT_BAUD_RATE));
        // A confirmed switch stays.
        link.pending = Some(protocol::FAST_BAUD_RATE);
        assert_eq!(link.take_switch(0, true), Some(protocol::FAST_BAUD_RATE));
        link.confirmed();
        assert_eq!(link.take_switch(u64::MAX, true), None);
        assert_eq!(link.baud, protocol::FAST_BAUD_RATE);
    }
}
