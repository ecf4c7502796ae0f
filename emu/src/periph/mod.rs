//! The STM32G474's peripherals as the firmware uses them, behind one bus: address decoding,
//! the event queue in CPU cycles, the interrupt lines (level-sensitive, as the NVIC sees
//! them), DMA between the peripherals and RAM, and the surroundings ([`Env`]: the plant).

pub mod adc;
pub mod dma;
pub mod scs;
pub mod sys;
pub mod tim;
pub mod usart;

use std::collections::BTreeMap;

use crate::machine::SYSCLK_HZ;
use crate::unicorn::{Api, Engine};
use sys::{Flash, FlashOp, Gpio, Iwdg, Plain, Rcc, Wwdg};

/// The engine's memory, for DMA.
#[derive(Clone, Copy)]
pub struct Mem {
    pub(crate) api: &'static Api,
    pub(crate) uc: Engine,
}

impl Mem {
    /// Writes `bytes` at `address` (false: no memory there).
    pub fn write(&self, address: u32, bytes: &[u8]) -> bool {
        self.api.write(self.uc, address.into(), bytes).is_ok()
    }
    /// Reads into `out` (false: no memory there).
    pub fn read(&self, address: u32, out: &mut [u8]) -> bool {
        self.api.read(self.uc, address.into(), out).is_ok()
    }
}

/// The H-bridge's inputs as the pins drive them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bridge {
    /// Enable pin (PA9) high.
    pub enable: bool,
    /// Direction pin (PB5) high: reverse.
    pub reverse: bool,
    /// PWM duty on PA8 (TIM1_CH1), `None` when the output sits at its idle level (low).
    pub duty: Option<f64>,
}

/// The analog inputs of one ADC scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Analog {
    /// ADC code of the current sensor (PA0), as the plant's sensor chain gives it.
    pub current_code: u16,
    /// Bus divider output (PA1), V.
    pub bus_pin_v: f64,
    /// NTC divider output (PB0), V.
    pub ntc_pin_v: f64,
    /// VDDA, V.
    pub vdda_v: f64,
}

/// What surrounds the MCU: the plant and the bench.
pub trait Env: Send {
    /// Moves the world to `t_s` (seconds since power-on) with the bridge driven as
    /// `bridge` since the last call, and samples the analog inputs.
    fn sample(&mut self, t_s: f64, bridge: Bridge) -> Analog;
    /// The cam encoder's count (TIM4) and the output encoder's (TIM3).
    fn encoder_counts(&self) -> (u16, u16);
    /// Levels driven into GPIO port `port` (0 = A) from outside, a bit per pin.
    fn inputs(&self, port: usize) -> u32;
    /// The current sensor's voltage at PA0 (COMP3's plus input) now, V.
    fn comparator_in_v(&self) -> f64;
    /// The concrete surroundings (the board reaches its plant through it).
    fn as_any(&mut self) -> &mut dyn std::any::Any;
}

/// Peripheral windows: (base, size, name).
const BLOCKS: &[(u32, u32, &str)] = &[
    (0x4000_0000, 0x400, "TIM2"),
    (0x4000_0400, 0x400, "TIM3"),
    (0x4000_0800, 0x400, "TIM4"),
    (0x4000_2C00, 0x400, "WWDG"),
    (0x4000_3000, 0x400, "IWDG"),
    (0x4000_4400, 0x400, "USART2"),
    (0x4000_7000, 0x400, "PWR"),
    (0x4001_0000, 0x200, "SYSCFG"),
    (0x4001_0200, 0x200, "COMP"),
    (0x4001_0400, 0x400, "EXTI"),
    (0x4001_2C00, 0x400, "TIM1"),
    (0x4002_0000, 0x400, "DMA1"),
    (0x4002_0800, 0x400, "DMAMUX1"),
    (0x4002_1000, 0x400, "RCC"),
    (0x4002_2000, 0x400, "FLASH"),
    (0x4002_3000, 0x400, "CRC"),
    (0x4800_0000, 0x1C00, "GPIO"),
    (0x5000_0000, 0x100, "ADC1"),
    (0x5000_0300, 0x100, "ADC12_COMMON"),
    (0x5000_1000, 0x400, "DAC3"),
    (0xE000_0000, 0x10_0000, "SCS"),
];

/// Interrupt numbers.
const TIM1_BRK: usize = 24;
const TIM1_UP: usize = 25;
const TIM1_CC: usize = 27;
const TIM2_IRQ: usize = 28;
const TIM3_IRQ: usize = 29;
const TIM4_IRQ: usize = 30;
const EXTI15_10: usize = 40;

/// Everything memory-mapped.
pub struct Bus {
    /// NVIC, SCB, SysTick, MPU, DWT, DBGMCU.
    pub scs: scs::Scs,
    /// RCC.
    pub rcc: Rcc,
    pwr: Plain,
    /// FLASH controller.
    pub flash: Flash,
    syscfg: Plain,
    comp: Plain,
    dac3: Plain,
    exti: Plain,
    crc: Plain,
    gpio: Vec<Gpio>,
    /// TIM1.
    pub tim1: tim::Timer,
    /// TIM2 (the time driver).
    pub tim2: tim::Timer,
    /// TIM3 (output encoder).
    pub tim3: tim::Timer,
    /// TIM4 (cam encoder).
    pub tim4: tim::Timer,
    /// ADC1.
    pub adc: adc::Adc,
    /// DMA1 and DMAMUX1.
    pub dma: dma::Dma,
    /// USART2, the host link.
    pub usart: usart::Usart,
    /// IWDG.
    pub iwdg: Iwdg,
    /// WWDG.
    pub wwdg: Wwdg,
    /// The surroundings.
    pub env: Box<dyn Env>,
    /// Accesses no model covers: address -> (pc, write).
    pub unmodelled: BTreeMap<u32, (u32, bool)>,
    reset: Option<&'static str>,
    attention: bool,
    /// The comparator's output the break last saw.
    comp_out: bool,
    /// The last scan's analog values.
    analog: Analog,
    /// Flash words to restore after an illegal write went through: (address, old).
    pub flash_restore: Vec<(u32, u32)>,
}

impl Bus {
    /// The peripherals at reset around `env`.
    pub fn new(env: Box<dyn Env>) -> Self {
        Self {
            scs: scs::Scs::default(),
            rcc: Rcc::default(),
            pwr: Plain::new(
                &[
                    0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x18, 0x20, 0x24, 0x28, 0x2C, 0x30, 0x34,
                    0x38, 0x3C, 0x40, 0x44, 0x48, 0x4C, 0x50, 0x54, 0x58, 0x5C, 0x60, 0x64, 0x80,
                ],
                &[(0x00, 0x200), (0x08, 0x8000), (0x80, 0x100)],
            ),
            flash: Flash::default(),
            syscfg: Plain::new(
                &[0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x18, 0x1C, 0x20, 0x24],
                &[(0x04, 0x7C00_0001)],
            ),
            comp: Plain::new(&[0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x18], &[]),
            dac3: Plain::new(
                &[
                    0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x18, 0x1C, 0x20, 0x24, 0x28, 0x2C, 0x30,
                    0x34, 0x38, 0x3C, 0x40, 0x44, 0x48, 0x4C, 0x50, 0x58, 0x5C,
                ],
                &[],
            ),
            exti: Plain::new(
                &[
                    0x00, 0x04, 0x08, 0x0C, 0x10, 0x14, 0x20, 0x24, 0x28, 0x2C, 0x30, 0x34,
                ],
                &[(0x00, 0xFF82_0000), (0x20, 0x0000_0187)],
            ),
            crc: Plain::new(
                &[0x00, 0x04, 0x08, 0x10, 0x14],
                &[
                    (0x00, 0xFFFF_FFFF),
                    (0x10, 0xFFFF_FFFF),
                    (0x14, 0x04C1_1DB7),
                ],
            ),
            gpio: (0..7).map(Gpio::new).collect(),
            tim1: tim::Timer::new(tim::Kind::Advanced),
            tim2: tim::Timer::new(tim::Kind::Gp32),
            tim3: tim::Timer::new(tim::Kind::Gp16),
            tim4: tim::Timer::new(tim::Kind::Gp16),
            adc: adc::Adc::default(),
            dma: dma::Dma::default(),
            usart: usart::Usart::default(),
            iwdg: Iwdg::default(),
            wwdg: Wwdg::default(),
            env,
            unmodelled: BTreeMap::new(),
            reset: None,
            attention: false,
            comp_out: false,
            analog: Analog {
                current_code: 0,
                bus_pin_v: 0.0,
                ntc_pin_v: 0.0,
                vdda_v: 3.3,
            },
            flash_restore: Vec::new(),
        }
    }

    /// A system reset: every peripheral back to reset values (RCC keeps the reset flags,
    /// the plant and the host's bytes on the line stay).
    pub fn reset(&mut self, _now: u64) {
        let incoming = std::mem::take(&mut self.usart.incoming);
        let out = std::mem::take(&mut self.usart.out);
        let flags = self.rcc.regs.get(0x94) & 0xFE00_0000;
        self.rcc = Rcc::default();
        self.rcc.regs.set(0x94, flags);
        self.pwr.reset();
        self.flash.reset();
        self.syscfg.reset();
        self.comp.reset();
        self.dac3.reset();
        self.exti.reset();
        self.crc.reset();
        for (k, g) in self.gpio.iter_mut().enumerate() {
            *g = Gpio::new(k);
        }
        self.tim1 = tim::Timer::new(tim::Kind::Advanced);
        self.tim2 = tim::Timer::new(tim::Kind::Gp32);
        self.tim3 = tim::Timer::new(tim::Kind::Gp16);
        self.tim4 = tim::Timer::new(tim::Kind::Gp16);
        self.adc = adc::Adc::default();
        self.dma = dma::Dma::default();
        self.usart = usart::Usart::default();
        self.usart.out = out;
        // Bytes arriving while the chip resets are lost with the receiver off.
        self.usart.lost += incoming.len() as u64;
        self.iwdg = Iwdg::default();
        self.wwdg = Wwdg::default();
        self.reset = None;
    }

    /// The core locked up: with SYSCFG_CFGR2.CLL, TIM1 breaks (RM0440 28.3.16). Returns
    /// whether the main output was switched off by it.
    pub fn lockup(&mut self) -> bool {
        if self.syscfg.get(0x1C) & 1 == 0 {
            return false;
        }
        let before = self.tim1.hw_breaks;
        if self.tim1.break_in() {
            self.scs.pend(TIM1_BRK);
        }
        self.tim1.hw_breaks > before || self.tim1.bdtr & (1 << 15) == 0
    }

    /// A reset the peripherals asked for (watchdog, SYSRESETREQ), with its cause.
    pub fn take_reset(&mut self) -> Option<&'static str> {
        if std::mem::take(&mut self.scs.reset_requested) {
            self.rcc.system_reset(sys::csr::SFTRSTF);
            return Some("software (SYSRESETREQ)");
        }
        let cause = self.reset.take()?;
        Some(cause)
    }

    /// Whether the last write needs the run loop (an interrupt, a reset, an MPU change).
    pub fn wants_attention(&mut self) -> bool {
        std::mem::take(&mut self.attention) || self.scs.reset_requested || self.scs.mpu_changed()
    }

    /// The bridge as the pins drive it.
    pub fn bridge(&self) -> Bridge {
        Bridge {
            enable: self.gpio[0].output_high(9),
            reverse: self.gpio[1].output_high(5),
            duty: if self.gpio[0].mode(8) == 2 {
                self.tim1.ch1_duty()
            } else {
                None
            },
        }
    }

    fn time_s(now: u64) -> f64 {
        now as f64 / SYSCLK_HZ as f64
    }

    /// Steps the plant to `now` (the ADC trigger's moment, or a catch-up).
    pub fn sample(&mut self, now: u64) {
        let bridge = self.bridge();
        self.analog = self.env.sample(Self::time_s(now), bridge);
        self.comparator(now);
    }

    /// COMP3: the current sensor's pin against DAC3 channel 1, into TIM1's break.
    fn comparator(&mut self, _now: u64) {
        let csr = self.comp.get(0x08);
        let on = csr & 1 != 0 && (csr >> 4) & 7 == 0b100;
        let dac_on = self.dac3.get(0x00) & 1 != 0;
        let dac_v = f64::from(self.dac3.get(0x08) & 0xFFF) / 4095.0 * self.analog.vdda_v;
        let raw = on && dac_on && self.env.comparator_in_v() > dac_v;
        let out = raw ^ (csr & (1 << 15) != 0) && on;
        self.comp_out = out;
        if let Some(inverted) = self.tim1.break_from_comp3() {
            let level = out ^ inverted;
            let active = if self.tim1.break_active_high() {
                level
            } else {
                !level
            };
            if active && self.tim1.break_in() {
                self.scs.pend(TIM1_BRK);
                self.attention = true;
            }
        }
    }

    /// The earliest peripheral event that needs processing (timers, conversions, the line,
    /// the watchdogs).
    fn next_due(&self) -> Option<u64> {
        let trig = self.adc.waits_for_tim1() && self.tim1.trgo_on_update();
        [
            self.tim1.next_event(trig),
            self.tim2.next_event(false),
            self.tim3.next_event(false),
            self.tim4.next_event(false),
            self.adc.next_event(),
            self.usart.next_event(),
            self.iwdg.running.then_some(self.iwdg.expires),
            self.wwdg.next_event(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// The earliest moment after `now` something happens: an event to process, a SysTick
    /// wrap, the end of a flash operation (a sleeping core wakes to look).
    pub fn next_event(&self, now: u64) -> Option<u64> {
        [
            self.next_due(),
            self.scs.next_event(now),
            (self.flash.busy_until > now).then_some(self.flash.busy_until),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Runs every peripheral event up to `now`, in time order, and refreshes the
    /// interrupt lines.
    pub fn advance(&mut self, now: u64, mem: &Mem) {
        while let Some(t) = self.next_due().filter(|t| *t <= now) {
            self.step_events(t, mem);
        }
        self.scs.advance(now);
        self.refresh_lines();
    }

    fn step_events(&mut self, t: u64, mem: &Mem) {
        // TIM1: updates trigger the ADC's scans (the plant is sampled there).
        let trig = self.adc.waits_for_tim1() && self.tim1.trgo_on_update();
        let mut updates = Vec::new();
        let f = self.tim1.advance(t, |at| updates.push(at));
        if f.update_irq {
            self.scs.pend(TIM1_UP);
        }
        if f.irq {
            self.scs.pend(TIM1_CC);
        }
        for at in updates {
            if trig {
                self.sample(at);
                let a = self.analog;
                self.adc.trigger(at, |ch| channel_code(ch, &a));
            }
        }
        for (k, irq) in [(2, TIM2_IRQ), (3, TIM3_IRQ), (4, TIM4_IRQ)] {
            let timer = match k {
                2 => &mut self.tim2,
                3 => &mut self.tim3,
                _ => &mut self.tim4,
            };
            let f = timer.advance(t, |_| {});
            if f.irq || f.update_irq {
                self.scs.pend(irq);
            }
        }
        while let Some((value, irq)) = self.adc.finish(t) {
            if irq {
                self.scs.pend(adc::IRQ);
            }
            if self.adc.dma_enabled() {
                match self.dma.channel_for(adc::DR_ADDRESS) {
                    Some(k) => {
                        let addr = self.dma.ch[k].memory_address();
                        mem.write(addr, &value.to_le_bytes());
                        self.adc.dr_taken();
                        if self.dma.transferred(k) {
                            self.scs.pend(dma::IRQ[k]);
                        }
                    }
                    None => {
                        if self.adc.overrun() {
                            self.scs.pend(adc::IRQ);
                        }
                    }
                }
            }
        }
        if self.usart.tx_step(t) {
            self.pump_tx(t, mem);
        }
        while let Some(b) = self.usart.rx_step(t) {
            if let Some(b) = b {
                if self.usart.rx_dma()
                    && let Some(k) = self.dma.channel_for(usart::RDR)
                {
                    let addr = self.dma.ch[k].memory_address();
                    mem.write(addr, &[b]);
                    if self.dma.transferred(k) {
                        self.scs.pend(dma::IRQ[k]);
                    }
                    continue;
                }
                self.usart.store(b);
            }
        }
        if self.iwdg.running && self.iwdg.expires <= t {
            self.rcc.system_reset(sys::csr::IWDGRSTF);
            self.reset = Some("independent watchdog (IWDG)");
            self.iwdg.running = false;
        }
        let (ewi, wwdg_reset) = self.wwdg.advance(t);
        if ewi {
            self.scs.pend(sys::WWDG_IRQ);
        }
        if wwdg_reset {
            self.rcc.system_reset(sys::csr::WWDGRSTF);
            self.reset = Some("window watchdog (WWDG)");
            self.wwdg.running = false;
        }
    }

    /// Feeds the transmitter from its DMA channel while it takes bytes.
    fn pump_tx(&mut self, now: u64, mem: &Mem) {
        while self.usart.wants_tx_dma() {
            let Some(k) = self.dma.channel_for(usart::TDR) else {
                break;
            };
            let mut b = [0u8];
            mem.read(self.dma.ch[k].memory_address(), &mut b);
            self.usart.write_tdr(b[0], now);
            if self.dma.transferred(k) {
                self.scs.pend(dma::IRQ[k]);
            }
        }
    }

    /// Level-sensitive lines: a peripheral still asking is pending again (unless active).
    fn refresh_lines(&mut self) {
        let dma_lines: Vec<(usize, bool)> = (0..dma::CHANNELS)
            .map(|k| {
                let flags = (self.dma.isr >> (4 * k)) & 0xE;
                (dma::IRQ[k], flags & self.dma.ch[k].ccr & 0xE != 0)
            })
            .collect();
        let lines = [
            (usart::IRQ, self.usart.line()),
            (TIM2_IRQ, self.tim2.sr & self.tim2.dier & 0x1F != 0),
            (TIM1_BRK, self.tim1.sr & self.tim1.dier & (1 << 7) != 0),
            (TIM1_UP, self.tim1.sr & self.tim1.dier & 1 != 0),
        ];
        for (irq, high) in dma_lines.into_iter().chain(lines) {
            if high {
                self.scs.pend(irq);
            }
        }
        let exti_pr = self.exti.get(0x14) & self.exti.get(0x00);
        if exti_pr & 0xFC00 != 0 {
            self.scs.pend(EXTI15_10);
        }
    }

    /// A bus read at `a` by the instruction at `pc`.
    pub fn read(&mut self, a: u32, size: u32, now: u64, pc: u32, mem: &Mem) -> u32 {
        let aligned = a & !3;
        let shift = 8 * (a & 3);
        let value = match block(a) {
            Some((base, "TIM1")) => self.tim1.read(aligned - base, now, 0),
            Some((base, "TIM2")) => {
                self.tim2.advance(now, |_| {});
                self.tim2.read(aligned - base, now, 0)
            }
            Some((base, "TIM3")) => {
                self.tim3
                    .read(aligned - base, now, self.env.encoder_counts().1)
            }
            Some((base, "TIM4")) => {
                self.tim4
                    .read(aligned - base, now, self.env.encoder_counts().0)
            }
            Some((base, "WWDG")) => self.wwdg.read(aligned - base, now),
            Some((base, "IWDG")) => self.iwdg.read(aligned - base),
            Some((base, "USART2")) => {
                self.advance(now, mem);
                self.usart.read(aligned - base)
            }
            Some((base, "PWR")) => self.pwr.read(aligned - base),
            Some((base, "SYSCFG")) => self.syscfg.read(aligned - base),
            Some((base, "COMP")) => {
                let o = aligned - base;
                self.comp.read(o).map(|v| {
                    if o == 0x08 {
                        (v & !(1 << 30)) | (u32::from(self.comp_out) << 30)
                    } else {
                        v
                    }
                })
            }
            Some((base, "EXTI")) => self.exti.read(aligned - base),
            Some((base, "DMA1")) => {
                self.advance(now, mem);
                self.dma.read(aligned - base)
            }
            Some((base, "DMAMUX1")) => self.dma.mux_read(aligned - base),
            Some((base, "RCC")) => self.rcc.read(aligned - base),
            Some((base, "FLASH")) => self.flash.read(aligned - base, now),
            Some((base, "CRC")) => self.crc.read(aligned - base),
            Some((base, "GPIO")) => {
                let port = ((aligned - base) / 0x400) as usize;
                let inputs = self.env.inputs(port);
                self.gpio[port].read((aligned - base) % 0x400, inputs)
            }
            Some((base, "ADC1")) => {
                self.advance(now, mem);
                self.adc.read(aligned - base)
            }
            Some((base, "ADC12_COMMON")) => self.adc.common_read(aligned - base),
            Some((base, "DAC3")) => {
                let o = aligned - base;
                // DOR1 follows DHR12R1 (no trigger); SR: no underrun, BWST clear.
                match o {
                    0x2C => Some(self.dac3.get(0x08) & 0xFFF),
                    0x34 => Some(0),
                    _ => self.dac3.read(o),
                }
            }
            Some((_, "SCS")) => self.scs.read(aligned, now),
            _ => None,
        };
        match value {
            Some(v) => (v >> shift) & mask(size),
            None => {
                self.unmodelled.entry(a).or_insert((pc, false));
                0
            }
        }
    }

    /// A bus write at `a` by the instruction at `pc`.
    pub fn write(&mut self, a: u32, size: u32, v: u32, now: u64, pc: u32, mem: &Mem) {
        let aligned = a & !3;
        let o_shift = 8 * (a & 3);
        // Narrow writes merge into the word (the G4's peripherals take 8/16-bit writes as
        // the register's lanes).
        let merge = |old: u32| -> u32 {
            if size >= 4 {
                v
            } else {
                (old & !(mask(size) << o_shift)) | ((v & mask(size)) << o_shift)
            }
        };
        let ok = match block(a) {
            Some((base, "TIM1")) => {
                let o = aligned - base;
                self.advance(now, mem);
                let old = self.tim1.read(o, now, 0).unwrap_or(0);
                let r = self.tim1.write(o, merge(old), now, 0);
                // A duty or main output change moves the bridge: bring the plant up to now.
                if matches!(o, 0x34 | 0x44) {
                    self.comparator(now);
                }
                self.attention = true;
                r.is_some()
            }
            Some((base, "TIM2")) => {
                self.tim2.advance(now, |_| {});
                let o = aligned - base;
                let old = self.tim2.read(o, now, 0).unwrap_or(0);
                self.attention = true;
                self.tim2.write(o, merge(old), now, 0).is_some()
            }
            Some((base, "TIM3")) => {
                let o = aligned - base;
                let enc_out = self.env.encoder_counts().1;
                let old = self.tim3.read(o, now, enc_out).unwrap_or(0);
                self.tim3.write(o, merge(old), now, enc_out).is_some()
            }
            Some((base, "TIM4")) => {
                let o = aligned - base;
                let enc_cam = self.env.encoder_counts().0;
                let old = self.tim4.read(o, now, enc_cam).unwrap_or(0);
                self.tim4.write(o, merge(old), now, enc_cam).is_some()
            }
            Some((base, "WWDG")) => match self.wwdg.write(aligned - base, merge(0), now) {
                Some(true) => {
                    self.rcc.system_reset(sys::csr::WWDGRSTF);
                    self.reset = Some("window watchdog (WWDG, refresh outside the window)");
                    self.attention = true;
                    true
                }
                Some(false) => true,
                None => false,
            },
            Some((base, "IWDG")) => self.iwdg.write(aligned - base, merge(0), now),
            Some((base, "USART2")) => {
                self.advance(now, mem);
                let o = aligned - base;
                let old = if o == 0x28 {
                    0
                } else {
                    self.usart.read(o).unwrap_or(0)
                };
                let r = self.usart.write(o, merge(old), now);
                self.pump_tx(now, mem);
                self.attention = true;
                r
            }
            Some((base, "PWR")) => {
                let o = aligned - base;
                self.pwr.write(o, merge(self.pwr.get(o)))
            }
            Some((base, "SYSCFG")) => {
                let o = aligned - base;
                self.syscfg.write(o, merge(self.syscfg.get(o)))
            }
            Some((base, "COMP")) => {
                let o = aligned - base;
                // LOCK (bit 31) makes the CSR read-only until reset.
                if self.comp.get(o) & (1 << 31) != 0 {
                    true
                } else {
                    let r = self.comp.write(o, merge(self.comp.get(o)));
                    self.comparator(now);
                    r
                }
            }
            Some((base, "EXTI")) => {
                let o = aligned - base;
                if o == 0x14 || o == 0x34 {
                    // PR: write 1 to clear.
                    let pr = self.exti.get(o) & !v;
                    self.exti.set(o, pr);
                    true
                } else {
                    self.exti.write(o, merge(self.exti.get(o)))
                }
            }
            Some((base, "DMA1")) => {
                self.advance(now, mem);
                let r = self.dma.write(aligned - base, merge(0));
                self.pump_tx(now, mem);
                self.attention = true;
                r
            }
            Some((base, "DMAMUX1")) => self.dma.mux_write(aligned - base, merge(0)),
            Some((base, "RCC")) => {
                let o = aligned - base;
                let old = self.rcc.regs.get(o);
                match self.rcc.write(o, merge(old)) {
                    Some(pulsed) => {
                        self.reset_pulse(o, pulsed, now);
                        true
                    }
                    None => false,
                }
            }
            Some((base, "FLASH")) => match self.flash.write(aligned - base, merge(0), now) {
                Some(FlashOp::Erase(page)) => {
                    mem.write(page, &[0xFF; 2048]);
                    true
                }
                Some(FlashOp::None) => true,
                None => false,
            },
            Some((base, "CRC")) => {
                let o = aligned - base;
                self.crc.write(o, merge(self.crc.get(o)))
            }
            Some((base, "GPIO")) => {
                let port = ((aligned - base) / 0x400) as usize;
                let o = (aligned - base) % 0x400;
                let old = self.gpio[port].read(o, 0).unwrap_or(0);
                let value = if o == 0x18 || o == 0x28 {
                    v << o_shift
                } else {
                    merge(old)
                };
                let r = self.gpio[port].write(o, value);
                // The bridge's pins moved: the plant sees it from the next sample.
                r
            }
            Some((base, "ADC1")) => {
                self.advance(now, mem);
                let o = aligned - base;
                let old = self.adc.read(o).unwrap_or(0);
                self.adc.write(o, merge(old))
            }
            Some((base, "ADC12_COMMON")) => self.adc.common_write(aligned - base, merge(0)),
            Some((base, "DAC3")) => {
                let o = aligned - base;
                let r = self.dac3.write(o, merge(self.dac3.get(o)));
                self.comparator(now);
                r
            }
            Some((_, "SCS")) => {
                let old = self.scs.read(aligned, now).unwrap_or(0);
                let value = if matches!(aligned, 0xE000_E400..=0xE000_E4EF | 0xE000_ED18..=0xE000_ED23)
                {
                    // Byte-addressed priority registers.
                    let r = self.scs.write(a, v, size, now);
                    self.attention = true;
                    if r {
                        return;
                    }
                    old
                } else {
                    merge(old)
                };
                let r = self.scs.write(aligned, value, 4, now);
                self.attention = true;
                r
            }
            _ => false,
        };
        if !ok {
            self.unmodelled.entry(a).or_insert((pc, true));
        }
    }

    /// Reset pulses of the RCC's reset registers: the peripheral's registers return to
    /// their reset values.
    fn reset_pulse(&mut self, reg: u32, bits: u32, _now: u64) {
        let set = |b: u32| bits & (1 << b) != 0;
        match reg {
            0x28 if set(0) || set(2) => self.dma = dma::Dma::default(),
            0x2C => {
                for k in 0..7 {
                    if set(k) {
                        self.gpio[k as usize] = Gpio::new(k as usize);
                    }
                }
                if set(13) {
                    self.adc = adc::Adc::default();
                }
                if set(18) {
                    self.dac3.reset();
                }
            }
            0x38 => {
                if set(0) {
                    self.tim2 = tim::Timer::new(tim::Kind::Gp32);
                }
                if set(1) {
                    self.tim3 = tim::Timer::new(tim::Kind::Gp16);
                }
                if set(2) {
                    self.tim4 = tim::Timer::new(tim::Kind::Gp16);
                }
                if set(17) {
                    let keep = (
                        std::mem::take(&mut self.usart.out),
                        std::mem::take(&mut self.usart.incoming),
                    );
                    self.usart = usart::Usart::default();
                    self.usart.out = keep.0;
                    self.usart.incoming = keep.1;
                }
            }
            0x40 => {
                if set(0) {
                    // SYSCFG, COMP, OPAMP and VREFBUF share this reset.
                    self.syscfg.reset();
                    self.comp.reset();
                }
                if set(11) {
                    self.tim1 = tim::Timer::new(tim::Kind::Advanced);
                }
            }
            _ => {}
        }
    }

    /// Whether SYSCFG_CFGR2.CLL is set (for checks).
    pub fn lockup_breaks_tim1(&self) -> bool {
        self.syscfg.get(0x1C) & 1 != 0
    }

    /// A CPU write of `value` into flash memory over `old`: whether the flash takes it
    /// (programming enabled, the double word erased); otherwise an error flag is set and the
    /// word keeps `old`.
    pub fn flash_write(&mut self, address: u32, value: u32, old: u32, now: u64) -> bool {
        if self.flash.cr_pg() && old != 0xFFFF_FFFF {
            self.flash.program_error();
            return false;
        }
        match self.flash.program(address & !3, value, now) {
            Some(_) => true,
            None => self.flash.cr_pg() && self.flash.half_pending(),
        }
    }
}

fn mask(size: u32) -> u32 {
    match size {
        1 => 0xFF,
        2 => 0xFFFF,
        _ => 0xFFFF_FFFF,
    }
}

fn block(a: u32) -> Option<(u32, &'static str)> {
    BLOCKS
        .iter()
        .find(|(base, size, _)| a >= *base && a - base < *size)
        .map(|(base, _, name)| (*base, *name))
}

/// The code of ADC1 channel `ch` for the scan's analog values.
fn channel_code(ch: u32, a: &Analog) -> u16 {
    let code = |v: f64| ((v / a.vdda_v) * 4095.0).round().clamp(0.0, 4095.0) as u16;
    match ch {
        1 => a.current_code,
        2 => code(a.bus_pin_v),
        15 => code(a.ntc_pin_v),
        18 => {
            // VREFINT: VREFINT_CAL was measured at 3.0 V.
            let v = f64::from(crate::machine::VREFINT_CAL) / 4095.0 * 3.0;
            code(v)
        }
        _ => 0,
    }
}
