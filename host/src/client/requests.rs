//! The typed requests: identity, faults, release and open loop with their heartbeats, the
//! rig parameters, telemetry, and the unsolicited messages.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use protocol::session::{Session, hello_outcome};
use protocol::{
    DeviceInfo, DeviceMessage, FaultFlags, NackCode, Reply, Request, RigParameters, TelemetrySample,
};

use super::{Client, FaultStatus, advice};
use crate::RigError;

impl<T: Read + Write> Client<T> {
    /// Says `Hello` and checks the versions (the device's `time_scale` then sets
    /// [`ClientOptions::time_scale`](super::ClientOptions::time_scale), so heartbeats keep
    /// pace with a virtual rig served faster than real time): a device of another protocol version or
    /// schema is refused with what to update.
    pub fn hello(&mut self) -> Result<DeviceInfo, RigError> {
        let hello = Session::hello();
        let reply = self.exchange(&hello)?;
        match hello_outcome(&reply) {
            Some(Ok(info)) => {
                if info.time_scale.is_finite() && info.time_scale > 0.0 {
                    self.opts.time_scale = f64::from(info.time_scale);
                }
                Ok(info.clone())
            }
            Some(Err(e)) => Err(advice::version_error(e)),
            None => match reply {
                Reply::Nack(code) => Err(advice::refused(&hello, code)),
                other => Err(advice::unexpected(&hello, &other, &self.opts.port_name)),
            },
        }
    }

    /// Device identity and versions.
    pub fn info(&mut self) -> Result<DeviceInfo, RigError> {
        match self.request(&Request::GetInfo)? {
            Reply::Info(info) => Ok(info),
            other => Err(advice::unexpected(
                &Request::GetInfo,
                &other,
                &self.opts.port_name,
            )),
        }
    }

    /// Active and latched faults.
    pub fn faults(&mut self) -> Result<FaultStatus, RigError> {
        self.faults_request(&Request::GetFaults)
    }

    /// Clears the latched faults whose condition is gone; returns what remains.
    pub fn clear_faults(&mut self) -> Result<FaultStatus, RigError> {
        self.faults_request(&Request::ClearFaults)
    }

    fn faults_request(&mut self, req: &Request) -> Result<FaultStatus, RigError> {
        match self.request(req)? {
            Reply::Faults { active, latched } => Ok(FaultStatus { active, latched }),
            other => Err(advice::unexpected(req, &other, &self.opts.port_name)),
        }
    }

    /// Starts (`on`) vibration at `target_hz`, or stops it. While on, the client keeps the
    /// release alive with heartbeats during every wait.
    ///
    /// A device still measuring its current sensor's zero (the first ~100 ms after boot or a
    /// re-zero) refuses a drive with `CurrentZeroPending`; the client asks again until it is
    /// accepted, for at most [`sim::riglink::ZERO_WAIT_S`] of the device's time.
    pub fn release(&mut self, on: bool, target_hz: f32) -> Result<(), RigError> {
        self.drive(&Request::Release {
            on,
            target_hz,
            session: 0,
        })
    }

    /// Drives the vibrator with a fixed voltage `volts` (open loop, for calibration); 0
    /// stops it. Kept alive by heartbeats like a release; waits for the current zero as
    /// [`Client::release`] does.
    pub fn open_loop(&mut self, volts: f32) -> Result<(), RigError> {
        self.drive(&Request::OpenLoop { volts, session: 0 })
    }

    /// Sends a drive request and requires an `Ack`, asking again while the device refuses
    /// it with `CurrentZeroPending`, as the scenarios' [`sim::riglink::drive`] does (every
    /// [`sim::riglink::ZERO_RETRY_S`] of device time, for at most
    /// [`sim::riglink::ZERO_WAIT_S`]); then that refusal stands, with its reason.
    ///
    /// Heartbeats as [`sim::riglink::heartbeated`] sends them: from the moment a drive that
    /// starts is sent, on while it runs, off once it stops or is refused.
    fn drive(&mut self, req: &Request) -> Result<(), RigError> {
        sim::riglink::heartbeated(
            self,
            req,
            |c, on| c.set_keep_alive(on),
            |c| c.drive_once(req),
        )
    }

    fn drive_once(&mut self, req: &Request) -> Result<(), RigError> {
        use sim::riglink::{ZERO_RETRY_S, ZERO_WAIT_S};
        let scale = self.opts.time_scale;
        let give_up =
            crate::limits::deadline_after(crate::limits::wall_duration(ZERO_WAIT_S, scale));
        loop {
            match self.ack(req) {
                Err(e)
                    if e.refusal() == Some(NackCode::CurrentZeroPending)
                        && Instant::now() < give_up =>
                {
                    self.pause(crate::limits::wall_duration(ZERO_RETRY_S, scale))?;
                }
                done => return done,
            }
        }
    }

    /// Sends one heartbeat and waits for its `Ack`.
    pub fn heartbeat(&mut self) -> Result<(), RigError> {
        self.ack(&Request::Heartbeat { session: 0 })
    }

    /// Whether the client is keeping a release (or open-loop drive) alive.
    pub fn keeping_alive(&self) -> bool {
        self.session.keeping_alive()
    }

    /// Starts sending heartbeats during every wait (after a release sent with
    /// [`Client::request`]).
    pub fn start_keep_alive(&mut self) {
        self.set_keep_alive(true);
    }

    /// Stops sending heartbeats (the device stops at its comms timeout).
    pub fn stop_keep_alive(&mut self) {
        self.set_keep_alive(false);
    }

    fn set_keep_alive(&mut self, on: bool) {
        let every = on.then(|| self.opts.heartbeat_interval());
        let now = self.now();
        self.session.keep_alive(every, now);
    }

    /// The rig parameters (calibration record) the device uses.
    pub fn calibration(&mut self) -> Result<RigParameters, RigError> {
        match self.request(&Request::GetParameters)? {
            Reply::Parameters(p) => Ok(p),
            other => Err(advice::unexpected(
                &Request::GetParameters,
                &other,
                &self.opts.port_name,
            )),
        }
    }

    /// Validates `params` here, then has the device validate, store and activate them; a
    /// refusal names the field.
    pub fn set_calibration(&mut self, params: &RigParameters) -> Result<(), RigError> {
        params.validate().map_err(|e| RigError::BadValue {
            what: "calibration".into(),
            why: e.to_string(),
        })?;
        self.ack(&Request::SetParameters(*params))
    }

    /// Starts the telemetry stream at `rate_hz` samples per device second (and the health
    /// sample once a second).
    pub fn start_telemetry(&mut self, rate_hz: u16) -> Result<(), RigError> {
        self.session.restart_telemetry_count();
        self.ack(&Request::StartTelemetry { rate_hz })
    }

    /// Stops the telemetry stream and drops queued samples.
    pub fn stop_telemetry(&mut self) -> Result<(), RigError> {
        self.ack(&Request::StopTelemetry)?;
        self.discard_telemetry();
        Ok(())
    }

    /// Drops the telemetry samples received but not yet taken (after a change, to read
    /// only what follows it).
    pub fn discard_telemetry(&mut self) {
        self.inbox
            .retain(|m| !matches!(m, DeviceMessage::Telemetry(_)));
    }

    /// Fault events received so far (flags that rose, device time in µs); taking them
    /// empties the list.
    pub fn take_fault_events(&mut self) -> Vec<(FaultFlags, u64)> {
        std::mem::take(&mut self.fault_events)
    }

    /// The next unsolicited message (telemetry, health, capture data, fault event),
    /// waiting up to `timeout`; heartbeats continue meanwhile.
    pub fn recv(&mut self, timeout: Duration) -> Result<Option<DeviceMessage>, RigError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(msg) = self.inbox.pop_front() {
                return Ok(Some(msg));
            }
            self.pump()?;
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    /// The next telemetry sample, waiting up to `timeout`. Other unsolicited messages are
    /// dropped (fault events stay in [`Client::take_fault_events`]).
    pub fn next_telemetry(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<TelemetrySample>, RigError> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv(left)? {
                Some(DeviceMessage::Telemetry(t)) => return Ok(Some(t)),
                Some(_) => continue,
                None => return Ok(None),
            }
        }
    }

    /// Reads what has arrived and sends a heartbeat if one is due, without waiting.
    pub fn tick(&mut self) -> Result<(), RigError> {
        self.pump()
    }
}
