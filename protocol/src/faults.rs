//! Fault bits reported by the supervisor. Any active fault stops the vibrator (the safe
//! state); faults latch until [`crate::Request::ClearFaults`].
//!
//! Overcurrent has two layers, each with its own bit so `rig faults` says which one
//! tripped: [`FaultFlags::HW_OVERCURRENT`] is the comparator and timer-break path that
//! switches the bridge off within microseconds without software, [`FaultFlags::OVERCURRENT`]
//! the firmware's check of the measured current. Each latches when its own layer saw the
//! condition, so both may be set.
//!
//! The names are user-visible (`rig faults`, `rig sim faults`): never rename one.

use crate::flags::flag_set;

flag_set! {
    /// Set of supervisor faults, a `u32` varint on the wire (bits 17 and up are free for
    /// later faults; a peer keeps bits it has no name for).
    pub struct FaultFlags(u32) {
        /// Measured motor current above `RigParameters::max_current_a` (the software layer).
        const OVERCURRENT = 0;
        /// The cam does not turn although the motor is driven.
        const STALL = 1;
        /// Encoder signal lost or implausible.
        const ENCODER_LOSS = 2;
        /// Current-sensor zero offset outside its expected range (at re-zero).
        const CURRENT_ZERO_RANGE = 3;
        /// The control loop missed its deadline.
        const CONTROL_OVERRUN = 4;
        /// The stored rig parameters (calibration) failed their check; the paper's defaults
        /// are in use.
        const CALIBRATION_INVALID = 5;
        /// The last reset was caused by the watchdog.
        const WATCHDOG_RESET = 6;
        /// No heartbeat within the comms timeout while released.
        const COMMS_TIMEOUT = 7;
        /// The required cam torque (Eq. 10) exceeds what the vibrator can deliver.
        const CANNOT_RELEASE = 8;
        /// The cam or output is mechanically blocked.
        const JAM = 9;
        /// Load estimate above `RigParameters::max_release_load_nm`.
        const OVERLOAD = 10;
        /// A torque or speed estimate is outside physical bounds (NaN, sign, magnitude).
        const ESTIMATE_IMPLAUSIBLE = 11;
        /// The cam turns against the drive's sign for longer than the set time: the encoder
        /// (or the motor) is wired reversed.
        const REVERSED_ENCODER = 12;
        /// While released, the load estimate rose above the board's cap on the release load
        /// (the gear's tooth-strength limit), which no parameter record can lift.
        const LOAD_LIMIT = 13;
        /// The output shaft turns faster than the configured limit (output encoder fitted).
        const OUTPUT_OVERSPEED = 14;
        /// The hardware overcurrent trip (comparator into the PWM timer's break input)
        /// switched the bridge off.
        const HW_OVERCURRENT = 15;
        /// The bridge's supply bus rose above `model::hardware::board::BUS_OVERVOLTAGE_V`
        /// (the bridge pumping a supply that cannot sink, or a supply set too high): the
        /// drive stopped; clears once the bus is back under the threshold.
        const BUS_OVERVOLTAGE = 16;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bits_are_distinct_and_named() {
        let mut seen = 0u32;
        for (_, flag) in FaultFlags::NAMED {
            assert_eq!(flag.bits().count_ones(), 1);
            assert_eq!(seen & flag.bits(), 0);
            seen |= flag.bits();
        }
        assert_eq!(FaultFlags::all().bits(), seen);
    }

    #[test]
    fn display_lists_names_and_unknown_bits() {
        let f = FaultFlags::OVERCURRENT | FaultFlags::JAM | FaultFlags::from_bits_retain(0x10_0000);
        assert_eq!(f.to_string(), "OVERCURRENT | JAM | 0x100000");
        assert_eq!(FaultFlags::empty().to_string(), "none");
        assert_eq!(format!("{:?}", FaultFlags::STALL), "FaultFlags(STALL)");
        let new = FaultFlags::REVERSED_ENCODER
            | FaultFlags::LOAD_LIMIT
            | FaultFlags::OUTPUT_OVERSPEED
            | FaultFlags::HW_OVERCURRENT;
        assert_eq!(
            new.to_string(),
            "REVERSED_ENCODER | LOAD_LIMIT | OUTPUT_OVERSPEED | HW_OVERCURRENT"
        );
        assert_eq!(new.bits(), 0xF000);
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
