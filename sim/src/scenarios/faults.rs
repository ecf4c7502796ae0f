//! Fault drills: each drives the rig into a fault and checks that the firmware reaches the
//! safe state (motor off) and latches the fault. `rig sim faults --json` prints one object
//! per drill.

use model::plant::{CamSetup, Load};
use protocol::{FaultFlags, Reply, Request};
use serde::Serialize;

use super::{hello, release};
use crate::SimError;
use crate::{Injections, SimConfig, SimLink, SimRig};

/// The drills, in the order they run.
pub const DRILLS: [&str; 8] = [
    "overcurrent",
    "encoder-loss",
    "comms-loss",
    "bad-calibration",
    "reversed-encoder",
    "load-limit",
    "overvoltage",
    "debug-halt",
];

/// How long a debug halt lasts before the IWDG (~250 ms, not frozen in debug) resets the
/// chip and the bridge's pull-downs switch it off, s.
const HALT_UNTIL_IWDG_S: f64 = 0.25;

/// Longest a drill waits for the safe state, s.
const SAFE_WITHIN_S: f64 = 3.0;

/// One drill's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct FaultOutcome {
    /// Drill name.
    pub name: String,
    /// The motor is off at the end (bridge disabled, no current).
    pub motor_off: bool,
    /// A fault is latched at the end.
    pub fault_latched: bool,
    /// From the fault's cause to the bridge switching off, s (0 when it never ran).
    pub time_to_safe_s: Option<f64>,
    /// Names of the latched faults.
    pub faults: Vec<String>,
    /// A release request is refused while the fault is latched.
    pub release_refused: bool,
    /// The largest motor current from the drill's cause to its end, A (|i|, the plant's).
    pub peak_current_a: f64,
    /// Whether that peak is inside the current sensor's range (ACS714-05: +-5 A): beyond
    /// it the firmware reads a clipped current and the comparator trip is blind.
    pub peak_within_sensor_range: bool,
    /// The drive the drill ran on: `brake` or `coast` (the plant's).
    pub decay: &'static str,
}

impl FaultOutcome {
    /// Whether the drill ended safe: the motor off with a fault latched (for `debug-halt`,
    /// where the halted core latches nothing, the IWDG's reset is the safe state), and the
    /// current never beyond the sensor's range, except in `overcurrent`, whose jam drives
    /// the current to the comparator's trip (6 A, `model::hardware::comparator::TRIP_A`,
    /// above the ACS714-05's +-5 A but inside its linear output) by design.
    pub fn ends_safe(&self) -> bool {
        self.motor_off
            && (self.fault_latched || self.name == "debug-halt")
            && (self.peak_within_sensor_range || self.name == "overcurrent")
    }
}

/// Runs the named drills (all of [`DRILLS`] when empty).
pub fn run(names: &[String], seed: u64) -> Result<Vec<FaultOutcome>, SimError> {
    let names: Vec<String> = if names.is_empty() {
        DRILLS.iter().map(|s| s.to_string()).collect()
    } else {
        names.to_vec()
    };
    names.iter().map(|n| run_one(n, seed)).collect()
}

/// A drill's rig, boxed: `run_one` holds one per drill arm, and a debug build gives each
/// arm's 46 KB link (and its `Result`) a stack slot of its own, past a test thread's 2 MiB.
fn rig(seed: u64, setup: impl FnOnce(&mut SimConfig)) -> Result<Box<SimLink>, SimError> {
    let mut config =
        SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(1.0)).map_err(|source| {
            SimError::Gear {
                z: model::paper::RIG_Z,
                source,
            }
        })?;
    config.seed = seed;
    setup(&mut config);
    let mut link = Box::new(SimLink::new(SimRig::new(config)));
    hello(&mut link)?;
    Ok(link)
}

fn motor_off(link: &SimLink) -> bool {
    !link.rig.drive().enabled && link.rig.plant().state().current.abs() < 1e-3
}

/// Advances `link` by `seconds` in 0.1 ms steps, raising `peak` to the largest |current|.
fn wait_tracking(link: &mut SimLink, seconds: f64, peak: &mut f64) {
    let steps = (seconds / 1e-4).round() as u32;
    for _ in 0..steps {
        link.wait(1e-4);
        *peak = peak.max(link.rig.plant().state().current.abs());
    }
}

fn run_one(name: &str, seed: u64) -> Result<FaultOutcome, SimError> {
    let mut peak = 0.0f64;
    let (mut link, cause) = match name {
        "debug-halt" => {
            // A probe halts the core at 15 Hz, mid-vibration (the review's case): the core
            // stops, the bridge keeps the board's halt state until the IWDG resets the chip.
            let mut link = rig(seed, |_| {})?;
            release(&mut link, 15.0)?;
            link.wait(1.5);
            peak = link.rig.plant().state().current.abs();
            link.rig.debug_halt();
            let steps = (HALT_UNTIL_IWDG_S / 1e-4).round() as u32;
            for _ in 0..steps {
                link.rig.advance(1e-4);
                peak = peak.max(link.rig.plant().state().current.abs());
            }
            link.rig.watchdog_reset_pins();
            link.rig.advance(0.05);
            let motor_off = motor_off(&link);
            let range = model::hardware::acs714::RANGE_A;
            return Ok(FaultOutcome {
                name: name.to_string(),
                motor_off,
                // The halted core latches nothing; the reset that follows is the safe state.
                fault_latched: false,
                time_to_safe_s: Some(HALT_UNTIL_IWDG_S),
                faults: Vec::new(),
                release_refused: true,
                peak_current_a: peak,
                peak_within_sensor_range: peak <= range,
                decay: decay_name(&link),
            });
        }
        "overcurrent" => {
            let mut link = rig(seed, |_| {})?;
            release(&mut link, 10.0)?;
            link.wait(1.5);
            // The cam jams: its shaft stops dead while the loop still drives it. The
            // comparator's break cuts the bridge before any control step runs.
            link.rig.plant_mut().set_cam(CamSetup::Blocked);
            (link, true)
        }
        "reversed-encoder" => {
            // A and B swapped from the start: the speed reads against the drive.
            let mut link = rig(seed, |_| {})?;
            link.rig.inject(Injections {
                encoder_reversed: true,
                ..Default::default()
            });
            release(&mut link, 10.0)?;
            // Timed from the moment the bridge first drives.
            link.wait_until(SAFE_WITHIN_S, 0.0001, |l| l.rig.bridge_on());
            (link, true)
        }
        "load-limit" => {
            // A record stored before the caps, asking for 1e30 N m (OVERLOAD off): a load
            // above the gear's 3.68 N m while released still stops the rig.
            let mut link = rig(seed, |c| {
                c.calibration.max_release_load_nm = 1e30;
                c.calibration.max_current_a = 4.8;
            })?;
            release(&mut link, 10.0)?;
            link.wait(1.5);
            link.rig.plant_mut().set_load(Load::Torque(3.95));
            (link, true)
        }
        "overvoltage" => {
            // The bus passes the bridge's limit while vibrating: the bench supply turned up
            // from 12 V at 10 V/s (a braking bridge pumping a supply that cannot sink ends
            // the same way, [`model::plant::bus`]). The firmware reads the bus divider and
            // stops the drive; the fault holds while the bus stays high. Timed from the
            // millisecond the bus crosses the limit.
            let mut link = rig(seed, |_| {})?;
            release(&mut link, 10.0)?;
            link.wait(1.5);
            let limit = model::hardware::board::BUS_OVERVOLTAGE_V;
            let mut supply = link.rig.plant().params().supply;
            while link.rig.plant().bus_voltage() <= limit && supply < 40.0 {
                supply += 0.01;
                link.rig.plant_mut().set_supply(supply);
                link.wait(0.001);
            }
            (link, true)
        }
        "encoder-loss" => {
            let mut link = rig(seed, |_| {})?;
            release(&mut link, 10.0)?;
            link.wait(1.5);
            link.rig.inject(Injections {
                encoder_frozen: true,
                ..Default::default()
            });
            (link, true)
        }
        "comms-loss" => {
            let mut link = rig(seed, |_| {})?;
            release(&mut link, 10.0)?;
            link.wait(1.5);
            // The host vanishes: no more heartbeats.
            link.keep_alive(None);
            (link, true)
        }
        "bad-calibration" => {
            let link = rig(seed, |c| {
                c.calibration.c1_nmm_per_a = f32::NAN;
                c.calibration_status = protocol::ParametersStatus::Invalid;
            })?;
            (link, false)
        }
        other => {
            return Err(SimError::BadValue {
                what: format!("fault drill '{other}'"),
                why: format!("unknown; choose from {}", DRILLS.join(", ")),
            });
        }
    };
    peak = peak.max(link.rig.plant().state().current.abs());
    let time_to_safe_s = if cause {
        let mut seen = peak;
        let t = link.wait_until(SAFE_WITHIN_S, 0.0001, |l| {
            seen = seen.max(l.rig.plant().state().current.abs());
            !l.rig.bridge_on()
        });
        peak = seen;
        t
    } else {
        Some(0.0)
    };
    link.keep_alive(None);
    wait_tracking(&mut link, 0.6, &mut peak);
    let release_refused = !matches!(
        link.request(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        })?,
        Reply::Ack
    );
    link.wait(0.2);
    let latched = crate::RigLink::latched_faults(&mut *link)?;
    Ok(FaultOutcome {
        name: name.to_string(),
        motor_off: motor_off(&link),
        fault_latched: latched != FaultFlags::empty(),
        time_to_safe_s,
        faults: latched.names().map(str::to_string).collect(),
        release_refused,
        peak_current_a: peak,
        peak_within_sensor_range: peak <= model::hardware::acs714::RANGE_A,
        decay: decay_name(&link),
    })
}

fn decay_name(link: &SimLink) -> &'static str {
    if link.rig.plant().params().regeneration {
        "brake"
    } else {
        "coast"
    }
}

/// The debug-halt drill's peak current with TIM1 stopped (`true`, the old setting) or
/// running (`false`, the firmware's) through a 250 ms halt at 15 Hz on the default
/// (braking) rig, A.
pub fn debug_halt_peak_a(tim1_stops: bool, seed: u64) -> Result<f64, SimError> {
    let mut link = rig(seed, |_| {})?;
    release(&mut link, 15.0)?;
    link.wait(1.5);
    let mut peak = link.rig.plant().state().current.abs();
    link.rig.debug_halt_with(tim1_stops);
    for _ in 0..(HALT_UNTIL_IWDG_S / 1e-4).round() as u32 {
        link.rig.advance(1e-4);
        peak = peak.max(link.rig.plant().state().current.abs());
    }
    Ok(peak)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_debug_halt_never_brakes_beyond_the_sensors_range() {
        // The review's case: the G2 braking a 15 Hz cam on a halt (TIM1 stopped, PA8 low,
        // the enable high) drives far beyond the ACS714-05's 5 A; with TIM1 left running
        // (the firmware's setting) the halt keeps the last duty's current.
        let range = model::hardware::acs714::RANGE_A;
        let stopped = debug_halt_peak_a(true, 1).unwrap();
        assert!(stopped > 2.0 * range, "{stopped} A with TIM1 stopped");
        let running = debug_halt_peak_a(false, 1).unwrap();
        assert!(running < range, "{running} A with TIM1 running");
        const { assert!(!model::hardware::board::TIM1_STOPS_IN_DEBUG) };
        let o = run(&["debug-halt".into(), "overvoltage".into()], 1).unwrap();
        for d in &o {
            assert_eq!(d.decay, "brake", "{d:?}");
            assert!(d.ends_safe(), "{d:?}");
            assert!(d.peak_current_a < range, "{d:?}");
        }
    }
}
