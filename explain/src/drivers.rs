//! Which variable drives a named effect: a library law says what its current follows (the
//! cam speed, the load, the motor temperature or the time), but in a test session several
//! variables move together (the motor warms while the revolutions add up; the current rises
//! with speed and load). A named effect is only an explanation when its own driver fits the
//! discrepancy clearly better than a generic shape in *another* driver of like complexity:
//! otherwise tooth wear that grows with the revolutions run passes for thermal drift, and a
//! current sensor's nonlinearity for a speed or load law.
//!
//! In the final model refitted without the effect (the other named effects keep their
//! share), every generic shape of one coefficient in another driver (the driver scaled to 1
//! at its largest value, its square, and the driver times the friction current; for the
//! current also a parabola about its middle) is fitted to the residual together with the
//! model's own unknowns (linearised at that fit, weighted by the final model's noise). The effect's own change of the fitted current is
//! scored the same way. The effect is `separated` when it explains at least
//! [`SEPARATION_CHI2`] more chi-square than the best alternative; when not, the verdict
//! cannot be `explained`, its confidence is the bootstrap share times the named law's
//! weight against the alternative ([`DriverCheck::weight`]), and the report names the
//! alternative driver and the test that would separate the two.

use serde::Serialize;

use crate::fit::{self, Fit};
use crate::library::{self, ThermalDriver};
use crate::mechanism::Mechanism;
use crate::points::TestPoints;
use crate::stats;

/// Chi-square (twice the log-likelihood ratio) by which a named effect must beat the best
/// generic shape in another driver: e to 1 in likelihood, where "positive" evidence starts
/// on Kass and Raftery's scale (less is "not worth more than a bare mention").
pub const SEPARATION_CHI2: f64 = 2.0;

/// A variable a discrepancy can follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Driver {
    /// The time since the first test.
    Time,
    /// The cam revolutions run since the first test (time at speed).
    Revolutions,
    /// The motor temperature.
    Temperature,
    /// The cam speed.
    Speed,
    /// The load torque.
    Load,
    /// The measured current itself (a sensor's error follows it).
    Current,
}

impl Driver {
    /// Every driver, in the order alternatives are listed.
    pub const ALL: [Driver; 6] = [
        Driver::Time,
        Driver::Revolutions,
        Driver::Temperature,
        Driver::Speed,
        Driver::Load,
        Driver::Current,
    ];

    /// The driver in words.
    pub fn words(self) -> &'static str {
        match self {
            Driver::Time => "the time",
            Driver::Revolutions => "the revolutions run",
            Driver::Temperature => "the motor temperature",
            Driver::Speed => "the cam speed",
            Driver::Load => "the load",
            Driver::Current => "the current",
        }
    }

    /// Whether the driver moves with the session rather than with the test plan's levels.
    fn in_session(self) -> bool {
        matches!(
            self,
            Driver::Time | Driver::Revolutions | Driver::Temperature
        )
    }
}

/// The drivers a candidate's law follows (empty: a constant or a variance, which has no
/// driver to confuse, or a user effect, whose law the user wrote).
pub fn drivers_of(points: &TestPoints, cand: Mechanism) -> Vec<Driver> {
    let mut out = Vec::new();
    let thermal = |out: &mut Vec<Driver>| match points.thermal {
        ThermalDriver::Temperature { .. } => out.push(Driver::Temperature),
        ThermalDriver::Time => out.push(Driver::Time),
        ThermalDriver::Unavailable => {}
    };
    match cand {
        Mechanism::Effect(e) => {
            // The data an effect needs to show is what its law follows.
            if e.mean_param().is_none() {
                return out;
            }
            let needs = e.info().needs;
            if needs.speed_levels > 0 {
                out.push(Driver::Speed);
            }
            if needs.load_levels > 0 {
                out.push(Driver::Load);
            }
            if needs.thermal_driver {
                thermal(&mut out);
            }
        }
        Mechanism::Term(t) => {
            let Some(form) = points.terms[t].form() else {
                return out;
            };
            let needs = form.info().needs;
            if needs.time_only {
                out.push(Driver::Time);
            }
            if needs.speed_levels > 0 {
                out.push(Driver::Speed);
            }
            if needs.load_levels > 0 {
                out.push(Driver::Load);
            }
        }
    }
    out
}

/// A generic shape in another driver, scored against a named effect.
#[derive(Debug, Clone, Serialize)]
pub struct Alternative {
    /// Its driver.
    pub driver: Driver,
    /// The shape, e.g. `t` or `t x friction current` (each scaled to 1 at the data's
    /// largest value).
    pub shape: String,
    /// The shape in words.
    pub words: String,
    /// Chi-square it explains of the step's residual (the model's unknowns refitted).
    pub chi2: f64,
}

/// Whether a named effect's own driver beats every generic shape in another driver.
#[derive(Debug, Clone, Serialize)]
pub struct DriverCheck {
    /// What the effect's law follows.
    pub drivers: Vec<Driver>,
    /// Chi-square the effect explains of its step's residual (its fitted change of the
    /// current, scored as the alternatives are).
    pub chi2: f64,
    /// The best generic shape in another driver (null when the data offers none).
    pub best_alternative: Option<Alternative>,
    /// Whether the effect explains at least `margin` more chi-square than that alternative.
    pub separated: bool,
    /// The margin, chi-square units.
    pub margin: f64,
    /// The test that would separate the effect from the alternative (empty when separated).
    pub separating_test: String,
}

impl DriverCheck {
    /// The weight of the named law against the best alternative, two models of one
    /// coefficient each: 1 / (1 + exp((chi2_alternative - chi2) / 2)) (their BIC weights,
    /// the penalties cancelling); 1 without an alternative.
    pub fn weight(&self) -> f64 {
        self.best_alternative
            .as_ref()
            .map_or(1.0, |a| 1.0 / (1.0 + ((a.chi2 - self.chi2) / 2.0).exp()))
    }

    /// The chi-square the effect explains beyond the best alternative (all of it when the
    /// data offers none).
    pub fn margin_over_best(&self) -> f64 {
        self.chi2 - self.best_alternative.as_ref().map_or(0.0, |a| a.chi2)
    }

    /// One sentence for the finding.
    pub fn summary(&self, name: &str) -> String {
        match &self.best_alternative {
            None => String::new(),
            Some(a) if self.separated => format!(
                "{name} follows {} better than any generic shape in another variable (best: {} in {}, chi^2 {:.1} against {:.1})",
                join_words(&self.drivers),
                a.words,
                a.driver.words(),
                a.chi2,
                self.chi2
            ),
            Some(a) => format!(
                "what {name} explains (chi^2 {:.1}) is matched by a generic shape in another variable: {} (chi^2 {:.1}); the data do not say whether the discrepancy follows {} or {}; {}",
                self.chi2,
                a.words,
                a.chi2,
                join_words(&self.drivers),
                a.driver.words(),
                self.separating_test
            ),
        }
    }
}

fn join_words(drivers: &[Driver]) -> String {
    drivers
        .iter()
        .map(|d| d.words())
        .collect::<Vec<_>>()
        .join(" and ")
}

/// The test that tells a law in `own` from one in `other`.
fn separating_test(own: &[Driver], other: Driver) -> String {
    let session = |d: Driver| d.in_session();
    let own_session = own.iter().any(|&d| session(d));
    let text = if other == Driver::Current || own.contains(&Driver::Current) {
        "tests that reach the same current at other speeds and loads, or a check of the current sensor against a reference meter, would separate them"
    } else if own.contains(&Driver::Temperature) && session(other) {
        "a cool-down rest part-way through the session (tests repeated after the motor has cooled, while time and revolutions run on) would separate them"
    } else if own_session && other == Driver::Temperature {
        "a cool-down rest part-way through the session (the temperature falls back while time and revolutions run on) would separate them"
    } else if own_session && session(other) {
        "tests that stay at one cam speed for a stretch and then at another (revolutions then grow at another rate than time), and a temp_c column, would separate them"
    } else if own_session != session(other) {
        "the same tests repeated in a shuffled order (time, revolutions and temperature then no longer follow the plan's speeds and loads) would separate them"
    } else {
        "more speed levels at each load and more loads at each speed level would separate them"
    };
    text.to_string()
}

/// Whitened columns of a fit's unknowns and the Cholesky factor of their Gram matrix: fits
/// one more column to a residual with the unknowns refitted (linearised).
struct Projector {
    /// sqrt(rows) / sigma of each point.
    scale: Vec<f64>,
    /// Whitened Jacobian, point-major.
    jac: Vec<f64>,
    p: usize,
    chol: Option<Vec<f64>>,
    /// Whitened residual of the fit.
    residual: Vec<f64>,
}

impl Projector {
    /// The projector of `current`'s unknowns, whitened by the noise of `noise` (the fit with
    /// the effect: the step's residual is not noise).
    fn new(points: &TestPoints, current: &Fit, noise: &Fit) -> Self {
        let (f, raw, p) = fit::jacobian(points, current);
        let ev = noise.model.evaluator();
        let n = points.len();
        let scale: Vec<f64> = (0..n)
            .map(|k| points.weight[k].sqrt() / noise.sigma_with(&ev, &points.ops[k]).max(1e-12))
            .collect();
        let mut jac = vec![0.0; n * p];
        for k in 0..n {
            for x in 0..p {
                jac[k * p + x] = scale[k] * raw[k * p + x];
            }
        }
        let mut gram = vec![0.0; p * p];
        for k in 0..n {
            for x in 0..p {
                for y in 0..p {
                    gram[x * p + y] += jac[k * p + x] * jac[k * p + y];
                }
            }
        }
        for x in 0..p {
            gram[x * p + x] += 1e-12 * gram[x * p + x].abs() + 1e-300;
        }
        let residual = (0..n)
            .map(|k| scale[k] * (points.current[k] - f[k]))
            .collect();
        Self {
            chol: if p == 0 {
                None
            } else {
                stats::cholesky(&gram, p)
            },
            scale,
            jac,
            p,
            residual,
        }
    }

    /// Chi-square that column `x` (A per unit coefficient at each point) explains of the
    /// residual with the unknowns refitted.
    fn chi2(&self, x: &[f64]) -> f64 {
        let p = self.p;
        let xw: Vec<f64> = x.iter().zip(&self.scale).map(|(a, s)| a * s).collect();
        let total: f64 = xw.iter().map(|v| v * v).sum();
        let mut perp = xw;
        if let Some(l) = &self.chol {
            let mut b = vec![0.0; p];
            for (k, v) in perp.iter().enumerate() {
                for (y, by) in b.iter_mut().enumerate() {
                    *by += self.jac[k * p + y] * v;
                }
            }
            let c = stats::cholesky_solve(l, p, &b);
            for (k, v) in perp.iter_mut().enumerate() {
                *v -= (0..p).map(|y| self.jac[k * p + y] * c[y]).sum::<f64>();
            }
        }
        let s: f64 = perp.iter().map(|v| v * v).sum();
        // A shape the model's own unknowns already span (or NaN) explains nothing new.
        if !(s.is_finite() && total.is_finite()) || s <= 1e-9 * total {
            return 0.0;
        }
        let u: f64 = perp.iter().zip(&self.residual).map(|(a, b)| a * b).sum();
        u * u / s
    }
}

/// Each point's value of `driver` (`None` when the data does not log it).
fn driver_values(points: &TestPoints, current: &Fit, driver: Driver) -> Option<Vec<f64>> {
    let n = points.len();
    match driver {
        Driver::Time => points.time_known.then(|| points.time_s.clone()),
        Driver::Revolutions => points.time_known.then(|| revolutions(points)),
        Driver::Temperature => matches!(points.thermal, ThermalDriver::Temperature { .. })
            .then(|| points.temp_c.clone()),
        Driver::Speed => Some(points.ops.iter().map(|op| op.omega_n.abs()).collect()),
        Driver::Load => Some(points.ops.iter().map(|op| op.tau_rot.abs()).collect()),
        Driver::Current => {
            let f = current.predict(points);
            Some((0..n).map(|k| f[k].abs()).collect())
        }
    }
}

/// The cam revolutions run before each point (mean over its rows), rad: the speed of each
/// row times the time since the row before, summed in time order.
fn revolutions(points: &TestPoints) -> Vec<f64> {
    let rv = &points.row_view;
    let mut sum = vec![0.0; points.len()];
    let mut count = vec![0.0; points.len()];
    let (mut total, mut last_t) = (0.0, rv.time_s.first().copied().unwrap_or(0.0));
    for j in 0..rv.len() {
        let t = rv.time_s[j];
        total += rv.omega_n[j].abs() * (t - last_t).max(0.0);
        last_t = t;
        let k = rv.point[j] as usize;
        if k < sum.len() {
            sum[k] += total;
            count[k] += 1.0;
        }
    }
    sum.iter()
        .zip(&count)
        .map(|(s, c)| if *c > 0.0 { s / c } else { 0.0 })
        .collect()
}

/// The generic shapes in `driver` with values `v` at each point: (shape, words, column).
fn shapes(driver: Driver, v: &[f64], friction: &[f64]) -> Vec<(String, String, Vec<f64>)> {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    // A driver that does not vary (or is not finite) offers no shape.
    let spread = hi - lo;
    if spread.is_nan() || spread <= 1e-9 * hi.abs().max(1e-9) {
        return Vec::new();
    }
    let f_max = friction
        .iter()
        .fold(0.0f64, |m, f| m.max(f.abs()))
        .max(1e-12);
    // The temperature from its lowest value; the others from zero (their laws vanish there).
    let origin = if driver == Driver::Temperature {
        lo
    } else {
        0.0
    };
    let span = hi - origin;
    let x: Vec<f64> = v.iter().map(|a| (a - origin) / span).collect();
    let sym = match driver {
        Driver::Time => "t",
        Driver::Revolutions => "revolutions",
        Driver::Temperature => "temp",
        Driver::Speed => "w",
        Driver::Load => "tau",
        Driver::Current => "i",
    };
    let what = driver.words();
    let mut out = vec![
        (
            sym.to_string(),
            format!("a current that grows like {what}"),
            x.clone(),
        ),
        (
            format!("{sym}^2"),
            format!("a current that grows like {what} squared"),
            x.iter().map(|a| a * a).collect(),
        ),
        (
            format!("{sym} x friction current"),
            format!("friction that grows with {what}"),
            x.iter().zip(friction).map(|(a, f)| a * f / f_max).collect(),
        ),
    ];
    if driver == Driver::Current {
        let mid = 0.5 * (lo + hi);
        let half = 0.5 * (hi - lo);
        out.push((
            "(i - i_mid)^2".into(),
            "a reading that bends with the current about its middle (a sensor nonlinearity)".into(),
            v.iter().map(|a| ((a - mid) / half).powi(2)).collect(),
        ));
    }
    out
}

/// The driver check of `cand`, named at the step from `current` to `with`; `None` when
/// its law has no driver to confuse (a constant, a variance, a user effect).
pub fn check(
    points: &TestPoints,
    current: &Fit,
    with: &Fit,
    cand: Mechanism,
) -> Option<DriverCheck> {
    let own = drivers_of(points, cand);
    if own.is_empty() {
        return None;
    }
    let projector = Projector::new(points, current, with);
    let before = current.predict(points);
    let after = with.predict(points);
    let change: Vec<f64> = after.iter().zip(&before).map(|(a, b)| a - b).collect();
    let chi2 = projector.chi2(&change);
    let ev = current.model.evaluator();
    let friction: Vec<f64> = points
        .ops
        .iter()
        .map(|op| ev.friction_current(op))
        .collect();
    let mut best: Option<Alternative> = None;
    for driver in Driver::ALL {
        if own.contains(&driver) {
            continue;
        }
        let Some(v) = driver_values(points, current, driver) else {
            continue;
        };
        for (shape, words, column) in shapes(driver, &v, &friction) {
            let c = projector.chi2(&column);
            if best.as_ref().is_none_or(|b| c > b.chi2) {
                best = Some(Alternative {
                    driver,
                    shape,
                    words,
                    chi2: c,
                });
            }
        }
    }
    let separated = best
        .as_ref()
        .is_none_or(|a| chi2 - a.chi2 >= SEPARATION_CHI2);
    let separating_test = match (&best, separated) {
        (Some(a), false) => separating_test(&own, a.driver),
        _ => String::new(),
    };
    Some(DriverCheck {
        drivers: own,
        chi2,
        best_alternative: best,
        separated,
        margin: SEPARATION_CHI2,
        separating_test,
    })
}

/// The driver check of `cand` in the final model `after`: against `after` refitted without
/// it, so the other named effects keep their share and an alternative competes only for
/// this effect's.
pub fn check_in_final(points: &TestPoints, after: &Fit, cand: Mechanism) -> Option<DriverCheck> {
    if drivers_of(points, cand).is_empty() || !cand.in_spec(&after.spec) {
        return None;
    }
    let spec = crate::extrapolation::without(&after.spec, cand);
    let mut model = after.model;
    if let Mechanism::Effect(e) = cand {
        library::clear_params(e, &mut model.effects);
    }
    let starts = after.term_starts(points, &spec);
    let less = fit::fit_from(points, &points.all, &spec, &model, &starts);
    check(points, &less, after, cand)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_separating_test_fits_the_two_drivers() {
        let t = |own: &[Driver], other| separating_test(own, other);
        assert!(t(&[Driver::Temperature], Driver::Time).contains("cool-down rest"));
        assert!(t(&[Driver::Temperature], Driver::Revolutions).contains("cool-down rest"));
        assert!(t(&[Driver::Time], Driver::Temperature).contains("cool-down rest"));
        assert!(t(&[Driver::Time], Driver::Revolutions).contains("one cam speed for a stretch"));
        assert!(t(&[Driver::Speed], Driver::Current).contains("reference meter"));
        assert!(t(&[Driver::Load], Driver::Time).contains("shuffled order"));
        assert!(t(&[Driver::Time], Driver::Load).contains("shuffled order"));
        assert!(t(&[Driver::Speed], Driver::Load).contains("more speed levels"));
    }

    #[test]
    fn a_check_reads_as_its_numbers() {
        let alt = Alternative {
            driver: Driver::Time,
            shape: "t x friction current".into(),
            words: "friction that grows with the time".into(),
            chi2: 120.0,
        };
        let mut check = DriverCheck {
            drivers: vec![Driver::Temperature],
            chi2: 80.0,
            best_alternative: Some(alt),
            separated: false,
            margin: SEPARATION_CHI2,
            separating_test: separating_test(&[Driver::Temperature], Driver::Time),
        };
        let s = check.summary("thermal-drift");
        assert!(s.contains("chi^2 80.0") && s.contains("chi^2 120.0"), "{s}");
        // 40 chi-square behind the alternative: the named law's weight is e^-20.
        assert!((check.weight() - 1.0 / (1.0 + 20f64.exp())).abs() < 1e-12);
        assert!(s.contains("the motor temperature or the time"), "{s}");
        assert!(s.contains("cool-down rest"), "{s}");
        check.separated = true;
        check.chi2 = 300.0;
        let s = check.summary("thermal-drift");
        assert!(s.contains("better than any generic shape"), "{s}");
    }
}
