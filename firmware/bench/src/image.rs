//! The bench session on the target (see the crate documentation).

use core::mem::MaybeUninit;

use cortex_m_rt::entry;
use firmware_core::{BootInfo, Core, CoreConfig, Inputs, Outputs};
use model::GearSet;
use model::plant::{Drive, Load, Plant, PlantParams};
use protocol::{
    MAX_REQUEST_FRAME_SIZE, PROTOCOL_VERSION, ParametersStatus, Request, ResetCause, RigParameters,
    SCHEMA_HASH, SupervisorState,
};

/// Marker codes, read by the emulator driver from `r0` (keep in step with `driver.py`).
pub mod code {
    /// Begin a measured [`super::Core::step`]; argument: phase | target Hz << 8.
    pub const BEGIN_STEP: u32 = 1;
    /// Begin a measured `receive`; argument: request kind | last chunk << 8.
    pub const BEGIN_RECEIVE: u32 = 2;
    /// Begin a measured `transmit`; argument: 0.
    pub const BEGIN_TRANSMIT: u32 = 3;
    /// Begin a measured `persist_result`; argument: 0.
    pub const BEGIN_PERSIST: u32 = 4;
    /// Begin an empty measurement (the markers' own cost, subtracted from the others).
    pub const BEGIN_EMPTY: u32 = 5;
    /// End of the measured call.
    pub const END: u32 = 0x10;
    /// Detail of the call just measured (step: revolution boundary bit 0, state after in
    /// bits 8..; transmit: bytes returned, uploading bit 16, streaming bit 17).
    pub const NOTE: u32 = 0x11;
    /// The session ended as planned.
    pub const DONE: u32 = 0x20;
    /// The session failed; argument: [`super::fail`] reason | detail << 8.
    pub const FAIL: u32 = 0x21;
}

/// Step phases (the `BEGIN_STEP` argument's low byte).
pub mod phase {
    /// Supervisor locked (telemetry on).
    pub const LOCKED: u32 = 1;
    /// Spinning up to a target.
    pub const SPIN_UP: u32 = 2;
    /// Vibrating at the target.
    pub const VIBRATING: u32 = 3;
    /// Vibrating with a capture recording.
    pub const CAPTURE: u32 = 4;
    /// Braking to rest.
    pub const STOPPING: u32 = 5;
    /// A fault latched.
    pub const FAULT: u32 = 6;
    /// Vibrating with the continuous stream on (10 kHz).
    pub const STREAM: u32 = 7;
}

/// Why a session failed (the `FAIL` argument's low byte).
pub mod fail {
    /// A fault latched; detail: the fault bits.
    pub const FAULT: u32 = 1;
    /// The supervisor did not reach `Vibrating` in time; detail: target Hz.
    pub const NOT_VIBRATING: u32 = 2;
    /// The supervisor did not reach `Locked` in time.
    pub const NOT_LOCKED: u32 = 3;
    /// The capture did not finish uploading in time.
    pub const CAPTURE: u32 = 4;
    /// The calibration was not handed out for a flash write.
    pub const PERSIST: u32 = 5;
    /// A request could not be encoded.
    pub const ENCODE: u32 = 6;
    /// The image panicked.
    pub const PANIC: u32 = 7;
    /// The 10 kHz stream skipped samples (the link fell behind); detail: how many.
    pub const STREAM: u32 = 8;
}

/// Request kinds (the `BEGIN_RECEIVE` argument's low byte).
mod request_kind {
    pub const HELLO: u32 = 1;
    pub const START_TELEMETRY: u32 = 2;
    pub const RELEASE: u32 = 3;
    pub const HEARTBEAT: u32 = 4;
    pub const START_CAPTURE: u32 = 5;
    pub const SET_CALIBRATION: u32 = 6;
    pub const START_STREAM: u32 = 7;
    pub const STOP_STREAM: u32 = 8;
}

/// Plant (and ADC) rate, Hz, as in the sim.
const PLANT_HZ: u64 = 10_000;
/// Host link rate (the firmware's `board::HOST_BAUD_RATE`), 10 bits per byte.
const BAUD: u64 = 921_600;
/// Bytes one `host_rx` read hands to `receive` at most.
const RX_CHUNK: usize = 64;
/// Heartbeat interval while a release is live, us.
const HEARTBEAT_US: u64 = protocol::HEARTBEAT_INTERVAL_MS as u64 * 1000;
/// Load on the output, N m (the sim benchmark's).
const LOAD_NM: f64 = 2.0;
/// The paper's gear set.
const GEAR: [u32; 4] = [49, 51, 50, 50];

/// Where the emulator stops: it reads `code` and `arg` and returns for the function.
#[allow(unsafe_code)] // `no_mangle`: the driver finds the marker by this exact name.
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn bench_marker(code: u32, arg: u32) {
    // Never runs under the driver; keeps the calls from being optimised away.
    core::hint::black_box((code, arg));
}

#[inline(never)]
fn measured_step(core: &mut Core, inputs: &Inputs<'_>, tag: u32) -> Outputs {
    bench_marker(code::BEGIN_STEP, tag);
    let out = core.step(inputs);
    bench_marker(code::END, 0);
    out
}

#[inline(never)]
fn measured_receive(core: &mut Core, now_us: u64, bytes: &[u8], tag: u32) {
    bench_marker(code::BEGIN_RECEIVE, tag);
    core.receive(now_us, bytes);
    bench_marker(code::END, 0);
}

#[inline(never)]
fn measured_transmit(core: &mut Core, out: &mut [u8]) -> usize {
    bench_marker(code::BEGIN_TRANSMIT, 0);
    let n = core.transmit(out);
    bench_marker(code::END, 0);
    n
}

#[inline(never)]
fn measured_persist(core: &mut Core, ok: bool) {
    bench_marker(code::BEGIN_PERSIST, 0);
    core.persist_result(ok);
    bench_marker(code::END, 0);
}

#[inline(never)]
fn measured_empty() {
    bench_marker(code::BEGIN_EMPTY, 0);
    bench_marker(code::END, 0);
}

/// A failed session: the reason and its detail.
struct Failed(u32, u32);

/// The rig: plant, core and the binary's glue, in virtual time.
struct Bench {
    core: &'static mut Core,
    plant: Plant,
    tick: u64,
    adc: [u16; 16],
    adc_len: usize,
    drive: Drive,
    seq: u16,
    keep_alive: bool,
    last_heartbeat_us: u64,
    tx_free_at_us: u64,
    tx_buf: [u8; 256],
    persisted: u32,
}

impl Bench {
    fn now_us(&self) -> u64 {
        self.tick * 1_000_000 / PLANT_HZ
    }

    fn status(&self) -> firmware_core::Status {
        self.core.status()
    }

    /// Sends `req` as the host would; the device handles it in 64-byte chunks.
    fn request(&mut self, req: &Request, kind: u32) -> Result<(), Failed> {
        self.seq = self.seq.wrapping_add(1);
        let mut frame = [0u8; MAX_REQUEST_FRAME_SIZE];
        let bytes = protocol::encode_frame(self.seq, req, &mut frame)
            .map_err(|_| Failed(fail::ENCODE, kind))?;
        let now = self.now_us();
        let chunks = bytes.len().div_ceil(RX_CHUNK);
        for (i, chunk) in bytes.chunks(RX_CHUNK).enumerate() {
            let last = u32::from(i + 1 == chunks);
            measured_receive(self.core, now, chunk, kind | last << 8);
        }
        Ok(())
    }

    fn release(&mut self, hz: f32) -> Result<(), Failed> {
        let req = Request::Release {
            on: hz > 0.0,
            target_hz: hz,
            session: 0,
        };
        self.request(&req, request_kind::RELEASE)?;
        self.keep_alive = hz > 0.0;
        self.last_heartbeat_us = self.now_us();
        Ok(())
    }

    /// Runs `ms` control periods.
    fn run_ms(&mut self, ms: u32) -> Result<(), Failed> {
        for _ in 0..ms {
            self.period()?;
        }
        Ok(())
    }

    /// Runs until the supervisor is in `state`, at most `limit_ms`.
    fn until_state(&mut self, state: SupervisorState, limit_ms: u32) -> Result<(), Failed> {
        for _ in 0..limit_ms {
            if self.status().state == state {
                return Ok(());
            }
            self.period()?;
        }
        Err(match state {
            SupervisorState::Locked => Failed(fail::NOT_LOCKED, 0),
            _ => Failed(fail::NOT_VIBRATING, self.status().target_hz as u32),
        })
    }

    /// One control period: ten plant ticks, the control step, the host link.
    fn period(&mut self) -> Result<(), Failed> {
        let dt = 1.0 / PLANT_HZ as f64;
        for _ in 0..PLANT_HZ / 1000 {
            self.plant.step(dt, self.drive);
            if self.adc_len < self.adc.len() {
                self.adc[self.adc_len] = self.plant.current_adc();
                self.adc_len += 1;
            }
            self.tick += 1;
        }
        let now = self.now_us();
        let before = self.status();
        let phase = if !before.latched_faults.is_empty() {
            phase::FAULT
        } else {
            match before.state {
                SupervisorState::Locked => phase::LOCKED,
                SupervisorState::SpinUp => phase::SPIN_UP,
                SupervisorState::Vibrating if before.capture_recording => phase::CAPTURE,
                SupervisorState::Vibrating if before.stream_rate_hz > 0 => phase::STREAM,
                SupervisorState::Vibrating => phase::VIBRATING,
                SupervisorState::Stopping => phase::STOPPING,
                _ => phase::FAULT,
            }
        };
        let tag = phase | ((before.target_hz + 0.5) as u32) << 8;
        let inputs = Inputs {
            now_us: now,
            current_adc: &self.adc[..self.adc_len],
            encoder_count: self.plant.encoder_count(),
            release_button: false,
        };
        let out = measured_step(self.core, &inputs, tag);
        self.adc_len = 0;
        let after = self.status();
        // The count restarts at zero when vibration starts again.
        let boundary = u32::from(after.revolutions > before.revolutions);
        bench_marker(code::NOTE, boundary | (after.state as u32) << 8);
        if !after.latched_faults.is_empty() {
            return Err(Failed(fail::FAULT, after.latched_faults.bits()));
        }
        self.drive = Drive {
            duty: f64::from(out.duty),
            enabled: out.enable,
        };
        if out.persist.is_some() {
            // The flash write itself is the binary's (outside the lock); its report is not.
            measured_persist(self.core, true);
            self.persisted += 1;
        }
        self.host_tx(now);
        if self.keep_alive && now - self.last_heartbeat_us >= HEARTBEAT_US {
            self.last_heartbeat_us = now;
            self.request(&Request::Heartbeat { session: 0 }, request_kind::HEARTBEAT)?;
        }
        Ok(())
    }

    /// The `host_tx` task: `transmit` into 256 bytes whenever the UART is free.
    fn host_tx(&mut self, now: u64) {
        let mut t = self.tx_free_at_us;
        while t <= now {
            let n = measured_transmit(self.core, &mut self.tx_buf);
            let status = self.core.status();
            let uploading = u32::from(status.capture_uploading);
            let streaming = u32::from(status.stream_rate_hz > 0);
            bench_marker(code::NOTE, n as u32 | uploading << 16 | streaming << 17);
            if n == 0 {
                t = now + 1;
                break;
            }
            t = t.max(now.saturating_sub(1000)) + n as u64 * 10 * 1_000_000 / BAUD;
        }
        self.tx_free_at_us = t;
    }
}

/// The session (see the crate documentation).
fn session(b: &mut Bench) -> Result<(), Failed> {
    b.request(
        &Request::Hello {
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
        },
        request_kind::HELLO,
    )?;
    b.request(
        &Request::StartTelemetry { rate_hz: 1000 },
        request_kind::START_TELEMETRY,
    )?;
    b.run_ms(500)?;

    b.release(10.0)?;
    b.until_state(SupervisorState::Vibrating, 3000)?;
    b.run_ms(1500)?;
    b.request(
        &Request::StartCapture {
            sample_rate_hz: 10_000,
            samples: firmware_core::CAPTURE_CAPACITY as u32,
        },
        request_kind::START_CAPTURE,
    )?;
    b.run_ms(10)?;
    let mut left = 5000;
    while {
        let s = b.status();
        s.capture_recording || s.capture_uploading
    } {
        if left == 0 {
            return Err(Failed(fail::CAPTURE, 0));
        }
        left -= 1;
        b.period()?;
    }

    for hz in [5.0, 15.0] {
        b.release(hz)?;
        b.run_ms(10)?;
        b.until_state(SupervisorState::Vibrating, 3000)?;
        b.run_ms(1500)?;
    }

    // The continuous stream at 10 kHz (every ADC sample), telemetry at 100 Hz beside it
    // (both at 1 kHz do not fit the link), vibrating at 10 Hz.
    b.request(
        &Request::StartTelemetry { rate_hz: 100 },
        request_kind::START_TELEMETRY,
    )?;
    b.request(
        &Request::StartStream { rate_hz: 10_000 },
        request_kind::START_STREAM,
    )?;
    b.release(10.0)?;
    b.run_ms(10)?;
    b.until_state(SupervisorState::Vibrating, 3000)?;
    b.run_ms(1500)?;
    if b.status().stream_samples_skipped > 0 {
        return Err(Failed(fail::STREAM, b.status().stream_samples_skipped));
    }
    b.request(&Request::StopStream, request_kind::STOP_STREAM)?;
    b.request(
        &Request::StartTelemetry { rate_hz: 1000 },
        request_kind::START_TELEMETRY,
    )?;

    b.release(0.0)?;
    b.until_state(SupervisorState::Locked, 3000)?;
    b.run_ms(100)?;

    let mut calibration = RigParameters::paper();
    calibration.z = GEAR.map(|z| z as u16);
    b.request(
        &Request::SetParameters(calibration),
        request_kind::SET_CALIBRATION,
    )?;
    b.run_ms(10)?;
    if b.persisted != 1 {
        return Err(Failed(fail::PERSIST, b.persisted));
    }
    // A profile-shifted design with unequal tooth sums (`rig design search`'s): its two
    // working pressure angles are solved under the lock, on receipt and on activation.
    let shifted = RigParameters {
        z: [54, 50, 50, 55],
        profile_shift: [-0.1, -0.1, -0.4, -0.265_678_2],
        ..calibration
    };
    b.request(
        &Request::SetParameters(shifted),
        request_kind::SET_CALIBRATION,
    )?;
    b.run_ms(10)?;
    if b.persisted != 2 {
        return Err(Failed(fail::PERSIST, b.persisted));
    }
    Ok(())
}

#[entry]
fn main() -> ! {
    measured_empty();
    let mut parameters = RigParameters::paper();
    parameters.z = GEAR.map(|z| z as u16);
    let boot = BootInfo {
        reset_cause: ResetCause::PowerOn,
        firmware_build: BootInfo::UNKNOWN_BUILD,
        parameters,
        parameters_status: ParametersStatus::Valid,
    };
    // As the firmware does: the core (~43 KiB) straight into a static slot.
    let slot = cortex_m::singleton!(: MaybeUninit<Core> = MaybeUninit::uninit());
    let result = match (slot, GearSet::paper(GEAR)) {
        (Some(slot), Ok(gear)) => {
            let mut bench = Bench {
                core: slot.write(Core::new(CoreConfig::default(), boot)),
                plant: Plant::new(PlantParams::paper(gear, Load::Torque(LOAD_NM)), 1),
                tick: 0,
                adc: [0; 16],
                adc_len: 0,
                drive: Drive::default(),
                seq: 0,
                keep_alive: false,
                last_heartbeat_us: 0,
                tx_free_at_us: 0,
                tx_buf: [0; 256],
                persisted: 0,
            };
            session(&mut bench)
        }
        _ => Err(Failed(fail::PANIC, 0)),
    };
    match result {
        Ok(()) => bench_marker(code::DONE, 0),
        Err(Failed(reason, detail)) => bench_marker(code::FAIL, reason | detail << 8),
    }
    loop {
        cortex_m::asm::nop();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    bench_marker(code::FAIL, fail::PANIC);
    loop {
        cortex_m::asm::nop();
    }
}
