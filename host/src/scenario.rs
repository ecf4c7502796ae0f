//! The real rig's side of the shared scenarios: [`DeviceLink`], a [`sim::RigLink`] over the
//! serial client, so the scenarios of [`sim::riglink`] run on a real rig as on the virtual one.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use protocol::{DeviceMessage, Reply, Request, SupervisorState};
use sim::RigLink;

use crate::RigError;
use crate::client::Client;

/// A real rig's session: the client plus the newest telemetry state.
pub struct DeviceLink<T: Read + Write> {
    /// The client.
    pub client: Client<T>,
    last_state: Option<SupervisorState>,
}

impl<T: Read + Write> DeviceLink<T> {
    /// Wraps a connected client.
    pub fn new(client: Client<T>) -> Self {
        Self {
            client,
            last_state: None,
        }
    }
}

impl<T: Read + Write> RigLink for DeviceLink<T> {
    type Error = RigError;

    fn request(&mut self, req: &Request) -> Result<Reply, RigError> {
        self.client.request(req)
    }

    fn keep_alive(&mut self, on: bool) {
        if on {
            self.client.start_keep_alive();
        } else {
            self.client.stop_keep_alive();
        }
    }

    fn wait(&mut self, seconds: f64) -> Result<(), RigError> {
        // A virtual device may run faster than real time.
        let scale = self.client.options().time_scale.max(1e-9);
        let deadline = Instant::now() + Duration::from_secs_f64((seconds / scale).max(0.0));
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(());
            }
            if let Some(DeviceMessage::Telemetry(t)) = self.client.recv(left)? {
                self.last_state = Some(t.state);
            }
        }
    }

    fn state(&mut self) -> Result<SupervisorState, RigError> {
        if let Some(t) = self.client.next_telemetry(Duration::from_millis(200))? {
            self.last_state = Some(t.state);
        }
        self.last_state
            .ok_or_else(|| RigError::Protocol("the rig sends no telemetry".into()))
    }
}
