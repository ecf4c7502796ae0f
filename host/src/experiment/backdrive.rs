//! `backdrive` (Table 1): the load hangs on the locked gear for a set time (held or
//! backdriven without vibration), then the vibrator runs (backdriven with vibration?),
//! then locks. The verdicts come from the output encoder when fitted, from the virtual
//! rig's plant, or from the operator ("did the output move? [y/n]").

use serde::Serialize;

use super::bench::{Bench, Go, MOTION_RAD, Operator, interrupted};
use crate::RigError;

/// The procedure's settings.
#[derive(Debug, Clone, Copy)]
pub struct Backdrive {
    /// Load hung on the output, N m (Table 1: 3.68 N m, the teeth's limit).
    pub load_nm: f64,
    /// Hold without vibration, s.
    pub hold_s: f64,
    /// Vibration frequency, Hz.
    pub hz: f64,
    /// How long the vibrator runs, s.
    pub release_s: f64,
}

impl Default for Backdrive {
    fn default() -> Self {
        Self {
            load_nm: model::paper::TAU_ROT_MAX,
            hold_s: 1.0,
            hz: 10.0,
            release_s: 1.5,
        }
    }
}

/// One gear set's verdicts.
#[derive(Debug, Clone, Serialize)]
pub struct BackdriveVerdict {
    /// The gear set, when known.
    pub z: Option<[u32; 4]>,
    /// Load, N m.
    pub load_nm: f64,
    /// The output turned under the load with the vibrator off.
    pub backdriven_without_vibration: bool,
    /// The output turned once the vibrator ran.
    pub backdriven_with_vibration: bool,
    /// Who judged: `output encoder`, `virtual rig` or `operator`.
    pub judged_by: &'static str,
}

/// Runs the procedure on the gear set fitted to `bench`.
pub fn run<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &mut Operator,
    opts: &Backdrive,
    z: Option<[u32; 4]>,
) -> Result<Option<BackdriveVerdict>, RigError> {
    let asks = operator.forced || !bench.is_virtual();
    let set_by_rig = !operator.forced && bench.set_load(opts.load_nm)?;
    if !set_by_rig
        && asks
        && operator.before(&format!(
            "hang {} N m on the pulley",
            reporting::human(opts.load_nm)
        ))? == Go::Skip
    {
        return Ok(None);
    }
    super::bench::allow_load(bench, opts.load_nm)?;
    bench.start_telemetry(20)?;
    let result = judge(bench, operator, opts, z);
    bench.lock_gear();
    let _ = bench.stop_telemetry();
    if bench.is_virtual() && !operator.forced {
        let _ = bench.set_load(0.0);
    }
    result.map(Some)
}

fn angle<B: Bench + ?Sized>(bench: &mut B) -> Result<(Option<f64>, &'static str), RigError> {
    let t = bench.sample()?;
    if let Some(a) = t
        .map(|t| f64::from(t.output_angle_rad))
        .filter(|a| a.is_finite())
    {
        return Ok((Some(a), "output encoder"));
    }
    Ok((bench.peek_output(), "virtual rig"))
}

fn wait<B: Bench + ?Sized>(bench: &mut B, operator: &Operator, s: f64) -> Result<(), RigError> {
    let mut left = s;
    while left > 0.0 {
        if operator.interrupted() {
            return Err(interrupted());
        }
        bench.wait(left.min(0.1))?;
        left -= 0.1;
    }
    Ok(())
}

fn judge<B: Bench + ?Sized>(
    bench: &mut B,
    operator: &mut Operator,
    opts: &Backdrive,
    z: Option<[u32; 4]>,
) -> Result<BackdriveVerdict, RigError> {
    let (a0, by) = angle(bench)?;
    wait(bench, operator, opts.hold_s)?;
    let (a1, _) = angle(bench)?;
    let forced = operator.forced;
    let moved = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if !forced => Some((b - a).abs() > MOTION_RAD),
        _ => None,
    };
    let without = match moved(a0, a1) {
        Some(m) => m,
        None => operator.yes_no(&format!(
            "locked for {} s: did the output move?",
            reporting::human(opts.hold_s)
        ))?,
    };
    bench.release(true, opts.hz)?;
    wait(bench, operator, opts.release_s)?;
    let (a2, _) = angle(bench)?;
    bench.release(false, 0.0)?;
    let with = match moved(a1, a2) {
        Some(m) => m,
        None => operator.yes_no(&format!(
            "vibrating at {} Hz: did the output move?",
            reporting::human(opts.hz)
        ))?,
    };
    let judged_by = if moved(a0, a1).is_none() {
        "operator"
    } else {
        by
    };
    Ok(BackdriveVerdict {
        z,
        load_nm: opts.load_nm,
        backdriven_without_vibration: without,
        backdriven_with_vibration: with,
        judged_by,
    })
}
