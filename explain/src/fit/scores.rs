//! Score statistics of a fitted model: the Gram matrix and scores of its unknowns and of
//! further directions (a candidate's parameters), for the score tests of the selection.

use model::effects::{CurrentModel, PARAM_COUNT, Param};

use super::Fit;
use super::solver::{DIFF_STEP, State, bounds_of, mean_jacobian};
use crate::points::TestPoints;

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
