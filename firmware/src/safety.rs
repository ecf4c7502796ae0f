//! Vibration off on every failure: the safe state, the handlers that reach it, the stall
//! watchdog, and the flash double-ECC path that lets a torn calibration record count as
//! corrupt instead of hanging the boot.
//!
//! # The safe state
//!
//! [`safe_state`] is two stores, nothing that can fault again (no allocation, no formatting,
//! no driver, no critical section):
//!
//! | # | register               | address       | write                         | effect |
//! |---|------------------------|---------------|-------------------------------|--------|
//! | 1 | GPIOA_BSRR             | `0x4800_0018` | `1 << 25` (BR9)               | PA9 low: bridge enable (sleep) off, outputs high-Z |
//! | 2 | TIM1_BDTR              | `0x4001_2C44` | read, clear bit 15 (MOE)      | TIM1 outputs to their idle level: PA8 (PWM) low (OSSI = 1, OIS1 = 0) |
//!
//! The enable goes first: one store with no read, and on its own it stops the bridge.
//! MOE stays clear (AOE = 0), so only the control task can switch the PWM on again.
//!
//! | failure                               | who reaches the safe state             | then |
//! |---------------------------------------|----------------------------------------|------|
//! | panic                                 | [`panic`] (`rust_begin_unwind`), via [`rig_safe_state`] | logs its location once, ~1 ms for the probe, resets |
//! | HardFault (and escalated Mem/Bus/Usage faults) | `HardFault` (no trampoline: no stack read) | records CFSR, resets |
//! | NMI not from a storage ECC error      | `NonMaskableInt`                       | records FLASH_ECCR, resets |
//! | an interrupt or exception with no handler | `DefaultHandler`                   | records the IRQ number, resets |
//! | control loop stalled (ADC, DMA, a step that never ends) | WWDG early-wakeup interrupt, [`StallWatchdog`] | resets; the WWDG resets 48 us later anyway |
//! | stall with interrupts masked, or a lockup | the WWDG reset itself (~2 ms)       | GPIOs reset to analog: the bridge's pull-downs hold it off |
//! | everything else                       | the IWDG (~250 ms, `main.rs`)          | reset |
//! | overcurrent                           | COMP3 -> TIM1 break clears MOE in hardware ([`crate::trip`]); `TIM1_BRK_TIM15` drops the enable ~1 us later | the control step latches it |
//!
//! Handlers other than the panic handler do not log (the fault may be inside the logger);
//! they leave a [`Crash`] record in `.uninit` RAM that the next boot reports.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use cortex_m::peripheral::SCB;
use cortex_m_rt::exception;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac::wwdg::vals::Wdgtb;
use embassy_stm32::peripherals::WWDG;
use embassy_stm32::{Peri, interrupt, pac};

/// TIM1_BDTR (the metapac's `TIM1.bdtr()`, 0x4001_2C44): break and dead-time register.
/// (A function: pointer arithmetic on an address is not allowed in a `const`; it folds to a
/// literal.)
#[inline(always)]
fn tim1_bdtr() -> *mut u32 {
    pac::TIM1.bdtr().as_ptr().cast::<u32>()
}
/// TIM1_BDTR.MOE, main output enable (RM0440 28.6.20, bit 15).
const BDTR_MOE: u32 = 1 << 15;
/// GPIOA_BSRR (the metapac's `GPIOA.bsrr()`, 0x4800_0018): atomic set/reset of GPIOA pins.
#[inline(always)]
fn gpioa_bsrr() -> *mut u32 {
    pac::GPIOA.bsrr().as_ptr().cast::<u32>()
}
/// BSRR reset bit of PA9, the bridge enable.
const BRIDGE_ENABLE_OFF: u32 = 1 << (16 + 9);

/// Switches the bridge off by direct register writes (table above). Callable from any
/// context, any number of times.
///
/// # Safety
/// Writes TIM1 and GPIOA registers behind the drivers' backs; only ever towards "off", which
/// every driver state tolerates.
#[inline(always)]
pub unsafe fn safe_state() {
    unsafe {
        gpioa_bsrr().write_volatile(BRIDGE_ENABLE_OFF);
        let bdtr = tim1_bdtr();
        bdtr.write_volatile(bdtr.read_volatile() & !BDTR_MOE);
    }
}

/// [`safe_state`] as a named, linked symbol: what the panic handler calls, and what a
/// target emulator looks for to count the cycles from a panic to the safe state.
///
/// # Safety
/// As [`safe_state`].
#[unsafe(no_mangle)]
#[inline(never)]
pub unsafe extern "C" fn rig_safe_state() {
    unsafe { safe_state() }
}

/// Why the previous run ended, as its handler recorded it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum CrashCause {
    /// A panic; detail = source line.
    Panic,
    /// A HardFault; detail = SCB CFSR.
    HardFault,
    /// An NMI that was not a storage ECC error; detail = FLASH_ECCR.
    Nmi,
    /// An interrupt or exception without a handler; detail = its number (IRQn, negative for
    /// core exceptions).
    Unhandled,
    /// The control loop missed its deadline (WWDG early wakeup); detail = 0.
    ControlStall,
}

/// A [`CrashCause`] with its detail word.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub struct Crash {
    /// What happened.
    pub cause: CrashCause,
    /// Cause-specific detail (see [`CrashCause`]).
    pub detail: u32,
}

/// Marks a record as written by this firmware (the low byte is the cause).
const CRASH_MAGIC: u32 = 0x5249_4700;

/// Survives a reset (not zeroed at boot): `[magic | cause, detail, check]`.
#[unsafe(link_section = ".uninit.rig_crash")]
static mut CRASH: MaybeUninit<[u32; 3]> = MaybeUninit::uninit();

fn crash_words() -> *mut u32 {
    (&raw mut CRASH).cast::<u32>()
}

fn crash_check(head: u32, detail: u32) -> u32 {
    !head ^ detail.rotate_left(7)
}

/// Records the first failure of this run (a second one, e.g. the WWDG firing while the
/// panic handler waits, does not overwrite it).
fn record(cause: CrashCause, detail: u32) {
    if take_crash_inner(false).is_some() {
        return;
    }
    let head = CRASH_MAGIC | cause as u32;
    // SAFETY: a 12-byte static only this module touches, written with volatile stores.
    unsafe {
        let w = crash_words();
        w.write_volatile(head);
        w.add(1).write_volatile(detail);
        w.add(2).write_volatile(crash_check(head, detail));
    }
}

fn take_crash_inner(clear: bool) -> Option<Crash> {
    // SAFETY: as in `record`; uninitialised RAM is just some bits for a u32.
    let (head, detail, check) = unsafe {
        let w = crash_words();
        let words = (
            w.read_volatile(),
            w.add(1).read_volatile(),
            w.add(2).read_volatile(),
        );
        if clear {
            w.write_volatile(0);
        }
        words
    };
    if head & !0xFF != CRASH_MAGIC || check != crash_check(head, detail) {
        return None;
    }
    let cause = match head & 0xFF {
        0 => CrashCause::Panic,
        1 => CrashCause::HardFault,
        2 => CrashCause::Nmi,
        3 => CrashCause::Unhandled,
        4 => CrashCause::ControlStall,
        _ => return None,
    };
    Some(Crash { cause, detail })
}

/// The previous run's failure record, if it ended in a handler; clears it.
pub fn take_crash() -> Option<Crash> {
    take_crash_inner(true)
}

/// Cycles the panic handler waits before resetting, so a probe can read the last log line
/// (1 ms at 170 MHz; the bridge is already off).
const RTT_DRAIN_CYCLES: u32 = 170_000;

/// Set by the first panic: a panic inside the panic handler's logging resets at once.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
#[inline(never)]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // SAFETY: see `safe_state`.
    unsafe { rig_safe_state() };
    let line = info.location().map_or(0, |l| l.line());
    record(CrashCause::Panic, line);
    if !PANICKING.swap(true, Ordering::Relaxed) {
        if let Some(at) = info.location() {
            // Called through a pointer the optimiser cannot see through: a direct call
            // would put the logger, which can itself panic, in a cycle with this handler,
            // and then the handler keeps every panic message's `core::fmt` arguments alive
            // although it never formats them (3.0 KB of flash: `usize` formatting, padding,
            // the message strings). Through the pointer, the message is provably unused.
            let log: fn(&str, u32) = log_panic;
            core::hint::black_box(log)(at.file(), at.line());
        }
        cortex_m::asm::delay(RTT_DRAIN_CYCLES);
    }
    SCB::sys_reset()
}

/// The panic handler's one log line (see the call for why it is not inlined).
#[inline(never)]
fn log_panic(file: &str, line: u32) {
    defmt::error!("panic at {=str}:{=u32}: bridge off, resetting", file, line);
}

#[exception(trampoline = false)]
unsafe fn HardFault() -> ! {
    // SAFETY: see `safe_state`.
    unsafe { safe_state() };
    // SAFETY: a read of the Configurable Fault Status Register cannot fault.
    let cfsr = unsafe { (*SCB::PTR).cfsr.read() };
    record(CrashCause::HardFault, cfsr);
    SCB::sys_reset()
}

#[exception]
unsafe fn NonMaskableInt() {
    let eccr = pac::FLASH.eccr().read();
    if (eccr.eccd() || eccr.eccd2()) && !eccr.sysf_ecc() && in_storage(ecc_address(eccr.0)) {
        // A torn double word in the calibration store: count it, clear the flag and let the
        // read return; the store's ECC hook turns it into a corrupt slot.
        pac::FLASH.eccr().write(|w| {
            w.set_eccd(true);
            w.set_eccd2(true);
        });
        FLASH_ECC_ERRORS.fetch_add(1, Ordering::Relaxed);
        return;
    }
    // SAFETY: see `safe_state`.
    unsafe { safe_state() };
    record(CrashCause::Nmi, eccr.0);
    SCB::sys_reset()
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    // SAFETY: see `safe_state`.
    unsafe { safe_state() };
    record(CrashCause::Unhandled, irqn as u32);
    SCB::sys_reset()
}

// Declaring linker symbols takes an `unsafe extern` block; only its address is taken.
unsafe extern "C" {
    // cortex-m-rt's `link.x`: the end of the statics (`.data`, `.bss`, `.uninit`), where a
    // heap would start (the firmware has none), and the initial stack pointer (the end of
    // RAM in `memory.x`).
    static __sheap: u8;
    static _stack_start: u8;
}

/// Sets SYSCFG_CFGR2.CLL (the core's LOCKUP into TIM1's break) and reads it back: `true`
/// when it is set. `embassy_stm32::init` pulses SYSCFG's reset (RCC_APB2RSTR.SYSCFGRST),
/// which clears the bit [`arm_last_resort`] set before it, so `main` calls this after the
/// init and logs the read-back (the target bench's boot trace checks the order).
pub fn arm_lockup_break() -> bool {
    pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    pac::SYSCFG.cfgr2().modify(|w| w.set_cll(true));
    pac::SYSCFG.cfgr2().read().cll()
}

/// The priority of the control executor (UART4's vector) and the ceiling of the core's
/// lock ([`CeilingMutex`]): the highest priority of any code that locks the core.
pub const CORE_CEILING: Priority = Priority::P6;

/// The core's lock: a priority ceiling with BASEPRI instead of a critical section
/// (PRIMASK). While locked, BASEPRI masks [`CORE_CEILING`] and below (the control executor
/// and thread mode, the only code that touches the core), so the lock is exclusive; the
/// trip's break interrupt and the WWDG's early wakeup (both P0, above the ceiling, and
/// neither touches the core) are never delayed by it, however long a step takes. The
/// target bench's boot trace checks both priorities against the ceiling.
pub struct CeilingMutex;

// SAFETY: every user of the core runs at or below CORE_CEILING (thread mode, and the control
// executor at exactly CORE_CEILING: `main`), so with BASEPRI at the ceiling none of them can
// preempt the holder, and the holder's own code cannot re-enter `lock` from a higher
// priority. Interrupts above the ceiling never touch the core.
unsafe impl embassy_sync::blocking_mutex::raw::RawMutex for CeilingMutex {
    const INIT: Self = CeilingMutex;

    fn lock<R>(&self, f: impl FnOnce() -> R) -> R {
        let before = cortex_m::register::basepri::read();
        // Raises BASEPRI only (BASEPRI_MAX), so a nested lock keeps the outer ceiling.
        cortex_m::register::basepri_max::write(u8::from(CORE_CEILING));
        let r = f();
        // SAFETY: restores the value read above; a lock never lowers the mask below the
        // level its caller had.
        unsafe { cortex_m::register::basepri::write(before) };
        r
    }
}

/// MPU region used by the stack guard.
const STACK_GUARD_REGION: u32 = 0;
/// MPU_CTRL: ENABLE | PRIVDEFENA (the default memory map everywhere else); HFNMIENA clear,
/// so the HardFault and NMI handlers run with the MPU off.
const MPU_CTRL_ENABLE_PRIVDEFENA: u32 = 0b101;

/// Arms the two last-resort layers against a run that cannot reach a handler (call first
/// thing in `main`; both stay until reset):
///
/// - the stack guard (`crate::stack_guard`): an MPU region with no access between the
///   statics and the stack, so an overflow faults instead of overwriting the core, the
///   executor and the crash record;
/// - SYSCFG_CFGR2.CLL: the Cortex-M4's LOCKUP output into TIM1's break, so a core lockup
///   (a fault inside the HardFault handler or its stacking) clears MOE in hardware instead
///   of leaving TIM1 switching until the window watchdog resets the chip (~2 ms later).
///   The bit is write-once: only a reset clears it, and `embassy_stm32::init`'s pulse of
///   SYSCFG's reset does: [`arm_lockup_break`] sets it again after the init.
pub fn arm_last_resort() {
    // SYSCFG is clocked with RCC_APB2ENR.SYSCFGEN (the bit embassy's init sets too).
    pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    pac::SYSCFG.cfgr2().modify(|w| w.set_cll(true));
    let statics_end = (&raw const __sheap) as u32;
    let stack_top = (&raw const _stack_start) as u32;
    let Some(region) = crate::stack_guard::region(STACK_GUARD_REGION, statics_end, stack_top)
    else {
        // No room (the statics fill RAM): the link-time budget check fails long before.
        return;
    };
    // SAFETY: the MPU is programmed once at boot, before anything runs on the stack's
    // floor; the region only denies accesses to otherwise unused RAM between the statics
    // and the stack.
    unsafe {
        let mpu = &*cortex_m::peripheral::MPU::PTR;
        mpu.rbar.write(region.rbar);
        mpu.rasr.write(region.rasr);
        mpu.ctrl.write(MPU_CTRL_ENABLE_PRIVDEFENA);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// Unmasks the break interrupt (TIM1_BRK_TIM15; TIM15 is unused) at the highest priority.
pub fn enable_break_interrupt() {
    interrupt::TIM1_BRK_TIM15.unpend();
    interrupt::TIM1_BRK_TIM15.set_priority(Priority::P0);
    // SAFETY: the handler below is bound to this vector.
    unsafe { interrupt::TIM1_BRK_TIM15.enable() };
}

/// Set by the break interrupt, cleared only by the bridge's re-arm
/// (`firmware_core::bridge::BridgeHw::clear_break`): a trip software cannot undo by
/// setting MOE again once the comparator has fallen back.
pub static BREAK_LATCHED: AtomicBool = AtomicBool::new(false);

/// Hardware overcurrent trips since boot (the break interrupt counts them).
pub static HW_TRIPS: AtomicU32 = AtomicU32::new(0);

/// TIM1's break (COMP3 over the current threshold): the hardware has already cleared MOE;
/// this drops the bridge enable as well (~1 us later) and masks itself until the control
/// task re-arms the break after the core has acknowledged the trip.
#[interrupt]
#[allow(non_snake_case)]
unsafe fn TIM1_BRK_TIM15() {
    // SAFETY: a store to the enable pin's reset bit, as in `safe_state`.
    unsafe { gpioa_bsrr().write_volatile(BRIDGE_ENABLE_OFF) };
    // Latched for the control task, which may be between its break check and MOE: it
    // re-checks this after setting MOE and holds the bridge off until a deliberate re-arm.
    BREAK_LATCHED.store(true, Ordering::Release);
    pac::TIM1.dier().modify(|w| w.set_bie(false));
    HW_TRIPS.fetch_add(1, Ordering::Relaxed);
}

/// The window watchdog's early wakeup: the control loop did not come round in time.
#[interrupt]
#[allow(non_snake_case)]
unsafe fn WWDG() {
    // SAFETY: see `safe_state`.
    unsafe { safe_state() };
    record(CrashCause::ControlStall, 0);
    SCB::sys_reset()
}

/// APB1 clock that counts the WWDG (SYSCLK, APB1 undivided: `board::config`).
const PCLK1_HZ: u32 = model::hardware::board::SYSCLK_HZ as u32;
/// WWDG prescaler: 4096 x 2.
const WWDG_DIVIDER: u32 = 4096 * 2;
/// One WWDG count, ns (48.2 us).
const WWDG_TICK_NS: u32 = (WWDG_DIVIDER as u64 * 1_000_000_000 / PCLK1_HZ as u64) as u32;
/// Longest gap between two control steps before the early wakeup fires, us: two control
/// periods, the core's own `CONTROL_OVERRUN` threshold.
pub const STALL_TIMEOUT_US: u32 = 2_000;
/// The counter value each step reloads: the early wakeup fires at 0x40, so this many counts
/// (41 x 48.2 us = 1.98 ms) after the last step.
const WWDG_RELOAD: u8 = 0x40 + (STALL_TIMEOUT_US * 1000 / WWDG_TICK_NS) as u8;
const _: () = assert!(WWDG_RELOAD <= 0x7F && WWDG_RELOAD > 0x40);

/// The window watchdog as a control-loop deadline: each control step reloads it; a step
/// that does not come within [`STALL_TIMEOUT_US`] (ADC or DMA stalled, a step that never
/// ends) raises its early-wakeup interrupt, which puts the bridge in the safe state and
/// resets. The IWDG (~250 ms, fed by a task that needs every task's check-in) stays as the
/// last layer.
pub struct StallWatchdog {
    _wwdg: Peri<'static, WWDG>,
}

impl StallWatchdog {
    /// Clocks the WWDG and freezes it while a debugger halts the core (TIM1's outputs are
    /// switched off by the same halt); it does not run until [`StallWatchdog::start`].
    pub fn new(wwdg: Peri<'static, WWDG>) -> Self {
        pac::RCC.apb1enr1().modify(|w| w.set_wwdgen(true));
        pac::DBGMCU.apb1lfzr().modify(|w| w.set_wwdg(true));
        Self { _wwdg: wwdg }
    }

    /// Starts the deadline (once; the WWDG cannot be stopped until reset). Call right
    /// before the control loop's first wait for data.
    pub fn start(&mut self) {
        pac::WWDG.cfr().write(|w| {
            w.set_w(0x7F);
            w.set_wdgtb(Wdgtb::DIV2);
            w.set_ewi(true);
        });
        pac::WWDG.sr().write(|w| w.set_ewif(false));
        interrupt::WWDG.unpend();
        interrupt::WWDG.set_priority(Priority::P0);
        // SAFETY: the handler above is bound to this vector.
        unsafe { interrupt::WWDG.enable() };
        self.feed();
    }

    /// Reloads the deadline: call once per control step.
    #[inline]
    pub fn feed(&mut self) {
        pac::WWDG.cr().write(|w| {
            w.set_t(WWDG_RELOAD);
            w.set_wdga(true);
        });
    }
}

/// Double-ECC errors the NMI handler saw in the STORAGE region since
/// [`take_flash_ecc_error`] last took them.
pub static FLASH_ECC_ERRORS: AtomicU32 = AtomicU32::new(0);

/// Whether the NMI handler saw a double-ECC error in the STORAGE region since the last
/// call, clearing the record: the calibration store's ECC hook
/// (`CalibrationStore::with_ecc_check`), which then counts the slot it read as corrupt.
pub fn take_flash_ecc_error() -> bool {
    FLASH_ECC_ERRORS.swap(0, Ordering::Relaxed) != 0
}

// Declaring linker symbols takes an `unsafe extern` block; only their addresses are taken.
unsafe extern "C" {
    // Defined by memory.x.
    static __storage_start: u8;
    static __storage_end: u8;
}

/// The STORAGE region of `memory.x`, absolute addresses `[start, end)`.
pub fn storage_region() -> (u32, u32) {
    (
        (&raw const __storage_start) as u32,
        (&raw const __storage_end) as u32,
    )
}

fn in_storage(address: u32) -> bool {
    let (start, end) = storage_region();
    (start..end).contains(&address)
}

/// Flash start, and bank 2's offset in dual-bank mode (DBANK = 1, 2 x 256 KiB).
const FLASH_BASE: u32 = 0x0800_0000;
const BANK2_OFFSET: u32 = 0x4_0000;

/// The address FLASH_ECCR reports: ADDR_ECC is a byte offset in the bank BK_ECC names.
fn ecc_address(eccr: u32) -> u32 {
    let reg = pac::flash::regs::Eccr(eccr);
    FLASH_BASE + if reg.bk_ecc() { BANK2_OFFSET } else { 0 } + reg.addr_ecc()
}
