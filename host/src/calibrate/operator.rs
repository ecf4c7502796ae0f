//! The two operators of a calibration: a person at a real rig (prompts on the terminal, gauge readings typed
//! or from a CSV file), and the virtual device's plant (cam setup switched in the
//! simulation, the gauge read from the simulated arm).

use std::io::BufRead;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget};
use model::plant::CamSetup;

use super::{GaugeOperator, GaugeUnit, Reading, Setup, StepMeasurement, parse_reading};
use crate::RigError;
use crate::virtual_device::VirtualDevice;

fn cam_setup(setup: Setup) -> CamSetup {
    match setup {
        Setup::NoLoad => CamSetup::Uncoupled,
        Setup::Gauge => CamSetup::Blocked,
        Setup::Done => CamSetup::Coupled,
    }
}

/// The virtual device as the bench: the operator's hands are the simulation's.
#[derive(Debug)]
pub struct VirtualOperator<'a> {
    device: &'a VirtualDevice,
    gauge: Option<Vec<f64>>,
    held_nmm: Option<f64>,
    window: WindowMean,
}

/// The virtual gauge's mean over an averaging window, N mm.
#[derive(Debug, Default)]
struct WindowMean {
    sum: f64,
    n: usize,
}

impl WindowMean {
    fn add(&mut self, v: f64) {
        self.sum += v;
        self.n += 1;
    }

    /// The mean so far (`None` without a sample), and a fresh start.
    fn take(&mut self) -> Option<f64> {
        let mean = (self.n > 0).then(|| self.sum / self.n as f64);
        *self = Self::default();
        mean
    }
}

impl<'a> VirtualOperator<'a> {
    /// The bench of `device`; `gauge` readings (N mm), when given, replace the simulated
    /// gauge.
    pub fn new(device: &'a VirtualDevice, gauge: Option<Vec<f64>>) -> Self {
        Self {
            device,
            gauge,
            held_nmm: None,
            window: WindowMean::default(),
        }
    }
}

/// The virtual gauge's torque now, N mm.
fn virtual_gauge_nmm(device: &VirtualDevice) -> f64 {
    device.with_plant(|p| p.state().gauge_torque) * 1e3
}

impl GaugeOperator for VirtualOperator<'_> {
    fn prepare(&mut self, setup: Setup) -> Result<(), RigError> {
        self.device.with_plant(|p| p.set_cam(cam_setup(setup)));
        Ok(())
    }

    fn window_sample(&mut self, _step: usize) {
        self.window.add(virtual_gauge_nmm(self.device));
    }

    fn pressed(&mut self, _step: usize) {
        // What the gauge showed over the window the current was averaged on.
        self.held_nmm = self
            .window
            .take()
            .or_else(|| Some(virtual_gauge_nmm(self.device)));
    }

    fn gauge_nmm(
        &mut self,
        step: usize,
        _measured: &StepMeasurement,
        _keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<Reading, RigError> {
        if let Some(g) = &self.gauge {
            return from_file(g, step);
        }
        self.held_nmm.take().map(Reading::Nmm).ok_or_else(|| {
            RigError::Operator(format!(
                "the virtual gauge held no reading at torque step {}",
                step + 1
            ))
        })
    }
}

fn from_file(g: &[f64], step: usize) -> Result<Reading, RigError> {
    g.get(step)
        .copied()
        .map(Reading::Nmm)
        .ok_or_else(|| RigError::Operator(format!("no gauge reading for torque step {}", step + 1)))
}

/// A person at the rig: set-up instructions and gauge prompts on stderr, answers on stdin
/// (read by a thread, so the drive's heartbeat goes on while the operator types). At a
/// gauge prompt `r` measures the step again. While a prompt waits the progress bar is off
/// the screen, so it never draws over the prompt. With a virtual device (`--sim
/// --operator`) the set-up also happens on the simulated rig, as the person's hands.
#[derive(Debug)]
pub struct TerminalOperator<'a> {
    gauge: Option<Vec<f64>>,
    unit: GaugeUnit,
    progress: ProgressBar,
    lines: Option<Receiver<std::io::Result<String>>>,
    interrupted: Arc<AtomicBool>,
    device: Option<&'a VirtualDevice>,
    held_nmm: Option<f64>,
    window: WindowMean,
}

impl<'a> TerminalOperator<'a> {
    /// Prompts through `progress`; `gauge` readings (N mm), when given, are used instead of
    /// asking; typed readings are in `unit`; `interrupted` (Ctrl-C) ends a wait.
    pub fn new(
        gauge: Option<Vec<f64>>,
        unit: GaugeUnit,
        progress: ProgressBar,
        interrupted: Arc<AtomicBool>,
    ) -> Self {
        Self {
            gauge,
            unit,
            progress,
            lines: None,
            interrupted,
            device: None,
            held_nmm: None,
            window: WindowMean::default(),
        }
    }

    /// Also sets up `device`'s simulated rig at each step (rehearsal on the virtual rig).
    pub fn with_device(mut self, device: &'a VirtualDevice) -> Self {
        self.device = Some(device);
        self
    }

    /// Asks `prompt` and waits for a line, calling `keep_alive` while waiting.
    fn ask(
        &mut self,
        prompt: &str,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<String, RigError> {
        // The bar leaves the screen while the prompt waits: nothing draws over it.
        let visible = !self.progress.is_hidden();
        if visible {
            self.progress.set_draw_target(ProgressDrawTarget::hidden());
            eprint!("\r\x1b[2K");
        }
        eprint!("{prompt}");
        let answer = self.read_line(keep_alive);
        if visible {
            self.progress.set_draw_target(ProgressDrawTarget::stderr());
        }
        answer
    }

    fn read_line(
        &mut self,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<String, RigError> {
        let lines = self.lines.get_or_insert_with(|| {
            let (tx, rx) = channel();
            std::thread::spawn(move || {
                for line in std::io::stdin().lock().lines() {
                    if tx.send(line).is_err() {
                        return;
                    }
                }
            });
            rx
        });
        loop {
            if self.interrupted.load(Ordering::SeqCst) {
                eprintln!();
                return Err(super::interrupted_error());
            }
            match lines.recv_timeout(Duration::from_millis(20)) {
                Ok(Ok(line)) => return Ok(line.trim().to_owned()),
                Ok(Err(e)) => return Err(RigError::Output(e)),
                Err(RecvTimeoutError::Timeout) => keep_alive()?,
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(RigError::Operator(
                        "calibrate needs the operator at the rig, but standard input ended: run it in a terminal (gauge readings can come from --gauge-csv FILE); the points measured so far are kept (points.csv)".into(),
                    ));
                }
            }
        }
    }
}

impl GaugeOperator for TerminalOperator<'_> {
    fn prepare(&mut self, setup: Setup) -> Result<(), RigError> {
        if let Some(d) = self.device {
            d.with_plant(|p| p.set_cam(cam_setup(setup)));
        }
        if setup == Setup::Done {
            self.progress
                .suspend(|| eprintln!("{}", setup.instructions()));
            return Ok(());
        }
        self.ask(
            &format!("{}\nPress Enter when ready. ", setup.instructions()),
            &mut || Ok(()),
        )
        .map(|_| ())
    }

    fn window_sample(&mut self, _step: usize) {
        if let Some(d) = self.device {
            self.window.add(virtual_gauge_nmm(d));
        }
    }

    fn pressed(&mut self, _step: usize) {
        self.held_nmm = self.window.take();
    }

    fn gauge_nmm(
        &mut self,
        step: usize,
        m: &StepMeasurement,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<Reading, RigError> {
        if let Some(g) = &self.gauge {
            return from_file(g, step);
        }
        // Rehearsal on the virtual rig: what its gauge held, for the person to type.
        let shown = self
            .held_nmm
            .take()
            .map(|v| format!(" The virtual gauge holds {v:.1} N mm."))
            .unwrap_or_default();
        let what = match self.unit {
            GaugeUnit::Torque => "Gauge torque (N mm".to_string(),
            GaugeUnit::Force { arm_m: Some(l) } => {
                format!("Gauge force (N, on the {} m arm", reporting::human(l))
            }
            GaugeUnit::Force { arm_m: None } => "Gauge force and arm (F N @ L m".to_string(),
        };
        loop {
            let answer = self.ask(
                &format!(
                    "step {}: {:.2} V, {:.3} A; the drive is off, the gear locked.{shown} Held {what}; r: redo the step): ",
                    step + 1,
                    m.volts,
                    m.current_a
                ),
                keep_alive,
            )?;
            if answer.eq_ignore_ascii_case("r") {
                return Ok(Reading::Redo);
            }
            match parse_reading(&answer, self.unit) {
                Ok(v) => return Ok(Reading::Nmm(v)),
                Err(why) => eprintln!("{why}"),
            }
        }
    }
}
