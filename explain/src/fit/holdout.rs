//! Held-out validation over blocks of test points, and the threads the fits run on.

use model::effects::CurrentModel;

use super::{ModelSpec, fit_from};
use crate::points::TestPoints;

/// Runs `f` over `items` on as many threads as the machine has cores (two on the project's
/// machines); results in the order of `items`. Each thread takes the next item as it
/// finishes one, so items of unequal cost (a family form's fit against a library effect's,
/// the folds of a hold-out) keep every core busy to the end.
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(items.len())
        .max(1);
    if threads == 1 {
        return items.iter().map(&f).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let worker = || {
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let Some(item) = items.get(k) else {
                return done;
            };
            done.push((k, f(item)));
        }
    };
    let mut out: Vec<(usize, R)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads).map(|_| s.spawn(worker)).collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a fit thread does not panic"))
            .collect()
    });
    out.sort_by_key(|(k, _)| *k);
    out.into_iter().map(|(_, r)| r).collect()
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
