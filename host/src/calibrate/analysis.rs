//! The fits of the calibration: C1, C2 from the torque steps, C5, C6 from the no-load
//! sweep, C3 = C1 C5 and C4 = C1 C6 + C2 with propagated uncertainty, checked against a
//! direct fit of the loss torque.

use std::io::Write;

use serde::Serialize;

use rigfile::{FitSection, paper_units};

use super::fit::{Estimate, LineFit};
use super::{Measurements, StepMeasurement};
use crate::RigError;

/// A constant against the paper's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct VersusPaper {
    /// Measured.
    pub measured: f64,
    /// Table 2.
    pub paper: f64,
    /// (measured - paper) / |paper|.
    pub rel_error: f64,
}

/// C3 and C4 two ways.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Consistency {
    /// C3 = C1 C5 with its propagated uncertainty, N mm s/rad.
    pub c3_derived: Estimate,
    /// C4 = C1 C6 + C2 with its propagated uncertainty, N mm.
    pub c4_derived: Estimate,
    /// Slope of the direct fit of the loss torque C1 i + C2 against cam speed.
    pub c3_direct: f64,
    /// Intercept of that fit.
    pub c4_direct: f64,
    /// Whether derived and direct values agree within the derived 95 % intervals.
    pub agree: bool,
}

/// The fitted calibration (the model's [`model::Calibration`]) and the fits' statistics.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationResult {
    /// C1-C6 (SI inside; `c1`..`c6` in the paper's units at the top level of the JSON).
    #[serde(flatten, serialize_with = "paper_units::serialize")]
    pub calibration: model::Calibration,
    /// Torque against current: slope C1, intercept C2.
    pub torque_fit: LineFit,
    /// No-load current against cam speed: slope C5, intercept C6.
    pub no_load_fit: LineFit,
    /// The loss torque C1 i + C2 of the no-load points against cam speed: slope C3,
    /// intercept C4 (the direct fit).
    pub loss_fit: LineFit,
    /// C3 and C4 derived and direct.
    pub consistency: Consistency,
    /// Each constant against Table 2, C1..C6.
    pub versus_paper: [VersusPaper; 6],
    /// No-load points left out because the cam did not turn.
    pub stalled_points: usize,
}

impl CalibrationResult {
    /// C1..C6 in the paper's units.
    pub fn constants(&self) -> [f64; 6] {
        paper_units::to_paper(&self.calibration)
    }

    /// The constants in SI.
    pub fn to_model(&self) -> model::Calibration {
        self.calibration
    }

    /// `base` with C1..C6 replaced by these.
    pub fn apply_to(&self, base: &protocol::RigParameters) -> protocol::RigParameters {
        rigfile::wire::with_constants(base, &self.calibration)
    }

    /// The fit statistics as the rig file's `[calibration.fit]` (paper units, rounded to
    /// the digits that carry information).
    pub fn fit_section(&self) -> FitSection {
        let r = |v: f64| significant(v, 8);
        let ci = |v: [f64; 2]| v.map(|x| significant(x, 8));
        FitSection {
            torque_points: self.torque_fit.n as u32,
            torque_r_squared: r(self.torque_fit.r_squared),
            torque_residual_sd_nmm: r(self.torque_fit.residual_sd),
            no_load_points: self.no_load_fit.n as u32,
            no_load_r_squared: r(self.no_load_fit.r_squared),
            no_load_residual_sd_a: r(self.no_load_fit.residual_sd),
            ci95: [
                self.torque_fit.slope_ci95,
                self.torque_fit.intercept_ci95,
                self.consistency.c3_derived.ci95,
                self.consistency.c4_derived.ci95,
                self.no_load_fit.slope_ci95,
                self.no_load_fit.intercept_ci95,
            ]
            .map(ci),
            loss_direct: [self.consistency.c3_direct, self.consistency.c4_direct].map(r),
            consistent: self.consistency.agree,
        }
    }
}

/// `v` rounded to `digits` significant digits.
fn significant(v: f64, digits: usize) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    format!("{v:.*e}", digits.saturating_sub(1))
        .parse()
        .unwrap_or(v)
}

/// Below this mean speed a no-load point counts as stalled (the motor did not break away).
const STALLED_RAD_S: f64 = 0.02;

/// Fits C1, C2 (torque steps) and C5, C6 (no-load sweep), derives C3, C4 and checks them
/// against the direct fit.
pub fn analyse(m: &Measurements) -> Result<CalibrationResult, RigError> {
    let (i, tau): (Vec<f64>, Vec<f64>) = m
        .torque
        .iter()
        .map(|p| (p.step.current_a, p.gauge_nmm))
        .unzip();
    let torque_fit = LineFit::fit(&i, &tau).ok_or_else(|| {
        RigError::CalibrationFit(format!(
            "the torque-current fit needs at least 3 steps with different currents (got {})",
            m.torque.len()
        ))
    })?;
    let turning: Vec<&StepMeasurement> = m
        .no_load
        .iter()
        .filter(|s| s.cam_speed_rad_s > STALLED_RAD_S)
        .collect();
    let (w, i0): (Vec<f64>, Vec<f64>) = turning
        .iter()
        .map(|s| (s.cam_speed_rad_s, s.current_a))
        .unzip();
    let no_load_fit = LineFit::fit(&w, &i0).ok_or_else(|| {
        RigError::CalibrationFit(format!(
            "the no-load fit needs at least 3 sweep steps where the cam turns (got {} of {}): is the cam uncoupled, and does the motor start at 1.9 V?",
            turning.len(),
            m.no_load.len()
        ))
    })?;
    let (c1, c2) = (torque_fit.slope, torque_fit.intercept);
    let (c5, c6) = (no_load_fit.slope, no_load_fit.intercept);
    // The two fits are independent: each contributes its own variance, with its own
    // degrees of freedom, to the derived constants' intervals.
    let (dof_t, dof_n) = (
        torque_fit.n.saturating_sub(2),
        no_load_fit.n.saturating_sub(2),
    );
    let c3 = Estimate::from_parts(
        c1 * c5,
        &[
            (c5.powi(2) * torque_fit.slope_se.powi(2), dof_t),
            (c1.powi(2) * no_load_fit.slope_se.powi(2), dof_n),
        ],
    );
    let c4 = Estimate::from_parts(
        c1 * c6 + c2,
        &[
            (
                c6.powi(2) * torque_fit.slope_se.powi(2)
                    + torque_fit.intercept_se.powi(2)
                    + 2.0 * c6 * torque_fit.covariance,
                dof_t,
            ),
            (c1.powi(2) * no_load_fit.intercept_se.powi(2), dof_n),
        ],
    );
    let loss: Vec<f64> = i0.iter().map(|&i| c1 * i + c2).collect();
    let loss_fit = LineFit::fit(&w, &loss).ok_or_else(|| {
        RigError::CalibrationFit("the direct loss-torque fit has no spread in cam speed".into())
    })?;
    // Half a unit in the last place of the inputs: exact agreement must not fail on rounding.
    let within = |e: &Estimate, v: f64| {
        let slack = 1e-9 * e.value.abs().max(1e-12);
        v >= e.ci95[0] - slack && v <= e.ci95[1] + slack
    };
    let consistency = Consistency {
        c3_derived: c3,
        c4_derived: c4,
        c3_direct: loss_fit.slope,
        c4_direct: loss_fit.intercept,
        agree: within(&c3, loss_fit.slope) && within(&c4, loss_fit.intercept),
    };
    let constants = [c1, c2, c3.value, c4.value, c5, c6];
    let table2 = paper_units::table2();
    let versus_paper = std::array::from_fn(|k| VersusPaper {
        measured: constants[k],
        paper: table2[k],
        rel_error: (constants[k] - table2[k]) / table2[k].abs(),
    });
    Ok(CalibrationResult {
        calibration: paper_units::from_paper(constants),
        torque_fit,
        no_load_fit,
        loss_fit,
        consistency,
        versus_paper,
        stalled_points: m.no_load.len() - turning.len(),
    })
}

/// Writes the measured points as CSV: `test,volts,current_a,current_sd_a,cam_speed_rad_s,gauge_nmm`.
pub fn write_points_csv<W: Write>(m: &Measurements, out: W) -> Result<(), csv::Error> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record([
        "test",
        "volts",
        "current_a",
        "current_sd_a",
        "cam_speed_rad_s",
        "gauge_nmm",
    ])?;
    let row = |test: &str, s: &StepMeasurement, gauge: Option<f64>| {
        vec![
            test.to_owned(),
            format!("{:.3}", s.volts),
            format!("{:.6}", s.current_a),
            format!("{:.6}", s.current_sd_a),
            format!("{:.5}", s.cam_speed_rad_s),
            gauge.map(|g| format!("{g:.4}")).unwrap_or_default(),
        ]
    };
    for s in &m.no_load {
        w.write_record(row("no_load", s, None))?;
    }
    for p in &m.torque {
        w.write_record(row("torque", &p.step, Some(p.gauge_nmm)))?;
    }
    w.flush()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{CalibrationSchedule, TorquePoint};
    use super::*;

    fn step(volts: f64, current_a: f64, cam_speed_rad_s: f64) -> StepMeasurement {
        StepMeasurement {
            volts,
            current_a,
            current_sd_a: 0.01,
            cam_speed_rad_s,
            samples: 100,
        }
    }

    /// Points exactly on Table 2's lines give Table 2 back (C3, C4 derived).
    #[test]
    fn table2_lines_give_table2() {
        let c = paper_units::table2();
        let no_load = (0..10)
            .map(|k| {
                let w = 1.0 + f64::from(k);
                step(1.9 - 0.1 * f64::from(k), c[4] * w + c[5], w)
            })
            .collect();
        let torque = (0..9)
            .map(|k| {
                let i = 2.4 + 0.2 * f64::from(k);
                TorquePoint {
                    step: step(1.0, i, 0.0),
                    gauge_nmm: c[0] * i + c[1],
                }
            })
            .collect();
        let r = analyse(&Measurements { no_load, torque }).unwrap();
        let [c1, c2, c3, c4, ..] = r.constants();
        assert!((c1 - 62.1).abs() < 1e-9 && (c2 + 138.0).abs() < 1e-9);
        assert!((c3 - 62.1 * 0.00378).abs() < 1e-9);
        assert!((c4 - (62.1 * 2.25 - 138.0)).abs() < 1e-9);
        assert!(r.consistency.agree);
        assert!((r.torque_fit.r_squared - 1.0).abs() < 1e-12);
        assert_eq!(r.stalled_points, 0);
        let cal = r.apply_to(&protocol::RigParameters::paper());
        assert_eq!(cal.validate(), Ok(()));
    }

    /// The plan run on the plant directly (ideal drive and sensors, no firmware): the
    /// voltages reach Table 2, the motor keeps turning down to 1.0 V, C4 is close.
    #[test]
    fn plan_on_the_plant_gives_table2() {
        use model::plant::{CamSetup, Drive, Load, Plant, PlantParams};
        let gear = model::paper::RIG_GEARS;
        let mut plant = Plant::new(PlantParams::paper(gear, Load::Torque(0.0)), 7);
        let plan = CalibrationSchedule::default();
        let dt = 1e-4;
        let run = |plant: &mut Plant, volts: f64| {
            let drive = Drive {
                duty: volts / plant.params().supply,
                enabled: true,
            };
            for _ in 0..((plan.settle_s + plan.spin_up_s) / dt) as usize {
                plant.step(dt, drive);
            }
            let n = (plan.average_s / dt) as usize;
            let (mut i, mut w) = (0.0, 0.0);
            for _ in 0..n {
                plant.step(dt, drive);
                i += plant.logged_current();
                w += plant.state().cam_speed.abs();
            }
            step(volts, i / n as f64, w / n as f64)
        };
        plant.set_cam(CamSetup::Uncoupled);
        let no_load: Vec<_> = plan
            .sweep_volts
            .iter()
            .map(|&v| run(&mut plant, v))
            .collect();
        plant.set_cam(CamSetup::Blocked);
        let torque = plan
            .torque_volts
            .iter()
            .map(|&v| {
                let s = run(&mut plant, v);
                TorquePoint {
                    step: s,
                    gauge_nmm: plant.state().gauge_torque * 1e3,
                }
            })
            .collect();
        let r = analyse(&Measurements { no_load, torque }).unwrap();
        assert_eq!(r.stalled_points, 0);
        for v in &r.versus_paper[..3] {
            assert!(v.rel_error.abs() < 0.05, "{v:?}");
        }
        assert!(
            r.versus_paper[3].rel_error.abs() < 0.5,
            "{:?}",
            r.versus_paper[3]
        );
        for v in &r.versus_paper[4..] {
            assert!(v.rel_error.abs() < 0.05, "{v:?}");
        }
    }

    #[test]
    fn stalled_points_are_left_out_and_too_few_is_an_error() {
        let no_load: Vec<_> = (0..5)
            .map(|k| step(1.0, 2.2, if k < 3 { 0.0 } else { 5.0 }))
            .collect();
        let torque = (0..3)
            .map(|k| TorquePoint {
                step: step(1.0, 2.4 + f64::from(k), 0.0),
                gauge_nmm: 10.0 * f64::from(k),
            })
            .collect();
        let e = analyse(&Measurements { no_load, torque })
            .unwrap_err()
            .to_string();
        assert!(e.contains("2 of 5"), "{e}");
    }
}
