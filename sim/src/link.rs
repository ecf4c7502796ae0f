//! A host-side session with a [`SimRig`] over the real wire format: requests are encoded
//! into frames, fed to the firmware's protocol server, and its replies deframed, all in
//! virtual time (the host side of a software-in-the-loop run).

use protocol::{DeviceDeframer, DeviceMessage, Request, TelemetrySample};

use crate::SimError;
use crate::SimRig;

/// Longest a reply may take in virtual time, s.
const REPLY_TIMEOUT_S: f64 = 0.5;
/// Virtual time per polling step while waiting, s.
const POLL_S: f64 = 0.001;

/// A virtual-time host session with a simulated rig.
pub struct SimLink {
    /// The rig.
    pub rig: SimRig,
    deframer: DeviceDeframer,
    seq: u16,
    rx: Vec<u8>,
    /// The newest telemetry sample seen.
    pub last_telemetry: Option<TelemetrySample>,
    /// Unsolicited messages (fault events, capture chunks) in arrival order.
    pub events: Vec<DeviceMessage>,
    heartbeat_every_s: Option<f64>,
    since_heartbeat: f64,
}

/// `steps` of `step_s` in seconds as a person writes them: 304 steps of 1 ms are 0.304 s,
/// not the 0.3040000000000002 that adding 0.001 up gives.
fn steps_to_s(steps: u32, step_s: f64) -> f64 {
    let per_s = 1.0 / step_s;
    if (per_s - per_s.round()).abs() < 1e-9 {
        f64::from(steps) / per_s.round()
    } else {
        f64::from(steps) * step_s
    }
}

impl SimLink {
    /// Opens a session on `rig`.
    pub fn new(rig: SimRig) -> Self {
        Self {
            rig,
            deframer: DeviceDeframer::new(),
            seq: 0,
            rx: Vec::new(),
            last_telemetry: None,
            events: Vec::new(),
            heartbeat_every_s: None,
            since_heartbeat: 0.0,
        }
    }

    /// Sends `req` and waits (in virtual time) for the reply with its sequence number.
    pub fn request(&mut self, req: &Request) -> Result<DeviceMessage, SimError> {
        self.seq = self.seq.wrapping_add(1);
        let seq = self.seq;
        let frame =
            protocol::encode_frame_vec(seq, req).map_err(|e| SimError::Protocol(e.to_string()))?;
        self.rig.to_device(&frame);
        let mut waited = 0.0;
        while waited < REPLY_TIMEOUT_S {
            self.rig.advance(POLL_S);
            waited += POLL_S;
            if let Some(reply) = self.pump(Some(seq)) {
                return Ok(reply);
            }
        }
        Err(SimError::Protocol(format!(
            "the simulated device did not answer {} within {REPLY_TIMEOUT_S} s",
            crate::names::request_name(req)
        )))
    }

    /// Keeps a release alive: a heartbeat every `interval_s` while [`Self::wait`] runs
    /// (`None` stops sending them, as a host that lost its link).
    pub fn keep_alive(&mut self, interval_s: Option<f64>) {
        self.heartbeat_every_s = interval_s;
        self.since_heartbeat = 0.0;
    }

    /// Lets `seconds` of virtual time pass, collecting telemetry and events and sending
    /// heartbeats when asked to.
    pub fn wait(&mut self, seconds: f64) {
        let mut left = seconds;
        while left > 1e-12 {
            let dt = left.min(0.01);
            self.rig.advance(dt);
            left -= dt;
            self.since_heartbeat += dt;
            if let Some(every) = self.heartbeat_every_s
                && self.since_heartbeat >= every
            {
                self.since_heartbeat = 0.0;
                self.seq = self.seq.wrapping_add(1);
                if let Ok(frame) = protocol::encode_frame_vec(self.seq, &Request::Heartbeat) {
                    self.rig.to_device(&frame);
                }
            }
            self.pump(None);
        }
    }

    /// Lets time pass until `done` holds or `limit_s` elapses; returns the time waited.
    pub fn wait_until(
        &mut self,
        limit_s: f64,
        step_s: f64,
        mut done: impl FnMut(&SimLink) -> bool,
    ) -> Option<f64> {
        let mut waited = 0.0;
        let mut steps = 0u32;
        while waited <= limit_s {
            if done(self) {
                return Some(steps_to_s(steps, step_s));
            }
            self.wait(step_s);
            waited += step_s;
            steps += 1;
        }
        None
    }

    /// Deframes what the device sent; returns the reply to `want` if it came.
    fn pump(&mut self, want: Option<u16>) -> Option<DeviceMessage> {
        self.rig.from_device(&mut self.rx);
        let bytes = std::mem::take(&mut self.rx);
        let mut reply = None;
        let (events, telemetry) = (&mut self.events, &mut self.last_telemetry);
        self.deframer.push(&bytes, |frame| {
            let Ok(frame) = frame else { return };
            match frame.msg {
                DeviceMessage::Telemetry(t) => *telemetry = Some(t),
                msg @ (DeviceMessage::FaultEvent { .. }
                | DeviceMessage::CaptureChunk(_)
                | DeviceMessage::CaptureDone { .. }) => events.push(msg),
                // Ack and Nack name the request they answer; others' are stale.
                msg @ (DeviceMessage::Ack { seq } | DeviceMessage::Nack { seq, .. })
                    if Some(seq) == want =>
                {
                    reply = Some(msg)
                }
                DeviceMessage::Ack { .. } | DeviceMessage::Nack { .. } => {}
                // Data replies carry the device's own frame number: with one request
                // outstanding, the next one is the answer.
                msg if want.is_some() => reply = Some(msg),
                _ => {}
            }
        });
        reply
    }
}
