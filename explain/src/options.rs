//! The settings a user gives `rig explain` (and Python's `explain`), checked once: one check
//! per setting, which the CLI's value parsers and the Python door both call, so a bad value
//! gets the same reason from either. The reason says what to give; the caller names the
//! setting as its user wrote it (the CLI's flag, Python's keyword).

use crate::{ExplainError, Options};

/// Fewest and most folds of the held-out validation.
pub const FOLDS: std::ops::RangeInclusive<u32> = 2..=20;
/// Most replicates of the block bootstrap.
pub const MAX_REPLICATES: u32 = 10_000;

impl Options {
    /// The false-discovery guard's level, in (0, 0.5); else what to give.
    pub fn check_alpha(alpha: f64) -> Result<f64, String> {
        if alpha > 0.0 && alpha < 0.5 {
            Ok(alpha)
        } else {
            Err("the guard level must lie in (0, 0.5), e.g. 0.01".into())
        }
    }

    /// The folds of the held-out validation, [`FOLDS`]; else what to give.
    pub fn check_folds(folds: u32) -> Result<usize, String> {
        if FOLDS.contains(&folds) {
            Ok(folds as usize)
        } else {
            Err(format!("give {} to {} folds", FOLDS.start(), FOLDS.end()))
        }
    }

    /// The bootstrap's replicates, 0 (none) to [`MAX_REPLICATES`]; else what to give.
    pub fn check_replicates(replicates: u32) -> Result<usize, String> {
        if replicates <= MAX_REPLICATES {
            Ok(replicates as usize)
        } else {
            Err(format!("give 0 to {MAX_REPLICATES} replicates"))
        }
    }

    /// A row noise of the current the user knows, mA, as the lack-of-fit test's reference
    /// in A (`None` for 0: none stated); else what to give.
    pub fn check_stated_noise_ma(noise_ma: f64) -> Result<Option<f64>, String> {
        if noise_ma.is_finite() && noise_ma >= 0.0 {
            Ok((noise_ma > 0.0).then_some(noise_ma * 1e-3))
        } else {
            Err("give zero or a positive noise in mA".into())
        }
    }

    /// The default options with each setting given ([`Options::check_alpha`] and its
    /// siblings); a setting outside its range is an error naming it as the library and
    /// Python spell it (`alpha 0.7: ...`).
    pub fn checked(
        alpha: Option<f64>,
        folds: Option<u32>,
        replicates: Option<u32>,
        stated_noise_ma: Option<f64>,
    ) -> Result<Options, ExplainError> {
        fn named<T, V: std::fmt::Display>(
            name: &str,
            value: V,
            checked: Result<T, String>,
        ) -> Result<T, ExplainError> {
            checked.map_err(|why| ExplainError::BadValue {
                what: format!("{name} {value}"),
                why,
            })
        }
        let mut options = Options::default();
        if let Some(a) = alpha {
            options.alpha = named("alpha", a, Options::check_alpha(a))?;
        }
        if let Some(f) = folds {
            options.folds = named("folds", f, Options::check_folds(f))?;
        }
        if let Some(r) = replicates {
            options.replicates = named("replicates", r, Options::check_replicates(r))?;
        }
        if let Some(n) = stated_noise_ma {
            options.stated_noise_a =
                named("stated_noise_ma", n, Options::check_stated_noise_ma(n))?;
        }
        Ok(options)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_setting_is_checked_at_its_bounds() {
        assert_eq!(Options::check_alpha(0.01), Ok(0.01));
        for bad in [0.0, 0.5, -0.1, f64::NAN, f64::INFINITY] {
            assert!(Options::check_alpha(bad).is_err(), "{bad}");
        }
        assert_eq!(Options::check_folds(2), Ok(2));
        assert_eq!(Options::check_folds(20), Ok(20));
        assert_eq!(Options::check_folds(1), Err("give 2 to 20 folds".into()));
        assert!(Options::check_folds(21).is_err());
        assert_eq!(Options::check_replicates(0), Ok(0));
        assert_eq!(Options::check_replicates(10_000), Ok(10_000));
        assert!(Options::check_replicates(10_001).is_err());
        assert_eq!(Options::check_stated_noise_ma(0.0), Ok(None));
        assert_eq!(Options::check_stated_noise_ma(20.0), Ok(Some(0.02)));
        assert!(Options::check_stated_noise_ma(-1.0).is_err());
        assert!(Options::check_stated_noise_ma(f64::NAN).is_err());
    }

    #[test]
    fn checked_options_keep_the_defaults_and_name_a_bad_setting() {
        assert_eq!(
            Options::checked(None, None, None, None).unwrap(),
            Options::default()
        );
        let o = Options::checked(Some(0.01), Some(4), Some(0), Some(15.0)).unwrap();
        assert_eq!(
            (o.alpha, o.folds, o.replicates, o.stated_noise_a),
            (0.01, 4, 0, Some(0.015))
        );
        let e = Options::checked(Some(0.7), None, None, None)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "alpha 0.7: the guard level must lie in (0, 0.5), e.g. 0.01"
        );
        let e = Options::checked(None, Some(30), None, None)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "folds 30: give 2 to 20 folds");
        let e = Options::checked(None, None, Some(20_000), None)
            .unwrap_err()
            .to_string();
        assert_eq!(e, "replicates 20000: give 0 to 10000 replicates");
        let e = Options::checked(None, None, None, Some(-2.0))
            .unwrap_err()
            .to_string();
        assert_eq!(e, "stated_noise_ma -2: give zero or a positive noise in mA");
    }
}
