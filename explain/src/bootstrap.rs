//! Confidence in the selection: a block bootstrap of the whole forward selection.
//!
//! The test points are cut into blocks of consecutive points in time order
//! ([`TestPoints::block`]: five or more points each, at most 32 blocks), so slow drifts and
//! correlated noise stay inside a block. A replicate draws as many blocks as there are, with
//! replacement, and reruns the forward selection on the resampled data: at each step every
//! candidate is refitted jointly with the replicate's current model, the best is added when
//! its BIC improvement clears the guard's critical value of that step (the same null
//! simulation as the real selection, [`select::explore`]), and the next step starts from it;
//! the held-out check is not repeated. Each refit is one bounded Gauss-Newton step from the
//! fit on all the data, computed from per-block sums of the normal equations, so a replicate
//! costs a few small matrix solves whatever the number of rows. Paths the real selection
//! did not take are explored (fitted on all the data) as replicates reach them.
//!
//! Out of it: how often each effect is selected (its inclusion probability), how often each
//! set of effects is, and for a named effect how often a competitor is selected without it
//! (the ambiguity judgement of [`crate::explain`]). The seed is fixed: a run repeats exactly.

use std::collections::BTreeMap;

use model::effects::{Effect, PARAM_COUNT};
use model::plant::NoiseSource;

use crate::fit::{self, Fit};
use crate::library;
use crate::points::TestPoints;
use crate::select::{self, Options, Selection};
use crate::stats;

/// Seed of the block draws, fixed so a run repeats exactly.
pub const BOOTSTRAP_SEED: u64 = 0xb007_5742_0000_0014;

/// The linearised log-likelihood of one fitted model, summed per bootstrap block.
#[derive(Debug, Clone)]
struct Lin {
    /// Free parameters.
    p: usize,
    /// Their fitted values and bounds.
    theta: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Per block: J^T W J (p x p), J^T W e, sum of W e^2 (rows, spread included), rows,
    /// sum of rows x ln(relative variance), backdrive errors and observations.
    a: Vec<Vec<f64>>,
    u: Vec<Vec<f64>>,
    c: Vec<f64>,
    n: Vec<f64>,
    log_var: Vec<f64>,
    hold_errors: Vec<f64>,
    hold_total: Vec<f64>,
    /// Parameters counted by the BIC.
    k: usize,
}

impl Lin {
    fn of(points: &TestPoints, fit: &Fit) -> Self {
        let blocks = points.blocks;
        let p = fit.free.len();
        let idx: Vec<usize> = fit.free.iter().map(|q| q.index()).collect();
        let params = fit.model.params();
        let theta: Vec<f64> = idx.iter().map(|&i| params[i]).collect();
        let (lo, hi): (Vec<f64>, Vec<f64>) = fit.free.iter().map(|&q| library::bounds(q)).unzip();
        let ev = fit.model.evaluator();
        let s2 = fit.sigma0 * fit.sigma0;
        let r = fit.model.effects.mesh_ripple_rms;
        let rho = if r > 0.0 && s2 > 0.0 { r * r / s2 } else { 0.0 };
        let mut lin = Lin {
            p,
            theta,
            lo,
            hi,
            a: vec![vec![0.0; p * p]; blocks],
            u: vec![vec![0.0; p]; blocks],
            c: vec![0.0; blocks],
            n: vec![0.0; blocks],
            log_var: vec![0.0; blocks],
            hold_errors: vec![0.0; blocks],
            hold_total: vec![0.0; blocks],
            k: fit.k,
        };
        let mut grad = [0.0; PARAM_COUNT];
        for k in 0..points.len() {
            let op = &points.ops[k];
            let f = ev.current_and_gradient(op, &mut grad);
            let e = points.current[k] - f;
            let v = if rho > 0.0 {
                let fr = ev.friction_current(op);
                1.0 + rho * fr * fr
            } else {
                1.0
            };
            let n = points.weight[k];
            let w = n / v;
            let b = points.block[k] as usize;
            let (a, u) = (&mut lin.a[b], &mut lin.u[b]);
            for i in 0..p {
                let gi = grad[idx[i]];
                u[i] += w * gi * e;
                for j in 0..=i {
                    a[i * p + j] += w * gi * grad[idx[j]];
                }
            }
            lin.c[b] += (n * e * e + points.within_ss[k]) / v;
            lin.n[b] += n;
            lin.log_var[b] += n * v.ln();
        }
        for a in &mut lin.a {
            for i in 0..p {
                for j in 0..i {
                    a[j * p + i] = a[i * p + j];
                }
            }
        }
        let bush = fit.spec.has(Effect::LinearBushFriction);
        let (hold, corner) = (
            fit.model.effects.bush_hold_torque,
            fit.model.effects.bush_corner_speed,
        );
        for h in &points.holds {
            let predicted_held =
                bush && corner > 0.0 && h.tau_rot.abs() * (1.0 + h.omega_n / corner) <= hold;
            let b = h.block as usize;
            let count = f64::from(h.count);
            lin.hold_total[b] += count;
            if predicted_held == h.backdriven {
                lin.hold_errors[b] += count;
            }
        }
        lin
    }

    /// BIC of the model refitted (one bounded Gauss-Newton step) to the data with block `b`
    /// counted `m[b]` times.
    fn bic(&self, m: &[f64]) -> f64 {
        let p = self.p;
        let mut a = vec![0.0; p * p];
        let mut u = vec![0.0; p];
        let (mut c, mut n, mut l, mut err, mut tot) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (b, &mb) in m.iter().enumerate() {
            if mb == 0.0 {
                continue;
            }
            for (x, y) in a.iter_mut().zip(&self.a[b]) {
                *x += mb * y;
            }
            for (x, y) in u.iter_mut().zip(&self.u[b]) {
                *x += mb * y;
            }
            c += mb * self.c[b];
            n += mb * self.n[b];
            l += mb * self.log_var[b];
            err += mb * self.hold_errors[b];
            tot += mb * self.hold_total[b];
        }
        if n < 2.0 {
            return f64::INFINITY;
        }
        let delta = bounded_step(&a, &u, p, &self.theta, &self.lo, &self.hi);
        let mut rss = c;
        for i in 0..p {
            rss -= 2.0 * u[i] * delta[i];
            for j in 0..p {
                rss += delta[i] * a[i * p + j] * delta[j];
            }
        }
        let rss = rss.max(1e-12 * c).max(1e-300);
        let ll = -0.5 * (n * (2.0 * std::f64::consts::PI * rss / n).ln() + n + l)
            + if tot > 0.0 {
                fit::hold_loglik(tot, err)
            } else {
                0.0
            };
        -2.0 * ll + self.k as f64 * n.ln()
    }
}

/// The minimiser of c - 2 u'd + d'A d with theta + d inside [lo, hi]: parameters the
/// unconstrained step pushes out of their box are held at the bound and the rest re-solved.
fn bounded_step(a: &[f64], u: &[f64], p: usize, theta: &[f64], lo: &[f64], hi: &[f64]) -> Vec<f64> {
    let mut delta = vec![0.0; p];
    let mut fixed = vec![false; p];
    for i in 0..p {
        if a[i * p + i] <= 0.0 {
            fixed[i] = true;
        }
    }
    for _ in 0..=p {
        let act: Vec<usize> = (0..p).filter(|&i| !fixed[i]).collect();
        let q = act.len();
        if q == 0 {
            break;
        }
        let mut s = vec![0.0; q * q];
        let mut rhs = vec![0.0; q];
        for (x, &i) in act.iter().enumerate() {
            rhs[x] = u[i];
            for j in (0..p).filter(|&j| fixed[j]) {
                rhs[x] -= a[i * p + j] * delta[j];
            }
            for (y, &j) in act.iter().enumerate() {
                s[x * q + y] = a[i * p + j];
            }
            s[x * q + x] *= 1.0 + 1e-10;
        }
        let Some(l) = stats::cholesky(&s, q) else {
            // Singular: no step for the free parameters.
            for &i in &act {
                delta[i] = 0.0;
            }
            break;
        };
        let sol = stats::cholesky_solve(&l, q, &rhs);
        let mut clamped = false;
        for (x, &i) in act.iter().enumerate() {
            let v = theta[i] + sol[x];
            if v < lo[i] {
                delta[i] = lo[i] - theta[i];
                fixed[i] = true;
                clamped = true;
            } else if v > hi[i] {
                delta[i] = hi[i] - theta[i];
                fixed[i] = true;
                clamped = true;
            } else {
                delta[i] = sol[x];
            }
        }
        if !clamped {
            break;
        }
    }
    delta
}

/// One step of the selection as the bootstrap sees it: the guard's critical value and the
/// fitted candidates.
#[derive(Debug, Clone)]
struct StepNode {
    critical: f64,
    children: Vec<Effect>,
}

/// What the bootstrap found.
#[derive(Debug, Clone)]
pub struct Bootstrap {
    /// Replicates drawn.
    pub replicates: usize,
    /// Blocks of consecutive test points.
    pub blocks: usize,
    /// Test points per block.
    pub block_length: usize,
    /// The seed of the draws.
    pub seed: u64,
    /// The effects each replicate selected (beyond the loaded ones), sorted.
    pub selected: Vec<Vec<Effect>>,
}

impl Bootstrap {
    /// Share of replicates that select `effect`.
    pub fn inclusion(&self, effect: Effect) -> f64 {
        self.share(|s| s.contains(&effect))
    }

    /// Share of replicates whose selection satisfies `pred`.
    pub fn share(&self, pred: impl Fn(&[Effect]) -> bool) -> f64 {
        if self.selected.is_empty() {
            return 0.0;
        }
        self.selected.iter().filter(|s| pred(s)).count() as f64 / self.selected.len() as f64
    }

    /// Share of replicates that select exactly `set` (any order).
    pub fn set_share(&self, set: &[Effect]) -> f64 {
        let mut want = set.to_vec();
        want.sort();
        self.share(|s| s == want.as_slice())
    }

    /// The distinct selections with their shares, most frequent first.
    pub fn sets(&self) -> Vec<(Vec<Effect>, f64)> {
        let mut counts: BTreeMap<&Vec<Effect>, usize> = BTreeMap::new();
        for s in &self.selected {
            *counts.entry(s).or_default() += 1;
        }
        let mut out: Vec<(Vec<Effect>, f64)> = counts
            .into_iter()
            .map(|(s, c)| (s.clone(), c as f64 / self.selected.len() as f64))
            .collect();
        out.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        out
    }
}

/// Block multiplicities of `replicates` draws over `blocks` blocks.
fn draws(replicates: usize, blocks: usize) -> Vec<Vec<f64>> {
    let mut rng = NoiseSource::new(BOOTSTRAP_SEED);
    (0..replicates)
        .map(|_| {
            let mut m = vec![0.0; blocks];
            for _ in 0..blocks {
                m[(rng.next_u64() % blocks as u64) as usize] += 1.0;
            }
            m
        })
        .collect()
}

/// Runs the block bootstrap of `selection` on `points`; `None` when `opts.replicates` is 0
/// or there are fewer than two blocks.
pub fn bootstrap(points: &TestPoints, selection: &Selection, opts: &Options) -> Option<Bootstrap> {
    if opts.replicates == 0 || points.blocks < 2 {
        return None;
    }
    let depth = opts
        .max_effects
        .saturating_sub(selection.start.spec.effects.len());
    // Fits and steps by path (the effects added, in order), seeded from the real selection.
    let mut fits: BTreeMap<Vec<Effect>, Fit> = BTreeMap::new();
    let mut steps: BTreeMap<Vec<Effect>, StepNode> = BTreeMap::new();
    let mut path = Vec::new();
    fits.insert(path.clone(), selection.start.clone());
    for step in &selection.steps {
        let mut children = Vec::new();
        for c in &step.candidates {
            if let Some(f) = &c.fit {
                let mut child = path.clone();
                child.push(c.effect);
                fits.insert(child, f.clone());
                children.push(c.effect);
            }
        }
        steps.insert(
            path.clone(),
            StepNode {
                critical: step.critical,
                children,
            },
        );
        match step.best() {
            Some(b) if step.accepted => path.push(b.effect),
            _ => break,
        }
    }
    let mut lins: BTreeMap<Vec<Effect>, Lin> = BTreeMap::new();
    let m = draws(opts.replicates, points.blocks);
    let mut paths: Vec<Vec<Effect>> = vec![Vec::new(); opts.replicates];
    let mut active = vec![true; opts.replicates];
    for _level in 0..depth {
        // Explore the paths the replicates reached that the real selection did not.
        let mut wanted: Vec<Vec<Effect>> = paths
            .iter()
            .zip(&active)
            .filter(|(p, a)| **a && !steps.contains_key(*p))
            .map(|(p, _)| p.clone())
            .collect();
        wanted.sort();
        wanted.dedup();
        let explored = fit::par_map(&wanted, |p| {
            let current = &fits[p];
            select::explore(points, current, opts).map(|ex| {
                let children: Vec<(Effect, Fit)> = ex
                    .candidates
                    .into_iter()
                    .filter_map(|c| c.fit.map(|f| (c.effect, f)))
                    .collect();
                (ex.critical, children)
            })
        });
        for (p, ex) in wanted.into_iter().zip(explored) {
            let node = match ex {
                Some((critical, children)) => {
                    let names = children.iter().map(|(e, _)| *e).collect();
                    for (e, f) in children {
                        let mut child = p.clone();
                        child.push(e);
                        fits.insert(child, f);
                    }
                    StepNode {
                        critical,
                        children: names,
                    }
                }
                None => StepNode {
                    critical: f64::INFINITY,
                    children: Vec::new(),
                },
            };
            steps.insert(p, node);
        }
        // Linearise every model the replicates compare at this level.
        let mut needed: Vec<Vec<Effect>> = Vec::new();
        for (p, _) in paths.iter().zip(&active).filter(|(_, a)| **a) {
            needed.push(p.clone());
            for &c in &steps[p].children {
                let mut child = p.clone();
                child.push(c);
                needed.push(child);
            }
        }
        needed.sort();
        needed.dedup();
        needed.retain(|p| !lins.contains_key(p));
        let made = fit::par_map(&needed, |p| Lin::of(points, &fits[p]));
        for (p, l) in needed.into_iter().zip(made) {
            lins.insert(p, l);
        }
        // One step of every active replicate.
        let moves = fit::par_map(&(0..opts.replicates).collect::<Vec<_>>(), |&r| {
            if !active[r] {
                return None;
            }
            let p = &paths[r];
            let node = &steps[p];
            let here = lins[p].bic(&m[r]);
            let mut best: Option<(Effect, f64)> = None;
            for &c in &node.children {
                let mut child = p.clone();
                child.push(c);
                let gain = here - lins[&child].bic(&m[r]);
                if best.is_none_or(|(_, g)| gain > g) {
                    best = Some((c, gain));
                }
            }
            best.filter(|&(_, g)| g > 0.0 && g > node.critical)
                .map(|(e, _)| e)
        });
        let mut any = false;
        for (r, mv) in moves.into_iter().enumerate() {
            match mv {
                Some(e) => {
                    paths[r].push(e);
                    any = true;
                }
                None => active[r] = false,
            }
        }
        if !any {
            break;
        }
    }
    let selected = paths
        .into_iter()
        .map(|mut p| {
            p.sort();
            p
        })
        .collect();
    Some(Bootstrap {
        replicates: opts.replicates,
        blocks: points.blocks,
        block_length: points.block_length,
        seed: BOOTSTRAP_SEED,
        selected,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounded_step_holds_parameters_at_their_bounds() {
        // Two parameters, the unconstrained step pushes the second below its bound 0.
        let a = [2.0, 0.5, 0.5, 1.0];
        let u = [1.0, -1.0];
        let d = bounded_step(&a, &u, 2, &[1.0, 0.0], &[0.0, 0.0], &[3.0, 3.0]);
        assert_eq!(d[1], 0.0);
        assert!((d[0] - 0.5).abs() < 1e-9, "{d:?}");
        let free = bounded_step(&a, &u, 2, &[1.0, 5.0], &[0.0, 0.0], &[3.0, 10.0]);
        // A d = u: d = (1/1.75) * [1*1 + 0.5, -1*2 - 0.5] / ... checked by substitution.
        let r0 = 2.0 * free[0] + 0.5 * free[1] - 1.0;
        let r1 = 0.5 * free[0] + 1.0 * free[1] + 1.0;
        assert!(r0.abs() < 1e-6 && r1.abs() < 1e-6, "{free:?}");
    }

    #[test]
    fn draws_resample_every_block_count() {
        let m = draws(50, 12);
        assert_eq!(m.len(), 50);
        assert!(m.iter().all(|r| r.iter().sum::<f64>() == 12.0));
        assert_eq!(draws(50, 12), m);
    }
}
