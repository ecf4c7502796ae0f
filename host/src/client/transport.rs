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
///
/// The port is opened exclusively (TIOCEXCL and an exclusive `flock` on Unix), so a second
/// client (another `rig`, a terminal program that locks) cannot drive the rig at the same
/// time: it gets [`RigError::PortBusy`], naming the holder where it can be found.
pub fn open_serial(port: &str, baud: u32) -> Result<SerialTransport, RigError> {
    let opened = serialport::new(port, baud)
        .timeout(SERIAL_READ_TIMEOUT)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .exclusive(true)
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
    if is_busy(e) {
        return RigError::PortBusy {
            port: port.to_owned(),
            why: format!("{e}; {}", holder_hint(port)),
        };
    }
    let why = match e.kind() {
        // Windows reports a missing port and one another program holds alike.
        ErrorKind::NoDevice => {
            format!("{e} (the port does not exist, is gone, or another program holds it)")
        }
        ErrorKind::Io(io::ErrorKind::NotFound) => format!("{e} (no such port)"),
        ErrorKind::Io(io::ErrorKind::PermissionDenied) => {
            format!("{e} (no permission: add your user to the `dialout` group, then log in again)")
        }
        ErrorKind::InvalidInput => format!("{e} (the port does not accept {baud} baud)"),
        _ => e.to_string(),
    };
    RigError::PortOpen {
        port: port.to_owned(),
        why,
    }
}

/// Whether the open failed because another opener holds the port. On Unix serialport
/// reports both the TIOCEXCL refusal (EBUSY) and a held exclusive `flock` as `NoDevice`
/// (a missing port is `NotFound` there); elsewhere only the operating system's words tell.
fn is_busy(e: &serialport::Error) -> bool {
    let words = e.description.to_ascii_lowercase();
    (cfg!(unix) && e.kind() == serialport::ErrorKind::NoDevice)
        || words.contains("busy")
        || words.contains("in use")
}

/// Who holds `port`, in words: the processes found with it open (Linux, those this user
/// may see), else the command that finds them.
fn holder_hint(port: &str) -> String {
    let holders = port_holders(port);
    if holders.is_empty() {
        if cfg!(target_os = "linux") {
            format!("another program holds it (`fuser -v {port}` or `lsof {port}` names it)")
        } else if cfg!(unix) {
            format!("another program holds it (`lsof {port}` names it)")
        } else {
            "another program holds it".to_owned()
        }
    } else {
        let list: Vec<String> = holders
            .iter()
            .map(|(pid, name)| format!("process {pid} ({name})"))
            .collect();
        format!("held by {}", list.join(", "))
    }
}

/// The processes (id, command name) other than this one with `port` open, from /proc.
#[cfg(target_os = "linux")]
fn port_holders(port: &str) -> Vec<(u32, String)> {
    let Ok(target) = std::fs::canonicalize(port) else {
        return Vec::new();
    };
    let me = std::process::id();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for entry in procs.flatten() {
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        if pid == me {
            continue;
        }
        // Processes of other users are unreadable without privileges: skipped.
        let Ok(fds) = std::fs::read_dir(entry.path().join("fd")) else {
            continue;
        };
        let holds = fds
            .flatten()
            .any(|fd| std::fs::read_link(fd.path()).is_ok_and(|p| p == target));
        if holds {
            let name = std::fs::read_to_string(entry.path().join("comm"))
                .map(|n| n.trim().to_owned())
                .unwrap_or_else(|_| "unknown".to_owned());
            found.push((pid, name));
        }
    }
    found
}

/// Not looked up outside Linux: the hint names the command that finds them.
#[cfg(not(target_os = "linux"))]
fn port_holders(_port: &str) -> Vec<(u32, String)> {
    Vec::new()
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

    /// A port another opener holds is busy, not missing: the served rig's pseudo-terminal
    /// held by one open, opened again.
    #[cfg(unix)]
    #[test]
    fn held_port_is_busy_not_missing() {
        let (_master, name) = crate::virtual_device::PtyMaster::open().expect("a pseudo-terminal");
        let first = open_serial(&name, 921_600).expect("the first open");
        let err = open_serial(&name, 921_600).expect_err("the port is held");
        let text = err.to_string();
        assert!(matches!(err, RigError::PortBusy { .. }), "{text}");
        assert!(
            text.contains(&format!("serial port {name} is busy")),
            "{text}"
        );
        assert!(!text.contains("does not exist"), "{text}");
        drop(first);
        open_serial(&name, 921_600).expect("free again once the first is closed");
    }
}
