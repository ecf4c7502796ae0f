//! The System Control Space (ARMv7-M B3.2-B3.4): NVIC, SCB, SysTick, MPU, DWT's cycle
//! counter, the FPU's context registers, and DBGMCU.

use crate::machine::exc;

/// External interrupts of the STM32G474 (RM0440 table 97: 0..=101).
pub const IRQS: usize = 102;
/// Priority bits the G4 implements (the upper nibble).
const PRIO_MASK: u8 = 0xF0;

/// NVIC and SCB state.
#[derive(Debug, Clone)]
pub struct Scs {
    enabled: [bool; IRQS],
    pending: [bool; IRQS],
    prio: [u8; IRQS],
    /// SHPR1-3 bytes for exceptions 4..=15.
    shpr: [u8; 12],
    pendsv: bool,
    systick_pending: bool,
    /// Active exceptions, innermost last.
    active: Vec<u32>,
    /// VTOR.
    pub vtor: u32,
    aircr_prigroup: u32,
    scr: u32,
    ccr: u32,
    shcsr: u32,
    cfsr: u32,
    hfsr: u32,
    /// MMFAR.
    pub mmfar: u32,
    bfar: u32,
    cpacr: u32,
    fpccr: u32,
    fpcar: u32,
    fpdscr: u32,
    demcr: u32,
    dwt_ctrl: u32,
    /// CYCCNT = (cycles - cyc_base) while counting.
    cyc_base: u64,
    cyc_frozen: u32,
    mpu_ctrl: u32,
    mpu_rnr: u32,
    mpu_rbar: [u32; 8],
    mpu_rasr: [u32; 8],
    mpu_changed: bool,
    /// The guard region currently protected in the engine (base, size).
    pub protected: Option<(u32, u32)>,
    systick_csr: u32,
    systick_rvr: u32,
    systick_base: u64,
    dbgmcu: [u32; 5],
    /// SYSRESETREQ was written.
    pub reset_requested: bool,
    /// The last fault's description (for reports).
    pub last_fault: Option<String>,
}

impl Default for Scs {
    fn default() -> Self {
        Self {
            enabled: [false; IRQS],
            pending: [false; IRQS],
            prio: [0; IRQS],
            shpr: [0; 12],
            pendsv: false,
            systick_pending: false,
            active: Vec::new(),
            vtor: 0,
            aircr_prigroup: 0,
            scr: 0,
            ccr: 0x200,
            shcsr: 0,
            cfsr: 0,
            hfsr: 0,
            mmfar: 0,
            bfar: 0,
            cpacr: 0,
            fpccr: 0xC000_0000,
            fpcar: 0,
            fpdscr: 0,
            demcr: 0,
            dwt_ctrl: 0x4000_0000,
            cyc_base: 0,
            cyc_frozen: 0,
            mpu_ctrl: 0,
            mpu_rnr: 0,
            mpu_rbar: [0; 8],
            mpu_rasr: [0; 8],
            mpu_changed: false,
            protected: None,
            systick_csr: 0,
            systick_rvr: 0,
            systick_base: 0,
            dbgmcu: [0x2000_6469, 0, 0, 0, 0],
            reset_requested: false,
            last_fault: None,
        }
    }
}

impl Scs {
    /// Back to the reset state (the protected guard is released by the machine).
    pub fn reset(&mut self) {
        let protected = self.protected;
        let dbgmcu = self.dbgmcu;
        *self = Self::default();
        self.protected = protected;
        // DBGMCU is reset by power-on only.
        self.dbgmcu = dbgmcu;
        self.mpu_changed = protected.is_some();
    }

    /// Marks IRQ `n` pending (a peripheral's request).
    pub fn pend(&mut self, n: usize) {
        if n < IRQS {
            self.pending[n] = true;
        }
    }

    /// Whether anything is pending at all (a cheap test before [`Scs::ready`]).
    pub fn any_pending(&self) -> bool {
        self.pendsv || self.systick_pending || self.pending.iter().any(|p| *p)
    }

    fn priority(&self, number: u32) -> i32 {
        match number {
            2 => -2,
            3 => -1,
            4..=15 => i32::from(self.shpr[number as usize - 4] & PRIO_MASK),
            n => i32::from(self.prio[(n - exc::IRQ0) as usize] & PRIO_MASK),
        }
    }

    /// Priority of the innermost active exception (256 in thread mode).
    pub fn active_priority(&self) -> i32 {
        self.active
            .iter()
            .map(|n| self.priority(*n))
            .min()
            .unwrap_or(256)
    }

    /// The most urgent pending exception that preempts `execution_priority`.
    pub fn ready(&self, execution_priority: i32) -> Option<u32> {
        let mut best: Option<(i32, u32)> = None;
        let mut consider = |n: u32, p: i32| {
            if p < execution_priority && best.is_none_or(|(bp, _)| p < bp) {
                best = Some((p, n));
            }
        };
        if self.pendsv {
            consider(exc::PENDSV, self.priority(exc::PENDSV));
        }
        if self.systick_pending {
            consider(exc::SYSTICK, self.priority(exc::SYSTICK));
        }
        for k in 0..IRQS {
            if self.pending[k] && self.enabled[k] && !self.active.contains(&(exc::IRQ0 + k as u32))
            {
                consider(exc::IRQ0 + k as u32, self.priority(exc::IRQ0 + k as u32));
            }
        }
        best.map(|(_, n)| n)
    }

    /// Clears the pending state of `n` as it is taken.
    pub fn clear_pending(&mut self, n: u32) {
        match n {
            exc::PENDSV => self.pendsv = false,
            exc::SYSTICK => self.systick_pending = false,
            n if n >= exc::IRQ0 => self.pending[(n - exc::IRQ0) as usize] = false,
            _ => {}
        }
    }

    /// `n` becomes active.
    pub fn activate(&mut self, n: u32) {
        self.active.push(n);
    }

    /// The innermost active exception returns.
    pub fn deactivate(&mut self) {
        self.active.pop();
    }

    /// Whether the configurable fault `n` (4..=6) is enabled in SHCSR.
    pub fn fault_enabled(&self, n: u32) -> bool {
        match n {
            exc::MEM_MANAGE => self.shcsr & (1 << 16) != 0,
            exc::BUS_FAULT => self.shcsr & (1 << 17) != 0,
            exc::USAGE_FAULT => self.shcsr & (1 << 18) != 0,
            _ => true,
        }
    }

    /// Sets the fault status registers for a fault of kind `n` described by `why`.
    pub fn record_fault(&mut self, n: u32, why: &str) {
        if why.contains("UDF") || why.contains("undefined") {
            self.cfsr |= 1 << 16;
        } else if why.contains("stack guard") || why.contains("MSTKERR") {
            self.cfsr |= if why.contains("MSTKERR") {
                1 << 4
            } else {
                (1 << 1) | (1 << 7)
            };
        } else if why.contains("BusFault") {
            self.cfsr |= (1 << 9) | (1 << 15);
        }
        if n == exc::HARD_FAULT && !why.contains("BKPT") {
            self.hfsr |= 1 << 30;
        }
        self.last_fault = Some(why.to_string());
    }

    /// Whether `address` is in an enabled no-access MPU region (the stack guard).
    pub fn in_guard(&self, address: u32) -> bool {
        self.guard()
            .is_some_and(|(b, s)| address >= b && address - b < s)
    }

    /// Whether a frame at `[frame, frame + len)` may be stacked.
    pub fn stack_allowed(&self, frame: u32, len: u32) -> bool {
        !(self.in_guard(frame) || self.in_guard(frame + len - 1))
    }

    /// The MPU's no-access region, if the MPU is on and one is configured.
    pub fn guard(&self) -> Option<(u32, u32)> {
        if self.mpu_ctrl & 1 == 0 {
            return None;
        }
        (0..8).find_map(|k| {
            let rasr = self.mpu_rasr[k];
            let ap = (rasr >> 24) & 7;
            (rasr & 1 != 0 && ap == 0).then(|| {
                let size = 1u32 << (((rasr >> 1) & 0x1F) + 1);
                (self.mpu_rbar[k] & !0x1F & !(size - 1), size)
            })
        })
    }

    /// A new guard to protect, once per MPU change.
    pub fn take_mpu_change(&mut self) -> Option<Option<(u32, u32)>> {
        if !std::mem::take(&mut self.mpu_changed) {
            return None;
        }
        Some(self.guard())
    }

    /// Whether the MPU changed (the run loop applies it).
    pub fn mpu_changed(&self) -> bool {
        self.mpu_changed
    }

    /// SysTick's next wrap, if it counts with its interrupt on.
    pub fn next_event(&self, now: u64) -> Option<u64> {
        if self.systick_csr & 3 != 3 || self.systick_rvr == 0 {
            return None;
        }
        let period = self.systick_period();
        let elapsed = now.saturating_sub(self.systick_base);
        Some(self.systick_base + (elapsed / period + 1) * period)
    }

    fn systick_period(&self) -> u64 {
        let div = if self.systick_csr & 4 != 0 { 1 } else { 8 };
        (u64::from(self.systick_rvr) + 1) * div
    }

    /// SysTick's wraps up to `now`.
    pub fn advance(&mut self, now: u64) {
        if self.systick_csr & 1 == 0 || self.systick_rvr == 0 {
            return;
        }
        let period = self.systick_period();
        let wraps = now.saturating_sub(self.systick_base) / period;
        if wraps > 0 {
            self.systick_base += wraps * period;
            self.systick_csr |= 1 << 16;
            if self.systick_csr & 2 != 0 {
                self.systick_pending = true;
            }
        }
    }

    /// Reads the SCS register at `a` (None: not modelled).
    pub fn read(&mut self, a: u32, now: u64) -> Option<u32> {
        let irq_word = |arr: &[bool; IRQS], base: u32| -> u32 {
            let w = ((a - base) / 4) as usize;
            (0..32)
                .filter(|b| arr.get(w * 32 + b).copied().unwrap_or(false))
                .fold(0, |acc, b| acc | (1 << b))
        };
        Some(match a {
            0xE000_1000 => self.dwt_ctrl,
            0xE000_1004 => self.cyccnt(now),
            0xE000_E004 => 3, // ICTR: 128 interrupts
            0xE000_E008 => 0,
            0xE000_E010 => {
                let v = self.systick_csr;
                self.systick_csr &= !(1 << 16);
                v
            }
            0xE000_E014 => self.systick_rvr,
            0xE000_E018 => {
                if self.systick_csr & 1 == 0 {
                    0
                } else {
                    let period = self.systick_period();
                    let into = now.saturating_sub(self.systick_base) % period;
                    ((period - into) / if self.systick_csr & 4 != 0 { 1 } else { 8 }) as u32
                }
            }
            0xE000_E01C => 0x4000_0000 | 21_250, // CALIB: no reference clock, 1 ms at HCLK/8
            0xE000_E100..=0xE000_E11C => irq_word(&self.enabled, 0xE000_E100),
            0xE000_E180..=0xE000_E19C => irq_word(&self.enabled, 0xE000_E180),
            0xE000_E200..=0xE000_E21C => irq_word(&self.pending, 0xE000_E200),
            0xE000_E280..=0xE000_E29C => irq_word(&self.pending, 0xE000_E280),
            0xE000_E300..=0xE000_E31C => {
                let w = (a - 0xE000_E300) / 4;
                self.active
                    .iter()
                    .filter(|n| **n >= exc::IRQ0 && (**n - exc::IRQ0) / 32 == w)
                    .fold(0, |acc, n| acc | 1 << ((n - exc::IRQ0) % 32))
            }
            0xE000_E400..=0xE000_E4EF => {
                let k = (a - 0xE000_E400) as usize;
                u32::from_le_bytes([0, 1, 2, 3].map(|i| self.prio.get(k + i).copied().unwrap_or(0)))
            }
            0xE000_ED00 => 0x410F_C241,
            0xE000_ED04 => {
                let vectactive = self.active.last().copied().unwrap_or(0);
                let pending = self.ready(256).unwrap_or(0);
                vectactive
                    | (pending << 12)
                    | (u32::from(self.pending.iter().any(|p| *p)) << 22)
                    | (u32::from(self.systick_pending) << 26)
                    | (u32::from(self.pendsv) << 28)
            }
            0xE000_ED08 => self.vtor,
            0xE000_ED0C => 0xFA05_0000 | (self.aircr_prigroup << 8),
            0xE000_ED10 => self.scr,
            0xE000_ED14 => self.ccr,
            0xE000_ED18..=0xE000_ED23 => {
                let k = (a - 0xE000_ED18) as usize;
                u32::from_le_bytes([0, 1, 2, 3].map(|i| self.shpr.get(k + i).copied().unwrap_or(0)))
            }
            0xE000_ED24 => self.shcsr,
            0xE000_ED28 => self.cfsr,
            0xE000_ED2C => self.hfsr,
            0xE000_ED30 => 0,
            0xE000_ED34 => self.mmfar,
            0xE000_ED38 => self.bfar,
            0xE000_ED3C => 0,
            0xE000_ED88 => self.cpacr,
            0xE000_ED90 => 8 << 8,
            0xE000_ED94 => self.mpu_ctrl,
            0xE000_ED98 => self.mpu_rnr,
            0xE000_ED9C | 0xE000_EDA4 | 0xE000_EDAC | 0xE000_EDB4 => {
                self.mpu_rbar[(self.mpu_rnr & 7) as usize] | (self.mpu_rnr & 7)
            }
            0xE000_EDA0 | 0xE000_EDA8 | 0xE000_EDB0 | 0xE000_EDB8 => {
                self.mpu_rasr[(self.mpu_rnr & 7) as usize]
            }
            0xE000_EDF0 => 0, // DHCSR: no debugger
            0xE000_EDFC => self.demcr,
            0xE000_EF34 => self.fpccr,
            0xE000_EF38 => self.fpcar,
            0xE000_EF3C => self.fpdscr,
            0xE004_2000..=0xE004_2010 => self.dbgmcu[((a - 0xE004_2000) / 4) as usize],
            _ => return None,
        })
    }

    fn cyccnt(&self, now: u64) -> u32 {
        if self.dwt_ctrl & 1 != 0 && self.demcr & (1 << 24) != 0 {
            now.wrapping_sub(self.cyc_base) as u32
        } else {
            self.cyc_frozen
        }
    }

    /// Writes the SCS register at `a` (false: not modelled).
    pub fn write(&mut self, a: u32, v: u32, size: u32, now: u64) -> bool {
        let set_bits = |arr: &mut [bool; IRQS], base: u32, to: bool| {
            let w = ((a - base) / 4) as usize;
            for b in 0..32 {
                if v >> b & 1 != 0
                    && let Some(x) = arr.get_mut(w * 32 + b)
                {
                    *x = to;
                }
            }
        };
        match a {
            0xE000_1000 => {
                let was = self.cyccnt(now);
                self.dwt_ctrl = (self.dwt_ctrl & 0xF000_0000) | (v & 0x0FFF_FFFF);
                self.cyc_frozen = was;
                self.cyc_base = now.wrapping_sub(u64::from(was));
            }
            0xE000_1004 => {
                self.cyc_frozen = v;
                self.cyc_base = now.wrapping_sub(u64::from(v));
            }
            0xE000_E010 => {
                if v & 1 != 0 && self.systick_csr & 1 == 0 {
                    self.systick_base = now;
                }
                self.systick_csr = v & 7;
            }
            0xE000_E014 => self.systick_rvr = v & 0x00FF_FFFF,
            0xE000_E018 => {
                self.systick_base = now;
                self.systick_csr &= !(1 << 16);
            }
            0xE000_E100..=0xE000_E11C => set_bits(&mut self.enabled, 0xE000_E100, true),
            0xE000_E180..=0xE000_E19C => set_bits(&mut self.enabled, 0xE000_E180, false),
            0xE000_E200..=0xE000_E21C => set_bits(&mut self.pending, 0xE000_E200, true),
            0xE000_E280..=0xE000_E29C => set_bits(&mut self.pending, 0xE000_E280, false),
            0xE000_E400..=0xE000_E4EF => {
                let k = (a - 0xE000_E400) as usize;
                for i in 0..size as usize {
                    if let Some(p) = self.prio.get_mut(k + i) {
                        *p = (v >> (8 * i)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_ED04 => {
                if v & (1 << 28) != 0 {
                    self.pendsv = true;
                }
                if v & (1 << 27) != 0 {
                    self.pendsv = false;
                }
                if v & (1 << 26) != 0 {
                    self.systick_pending = true;
                }
                if v & (1 << 25) != 0 {
                    self.systick_pending = false;
                }
            }
            0xE000_ED08 => self.vtor = v & !0x7F,
            0xE000_ED0C => {
                if v >> 16 == 0x05FA {
                    self.aircr_prigroup = (v >> 8) & 7;
                    if v & 4 != 0 {
                        self.reset_requested = true;
                    }
                }
            }
            0xE000_ED10 => self.scr = v & 0x16,
            0xE000_ED14 => self.ccr = v,
            0xE000_ED18..=0xE000_ED23 => {
                let k = (a - 0xE000_ED18) as usize;
                for i in 0..size as usize {
                    if let Some(p) = self.shpr.get_mut(k + i) {
                        *p = (v >> (8 * i)) as u8 & PRIO_MASK;
                    }
                }
            }
            0xE000_ED24 => self.shcsr = v,
            0xE000_ED28 => self.cfsr &= !v,
            0xE000_ED2C => self.hfsr &= !v,
            0xE000_ED34 => self.mmfar = v,
            0xE000_ED38 => self.bfar = v,
            0xE000_ED88 => self.cpacr = v,
            0xE000_ED94 => {
                self.mpu_ctrl = v & 7;
                self.mpu_changed = true;
            }
            0xE000_ED98 => self.mpu_rnr = v & 0xFF,
            0xE000_ED9C | 0xE000_EDA4 | 0xE000_EDAC | 0xE000_EDB4 => {
                if v & (1 << 4) != 0 {
                    self.mpu_rnr = v & 0xF;
                }
                self.mpu_rbar[(self.mpu_rnr & 7) as usize] = v & !0x1F;
                self.mpu_changed = true;
            }
            0xE000_EDA0 | 0xE000_EDA8 | 0xE000_EDB0 | 0xE000_EDB8 => {
                self.mpu_rasr[(self.mpu_rnr & 7) as usize] = v;
                self.mpu_changed = true;
            }
            0xE000_EDF0 => {}
            0xE000_EDFC => self.demcr = v,
            0xE000_EF00 => self.pend((v & 0x1FF) as usize),
            0xE000_EF34 => self.fpccr = v,
            0xE000_EF38 => self.fpcar = v,
            0xE000_EF3C => self.fpdscr = v,
            0xE004_2004..=0xE004_2010 => self.dbgmcu[((a - 0xE004_2000) / 4) as usize] = v,
            _ => return false,
        }
        true
    }
}
