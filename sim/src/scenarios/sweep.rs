//! The paper's required-torque test (Figs. 8-9): (Z1, Z4) = (49, 50), tau_rot from 0.368 to
//! 3.68 N m at V_in = 3.6, 6.2 and 8.8 V, five repeats, in random order as on a bench. Per
//! point: the mean current over 0.5 s from the start of constant cam speed (as the paper),
//! the cam speed, the firmware's tau_cam estimate and Eq. (10). The settings, rows and
//! summary `rig sim torque-sweep` prints; `rig experiment torque-sweep` runs it
//! (`host::experiment::paper::torque_sweep`).

use model::paper;
use model::plant::PlantEffects;
use serde::Serialize;

/// The sweep's settings.
#[derive(Debug, Clone)]
pub struct SweepOptions {
    /// Gear set.
    pub z: [u32; 4],
    /// Load torques, N m.
    pub loads: Vec<f64>,
    /// Supply voltages, V.
    pub voltages: Vec<f64>,
    /// Repeats per point.
    pub repeats: u32,
    /// Averaging window from the start of constant cam speed, s.
    pub window_s: f64,
    /// Rest between test points (the motor cools), s.
    pub rest_s: f64,
    /// Seed of the sensor noise and of the test order.
    pub seed: u64,
    /// Effects switched on in the plant (for the discrepancy workflow); by default the
    /// `paper` preset's ([`crate::Preset::paper`]), as the paper's rig measured.
    pub effects: PlantEffects,
    /// The ACS714's supply, V (ratiometric zero and sensitivity; the board allows
    /// 4.5-5.5 V).
    pub sensor_supply_v: f64,
}

impl Default for SweepOptions {
    fn default() -> Self {
        Self {
            z: paper::RIG_Z,
            loads: (1..=10)
                .map(|k| paper::TAU_ROT_MIN_TESTED * k as f64)
                .collect(),
            voltages: paper::SUPPLY_VOLTAGES.to_vec(),
            repeats: paper::REQUIRED_TORQUE_REPEATS,
            window_s: paper::CURRENT_AVERAGING_S,
            rest_s: 10.0,
            seed: 1,
            effects: crate::Preset::paper().effects,
            sensor_supply_v: model::hardware::acs714::SUPPLY_NOMINAL_V,
        }
    }
}

/// One test point (one CSV row): the rig tools' one measured-row type. The sweep fills
/// its supply, cam speed, load, current, temperature, repeat, backdrive observation and the
/// three tau_cam columns ([`rigfile::row::SIM_SWEEP`]).
pub use rigfile::row::MeasuredRow;

/// The name a sweep's row had before the rig tools shared one row type.
pub type SweepPoint = MeasuredRow;

/// What `rig sim torque-sweep --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct SweepSummary {
    /// Test points run.
    pub points: usize,
    /// Mean cam frequency per supply voltage, Hz, in `voltages` order.
    pub mean_hz_per_voltage: Vec<(f64, f64)>,
    /// The mean current grows with the load at every voltage.
    pub current_grows_with_load: bool,
    /// The mean current grows with the voltage (cam speed) at every load.
    pub current_grows_with_speed: bool,
    /// The firmware's tau_cam estimate grows with the load at every voltage.
    pub tau_cam_grows_with_load: bool,
    /// The firmware's tau_cam estimate grows with the cam speed at every load.
    pub tau_cam_grows_with_speed: bool,
    /// RMS difference of the measured tau_cam from Eq. (10), N m.
    pub rmse_tau_cam_vs_eq10_nm: f64,
    /// RMS difference of the firmware's estimate from the measured tau_cam, N m.
    pub rmse_estimate_vs_measured_nm: f64,
    /// Points where the output did not backdrive.
    pub not_backdriven: usize,
}

/// Summarises the points (means over repeats) and checks the paper's trends.
pub fn summarise(points: &[MeasuredRow], opts: &SweepOptions) -> SweepSummary {
    let mean = |v: f64, tau: f64, f: &dyn Fn(&MeasuredRow) -> f64| {
        let sel: Vec<f64> = points
            .iter()
            .filter(|p| p.v_in == Some(v) && p.tau_rot == tau)
            .map(f)
            .collect();
        sel.iter().sum::<f64>() / sel.len().max(1) as f64
    };
    let grows = |f: &dyn Fn(&MeasuredRow) -> f64| {
        let by_load = opts.voltages.iter().all(|&v| {
            opts.loads
                .windows(2)
                .all(|w| mean(v, w[1], f) > mean(v, w[0], f))
        });
        let by_speed = opts.loads.iter().all(|&tau| {
            opts.voltages
                .windows(2)
                .all(|w| mean(w[1], tau, f) > mean(w[0], tau, f))
        });
        (by_load, by_speed)
    };
    // A value the sweep did not measure (none here) counts as NaN: no trend, RMS NaN.
    let value = |v: Option<f64>| v.unwrap_or(f64::NAN);
    let (current_grows_with_load, current_grows_with_speed) = grows(&|p| value(p.i_in));
    let (tau_cam_grows_with_load, tau_cam_grows_with_speed) = grows(&|p| value(p.tau_cam_est));
    let rms = |f: &dyn Fn(&MeasuredRow) -> f64| {
        (points.iter().map(|p| f(p).powi(2)).sum::<f64>() / points.len().max(1) as f64).sqrt()
    };
    SweepSummary {
        points: points.len(),
        mean_hz_per_voltage: opts
            .voltages
            .iter()
            .map(|&v| {
                let sel: Vec<f64> = points
                    .iter()
                    .filter(|p| p.v_in == Some(v))
                    .map(|p| p.omega_n)
                    .collect();
                (
                    v,
                    sel.iter().sum::<f64>()
                        / sel.len().max(1) as f64
                        / (2.0 * std::f64::consts::PI),
                )
            })
            .collect(),
        current_grows_with_load,
        current_grows_with_speed,
        tau_cam_grows_with_load,
        tau_cam_grows_with_speed,
        rmse_tau_cam_vs_eq10_nm: rms(&|p| value(p.tau_cam_meas) - value(p.tau_cam_eq10)),
        rmse_estimate_vs_measured_nm: rms(&|p| value(p.tau_cam_est) - value(p.tau_cam_meas)),
        not_backdriven: points
            .iter()
            .filter(|p| p.backdriven == Some(false))
            .count(),
    }
}

/// Writes the points as CSV ([`rigfile::row::SIM_SWEEP`]: `t_s,v_in_v,omega_n_rad_s,
/// tau_rot_nm,i_in_a,temp_c,...`; no header without points) to `out`; callers that write a
/// file do so atomically (`reporting::write_atomic_with`).
pub fn write_csv<W: std::io::Write>(points: &[MeasuredRow], out: W) -> Result<(), csv::Error> {
    rigfile::row::SIM_SWEEP.write_csv(out, true, points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_columns_and_number_format_are_fixed() {
        // Numbers as the csv crate's serializer writes them (shortest round trip, `5.0`,
        // `1e-7`), under the column names, in this order.
        let p = MeasuredRow {
            t_s: Some(1.5),
            v_in: Some(3.6),
            omega_n: 31.41592653589793,
            tau_rot: 0.368,
            i_in: Some(2.5),
            temp_c: Some(25.0),
            repeat: Some(4),
            tau_cam_est: Some(1e-7),
            tau_cam_meas: Some(0.1 + 0.2),
            tau_cam_eq10: Some(12345678.0),
            backdriven: Some(false),
            // Not sim columns: not written.
            point: Some(7),
            load_kg: Some(1.0),
            target_hz: None,
        };
        let moved = MeasuredRow {
            backdriven: Some(true),
            ..p
        };
        let mut out = Vec::new();
        write_csv(&[p, moved], &mut out).unwrap();
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "t_s,v_in_v,omega_n_rad_s,tau_rot_nm,i_in_a,temp_c,repeat,tau_cam_est_nm,tau_cam_meas_nm,tau_cam_eq10_nm,backdriven\n\
             1.5,3.6,31.41592653589793,0.368,2.5,25.0,4,1e-7,0.30000000000000004,12345678.0,0\n\
             1.5,3.6,31.41592653589793,0.368,2.5,25.0,4,1e-7,0.30000000000000004,12345678.0,1\n"
        );
    }
}
