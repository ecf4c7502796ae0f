//! Straight-line least squares with the statistics a calibration report needs: R^2, the
//! residual spread, standard errors and 95 % intervals (Student t).

use serde::Serialize;

/// An ordinary least-squares line `y = slope x + intercept`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LineFit {
    /// Slope.
    pub slope: f64,
    /// Intercept.
    pub intercept: f64,
    /// Coefficient of determination.
    pub r_squared: f64,
    /// Residual standard deviation (n - 2 degrees of freedom).
    pub residual_sd: f64,
    /// Largest absolute residual.
    pub residual_max: f64,
    /// Standard error of the slope.
    pub slope_se: f64,
    /// Standard error of the intercept.
    pub intercept_se: f64,
    /// Covariance of slope and intercept.
    pub covariance: f64,
    /// 95 % interval of the slope.
    pub slope_ci95: [f64; 2],
    /// 95 % interval of the intercept.
    pub intercept_ci95: [f64; 2],
    /// Number of points.
    pub n: usize,
}

impl LineFit {
    /// Fits `y` against `x`; `None` with fewer than three points or no spread in `x`.
    pub fn fit(x: &[f64], y: &[f64]) -> Option<Self> {
        let n = x.len().min(y.len());
        if n < 3 {
            return None;
        }
        let nf = n as f64;
        let mx = x.iter().take(n).sum::<f64>() / nf;
        let my = y.iter().take(n).sum::<f64>() / nf;
        let sxx: f64 = x.iter().take(n).map(|a| (a - mx).powi(2)).sum();
        let syy: f64 = y.iter().take(n).map(|b| (b - my).powi(2)).sum();
        let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
        if sxx <= 0.0 || !sxx.is_finite() {
            return None;
        }
        let slope = sxy / sxx;
        let intercept = my - slope * mx;
        let residuals: Vec<f64> = x
            .iter()
            .zip(y)
            .map(|(a, b)| b - (slope * a + intercept))
            .collect();
        let sse: f64 = residuals.iter().map(|r| r * r).sum();
        let dof = nf - 2.0;
        let s2 = sse / dof;
        let slope_se = (s2 / sxx).sqrt();
        let intercept_se = (s2 * (1.0 / nf + mx * mx / sxx)).sqrt();
        let t = t_975(n - 2);
        Some(Self {
            slope,
            intercept,
            r_squared: if syy > 0.0 { 1.0 - sse / syy } else { 1.0 },
            residual_sd: s2.sqrt(),
            residual_max: residuals.iter().fold(0.0, |m: f64, r| m.max(r.abs())),
            slope_se,
            intercept_se,
            covariance: -mx * s2 / sxx,
            slope_ci95: [slope - t * slope_se, slope + t * slope_se],
            intercept_ci95: [intercept - t * intercept_se, intercept + t * intercept_se],
            n,
        })
    }

    /// The line at `x`.
    pub fn at(&self, x: f64) -> f64 {
        self.slope * x + self.intercept
    }
}

/// A derived value with its standard error and 95 % interval (normal approximation, or
/// Student's t when built from fits' parts: [`Estimate::from_parts`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    /// The value.
    pub value: f64,
    /// Its standard error.
    pub se: f64,
    /// Its 95 % interval.
    pub ci95: [f64; 2],
}

impl Estimate {
    /// `value` with standard error `se`.
    pub fn new(value: f64, se: f64) -> Self {
        Self {
            value,
            se,
            ci95: [value - 1.96 * se, value + 1.96 * se],
        }
    }

    /// `value` whose variance is the sum of independent `parts`, each `(variance, degrees
    /// of freedom)` of the fit it comes from. The 95 % interval uses Student's t at the
    /// Welch-Satterthwaite degrees of freedom (rounded down): with two line fits of 9 and 10
    /// points, t is about 2.3, where the normal 1.96 would claim more than the fits know.
    pub fn from_parts(value: f64, parts: &[(f64, usize)]) -> Self {
        let var: f64 = parts.iter().map(|&(v, _)| v.max(0.0)).sum();
        let spread: f64 = parts
            .iter()
            .map(|&(v, dof)| v.max(0.0).powi(2) / dof.max(1) as f64)
            .sum();
        let se = var.sqrt();
        let t = if spread > 0.0 {
            t_975((var * var / spread).floor() as usize)
        } else {
            1.959_964
        };
        Self {
            value,
            se,
            ci95: [value - t * se, value + t * se],
        }
    }
}

/// The 97.5 % quantile of Student's t with `dof` degrees of freedom (two-sided 95 %).
pub fn t_975(dof: usize) -> f64 {
    const TABLE: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match dof {
        0 => f64::INFINITY,
        1..=30 => TABLE[dof - 1],
        _ => {
            // Cornish-Fisher expansion around the normal quantile.
            let z: f64 = 1.959_964;
            let d = dof as f64;
            z + (z.powi(3) + z) / (4.0 * d)
                + (5.0 * z.powi(5) + 16.0 * z.powi(3) + 3.0 * z) / (96.0 * d * d)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_line_and_known_statistics() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let y = [2.1, 3.9, 6.2, 7.8, 10.1];
        let f = LineFit::fit(&x, &y).unwrap();
        // Reference values from the closed-form OLS on these five points.
        assert!((f.slope - 1.99).abs() < 1e-9);
        assert!((f.intercept - 0.05).abs() < 1e-9);
        assert!(f.r_squared > 0.99 && f.r_squared < 1.0);
        assert!((f.slope_ci95[1] - f.slope - 3.182 * f.slope_se).abs() < 1e-12);
        assert!(LineFit::fit(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]).is_none());
        assert!(LineFit::fit(&[1.0, 2.0], &[1.0, 2.0]).is_none());
    }

    #[test]
    fn t_quantiles() {
        assert_eq!(t_975(1), 12.706);
        assert_eq!(t_975(30), 2.042);
        assert!((t_975(60) - 2.000).abs() < 0.002);
        assert!((t_975(1000) - 1.962).abs() < 0.002);
    }
}
