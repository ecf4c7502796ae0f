//! The Unicorn engine (2.x) as a library loaded at run time.
//!
//! No C build: the engine comes as `libunicorn.so.2` from the pinned `unicorn` wheel on PyPI
//! (the same one the target bench uses), which `cargo xtask setup` installs into
//! `target/target-bench-venv`. [`Api::load`] finds it there, at `$RIG_UNICORN`, or in
//! any `unicorn` package the machine's `python3` can import, and says what to do when
//! none is found.
//!
//! Only the part of the C API the board needs is declared, with the constants of
//! `unicorn/unicorn.h` and `unicorn/arm.h` (2.1).
#![allow(unsafe_code)]

use std::ffi::{CStr, c_char, c_int, c_void};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::EmuError;

/// The Unicorn version the project pins (the target bench's `UNICORN_VERSION` too).
pub const UNICORN_VERSION: &str = "2.1.4";

/// `uc_engine *`.
pub type Engine = *mut c_void;

pub type MmioRead = unsafe extern "C" fn(Engine, u64, u32, *mut c_void) -> u64;
pub type MmioWrite = unsafe extern "C" fn(Engine, u64, u32, u64, *mut c_void);

pub const UC_ARCH_ARM: c_int = 1;
pub const UC_MODE_THUMB: c_int = 1 << 4;
pub const UC_MODE_MCLASS: c_int = 1 << 5;
pub const UC_PROT_NONE: u32 = 0;
pub const UC_PROT_ALL: u32 = 7;
pub const UC_PROT_READ: u32 = 1;
pub const UC_PROT_EXEC: u32 = 4;

pub const UC_HOOK_INTR: c_int = 1;
pub const UC_HOOK_BLOCK: c_int = 8;
pub const UC_HOOK_MEM_READ_UNMAPPED: c_int = 16;
pub const UC_HOOK_MEM_WRITE_UNMAPPED: c_int = 32;
pub const UC_HOOK_MEM_FETCH_UNMAPPED: c_int = 64;
pub const UC_HOOK_MEM_READ_PROT: c_int = 128;
pub const UC_HOOK_MEM_WRITE_PROT: c_int = 256;

/// `UC_CTL_WRITE(UC_CTL_CPU_MODEL, 1)`.
const UC_CTL_CPU_MODEL_WRITE: u32 = 7 | (1 << 26) | (1 << 30);
/// `UC_CPU_ARM_CORTEX_M4`.
const UC_CPU_ARM_CORTEX_M4: c_int = 9;

pub const REG_LR: c_int = 10;
pub const REG_PC: c_int = 11;
pub const REG_SP: c_int = 12;
pub const REG_FPSCR: c_int = 6;
pub const REG_R0: c_int = 66;
pub const REG_R12: c_int = 78;
pub const REG_S0: c_int = 79;
pub const REG_IPSR: c_int = 114;
pub const REG_CONTROL: c_int = 117;
pub const REG_XPSR: c_int = 120;
pub const REG_PRIMASK: c_int = 123;
pub const REG_BASEPRI: c_int = 124;
pub const REG_FAULTMASK: c_int = 126;

/// The entry points, resolved once per process.
#[allow(clippy::type_complexity)]
pub struct Api {
    _lib: libloading::Library,
    /// Where the library was loaded from.
    pub path: PathBuf,
    open: unsafe extern "C" fn(c_int, c_int, *mut Engine) -> c_int,
    close: unsafe extern "C" fn(Engine) -> c_int,
    ctl: unsafe extern "C" fn(Engine, u32, ...) -> c_int,
    strerror: unsafe extern "C" fn(c_int) -> *const c_char,
    reg_write: unsafe extern "C" fn(Engine, c_int, *const c_void) -> c_int,
    reg_read: unsafe extern "C" fn(Engine, c_int, *mut c_void) -> c_int,
    mem_write: unsafe extern "C" fn(Engine, u64, *const c_void, u64) -> c_int,
    mem_read: unsafe extern "C" fn(Engine, u64, *mut c_void, u64) -> c_int,
    emu_start: unsafe extern "C" fn(Engine, u64, u64, u64, usize) -> c_int,
    emu_stop: unsafe extern "C" fn(Engine) -> c_int,
    hook_add: unsafe extern "C" fn(
        Engine,
        *mut usize,
        c_int,
        *mut c_void,
        *mut c_void,
        u64,
        u64,
        ...
    ) -> c_int,
    mem_map: unsafe extern "C" fn(Engine, u64, u64, u32) -> c_int,
    mem_protect: unsafe extern "C" fn(Engine, u64, u64, u32) -> c_int,
    mmio_map: unsafe extern "C" fn(
        Engine,
        u64,
        u64,
        MmioRead,
        *mut c_void,
        MmioWrite,
        *mut c_void,
    ) -> c_int,
    version: unsafe extern "C" fn(*mut u32, *mut u32) -> u32,
}

static API: OnceLock<Result<Api, String>> = OnceLock::new();

/// Where the library is looked for, in order.
pub fn candidates() -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Some(p) = std::env::var_os("RIG_UNICORN") {
        out.push(PathBuf::from(p));
    }
    // The project's venv (cargo xtask setup / target-bench), from the crate's or the
    // current folder's `target`.
    let roots = [
        std::env::var_os("CARGO_TARGET_DIR").map(PathBuf::from),
        Some(
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("..")
                .join("target"),
        ),
        std::env::current_dir().ok().map(|d| d.join("target")),
    ];
    for root in roots.into_iter().flatten() {
        let lib = root.join("target-bench-venv").join("lib");
        if let Ok(entries) = std::fs::read_dir(&lib) {
            for e in entries.flatten() {
                out.push(e.path().join("site-packages/unicorn/lib/libunicorn.so.2"));
            }
        }
    }
    // A `pip install unicorn` the machine's python3 sees.
    if let Ok(o) = std::process::Command::new("python3")
        .args([
            "-c",
            "import importlib.util as u, os; s = u.find_spec('unicorn'); print(os.path.dirname(s.origin) if s else '')",
        ])
        .stderr(std::process::Stdio::null())
        .output()
    {
        let dir = String::from_utf8_lossy(&o.stdout).trim().to_string();
        if !dir.is_empty() {
            out.push(Path::new(&dir).join("lib").join("libunicorn.so.2"));
        }
    }
    out
}

impl Api {
    /// The loaded engine, or why it could not be loaded (with what to do).
    pub fn get() -> Result<&'static Api, EmuError> {
        API.get_or_init(Self::load)
            .as_ref()
            .map_err(|e| EmuError::NoEmulator(e.clone()))
    }

    fn load() -> Result<Api, String> {
        let tried = candidates();
        let mut errors = Vec::new();
        for path in &tried {
            if !path.exists() {
                continue;
            }
            match Self::open_at(path) {
                Ok(api) => return Ok(api),
                Err(e) => errors.push(format!("{}: {e}", path.display())),
            }
        }
        Err(format!(
            "the Unicorn engine {UNICORN_VERSION} (libunicorn.so.2) was not found{}; install it with `cargo xtask setup` (pip installs the pinned `unicorn` wheel into target/target-bench-venv) or `pip install unicorn=={UNICORN_VERSION}`, or point RIG_UNICORN at libunicorn.so.2",
            if errors.is_empty() {
                String::new()
            } else {
                format!(" ({})", errors.join("; "))
            }
        ))
    }

    fn open_at(path: &Path) -> Result<Api, String> {
        // SAFETY: loading a shared library runs its initialisers; libunicorn's are plain C
        // (no global state beyond its own tables).
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| e.to_string())?;
        macro_rules! sym {
            ($name:literal) => {
                // SAFETY: the symbol's type is the C prototype of unicorn.h (2.1).
                *unsafe { lib.get($name) }.map_err(|e| e.to_string())?
            };
        }
        let api = Api {
            open: sym!(b"uc_open\0"),
            close: sym!(b"uc_close\0"),
            ctl: sym!(b"uc_ctl\0"),
            strerror: sym!(b"uc_strerror\0"),
            reg_write: sym!(b"uc_reg_write\0"),
            reg_read: sym!(b"uc_reg_read\0"),
            mem_write: sym!(b"uc_mem_write\0"),
            mem_read: sym!(b"uc_mem_read\0"),
            emu_start: sym!(b"uc_emu_start\0"),
            emu_stop: sym!(b"uc_emu_stop\0"),
            hook_add: sym!(b"uc_hook_add\0"),
            mem_map: sym!(b"uc_mem_map\0"),
            mem_protect: sym!(b"uc_mem_protect\0"),
            mmio_map: sym!(b"uc_mmio_map\0"),
            version: sym!(b"uc_version\0"),
            path: path.to_path_buf(),
            _lib: lib,
        };
        let (mut major, mut minor) = (0u32, 0u32);
        // SAFETY: plain out-parameters.
        unsafe { (api.version)(&mut major, &mut minor) };
        if major != 2 {
            return Err(format!("version {major}.{minor}, not 2.x"));
        }
        Ok(api)
    }

    fn check(&self, what: &str, code: c_int) -> Result<(), EmuError> {
        if code == 0 {
            return Ok(());
        }
        // SAFETY: uc_strerror returns a static C string for any code.
        let text = unsafe { CStr::from_ptr((self.strerror)(code)) }
            .to_string_lossy()
            .into_owned();
        Err(EmuError::Engine(format!("{what}: {text} (code {code})")))
    }

    /// A Cortex-M4 (Thumb, M profile) engine.
    pub fn open_m4(&self) -> Result<Engine, EmuError> {
        let mut uc: Engine = std::ptr::null_mut();
        // SAFETY: out-parameter.
        let code = unsafe { (self.open)(UC_ARCH_ARM, UC_MODE_THUMB | UC_MODE_MCLASS, &mut uc) };
        self.check("uc_open", code)?;
        // SAFETY: `uc` is open; the control takes one int.
        let code = unsafe { (self.ctl)(uc, UC_CTL_CPU_MODEL_WRITE, UC_CPU_ARM_CORTEX_M4) };
        self.check("uc_ctl(CPU_MODEL)", code)?;
        Ok(uc)
    }

    /// Closes `uc`.
    pub fn close(&self, uc: Engine) {
        // SAFETY: called once per engine, after its last use.
        unsafe { (self.close)(uc) };
    }

    /// Maps RAM-like memory.
    pub fn mem_map(&self, uc: Engine, base: u64, size: u64, perms: u32) -> Result<(), EmuError> {
        // SAFETY: plain values.
        let code = unsafe { (self.mem_map)(uc, base, size, perms) };
        self.check(&format!("uc_mem_map({base:#x}, {size:#x})"), code)
    }

    /// Changes the permissions of mapped memory.
    pub fn mem_protect(
        &self,
        uc: Engine,
        base: u64,
        size: u64,
        perms: u32,
    ) -> Result<(), EmuError> {
        // SAFETY: plain values.
        let code = unsafe { (self.mem_protect)(uc, base, size, perms) };
        self.check(&format!("uc_mem_protect({base:#x}, {size:#x})"), code)
    }

    /// Maps `size` bytes at `base` to the callbacks, with `user` as their data.
    pub fn mmio_map(
        &self,
        uc: Engine,
        base: u64,
        size: u64,
        read: MmioRead,
        write: MmioWrite,
        user: *mut c_void,
    ) -> Result<(), EmuError> {
        // SAFETY: the callbacks match the C prototypes; `user` outlives the engine (the
        // board owns both).
        let code = unsafe { (self.mmio_map)(uc, base, size, read, user, write, user) };
        self.check(&format!("uc_mmio_map({base:#x})"), code)
    }

    /// Adds a hook over `[begin, end]` (all memory when begin > end).
    pub fn hook_add(
        &self,
        uc: Engine,
        kind: c_int,
        callback: *mut c_void,
        user: *mut c_void,
        begin: u64,
        end: u64,
    ) -> Result<(), EmuError> {
        let mut handle = 0usize;
        // SAFETY: `callback` has the prototype `kind` calls for; `user` outlives the engine.
        let code = unsafe { (self.hook_add)(uc, &mut handle, kind, callback, user, begin, end) };
        self.check("uc_hook_add", code)
    }

    /// Writes `bytes` at `address`.
    pub fn write(&self, uc: Engine, address: u64, bytes: &[u8]) -> Result<(), EmuError> {
        // SAFETY: the slice is valid for its length.
        let code =
            unsafe { (self.mem_write)(uc, address, bytes.as_ptr().cast(), bytes.len() as u64) };
        self.check(&format!("write at {address:#x}"), code)
    }

    /// Reads `out.len()` bytes at `address`.
    pub fn read(&self, uc: Engine, address: u64, out: &mut [u8]) -> Result<(), EmuError> {
        // SAFETY: the slice is valid for its length.
        let code =
            unsafe { (self.mem_read)(uc, address, out.as_mut_ptr().cast(), out.len() as u64) };
        self.check(&format!("read at {address:#x}"), code)
    }

    /// A 32-bit word at `address` (0 when unreadable).
    pub fn read_u32(&self, uc: Engine, address: u64) -> u32 {
        let mut b = [0u8; 4];
        let _ = self.read(uc, address, &mut b);
        u32::from_le_bytes(b)
    }

    /// Writes a 32-bit word.
    pub fn write_u32(&self, uc: Engine, address: u64, value: u32) -> Result<(), EmuError> {
        self.write(uc, address, &value.to_le_bytes())
    }

    /// A 32-bit register.
    pub fn reg(&self, uc: Engine, reg: c_int) -> u32 {
        let mut v = 0u64;
        // SAFETY: the engine writes at most 8 bytes for a core register.
        unsafe { (self.reg_read)(uc, reg, (&mut v as *mut u64).cast()) };
        v as u32
    }

    /// Sets a 32-bit register.
    pub fn set_reg(&self, uc: Engine, reg: c_int, value: u32) {
        let v = u64::from(value);
        // SAFETY: the engine reads at most 8 bytes for a core register.
        unsafe { (self.reg_write)(uc, reg, (&v as *const u64).cast()) };
    }

    /// Runs from `begin` (Thumb bit added) until stopped or `count` instructions (0: no
    /// limit) ran.
    pub fn start(&self, uc: Engine, begin: u32, count: usize) -> Result<(), EmuError> {
        // SAFETY: plain values; hooks run on this thread.
        let code = unsafe { (self.emu_start)(uc, u64::from(begin | 1), 0, 0, count) };
        self.check(&format!("emulation from {begin:#010x}"), code)
    }

    /// Asks a running emulation to stop (from a hook).
    pub fn stop(&self, uc: Engine) {
        // SAFETY: allowed from hooks.
        unsafe { (self.emu_stop)(uc) };
    }
}
