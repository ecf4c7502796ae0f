//! What `rig monitor` shows and logs, apart from how: when the firmware's estimates are
//! current ([`Freshness`], [`STALE_RULE`]) and the row schema of its CSV log and JSON lines
//! ([`MonitorRow`], [`CSV_HEADER`]). One unit per quantity (tau in N m); a stale estimate
//! or a value the board does not report is an empty CSV field and `null` in JSON.

use protocol::{HealthSample, StatusFlags, SupervisorState, TelemetrySample};
use serde::{Serialize, Serializer};

/// When the view shows the firmware's estimates (tau_cam, tau_rot) as `-`.
pub const STALE_RULE: &str = "tau_cam and tau_rot show `-` when stale: gear locked, a fault, or no cam revolution for more than 1 s (the estimator updates once a revolution)";

/// The meaning of status flag `name`.
pub fn status_meaning(name: &str) -> Option<&'static str> {
    // The protocol's one table of flags and their help.
    StatusFlags::help_of(name)
}

/// Whether the firmware's per-revolution estimates are current: not when the gear is
/// locked, a fault is active or latched, or the cam has not completed a revolution for
/// more than [`Freshness::STALE_AFTER_S`] of device time.
#[derive(Debug, Default, Clone, Copy)]
pub struct Freshness {
    turned_rad: f64,
    last_us: Option<u64>,
    last_rev_us: Option<u64>,
}

impl Freshness {
    /// Device seconds without a whole cam revolution after which estimates are stale.
    pub const STALE_AFTER_S: f64 = 1.0;

    /// Takes sample `t`; true when its estimates are current.
    pub fn update(&mut self, t: &TelemetrySample) -> bool {
        let now = t.device_time_us;
        if let Some(prev) = self.last_us {
            let dt = now.saturating_sub(prev) as f64 * 1e-6;
            self.turned_rad += f64::from(t.cam_speed_rad_s.abs()) * dt;
        }
        self.last_us = Some(now);
        if self.turned_rad >= std::f64::consts::TAU {
            self.turned_rad %= std::f64::consts::TAU;
            self.last_rev_us = Some(now);
        }
        let turning = self
            .last_rev_us
            .is_some_and(|r| now.saturating_sub(r) as f64 * 1e-6 <= Self::STALE_AFTER_S);
        let locked_or_faulted = matches!(t.state, SupervisorState::Locked | SupervisorState::Fault)
            || !t.faults.is_empty();
        turning && !locked_or_faulted
    }
}

/// CSV header of the monitor log. The first ten columns are the original log's; the
/// output shaft and the board's health (its newest once-a-second report) follow.
pub const CSV_HEADER: [&str; 16] = [
    "device_time_s",
    "state",
    "cam_speed_rad_s",
    "cam_hz",
    "current_a",
    "pwm_duty",
    "tau_cam_nm",
    "tau_rot_nm",
    "faults",
    "status",
    "output_rad",
    "output_rad_s",
    "bus_v",
    "motor_temp_c",
    "step_cycles_mean",
    "step_cycles_max",
];

/// The board's health values as reported: `None` where not sensed (NaN) or, for the step
/// cycles, not measured (0: never on the virtual rig).
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct HealthValues {
    /// Bus voltage, V.
    pub bus_v: Option<f32>,
    /// Motor temperature, deg C.
    pub motor_temp_c: Option<f32>,
    /// Mean control-step cycles over the last second.
    pub step_cycles_mean: Option<u32>,
    /// Largest control-step cycles over the last second.
    pub step_cycles_max: Option<u32>,
}

impl HealthValues {
    /// The values of `h` that are reported (all `None` without a report).
    pub fn of(h: Option<&HealthSample>) -> Self {
        match h {
            Some(h) => Self {
                bus_v: finite(true, h.bus_voltage_v),
                motor_temp_c: finite(true, h.motor_temp_c),
                step_cycles_mean: (h.step_cycles_mean > 0).then_some(h.step_cycles_mean),
                step_cycles_max: (h.step_cycles_max > 0).then_some(h.step_cycles_max),
            },
            None => Self::default(),
        }
    }
}

/// `v` when `ok` and a number.
fn finite(ok: bool, v: f32) -> Option<f32> {
    (ok && v.is_finite()).then_some(v)
}

/// JSON numbers of `f32` values as their shortest decimal (62.1, not 62.099998).
fn human<S: Serializer>(v: &Option<f32>, s: S) -> Result<S::Ok, S::Error> {
    v.map(|v| reporting::human_f64(f64::from(v))).serialize(s)
}

/// One telemetry sample as `rig monitor` logs it: a row of `--csv` ([`MonitorRow::csv_record`],
/// under [`CSV_HEADER`]) and, serialized, a line of `--json` (SI units, names as in the
/// CSV, `seq` besides, no `cam_hz`). A stale estimate and what is not reported are `None`;
/// the health values are the newest once-a-second report's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MonitorRow {
    /// Device time, s.
    pub device_time_s: f64,
    /// The sample's sequence number.
    pub seq: u32,
    /// Supervisor state name.
    pub state: &'static str,
    /// Cam speed, rad/s.
    pub cam_speed_rad_s: f32,
    /// Motor current, A.
    pub current_a: f32,
    /// Drive duty, -1..1.
    pub pwm_duty: f32,
    /// Cam torque estimate, N m (None when stale).
    #[serde(serialize_with = "human")]
    pub tau_cam_nm: Option<f32>,
    /// Load estimate, N m (None when stale).
    #[serde(serialize_with = "human")]
    pub tau_rot_nm: Option<f32>,
    /// Active and latched fault names.
    pub faults: Vec<&'static str>,
    /// Status flag names.
    pub status: Vec<&'static str>,
    /// Output shaft angle, rad (None without an output encoder).
    #[serde(serialize_with = "human")]
    pub output_rad: Option<f32>,
    /// Output shaft speed, rad/s.
    #[serde(serialize_with = "human")]
    pub output_rad_s: Option<f32>,
    /// Bus voltage, V.
    #[serde(serialize_with = "human")]
    pub bus_v: Option<f32>,
    /// Motor temperature, deg C.
    #[serde(serialize_with = "human")]
    pub motor_temp_c: Option<f32>,
    /// Mean control-step cycles over the last second.
    pub step_cycles_mean: Option<u32>,
    /// Largest control-step cycles over the last second.
    pub step_cycles_max: Option<u32>,
}

impl MonitorRow {
    /// The row of sample `t`, its estimates shown only when `fresh` ([`Freshness`]), with
    /// the newest `health` report.
    pub fn new(t: &TelemetrySample, fresh: bool, health: Option<&HealthSample>) -> Self {
        let h = HealthValues::of(health);
        Self {
            device_time_s: t.device_time_us as f64 / 1e6,
            seq: t.seq,
            state: t.state.name(),
            cam_speed_rad_s: t.cam_speed_rad_s,
            current_a: t.current_a,
            pwm_duty: t.pwm_duty,
            tau_cam_nm: finite(fresh, t.tau_cam_nm),
            tau_rot_nm: finite(fresh, t.tau_rot_nm),
            faults: t.faults.names().collect(),
            status: t.status.names().collect(),
            output_rad: finite(true, t.output_angle_rad),
            output_rad_s: finite(true, t.output_speed_rad_s),
            bus_v: h.bus_v,
            motor_temp_c: h.motor_temp_c,
            step_cycles_mean: h.step_cycles_mean,
            step_cycles_max: h.step_cycles_max,
        }
    }

    /// The row's CSV fields under [`CSV_HEADER`] (fixed decimals; empty where `None`).
    pub fn csv_record(&self) -> [String; 16] {
        let num =
            |v: Option<f32>, digits: usize| v.map(|v| format!("{v:.digits$}")).unwrap_or_default();
        let count = |c: Option<u32>| c.map(|c| c.to_string()).unwrap_or_default();
        [
            format!("{:.6}", self.device_time_s),
            self.state.to_owned(),
            format!("{:.4}", self.cam_speed_rad_s),
            format!("{:.4}", self.cam_speed_rad_s.abs() / std::f32::consts::TAU),
            format!("{:.4}", self.current_a),
            format!("{:.4}", self.pwm_duty),
            num(self.tau_cam_nm, 6),
            num(self.tau_rot_nm, 5),
            self.faults.join("|"),
            self.status.join("|"),
            num(self.output_rad, 5),
            num(self.output_rad_s, 4),
            num(self.bus_v, 3),
            num(self.motor_temp_c, 2),
            count(self.step_cycles_mean),
            count(self.step_cycles_max),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::FaultFlags;

    fn sample() -> TelemetrySample {
        TelemetrySample {
            seq: 7,
            device_time_us: 1_500_000,
            cam_speed_rad_s: 62.832,
            current_a: 2.5,
            pwm_duty: 0.3,
            tau_cam_nm: 0.05,
            tau_rot_nm: 1.2,
            state: SupervisorState::Vibrating,
            faults: FaultFlags::empty(),
            status: StatusFlags::HOST_RELEASE,
            output_angle_rad: f32::NAN,
            output_speed_rad_s: f32::NAN,
        }
    }

    /// The JSON line's keys are the CSV's columns, less `cam_hz` (derived), plus `seq`:
    /// pinned, as readers of `--json` depend on them.
    #[test]
    fn json_keys_are_the_csv_columns_plus_seq() {
        let row = MonitorRow::new(&sample(), true, None);
        let json = serde_json::to_value(&row).unwrap();
        let mut keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        keys.sort_unstable();
        let mut want: Vec<&str> = CSV_HEADER
            .iter()
            .copied()
            .filter(|&c| c != "cam_hz")
            .chain(["seq"])
            .collect();
        want.sort_unstable();
        assert_eq!(keys, want);
        assert_eq!(json["tau_rot_nm"], 1.2);
        assert_eq!(json["seq"], 7);
        assert!(json["output_rad"].is_null() && json["bus_v"].is_null());
        let csv = row.csv_record();
        assert_eq!(csv[0], "1.500000");
        assert_eq!(csv[3], "10.0000");
        assert_eq!((csv[6].as_str(), csv[7].as_str()), ("0.050000", "1.20000"));
        assert_eq!(csv[10], "");
    }
}
