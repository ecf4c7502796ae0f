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
        const OVERCURRENT = 0
            => "motor current above the calibration's max_current_a: check for a jammed cam, then `rig clear`";
        /// The cam does not turn although the motor is driven.
        const STALL = 1
            => "the cam did not turn although driven: check the cam and the motor wiring, then `rig clear`";
        /// Encoder signal lost or implausible.
        const ENCODER_LOSS = 2
            => "encoder signal lost or implausible: check the AMT102 cable, then `rig clear`";
        /// Current-sensor zero offset outside its expected range (at re-zero).
        const CURRENT_ZERO_RANGE = 3
            => "current-sensor zero out of range: check the ACS714 supply with the motor off, then `rig clear`";
        /// The control loop missed its deadline.
        const CONTROL_OVERRUN = 4
            => "the control loop missed its deadline: report it with `rig info` and `rig log`, then `rig clear`";
        /// The stored rig parameters (calibration) failed their check; the paper's defaults
        /// are in use.
        const CALIBRATION_INVALID = 5
            => "the stored calibration failed its check (the paper's values are in use): `rig calibration set FILE` or `rig calibrate`";
        /// The last reset was caused by the watchdog.
        const WATCHDOG_RESET = 6
            => "the firmware was reset by its watchdog (the control loop stalled): report it with `rig log`, then `rig clear`";
        /// No heartbeat within the comms timeout while released.
        const COMMS_TIMEOUT = 7
            => "no accepted request (heartbeat) within the comms timeout while released: the host went away or the link stalled; `rig clear` to release again";
        /// The required cam torque (Eq. 10) exceeds what the vibrator can deliver.
        const CANNOT_RELEASE = 8
            => "the required cam torque (Eq. 10) exceeds what the vibrator delivers: lower the load, then `rig clear`";
        /// The cam or output is mechanically blocked.
        const JAM = 9
            => "the cam or the output is blocked: free it with the motor off, then `rig clear`";
        /// Load estimate above `RigParameters::max_release_load_nm`.
        const OVERLOAD = 10
            => "load estimate above the calibration's max_release_load_nm: lower the load, then `rig clear`";
        /// A torque or speed estimate is outside physical bounds (NaN, sign, magnitude).
        const ESTIMATE_IMPLAUSIBLE = 11
            => "a torque or speed estimate is out of physical bounds: check the calibration and the sensors, then `rig clear`";
        /// The cam turns against the drive's sign for longer than the set time: the encoder
        /// (or the motor) is wired reversed.
        const REVERSED_ENCODER = 12
            => "the cam turns against the drive: swap the encoder's A/B wires (or the motor leads), then `rig clear`";
        /// While released, the load estimate rose above the board's cap on the release load
        /// (the gear's tooth-strength limit), which no parameter record can lift.
        const LOAD_LIMIT = 13
            => "while released the load estimate rose above the board's cap (tooth strength, 3.68 N m): lower the load, then `rig clear`";
        /// The output shaft turns faster than the configured limit (output encoder fitted).
        const OUTPUT_OVERSPEED = 14
            => "the output shaft turned faster than the limit (a falling load): stop the load by hand, then `rig clear` once it rests";
        /// The hardware overcurrent trip (comparator into the PWM timer's break input)
        /// switched the bridge off.
        const HW_OVERCURRENT = 15
            => "the hardware overcurrent trip switched the bridge off: check for a short or a jammed cam, then `rig clear` (it clears once the current is below the trip)";
        /// The bridge's supply bus rose above `model::hardware::board::BUS_OVERVOLTAGE_V`
        /// (the bridge pumping a supply that cannot sink, or a supply set too high): the
        /// drive stopped; clears once the bus is back under the threshold.
        const BUS_OVERVOLTAGE = 16
            => "the bridge's supply bus rose above its limit (a supply that cannot sink the braking current, or set too high): lower the supply or fit a braking resistor, then `rig clear` once the bus is back under the limit";
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
    fn every_fault_and_status_flag_has_help() {
        fn check<F: Copy>(table: &[crate::FlagInfo<F>], bits: impl Fn(F) -> u64, all: u64) {
            let mut covered = 0;
            for row in table {
                assert!(
                    row.help.len() > 20 && !row.help.contains("unknown"),
                    "{} has no real help: {:?}",
                    row.name,
                    row.help
                );
                covered |= bits(row.flag);
            }
            assert_eq!(covered, all, "a named bit is missing from the table");
        }
        check(
            FaultFlags::TABLE,
            |f| u64::from(f.bits()),
            u64::from(FaultFlags::all().bits()),
        );
        check(
            crate::StatusFlags::TABLE,
            |f| u64::from(f.bits()),
            u64::from(crate::StatusFlags::all().bits()),
        );
        check(
            crate::Capabilities::TABLE,
            |f| u64::from(f.bits()),
            u64::from(crate::Capabilities::all().bits()),
        );
        // Every fault tells the user how to get out of it.
        for row in FaultFlags::TABLE {
            assert!(row.help.contains("rig "), "{}: {}", row.name, row.help);
        }
        assert_eq!(
            FaultFlags::help_of("OUTPUT_OVERSPEED"),
            Some(FaultFlags::TABLE[14].help)
        );
        assert_eq!(FaultFlags::help_of("NO_SUCH_FAULT"), None);
        let f = FaultFlags::JAM | FaultFlags::from_bits_retain(1 << 20);
        assert_eq!(
            f.explained().map(|r| r.name).collect::<std::vec::Vec<_>>(),
            ["JAM"]
        );
        assert_eq!(f.unknown().bits(), 1 << 20);
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
