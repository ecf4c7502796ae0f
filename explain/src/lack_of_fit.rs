//! Lack of fit of the final model: do its residuals, averaged over the test conditions that
//! were repeated, stay within the noise the data's own repeats show?
//!
//! A cell is one speed level and one load level ([`TestPoints::speed_level`],
//! [`TestPoints::load_level`]). The mean residual of every cell is compared with the noise of
//! a mean of its rows, s^2 / n_c, plus the square of the model's own resolution
//! ([`fit::SIGMA_FLOOR_A`], the floor the likelihood uses too):
//! X = sum over cells of m_c^2 / (s^2 / n_c + f^2), with cells - p degrees of freedom (p:
//! the fitted mean parameters). The noise s comes, in order of preference, from
//! - the pure error of the repeats: the spread of the residuals within each cell (the
//!   classical F-test of lack of fit, against n - cells degrees of freedom);
//! - the same from successive repeats only, when the repeats drift (their spread within
//!   cells exceeds twice the spread of consecutive repeats): the drift is then part of the
//!   discrepancy, not of the noise;
//! - the noise the user states (`--stated-noise-ma`, or the synthetic sweep's);
//! - the current sensor's specification per sample (an upper bound for averaged rows, so the
//!   test is conservative);
//!
//! and the report says which. When the model's own resolution dominates the noise of the
//! cell means, the test is against that floor (`noise-floor`), as a chi-square.
//!
//! Where the discrepancy lives: the speed levels, load levels and stretches of time (or
//! temperature) whose mean residual stands out from that noise by more than
//! [`LOCATION_Z`].

use serde::Serialize;

use super::fit::{self, Fit};
use super::gap::{Bin, Gap};
use super::points::TestPoints;
use super::stats;

/// Level of the lack-of-fit test: a p-value below it is a significant discrepancy. Stricter
/// than the usual 0.05 so that effect-free data gives a false `unexplained` in about one set
/// in a thousand.
pub const LACK_OF_FIT_ALPHA: f64 = 0.001;
/// Fewest degrees of freedom of pure error for the repeats to be the reference.
pub const MIN_PURE_ERROR_DOF: usize = 5;
/// Repeats drift when their spread within cells exceeds this many times the spread of
/// consecutive repeats (in variance).
pub const DRIFT_VARIANCE_RATIO: f64 = 2.0;
/// A bin is where the discrepancy lives when its mean residual is this many of its standard
/// errors (the model's resolution included) from zero.
pub const LOCATION_Z: f64 = 3.5;

/// The current sensor's noise per sample, A: the ACS714's output noise over its
/// sensitivity (27 mA).
pub fn sensor_spec_sigma_a() -> f64 {
    model::hardware::acs714::NOISE_RMS_V / model::hardware::acs714::SENSITIVITY_V_PER_A
}

/// A speed level, load range or stretch of time where the final model misses.
#[derive(Debug, Clone, Serialize)]
pub struct Location {
    /// The axis: `omega_n_rad_s`, `tau_rot_nm`, `t_s` or `temp_c`.
    pub axis: String,
    /// The bin (e.g. "15.0 Hz", "3.68 N m", "120-300 s").
    pub label: String,
    /// Rows in it.
    pub rows: usize,
    /// Mean residual (measured - model), mA.
    pub mean_residual_ma: f64,
    /// That mean over its standard error (the model's resolution included).
    pub z: f64,
}

/// The lack-of-fit test of the final model.
#[derive(Debug, Clone, Serialize)]
pub struct LackOfFit {
    /// Whether the test could be made (more cells than fitted parameters).
    pub testable: bool,
    /// The test: `F` (against pure error) or `chi-square` (against a stated noise).
    pub test: String,
    /// The statistic: F, or X for the chi-square.
    pub statistic: f64,
    /// Degrees of freedom of the lack of fit (cells - fitted mean parameters).
    pub dof: f64,
    /// Degrees of freedom of the noise estimate (null for a stated noise).
    pub dof_error: Option<f64>,
    /// The p-value.
    pub p_value: f64,
    /// Whether p is below [`LACK_OF_FIT_ALPHA`].
    pub significant: bool,
    /// The level used.
    pub alpha: f64,
    /// What the test is against: `pure-error`, `pure-error-successive` (the repeats drift),
    /// `stated-noise`, `sensor-spec` or `noise-floor`.
    pub against: String,
    /// The same in words, with the numbers.
    pub against_text: String,
    /// The row noise of the reference, A.
    pub sigma_a: f64,
    /// The model's own resolution added to every cell mean, A.
    pub floor_a: f64,
    /// Cells (speed level x load level) with rows.
    pub cells: usize,
    /// Rows per cell, mean.
    pub rows_per_cell: f64,
    /// RMS of the cell means of the residuals, mA.
    pub cell_rms_ma: f64,
    /// Where the discrepancy lives, strongest first (empty when nothing stands out).
    pub locations: Vec<Location>,
}

impl LackOfFit {
    /// The test in words, e.g. "lack of fit F = 4.2 on 25 and 120 dof, p = 3e-8, against
    /// the pure error of the repeats (9.8 mA)".
    pub fn text(&self) -> String {
        if !self.testable {
            return format!("lack of fit not testable: {}", self.against_text);
        }
        let dof = match self.dof_error {
            Some(d) if self.test == "F" => format!("on {:.0} and {:.0} dof", self.dof, d),
            _ => format!("on {:.0} dof", self.dof),
        };
        format!(
            "lack of fit {} = {:.2} {dof}, p = {}, against {}",
            if self.test == "F" { "F" } else { "X^2" },
            self.statistic,
            p_short(self.p_value),
            self.against_text
        )
    }

    /// Where the discrepancy lives, in words ("" when nothing stands out).
    pub fn locations_text(&self) -> String {
        self.locations
            .iter()
            .map(|l| {
                format!(
                    "{} {:+.1} mA at {} ({} rows)",
                    axis_word(&l.axis),
                    l.mean_residual_ma,
                    l.label,
                    l.rows
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

fn axis_word(axis: &str) -> &'static str {
    match axis {
        "omega_n_rad_s" => "by cam speed:",
        "tau_rot_nm" => "by load:",
        "temp_c" => "by temperature:",
        _ => "in time:",
    }
}

/// A p-value as printed: 3 significant digits, or "< 1e-12".
pub fn p_short(p: f64) -> String {
    if p < 1e-12 {
        "< 1e-12".into()
    } else if p < 0.001 {
        format!("{p:.1e}")
    } else {
        format!("{p:.3}")
    }
}

/// Fitted parameters of the mean current of `fit` (mu, effects, term coordinates).
fn mean_parameters(fit: &Fit) -> usize {
    fit.free.len() + fit.term_x.iter().map(Vec::len).sum::<usize>()
}

/// The lack-of-fit test of `fit` (fitted to every point of `points`), whose measured minus
/// fitted current of every row of [`TestPoints::row_view`] is `residuals`, with `gap` its gap
/// for the locations; `stated_noise_a` is the row noise the user states, if any.
pub fn lack_of_fit(
    points: &TestPoints,
    fit: &Fit,
    residuals: &[f64],
    gap: &Gap,
    stated_noise_a: Option<f64>,
) -> LackOfFit {
    let rv = &points.row_view;
    let levels = points.load_centres.len().max(1);
    let cell_of = |j: usize| {
        let k = rv.point[j] as usize;
        points.speed_level[k] * levels + points.load_level[k]
    };
    let cells_total = points.speed_centres.len().max(1) * levels;
    // Per cell: rows, sum, square sum, last residual in time order; successive differences.
    let mut acc = vec![(0usize, 0.0f64, 0.0f64, f64::NAN); cells_total];
    let (mut succ_ss, mut succ_pairs) = (0.0f64, 0usize);
    for (j, &e) in residuals.iter().enumerate() {
        let a = &mut acc[cell_of(j)];
        if a.3.is_finite() {
            succ_ss += (e - a.3) * (e - a.3);
            succ_pairs += 1;
        }
        a.0 += 1;
        a.1 += e;
        a.2 += e * e;
        a.3 = e;
    }
    let used: Vec<(usize, f64)> = acc
        .iter()
        .filter(|a| a.0 > 0)
        .map(|a| (a.0, a.1 / a.0 as f64))
        .collect();
    let cells = used.len();
    let n: usize = used.iter().map(|u| u.0).sum();
    let pe_ss: f64 = acc
        .iter()
        .filter(|a| a.0 > 0)
        .map(|a| (a.2 - a.1 * a.1 / a.0 as f64).max(0.0))
        .sum();
    let pe_dof = n.saturating_sub(cells);
    let p = mean_parameters(fit);
    let dof = cells as f64 - p as f64;
    let floor = fit::SIGMA_FLOOR_A;
    let rows_per_cell = n as f64 / cells.max(1) as f64;
    let cell_rms_ma =
        (used.iter().map(|u| u.1 * u.1).sum::<f64>() / cells.max(1) as f64).sqrt() * 1e3;

    // The reference noise of a row.
    let (mut against, mut sigma, mut dof_error, mut text) = if pe_dof >= MIN_PURE_ERROR_DOF {
        let s2_pe = pe_ss / pe_dof as f64;
        let s2_succ = if succ_pairs >= MIN_PURE_ERROR_DOF {
            succ_ss / (2.0 * succ_pairs as f64)
        } else {
            f64::NAN
        };
        if s2_succ.is_finite() && s2_pe > DRIFT_VARIANCE_RATIO * s2_succ {
            (
                "pure-error-successive",
                s2_succ.sqrt(),
                Some(succ_pairs as f64),
                format!(
                    "the pure error of successive repeats ({:.1} mA; the repeats drift: {:.1} mA within cells)",
                    s2_succ.sqrt() * 1e3,
                    s2_pe.sqrt() * 1e3
                ),
            )
        } else {
            (
                "pure-error",
                s2_pe.sqrt(),
                Some(pe_dof as f64),
                format!(
                    "the pure error of the repeats ({:.1} mA, {pe_dof} dof in {cells} cells)",
                    s2_pe.sqrt() * 1e3
                ),
            )
        }
    } else if let Some(s) = stated_noise_a.filter(|s| s.is_finite() && *s > 0.0) {
        (
            "stated-noise",
            s,
            None,
            format!(
                "the stated noise ({:.1} mA; too few repeats for a pure error)",
                s * 1e3
            ),
        )
    } else {
        let s = sensor_spec_sigma_a();
        (
            "sensor-spec",
            s,
            None,
            format!(
                "the current sensor's specification ({:.0} mA per sample, an upper bound for averaged rows; too few repeats for a pure error and no --stated-noise-ma)",
                s * 1e3
            ),
        )
    };
    // The model's resolution dominates the noise of a typical cell mean.
    if floor * floor > sigma * sigma / rows_per_cell.max(1.0) {
        text = format!(
            "the model's own resolution ({:.1} mA, above the {:.1} mA noise of a cell mean from {text})",
            floor * 1e3,
            sigma / rows_per_cell.max(1.0).sqrt() * 1e3
        );
        against = "noise-floor";
        dof_error = None;
    }
    if sigma <= 0.0 || !sigma.is_finite() {
        sigma = 0.0;
    }
    let x: f64 = used
        .iter()
        .map(|&(nc, m)| m * m / (sigma * sigma / nc as f64 + floor * floor))
        .sum();
    let locations = locations(gap, sigma, floor);
    if dof < 1.0 {
        return LackOfFit {
            testable: false,
            test: "none".into(),
            statistic: 0.0,
            dof,
            dof_error,
            p_value: 1.0,
            significant: false,
            alpha: LACK_OF_FIT_ALPHA,
            against: "none".into(),
            against_text: format!(
                "{cells} cells of speed and load for {p} fitted parameters: test more speed and load levels"
            ),
            sigma_a: sigma,
            floor_a: floor,
            cells,
            rows_per_cell,
            cell_rms_ma,
            locations,
        };
    }
    let (test, statistic, p_value) = match dof_error {
        Some(d2) => ("F", x / dof, stats::f_sf(x / dof, dof, d2)),
        None => ("chi-square", x, stats::chi2_sf(x, dof)),
    };
    LackOfFit {
        testable: true,
        test: test.into(),
        statistic,
        dof,
        dof_error,
        p_value,
        significant: p_value < LACK_OF_FIT_ALPHA,
        alpha: LACK_OF_FIT_ALPHA,
        against: against.into(),
        against_text: text,
        sigma_a: sigma,
        floor_a: floor,
        cells,
        rows_per_cell,
        cell_rms_ma,
        locations,
    }
}

/// The bins of `gap` whose mean residual stands out from the noise `sigma` of their rows and
/// the model's resolution `floor`, strongest first (up to six).
fn locations(gap: &Gap, sigma: f64, floor: f64) -> Vec<Location> {
    let thermal = gap.thermal_axis.clone().unwrap_or_else(|| "t_s".into());
    let axes: [(&str, &[Bin]); 3] = [
        ("omega_n_rad_s", &gap.by_speed),
        ("tau_rot_nm", &gap.by_load),
        (thermal.as_str(), &gap.by_thermal),
    ];
    let mut out: Vec<Location> = Vec::new();
    for (axis, bins) in axes {
        for b in bins.iter().filter(|b| b.rows > 0) {
            let se = (sigma * sigma / b.rows as f64 + floor * floor).sqrt() * 1e3;
            let z = b.mean_residual_ma / se;
            if z.abs() > LOCATION_Z {
                out.push(Location {
                    axis: axis.to_string(),
                    label: b.label.clone(),
                    rows: b.rows,
                    mean_residual_ma: b.mean_residual_ma,
                    z,
                });
            }
        }
    }
    out.sort_by(|a, b| b.z.abs().total_cmp(&a.z.abs()));
    out.truncate(6);
    out
}
