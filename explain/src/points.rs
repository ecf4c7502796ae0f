//! The measured rows as test points for the fits: operating points, the levels of cam speed
//! and load they were taken at, blocks of test points for held-out validation and the
//! bootstrap, time order and the thermal driver.
//!
//! Up to [`AGGREGATE_ABOVE`] rows every row is a fitting point. Above, rows taken at the same
//! conditions (cam speed within 2 %, load within 0.5 % of its range, the same stretch of the
//! session and of the thermal driver) are pooled into one point: its mean operating point,
//! its mean current (each row shifted to the mean operating point by the reference model's
//! local slope), its row count and the sum of squared deviations of its rows. The Gaussian
//! likelihood of the rows is then exactly the pooled one up to the within-point variation
//! of the model, which the shift removes to first order; a million rows become a few
//! thousand points.

use std::collections::HashMap;

use model::effects::{CurrentEvaluator, CurrentModel, OperatingPoint};
use model::plant::NoiseSource;

use super::data::Dataset;
use super::library::{DataTraits, ThermalDriver};
use super::terms::{Inputs, Term};

/// Seed of the fold assignment, fixed so a run repeats exactly.
const FOLD_SEED: u64 = 0x0f01_d5ee_d000_0006;
/// Above this many rows with a current, rows at like conditions are pooled into one point.
pub const AGGREGATE_ABOVE: usize = 4000;
/// Most pooled points; the pooling coarsens until it fits.
const MAX_POINTS: usize = 6000;
/// Fewest test points in a bootstrap block.
const MIN_BLOCK_LENGTH: usize = 5;
/// Most bootstrap blocks.
const MAX_BLOCKS: usize = 32;

/// A backdrive observation: cam speed, load, whether it backdrove, and how many rows at
/// those conditions (one unless pooled).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldCheck {
    /// Cam speed, rad/s.
    pub omega_n: f64,
    /// Load torque, N m.
    pub tau_rot: f64,
    /// Whether the output backdrove.
    pub backdriven: bool,
    /// Rows with this observation.
    pub count: u32,
    /// Bootstrap block of the rows.
    pub block: u32,
}

/// The rows behind the points, in time order: what the residual tests and plots of single
/// rows need.
#[derive(Debug, Clone, Default)]
pub struct RowView {
    /// Cam speed, rad/s.
    pub omega_n: Vec<f64>,
    /// Load, N m.
    pub tau_rot: Vec<f64>,
    /// Thermal driver (see [`OperatingPoint::thermal`]).
    pub thermal: Vec<f64>,
    /// Time since the first test, s (0 without a `t_s` column).
    pub time_s: Vec<f64>,
    /// Motor temperature, deg C (the calibration's without a `temp_c` column).
    pub temp_c: Vec<f64>,
    /// Measured current, A.
    pub current: Vec<f64>,
    /// The fitting point the row belongs to.
    pub point: Vec<u32>,
    /// The row's index in the data set.
    pub row: Vec<u32>,
    /// Quantile bin of the thermal driver (of [`THERMAL_BINS`], equal counts in the order of
    /// the driver; empty when the data has no thermal driver).
    pub thermal_bin: Vec<u8>,
}

/// Quantile bins of the thermal driver in the gap tables.
pub const THERMAL_BINS: usize = 5;

/// Each value's quantile bin of `bins` equal-count bins in the order of (value, index): the
/// split a full sort would give, found by successive selections in linear time.
fn quantile_bins(x: &[f64], bins: usize) -> Vec<u8> {
    let n = x.len();
    let bins = bins.min(n).max(1);
    let mut pairs: Vec<(f64, u32)> = x.iter().copied().zip(0..n as u32).collect();
    let order = |a: &(f64, u32), b: &(f64, u32)| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1));
    let mut start = 0;
    for b in 1..bins {
        let rank = b * n / bins;
        if rank > start && rank < n {
            pairs[start..].select_nth_unstable_by(rank - start, order);
        }
        start = rank;
    }
    let mut out = vec![0u8; n];
    for b in 0..bins {
        for p in &pairs[b * n / bins..(b + 1) * n / bins] {
            out[p.1 as usize] = b as u8;
        }
    }
    out
}

impl RowView {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.current.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.current.is_empty()
    }

    /// Operating point of row `j`.
    pub fn op(&self, j: usize) -> OperatingPoint {
        OperatingPoint::new(self.omega_n[j], self.tau_rot[j], self.thermal[j])
    }

    /// Measured minus modelled current of every row, in time order, A.
    pub fn residuals(&self, ev: &CurrentEvaluator) -> Vec<f64> {
        (0..self.len())
            .map(|j| self.current[j] - ev.current(&self.op(j)))
            .collect()
    }
}

/// Test points ready for fitting. Index `k` runs over the fitting points (rows with a
/// current, or pools of them on large data).
#[derive(Debug, Clone)]
pub struct TestPoints {
    /// Operating points (the thermal driver included).
    pub ops: Vec<OperatingPoint>,
    /// Measured current (mean over the point's rows), A.
    pub current: Vec<f64>,
    /// Rows in each point.
    pub weight: Vec<f64>,
    /// Sum of squared deviations of the point's row currents from their mean, A^2 (0 for a
    /// single row).
    pub within_ss: Vec<f64>,
    /// Bootstrap block of each point (blocks of consecutive test points in time order).
    pub block: Vec<u32>,
    /// Number of bootstrap blocks.
    pub blocks: usize,
    /// Test points (rows) per bootstrap block.
    pub block_length: usize,
    /// First data row of each point.
    pub rows: Vec<usize>,
    /// Speed level of each point (index into `speed_centres`).
    pub speed_level: Vec<usize>,
    /// Mean cam speed of each speed level, rad/s.
    pub speed_centres: Vec<f64>,
    /// Load level of each point (index into `load_centres`).
    pub load_level: Vec<usize>,
    /// Mean load of each load level, N m.
    pub load_centres: Vec<f64>,
    /// Held-out fold of each point (whole blocks of one speed and load level share a fold).
    pub fold: Vec<usize>,
    /// Number of folds (0 when there are too few blocks to hold any out).
    pub folds: usize,
    /// What drives the thermal drift.
    pub thermal: ThermalDriver,
    /// Whether the time order comes from a `t_s` column.
    pub time_known: bool,
    /// Every row's backdrive check, when the data has non-backdriven rows.
    pub holds: Vec<HoldCheck>,
    /// Every point, 0..n, for fits on all of them.
    pub all: Vec<usize>,
    /// Rows with a current behind the points.
    pub n_rows: usize,
    /// Whether rows were pooled.
    pub pooled: bool,
    /// The rows, in time order.
    pub row_view: RowView,
    /// Time of each point since the first test, s (0 without a `t_s` column).
    pub time_s: Vec<f64>,
    /// Motor temperature of each point, deg C (the calibration's without `temp_c`).
    pub temp_c: Vec<f64>,
    /// The points in time order.
    pub time_order: Vec<usize>,
    /// The term effects the selection may use ([`crate::terms`]); empty until
    /// [`crate::explain`] sets them.
    pub terms: Vec<Term>,
}

/// Groups `values` (with `weights`) into levels: sorted values split where the gap exceeds
/// `gap(previous)`; when that gives more than `max_levels` levels or one wider than
/// `span(centre)`, quantile bins (`fallback` of them, by weight) instead. Returns each
/// value's level and the levels' weighted means.
fn levels(
    values: &[f64],
    weights: &[f64],
    gap: impl Fn(f64) -> f64,
    span: impl Fn(f64) -> f64,
    max_levels: usize,
    fallback: usize,
) -> (Vec<usize>, Vec<f64>) {
    let n = values.len();
    let mut keyed: Vec<(f64, usize)> = values.iter().copied().zip(0..n).collect();
    keyed.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let order: Vec<usize> = keyed.into_iter().map(|(_, k)| k).collect();
    let mut level = vec![0usize; n];
    let mut groups: Vec<Vec<usize>> = vec![Vec::new()];
    for (pos, &k) in order.iter().enumerate() {
        if pos > 0 {
            let prev = values[order[pos - 1]];
            if values[k] - prev > gap(prev) {
                groups.push(Vec::new());
            }
        }
        groups.last_mut().expect("one group").push(k);
    }
    let ok = groups.len() <= max_levels
        && groups.iter().all(|g| {
            let lo = values[g[0]];
            let hi = values[*g.last().expect("non-empty")];
            hi - lo <= span(0.5 * (lo + hi))
        });
    if !ok {
        let bins = fallback.min(n).max(1);
        let total: f64 = weights.iter().sum();
        groups = vec![Vec::new(); bins];
        let (mut b, mut cum) = (0usize, 0.0f64);
        for &k in &order {
            while b + 1 < bins && ((b + 1) as f64 * total / bins as f64).floor() <= cum {
                b += 1;
            }
            groups[b].push(k);
            cum += weights[k];
        }
        groups.retain(|g| !g.is_empty());
    }
    let centres = groups
        .iter()
        .enumerate()
        .map(|(id, g)| {
            for &k in g {
                level[k] = id;
            }
            let w: f64 = g.iter().map(|&k| weights[k]).sum();
            g.iter().map(|&k| values[k] * weights[k]).sum::<f64>() / w
        })
        .collect();
    (level, centres)
}

/// Running sums of one pooled point.
#[derive(Debug, Clone, Copy, Default)]
struct Pool {
    count: f64,
    omega: f64,
    tau: f64,
    thermal: f64,
    shift: f64,
    shift_sq: f64,
    time: f64,
    temp: f64,
    first_row: usize,
    block: u32,
}

impl TestPoints {
    /// Prepares `data`; `reference_c` is the motor temperature at calibration (the thermal
    /// drift's T0), `max_folds` the number of held-out folds wanted, `excluded` the rows to
    /// leave out (outliers; may be empty) and `reference` the model whose local slope shifts
    /// pooled rows to their point's mean conditions.
    pub fn new(
        data: &Dataset,
        reference_c: f64,
        max_folds: usize,
        excluded: &[bool],
        reference: &CurrentModel,
    ) -> Self {
        let thermal = if data.has_temperature {
            ThermalDriver::Temperature { reference_c }
        } else if data.has_time {
            ThermalDriver::Time
        } else {
            ThermalDriver::Unavailable
        };
        let is_out = |k: usize| excluded.get(k).copied().unwrap_or(false);
        let t = data.t_s();
        let t0 = t.map_or(0.0, |t| {
            (0..data.len())
                .filter(|&k| !is_out(k))
                .map(|k| t[k])
                .fold(f64::INFINITY, f64::min)
        });
        let x_of = |k: usize| match thermal {
            ThermalDriver::Temperature { reference_c } => {
                data.temp_c().map_or(0.0, |c| c[k]) - reference_c
            }
            ThermalDriver::Time => t.map_or(0.0, |t| t[k]) - t0,
            ThermalDriver::Unavailable => 0.0,
        };
        let (omega, tau, current) = (data.omega_n(), data.tau_rot(), data.i_in());
        let time_of = |k: usize| t.map_or(0.0, |t| t[k] - t0);
        let temp_of = |k: usize| data.temp_c().map_or(reference_c, |c| c[k]);
        let mut time_s = Vec::new();
        let mut temp_c = Vec::new();

        // Every kept row in time order (by t_s, else file order), and its bootstrap block.
        let mut order: Vec<u32> = (0..data.len() as u32)
            .filter(|&k| !is_out(k as usize))
            .collect();
        if let Some(t) = t
            && !order
                .windows(2)
                .all(|w| t[w[0] as usize] <= t[w[1] as usize])
        {
            order.sort_by(|&a, &b| t[a as usize].total_cmp(&t[b as usize]).then(a.cmp(&b)));
        }
        let kept = order.len();
        let block_length = MIN_BLOCK_LENGTH
            .max(kept.div_ceil(MAX_BLOCKS))
            .min(kept.max(1));
        let blocks = kept.div_ceil(block_length).max(1);
        let mut block_of_row = vec![0u32; data.len()];
        for (pos, &k) in order.iter().enumerate() {
            block_of_row[k as usize] = (pos / block_length) as u32;
        }
        let with_current: Vec<usize> = (0..data.len())
            .filter(|&k| !is_out(k) && !current[k].is_nan())
            .collect();
        let n_rows = with_current.len();
        let pooled = n_rows > AGGREGATE_ABOVE;

        let mut ops = Vec::new();
        let mut cur = Vec::new();
        let mut weight = Vec::new();
        let mut within_ss = Vec::new();
        let mut rows = Vec::new();
        let mut block = Vec::new();
        let mut point_of_row = vec![u32::MAX; data.len()];
        if !pooled {
            for &k in &with_current {
                point_of_row[k] = ops.len() as u32;
                ops.push(OperatingPoint::new(omega[k], tau[k], x_of(k)));
                cur.push(current[k]);
                weight.push(1.0);
                within_ss.push(0.0);
                rows.push(k);
                block.push(block_of_row[k]);
                time_s.push(time_of(k));
                temp_c.push(temp_of(k));
            }
        } else {
            let ev = reference.evaluator();
            let range = |f: &dyn Fn(usize) -> f64| {
                with_current
                    .iter()
                    .map(|&k| f(k))
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                        (a.min(v), b.max(v))
                    })
            };
            let (tau_lo, tau_hi) = range(&|k| tau[k]);
            let (x_lo, x_hi) = range(&|k| x_of(k));
            let mut scale = 1.0;
            let pools = loop {
                let w_speed = 0.02 * scale;
                let w_tau = 0.005 * scale * (tau_hi - tau_lo) + 1e-12;
                let w_x = scale * (x_hi - x_lo) / 16.0 + 1e-12;
                let mut index: HashMap<(i64, i64, i64, u32), u32> = HashMap::new();
                let mut pools: Vec<Pool> = Vec::new();
                let mut too_many = false;
                for &k in &with_current {
                    let key = (
                        (omega[k].ln() / w_speed).floor() as i64,
                        ((tau[k] - tau_lo) / w_tau).floor() as i64,
                        ((x_of(k) - x_lo) / w_x).floor() as i64,
                        block_of_row[k],
                    );
                    let id = *index.entry(key).or_insert_with(|| {
                        pools.push(Pool {
                            first_row: k,
                            block: block_of_row[k],
                            ..Pool::default()
                        });
                        (pools.len() - 1) as u32
                    });
                    if pools.len() > MAX_POINTS {
                        too_many = true;
                        break;
                    }
                    point_of_row[k] = id;
                }
                if !too_many {
                    break pools;
                }
                scale *= 2.0;
            };
            let mut pools = pools;
            for &k in &with_current {
                let x = x_of(k);
                let op = OperatingPoint::new(omega[k], tau[k], x);
                let shift = current[k] - ev.current(&op);
                let p = &mut pools[point_of_row[k] as usize];
                p.count += 1.0;
                p.omega += omega[k];
                p.tau += tau[k];
                p.thermal += x;
                p.shift += shift;
                p.shift_sq += shift * shift;
                p.time += time_of(k);
                p.temp += temp_of(k);
            }
            for p in &pools {
                let n = p.count;
                let op = OperatingPoint::new(p.omega / n, p.tau / n, p.thermal / n);
                let mean_shift = p.shift / n;
                ops.push(op);
                cur.push(ev.current(&op) + mean_shift);
                weight.push(n);
                within_ss.push((p.shift_sq - n * mean_shift * mean_shift).max(0.0));
                rows.push(p.first_row);
                block.push(p.block);
                time_s.push(p.time / n);
                temp_c.push(p.temp / n);
            }
        }
        let n = ops.len();
        let speeds: Vec<f64> = ops.iter().map(|o| o.omega_n).collect();
        let loads: Vec<f64> = ops.iter().map(|o| o.tau_rot.abs()).collect();
        let (speed_level, speed_centres) =
            levels(&speeds, &weight, |w| 0.08 * w, |w| 0.3 * w, 12, 5);
        let (lo, hi) = loads
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let range = (hi - lo).max(1e-9);
        let (load_level, load_centres) = levels(
            &loads,
            &weight,
            |_| 0.03 * range + 1e-6,
            |_| 0.12 * range + 1e-6,
            25,
            10,
        );

        // Blocks of test points: one speed level and one load level each.
        let n_loads = load_centres.len();
        let block_of = |k: usize| speed_level[k] * n_loads + load_level[k];
        let mut block_ids: Vec<usize> = (0..n).map(block_of).collect();
        block_ids.sort_unstable();
        block_ids.dedup();
        let folds = if block_ids.len() >= 4 {
            max_folds.min(block_ids.len())
        } else {
            0
        };
        let mut shuffled = block_ids.clone();
        let mut rng = NoiseSource::new(FOLD_SEED);
        for i in (1..shuffled.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            shuffled.swap(i, j);
        }
        let position: HashMap<usize, usize> = shuffled
            .iter()
            .enumerate()
            .map(|(pos, &b)| (b, pos))
            .collect();
        let fold = (0..n)
            .map(|k| {
                if folds == 0 {
                    0
                } else {
                    position[&block_of(k)] % folds
                }
            })
            .collect();

        // The rows in time order.
        let mut row_view = RowView::default();
        let timed: Vec<usize> = order
            .iter()
            .map(|&k| k as usize)
            .filter(|&k| point_of_row[k] != u32::MAX)
            .collect();
        row_view.omega_n = timed.iter().map(|&k| omega[k]).collect();
        row_view.tau_rot = timed.iter().map(|&k| tau[k]).collect();
        row_view.thermal = timed.iter().map(|&k| x_of(k)).collect();
        row_view.time_s = timed.iter().map(|&k| time_of(k)).collect();
        row_view.temp_c = timed.iter().map(|&k| temp_of(k)).collect();
        if thermal != ThermalDriver::Unavailable {
            row_view.thermal_bin = quantile_bins(&row_view.thermal, THERMAL_BINS);
        }
        row_view.current = timed.iter().map(|&k| current[k]).collect();
        row_view.point = timed.iter().map(|&k| point_of_row[k]).collect();
        row_view.row = timed.iter().map(|&k| k as u32).collect();

        let holds = match data.backdriven() {
            Some(bd) if (0..data.len()).any(|k| !is_out(k) && !bd[k]) => {
                let kept: Vec<usize> = (0..data.len()).filter(|&k| !is_out(k)).collect();
                if kept.len() <= AGGREGATE_ABOVE {
                    kept.iter()
                        .map(|&k| HoldCheck {
                            omega_n: omega[k],
                            tau_rot: tau[k],
                            backdriven: bd[k],
                            count: 1,
                            block: block_of_row[k],
                        })
                        .collect()
                } else {
                    // Pooled like the currents: same speed (2 %), load and block.
                    let (tau_lo, tau_hi) = kept
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &k| {
                            (a.min(tau[k]), b.max(tau[k]))
                        });
                    let w_tau = 0.005 * (tau_hi - tau_lo) + 1e-12;
                    let mut index: HashMap<(i64, i64, u32, bool), usize> = HashMap::new();
                    let mut sums: Vec<(f64, f64, HoldCheck)> = Vec::new();
                    for &k in &kept {
                        let key = (
                            (omega[k].ln() / 0.02).floor() as i64,
                            ((tau[k] - tau_lo) / w_tau).floor() as i64,
                            block_of_row[k],
                            bd[k],
                        );
                        let id = *index.entry(key).or_insert_with(|| {
                            sums.push((
                                0.0,
                                0.0,
                                HoldCheck {
                                    omega_n: 0.0,
                                    tau_rot: 0.0,
                                    backdriven: bd[k],
                                    count: 0,
                                    block: block_of_row[k],
                                },
                            ));
                            sums.len() - 1
                        });
                        let s = &mut sums[id];
                        s.0 += omega[k];
                        s.1 += tau[k];
                        s.2.count += 1;
                    }
                    sums.into_iter()
                        .map(|(w, tq, mut h)| {
                            h.omega_n = w / f64::from(h.count);
                            h.tau_rot = tq / f64::from(h.count);
                            h
                        })
                        .collect()
                }
            }
            _ => Vec::new(),
        };
        let mut time_order: Vec<usize> = (0..n).collect();
        time_order.sort_by(|&a, &b| time_s[a].total_cmp(&time_s[b]).then(a.cmp(&b)));
        Self {
            time_s,
            temp_c,
            time_order,
            terms: Vec::new(),
            ops,
            current: cur,
            weight,
            within_ss,
            block,
            blocks,
            block_length,
            rows,
            speed_level,
            speed_centres,
            load_level,
            load_centres,
            fold,
            folds,
            thermal,
            time_known: data.has_time,
            holds,
            all: (0..n).collect(),
            n_rows,
            pooled,
            row_view,
        }
    }

    /// Number of fitting points.
    pub fn len(&self) -> usize {
        self.ops.len()
    }

    /// Whether there are no points.
    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    /// What the data offers to the effects library.
    pub fn traits(&self) -> DataTraits {
        DataTraits {
            speed_levels: self.speed_centres.len(),
            load_levels: self.load_centres.len(),
            rows: self.n_rows,
            thermal: self.thermal,
            held_rows: self
                .holds
                .iter()
                .filter(|h| !h.backdriven)
                .map(|h| h.count as usize)
                .sum(),
        }
    }

    /// Points outside fold `f` (training) and inside it (held out).
    pub fn split(&self, f: usize) -> (Vec<usize>, Vec<usize>) {
        (0..self.len()).partition(|&k| self.fold[k] != f)
    }

    /// The points' conditions, for evaluating terms.
    pub fn inputs(&self) -> Inputs<'_> {
        Inputs {
            ops: &self.ops,
            time: &self.time_s,
            temp: &self.temp_c,
            order: &self.time_order,
        }
    }

    /// Rows behind the points of `subset`.
    pub fn rows_in(&self, subset: &[usize]) -> f64 {
        subset.iter().map(|&k| self.weight[k]).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_bins_split_like_a_sort() {
        let x: Vec<f64> = (0..103).map(|k| ((k * 37) % 101) as f64 / 7.0).collect();
        let bins = quantile_bins(&x, 5);
        let mut order: Vec<usize> = (0..x.len()).collect();
        order.sort_by(|&a, &b| x[a].total_cmp(&x[b]).then(a.cmp(&b)));
        for b in 0..5 {
            for &k in &order[b * 103 / 5..(b + 1) * 103 / 5] {
                assert_eq!(bins[k] as usize, b);
            }
        }
    }

    #[test]
    fn levels_find_the_paper_sweep_and_fall_back_to_bins() {
        let speeds: Vec<f64> = (0..60)
            .map(|k| [31.4, 62.8, 94.2][k % 3] * (1.0 - 0.01 * (k % 5) as f64))
            .collect();
        let ones = vec![1.0; speeds.len()];
        let (lv, c) = levels(&speeds, &ones, |w| 0.08 * w, |w| 0.3 * w, 12, 5);
        assert_eq!(c.len(), 3);
        assert_eq!(lv[0], 0);
        assert_eq!(lv[2], 2);
        // Continuous values: quantile bins.
        let cont: Vec<f64> = (0..1000).map(|k| 0.3 + k as f64 * 0.0033).collect();
        let ones = vec![1.0; cont.len()];
        let (_, c) = levels(&cont, &ones, |_| 0.1, |_| 0.1, 25, 10);
        assert_eq!(c.len(), 10);
    }
}
