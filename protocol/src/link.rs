//! Link parameters both sides must agree on: serial settings and session timing.

/// UART baud rate both sides use by default (8N1).
pub const DEFAULT_BAUD_RATE: u32 = 921_600;

/// The fast link (issue 35): 4,000,000 Bd, exactly what the STM32G474's USART gives from its
/// 170 MHz clock with 8x oversampling (USARTDIV = 2 x 170 MHz / 4 Mbaud = 85). A host and a
/// device that both support it agree on it after `Hello` ([`crate::Request::SetBaud`],
/// [`crate::DeviceInfo::max_baud`]); otherwise, and whenever the switch fails, both run at
/// [`DEFAULT_BAUD_RATE`]. The Nucleo's ST-LINK V3 virtual COM port is documented for up to
/// 16 Mbaud; that it carries 4 Mbaud cleanly only a board can confirm.
pub const FAST_BAUD_RATE: u32 = 4_000_000;

/// After switching to a baud rate agreed by [`crate::Request::SetBaud`], a device that
/// accepts no request at the new rate within this long (device time) goes back to
/// [`DEFAULT_BAUD_RATE`], ms: a host that could not follow finds it there.
pub const BAUD_CONFIRM_MS: u32 = 1000;

/// Bits on the line per byte at 8N1: a start bit, eight data bits, a stop bit.
pub const UART_BITS_PER_BYTE: u32 = 10;

/// Bytes per second a UART at `baud` carries at 8N1 (92,160 at [`DEFAULT_BAUD_RATE`]): no
/// device sends faster, and a virtual rig paces its output to it.
pub const fn link_bytes_per_s(baud: u32) -> u32 {
    baud / UART_BITS_PER_BYTE
}

/// Highest telemetry rate the device accepts in `StartTelemetry`, Hz.
pub const MAX_TELEMETRY_RATE_HZ: u16 = 1000;

/// A release lapses (vibration stops) when no accepted request arrives for this long, ms.
pub const COMMS_TIMEOUT_MS: u32 = 500;

/// How often the host sends `Heartbeat` while a release is live, ms.
pub const HEARTBEAT_INTERVAL_MS: u32 = 150;

/// Requests a host may have outstanding (sent, reply not yet received) at once. The
/// device keeps room in its transmit queue for this many replies of the largest size, so
/// within the window every request is answered even while telemetry at 1 kHz and a capture
/// upload share the link; a request that arrives while this many replies still wait to be
/// sent is answered `Nack(Busy)` and has no effect. A host's heartbeats count.
pub const REQUEST_WINDOW: usize = 4;

/// After a fault rises, requests other than `Hello`, `GetInfo`, `GetFaults`, `ClearFaults`
/// and the locks (`Release { on: false }`, `OpenLoop { volts: 0 }`) are refused with
/// `Nack(InFaultHold)` for this long, ms (device time), whether or not the fault is cleared
/// meanwhile: a host cannot restart the motor into a fault that is still settling.
pub const FAULT_HOLD_MS: u32 = 500;

// Two heartbeats may be lost in a row without dropping the load.
const _: () = assert!(3 * HEARTBEAT_INTERVAL_MS < COMMS_TIMEOUT_MS);
