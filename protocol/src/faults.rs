//! Fault bits reported by the supervisor. Any active fault stops the vibrator (the safe
//! state); faults latch until [`crate::Request::ClearFaults`].

use crate::flags::flag_set;

flag_set! {
    /// Set of supervisor faults, a `u16` on the wire.
    pub struct FaultFlags(u16) {
        /// Motor current above `Calibration::max_current_a`.
        const OVERCURRENT = 0;
        /// The cam does not turn although the motor is driven.
        const STALL = 1;
        /// Encoder signal lost or implausible.
        const ENCODER_LOSS = 2;
        /// Current-sensor zero offset outside its expected range (at re-zero).
        const CURRENT_ZERO_RANGE = 3;
        /// The control loop missed its deadline.
        const CONTROL_OVERRUN = 4;
        /// Stored calibration failed its check; the paper's defaults are in use.
        const CALIBRATION_INVALID = 5;
        /// The last reset was caused by the watchdog.
        const WATCHDOG_RESET = 6;
        /// No heartbeat within the comms timeout while released.
        const COMMS_TIMEOUT = 7;
        /// The required cam torque (Eq. 10) exceeds what the vibrator can deliver.
        const CANNOT_RELEASE = 8;
        /// The cam or output is mechanically blocked.
        const JAM = 9;
        /// Load estimate above `Calibration::max_release_load_nm`.
        const OVERLOAD = 10;
        /// A torque or speed estimate is outside physical bounds (NaN, sign, magnitude).
        const ESTIMATE_IMPLAUSIBLE = 11;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_are_distinct_and_named() {
        let mut seen = 0u16;
        for (_, flag) in FaultFlags::NAMED {
            assert_eq!(flag.bits().count_ones(), 1);
            assert_eq!(seen & flag.bits(), 0);
            seen |= flag.bits();
        }
        assert_eq!(FaultFlags::all().bits(), seen);
    }

    #[test]
    fn display_lists_names_and_unknown_bits() {
        let f = FaultFlags::OVERCURRENT | FaultFlags::JAM | FaultFlags::from_bits_retain(0x8000);
        assert_eq!(f.to_string(), "OVERCURRENT | JAM | 0x8000");
        assert_eq!(FaultFlags::empty().to_string(), "none");
        assert_eq!(format!("{:?}", FaultFlags::STALL), "FaultFlags(STALL)");
    }

    #[test]
    fn set_operations() {
        let mut f = FaultFlags::empty();
        f.insert(FaultFlags::STALL | FaultFlags::OVERLOAD);
        assert!(f.contains(FaultFlags::STALL));
        assert!(f.intersects(FaultFlags::OVERLOAD | FaultFlags::JAM));
        assert!(!f.contains(FaultFlags::OVERLOAD | FaultFlags::JAM));
        f.set(FaultFlags::STALL, false);
        assert_eq!(f, FaultFlags::OVERLOAD);
        f.remove(FaultFlags::OVERLOAD);
        assert!(f.is_empty());
    }
}
