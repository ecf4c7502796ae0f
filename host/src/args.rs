//! Parsers for command-line values that say exactly what is wrong with a bad value.

/// Parses `Z1,Z2,Z3,Z4` tooth counts, e.g. `49,51,50,50`.
pub fn parse_teeth(s: &str) -> Result<[u32; 4], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 4 {
        return Err(format!(
            "expected four comma-separated tooth counts Z1,Z2,Z3,Z4 (for example 49,51,50,50), got {} value(s) in '{s}'",
            parts.len()
        ));
    }
    let mut z = [0u32; 4];
    for (i, p) in parts.iter().enumerate() {
        z[i] = match p.parse::<i64>() {
            Ok(v) if v >= 1 && v <= u32::MAX as i64 => v as u32,
            Ok(v) => {
                return Err(format!(
                    "Z{} = {v}: tooth counts must be positive whole numbers",
                    i + 1
                ));
            }
            Err(_) => {
                return Err(format!(
                    "Z{} = '{p}' is not a whole number of teeth (for example 49,51,50,50)",
                    i + 1
                ));
            }
        };
    }
    Ok(z)
}

/// Parses a finite number (rejects `nan` and `inf`).
pub fn finite(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("'{s}' is not a finite number")),
        Err(_) => Err(format!("'{s}' is not a number")),
    }
}

/// Parses a finite number > 0.
pub fn positive(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{v} must be greater than zero"))
    }
}

/// Parses a finite number >= 0.
pub fn non_negative(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("{v} must not be negative"))
    }
}

/// Parses a whole number (for a count such as folds or replicates).
pub fn whole(s: &str) -> Result<u32, String> {
    s.trim()
        .parse::<u32>()
        .map_err(|_| format!("'{s}' is not a whole number"))
}

/// Parses `s` with `parse`, then checks it with the library's `check` (the one check of a
/// setting, which Python calls too): its reason after the value, as clap shows it under
/// the flag's name.
pub fn checked<T: std::fmt::Display + Copy, U>(
    s: &str,
    parse: fn(&str) -> Result<T, String>,
    check: fn(T) -> Result<U, String>,
) -> Result<U, String> {
    let v = parse(s)?;
    check(v).map_err(|why| format!("{v}: {why}"))
}

/// Parses an efficiency in (0, 1].
pub fn efficiency(s: &str) -> Result<f64, String> {
    let v = finite(s)?;
    if v > 0.0 && v <= 1.0 {
        Ok(v)
    } else {
        Err(format!("{v} is not an efficiency: give a value in (0, 1]"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn teeth_are_parsed_or_explained() {
        assert_eq!(parse_teeth("49,51,50,50"), Ok([49, 51, 50, 50]));
        assert_eq!(parse_teeth(" 49, 51 ,50,50"), Ok([49, 51, 50, 50]));
        assert!(parse_teeth("49,51,50").unwrap_err().contains("four"));
        assert!(parse_teeth("0,51,50,50").unwrap_err().contains("positive"));
        assert!(parse_teeth("-1,51,50,50").unwrap_err().contains("positive"));
        assert!(
            parse_teeth("a,51,50,50")
                .unwrap_err()
                .contains("not a whole number")
        );
        assert!(parse_teeth("4.5,51,50,50").unwrap_err().contains("Z1"));
    }

    #[test]
    fn numbers_must_be_finite_and_in_range() {
        assert!(finite("nan").is_err());
        assert!(finite("inf").is_err());
        assert!(positive("0").is_err());
        assert!(non_negative("-0.1").is_err());
        assert!(efficiency("1.2").is_err());
        assert_eq!(efficiency("0.423"), Ok(0.423));
    }
}
