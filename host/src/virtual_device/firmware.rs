//! The firmware image in the loop (`rig sim serve --firmware`, `--sim --firmware`): the
//! release ELF running on the emulated STM32G474 ([`emu::Board`]) with the virtual rig's
//! plant, on a pseudo-terminal like the virtual device, through the same device loop
//! ([`super::Served`]): the bytes a client sends cross the emulated USART at its baud, and
//! every answer is the image's own.
//!
//! The emulation runs at whatever speed this machine allows (about 0.1-0.5x real time
//! here): device time then runs slower than the wall clock, the loop says by how much
//! ([`FirmwareDevice::behind_s`]), and a client's heartbeats, paced by the wall clock for a
//! device that reports real time (the image does), only come more often in device time than
//! on a board: never too rarely.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;

use model::plant::Plant;

use super::{Pacing, Served, Shared, WallNoise, lock, spawn};
use crate::RigError;

/// The board and the first error it ran into (the loop keeps serving what it has).
pub struct ImageRig {
    board: emu::Board,
    /// Why the emulation stopped, if it did.
    pub error: Option<String>,
    /// A rig file's user effects at work in the plant ([`sim::user_effects`]).
    user: Option<sim::user_effects::UserDrive>,
}

/// Device time between two updates of the user effects' current on the emulated board, s
/// (the firmware core's virtual rig updates it at every control step, 1 ms).
const USER_UPDATE_S: f64 = 1e-3;

impl Served for ImageRig {
    fn to_device(&mut self, bytes: &[u8]) {
        self.board.to_device(bytes);
    }
    fn advance(&mut self, seconds: f64) {
        let mut left = seconds;
        while self.error.is_none() && left > 0.0 {
            let dt = match self.user {
                Some(_) => left.min(USER_UPDATE_S),
                None => left,
            };
            if let Err(e) = self.board.advance(dt) {
                self.error = Some(e.to_string());
            }
            if let Some(user) = self.user.as_mut() {
                let t = self.board.time();
                user.update(self.board.plant_mut(), dt, t);
            }
            left -= dt;
        }
    }
    fn device_output(&mut self, out: &mut Vec<u8>) {
        self.board.from_device(out);
    }
    fn time(&self) -> f64 {
        self.board.time()
    }
    fn driving(&self) -> bool {
        // The image's own state is not visible from outside; its bridge enable is.
        self.board.bridge().enable
    }
}

/// Device time the board runs before its port is announced, s (the image's boot takes
/// about 20 ms).
const BOOT_S: f64 = 0.1;

/// Device time the pace is measured over before serving, s.
const PACE_TRIAL_S: f64 = 0.3;

/// The pace for a board that runs at `measured` device seconds per wall second when
/// `asked` was asked: four fifths of what was measured (room for a busier moment), in steps
/// of 0.05, at least 0.05, never above `asked`.
pub fn pace_for(asked: f64, measured: f64) -> f64 {
    let sustainable = ((0.8 * measured) / 0.05).floor() * 0.05;
    asked.min(sustainable.max(0.05))
}

/// The release image `cargo xtask firmware` builds, in this source tree's `target`: the
/// default (braking) image's kept copy `firmware-brake`, else `firmware` (the last built).
pub fn default_firmware_elf() -> PathBuf {
    let release = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("..")
                .join("target")
        })
        .join("thumbv7em-none-eabihf")
        .join("release");
    let brake = release.join("firmware-brake");
    if brake.exists() {
        brake
    } else {
        release.join("firmware")
    }
}

/// The default image and the emulator, ready to serve: the image's path, or what is
/// missing with what to do.
pub fn emulated_board_ready() -> Result<PathBuf, String> {
    let elf = default_firmware_elf();
    if !elf.exists() {
        return Err(format!(
            "no firmware image at {}: build it with `cargo xtask firmware`",
            elf.display()
        ));
    }
    emu::emulator().map_err(|e| e.to_string())?;
    Ok(elf)
}

/// The emulated board with the firmware image, on a pseudo-terminal, until dropped.
pub struct FirmwareDevice {
    port: String,
    elf: PathBuf,
    pace: f64,
    measured: f64,
    shared: Arc<Shared<ImageRig>>,
    thread: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for FirmwareDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FirmwareDevice")
            .field("port", &self.port)
            .field("elf", &self.elf)
            .finish()
    }
}

impl FirmwareDevice {
    /// Loads `elf` (None: [`default_firmware_elf`]) onto the emulated board around
    /// `config`'s plant (with its user effects) and serves it at `speed` times the wall
    /// clock at most, with `noise` on the line.
    pub fn start(
        elf: Option<&Path>,
        config: &sim::SimConfig,
        seed: u64,
        speed: f64,
        noise: Option<WallNoise>,
    ) -> Result<Self, RigError> {
        let elf = elf.map_or_else(default_firmware_elf, Path::to_path_buf);
        if !elf.exists() {
            return Err(RigError::BadValue {
                what: format!("--firmware {}", elf.display()),
                why: "no such file: build the release image with `cargo xtask firmware` (or give the ELF to run)".into(),
            });
        }
        let plant = config.plant;
        let user = config
            .user_effects
            .clone()
            .map(sim::user_effects::UserDrive::new);
        let config = |time_scale| emu::BoardConfig {
            elf: elf.clone(),
            plant,
            seed,
            time_scale,
        };
        let fail = |e: emu::EmuError| RigError::VirtualDevice(e.to_string());
        // The pace: what this machine sustains (measured over the first 0.3 s of device
        // time, with a fifth spare), never more than asked; the image reports it in `Info`.
        let mut trial = emu::Board::new(config(None)).map_err(fail)?;
        let started = std::time::Instant::now();
        trial.advance(PACE_TRIAL_S).map_err(fail)?;
        let measured = PACE_TRIAL_S / started.elapsed().as_secs_f64().max(1e-6);
        drop(trial);
        let pace = pace_for(speed, measured);
        let mut board = emu::Board::new(config(Some(pace as f32))).map_err(fail)?;
        // Powered up before anyone opens the port, as a board on the bench: the image has
        // booted and listens on its UART by the time the port is announced.
        board.advance(BOOT_S).map_err(fail)?;
        let rig = ImageRig {
            board,
            error: None,
            user,
        };
        let (port, shared, thread) = spawn(rig, pace, noise, Pacing::BoardTime)?;
        Ok(Self {
            port,
            elf,
            pace,
            measured,
            shared,
            thread: Some(thread),
        })
    }

    /// The pseudo-terminal's port name.
    pub fn port_name(&self) -> &str {
        &self.port
    }

    /// Device seconds per wall-clock second the board is served at (and reports).
    pub fn pace(&self) -> f64 {
        self.pace
    }

    /// The emulation's speed measured at start, device seconds per wall second.
    pub fn measured_speed(&self) -> f64 {
        self.measured
    }

    /// The image running.
    pub fn elf(&self) -> &Path {
        &self.elf
    }

    /// Device time since power-on, s.
    pub fn time(&self) -> f64 {
        lock(&self.shared.rig).board.time()
    }

    /// Device seconds the board fell behind the wall clock (times the speed asked).
    pub fn behind_s(&self) -> f64 {
        *lock(&self.shared.behind_s)
    }

    /// Why the emulation stopped, if it did.
    pub fn error(&self) -> Option<String> {
        lock(&self.shared.rig).error.clone()
    }

    /// Runs `f` on the emulated board (the emulation pauses meanwhile).
    pub fn with_board<R>(&self, f: impl FnOnce(&mut emu::Board) -> R) -> R {
        f(&mut lock(&self.shared.rig).board)
    }

    /// Runs `f` on the plant, as an operator's hand at the rig.
    pub fn with_plant<R>(&self, f: impl FnOnce(&mut Plant) -> R) -> R {
        self.with_board(|b| f(b.plant_mut()))
    }
}

impl Drop for FirmwareDevice {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::client::{Client, ClientOptions, open_serial};
    use crate::virtual_device::VirtualDevice;

    /// The release image and the emulator, or None (skipped with a message) when this
    /// machine has neither; `cargo xtask test` sets RIG_REQUIRE_EMULATOR, which makes their
    /// absence a failure.
    fn image() -> Option<PathBuf> {
        match emulated_board_ready() {
            Ok(elf) => Some(elf),
            Err(why) if std::env::var_os("RIG_REQUIRE_EMULATOR").is_some() => panic!("{why}"),
            Err(why) => {
                eprintln!("skipped: {why}");
                None
            }
        }
    }

    /// Releases at 10 Hz with telemetry at 1 kHz; returns (mean cam speed, mean tau_cam)
    /// over `hold_s` of device time once the speed settled, after checking that the samples
    /// come 1 ms apart in device time with no sequence gap.
    fn release_10_hz(port: &str, hold_s: f64) -> (f64, f64) {
        let io = open_serial(port, protocol::DEFAULT_BAUD_RATE).unwrap();
        let (mut client, _) = Client::connect(io, ClientOptions::new(port)).unwrap();
        client.start_telemetry(1000).unwrap();
        client.release(true, 10.0).unwrap();
        let target = std::f64::consts::TAU * 10.0;
        let mut settled_at = None;
        let mut last: Option<protocol::TelemetrySample> = None;
        let (mut speed, mut tau, mut n) = (0.0, 0.0, 0.0);
        loop {
            let s = client
                .next_telemetry(Duration::from_secs(10))
                .unwrap()
                .expect("telemetry keeps coming");
            if let Some(prev) = &last {
                assert_eq!(s.seq, prev.seq + 1, "a telemetry sample went missing");
                // 1 kHz in device time; each step reads the clock after its interrupt's
                // latency, which varies by a few microseconds (on silicon too).
                let dt = s.device_time_us - prev.device_time_us;
                assert!((995..=1005).contains(&dt), "samples {dt} us apart");
            }
            let t = s.device_time_us as f64 * 1e-6;
            assert!(
                s.faults.is_empty(),
                "faults during the release: {}",
                s.faults
            );
            if settled_at.is_none() && (f64::from(s.cam_speed_rad_s) - target).abs() < 0.02 * target
            {
                // Settled: one more second for the estimate's filters, then the hold.
                settled_at = Some(t + 1.0);
            }
            if let Some(from) = settled_at
                && t >= from
            {
                speed += f64::from(s.cam_speed_rad_s);
                tau += f64::from(s.tau_cam_nm);
                n += 1.0;
                if t >= from + hold_s {
                    break;
                }
            }
            assert!(
                t < 30.0,
                "10 Hz not reached and held by {t} s of device time"
            );
            last = Some(s);
        }
        client.release(false, 0.0).unwrap();
        (speed / n, tau / n)
    }

    #[test]
    fn the_release_image_holds_10_hz_with_telemetry_whole_and_estimates_as_the_virtual_rig() {
        let Some(elf) = image() else { return };
        let config = VirtualDevice::paper_config(&sim::Preset::paper());
        let dev = FirmwareDevice::start(Some(&elf), &config, 1, 1.0, None).unwrap();
        let (image_speed, image_tau) = release_10_hz(dev.port_name(), 2.0);
        assert!(dev.error().is_none(), "{:?}", dev.error());
        let target = std::f64::consts::TAU * 10.0;
        assert!(
            (image_speed - target).abs() < 0.01 * target,
            "held {image_speed} rad/s"
        );
        // The same plant and seed behind the firmware core in process.
        let virt = VirtualDevice::start(config, 1.0).unwrap();
        let (_, core_tau) = release_10_hz(virt.port_name(), 2.0);
        eprintln!(
            "held {image_speed:.3} rad/s; tau_cam: image {:.3} N mm, virtual rig {:.3} N mm",
            image_tau * 1e3,
            core_tau * 1e3
        );
        assert!(
            (image_tau - core_tau).abs() <= 0.5e-3,
            "tau_cam: image {:.3} N mm, virtual rig {:.3} N mm",
            image_tau * 1e3,
            core_tau * 1e3
        );
    }

    fn serve(elf: &Path) -> FirmwareDevice {
        let config = VirtualDevice::paper_config(&sim::Preset::paper());
        FirmwareDevice::start(Some(elf), &config, 1, 1.0, None).unwrap()
    }

    fn client(
        dev: &FirmwareDevice,
    ) -> (Client<crate::client::SerialTransport>, protocol::DeviceInfo) {
        let io = open_serial(dev.port_name(), protocol::DEFAULT_BAUD_RATE).unwrap();
        // These tests are not of the reply time: the emulated board keeps its pace only
        // while this machine has the cores it was measured with, and on a loaded one falls
        // behind it (its clock runs slow), so a reply that is coming never times out here.
        let mut opts = ClientOptions::new(dev.port_name());
        opts.reply_timeout = Duration::from_secs(10);
        Client::connect(io, opts).unwrap()
    }

    /// Telemetry until `done` holds for a sample, within `limit_s` of device time.
    fn until(
        client: &mut Client<crate::client::SerialTransport>,
        limit_s: f64,
        what: &str,
        mut done: impl FnMut(&protocol::TelemetrySample) -> bool,
    ) -> protocol::TelemetrySample {
        let mut first = None;
        loop {
            let s = client
                .next_telemetry(Duration::from_secs(10))
                .unwrap()
                .unwrap_or_else(|| panic!("telemetry stopped before {what}"));
            let t = s.device_time_us as f64 * 1e-6;
            let t0 = *first.get_or_insert(t);
            if done(&s) {
                return s;
            }
            assert!(
                t - t0 < limit_s,
                "no {what} within {limit_s} s of device time"
            );
        }
    }

    /// A client with telemetry at 1 kHz and a 10 Hz release past its spin-up (above 20 rad/s).
    fn spun_up(dev: &FirmwareDevice) -> Client<crate::client::SerialTransport> {
        let (mut c, _) = client(dev);
        c.start_telemetry(1000).unwrap();
        c.release(true, 10.0).unwrap();
        until(&mut c, 5.0, "spin-up", |s| s.cam_speed_rad_s > 20.0);
        c
    }

    /// Runs the board until it has reset, within `limit_s` of device time.
    fn until_reset(dev: &FirmwareDevice, limit_s: f64) -> (u64, &'static str) {
        let from = dev.time();
        loop {
            if let Some(r) = dev.with_board(|b| b.machine().resets.first().copied()) {
                return r;
            }
            assert!(
                dev.time() - from < limit_s,
                "no reset within {limit_s} s of device time"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    #[test]
    fn a_jammed_cam_trips_comp3_and_the_break_clears_the_main_output_in_hardware() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        let mut c = spun_up(&dev);
        // The arm on the vibrator shaft meets a stop: the cam cannot turn.
        dev.with_plant(|p| p.set_cam(model::plant::CamSetup::Blocked));
        let s = until(&mut c, 2.0, "a latched fault", |s| !s.faults.is_empty());
        let breaks = dev.with_board(|b| b.machine().bus.tim1.hw_breaks);
        assert!(breaks >= 1, "no hardware break; faults {}", s.faults);
        assert!(
            s.faults.contains(protocol::FaultFlags::HW_OVERCURRENT),
            "the core latched {} without the trip",
            s.faults
        );
        // The break interrupt and the core then hold the bridge off.
        until(&mut c, 1.0, "the bridge off", |_| true);
        let bridge = dev.with_board(|b| b.bridge());
        assert!(!bridge.enable && bridge.duty.is_none(), "{bridge:?}");
        let peak = dev.with_plant(|p| p.state().current.abs());
        assert!(peak < 1.0, "current {peak} A after the trip");
    }

    #[test]
    fn a_stopped_time_driver_hangs_the_tasks_and_the_watchdog_resets_into_a_safe_boot() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        // TIM2 stops (the time driver's counter): every timed task hangs; the control loop,
        // paced by the ADC, goes on, but the watchdog's feeder never runs again.
        dev.with_board(|b| b.machine_mut().bus.tim2.cr1 &= !1);
        let (at, cause) = until_reset(&dev, 2.0);
        assert!(cause.contains("IWDG"), "{cause}");
        // The IWDG's ~250 ms (LSI at 32 kHz) after its last feed.
        let t = at as f64 / 170e6;
        assert!(t < 0.1 + 0.1 + 0.3, "reset at {t} s");
        let (_, info) = client(&dev);
        assert_eq!(info.reset_cause, protocol::ResetCause::Watchdog);
        assert!(!dev.with_board(|b| b.bridge().enable));
    }

    #[test]
    fn a_stack_overflow_into_the_guard_locks_up_breaks_tim1_and_ends_in_a_watchdog_reset() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        let c = spun_up(&dev);
        // The stack pointer right above the MPU guard, as a call chain too deep would leave it.
        let guard = dev.with_board(|b| b.machine_mut().inject_stack_overflow(8));
        assert!(guard.is_some(), "the image set no stack guard");
        // Locked up, nothing refreshes the window watchdog: it resets the chip within its
        // ~2 ms deadline, before the IWDG would.
        let (_, cause) = until_reset(&dev, 2.0);
        assert!(cause.contains("WWDG"), "{cause}");
        let faults = dev.with_board(|b| b.machine().faults.clone());
        let lockup = faults
            .iter()
            .find(|(_, f)| f.contains("lockup"))
            .expect("a lockup");
        assert!(lockup.1.contains("stack guard"), "{faults:?}");
        assert!(
            lockup.1.contains("CLL: true"),
            "TIM1 kept switching: {faults:?}"
        );
        drop(c);
        let (_, info) = client(&dev);
        assert_eq!(info.reset_cause, protocol::ResetCause::Watchdog);
    }

    #[test]
    fn ten_seconds_of_closed_loop_keep_the_stack_2_kib_above_its_guard() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        let (mut c, _) = client(&dev);
        c.start_telemetry(1000).unwrap();
        c.release(true, 10.0).unwrap();
        let t0 = until(&mut c, 5.0, "telemetry", |_| true).device_time_us;
        until(&mut c, 11.0, "10 s of release", |s| {
            s.device_time_us - t0 >= 10_000_000
        });
        c.release(false, 0.0).unwrap();
        let (lowest, guard) =
            dev.with_board(|b| (b.machine().lowest_sp(), b.machine().bus.scs.guard()));
        let (base, size) = guard.expect("a stack guard");
        let margin = i64::from(lowest) - i64::from(base + size);
        eprintln!(
            "lowest stack pointer {lowest:#x}, guard top {:#x}: margin {margin} B",
            base + size
        );
        assert!(margin >= 2048, "margin {margin} B");
    }

    #[test]
    fn the_fast_link_runs_the_emulated_usart_at_what_its_register_gives() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        let (mut c, info) = client(&dev);
        assert_eq!(info.max_baud, protocol::FAST_BAUD_RATE);
        c.agree_baud(&info, protocol::FAST_BAUD_RATE).unwrap();
        c.faults().unwrap();
        // BRR 0x53 with OVER8: USARTDIV 86, 2 x 170 MHz / 86.
        let baud = dev.with_board(|b| b.machine().bus.usart.baud());
        assert_eq!(baud, 3_953_488);
    }

    #[test]
    fn a_calibration_written_is_programmed_into_the_emulated_flash_and_survives_a_reset() {
        let Some(elf) = image() else { return };
        let dev = serve(&elf);
        let (mut c, info) = client(&dev);
        assert_eq!(info.parameters_status, protocol::ParametersStatus::Defaults);
        let mut params = protocol::RigParameters::paper();
        params.mu_s = 0.27;
        let t0 = dev.time();
        let r = c.set_calibration(&params);
        let (erases, programs, faults) = dev.with_board(|b| {
            let f = &b.machine().bus.flash;
            (f.erases, f.programs, b.machine().faults.clone())
        });
        eprintln!(
            "erases {erases}, programs {programs}, {:.3} s, faults {faults:?}",
            dev.time() - t0
        );
        r.unwrap();
        assert!(
            erases >= 1 && programs >= 1,
            "{erases} erases, {programs} programs"
        );
        // A reset (SYSRESETREQ from outside: the probe's reset) boots with it.
        dev.with_board(|b| b.machine_mut().bus.scs.reset_requested = true);
        until_reset(&dev, 1.0);
        drop(c);
        std::thread::sleep(Duration::from_millis(200));
        let (mut c, info) = client(&dev);
        assert_eq!(info.parameters_status, protocol::ParametersStatus::Valid);
        assert_eq!(c.calibration().unwrap().mu_s, 0.27);
    }
}
