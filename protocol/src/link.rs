//! Link parameters both sides must agree on: serial settings and session timing.

/// UART baud rate both sides use by default (8N1).
pub const DEFAULT_BAUD_RATE: u32 = 921_600;

/// Highest telemetry rate the device accepts in `StartTelemetry`, Hz.
pub const MAX_TELEMETRY_RATE_HZ: u16 = 1000;

/// A release lapses (vibration stops) when no accepted request arrives for this long, ms.
pub const COMMS_TIMEOUT_MS: u32 = 500;

/// How often the host sends `Heartbeat` while a release is live, ms.
pub const HEARTBEAT_INTERVAL_MS: u32 = 150;

// Two heartbeats may be lost in a row without dropping the load.
const _: () = assert!(3 * HEARTBEAT_INTERVAL_MS < COMMS_TIMEOUT_MS);
