//! The shape of what remains: when a significant lack of fit is left, a sparse selection over
//! a generic basis of the logged variables (powers and products of speed and load, time,
//! temperature, a narrow peak at each speed level, a step between speed levels) describes the
//! final model's residual. Forward selection by BIC (at most [`MAX_TERMS`] terms), repeated
//! on block-bootstrap resamples of the test points, gives each term's inclusion probability.
//! The result is said in words and written as a ready `[[user_effects]]` entry to name, paste
//! into the rig file and refit.

use serde::Serialize;

use super::fit::Fit;
use super::points::TestPoints;
use super::stats;

/// Most basis terms in the description.
pub const MAX_TERMS: usize = 3;
/// Bootstrap resamples of the selection.
const RESAMPLES: usize = 100;
/// Seed of the resamples, fixed so a run repeats exactly.
const SEED: u64 = 0x5a9e_0f4e_5100_0019;
/// A term is part of the shape when it is selected in at least this share of the resamples.
const FIRM_SHARE: f64 = 0.6;

/// What a basis function computes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BasisKind {
    /// (w / w_max)^pw (tau / tau_max)^pt.
    Power {
        /// Power of the speed.
        pw: i32,
        /// Power of the load.
        pt: i32,
        /// Speed scale, rad/s.
        w_max: f64,
        /// Load scale, N m.
        tau_max: f64,
    },
    /// t / t_max.
    Time {
        /// Time scale, s.
        t_max: f64,
    },
    /// (temp - lo) / span.
    Temperature {
        /// Lowest temperature, deg C.
        lo: f64,
        /// Span, K.
        span: f64,
    },
    /// exp(-((w - centre) / width)^2).
    Peak {
        /// Centre, rad/s.
        centre: f64,
        /// Width, rad/s.
        width: f64,
    },
    /// 1 / (1 + exp(-(w - at) / sharpness)).
    Step {
        /// Where, rad/s.
        at: f64,
        /// Sharpness, rad/s.
        sharpness: f64,
    },
}

impl BasisKind {
    /// Its value at cam speed `w` (rad/s), load `tau` (N m), time `t` (s) and motor
    /// temperature `temp` (deg C).
    pub fn eval(&self, w: f64, tau: f64, t: f64, temp: f64) -> f64 {
        match *self {
            BasisKind::Power {
                pw,
                pt,
                w_max,
                tau_max,
            } => (w / w_max).powi(pw) * (tau.abs() / tau_max).powi(pt),
            BasisKind::Time { t_max } => t / t_max,
            BasisKind::Temperature { lo, span } => (temp - lo) / span,
            BasisKind::Peak { centre, width } => (-((w - centre) / width).powi(2)).exp(),
            BasisKind::Step { at, sharpness } => 1.0 / (1.0 + (-(w - at) / sharpness).exp()),
        }
    }
}

/// One basis function, with how it reads in words and in a user effect's expression.
#[derive(Debug, Clone)]
struct Basis {
    name: String,
    words: String,
    /// The expression over the user-effect variables (w, tau, t, temp) without its
    /// coefficient.
    expression: String,
    kind: BasisKind,
    values: Vec<f64>,
}

/// One term of the residual's shape.
#[derive(Debug, Clone, Serialize)]
pub struct ShapeTerm {
    /// The basis function, e.g. `w^2 tau`.
    pub basis: String,
    /// The same in words.
    pub words: String,
    /// Its coefficient on all the data, A (the basis is scaled to 1 at the data's largest
    /// speed, load, time or temperature rise, so this is the current it adds there).
    pub coefficient_a: f64,
    /// Share of the bootstrap resamples that select it.
    pub inclusion_probability: f64,
}

/// The residual's shape.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualShape {
    /// The terms selected on all the data, firmest first.
    pub terms: Vec<ShapeTerm>,
    /// Other terms the resamples select in a fifth or more of the cases.
    pub rivals: Vec<ShapeTerm>,
    /// Whether every selected term is firm (selected in at least 60 % of the resamples).
    pub separable: bool,
    /// The shape in words.
    pub description: String,
    /// A ready `[[user_effects]]` entry (TOML) for the rig file.
    pub user_effect: String,
    /// RMSE of the residual before and after the shape, mA.
    pub rmse_ma: [f64; 2],
    /// The selected basis functions with their coefficients (A), for predictions.
    #[serde(skip)]
    pub parts: Vec<(BasisKind, f64)>,
}

impl ResidualShape {
    /// The shape's current at cam speed `w` (rad/s), load `tau` (N m), time `t` (s) and motor
    /// temperature `temp` (deg C), A.
    pub fn current(&self, w: f64, tau: f64, t: f64, temp: f64) -> f64 {
        self.parts
            .iter()
            .map(|(k, c)| c * k.eval(w, tau, t, temp))
            .sum()
    }
}

fn bases(points: &TestPoints) -> Vec<Basis> {
    let n = points.len();
    let w_max = points
        .ops
        .iter()
        .fold(0.0f64, |m, op| m.max(op.omega_n.abs()))
        .max(1e-9);
    let tau_max = points
        .ops
        .iter()
        .fold(0.0f64, |m, op| m.max(op.tau_rot.abs()))
        .max(1e-9);
    let t_max = points.time_s.iter().fold(0.0f64, |m, &t| m.max(t));
    let (temp_lo, temp_hi) = points
        .temp_c
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
            (a.min(t), b.max(t))
        });
    let (ws, ts) = (fmt(w_max), fmt(tau_max));
    let mut out = Vec::new();
    let mut push = |name: &str, words: &str, expression: String, kind: BasisKind| {
        let values = (0..n)
            .map(|k| {
                let op = &points.ops[k];
                kind.eval(op.omega_n, op.tau_rot, points.time_s[k], points.temp_c[k])
            })
            .collect();
        out.push(Basis {
            name: name.into(),
            words: words.into(),
            expression,
            kind,
            values,
        })
    };
    let power = |pw: i32, pt: i32| BasisKind::Power {
        pw,
        pt,
        w_max,
        tau_max,
    };
    push("1", "a constant", "1".into(), power(0, 0));
    push("w", "grows like speed", format!("(w / {ws})"), power(1, 0));
    push(
        "w^2",
        "grows like speed squared",
        format!("(w / {ws})^2"),
        power(2, 0),
    );
    push(
        "w^3",
        "grows like speed cubed",
        format!("(w / {ws})^3"),
        power(3, 0),
    );
    push(
        "tau",
        "grows like load",
        format!("(tau / {ts})"),
        power(0, 1),
    );
    push(
        "tau^2",
        "grows like load squared",
        format!("(tau / {ts})^2"),
        power(0, 2),
    );
    push(
        "w tau",
        "grows like speed times load",
        format!("(w / {ws}) * (tau / {ts})"),
        power(1, 1),
    );
    push(
        "w^2 tau",
        "grows like speed squared times load",
        format!("(w / {ws})^2 * (tau / {ts})"),
        power(2, 1),
    );
    push(
        "w tau^2",
        "grows like speed times load squared",
        format!("(w / {ws}) * (tau / {ts})^2"),
        power(1, 2),
    );
    if t_max > 0.0 {
        let tm = fmt(t_max);
        push(
            "t",
            "grows with time through the session",
            format!("(t / {tm})"),
            BasisKind::Time { t_max },
        );
    }
    if temp_hi - temp_lo > 1.0 {
        let span = temp_hi - temp_lo;
        let (lo, sp) = (fmt(temp_lo), fmt(span));
        push(
            "temp",
            "grows with the motor temperature",
            format!("((temp - {lo}) / {sp})"),
            BasisKind::Temperature { lo: temp_lo, span },
        );
    }
    // Narrow peaks at each speed level and steps between neighbouring levels.
    let mut levels = points.speed_centres.clone();
    levels.sort_by(f64::total_cmp);
    if levels.len() >= 3 {
        for (i, &c) in levels.iter().enumerate() {
            let gap = [
                i.checked_sub(1).map(|j| c - levels[j]),
                levels.get(i + 1).map(|&d| d - c),
            ]
            .into_iter()
            .flatten()
            .fold(f64::INFINITY, f64::min);
            let width = 0.25 * gap;
            let hz = c / std::f64::consts::TAU;
            push(
                &format!("peak {hz:.1} Hz"),
                &format!("a narrow peak at {hz:.1} Hz of cam speed (a resonance?)"),
                format!("exp(-((w - {}) / {})^2)", fmt(c), fmt(width)),
                BasisKind::Peak { centre: c, width },
            );
        }
        for pair in levels.windows(2) {
            let m = 0.5 * (pair[0] + pair[1]);
            let s = (pair[1] - pair[0]) / 20.0;
            let hz = m / std::f64::consts::TAU;
            push(
                &format!("step {hz:.1} Hz"),
                &format!("a step up above {hz:.1} Hz of cam speed"),
                format!("1 / (1 + exp(-(w - {}) / {}))", fmt(m), fmt(s)),
                BasisKind::Step {
                    at: m,
                    sharpness: s,
                },
            );
        }
    }
    out
}

/// A number for an expression: 6 significant digits.
fn fmt(v: f64) -> String {
    let s = format!("{v:.6e}");
    let parsed: f64 = s.parse().unwrap_or(v);
    format!("{parsed}")
}

/// Weighted moments of the bases and the residual: the Gram matrix (B x B), the bases times
/// the residual, the residual's square sum, the rows and the rows' spread within points.
/// Moments add, so a bootstrap resample of blocks is a weighted sum of the blocks' moments
/// (and a fit without one group is the total less that group's).
#[derive(Debug, Clone)]
pub(crate) struct Moments {
    pub(crate) gram: Vec<f64>,
    pub(crate) xy: Vec<f64>,
    pub(crate) yy: f64,
    pub(crate) rows: f64,
    pub(crate) within: f64,
}

impl Moments {
    pub(crate) fn zero(b: usize) -> Self {
        Self {
            gram: vec![0.0; b * b],
            xy: vec![0.0; b],
            yy: 0.0,
            rows: 0.0,
            within: 0.0,
        }
    }

    pub(crate) fn add_scaled(&mut self, other: &Moments, s: f64) {
        self.gram
            .iter_mut()
            .zip(&other.gram)
            .for_each(|(a, b)| *a += s * b);
        self.xy
            .iter_mut()
            .zip(&other.xy)
            .for_each(|(a, b)| *a += s * b);
        self.yy += s * other.yy;
        self.rows += s * other.rows;
        self.within += s * other.within;
    }

    /// The sum of `parts`.
    pub(crate) fn total(parts: &[Moments], b: usize) -> Self {
        let mut out = Moments::zero(b);
        for m in parts {
            out.add_scaled(m, 1.0);
        }
        out
    }
}

/// The moments of residual `y` on the columns `cols` (each a value per point of `points`),
/// one set per group: point `k` goes to group `group_of(k)` (clamped to `groups - 1`).
pub(crate) fn grouped_moments(
    points: &TestPoints,
    cols: &[&[f64]],
    y: &[f64],
    group_of: impl Fn(usize) -> usize,
    groups: usize,
) -> Vec<Moments> {
    let nb = cols.len();
    let groups = groups.max(1);
    let mut out = vec![Moments::zero(nb); groups];
    let mut x = vec![0.0; nb];
    for k in 0..y.len() {
        let m = &mut out[group_of(k).min(groups - 1)];
        let w = points.weight[k];
        m.yy += w * y[k] * y[k];
        m.rows += w;
        m.within += points.within_ss[k];
        for (xi, c) in x.iter_mut().zip(cols) {
            *xi = c[k];
        }
        for i in 0..nb {
            let wxi = w * x[i];
            m.xy[i] += wxi * y[k];
            let row = &mut m.gram[i * nb..i * nb + i + 1];
            for (g, xj) in row.iter_mut().zip(&x) {
                *g += wxi * xj;
            }
        }
    }
    for m in &mut out {
        for i in 0..nb {
            for j in 0..i {
                m.gram[j * nb + i] = m.gram[i * nb + j];
            }
        }
    }
    out
}

/// The moments of each bootstrap block of `points` for residual `y`.
fn block_moments(points: &TestPoints, bases: &[Basis], y: &[f64]) -> Vec<Moments> {
    let cols: Vec<&[f64]> = bases.iter().map(|b| b.values.as_slice()).collect();
    grouped_moments(
        points,
        &cols,
        y,
        |k| points.block[k] as usize,
        points.blocks,
    )
}

/// Weighted least squares of the residual on the bases `chosen`, from moments `m`:
/// coefficients and SSE.
pub(crate) fn least_squares(m: &Moments, nb: usize, chosen: &[usize]) -> Option<(Vec<f64>, f64)> {
    let p = chosen.len();
    if p == 0 {
        return Some((Vec::new(), m.yy));
    }
    let mut a = vec![0.0; p * p];
    let mut b = vec![0.0; p];
    for (i, &ci) in chosen.iter().enumerate() {
        b[i] = m.xy[ci];
        for (j, &cj) in chosen.iter().enumerate() {
            a[i * p + j] = m.gram[ci * nb + cj];
        }
        // A touch of ridge keeps nearly collinear bases solvable.
        a[i * p + i] *= 1.0 + 1e-10;
    }
    let l = stats::cholesky(&a, p)?;
    let c = stats::cholesky_solve(&l, p, &b);
    let fitted: f64 = c.iter().zip(&b).map(|(c, b)| c * b).sum();
    Some((c, (m.yy - fitted).max(0.0)))
}

/// Forward selection by BIC over the bases, from moments `m`.
fn select(m: &Moments, nb: usize) -> Vec<usize> {
    let n = m.rows;
    if n < 3.0 {
        return Vec::new();
    }
    let bic = |sse: f64, k: usize| n * ((sse + m.within).max(1e-300) / n).ln() + k as f64 * n.ln();
    let mut chosen: Vec<usize> = Vec::new();
    let mut best_bic = bic(m.yy, 0);
    while chosen.len() < MAX_TERMS {
        let mut step: Option<(usize, f64)> = None;
        for c in 0..nb {
            if chosen.contains(&c) {
                continue;
            }
            let mut trial = chosen.clone();
            trial.push(c);
            if let Some((_, sse)) = least_squares(m, nb, &trial) {
                let b = bic(sse, trial.len());
                if step.is_none_or(|(_, s)| b < s) {
                    step = Some((c, b));
                }
            }
        }
        match step {
            Some((c, b)) if b < best_bic - 2.0 => {
                chosen.push(c);
                best_bic = b;
            }
            _ => break,
        }
    }
    chosen
}

/// Measured minus `fit`'s current at every point of `points`, A.
pub(crate) fn residual(points: &TestPoints, fit: &Fit) -> Vec<f64> {
    points
        .current
        .iter()
        .zip(fit.predict(points))
        .map(|(m, f)| m - f)
        .collect()
}

/// The shape of the residual of `fit` on `points`.
pub fn residual_shape(points: &TestPoints, fit: &Fit) -> ResidualShape {
    let bases = bases(points);
    let nb = bases.len();
    let y = residual(points, fit);
    let by_block = block_moments(points, &bases, &y);
    let total = Moments::total(&by_block, nb);
    let chosen = select(&total, nb);
    let (coefficients, sse1) = least_squares(&total, nb, &chosen).unwrap_or((Vec::new(), total.yy));
    // Block bootstrap of the selection.
    let mut counts = vec![0usize; nb];
    for draws in crate::bootstrap::block_draws(SEED, by_block.len()).take(RESAMPLES) {
        let mut m = Moments::zero(nb);
        for (b, d) in by_block.iter().zip(&draws) {
            if *d > 0.0 {
                m.add_scaled(b, *d);
            }
        }
        for c in select(&m, nb) {
            counts[c] += 1;
        }
    }
    let share = |c: usize| counts[c] as f64 / RESAMPLES as f64;
    let term = |c: usize, coefficient_a: f64| ShapeTerm {
        basis: bases[c].name.clone(),
        words: bases[c].words.clone(),
        coefficient_a,
        inclusion_probability: share(c),
    };
    let mut terms: Vec<ShapeTerm> = chosen
        .iter()
        .zip(&coefficients)
        .map(|(&c, &k)| term(c, k))
        .collect();
    terms.sort_by(|a, b| b.inclusion_probability.total_cmp(&a.inclusion_probability));
    let rivals: Vec<ShapeTerm> = (0..bases.len())
        .filter(|c| !chosen.contains(c) && share(*c) >= 0.2)
        .map(|c| term(c, f64::NAN))
        .collect();
    let separable =
        !terms.is_empty() && terms.iter().all(|t| t.inclusion_probability >= FIRM_SHARE);
    let n = total.rows.max(1.0);
    let sse0 = total.yy;
    let description = describe(&terms, &rivals, separable);
    let user_effect = user_effect(&bases, &chosen, &coefficients);
    let parts = chosen
        .iter()
        .zip(&coefficients)
        .map(|(&c, &k)| (bases[c].kind, k))
        .collect();
    ResidualShape {
        parts,
        terms,
        rivals,
        separable,
        description,
        user_effect,
        rmse_ma: [(sse0 / n).sqrt() * 1e3, (sse1 / n).sqrt() * 1e3],
    }
}

fn describe(terms: &[ShapeTerm], rivals: &[ShapeTerm], separable: bool) -> String {
    if terms.is_empty() {
        return "no term of the generic basis describes the residual better than noise".into();
    }
    let parts: Vec<String> = terms
        .iter()
        .map(|t| {
            format!(
                "{} ({:+.1} mA at the largest value, in {:.0} % of resamples)",
                t.words,
                t.coefficient_a * 1e3,
                100.0 * t.inclusion_probability
            )
        })
        .collect();
    let mut s = format!("the residual {}", parts.join(", plus "));
    if !separable || !rivals.is_empty() {
        let _ = std::fmt::Write::write_fmt(
            &mut s,
            format_args!(
                "; the data cannot firmly separate it from {}: tests at more speed levels (for shapes over speed) or more loads (for shapes over load) would",
                if rivals.is_empty() {
                    "other shapes".to_string()
                } else {
                    rivals
                        .iter()
                        .map(|r| format!("{} ({:.0} %)", r.words, 100.0 * r.inclusion_probability))
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ),
        );
    }
    s
}

fn user_effect(bases: &[Basis], chosen: &[usize], coefficients: &[f64]) -> String {
    if chosen.is_empty() {
        return String::new();
    }
    let expression = chosen
        .iter()
        .enumerate()
        .map(|(i, &c)| format!("c{} * {}", i + 1, bases[c].expression))
        .collect::<Vec<_>>()
        .join(" + ");
    let params = chosen
        .iter()
        .enumerate()
        .map(|(i, _)| {
            let v = coefficients.get(i).copied().unwrap_or(0.0);
            let b = (4.0 * v.abs()).max(0.05);
            format!(
                "c{} = {{ unit = \"A\", bounds = [{}, {}], start = {} }}",
                i + 1,
                fmt(-b),
                fmt(b),
                fmt(v)
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "[[user_effects]]\nname = \"residual-shape\"  # name it after its cause\nexpression = \"{expression}\"\nparams = {{ {params} }}\n"
    )
}
