//! Where a fitted model and the measurement disagree: RMSE, residuals binned by cam speed,
//! load and time or temperature, a whiteness test in time order and correlation tests of the
//! residuals against the test conditions.

use serde::Serialize;

use super::fit::Fit;
use super::library::ThermalDriver;
use super::points::{THERMAL_BINS, TestPoints};
use super::stats;

/// Mean residual of one bin.
#[derive(Debug, Clone, Serialize)]
pub struct Bin {
    /// What the bin holds (e.g. "10.1 Hz", "1.47 N m", "31-35 C").
    pub label: String,
    /// Centre of the bin in the axis' unit (rad/s, N m, deg C or s).
    pub centre: f64,
    /// Rows in the bin.
    pub rows: usize,
    /// Mean residual (measured - model), mA.
    pub mean_residual_ma: f64,
    /// Standard error of that mean, mA.
    pub std_error_ma: f64,
}

/// Whiteness of the residuals in time order.
#[derive(Debug, Clone, Serialize)]
pub struct Whiteness {
    /// The order tested: "t_s" or "file".
    pub order: String,
    /// Lags of the Ljung-Box test.
    pub lags: usize,
    /// Ljung-Box statistic.
    pub ljung_box_q: f64,
    /// Its p-value (small: the residuals are correlated in time).
    pub p_value: f64,
    /// Durbin-Watson statistic (2: no lag-one correlation).
    pub durbin_watson: f64,
}

/// Correlation of the residuals with one test condition.
#[derive(Debug, Clone, Serialize)]
pub struct Correlation {
    /// The condition.
    pub with: String,
    /// Pearson correlation.
    pub r: f64,
    /// Two-sided p-value.
    pub p_value: f64,
}

/// The disagreement of one fitted model with the measurement.
#[derive(Debug, Clone, Serialize)]
pub struct Gap {
    /// Root mean square residual, A.
    pub rmse_a: f64,
    /// Mean residual, A.
    pub mean_residual_a: f64,
    /// Rows.
    pub rows: usize,
    /// Residuals by cam speed level.
    pub by_speed: Vec<Bin>,
    /// Residuals by load level.
    pub by_load: Vec<Bin>,
    /// Residuals by motor temperature (or time when no temperature was logged).
    pub by_thermal: Vec<Bin>,
    /// The axis of `by_thermal`: "temp_c", "t_s" or none.
    pub thermal_axis: Option<String>,
    /// Whiteness in time order.
    pub whiteness: Whiteness,
    /// Correlations with the test conditions (and of |residual| with the friction current).
    pub correlations: Vec<Correlation>,
}

/// Mean residual per level (`levels[j]` of row `j`), as bins labelled by their centre.
fn group(
    levels: impl Iterator<Item = usize>,
    centres: &[f64],
    residuals: &[f64],
    label: impl Fn(f64) -> String,
) -> Vec<Bin> {
    let mut sums = vec![(0usize, 0.0f64, 0.0f64); centres.len()];
    for (l, e) in levels.zip(residuals) {
        let s = &mut sums[l];
        s.0 += 1;
        s.1 += e;
        s.2 += e * e;
    }
    centres
        .iter()
        .zip(sums)
        .map(|(&c, (n, sum, sq))| bin_from_sums(label(c), c, n, sum, sq))
        .collect()
}

fn bin_from_sums(label: String, centre: f64, n: usize, sum: f64, sq: f64) -> Bin {
    let m = if n > 0 { sum / n as f64 } else { 0.0 };
    let sd = if n > 1 {
        ((sq - n as f64 * m * m).max(0.0) / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    Bin {
        label,
        centre,
        rows: n,
        mean_residual_ma: m * 1e3,
        std_error_ma: sd / (n.max(1) as f64).sqrt() * 1e3,
    }
}

/// The gap between `fit` (fitted to every point) and the measured currents of every row.
pub fn gap(points: &TestPoints, fit: &Fit) -> Gap {
    gap_of(points, fit, &fit.predict_rows(points))
}

/// [`gap`] with the fit's prediction of every row ([`Fit::predict_rows`]) at hand.
pub fn gap_of(points: &TestPoints, fit: &Fit, predicted_rows: &[f64]) -> Gap {
    let rv = &points.row_view;
    let ev = fit.model.evaluator();
    let res: Vec<f64> = rv
        .current
        .iter()
        .zip(predicted_rows)
        .map(|(y, f)| y - f)
        .collect();
    let n = res.len();
    let point = |j: usize| rv.point[j] as usize;
    let by_speed = group(
        (0..n).map(|j| points.speed_level[point(j)]),
        &points.speed_centres,
        &res,
        |w| format!("{:.1} Hz", w / (2.0 * std::f64::consts::PI)),
    );
    let by_load = group(
        (0..n).map(|j| points.load_level[point(j)]),
        &points.load_centres,
        &res,
        |t| format!("{t:.2} N m"),
    );
    let x = &rv.thermal;
    let (thermal_axis, offset, unit) = match points.thermal {
        ThermalDriver::Temperature { reference_c } => (Some("temp_c"), reference_c, "C"),
        ThermalDriver::Time => (Some("t_s"), 0.0, "s"),
        ThermalDriver::Unavailable => (None, 0.0, ""),
    };
    let by_thermal = if thermal_axis.is_some() && !rv.thermal_bin.is_empty() {
        // (rows, sum, square sum of residuals, lowest, highest and sum of the driver)
        let mut acc = vec![(0usize, 0.0, 0.0, f64::INFINITY, f64::NEG_INFINITY, 0.0); THERMAL_BINS];
        for j in 0..n {
            let a = &mut acc[rv.thermal_bin[j] as usize];
            a.0 += 1;
            a.1 += res[j];
            a.2 += res[j] * res[j];
            a.3 = a.3.min(x[j]);
            a.4 = a.4.max(x[j]);
            a.5 += x[j];
        }
        acc.into_iter()
            .filter(|a| a.0 > 0)
            .map(|(rows, sum, sq, lo, hi, xs)| {
                let (lo, hi) = (lo + offset, hi + offset);
                let c = xs / rows as f64 + offset;
                bin_from_sums(format!("{lo:.0}-{hi:.0} {unit}"), c, rows, sum, sq)
            })
            .collect()
    } else {
        Vec::new()
    };
    let lags = (n / 5).clamp(1, 10);
    let (q, p) = stats::ljung_box(&res, lags);
    let whiteness = Whiteness {
        order: if points.time_known { "t_s" } else { "file" }.into(),
        lags,
        ljung_box_q: q,
        p_value: p,
        durbin_watson: stats::durbin_watson(&res),
    };
    let omega = |j: usize| rv.omega_n[j];
    let tau = |j: usize| rv.tau_rot[j];
    let tau_omega = |j: usize| rv.tau_rot[j] * rv.omega_n[j];
    let mut conditions: Vec<(&str, &dyn Fn(usize) -> f64)> = vec![
        ("omega_n_rad_s", &omega),
        ("tau_rot_nm", &tau),
        ("tau_rot_nm*omega_n_rad_s", &tau_omega),
    ];
    let thermal_of = |j: usize| x[j];
    if let Some(axis) = thermal_axis {
        conditions.push((axis, &thermal_of));
    }
    let mut correlations: Vec<Correlation> = conditions
        .into_iter()
        .map(|(with, v)| {
            let r = stats::pearson_by(n, v, |j| res[j]);
            Correlation {
                with: with.to_string(),
                r,
                p_value: stats::correlation_p_value(r, n),
            }
        })
        .collect();
    let fric: Vec<f64> = (0..n).map(|j| ev.friction_current(&rv.op(j))).collect();
    let r = stats::pearson_by(n, |j| fric[j], |j| res[j].abs());
    drop(fric);
    correlations.push(Correlation {
        with: "|residual| vs friction current".into(),
        r,
        p_value: stats::correlation_p_value(r, n),
    });
    Gap {
        rmse_a: stats::rms(&res),
        mean_residual_a: stats::mean(&res),
        rows: n,
        by_speed,
        by_load,
        by_thermal,
        thermal_axis: thermal_axis.map(str::to_string),
        whiteness,
        correlations,
    }
}
