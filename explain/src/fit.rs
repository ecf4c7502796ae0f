//! Fitting the current model to the test points: bounded Levenberg-Marquardt on the mean
//! parameters and the terms' coordinates (normal equations solved by Cholesky on a few
//! unknowns; the model's derivatives analytic, the terms' by forward differences), a profiled
//! variance parameter for the mesh ripple, a threshold fit for the linear bush's holding, the
//! Gaussian (and backdrive) likelihood with BIC, and blocked held-out validation.

use model::effects::{CurrentEvaluator, CurrentModel, Effect, OperatingPoint, PARAM_COUNT, Param};

use super::library;
use super::points::{HoldCheck, TestPoints};
use super::stats;
use super::terms::{ModelAt, Needs, Term};

/// Assumed rate at which a backdrive observation is wrong (a slip, a misread), for the
/// likelihood of the `backdriven` column.
pub const HOLD_LABEL_ERROR: f64 = 0.01;
/// Iteration limit of the Levenberg-Marquardt loop.
const MAX_ITERATIONS: usize = 60;
/// Alternations between the mean and the ripple variance.
const RIPPLE_ROUNDS: usize = 3;
/// Forward-difference step of a coordinate, as a share of its bounds' width.
const DIFF_STEP: f64 = 1e-7;
/// Floor of the row noise scale in the likelihood, A: the resolution to which the model
/// itself is known. Table 2 prints the no-load current C6 = 2.25 A to 10 mA, and the rig's
/// 12-bit current reading it was taken through steps by 6.5 mA: the model's current is not
/// known more finely than a uniform 10 mA step, rms 10 mA / sqrt 12 = 2.9 mA. Rows more
/// precise than that (long whole-revolution averages on a virtual rig, many repeats at a
/// few proposed points) would otherwise turn the model's own rounding, a milliampere or
/// two, into a confident finding. Noisier data (a bench, the synthetic sweeps at 5 mA and
/// more) never reach the floor.
pub const SIGMA_FLOOR_A: f64 = 0.010 / 3.464_101_615_137_754_4;

/// Which effects a model carries on top of the paper's.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelSpec {
    /// The library effects in their own laws, in the order they were added.
    pub effects: Vec<Effect>,
    /// The terms ([`TestPoints::terms`] indices), in the order they were added.
    pub terms: Vec<usize>,
}

impl ModelSpec {
    /// The paper's model (mu fitted).
    pub fn base() -> Self {
        Self::default()
    }

    /// This model with `effect` added.
    pub fn with(&self, effect: Effect) -> Self {
        let mut s = self.clone();
        if !s.has(effect) {
            s.effects.push(effect);
        }
        s
    }

    /// This model with term `term` added.
    pub fn with_term(&self, term: usize) -> Self {
        let mut s = self.clone();
        if !s.terms.contains(&term) {
            s.terms.push(term);
        }
        s
    }

    /// Whether the model carries `effect` in its library law.
    pub fn has(&self, effect: Effect) -> bool {
        self.effects.contains(&effect)
    }

    /// Parameters of the mean current that are fitted: mu and one per effect (the terms'
    /// coordinates follow them in a fit).
    pub fn free_params(&self) -> Vec<Param> {
        let mut p = vec![Param::Mu];
        p.extend(self.effects.iter().filter_map(|e| e.mean_param()));
        p
    }

    /// BIC penalty for `n` rows: ln n per parameter (noise level included), the terms'
    /// shapes at [`crate::terms::SHAPE_PENALTY`].
    pub fn penalty(&self, terms: &[Term], n: f64) -> f64 {
        let shapes: usize = self.terms.iter().map(|&t| terms[t].shape_count()).sum();
        (self.parameter_count(terms) - shapes) as f64 * n.ln()
            + shapes as f64 * crate::terms::SHAPE_PENALTY
    }

    /// Parameters counted by the information criterion (noise level included), the terms of
    /// `terms`.
    pub fn parameter_count(&self, terms: &[Term]) -> usize {
        2 + self
            .effects
            .iter()
            .map(|&e| library::parameter_count(e))
            .sum::<usize>()
            + self
                .terms
                .iter()
                .map(|&t| terms[t].parameter_count())
                .sum::<usize>()
    }
}

/// A fitted model.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The effects it carries.
    pub spec: ModelSpec,
    /// The fitted model (mean, ripple and bush hold parameters).
    pub model: CurrentModel,
    /// The fitted mean parameters, in the order of `cov` (the terms' coordinates follow).
    pub free: Vec<Param>,
    /// The fitted coordinates of each term of `spec.terms`.
    pub term_x: Vec<Vec<f64>>,
    /// Measured minus fitted current of the fitted points (of each point's mean current), A.
    pub residuals: Vec<f64>,
    /// Sum of squared residuals of the fitted rows (the points' spread included), A^2.
    pub sse: f64,
    /// Standard deviation of the current noise without ripple, A.
    pub sigma0: f64,
    /// Log-likelihood of the currents (Gaussian).
    pub loglik_current: f64,
    /// Log-likelihood of the backdrive observations (0 without non-backdriven rows).
    pub loglik_hold: f64,
    /// Backdrive observations the model gets wrong.
    pub hold_errors: usize,
    /// Number of fitted rows.
    pub n: usize,
    /// Number of parameters.
    pub k: usize,
    /// Shape parameters among them (penalised at [`crate::terms::SHAPE_PENALTY`]).
    pub shapes: usize,
    /// Bayesian information criterion, -2 ln L + k ln n.
    pub bic: f64,
    /// Covariance of the free parameters then the terms' coordinates (row-major), NaN where
    /// one sits on a bound.
    pub cov: Vec<f64>,
    /// Whether the iteration converged.
    pub converged: bool,
}

impl Fit {
    /// Root mean square of the residuals of the fitted rows, A.
    pub fn rmse(&self) -> f64 {
        (self.sse / self.n.max(1) as f64).sqrt()
    }

    /// Total log-likelihood.
    pub fn loglik(&self) -> f64 {
        self.loglik_current + self.loglik_hold
    }

    fn unknowns(&self) -> usize {
        self.free.len() + self.term_x.iter().map(Vec::len).sum::<usize>()
    }

    fn std_error_at(&self, i: usize) -> Option<f64> {
        let p = self.unknowns();
        let v = *self.cov.get(i * p + i)?;
        (v.is_finite() && v >= 0.0).then(|| v.sqrt())
    }

    /// Standard error of a free parameter, if it is free and off its bounds.
    pub fn std_error(&self, param: Param) -> Option<f64> {
        let i = self.free.iter().position(|&q| q == param)?;
        self.std_error_at(i)
    }

    /// Standard error of coordinate `coord` of the `t`-th term of the spec.
    pub fn term_std_error(&self, t: usize, coord: usize) -> Option<f64> {
        let offset = self.free.len() + self.term_x[..t].iter().map(Vec::len).sum::<usize>();
        self.std_error_at(offset + coord)
    }

    /// Noise standard deviation at `op`, A (the ripple scatters the friction term).
    pub fn sigma_at(&self, op: &OperatingPoint) -> f64 {
        self.sigma_with(&self.model.evaluator(), op)
    }

    /// [`Fit::sigma_at`] with the model's evaluator at hand.
    pub fn sigma_with(&self, ev: &CurrentEvaluator, op: &OperatingPoint) -> f64 {
        let r = self.model.effects.mesh_ripple_rms;
        if r == 0.0 {
            self.sigma0
        } else {
            let f = r * ev.friction_current(op);
            (self.sigma0 * self.sigma0 + f * f).sqrt()
        }
    }

    /// The fitted mean current at every point, A.
    pub fn predict(&self, points: &TestPoints) -> Vec<f64> {
        predict(points, &self.model, &self.spec.terms, &self.term_x)
    }

    /// The fitted mean current of every row of [`TestPoints::row_view`] (time order), A.
    pub fn predict_rows(&self, points: &TestPoints) -> Vec<f64> {
        let rv = &points.row_view;
        let ev = self.model.evaluator();
        if self.spec.terms.is_empty() {
            return (0..rv.len()).map(|j| ev.current(&rv.op(j))).collect();
        }
        let ops: Vec<OperatingPoint> = (0..rv.len()).map(|j| rv.op(j)).collect();
        let mut out: Vec<f64> = ops.iter().map(|op| ev.current(op)).collect();
        let order: Vec<usize> = (0..rv.len()).collect();
        let inputs = super::terms::Inputs {
            ops: &ops,
            time: &rv.time_s,
            temp: &rv.temp_c,
            order: &order,
        };
        for (&t, x) in self.spec.terms.iter().zip(&self.term_x) {
            points.terms[t].add(&self.model, &inputs, x, &mut out);
        }
        out
    }
}

/// The terms' current at every point (zeros without terms), A.
fn term_sum(
    points: &TestPoints,
    model: &CurrentModel,
    terms: &[usize],
    term_x: &[Vec<f64>],
) -> Vec<f64> {
    let mut out = vec![0.0; points.len()];
    if terms.is_empty() {
        return out;
    }
    let inputs = points.inputs();
    for (&t, x) in terms.iter().zip(term_x) {
        points.terms[t].add(model, &inputs, x, &mut out);
    }
    out
}

/// The mean current of `model` with `terms` at `term_x` at every point, A.
pub fn predict(
    points: &TestPoints,
    model: &CurrentModel,
    terms: &[usize],
    term_x: &[Vec<f64>],
) -> Vec<f64> {
    let ev = model.evaluator();
    let mut out = term_sum(points, model, terms, term_x);
    for (o, op) in out.iter_mut().zip(&points.ops) {
        *o += ev.current(op);
    }
    out
}

/// The value a fit's unknowns take, and how to put them back.
#[derive(Debug, Clone)]
struct State {
    model: CurrentModel,
    term_x: Vec<Vec<f64>>,
}

impl State {
    fn theta(&self, free: &[Param]) -> Vec<f64> {
        let p = self.model.params();
        free.iter()
            .map(|q| p[q.index()])
            .chain(self.term_x.iter().flatten().copied())
            .collect()
    }

    fn set(&mut self, free: &[Param], theta: &[f64]) {
        let mut p = self.model.params();
        for (q, v) in free.iter().zip(theta) {
            p[q.index()] = *v;
        }
        self.model.set_params(&p);
        let mut k = free.len();
        for x in &mut self.term_x {
            for v in x.iter_mut() {
                *v = theta[k];
                k += 1;
            }
        }
    }
}

/// Bounds of the unknowns: the free parameters', then the terms' coordinates'.
fn bounds_of(points: &TestPoints, free: &[Param], terms: &[usize]) -> Vec<(f64, f64)> {
    free.iter()
        .map(|&q| library::bounds(q))
        .chain(
            terms
                .iter()
                .flat_map(|&t| points.terms[t].params.iter().map(|p| p.fit_bounds())),
        )
        .collect()
}

/// Mean current at every point of `subset` and its derivatives with respect to the free
/// parameters then the terms' coordinates (row-major, `subset.len()` x unknowns).
fn mean_jacobian(
    points: &TestPoints,
    subset: &[usize],
    state: &State,
    free: &[Param],
    terms: &[usize],
    bounds: &[(f64, f64)],
) -> (Vec<f64>, Vec<f64>) {
    let p = free.len();
    let q = bounds.len();
    let mut f = Vec::with_capacity(subset.len());
    let mut jac = vec![0.0; subset.len() * q];
    let mut grad = [0.0; PARAM_COUNT];
    let ev = state.model.evaluator();
    for (r, &k) in subset.iter().enumerate() {
        f.push(ev.current_and_gradient(&points.ops[k], &mut grad));
        for i in 0..p {
            jac[r * q + i] = grad[free[i].index()];
        }
    }
    if terms.is_empty() {
        return (f, jac);
    }
    // The model's quantities once for the terms' own coordinates (the model stays); each
    // term's part apart, so a coordinate's column moves only its term.
    let inputs = points.inputs();
    let needs = terms
        .iter()
        .fold(Needs::default(), |n, &t| n.or(points.terms[t].needs()));
    let at = ModelAt::new(&state.model, &points.ops, needs);
    let parts: Vec<Vec<f64>> = terms
        .iter()
        .zip(&state.term_x)
        .map(|(&t, x)| {
            let mut out = vec![0.0; points.len()];
            points.terms[t].add_at(&at, &inputs, x, &mut out);
            out
        })
        .collect();
    let mut base = vec![0.0; points.len()];
    for part in &parts {
        for (b, v) in base.iter_mut().zip(part) {
            *b += v;
        }
    }
    for (r, &k) in subset.iter().enumerate() {
        f[r] += base[k];
    }
    let theta = state.theta(free);
    // Which term and coordinate each unknown after the free parameters is.
    let coords: Vec<(usize, usize)> = state
        .term_x
        .iter()
        .enumerate()
        .flat_map(|(j, x)| (0..x.len()).map(move |c| (j, c)))
        .collect();
    for i in 0..q {
        let h = DIFF_STEP * (bounds[i].1 - bounds[i].0).max(1e-12);
        if i < p {
            let mut shifted = theta.clone();
            shifted[i] += h;
            let mut s = state.clone();
            s.set(free, &shifted);
            let moved = term_sum(points, &s.model, terms, &s.term_x);
            for (r, &k) in subset.iter().enumerate() {
                jac[r * q + i] += (moved[k] - base[k]) / h;
            }
        } else {
            let (j, c) = coords[i - p];
            let mut x = state.term_x[j].clone();
            x[c] += h;
            let mut moved = vec![0.0; points.len()];
            points.terms[terms[j]].add_at(&at, &inputs, &x, &mut moved);
            for (r, &k) in subset.iter().enumerate() {
                jac[r * q + i] += (moved[k] - parts[j][k]) / h;
            }
        }
    }
    (f, jac)
}

/// Fits `spec` to the points `subset` of `points`, starting from `start` (the terms at their
/// first starts).
pub fn fit(points: &TestPoints, subset: &[usize], spec: &ModelSpec, start: &CurrentModel) -> Fit {
    let starts: Vec<Vec<f64>> = spec
        .terms
        .iter()
        .map(|&t| points.terms[t].start_point())
        .collect();
    fit_from(points, subset, spec, start, &starts)
}

/// Fits `spec` to the points `subset` of `points`, starting from `start` and the terms'
/// coordinates `start_terms`.
pub fn fit_from(
    points: &TestPoints,
    subset: &[usize],
    spec: &ModelSpec,
    start: &CurrentModel,
    start_terms: &[Vec<f64>],
) -> Fit {
    fit_capped(points, subset, spec, start, start_terms, MAX_ITERATIONS)
}

/// [`fit_from`] with at most `max_iterations` Levenberg-Marquardt iterations per round (a
/// quick look at where a start leads).
pub fn fit_capped(
    points: &TestPoints,
    subset: &[usize],
    spec: &ModelSpec,
    start: &CurrentModel,
    start_terms: &[Vec<f64>],
    max_iterations: usize,
) -> Fit {
    let mut model = *start;
    // Effects not in the spec are switched off; those in it keep their start values.
    for e in Effect::ALL {
        if !spec.has(e) {
            library::clear_params(e, &mut model.effects);
        }
    }
    let free = spec.free_params();
    let bounds = bounds_of(points, &free, &spec.terms);
    let mut state = State {
        model,
        term_x: start_terms.to_vec(),
    };
    let ripple = spec.has(Effect::MeshLoadSharingRipple);
    let counts: Vec<f64> = subset.iter().map(|&k| points.weight[k]).collect();
    let n = counts.iter().sum::<f64>();
    let within: f64 = subset.iter().map(|&k| points.within_ss[k]).sum();
    let mut result = levenberg_marquardt(
        points,
        subset,
        &points.weight,
        &mut state,
        &free,
        &spec.terms,
        &bounds,
        max_iterations,
    );
    let residuals_of = |state: &State| -> (Vec<f64>, Vec<f64>) {
        let all = predict(points, &state.model, &spec.terms, &state.term_x);
        let ev = state.model.evaluator();
        subset
            .iter()
            .map(|&k| {
                (
                    points.current[k] - all[k],
                    ev.friction_current(&points.ops[k]),
                )
            })
            .unzip()
    };
    if ripple {
        for _ in 0..RIPPLE_ROUNDS {
            let (e, fric) = residuals_of(&state);
            let sse = point_sse(points, subset, &e);
            let rho = ripple_profile(&sse, &counts, &fric).0;
            let w: Vec<f64> = {
                let mut w = points.weight.clone();
                for (j, &k) in subset.iter().enumerate() {
                    w[k] /= 1.0 + rho * fric[j] * fric[j];
                }
                w
            };
            result = levenberg_marquardt(
                points,
                subset,
                &w,
                &mut state,
                &free,
                &spec.terms,
                &bounds,
                max_iterations,
            );
        }
    }
    let (residuals, fric) = residuals_of(&state);
    let mut model = state.model;
    let point_sse = point_sse(points, subset, &residuals);
    let sse: f64 = point_sse.iter().sum();
    let (sigma0, loglik_current) = if ripple {
        let (rho, s2) = ripple_profile(&point_sse, &counts, &fric);
        let floored = s2.max(SIGMA_FLOOR_A * SIGMA_FLOOR_A);
        let ll = -0.5
            * (n * (2.0 * std::f64::consts::PI * floored).ln()
                + fric
                    .iter()
                    .zip(&counts)
                    .map(|(f, c)| c * (1.0 + rho * f * f).ln())
                    .sum::<f64>()
                + n * s2 / floored);
        model.effects.mesh_ripple_rms = (rho * s2).sqrt();
        (floored.sqrt(), ll)
    } else {
        let s2 = (sse / n).max(1e-300);
        let floored = s2.max(SIGMA_FLOOR_A * SIGMA_FLOOR_A);
        let ll = -0.5 * n * ((2.0 * std::f64::consts::PI * floored).ln() + s2 / floored);
        (floored.sqrt(), ll)
    };

    // The backdrive observations.
    let (hold_errors, loglik_hold) = if points.holds.is_empty() {
        (0, 0.0)
    } else if spec.has(Effect::LinearBushFriction) {
        let (hold, omega_b, errors) = fit_hold(&points.holds);
        model.effects.bush_hold_torque = hold;
        model.effects.bush_corner_speed = omega_b;
        (errors, hold_loglik(hold_rows(&points.holds), errors as f64))
    } else {
        let errors = held_rows(&points.holds);
        (errors, hold_loglik(hold_rows(&points.holds), errors as f64))
    };

    // Covariance of the unknowns off their bounds: s^2 (J^T W J)^-1.
    let theta = state.theta(&free);
    let p = theta.len();
    let mut cov = vec![f64::NAN; p * p];
    let dof = (n - p as f64).max(1.0);
    let s2 = (result.cost + within) / dof;
    let inner: Vec<usize> = (0..p)
        .filter(|&i| {
            let (lo, hi) = bounds[i];
            theta[i] > lo && theta[i] < hi && result.jtj[i * p + i] > 0.0
        })
        .collect();
    let q = inner.len();
    let sub: Vec<f64> = inner
        .iter()
        .flat_map(|&i| inner.iter().map(move |&j| (i, j)))
        .map(|(i, j)| result.jtj[i * p + j])
        .collect();
    if let Some(inv) = stats::invert_spd(&sub, q) {
        for (a, &i) in inner.iter().enumerate() {
            for (b, &j) in inner.iter().enumerate() {
                cov[i * p + j] = s2 * inv[a * q + b];
            }
        }
    }

    let k = spec.parameter_count(&points.terms);
    let shapes: usize = spec
        .terms
        .iter()
        .map(|&t| points.terms[t].shape_count())
        .sum();
    let loglik = loglik_current + loglik_hold;
    Fit {
        spec: spec.clone(),
        model,
        free,
        term_x: state.term_x,
        residuals,
        sse,
        sigma0,
        loglik_current,
        loglik_hold,
        hold_errors,
        n: n.round() as usize,
        k,
        shapes,
        bic: -2.0 * loglik + spec.penalty(&points.terms, n),
        cov,
        converged: result.converged,
    }
}

/// Log-likelihood of `total` backdrive observations of which `errors` are mispredicted.
pub fn hold_loglik(total: f64, errors: f64) -> f64 {
    errors * HOLD_LABEL_ERROR.ln() + (total - errors) * (1.0 - HOLD_LABEL_ERROR).ln()
}

/// Rows of the backdrive observations.
fn hold_rows(holds: &[HoldCheck]) -> f64 {
    holds.iter().map(|h| f64::from(h.count)).sum()
}

/// Squared residuals of the rows of each point of `subset` (mean residual `e`), A^2.
fn point_sse(points: &TestPoints, subset: &[usize], e: &[f64]) -> Vec<f64> {
    subset
        .iter()
        .zip(e)
        .map(|(&k, e)| points.weight[k] * e * e + points.within_ss[k])
        .collect()
}

/// Rows observed not to backdrive.
pub fn held_rows(holds: &[HoldCheck]) -> usize {
    holds
        .iter()
        .filter(|h| !h.backdriven)
        .map(|h| h.count as usize)
        .sum()
}

/// Maximum-likelihood ratio rho = (r / sigma0)^2 of the ripple variance
/// sigma^2 = sigma0^2 (1 + rho F^2), and sigma0^2 at it, from each point's squared row
/// residuals `sse`, row count `count` and friction current `fric`: the root of the profile
/// likelihood's slope by Newton's method, kept inside a bracket (bisection in
/// u = ln(1 + rho F_max^2) whenever a Newton step leaves it).
pub fn ripple_profile(sse: &[f64], count: &[f64], fric: &[f64]) -> (f64, f64) {
    let n: f64 = count.iter().sum();
    let f_max = fric.iter().fold(0.0f64, |m, f| m.max(f.abs())).max(1e-9);
    let sq: Vec<(f64, f64, f64)> = sse
        .iter()
        .zip(count)
        .zip(fric)
        .map(|((e2, c), f)| (*e2, *c, f * f))
        .collect();
    // Slope and curvature of n ln S(rho) + sum ln(1 + rho F^2), and S / n.
    let derivatives = |rho: f64| {
        let (mut s, mut t, mut u, mut w, mut x) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(e2, c, f2) in &sq {
            let iv = 1.0 / (1.0 + rho * f2);
            s += e2 * iv;
            t += e2 * f2 * iv * iv;
            u += c * f2 * iv;
            w += e2 * f2 * f2 * iv * iv * iv;
            x += c * f2 * f2 * iv * iv;
        }
        let s = s.max(1e-300);
        let slope = u - n * t / s;
        let curvature = 2.0 * n * w / s - n * t * t / (s * s) - x;
        (slope, curvature, s / n)
    };
    let rho_of = |u: f64| (u.exp() - 1.0) / (f_max * f_max);
    let (d0, _, s0) = derivatives(0.0);
    if d0 >= 0.0 {
        return (0.0, s0);
    }
    let (mut lo, mut hi) = (0.0f64, rho_of(12.0));
    let (d_hi, _, s_hi) = derivatives(hi);
    if d_hi < 0.0 {
        return (hi, s_hi);
    }
    let u_of = |rho: f64| (1.0 + rho * f_max * f_max).ln();
    let mut rho = rho_of(0.5 * u_of(hi));
    for _ in 0..100 {
        let (d, c, _) = derivatives(rho);
        if d < 0.0 {
            lo = rho;
        } else {
            hi = rho;
        }
        let newton = rho - d / c;
        let next = if c > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            rho_of(0.5 * (u_of(lo) + u_of(hi)))
        };
        let done = (next - rho).abs() <= 1e-10 * rho.max(1e-300) || u_of(hi) - u_of(lo) < 1e-12;
        rho = next;
        if done {
            break;
        }
    }
    (rho, derivatives(rho).2)
}

/// Threshold fit of the bush's hold: the load holds when |tau| (1 + w_n / w_b) <= hold.
/// Returns (hold N m, w_b rad/s, mispredicted rows), choosing among equally good thresholds
/// the one with the widest relative margin.
pub fn fit_hold(holds: &[HoldCheck]) -> (f64, f64, usize) {
    let held_total = held_rows(holds);
    let mut best = (0.0, 0.0, held_total, 0.0f64);
    // Corner speeds 3..3000 rad/s: at the top the hold hardly fades over the tested speeds.
    let corners: Vec<f64> = (0..=48)
        .map(|k| 3.0 * 10f64.powf(k as f64 * 3.0 / 48.0))
        .collect();
    for omega_b in corners {
        let mut r: Vec<(f64, bool, usize)> = holds
            .iter()
            .map(|h| {
                (
                    h.tau_rot.abs() * (1.0 + h.omega_n / omega_b),
                    h.backdriven,
                    h.count as usize,
                )
            })
            .collect();
        r.sort_by(|a, b| a.0.total_cmp(&b.0));
        // Threshold after position i: rows 0..=i held, the rest backdriven.
        let mut wrong_below = 0; // backdriven rows predicted held
        let mut held_above = held_total; // held rows predicted backdriven
        for i in 0..r.len() {
            if r[i].1 {
                wrong_below += r[i].2;
            } else {
                held_above -= r[i].2;
            }
            let errors = wrong_below + held_above;
            let next = r.get(i + 1).map(|x| x.0).unwrap_or(r[i].0 * 2.0);
            if next <= r[i].0 {
                continue; // no threshold fits between equal values
            }
            let margin = next / r[i].0.max(1e-12);
            // Fewer errors wins; among equals the widest margin, but never over "no hold".
            let better = errors < best.2 || (errors == best.2 && best.0 > 0.0 && margin > best.3);
            if better {
                let hold = (r[i].0.max(1e-9) * next).sqrt();
                best = (hold, omega_b, errors, margin);
            }
        }
    }
    (best.0, best.1, best.2)
}

/// Runs `f` over `items` on as many threads as the machine has cores (two on the project's
/// machines), in order.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(items.len())
        .max(1);
    if threads == 1 {
        return items.iter().map(&f).collect();
    }
    let chunk = items.len().div_ceil(threads);
    std::thread::scope(|s| {
        let handles: Vec<_> = items
            .chunks(chunk)
            .map(|part| s.spawn(|| part.iter().map(&f).collect::<Vec<R>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a fit thread does not panic"))
            .collect()
    })
}

/// Outcome of one Levenberg-Marquardt run.
struct LmResult {
    /// Weighted sum of squared residuals of the points at the end (their spread aside).
    cost: f64,
    /// J^T W J at the end (all unknowns).
    jtj: Vec<f64>,
    /// Whether the iteration converged.
    converged: bool,
}

/// Weighted cost, J^T W J and J^T W r at `state`.
fn normal_equations(
    points: &TestPoints,
    subset: &[usize],
    weights: &[f64],
    state: &State,
    free: &[Param],
    terms: &[usize],
    bounds: &[(f64, f64)],
) -> (f64, Vec<f64>, Vec<f64>) {
    let p = bounds.len();
    let (f, jac) = mean_jacobian(points, subset, state, free, terms, bounds);
    let mut a = vec![0.0; p * p];
    let mut g = vec![0.0; p];
    let mut cost = 0.0;
    for (row, &k) in subset.iter().enumerate() {
        let w = weights[k];
        let r = points.current[k] - f[row];
        cost += w * r * r;
        let j = &jac[row * p..(row + 1) * p];
        for i in 0..p {
            g[i] += w * j[i] * r;
        }
        for i in 0..p {
            let ji = w * j[i];
            for l in 0..=i {
                a[i * p + l] += ji * j[l];
            }
        }
    }
    for i in 0..p {
        for l in 0..i {
            a[l * p + i] = a[i * p + l];
        }
    }
    (cost, a, g)
}

/// Bounded Levenberg-Marquardt on the free parameters and the terms' coordinates of `state`
/// (updated in place), at most `max_iterations` iterations.
#[allow(clippy::too_many_arguments)] // normal_equations' pieces and the iteration cap
fn levenberg_marquardt(
    points: &TestPoints,
    subset: &[usize],
    weights: &[f64],
    state: &mut State,
    free: &[Param],
    terms: &[usize],
    bounds: &[(f64, f64)],
    max_iterations: usize,
) -> LmResult {
    let p = bounds.len();
    // Start inside the bounds.
    let mut theta = state.theta(free);
    for (v, &(lo, hi)) in theta.iter_mut().zip(bounds) {
        *v = v.clamp(lo, hi);
    }
    state.set(free, &theta);
    let (mut cost, mut a, mut g) =
        normal_equations(points, subset, weights, state, free, terms, bounds);
    let mut lambda = 1e-3;
    let mut converged = false;
    for _ in 0..max_iterations {
        let theta = state.theta(free);
        let mut accepted = false;
        let mut small_step = false;
        while lambda < 1e14 {
            let Some(step) = bounded_step(&a, &g, p, lambda, bounds, &theta) else {
                break;
            };
            let mut trial = theta.clone();
            let mut largest = 0.0f64;
            for i in 0..p {
                let (lo, hi) = bounds[i];
                trial[i] = (theta[i] + step[i]).clamp(lo, hi);
                largest = largest.max(step[i].abs() * a[i * p + i].sqrt());
            }
            let mut s = state.clone();
            s.set(free, &trial);
            // Cost and normal equations at the trial point in one pass.
            let (c, a_new, g_new) =
                normal_equations(points, subset, weights, &s, free, terms, bounds);
            let negligible = largest <= 1e-9 * cost.sqrt().max(1e-300);
            if c.is_finite() && c < cost {
                let gain = cost - c;
                *state = s;
                (cost, a, g) = (c, a_new, g_new);
                lambda = (lambda * 0.2).max(1e-12);
                accepted = true;
                small_step = gain <= 1e-10 * cost.max(1e-300) || negligible;
                break;
            }
            if negligible || (c.is_finite() && c - cost <= 1e-12 * cost) {
                // At the optimum: no step changes the fit beyond rounding.
                break;
            }
            lambda *= 10.0;
        }
        if !accepted || small_step {
            converged = true;
            break;
        }
    }
    LmResult {
        cost,
        jtj: a,
        converged,
    }
}

/// Scaled, damped Gauss-Newton step; unknowns on a bound that the step would push out of
/// the box are held. `None` when the system is singular.
fn bounded_step(
    a: &[f64],
    g: &[f64],
    p: usize,
    lambda: f64,
    bounds: &[(f64, f64)],
    theta: &[f64],
) -> Option<Vec<f64>> {
    let mut held = vec![false; p];
    for i in 0..p {
        if a[i * p + i] <= 0.0 {
            held[i] = true;
        }
        let (lo, hi) = bounds[i];
        let v = theta[i];
        if (v <= lo && g[i] < 0.0) || (v >= hi && g[i] > 0.0) {
            held[i] = true;
        }
    }
    for _ in 0..=p {
        let act: Vec<usize> = (0..p).filter(|&i| !held[i]).collect();
        let m = act.len();
        let mut step = vec![0.0; p];
        if m == 0 {
            return Some(step);
        }
        let d: Vec<f64> = act.iter().map(|&i| a[i * p + i].sqrt()).collect();
        let mut s = vec![0.0; m * m];
        let mut rhs = vec![0.0; m];
        for (x, &i) in act.iter().enumerate() {
            for (y, &j) in act.iter().enumerate() {
                s[x * m + y] = a[i * p + j] / (d[x] * d[y]);
            }
            s[x * m + x] += lambda;
            rhs[x] = g[i] / d[x];
        }
        let l = stats::cholesky(&s, m)?;
        let sol = stats::cholesky_solve(&l, m, &rhs);
        for (x, &i) in act.iter().enumerate() {
            step[i] = sol[x] / d[x];
        }
        // Hold any unknown the step pushes through its bound from the bound itself.
        let mut changed = false;
        for i in 0..p {
            let (lo, hi) = bounds[i];
            let v = theta[i];
            if !held[i] && ((v <= lo && step[i] < 0.0) || (v >= hi && step[i] > 0.0)) {
                held[i] = true;
                changed = true;
            }
        }
        if !changed {
            return Some(step);
        }
    }
    None
}

/// Held-out validation over blocks of test points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldOut {
    /// Root mean square of the held-out prediction errors, A.
    pub rmse: f64,
    /// Mean negative log predictive density of the held-out currents.
    pub nlpd: f64,
}

/// Refits `spec` with each fold held out (starting from `start` and the terms at
/// `start_terms`) and scores the predictions of the held-out points; `None` when the data
/// has too few blocks to hold any out.
pub fn held_out(
    points: &TestPoints,
    spec: &ModelSpec,
    start: &CurrentModel,
    start_terms: &[Vec<f64>],
) -> Option<HeldOut> {
    if points.folds == 0 {
        return None;
    }
    let folds: Vec<usize> = (0..points.folds).collect();
    let parts = par_map(&folds, |&f| {
        let (train, test) = points.split(f);
        if train.len() < 3 || test.is_empty() {
            return (0.0, 0.0, 0.0);
        }
        let fit = fit_from(points, &train, spec, start, start_terms);
        let ev = fit.model.evaluator();
        let all = fit.predict(points);
        let (mut sse, mut nlpd, mut count) = (0.0, 0.0, 0.0);
        for &k in &test {
            let op = &points.ops[k];
            let e = points.current[k] - all[k];
            let s = fit.sigma_with(&ev, op).max(1e-12);
            let (n, e2) = (
                points.weight[k],
                points.weight[k] * e * e + points.within_ss[k],
            );
            sse += e2;
            nlpd += n * 0.5 * (2.0 * std::f64::consts::PI * s * s).ln() + 0.5 * e2 / (s * s);
            count += n;
        }
        (sse, nlpd, count)
    });
    let (sse, nlpd, count) = parts
        .into_iter()
        .fold((0.0, 0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2));
    (count > 0.0).then(|| HeldOut {
        rmse: (sse / count).sqrt(),
        nlpd: nlpd / count,
    })
}

/// A direction of the score tests beyond a fit's own unknowns.
#[derive(Debug, Clone, PartialEq)]
pub enum Column {
    /// A mean parameter of the model.
    Param(Param),
    /// Coordinate `coord` of term `term` ([`TestPoints::terms`]) at the term's coordinates
    /// `at`.
    Term {
        /// The term.
        term: usize,
        /// Its coordinate.
        coord: usize,
        /// Where the derivative is taken.
        at: Vec<f64>,
    },
}

/// Score statistics of a fitted model over every point: the Gram matrix of the noise-whitened
/// derivative columns of its unknowns followed by `extra` columns, the scores (whitened
/// columns times whitened residuals), and the standardised score of a ripple variance (the
/// friction current's square against the squared residuals).
#[derive(Debug, Clone)]
pub struct Scores {
    /// (p + extra) x (p + extra) Gram matrix, row-major.
    pub gram: Vec<f64>,
    /// Scores, p + extra.
    pub score: Vec<f64>,
    /// The fit's own unknowns (the first columns).
    pub own: usize,
    /// Standardised score of a ripple variance at zero (about N(0, 1) without ripple).
    pub ripple_z: f64,
}

/// The derivative of term `term` at coordinates `at` (coordinate `coord`) under `model`, at
/// every point.
fn term_column(
    points: &TestPoints,
    model: &CurrentModel,
    term: usize,
    coord: usize,
    at: &[f64],
) -> Vec<f64> {
    let t = &points.terms[term];
    let (lo, hi) = t.params[coord].fit_bounds();
    let h = DIFF_STEP * (hi - lo).max(1e-12) * 10.0;
    let inputs = points.inputs();
    let mut base = vec![0.0; points.len()];
    t.add(model, &inputs, at, &mut base);
    let mut moved = vec![0.0; points.len()];
    let mut x = at.to_vec();
    x[coord] += h;
    t.add(model, &inputs, &x, &mut moved);
    moved.iter().zip(&base).map(|(m, b)| (m - b) / h).collect()
}

/// The [`Scores`] of `fit` with the `extra` columns.
pub fn scores(points: &TestPoints, fit: &Fit, extra: &[Column]) -> Scores {
    let (f, jac, own) = jacobian(points, fit);
    let mut grad = [0.0; PARAM_COUNT];
    let ev = fit.model.evaluator();
    let term_cols: Vec<Option<Vec<f64>>> = extra
        .iter()
        .map(|c| match c {
            Column::Term { term, coord, at } => {
                Some(term_column(points, &fit.model, *term, *coord, at))
            }
            Column::Param(_) => None,
        })
        .collect();
    let m = own + extra.len();
    let mut gram = vec![0.0; m * m];
    let mut score = vec![0.0; m];
    let mut j = vec![0.0; m];
    let (mut f2_sum, mut f4_sum, mut f2e2_sum) = (0.0, 0.0, 0.0);
    for k in 0..points.len() {
        let op = &points.ops[k];
        ev.current_and_gradient(op, &mut grad);
        let sigma = fit.sigma_with(&ev, op).max(1e-12);
        let w = 1.0 / sigma;
        let n = points.weight[k];
        let e = points.current[k] - f[k];
        let r = e * w;
        for x in 0..own {
            j[x] = w * jac[k * own + x];
        }
        for (x, c) in extra.iter().enumerate() {
            j[own + x] = w * match c {
                Column::Param(q) => grad[q.index()],
                Column::Term { .. } => term_cols[x].as_ref().expect("a term column")[k],
            };
        }
        for x in 0..m {
            score[x] += n * j[x] * r;
            let jx = n * j[x];
            for y in 0..=x {
                gram[x * m + y] += jx * j[y];
            }
        }
        let fr = ev.friction_current(op);
        let f2 = fr * fr;
        f2_sum += n * f2;
        f4_sum += n * f2 * f2;
        f2e2_sum += f2 * (n * e * e + points.within_ss[k]) * w * w;
    }
    for x in 0..m {
        for y in 0..x {
            gram[y * m + x] = gram[x * m + y];
        }
    }
    let n = points.rows_in(&points.all).max(1.0);
    let spread = 2.0 * (f4_sum - f2_sum * f2_sum / n);
    let ripple_z = if spread > 0.0 {
        // Whitened residuals average one in square at the ML fit, so the centred score is
        // sum F^2 (r^2 - 1).
        (f2e2_sum - f2_sum) / spread.sqrt()
    } else {
        0.0
    };
    Scores {
        gram,
        score,
        own,
        ripple_z,
    }
}

/// The derivatives of `fit`'s mean current at every point with respect to its unknowns (free
/// parameters, then terms' coordinates), row-major, and the fitted mean.
pub fn jacobian(points: &TestPoints, fit: &Fit) -> (Vec<f64>, Vec<f64>, usize) {
    let state = State {
        model: fit.model,
        term_x: fit.term_x.clone(),
    };
    let bounds = bounds_of(points, &fit.free, &fit.spec.terms);
    let (f, jac) = mean_jacobian(
        points,
        &points.all,
        &state,
        &fit.free,
        &fit.spec.terms,
        &bounds,
    );
    (f, jac, bounds.len())
}

/// Bounds of `fit`'s unknowns and their fitted values.
pub fn unknowns(points: &TestPoints, fit: &Fit) -> (Vec<f64>, Vec<(f64, f64)>) {
    let state = State {
        model: fit.model,
        term_x: fit.term_x.clone(),
    };
    (
        state.theta(&fit.free),
        bounds_of(points, &fit.free, &fit.spec.terms),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Dataset, MeasuredRow};
    use model::plant::NoiseSource;
    use model::{CamDrive, paper};

    fn paper_model() -> CurrentModel {
        let drive = CamDrive::paper(paper::RIG_GEARS);
        CurrentModel::paper(drive, paper::CALIBRATION, paper::MU_S)
    }

    fn sweep(truth: &CurrentModel, noise: f64, seed: u64) -> TestPoints {
        let mut rng = NoiseSource::new(seed);
        let mut rows = Vec::new();
        for rep in 0..5 {
            for hz in paper::VIBRATION_HZ {
                for l in 1..=10 {
                    let w = 2.0 * std::f64::consts::PI * hz;
                    let tau = paper::TAU_ROT_MIN_TESTED * l as f64;
                    let t = (rep * 30 + l) as f64 * 20.0;
                    let op = OperatingPoint::new(w, tau, t);
                    rows.push(MeasuredRow {
                        omega_n: w,
                        tau_rot: tau,
                        i_in: Some(truth.current(&op) + noise * rng.normal()),
                        t_s: Some(t),
                        ..Default::default()
                    });
                }
            }
        }
        TestPoints::new(&Dataset::from_rows("t", rows).unwrap(), 25.0, 5, &[], truth)
    }

    #[test]
    fn base_fit_recovers_mu() {
        let truth = paper_model();
        let pts = sweep(&truth, 0.02, 1);
        let mut start = truth;
        start.mu = 0.1;
        let f = fit(&pts, &pts.all, &ModelSpec::base(), &start);
        assert!(f.converged);
        assert!((f.model.mu - 0.271).abs() < 0.01, "{}", f.model.mu);
        assert!((f.rmse() - 0.02).abs() < 0.005, "{}", f.rmse());
        let se = f.std_error(Param::Mu).unwrap();
        assert!(se > 0.0 && se < 0.01, "{se}");
    }

    #[test]
    fn joint_fit_recovers_an_effect_and_beats_the_base_by_bic() {
        let mut truth = paper_model();
        truth.effects.axial_corner_speed = 25.0;
        let pts = sweep(&truth, 0.015, 2);
        let base = fit(&pts, &pts.all, &ModelSpec::base(), &paper_model());
        let spec = ModelSpec::base().with(Effect::SpeedDependentAxialFriction);
        let with = fit(&pts, &pts.all, &spec, &base.model);
        assert!(with.bic < base.bic - 20.0, "{} vs {}", with.bic, base.bic);
        assert!(
            (with.model.effects.axial_corner_speed - 25.0).abs() < 5.0,
            "{}",
            with.model.effects.axial_corner_speed
        );
        let ho_base = held_out(&pts, &ModelSpec::base(), &base.model, &[]).unwrap();
        let ho_with = held_out(&pts, &spec, &with.model, &[]).unwrap();
        assert!(ho_with.rmse < ho_base.rmse);
    }

    #[test]
    fn ripple_variance_is_profiled() {
        let e: Vec<f64> = (0..400)
            .map(|k| {
                let f = 0.1 + (k % 10) as f64 * 0.1;
                let z = if k % 2 == 0 { 1.0 } else { -1.0 };
                z * (0.02f64.powi(2) + (0.1 * f).powi(2)).sqrt()
            })
            .collect();
        let fric: Vec<f64> = (0..400).map(|k| 0.1 + (k % 10) as f64 * 0.1).collect();
        let e2: Vec<f64> = e.iter().map(|e| e * e).collect();
        let (rho, s2) = ripple_profile(&e2, &vec![1.0; e.len()], &fric);
        let r = (rho * s2).sqrt();
        assert!((r - 0.1).abs() < 0.01, "{r}");
        assert!((s2.sqrt() - 0.02).abs() < 0.003, "{}", s2.sqrt());
    }

    #[test]
    fn hold_threshold_separates_light_slow_points() {
        let mut holds = Vec::new();
        for hz in paper::VIBRATION_HZ {
            for l in 1..=10 {
                let w = 2.0 * std::f64::consts::PI * hz;
                let tau = paper::TAU_ROT_MIN_TESTED * l as f64;
                let held = tau <= 0.8 / (1.0 + w / 40.0);
                holds.push(HoldCheck {
                    omega_n: w,
                    tau_rot: tau,
                    backdriven: !held,
                    count: 1,
                    block: 0,
                });
            }
        }
        assert!(holds.iter().any(|h| !h.backdriven));
        let (hold, _wb, errors) = fit_hold(&holds);
        assert_eq!(errors, 0);
        assert!(hold > 0.368);
    }
}
