//! The thread that owns the port. Python never touches the client: every request is a job
//! sent to this thread, which runs it and answers on a channel. Between jobs the thread
//! keeps the link serviced: heartbeats while a release is live, telemetry into a running
//! recording, a release's end at its deadline or when Python stops confirming it.
//!
//! The device stays safe whatever Python does: a release always ends at its duration (or,
//! for a release without one, when Python has not confirmed it within its keep-alive
//! window), when the [`crate::rig::NativeRig`] is dropped (the channel closes: the thread locks
//! the gear and exits), and when the process dies (no heartbeats: the device's comms
//! timeout stops it).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use host::RigError;
use host::experiment::bench::{Bench, DeviceBench, RigLink};
use host::monitor::Freshness;
use host::recording::{StreamRow, StreamRows};
use protocol::{
    DeviceMessage, HealthSample, StreamBlock, StreamDecoder, StreamEvent, TelemetrySample,
};

/// A unit of work for the port's thread.
pub type Job = Box<dyn FnOnce(&mut Worker) + Send + 'static>;

/// Longest the thread waits for the port in one turn between jobs.
const TURN: Duration = Duration::from_millis(5);
/// Longest the thread sleeps on an idle link (nothing live, nothing recording).
const IDLE: Duration = Duration::from_millis(50);
/// A stream recording with no block for this long (device seconds, then 2 s of wall time
/// more) has stopped: the device ends the stream when no request reaches it within the
/// comms timeout (a host starved of CPU), and the recording fails saying so.
const STREAM_SILENCE_S: f64 = 2.0;

/// Locks `m`, whatever a panicking holder left (the data are plain values).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// How a release ended, shared with the Python `Release` object.
#[derive(Debug, Default)]
pub struct ReleaseStatus {
    /// Vibrating now (as far as the host asked).
    pub live: bool,
    /// Why it ended: `duration`, `stop`, `keep-alive` (Python stopped confirming), `rig
    /// closed`, or `error: ...` when locking failed.
    pub ended_by: Option<String>,
    /// Last confirmation from Python (explicit keep-alive releases).
    pub touched: Option<Instant>,
}

/// A release the thread keeps alive.
pub struct LiveRelease {
    /// Shared with Python.
    pub status: Arc<Mutex<ReleaseStatus>>,
    /// End of the release's duration (wall clock).
    pub ends: Option<Instant>,
    /// For a release without a duration: how long a Python confirmation lasts.
    pub confirm_within: Option<Duration>,
}

/// One telemetry sample with the newest health report at its arrival.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// The sample.
    pub sample: TelemetrySample,
    /// Whether its estimates are current (the monitor's rule).
    pub fresh: bool,
    /// The newest health report then.
    pub health: Option<HealthSample>,
}

/// A telemetry recording, filled by the thread, read by Python.
#[derive(Debug, Default)]
pub struct Recording {
    /// The samples so far (Python takes them).
    pub rows: Mutex<Vec<Row>>,
    /// Samples missing from the stream (gaps in the device's sample counter).
    pub lost: Mutex<u64>,
    /// Gaps: `(seq before, seq after)` of each.
    pub gaps: Mutex<Vec<(u32, u32)>>,
    /// Device time to stop at, µs (none: until stopped).
    pub stop_at_us: Mutex<Option<u64>>,
    /// Duration asked, device µs, from the first sample (set into `stop_at_us` then).
    pub duration_us: Option<u64>,
    /// Ended (duration reached, stopped, or failed).
    pub done: AtomicBool,
    /// Why it failed.
    pub error: Mutex<Option<String>>,
    /// The device's sequence of the last sample.
    last_seq: Mutex<Option<u32>>,
    freshness: Mutex<Freshness>,
    /// A recording of the continuous stream (every sample, `rig record`'s rows) instead of
    /// telemetry.
    pub stream: Option<StreamPart>,
}

/// The continuous stream's side of a [`Recording`].
#[derive(Debug)]
pub struct StreamPart {
    /// The samples so far (Python takes them).
    pub rows: Mutex<Vec<StreamRow>>,
    /// Sample number to end before (from `seconds`; none: until stopped).
    pub end_seq: Option<u32>,
    convert: Mutex<StreamRows>,
    decoder: Mutex<StreamDecoder>,
    /// When the last block (or the start) arrived, wall clock.
    last_block: Mutex<Option<Instant>>,
}

impl Recording {
    /// A recording that ends after `duration_us` of device time, or when stopped.
    pub fn new(duration_us: Option<u64>) -> Self {
        Self {
            duration_us,
            ..Self::default()
        }
    }

    /// A recording of the continuous stream at `rate_hz` for `seconds` of device time
    /// (`seconds * rate_hz` samples; None: until stopped).
    pub fn stream(rate_hz: u16, seconds: Option<f64>) -> Self {
        let mut decoder = StreamDecoder::new();
        // Samples are numbered from 0 at the start: any lost before the first are counted.
        decoder.push(&StreamBlock::pack(0, &[]), |_| {});
        Self {
            stream: Some(StreamPart {
                rows: Mutex::default(),
                end_seq: seconds.map(|s| {
                    (s * f64::from(rate_hz))
                        .round()
                        .clamp(1.0, f64::from(u32::MAX)) as u32
                }),
                convert: Mutex::new(StreamRows::new(rate_hz)),
                decoder: Mutex::new(decoder),
                last_block: Mutex::new(Some(Instant::now())),
            }),
            ..Self::default()
        }
    }

    /// Takes a stream block: its samples (up to the end asked), and the samples lost before
    /// it counted and placed.
    pub fn push_block(&self, block: &StreamBlock) {
        let Some(part) = &self.stream else {
            return;
        };
        if self.done.load(Ordering::SeqCst) {
            return;
        }
        *lock(&part.last_block) = Some(Instant::now());
        let end = part.end_seq.unwrap_or(u32::MAX);
        let mut events = Vec::new();
        lock(&part.decoder).push(block, |e| events.push(e));
        let mut convert = lock(&part.convert);
        let mut rows = lock(&part.rows);
        for e in events {
            match e {
                StreamEvent::Lost { first_seq, count } => {
                    let count = count.min(end.saturating_sub(first_seq));
                    if count > 0 {
                        *lock(&self.lost) += u64::from(count);
                        lock(&self.gaps)
                            .push((first_seq.wrapping_sub(1), first_seq.wrapping_add(count)));
                    }
                }
                StreamEvent::Sample { seq, sample } if seq < end => {
                    rows.push(convert.row(seq, &sample));
                }
                StreamEvent::Sample { .. } => {}
            }
        }
        if lock(&part.decoder)
            .expected_seq()
            .is_some_and(|next| next >= end)
        {
            self.done.store(true, Ordering::SeqCst);
        }
    }

    /// Samples held now.
    pub fn len(&self) -> usize {
        match &self.stream {
            Some(part) => lock(&part.rows).len(),
            None => lock(&self.rows).len(),
        }
    }

    fn push(&self, sample: TelemetrySample, health: Option<HealthSample>) {
        if self.done.load(Ordering::SeqCst) {
            return;
        }
        {
            let mut stop = lock(&self.stop_at_us);
            if stop.is_none()
                && let Some(d) = self.duration_us
            {
                *stop = Some(sample.device_time_us + d);
            }
            if let Some(s) = *stop
                && sample.device_time_us >= s
            {
                self.done.store(true, Ordering::SeqCst);
                return;
            }
        }
        let mut last = lock(&self.last_seq);
        if let Some(prev) = *last {
            let expected = prev.wrapping_add(1);
            if sample.seq != expected && sample.seq > prev {
                *lock(&self.lost) += u64::from(sample.seq - expected);
                lock(&self.gaps).push((prev, sample.seq));
            }
        }
        *last = Some(sample.seq);
        let fresh = lock(&self.freshness).update(&sample);
        lock(&self.rows).push(Row {
            sample,
            fresh,
            health,
        });
    }

    fn fail(&self, e: &RigError) {
        *lock(&self.error) = Some(e.to_string());
        self.done.store(true, Ordering::SeqCst);
    }
}

/// The port's thread's state.
pub struct Worker {
    /// The device.
    pub bench: DeviceBench,
    /// The release being kept alive.
    pub release: Option<LiveRelease>,
    /// The telemetry recording running.
    pub recording: Option<Arc<Recording>>,
    /// The newest health report.
    pub health: Option<HealthSample>,
    /// Set by Python's KeyboardInterrupt: a running procedure stops at its next check.
    pub stop: Arc<AtomicBool>,
}

impl Worker {
    /// Device seconds per wall-clock second.
    pub fn time_scale(&self) -> f64 {
        self.bench.session.time_scale().max(1e-9)
    }

    /// Wall time of `device_s` device seconds.
    pub fn wall(&self, device_s: f64) -> Duration {
        host::limits::wall_duration(device_s, self.time_scale())
    }

    /// Locks the gear and ends the live release (if any), saying why.
    pub fn end_release(&mut self, why: &str) -> Result<(), RigError> {
        let Some(r) = self.release.take() else {
            return Ok(());
        };
        let locked = self.bench.session.client.release(false, 0.0);
        self.bench.keep_alive(false);
        let mut st = lock(&r.status);
        st.live = false;
        st.ended_by = Some(match &locked {
            Ok(()) => why.to_owned(),
            Err(e) => format!("error: {e}"),
        });
        locked
    }

    /// Stops the continuous stream, and the heartbeats it needed unless a release is live.
    pub fn end_stream(&mut self) -> Result<(), RigError> {
        if self.release.is_none() {
            self.bench.keep_alive(false);
        }
        self.bench
            .session
            .client
            .ack(&protocol::Request::StopStream)
    }

    /// Takes the unsolicited messages that arrived (during a job too) into the recording.
    fn drain(&mut self) -> Result<(), RigError> {
        let wait = if self.release.is_some() || self.recording.is_some() {
            TURN
        } else {
            Duration::ZERO
        };
        let mut first = true;
        loop {
            let msg = self
                .bench
                .session
                .client
                .recv(if first { wait } else { Duration::ZERO })?;
            first = false;
            match msg {
                Some(DeviceMessage::Telemetry(t)) => {
                    if let Some(rec) = &self.recording {
                        rec.push(t, self.health);
                        if rec.done.load(Ordering::SeqCst) {
                            self.recording = None;
                        }
                    }
                }
                Some(DeviceMessage::StreamBlock(b)) => {
                    if let Some(rec) = &self.recording {
                        rec.push_block(&b);
                        if rec.done.load(Ordering::SeqCst) {
                            self.recording = None;
                            self.end_stream()?;
                        }
                    }
                }
                Some(DeviceMessage::Health(h)) => self.health = Some(h),
                Some(_) => {}
                None => return Ok(()),
            }
        }
    }

    /// One turn between jobs: end a release that is due, service the link.
    fn service(&mut self) {
        if let Some(r) = &self.release {
            let now = Instant::now();
            let due = r.ends.is_some_and(|e| now >= e);
            let unconfirmed = r.confirm_within.is_some_and(|w| {
                lock(&r.status)
                    .touched
                    .is_none_or(|t| now.duration_since(t) > w)
            });
            if due {
                let _ = self.end_release("duration");
            } else if unconfirmed {
                let _ = self.end_release("keep-alive");
            }
        }
        // The continuous stream stops at the comms timeout without requests: heartbeats
        // go on while it runs (a release's end turns them off).
        if self.recording.as_ref().is_some_and(|r| r.stream.is_some())
            && !self.bench.session.client.keeping_alive()
        {
            self.bench.keep_alive(true);
        }
        if let Err(e) = self.drain()
            && let Some(rec) = self.recording.take()
        {
            rec.fail(&e);
        }
        let silence = self.wall(STREAM_SILENCE_S) + Duration::from_secs(2);
        let stalled = self.recording.as_ref().is_some_and(|r| {
            r.stream
                .as_ref()
                .is_some_and(|p| lock(&p.last_block).is_some_and(|t| t.elapsed() > silence))
        });
        if stalled && let Some(rec) = self.recording.take() {
            let _ = self.end_stream();
            rec.fail(&RigError::Protocol(format!(
                "the stream stopped: no samples for {STREAM_SILENCE_S} s (the device ends it when no request reaches it within {} ms: was this process starved of CPU?)",
                protocol::COMMS_TIMEOUT_MS
            )));
        }
    }

    /// The thread's loop: jobs, and the link between them, until every sender is gone;
    /// then the gear is locked.
    pub fn run(mut self, jobs: Receiver<Job>) {
        loop {
            let busy = self.release.is_some() || self.recording.is_some();
            let wait = if busy { Duration::ZERO } else { IDLE };
            match jobs.recv_timeout(wait) {
                Ok(job) => job(&mut self),
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            self.service();
        }
        let _ = self.end_release("rig closed");
        self.bench.lock_gear();
        if let Some(rec) = self.recording.take() {
            rec.done.store(true, Ordering::SeqCst);
        }
    }
}

/// Starts the port's thread over `bench`; returns the job sender and the thread (which
/// ends, the gear locked and the port closed, once every sender is dropped).
pub fn spawn(
    bench: DeviceBench,
    stop: Arc<AtomicBool>,
) -> Result<(Sender<Job>, std::thread::JoinHandle<()>), RigError> {
    let (tx, rx) = std::sync::mpsc::channel::<Job>();
    let worker = Worker {
        bench,
        release: None,
        recording: None,
        health: None,
        stop,
    };
    let thread = std::thread::Builder::new()
        .name("backdrive_rig port".into())
        .spawn(move || {
            leave_stop_signals_to_python();
            worker.run(rx)
        })
        .map_err(|e| RigError::VirtualDevice(format!("cannot start the port's thread: {e}")))?;
    Ok((tx, thread))
}

/// Blocks SIGINT, SIGTERM and SIGHUP in the calling thread (the port's). Python runs its
/// signal handlers in the main thread, which learns of a signal another thread received only
/// when it next runs Python code: a Ctrl-C the kernel handed to this thread would leave a
/// main thread asleep in `time.sleep` (inside a `with rig.release(...)`) without its
/// KeyboardInterrupt. Blocked here, a process-directed signal goes to a thread that takes
/// it. A failure leaves the thread as it was.
#[cfg(unix)]
fn leave_stop_signals_to_python() {
    use nix::sys::signal::{SigmaskHow, pthread_sigmask};
    let _ = pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&stop_signals()), None);
}

/// The signals that stop a script (Ctrl-C, `kill`, a closed terminal).
#[cfg(unix)]
fn stop_signals() -> nix::sys::signal::SigSet {
    use nix::sys::signal::{SigSet, Signal};
    let mut set = SigSet::empty();
    for signal in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
        set.add(signal);
    }
    set
}

#[cfg(not(unix))]
fn leave_stop_signals_to_python() {}

/// Runs `f` with SIGINT, SIGTERM and SIGHUP blocked in the calling thread, then restores its
/// mask: every thread `f` starts (the in-process virtual rig's simulation thread) inherits
/// the block and so, like the port's thread, leaves stop signals to Python's main thread.
#[cfg(unix)]
pub fn with_stop_signals_left_to_python<T>(f: impl FnOnce() -> T) -> T {
    use nix::sys::signal::{SigSet, SigmaskHow, pthread_sigmask};
    let mut before = SigSet::empty();
    let blocked = pthread_sigmask(
        SigmaskHow::SIG_BLOCK,
        Some(&stop_signals()),
        Some(&mut before),
    )
    .is_ok();
    let out = f();
    if blocked {
        let _ = pthread_sigmask(SigmaskHow::SIG_SETMASK, Some(&before), None);
    }
    out
}

/// Runs `f` (no signal masks off Unix).
#[cfg(not(unix))]
pub fn with_stop_signals_left_to_python<T>(f: impl FnOnce() -> T) -> T {
    f()
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{FaultFlags, StatusFlags, SupervisorState};

    fn sample(seq: u32, t_us: u64) -> TelemetrySample {
        TelemetrySample {
            seq,
            device_time_us: t_us,
            cam_speed_rad_s: 62.8,
            current_a: 2.5,
            pwm_duty: 0.5,
            tau_cam_nm: 0.02,
            tau_rot_nm: 1.5,
            state: SupervisorState::Vibrating,
            faults: FaultFlags::empty(),
            status: StatusFlags::HOST_RELEASE,
            output_angle_rad: 0.0,
            output_speed_rad_s: 0.0,
        }
    }

    #[test]
    fn gaps_in_the_device_counter_are_counted_and_placed() {
        let rec = Recording::new(None);
        // 1 kHz from seq 100; 103-104 and 110 never arrive.
        for seq in (100..=102).chain(105..=109).chain(111..=112) {
            rec.push(sample(seq, u64::from(seq) * 1000), None);
        }
        assert_eq!(*lock(&rec.lost), 3);
        assert_eq!(*lock(&rec.gaps), vec![(102, 105), (109, 111)]);
        assert_eq!(lock(&rec.rows).len(), 10);
        assert!(!rec.done.load(Ordering::SeqCst));
    }

    #[test]
    fn a_duration_counts_from_the_first_sample_in_device_time() {
        // 2 ms from the first sample at t = 5 s: samples at 5.000 and 5.001 s, not 5.002.
        let rec = Recording::new(Some(2_000));
        for (k, seq) in (7..12).enumerate() {
            rec.push(sample(seq, 5_000_000 + k as u64 * 1000), None);
        }
        assert_eq!(lock(&rec.rows).len(), 2);
        assert!(rec.done.load(Ordering::SeqCst));
        assert_eq!(*lock(&rec.lost), 0);
    }

    #[test]
    fn stale_estimates_follow_the_monitor_rule() {
        // Locked: the estimates are not current, whatever the cam does.
        let rec = Recording::new(None);
        let mut s = sample(1, 0);
        s.state = SupervisorState::Locked;
        rec.push(s, None);
        assert!(!lock(&rec.rows)[0].fresh);
    }

    #[cfg(unix)]
    #[test]
    fn threads_started_inside_leave_stop_signals_to_the_caller_and_the_mask_comes_back() {
        use nix::sys::signal::{SigSet, SigmaskHow, Signal, pthread_sigmask};
        let mask = || {
            let mut now = SigSet::empty();
            pthread_sigmask(SigmaskHow::SIG_BLOCK, None, Some(&mut now)).unwrap();
            now
        };
        let stops = [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP];
        let before = stops.map(|s| mask().contains(s));
        let inside = with_stop_signals_left_to_python(|| {
            std::thread::spawn(move || {
                let m = mask();
                stops.map(|s| m.contains(s))
            })
            .join()
            .unwrap()
        });
        assert_eq!(
            inside,
            [true, true, true],
            "the started thread takes no stop signal"
        );
        let after = stops.map(|s| mask().contains(s));
        assert_eq!(after, before, "the caller's mask is restored");
    }
}
