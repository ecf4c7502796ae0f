//! The likelihood of a fit beyond the Gaussian mean: the noise floor, the backdrive
//! observations (a threshold fit of the linear bush's holding) and the mesh ripple's
//! profiled variance.

use crate::points::{HoldCheck, TestPoints};

/// Assumed rate at which a backdrive observation is wrong (a slip, a misread), for the
/// likelihood of the `backdriven` column.
pub const HOLD_LABEL_ERROR: f64 = 0.01;
/// Floor of the row noise scale in the likelihood, A: the resolution to which the model
/// itself is known. Table 2 prints the no-load current C6 = 2.25 A to 10 mA, and the rig's
/// 12-bit current reading it was taken through steps by 6.5 mA: the model's current is not
/// known more finely than a uniform 10 mA step, rms 10 mA / sqrt 12 = 2.9 mA. Rows more
/// precise than that (long whole-revolution averages on a virtual rig, many repeats at a
/// few proposed points) would otherwise turn the model's own rounding, a milliampere or
/// two, into a confident finding. Noisier data (a bench, the synthetic sweeps at 5 mA and
/// more) never reach the floor.
pub const SIGMA_FLOOR_A: f64 = 0.010 / 3.464_101_615_137_754_4;

/// Log-likelihood of `total` backdrive observations of which `errors` are mispredicted.
pub fn hold_loglik(total: f64, errors: f64) -> f64 {
    errors * HOLD_LABEL_ERROR.ln() + (total - errors) * (1.0 - HOLD_LABEL_ERROR).ln()
}

/// Rows of the backdrive observations.
pub(super) fn hold_rows(holds: &[HoldCheck]) -> f64 {
    holds.iter().map(|h| f64::from(h.count)).sum()
}

/// Squared residuals of the rows of each point of `subset` (mean residual `e`), A^2.
pub(super) fn point_sse(points: &TestPoints, subset: &[usize], e: &[f64]) -> Vec<f64> {
    subset
        .iter()
        .zip(e)
        .map(|(&k, e)| points.weight[k] * e * e + points.within_ss[k])
        .collect()
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
