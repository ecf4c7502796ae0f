//! [`Bench`]: the one interface the procedures drive a rig through, with its two
//! implementations: [`InProcessBench`] (the in-process virtual rig, [`sim::SimLink`], virtual
//! time) and [`DeviceBench`] (a device over the serial client: a real rig, a served virtual
//! rig, or `--sim`); and [`Operator`], the person at the bench (prompts on stderr, answers
//! on stdin).

use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use protocol::{
    Capabilities, DeviceInfo, DeviceMessage, NackCode, Reply, Request, RigParameters, SimCommand,
    SupervisorState, TelemetrySample,
};

pub use sim::RigLink;

use crate::RigError;
use crate::connection::Connection;

/// Output rotation that counts as "the output moved", rad: 0.1 mm of rope on the paper's
/// 75 mm pulley (docs/plans.md).
pub const MOTION_RAD: f64 = 0.1e-3 / model::paper::R_OUT;

/// The one backdrive rule of every procedure (`backdriven` in the sweep's CSV, Table 1's
/// verdicts, Fig. 5's hold): the output moved by more than [`MOTION_RAD`] between two
/// readings of its angle, rad. `None` when either reading is missing (no output encoder on
/// a real rig): then the operator is asked.
pub fn moved(from_rad: Option<f64>, to_rad: Option<f64>) -> Option<bool> {
    match (from_rad, to_rad) {
        (Some(a), Some(b)) => Some((b - a).abs() > MOTION_RAD),
        _ => None,
    }
}

/// A rig the procedures drive, the same on the virtual rig and on a real one: the one rig
/// link ([`RigLink`]: requests, whose refusal is [`RigError::Refused`], heartbeats and
/// device time, as the shared scenarios use it) with what the procedures read besides
/// (identity, telemetry samples, temperature).
pub trait Bench: RigLink<Error = RigError> {
    /// What the device said at `Hello`.
    fn info(&self) -> &DeviceInfo;
    /// The next telemetry sample, waiting up to about 2 device seconds (`None`: none came).
    fn sample(&mut self) -> Result<Option<TelemetrySample>, RigError>;
    /// The motor temperature of the newest health sample, deg C, when sensed.
    fn motor_temp_c(&self) -> Option<f64>;
    /// The output angle as someone standing at a virtual rig sees it, rad (`None` on a
    /// real rig: there the output encoder reports it in telemetry, or the operator does).
    fn peek_output(&mut self) -> Option<f64>;

    /// The device's calibration.
    fn calibration(&mut self) -> Result<RigParameters, RigError> {
        match self.request(&Request::GetParameters)? {
            Reply::Parameters(p) => Ok(p),
            _ => Err(RigError::Protocol(
                "the device answered GetParameters with something else".into(),
            )),
        }
    }

    /// Whether the device is a virtual rig that serves `Request::Simulation`.
    fn is_virtual(&self) -> bool {
        self.info().capabilities.contains(Capabilities::SIMULATION)
    }

    /// Hangs `tau_rot_nm` on a virtual rig's output through `SimCommand::SetLoad`; false
    /// when the device is real (it refuses with `SimulationOnly`): then the operator does.
    fn set_load(&mut self, tau_rot_nm: f64) -> Result<bool, RigError> {
        let req = Request::Simulation(SimCommand::SetLoad {
            tau_rot_nm: tau_rot_nm as f32,
        });
        match self.request(&req) {
            Ok(_) => Ok(true),
            Err(RigError::Refused {
                code: NackCode::SimulationOnly | NackCode::UnknownMessage,
                ..
            }) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Sends `req` and requires an `Ack`.
    fn ack(&mut self, req: &Request) -> Result<(), RigError> {
        match self.request(req)? {
            Reply::Ack => Ok(()),
            _ => Err(RigError::Protocol(format!(
                "the device answered {} with something else than Ack",
                req.name()
            ))),
        }
    }

    /// Open-loop drive at `volts` (0 stops), kept alive from its request while on; waits for
    /// the rig's current zero ([`sim::riglink::drive`]).
    fn open_loop(&mut self, volts: f64) -> Result<(), RigError> {
        sim::riglink::drive(
            self,
            &Request::OpenLoop {
                volts: volts as f32,
                session: 0,
            },
        )
    }

    /// Release at `hz` (closed loop) or lock (`on` false), kept alive from its request while
    /// on; waits for the rig's current zero ([`sim::riglink::drive`]).
    fn release(&mut self, on: bool, hz: f64) -> Result<(), RigError> {
        sim::riglink::drive(
            self,
            &Request::Release {
                on,
                target_hz: if on { hz as f32 } else { 0.0 },
                session: 0,
            },
        )
    }

    /// Locks the gear whatever runs: open loop off, release off, heartbeats off. Best
    /// effort (the device stops at its comms timeout anyway).
    fn lock_gear(&mut self) {
        let _ = self.request(&Request::OpenLoop {
            volts: 0.0,
            session: 0,
        });
        let _ = self.request(&Request::Release {
            on: false,
            target_hz: 0.0,
            session: 0,
        });
        self.keep_alive(false);
    }

    /// Starts telemetry at `rate_hz`.
    fn start_telemetry(&mut self, rate_hz: u16) -> Result<(), RigError> {
        self.ack(&Request::StartTelemetry { rate_hz })
    }

    /// Stops telemetry.
    fn stop_telemetry(&mut self) -> Result<(), RigError> {
        self.ack(&Request::StopTelemetry)
    }
}

/// The in-process virtual rig, in virtual time (as fast as the machine runs it).
pub struct InProcessBench {
    /// The session with the simulated rig.
    pub link: sim::SimLink,
    info: DeviceInfo,
    rate_hz: f64,
    last_seq: Option<u32>,
    /// The plant's true cam torque over whole revolutions, read at every telemetry
    /// sample with the device time, s, when a revolution completed since the last reading.
    cam_torque: Vec<(f64, model::plant::CamTorqueLedger)>,
}

impl InProcessBench {
    /// Boots `config`'s rig and opens the session (hello).
    pub fn new(mut config: sim::SimConfig) -> Result<Self, RigError> {
        virtual_release_limit(&mut config);
        let mut link = sim::SimLink::new(sim::SimRig::new(config));
        let hello = protocol::session::Session::hello();
        let reply = link.request(&hello)?;
        let info = match protocol::session::hello_outcome(&reply) {
            Some(Ok(info)) => info.clone(),
            Some(Err(e)) => return Err(RigError::Protocol(e.to_string())),
            None => {
                return Err(RigError::Protocol(
                    "the simulated rig did not answer Hello".into(),
                ));
            }
        };
        Ok(Self {
            link,
            info,
            rate_hz: 50.0,
            last_seq: None,
            cam_torque: Vec::new(),
        })
    }

    /// The plant's true mean cam torque over the whole revolutions completed between
    /// device times `from_s` and `to_s` (as read at telemetry samples), N m: what the
    /// firmware's per-revolution estimates of that window stand for. `None` when no
    /// revolution completed in it.
    pub fn true_cam_torque_nm(&self, from_s: f64, to_s: f64) -> Option<f64> {
        let first = self.cam_torque.iter().find(|(t, _)| *t >= from_s)?;
        let last = self.cam_torque.iter().rev().find(|(t, _)| *t <= to_s)?;
        last.1.mean_since(&first.1)
    }

    fn note_cam_torque(&mut self) {
        let ledger = self.link.rig.plant().cam_torque_ledger();
        if self.cam_torque.last().map(|(_, l)| l.revolutions) != Some(ledger.revolutions) {
            self.cam_torque.push((self.link.rig.time(), ledger));
        }
    }
}

/// The newest telemetry state of `bench` (a sample taken for it).
fn sampled_state<B: Bench + ?Sized>(bench: &mut B) -> Result<SupervisorState, RigError> {
    bench
        .sample()?
        .map(|t| t.state)
        .ok_or_else(|| RigError::Protocol("the rig sends no telemetry".into()))
}

impl RigLink for InProcessBench {
    type Error = RigError;

    fn request(&mut self, req: &Request) -> Result<Reply, RigError> {
        if let Request::StartTelemetry { rate_hz } = req {
            self.rate_hz = f64::from((*rate_hz).max(1));
        }
        match self.link.request(req)? {
            Reply::Nack(code) => Err(RigError::Refused {
                request: req.name(),
                code,
                advice: crate::client::nack_advice(code),
            }),
            reply => Ok(reply),
        }
    }

    fn keep_alive(&mut self, on: bool) {
        self.link
            .keep_alive(on.then_some(sim::scenarios::HEARTBEAT_S));
    }

    fn wait(&mut self, seconds: f64) -> Result<(), RigError> {
        self.link.wait(seconds);
        Ok(())
    }

    fn refusal(&self, error: &RigError) -> Option<protocol::NackCode> {
        error.refusal()
    }

    fn state(&mut self) -> Result<SupervisorState, RigError> {
        sampled_state(self)
    }

    fn clock_s(&mut self) -> f64 {
        self.link.rig.time()
    }
}

impl Bench for InProcessBench {
    fn info(&self) -> &DeviceInfo {
        &self.info
    }

    fn sample(&mut self) -> Result<Option<TelemetrySample>, RigError> {
        let step = 1.0 / self.rate_hz;
        let mut waited = 0.0;
        while waited < 0.5 {
            self.link.wait(step);
            waited += step;
            self.note_cam_torque();
            if let Some(t) = self.link.last_telemetry
                && Some(t.seq) != self.last_seq
            {
                self.last_seq = Some(t.seq);
                return Ok(Some(t));
            }
        }
        Ok(None)
    }

    fn motor_temp_c(&self) -> Option<f64> {
        // The virtual rig's thermistor when it reports one, else the plant's own.
        let sensed = self
            .link
            .last_health
            .map(|h| f64::from(h.motor_temp_c))
            .filter(|t| t.is_finite());
        sensed.or(Some(self.link.rig.plant().state().temperature))
    }

    fn peek_output(&mut self) -> Option<f64> {
        Some(self.link.rig.plant().state().output_angle)
    }
}

/// A device over the serial client: a real rig, a served virtual rig, or `--sim`.
pub struct DeviceBench {
    /// The session.
    pub session: Connection,
    temp_c: Option<f64>,
    /// The device time of the newest telemetry sample received, s (its
    /// [`RigLink::clock_s`]).
    device_time_s: Option<f64>,
    /// Raised by a signal (Ctrl-C): a rest or settle ([`Bench::wait`]) ends within
    /// [`STOP_POLL`] with [`interrupted`].
    stop: Option<Arc<AtomicBool>>,
}

/// How often a wait looks at the stop flag, wall clock.
const STOP_POLL: Duration = Duration::from_millis(20);

impl DeviceBench {
    /// Wraps an open session.
    pub fn new(session: Connection) -> Self {
        Self {
            session,
            temp_c: None,
            device_time_s: None,
            stop: None,
        }
    }

    /// This bench with its waits ended by `stop` (the flag a signal raises): a rest of
    /// 10 s answers Ctrl-C within 20 ms, not at its end.
    pub fn stopped_by(mut self, stop: Arc<AtomicBool>) -> Self {
        self.stop = Some(stop);
        self
    }

    fn note(&mut self, msg: &DeviceMessage) {
        if let DeviceMessage::Telemetry(t) = msg {
            self.device_time_s = Some(t.device_time_us as f64 / 1e6);
        }
        if let DeviceMessage::Health(h) = msg
            && h.motor_temp_c.is_finite()
            && self
                .session
                .info
                .capabilities
                .contains(Capabilities::MOTOR_TEMP)
        {
            self.temp_c = Some(f64::from(h.motor_temp_c));
        }
    }
}

impl RigLink for DeviceBench {
    type Error = RigError;

    fn request(&mut self, req: &Request) -> Result<Reply, RigError> {
        self.session.client.request(req)
    }

    fn keep_alive(&mut self, on: bool) {
        if on {
            self.session.client.start_keep_alive();
        } else {
            self.session.client.stop_keep_alive();
        }
    }

    fn wait(&mut self, seconds: f64) -> Result<(), RigError> {
        let scale = self.session.time_scale();
        let deadline = crate::limits::deadline_after(crate::limits::wall_duration(seconds, scale));
        loop {
            if self.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst)) {
                return Err(interrupted());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            if let Some(msg) = self.session.client.recv(left.min(STOP_POLL))? {
                self.note(&msg);
            }
        }
    }

    fn refusal(&self, error: &RigError) -> Option<protocol::NackCode> {
        error.refusal()
    }

    fn state(&mut self) -> Result<SupervisorState, RigError> {
        sampled_state(self)
    }

    /// The device's own time (a served virtual rig does not keep its speed-up while the
    /// host is quiet, so the host's clock would not do): the newest telemetry sample's,
    /// waiting for one when none came yet (0 when none comes).
    fn clock_s(&mut self) -> f64 {
        if self.device_time_s.is_none() {
            let _ = self.sample();
        }
        self.device_time_s.unwrap_or(0.0)
    }
}

impl Bench for DeviceBench {
    fn info(&self) -> &DeviceInfo {
        &self.session.info
    }

    fn start_telemetry(&mut self, rate_hz: u16) -> Result<(), RigError> {
        self.session.client.start_telemetry(rate_hz)
    }

    fn stop_telemetry(&mut self) -> Result<(), RigError> {
        // Also drops the samples received but not taken: the next reading is fresh.
        self.session.client.stop_telemetry()
    }

    fn sample(&mut self) -> Result<Option<TelemetrySample>, RigError> {
        let scale = self.session.time_scale().max(1e-9);
        // Two device seconds, and at least one wall-clock second: a virtual device on a busy
        // machine stalls for longer than its speed-up suggests.
        let deadline = Instant::now() + Duration::from_secs_f64((2.0 / scale).max(1.0));
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.session.client.recv(left)? {
                Some(msg @ DeviceMessage::Telemetry(t)) => {
                    self.note(&msg);
                    return Ok(Some(t));
                }
                Some(other) => self.note(&other),
                None => return Ok(None),
            }
        }
    }

    fn motor_temp_c(&self) -> Option<f64> {
        self.temp_c
    }

    fn peek_output(&mut self) -> Option<f64> {
        self.session
            .device
            .as_ref()
            .map(|d| d.with_plant(|p| p.state().output_angle))
    }
}

/// The person at the bench: prompts on stderr, answers from stdin. On a virtual rig
/// (unless `forced`) nobody is asked.
pub struct Operator {
    /// Ask even on a virtual rig (`--operator`).
    pub forced: bool,
    /// Set by Ctrl-C.
    pub stop: Arc<AtomicBool>,
    /// The answers, line by line, read by a thread so a prompt can notice Ctrl-C.
    lines: std::sync::mpsc::Receiver<std::io::Result<String>>,
}

/// Reads `input` line by line on a thread.
fn line_reader(
    mut input: Box<dyn BufRead + Send>,
) -> std::sync::mpsc::Receiver<std::io::Result<String>> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        loop {
            let mut line = String::new();
            let read = input.read_line(&mut line);
            let end = matches!(read, Ok(0) | Err(_));
            // Ok(0) ends the input: the receiver sees the channel close.
            if !matches!(read, Ok(0)) && tx.send(read.map(|_| line)).is_err() {
                return;
            }
            if end {
                return;
            }
        }
    });
    rx
}

/// An operator's answer to a prompt before a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Go {
    /// Run the point.
    Run,
    /// Skip the point.
    Skip,
}

/// An operator's verdict after a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Keep the point; the output moved (Some(true)), did not (Some(false)), or unknown.
    Keep(Option<bool>),
    /// Run the point again.
    Redo,
}

impl Operator {
    /// An operator on this process's stdin.
    pub fn stdin(forced: bool, stop: Arc<AtomicBool>) -> Self {
        Self {
            forced,
            stop,
            lines: line_reader(Box::new(std::io::BufReader::new(std::io::stdin()))),
        }
    }

    /// An operator answering from `input` (tests).
    pub fn scripted(input: &'static [u8], forced: bool) -> Self {
        Self {
            forced,
            stop: Arc::new(AtomicBool::new(false)),
            lines: line_reader(Box::new(input)),
        }
    }

    /// Whether Ctrl-C was pressed.
    pub fn interrupted(&self) -> bool {
        self.stop.load(Ordering::SeqCst)
    }

    /// Asks `question` (on stderr) and returns the trimmed, lower-case answer; the end of
    /// the input or Ctrl-C is an interruption.
    pub fn ask(&mut self, question: &str) -> Result<String, RigError> {
        use std::sync::mpsc::RecvTimeoutError;
        eprint!("{question} ");
        loop {
            if self.interrupted() {
                eprintln!();
                return Err(interrupted());
            }
            match self.lines.recv_timeout(Duration::from_millis(20)) {
                Ok(line) => return Ok(line?.trim().to_lowercase()),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    eprintln!();
                    return Err(RigError::Operator(
                        "the operator's input ended (stdin closed): stopped, the gear is locked"
                            .into(),
                    ));
                }
            }
        }
    }

    /// Before a point: Enter runs it, `s` skips it.
    pub fn before(&mut self, question: &str) -> Result<Go, RigError> {
        loop {
            match self
                .ask(&format!("{question}, then Enter (s: skip this point)"))?
                .as_str()
            {
                "" => return Ok(Go::Run),
                "s" | "skip" => return Ok(Go::Skip),
                other => eprintln!("  '{other}': press Enter to run the point, or s to skip it"),
            }
        }
    }

    /// After a point: did the output move (asked only when `ask_moved`), or redo it.
    pub fn after(&mut self, summary: &str, ask_moved: bool) -> Result<Verdict, RigError> {
        loop {
            let q = if ask_moved {
                format!("{summary}: did the output move? [y/n] (r: redo the point)")
            } else {
                format!("{summary}: Enter keeps it (r: redo the point)")
            };
            match (self.ask(&q)?.as_str(), ask_moved) {
                ("r" | "redo", _) => return Ok(Verdict::Redo),
                ("y" | "yes", true) => return Ok(Verdict::Keep(Some(true))),
                ("n" | "no", true) => return Ok(Verdict::Keep(Some(false))),
                ("", false) => return Ok(Verdict::Keep(None)),
                (other, _) => eprintln!("  '{other}': answer y, n or r"),
            }
        }
    }

    /// A yes/no question.
    pub fn yes_no(&mut self, question: &str) -> Result<bool, RigError> {
        loop {
            match self.ask(&format!("{question} [y/n]"))?.as_str() {
                "y" | "yes" => return Ok(true),
                "n" | "no" => return Ok(false),
                other => eprintln!("  '{other}': answer y or n"),
            }
        }
    }
}

/// On a virtual rig, raises the release limit (`max_release_load_nm`, the paper's
/// calibration has 1.0 N m) above `top_nm`, up to the board's cap, so the paper's heavier loads can be released; a
/// real rig's limit is the operator's to set (`rig calibration set`).
pub fn allow_load<B: Bench + ?Sized>(bench: &mut B, top_nm: f64) -> Result<(), RigError> {
    if !bench.is_virtual() {
        return Ok(());
    }
    let mut cal = bench.calibration()?;
    // Never above the board's cap (the gear's tooth strength): the firmware refuses that, and
    // the core allows estimate noise around the cap itself.
    let wanted = (1.25 * top_nm).min(model::BoardLimits::PAPER.max_release_load_nm);
    if f64::from(cal.max_release_load_nm) < wanted {
        cal.max_release_load_nm = wanted as f32;
        bench.ack(&Request::SetParameters(cal))?;
    }
    Ok(())
}

/// The virtual rig's stored record releases the paper's heaviest load with room for the
/// estimate's noise (as the simulator's own sweep does): a record stored in flash is taken
/// as it is, where `SetParameters` would refuse a limit above the board's cap.
pub fn virtual_release_limit(config: &mut sim::SimConfig) {
    let wanted = (1.25 * model::paper::TAU_ROT_MAX) as f32;
    let limit = &mut config.calibration.max_release_load_nm;
    *limit = limit.max(wanted);
}

/// The error for Ctrl-C during a procedure.
pub fn interrupted() -> RigError {
    RigError::Operator(format!(
        "interrupted ({}): the gear is locked",
        crate::signals::interrupt_name()
    ))
}
