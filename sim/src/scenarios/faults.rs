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
pub const DRILLS: [&str; 7] = [
    "overcurrent",
    "encoder-loss",
    "comms-loss",
    "bad-calibration",
    "reversed-encoder",
    "load-limit",
    "overvoltage",
];

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

fn rig(seed: u64, setup: impl FnOnce(&mut SimConfig)) -> Result<SimLink, SimError> {
    let mut config =
        SimConfig::for_gear(model::paper::RIG_Z, Load::Torque(1.0)).map_err(|source| {
            SimError::Gear {
                z: model::paper::RIG_Z,
                source,
            }
        })?;
    config.seed = seed;
    setup(&mut config);
    let mut link = SimLink::new(SimRig::new(config));
    hello(&mut link)?;
    Ok(link)
}

fn motor_off(link: &SimLink) -> bool {
    !link.rig.drive().enabled && link.rig.plant().state().current.abs() < 1e-3
}

fn run_one(name: &str, seed: u64) -> Result<FaultOutcome, SimError> {
    let (mut link, cause) = match name {
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
    let time_to_safe_s = if cause {
        link.wait_until(SAFE_WITHIN_S, 0.0001, |l| !l.rig.bridge_on())
    } else {
        Some(0.0)
    };
    link.keep_alive(None);
    link.wait(0.6);
    let release_refused = !matches!(
        link.request(&Request::Release {
            on: true,
            target_hz: 10.0,
            session: 0
        })?,
        Reply::Ack
    );
    link.wait(0.2);
    let latched = crate::RigLink::latched_faults(&mut link)?;
    Ok(FaultOutcome {
        name: name.to_string(),
        motor_off: motor_off(&link),
        fault_latched: latched != FaultFlags::empty(),
        time_to_safe_s,
        faults: latched.names().map(str::to_string).collect(),
        release_refused,
    })
}
