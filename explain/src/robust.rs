//! Robustness: rows that cannot be right, rows that stand out from their neighbours, and rig
//! values that make no physical sense.
//!
//! 1. Range rules (the rig's hardware, [`model::hardware`]): a current beyond the current
//!    sensor's range (ACS714, +-5 A), a cam speed beyond the motor's no-load speed at the
//!    H-bridge supply (12 V / 0.078 V s/rad = 154 rad/s), a motor temperature outside
//!    -40..150 C, or a negative mean current. Such a row is an outlier. When most rows break
//!    the same rule the column is wrong as a whole (a unit or a sign), and that is an error
//!    naming the fix.
//! 2. Residual rule: each row's residual under the starting model, less the median of the
//!    rows at the same conditions (same cam-speed and load level; on pooled data the rows of
//!    its pool) and, in time order, less the running median of its 11 neighbours, so every
//!    smooth effect (of any form) drops out and an isolated bad row is left standing. A row
//!    more than [`OUTLIER_LIMIT`] robust standard deviations away is an outlier; the scale is
//!    taken per load level (the mesh ripple scatters heavy loads more) and sees a minority
//!    spread ([`spread_scale`]).
//! 3. Warnings: negative loads (the model uses |tau_rot|), loads and frequencies above the
//!    board's caps ([`model::BoardLimits::check`], the firmware's rule), voltages above the
//!    H-bridge supply, and rig-file values: the calibration is checked with the firmware's
//!    [`model::Calibration::check`] against the RS-735 (a wrong sign is an error, an
//!    implausible or inconsistent constant a warning), the cam and friction values against
//!    plausible ranges.
//!
//! Outliers are excluded from every fit and listed with their data row, file line and the
//! reason.

use model::hardware::{acs714, board, rs735};
use model::{BoardLimits, CalibrationIssue, MotorConstants};
use rigfile::RigFile;
use serde::Serialize;

use crate::ExplainError;
use crate::data::Dataset;
use crate::points::TestPoints;

/// Robust standard deviations beyond which a row is an outlier.
pub const OUTLIER_LIMIT: f64 = 5.5;
/// Motor temperatures outside this range, deg C, are not a working motor's.
pub const TEMPERATURE_RANGE_C: (f64, f64) = (-40.0, 150.0);
/// When more than this share of the rows stand out, they are not isolated bad rows: they are
/// reported in a warning and kept.
const MAX_OUTLIER_SHARE: f64 = 0.05;
/// Half-width of the running median in time order.
const RUNNING_HALF_WIDTH: usize = 5;
/// Fewest rows at one set of conditions whose median stands for them.
const MIN_NEIGHBOURS: usize = 3;
/// Fewest rows of a pool whose median stands for them (else the cell's does).
const MIN_POOL_ROWS: f64 = 8.0;
/// Fewest rows of a load level with a scale of their own.
const MIN_LEVEL_ROWS: usize = 8;
/// Rows the global scale counts for when a load level's scale is shrunk towards it.
const LEVEL_PRIOR_ROWS: f64 = 30.0;
/// Scale of the median absolute deviation to a normal standard deviation.
const MAD_SCALE: f64 = 1.4826;

/// A row set aside.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Outlier {
    /// Data row as the user counts it (1-based, the header not counted).
    pub row: usize,
    /// Line in the file (1-based, the header is line 1).
    pub line: u64,
    /// The column at fault.
    pub column: String,
    /// Its value.
    pub value: f64,
    /// Why the row was set aside.
    pub reason: String,
}

/// The cam speed the motor reaches without load at the H-bridge supply, rad/s.
pub fn no_load_cam_speed() -> f64 {
    board::BRIDGE_SUPPLY_V / rs735::KE_CAM_V_S_PER_RAD
}

/// What the range rules found in a data set.
#[derive(Debug, Clone, Default)]
pub struct RangeCheck {
    /// Rows to leave out (indexed like the data set).
    pub excluded: Vec<bool>,
    /// Those rows, with why.
    pub outliers: Vec<Outlier>,
    /// Things to fix that did not exclude a row.
    pub warnings: Vec<String>,
}

/// Rows of `data` that break a range rule, and the warnings its columns give. An error when
/// most rows break the same rule (a unit or sign slip of a whole column).
pub fn range_check(data: &Dataset) -> Result<RangeCheck, ExplainError> {
    let n = data.len();
    let mut excluded = vec![false; n];
    let mut outliers = Vec::new();
    let mut warnings = Vec::new();
    let w_max = no_load_cam_speed();
    let (t_lo, t_hi) = TEMPERATURE_RANGE_C;
    let current = data.i_in();
    let with_current = current.iter().filter(|v| !v.is_nan()).count();
    // (column, rule text, fix, test, rows to judge)
    type Rule<'a> = (
        &'static str,
        String,
        &'static str,
        Box<dyn Fn(usize) -> Option<f64> + 'a>,
        usize,
    );
    let mut rules: Vec<Rule> = vec![
        (
            "i_in_a",
            format!(
                "is beyond the current sensor's range (ACS714, +-{} A)",
                acs714::RANGE_A
            ),
            "give the current in A (not mA) or remove the misread rows",
            Box::new(|k| {
                let v = current[k];
                (v.abs() > acs714::RANGE_A).then_some(v)
            }),
            with_current,
        ),
        (
            "i_in_a",
            "is negative: the vibrator drives the cam, so its mean current is positive".into(),
            "check the current sensor's sign and flip the column",
            Box::new(|k| {
                let v = current[k];
                (v < 0.0 && v.abs() <= acs714::RANGE_A).then_some(v)
            }),
            with_current,
        ),
        (
            "omega_n_rad_s",
            format!(
                "is beyond the motor's no-load cam speed ({:.0} rad/s, {:.1} Hz at the {} V supply)",
                w_max,
                w_max / (2.0 * std::f64::consts::PI),
                board::BRIDGE_SUPPLY_V
            ),
            "give the cam speed in rad/s (not rpm, and not the motor shaft's speed)",
            Box::new(|k| {
                let v = data.omega_n()[k];
                (v > w_max).then_some(v)
            }),
            n,
        ),
    ];
    if let Some(temp) = data.temp_c() {
        rules.push((
            "temp_c",
            format!("is outside the motor's possible temperatures ({t_lo}..{t_hi} C)"),
            "give the motor temperature in deg C (not K or F)",
            Box::new(move |k| {
                let v = temp[k];
                (!(t_lo..=t_hi).contains(&v)).then_some(v)
            }),
            n,
        ));
    }
    for (column, rule, fix, test, judged) in &rules {
        let hits: Vec<(usize, f64)> = (0..n).filter_map(|k| test(k).map(|v| (k, v))).collect();
        if hits.is_empty() {
            continue;
        }
        if 2 * hits.len() > *judged {
            let (k, v) = hits[0];
            return Err(ExplainError::BadValue {
                what: format!("{} column {column}", data.name),
                why: format!(
                    "{} {rule} in {} of {judged} rows (first: row {}, line {}, {v}): {fix}",
                    column,
                    hits.len(),
                    k + 1,
                    data.line(k)
                ),
            });
        }
        for (k, v) in hits {
            if !excluded[k] {
                excluded[k] = true;
                outliers.push(Outlier {
                    row: k + 1,
                    line: data.line(k),
                    column: column.to_string(),
                    value: v,
                    reason: format!("{column} = {} {rule}; {fix}", short(v)),
                });
            }
        }
    }

    // Warnings: negative loads, the board's caps, the supply.
    let tau = data.tau_rot();
    let negative: Vec<usize> = (0..n).filter(|&k| tau[k] < 0.0).collect();
    if let Some(&k) = negative.first() {
        warnings.push(format!(
            "tau_rot_nm is negative in {} of {n} rows (first: row {}, line {}): the model uses the load's magnitude |tau_rot|; if the sign is not a direction convention, fix the column",
            negative.len(),
            k + 1,
            data.line(k)
        ));
    }
    let kept = |k: &usize| !excluded[*k];
    let max_load = (0..n)
        .filter(kept)
        .map(|k| tau[k].abs())
        .fold(0.0, f64::max);
    let max_freq = (0..n)
        .filter(kept)
        .map(|k| data.omega_n()[k] / (2.0 * std::f64::consts::PI))
        .fold(0.0, f64::max);
    let caps = BoardLimits::PAPER;
    for requested in [
        BoardLimits {
            max_release_load_nm: max_load,
            ..caps
        },
        BoardLimits {
            max_freq_hz: max_freq,
            ..caps
        },
    ] {
        if let Err(issue) = caps.check(&requested)
            && issue.kind == model::calibration::LimitIssueKind::AboveCap
        {
            warnings.push(format!(
                "the data's largest {} is above what the rig's board runs: {issue}; the fits use the rows, but check the column's unit",
                match issue.field {
                    model::calibration::LimitField::MaxReleaseLoad => "load",
                    _ => "vibration frequency",
                }
            ));
        }
    }
    if let Some(v) = data.v_in() {
        let over: Vec<usize> = (0..n)
            .filter(|&k| v[k].abs() > board::BRIDGE_SUPPLY_V)
            .collect();
        if let Some(&k) = over.first() {
            warnings.push(format!(
                "v_in_v is above the H-bridge supply ({} V) in {} rows (first: row {}, line {}, {} V): the column is not used by the fits, but check its unit",
                board::BRIDGE_SUPPLY_V,
                over.len(),
                k + 1,
                data.line(k),
                short(v[k])
            ));
        }
    }
    warnings.extend(duplicates(data));
    Ok(RangeCheck {
        excluded,
        outliers,
        warnings,
    })
}

/// Repeated rows (every value the same as another row's) and repeated time stamps, as
/// warnings: a logger that wrote a line twice, or files joined twice, weigh some test points
/// double. Sorted 64-bit keys keep it linear in memory (8 bytes a row).
fn duplicates(data: &Dataset) -> Vec<String> {
    let n = data.len();
    let mut out = Vec::new();
    let mix = |h: u64, v: f64| -> u64 {
        (h ^ v.to_bits())
            .wrapping_mul(0x9e37_79b9_7f4a_7c15)
            .rotate_left(29)
    };
    let t = data.t_s();
    let count_repeats = |mut keys: Vec<u64>| -> usize {
        keys.sort_unstable();
        keys.windows(2).filter(|w| w[0] == w[1]).count()
    };
    let rows = count_repeats(
        (0..n)
            .map(|k| {
                let mut h = mix(0, data.omega_n()[k]);
                h = mix(h, data.tau_rot()[k]);
                h = mix(h, data.i_in()[k]);
                t.map_or(h, |t| mix(h, t[k]))
            })
            .collect(),
    );
    if rows > 0 {
        out.push(format!(
            "{rows} of {n} rows repeat an earlier row exactly (cam speed, load, current{}): a line written twice or a file joined twice weighs those test points double; remove the copies if they are not real repeats",
            if t.is_some() { " and time" } else { "" }
        ));
    }
    if let Some(t) = t {
        let stamps = count_repeats(
            t.iter()
                .filter(|v| v.is_finite())
                .map(|v| v.to_bits())
                .collect(),
        );
        if stamps > rows {
            out.push(format!(
                "{stamps} of {n} rows share their t_s with another row: the time order (whiteness, drift, blocks) is ambiguous there; check the logger's clock or the column"
            ));
        }
    }
    out
}

/// Rows the unit screen ([`unit_check`]) reads at most (evenly spread over the file).
const UNIT_SCREEN_ROWS: usize = 20_000;

/// Largest ratio of the upper to the lower quartile of the back-EMF speed shares for the
/// `v_in_v` column to speak on the speed's unit: the motor's resistance warms by at most
/// half over a session (+0.39 %/K up to 150 C), which moves a share by far less.
const BACK_EMF_SCATTER: f64 = 1.5;

/// The cam-speed units the unit screen tries: rad/s per unit, name, and the fix.
const SPEED_UNITS: [(f64, &str, &str); 3] = [
    (1.0, "rad/s", ""),
    (
        std::f64::consts::TAU,
        "Hz",
        "multiply the column by 2 pi = 6.283",
    ),
    (
        std::f64::consts::TAU / 60.0,
        "rpm",
        "multiply the column by 2 pi / 60 = 0.1047",
    ),
];

/// One row the unit screen reads: cam speed, load and current as given, and the vibrator
/// voltage (NaN without a `v_in_v` column).
#[derive(Debug, Clone, Copy)]
struct ScreenRow {
    omega_n: f64,
    tau_rot: f64,
    i_in: f64,
    v_in: f64,
}

/// One reading of the speed and load columns: scale factors to SI and the unit they assume.
struct Reading {
    speed_scale: f64,
    load_scale: f64,
    speed_unit: &'static str,
    load_unit: &'static str,
}

/// The paper's model fitted to the rows under one [`Reading`].
struct ReadingFit {
    /// mu by least squares.
    mu: f64,
    /// RMS misfit, A.
    rmse: f64,
    /// Rows of the heavier half whose friction current alone, at the least physical mu and
    /// the loads of the reading, exceeds the row's whole measured current.
    loads_beyond_current: usize,
}

/// The paper's model with mu fitted by least squares on `rows` read with `r`. The current
/// is affine in mu (Eq. 10), so two evaluations per row give it exactly: the friction
/// current per unit mu, a, and the rest, b. With `mu_lo` the least physical mu, a row whose
/// `mu_lo a` exceeds its measured current cannot carry its load as read: the rest (loss,
/// inertia, -C2 / C1) is never negative, so on any rig the measured current pays at least
/// the friction of the true mu >= `mu_lo`. Those rows are counted among the ones whose
/// load is at least `heavy` (as given), where the friction weighs most.
fn affine_mu_fit(
    start: &model::effects::CurrentModel,
    rows: &[ScreenRow],
    r: &Reading,
    mu_lo: f64,
    heavy: f64,
) -> ReadingFit {
    let at = |mu: f64| {
        let mut m = *start;
        m.mu = mu;
        m
    };
    let (m0, m1) = (at(0.0).evaluator(), at(1.0).evaluator());
    let (mut saa, mut say) = (0.0, 0.0);
    let mut loads_beyond_current = 0;
    let mut parts = Vec::with_capacity(rows.len());
    for row in rows {
        let op = model::effects::OperatingPoint::new(
            row.omega_n * r.speed_scale,
            row.tau_rot * r.load_scale,
            0.0,
        );
        let b = m0.current(&op);
        let a = m1.current(&op) - b;
        let y = row.i_in;
        saa += a * a;
        say += a * (y - b);
        if row.tau_rot.abs() >= heavy && mu_lo * a > y {
            loads_beyond_current += 1;
        }
        parts.push((a, b, y));
    }
    let mu = if saa > 0.0 { say / saa } else { 0.0 };
    let sse: f64 = parts
        .iter()
        .map(|(a, b, y)| (y - b - mu * a) * (y - b - mu * a))
        .sum();
    ReadingFit {
        mu,
        rmse: (sse / rows.len().max(1) as f64).sqrt(),
        loads_beyond_current,
    }
}

/// Median over the rows with a voltage of the cam speed as given over the speed the
/// motor's back-EMF allows at that voltage and current, (v - R i) / (N Ke) (the RS-735,
/// [`rs735`]). `None` without a `v_in_v` column, with fewer than [`crate::data::MIN_ROWS`]
/// rows between the breakaway voltage and the supply, or when the shares scatter by more
/// than [`BACK_EMF_SCATTER`] between their quartiles: then the column is not the motor's
/// voltage (the bridge supply logged instead, or a duty cycle) and says nothing on the speed.
fn speed_share_of_back_emf(rows: &[ScreenRow]) -> Option<f64> {
    let mut shares: Vec<f64> = rows
        .iter()
        .filter(|r| (rs735::BREAKAWAY_V..=board::BRIDGE_SUPPLY_V).contains(&r.v_in.abs()))
        .filter_map(|r| {
            let emf = r.v_in.abs() - rs735::RESISTANCE_OHM * r.i_in.abs();
            (emf > 0.0).then(|| r.omega_n.abs() * rs735::KE_CAM_V_S_PER_RAD / emf)
        })
        .collect();
    if shares.len() < crate::data::MIN_ROWS {
        return None;
    }
    shares.sort_unstable_by(f64::total_cmp);
    let at = |p: f64| shares[((shares.len() - 1) as f64 * p).round() as usize];
    (at(0.75) <= BACK_EMF_SCATTER * at(0.25)).then(|| at(0.5))
}

/// Refuses a speed or load column in another unit than the header says (cam speed in Hz or
/// rpm in `omega_n_rad_s`, loads in N mm in `tau_rot_nm`), naming the column and its
/// probable unit. The evidence is the magnitude, from the rig's physics, so that data in
/// the header's units is not refused on any rig (a fit alone is not: where the model misses
/// an effect, a saturating sensor's flattened top fits a tenth of the speeds better):
///
/// - loads: read as given, in most rows of the heavier half the friction at the least
///   physical mu would alone draw more current than the vibrator drew, and read in N mm it
///   would not;
/// - speeds, with a `v_in_v` column: the speeds as given sit nearer, in ratio, to the
///   probable unit's share of the speed the motor's back-EMF allows at those voltages than
///   to that speed itself (a rad/s column would be taken for Hz only with a winding of 2.4
///   times the RS-735's resistance at 3.6 V and 2.5 A).
///
/// Without a voltage the current cannot bound the speed's magnitude (a viscous loss within
/// its physical limit matches a Hz column's rise), so a Hz reading then rests on the fit of
/// the paper's model to a sample of the rows: it must fit at least as well with a physical mu
/// where the given reading needs an unphysical mu, or fit clearly better (half the misfit,
/// and a quarter of it when the given mu is physical); rpm is then left to the range rules.
/// Those rules of [`range_check`] catch the larger slips (cam speeds beyond the motor's
/// no-load speed at the supply, currents beyond the sensor's range: mA), which data in the
/// header's units cannot break.
pub fn unit_check(
    data: &Dataset,
    excluded: &[bool],
    start: &model::effects::CurrentModel,
) -> Result<(), ExplainError> {
    let current = data.i_in();
    let usable: Vec<usize> = (0..data.len())
        .filter(|&k| !excluded[k] && current[k].is_finite())
        .collect();
    if usable.len() < crate::data::MIN_ROWS {
        return Ok(());
    }
    let step = usable.len().div_ceil(UNIT_SCREEN_ROWS).max(1);
    let voltage = data.v_in();
    let rows: Vec<ScreenRow> = usable
        .iter()
        .step_by(step)
        .map(|&k| ScreenRow {
            omega_n: data.omega_n()[k],
            tau_rot: data.tau_rot()[k],
            i_in: current[k],
            v_in: voltage.map_or(f64::NAN, |v| v[k]),
        })
        .collect();
    let w_max = no_load_cam_speed();
    let top_speed = rows.iter().fold(0.0f64, |m, r| m.max(r.omega_n.abs()));
    // Indexed by 2 * speed unit + load unit.
    let readings: Vec<Reading> = SPEED_UNITS
        .iter()
        .flat_map(|&(speed_scale, speed_unit, _)| {
            [(1.0, "N m"), (1e-3, "N mm")].map(|(load_scale, load_unit)| Reading {
                speed_scale,
                load_scale,
                speed_unit,
                load_unit,
            })
        })
        .collect();
    let physical = model::effects::MU_PHYSICAL.range(&model::effects::LimitContext {
        max_axial_force_n: 0.0,
        eccentricity_m: 0.0,
    });
    let is_physical = |mu: f64| mu >= physical.0 && mu <= physical.1;
    // The heavier half of the rows (by load).
    let mut loads: Vec<f64> = rows.iter().map(|r| r.tau_rot.abs()).collect();
    let heavy = median(&mut loads);
    let heavy_rows = rows.iter().filter(|r| r.tau_rot.abs() >= heavy).count();
    let fits: Vec<ReadingFit> = readings
        .iter()
        .map(|r| affine_mu_fit(start, &rows, r, physical.0, heavy))
        .collect();
    let (mu0, rmse0) = (fits[0].mu, fits[0].rmse);
    let speed_share = speed_share_of_back_emf(&rows);
    // Candidate readings, best fit first: the first one both kinds of evidence back.
    let mut order: Vec<usize> = (1..readings.len())
        // A reading in Hz must still be a speed the motor reaches.
        .filter(|&j| top_speed * readings[j].speed_scale <= w_max)
        .collect();
    order.sort_by(|&a, &b| fits[a].rmse.total_cmp(&fits[b].rmse));
    let most = |count: usize| 2 * count > heavy_rows;
    let chosen = order.into_iter().find(|&j| {
        let (r, fit) = (&readings[j], &fits[j]);
        // Loads: impossible as given (at this reading's speeds), possible as read.
        let loads = (r.load_scale != 1.0)
            .then(|| most(fits[j & !1].loads_beyond_current) && !most(fit.loads_beyond_current));
        // Speeds: nearer, in ratio, to what this unit gives at the voltages than to rad/s.
        let speeds = (r.speed_scale != 1.0).then(|| {
            speed_share.map(|q| {
                let given = 1.0 / r.speed_scale;
                (q.ln() - given.ln()).abs() < q.ln().abs()
            })
        });
        if loads == Some(false) || speeds == Some(Some(false)) {
            return false;
        }
        if speeds != Some(None) {
            // Each changed column is impossible as given: that is the evidence (the fit is
            // not, where the model misses an effect: a saturating sensor's flattened top
            // fits slower speeds better).
            return true;
        }
        // Speeds without a voltage to weigh them by: the current alone cannot bound the
        // speed's magnitude (a viscous loss within its physical limit matches a Hz column's
        // rise), so only Hz, on the fit alone; rpm that the range rules pass stays. (A
        // saturating sensor's flattened top makes a tenth of the speeds fit better.)
        if r.speed_scale < 1.0 {
            return false;
        }
        // Loads scaled by 1000
        // scale mu by 1/1000 and fit as well: an unphysical mu that a probable unit makes
        // physical, at no worse a fit, is enough; otherwise the other reading must fit
        // clearly better.
        let same_fit_physical_mu = !is_physical(mu0) && fit.rmse <= 1.25 * rmse0;
        let clearly_better =
            fit.rmse < 0.5 * rmse0 && (!is_physical(mu0) || fit.rmse < 0.25 * rmse0);
        is_physical(fit.mu) && (same_fit_physical_mu || clearly_better)
    });
    let Some(j) = chosen else {
        return Ok(());
    };
    let (r, mu, rmse) = (&readings[j], fits[j].mu, fits[j].rmse);
    let mut columns = Vec::new();
    if r.load_scale != 1.0 {
        columns.push(format!(
            "column tau_rot_nm looks like {} (largest load {}), not N m: at the least physical tooth friction (mu = {}) loads that large would draw more current in friction alone than the vibrator drew in {} of the {} rows of the heavier half; give the load in N m (divide the column by 1000)",
            r.load_unit,
            short(data.tau_rot().iter().fold(0.0f64, |m, v| m.max(v.abs()))),
            physical.0,
            fits[j & !1].loads_beyond_current,
            heavy_rows
        ));
    }
    if r.speed_scale != 1.0 {
        let against_voltage = speed_share.map_or(String::new(), |q| {
            format!(
                " (read as rad/s it is {} times the speed the motor's back-EMF allows at the v_in_v voltages, median)",
                short(q)
            )
        });
        let fix = SPEED_UNITS
            .iter()
            .find(|u| u.1 == r.speed_unit)
            .map_or("", |u| u.2);
        columns.push(format!(
            "column omega_n_rad_s looks like the cam speed in {} (largest {}), not rad/s{against_voltage}: give it in rad/s ({fix})",
            r.speed_unit,
            short(top_speed)
        ));
    }
    Err(ExplainError::BadValue {
        what: format!("{} units", data.name),
        why: format!(
            "{}. Read as given, the paper's model needs mu = {} and misses by {:.0} mA RMS; read in {} and {} it fits with mu = {:.3} to {:.0} mA RMS",
            columns.join("; "),
            short(mu0),
            rmse0 * 1e3,
            r.speed_unit,
            r.load_unit,
            mu,
            rmse * 1e3
        ),
    })
}

/// A number with four significant digits.
fn short(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (3 - v.abs().log10().floor() as i32).clamp(0, 8) as usize;
    format!("{v:.digits$}")
}

/// Median of `v` (reordered); 0 for an empty slice.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    let m = *m;
    if v.len() % 2 == 1 {
        m
    } else {
        let lower = v[..mid].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (m + lower)
    }
}

/// Median of the sorted `sorted` with one value equal to `v` left out.
fn median_without(sorted: &[f64], v: f64) -> f64 {
    let skip = sorted
        .binary_search_by(|x| x.total_cmp(&v))
        .unwrap_or_else(|i| i.min(sorted.len() - 1));
    let m = sorted.len() - 1;
    let at = |i: usize| if i < skip { sorted[i] } else { sorted[i + 1] };
    if m % 2 == 1 {
        at(m / 2)
    } else {
        0.5 * (at(m / 2 - 1) + at(m / 2))
    }
}

/// Robust standard deviation 1.4826 MAD of `v` (reordered).
pub fn robust_scale(v: &mut [f64]) -> f64 {
    let m = median(v);
    for x in v.iter_mut() {
        *x = (*x - m).abs();
    }
    MAD_SCALE * median(v)
}

/// A scale that also sees a minority spread: the larger of 1.4826 MAD and the 90th
/// percentile of the absolute deviations from the median over 1.645 (both the standard
/// deviation for normal data). The mesh ripple's two-valued scatter puts a third of the rows
/// well off the median: the MAD alone would call them outliers; the percentile, which one
/// or two wild rows in ten cannot move, does not. `v` is reordered.
pub fn spread_scale(v: &mut [f64]) -> f64 {
    let mad = robust_scale(v);
    if v.len() < 2 {
        return mad;
    }
    let k = (0.9 * (v.len() - 1) as f64).floor() as usize;
    let (_, q, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    mad.max(*q / 1.645)
}

/// Rows of `points` (already free of range outliers) whose residual under `model`, less its
/// neighbours', stands out by more than [`OUTLIER_LIMIT`] robust standard deviations.
/// Returns the outliers (data rows) and the warning when there are too many to drop.
pub fn residual_outliers(
    data: &Dataset,
    points: &TestPoints,
    model: &model::effects::CurrentModel,
) -> (Vec<Outlier>, Option<String>) {
    let rv = &points.row_view;
    let n = rv.len();
    if n < 2 * MIN_LEVEL_ROWS {
        return (Vec::new(), None);
    }
    let ev = model.evaluator();
    let e = rv.residuals(&ev);
    // Less the median of the rows at the same conditions: the rows of the same speed and
    // load level; on pooled data the rows of the same pool (same conditions and stretch of
    // the session) where it has enough of them.
    let loads = points.load_centres.len();
    let cell: Vec<usize> = rv
        .point
        .iter()
        .map(|&p| points.speed_level[p as usize] * loads + points.load_level[p as usize])
        .collect();
    // Each group's sorted residuals: a row's neighbours' median leaves the row itself out
    // (else a fifth of the rows of a five-row cell would sit at exactly zero).
    let sorted_groups = |key: &[usize]| -> Vec<Vec<f64>> {
        let groups = key.iter().copied().max().map_or(0, |m| m + 1);
        let mut members: Vec<Vec<f64>> = vec![Vec::new(); groups];
        for (j, &g) in key.iter().enumerate() {
            members[g].push(e[j]);
        }
        for m in &mut members {
            m.sort_unstable_by(f64::total_cmp);
        }
        members
    };
    let others_median = |sorted: &[f64], v: f64| -> Option<f64> {
        (sorted.len() > MIN_NEIGHBOURS).then(|| median_without(sorted, v))
    };
    let by_cell = sorted_groups(&cell);
    let pool: Vec<usize> = rv.point.iter().map(|&p| p as usize).collect();
    let by_pool = if points.pooled {
        sorted_groups(&pool)
    } else {
        Vec::new()
    };
    let mut d = e.clone();
    for j in 0..n {
        let local = if points.pooled && points.weight[pool[j]] >= MIN_POOL_ROWS {
            others_median(&by_pool[pool[j]], e[j])
        } else {
            None
        };
        if let Some(m) = local.or_else(|| others_median(&by_cell[cell[j]], e[j])) {
            d[j] = e[j] - m;
        }
    }
    let mut buf = Vec::new();
    // Less the running median in time order (unpooled data: pools are local in time).
    if !points.pooled {
        let h = RUNNING_HALF_WIDTH;
        let running: Vec<f64> = (0..n)
            .map(|j| {
                let (lo, hi) = (j.saturating_sub(h), (j + h + 1).min(n));
                buf.clear();
                buf.extend((lo..hi).filter(|&i| i != j).map(|i| d[i]));
                median(&mut buf)
            })
            .collect();
        for j in 0..n {
            d[j] -= running[j];
        }
    }
    // Robust scale per load level, floored at half the global one.
    let mut all = d.clone();
    let global = spread_scale(&mut all).max(1e-12);
    let levels = points.load_centres.len();
    let mut by_level: Vec<Vec<f64>> = vec![Vec::new(); levels];
    for j in 0..n {
        by_level[points.load_level[rv.point[j] as usize]].push(d[j]);
    }
    // A level's own scale, shrunk towards the global one as if that were backed by
    // LEVEL_PRIOR_ROWS rows (fifteen rows alone estimate a scale only to some 30 %).
    let scale: Vec<f64> = by_level
        .iter_mut()
        .map(|v| {
            if v.len() >= MIN_LEVEL_ROWS {
                let n = v.len() as f64;
                let s = spread_scale(v);
                ((n * s * s + LEVEL_PRIOR_ROWS * global * global) / (n + LEVEL_PRIOR_ROWS))
                    .sqrt()
                    .max(0.5 * global)
            } else {
                global
            }
        })
        .collect();
    let mut found: Vec<(usize, f64, f64)> = (0..n)
        .filter_map(|j| {
            let s = scale[points.load_level[rv.point[j] as usize]];
            let z = d[j].abs() / s;
            (z > OUTLIER_LIMIT).then_some((j, z, d[j]))
        })
        .collect();
    if found.is_empty() {
        return (Vec::new(), None);
    }
    if found.len() as f64 > MAX_OUTLIER_SHARE * n as f64 {
        let worst = found
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .expect("non-empty");
        let k = rv.row[worst.0] as usize;
        return (
            Vec::new(),
            Some(format!(
                "{} of {n} rows stand out from the rows at like conditions by more than {OUTLIER_LIMIT} robust standard deviations (worst: row {}, line {}, {:.0}): too many to be isolated bad rows, so none was set aside; the noise may not be Gaussian, or conditions changed during the session",
                found.len(),
                k + 1,
                data.line(k),
                worst.1
            )),
        );
    }
    found.sort_by_key(|f| rv.row[f.0]);
    let outliers = found
        .into_iter()
        .map(|(j, z, dev)| {
            let k = rv.row[j] as usize;
            let op = rv.op(j);
            Outlier {
                row: k + 1,
                line: data.line(k),
                column: "i_in_a".into(),
                value: rv.current[j],
                reason: format!(
                    "i_in_a = {} A is {:+.1} mA off the rows at like conditions ({:.1} Hz, {:.2} N m) and its neighbours in time: {:.0} robust standard deviations, beyond the limit of {OUTLIER_LIMIT}",
                    short(rv.current[j]),
                    dev * 1e3,
                    op.omega_n / (2.0 * std::f64::consts::PI),
                    op.tau_rot,
                    z
                ),
            }
        })
        .collect();
    (outliers, None)
}

/// Checks the rig file's values with the firmware's rules: an error for a calibration
/// constant of the wrong sign, warnings for implausible or inconsistent ones and for cam and
/// friction values outside plausible ranges.
pub fn check_rig(rig: &RigFile) -> Result<Vec<String>, ExplainError> {
    let mut warnings = Vec::new();
    let fix = |issue: &CalibrationIssue| {
        format!(
            "[calibration] {issue} (the firmware's calibration check against the RS-735); fix {} in the rig file (Table 2 of the paper: c1 = 62.1, c2 = -138, c3 = 0.235, c4 = 1.69, c5 = 0.00378, c6 = 2.25)",
            issue.field.name()
        )
    };
    if let Err(issue) = rig.calibration().check(&MotorConstants::RS735) {
        match issue.kind {
            model::calibration::IssueKind::NotFinite
            | model::calibration::IssueKind::WrongSign { .. } => {
                return Err(ExplainError::RigFile {
                    file: "(--model)".into(),
                    why: fix(&issue),
                });
            }
            _ => warnings.push(format!("rig file {}", fix(&issue))),
        }
    }
    let (t_lo, t_hi) = TEMPERATURE_RANGE_C;
    let plausible = [
        (
            "[cam] eccentricity_mm",
            rig.cam.eccentricity_mm,
            model::paper::MIN_ECCENTRICITY * 1e3 * 0.5,
            10.0,
            "the paper's cam has 1.0 mm; at least 0.3 mm is needed for the switching",
        ),
        (
            "[cam] carrier_mass_kg",
            rig.cam.carrier_mass_kg,
            0.1,
            50.0,
            "the paper's carrier has 3.82 kg",
        ),
        (
            "[friction] mu_s",
            rig.friction.mu_s,
            0.01,
            1.0,
            "steel on steel lies near 0.1-0.3; the paper has 0.271",
        ),
        (
            "[calibration] temperature_c",
            rig.calibration.temperature_c,
            t_lo,
            t_hi,
            "give the motor temperature at calibration in deg C",
        ),
    ];
    for (what, v, lo, hi, hint) in plausible {
        if !(lo..=hi).contains(&v) {
            warnings.push(format!(
                "rig file {what} = {} is outside the plausible {lo}..{hi} ({hint}): check the value and its unit",
                short(v)
            ));
        }
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::MeasuredRow;

    fn rows(k: usize) -> Vec<MeasuredRow> {
        (0..k)
            .map(|j| MeasuredRow {
                omega_n: 31.4 * (1 + j % 3) as f64,
                tau_rot: 0.368 * (1 + j % 10) as f64,
                i_in: Some(2.5),
                temp_c: Some(30.0),
                ..Default::default()
            })
            .collect()
    }

    #[test]
    fn range_rules_flag_rows_and_whole_columns() {
        let mut r = rows(40);
        r[7].i_in = Some(100.0);
        r[9].omega_n = 900.0;
        r[11].temp_c = Some(300.0);
        r[13].tau_rot = -1.0;
        let d = Dataset::from_rows("m.csv", r).unwrap();
        let RangeCheck {
            excluded: ex,
            outliers: out,
            warnings: warn,
        } = range_check(&d).unwrap();
        assert_eq!(out.len(), 3);
        assert!(ex[7] && ex[9] && ex[11] && !ex[13]);
        assert_eq!((out[0].row, out[0].line), (8, 9));
        assert!(
            out[0].reason.contains("current sensor's range"),
            "{}",
            out[0].reason
        );
        assert!(out.iter().any(|o| o.column == "temp_c"));
        assert!(
            warn.iter()
                .any(|w| w.contains("negative") && w.contains("row 14")),
            "{warn:?}"
        );
        // A whole column in the wrong unit is an error naming the fix.
        let r: Vec<MeasuredRow> = rows(40)
            .into_iter()
            .map(|mut m| {
                m.i_in = Some(2500.0);
                m
            })
            .collect();
        let e = range_check(&Dataset::from_rows("m.csv", r).unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("i_in_a") && e.contains("not mA"), "{e}");
    }

    #[test]
    fn rig_values_are_checked_with_the_firmware_rules() {
        assert!(check_rig(&RigFile::paper()).unwrap().is_empty());
        let bad = RigFile::parse("[calibration]\nc2 = 138.0\n", "r.toml").unwrap();
        let e = check_rig(&bad).unwrap_err().to_string();
        assert!(e.contains("c2") && e.contains("wrong sign"), "{e}");
        let odd = RigFile::parse(
            "[calibration]\nc1 = 200.0\n[cam]\neccentricity_mm = 40.0\n",
            "r.toml",
        )
        .unwrap();
        let w = check_rig(&odd).unwrap();
        assert!(w.iter().any(|w| w.contains("c1")), "{w:?}");
        assert!(w.iter().any(|w| w.contains("eccentricity_mm")), "{w:?}");
    }

    #[test]
    fn median_without_leaves_one_value_out() {
        let s = [1.0, 2.0, 3.0, 10.0, 11.0];
        assert_eq!(median_without(&s, 1.0), 6.5);
        assert_eq!(median_without(&s, 3.0), 6.0);
        assert_eq!(median_without(&s, 11.0), 2.5);
        assert_eq!(median_without(&[1.0, 2.0, 3.0, 4.0], 4.0), 2.0);
    }

    #[test]
    fn robust_scale_ignores_one_wild_value() {
        let mut v: Vec<f64> = (0..101)
            .map(|k| ((k * 37) % 101) as f64 / 100.0 - 0.5)
            .collect();
        let clean = robust_scale(&mut v.clone());
        v[3] = 1e6;
        let dirty = robust_scale(&mut v);
        assert!((dirty / clean - 1.0).abs() < 0.05, "{clean} {dirty}");
    }
}
