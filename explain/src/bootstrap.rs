//! Confidence in the selection: a block bootstrap of the whole forward selection.
//!
//! The test points are cut into blocks of consecutive points in time order
//! ([`TestPoints::block`]: five or more points each, at most 32 blocks), so slow drifts and
//! correlated noise stay inside a block. A replicate draws as many blocks as there are, with
//! replacement, and reruns the forward selection on the resampled data: at each step every
//! candidate is refitted jointly with the replicate's current model, the best is added when
//! its BIC improvement clears the guard's critical value of that step (the same null
//! simulation as the real selection, [`select::explore`]) and it predicts the held-out folds
//! better, and the next step starts from it. Each refit is one bounded Gauss-Newton step
//! from the fit on all the data, computed from per-block and per-fold sums of the normal
//! equations, so a replicate costs a few small matrix solves whatever the number of rows.
//! Paths the real selection did not take are explored (fitted on all the data, with a quarter
//! of the null draws) when at least 2 % of the replicates reach them; replicates on rarer
//! paths stop there.
//!
//! Out of it: how often each effect is selected (its inclusion probability), how often each
//! set of effects is, and for a named effect how often a competitor is selected without it
//! (the ambiguity judgement of [`crate::explain`]). The seed is fixed: a run repeats exactly.

use std::collections::{BTreeMap, BTreeSet};

use model::effects::Effect;
use model::plant::NoiseSource;

use crate::fit::{self, Fit};
use crate::mechanism::Mechanism;
use crate::points::TestPoints;
use crate::select::{self, Options, Selection};
use crate::stats;

/// Seed of the block draws, fixed so a run repeats exactly.
pub const BOOTSTRAP_SEED: u64 = 0xb007_5742_0000_0014;
/// A path the real selection did not take is explored when at least this share of the
/// replicates reach it; replicates on rarer paths stop there.
const MIN_PATH_SHARE: f64 = 0.02;
/// Draws of the guard's null simulation on paths the real selection did not take, as a
/// share of `Options::null_draws`.
const ALT_NULL_SHARE: f64 = 0.25;

/// Sums of the linearised fit over the points of one cell (a bootstrap block and a held-out
/// fold): J^T W J (p x p), J^T W e, sum of W e^2 over the rows (spread included), rows, and
/// rows x ln(relative noise variance).
#[derive(Debug, Clone)]
struct Sums {
    a: Vec<f64>,
    u: Vec<f64>,
    c: f64,
    n: f64,
    log_var: f64,
}

impl Sums {
    fn zero(p: usize) -> Self {
        Self {
            a: vec![0.0; p * p],
            u: vec![0.0; p],
            c: 0.0,
            n: 0.0,
            log_var: 0.0,
        }
    }

    fn add(&mut self, other: &Sums, times: f64) {
        for (x, y) in self.a.iter_mut().zip(&other.a) {
            *x += times * y;
        }
        for (x, y) in self.u.iter_mut().zip(&other.u) {
            *x += times * y;
        }
        self.c += times * other.c;
        self.n += times * other.n;
        self.log_var += times * other.log_var;
    }

    /// Weighted residual sum of squares after the step `delta`.
    fn rss(&self, delta: &[f64]) -> f64 {
        let p = delta.len();
        let mut rss = self.c;
        for i in 0..p {
            rss -= 2.0 * self.u[i] * delta[i];
            for j in 0..p {
                rss += delta[i] * self.a[i * p + j] * delta[j];
            }
        }
        rss.max(1e-12 * self.c).max(1e-300)
    }
}

/// A replicate's scores of one model: its BIC and its held-out RMSE and log score.
#[derive(Debug, Clone, Copy)]
struct Score {
    bic: f64,
    held_out: Option<fit::HeldOut>,
}

/// The linearised log-likelihood of one fitted model, summed per bootstrap block and
/// held-out fold.
#[derive(Debug, Clone)]
struct Lin {
    /// Free parameters.
    p: usize,
    /// Their fitted values and bounds.
    theta: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    /// Folds (at least one).
    folds: usize,
    /// Sums per block and fold, `cells[block * folds + fold]`.
    cells: Vec<Sums>,
    /// Backdrive errors and observations per block.
    hold_errors: Vec<f64>,
    hold_total: Vec<f64>,
    /// Parameters counted by the BIC, and the shapes among them.
    k: usize,
    shapes: usize,
}

impl Lin {
    fn of(points: &TestPoints, fit: &Fit) -> Self {
        let blocks = points.blocks;
        let folds = points.folds.max(1);
        let (theta, bounds) = fit::unknowns(points, fit);
        let (lo, hi): (Vec<f64>, Vec<f64>) = bounds.into_iter().unzip();
        let (mean, jac, p) = fit::jacobian(points, fit);
        let ev = fit.model.evaluator();
        let s2 = fit.sigma0 * fit.sigma0;
        let r = fit.model.effects.mesh_ripple_rms;
        let rho = if r > 0.0 && s2 > 0.0 { r * r / s2 } else { 0.0 };
        let mut lin = Lin {
            p,
            theta,
            lo,
            hi,
            folds,
            cells: vec![Sums::zero(p); blocks * folds],
            hold_errors: vec![0.0; blocks],
            hold_total: vec![0.0; blocks],
            k: fit.k,
            shapes: fit.shapes,
        };
        for k in 0..points.len() {
            let op = &points.ops[k];
            let grad = &jac[k * p..(k + 1) * p];
            let e = points.current[k] - mean[k];
            let v = if rho > 0.0 {
                let fr = ev.friction_current(op);
                1.0 + rho * fr * fr
            } else {
                1.0
            };
            let n = points.weight[k];
            let w = n / v;
            let fold = if points.folds == 0 { 0 } else { points.fold[k] };
            let cell = &mut lin.cells[points.block[k] as usize * folds + fold];
            for i in 0..p {
                let gi = grad[i];
                cell.u[i] += w * gi * e;
                for (j, gj) in grad.iter().enumerate().take(i + 1) {
                    cell.a[i * p + j] += w * gi * gj;
                }
            }
            cell.c += (n * e * e + points.within_ss[k]) / v;
            cell.n += n;
            cell.log_var += n * v.ln();
        }
        for cell in &mut lin.cells {
            for i in 0..p {
                for j in 0..i {
                    cell.a[j * p + i] = cell.a[i * p + j];
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

    /// The model refitted (one bounded Gauss-Newton step) to the data with block `b` counted
    /// `m[b]` times: its BIC and, with folds, its held-out scores (each fold predicted by the
    /// step fitted to the others).
    fn score(&self, m: &[f64]) -> Score {
        let (p, folds) = (self.p, self.folds);
        let mut per_fold = vec![Sums::zero(p); folds];
        let (mut err, mut tot) = (0.0, 0.0);
        for (b, &mb) in m.iter().enumerate() {
            if mb == 0.0 {
                continue;
            }
            for (f, sums) in per_fold.iter_mut().enumerate() {
                sums.add(&self.cells[b * folds + f], mb);
            }
            err += mb * self.hold_errors[b];
            tot += mb * self.hold_total[b];
        }
        let mut total = Sums::zero(p);
        for sums in &per_fold {
            total.add(sums, 1.0);
        }
        let n = total.n;
        if n < 2.0 {
            return Score {
                bic: f64::INFINITY,
                held_out: None,
            };
        }
        let delta = bounded_step(&total.a, &total.u, p, &self.theta, &self.lo, &self.hi);
        let rss = total.rss(&delta);
        // The same floor of the noise scale as the fit's likelihood ([`fit::SIGMA_FLOOR_A`]).
        let s2 = rss / n;
        let floored = s2.max(fit::SIGMA_FLOOR_A * fit::SIGMA_FLOOR_A);
        let ll = -0.5
            * (n * (2.0 * std::f64::consts::PI * floored).ln() + n * s2 / floored + total.log_var)
            + if tot > 0.0 {
                fit::hold_loglik(tot, err)
            } else {
                0.0
            };
        let bic = -2.0 * ll
            + (self.k - self.shapes) as f64 * n.ln()
            + self.shapes as f64 * crate::terms::SHAPE_PENALTY;
        let held_out = (folds > 1).then(|| {
            let (mut sse, mut nlpd, mut rows) = (0.0, 0.0, 0.0);
            for test in per_fold.iter().filter(|s| s.n > 0.0) {
                let mut train = total.clone();
                train.add(test, -1.0);
                if train.n < 3.0 {
                    continue;
                }
                let d = bounded_step(&train.a, &train.u, p, &self.theta, &self.lo, &self.hi);
                let s2 = train.rss(&d) / train.n;
                let e2 = test.rss(&d);
                // The test rows' squared residuals unscaled by their relative variance
                // enter the RMSE only approximately (the ripple's scale is held).
                sse += e2;
                nlpd += 0.5 * test.n * (2.0 * std::f64::consts::PI * s2).ln()
                    + 0.5 * test.log_var
                    + 0.5 * e2 / s2;
                rows += test.n;
            }
            fit::HeldOut {
                rmse: (sse / rows.max(1.0)).sqrt(),
                nlpd: nlpd / rows.max(1.0),
            }
        });
        Score { bic, held_out }
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
    children: Vec<Mechanism>,
    /// The pairs fitted jointly at this step (first, second), as in [`select::pair_fits`].
    pairs: Vec<(Mechanism, Mechanism)>,
}

/// Files a step's pair fits under their paths (`path` then the pair); returns the pairs.
fn insert_pairs(
    path: &[Mechanism],
    pairs: &[select::PairFit],
    fits: &mut BTreeMap<Vec<Mechanism>, Fit>,
    implausible: &mut BTreeSet<Vec<Mechanism>>,
) -> Vec<(Mechanism, Mechanism)> {
    let mut out = Vec::new();
    for pf in pairs {
        let key = [path, &[pf.first, pf.second]].concat();
        if !pf.plausible {
            implausible.insert(key.clone());
        }
        fits.entry(key).or_insert_with(|| pf.fit.clone());
        out.push((pf.first, pf.second));
    }
    out
}

/// Whether held-out points confirm adding `e` (scores `before` and `after`), by the
/// selection's rule: the log score for the mesh ripple, the RMSE within 1 % for the bush
/// (whose evidence is the backdrive observations), the RMSE otherwise.
fn confirms(e: Mechanism, before: Option<fit::HeldOut>, after: Option<fit::HeldOut>) -> bool {
    match (before, after) {
        (Some(b), Some(a)) if e == Mechanism::Effect(Effect::MeshLoadSharingRipple) => {
            a.nlpd < b.nlpd
        }
        (Some(b), Some(a)) if e == Mechanism::Effect(Effect::LinearBushFriction) => {
            a.rmse <= 1.01 * b.rmse
        }
        (Some(b), Some(a)) => a.rmse < b.rmse,
        _ => true,
    }
}

/// A replicate's pair step at `node` (path `p`), by the selection's rule
/// ([`select::choose_pair`]) on the replicate's scores, confirmed on held-out points as the
/// selection confirms it.
fn pair_move(
    p: &[Mechanism],
    node: &StepNode,
    here: &Score,
    lins: &BTreeMap<Vec<Mechanism>, Lin>,
    implausible: &BTreeSet<Vec<Mechanism>>,
    m: &[f64],
) -> Option<Vec<Mechanism>> {
    if node.pairs.is_empty() {
        return None;
    }
    let scored = |key: Vec<Mechanism>| {
        let s = lins.get(&key)?.score(m);
        let plausible = !implausible.contains(&key);
        Some((s, plausible))
    };
    let singles: Vec<(Mechanism, select::Scored)> = node
        .children
        .iter()
        .filter_map(|&c| {
            let (s, plausible) = scored([p, &[c]].concat())?;
            Some((
                c,
                select::Scored {
                    bic: s.bic,
                    plausible,
                },
            ))
        })
        .collect();
    let mut held = Vec::new();
    let pairs: Vec<(Mechanism, Mechanism, select::Scored)> = node
        .pairs
        .iter()
        .filter_map(|&(a, b)| {
            let (s, plausible) = scored([p, &[a, b]].concat())?;
            held.push(s.held_out);
            Some((
                a,
                b,
                select::Scored {
                    bic: s.bic,
                    plausible,
                },
            ))
        })
        .collect();
    let k = select::choose_pair(here.bic, &singles, &pairs, node.critical)?;
    // As the selection's steps: the first confirmed over the model before, the second over
    // the first, and the pair over the model before.
    let (first, second, _) = pairs[k];
    let first_held = scored([p, &[first]].concat()).and_then(|(s, _)| s.held_out);
    let confirmed = confirms(first, here.held_out, first_held)
        && confirms(second, first_held, held[k])
        && confirms(second, here.held_out, held[k]);
    confirmed.then(|| vec![pairs[k].0, pairs[k].1])
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
    pub selected: Vec<Vec<Mechanism>>,
}

impl Bootstrap {
    /// Share of replicates that select `cand`.
    pub fn inclusion(&self, cand: Mechanism) -> f64 {
        self.share(|s| s.contains(&cand))
    }

    /// Share of replicates whose selection satisfies `pred`.
    pub fn share(&self, pred: impl Fn(&[Mechanism]) -> bool) -> f64 {
        if self.selected.is_empty() {
            return 0.0;
        }
        self.selected.iter().filter(|s| pred(s)).count() as f64 / self.selected.len() as f64
    }

    /// Share of replicates that select exactly `set` (any order).
    pub fn set_share(&self, set: &[Mechanism]) -> f64 {
        let mut want = set.to_vec();
        want.sort();
        self.share(|s| s == want.as_slice())
    }

    /// The distinct selections with their shares, most frequent first.
    pub fn sets(&self) -> Vec<(Vec<Mechanism>, f64)> {
        let mut counts: BTreeMap<&Vec<Mechanism>, usize> = BTreeMap::new();
        for s in &self.selected {
            *counts.entry(s).or_default() += 1;
        }
        let mut out: Vec<(Vec<Mechanism>, f64)> = counts
            .into_iter()
            .map(|(s, c)| (s.clone(), c as f64 / self.selected.len() as f64))
            .collect();
        out.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        out
    }
}

/// Block multiplicities of resamples with replacement over `blocks` blocks: each item is
/// one resample (how often each block was drawn, `blocks` draws in all), from the seeded
/// stream `seed`, so a run repeats exactly. The bootstrap of the selection and that of the
/// residual's shape ([`crate::residual_shape`]) both draw so.
pub fn block_draws(seed: u64, blocks: usize) -> impl Iterator<Item = Vec<f64>> {
    let mut rng = NoiseSource::new(seed);
    std::iter::repeat_with(move || {
        let mut m = vec![0.0; blocks];
        for _ in 0..blocks {
            m[(rng.next_u64() % blocks as u64) as usize] += 1.0;
        }
        m
    })
}

/// Block multiplicities of `replicates` draws over `blocks` blocks.
fn draws(replicates: usize, blocks: usize) -> Vec<Vec<f64>> {
    block_draws(BOOTSTRAP_SEED, blocks)
        .take(replicates)
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
    let mut fits: BTreeMap<Vec<Mechanism>, Fit> = BTreeMap::new();
    // Paths whose last effect's full-data fit breaks a physical limit: as in the selection,
    // a replicate that reaches one names nothing more.
    let mut implausible: BTreeSet<Vec<Mechanism>> = BTreeSet::new();
    // Of those, the paths whose last shape sits on the edge of its search: no partner makes
    // them plausible (as in the selection), so a replicate that reaches one stops.
    let mut dead_ends: BTreeSet<Vec<Mechanism>> = BTreeSet::new();
    let mut steps: BTreeMap<Vec<Mechanism>, StepNode> = BTreeMap::new();
    let mut path = Vec::new();
    fits.insert(path.clone(), selection.start.clone());
    for step in &selection.steps {
        let mut children = Vec::new();
        for c in &step.candidates {
            if let Some(f) = &c.fit {
                let mut child = path.clone();
                child.push(c.cand);
                let plausibility = crate::plausibility::check_model(points, f);
                if !plausibility.plausible {
                    implausible.insert(child.clone());
                }
                if !plausibility.only_physical_limits_broken() {
                    dead_ends.insert(child.clone());
                }
                fits.insert(child, f.clone());
                children.push(c.cand);
            }
        }
        let pairs = insert_pairs(&path, &step.pairs, &mut fits, &mut implausible);
        steps.insert(
            path.clone(),
            StepNode {
                critical: step.critical,
                children,
                pairs,
            },
        );
        match step.best() {
            Some(b) if step.accepted => path.push(b.cand),
            _ => break,
        }
    }
    let mut lins: BTreeMap<Vec<Mechanism>, Lin> = BTreeMap::new();
    let m = draws(opts.replicates, points.blocks);
    let mut paths: Vec<Vec<Mechanism>> = vec![Vec::new(); opts.replicates];
    let mut active = vec![true; opts.replicates];
    // Replicates whose last effect is implausible alone (kept only if the next one makes
    // the pair plausible).
    let mut provisional = vec![false; opts.replicates];
    for _level in 0..depth {
        // Explore the paths the replicates reached that the real selection did not.
        let mut reached: BTreeMap<&Vec<Mechanism>, usize> = BTreeMap::new();
        for (p, _) in paths
            .iter()
            .zip(&active)
            .filter(|(p, a)| **a && !steps.contains_key(*p))
        {
            *reached.entry(p).or_default() += 1;
        }
        let min_count = (MIN_PATH_SHARE * opts.replicates as f64).ceil() as usize;
        let wanted: Vec<Vec<Mechanism>> = reached
            .iter()
            .filter(|&(_, &c)| c >= min_count)
            .map(|(p, _)| (*p).clone())
            .collect();
        let rare: Vec<Vec<Mechanism>> = reached
            .iter()
            .filter(|&(_, &c)| c < min_count)
            .map(|(p, _)| (*p).clone())
            .collect();
        let alt_opts = Options {
            null_draws: ((opts.null_draws as f64 * ALT_NULL_SHARE) as usize).max(1000),
            ..*opts
        };
        let explored = crate::parallel::par_map(&wanted, |p| {
            let current = &fits[p];
            select::explore(points, current, &alt_opts).map(|ex| {
                // Pairs where the best candidate clears the guard, as in the selection.
                let pairs = if p.len() + 2 <= depth
                    && ex
                        .candidates
                        .first()
                        .is_some_and(|c| c.improvement > ex.critical)
                {
                    select::pair_fits(points, &ex.candidates)
                } else {
                    Vec::new()
                };
                let children: Vec<(Mechanism, Fit)> = ex
                    .candidates
                    .into_iter()
                    .filter_map(|c| c.fit.map(|f| (c.cand, f)))
                    .collect();
                (ex.critical, children, pairs)
            })
        });
        for (p, ex) in wanted.into_iter().zip(explored) {
            let node = match ex {
                Some((critical, children, pair_fits)) => {
                    let pairs = insert_pairs(&p, &pair_fits, &mut fits, &mut implausible);
                    let names = children.iter().map(|(e, _)| *e).collect();
                    for (e, f) in children {
                        let mut child = p.clone();
                        child.push(e);
                        let plausibility = crate::plausibility::check_model(points, &f);
                        if !plausibility.plausible {
                            implausible.insert(child.clone());
                        }
                        if !plausibility.only_physical_limits_broken() {
                            dead_ends.insert(child.clone());
                        }
                        fits.insert(child, f);
                    }
                    StepNode {
                        critical,
                        children: names,
                        pairs,
                    }
                }
                None => StepNode {
                    critical: f64::INFINITY,
                    children: Vec::new(),
                    pairs: Vec::new(),
                },
            };
            steps.insert(p, node);
        }
        for p in rare {
            steps.insert(
                p,
                StepNode {
                    critical: f64::INFINITY,
                    children: Vec::new(),
                    pairs: Vec::new(),
                },
            );
        }
        // Linearise every model the replicates compare at this level.
        let mut needed: Vec<Vec<Mechanism>> = Vec::new();
        for (p, _) in paths.iter().zip(&active).filter(|(_, a)| **a) {
            needed.push(p.clone());
            for &c in &steps[p].children {
                let mut child = p.clone();
                child.push(c);
                needed.push(child);
            }
            for &(a, b) in &steps[p].pairs {
                needed.push([p.as_slice(), &[a, b]].concat());
            }
        }
        needed.sort();
        needed.dedup();
        needed.retain(|p| !lins.contains_key(p));
        let made = crate::parallel::par_map(&needed, |p| Lin::of(points, &fits[p]));
        for (p, l) in needed.into_iter().zip(made) {
            lins.insert(p, l);
        }
        // One step of every active replicate.
        let moves = crate::parallel::par_map(&(0..opts.replicates).collect::<Vec<_>>(), |&r| {
            if !active[r] {
                return None;
            }
            let p = &paths[r];
            if p.len() >= depth {
                return None;
            }
            let node = &steps[p];
            let here = lins[p].score(&m[r]);
            if let Some(pair) = pair_move(p, node, &here, &lins, &implausible, &m[r]) {
                return Some((pair, false));
            }
            let mut best: Option<(Mechanism, f64, Score)> = None;
            for &c in &node.children {
                let mut child = p.clone();
                child.push(c);
                let s = lins[&child].score(&m[r]);
                let gain = here.bic - s.bic;
                if best.is_none_or(|(_, g, _)| gain > g) {
                    best = Some((c, gain, s));
                }
            }
            let (e, gain, s) = best?;
            let mut reached = p.clone();
            reached.push(e);
            // As in the selection, an implausible model is only a way to a plausible pair:
            // a replicate that is already on one stops.
            let beyond_limits = implausible.contains(&reached);
            if beyond_limits && (provisional[r] || dead_ends.contains(&reached)) {
                return None;
            }
            let confirmed = confirms(e, here.held_out, s.held_out);
            (gain > 0.0 && gain > node.critical && confirmed).then_some((vec![e], beyond_limits))
        });
        let mut any = false;
        for (r, mv) in moves.into_iter().enumerate() {
            match mv {
                Some((added, beyond_limits)) => {
                    paths[r].extend(added);
                    provisional[r] = beyond_limits;
                    any = true;
                }
                None => {
                    active[r] = false;
                    if std::mem::take(&mut provisional[r]) {
                        paths[r].pop();
                    }
                }
            }
        }
        if !any {
            break;
        }
    }
    // A replicate still on an implausible model names nothing of it.
    for (p, pending) in paths.iter_mut().zip(&provisional) {
        if *pending {
            p.pop();
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
