//! Fitting the current model to the test points: bounded Levenberg-Marquardt on the mean
//! parameters (normal equations solved by Cholesky on a few unknowns), a profiled variance
//! parameter for the mesh ripple, a threshold fit for the linear bush's holding, the Gaussian
//! (and backdrive) likelihood with BIC, and blocked held-out validation.

use model::effects::{CurrentEvaluator, CurrentModel, Effect, OperatingPoint, PARAM_COUNT, Param};

use super::library;
use super::points::{HoldCheck, TestPoints};
use super::stats;

/// Assumed rate at which a backdrive observation is wrong (a slip, a misread), for the
/// likelihood of the `backdriven` column.
pub const HOLD_LABEL_ERROR: f64 = 0.01;
/// Iteration limit of the Levenberg-Marquardt loop.
const MAX_ITERATIONS: usize = 60;
/// Alternations between the mean and the ripple variance.
const RIPPLE_ROUNDS: usize = 3;

/// Which effects a model carries on top of the paper's.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelSpec {
    /// The effects, in the order they were added.
    pub effects: Vec<Effect>,
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

    /// Whether the model carries `effect`.
    pub fn has(&self, effect: Effect) -> bool {
        self.effects.contains(&effect)
    }

    /// Parameters of the mean current that are fitted: mu and one per effect.
    pub fn free_params(&self) -> Vec<Param> {
        let mut p = vec![Param::Mu];
        p.extend(self.effects.iter().filter_map(|e| e.mean_param()));
        p
    }

    /// Parameters counted by the information criterion (noise level included).
    pub fn parameter_count(&self) -> usize {
        2 + self
            .effects
            .iter()
            .map(|&e| library::parameter_count(e))
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
    /// The fitted mean parameters, in the order of `cov`.
    pub free: Vec<Param>,
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
    /// Bayesian information criterion, -2 ln L + k ln n.
    pub bic: f64,
    /// Covariance of the free parameters (row-major), NaN where a parameter sits on a bound.
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

    /// Standard error of a free parameter, if it is free and off its bounds.
    pub fn std_error(&self, param: Param) -> Option<f64> {
        let p = self.free.len();
        let i = self.free.iter().position(|&q| q == param)?;
        let v = self.cov[i * p + i];
        (v.is_finite() && v >= 0.0).then(|| v.sqrt())
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
}

/// Fits `spec` to the points `subset` of `points`, starting from `start`.
pub fn fit(points: &TestPoints, subset: &[usize], spec: &ModelSpec, start: &CurrentModel) -> Fit {
    let mut model = *start;
    // Effects not in the spec are switched off; those in it keep their start values.
    for e in Effect::ALL {
        if !spec.has(e) {
            library::clear_params(e, &mut model.effects);
        }
    }
    let free = spec.free_params();
    let ripple = spec.has(Effect::MeshLoadSharingRipple);
    let counts: Vec<f64> = subset.iter().map(|&k| points.weight[k]).collect();
    let n = counts.iter().sum::<f64>();
    let within: f64 = subset.iter().map(|&k| points.within_ss[k]).sum();
    let mut result = levenberg_marquardt(points, subset, &points.weight, &mut model, &free);
    if ripple {
        for _ in 0..RIPPLE_ROUNDS {
            let (e, fric) = residuals_and_friction(points, subset, &model);
            let sse = point_sse(points, subset, &e);
            let rho = ripple_profile(&sse, &counts, &fric).0;
            let w: Vec<f64> = {
                let mut w = points.weight.clone();
                for (j, &k) in subset.iter().enumerate() {
                    w[k] /= 1.0 + rho * fric[j] * fric[j];
                }
                w
            };
            result = levenberg_marquardt(points, subset, &w, &mut model, &free);
        }
    }
    let (residuals, fric) = if ripple {
        residuals_and_friction(points, subset, &model)
    } else {
        let ev = model.evaluator();
        let r = subset
            .iter()
            .map(|&k| points.current[k] - ev.current(&points.ops[k]))
            .collect();
        (r, Vec::new())
    };
    let point_sse = point_sse(points, subset, &residuals);
    let sse: f64 = point_sse.iter().sum();
    let (sigma0, loglik_current) = if ripple {
        let (rho, s2) = ripple_profile(&point_sse, &counts, &fric);
        let ll = -0.5
            * (n * (2.0 * std::f64::consts::PI * s2).ln()
                + fric
                    .iter()
                    .zip(&counts)
                    .map(|(f, c)| c * (1.0 + rho * f * f).ln())
                    .sum::<f64>()
                + n);
        model.effects.mesh_ripple_rms = (rho * s2).sqrt();
        (s2.sqrt(), ll)
    } else {
        let s2 = (sse / n).max(1e-300);
        let ll = -0.5 * n * ((2.0 * std::f64::consts::PI * s2).ln() + 1.0);
        (s2.sqrt(), ll)
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

    // Covariance of the parameters off their bounds: s^2 (J^T W J)^-1.
    let p = free.len();
    let mut cov = vec![f64::NAN; p * p];
    let dof = (n - p as f64).max(1.0);
    let s2 = (result.cost + within) / dof;
    let theta = model.params();
    let inner: Vec<usize> = (0..p)
        .filter(|&i| {
            let (lo, hi) = library::bounds(free[i]);
            let v = theta[free[i].index()];
            v > lo && v < hi && result.jtj[i * p + i] > 0.0
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

    let k = spec.parameter_count();
    let loglik = loglik_current + loglik_hold;
    Fit {
        spec: spec.clone(),
        model,
        free,
        residuals,
        sse,
        sigma0,
        loglik_current,
        loglik_hold,
        hold_errors,
        n: n.round() as usize,
        k,
        bic: -2.0 * loglik + k as f64 * n.ln(),
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

/// Residuals and friction currents of `subset` under `model`.
fn residuals_and_friction(
    points: &TestPoints,
    subset: &[usize],
    model: &CurrentModel,
) -> (Vec<f64>, Vec<f64>) {
    let ev = model.evaluator();
    subset
        .iter()
        .map(|&k| {
            let op = &points.ops[k];
            (points.current[k] - ev.current(op), ev.friction_current(op))
        })
        .unzip()
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
    /// J^T W J at the end (free parameters).
    jtj: Vec<f64>,
    /// Whether the iteration converged.
    converged: bool,
}

/// Weighted cost, J^T W J and J^T W r at `model`.
fn normal_equations(
    points: &TestPoints,
    subset: &[usize],
    weights: &[f64],
    model: &CurrentModel,
    free: &[Param],
) -> (f64, Vec<f64>, Vec<f64>) {
    let p = free.len();
    let idx: Vec<usize> = free.iter().map(|q| q.index()).collect();
    let mut a = vec![0.0; p * p];
    let mut g = vec![0.0; p];
    let mut cost = 0.0;
    let mut grad = [0.0; PARAM_COUNT];
    let mut j = [0.0; PARAM_COUNT];
    let ev = model.evaluator();
    for &k in subset {
        let f = ev.current_and_gradient(&points.ops[k], &mut grad);
        let w = weights[k];
        let r = points.current[k] - f;
        cost += w * r * r;
        for i in 0..p {
            j[i] = grad[idx[i]];
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

/// Bounded Levenberg-Marquardt on the parameters `free` of `model` (updated in place).
fn levenberg_marquardt(
    points: &TestPoints,
    subset: &[usize],
    weights: &[f64],
    model: &mut CurrentModel,
    free: &[Param],
) -> LmResult {
    let p = free.len();
    // Start inside the bounds.
    let mut theta = model.params();
    for &q in free {
        let (lo, hi) = library::bounds(q);
        theta[q.index()] = theta[q.index()].clamp(lo, hi);
    }
    model.set_params(&theta);
    let (mut cost, mut a, mut g) = normal_equations(points, subset, weights, model, free);
    let mut lambda = 1e-3;
    let mut converged = false;
    for _ in 0..MAX_ITERATIONS {
        let theta = model.params();
        let mut accepted = false;
        let mut small_step = false;
        while lambda < 1e14 {
            let Some(step) = bounded_step(&a, &g, p, lambda, free, &theta) else {
                break;
            };
            let mut trial = theta;
            let mut largest = 0.0f64;
            for (i, &q) in free.iter().enumerate() {
                let (lo, hi) = library::bounds(q);
                trial[q.index()] = (theta[q.index()] + step[i]).clamp(lo, hi);
                largest = largest.max(step[i].abs() * a[i * p + i].sqrt());
            }
            let mut m = *model;
            m.set_params(&trial);
            // Cost and normal equations at the trial point in one pass.
            let (c, a_new, g_new) = normal_equations(points, subset, weights, &m, free);
            let negligible = largest <= 1e-9 * cost.sqrt().max(1e-300);
            if c.is_finite() && c < cost {
                let gain = cost - c;
                *model = m;
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

/// Scaled, damped Gauss-Newton step; parameters on a bound that the step would push out of
/// the box are held. `None` when the system is singular.
fn bounded_step(
    a: &[f64],
    g: &[f64],
    p: usize,
    lambda: f64,
    free: &[Param],
    theta: &[f64; PARAM_COUNT],
) -> Option<Vec<f64>> {
    let mut held = vec![false; p];
    for (i, &q) in free.iter().enumerate() {
        if a[i * p + i] <= 0.0 {
            held[i] = true;
        }
        let (lo, hi) = library::bounds(q);
        let v = theta[q.index()];
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
        // Hold any parameter the step pushes through its bound from the bound itself.
        let mut changed = false;
        for (i, &q) in free.iter().enumerate() {
            let (lo, hi) = library::bounds(q);
            let v = theta[q.index()];
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

/// Refits `spec` with each fold held out (starting from `start`) and scores the predictions
/// of the held-out points; `None` when the data has too few blocks to hold any out.
pub fn held_out(points: &TestPoints, spec: &ModelSpec, start: &CurrentModel) -> Option<HeldOut> {
    if points.folds == 0 {
        return None;
    }
    let folds: Vec<usize> = (0..points.folds).collect();
    let parts = par_map(&folds, |&f| {
        let (train, test) = points.split(f);
        if train.len() < 3 || test.is_empty() {
            return (0.0, 0.0, 0.0);
        }
        let fit = fit(points, &train, spec, start);
        let ev = fit.model.evaluator();
        let (mut sse, mut nlpd, mut count) = (0.0, 0.0, 0.0);
        for &k in &test {
            let op = &points.ops[k];
            let e = points.current[k] - ev.current(op);
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

/// Score statistics of a fitted model over every point: the Gram matrix of the noise-whitened
/// derivative columns of its free parameters followed by `extra` parameters, the scores
/// (whitened columns times whitened residuals), and the standardised score of a ripple
/// variance (the friction current's square against the squared residuals).
#[derive(Debug, Clone)]
pub struct Scores {
    /// (p + extra) x (p + extra) Gram matrix, row-major.
    pub gram: Vec<f64>,
    /// Scores, p + extra.
    pub score: Vec<f64>,
    /// Standardised score of a ripple variance at zero (about N(0, 1) without ripple).
    pub ripple_z: f64,
}

/// The [`Scores`] of `fit` with the `extra` parameters.
pub fn scores(points: &TestPoints, fit: &Fit, extra: &[Param]) -> Scores {
    let cols: Vec<usize> = fit.free.iter().chain(extra).map(|q| q.index()).collect();
    let m = cols.len();
    let mut gram = vec![0.0; m * m];
    let mut score = vec![0.0; m];
    let mut grad = [0.0; PARAM_COUNT];
    let mut j = vec![0.0; m];
    let ev = fit.model.evaluator();
    let (mut f2_sum, mut f4_sum, mut f2e2_sum) = (0.0, 0.0, 0.0);
    for k in 0..points.len() {
        let op = &points.ops[k];
        let f = ev.current_and_gradient(op, &mut grad);
        let sigma = fit.sigma_with(&ev, op).max(1e-12);
        let w = 1.0 / sigma;
        let n = points.weight[k];
        let e = points.current[k] - f;
        let r = e * w;
        for (x, &c) in cols.iter().enumerate() {
            j[x] = w * grad[c];
            score[x] += n * j[x] * r;
        }
        for x in 0..m {
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
        ripple_z,
    }
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
        let ho_base = held_out(&pts, &ModelSpec::base(), &base.model).unwrap();
        let ho_with = held_out(&pts, &spec, &with.model).unwrap();
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
