//! The two benches: a person at a real rig (prompts on the terminal, gauge readings typed
//! or from a CSV file), and the virtual device's plant (cam setup switched in the
//! simulation, the gauge read from the simulated arm).

use std::io::BufRead;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::time::Duration;

use indicatif::ProgressBar;
use model::plant::CamSetup;

use super::{Bench, Setup, StepMeasurement};
use crate::RigError;
use crate::device::VirtualDevice;

/// The virtual device as the bench: the operator's hands are the simulation's.
#[derive(Debug)]
pub struct SimBench<'a> {
    device: &'a VirtualDevice,
    gauge: Option<Vec<f64>>,
}

impl<'a> SimBench<'a> {
    /// The bench of `device`; `gauge` readings (N mm), when given, replace the simulated
    /// gauge.
    pub fn new(device: &'a VirtualDevice, gauge: Option<Vec<f64>>) -> Self {
        Self { device, gauge }
    }
}

impl Bench for SimBench<'_> {
    fn prepare(&mut self, setup: Setup) -> Result<(), RigError> {
        let cam = match setup {
            Setup::NoLoad => CamSetup::Uncoupled,
            Setup::Gauge => CamSetup::Blocked,
            Setup::Done => CamSetup::Coupled,
        };
        self.device.with_plant(|p| p.set_cam(cam));
        Ok(())
    }

    fn gauge_nmm(
        &mut self,
        step: usize,
        _measured: &StepMeasurement,
        _keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<f64, RigError> {
        if let Some(g) = &self.gauge {
            return g.get(step).copied().ok_or_else(|| {
                RigError::Operator(format!("no gauge reading for torque step {}", step + 1))
            });
        }
        Ok(self.device.with_plant(|p| p.state().gauge_torque) * 1e3)
    }
}

/// A person at the rig: set-up instructions and gauge prompts on stderr, answers on stdin
/// (read by a thread, so the drive's heartbeat goes on while the operator types).
#[derive(Debug)]
pub struct OperatorBench {
    gauge: Option<Vec<f64>>,
    progress: ProgressBar,
    lines: Option<Receiver<std::io::Result<String>>>,
}

impl OperatorBench {
    /// Prompts through `progress` (suspended while asking); `gauge` readings (N mm), when
    /// given, are used instead of asking.
    pub fn new(gauge: Option<Vec<f64>>, progress: ProgressBar) -> Self {
        Self {
            gauge,
            progress,
            lines: None,
        }
    }

    /// Asks `prompt` and waits for a line, calling `keep_alive` while waiting.
    fn ask(
        &mut self,
        prompt: &str,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<String, RigError> {
        self.progress.suspend(|| eprint!("{prompt}"));
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
            match lines.recv_timeout(Duration::from_millis(20)) {
                Ok(Ok(line)) => return Ok(line.trim().to_owned()),
                Ok(Err(e)) => return Err(RigError::Output(e)),
                Err(RecvTimeoutError::Timeout) => keep_alive()?,
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(RigError::Operator(
                        "calibrate needs the operator at the rig, but standard input ended: run it in a terminal (gauge readings can come from --gauge-csv FILE)".into(),
                    ));
                }
            }
        }
    }
}

impl Bench for OperatorBench {
    fn prepare(&mut self, setup: Setup) -> Result<(), RigError> {
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

    fn gauge_nmm(
        &mut self,
        step: usize,
        m: &StepMeasurement,
        keep_alive: &mut dyn FnMut() -> Result<(), RigError>,
    ) -> Result<f64, RigError> {
        if let Some(g) = &self.gauge {
            return g.get(step).copied().ok_or_else(|| {
                RigError::Operator(format!("no gauge reading for torque step {}", step + 1))
            });
        }
        loop {
            let answer = self.ask(
                &format!(
                    "step {}: {:.2} V, {:.3} A. Gauge torque (N mm): ",
                    step + 1,
                    m.volts,
                    m.current_a
                ),
                keep_alive,
            )?;
            match answer.parse::<f64>() {
                Ok(v) if v.is_finite() => return Ok(v),
                _ => self.progress.suspend(|| {
                    eprintln!("'{answer}' is not a number: type the torque in N mm, e.g. 37.5")
                }),
            }
        }
    }
}
