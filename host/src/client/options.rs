//! How the client talks to the device, and what it reports about the link and the faults.

use std::time::Duration;

use protocol::FaultFlags;
use protocol::session::{SessionConfig, SessionStats};

/// How the client talks to the device.
#[derive(Debug, Clone)]
pub struct ClientOptions {
    /// The port's name, for messages (`/dev/ttyACM0`, `virtual device on /dev/pts/3`).
    pub port_name: String,
    /// How long to wait for a reply before trying again, wall clock.
    pub reply_timeout: Duration,
    /// Extra tries of a request that is safe to repeat ([`protocol::Request::retry_safe`]).
    pub retries: u32,
    /// Device seconds per wall-clock second: 1 for hardware, the `--speed` of the virtual
    /// device. Heartbeats are sent this much more often.
    pub time_scale: f64,
}

impl ClientOptions {
    /// Defaults for a hardware port called `port_name`: 500 ms replies, 2 retries.
    pub fn new(port_name: impl Into<String>) -> Self {
        Self {
            port_name: port_name.into(),
            reply_timeout: Duration::from_millis(500),
            retries: 2,
            time_scale: 1.0,
        }
    }

    /// The session's waiting and retrying.
    pub(super) fn session_config(&self) -> SessionConfig {
        SessionConfig {
            reply_timeout: self.reply_timeout,
            retries: self.retries,
        }
    }

    /// Wall-clock time between heartbeats: the protocol's interval in device time.
    pub(super) fn heartbeat_interval(&self) -> Duration {
        let device_s = f64::from(protocol::HEARTBEAT_INTERVAL_MS) / 1000.0;
        crate::limits::wall_duration(device_s, self.time_scale.max(1e-3))
    }
}

/// Faults as the device reports them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultStatus {
    /// Faults whose condition is present now.
    pub active: FaultFlags,
    /// Faults latched since the last clear (the motor stays off while any is latched).
    pub latched: FaultFlags,
}

/// Counters of the link since the client was made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct LinkStats {
    /// Frames decoded.
    pub frames_ok: u32,
    /// Frames dropped by the deframer (CRC, framing, overflow, unknown layout).
    pub frame_errors: u32,
    /// Device frames that never arrived (gaps in the device's frame numbers: its queue was
    /// full, or the line lost them).
    pub frames_lost: u32,
    /// Replies that matched no pending request (late answers to a timed-out try).
    pub stale_replies: u32,
    /// Requests sent again after a timeout.
    pub retries: u32,
    /// Heartbeats sent.
    pub heartbeats: u32,
    /// Telemetry samples missing from the stream (gaps in the sample counter).
    pub telemetry_lost: u64,
    /// Bytes received from the device.
    pub bytes_in: u64,
}

impl From<SessionStats> for LinkStats {
    fn from(s: SessionStats) -> Self {
        Self {
            frames_ok: s.frames_ok,
            frame_errors: s.frame_errors,
            frames_lost: s.frames_lost,
            stale_replies: s.stale_replies,
            retries: s.retries,
            heartbeats: s.heartbeats,
            telemetry_lost: s.telemetry_lost,
            bytes_in: s.bytes_in,
        }
    }
}
