//! USART2 (RM0440 37) without its FIFO: bytes on the line at the programmed baud (8N1),
//! TDR and the shift register, RXNE/ORE, IDLE after a frame of silence, TC, and the DMA
//! requests of CR3.DMAR/DMAT.

use std::collections::VecDeque;

/// USART2's base, RDR and TDR (the DMA's peripheral addresses).
pub const BASE: u32 = 0x4000_4400;
/// RDR.
pub const RDR: u32 = BASE + 0x24;
/// TDR.
pub const TDR: u32 = BASE + 0x28;
/// USART2's interrupt.
pub const IRQ: usize = 38;
/// Kernel clock (PCLK1 at 170 MHz), Hz.
const KERNEL_HZ: u64 = 170_000_000;

/// The UART and its line.
#[derive(Debug, Clone, Default)]
pub struct Usart {
    cr1: u32,
    cr2: u32,
    /// CR3.
    pub cr3: u32,
    brr: u32,
    other: [u32; 4],
    isr: u32,
    rdr: u8,
    tdr: Option<u8>,
    shifter: Option<(u64, u8)>,
    /// Bytes from the host waiting to cross the line.
    pub incoming: VecDeque<u8>,
    rx_next: Option<u64>,
    idle_at: Option<u64>,
    /// Bytes that left for the host.
    pub out: Vec<u8>,
    /// Received bytes lost (receiver off or overrun).
    pub lost: u64,
}

impl Usart {
    fn enabled(&self) -> bool {
        self.cr1 & 1 != 0
    }

    /// CPU cycles per frame (10 bits) at the programmed baud.
    pub fn frame_cycles(&self) -> u64 {
        let div = if self.cr1 & (1 << 15) != 0 {
            let d = (self.brr & 0xFFF0) | ((self.brr & 7) << 1);
            u64::from(d) / 2
        } else {
            u64::from(self.brr & 0xFFFF)
        };
        // One bit is `div` kernel clocks; the kernel clock is the CPU's here.
        let _ = KERNEL_HZ;
        10 * div.max(16)
    }

    /// The baud the registers give.
    pub fn baud(&self) -> u64 {
        10 * KERNEL_HZ / self.frame_cycles()
    }

    /// Host bytes arrive at the pin (queued behind those on the line).
    pub fn receive(&mut self, bytes: &[u8], now: u64) {
        self.incoming.extend(bytes.iter().copied());
        if self.rx_next.is_none() && !self.incoming.is_empty() {
            self.rx_next = Some(now + self.frame_cycles());
        }
    }

    /// Next line event.
    pub fn next_event(&self) -> Option<u64> {
        [self.shifter.map(|(t, _)| t), self.rx_next, self.idle_at]
            .into_iter()
            .flatten()
            .min()
    }

    /// The interrupt line (level).
    pub fn line(&self) -> bool {
        let (cr1, isr) = (self.cr1, self.isr);
        (cr1 & (1 << 5) != 0 && isr & ((1 << 5) | (1 << 3)) != 0)
            || (cr1 & (1 << 6) != 0 && isr & (1 << 6) != 0)
            || (cr1 & (1 << 7) != 0 && isr & (1 << 7) != 0)
            || (cr1 & (1 << 4) != 0 && isr & (1 << 4) != 0)
            || (self.cr3 & 1 != 0 && isr & 0b1110 != 0)
            || (cr1 & (1 << 8) != 0 && isr & 1 != 0)
    }

    /// Whether the transmitter takes a byte (TXE) for DMA.
    pub fn wants_tx_dma(&self) -> bool {
        self.enabled() && self.cr1 & (1 << 3) != 0 && self.cr3 & (1 << 7) != 0 && self.tdr.is_none()
    }

    /// A byte written to TDR at `now`.
    pub fn write_tdr(&mut self, b: u8, now: u64) {
        if !self.enabled() || self.cr1 & (1 << 3) == 0 {
            return;
        }
        if self.shifter.is_none() {
            self.shifter = Some((now + self.frame_cycles(), b));
            self.isr &= !(1 << 6);
        } else {
            self.tdr = Some(b);
            self.isr &= !(1 << 7);
        }
    }

    /// The transmit side's event at `now`, if due.
    pub fn tx_step(&mut self, now: u64) -> bool {
        let Some((t, b)) = self.shifter else {
            return false;
        };
        if t > now {
            return false;
        }
        self.out.push(b);
        self.shifter = None;
        if let Some(next) = self.tdr.take() {
            self.shifter = Some((t + self.frame_cycles(), next));
            self.isr |= 1 << 7;
        } else {
            self.isr |= (1 << 6) | (1 << 7);
        }
        true
    }

    /// The receive side's event at `now`, if due: a byte to store (DMA or RDR).
    pub fn rx_step(&mut self, now: u64) -> Option<Option<u8>> {
        if let Some(t) = self.idle_at
            && t <= now
            && self.rx_next.is_none_or(|r| r > t)
        {
            self.idle_at = None;
            if self.receiving() {
                self.isr |= 1 << 4;
            }
            return Some(None);
        }
        let t = self.rx_next?;
        if t > now {
            return None;
        }
        let b = self.incoming.pop_front();
        self.rx_next = (!self.incoming.is_empty()).then(|| t + self.frame_cycles());
        self.idle_at = Some(t + self.frame_cycles());
        match b {
            Some(b) if self.receiving() => Some(Some(b)),
            Some(_) => {
                self.lost += 1;
                Some(None)
            }
            None => Some(None),
        }
    }

    fn receiving(&self) -> bool {
        self.enabled() && self.cr1 & (1 << 2) != 0
    }

    /// Whether received bytes go to DMA.
    pub fn rx_dma(&self) -> bool {
        self.cr3 & (1 << 6) != 0
    }

    /// A received byte into RDR (no DMA).
    pub fn store(&mut self, b: u8) {
        if self.isr & (1 << 5) != 0 {
            self.isr |= 1 << 3;
            self.lost += 1;
        } else {
            self.rdr = b;
            self.isr |= 1 << 5;
        }
    }

    /// Register read at `o`.
    pub fn read(&mut self, o: u32) -> Option<u32> {
        Some(match o {
            0x00 => self.cr1,
            0x04 => self.cr2,
            0x08 => self.cr3,
            0x0C => self.brr,
            0x10 | 0x14 | 0x2C => self.other[((o >> 2) & 3) as usize],
            0x18 => 0,
            0x1C => {
                let mut isr = self.isr;
                if self.enabled() {
                    isr |= u32::from(self.cr1 & (1 << 3) != 0) << 21;
                    isr |= u32::from(self.cr1 & (1 << 2) != 0) << 22;
                }
                if self.shifter.is_some() || self.rx_next.is_some() {
                    isr |= 1 << 16;
                }
                isr
            }
            0x20 => 0,
            0x24 => {
                self.isr &= !(1 << 5);
                u32::from(self.rdr)
            }
            0x28 => 0,
            _ => return None,
        })
    }

    /// Register write at `o`.
    pub fn write(&mut self, o: u32, v: u32, now: u64) -> bool {
        match o {
            0x00 => {
                let was = self.enabled();
                self.cr1 = v;
                if self.enabled() && !was {
                    self.isr |= (1 << 7) | (1 << 6);
                }
                if !self.enabled() {
                    self.shifter = None;
                    self.tdr = None;
                    self.isr = 0;
                }
            }
            0x04 => self.cr2 = v,
            0x08 => self.cr3 = v,
            0x0C => self.brr = v & 0xFFFF,
            0x10 | 0x14 | 0x2C => self.other[((o >> 2) & 3) as usize] = v,
            0x18 => {
                if v & (1 << 3) != 0 {
                    self.isr &= !(1 << 5);
                }
            }
            // ICR: PE, FE, NE, ORE, IDLE, TC (and the rest).
            0x20 => self.isr &= !(v & 0x0012_1B5F),
            0x28 => self.write_tdr(v as u8, now),
            _ => return false,
        }
        true
    }
}
