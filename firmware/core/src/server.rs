//! The protocol server: every [`Request`] gets exactly one [`Reply`] carrying the request's
//! frame `seq` (`SetParameters`' comes after the flash write).
//!
//! Garbled frames are counted by the deframer and otherwise ignored; an intact frame of an
//! unknown message is refused with `UnknownMessage`, one of a known request with a field
//! out of its type's range (a bool of 2) with `BadArgument`. A request that arrives while
//! [`protocol::REQUEST_WINDOW`] replies still wait in the transmit queue is refused with
//! `Busy` and has no effect. A value the device cannot use exactly is refused with
//! `BadArgument`, never replaced by a nearby one. Only the drive owner's accepted drive
//! requests (`Release`, `OpenLoop`, `Heartbeat` carrying its session, answered but not with
//! a `Nack`) refresh the release heartbeat: a stream of refused requests, undecodable
//! frames or another process's requests must not keep the motor vibrating. `Simulation` commands are for the
//! virtual rig: [`Core::receive`] refuses them with `SimulationOnly`, and the simulator
//! serves them through [`Core::receive_with`].

use protocol::{
    DeviceInfo, DeviceMessage, Error, FaultFlags, FirmwareVersion, Frame, HelloAnswer,
    LegacyV1Nack, MAX_TELEMETRY_RATE_HZ, NackCode, PROTOCOL_VERSION, ParametersStatus,
    REQUEST_WINDOW, Reply, Request, RigParameters, SCHEMA_HASH, SimCommand, SupervisorState,
    hello_answer,
};

use crate::config::CoreConfig;
use crate::controller::{Core, Derived, Persist, Streams, check_board_caps};
use crate::current::CurrentSense;
use crate::faults::FaultMonitor;
use crate::release::{self, DriveAnswer, DriveLimits};

/// This firmware's version, from the crate version.
pub const FIRMWARE_VERSION: FirmwareVersion = parse_version(env!("CARGO_PKG_VERSION"));

/// `major.minor.patch` (anything after a `-` or `+` ignored) as a [`FirmwareVersion`].
const fn parse_version(text: &str) -> FirmwareVersion {
    let bytes = text.as_bytes();
    let mut parts = [0u8; 3];
    let (mut part, mut i) = (0, 0);
    while i < bytes.len() && part < 3 {
        match bytes[i] {
            b'.' => part += 1,
            b @ b'0'..=b'9' => parts[part] = parts[part] * 10 + (b - b'0'),
            _ => break,
        }
        i += 1;
    }
    FirmwareVersion {
        major: parts[0],
        minor: parts[1],
        patch: parts[2],
    }
}

/// How a request is answered.
enum Answer {
    /// This reply, now.
    Now(Reply),
    /// After the flash write (`SetParameters`); see [`crate::Core::persist_result`].
    Later,
    /// A protocol v1 host's `Hello`: v1's own refusal, which it can decode.
    LegacyV1Nack,
}

impl Answer {
    const fn nack(code: NackCode) -> Self {
        Self::Now(Reply::Nack(code))
    }
}

impl Core {
    /// Takes bytes from the host link, in chunks of any size, and answers complete
    /// requests. `Simulation` commands are refused with `SimulationOnly`.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) {
        self.receive_with(now_us, bytes, |_| Err(NackCode::SimulationOnly));
    }

    /// As [`Core::receive`], with `simulation` serving `Request::Simulation` commands (the
    /// virtual rig acts on its plant): `Ok` is acknowledged, `Err(code)` refused. Its
    /// answer goes out in order with the other replies, under the device's frame numbers.
    pub fn receive_with(
        &mut self,
        now_us: u64,
        bytes: &[u8],
        mut simulation: impl FnMut(SimCommand) -> Result<(), NackCode>,
    ) {
        for &byte in bytes {
            match self.deframer.push_byte(byte) {
                Some(Ok(Frame { seq, msg })) => {
                    if self.tx.queued_replies() >= REQUEST_WINDOW {
                        // Beyond the window: refused before it acts.
                        self.answer(seq, Answer::nack(NackCode::Busy));
                        continue;
                    }
                    let answer = match msg {
                        // An operator's action on the virtual rig, allowed in a fault hold.
                        Request::Simulation(command) => match simulation(command) {
                            Ok(()) => Answer::Now(Reply::Ack),
                            Err(code) => Answer::nack(code),
                        },
                        other => self.handle(now_us, seq, other),
                    };
                    // Any accepted request keeps the continuous stream alive, and confirms
                    // the link's rate after a switch.
                    if matches!(answer, Answer::Now(ref r) if !matches!(r, Reply::Nack(_)))
                        || matches!(answer, Answer::Later)
                    {
                        self.stream.refresh(now_us);
                        self.link.confirmed();
                    }
                    self.answer(seq, answer);
                }
                Some(Err(Error::Decode { seq: Some(seq) })) => {
                    let known = self
                        .deframer
                        .last_body()
                        .is_some_and(Request::names_known_request);
                    let code = if self.tx.queued_replies() >= REQUEST_WINDOW {
                        NackCode::Busy
                    } else if known {
                        NackCode::BadArgument
                    } else {
                        NackCode::UnknownMessage
                    };
                    self.answer(seq, Answer::nack(code));
                }
                // Counted in the deframer's stats; nothing to answer.
                Some(Err(_)) | None => {}
            }
        }
    }

    /// Sends the answer to request `seq` (an accepted drive request of the drive's owner
    /// refreshed the heartbeat in [`Core::handle`]).
    fn answer(&mut self, seq: u16, answer: Answer) {
        match answer {
            Answer::Now(reply) => self.send_reply(seq, reply),
            Answer::Later => {}
            Answer::LegacyV1Nack => {
                self.tx.push_reply(&LegacyV1Nack { hello_seq: seq });
            }
        }
    }

    /// Queues `reply` to the request with frame sequence number `seq`.
    pub(crate) fn send_reply(&mut self, seq: u16, reply: Reply) {
        self.tx.push_reply(&DeviceMessage::reply(seq, reply));
    }

    fn info(&self, now_us: u64) -> DeviceInfo {
        DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
            firmware_version: FIRMWARE_VERSION,
            firmware_build: truncated(self.firmware_build),
            board: truncated(self.config.board_name),
            parameters_status: self.parameters_status,
            reset_cause: self.reset_cause,
            uptime_s: whole_seconds(now_us),
            capabilities: self.config.capabilities,
            time_scale: self.config.time_scale,
            max_baud: self.config.max_baud,
        }
    }

    fn faults_reply(&self) -> Reply {
        faults_reply(&self.faults, self.active_faults())
    }

    fn motor_idle(&self) -> bool {
        matches!(
            self.supervisor.state(),
            SupervisorState::Locked | SupervisorState::Fault
        )
    }

    /// What `Release` and `OpenLoop` are checked against now.
    fn drive_limits(&self) -> DriveLimits {
        let s = self.config.supervisor;
        DriveLimits {
            min_hz: s.min_freq_hz,
            // Up to the parameters' own limit (at most the board's): never clamped to it.
            max_hz: s.max_freq_hz.min(self.derived.max_hz),
            max_volts: self.config.supply_v * self.config.motor.max_duty,
            locked: !self.faults.latched().is_empty()
                || self.parameters_status == ParametersStatus::Invalid,
            zero_pending: !self.zero_ready(),
        }
    }

    /// Answers `msg`: the fault hold first, then each request by a plain function of the
    /// state it acts on.
    fn handle(&mut self, now: u64, seq: u16, msg: Request) -> Answer {
        // Status, clearing and locking (the safe direction) are never held off.
        let status_or_clear = matches!(
            msg,
            Request::Hello { .. }
                | Request::GetInfo
                | Request::GetFaults
                | Request::ClearFaults
                | Request::Release { on: false, .. }
        ) || matches!(msg, Request::OpenLoop { volts, .. } if volts == 0.0);
        if !status_or_clear && self.faults.in_hold(now) {
            return Answer::nack(NackCode::InFaultHold);
        }
        match msg {
            Request::Hello {
                protocol_version,
                schema_hash,
            } => hello(protocol_version, schema_hash, self.info(now)),
            Request::GetInfo => Answer::Now(Reply::Info(self.info(now))),
            Request::Release {
                on,
                target_hz,
                session,
            } => {
                let limits = self.drive_limits();
                let answer = release::release(&mut self.release, &limits, on, target_hz, session);
                self.release.beat(now, session, answer.is_ok());
                answer.into()
            }
            Request::OpenLoop { volts, session } => {
                let limits = self.drive_limits();
                let answer = release::open_loop(&mut self.release, &limits, volts, session);
                self.release.beat(now, session, answer.is_ok());
                answer.into()
            }
            Request::Heartbeat { session } => {
                self.release.beat(now, session, true);
                Answer::Now(Reply::Ack)
            }
            Request::GetParameters => Answer::Now(Reply::Parameters(self.parameters)),
            Request::SetParameters(parameters) => {
                let idle = self.motor_idle();
                set_parameters(&mut self.persist, idle, &self.config, parameters, seq)
            }
            Request::StartTelemetry { rate_hz } => {
                start_telemetry(&mut self.streams, self.config.control_hz, rate_hz)
            }
            Request::StopTelemetry => {
                self.streams.stop();
                Answer::Now(Reply::Ack)
            }
            Request::StartCapture {
                sample_rate_hz,
                samples,
            } => {
                let adc_hz = self.config.sample_rate_hz();
                match self.capture.start(sample_rate_hz, samples, adc_hz) {
                    Ok(_) => Answer::Now(Reply::Ack),
                    Err(code) => Answer::nack(code),
                }
            }
            Request::StartStream { rate_hz } => {
                match crate::stream::stream_decimation(self.config.sample_rate_hz(), rate_hz) {
                    Ok(decimation) => {
                        // The link must carry it beside the telemetry running.
                        let telemetry_hz = match self.streams.telemetry_period {
                            0 => 0,
                            period => {
                                u16::try_from(self.config.control_hz / period).unwrap_or(u16::MAX)
                            }
                        };
                        match protocol::stream_rate_for_link(rate_hz, telemetry_hz, self.link.baud)
                        {
                            Some(fits) if fits == rate_hz => {
                                self.stream.start(rate_hz, decimation, now);
                                Answer::Now(Reply::Ack)
                            }
                            Some(fits_hz) => Answer::nack(NackCode::StreamRate { fits_hz }),
                            None => Answer::nack(NackCode::BadArgument),
                        }
                    }
                    Err(code) => Answer::nack(code),
                }
            }
            Request::SetBaud { baud } => {
                if baud == protocol::DEFAULT_BAUD_RATE || baud == self.config.max_baud {
                    self.link.pending = Some(baud);
                    Answer::Now(Reply::Ack)
                } else {
                    Answer::nack(NackCode::BadArgument)
                }
            }
            Request::StopStream => {
                self.stream.stop();
                Answer::Now(Reply::Ack)
            }
            Request::GetFaults => Answer::Now(self.faults_reply()),
            Request::ClearFaults => {
                let active = self.active_faults();
                clear_faults(&mut self.faults, active)
            }
            Request::RezeroCurrent => {
                let idle = self.motor_idle();
                rezero_current(&mut self.current, idle)
            }
            // Served in `receive_with`; listed so a new request fails to compile here.
            Request::Simulation(_) => Answer::nack(NackCode::SimulationOnly),
            // `Request` is non-exhaustive: a newer host's request this firmware lacks.
            _ => Answer::nack(NackCode::UnknownMessage),
        }
    }
}

impl From<DriveAnswer> for Answer {
    fn from(answer: DriveAnswer) -> Self {
        match answer {
            Ok(reply) => Self::Now(reply),
            Err(code) => Self::nack(code),
        }
    }
}

/// `Hello`: the device's `Info` when the host speaks this protocol, v1's own refusal to a
/// v1 host, `VersionMismatch` otherwise.
fn hello(protocol_version: u16, schema_hash: u32, info: DeviceInfo) -> Answer {
    match hello_answer(protocol_version, schema_hash) {
        HelloAnswer::Info => Answer::Now(Reply::Info(info)),
        HelloAnswer::LegacyV1Nack => Answer::LegacyV1Nack,
        HelloAnswer::VersionMismatch => Answer::nack(NackCode::VersionMismatch {
            device_protocol: PROTOCOL_VERSION,
            device_schema_hash: SCHEMA_HASH,
        }),
    }
}

/// `SetParameters`: only with the motor idle and no write under way; a record that passes
/// the checks goes to flash, and is made active and acknowledged once the binary reports
/// the write (`Core::persist_result`).
fn set_parameters(
    persist: &mut Persist,
    motor_idle: bool,
    config: &CoreConfig,
    parameters: RigParameters,
    seq: u16,
) -> Answer {
    if !motor_idle || *persist != Persist::Idle {
        return Answer::nack(NackCode::Busy);
    }
    let checked = Derived::check(&parameters).and_then(|()| check_board_caps(&parameters, config));
    match checked {
        Err(rejection) => Answer::nack(NackCode::ParametersRejected(rejection)),
        Ok(()) => {
            *persist = Persist::Requested { parameters, seq };
            Answer::Later
        }
    }
}

/// `StartTelemetry`: exactly the rate asked, the control rate divided by a whole number, at
/// most `MAX_TELEMETRY_RATE_HZ`.
fn start_telemetry(streams: &mut Streams, control_hz: u32, rate_hz: u16) -> Answer {
    let rate = u32::from(rate_hz);
    if rate == 0
        || rate_hz > MAX_TELEMETRY_RATE_HZ
        || rate > control_hz
        || !control_hz.is_multiple_of(rate)
    {
        return Answer::nack(NackCode::BadArgument);
    }
    streams.start(control_hz / rate);
    Answer::Now(Reply::Ack)
}

/// `ClearFaults`: clears the latched faults whose condition (`active`) is gone.
fn clear_faults(faults: &mut FaultMonitor, active: FaultFlags) -> Answer {
    faults.clear(active);
    Answer::Now(faults_reply(faults, active))
}

/// The `Faults` reply.
fn faults_reply(faults: &FaultMonitor, active: FaultFlags) -> Reply {
    Reply::Faults {
        active,
        latched: faults.latched(),
    }
}

/// `RezeroCurrent`: a new current-sensor zero, only with the motor idle and no zeroing
/// under way.
fn rezero_current(current: &mut CurrentSense, motor_idle: bool) -> Answer {
    if motor_idle && !current.zeroing() {
        current.begin_zero();
        Answer::Now(Reply::Ack)
    } else {
        Answer::nack(NackCode::Busy)
    }
}

/// `text` cut to the string's capacity at a character boundary.
/// `now_us / 1_000_000`, saturating at `u32::MAX`. Long division in 12-bit digits: each
/// partial remainder times 2^12 stays within 32 bits (10^6 x 2^12 < 2^32), so the target
/// needs no 64-bit software division (about 1 KB of flash).
#[allow(
    clippy::cast_possible_truncation,
    reason = "masked to 12 bits before the cast"
)]
fn whole_seconds(now_us: u64) -> u32 {
    const US_PER_S: u32 = 1_000_000;
    let (mut q, mut r) = (0u64, 0u32);
    for digit in (0..6).rev() {
        let cur = (r << 12) | ((now_us >> (12 * digit)) & 0xFFF) as u32;
        q = (q << 12) | u64::from(cur / US_PER_S);
        r = cur % US_PER_S;
    }
    u32::try_from(q).unwrap_or(u32::MAX)
}

fn truncated<const N: usize>(text: &str) -> heapless::String<N> {
    let mut cut = text.len().min(N);
    while !text.is_char_boundary(cut) {
        cut -= 1;
    }
    let mut out = heapless::String::new();
    // Cannot fail: `cut` bytes fit the capacity.
    let _ = out.push_str(&text[..cut]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_seconds_is_the_division() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        let last_second = u64::from(u32::MAX) * 1_000_000 + 999_999;
        let edges = [0, 1, 999_999, 1_000_000, 1_000_001, last_second];
        let random = (0..10_000).map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x >> (x % 64)
        });
        for us in edges.into_iter().chain(random) {
            let want = u32::try_from(us / 1_000_000).unwrap_or(u32::MAX);
            assert_eq!(whole_seconds(us), want, "{us}");
        }
        assert_eq!(whole_seconds(last_second + 1), u32::MAX);
        assert_eq!(whole_seconds(u64::MAX), u32::MAX);
    }

    #[test]
    fn version_parses() {
        let v = parse_version("1.22.3-rc1");
        assert_eq!((v.major, v.minor, v.patch), (1, 22, 3));
        let v = FIRMWARE_VERSION;
        assert_eq!(
            format!("{v}"),
            env!("CARGO_PKG_VERSION").split('-').next().unwrap()
        );
    }

    #[test]
    fn long_names_are_cut_at_a_character() {
        let s: heapless::String<4> = truncated("abcdef");
        assert_eq!(s, "abcd");
        let s: heapless::String<4> = truncated("abcé");
        assert_eq!(s, "abc");
    }
}
