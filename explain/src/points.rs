//! The measured rows as test points for the fits: operating points, the levels of cam speed
//! and load they were taken at, blocks of test points for held-out validation, time order and
//! the thermal driver.

use model::effects::OperatingPoint;
use model::plant::NoiseSource;

use super::data::Dataset;
use super::library::{DataTraits, ThermalDriver};

/// Seed of the fold assignment, fixed so a run repeats exactly.
const FOLD_SEED: u64 = 0x0f01_d5ee_d000_0006;

/// A non-backdriven check of one row: cam speed, load and whether it backdrove.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoldCheck {
    /// Cam speed, rad/s.
    pub omega_n: f64,
    /// Load torque, N m.
    pub tau_rot: f64,
    /// Whether the output backdrove.
    pub backdriven: bool,
}

/// Test points ready for fitting. Index `k` runs over the rows with a current.
#[derive(Debug, Clone)]
pub struct TestPoints {
    /// Operating points (the thermal driver included).
    pub ops: Vec<OperatingPoint>,
    /// Measured current, A.
    pub current: Vec<f64>,
    /// Row of the data set each point comes from.
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
    /// Points in time order (by `t_s`, else file order).
    pub time_order: Vec<usize>,
    /// Whether `time_order` comes from a `t_s` column.
    pub time_known: bool,
    /// Every row's backdrive check, when the data has non-backdriven rows.
    pub holds: Vec<HoldCheck>,
    /// Every point, 0..n, for fits on all of them.
    pub all: Vec<usize>,
}

/// Groups `values` into levels: sorted values split where the gap exceeds `gap(previous)`;
/// when that gives more than `max_levels` levels or one wider than `span(centre)`, quantile
/// bins (`fallback` of them) instead. Returns each value's level and the level means.
fn levels(
    values: &[f64],
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
        groups = (0..bins)
            .map(|b| order[b * n / bins..(b + 1) * n / bins].to_vec())
            .filter(|g| !g.is_empty())
            .collect();
    }
    let centres = groups
        .iter()
        .enumerate()
        .map(|(id, g)| {
            for &k in g {
                level[k] = id;
            }
            g.iter().map(|&k| values[k]).sum::<f64>() / g.len() as f64
        })
        .collect();
    (level, centres)
}

impl TestPoints {
    /// Prepares `data`; `reference_c` is the motor temperature at calibration (the thermal
    /// drift's T0) and `max_folds` the number of held-out folds wanted.
    pub fn new(data: &Dataset, reference_c: f64, max_folds: usize) -> Self {
        let thermal = if data.has_temperature {
            ThermalDriver::Temperature { reference_c }
        } else if data.has_time {
            ThermalDriver::Time
        } else {
            ThermalDriver::Unavailable
        };
        let t0 = data
            .rows
            .iter()
            .filter_map(|r| r.t_s)
            .fold(f64::INFINITY, f64::min);
        let mut ops = Vec::new();
        let mut current = Vec::new();
        let mut rows = Vec::new();
        for (k, r) in data.rows.iter().enumerate() {
            let Some(i) = r.i_in else { continue };
            let x = match thermal {
                ThermalDriver::Temperature { reference_c } => {
                    r.temp_c.unwrap_or(reference_c) - reference_c
                }
                ThermalDriver::Time => r.t_s.unwrap_or(t0) - t0,
                ThermalDriver::Unavailable => 0.0,
            };
            ops.push(OperatingPoint::new(r.omega_n, r.tau_rot, x));
            current.push(i);
            rows.push(k);
        }
        let n = ops.len();
        let speeds: Vec<f64> = ops.iter().map(|o| o.omega_n).collect();
        let loads: Vec<f64> = ops.iter().map(|o| o.tau_rot.abs()).collect();
        let (speed_level, speed_centres) = levels(&speeds, |w| 0.08 * w, |w| 0.3 * w, 12, 5);
        let (lo, hi) = loads
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let range = (hi - lo).max(1e-9);
        let (load_level, load_centres) = levels(
            &loads,
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
        let position: std::collections::HashMap<usize, usize> = shuffled
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

        let mut time_order: Vec<usize> = (0..n).collect();
        if data.has_time {
            let t: Vec<f64> = rows
                .iter()
                .map(|&r| data.rows[r].t_s.unwrap_or(0.0))
                .collect();
            // Logs are usually in time order already.
            if !t.windows(2).all(|w| w[0] <= w[1]) {
                time_order.sort_by(|&a, &b| t[a].total_cmp(&t[b]).then(a.cmp(&b)));
            }
        }
        let holds = if data.has_backdriven && data.rows.iter().any(|r| r.backdriven == Some(false))
        {
            data.rows
                .iter()
                .map(|r| HoldCheck {
                    omega_n: r.omega_n,
                    tau_rot: r.tau_rot,
                    backdriven: r.backdriven.unwrap_or(true),
                })
                .collect()
        } else {
            Vec::new()
        };
        Self {
            ops,
            current,
            rows,
            speed_level,
            speed_centres,
            load_level,
            load_centres,
            fold,
            folds,
            thermal,
            time_order,
            time_known: data.has_time,
            holds,
            all: (0..n).collect(),
        }
    }

    /// Number of points with a current.
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
            rows: self.len(),
            thermal: self.thermal,
            held_rows: self.holds.iter().filter(|h| !h.backdriven).count(),
        }
    }

    /// Points outside fold `f` (training) and inside it (held out).
    pub fn split(&self, f: usize) -> (Vec<usize>, Vec<usize>) {
        (0..self.len()).partition(|&k| self.fold[k] != f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_find_the_paper_sweep_and_fall_back_to_bins() {
        let speeds: Vec<f64> = (0..60)
            .map(|k| [31.4, 62.8, 94.2][k % 3] * (1.0 - 0.01 * (k % 5) as f64))
            .collect();
        let (lv, c) = levels(&speeds, |w| 0.08 * w, |w| 0.3 * w, 12, 5);
        assert_eq!(c.len(), 3);
        assert_eq!(lv[0], 0);
        assert_eq!(lv[2], 2);
        // Continuous values: quantile bins.
        let cont: Vec<f64> = (0..1000).map(|k| 0.3 + k as f64 * 0.0033).collect();
        let (_, c) = levels(&cont, |_| 0.1, |_| 0.1, 25, 10);
        assert_eq!(c.len(), 10);
    }
}
