//! The solver: bounded Levenberg-Marquardt on the free parameters and the terms'
//! coordinates, normal equations solved by Cholesky on a few unknowns; the model's
//! derivatives analytic, the terms' by forward differences.

use model::effects::{CurrentModel, PARAM_COUNT, Param};

use super::term_sum;
use crate::library;
use crate::points::TestPoints;
use crate::stats;
use crate::terms::{ModelAt, Needs};

/// Forward-difference step of a coordinate, as a share of its bounds' width.
pub(super) const DIFF_STEP: f64 = 1e-7;

/// The value a fit's unknowns take, and how to put them back.
#[derive(Debug, Clone)]
pub(super) struct State {
    pub(super) model: CurrentModel,
    pub(super) term_x: Vec<Vec<f64>>,
}

impl State {
    pub(super) fn theta(&self, free: &[Param]) -> Vec<f64> {
        let p = self.model.params();
        free.iter()
            .map(|q| p[q.index()])
            .chain(self.term_x.iter().flatten().copied())
            .collect()
    }

    pub(super) fn set(&mut self, free: &[Param], theta: &[f64]) {
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
pub(super) fn bounds_of(points: &TestPoints, free: &[Param], terms: &[usize]) -> Vec<(f64, f64)> {
    free.iter()
        .map(|&q| library::bounds(q))
        .chain(
            terms
                .iter()
                .flat_map(|&t| points.terms[t].params.iter().map(|p| p.fit_bounds())),
        )
        .collect()
}

/// The mean current at the points of a subset with the model's analytic derivatives, and
/// the terms' parts: everything a trial point of the solver needs for its cost. The terms'
/// forward-difference columns ([`Evaluation::add_term_columns`]) are added only to a point
/// the solver moves to.
struct Evaluation {
    /// Mean current at each point of the subset, A.
    f: Vec<f64>,
    /// Derivatives, row-major (subset x unknowns): the model's, then (once added) the terms'.
    jac: Vec<f64>,
    /// The model's quantities the terms read (none without terms).
    at: Option<ModelAt>,
    /// Each term's current at every point, A.
    parts: Vec<Vec<f64>>,
    /// Their sum at every point, A.
    base: Vec<f64>,
}

impl Evaluation {
    /// The mean current of `state` at `subset` with the derivatives of the model's free
    /// parameters (the terms' columns left at zero).
    fn at(
        points: &TestPoints,
        subset: &[usize],
        state: &State,
        free: &[Param],
        terms: &[usize],
        unknowns: usize,
    ) -> Self {
        let p = free.len();
        let q = unknowns;
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
            return Self {
                f,
                jac,
                at: None,
                parts: Vec::new(),
                base: Vec::new(),
            };
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
        Self {
            f,
            jac,
            at: Some(at),
            parts,
            base,
        }
    }

    /// Adds the terms' derivatives by forward differences: of their parts in the model's
    /// free parameters, and in their own coordinates.
    fn add_term_columns(
        &mut self,
        points: &TestPoints,
        subset: &[usize],
        state: &State,
        free: &[Param],
        terms: &[usize],
        bounds: &[(f64, f64)],
    ) {
        let Some(at) = &self.at else {
            return;
        };
        let p = free.len();
        let q = bounds.len();
        let inputs = points.inputs();
        let theta = state.theta(free);
        // Which term and coordinate each unknown after the free parameters is.
        let coords: Vec<(usize, usize)> = state
            .term_x
            .iter()
            .enumerate()
            .flat_map(|(j, x)| (0..x.len()).map(move |c| (j, c)))
            .collect();
        let (jac, base, parts) = (&mut self.jac, &self.base, &self.parts);
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
                points.terms[terms[j]].add_at(at, &inputs, &x, &mut moved);
                for (r, &k) in subset.iter().enumerate() {
                    jac[r * q + i] += (moved[k] - parts[j][k]) / h;
                }
            }
        }
    }
}

/// Mean current at every point of `subset` and its derivatives with respect to the free
/// parameters then the terms' coordinates (row-major, `subset.len()` x unknowns).
pub(super) fn mean_jacobian(
    points: &TestPoints,
    subset: &[usize],
    state: &State,
    free: &[Param],
    terms: &[usize],
    bounds: &[(f64, f64)],
) -> (Vec<f64>, Vec<f64>) {
    let mut ev = Evaluation::at(points, subset, state, free, terms, bounds.len());
    ev.add_term_columns(points, subset, state, free, terms, bounds);
    (ev.f, ev.jac)
}

/// Outcome of one Levenberg-Marquardt run.
pub(super) struct LmResult {
    /// Weighted sum of squared residuals of the points at the end (their spread aside).
    pub(super) cost: f64,
    /// J^T W J at the end (all unknowns).
    pub(super) jtj: Vec<f64>,
    /// Whether the iteration converged.
    pub(super) converged: bool,
}

/// Weighted sum of squared residuals of the mean current `f` at the points of `subset`.
fn weighted_cost(points: &TestPoints, subset: &[usize], weights: &[f64], f: &[f64]) -> f64 {
    let mut cost = 0.0;
    for (row, &k) in subset.iter().enumerate() {
        let r = points.current[k] - f[row];
        cost += weights[k] * r * r;
    }
    cost
}

/// J^T W J and J^T W r of the mean current `f` and its derivatives `jac` (`p` unknowns).
fn normal_matrix(
    points: &TestPoints,
    subset: &[usize],
    weights: &[f64],
    f: &[f64],
    jac: &[f64],
    p: usize,
) -> (Vec<f64>, Vec<f64>) {
    let mut a = vec![0.0; p * p];
    let mut g = vec![0.0; p];
    for (row, &k) in subset.iter().enumerate() {
        let w = weights[k];
        let r = points.current[k] - f[row];
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
    (a, g)
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
    let (f, jac) = mean_jacobian(points, subset, state, free, terms, bounds);
    let cost = weighted_cost(points, subset, weights, &f);
    let (a, g) = normal_matrix(points, subset, weights, &f, &jac, bounds.len());
    (cost, a, g)
}

/// Bounded Levenberg-Marquardt on the free parameters and the terms' coordinates of `state`
/// (updated in place), at most `max_iterations` iterations.
#[allow(clippy::too_many_arguments)] // normal_equations' pieces and the iteration cap
pub(super) fn levenberg_marquardt(
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
            // The cost at the trial point first; the terms' difference columns and the normal
            // equations only when the solver moves there.
            let mut at_trial = Evaluation::at(points, subset, &s, free, terms, p);
            let c = weighted_cost(points, subset, weights, &at_trial.f);
            let negligible = largest <= 1e-9 * cost.sqrt().max(1e-300);
            if c.is_finite() && c < cost {
                let gain = cost - c;
                at_trial.add_term_columns(points, subset, &s, free, terms, bounds);
                let (a_new, g_new) =
                    normal_matrix(points, subset, weights, &at_trial.f, &at_trial.jac, p);
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
