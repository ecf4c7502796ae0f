//! ADC1 and the ADC12 common registers (RM0440 21): enable, calibration, a regular
//! sequence started by an external trigger (TIM1_TRGO), conversion times from the sampling
//! times and the ADC clock, results to DMA, EOC/EOS/OVR.

/// ADC1's regular data register, the DMA's peripheral address.
pub const DR_ADDRESS: u32 = 0x5000_0040;
/// EXTSEL of TIM1_TRGO for ADC1/2's regular group (RM0440 table 163).
pub const EXTSEL_TIM1_TRGO: u32 = 9;
/// ADC1_2's interrupt.
pub const IRQ: usize = 18;

/// Sampling times in ADC clock cycles, by SMPx code.
const SAMPLE_CYCLES: [f64; 8] = [2.5, 6.5, 12.5, 24.5, 47.5, 92.5, 247.5, 640.5];

/// ADC1 with the common registers.
#[derive(Debug, Clone)]
pub struct Adc {
    isr: u32,
    ier: u32,
    cr: u32,
    cfgr: u32,
    cfgr2: u32,
    smpr: [u32; 2],
    tr: [u32; 3],
    sqr: [u32; 4],
    dr: u32,
    other: std::collections::BTreeMap<u32, u32>,
    /// Common CCR.
    ccr: u32,
    /// Conversions in flight: (cycle done, channel code).
    pub queue: Vec<(u64, u16)>,
    /// DR holds a result no one read.
    unread: bool,
    /// Scans started.
    pub scans: u64,
    /// Overruns.
    pub overruns: u64,
}

impl Default for Adc {
    fn default() -> Self {
        Self {
            isr: 0,
            ier: 0,
            cr: 0x2000_0000,
            cfgr: 0x8000_0000,
            cfgr2: 0,
            smpr: [0; 2],
            tr: [0x0FFF_0000, 0x00FF_0000, 0x00FF_0000],
            sqr: [0; 4],
            dr: 0,
            other: Default::default(),
            ccr: 0,
            queue: Vec::new(),
            unread: false,
            scans: 0,
            overruns: 0,
        }
    }
}

impl Adc {
    /// Whether a TIM1_TRGO starts a sequence now.
    pub fn waits_for_tim1(&self) -> bool {
        self.cr & 1 != 0
            && self.cr & (1 << 2) != 0
            && (self.cfgr >> 10) & 3 == 1
            && (self.cfgr >> 5) & 0x1F == EXTSEL_TIM1_TRGO
    }

    /// Whether results go to DMA.
    pub fn dma_enabled(&self) -> bool {
        self.cfgr & 1 != 0
    }

    /// The regular sequence's channels.
    pub fn sequence(&self) -> Vec<u32> {
        let len = (self.sqr[0] & 0xF) + 1;
        (0..len)
            .map(|k| {
                let (reg, slot) = ((k + 1) / 5, (k + 1) % 5);
                (self.sqr[reg as usize] >> (6 * slot)) & 0x1F
            })
            .collect()
    }

    /// CPU cycles per ADC clock cycle (kernel clock SYSCLK, `adc12sel = SYS`).
    fn cpu_cycles_per_adc_cycle(&self) -> f64 {
        match (self.ccr >> 16) & 3 {
            0 => {
                const DIV: [f64; 12] = [1., 2., 4., 6., 8., 10., 12., 16., 32., 64., 128., 256.];
                DIV[(((self.ccr >> 18) & 0xF) as usize).min(11)]
            }
            1 => 1.0,
            2 => 2.0,
            _ => 4.0,
        }
    }

    fn sample_cycles(&self, ch: u32) -> f64 {
        let (reg, slot) = ((ch / 10) as usize, ch % 10);
        SAMPLE_CYCLES[((self.smpr.get(reg).copied().unwrap_or(0) >> (3 * slot)) & 7) as usize]
    }

    /// Starts the sequence at `now` with the channels' codes `code(ch)`; false when a
    /// sequence is still converting (the trigger is ignored, as on silicon).
    pub fn trigger(&mut self, now: u64, mut code: impl FnMut(u32) -> u16) -> bool {
        if !self.queue.is_empty() {
            return false;
        }
        let per = self.cpu_cycles_per_adc_cycle();
        let mut t = now as f64;
        for ch in self.sequence() {
            t += (self.sample_cycles(ch) + 12.5) * per;
            self.queue.push((t.ceil() as u64, code(ch)));
        }
        self.scans += 1;
        true
    }

    /// The next conversion's end.
    pub fn next_event(&self) -> Option<u64> {
        self.queue.first().map(|(t, _)| *t)
    }

    /// Finishes the conversion due at or before `now`: its result (for DMA) and whether
    /// the interrupt asks for service.
    pub fn finish(&mut self, now: u64) -> Option<(u16, bool)> {
        let (t, value) = *self.queue.first()?;
        if t > now {
            return None;
        }
        self.queue.remove(0);
        if self.unread && !self.dma_enabled() {
            self.isr |= 1 << 4;
            self.overruns += 1;
            if self.cfgr & (1 << 12) == 0 {
                return Some((value, self.ier & (1 << 4) != 0));
            }
        }
        self.dr = u32::from(value);
        self.unread = true;
        self.isr |= 1 << 2;
        if self.queue.is_empty() {
            self.isr |= 1 << 3;
        }
        Some((value, self.ier & self.isr & 0x1F != 0))
    }

    /// The DMA read DR.
    pub fn dr_taken(&mut self) {
        self.unread = false;
        self.isr &= !(1 << 2);
    }

    /// The DMA could not take a result: overrun.
    pub fn overrun(&mut self) -> bool {
        self.isr |= 1 << 4;
        self.overruns += 1;
        self.ier & (1 << 4) != 0
    }

    /// ADC1 register at `o`.
    pub fn read(&mut self, o: u32) -> Option<u32> {
        Some(match o {
            0x00 => self.isr,
            0x04 => self.ier,
            0x08 => self.cr,
            0x0C => self.cfgr,
            0x10 => self.cfgr2,
            0x14 | 0x18 => self.smpr[((o - 0x14) / 4) as usize],
            0x20..=0x28 => self.tr[((o - 0x20) / 4) as usize],
            0x30..=0x3C => self.sqr[((o - 0x30) / 4) as usize],
            0x40 => {
                self.dr_taken();
                self.dr
            }
            0x4C | 0x60..=0x6C | 0x80..=0x8C | 0xA0 | 0xA4 | 0xB0 | 0xB4 | 0xC0 => {
                self.other.get(&o).copied().unwrap_or(0)
            }
            _ => return None,
        })
    }

    /// Writes ADC1's register at `o`.
    pub fn write(&mut self, o: u32, v: u32) -> bool {
        match o {
            // rc_w1
            0x00 => self.isr &= !v,
            0x04 => self.ier = v,
            0x08 => {
                let mut cr = (self.cr & 0x7) | (v & !0x3F);
                if v & 1 != 0 {
                    // ADEN: ready after tSTAB (not modelled: at once).
                    cr |= 1;
                    self.isr |= 1;
                }
                if v & 2 != 0 {
                    cr &= !0x7;
                    self.queue.clear();
                }
                if v & 4 != 0 && cr & 1 != 0 {
                    cr |= 4;
                }
                if v & 0x10 != 0 {
                    cr &= !4;
                    self.queue.clear();
                }
                // ADCAL: the calibration is done by the time it is read back.
                cr &= !(1 << 31);
                self.cr = cr;
            }
            0x0C => self.cfgr = v,
            0x10 => self.cfgr2 = v,
            0x14 | 0x18 => self.smpr[((o - 0x14) / 4) as usize] = v,
            0x20..=0x28 => self.tr[((o - 0x20) / 4) as usize] = v,
            0x30..=0x3C => self.sqr[((o - 0x30) / 4) as usize] = v,
            0x4C | 0x60..=0x6C | 0xA0 | 0xA4 | 0xB0 | 0xB4 | 0xC0 => {
                self.other.insert(o, v);
            }
            _ => return false,
        }
        true
    }

    /// Common register at `o` (from the ADC12 common block).
    pub fn common_read(&self, o: u32) -> Option<u32> {
        match o {
            0x00 => Some(self.isr & 0x7FF),
            0x08 => Some(self.ccr),
            0x0C => Some(0),
            _ => None,
        }
    }

    /// Writes a common register.
    pub fn common_write(&mut self, o: u32, v: u32) -> bool {
        match o {
            0x08 => self.ccr = v,
            _ => return false,
        }
        true
    }
}
