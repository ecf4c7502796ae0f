//! Waiting on a `rig` child process's own progress, never on the wall clock: its output
//! read as it comes ([`Output`]), and whether it handles a signal yet ([`wait_for_handler`]).
//! On a loaded machine a child starts late and runs slowly; a signal sent after a guessed
//! sleep can land before the child installed its handler, or before the procedure began.
#![allow(dead_code)]

use std::io::Read;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Wall-clock guard of these waits: only a child that stopped making progress trips it (a
/// loaded machine slows a child, it does not stop it).
pub const STUCK: Duration = Duration::from_secs(120);

/// A child's pipe (stdout or stderr), read on a thread as the child writes it; what it
/// wrote so far is kept, so prompts that end without a newline are seen too.
pub struct Output {
    text: Arc<Mutex<String>>,
    reader: JoinHandle<()>,
}

impl Output {
    /// Reads `pipe` (from `child.stdout.take()` or `child.stderr.take()`) until it closes.
    pub fn read(mut pipe: impl Read + Send + 'static) -> Self {
        let text = Arc::new(Mutex::new(String::new()));
        let sink = Arc::clone(&text);
        let reader = std::thread::spawn(move || {
            let mut buf = [0u8; 4096];
            while let Ok(n) = pipe.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let mut t = sink.lock().unwrap_or_else(|e| e.into_inner());
                t.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        });
        Self { text, reader }
    }

    /// What the child wrote so far.
    pub fn so_far(&self) -> String {
        self.text.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Waits until the child wrote `needle` `count` times; panics naming `what` (with
    /// the output so far) if the pipe closes first or the child stops for [`STUCK`].
    pub fn wait_for(&self, needle: &str, count: usize, what: &str) {
        let t0 = Instant::now();
        loop {
            let text = self.so_far();
            if text.matches(needle).count() >= count {
                return;
            }
            assert!(
                !self.reader.is_finished(),
                "the child closed its output before {what}:\n{text}"
            );
            assert!(
                t0.elapsed() < STUCK,
                "no {what} after {STUCK:?} of wall time:\n{text}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Everything the child wrote, once it closed the pipe (it exited).
    pub fn all(self) -> String {
        let _ = self.reader.join();
        let text = self.text.lock().unwrap_or_else(|e| e.into_inner());
        text.clone()
    }
}

/// Waits until process `pid` catches `signal` (its handler is installed: Linux's
/// `/proc/PID/status`, `SigCgt`); panics after [`STUCK`].
pub fn wait_for_handler(pid: u32, signal: u32) {
    let t0 = Instant::now();
    let bit = 1u64 << (signal - 1);
    loop {
        let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
        let caught = status
            .lines()
            .find_map(|l| l.strip_prefix("SigCgt:"))
            .and_then(|h| u64::from_str_radix(h.trim(), 16).ok())
            .unwrap_or(0);
        if caught & bit != 0 {
            return;
        }
        assert!(
            t0.elapsed() < STUCK,
            "process {pid} installed no handler of signal {signal} in {STUCK:?}"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
}
