//! What the device can honour. The firmware clamps or rounds some values it is sent (a
//! release frequency above the calibration's `max_freq_hz`, a capture or telemetry rate
//! that is not its sample clock divided by a whole number); the verbs check here first and
//! refuse such a value with the range the device accepts, so nothing is silently replaced.
//!
//! The numbers come from the firmware core's own configuration ([`CoreConfig::default`],
//! what the firmware binary and the virtual device run), so host and firmware built from one
//! checkout (the protocol's schema hash makes sure of that) agree.

use std::time::{Duration, Instant};

use firmware_core::CoreConfig;

use crate::RigError;

/// Release frequencies the device drives as asked, Hz: from the supervisor's lowest to the
/// lower of its highest and the calibration's `max_freq_hz` (above that the firmware
/// would silently drive at `max_freq_hz`).
pub fn release_freq_range(calibration: &protocol::RigParameters) -> (f32, f32) {
    let s = CoreConfig::default().supervisor;
    (s.min_freq_hz, s.max_freq_hz.min(calibration.max_freq_hz))
}

/// `hz` for `option` as the device takes it, or the error naming the allowed range.
pub fn check_release_freq(
    option: &str,
    hz: f64,
    calibration: &protocol::RigParameters,
) -> Result<f32, RigError> {
    let (lo, hi) = release_freq_range(calibration);
    let sent = hz as f32;
    if sent.is_finite() && (lo..=hi).contains(&sent) {
        return Ok(sent);
    }
    let why = if sent > hi && hi < CoreConfig::default().supervisor.max_freq_hz {
        format!(
            "the device drives {lo} to {hi} Hz: its calibration's max_freq_hz is {hi} (`rig calibration get` shows it, `rig calibration set` changes it); give a frequency in that range"
        )
    } else {
        format!("the device drives {lo} to {hi} Hz: give a frequency in that range")
    };
    Err(RigError::BadValue {
        what: format!("{option} {hz}"),
        why,
    })
}

/// The device's capture clock (its current-sampling rate), Hz.
pub fn capture_clock_hz() -> u32 {
    CoreConfig::default().sample_rate_hz()
}

/// Samples the device's capture buffer holds.
pub fn capture_capacity() -> u32 {
    firmware_core::CAPTURE_CAPACITY as u32
}

/// Capture rates the device records at exactly, Hz, highest first: its capture clock
/// divided by a whole number, at least [`firmware_core::MIN_SAMPLE_RATE_HZ`].
pub fn capture_rates() -> Vec<u32> {
    exact_rates(
        capture_clock_hz(),
        u32::from(firmware_core::MIN_SAMPLE_RATE_HZ),
        capture_clock_hz(),
    )
}

/// Telemetry rates the device sends at exactly, Hz, highest first: its control rate
/// divided by a whole number, at most [`protocol::MAX_TELEMETRY_RATE_HZ`].
pub fn telemetry_rates() -> Vec<u32> {
    let control = CoreConfig::default().control_hz;
    exact_rates(
        control,
        1,
        control.min(u32::from(protocol::MAX_TELEMETRY_RATE_HZ)),
    )
}

fn exact_rates(clock: u32, lo: u32, hi: u32) -> Vec<u32> {
    (1..=clock)
        .filter(|&d| clock.is_multiple_of(d))
        .map(|d| clock / d)
        .filter(|r| (lo..=hi).contains(r))
        .collect()
}

/// `hz` for `option` if the device runs at exactly that rate, else the error naming the
/// nearest rates it does run at (it would divide `clock` by the nearest whole number).
fn check_rate(
    option: &str,
    hz: u32,
    rates: &[u32],
    clock: u32,
    what: &str,
) -> Result<(), RigError> {
    if rates.contains(&hz) {
        return Ok(());
    }
    let below = rates.iter().copied().find(|&r| r < hz);
    let above = rates.iter().rev().copied().find(|&r| r > hz);
    let nearest = match (below, above) {
        (Some(b), Some(a)) => format!("the nearest are {b} and {a} Hz"),
        (Some(b), None) => format!("the highest is {b} Hz"),
        (None, Some(a)) => format!("the lowest is {a} Hz"),
        (None, None) => "none".into(),
    };
    let all: Vec<String> = rates.iter().map(u32::to_string).collect();
    Err(RigError::BadValue {
        what: format!("{option} {hz}"),
        why: format!(
            "the device {what} at {clock} Hz divided by a whole number, so it would not run at {hz} Hz; {nearest} (allowed: {} Hz)",
            all.join(", ")
        ),
    })
}

/// Checks a capture rate (see [`capture_rates`]).
pub fn check_capture_rate(option: &str, hz: u16) -> Result<(), RigError> {
    check_rate(
        option,
        u32::from(hz),
        &capture_rates(),
        capture_clock_hz(),
        "records captures",
    )
}

/// Checks a telemetry rate (see [`telemetry_rates`]).
pub fn check_telemetry_rate(option: &str, hz: u16) -> Result<(), RigError> {
    check_rate(
        option,
        u32::from(hz),
        &telemetry_rates(),
        CoreConfig::default().control_hz,
        "sends telemetry",
    )
}

/// Longest duration a user may give anywhere (a plan's durations and rests, a Python
/// release or recording), device seconds: an hour ([`rigfile::plan::MAX_SECONDS`]).
pub const MAX_SECONDS: f64 = rigfile::plan::MAX_SECONDS;

/// `seconds` for `field` if it is a positive duration of at most [`MAX_SECONDS`], else the
/// error naming the field and the range.
pub fn check_seconds(field: &str, seconds: f64) -> Result<f64, RigError> {
    if seconds.is_finite() && seconds > 0.0 && seconds <= MAX_SECONDS {
        Ok(seconds)
    } else {
        Err(RigError::BadValue {
            what: format!("{field} {seconds}"),
            why: format!("give a positive number of device seconds, at most {MAX_SECONDS}"),
        })
    }
}

/// Wall-clock time of `device_s` device seconds at `time_scale` device seconds per wall
/// second. Never panics: NaN and negative give zero, too long saturates at a century.
pub fn wall_duration(device_s: f64, time_scale: f64) -> Duration {
    const CENTURY_S: f64 = 100.0 * 365.25 * 86_400.0;
    let s = device_s / time_scale.max(1e-9);
    if s.is_nan() || s <= 0.0 {
        Duration::ZERO
    } else {
        Duration::from_secs_f64(s.min(CENTURY_S))
    }
}

/// The instant `wait` from now, saturating far in the future instead of overflowing.
pub fn deadline_after(wait: Duration) -> Instant {
    let now = Instant::now();
    now.checked_add(wait)
        .or_else(|| now.checked_add(Duration::from_secs(86_400 * 365)))
        .unwrap_or(now)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn release_range_is_the_calibrations() {
        let paper = protocol::RigParameters::paper();
        assert_eq!(release_freq_range(&paper), (1.0, 15.0));
        assert_eq!(check_release_freq("--freq", 10.0, &paper).unwrap(), 10.0);
        let e = check_release_freq("--freq", 18.0, &paper)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("--freq 18") && e.contains("1 to 15 Hz") && e.contains("max_freq_hz"),
            "{e}"
        );
        let e = check_release_freq("--release", 40.0, &paper)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--release 40") && e.contains("1 to 15 Hz"),
            "{e}"
        );
        assert!(check_release_freq("--freq", 0.5, &paper).is_err());
    }

    #[test]
    fn rates_are_the_clock_divided_by_whole_numbers() {
        let c = capture_rates();
        assert_eq!(c.first(), Some(&10_000));
        assert!(c.contains(&5000) && c.contains(&2500) && c.contains(&100));
        assert!(!c.contains(&3333) && c.iter().all(|&r| r >= 100));
        assert!(check_capture_rate("--rate", 10_000).is_ok());
        let e = check_capture_rate("--rate", 3000).unwrap_err().to_string();
        assert!(
            e.starts_with("--rate 3000") && e.contains("2500 and 5000 Hz"),
            "{e}"
        );
        let t = telemetry_rates();
        assert!(t.contains(&1000) && t.contains(&50) && t.contains(&1));
        assert!(check_telemetry_rate("--rate", 50).is_ok());
        let e = check_telemetry_rate("--rate", 300).unwrap_err().to_string();
        assert!(e.contains("250 and 500 Hz"), "{e}");
        assert_eq!(capture_capacity(), 10_000);
    }

    #[test]
    fn user_seconds_are_checked_and_wall_durations_never_panic() {
        assert_eq!(check_seconds("seconds", 2.5).unwrap(), 2.5);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e300, 3600.001] {
            let e = check_seconds("seconds", bad).unwrap_err().to_string();
            assert!(e.contains("seconds") && e.contains("3600"), "{e}");
        }
        for (s, scale) in [
            (1e300, 1.0),
            (f64::NAN, 1.0),
            (-5.0, 1.0),
            (1.0, 0.0),
            (1e18, 1e-9),
        ] {
            let d = wall_duration(s, scale);
            assert!(d <= Duration::from_secs(3_200_000_000), "{d:?}");
            let _ = deadline_after(d);
        }
        assert_eq!(wall_duration(2.0, 10.0), Duration::from_millis(200));
        let _ = deadline_after(Duration::MAX);
    }
}
