//! The system peripherals (RM0440): RCC (ready bits, reset flags, peripheral reset pulses),
//! PWR, FLASH (latency, option bytes, unlock, page erase and double-word programming with
//! their timing, ECC), SYSCFG, COMP3, DAC3, GPIO, EXTI, IWDG and WWDG.

use std::collections::BTreeMap;

/// Registers that only hold what was written (their effect is not modelled beyond that).
#[derive(Debug, Clone, Default)]
pub struct Plain {
    known: &'static [u32],
    reset: &'static [(u32, u32)],
    values: BTreeMap<u32, u32>,
}

impl Plain {
    /// A block whose registers are at `known` offsets with reset values `reset`.
    pub fn new(known: &'static [u32], reset: &'static [(u32, u32)]) -> Self {
        let mut p = Self {
            known,
            reset,
            values: BTreeMap::new(),
        };
        p.reset();
        p
    }
    /// Reset values.
    pub fn reset(&mut self) {
        self.values = self.reset.iter().copied().collect();
    }
    /// Value at `o`, if the offset is a register.
    pub fn read(&self, o: u32) -> Option<u32> {
        self.known
            .contains(&o)
            .then(|| self.values.get(&o).copied().unwrap_or(0))
    }
    /// Stores `v` at `o`, if the offset is a register.
    pub fn write(&mut self, o: u32, v: u32) -> bool {
        if self.known.contains(&o) {
            self.values.insert(o, v);
            true
        } else {
            false
        }
    }
    /// Current value (0 when never written).
    pub fn get(&self, o: u32) -> u32 {
        self.values.get(&o).copied().unwrap_or(0)
    }
    /// Sets a value directly (hardware side).
    pub fn set(&mut self, o: u32, v: u32) {
        self.values.insert(o, v);
    }
}

/// RCC_CSR reset flags.
pub mod csr {
    /// NRST pin (every internal reset pulls it too).
    pub const PINRSTF: u32 = 1 << 26;
    /// Brown-out / power-on.
    pub const BORRSTF: u32 = 1 << 27;
    /// Software (SYSRESETREQ).
    pub const SFTRSTF: u32 = 1 << 28;
    /// Independent watchdog.
    pub const IWDGRSTF: u32 = 1 << 29;
    /// Window watchdog.
    pub const WWDGRSTF: u32 = 1 << 30;
}

const RCC_REGS: &[u32] = &[
    0x00, 0x04, 0x08, 0x0C, 0x18, 0x1C, 0x20, 0x28, 0x2C, 0x30, 0x38, 0x3C, 0x40, 0x48, 0x4C, 0x50,
    0x58, 0x5C, 0x60, 0x68, 0x6C, 0x70, 0x78, 0x7C, 0x80, 0x88, 0x90, 0x94, 0x98, 0x9C,
];
const RCC_RESET: &[(u32, u32)] = &[
    (0x00, 0x0000_0063),
    (0x04, 0x4000_0000),
    (0x08, 0x0000_0005),
    (0x0C, 0x0000_1000),
    (0x48, 0x0000_0100),
    (0x50, 0x0000_0000),
    (0x58, 0x0000_0400),
    (0x94, 0x0C00_0000),
    (0x98, 0x0000_0000),
];

/// Reset and clock control.
#[derive(Debug, Clone)]
pub struct Rcc {
    /// The registers.
    pub regs: Plain,
}

impl Default for Rcc {
    fn default() -> Self {
        Self {
            regs: Plain::new(RCC_REGS, RCC_RESET),
        }
    }
}

impl Rcc {
    /// Power-on: every register at reset, CSR says power-on and pin.
    pub fn power_on(&mut self) {
        self.regs.reset();
        self.regs.set(0x94, csr::PINRSTF | csr::BORRSTF);
    }

    /// A system reset by `flags` (CSR keeps its flags until RMVF).
    pub fn system_reset(&mut self, flags: u32) {
        let csr = self.regs.get(0x94) & 0xFE00_0000;
        self.regs.reset();
        self.regs.set(0x94, (csr | flags | csr::PINRSTF) & !1);
    }

    /// Read with the ready bits following their enables.
    pub fn read(&self, o: u32) -> Option<u32> {
        let v = self.regs.read(o)?;
        Some(match o {
            0x00 => {
                let mut v = v;
                for (on, rdy) in [(8, 10), (16, 17), (24, 25)] {
                    if v >> on & 1 != 0 {
                        v |= 1 << rdy;
                    } else {
                        v &= !(1 << rdy);
                    }
                }
                v
            }
            0x08 => (v & !0xC) | ((v & 3) << 2),
            0x90 | 0x94 | 0x98 => {
                if v & 1 != 0 {
                    v | 2
                } else {
                    v & !2
                }
            }
            _ => v,
        })
    }

    /// Write; returns the reset bits newly set in a reset register (offset, bits).
    pub fn write(&mut self, o: u32, v: u32) -> Option<u32> {
        if o == 0x94 {
            // RMVF clears the reset flags.
            let flags = if v & (1 << 23) != 0 {
                0
            } else {
                self.regs.get(0x94) & 0xFE00_0000
            };
            self.regs.set(0x94, (v & 0x1) | flags);
            return Some(0);
        }
        let old = self.regs.get(o);
        if !self.regs.write(o, v) {
            return None;
        }
        Some(if matches!(o, 0x28 | 0x2C | 0x30 | 0x38 | 0x3C | 0x40) {
            v & !old
        } else {
            0
        })
    }
}

/// The calibration store's flash controller (RM0440 5): unlock sequence, page erase and
/// double-word programming with the datasheet's timing (DS12288: 22 ms a page, 82 us a
/// double word), BSY while busy, EOP, the errors a wrong sequence gives.
#[derive(Debug, Clone)]
pub struct Flash {
    acr: u32,
    keys: u8,
    cr: u32,
    sr: u32,
    eccr: u32,
    other: Plain,
    /// Busy until this cycle.
    pub busy_until: u64,
    /// The first word of a double word being programmed.
    half: Option<(u32, u32)>,
    /// Erases and programs done.
    pub erases: u32,
    /// Double words programmed.
    pub programs: u32,
}

/// Page erase time, s (DS12288 table 49, typical).
pub const PAGE_ERASE_S: f64 = 22.0e-3;
/// Double-word program time, s.
pub const PROGRAM_S: f64 = 82.0e-6;

impl Default for Flash {
    fn default() -> Self {
        Self {
            acr: 0x600,
            keys: 0,
            cr: 0xC000_0000,
            sr: 0,
            eccr: 0,
            other: Plain::new(
                &[
                    0x04, 0x0C, 0x20, 0x24, 0x28, 0x2C, 0x30, 0x44, 0x48, 0x4C, 0x50, 0x70, 0x80,
                ],
                // OPTR: the G474RE's factory option bytes (DBANK set).
                &[(0x20, 0xFFEF_F8AA)],
            ),
            busy_until: 0,
            half: None,
            erases: 0,
            programs: 0,
        }
    }
}

/// What a flash register write asks the memory to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlashOp {
    /// Nothing.
    None,
    /// Erase the 2 KiB page at this address.
    Erase(u32),
}

impl Flash {
    /// Reset (ACR latency back to 0 wait states).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Register read at `o`.
    pub fn read(&self, o: u32, now: u64) -> Option<u32> {
        Some(match o {
            0x00 => self.acr,
            0x08 => 0,
            0x10 => self.sr | (u32::from(now < self.busy_until) << 16),
            0x14 => self.cr,
            0x18 => self.eccr,
            o => self.other.read(o)?,
        })
    }

    /// Register write at `o`.
    pub fn write(&mut self, o: u32, v: u32, now: u64) -> Option<FlashOp> {
        let mut op = FlashOp::None;
        match o {
            0x00 => self.acr = v,
            0x08 => {
                // KEY1 then KEY2 unlocks CR; anything else locks it until reset.
                self.keys = match (self.keys, v) {
                    (0, 0x4567_0123) => 1,
                    (1, 0xCDEF_89AB) => {
                        self.cr &= !(1 << 31);
                        0
                    }
                    _ => {
                        self.sr |= 1 << 1;
                        0
                    }
                };
            }
            0x10 => self.sr &= !(v & 0xC3FB),
            0x14 => {
                if self.cr & (1 << 31) != 0 {
                    // Locked: only LOCK and OPTLOCK stay.
                    return Some(op);
                }
                self.cr = v;
                if v & (1 << 16) != 0 && v & (1 << 1) != 0 {
                    // STRT with PER: erase page PNB of bank BKER.
                    let page = (v >> 3) & 0x7F;
                    let bank = (v >> 11) & 1;
                    let address = 0x0800_0000 + bank * 0x4_0000 + page * 2048;
                    self.busy_until = now + (PAGE_ERASE_S * 170.0e6) as u64;
                    self.sr |= 1;
                    self.cr &= !(1 << 16);
                    self.erases += 1;
                    op = FlashOp::Erase(address);
                }
            }
            0x18 => self.eccr = v,
            o => {
                if !self.other.write(o, v) {
                    return None;
                }
            }
        }
        Some(op)
    }

    /// A CPU write of `value` into flash memory at `address`: programmed when PG is set and
    /// the double word is complete (returns the words to store), an error flag otherwise.
    pub fn program(&mut self, address: u32, value: u32, now: u64) -> Option<(u32, [u32; 2])> {
        if self.cr & 1 == 0 || self.cr & (1 << 31) != 0 {
            // PGSERR: a write to flash with no programming enabled.
            self.sr |= 1 << 7;
            return None;
        }
        match self.half.take() {
            None if address.is_multiple_of(8) => {
                self.half = Some((address, value));
                None
            }
            Some((first, w0)) if address == first + 4 => {
                self.busy_until = now + (PROGRAM_S * 170.0e6) as u64;
                self.sr |= 1;
                self.programs += 1;
                Some((first, [w0, value]))
            }
            _ => {
                // PGAERR / SIZERR.
                self.sr |= 1 << 5;
                None
            }
        }
    }

    /// Programming enabled (CR.PG, unlocked).
    pub fn cr_pg(&self) -> bool {
        self.cr & 1 != 0 && self.cr & (1 << 31) == 0
    }

    /// The first word of a double word is waiting for the second.
    pub fn half_pending(&self) -> bool {
        self.half.is_some()
    }

    /// A programmed double word was not erased: PROGERR.
    pub fn program_error(&mut self) {
        self.sr |= 1 << 3;
    }
}

/// GPIO port (RM0440 9).
#[derive(Debug, Clone)]
pub struct Gpio {
    regs: Plain,
}

const GPIO_REGS: &[u32] = &[0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x1C, 0x20, 0x24];

impl Gpio {
    /// Port `k` (0 = A) at reset.
    pub fn new(k: usize) -> Self {
        const A: &[(u32, u32)] = &[
            (0x00, 0xABFF_FFFF),
            (0x08, 0x0C00_0000),
            (0x0C, 0x6400_0000),
        ];
        const B: &[(u32, u32)] = &[(0x00, 0xFFFF_FEBF), (0x0C, 0x0000_0100)];
        const OTHER: &[(u32, u32)] = &[(0x00, 0xFFFF_FFFF)];
        let reset = match k {
            0 => A,
            1 => B,
            _ => OTHER,
        };
        Self {
            regs: Plain::new(GPIO_REGS, reset),
        }
    }

    /// Back to reset.
    pub fn reset(&mut self) {
        self.regs.reset();
    }

    /// ODR.
    pub fn odr(&self) -> u32 {
        self.regs.get(0x14)
    }

    /// Pin `n`'s mode (0 input, 1 output, 2 alternate, 3 analog).
    pub fn mode(&self, n: u32) -> u32 {
        (self.regs.get(0x00) >> (2 * n)) & 3
    }

    /// Whether pin `n` drives high as a GPIO output.
    pub fn output_high(&self, n: u32) -> bool {
        self.mode(n) == 1 && self.odr() >> n & 1 != 0
    }

    /// Register read; `inputs` are the levels driven from outside (bit per pin).
    pub fn read(&self, o: u32, inputs: u32) -> Option<u32> {
        if o == 0x10 {
            let mut idr = 0;
            let pupdr = self.regs.get(0x0C);
            for n in 0..16 {
                let level = match self.mode(n) {
                    1 => self.odr() >> n & 1,
                    3 => 0,
                    _ => match (inputs >> n) & 1 {
                        1 => 1,
                        _ => u32::from((pupdr >> (2 * n)) & 3 == 1),
                    },
                };
                idr |= level << n;
            }
            return Some(idr);
        }
        if o == 0x18 || o == 0x28 {
            return Some(0);
        }
        self.regs.read(o)
    }

    /// Register write.
    pub fn write(&mut self, o: u32, v: u32) -> bool {
        match o {
            0x18 => {
                let odr = (self.odr() | (v & 0xFFFF)) & !(v >> 16);
                self.regs.set(0x14, odr);
                true
            }
            0x28 => {
                let odr = self.odr() & !(v & 0xFFFF);
                self.regs.set(0x14, odr);
                true
            }
            _ => self.regs.write(o, v),
        }
    }
}

/// Independent watchdog (RM0440 42): LSI at 32 kHz, key register, reload, timeout reset.
#[derive(Debug, Clone, Default)]
pub struct Iwdg {
    pr: u32,
    rlr: u32,
    winr: u32,
    unlocked: bool,
    /// Started (cannot be stopped until reset).
    pub running: bool,
    /// The reset falls at this cycle.
    pub expires: u64,
    /// Reloads since start.
    pub reloads: u64,
}

/// LSI frequency, Hz.
const LSI_HZ: u64 = 32_000;

impl Iwdg {
    fn timeout_cycles(&self) -> u64 {
        let div = 4u64 << self.pr.min(6);
        let rl = if self.rlr == 0 {
            0xFFF
        } else {
            u64::from(self.rlr)
        };
        (rl + 1) * div * 170_000_000 / LSI_HZ
    }

    /// Register read.
    pub fn read(&self, o: u32) -> Option<u32> {
        Some(match o {
            0x00 => 0,
            0x04 => self.pr,
            0x08 => {
                if self.rlr == 0 {
                    0xFFF
                } else {
                    self.rlr
                }
            }
            0x0C => 0,
            0x10 => {
                if self.winr == 0 {
                    0xFFF
                } else {
                    self.winr
                }
            }
            _ => return None,
        })
    }

    /// Register write.
    pub fn write(&mut self, o: u32, v: u32, now: u64) -> bool {
        match o {
            0x00 => match v & 0xFFFF {
                0x5555 => self.unlocked = true,
                0xCCCC => {
                    self.running = true;
                    self.expires = now + self.timeout_cycles();
                }
                0xAAAA => {
                    self.unlocked = false;
                    self.reloads += 1;
                    self.expires = now + self.timeout_cycles();
                }
                _ => self.unlocked = false,
            },
            0x04 if self.unlocked => self.pr = v & 7,
            0x08 if self.unlocked => self.rlr = v & 0xFFF,
            0x10 if self.unlocked => {
                self.winr = v & 0xFFF;
                if self.running {
                    self.expires = now + self.timeout_cycles();
                }
            }
            0x04 | 0x08 | 0x10 => {}
            _ => return false,
        }
        true
    }
}

/// Window watchdog (RM0440 43): the 7-bit counter at PCLK1 / 4096 / 2^WDGTB, early wakeup
/// at 0x40, reset at 0x3F or on a refresh outside the window.
#[derive(Debug, Clone, Default)]
pub struct Wwdg {
    cr: u32,
    cfr: u32,
    sr: u32,
    /// Counter value at `t0`.
    t0: u64,
    c0: u32,
    /// Started.
    pub running: bool,
    ewi_done: bool,
}

/// WWDG's interrupt.
pub const WWDG_IRQ: usize = 0;

impl Wwdg {
    fn tick(&self) -> u64 {
        4096 << ((self.cfr >> 11) & 7)
    }
    fn counter(&self, now: u64) -> u32 {
        if !self.running {
            return self.cr & 0x7F;
        }
        let dec = now.saturating_sub(self.t0) / self.tick();
        self.c0.saturating_sub(dec.min(0x7F) as u32)
    }

    /// Reset time and the early-wakeup time.
    pub fn next_event(&self) -> Option<u64> {
        if !self.running {
            return None;
        }
        let ewi = u64::from(self.c0.saturating_sub(0x40)) * self.tick() + self.t0;
        let reset = u64::from(self.c0.saturating_sub(0x3F)) * self.tick() + self.t0;
        if !self.ewi_done && self.cfr & (1 << 9) != 0 {
            Some(ewi.min(reset))
        } else {
            Some(reset)
        }
    }

    /// At `now`: (early wakeup due, reset due).
    pub fn advance(&mut self, now: u64) -> (bool, bool) {
        if !self.running {
            return (false, false);
        }
        let c = self.counter(now);
        let mut ewi = false;
        if c <= 0x40 && !self.ewi_done {
            self.ewi_done = true;
            self.sr |= 1;
            ewi = self.cfr & (1 << 9) != 0;
        }
        (ewi, c < 0x40)
    }

    /// Register read.
    pub fn read(&self, o: u32, now: u64) -> Option<u32> {
        Some(match o {
            0x00 => (self.cr & 0x80) | self.counter(now),
            0x04 => self.cfr,
            0x08 => self.sr,
            _ => return None,
        })
    }

    /// Register write; true when the write itself resets the chip.
    pub fn write(&mut self, o: u32, v: u32, now: u64) -> Option<bool> {
        match o {
            0x00 => {
                let c = self.counter(now);
                let window = self.cfr & 0x7F;
                let early = self.running && c > window;
                if v & 0x80 != 0 {
                    self.running = true;
                }
                self.cr = v & 0xFF;
                self.c0 = v & 0x7F;
                self.t0 = now;
                self.ewi_done = false;
                Some(early || (self.running && v & 0x40 == 0))
            }
            0x04 => {
                self.cfr = v;
                Some(false)
            }
            0x08 => {
                self.sr &= v;
                Some(false)
            }
            _ => None,
        }
    }
}
