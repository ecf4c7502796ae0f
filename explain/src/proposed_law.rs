//! A proposed law when no library law fits: a search over expressions in the rig's drivers
//! whose units are right by construction, fitted to what the final model leaves, accepted
//! only when it predicts held-out levels better than the generic residual shapes
//! ([`crate::residual_shape`]) and survives the block bootstrap.
//!
//! The drivers are the user-effect variables ([`crate::terms::USER_VARIABLES`]) with their
//! units: cam speed `w` (rad/s), load `tau` (N m), time `t` (s), the temperature rise
//! `temp - T0` over the data's coolest point (K), the model's current `i`, friction current
//! `i_f` and inertia current `i_m` (A) and the axial tooth force `f_ax` (N). A law is a sum
//! of at most [`MAX_TERMS`] terms, each a coefficient times a product of drivers (speed and
//! load in half-integer powers up to 3, the others to the first power) and optionally a
//! dimensionless function of one driver over a scale of the same unit: `1 - exp(-x / s)`
//! (a rise that saturates), `exp(-x / s)` (a fall that fades) or `1 / (1 + (x / s)^2)` (a
//! fall past a corner). Each coefficient's unit is
//! A over its term's units and each scale's unit is its driver's, so every law's unit is A
//! whatever it is; [`Law::unit`] recomputes it from the pieces and the search keeps only
//! laws it finds in A, and a function's argument must come out dimensionless.
//!
//! Scoring: each law's coefficients are least squares on the residual (its scales on a
//! geometric grid over the driver's range), chosen by BIC (a coefficient costs ln n, a
//! scale 2 ln of the grid's size, the price of choosing it among the grid's values).
//! Held out: every speed level, then every load level (with three or more of them; else the
//! blocks of the held-out validation) is predicted from a refit on the others; the law is
//! proposed only when its held-out RMSE beats the generic residual shape's held out the
//! same way and the residual's own, its BIC gain is strong ([`MIN_BIC_GAIN`]), and each of
//! its terms (scales aside) is in the best law of at least [`MIN_SHARE`] of the
//! block-bootstrap resamples.
//! It is only looked for when the verdict leaves a significant lack of fit, so effect-free
//! data never gets one. `EXPLAIN_DIAG_LAW=1` prints the search's steps to stderr.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use serde::Serialize;

use crate::fit::Fit;
use crate::lack_of_fit::LackOfFit;
use crate::points::TestPoints;
use crate::residual_shape::{Moments, ResidualShape, grouped_moments, least_squares, residual};
use crate::terms::{ModelAt, Needs};

/// Most terms in a law.
pub const MAX_TERMS: usize = 2;
/// Scales tried for each function of a driver (a geometric grid over its range).
const SCALES: usize = 6;
/// Fewest BIC units a law must gain over the residual alone (strong evidence).
pub const MIN_BIC_GAIN: f64 = 10.0;
/// Share of the bootstrap resamples whose best law must have each of the proposed law's
/// terms (scales aside).
pub const MIN_SHARE: f64 = 0.5;
/// Bootstrap resamples of the search.
const RESAMPLES: usize = 60;
/// Seed of the resamples, fixed so a run repeats exactly.
const SEED: u64 = 0x1a3f_77c0_9e21_0b35;

/// A driver: one of the user-effect variables, with its unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Driver {
    /// Cam speed, rad/s.
    Speed,
    /// Load, N m.
    Load,
    /// Time since the first test, s.
    Time,
    /// Temperature rise over the data's coolest point, K.
    TempRise,
    /// The model's current, A.
    Current,
    /// The model's friction current, A.
    FrictionCurrent,
    /// The inertia term's current, A.
    InertiaCurrent,
    /// The axial tooth force, N.
    AxialForce,
}

/// The base units the drivers carry, in the order of a [`Unit`]'s exponents.
pub const BASE_UNITS: [&str; 6] = ["A", "rad/s", "N m", "s", "K", "N"];

/// A unit: exponents (in halves) of [`BASE_UNITS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Unit(pub [i32; 6]);

impl Unit {
    /// The ampere.
    pub const AMPERE: Unit = Unit([2, 0, 0, 0, 0, 0]);
    /// No unit.
    pub const ONE: Unit = Unit([0; 6]);

    fn base(index: usize) -> Unit {
        let mut u = [0; 6];
        u[index] = 2;
        Unit(u)
    }

    /// This unit to the power `halves / 2`.
    pub fn pow_halves(self, halves: i32) -> Unit {
        Unit(self.0.map(|e| e * halves / 2))
    }

    /// The product of two units.
    pub fn times(self, other: Unit) -> Unit {
        let mut u = self.0;
        u.iter_mut().zip(other.0).for_each(|(a, b)| *a += b);
        Unit(u)
    }

    /// The inverse.
    pub fn inverse(self) -> Unit {
        Unit(self.0.map(|e| -e))
    }

    /// In words, e.g. `A (rad/s)^-2 (N m)^-1`, `rad/s`, `1`.
    pub fn text(self) -> String {
        let factors: Vec<(&str, i32)> = BASE_UNITS
            .iter()
            .zip(self.0)
            .filter(|(_, e)| *e != 0)
            .map(|(n, e)| (*n, e))
            .collect();
        if factors.is_empty() {
            return "1".into();
        }
        let alone = factors.len() == 1;
        factors
            .iter()
            .map(|&(name, e)| {
                let compound = name.contains(' ') || name.contains('/');
                if e == 2 && (alone || !compound) {
                    return name.to_string();
                }
                let base = if compound {
                    format!("({name})")
                } else {
                    name.to_string()
                };
                match e {
                    2 => base,
                    e if e % 2 == 0 => format!("{base}^{}", e / 2),
                    e => format!("{base}^{}", f64::from(e) / 2.0),
                }
            })
            .collect::<Vec<_>>()
            .join(" ")
    }
}

impl Driver {
    /// Every driver: speed and load first, then the others.
    pub const ALL: [Driver; 8] = [
        Driver::Speed,
        Driver::Load,
        Driver::Time,
        Driver::TempRise,
        Driver::Current,
        Driver::FrictionCurrent,
        Driver::InertiaCurrent,
        Driver::AxialForce,
    ];

    /// Its unit.
    pub fn unit(self) -> Unit {
        match self {
            Driver::Speed => Unit::base(1),
            Driver::Load => Unit::base(2),
            Driver::Time => Unit::base(3),
            Driver::TempRise => Unit::base(4),
            Driver::Current | Driver::FrictionCurrent | Driver::InertiaCurrent => Unit::AMPERE,
            Driver::AxialForce => Unit::base(5),
        }
    }

    /// The user-effect variable it reads.
    pub fn variable(self) -> &'static str {
        match self {
            Driver::Speed => "w",
            Driver::Load => "tau",
            Driver::Time => "t",
            Driver::TempRise => "temp",
            Driver::Current => "i",
            Driver::FrictionCurrent => "i_f",
            Driver::InertiaCurrent => "i_m",
            Driver::AxialForce => "f_ax",
        }
    }
}

/// A dimensionless function of one driver over a fitted scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Shape {
    /// `1 - exp(-x / s)`: a rise that saturates above s.
    Saturating,
    /// `exp(-x / s)`: a fall that fades above s.
    Fading,
    /// `1 / (1 + (x / s)^2)`: a fall past s as a first-order filter's power (a drive that
    /// stops following above a corner).
    Corner,
}

/// A term's identity with its scale left out: its drivers' powers and, for a shape, whether
/// it rises and of which driver.
type Family = (Vec<(Driver, i32)>, Option<(bool, Driver)>);

/// Groupings of the points for held-out validation: each point's group and the count.
type Groupings = Vec<(Vec<usize>, usize)>;

/// One term of a law: a coefficient times `drivers` (each to a power in halves) times an
/// optional shape of one driver over a scale.
#[derive(Debug, Clone, PartialEq)]
pub struct LawTerm {
    /// The drivers and their powers in halves (sorted, no zero power).
    pub powers: Vec<(Driver, i32)>,
    /// A shape of a driver over a scale (the scale's value).
    pub shape: Option<(Shape, Driver, f64)>,
    /// The coefficient's unit: A over the product's.
    pub coefficient_unit: Unit,
}

impl LawTerm {
    fn new(powers: Vec<(Driver, i32)>, shape: Option<(Shape, Driver, f64)>) -> Self {
        let product = powers
            .iter()
            .fold(Unit::ONE, |u, &(d, h)| u.times(d.unit().pow_halves(h)));
        Self {
            powers,
            shape,
            coefficient_unit: Unit::AMPERE.times(product.inverse()),
        }
    }

    /// The term's unit recomputed from its pieces (the coefficient's, the drivers' powers
    /// and the shape's argument, which must be dimensionless): `None` when the argument is
    /// not.
    pub fn unit(&self) -> Option<Unit> {
        if let Some((_, d, _)) = self.shape {
            // x / s with s in x's unit.
            let argument = d.unit().times(d.unit().inverse());
            if argument != Unit::ONE {
                return None;
            }
        }
        Some(
            self.powers
                .iter()
                .fold(self.coefficient_unit, |u, &(d, h)| {
                    u.times(d.unit().pow_halves(h))
                }),
        )
    }

    /// Identity of the term with its scale left out, and the two falls (fading, past a
    /// corner) as one: the bootstrap compares these, and a law has one term of each.
    fn family(&self) -> Family {
        (
            self.powers.clone(),
            self.shape.map(|(s, d, _)| (s == Shape::Saturating, d)),
        )
    }
}

/// A candidate column: a term's value at every point (its coefficient 1) and the scale
/// grid's size it was chosen from (1 without a shape).
struct Column {
    term: LawTerm,
    values: Vec<f64>,
    grid: usize,
    /// The term's family ([`LawTerm::family`]) as a number: columns that differ only in
    /// their scale share it.
    family: usize,
}

/// The drivers' values at every point, with what an expression needs to read them.
struct DriverValues {
    values: BTreeMap<Driver, Vec<f64>>,
    /// The coolest temperature, deg C (the temperature rise's origin).
    temp0: f64,
    /// Drivers that are negative somewhere (read through `abs()`).
    signed: Vec<Driver>,
}

impl DriverValues {
    fn new(points: &TestPoints, fit: &Fit) -> Self {
        let n = points.len();
        let at = ModelAt::new(
            &fit.model,
            &points.ops,
            Needs {
                current: true,
                friction: true,
                inertia: true,
                axial: true,
            },
        );
        let temp0 = points.temp_c.iter().copied().fold(f64::INFINITY, f64::min);
        let mut values = BTreeMap::new();
        values.insert(
            Driver::Speed,
            points.ops.iter().map(|op| op.omega_n).collect(),
        );
        values.insert(
            Driver::Load,
            points.ops.iter().map(|op| op.tau_rot).collect(),
        );
        if points.time_known && points.time_s.iter().any(|&t| t > 0.0) {
            values.insert(Driver::Time, points.time_s.clone());
        }
        let span = points
            .temp_c
            .iter()
            .fold(f64::NEG_INFINITY, |m, &t| m.max(t - temp0));
        if span > 1.0 {
            values.insert(
                Driver::TempRise,
                points.temp_c.iter().map(|t| t - temp0).collect(),
            );
        }
        for (d, v) in [
            (Driver::Current, at.current),
            (Driver::FrictionCurrent, at.friction),
            (Driver::InertiaCurrent, at.inertia),
            (Driver::AxialForce, at.axial),
        ] {
            if v.len() == n && v.iter().all(|x| x.is_finite()) {
                values.insert(d, v);
            }
        }
        // A driver that never changes is a constant's business.
        values.retain(|_, v| {
            let (lo, hi) = v
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            hi - lo > 1e-9 * hi.abs().max(lo.abs()).max(1e-300)
        });
        let signed = values
            .iter()
            .filter(|(_, v)| v.iter().any(|&x| x < 0.0))
            .map(|(&d, _)| d)
            .collect();
        Self {
            values,
            temp0,
            signed,
        }
    }

    /// The driver as it enters a law: its magnitude.
    fn magnitude(&self, d: Driver, k: usize) -> f64 {
        self.values[&d][k].abs()
    }

    /// The driver in an expression.
    fn read(&self, d: Driver) -> String {
        let v = match d {
            Driver::TempRise => format!("(temp - {})", number(self.temp0)),
            _ => d.variable().to_string(),
        };
        if self.signed.contains(&d) {
            format!("abs({v})")
        } else {
            v
        }
    }
}

/// The candidate columns over the drivers the data has.
fn columns(dv: &DriverValues, n: usize) -> Vec<Column> {
    let has = |d: Driver| dv.values.contains_key(&d);
    let (w, tau) = (Driver::Speed, Driver::Load);
    let mut products: Vec<Vec<(Driver, i32)>> = vec![vec![]];
    // Speed and load in half-integer powers up to 3 in all.
    for hw in [0, 1, 2, 3, 4, 6] {
        for ht in [0, 1, 2, 4] {
            if (hw, ht) == (0, 0) || hw + ht > 6 || (hw % 2 == 1 && ht % 2 == 1) {
                continue;
            }
            let mut p = Vec::new();
            if hw > 0 {
                p.push((w, hw));
            }
            if ht > 0 {
                p.push((tau, ht));
            }
            products.push(p);
        }
    }
    // The others to the first power, alone or times speed or load.
    for &d in &Driver::ALL[2..] {
        products.push(vec![(d, 2)]);
        products.push(vec![(w, 2), (d, 2)]);
        products.push(vec![(tau, 2), (d, 2)]);
    }
    let mut out = Vec::new();
    let mut families = Vec::new();
    let mut push = |powers: Vec<(Driver, i32)>, shape: Option<(Shape, Driver, f64)>, grid| {
        if powers.iter().any(|&(d, _)| !has(d)) {
            return;
        }
        let mut powers = powers;
        powers.sort();
        let values = (0..n)
            .map(|k| {
                let p: f64 = powers
                    .iter()
                    .map(|&(d, h)| {
                        let x = dv.magnitude(d, k);
                        if h % 2 == 0 {
                            x.powi(h / 2)
                        } else {
                            x.powf(h as f64 / 2.0)
                        }
                    })
                    .product();
                let g = match shape {
                    None => 1.0,
                    Some((Shape::Saturating, d, s)) => 1.0 - (-dv.magnitude(d, k) / s).exp(),
                    Some((Shape::Fading, d, s)) => (-dv.magnitude(d, k) / s).exp(),
                    Some((Shape::Corner, d, s)) => 1.0 / (1.0 + (dv.magnitude(d, k) / s).powi(2)),
                };
                p * g
            })
            .collect();
        let term = LawTerm::new(powers, shape);
        let key = term.family();
        let family = match families.iter().position(|f| *f == key) {
            Some(i) => i,
            None => {
                families.push(key);
                families.len() - 1
            }
        };
        out.push(Column {
            term,
            values,
            grid,
            family,
        });
    };
    for p in &products {
        push(p.clone(), None, 1);
    }
    // Shapes of speed, load, time and axial force, alone or times speed or load.
    for d in [w, tau, Driver::Time, Driver::AxialForce] {
        let Some(v) = dv.values.get(&d) else { continue };
        let (lo, hi) = v
            .iter()
            .map(|x| x.abs())
            .filter(|x| *x > 0.0)
            .fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
        if !(hi > 0.0 && lo.is_finite()) {
            continue;
        }
        let (a, b) = ((0.5 * lo).max(0.02 * hi), 2.0 * hi);
        for j in 0..SCALES {
            let s = a * (b / a).powf(j as f64 / (SCALES - 1) as f64);
            for shape in [Shape::Saturating, Shape::Fading, Shape::Corner] {
                for prefactor in [vec![], vec![(w, 2)], vec![(tau, 2)]] {
                    push(prefactor, Some((shape, d, s)), SCALES);
                }
            }
        }
    }
    out
}

/// A law: the sum of its terms with their fitted coefficients.
#[derive(Debug, Clone, PartialEq)]
pub struct Law {
    /// The terms.
    pub terms: Vec<LawTerm>,
    /// Their coefficients, in each term's coefficient unit.
    pub coefficients: Vec<f64>,
}

impl Law {
    /// The law's unit, recomputed from its terms: `None` when a shape's argument is not
    /// dimensionless or two terms differ.
    pub fn unit(&self) -> Option<Unit> {
        let mut units = self.terms.iter().map(LawTerm::unit);
        let first = units.next()??;
        units.all(|u| u == Some(first)).then_some(first)
    }
}

/// The proposed law, as `rig explain` reports it.
#[derive(Debug, Clone, Serialize)]
pub struct ProposedLaw {
    /// The law as an expression over the user-effect variables and its parameters (`c1`,
    /// `c2` coefficients, `s1`, `s2` scales), giving the extra current in A.
    pub expression: String,
    /// The unit of every parameter and variable it uses (the expression itself is in A).
    pub units: BTreeMap<String, String>,
    /// The fitted parameters, in their units.
    pub params: BTreeMap<String, f64>,
    /// The law in words.
    pub words: String,
    /// RMSE of the held-out predictions with the law (rows, their spread within points
    /// included), A.
    pub holdout_rmse_a: f64,
    /// The pure error of the repeats (rows), A; null when the data has too few repeats and
    /// the lack of fit was tested against another noise.
    pub pure_error_a: Option<f64>,
    /// The same held out with the generic residual shape instead, A.
    pub generic_holdout_rmse_a: f64,
    /// The same held out without any term (the residual itself), A.
    pub residual_holdout_rmse_a: f64,
    /// What was held out: `speed levels and load levels`, `speed levels`, `load levels` or
    /// `blocks`.
    pub held_out: String,
    /// BIC gain over the residual alone.
    pub bic_gain: f64,
    /// Share of the block-bootstrap resamples whose best law has each of this law's terms
    /// (scales aside): the least of the terms' shares.
    pub bootstrap_share: f64,
    /// A ready `[[user_effects]]` entry (TOML) for the rig file.
    pub user_effect: String,
}

/// The groups a held-out validation leaves out one at a time, and what they are.
fn holdout_groups(points: &TestPoints) -> Option<(Groupings, String)> {
    let n = points.len();
    let mut sets = Vec::new();
    let mut what = Vec::new();
    if points.speed_centres.len() >= 3 {
        sets.push((points.speed_level.clone(), points.speed_centres.len()));
        what.push("speed levels");
    }
    if points.load_centres.len() >= 3 {
        sets.push((points.load_level.clone(), points.load_centres.len()));
        what.push("load levels");
    }
    if sets.is_empty() {
        if points.folds == 0 {
            return None;
        }
        sets.push((points.fold.clone(), points.folds));
        what.push("blocks");
    }
    debug_assert!(sets.iter().all(|(g, _)| g.len() == n));
    Some((sets, what.join(" and ")))
}

/// Held-out RMSE of the columns `chosen` refitted without each group in turn, from the
/// groups' moments (`sets`: per grouping, one moments per group) and their totals.
fn holdout_rmse(sets: &[(Vec<Moments>, Moments)], nb: usize, chosen: &[usize]) -> f64 {
    let (mut sse, mut rows) = (0.0, 0.0);
    for (groups, total) in sets {
        for g in groups {
            if g.rows <= 0.0 {
                continue;
            }
            let mut train = total.clone();
            train.add_scaled(g, -1.0);
            let c = least_squares(&train, nb, chosen)
                .map(|(c, _)| c)
                .unwrap_or_else(|| vec![0.0; chosen.len()]);
            // e'e over the group's points = yy - 2 c.xy + c' G c, plus the spread within.
            let mut e2 = g.yy;
            for (a, &ia) in chosen.iter().enumerate() {
                e2 -= 2.0 * c[a] * g.xy[ia];
                for (b, &ib) in chosen.iter().enumerate() {
                    e2 += c[a] * c[b] * g.gram[ia * nb + ib];
                }
            }
            sse += e2.max(0.0) + g.within;
            rows += g.rows;
        }
    }
    if rows > 0.0 {
        (sse / rows).sqrt()
    } else {
        f64::INFINITY
    }
}

/// The best law (column indices) on moments `m` by BIC, with its BIC gain over none.
/// The best law (column indices) on moments `m` by BIC, with its BIC gain over none.
fn best_law(m: &Moments, columns: &[Column]) -> Option<(Vec<usize>, f64)> {
    let nb = columns.len();
    let n = m.rows;
    if n < 3.0 {
        return None;
    }
    let bic = |sse: f64, chosen: &[usize]| {
        let k: f64 = chosen
            .iter()
            .map(|&c| {
                let g = columns[c].grid;
                n.ln() + if g > 1 { 2.0 * (g as f64).ln() } else { 0.0 }
            })
            .sum();
        n * ((sse + m.within).max(1e-300) / n).ln() + k
    };
    let none = bic(m.yy, &[]);
    let g = |a: usize, b: usize| m.gram[a * nb + b];
    let mut best: Option<(Vec<usize>, f64)> = None;
    let mut consider = |chosen: &[usize], sse: f64| {
        let b = bic(sse.max(0.0), chosen);
        if best.as_ref().is_none_or(|(_, s)| b < *s) {
            best = Some((chosen.to_vec(), b));
        }
    };
    for a in 0..nb {
        // Least squares on one or two columns in closed form (a touch of ridge, as
        // `least_squares`).
        let gaa = g(a, a) * (1.0 + 1e-10);
        if gaa > 0.0 {
            consider(&[a], m.yy - m.xy[a] * m.xy[a] / gaa);
        }
        if MAX_TERMS >= 2 {
            for b in 0..a {
                // Two terms of one family (a shape at two scales) are one law's business.
                if columns[a].family == columns[b].family {
                    continue;
                }
                let gbb = g(b, b) * (1.0 + 1e-10);
                let gab = g(a, b);
                let det = gaa * gbb - gab * gab;
                if det.is_nan() || det <= 1e-12 * gaa * gbb {
                    continue;
                }
                let (xa, xb) = (m.xy[a], m.xy[b]);
                let fitted = (gbb * xa * xa - 2.0 * gab * xa * xb + gaa * xb * xb) / det;
                consider(&[b, a], m.yy - fitted);
            }
        }
    }
    best.map(|(c, b)| (c, none - b))
}

/// The proposed law for the residual of `fit` on `points`, or `None` when no law of the
/// search beats the generic `shape` on held-out levels, gains [`MIN_BIC_GAIN`] and survives
/// the bootstrap. Call it only when the lack of fit is significant.
pub fn propose(
    points: &TestPoints,
    fit: &Fit,
    shape: &ResidualShape,
    lack_of_fit: &LackOfFit,
) -> Option<ProposedLaw> {
    let n = points.len();
    let (groupings, held_out) = holdout_groups(points)?;
    let dv = DriverValues::new(points, fit);
    let columns = columns(&dv, n);
    if columns.is_empty() {
        return None;
    }
    let nb = columns.len();
    let y = residual(points, fit);
    let cols: Vec<&[f64]> = columns.iter().map(|c| c.values.as_slice()).collect();
    let by_block = grouped_moments(
        points,
        &cols,
        &y,
        |k| points.block[k] as usize,
        points.blocks,
    );
    let total = Moments::total(&by_block, nb);
    let (chosen, bic_gain) = best_law(&total, &columns)?;
    let diag = std::env::var_os("EXPLAIN_DIAG_LAW").is_some();
    if diag {
        eprintln!(
            "law: {} columns, best {:?} gain {bic_gain:.1}",
            nb,
            chosen.iter().map(|&c| &columns[c].term).collect::<Vec<_>>()
        );
    }
    if bic_gain < MIN_BIC_GAIN {
        return None;
    }
    let sets: Vec<(Vec<Moments>, Moments)> = groupings
        .iter()
        .map(|(group, count)| {
            let g = grouped_moments(points, &cols, &y, |k| group[k], *count);
            let t = Moments::total(&g, nb);
            (g, t)
        })
        .collect();
    let residual_rmse = holdout_rmse(&sets, nb, &[]);
    // The generic shape's bases, held out the same way.
    let generic_rmse = if shape.parts.is_empty() {
        residual_rmse
    } else {
        let gcols: Vec<Vec<f64>> = shape
            .parts
            .iter()
            .map(|(kind, _)| {
                (0..n)
                    .map(|k| {
                        let op = &points.ops[k];
                        kind.eval(op.omega_n, op.tau_rot, points.time_s[k], points.temp_c[k])
                    })
                    .collect()
            })
            .collect();
        let grefs: Vec<&[f64]> = gcols.iter().map(Vec::as_slice).collect();
        let gsets: Vec<(Vec<Moments>, Moments)> = groupings
            .iter()
            .map(|(group, count)| {
                let g = grouped_moments(points, &grefs, &y, |k| group[k], *count);
                let t = Moments::total(&g, grefs.len());
                (g, t)
            })
            .collect();
        let all: Vec<usize> = (0..grefs.len()).collect();
        holdout_rmse(&gsets, grefs.len(), &all)
    };
    // The block bootstrap of the search: how often each of the law's terms (scales aside)
    // is in the best law of a resample.
    let families: Vec<usize> = chosen.iter().map(|&c| columns[c].family).collect();
    let mut counts = vec![0usize; families.len()];
    let mut drawn = 0usize;
    for draws in crate::bootstrap::block_draws(SEED, by_block.len()).take(RESAMPLES) {
        let mut m = Moments::zero(nb);
        for (b, d) in by_block.iter().zip(&draws) {
            if *d > 0.0 {
                m.add_scaled(b, *d);
            }
        }
        drawn += 1;
        if let Some((c, _)) = best_law(&m, &columns) {
            for (count, f) in counts.iter_mut().zip(&families) {
                if c.iter().any(|&c| columns[c].family == *f) {
                    *count += 1;
                }
            }
        }
    }
    let share_of = |i: usize| counts[i] as f64 / drawn.max(1) as f64;
    // The law, or else its terms that survive the bootstrap on their own: each term in the
    // best law of at least MIN_SHARE of the resamples, and the held-out levels predicted
    // better than with the generic shape and with nothing.
    let firm: Vec<usize> = (0..chosen.len())
        .filter(|&i| share_of(i) >= MIN_SHARE)
        .collect();
    let (chosen, bootstrap_share) = if firm.len() == chosen.len() {
        let share = (0..chosen.len()).map(share_of).fold(1.0, f64::min);
        (chosen, share)
    } else if !firm.is_empty() {
        let share = firm.iter().map(|&i| share_of(i)).fold(1.0, f64::min);
        (firm.iter().map(|&i| chosen[i]).collect(), share)
    } else {
        if diag {
            eprintln!(
                "law: no term survives the bootstrap ({:?})",
                (0..chosen.len()).map(share_of).collect::<Vec<_>>()
            );
        }
        return None;
    };
    let law_rmse = holdout_rmse(&sets, nb, &chosen);
    if diag {
        eprintln!(
            "law: {} term(s), share {bootstrap_share:.2}; held out ({held_out}) law {:.1} generic {:.1} residual {:.1} mA; lof sigma {:.1} mA",
            chosen.len(),
            law_rmse * 1e3,
            generic_rmse * 1e3,
            residual_rmse * 1e3,
            lack_of_fit.sigma_a * 1e3
        );
    }
    if !(law_rmse < generic_rmse && law_rmse < residual_rmse) {
        return None;
    }
    let (coefficients, _) = least_squares(&total, nb, &chosen)?;
    let law = Law {
        terms: chosen.iter().map(|&c| columns[c].term.clone()).collect(),
        coefficients,
    };
    if law.unit() != Some(Unit::AMPERE) {
        return None;
    }
    let pure_error_a = lack_of_fit
        .against
        .starts_with("pure-error")
        .then_some(lack_of_fit.sigma_a);
    Some(render(
        &law,
        &dv,
        ProposedLaw {
            expression: String::new(),
            units: BTreeMap::new(),
            params: BTreeMap::new(),
            words: String::new(),
            holdout_rmse_a: law_rmse,
            pure_error_a,
            generic_holdout_rmse_a: generic_rmse,
            residual_holdout_rmse_a: residual_rmse,
            held_out,
            bic_gain,
            bootstrap_share,
            user_effect: String::new(),
        },
    ))
}

/// A number for an expression: 6 significant digits.
fn number(v: f64) -> String {
    let s = format!("{v:.6e}");
    let parsed: f64 = s.parse().unwrap_or(v);
    format!("{parsed}")
}

/// The law's expression, units, parameters, words and user effect, into `out`.
fn render(law: &Law, dv: &DriverValues, mut out: ProposedLaw) -> ProposedLaw {
    let mut terms = Vec::new();
    let mut words = Vec::new();
    let mut params = Vec::new();
    let mut scale_index = 0;
    for (i, (t, &c)) in law.terms.iter().zip(&law.coefficients).enumerate() {
        let cname = format!("c{}", i + 1);
        let mut factors = vec![cname.clone()];
        let mut word = Vec::new();
        for &(d, h) in &t.powers {
            let v = dv.read(d);
            factors.push(match h {
                1 => format!("sqrt({v})"),
                2 => v.clone(),
                h if h % 2 == 0 => format!("{v}^{}", h / 2),
                h => format!("{v}^{}", h as f64 / 2.0),
            });
            out.units.insert(d.variable().to_string(), d.unit().text());
            word.push(if h == 2 {
                d.variable().to_string()
            } else {
                format!("{}^{}", d.variable(), h as f64 / 2.0)
            });
        }
        out.units.insert(cname.clone(), t.coefficient_unit.text());
        out.params.insert(cname.clone(), c);
        let b = 4.0 * c.abs().max(1e-12);
        params.push(format!(
            "{cname} = {{ unit = \"{}\", bounds = [{}, {}], start = {} }}",
            t.coefficient_unit.text(),
            number(-b),
            number(b),
            number(c)
        ));
        if let Some((shape, d, s)) = t.shape {
            scale_index += 1;
            let sname = format!("s{scale_index}");
            let x = dv.read(d);
            factors.push(match shape {
                Shape::Saturating => format!("(1 - exp(-{x} / {sname}))"),
                Shape::Fading => format!("exp(-{x} / {sname})"),
                Shape::Corner => format!("1 / (1 + ({x} / {sname})^2)"),
            });
            word.push(match shape {
                Shape::Saturating => format!("(1 - exp(-{} / {sname}))", d.variable()),
                Shape::Fading => format!("exp(-{} / {sname})", d.variable()),
                Shape::Corner => format!("1 / (1 + ({} / {sname})^2)", d.variable()),
            });
            out.units.insert(d.variable().to_string(), d.unit().text());
            out.units.insert(sname.clone(), d.unit().text());
            out.params.insert(sname.clone(), s);
            params.push(format!(
                "{sname} = {{ unit = \"{}\", bounds = [{}, {}], start = {s}, null = {s}, log = true }}",
                d.unit().text(),
                number(s / 10.0),
                number(s * 10.0),
                s = number(s)
            ));
            let _ = write!(
                word.last_mut().expect("just pushed"),
                " with {sname} = {} {}",
                number(s),
                d.unit().text()
            );
        }
        terms.push(factors.join(" * "));
        words.push(format!(
            "{} {} x {}",
            number(c),
            t.coefficient_unit.text(),
            if word.is_empty() {
                "1".to_string()
            } else {
                word.join(" ")
            }
        ));
    }
    out.expression = terms.join(" + ");
    out.words = words.join(" + ");
    out.user_effect = format!(
        "# Runs on the virtual rig too: add this and [[model.terms]] with the same name to the\n# model `rig explain --write-model` writes, then `rig sim serve --model FILE`.\n[[user_effects]]\nname = \"proposed-law\"  # name it after its cause\nexpression = \"{}\"\nparams = {{ {} }}\n",
        out.expression,
        params.join(", ")
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_compose_and_read() {
        let w = Driver::Speed.unit();
        let tau = Driver::Load.unit();
        assert_eq!(w.text(), "rad/s");
        assert_eq!(Unit::ONE.text(), "1");
        let t = LawTerm::new(vec![(Driver::Speed, 4), (Driver::Load, 2)], None);
        assert_eq!(t.coefficient_unit.text(), "A (rad/s)^-2 (N m)^-1");
        assert_eq!(t.unit(), Some(Unit::AMPERE));
        let half = LawTerm::new(vec![(Driver::Speed, 1)], None);
        assert_eq!(half.coefficient_unit.text(), "A (rad/s)^-0.5");
        assert_eq!(w.times(tau).inverse().times(w).times(tau), Unit::ONE);
        // A current driver leaves a dimensionless coefficient.
        let f = LawTerm::new(vec![(Driver::FrictionCurrent, 2)], None);
        assert_eq!(f.coefficient_unit, Unit::ONE);
    }

    #[test]
    fn a_law_whose_terms_differ_in_unit_has_none() {
        let mut a = LawTerm::new(vec![(Driver::Speed, 2)], None);
        let b = LawTerm::new(vec![(Driver::Load, 2)], None);
        let law = Law {
            terms: vec![a.clone(), b],
            coefficients: vec![1.0, 1.0],
        };
        assert_eq!(law.unit(), Some(Unit::AMPERE));
        a.coefficient_unit = Unit::AMPERE;
        let wrong = Law {
            terms: vec![a, LawTerm::new(vec![], None)],
            coefficients: vec![1.0, 1.0],
        };
        assert_eq!(wrong.unit(), None, "A rad/s + A is not a unit");
    }
}
