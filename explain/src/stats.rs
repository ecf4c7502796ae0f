//! Small numerics for the fits and tests: Cholesky on small dense matrices, the normal and
//! chi-square tails, correlation and whiteness tests.

/// Cholesky factor L (row-major, lower) of the symmetric positive definite `a` (n x n), or
/// `None` when `a` is not positive definite.
pub fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// Solves L L^T x = b for the Cholesky factor `l`.
pub fn cholesky_solve(l: &[f64], n: usize, b: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; n];
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * y[k];
        }
        y[i] = s / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let mut s = y[i];
        for k in i + 1..n {
            s -= l[k * n + i] * x[k];
        }
        x[i] = s / l[i * n + i];
    }
    x
}

/// Inverse of the symmetric positive definite `a` (n x n), or `None`.
pub fn invert_spd(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let l = cholesky(a, n)?;
    let mut inv = vec![0.0; n * n];
    let mut e = vec![0.0; n];
    for j in 0..n {
        e.iter_mut().for_each(|v| *v = 0.0);
        e[j] = 1.0;
        let col = cholesky_solve(&l, n, &e);
        for i in 0..n {
            inv[i * n + j] = col[i];
        }
    }
    Some(inv)
}

/// Upper tail of the standard normal, P(Z > z).
pub fn normal_sf(z: f64) -> f64 {
    0.5 * libm::erfc(z / std::f64::consts::SQRT_2)
}

/// Upper tail of the chi-square distribution with `k` degrees of freedom, P(X > x).
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    gamma_q(0.5 * k, 0.5 * x)
}

/// Regularised upper incomplete gamma Q(a, x) (series below a + 1, continued fraction above).
fn gamma_q(a: f64, x: f64) -> f64 {
    let ln_front = a * x.ln() - x - libm::lgamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..500 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-15 {
                break;
            }
        }
        (1.0 - sum * ln_front.exp()).clamp(0.0, 1.0)
    } else {
        // Lentz's continued fraction.
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        (ln_front.exp() * h).clamp(0.0, 1.0)
    }
}

/// Regularised incomplete beta function I_x(a, b) (continued fraction, Lentz).
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front =
        libm::lgamma(a + b) - libm::lgamma(a) - libm::lgamma(b) + a * x.ln() + b * (1.0 - x).ln();
    // The fraction converges fast on the side of the distribution's bulk.
    if x < (a + 1.0) / (a + b + 2.0) {
        (ln_front.exp() * beta_fraction(a, b, x) / a).clamp(0.0, 1.0)
    } else {
        (1.0 - ln_front.exp() * beta_fraction(b, a, 1.0 - x) / b).clamp(0.0, 1.0)
    }
}

fn beta_fraction(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let clamp = |v: f64| if v.abs() < tiny { tiny } else { v };
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 / clamp(1.0 - qab * x / qap);
    let mut h = d;
    for m in 1..1000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 / clamp(1.0 + aa * d);
        c = clamp(1.0 + aa / c);
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 / clamp(1.0 + aa * d);
        c = clamp(1.0 + aa / c);
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Upper tail of the F distribution with `d1` and `d2` degrees of freedom, P(F > f).
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if f <= 0.0 || !f.is_finite() {
        return if f.is_finite() || f.is_nan() {
            1.0
        } else {
            0.0
        };
    }
    beta_inc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f))
}

/// Mean of `x` (0 for an empty slice).
pub fn mean(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        x.iter().sum::<f64>() / x.len() as f64
    }
}

/// Root mean square of `x`.
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        0.0
    } else {
        (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
    }
}

/// Pearson correlation of `x` and `y` (0 when either is constant).
pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let (mx, my) = (mean(x), mean(y));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        let (dx, dy) = (a - mx, b - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx <= 0.0 || syy <= 0.0 {
        0.0
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// Pearson correlation of `x(j)` and `y(j)` over j in 0..n, without collecting them (0 when
/// either is constant).
pub fn pearson_by(n: usize, x: impl Fn(usize) -> f64, y: impl Fn(usize) -> f64) -> f64 {
    if n == 0 {
        return 0.0;
    }
    let (mut mx, mut my) = (0.0, 0.0);
    for j in 0..n {
        mx += x(j);
        my += y(j);
    }
    mx /= n as f64;
    my /= n as f64;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for j in 0..n {
        let (dx, dy) = (x(j) - mx, y(j) - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx <= 0.0 || syy <= 0.0 {
        0.0
    } else {
        sxy / (sxx * syy).sqrt()
    }
}

/// Two-sided p-value of a correlation `r` over `n` pairs (Fisher's z).
pub fn correlation_p_value(r: f64, n: usize) -> f64 {
    if n < 4 {
        return 1.0;
    }
    let z = r.clamp(-0.999_999, 0.999_999).atanh() * ((n - 3) as f64).sqrt();
    (2.0 * normal_sf(z.abs())).min(1.0)
}

/// Ljung-Box statistic of `x` (in time order) over `lags` lags and its p-value
/// (chi-square with `lags` degrees of freedom).
pub fn ljung_box(x: &[f64], lags: usize) -> (f64, f64) {
    let n = x.len();
    if n < lags + 2 || lags == 0 {
        return (0.0, 1.0);
    }
    let m = mean(x);
    let c0: f64 = x.iter().map(|v| (v - m) * (v - m)).sum();
    if c0 <= 0.0 {
        return (0.0, 1.0);
    }
    let mut q = 0.0;
    for k in 1..=lags {
        let ck: f64 = (k..n).map(|t| (x[t] - m) * (x[t - k] - m)).sum();
        let r = ck / c0;
        q += r * r / (n - k) as f64;
    }
    q *= n as f64 * (n as f64 + 2.0);
    (q, chi2_sf(q, lags as f64))
}

/// Durbin-Watson statistic of `x` in time order (2: no lag-one correlation).
pub fn durbin_watson(x: &[f64]) -> f64 {
    let ss: f64 = x.iter().map(|v| v * v).sum();
    if ss <= 0.0 {
        return 2.0;
    }
    x.windows(2)
        .map(|w| (w[1] - w[0]) * (w[1] - w[0]))
        .sum::<f64>()
        / ss
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_inverts() {
        let a = [4.0, 2.0, 0.6, 2.0, 2.0, 0.5, 0.6, 0.5, 3.0];
        let l = cholesky(&a, 3).unwrap();
        let x = cholesky_solve(&l, 3, &[1.0, 2.0, 3.0]);
        for i in 0..3 {
            let ax: f64 = (0..3).map(|j| a[i * 3 + j] * x[j]).sum();
            assert!((ax - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        let inv = invert_spd(&a, 3).unwrap();
        let p01: f64 = (0..3).map(|k| a[k] * inv[k * 3 + 1]).sum();
        assert!(p01.abs() < 1e-12);
        assert!(cholesky(&[1.0, 2.0, 2.0, 1.0], 2).is_none());
    }

    #[test]
    fn tails_match_tables() {
        assert!((normal_sf(1.959964) - 0.025).abs() < 1e-6);
        assert!((chi2_sf(3.841459, 1.0) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(18.307038, 10.0) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(1.0, 30.0) - 1.0).abs() < 1e-9);
        assert!(chi2_sf(100.0, 2.0) < 1e-20);
        // F critical values from the tables (95 % and 99 %).
        assert!((f_sf(3.708_265, 3.0, 10.0) - 0.05).abs() < 1e-6);
        assert!((f_sf(4.102_685, 5.0, 20.0) - 0.01).abs() < 1e-6);
        assert!((f_sf(161.447_6, 1.0, 1.0) - 0.05).abs() < 1e-6);
        assert!((f_sf(1.0, 40.0, 40.0) - 0.5).abs() < 1e-9);
        assert_eq!(f_sf(0.0, 3.0, 10.0), 1.0);
    }

    #[test]
    fn correlation_and_whiteness() {
        let x: Vec<f64> = (0..100).map(|k| k as f64).collect();
        let y: Vec<f64> = x.iter().map(|v| 2.0 * v + 1.0).collect();
        assert!((pearson(&x, &y) - 1.0).abs() < 1e-12);
        assert!(correlation_p_value(0.05, 100) > 0.5);
        assert!(correlation_p_value(0.6, 100) < 1e-6);
        // A slow trend is not white; alternating signs are not either (DW near 4).
        let (_, p) = ljung_box(&x, 5);
        assert!(p < 1e-6);
        let alt: Vec<f64> = (0..100)
            .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        assert!(durbin_watson(&alt) > 3.5);
        assert!((rms(&[3.0, 4.0]) - (12.5f64).sqrt()).abs() < 1e-12);
    }
}
