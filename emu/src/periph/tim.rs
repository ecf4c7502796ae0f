//! Timers (RM0440 28-29) as the firmware uses them: TIM2 up-counting with compares and
//! overflow (embassy's time driver), TIM3/TIM4 in encoder mode (the counts come from the
//! plant's angles), TIM1 centre-aligned with its repetition counter, preloaded compare,
//! update as TRGO, and the break (BDTR.MOE cleared by hardware, BIF).

/// Which timer, for its specifics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// TIM1: advanced (repetition counter, break, main output).
    Advanced,
    /// TIM2: 32-bit general purpose.
    Gp32,
    /// TIM3/TIM4: 16-bit general purpose.
    Gp16,
}

/// Timer events of one step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Fired {
    /// An update event happened (TRGO with MMS = update).
    pub update: bool,
    /// The interrupt line asks for service.
    pub irq: bool,
    /// The update interrupt (TIM1 has its own vector).
    pub update_irq: bool,
}

/// One timer.
#[derive(Debug, Clone)]
pub struct Timer {
    kind: Kind,
    /// CR1.
    pub cr1: u32,
    cr2: u32,
    /// SMCR.
    pub smcr: u32,
    /// DIER.
    pub dier: u32,
    /// SR.
    pub sr: u32,
    ccmr: [u32; 3],
    /// CCER.
    pub ccer: u32,
    psc: u32,
    psc_active: u32,
    /// ARR (preload).
    pub arr: u32,
    arr_active: u32,
    rcr: u32,
    ccr: [u32; 6],
    /// Active (shadow) compare values.
    pub ccr_active: [u32; 6],
    /// BDTR.
    pub bdtr: u32,
    /// AF1.
    pub af1: u32,
    af2: u32,
    other: [u32; 8],
    /// Counter value at `t0` (up-counting), or the position in the up-down cycle.
    pos0: u64,
    t0: u64,
    /// Ticks since `t0` whose events were handled.
    handled: u64,
    /// Encoder mode: added to the plant's count.
    pub encoder_offset: u16,
    /// Update events since the counter started (centre-aligned: over/underflows).
    events: u64,
    /// Breaks that switched the main output off (MOE cleared by hardware).
    pub hw_breaks: u32,
}

impl Timer {
    /// A timer at its reset values.
    pub fn new(kind: Kind) -> Self {
        let arr = if kind == Kind::Gp32 {
            0xFFFF_FFFF
        } else {
            0xFFFF
        };
        Self {
            kind,
            cr1: 0,
            cr2: 0,
            smcr: 0,
            dier: 0,
            sr: 0,
            ccmr: [0; 3],
            ccer: 0,
            psc: 0,
            psc_active: 0,
            arr,
            arr_active: arr,
            rcr: 0,
            ccr: [0; 6],
            ccr_active: [0; 6],
            bdtr: 0,
            af1: if kind == Kind::Advanced { 1 } else { 0 },
            af2: if kind == Kind::Advanced { 1 } else { 0 },
            other: [0; 8],
            pos0: 0,
            t0: 0,
            handled: 0,
            encoder_offset: 0,
            events: 0,
            hw_breaks: 0,
        }
    }

    fn running(&self) -> bool {
        self.cr1 & 1 != 0 && !self.encoder_mode()
    }

    /// Encoder mode (SMCR.SMS 1..=3).
    pub fn encoder_mode(&self) -> bool {
        matches!(self.smcr & 7, 1..=3)
    }

    fn centre(&self) -> bool {
        (self.cr1 >> 5) & 3 != 0
    }

    fn div(&self) -> u64 {
        u64::from(self.psc_active) + 1
    }

    /// Counter period in ticks: ARR + 1 up-counting, 2 ARR centre-aligned.
    fn period(&self) -> u64 {
        if self.centre() {
            (2 * u64::from(self.arr_active)).max(2)
        } else {
            u64::from(self.arr_active) + 1
        }
    }

    fn ticks(&self, now: u64) -> u64 {
        now.saturating_sub(self.t0) / self.div()
    }

    /// Position in the counting cycle after `k` ticks from `t0`.
    fn pos(&self, k: u64) -> u64 {
        (self.pos0 + k) % self.period()
    }

    /// CNT now (`encoder`: the plant's count for encoder mode).
    pub fn cnt(&self, now: u64, encoder: u16) -> u32 {
        if self.encoder_mode() {
            return u32::from(encoder.wrapping_add(self.encoder_offset));
        }
        if self.cr1 & 1 == 0 {
            return self.pos0 as u32;
        }
        let p = self.pos(self.ticks(now));
        if self.centre() && p > u64::from(self.arr_active) {
            (self.period() - p) as u32
        } else {
            p as u32
        }
    }

    /// Counting down (centre-aligned, second half).
    fn down(&self, now: u64) -> bool {
        if !self.centre() || self.cr1 & 1 == 0 {
            return self.cr1 & (1 << 4) != 0;
        }
        self.pos(self.ticks(now)) >= u64::from(self.arr_active)
    }

    /// Restarts the counting from `cnt` at `now`.
    fn rebase(&mut self, now: u64, cnt: u32) {
        self.t0 = now;
        self.pos0 = u64::from(cnt);
        self.handled = 0;
    }

    /// The next tick after `handled` at which the counter is at `value`.
    fn next_at(&self, value: u64) -> Option<u64> {
        let period = self.period();
        if value >= period {
            return None;
        }
        let from = self.handled + 1;
        let at = (self.pos0 + from) % period;
        Some(from + (value + period - at) % period)
    }

    /// Ticks (from `t0`) of the next events that set flags: (tick, what).
    fn next_events(&self) -> Vec<(u64, u32)> {
        let mut out = Vec::new();
        if !self.running() {
            return out;
        }
        if self.centre() {
            // Over- and underflow: the update candidates.
            for v in [0, u64::from(self.arr_active)] {
                if let Some(k) = self.next_at(v) {
                    out.push((k, 0));
                }
            }
        } else if let Some(k) = self.next_at(0) {
            out.push((k, 0));
        }
        for ch in 0..4 {
            let v = u64::from(self.ccr_active[ch]);
            // Compare channels only matter with their interrupt on.
            if self.dier & (1 << (ch + 1)) != 0
                && let Some(k) = self.next_at(v)
            {
                out.push((k, ch as u32 + 1));
            }
        }
        out
    }

    /// The cycle of the next event that needs attention (an interrupt or a trigger).
    pub fn next_event(&self, trigger_used: bool) -> Option<u64> {
        let want_update = trigger_used || self.dier & 1 != 0;
        self.next_events()
            .into_iter()
            .filter(|(_, what)| *what != 0 || want_update)
            .map(|(k, _)| self.t0 + k * self.div())
            .min()
    }

    /// Handles the events up to `now`, one at a time (`each` sees every update).
    pub fn advance(&mut self, now: u64, mut each: impl FnMut(u64)) -> Fired {
        let mut fired = Fired::default();
        if !self.running() {
            return fired;
        }
        let limit = self.ticks(now);
        loop {
            let events = self.next_events();
            let Some(k) = events.iter().map(|(k, _)| *k).min().filter(|k| *k <= limit) else {
                break;
            };
            // Every event of that tick at once (an update and a compare can coincide).
            let at = self.t0 + k * self.div();
            self.handled = k;
            for (_, what) in events.into_iter().filter(|(t, _)| *t == k) {
                if what == 0 {
                    self.events += 1;
                    let rep = u64::from(self.rcr) + 1;
                    let update =
                        self.kind != Kind::Advanced || (self.events - 1).is_multiple_of(rep);
                    if update {
                        self.update_event(at, false);
                        fired.update = true;
                        each(at);
                        if self.dier & 1 != 0 {
                            fired.update_irq = true;
                        }
                    }
                } else {
                    self.sr |= 1 << what;
                    if self.dier & (1 << what) != 0 {
                        fired.irq = true;
                    }
                }
            }
        }
        // Every tick up to now is handled (events at later ticks come later).
        self.handled = self.handled.max(limit);
        fired
    }

    /// An update event: preloads transferred, UIF unless UG with URS.
    fn update_event(&mut self, now: u64, by_ug: bool) {
        if !(by_ug && self.cr1 & (1 << 2) != 0) && self.cr1 & (1 << 1) == 0 {
            self.sr |= 1;
        }
        let cnt = self.cnt(now, 0);
        let psc_changed = self.psc_active != self.psc;
        self.psc_active = self.psc;
        self.arr_active = self.arr;
        for ch in 0..6 {
            self.ccr_active[ch] = self.ccr[ch];
        }
        if psc_changed || by_ug {
            let start = if by_ug { 0 } else { cnt };
            self.rebase(now, start);
        }
    }

    /// Register read at offset `o` (None: not modelled).
    pub fn read(&self, o: u32, now: u64, encoder: u16) -> Option<u32> {
        Some(match o {
            0x00 => {
                let dir = u32::from(self.down(now)) << 4;
                (self.cr1 & !(1 << 4)) | dir
            }
            0x04 => self.cr2,
            0x08 => self.smcr,
            0x0C => self.dier,
            0x10 => self.sr,
            0x14 => 0,
            0x18 => self.ccmr[0],
            0x1C => self.ccmr[1],
            0x20 => self.ccer,
            0x24 => self.cnt(now, encoder),
            0x28 => self.psc,
            0x2C => self.arr,
            0x30 if self.kind == Kind::Advanced => self.rcr,
            0x34..=0x40 => self.ccr[((o - 0x34) / 4) as usize],
            0x44 if self.kind == Kind::Advanced => self.bdtr,
            0x48 | 0x4C if self.kind == Kind::Advanced => self.ccr[4 + ((o - 0x48) / 4) as usize],
            0x50 if self.kind == Kind::Advanced => self.ccmr[2],
            0x60 => self.af1,
            0x64 => self.af2,
            0x54..=0x68 => self.other[((o - 0x54) / 4) as usize % 8],
            _ => return None,
        })
    }

    /// Register write at offset `o`; returns whether an update event was generated by UG.
    pub fn write(&mut self, o: u32, v: u32, now: u64, encoder: u16) -> Option<bool> {
        let mut ug = false;
        match o {
            0x00 => {
                let cnt = self.cnt(now, encoder);
                let was_running = self.cr1 & 1 != 0;
                // DIR is read-only in centre-aligned mode.
                self.cr1 = v & 0xFFF;
                if self.cr1 & 1 != 0 && !was_running {
                    self.rebase(now, cnt);
                    self.events = 0;
                } else if self.cr1 & 1 == 0 && was_running {
                    self.pos0 = u64::from(cnt);
                }
                if self.cr1 & (1 << 7) == 0 {
                    self.arr_active = self.arr;
                }
            }
            0x04 => self.cr2 = v,
            0x08 => self.smcr = v,
            0x0C => self.dier = v,
            // rc_w0: writing 0 clears, 1 leaves the flag.
            0x10 => self.sr &= v,
            0x14 => {
                if v & 1 != 0 {
                    ug = true;
                    self.events = 0;
                    self.update_event(now, true);
                }
                // CCxG, BG: the flags.
                self.sr |= v & 0x1FE;
            }
            0x18 => self.ccmr[0] = v,
            0x1C => self.ccmr[1] = v,
            0x20 => self.ccer = v,
            0x24 => {
                if self.encoder_mode() {
                    self.encoder_offset = (v as u16).wrapping_sub(encoder);
                } else {
                    self.rebase(now, v);
                }
            }
            0x28 => self.psc = v & 0xFFFF,
            0x2C => {
                let cnt = self.cnt(now, encoder);
                self.arr = if self.kind == Kind::Gp32 {
                    v
                } else {
                    v & 0xFFFF
                };
                if self.cr1 & (1 << 7) == 0 {
                    self.arr_active = self.arr;
                    if self.running() {
                        self.rebase(now, cnt);
                    }
                }
            }
            0x30 if self.kind == Kind::Advanced => self.rcr = v & 0xFFFF,
            0x34..=0x40 | 0x48 | 0x4C => {
                let ch = if o >= 0x48 {
                    4 + ((o - 0x48) / 4) as usize
                } else {
                    ((o - 0x34) / 4) as usize
                };
                self.ccr[ch] = v;
                let preload = self.ccmr[ch / 2 % 3] >> (3 + 8 * (ch % 2)) & 1 != 0;
                if !preload {
                    self.ccr_active[ch] = v;
                }
            }
            0x44 if self.kind == Kind::Advanced => {
                // LOCK level 2 freezes the break and off-state bits once set; MOE stays free.
                let lock = (self.bdtr >> 8) & 3;
                if lock >= 2 {
                    self.bdtr = (self.bdtr & !(1 << 15)) | (v & (1 << 15));
                } else {
                    self.bdtr = v;
                }
            }
            0x50 if self.kind == Kind::Advanced => self.ccmr[2] = v,
            0x60 => self.af1 = v,
            0x64 => self.af2 = v,
            0x54..=0x68 => self.other[((o - 0x54) / 4) as usize % 8] = v,
            _ => return None,
        }
        Some(ug)
    }

    /// The break input became active: outputs off by hardware, BIF.
    pub fn break_in(&mut self) -> bool {
        if self.bdtr & (1 << 12) == 0 {
            return false;
        }
        if self.bdtr & (1 << 15) != 0 {
            self.hw_breaks += 1;
        }
        self.bdtr &= !(1 << 15);
        let new = self.sr & (1 << 7) == 0;
        self.sr |= 1 << 7;
        new && self.dier & (1 << 7) != 0
    }

    /// Whether the break input selects COMP3, with its polarity (true: inverted).
    pub fn break_from_comp3(&self) -> Option<bool> {
        (self.af1 & (1 << 3) != 0).then_some(self.af1 & (1 << 12) != 0)
    }

    /// Break active high (BDTR.BKP).
    pub fn break_active_high(&self) -> bool {
        self.bdtr & (1 << 13) != 0
    }

    /// The bridge input's duty from channel 1: compare over the period, when the main
    /// output and CH1 are on (`None`: the output is at its idle level, low).
    pub fn ch1_duty(&self) -> Option<f64> {
        let on = self.cr1 & 1 != 0 && self.bdtr & (1 << 15) != 0 && self.ccer & 1 != 0;
        // PWM mode 1, centre-aligned: high while CNT < CCR1, CNT sweeping 0..ARR..0.
        on.then(|| {
            let arr = f64::from(self.arr_active.max(1));
            (f64::from(self.ccr_active[0]) / arr).clamp(0.0, 1.0)
        })
    }

    /// MMS: the update event is TRGO.
    pub fn trgo_on_update(&self) -> bool {
        (self.cr2 >> 4) & 7 == 2
    }
}
