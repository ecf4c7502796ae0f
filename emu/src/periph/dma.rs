//! DMA1 (RM0440 12) with DMAMUX1 (13): eight channels, peripheral-to-memory and
//! memory-to-peripheral, normal and circular, the half and full transfer flags.

/// Channels of DMA1.
pub const CHANNELS: usize = 8;
/// DMA1_CHx's interrupt numbers (x = 1..=8).
pub const IRQ: [usize; CHANNELS] = [11, 12, 13, 14, 15, 16, 17, 96];

/// One channel.
#[derive(Debug, Clone, Copy, Default)]
pub struct Channel {
    /// CCR.
    pub ccr: u32,
    /// CNDTR as programmed (reloaded in circular mode).
    pub count: u32,
    /// CNDTR now: transfers left.
    pub remaining: u32,
    /// CPAR.
    pub cpar: u32,
    /// CMAR.
    pub cmar: u32,
    /// Transfers done since enabled (the memory index).
    pub index: u32,
}

impl Channel {
    /// Enabled and not done.
    pub fn active(&self) -> bool {
        self.ccr & 1 != 0 && self.remaining > 0
    }
    /// Memory to peripheral.
    pub fn to_peripheral(&self) -> bool {
        self.ccr & (1 << 4) != 0
    }
    fn size(bits: u32) -> u32 {
        match bits & 3 {
            0 => 1,
            1 => 2,
            _ => 4,
        }
    }
    /// Memory-side element size, bytes.
    pub fn msize(&self) -> u32 {
        Self::size(self.ccr >> 10)
    }
    /// The memory address of the next transfer.
    pub fn memory_address(&self) -> u32 {
        if self.ccr & (1 << 7) != 0 {
            self.cmar + self.index * self.msize()
        } else {
            self.cmar
        }
    }
}

/// DMA1 and DMAMUX1.
#[derive(Debug, Clone, Default)]
pub struct Dma {
    /// The channels.
    pub ch: [Channel; CHANNELS],
    /// ISR flags: GIF, TCIF, HTIF, TEIF per channel.
    pub isr: u32,
    /// DMAMUX1 channel configurations.
    pub mux: [u32; 16],
}

impl Dma {
    /// The enabled channel serving the peripheral register at `par`.
    pub fn channel_for(&self, par: u32) -> Option<usize> {
        (0..CHANNELS).find(|k| self.ch[*k].active() && self.ch[*k].cpar == par)
    }

    /// One transfer done on channel `k`: its flags, and whether its interrupt is due.
    pub fn transferred(&mut self, k: usize) -> bool {
        let c = &mut self.ch[k];
        c.index += 1;
        c.remaining -= 1;
        let mut flags = 0;
        if c.remaining == c.count / 2 {
            flags |= 1 << 2;
        }
        if c.remaining == 0 {
            flags |= 1 << 1;
            if c.ccr & (1 << 5) != 0 {
                c.remaining = c.count;
                c.index = 0;
            }
        }
        if flags == 0 {
            return false;
        }
        self.isr |= (flags | 1) << (4 * k);
        // TCIE (bit 1) and HTIE (bit 2) line up with TCIF and HTIF.
        c.ccr & flags & 0b110 != 0
    }

    /// DMA1 register at offset `o` (None: not modelled).
    pub fn read(&self, o: u32) -> Option<u32> {
        Some(match o {
            0x00 => self.isr,
            0x04 => 0,
            0x08..=0xA0 => {
                let k = ((o - 0x08) / 0x14) as usize;
                let c = self.ch.get(k)?;
                match (o - 0x08) % 0x14 {
                    0x00 => c.ccr,
                    0x04 => c.remaining,
                    0x08 => c.cpar,
                    0x0C => c.cmar,
                    _ => return None,
                }
            }
            _ => return None,
        })
    }

    /// Writes DMA1's register at `o`.
    pub fn write(&mut self, o: u32, v: u32) -> bool {
        match o {
            0x04 => {
                // IFCR: CGIFx clears all of channel x's flags.
                for k in 0..CHANNELS {
                    let bits = (v >> (4 * k)) & 0xF;
                    if bits & 1 != 0 {
                        self.isr &= !(0xF << (4 * k));
                    } else {
                        self.isr &= !(bits << (4 * k));
                    }
                }
            }
            0x08..=0xA0 => {
                let k = ((o - 0x08) / 0x14) as usize;
                let Some(c) = self.ch.get_mut(k) else {
                    return false;
                };
                match (o - 0x08) % 0x14 {
                    0x00 => {
                        if v & 1 != 0 && c.ccr & 1 == 0 {
                            c.remaining = c.count;
                            c.index = 0;
                        }
                        c.ccr = v & 0x7FFF;
                    }
                    0x04 => {
                        c.count = v & 0xFFFF;
                        c.remaining = c.count;
                        c.index = 0;
                    }
                    0x08 => c.cpar = v,
                    0x0C => c.cmar = v,
                    _ => return false,
                }
            }
            _ => return false,
        }
        true
    }

    /// DMAMUX1 register at offset `o`.
    pub fn mux_read(&self, o: u32) -> Option<u32> {
        match o {
            0x00..=0x3C => Some(self.mux[(o / 4) as usize]),
            0x80 => Some(0),
            0x100..=0x10C | 0x140 | 0x144 => Some(0),
            _ => None,
        }
    }

    /// Writes DMAMUX1's register at `o`.
    pub fn mux_write(&mut self, o: u32, v: u32) -> bool {
        match o {
            0x00..=0x3C => self.mux[(o / 4) as usize] = v,
            0x84 | 0x100..=0x10C | 0x144 => {}
            _ => return false,
        }
        true
    }
}
