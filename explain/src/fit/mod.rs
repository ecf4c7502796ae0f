//! Fitting the current model to the test points: bounded Levenberg-Marquardt on the mean
//! parameters and the terms' coordinates (normal equations solved by Cholesky on a few
//! unknowns; the model's derivatives analytic, the terms' by forward differences), a profiled
//! variance parameter for the mesh ripple, a threshold fit for the linear bush's holding, the
//! Gaussian (and backdrive) likelihood with BIC, and blocked held-out validation.
//!
//! One module per concept: the model spec (`spec`: [`ModelSpec`]), the solver (`solver`),
//! the likelihood's other parts (`likelihood`), held-out validation (`holdout`:
//! [`held_out`]) and the score statistics (`scores`: [`scores()`]); this module fits a spec
//! and holds the fitted model.

mod holdout;
mod likelihood;
mod scores;
mod solver;
mod spec;

use model::effects::{CurrentEvaluator, CurrentModel, Effect, OperatingPoint, Param};

pub use holdout::{HeldOut, held_out};
pub use likelihood::{
    HOLD_LABEL_ERROR, SIGMA_FLOOR_A, fit_hold, held_rows, hold_loglik, ripple_profile,
};
pub use scores::{Column, Scores, jacobian, scores, unknowns};
pub use spec::ModelSpec;

use crate::library;
use crate::points::TestPoints;
use crate::stats;
use likelihood::{hold_rows, point_sse};
use solver::{State, bounds_of, levenberg_marquardt};

/// Iteration limit of the Levenberg-Marquardt loop.
const MAX_ITERATIONS: usize = 60;
/// Alternations between the mean and the ripple variance.
const RIPPLE_ROUNDS: usize = 3;

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
    /// The start of each of `spec`'s terms: this fit's coordinates where it carries the term,
    /// else the term's first start (a refit of a related model starts where this one ended).
    pub fn term_starts(&self, points: &TestPoints, spec: &ModelSpec) -> Vec<Vec<f64>> {
        spec.terms
            .iter()
            .map(|&t| {
                self.spec
                    .terms
                    .iter()
                    .position(|&x| x == t)
                    .map(|pos| self.term_x[pos].clone())
                    .unwrap_or_else(|| points.terms[t].start_point())
            })
            .collect()
    }

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

    /// Covariance of coordinates `a` and `b` of the `t`-th term of the spec (`None` when
    /// either sits on a bound).
    pub fn term_cov(&self, t: usize, a: usize, b: usize) -> Option<f64> {
        let p = self.unknowns();
        let offset = self.free.len() + self.term_x[..t].iter().map(Vec::len).sum::<usize>();
        let v = *self.cov.get((offset + a) * p + offset + b)?;
        v.is_finite().then_some(v)
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
pub(crate) fn term_sum(
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{Dataset, MeasuredRow};
    use crate::points::HoldCheck;
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
