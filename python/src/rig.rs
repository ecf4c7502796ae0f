//! `Rig`: one device (a board, a served virtual rig, or the in-process virtual rig), its
//! port owned by a Rust thread ([`crate::worker`]). Every method sends a job to that thread
//! and waits for its answer with the GIL released, checking for Ctrl-C (KeyboardInterrupt)
//! meanwhile. Results cross as JSON text (the CLI's `--json` keys) or as little-endian
//! column bytes; the Python package turns them into objects, arrays and DataFrames.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use host::RigError;
use host::client::{Client, ClientOptions, open_serial};
use host::connection::{Connection, DeviceOpts};
use host::experiment::bench::{Bench, DeviceBench, Operator, RigLink};
use host::experiment::sweep::{self, SweepSetup, Window};
use host::experiment::{Plan, hold_release};
use host::reports::{ClearReport, FaultsReport, InfoReport};
use host::virtual_device::VirtualDevice;
use pyo3::prelude::*;
use serde::Serialize;

use crate::errors::{closed, to_py};
use crate::worker::{self, Job, LiveRelease, Recording, ReleaseStatus, Worker, lock};

/// How often a waiting call looks for Ctrl-C.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

fn json<T: Serialize>(v: &T) -> Result<String, RigError> {
    Ok(serde_json::to_string(v)?)
}

fn bad(what: impl Into<String>, why: impl Into<String>) -> RigError {
    RigError::BadValue {
        what: what.into(),
        why: why.into(),
    }
}

/// Waits for `rx` with the GIL released; on Ctrl-C sets `stop`, waits for the job to
/// finish (it locks the gear on its way out) and raises the KeyboardInterrupt.
fn wait<R: Send>(
    py: Python<'_>,
    rx: mpsc::Receiver<Result<R, RigError>>,
    stop: &AtomicBool,
) -> PyResult<R> {
    // `detach` needs what it borrows to be `Sync`; a receiver is only `Send`.
    let rx = Mutex::new(rx);
    let rx = &rx;
    loop {
        match py.detach(|| lock(rx).recv_timeout(SIGNAL_POLL)) {
            Ok(r) => return r.map_err(to_py),
            Err(RecvTimeoutError::Disconnected) => return Err(closed()),
            Err(RecvTimeoutError::Timeout) => {
                if let Err(interrupt) = py.check_signals() {
                    stop.store(true, Ordering::SeqCst);
                    // The job stops at its next check and locks the gear; its result is
                    // dropped, the interrupt raised.
                    let _ = py.detach(|| lock(rx).recv());
                    stop.store(false, Ordering::SeqCst);
                    return Err(interrupt);
                }
            }
        }
    }
}

/// The rig file's sections as JSON text, from a device's calibration record.
fn record_sections(record: &protocol::RigParameters) -> Result<String, RigError> {
    let (rig, _) = host::calibrate::file::for_record(record, None);
    let text = rig.to_toml()?;
    let value: toml::Value = toml::from_str(&text).map_err(|e| {
        RigError::Protocol(format!(
            "the rig file of the device's record does not parse: {e}"
        ))
    })?;
    json(&value)
}

/// `[("field", old, new)]` of two records' differing fields.
fn changes(old: &protocol::RigParameters, new: &protocol::RigParameters) -> Vec<String> {
    let (a, b) = (serde_json::to_value(old), serde_json::to_value(new));
    let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) = (a, b) else {
        return Vec::new();
    };
    b.iter()
        .filter(|(k, v)| a.get(*k) != Some(*v))
        .map(|(k, v)| {
            let was = a.get(k).map_or("none".into(), |w| w.to_string());
            format!("{k}: {was} -> {v}")
        })
        .collect()
}

/// A rig: a board on a serial port, a served virtual rig (`rig sim serve`), or the
/// in-process virtual rig.
#[pyclass(module = "backdrive_rig._native", name = "NativeRig")]
pub struct NativeRig {
    jobs: Mutex<Option<Sender<Job>>>,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
    stop: Arc<AtomicBool>,
    /// The port as messages name it (`the virtual device (/dev/pts/3)` for a virtual rig).
    port: String,
    /// The port's path (`/dev/pts/3`, `/dev/ttyACM0`).
    port_path: String,
    in_process: bool,
}

impl NativeRig {
    fn start(session: Connection) -> Result<Self, RigError> {
        let port = session.port().to_owned();
        let port_path = session
            .device
            .as_ref()
            .map_or_else(|| port.clone(), |d| d.port_name().to_owned());
        let in_process = session.device.is_some();
        let stop = Arc::new(AtomicBool::new(false));
        // KeyboardInterrupt raises `stop`: a procedure's rest ends at once, not at its end.
        let bench = DeviceBench::new(session).stopped_by(stop.clone());
        let (tx, thread) = worker::spawn(bench, stop.clone())?;
        Ok(Self {
            jobs: Mutex::new(Some(tx)),
            thread: Mutex::new(Some(thread)),
            stop,
            port,
            port_path,
            in_process,
        })
    }

    /// Runs `f` on the port's thread and waits for it (GIL released, Ctrl-C checked).
    fn call<R, F>(&self, py: Python<'_>, f: F) -> PyResult<R>
    where
        R: Send + 'static,
        F: FnOnce(&mut Worker) -> Result<R, RigError> + Send + 'static,
    {
        let (tx, rx) = mpsc::channel();
        let job: Job = Box::new(move |w: &mut Worker| {
            let _ = tx.send(f(w));
        });
        let sender = lock(&self.jobs).clone().ok_or_else(closed)?;
        sender.send(job).map_err(|_| closed())?;
        self.stop.store(false, Ordering::SeqCst);
        wait(py, rx, &self.stop)
    }
}

/// Refuses a procedure while a recording (it uses the telemetry stream) or, unless
/// `release_ok`, a release of the user's runs (the procedure drives the vibrator itself).
fn idle(w: &Worker, what: &str, release_ok: bool) -> Result<(), RigError> {
    if w.recording.is_some() {
        return Err(bad(
            what,
            "a recording is running: stop it (Recorder.stop()) before starting a procedure",
        ));
    }
    if w.release.is_some() && !release_ok {
        return Err(bad(
            what,
            "a release is live: end it (leave its `with` block) before starting a procedure",
        ));
    }
    Ok(())
}

#[pymethods]
impl NativeRig {
    /// Opens a board or a served virtual rig on serial port `port` and says Hello (a device
    /// of another protocol version or schema is refused, naming which side to update).
    #[staticmethod]
    #[pyo3(signature = (port, baud = protocol::DEFAULT_BAUD_RATE))]
    fn open(py: Python<'_>, port: String, baud: u32) -> PyResult<Self> {
        py.detach(|| {
            let session = DeviceOpts {
                port: Some(port),
                baud,
                ..DeviceOpts::default()
            }
            .connect()?;
            Self::start(session)
        })
        .map_err(to_py)
    }

    /// Starts the in-process virtual rig (firmware core + plant) and opens it.
    #[staticmethod]
    #[pyo3(signature = (preset = "paper".to_string(), effects = Vec::new(), model = None, speed = 1.0, seed = 1))]
    fn virtual_rig(
        py: Python<'_>,
        preset: String,
        effects: Vec<String>,
        model: Option<PathBuf>,
        speed: f64,
        seed: u64,
    ) -> PyResult<Self> {
        // Effects the firmware cancels: the rig runs them, Python is warned.
        let mut unseen: Vec<String> = Vec::new();
        let rig = py.detach(|| {
            let max = host::virtual_device::MAX_SPEED;
            if !(speed.is_finite() && speed > 0.0 && speed <= max) {
                return Err(bad(
                    format!("speed {speed}"),
                    format!("not a speed the simulation can keep: give a number above 0 and at most {max} (1 = real time)"),
                ));
            }
            let preset_value = sim::Preset::by_name(&preset)?;
            let mut config = match &model {
                Some(path) => {
                    VirtualDevice::rig_file_config(&rigfile::RigFile::load(path)?, &preset_value)?
                }
                None => VirtualDevice::paper_config(&preset_value),
            };
            for e in &effects {
                let spec = sim::EffectSpec::parse(e)?;
                if let Some(why) = spec.unseen_through_firmware() {
                    unseen.push(why);
                }
                spec.apply(&mut config.plant)?;
            }
            config.seed = seed;
            // The simulation thread starts with the stop signals blocked, as the port's.
            let device =
                worker::with_stop_signals_left_to_python(|| VirtualDevice::start(config, speed))?;
            let port = device.port_name().to_owned();
            let io = open_serial(&port, protocol::DEFAULT_BAUD_RATE)?;
            let mut opts = ClientOptions::new(format!("the virtual device ({port})"));
            opts.time_scale = speed;
            // As `--sim`: pseudo-terminal bytes wait for a kernel worker.
            opts.reply_timeout = Duration::from_secs(1);
            let (client, info) = Client::connect(io, opts)?;
            Self::start(Connection {
                client,
                info,
                device: Some(device),
                board: None,
            })
        })
        .map_err(to_py)?;
        for why in unseen {
            let message = std::ffi::CString::new(why.replace('\0', " "))
                .expect("no NUL is left in the message");
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyUserWarning>(),
                &message,
                1,
            )?;
        }
        Ok(rig)
    }

    /// The port's path (a pseudo-terminal for a virtual rig).
    #[getter]
    fn port(&self) -> String {
        self.port_path.clone()
    }

    /// `rig info --json`.
    fn info(&self, py: Python<'_>) -> PyResult<String> {
        let (port, sim) = (self.port.clone(), self.in_process);
        self.call(py, move |w| {
            let info = w.bench.session.client.info()?;
            json(&InfoReport::new(&info, &port, sim))
        })
    }

    /// `rig faults --json`.
    fn faults(&self, py: Python<'_>) -> PyResult<String> {
        self.call(py, |w| {
            json(&FaultsReport::from(w.bench.session.client.faults()?))
        })
    }

    /// `rig clear --json`.
    fn clear(&self, py: Python<'_>) -> PyResult<String> {
        self.call(py, |w| {
            let before = w.bench.session.client.faults()?;
            let after = w.bench.session.client.clear_faults()?;
            json(&ClearReport {
                cleared: before.latched.difference(after.latched).names().collect(),
                faults: FaultsReport::from(after),
            })
        })
    }

    /// The device's calibration record as the rig file's sections (JSON text).
    fn parameters(&self, py: Python<'_>) -> PyResult<String> {
        self.call(py, |w| {
            record_sections(&w.bench.session.client.calibration()?)
        })
    }

    /// Sends a rig file (TOML text, named `name` in errors) as the device's calibration:
    /// the rig file's checks, then the device's (a refusal names the field), then read back.
    fn set_parameters(&self, py: Python<'_>, toml_text: String, name: String) -> PyResult<String> {
        self.call(py, move |w| {
            let loaded = host::calibrate::file::parse(&toml_text, &name)?;
            let new = loaded.rig.to_wire()?;
            let defaulted: Vec<&str> = loaded.defaulted().iter().filter_map(|k| k.wire).collect();
            let client = &mut w.bench.session.client;
            let current = client.calibration()?;
            let changed = changes(&current, &new);
            if changed.is_empty() {
                return json(&serde_json::json!({
                    "changed": [], "written": false, "defaulted": defaulted
                }));
            }
            client.set_calibration(&new)?;
            let back = client.calibration()?;
            if back != new {
                return Err(RigError::Protocol(format!(
                    "the device stored a different calibration than sent on {}",
                    client.options().port_name
                )));
            }
            json(&serde_json::json!({
                "changed": changed, "written": true, "calibration": new, "defaulted": defaulted
            }))
        })
    }

    /// Starts a release at `freq_hz` (checked against the calibration's range as `rig
    /// release` does). `seconds`: its duration (device time); `None` with `confirm_s`:
    /// no duration, but it ends when Python has not called `confirm` for `confirm_s`.
    fn start_release(
        &self,
        py: Python<'_>,
        freq_hz: f64,
        seconds: Option<f64>,
        confirm_s: Option<f64>,
        status: &NativeReleaseStatus,
    ) -> PyResult<()> {
        let status = status.inner.clone();
        self.call(py, move |w| {
            if w.release.is_some() {
                return Err(bad(
                    "release",
                    "a release is already live on this rig: end it first (one `with rig.release(...)` at a time)",
                ));
            }
            if let Some(s) = seconds {
                host::limits::check_seconds("seconds", s)?;
            }
            let confirm_within = match (seconds, confirm_s) {
                (None, Some(c)) => Some(w.wall(host::limits::check_seconds("confirm_s", c)?)),
                (None, None) => {
                    return Err(bad("confirm_s", "a release without a duration needs a positive confirm_s (Python must confirm it within that)"));
                }
                (Some(_), _) => None,
            };
            let cal = w.bench.session.client.calibration()?;
            let hz = host::limits::check_release_freq("freq_hz", freq_hz, &cal)?;
            let ends = seconds.map(|s| host::limits::deadline_after(w.wall(s)));
            w.bench.session.client.release(true, hz)?;
            {
                let mut st = lock(&status);
                st.live = true;
                st.ended_by = None;
                st.touched = Some(Instant::now());
            }
            w.release = Some(LiveRelease {
                status,
                ends,
                confirm_within,
            });
            Ok(())
        })
    }

    /// Ends the live release (locks the gear); `why` is recorded as how it ended.
    fn stop_release(&self, py: Python<'_>, why: String) -> PyResult<()> {
        self.call(py, move |w| w.end_release(&why))
    }

    /// Starts recording telemetry at `rate_hz` for `seconds` of device time (None: until
    /// stopped), or with `stream` the continuous stream (every sample, `rig record`'s
    /// columns); returns the recording.
    #[pyo3(signature = (rate_hz, seconds, stream = false))]
    fn start_recording(
        &self,
        py: Python<'_>,
        rate_hz: u32,
        seconds: Option<f64>,
        stream: bool,
    ) -> PyResult<NativeRecording> {
        self.call(py, move |w| {
            if w.recording.is_some() {
                return Err(bad(
                    "record",
                    "a recording is already running on this rig: stop it first",
                ));
            }
            let max = if stream {
                protocol::MAX_STREAM_RATE_HZ
            } else {
                protocol::MAX_TELEMETRY_RATE_HZ
            };
            let hz = u16::try_from(rate_hz)
                .ok()
                .filter(|hz| (1..=max).contains(hz))
                .ok_or_else(|| {
                    bad(
                        format!("rate_hz {rate_hz}"),
                        format!(
                            "out of range: telemetry runs at 1 to 1000 Hz, the continuous stream (stream=True, or any rate above 1000 Hz) at 1 to {} Hz",
                            protocol::MAX_STREAM_RATE_HZ
                        ),
                    )
                })?;
            let seconds = match seconds {
                Some(s) => Some(host::limits::check_seconds("seconds", s)?),
                None => None,
            };
            let rec = if stream {
                let rec = Arc::new(Recording::stream(hz, seconds));
                w.bench.keep_alive(true);
                if let Err(e) = w
                    .bench
                    .session
                    .client
                    .ack(&protocol::Request::StartStream { rate_hz: hz })
                {
                    if w.release.is_none() {
                        w.bench.keep_alive(false);
                    }
                    return Err(e);
                }
                rec
            } else {
                host::limits::check_telemetry_rate("rate_hz", hz)?;
                let rec = Arc::new(Recording::new(seconds.map(|s| (s * 1e6).round() as u64)));
                w.bench.session.client.start_telemetry(hz)?;
                rec
            };
            w.recording = Some(rec.clone());
            Ok(NativeRecording {
                inner: rec,
                rate_hz,
            })
        })
    }

    /// Stops a recording (and the telemetry stream).
    fn stop_recording(&self, py: Python<'_>, recording: &NativeRecording) -> PyResult<()> {
        let rec = recording.inner.clone();
        self.call(py, move |w| {
            rec.done.store(true, Ordering::SeqCst);
            match &w.recording {
                Some(r) if Arc::ptr_eq(r, &rec) => w.recording = None,
                // Another thread's recording runs now: its telemetry stays on.
                Some(_) => return Ok(()),
                None => {}
            }
            if rec.stream.is_some() {
                w.end_stream()
            } else {
                w.bench.session.client.stop_telemetry()
            }
        })
    }

    /// Waits (GIL released) until `recording` is done; Ctrl-C raises KeyboardInterrupt.
    fn wait_recording(&self, py: Python<'_>, recording: &NativeRecording) -> PyResult<()> {
        loop {
            if recording.inner.done.load(Ordering::SeqCst) {
                return Ok(());
            }
            py.detach(|| std::thread::sleep(Duration::from_millis(10)));
            py.check_signals()?;
            if lock(&self.jobs).is_none() {
                return Err(closed());
            }
        }
    }

    /// Waits (GIL released) until `recording` holds `samples` samples or is done; Ctrl-C
    /// raises KeyboardInterrupt.
    fn wait_samples(
        &self,
        py: Python<'_>,
        recording: &NativeRecording,
        samples: usize,
    ) -> PyResult<()> {
        loop {
            if recording.inner.done.load(Ordering::SeqCst) || recording.inner.len() >= samples {
                return Ok(());
            }
            py.detach(|| std::thread::sleep(Duration::from_millis(5)));
            py.check_signals()?;
            if lock(&self.jobs).is_none() {
                return Err(closed());
            }
        }
    }

    /// A raw capture (`rig capture`): `seconds` at `rate_hz` recorded on the device and
    /// uploaded. Returns (JSON summary: the capture's counters, columns: `rig capture`'s CSV
    /// columns as (name, dtype, little-endian bytes)).
    fn capture<'py>(
        &self,
        py: Python<'py>,
        seconds: f64,
        rate_hz: u32,
    ) -> PyResult<(String, TypedColumns<'py>)> {
        let (summary, cap) = self.call(py, move |w| {
            idle(w, "capture", true)?;
            let hz = u16::try_from(rate_hz).map_err(|_| bad(format!("rate_hz {rate_hz}"), "too high: the device records at most at 10000 Hz"))?;
            host::limits::check_capture_rate("rate_hz", hz)?;
            let samples = (seconds * f64::from(hz)).round();
            if samples.is_nan() || samples < 1.0 {
                return Err(bad(format!("seconds {seconds}"), format!("shorter than one sample at {hz} Hz: give at least {} s", 1.0 / f64::from(hz))));
            }
            let capacity = host::limits::capture_capacity();
            if samples > f64::from(capacity) {
                return Err(bad(format!("seconds {seconds}"), format!("too long for one capture: the device's buffer holds {capacity} samples ({} s at {hz} Hz); give at most that, or a lower rate_hz", f64::from(capacity) / f64::from(hz))));
            }
            let cap = w.bench.session.client.capture(hz, samples as u32, |_| {})?;
            Ok((json(&cap)?, cap))
        })?;
        Ok((summary, crate::columns::capture(py, &cap)?))
    }

    /// `rig experiment torque-sweep` with `plan` (`paper`, `quick`, or a plan file's TOML
    /// text named `plan_name`), no CSV: returns (the outcome's JSON with `rows`, the
    /// provenance header).
    #[pyo3(signature = (plan, plan_name, window_revolutions = false, progress = None))]
    fn torque_sweep(
        &self,
        py: Python<'_>,
        plan: String,
        plan_name: String,
        window_revolutions: bool,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<(String, String)> {
        self.call(py, move |w| {
            // A plan that cannot run is refused first, whatever else stands in the way.
            let plan = match plan.as_str() {
                "paper" => Plan::paper(),
                "quick" => Plan::quick(),
                text => Plan::parse(text, &plan_name)?,
            };
            idle(w, "torque_sweep", false)?;
            let setup = SweepSetup {
                plan,
                window: if window_revolutions {
                    Window::Revolutions
                } else {
                    Window::Start
                },
                resume: false,
                force: false,
                command: "backdrive_rig Rig.torque_sweep".into(),
            };
            let mut operator = Operator::scripted(b"", false);
            operator.stop = w.stop.clone();
            let provenance = sweep::provenance(&mut w.bench, &setup)?;
            let outcome = sweep::run_to(&mut w.bench, &mut operator, &setup, None, &mut |l| {
                report_progress(progress.as_ref(), l);
            })?;
            let mut value = serde_json::to_value(&outcome)?;
            if let Some(map) = value.as_object_mut() {
                map.insert("rows".into(), serde_json::to_value(&outcome.rows)?);
            }
            Ok((json(&value)?, provenance))
        })
    }

    /// `rig discover` on this rig: the closed loop of sweeps and explanations
    /// ([`host::discover::discover`], the CLI's own), every round's rows appended to `csv`
    /// (a new file; an existing one only with `force`). Returns the CLI's `--json`.
    #[pyo3(signature = (csv, max_points = 60, seed = 1, replicates = 200, model = None, force = false, progress = None))]
    #[allow(clippy::too_many_arguments)]
    fn discover(
        &self,
        py: Python<'_>,
        csv: PathBuf,
        max_points: u32,
        seed: u64,
        replicates: u32,
        model: Option<PathBuf>,
        force: bool,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<String> {
        self.call(py, move |w| {
            // The CLI's checks (`--max-points`, `--replicates`), named as Python spells them.
            use host::discover::DiscoverySetup as Setup;
            let max_points = Setup::check_max_points(max_points)
                .map_err(|why| bad(format!("max_points {max_points}"), why))?;
            let replicates = Setup::check_replicates(replicates)
                .map_err(|why| bad(format!("replicates {replicates}"), why))?;
            let rig = host::discover::starting_rig(model.as_deref())?;
            // An existing CSV is refused before the rig moves, and never truncated.
            sweep::check_output(&csv, false, force)?;
            idle(w, "discover", false)?;
            let setup = host::discover::DiscoverySetup {
                csv: csv.clone(),
                force,
                max_points,
                seed,
                options: ::explain::Options {
                    replicates,
                    ..::explain::Options::default()
                },
                command: "backdrive_rig Rig.discover".into(),
            };
            let mut operator = Operator::scripted(b"", false);
            operator.stop = w.stop.clone();
            let found = host::discover::discover(&mut w.bench, &mut operator, &rig, &setup, &|l| {
                report_progress(progress.as_ref(), l);
            })
            .map_err(|stopped| stopped.error)?;
            json(&found.json(&setup))
        })
    }

    /// `rig experiment hold-release` (Fig. 5): returns the samples as JSON (the CSV's
    /// columns) and the verdict numbers.
    fn hold_release(
        &self,
        py: Python<'_>,
        load_nm: Option<f64>,
        hold_s: f64,
        freq_hz: f64,
        release_s: f64,
        after_s: f64,
    ) -> PyResult<String> {
        self.call(py, move |w| {
            idle(w, "hold_release", false)?;
            // The CLI's checks of each setting, named as Python spells them.
            let calibration = w.bench.calibration()?;
            let opts = hold_release::HoldRelease {
                load_nm,
                hold_s,
                hz: freq_hz,
                release_s,
                after_s,
            }
            .checked(hold_release::SettingNames::PYTHON, &calibration)?;
            let mut operator = Operator::scripted(b"", false);
            operator.stop = w.stop.clone();
            let samples = hold_release::run(&mut w.bench, &mut operator, &opts, &mut |_| {})?;
            let numbers = samples
                .iter()
                .any(|s| s.output_angle_rad.is_some())
                .then(|| hold_release::fig5_numbers(&samples, model::paper::R_OUT))
                .map(|n| {
                    serde_json::json!({
                        "held_without_vibration": n.held_without_vibration,
                        "release_to_motion_s": n.release_to_motion_s,
                        "output_speed_at_stop_rad_s": n.output_speed_at_stop_rad_s,
                        "output_speed_after_stop_rad_s": n.output_speed_after_stop_rad_s,
                        "load_drop_m": n.load_drop_m,
                        "stops_after_vibration": n.stops_after_vibration,
                        "after_stop_travel_rad": n.after_stop_travel_rad,
                    })
                });
            json(&serde_json::json!({ "samples": samples, "fig5": numbers }))
        })
    }

    /// Link counters (`LinkStats`) as JSON.
    fn link_stats(&self, py: Python<'_>) -> PyResult<String> {
        self.call(py, |w| json(&w.bench.session.client.stats()))
    }

    /// Locks the gear and closes the port (the in-process virtual rig stops); returns when
    /// the port is closed, so another program can open it. Dropping the rig does the same
    /// without waiting.
    fn close(&self, py: Python<'_>) {
        // The thread locks the gear and closes the port once its last sender is gone.
        drop(lock(&self.jobs).take());
        let thread = lock(&self.thread).take();
        if let Some(thread) = thread {
            let _ = py.detach(|| thread.join());
        }
    }
}

/// How a release stands, shared between Python's `Release` and the port's thread.
#[pyclass(module = "backdrive_rig._native", name = "NativeReleaseStatus")]
#[derive(Default)]
pub struct NativeReleaseStatus {
    inner: Arc<Mutex<ReleaseStatus>>,
}

#[pymethods]
impl NativeReleaseStatus {
    /// A status for a release not yet started.
    #[new]
    fn new() -> Self {
        Self::default()
    }

    /// Whether the release is live.
    #[getter]
    fn live(&self) -> bool {
        lock(&self.inner).live
    }

    /// Why it ended (None while live or before it started).
    #[getter]
    fn ended_by(&self) -> Option<String> {
        lock(&self.inner).ended_by.clone()
    }

    /// Confirms from Python that the program is alive (a release without a duration ends
    /// when this is not called within its `confirm_s`).
    fn confirm(&self) {
        lock(&self.inner).touched = Some(Instant::now());
    }
}

/// A telemetry recording filled by the port's thread.
#[pyclass(module = "backdrive_rig._native", name = "NativeRecording")]
pub struct NativeRecording {
    inner: Arc<Recording>,
    rate_hz: u32,
}

/// Column bytes of the monitor CSV's numeric columns, and its text columns.
use crate::columns::TypedColumns;

#[pymethods]
impl NativeRecording {
    /// Telemetry rate, Hz.
    #[getter]
    fn rate_hz(&self) -> u32 {
        self.rate_hz
    }

    /// Whether it has ended.
    #[getter]
    fn done(&self) -> bool {
        self.inner.done.load(Ordering::SeqCst)
    }

    /// Samples lost so far (gaps in the device's sample counter).
    #[getter]
    fn lost(&self) -> u64 {
        *lock(&self.inner.lost)
    }

    /// The gaps: (sequence number before, sequence number after).
    #[getter]
    fn gaps(&self) -> Vec<(u32, u32)> {
        lock(&self.inner.gaps).clone()
    }

    /// Why it failed, if it did.
    #[getter]
    fn error(&self) -> Option<String> {
        lock(&self.inner.error).clone()
    }

    /// Samples held now.
    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Whether it records the continuous stream (else telemetry).
    #[getter]
    fn stream(&self) -> bool {
        self.inner.stream.is_some()
    }

    /// The samples so far as columns (the monitor CSV's names and units; numeric columns as
    /// little-endian f64 bytes, NaN where the CSV is empty); `take` empties the buffer.
    #[pyo3(signature = (take = false))]
    fn columns<'py>(&self, py: Python<'py>, take: bool) -> PyResult<TypedColumns<'py>> {
        if let Some(part) = &self.inner.stream {
            let rows = {
                let mut rows = lock(&part.rows);
                if take {
                    std::mem::take(&mut *rows)
                } else {
                    rows.clone()
                }
            };
            return crate::columns::stream(py, &rows);
        }
        let rows = {
            let mut rows = lock(&self.inner.rows);
            if take {
                std::mem::take(&mut *rows)
            } else {
                rows.clone()
            }
        };
        crate::columns::telemetry(py, &rows)
    }
}

/// Hands a procedure's progress line to Python's `progress(done, total, line)` (`done`
/// and `total`: the points, `None` on a line without them), on the port's thread with the
/// GIL taken for the call. An exception in the callback is printed, not raised: the
/// procedure (and the gear's safety) does not depend on it.
fn report_progress(progress: Option<&Py<PyAny>>, line: &str) {
    let Some(callback) = progress else {
        return;
    };
    let (done, total) = host::progress::counts(line).unzip();
    Python::attach(|py| {
        if let Err(e) = callback.call1(py, (done, total, line.trim_start())) {
            e.print(py);
        }
    });
}
