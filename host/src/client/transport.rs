//! Byte transports the [`super::Client`] runs over: a serial port (hardware or the
//! virtual device's pseudo-terminal) and an in-memory pipe for unit tests.
//!
//! Both follow serialport's read convention: a read with nothing to deliver waits up to the
//! transport's timeout, then fails with [`std::io::ErrorKind::TimedOut`].

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use serialport::SerialPort;

use crate::RigError;

/// How long one read of a serial port waits for bytes: short, so wait loops can keep the
/// heartbeat going between reads.
pub const SERIAL_READ_TIMEOUT: Duration = Duration::from_millis(2);

/// An open serial port.
pub type SerialTransport = Box<dyn SerialPort>;

/// Opens `port` at `baud` (8N1, no flow control) for the client, and drops anything the
/// port buffered before.
pub fn open_serial(port: &str, baud: u32) -> Result<SerialTransport, RigError> {
    let opened = serialport::new(port, baud)
        .timeout(SERIAL_READ_TIMEOUT)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .open();
    let serial = opened.map_err(|e| port_open_error(port, baud, &e))?;
    // A stale byte from before (a half frame) only costs one frame, so failing to clear is
    // not worth refusing the port for.
    let _ = serial.clear(serialport::ClearBuffer::All);
    Ok(serial)
}

/// The error for a port that would not open, with what to do about it.
fn port_open_error(port: &str, baud: u32, e: &serialport::Error) -> RigError {
    use serialport::ErrorKind;
    let why = match e.kind() {
        ErrorKind::NoDevice => format!("{e} (the port does not exist or is gone)"),
        ErrorKind::Io(io::ErrorKind::NotFound) => format!("{e} (no such port)"),
        ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
            format!("{e} (no permission: add your user to the `dialout` group, then log in again)")
        }
        ErrorKind::InvalidInput => format!("{e} (the port does not accept {baud} baud)"),
        _ if e.description.contains("busy") || e.description.contains("Busy") => {
            format!("{e} (another program holds the port: close it first)")
        }
        _ => e.to_string(),
    };
    RigError::PortOpen {
        port: port.to_owned(),
        why,
    }
}

/// One direction of an in-memory pipe.
#[derive(Debug, Default)]
struct Channel {
    state: Mutex<ChannelState>,
    ready: Condvar,
}

#[derive(Debug, Default)]
struct ChannelState {
    bytes: VecDeque<u8>,
    closed: bool,
}

/// One end of an in-memory byte pipe: what one end writes, the other reads. Reads wait up
/// to the end's timeout like a serial port; a read after the other end was dropped fails
/// with [`io::ErrorKind::BrokenPipe`].
#[derive(Debug)]
pub struct PipeEnd {
    rx: Arc<Channel>,
    tx: Arc<Channel>,
    timeout: Duration,
}

/// A connected pair of in-memory pipe ends whose reads wait at most `timeout`.
pub fn memory_pipe(timeout: Duration) -> (PipeEnd, PipeEnd) {
    let a = Arc::new(Channel::default());
    let b = Arc::new(Channel::default());
    (
        PipeEnd {
            rx: Arc::clone(&a),
            tx: Arc::clone(&b),
            timeout,
        },
        PipeEnd {
            rx: b,
            tx: a,
            timeout,
        },
    )
}

impl PipeEnd {
    /// Changes how long a read waits for bytes.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }
}

fn lock(channel: &Channel) -> std::sync::MutexGuard<'_, ChannelState> {
    // A panic elsewhere cannot leave the byte queue inconsistent: keep using it.
    channel.state.lock().unwrap_or_else(|e| e.into_inner())
}

impl Read for PipeEnd {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        let deadline = Instant::now() + self.timeout;
        let mut state = lock(&self.rx);
        loop {
            if !state.bytes.is_empty() {
                let n = buf.len().min(state.bytes.len());
                for (slot, byte) in buf.iter_mut().zip(state.bytes.drain(..n)) {
                    *slot = byte;
                }
                return Ok(n);
            }
            if state.closed {
                return Err(io::Error::new(
                    io::ErrorKind::BrokenPipe,
                    "the other end of the pipe was closed",
                ));
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(io::Error::new(io::ErrorKind::TimedOut, "no bytes"));
            }
            state = self
                .rx
                .ready
                .wait_timeout(state, deadline - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

impl Write for PipeEnd {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut state = lock(&self.tx);
        if state.closed {
            return Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the other end of the pipe was closed",
            ));
        }
        state.bytes.extend(buf);
        self.tx.ready.notify_all();
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Drop for PipeEnd {
    fn drop(&mut self) {
        for channel in [&self.rx, &self.tx] {
            lock(channel).closed = true;
            channel.ready.notify_all();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_cross_and_reads_time_out() {
        let (mut a, mut b) = memory_pipe(Duration::from_millis(5));
        a.write_all(b"abc").unwrap();
        let mut buf = [0u8; 8];
        assert_eq!(b.read(&mut buf).unwrap(), 3);
        assert_eq!(&buf[..3], b"abc");
        let err = b.read(&mut buf).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
        drop(a);
        assert_eq!(
            b.read(&mut buf).unwrap_err().kind(),
            io::ErrorKind::BrokenPipe
        );
        assert!(b.write(b"x").is_err());
    }

    #[test]
    fn missing_port_names_the_port() {
        let err = open_serial("/dev/does-not-exist", 921_600).expect_err("no such port");
        let text = err.to_string();
        assert!(text.contains("/dev/does-not-exist"), "{text}");
        assert!(text.contains("rig ports"), "{text}");
    }
}
