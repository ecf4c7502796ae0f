//! The virtual device behind `--sim`: the firmware core and the simulated plant
//! ([`SimRig`]) on a pseudo-terminal, run in real time (or `speed` times faster) by a
//! thread of this process. The client opens the pseudo-terminal's port by name, exactly as
//! it opens a board's serial port, so every verb goes through the real serial path.
//!
//! Because the device lives in this process, procedures that need a hand at the rig (the
//! calibration's force gauge, uncoupling the cam) reach into the plant through
//! [`VirtualDevice::with_plant`].
//!
//! Served (`rig sim serve`, [`Pacing::BoardTime`]) the device keeps the board's time:
//! virtual time runs at `speed` times the wall clock and never waits for a host, so a host
//! whose heartbeats stop sees vibration stop after the comms timeout of device time (0.5 s
//! of wall time at speed 1), as on the board. The device says its speed in `Info`
//! (`DeviceInfo::time_scale`), and a client scales its heartbeats by it.
//!
//! In process (`--sim`, [`Pacing::HostWall`]) the device belongs to this process's own
//! client, whose heartbeats are compressed by `speed`: there, while a release is live and
//! the host has been quiet for more than [`HOST_QUIET_S`] of virtual time, the host's
//! silence in virtual time never runs ahead of its silence in wall time. So a stalled host
//! gets the same wall-clock slack as on a board, never more: one that stops for good
//! loses its release 0.5 s of wall time after its last byte, at any speed. A host that closed the port (quit or died, as when a served rig's
//! client is killed) trips the timeout at once, so the next client finds the fault. When
//! the machine cannot keep up (one turn of the loop covers at most 20 ms of wall time)
//! virtual time falls behind: [`VirtualDevice::behind_s`] says by how much, and `rig sim
//! serve` warns.
//!
//! Either way the device's output leaves at its UART's byte rate in device time
//! ([`SimRig::set_link_baud`] at [`protocol::DEFAULT_BAUD_RATE`]: 92,160 B/s): a virtual
//! rig never delivers faster than the board could, and a stream that does not fit beside
//! the telemetry skips samples in the firmware core, numbered, as the board does.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use model::plant::Plant;

use crate::RigError;
use sim::{ADC_HZ, SimConfig, SimRig};

mod firmware;
mod pty;

pub use firmware::{FirmwareDevice, default_firmware_elf, emulated_board_ready};

pub use pty::PtyMaster;

/// Longest wall time one loop turn may cover, s: if this process is starved of CPU the
/// simulation slows down (and says so) instead of jumping past the host's bytes.
const MAX_TURN_WALL: f64 = 0.02;

/// Longest device time one loop turn may step, s: half the slack between a heartbeat and
/// the comms timeout (0.5 - 0.15 s), so a step never jumps past a host's next heartbeat.
/// A turn that would step more slows the simulation down (counted in `behind_s`).
const MAX_TURN_DEVICE_S: f64 =
    (protocol::COMMS_TIMEOUT_MS - protocol::HEARTBEAT_INTERVAL_MS) as f64 / 2000.0;

/// Fastest simulation speed a virtual device takes (device seconds per wall second): a
/// host's heartbeats are `HEARTBEAT_INTERVAL_MS / speed` apart in wall time, and a loaded
/// machine delays a process by a few milliseconds; at 100x a 3.5 ms delay already uses the
/// whole slack before the comms timeout, so faster speeds would fail with `COMMS_TIMEOUT`
/// (at 500x every sweep did) and are refused.
pub const MAX_SPEED: f64 = 100.0;

/// Device output held while the host is not reading, bytes (a UART's queue would also
/// overflow): beyond it new output is dropped, as frames lost on the line. With no client
/// on the port nothing is held: a board's UART sends its bytes into the void, so the next
/// client starts with fresh frames, not old ones.
const MAX_PENDING: usize = 1 << 20;

/// Virtual time without a byte from the host after which an in-process device with a
/// live release waits for its host ([`Pacing::HostWall`]), s (a heartbeat is due every
/// 0.15 s).
pub const HOST_QUIET_S: f64 = 0.2;

/// How the device's virtual time relates to its host.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pacing {
    /// The board's time: `speed` times the wall clock, whatever the host does (served).
    BoardTime,
    /// As `BoardTime`, but a live release waits for a quiet host until the comms timeout
    /// has passed in wall time since its last byte (in process: the host's heartbeats are
    /// compressed by `speed`, its stalls are not).
    HostWall,
}

/// How long one turn waits for host bytes.
const POLL: Duration = Duration::from_millis(1);

/// Random bytes mixed into the line, both ways, in wall-clock time (`rig sim serve
/// --line-noise-bytes-per-s`), as a noisy cable would.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallNoise {
    /// Noise bytes per wall-clock second, in each direction.
    pub bytes_per_s: f64,
    /// Seed of the bytes and their timing.
    pub seed: u64,
}

struct Shared<D> {
    rig: Mutex<D>,
    noise_bytes: Mutex<u64>,
    stop: AtomicBool,
    dropped_bytes: Mutex<u64>,
    /// Virtual seconds lost because the loop could not keep up.
    behind_s: Mutex<f64>,
}

/// A simulated rig on a pseudo-terminal, running until dropped.
pub struct VirtualDevice {
    port: String,
    speed: f64,
    shared: Arc<Shared<SimRig>>,
    thread: Option<JoinHandle<()>>,
}

/// What the device loop drives: the firmware core's virtual rig ([`SimRig`]) or the
/// firmware image on the emulated board ([`emu::Board`]).
pub trait Served: Send + 'static {
    /// Host bytes arrive.
    fn to_device(&mut self, bytes: &[u8]);
    /// Runs for `seconds` of device time.
    fn advance(&mut self, seconds: f64);
    /// The device's output since the last call, appended to `out`.
    fn device_output(&mut self, out: &mut Vec<u8>);
    /// Device time, s.
    fn time(&self) -> f64;
    /// Whether the device drives the bridge for a host (a release or open-loop volts).
    fn driving(&self) -> bool;
    /// The port was closed: a continuous stream a core knows of stops (a board's image
    /// only learns it from the comms timeout).
    fn link_closed(&mut self) {}
}

impl Served for SimRig {
    fn to_device(&mut self, bytes: &[u8]) {
        SimRig::to_device(self, bytes);
    }
    fn advance(&mut self, seconds: f64) {
        SimRig::advance(self, seconds);
    }
    fn device_output(&mut self, out: &mut Vec<u8>) {
        SimRig::from_device(self, out);
    }
    fn time(&self) -> f64 {
        SimRig::time(self)
    }
    fn driving(&self) -> bool {
        let status = self.core().status();
        status.host_release || status.open_loop_volts.is_some()
    }
    fn link_closed(&mut self) {
        if self.core().status().stream_rate_hz > 0 {
            SimRig::link_closed(self);
        }
    }
}

impl std::fmt::Debug for VirtualDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VirtualDevice")
            .field("port", &self.port)
            .field("speed", &self.speed)
            .finish()
    }
}

impl VirtualDevice {
    /// Boots a simulated rig from `config` on a new pseudo-terminal for this process's own
    /// client, running `speed` times faster than real time (1 = real time), paced by
    /// [`Pacing::HostWall`].
    pub fn start(config: SimConfig, speed: f64) -> Result<Self, RigError> {
        Self::start_paced(config, speed, None, Pacing::HostWall)
    }

    /// A rig served to any client (`rig sim serve`): [`Pacing::BoardTime`], with `noise`
    /// random bytes mixed into the line both ways.
    pub fn start_with_noise(
        config: SimConfig,
        speed: f64,
        noise: Option<WallNoise>,
    ) -> Result<Self, RigError> {
        Self::start_paced(config, speed, noise, Pacing::BoardTime)
    }

    /// Boots a simulated rig with `pacing`.
    pub fn start_paced(
        config: SimConfig,
        speed: f64,
        noise: Option<WallNoise>,
        pacing: Pacing,
    ) -> Result<Self, RigError> {
        if !(speed.is_finite() && speed > 0.0) {
            return Err(RigError::BadValue {
                what: format!("--speed {speed}"),
                why: "must be a positive number (1 = real time)".into(),
            });
        }
        // The device says its time scale in `Info`, so any client scales its heartbeats.
        let mut config = config;
        config.core.time_scale = speed as f32;
        let mut rig = SimRig::new(config);
        rig.set_link_baud(Some(protocol::DEFAULT_BAUD_RATE));
        let (port, shared, thread) = spawn(rig, speed, noise, pacing)?;
        Ok(Self {
            port,
            speed,
            shared,
            thread: Some(thread),
        })
    }

    /// Starts the paper's (49, 50) rig with the `paper` preset ([`sim::Preset::paper`]: it
    /// behaves as the paper's rig measured); it reports itself as board `virtual`.
    pub fn paper(speed: f64) -> Result<Self, RigError> {
        Self::start(Self::paper_config(&sim::Preset::paper()), speed)
    }

    /// The paper's (49, 50) rig with `preset`, reporting itself as board `virtual`; its
    /// load rests on the floor after [`model::hardware::bench::OUTPUT_TRAVEL_RAD`] (a hung
    /// load that keeps falling, mu_d Lambda < 1, lands as on a bench and stops).
    pub fn paper_config(preset: &sim::Preset) -> SimConfig {
        let mut config = SimConfig::paper()
            .virtual_board()
            .with_floor(model::hardware::bench::LOAD_DROP_M);
        config.core.output_encoder = Some(firmware_core::OutputEncoderConfig::default());
        preset.apply(&mut config.plant);
        config
    }

    /// The virtual rig a rig file describes (gear, friction, the calibration stored in its
    /// flash, the floor `[load] drop_m` below the pulley), reporting itself as board `virtual` with an output encoder fitted (as
    /// [`VirtualDevice::paper_config`]): its plant runs the file's fitted
    /// `[model]` (every effect, or an error naming the one it cannot run), or `preset` when
    /// the file has none. `rig sim serve --model` and the device option `--sim --model`
    /// both build their plant here.
    pub fn rig_file_config(
        rig: &rigfile::RigFile,
        preset: &sim::Preset,
    ) -> Result<SimConfig, RigError> {
        let mut config = SimConfig::from_rig_file(rig)?
            .virtual_board()
            .with_floor(rig.load.drop_m);
        config.core.output_encoder = Some(firmware_core::OutputEncoderConfig::default());
        if rig.model.is_none() {
            preset.apply(&mut config.plant);
        } else {
            sim::preset::apply_model(rig, &mut config)?;
        }
        Ok(config)
    }

    /// [`VirtualDevice::rig_file_config`] of the rig file at `path` (the device option
    /// `--model`): a fitted `[model]` runs its effects; a plain rig file (gear, cam,
    /// friction, calibration) puts that rig on the virtual device with the `paper` preset.
    /// Errors name the file and what to do.
    pub fn fitted_config(path: &std::path::Path) -> Result<SimConfig, RigError> {
        let what = || format!("--model {}", path.display());
        let rig = rigfile::RigFile::load(path).map_err(|e| RigError::BadValue {
            what: what(),
            why: format!(
                "{e}; give a rig file with a fitted [model] (written by `rig explain --measured X --write-model FILE`, format in docs/rig-file.md)"
            ),
        })?;
        Self::rig_file_config(&rig, &sim::Preset::paper()).map_err(|e| RigError::BadValue {
            what: what(),
            why: e.to_string(),
        })
    }

    /// The pseudo-terminal's port name, to open like a serial port.
    pub fn port_name(&self) -> &str {
        &self.port
    }

    /// Virtual seconds per wall-clock second, as asked (and as `Info` reports it).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Virtual seconds the device fell behind `speed` times the wall clock because this
    /// machine could not run it that fast.
    pub fn behind_s(&self) -> f64 {
        *lock(&self.shared.behind_s)
    }

    /// Runs `f` on the simulated rig (the simulation pauses meanwhile).
    pub fn with_rig<R>(&self, f: impl FnOnce(&mut SimRig) -> R) -> R {
        f(&mut lock(&self.shared.rig))
    }

    /// Runs `f` on the plant, as an operator's hand at the rig.
    pub fn with_plant<R>(&self, f: impl FnOnce(&mut Plant) -> R) -> R {
        self.with_rig(|rig| f(rig.plant_mut()))
    }

    /// Virtual time since boot, s.
    pub fn time(&self) -> f64 {
        self.with_rig(|rig| rig.time())
    }

    /// Noise bytes mixed into the line so far, both ways.
    pub fn noise_bytes(&self) -> u64 {
        *lock(&self.shared.noise_bytes)
    }

    /// Device output dropped because the host did not read it, bytes.
    pub fn dropped_bytes(&self) -> u64 {
        *lock(&self.shared.dropped_bytes)
    }
}

impl Drop for VirtualDevice {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// A device loop's parts: the port's name, the state it shares, its thread.
type Spawned<D> = (String, Arc<Shared<D>>, JoinHandle<()>);

/// Puts `rig` on a new pseudo-terminal and starts its loop.
fn spawn<D: Served>(
    rig: D,
    speed: f64,
    noise: Option<WallNoise>,
    pacing: Pacing,
) -> Result<Spawned<D>, RigError> {
    let fail = |what: &str, e: &dyn std::fmt::Display| {
        RigError::VirtualDevice(format!(
            "{what}: {e} (pseudo-terminals must be available: /dev/ptmx)"
        ))
    };
    let (master, port) =
        PtyMaster::open().map_err(|e| fail("cannot open a pseudo-terminal pair", &e))?;
    let shared = Arc::new(Shared {
        rig: Mutex::new(rig),
        noise_bytes: Mutex::new(0),
        stop: AtomicBool::new(false),
        dropped_bytes: Mutex::new(0),
        behind_s: Mutex::new(0.0),
    });
    let worker = Arc::clone(&shared);
    let thread = std::thread::Builder::new()
        .name("virtual-device".into())
        .spawn(move || run(master, &*worker, speed, noise, pacing))
        .map_err(|e| fail("cannot start the simulation thread", &e))?;
    Ok((port, shared, thread))
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // The simulation is plain data: a panic elsewhere does not make it unusable.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The device loop: host bytes in, time advanced, device bytes out.
fn run<D: Served>(
    mut master: PtyMaster,
    shared: &Shared<D>,
    speed: f64,
    noise: Option<WallNoise>,
    pacing: Pacing,
) {
    let mut rng = model::plant::NoiseSource::new(noise.map_or(0, |n| n.seed));
    let mut noise_owed = [0.0f64; 2];
    let mut noise_bytes = |dt: f64, owed: &mut f64, out: &mut Vec<u8>| {
        if let Some(n) = noise {
            // Poisson-like: a random share of the mean keeps the gaps irregular.
            *owed += dt * n.bytes_per_s * 2.0 * rng.uniform();
            while *owed >= 1.0 {
                *owed -= 1.0;
                out.push((rng.next_u64() >> 56) as u8);
            }
        }
    };
    let mut buf = [0u8; 4096];
    let mut pending: Vec<u8> = Vec::new();
    let mut owed = 0.0f64;
    let mut last = Instant::now();
    // The host's last byte, in virtual and in wall time; whether time waits for it.
    let mut last_rx = (0.0f64, Instant::now());
    let mut waiting = false;
    let tick = 1.0 / f64::from(ADC_HZ);
    while !shared.stop.load(Ordering::SeqCst) {
        let received = if master.wait_readable(POLL) {
            master.read_available(&mut buf)
        } else {
            0
        };
        let now = Instant::now();
        let wall_dt = (now - last).as_secs_f64();
        let mut to_device_noise = Vec::new();
        noise_bytes(wall_dt, &mut noise_owed[0], &mut to_device_noise);
        let noise_start = pending.len();
        noise_bytes(wall_dt, &mut noise_owed[1], &mut pending);
        let noise_sent = to_device_noise.len() + pending.len() - noise_start;
        if noise_sent > 0 {
            *lock(&shared.noise_bytes) += noise_sent as u64;
        }
        let turn_wall = wall_dt.min(MAX_TURN_WALL).min(MAX_TURN_DEVICE_S / speed);
        if wall_dt > turn_wall {
            *lock(&shared.behind_s) += (wall_dt - turn_wall) * speed;
        }
        if !waiting {
            owed += turn_wall * speed;
        }
        last = now;
        let ticks = (owed / tick).floor();
        owed -= ticks * tick;
        {
            let mut rig = lock(&shared.rig);
            if !to_device_noise.is_empty() {
                rig.to_device(&to_device_noise);
            }
            if received > 0 {
                rig.to_device(&buf[..received]);
                last_rx = (rig.time(), now);
            }
            if ticks > 0.0 {
                rig.advance(ticks * tick);
            }
            let driving = rig.driving();
            if driving && master.hung_up() {
                // The port was closed (the client quit or died) with a release live: that
                // host is gone for good, and no other client may keep its release alive.
                // The comms timeout runs out now, before another client's bytes are read.
                rig.advance(f64::from(protocol::COMMS_TIMEOUT_MS) / 1000.0 + tick);
            }
            // The host's silence in virtual time never runs ahead of its silence in
            // wall time once past a heartbeat's slack.
            let quiet_virtual = rig.time() - last_rx.0;
            waiting = pacing == Pacing::HostWall
                && driving
                && !master.hung_up()
                && quiet_virtual > HOST_QUIET_S
                && quiet_virtual > (now - last_rx.1).as_secs_f64();
            let before = pending.len();
            rig.device_output(&mut pending);
            if pending.len() > MAX_PENDING {
                *lock(&shared.dropped_bytes) += (pending.len() - before) as u64;
                pending.truncate(before);
            }
            if master.hung_up() {
                // The client is gone: its continuous stream stops (a board only learns it
                // from the comms timeout).
                rig.link_closed();
                // Nobody reads the line: the output is gone, as on a board's UART.
                *lock(&shared.dropped_bytes) += pending.len() as u64;
                pending.clear();
            }
        }
        let written = master.write_available(&pending);
        pending.drain(..written);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::client::{Client, ClientOptions, open_serial};

    #[test]
    fn a_rig_file_builds_the_plant_of_its_fitted_model_or_the_preset() {
        let rig = |text: &str| rigfile::RigFile::parse(text, "test.toml").unwrap();
        let paper = sim::Preset::paper();
        // With a fitted [model]: its effects and mu, not the preset's.
        let fitted = rig(
            "[model]\nmu = 0.25\n\n[[model.effects]]\nname = \"vibrator-viscous-loss\"\nparams = { c_v_n_mm_s_per_rad = 0.2 }\n",
        );
        let c = VirtualDevice::rig_file_config(&fitted, &paper).unwrap();
        assert!((c.plant.effects.extra_viscous - 0.2e-3).abs() < 1e-12);
        assert_eq!(c.plant.effects.axial_friction_speed, None);
        assert_eq!(c.plant.mu_ax, 0.25);
        assert_eq!(c.core.board_name, sim::VIRTUAL_BOARD);
        assert!(
            c.core.output_encoder.is_some(),
            "as the paper's virtual device"
        );
        // Without one: the preset.
        let plain = rig("[friction]\nmu_s = 0.271\n");
        let c = VirtualDevice::rig_file_config(&plain, &paper).unwrap();
        assert_eq!(c.plant.effects, paper.effects);
        // An effect the plant cannot run is named.
        let timed = rig(
            "[model]\nmu = 0.25\n\n[[model.effects]]\nname = \"thermal-drift\"\nparams = { k_per_s = 1e-6 }\n",
        );
        let e = VirtualDevice::rig_file_config(&timed, &paper)
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot run thermal-drift against time"), "{e}");
    }

    fn connect(dev: &VirtualDevice) -> Client<crate::client::SerialTransport> {
        let io = open_serial(dev.port_name(), protocol::DEFAULT_BAUD_RATE).unwrap();
        let mut opts = ClientOptions::new(dev.port_name());
        opts.time_scale = dev.speed();
        Client::connect(io, opts).unwrap().0
    }

    #[test]
    fn the_virtual_rig_streams_a_second_at_10_khz_with_nothing_lost() {
        use protocol::{DeviceMessage, Request, StreamDecoder, StreamEvent};
        let dev = VirtualDevice::paper(1.0).unwrap();
        let mut client = connect(&dev);
        // Heartbeats keep the stream alive past the comms timeout.
        client.start_keep_alive();
        client
            .ack(&Request::StartStream { rate_hz: 10_000 })
            .unwrap();
        let mut decoder = StreamDecoder::new();
        let mut last_seq = None;
        // One second of device time: 10,000 samples, waiting on the device's blocks.
        while decoder.samples < 10_000 {
            match client.recv(Duration::from_secs(10)).unwrap() {
                Some(DeviceMessage::StreamBlock(block)) => decoder.push(&block, |e| {
                    if let StreamEvent::Sample { seq, .. } = e {
                        last_seq = Some(seq);
                    }
                }),
                Some(_) => {}
                None => panic!("the stream stopped after {} samples", decoder.samples),
            }
        }
        client.ack(&Request::StopStream).unwrap();
        assert_eq!(
            (decoder.lost, decoder.bad_blocks, decoder.restarts),
            (0, 0, 0)
        );
        assert_eq!(last_seq, Some(decoder.samples as u32 - 1));
        assert_eq!(dev.dropped_bytes(), 0);
        dev.with_rig(|rig| assert_eq!(rig.core().status().stream_samples_skipped, 0));
    }

    /// Wall-clock guard of the waits on the device's clock: only a device that stopped
    /// running trips it (a loaded machine slows the device, it does not stop it).
    const STUCK: Duration = Duration::from_secs(60);

    /// Waits until `done` holds on the simulated rig (polled between loop turns). Panics
    /// naming `what` after [`STUCK`] of wall time.
    fn wait_on_device(dev: &VirtualDevice, what: &str, mut done: impl FnMut(&SimRig) -> bool) {
        let guard = Instant::now() + STUCK;
        while !dev.with_rig(|rig| done(rig)) {
            assert!(
                Instant::now() < guard,
                "waited {STUCK:?} of wall time for {what} (device time {} s)",
                dev.time()
            );
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Waits until the device's clock reads at least `t_s`; returns the reading.
    fn wait_device_time(dev: &VirtualDevice, t_s: f64, what: &str) -> f64 {
        wait_on_device(dev, &format!("device time {t_s} s: {what}"), |rig| {
            rig.time() >= t_s
        });
        dev.time()
    }

    /// Device time plus the time it lost to a starved machine, s, read consistently (no
    /// loop turn counted its loss in between).
    fn time_and_behind(dev: &VirtualDevice) -> f64 {
        loop {
            let behind = dev.behind_s();
            let t = dev.time();
            if dev.behind_s() == behind {
                return t + behind;
            }
        }
    }

    /// A wall instant the device's loop has covered: `Instant::now()`, returned once two
    /// loop turns stepped device time (the second turn's wall clock was read after it).
    fn covered_wall_instant(dev: &VirtualDevice) -> Instant {
        let mark = Instant::now();
        let mut t = dev.time();
        for turn in ["first", "second"] {
            t = wait_device_time(dev, t + 1e-9, turn);
        }
        mark
    }

    #[test]
    fn the_served_rig_never_sends_faster_than_its_uart() {
        use protocol::{DeviceMessage, Request, StreamDecoder};
        let dev = VirtualDevice::start_with_noise(
            VirtualDevice::paper_config(&sim::Preset::paper()),
            1.0,
            None,
        )
        .unwrap();
        let mut client = connect(&dev);
        client.start_keep_alive();
        // The 10 kHz stream and then 1 kHz telemetry: about 76 kB/s with the cam at rest
        // (asked the other way round, the stream would be refused: the device budgets the
        // link for a vibrating cam, `protocol::stream_rate_for_link`).
        client
            .ack(&Request::StartStream { rate_hz: 10_000 })
            .unwrap();
        client.start_telemetry(1000).unwrap();
        let rate = f64::from(protocol::link_bytes_per_s(protocol::DEFAULT_BAUD_RATE));
        let line = |dev: &VirtualDevice| dev.with_rig(|r| (r.time(), r.link_bytes_sent()));
        let (t0, sent0) = line(&dev);
        let seen0 = client.stats().bytes_in;
        let mut decoder = StreamDecoder::new();
        // Two seconds of device time, waiting on the device's clock.
        while dev.time() < t0 + 2.0 {
            match client.recv(Duration::from_secs(10)).unwrap() {
                Some(DeviceMessage::StreamBlock(block)) => decoder.push(&block, |_| {}),
                Some(_) => {}
                None => panic!("the device went quiet"),
            }
        }
        let (t1, sent1) = line(&dev);
        let seen = client.stats().bytes_in - seen0;
        client.ack(&Request::StopStream).unwrap();
        let device_s = t1 - t0;
        // The device never sent faster than its UART, on its own clock (the byte in
        // flight aside), and the host saw no more than the device sent (plus what was on
        // the way when the count began: less than one write of the UART).
        assert!(
            (sent1 - sent0) as f64 <= rate * device_s + 1.0,
            "{} B in {device_s} s",
            sent1 - sent0
        );
        assert!(
            seen as f64 <= rate * device_s + sim::UART_WRITE as f64 + 1.0,
            "the host saw {seen} B in {device_s} s of device time"
        );
        // And the stream fitted beside the telemetry: nothing lost.
        assert_eq!((decoder.lost, decoder.bad_blocks), (0, 0));
        assert!(decoder.samples >= 19_000, "{} samples", decoder.samples);
    }

    #[test]
    fn the_link_agreed_at_4_mbaud_carries_the_stream_beside_1_khz_telemetry() {
        use protocol::{FAST_BAUD_RATE, NackCode, Request};
        let dev = VirtualDevice::paper(1.0).unwrap();
        let mut client = connect(&dev);
        client.start_telemetry(1000).unwrap();
        // At 921,600 Bd the link cannot carry it: refused naming the rate that fits.
        let e = client
            .ack(&Request::StartStream { rate_hz: 10_000 })
            .unwrap_err();
        assert_eq!(e.refusal(), Some(NackCode::StreamRate { fits_hz: 1_250 }));
        let info = client.info().unwrap();
        assert_eq!(info.max_baud, FAST_BAUD_RATE);
        client.agree_baud(&info, FAST_BAUD_RATE).unwrap();
        dev.with_rig(|r| {
            assert_eq!(r.core().link_baud(), FAST_BAUD_RATE);
            // 4,000,000 Bd as the board's USART gives it: 3,953,488 Bd.
            assert_eq!(r.link_bytes_per_s(), Some(395_348));
        });
        client.start_keep_alive();
        client
            .ack(&Request::StartStream { rate_hz: 10_000 })
            .unwrap();
        // Requests at the new rate confirm it: it stays past BAUD_CONFIRM_MS.
        let t0 = dev.time();
        while dev.time() < t0 + 1.5 {
            client.recv(Duration::from_millis(50)).unwrap();
        }
        assert_eq!(dev.with_rig(|r| r.core().link_baud()), FAST_BAUD_RATE);
        client.ack(&Request::StopStream).unwrap();
    }

    #[test]
    fn a_silent_host_loses_its_release_after_the_comms_timeout_of_board_time() {
        let speed = 1.0;
        let booted_by = Instant::now();
        let dev = VirtualDevice::paper(speed).unwrap();
        let mut client = connect(&dev);
        assert_eq!(client.options().time_scale, speed);
        client.release(true, 10.0).unwrap();
        // The release was accepted at or before this device time.
        let accepted_by = dev.time();
        let (paced_from, paced_from_wall) = (time_and_behind(&dev), Instant::now());
        let timeout_s = f64::from(protocol::COMMS_TIMEOUT_MS) / 1000.0;
        let period_s = 1e-3;
        // The host goes silent: no heartbeats, nothing read, until the device's clock is
        // past the timeout (a loaded machine slows the device, so wall time says nothing).
        wait_device_time(
            &dev,
            accepted_by + timeout_s + 0.1,
            "the comms timeout after a silent host's release",
        );
        let latched = client.faults().unwrap().latched;
        assert!(
            latched.contains(protocol::FaultFlags::COMMS_TIMEOUT),
            "{latched}"
        );
        let (_, risen_us) = client
            .take_fault_events()
            .into_iter()
            .find(|(f, _)| f.contains(protocol::FaultFlags::COMMS_TIMEOUT))
            .expect("a FaultEvent announced the timeout");
        let after_s = risen_us as f64 * 1e-6 - accepted_by;
        // Device time never waits for the host: the timeout rises at the comms timeout
        // after the last accepted request, within one control period.
        assert!(after_s <= timeout_s + period_s, "{after_s} s");
        // And device time kept the wall clock's pace (1x): what it did not run, a starved
        // machine took (`behind_s`), never the silent host (one loop turn of slack, and
        // one turn the two readings may straddle); nor did it run ahead of the wall clock.
        let covered = covered_wall_instant(&dev);
        let paced = time_and_behind(&dev);
        let wall_s = (covered - paced_from_wall).as_secs_f64();
        let slack_s = 2.0 * MAX_TURN_WALL * speed + 1.0 / f64::from(ADC_HZ);
        assert!(
            paced - paced_from >= wall_s * speed - slack_s,
            "device time + behind ran {} s in {wall_s} s of wall time",
            paced - paced_from
        );
        assert!(
            paced <= booted_by.elapsed().as_secs_f64() * speed,
            "device time + behind {paced} s ran ahead of the wall clock"
        );
        dev.with_rig(|rig| assert!(!rig.drive().enabled, "vibration stopped"));
    }

    #[test]
    fn a_served_rig_says_its_speed_and_the_client_keeps_pace() {
        let dev = VirtualDevice::paper(5.0).unwrap();
        let io = open_serial(dev.port_name(), protocol::DEFAULT_BAUD_RATE).unwrap();
        // A client that does not know the speed learns it from `Info`.
        let (mut client, info) = Client::connect(io, ClientOptions::new(dev.port_name())).unwrap();
        assert_eq!(info.time_scale, 5.0);
        assert_eq!(client.options().time_scale, 5.0);
        client.release(true, 10.0).unwrap();
        // Waiting inside the client sends heartbeats at 5x: the release stays live.
        client.recv(Duration::from_millis(200)).unwrap();
        assert!(client.faults().unwrap().latched.is_empty());
        client.release(false, 0.0).unwrap();
    }

    #[test]
    fn output_nobody_reads_is_dropped_and_a_new_client_starts_fresh() {
        // Issue 33: telemetry streamed to a client that went away piled up and reached the
        // next client seconds old.
        let dev = VirtualDevice::paper(5.0).unwrap();
        let mut gone = connect(&dev);
        gone.start_telemetry(1000).unwrap();
        drop(gone);
        let left_at = dev.time();
        // Two device seconds of telemetry with nobody on the port (about 100 kB).
        let came_at = wait_device_time(&dev, left_at + 2.0, "telemetry with nobody on the port");
        let mut next = connect(&dev);
        let first = next
            .next_telemetry(Duration::from_secs(5))
            .unwrap()
            .expect("the stream still runs");
        let age_s = came_at - first.device_time_us as f64 * 1e-6;
        assert!(age_s < 0.1, "the first sample is {age_s} s old");
    }

    #[test]
    fn a_host_that_closes_the_port_during_a_release_leaves_a_latched_fault() {
        let dev = VirtualDevice::paper(5.0).unwrap();
        let mut client = connect(&dev);
        client.release(true, 10.0).unwrap();
        client.recv(Duration::from_millis(50)).unwrap();
        drop(client);
        // The next client comes as soon as the device saw the port closed (before that,
        // a pty cannot tell a new client from the old one): it must not keep the gone
        // host's release alive.
        wait_on_device(&dev, "the device to see the port closed", |rig| {
            !rig.core().status().host_release
        });
        let mut next = connect(&dev);
        let latched = next.faults().unwrap().latched;
        assert!(
            latched.contains(protocol::FaultFlags::COMMS_TIMEOUT),
            "{latched}"
        );
    }

    #[test]
    fn client_talks_to_the_virtual_device_over_its_pty() {
        let dev = VirtualDevice::paper(4.0).unwrap();
        let io = open_serial(dev.port_name(), protocol::DEFAULT_BAUD_RATE).unwrap();
        let mut opts = ClientOptions::new(dev.port_name());
        opts.time_scale = dev.speed();
        let (mut client, info) = Client::connect(io, opts).unwrap();
        assert_eq!(info.protocol_version, protocol::PROTOCOL_VERSION);
        client.faults().unwrap();
        let t0 = dev.time();
        // Virtual time runs (the guard panics if it does not).
        wait_device_time(&dev, t0 + 0.05, "virtual time runs");
        // A second client after the first closed the port.
        drop(client);
        let io = open_serial(dev.port_name(), protocol::DEFAULT_BAUD_RATE).unwrap();
        let (_client, _) = Client::connect(io, ClientOptions::new(dev.port_name())).unwrap();
    }
}
