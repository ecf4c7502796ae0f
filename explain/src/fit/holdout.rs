//! Held-out validation over blocks of test points.

use model::effects::CurrentModel;

use super::{ModelSpec, fit_from};
use crate::parallel::par_map;
use crate::points::TestPoints;

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
