//! The device's end of a pseudo-terminal: the master, non-blocking, so the simulation loop
//! never stalls on a host that does not read (or is not there).
//!
//! The slave is set raw once here; the client opens it by name like a serial port.

use std::fs::File;
use std::io::{self, Read, Write};
use std::time::Duration;

use rustix::event::{PollFd, PollFlags, Timespec};
use rustix::fs::{Mode, OFlags};
use rustix::pty::OpenptFlags;

/// The master side of a pseudo-terminal pair.
#[derive(Debug)]
pub struct PtyMaster {
    file: File,
}

impl PtyMaster {
    /// Opens a new pair; returns the master and the slave's path (e.g. `/dev/pts/3`).
    pub fn open() -> io::Result<(Self, String)> {
        let master =
            rustix::pty::openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY | OpenptFlags::CLOEXEC)?;
        rustix::pty::grantpt(&master)?;
        rustix::pty::unlockpt(&master)?;
        let name = rustix::pty::ptsname(&master, Vec::new())?
            .into_string()
            .map_err(|_| io::Error::other("the pseudo-terminal's name is not UTF-8"))?;
        // Raw: no echo, no line editing, no CR/LF translation of the binary frames.
        let slave = rustix::fs::open(
            name.as_str(),
            OFlags::RDWR | OFlags::NOCTTY | OFlags::CLOEXEC,
            Mode::empty(),
        )?;
        let mut termios = rustix::termios::tcgetattr(&slave)?;
        termios.make_raw();
        rustix::termios::tcsetattr(&slave, rustix::termios::OptionalActions::Now, &termios)?;
        drop(slave);
        rustix::io::ioctl_fionbio(&master, true)?;
        Ok((
            Self {
                file: File::from(master),
            },
            name,
        ))
    }

    /// Waits up to `timeout` for bytes from the host; true when some may be read. Returns
    /// false at once (after sleeping `timeout`) while no client has the slave open.
    pub fn wait_readable(&self, timeout: Duration) -> bool {
        let mut fds = [PollFd::new(&self.file, PollFlags::IN)];
        let ts = Timespec {
            tv_sec: timeout.as_secs() as _,
            tv_nsec: timeout.subsec_nanos() as _,
        };
        match rustix::event::poll(&mut fds, Some(&ts)) {
            Ok(n) if n > 0 => {
                let revents = fds[0].revents();
                if revents.contains(PollFlags::IN) {
                    true
                } else {
                    // Hung up: nobody has the slave open. Poll would return at once again.
                    std::thread::sleep(timeout);
                    false
                }
            }
            _ => false,
        }
    }

    /// Whether no client has the slave open now (the last one closed it, or died).
    pub fn hung_up(&self) -> bool {
        let mut fds = [PollFd::new(&self.file, PollFlags::IN)];
        let ts = Timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        matches!(rustix::event::poll(&mut fds, Some(&ts)), Ok(n) if n > 0
            && fds[0].revents().contains(PollFlags::HUP)
            && !fds[0].revents().contains(PollFlags::IN))
    }

    /// Reads what the host sent, without waiting: 0 when there is nothing (or no host).
    pub fn read_available(&mut self, buf: &mut [u8]) -> usize {
        self.file.read(buf).unwrap_or(0)
    }

    /// Writes as much of `bytes` as the pseudo-terminal takes now; returns how much.
    pub fn write_available(&mut self, bytes: &[u8]) -> usize {
        self.file.write(bytes).unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_cross_in_both_directions_raw() {
        let (mut master, name) = PtyMaster::open().unwrap();
        let mut slave = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&name)
            .unwrap();
        // A newline and a carriage return must pass unchanged (raw mode).
        slave.write_all(&[0x0A, 0x0D, 0x00, 0x7F]).unwrap();
        assert!(master.wait_readable(Duration::from_millis(500)));
        let mut buf = [0u8; 16];
        let n = master.read_available(&mut buf);
        assert_eq!(&buf[..n], &[0x0A, 0x0D, 0x00, 0x7F]);
        assert_eq!(master.write_available(&[0x0D, 0x0A]), 2);
        let mut back = [0u8; 2];
        slave.read_exact(&mut back).unwrap();
        assert_eq!(back, [0x0D, 0x0A]);
        // Nothing more: a read does not block.
        assert_eq!(master.read_available(&mut buf), 0);
        assert!(!master.hung_up());
        drop(slave);
        assert!(!master.wait_readable(Duration::from_millis(5)));
        assert!(master.hung_up());
    }
}
