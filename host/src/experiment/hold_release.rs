//! `hold-release` (Fig. 5): the load hangs on the locked gear (held without vibration),
//! the vibrator runs (the gear releases, the load falls), the vibrator stops (with
//! mu_d Lambda < 1 the load keeps falling). The whole time history from telemetry, as
//! CSV and an SVG plot.

use std::path::Path;

use protocol::SupervisorState;
use reporting::plot::{self, Band, Legend, PALETTE, Series, XyPanel};
use serde::Serialize;

use super::bench::{Bench, Go, Operator, interrupted};
use crate::RigError;

/// Telemetry rate of the time history, Hz.
pub const TELEMETRY_HZ: u16 = 100;

/// The procedure's settings.
#[derive(Debug, Clone, Copy)]
pub struct HoldRelease {
    /// Load hung on the output, N m (Fig. 5: 1.0 kg on 75 mm, 0.736 N m); `None`: the
    /// load already on the rig (nobody is asked, nothing is set).
    pub load_nm: Option<f64>,
    /// Hold without vibration, s (the paper: 14.5 s).
    pub hold_s: f64,
    /// Vibration frequency, Hz (the paper: 3.6 V, about 5 Hz).
    pub hz: f64,
    /// How long the vibrator runs, s.
    pub release_s: f64,
    /// Recorded after the vibrator is switched off, s.
    pub after_s: f64,
}

impl Default for HoldRelease {
    fn default() -> Self {
        Self {
            load_nm: Some(model::paper::FIG5_LOAD.torque()),
            hold_s: model::paper::FIG5_HOLD_S,
            hz: model::paper::VIBRATION_HZ[0],
            release_s: 2.0,
            after_s: 1.5,
        }
    }
}

/// How a caller names the settings in its messages: the CLI's flags or Python's keywords.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SettingNames {
    /// The load, N m.
    pub load: &'static str,
    /// The hold without vibration, s.
    pub hold: &'static str,
    /// The vibration frequency, Hz.
    pub freq: &'static str,
    /// The vibration time, s.
    pub release: &'static str,
    /// The time recorded after the vibration stops, s.
    pub after: &'static str,
}

impl SettingNames {
    /// `rig experiment hold-release`'s flags.
    pub const CLI: Self = Self {
        load: "--load",
        hold: "--hold",
        freq: "--freq",
        release: "--release",
        after: "--after",
    };
    /// Python's `Rig.hold_release` keywords.
    pub const PYTHON: Self = Self {
        load: "load_nm",
        hold: "hold_s",
        freq: "freq_hz",
        release: "release_s",
        after: "after_s",
    };
}

/// Zero or more seconds; else what to give.
fn check_seconds(s: f64, positive: bool) -> Result<f64, String> {
    if s.is_finite() && (s > 0.0 || (!positive && s == 0.0)) {
        Ok(s)
    } else if positive {
        Err("give a positive number of seconds".into())
    } else {
        Err("give zero or a positive number of seconds".into())
    }
}

// One check per setting, which the CLI's value parsers and Python's `Rig.hold_release` both
// call ([`HoldRelease::checked`]); the reason says what to give, the caller names the setting.
impl HoldRelease {
    /// The hold without vibration, zero or more seconds.
    pub fn check_hold_s(s: f64) -> Result<f64, String> {
        check_seconds(s, false)
    }

    /// The vibration time, a positive number of seconds.
    pub fn check_release_s(s: f64) -> Result<f64, String> {
        check_seconds(s, true)
    }

    /// The time recorded after the vibration stops, zero or more seconds.
    pub fn check_after_s(s: f64) -> Result<f64, String> {
        check_seconds(s, false)
    }

    /// The load, 0 N m up to the gear's tooth strength (the board's release cap).
    pub fn check_load_nm(nm: f64) -> Result<f64, String> {
        let cap = model::BoardLimits::PAPER.max_release_load_nm;
        if nm.is_finite() && (0.0..=cap).contains(&nm) {
            Ok(nm)
        } else {
            Err(format!(
                "outside 0 to {} N m (the gear's tooth strength, {}): give at most that",
                reporting::human(cap),
                super::load_text(cap)
            ))
        }
    }

    /// These settings with every one checked, the frequency against the device's
    /// `calibration` ([`crate::limits::check_release_freq`], as `rig release`): the first
    /// bad one is an error naming it as `names` spell it. Nothing is silently changed.
    pub fn checked(
        self,
        names: SettingNames,
        calibration: &protocol::RigParameters,
    ) -> Result<Self, RigError> {
        let named = |name: &str, v: f64, checked: Result<f64, String>| {
            checked.map_err(|why| RigError::BadValue {
                what: format!("{name} {}", reporting::human(v)),
                why,
            })
        };
        if let Some(load) = self.load_nm {
            named(names.load, load, Self::check_load_nm(load))?;
        }
        named(names.hold, self.hold_s, Self::check_hold_s(self.hold_s))?;
        named(
            names.release,
            self.release_s,
            Self::check_release_s(self.release_s),
        )?;
        named(names.after, self.after_s, Self::check_after_s(self.after_s))?;
        let hz = crate::limits::check_release_freq(names.freq, self.hz, calibration)?;
        Ok(Self {
            hz: f64::from(hz),
            ..self
        })
    }
}

/// One sample of the time history (one CSV row).
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Sample {
    /// Time since the procedure started, s.
    pub t_s: f64,
    /// `hold`, `release` or `after`.
    pub phase: &'static str,
    /// Supervisor state.
    pub state: &'static str,
    /// Output angle since the start, rad (empty when nothing senses it).
    pub output_angle_rad: Option<f64>,
    /// Cam speed, rad/s.
    pub cam_speed_rad_s: f64,
    /// Motor current, A.
    pub current_a: f64,
}

/// Runs the procedure; `progress` gets a line per phase.
pub fn run<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &mut Operator,
    opts: &HoldRelease,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Sample>, RigError> {
    if let Some(load) = opts.load_nm {
        let asks = operator.forced || !bench.is_virtual();
        if asks
            && operator.before(&format!(
                "hang {} (Fig. 5: 1.0 kg on 75 mm)",
                super::load_text(load)
            ))? == Go::Skip
        {
            return Ok(Vec::new());
        }
        // On a virtual rig its hands hang what the operator confirmed (or the procedure
        // asked for); a real rig refuses the command and the person's load is on it.
        if bench.is_virtual() {
            bench.set_load(load)?;
        }
    }
    bench.start_telemetry(TELEMETRY_HZ)?;
    let mut samples = Vec::new();
    let result = record(bench, operator, opts, &mut samples, progress);
    bench.lock_gear();
    let _ = bench.stop_telemetry();
    result.map(|()| samples)
}

fn record<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &Operator,
    opts: &HoldRelease,
    samples: &mut Vec<Sample>,
    progress: &mut dyn FnMut(&str),
) -> Result<(), RigError> {
    let mut t0: Option<u64> = None;
    let mut angle0: Option<f64> = None;
    let phases = [
        ("hold", opts.hold_s),
        ("release", opts.release_s),
        ("after", opts.after_s),
    ];
    let mut end = 0.0;
    for (phase, length) in phases {
        progress(&format!("{phase}: {} s", reporting::human(length)));
        match phase {
            "release" => bench.release(true, opts.hz)?,
            "after" => bench.release(false, 0.0)?,
            _ => {}
        }
        end += length;
        loop {
            if operator.interrupted() {
                return Err(interrupted());
            }
            let Some(t) = bench.sample()? else {
                return Err(RigError::Protocol(
                    "telemetry stopped during hold-release: check the link".into(),
                ));
            };
            let start = *t0.get_or_insert(t.device_time_us);
            let t_s = t.device_time_us.saturating_sub(start) as f64 / 1e6;
            let angle = Some(f64::from(t.output_angle_rad))
                .filter(|a| a.is_finite())
                .or_else(|| bench.peek_output());
            let base = *angle0.get_or_insert(angle.unwrap_or(0.0));
            samples.push(Sample {
                t_s,
                phase,
                state: t.state.name(),
                output_angle_rad: angle.map(|a| a - base),
                cam_speed_rad_s: f64::from(t.cam_speed_rad_s),
                current_a: f64::from(t.current_a),
            });
            if !t.faults.is_empty() || t.state == SupervisorState::Fault {
                return Err(RigError::DeviceFault {
                    what: format!("hold-release ({phase})"),
                    faults: t.faults,
                });
            }
            if t_s >= end {
                break;
            }
        }
    }
    Ok(())
}

/// Writes the time history as CSV, atomically.
pub fn write_csv(samples: &[Sample], path: &Path) -> Result<(), RigError> {
    reporting::write_atomic_with(path, |tmp| {
        let mut w = csv::Writer::from_path(tmp).map_err(|e| RigError::BadValue {
            what: path.display().to_string(),
            why: format!("cannot write the CSV: {e}"),
        })?;
        for s in samples {
            // As a person writes them: the f32 readings as read, the angle (a difference
            // of two f32 readings) to the 7 digits they carry.
            let s = Sample {
                output_angle_rad: s.output_angle_rad.map(|a| reporting::significant(a, 7)),
                cam_speed_rad_s: reporting::human_f64(s.cam_speed_rad_s),
                current_a: reporting::human_f64(s.current_a),
                ..*s
            };
            w.serialize(s).map_err(|e| RigError::BadValue {
                what: path.display().to_string(),
                why: format!("cannot write the CSV: {e}"),
            })?;
        }
        w.flush()?;
        Ok(())
    })
}

/// Draws the time history (output angle, cam speed, current against time) into the SVG
/// file `path` printed at `size`, atomically.
pub fn write_svg(
    samples: &[Sample],
    path: &Path,
    size: reporting::figure::FigureSize,
) -> Result<(), RigError> {
    // The phases shaded, so the hold, the release and what follows read at a glance.
    let bands: Vec<Band> = ["hold", "release", "after"]
        .iter()
        .enumerate()
        .filter_map(|(k, &phase)| {
            let mut t = samples.iter().filter(|s| s.phase == phase).map(|s| s.t_s);
            let from = t.next()?;
            let to = t.next_back().unwrap_or(from);
            Some(Band {
                from,
                to,
                label: phase.into(),
                color: PALETTE[[2, 1, 4][k]],
            })
        })
        .collect();
    let x = plot::span(samples.iter().map(|s| s.t_s), 0.02, true);
    let panel =
        |caption: &str, y: &str, color: usize, f: &dyn Fn(&Sample) -> Option<f64>| XyPanel {
            caption: Some(caption.into()),
            x_label: plot::axis_label("t", "s"),
            y_label: y.into(),
            series: vec![Series::line(
                PALETTE[color % PALETTE.len()],
                2,
                samples
                    .iter()
                    .filter_map(|s| f(s).map(|v| (s.t_s, v)))
                    .collect(),
            )],
            x_range: Some(x),
            bands: bands.clone(),
            fine_grid: true,
            ..XyPanel::default()
        };
    let mut angle = panel(
        "output angle (Fig. 5)",
        &plot::axis_label("output angle", "rad"),
        0,
        &|s| s.output_angle_rad,
    );
    // The paper's number: the load held 14.5 s without vibration (Fig. 5).
    let paper_hold = model::paper::FIG5_HOLD_S;
    let (y0, y1) = angle.y_span();
    if let Some(start) = bands.first().map(|b| b.from)
        && x.1 >= start + paper_hold
    {
        angle.series.push(
            Series::line(
                PALETTE[5],
                1,
                vec![(start + paper_hold, y0), (start + paper_hold, y1)],
            )
            .labelled(format!("paper: held {} s", reporting::human(paper_hold))),
        );
        angle.series[0].label = Some("output angle".into());
        angle.legend = Some(Legend::Below);
    }
    let panels = [
        angle,
        panel("cam speed", &plot::axis_label("ω_n", "rad/s"), 1, &|s| {
            Some(s.cam_speed_rad_s)
        }),
        panel("motor current", &plot::axis_label("i_in", "A"), 2, &|s| {
            Some(s.current_a)
        }),
    ];
    // The title names the phases drawn (a run cut short has no release or after).
    let phases: Vec<&str> = bands.iter().map(|b| b.label.as_str()).collect();
    let title = if phases.is_empty() {
        "Fig. 5: time history".to_string()
    } else {
        format!("Fig. 5: {}", phases.join(", "))
    };
    Ok(plot::columns_figure(
        path,
        size,
        (470, 360),
        Some(&title),
        &panels,
    )?)
}

/// Fig. 5's numbers from a time history: whether the load held, when it moved after the
/// release request, the output speed when the vibration stopped and at the end, and the
/// rope paid out on a pulley of `radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fig5Numbers {
    /// The output stayed within 0.1 mm of rope during the hold.
    pub held_without_vibration: bool,
    /// From the release request to the first motion, s.
    pub release_to_motion_s: Option<f64>,
    /// Output speed at the end of the release, rad/s.
    pub output_speed_at_stop_rad_s: f64,
    /// Output speed at the end of the record, rad/s.
    pub output_speed_after_stop_rad_s: f64,
    /// Rope paid out, m.
    pub load_drop_m: f64,
    /// The output stood still (within 0.1 mm of rope) over the last
    /// [`STILL_WINDOW_S`] of the record after the cam stopped: mu_d Lambda > 1 brought it
    /// to rest.
    pub stops_after_vibration: bool,
    /// Output travel from the cam's stop to the end of the record, rad.
    pub after_stop_travel_rad: f64,
}

/// Cam speed below which the cam counts as stopped, rad/s.
pub const CAM_STOPPED_RAD_S: f64 = 0.5;

/// The output is at rest after the vibration when it did not move (0.1 mm of rope) over
/// this last stretch of the record, s.
pub const STILL_WINDOW_S: f64 = 0.2;

/// Reads [`Fig5Numbers`] from `samples`.
pub fn fig5_numbers(samples: &[Sample], radius_m: f64) -> Fig5Numbers {
    let angle = |s: &Sample| s.output_angle_rad.unwrap_or(0.0);
    let held = samples
        .iter()
        .filter(|s| s.phase == "hold")
        .all(|s| super::bench::moved(Some(0.0), Some(angle(s))) == Some(false));
    let release: Vec<&Sample> = samples.iter().filter(|s| s.phase == "release").collect();
    // The release is requested just before its first sample.
    let start = samples
        .iter()
        .rfind(|s| s.phase == "hold")
        .or(release.first().copied())
        .map_or(0.0, |s| s.t_s);
    let release_to_motion_s = release
        .iter()
        .find(|s| super::bench::moved(Some(0.0), Some(angle(s))) == Some(true))
        .map(|s| ((s.t_s - start) * 1e3).round() / 1e3);
    let speed = |set: &[&Sample]| match set {
        [.., a, b] if b.t_s > a.t_s => (angle(b) - angle(a)) / (b.t_s - a.t_s),
        _ => 0.0,
    };
    let all: Vec<&Sample> = samples.iter().collect();
    let after: Vec<&Sample> = samples.iter().filter(|s| s.phase == "after").collect();
    let stop = after
        .iter()
        .position(|s| s.cam_speed_rad_s.abs() < CAM_STOPPED_RAD_S);
    let (stops_after_vibration, after_stop_travel_rad) = match (stop, after.last()) {
        (Some(k), Some(last)) => {
            // At rest: no motion over the record's last STILL_WINDOW_S after the cam stop.
            let from = (last.t_s - STILL_WINDOW_S).max(after[k].t_s);
            let window_start = after[k..].iter().find(|s| s.t_s >= from).unwrap_or(last);
            let still = last.t_s - after[k].t_s >= STILL_WINDOW_S
                && super::bench::moved(Some(angle(window_start)), Some(angle(last))) == Some(false);
            (still, angle(last) - angle(after[k]))
        }
        _ => (false, 0.0),
    };
    Fig5Numbers {
        stops_after_vibration,
        after_stop_travel_rad,
        held_without_vibration: held,
        release_to_motion_s,
        output_speed_at_stop_rad_s: speed(&release),
        output_speed_after_stop_rad_s: speed(&all),
        load_drop_m: samples.last().map_or(0.0, |s| angle(s) * radius_m),
    }
}
