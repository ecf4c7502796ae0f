//! The stack guard: an MPU region with no access between the statics and the stack.
//!
//! cortex-m-rt puts the statics (`.data`, `.bss`, `.uninit`: the core, the executor, the
//! crash record) at the bottom of RAM and the stack at the top, growing down towards them.
//! Without a guard an overflow grows silently into them. [`region`] places a
//! [`GUARD_BYTES`] region, no access and never executable, just above the end of the
//! statics (rounded up to the region's alignment), so the first stack access below the
//! stack's floor raises a MemManage fault. MemManage is not enabled on its own, so it
//! escalates to HardFault, whose handler reaches the safe state without touching the stack
//! (`safety`); if the HardFault's own stacking faults too, the core locks up, and
//! SYSCFG_CFGR2.CLL turns the lockup into TIM1's break (MOE off in hardware) until the
//! window watchdog resets the chip.
//!
//! A frame that moves SP by more than [`GUARD_BYTES`] in one step can jump the guard (no
//! stack probes on thumbv7em); the target bench reports the deepest call (a few hundred
//! bytes) and the firmware's tasks keep their buffers in statics.
//!
//! Pure arithmetic, so it is tested on the host; `safety::install_stack_guard` programs it.

/// Size of the guard region, bytes (a power of two, at least 32: ARMv7-M MPU).
pub const GUARD_BYTES: u32 = 1024;

/// An ARMv7-M MPU region: what to write to MPU_RBAR (with the region number and VALID) and
/// MPU_RASR.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Region {
    /// Base address (aligned to the size).
    pub base: u32,
    /// MPU_RBAR: base | VALID | region number.
    pub rbar: u32,
    /// MPU_RASR: XN, AP = no access, SIZE, ENABLE.
    pub rasr: u32,
}

/// MPU_RBAR.VALID: the region number comes from RBAR's low bits.
const RBAR_VALID: u32 = 1 << 4;
/// MPU_RASR.XN: never executable.
const RASR_XN: u32 = 1 << 28;
/// MPU_RASR.ENABLE.
const RASR_ENABLE: u32 = 1;

/// The guard as MPU region `number` for statics ending at `statics_end` in a RAM ending at
/// `ram_end` (exclusive); `None` when the guard does not fit between them.
pub fn region(number: u32, statics_end: u32, ram_end: u32) -> Option<Region> {
    let base = statics_end.checked_add(GUARD_BYTES - 1)? & !(GUARD_BYTES - 1);
    // The guard must leave the stack room of its own.
    if base.checked_add(2 * GUARD_BYTES)? > ram_end || number > 7 {
        return None;
    }
    // SIZE: region of 2^(SIZE + 1) bytes; AP = 0b000 (no access, privileged or not).
    let size_field = GUARD_BYTES.trailing_zeros() - 1;
    Some(Region {
        base,
        rbar: base | RBAR_VALID | number,
        rasr: RASR_XN | (size_field << 1) | RASR_ENABLE,
    })
}

const _: () = assert!(GUARD_BYTES.is_power_of_two() && GUARD_BYTES >= 32);

#[cfg(test)]
mod tests {
    use super::*;

    const RAM_END: u32 = 0x2000_0000 + 96 * 1024;

    #[test]
    fn the_guard_sits_right_above_the_statics_aligned_to_its_size() {
        for end in [0x2000_B3A4u32, 0x2000_B400, 0x2000_B401, 0x2000_0000] {
            let r = region(0, end, RAM_END).expect("fits");
            assert_eq!(r.base % GUARD_BYTES, 0, "{end:#x}");
            // Never over the statics, and no more than one alignment step above them.
            assert!(
                r.base >= end && r.base - end < GUARD_BYTES,
                "{end:#x}: {r:x?}"
            );
            assert_eq!(r.rbar & !0x1F, r.base);
        }
    }

    #[test]
    fn register_words_follow_the_armv7m_encoding() {
        let r = region(3, 0x2000_B3A4, RAM_END).expect("fits");
        assert_eq!(r.base, 0x2000_B400);
        // RBAR: ADDR | VALID (bit 4) | REGION 3.
        assert_eq!(r.rbar, 0x2000_B413);
        // RASR: XN (28), AP 000 (no access), SIZE = 9 (2^10 bytes), ENABLE.
        assert_eq!(r.rasr, (1 << 28) | (9 << 1) | 1);
        assert_eq!((r.rasr >> 24) & 0b111, 0, "AP must be no access");
    }

    #[test]
    fn no_guard_without_room_for_it_and_a_stack() {
        assert_eq!(region(0, RAM_END - GUARD_BYTES, RAM_END), None);
        assert_eq!(region(0, u32::MAX - 10, RAM_END), None);
        assert_eq!(region(8, 0x2000_0000, RAM_END), None);
    }
}
