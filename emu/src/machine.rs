//! The Cortex-M4 around the Unicorn CPU: memory map, virtual time from the instruction
//! count, exception entry and return (ARMv7-M B1.5.6-B1.5.8), WFI/WFE, resets.
#![allow(unsafe_code)]

use std::collections::{BTreeMap, HashMap};
use std::ffi::c_void;

use crate::EmuError;
use crate::elf::Image;
use crate::periph::{Bus, Env, Mem};
use crate::unicorn::{self as uc, Api, Engine};

/// Core clock, Hz: one instruction is one cycle of it.
pub const SYSCLK_HZ: u64 = 170_000_000;

/// Flash, SRAM (SRAM1 + SRAM2, contiguous), CCM SRAM, system memory (factory values).
pub const FLASH: (u32, u32) = (0x0800_0000, 512 * 1024);
/// SRAM1 and SRAM2.
pub const RAM: (u32, u32) = (0x2000_0000, 96 * 1024);
const CCM: (u32, u32) = (0x1000_0000, 32 * 1024);
const SYSTEM: (u32, u32) = (0x1FFF_0000, 0x8000);
/// VREFINT_CAL (RM0440 21.4.34 / DS12288 table 9): VREFINT at 3.0 V, 12 bits.
pub const VREFINT_CAL_ADDR: u32 = 0x1FFF_75AA;
/// A typical part's VREFINT_CAL (1.212 V at VDDA 3.0 V).
pub const VREFINT_CAL: u16 = 1655;
/// How much of the flash is aliased at address 0 (the boot mapping), bytes.
const ALIAS_LEN: u32 = 64 * 1024;
/// Memory-mapped peripheral windows handed to [`Bus`].
const MMIO: [(u32, u32); 6] = [
    (0x4000_0000, 0x1_0000),  // APB1
    (0x4001_0000, 0x1_0000),  // APB2
    (0x4002_0000, 0x1_0000),  // AHB1
    (0x4800_0000, 0x2000),    // AHB2: GPIO
    (0x5000_0000, 0x2000),    // AHB2: ADC, DAC
    (0xE000_0000, 0x10_0000), // private peripheral bus: SCS, DWT, DBGMCU
];

/// Cycles from an exception's signal to its handler's first instruction (TRM 3.3).
const ENTRY_CYCLES: u64 = 12;
/// EXCP_EXCEPTION_EXIT of Unicorn's ARM core: a handler returned (EXC_RETURN in pc).
const INTNO_EXCEPTION_EXIT: u32 = 8;
/// EXCP_UDEF: an undefined instruction (the firmware's `udf` on a fatal error).
const INTNO_UDEF: u32 = 1;
/// EXCP_SWI, EXCP_BKPT.
const INTNO_SWI: u32 = 2;
const INTNO_BKPT: u32 = 7;

/// Fixed exception numbers.
pub mod exc {
    /// HardFault.
    pub const HARD_FAULT: u32 = 3;
    /// MemManage.
    pub const MEM_MANAGE: u32 = 4;
    /// BusFault.
    pub const BUS_FAULT: u32 = 5;
    /// UsageFault.
    pub const USAGE_FAULT: u32 = 6;
    /// SVCall.
    pub const SVCALL: u32 = 11;
    /// PendSV.
    pub const PENDSV: u32 = 14;
    /// SysTick.
    pub const SYSTICK: u32 = 15;
    /// First external interrupt.
    pub const IRQ0: u32 = 16;
}

/// A stop the image cannot continue from (lockup: a fault in the HardFault handler).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lockup {
    /// Where.
    pub pc: u32,
    /// What happened.
    pub why: String,
}

/// What the block hook and callbacks share with the run loop.
pub(crate) struct State {
    pub cycles: u64,
    pub deadline: u64,
    pub stop_requested: bool,
    pub returned: bool,
    pub lowest_sp: u32,
    pub fault: Option<(u32, String)>,
}

/// One MMIO window's callback data.
struct Window {
    machine: *mut Machine,
    base: u32,
}

/// The emulated MCU.
pub struct Machine {
    api: &'static Api,
    uc: Engine,
    /// The image's segments and symbols.
    pub image: Image,
    /// The peripherals, the NVIC and the SCB.
    pub bus: Bus,
    pub(crate) st: State,
    block_insns: HashMap<u32, u32>,
    // Boxed: the engine holds each window's address.
    #[allow(clippy::vec_box)]
    windows: Vec<Box<Window>>,
    sleeping: bool,
    event: bool,
    /// Lockups (the board stops running code until reset).
    pub lockup: Option<Lockup>,
    /// Exceptions taken, by number.
    pub exceptions_taken: BTreeMap<u32, u64>,
    /// Faults taken: (cycle, description with the pc).
    pub faults: Vec<(u64, String)>,
    /// Resets after the power-on one (watchdogs, software), with their cause.
    pub resets: Vec<(u64, &'static str)>,
}

// SAFETY: the engine and the callbacks' pointers are used only by the thread that holds
// the machine (`&mut self`); moving it to another thread moves all of them together.
unsafe impl Send for Machine {}

impl Drop for Machine {
    fn drop(&mut self) {
        self.api.close(self.uc);
    }
}

impl Machine {
    /// Loads `image` into a new MCU with an erased calibration store and `env` as its
    /// surroundings, held in reset (call [`Machine::power_on`]).
    pub fn new(image: Image, env: Box<dyn Env>) -> Result<Box<Self>, EmuError> {
        let api = Api::get()?;
        let engine = api.open_m4()?;
        let mut m = Box::new(Self {
            api,
            uc: engine,
            image,
            bus: Bus::new(env),
            st: State {
                cycles: 0,
                deadline: 0,
                stop_requested: false,
                returned: false,
                lowest_sp: u32::MAX,
                fault: None,
            },
            block_insns: HashMap::new(),
            windows: Vec::new(),
            sleeping: false,
            event: false,
            lockup: None,
            exceptions_taken: BTreeMap::new(),
            resets: Vec::new(),
            faults: Vec::new(),
        });
        m.map_memory()?;
        Ok(m)
    }

    fn map_memory(&mut self) -> Result<(), EmuError> {
        let (api, e) = (self.api, self.uc);
        api.mem_map(
            e,
            FLASH.0.into(),
            FLASH.1.into(),
            uc::UC_PROT_READ | uc::UC_PROT_EXEC,
        )?;
        api.mem_map(e, RAM.0.into(), RAM.1.into(), uc::UC_PROT_ALL)?;
        api.mem_map(e, CCM.0.into(), CCM.1.into(), uc::UC_PROT_ALL)?;
        api.mem_map(e, SYSTEM.0.into(), SYSTEM.1.into(), uc::UC_PROT_READ)?;
        api.write(e, u64::from(FLASH.0), &vec![0xFF; FLASH.1 as usize])?;
        for (addr, bytes) in &self.image.segments {
            api.write(e, u64::from(*addr), bytes)
                .map_err(|err| EmuError::Image {
                    path: "ELF".into(),
                    why: format!("segment at {addr:#010x} outside the G474's flash and RAM: {err}"),
                })?;
        }
        api.write(e, VREFINT_CAL_ADDR.into(), &VREFINT_CAL.to_le_bytes())?;
        // FLASH_SIZE (RM0440 47.2): 512 KiB.
        api.write(e, 0x1FFF_75E0, &512u16.to_le_bytes())?;
        // Booting from flash, address 0 aliases it (the vector table at VTOR's reset value).
        api.mem_map(
            e,
            0,
            u64::from(ALIAS_LEN),
            uc::UC_PROT_READ | uc::UC_PROT_EXEC,
        )?;
        let mut head = vec![0u8; ALIAS_LEN as usize];
        api.read(e, FLASH.0.into(), &mut head)?;
        api.write(e, 0, &head)?;
        let me: *mut Machine = self;
        for (base, size) in MMIO {
            let w = Box::new(Window { machine: me, base });
            let user = (&*w as *const Window).cast_mut().cast::<c_void>();
            api.mmio_map(e, base.into(), size.into(), mmio_read, mmio_write, user)?;
            self.windows.push(w);
        }
        let user = me.cast::<c_void>();
        api.hook_add(e, uc::UC_HOOK_BLOCK, on_block as *mut c_void, user, 1, 0)?;
        api.hook_add(e, uc::UC_HOOK_INTR, on_intr as *mut c_void, user, 1, 0)?;
        api.hook_add(
            e,
            uc::UC_HOOK_MEM_READ_UNMAPPED
                | uc::UC_HOOK_MEM_WRITE_UNMAPPED
                | uc::UC_HOOK_MEM_FETCH_UNMAPPED
                | uc::UC_HOOK_MEM_READ_PROT
                | uc::UC_HOOK_MEM_WRITE_PROT,
            on_bad_access as *mut c_void,
            user,
            1,
            0,
        )?;
        Ok(())
    }

    /// Writes `bytes` into the image in flash at `address` (and its boot alias), before
    /// power-on: a value the emulator hands the image (its pace).
    pub fn patch_flash(&mut self, address: u32, bytes: &[u8]) -> Result<(), EmuError> {
        self.api.write(self.uc, address.into(), bytes)?;
        if let Some(offset) = address.checked_sub(FLASH.0).filter(|o| *o < ALIAS_LEN) {
            self.api.write(self.uc, offset.into(), bytes)?;
        }
        Ok(())
    }

    /// Fault injection: moves the stack pointer to `bytes` above the MPU's stack guard, so
    /// the next push overflows into it (as a deeper call chain would). Returns the guard
    /// (base, size), or None when the image configured none.
    pub fn inject_stack_overflow(&mut self, bytes: u32) -> Option<(u32, u32)> {
        let (base, size) = self.bus.scs.guard()?;
        self.api
            .set_reg(self.uc, uc::REG_SP, (base + size + bytes) & !7);
        Some((base, size))
    }

    /// The engine's memory, for the board's own reads and writes.
    pub fn mem(&self) -> Mem {
        Mem {
            api: self.api,
            uc: self.uc,
        }
    }

    /// Virtual time since power-on, CPU cycles.
    pub fn cycles(&self) -> u64 {
        self.st.cycles
    }

    /// Lowest stack pointer seen at a block's start since power-on.
    pub fn lowest_sp(&self) -> u32 {
        self.st.lowest_sp
    }

    /// Addresses the image touched that no model covers: (address, pc, write).
    pub fn unmodelled(&self) -> &BTreeMap<u32, (u32, bool)> {
        &self.bus.unmodelled
    }

    /// The function at `pc` (for messages).
    pub fn where_is(&self, pc: u32) -> String {
        match self.image.function_at(pc) {
            Some(f) => format!("{pc:#010x} ({f})"),
            None => format!("{pc:#010x}"),
        }
    }

    /// Power-on reset: the reset flags say so.
    pub fn power_on(&mut self) {
        self.bus.rcc.power_on();
        self.reset_core();
    }

    /// A system reset by `cause` (RCC_CSR flags set by the caller's peripheral): RAM keeps
    /// its contents, every peripheral and the core start over.
    pub(crate) fn system_reset(&mut self, cause: &'static str) {
        self.resets.push((self.st.cycles, cause));
        self.reset_core();
    }

    fn reset_core(&mut self) {
        let (api, e) = (self.api, self.uc);
        self.bus.reset(self.st.cycles);
        self.bus.scs.reset();
        let sp = api.read_u32(e, FLASH.0.into());
        let pc = api.read_u32(e, u64::from(FLASH.0) + 4);
        for r in uc::REG_R0..=uc::REG_R12 {
            api.set_reg(e, r, 0);
        }
        api.set_reg(e, uc::REG_CONTROL, 0);
        api.set_reg(e, uc::REG_PRIMASK, 0);
        api.set_reg(e, uc::REG_BASEPRI, 0);
        api.set_reg(e, uc::REG_FAULTMASK, 0);
        api.set_reg(e, uc::REG_IPSR, 0);
        api.set_reg(e, uc::REG_SP, sp);
        api.set_reg(e, uc::REG_LR, 0xFFFF_FFFF);
        api.set_reg(e, uc::REG_PC, pc & !1);
        self.sleeping = false;
        self.event = false;
        self.lockup = None;
        self.st.fault = None;
    }

    /// Runs until virtual time `until` (cycles since power-on).
    pub fn run_until(&mut self, until: u64) -> Result<(), EmuError> {
        while self.st.cycles < until {
            let now = self.st.cycles;
            let mem = self.mem();
            self.bus.advance(now, &mem);
            if let Some(cause) = self.bus.take_reset() {
                self.system_reset(cause);
                continue;
            }
            if self.lockup.is_some() {
                // Locked up: nothing runs until a watchdog resets the chip.
                self.st.cycles = self
                    .bus
                    .next_event(now)
                    .unwrap_or(until)
                    .clamp(now + 1, until);
                continue;
            }
            if self.take_exception() {
                self.sleeping = false;
            }
            if self.sleeping {
                let next = self.bus.next_event(now).unwrap_or(until).min(until);
                self.st.cycles = next.max(now + 1);
                continue;
            }
            let next = self.bus.next_event(now).unwrap_or(u64::MAX);
            self.st.deadline = next.min(until).max(now + 1);
            self.st.stop_requested = false;
            self.st.returned = false;
            let pc = self.api.reg(self.uc, uc::REG_PC);
            let result = self.api.start(self.uc, pc, 0);
            for (address, old) in std::mem::take(&mut self.bus.flash_restore) {
                let _ = self.api.write_u32(self.uc, address.into(), old);
            }
            if let Some(guard) = self.bus.scs.take_mpu_change() {
                self.apply_mpu(guard)?;
            }
            if let Some((at, why)) = self.st.fault.take() {
                self.fault(at, &why, exc::HARD_FAULT);
                continue;
            }
            if let Err(e) = result {
                // Unicorn ends the run at WFI/WFE (pc after it) with "invalid instruction".
                if !self.sleep_if_asked() {
                    let at = self.api.reg(self.uc, uc::REG_PC);
                    self.fault(at, &e.to_string(), exc::HARD_FAULT);
                }
                continue;
            }
            if !self.st.stop_requested && !self.st.returned {
                self.sleep_if_asked();
            }
        }
        Ok(())
    }

    /// After a run ended by itself: if WFI or WFE just ran (pc after it), the core sleeps
    /// (WFE only without a latched event); returns whether it was one of them.
    fn sleep_if_asked(&mut self) -> bool {
        let pc = self.api.reg(self.uc, uc::REG_PC);
        let mut b = [0u8; 2];
        if self
            .api
            .read(self.uc, u64::from(pc.wrapping_sub(2)), &mut b)
            .is_err()
        {
            return false;
        }
        match u16::from_le_bytes(b) {
            // WFE: sleeps unless an event is latched (an exception since the last WFE).
            0xBF20 => {
                if self.event {
                    self.event = false;
                } else {
                    self.sleeping = true;
                }
                true
            }
            // WFI: sleeps until an exception is ready.
            0xBF30 => {
                self.sleeping = true;
                true
            }
            _ => false,
        }
    }

    /// A synchronous fault at `pc`: the handler the configuration selects, or a lockup
    /// when it happens in the HardFault handler.
    fn fault(&mut self, pc: u32, why: &str, number: u32) {
        let at = format!("{why} at {}", self.where_is(pc));
        self.faults.push((self.st.cycles, at));
        let ipsr = self.api.reg(self.uc, uc::REG_IPSR) & 0x1FF;
        if ipsr == exc::HARD_FAULT || ipsr == 2 {
            let broke = self.bus.lockup();
            self.faults.push((
                self.st.cycles,
                format!("{why} inside the HardFault handler: lockup (TIM1 broken by SYSCFG_CFGR2.CLL: {broke})"),
            ));
            self.lockup = Some(Lockup {
                pc,
                why: format!("{why} inside the HardFault handler (lockup)"),
            });
            return;
        }
        // A configurable fault that is not enabled escalates to HardFault.
        let number = if number == exc::HARD_FAULT || self.bus.scs.fault_enabled(number) {
            number
        } else {
            exc::HARD_FAULT
        };
        self.bus.scs.record_fault(number, why);
        self.enter(number, pc);
    }

    /// Takes the most urgent ready exception, if any.
    fn take_exception(&mut self) -> bool {
        let prio = self.execution_priority();
        match self.bus.scs.ready(prio) {
            Some(n) => {
                self.bus.scs.clear_pending(n);
                let pc = self.api.reg(self.uc, uc::REG_PC);
                self.enter(n, pc);
                true
            }
            None => false,
        }
    }

    /// The current execution priority (lower is more urgent; 256: thread mode).
    pub(crate) fn execution_priority(&self) -> i32 {
        let (api, e) = (self.api, self.uc);
        let mut p = self.bus.scs.active_priority();
        let basepri = api.reg(e, uc::REG_BASEPRI) & 0xFF;
        if basepri != 0 {
            p = p.min(basepri as i32);
        }
        if api.reg(e, uc::REG_PRIMASK) & 1 != 0 {
            p = p.min(0);
        }
        if api.reg(e, uc::REG_FAULTMASK) & 1 != 0 {
            p = p.min(-1);
        }
        p
    }

    /// Exception entry (B1.5.6): the frame (with the FP context when CONTROL.FPCA) on the
    /// current stack, EXC_RETURN in lr, the handler's vector in pc.
    fn enter(&mut self, number: u32, return_pc: u32) {
        let (api, e) = (self.api, self.uc);
        let control = api.reg(e, uc::REG_CONTROL);
        let ipsr = api.reg(e, uc::REG_IPSR) & 0x1FF;
        let thread = ipsr == 0;
        let psp = thread && control & 2 != 0;
        let fpca = control & 4 != 0;
        let mut xpsr = api.reg(e, uc::REG_XPSR);
        let sp = api.reg(e, uc::REG_SP);
        let frame_len: u32 = if fpca { 0x68 } else { 0x20 };
        let mut frame = sp.wrapping_sub(frame_len);
        if frame & 4 != 0 {
            frame &= !7;
            xpsr |= 1 << 9;
        } else {
            xpsr &= !(1 << 9);
        }
        let mut words = Vec::with_capacity(26);
        for r in [
            uc::REG_R0,
            uc::REG_R0 + 1,
            uc::REG_R0 + 2,
            uc::REG_R0 + 3,
            uc::REG_R12,
        ] {
            words.push(api.reg(e, r));
        }
        words.push(api.reg(e, uc::REG_LR));
        words.push(return_pc & !1);
        words.push(xpsr | (1 << 24));
        if fpca {
            for s in 0..16 {
                words.push(api.reg(e, uc::REG_S0 + s));
            }
            words.push(api.reg(e, uc::REG_FPSCR));
            words.push(0);
        }
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let in_ram = frame >= RAM.0 && frame + frame_len <= RAM.0 + RAM.1;
        if !in_ram || !self.bus.scs.stack_allowed(frame, frame_len) {
            // Stacking into the stack guard (or off RAM) faults (MSTKERR); the HardFault it
            // escalates to stacks at the same place and faults again: the core locks up
            // (ARMv7-M B1.5.15) until a reset, with SYSCFG_CFGR2.CLL breaking TIM1.
            self.bus
                .scs
                .record_fault(exc::MEM_MANAGE, "stacking error (MSTKERR)");
            let why = format!(
                "exception {number}'s frame at {frame:#010x} falls in the stack guard: lockup"
            );
            let broke = self.bus.lockup();
            self.faults.push((
                self.st.cycles,
                format!("{why} (TIM1 broken by SYSCFG_CFGR2.CLL: {broke})"),
            ));
            self.lockup = Some(Lockup { pc: return_pc, why });
            return;
        }
        let _ = api.write(e, frame.into(), &bytes);
        let exc_return = match (thread, psp, fpca) {
            (false, _, false) => 0xFFFF_FFF1,
            (false, _, true) => 0xFFFF_FFE1,
            (true, false, false) => 0xFFFF_FFF9,
            (true, false, true) => 0xFFFF_FFE9,
            (true, true, false) => 0xFFFF_FFFD,
            (true, true, true) => 0xFFFF_FFED,
        };
        if psp {
            // The handler runs on the main stack; the thread's stack keeps the frame.
            api.set_reg(e, uc::REG_SP, frame);
            api.set_reg(e, uc::REG_CONTROL, control & !2 & !4);
        } else {
            api.set_reg(e, uc::REG_SP, frame);
            api.set_reg(e, uc::REG_CONTROL, control & !4);
        }
        api.set_reg(e, uc::REG_LR, exc_return);
        api.set_reg(e, uc::REG_IPSR, number);
        let vector = api.read_u32(e, u64::from(self.bus.scs.vtor) + 4 * u64::from(number));
        api.set_reg(e, uc::REG_PC, vector & !1);
        self.bus.scs.activate(number);
        self.st.cycles += ENTRY_CYCLES;
        self.st.lowest_sp = self.st.lowest_sp.min(frame);
        self.event = true;
        *self.exceptions_taken.entry(number).or_default() += 1;
    }

    /// Exception return (B1.5.8), called from the interrupt hook with EXC_RETURN in pc.
    fn exception_return(&mut self) {
        let (api, e) = (self.api, self.uc);
        let exc_return = api.reg(e, uc::REG_PC) | 1;
        self.bus.scs.deactivate();
        let to_thread = exc_return & 8 != 0;
        let from_psp = exc_return & 4 != 0;
        let fp = exc_return & 0x10 == 0;
        let control = api.reg(e, uc::REG_CONTROL);
        let frame = if from_psp {
            // Unicorn's sp is the current stack; with SPSEL the process stack.
            api.set_reg(e, uc::REG_CONTROL, control | 2);
            api.reg(e, uc::REG_SP)
        } else {
            api.reg(e, uc::REG_SP)
        };
        let n = if fp { 26 } else { 8 };
        let mut bytes = vec![0u8; n * 4];
        let _ = api.read(e, frame.into(), &mut bytes);
        let w = |k: usize| u32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap_or([0; 4]));
        for (k, r) in [
            uc::REG_R0,
            uc::REG_R0 + 1,
            uc::REG_R0 + 2,
            uc::REG_R0 + 3,
            uc::REG_R12,
        ]
        .into_iter()
        .enumerate()
        {
            api.set_reg(e, r, w(k));
        }
        api.set_reg(e, uc::REG_LR, w(5));
        let pc = w(6);
        let xpsr = w(7);
        if fp {
            for s in 0..16 {
                api.set_reg(e, uc::REG_S0 + s as i32, w(8 + s));
            }
            api.set_reg(e, uc::REG_FPSCR, w(24));
        }
        let mut sp = frame + 4 * n as u32;
        if xpsr & (1 << 9) != 0 {
            sp += 4;
        }
        let mut control = api.reg(e, uc::REG_CONTROL);
        control = if fp { control | 4 } else { control & !4 };
        if !(to_thread && from_psp) {
            control &= !2;
        }
        api.set_reg(e, uc::REG_CONTROL, control);
        api.set_reg(e, uc::REG_SP, sp);
        // Flags and the IPSR of the interrupted context (thread: 0).
        api.set_reg(e, uc::REG_XPSR, (xpsr & !(1 << 9)) | (1 << 24));
        api.set_reg(e, uc::REG_IPSR, if to_thread { 0 } else { xpsr & 0x1FF });
        api.set_reg(e, uc::REG_PC, pc & !1);
        self.st.returned = true;
        // Let the run loop tail-chain a pending exception or go on.
        api.stop(e);
    }

    /// The core's registers r0-r12, sp, lr, pc, xpsr (for messages and tests).
    pub fn registers(&self) -> [u32; 17] {
        let (api, e) = (self.api, self.uc);
        let mut out = [0u32; 17];
        for (k, r) in out.iter_mut().take(13).enumerate() {
            *r = api.reg(e, uc::REG_R0 + k as i32);
        }
        out[13] = api.reg(e, uc::REG_SP);
        out[14] = api.reg(e, uc::REG_LR);
        out[15] = api.reg(e, uc::REG_PC);
        out[16] = api.reg(e, uc::REG_XPSR);
        out
    }

    fn count_block(&mut self, address: u32, size: u32) -> u32 {
        if let Some(n) = self.block_insns.get(&address) {
            return *n;
        }
        let mut code = vec![0u8; size as usize];
        let _ = self.api.read(self.uc, address.into(), &mut code);
        let mut n = 0;
        let mut k = 0;
        while k + 1 < code.len() {
            let hw = u16::from_le_bytes([code[k], code[k + 1]]);
            k += if hw >> 11 >= 0b11101 { 4 } else { 2 };
            n += 1;
        }
        let n = n.max(1);
        self.block_insns.insert(address, n);
        n
    }
}

/// SAFETY (all callbacks): `user` is the `Machine` (or one of its `Window`s) that owns the
/// engine; the engine calls back only from `uc_emu_start` on the thread that runs
/// [`Machine::run_until`], which does not touch the machine while the engine runs.
unsafe extern "C" fn on_block(_uc: Engine, address: u64, size: u32, user: *mut c_void) {
    let m = unsafe { &mut *user.cast::<Machine>() };
    let n = m.count_block(address as u32, size);
    m.st.cycles += u64::from(n);
    let sp = m.api.reg(m.uc, uc::REG_SP);
    if sp < m.st.lowest_sp {
        m.st.lowest_sp = sp;
    }
    let due = m.st.cycles >= m.st.deadline;
    let irq = m.bus.scs.any_pending() && m.bus.scs.ready(m.execution_priority()).is_some();
    if (due || irq) && !m.st.stop_requested {
        m.st.stop_requested = true;
        m.api.stop(m.uc);
    }
}

unsafe extern "C" fn on_intr(_uc: Engine, intno: u32, user: *mut c_void) {
    let m = unsafe { &mut *user.cast::<Machine>() };
    let pc = m.api.reg(m.uc, uc::REG_PC);
    match intno {
        INTNO_EXCEPTION_EXIT => m.exception_return(),
        INTNO_UDEF => {
            m.st.fault = Some((pc, "undefined instruction (UDF)".into()));
            m.api.stop(m.uc);
        }
        INTNO_SWI => {
            m.st.fault = Some((pc, "SVC without a handler model".into()));
            m.api.stop(m.uc);
        }
        INTNO_BKPT => {
            // A breakpoint without a debugger escalates to HardFault (DHCSR.C_DEBUGEN 0).
            m.st.fault = Some((pc, "BKPT with no debugger attached".into()));
            m.api.stop(m.uc);
        }
        other => {
            m.st.fault = Some((pc, format!("CPU exception {other}")));
            m.api.stop(m.uc);
        }
    }
}

unsafe extern "C" fn on_bad_access(
    _uc: Engine,
    kind: i32,
    address: u64,
    _size: i32,
    value: i64,
    user: *mut c_void,
) -> bool {
    let m = unsafe { &mut *user.cast::<Machine>() };
    let pc = m.api.reg(m.uc, uc::REG_PC);
    let write = kind == 20 || kind == 22; // UC_MEM_WRITE_UNMAPPED, UC_MEM_WRITE_PROT
    let address = address as u32;
    if kind == 22 && address >= FLASH.0 && address - FLASH.0 < FLASH.1 {
        // A store into flash: the controller programs it or flags an error; the engine
        // stores the word either way, so a refused one is put back after this run.
        let old = m.api.read_u32(m.uc, address.into());
        let now = m.st.cycles;
        if m.bus.flash_write(address, value as u32, old, now) {
            // Programmed (the engine does not store into read-only memory by itself).
            let _ = m.api.write_u32(m.uc, address.into(), value as u32);
        } else {
            m.bus.flash_restore.push((address, old));
            m.st.deadline = 0;
        }
        return true;
    }
    let why = if m.bus.scs.in_guard(address) {
        m.bus.scs.mmfar = address;
        format!("stack guard hit at {address:#010x} (MPU)")
    } else {
        m.bus.unmodelled.entry(address).or_insert((pc, write));
        format!(
            "{} of {address:#010x}: no memory or peripheral there (BusFault)",
            if write { "write" } else { "read" }
        )
    };
    m.st.fault = Some((pc, why));
    false
}

unsafe extern "C" fn mmio_read(_uc: Engine, offset: u64, size: u32, user: *mut c_void) -> u64 {
    let w = unsafe { &*user.cast::<Window>() };
    let m = unsafe { &mut *w.machine };
    let address = w.base + offset as u32;
    let mem = m.mem();
    let now = m.st.cycles;
    let pc = m.api.reg(m.uc, uc::REG_PC);
    u64::from(m.bus.read(address, size, now, pc, &mem))
}

unsafe extern "C" fn mmio_write(
    _uc: Engine,
    offset: u64,
    size: u32,
    value: u64,
    user: *mut c_void,
) {
    let w = unsafe { &*user.cast::<Window>() };
    let m = unsafe { &mut *w.machine };
    let address = w.base + offset as u32;
    let mem = m.mem();
    let now = m.st.cycles;
    let pc = m.api.reg(m.uc, uc::REG_PC);
    m.bus.write(address, size, value as u32, now, pc, &mem);
    // A write may make an interrupt pending, pull a reset or move an event nearer: the
    // run stops at the next block (a stop from here would replay this store).
    if m.bus.wants_attention() {
        m.st.deadline = 0;
    }
}

impl Machine {
    /// Protects (or frees) the stack guard region the MPU's configuration names.
    fn apply_mpu(&mut self, guard: Option<(u32, u32)>) -> Result<(), EmuError> {
        if let Some((old_base, old_size)) = self.bus.scs.protected.take() {
            self.api
                .mem_protect(self.uc, old_base.into(), old_size.into(), uc::UC_PROT_ALL)?;
        }
        if let Some((base, size)) = guard {
            // Unicorn's ARM pages are 1 KiB: smaller guards cannot be protected exactly.
            if base % 1024 == 0 && size % 1024 == 0 && base >= RAM.0 && base + size <= RAM.0 + RAM.1
            {
                self.api
                    .mem_protect(self.uc, base.into(), size.into(), uc::UC_PROT_NONE)?;
                self.bus.scs.protected = Some((base, size));
            }
        }
        Ok(())
    }
}
