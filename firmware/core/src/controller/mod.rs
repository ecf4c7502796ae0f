//! The control core: one [`Core::step`] per control period turns sensor readings into a
//! bridge command, and the host link goes through [`Core::receive`] and
//! [`Core::transmit`]. Time is passed in; there is no I/O, no heap and no hardware here.
//!
//! The pieces: [`io`] (boot facts, inputs, outputs, status), `derived` (the parameter
//! checks and what the loop derives from the record), `step` (one control period),
//! `streams` (telemetry, health and step timing), `persist` (a record on its way to
//! flash); the requests are served in `crate::server`.

mod derived;
mod io;
mod persist;
mod step;
mod streams;

use protocol::{FaultFlags, ParametersStatus, ResetCause, RigParameters};

use crate::capture::{Capture, CapturePhase};
use crate::config::CoreConfig;
use crate::current::CurrentSense;
use crate::encoder::CamEncoder;
use crate::estimator::TorqueEstimator;
use crate::faults::FaultMonitor;
use crate::release::Release;
use crate::speed_loop::SpeedLoop;
use crate::supervisor::Supervisor;
use crate::tx_queue::{CAPTURE_IN_FLIGHT, REPLY_RESERVE, TxQueue};

pub use derived::check_rules;
pub(crate) use derived::{Derived, check_board_caps};
pub use io::{BoardInputs, BootInfo, Inputs, Outputs, Status};
pub(crate) use persist::Persist;
use streams::StepTiming;
pub(crate) use streams::Streams;

/// The control core. See the crate documentation.
pub struct Core {
    pub(crate) config: CoreConfig,
    pub(crate) parameters: RigParameters,
    pub(crate) parameters_status: ParametersStatus,
    pub(crate) derived: Derived,
    pub(crate) current: CurrentSense,
    encoder: CamEncoder,
    speed_loop: SpeedLoop,
    estimator: TorqueEstimator,
    pub(crate) supervisor: Supervisor,
    pub(crate) faults: FaultMonitor,
    pub(crate) deframer: protocol::RequestDeframer,
    pub(crate) tx: TxQueue,
    pub(crate) now_us: u64,
    last_step_us: Option<u64>,
    /// The release requests (host, open loop, button) and their heartbeat.
    pub(crate) release: Release,
    duty: f32,
    enable: bool,
    pub(crate) persist: Persist,
    /// The output encoder, when fitted, and its latest count (`Core::set_output_encoder_count`).
    pub(crate) output_encoder: Option<crate::OutputEncoder>,
    pub(crate) output_count: Option<u16>,
    pub(crate) streams: Streams,
    /// The continuous stream: the steps' ring and the block being packed.
    pub(crate) stream: crate::stream::Stream,
    /// The host link's agreed rate.
    pub(crate) link: crate::link::LinkRate,
    step_timing: StepTiming,
    overruns: u32,
    pub(crate) capture: Capture,
    pub(crate) board: BoardInputs,
    pub(crate) reset_cause: ResetCause,
    pub(crate) firmware_build: &'static str,
}

impl Core {
    /// A core in `Locked`, measuring the current zero. A watchdog reset or an invalid
    /// parameter record latches its fault from the start. On the target build it in place
    /// with [`Core::new_in`] (the core is ~43 KiB, mostly the capture buffer).
    #[allow(unsafe_code)]
    pub fn new(config: CoreConfig, boot: BootInfo) -> Self {
        let mut slot = core::mem::MaybeUninit::uninit();
        Self::new_in(&mut slot, config, boot);
        // SAFETY: `new_in` initialised every field of the slot.
        unsafe { slot.assume_init() }
    }

    /// [`Core::new`] built in `slot` itself: each field is written in place, the capture
    /// buffer (40 000 B) zero-filled where it lies, so it never passes through a stack
    /// temporary (the firmware's boot frame was 44 KiB for one, 188 B from the stack
    /// guard; the target bench's boot trace measures the margin). Returns the core.
    #[allow(unsafe_code)]
    pub fn new_in(
        slot: &mut core::mem::MaybeUninit<Self>,
        config: CoreConfig,
        boot: BootInfo,
    ) -> &mut Self {
        use core::ptr::addr_of_mut;
        let (parameters, status, derived) = match Derived::new(&boot.parameters, &config) {
            Ok(d) if boot.parameters_status != ParametersStatus::Invalid => {
                (boot.parameters, boot.parameters_status, d)
            }
            _ => {
                let paper = RigParameters::paper();
                // Not `expect`: formatting the rejection would pull `Debug` into the image.
                let Ok(d) = Derived::new(&paper, &config) else {
                    panic!("the paper's parameters are valid (tested)");
                };
                (paper, ParametersStatus::Invalid, d)
            }
        };
        let step_s = config.period_us() as f32 * 1e-6;
        let mut config = config;
        if cfg!(feature = "output-encoder") && config.output_encoder.is_some() {
            config
                .capabilities
                .insert(protocol::Capabilities::OUTPUT_ENCODER);
        }
        let p = slot.as_mut_ptr();
        // SAFETY: `p` points to the slot, valid for writes and aligned; each field is
        // written once through a raw pointer (no reference to uninitialised memory), the
        // capture by `Capture::init_in` in place. The exhaustive pattern below fails to
        // compile when a field is added to `Core` without being listed here.
        unsafe {
            addr_of_mut!((*p).current).write(CurrentSense::new(&config.current, step_s));
            addr_of_mut!((*p).encoder).write(CamEncoder::new(config.counts_per_rev()));
            addr_of_mut!((*p).speed_loop).write(SpeedLoop::new(
                config.speed_loop,
                &config.motor,
                derived.feed_forward,
            ));
            addr_of_mut!((*p).estimator).write(TorqueEstimator::new(
                config.counts_per_rev(),
                config.estimator.max_revolution_us,
            ));
            addr_of_mut!((*p).supervisor).write(Supervisor::new(config.supervisor, derived.max_hz));
            addr_of_mut!((*p).faults).write(FaultMonitor::new(config.supervisor.fault_hold_us));
            addr_of_mut!((*p).deframer).write(protocol::RequestDeframer::new());
            addr_of_mut!((*p).tx).write(TxQueue::new());
            addr_of_mut!((*p).now_us).write(0);
            addr_of_mut!((*p).last_step_us).write(None);
            addr_of_mut!((*p).release).write(Release::new(config.supervisor.default_freq_hz));
            addr_of_mut!((*p).duty).write(0.0);
            addr_of_mut!((*p).enable).write(false);
            addr_of_mut!((*p).persist).write(Persist::Idle);
            addr_of_mut!((*p).output_encoder)
                .write(config.output_encoder.map(crate::OutputEncoder::new));
            addr_of_mut!((*p).output_count).write(None);
            addr_of_mut!((*p).streams).write(Streams::default());
            addr_of_mut!((*p).stream).write(crate::stream::Stream::default());
            addr_of_mut!((*p).link).write(crate::link::LinkRate::default());
            addr_of_mut!((*p).step_timing).write(StepTiming::default());
            addr_of_mut!((*p).overruns).write(0);
            Capture::init_in(addr_of_mut!((*p).capture));
            addr_of_mut!((*p).board).write(BoardInputs::default());
            addr_of_mut!((*p).reset_cause).write(boot.reset_cause);
            addr_of_mut!((*p).firmware_build).write(boot.firmware_build);
            addr_of_mut!((*p).config).write(config);
            addr_of_mut!((*p).parameters).write(parameters);
            addr_of_mut!((*p).parameters_status).write(status);
            addr_of_mut!((*p).derived).write(derived);
        }
        // Every field of `Core`, written above (a compile-time check, never run).
        const _: fn(Core) = |c| {
            let Core {
                current: _,
                encoder: _,
                speed_loop: _,
                estimator: _,
                supervisor: _,
                faults: _,
                deframer: _,
                tx: _,
                now_us: _,
                last_step_us: _,
                release: _,
                duty: _,
                enable: _,
                persist: _,
                output_encoder: _,
                output_count: _,
                streams: _,
                stream: _,
                link: _,
                step_timing: _,
                overruns: _,
                capture: _,
                board: _,
                reset_cause: _,
                firmware_build: _,
                config: _,
                parameters: _,
                parameters_status: _,
                derived: _,
            } = c;
        };
        // SAFETY: every field is initialised above.
        let core = unsafe { slot.assume_init_mut() };
        core.current.begin_zero();
        let mut boot_faults = FaultFlags::empty();
        boot_faults.set(FaultFlags::WATCHDOG_RESET, boot.watchdog_reset());
        boot_faults.set(
            FaultFlags::CALIBRATION_INVALID,
            status == ParametersStatus::Invalid,
        );
        core.raise(boot_faults);
        core
    }

    /// The board's measurements for the next [`Core::step`] (see [`BoardInputs`]); they
    /// stay until set again.
    pub fn set_board_inputs(&mut self, board: BoardInputs) {
        self.board = board;
    }

    /// Whether `HW_OVERCURRENT` is latched: while it is, the binary keeps the timer's break
    /// (the bridge stays off even if the break flag clears); once `ClearFaults` clears it,
    /// the binary may re-arm the break.
    pub fn break_latched(&self) -> bool {
        self.faults.latched().contains(FaultFlags::HW_OVERCURRENT)
    }

    /// The supervisor's state (as in [`Core::status`], without building the whole snapshot).
    pub fn state(&self) -> protocol::SupervisorState {
        self.supervisor.state()
    }

    /// The latched faults (as in [`Core::status`]).
    pub fn latched_faults(&self) -> FaultFlags {
        self.faults.latched()
    }

    /// The current sensor's measured zero, ADC counts, once measured (`None` while a
    /// zeroing runs).
    pub fn current_zero_adc(&self) -> Option<f32> {
        (!self.current.zeroing()).then(|| self.current.zero_counts())
    }

    /// The current sensor's zero once measured and found plausible, ADC counts; `None`
    /// before the first zero measurement ends (when [`Core::current_zero_adc`] still gives
    /// the nominal zero) or while one runs. The binary centres the overcurrent trip on it
    /// in the same control step, before the bridge may drive: the supervisor leaves
    /// `Locked` only once the zero is measured, so the trip never runs a release on the
    /// nominal zero (at a 5.5 V sensor supply the nominal-zero trip fired at 4.2 A, below
    /// the software limit; at 4.5 V at 8.2 A).
    pub fn measured_current_zero_adc(&self) -> Option<f32> {
        self.zero_ready().then(|| self.current.zero_counts())
    }

    /// Whether the current sensor's zero is measured and plausible, and no re-zero runs:
    /// the supervisor leaves `Locked` and a drive request is accepted only then.
    pub(crate) fn zero_ready(&self) -> bool {
        self.current.zero_valid() && !self.current.zeroing()
    }

    /// The configuration.
    pub fn config(&self) -> &CoreConfig {
        &self.config
    }

    /// The active rig parameters.
    pub fn parameters(&self) -> &RigParameters {
        &self.parameters
    }

    fn direction(&self) -> f32 {
        if self.config.motor.reverse { -1.0 } else { 1.0 }
    }

    /// Latches `flags`; any fault also drops the release requests (a held button must be
    /// let go once, a host must ask again).
    pub(crate) fn raise(&mut self, flags: FaultFlags) {
        if flags.is_empty() {
            return;
        }
        self.faults.raise(flags, self.now_us);
        self.release.drop_all();
        self.estimator.stop();
    }

    /// Faults whose condition is present now.
    pub(crate) fn active_faults(&self) -> FaultFlags {
        let mut a = FaultFlags::empty();
        a.set(
            FaultFlags::OVERCURRENT,
            self.current.step_mean_a().abs() > self.derived.current_limit_a,
        );
        a.set(
            FaultFlags::CURRENT_ZERO_RANGE,
            !self.current.zero_in_range(),
        );
        a.set(FaultFlags::BUS_OVERVOLTAGE, self.bus_overvoltage());
        a.set(
            FaultFlags::CALIBRATION_INVALID,
            self.parameters_status == ParametersStatus::Invalid,
        );
        a
    }

    /// Drains pending outgoing frame bytes into `out`; returns the count (0: nothing pending).
    /// The telemetry and health samples the steps took are framed here; otherwise one
    /// continuous-stream block is packed and framed from the steps' records; otherwise
    /// one capture chunk is generated. One of the three per call (so one call's work
    /// stays bounded: `cargo xtask target-bench`'s `lock_cycles_worst`), so replies and
    /// telemetry still go out while a stream runs or a capture uploads.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        // Bounded work under the binary's core lock: the telemetry samples the steps took,
        // or else one stream block, or else one capture message.
        if !self.frame_streams()
            && !self.frame_stream_block()
            && self.capture.phase() == CapturePhase::Uploading
            && self.tx.len() < CAPTURE_IN_FLIGHT
            && self.tx.free() >= protocol::MAX_DEVICE_FRAME_SIZE + REPLY_RESERVE
            && let Some(msg) = self.capture.next_message()
        {
            self.tx.push(&msg, REPLY_RESERVE);
        }
        self.tx.drain(out)
    }

    /// Packs and queues the next continuous-stream block, when the steps left enough
    /// samples and the queue has room for it beside the replies' reserve (otherwise the
    /// records wait in the ring); whether it did.
    fn frame_stream_block(&mut self) -> bool {
        if !self.stream.on() || self.tx.free() < protocol::MAX_DEVICE_FRAME_SIZE + REPLY_RESERVE {
            return false;
        }
        let Some(block) = self.stream.next_block() else {
            return false;
        };
        self.tx
            .push(&protocol::DeviceMessage::StreamBlock(block), REPLY_RESERVE);
        true
    }

    /// The host link's agreed rate, Bd (`Request::SetBaud`).
    pub fn link_baud(&self) -> u32 {
        self.link.baud
    }

    /// The rate the UART must switch to now, once (call it when the UART has sent
    /// everything): after an accepted `SetBaud` whose `Ack` has left the transmit queue, or
    /// back to [`protocol::DEFAULT_BAUD_RATE`] when no request was accepted at the new rate
    /// within [`protocol::BAUD_CONFIRM_MS`] of device time.
    pub fn take_baud_switch(&mut self, now_us: u64) -> Option<u32> {
        let idle = self.tx.is_empty();
        self.link.take_switch(now_us, idle)
    }

    /// The host closed the link (the virtual rig's client went away; a board's UART cannot
    /// tell, and the comms timeout stops the stream there): the stream stops.
    pub fn link_closed(&mut self) {
        self.stream.stop();
    }

    /// A snapshot of the core.
    pub fn status(&self) -> Status {
        let estimate = self.estimator.last();
        Status {
            state: self.supervisor.state(),
            latched_faults: self.faults.latched(),
            active_faults: self.active_faults(),
            flags: self.status_flags(),
            cam_speed_rad_s: self.encoder.speed_rad_s() * self.direction(),
            cam_angle_rad: self.encoder.angle_rad(),
            current_a: self.current.filtered_a(),
            duty: self.duty,
            enabled: self.enable,
            target_hz: self.supervisor.target_hz(),
            speed_reference_rad_s: self.speed_loop.reference(),
            tau_cam_nm: estimate.map_or(0.0, |e| e.tau_cam_nm),
            tau_rot_nm: estimate.map_or(0.0, |e| e.tau_rot_nm),
            estimate_valid: estimate.is_some(),
            revolutions: self.estimator.revolutions(),
            keeps_moving_after_stop: self.derived.keeps_moving,
            holds_at_rest: self.derived.holds_at_rest,
            host_release: self.release.host,
            open_loop_volts: self.release.open_loop_volts,
            button_release: self.release.button_held,
            current_zero_adc: self.current.zero_counts(),
            zeroing: self.current.zeroing(),
            parameters: self.parameters,
            parameters_status: self.parameters_status,
            deframer: self.deframer.stats(),
            tx_dropped: self.tx.dropped(),
            control_overruns: self.overruns,
            capture_recording: self.capture.phase() == CapturePhase::Recording,
            capture_uploading: self.capture.phase() == CapturePhase::Uploading,
            stream_rate_hz: self.stream.rate_hz(),
            stream_samples_skipped: self.stream.skipped_total(),
        }
    }
}
