//! Test plans: TOML files in the format of `docs/plans.md`, read and written with the
//! `toml` crate (`rig experiment torque-sweep --plan` runs them, `rig explain --propose`
//! and `rig discover` write them, `rig compare` replays a measured file as one), the
//! paper's built-in plans, and their expansion into the runs of a sweep in the order they
//! are run. One plan type and one drive enum ([`DriveMode`]) for all of them.

use serde::{Deserialize, Serialize};

use crate::RigFileError;

/// How a plan drives the vibrator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum DriveMode {
    /// Open loop at a supply voltage (`volts`), as the paper's bench supply.
    #[default]
    OpenLoop,
    /// Closed loop at a vibration frequency (`hz`).
    ClosedLoop,
}

/// The order the runs are done in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Order {
    /// Shuffled with `seed`, as on a bench (drift does not line up with the load).
    #[default]
    Random,
    /// As the points are listed, repeats one after another.
    AsListed,
}

/// Longest duration, rest or window a plan gives, s (an hour): user seconds beyond it are
/// refused before anything moves, so no arithmetic on them can overflow.
pub const MAX_SECONDS: f64 = 3600.0;
/// Most repeats of one point.
pub const MAX_REPEATS: u32 = 1000;
/// Most runs a plan makes (points times repeats): the runs are listed before the first.
pub const MAX_RUNS: u64 = 100_000;
/// Most `[[points]]` tables.
pub const MAX_POINTS: usize = 10_000;
/// Highest open-loop supply a plan gives, V (twice the bridge's 12 V: the simulator's
/// limit; a device refuses more than its own).
pub const MAX_VOLTS: f64 = 24.0;
/// Heaviest load a plan gives, N m: twice the paper's largest (what the simulator
/// accepts).
pub fn max_load_nm() -> f64 {
    2.0 * model::paper::TAU_ROT_MAX
}

/// Highest vibration frequency a plan gives, Hz (a device refuses more than its own cap).
pub const MAX_HZ: f64 = 1000.0;

/// One test point of a plan.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanPoint {
    /// Load torque tau_rot hung on the output, N m (>= 0).
    pub load_nm: f64,
    /// Open-loop supply, V (mode = "open-loop").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub volts: Option<f64>,
    /// Vibration frequency, Hz (mode = "closed-loop").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hz: Option<f64>,
    /// Repeats of this point (overrides the plan's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub repeats: Option<u32>,
    /// Run time at the point, s (default: until the averaging window ends).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// Wait until the motor is at this temperature before the point (when sensed), deg C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temp_c: Option<f64>,
}

/// A test plan (the TOML file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// Free text, written into the CSV's provenance.
    #[serde(default)]
    pub name: String,
    /// Open or closed loop.
    #[serde(default)]
    pub mode: DriveMode,
    /// Default repeats per point.
    #[serde(default = "one")]
    pub repeats: u32,
    /// Run order.
    #[serde(default)]
    pub order: Order,
    /// Seed of the random order.
    #[serde(default = "one_u64")]
    pub seed: u64,
    /// Rest between points (motor off, gear locked), s.
    #[serde(default = "default_rest")]
    pub rest_s: f64,
    /// Averaging window from the start of constant cam rotation, s.
    #[serde(default = "default_window")]
    pub window_s: f64,
    /// Free text: why these points.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub reason: String,
    /// The points.
    pub points: Vec<PlanPoint>,
}

fn one() -> u32 {
    1
}
fn one_u64() -> u64 {
    1
}
fn default_rest() -> f64 {
    2.0
}
fn default_window() -> f64 {
    model::paper::CURRENT_AVERAGING_S
}

/// One run of a point: what the sweep does, in order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run {
    /// Position in the run order, 0-based (the CSV's `point` column; `--resume` skips the
    /// ones written).
    pub index: usize,
    /// Load torque, N m.
    pub load_nm: f64,
    /// Open-loop supply, V (open loop).
    pub volts: Option<f64>,
    /// Vibration frequency, Hz (closed loop).
    pub hz: Option<f64>,
    /// Repeat, 0-based.
    pub repeat: u32,
    /// Run time at the point, s.
    pub duration_s: Option<f64>,
    /// Temperature to wait for, deg C.
    pub temp_c: Option<f64>,
}

/// Lightest and heaviest load of the paper's sweep, N m (Figs. 8-9).
pub const SWEEP_LOADS_NM: (f64, f64) =
    (model::paper::TAU_ROT_MIN_TESTED, model::paper::TAU_ROT_MAX);

/// `levels` loads evenly from the lightest to the heaviest of [`SWEEP_LOADS_NM`], as a
/// person writes them (to the micro-newton-metre: 1.104, not 1.1039999999999999).
pub fn sweep_loads(levels: u32) -> Vec<f64> {
    let (lo, hi) = SWEEP_LOADS_NM;
    let steps = f64::from(levels.max(2) - 1);
    (0..levels.max(2))
        .map(|k| ((lo + (hi - lo) * f64::from(k) / steps) * 1e6).round() / 1e6)
        .collect()
}

/// The paper's loads: `levels` evenly from 0.368 to 3.68 N m.
pub fn paper_loads(levels: u32) -> Vec<f64> {
    sweep_loads(levels)
}

impl Plan {
    /// A grid plan: every load at every supply voltage, open loop.
    pub fn grid(name: &str, loads: &[f64], volts: &[f64], repeats: u32, rest_s: f64) -> Self {
        Self {
            name: name.into(),
            mode: DriveMode::OpenLoop,
            repeats,
            order: Order::Random,
            seed: 1,
            rest_s,
            window_s: model::paper::CURRENT_AVERAGING_S,
            reason: String::new(),
            points: volts
                .iter()
                .flat_map(|&v| {
                    loads.iter().map(move |&l| PlanPoint {
                        load_nm: l,
                        volts: Some(v),
                        hz: None,
                        repeats: None,
                        duration_s: None,
                        temp_c: None,
                    })
                })
                .collect(),
        }
    }

    /// The paper's required-torque test (Figs. 8-9): 10 loads from 0.368 to 3.68 N m at
    /// 3.6, 6.2 and 8.8 V, five repeats, random order: 150 runs.
    pub fn paper() -> Self {
        Self::grid(
            "paper: Figs. 8-9 (10 loads x 3 supply voltages x 5 repeats)",
            &paper_loads(10),
            &model::paper::SUPPLY_VOLTAGES,
            model::paper::REQUIRED_TORQUE_REPEATS,
            10.0,
        )
    }

    /// A short plan for a first try: 5 loads at the paper's 3 voltages, twice: 30 runs (a
    /// fifth of the paper's), enough for `rig explain` to name one missing effect.
    pub fn quick() -> Self {
        Self::grid(
            "quick: 5 loads x 3 supply voltages x 2 repeats",
            &paper_loads(5),
            &model::paper::SUPPLY_VOLTAGES,
            2,
            0.5,
        )
    }

    /// Reads and checks a plan file.
    pub fn read(path: &std::path::Path) -> Result<Self, RigFileError> {
        let text = crate::text_input::read_text(
            path,
            crate::text_input::MAX_PLAN_BYTES,
            "a plan file (TOML, docs/plans.md)",
        )
        .map_err(|why| RigFileError::BadValue {
            what: format!("plan file {}", path.display()),
            why,
        })?;
        Self::parse(&text, &path.display().to_string())
    }

    /// Parses and checks a plan; `name` names the file in errors.
    pub fn parse(text: &str, name: &str) -> Result<Self, RigFileError> {
        let plan: Plan = toml::from_str(text).map_err(|e| RigFileError::BadValue {
            what: format!("plan file {name}"),
            why: format!(
                "{} (the format is in docs/plans.md)",
                e.message().trim_end()
            ),
        })?;
        plan.check(name)?;
        Ok(plan)
    }

    /// Checks every value against its stated range ([`MAX_SECONDS`], [`MAX_REPEATS`],
    /// [`MAX_RUNS`]); errors name the key and what to give.
    pub fn check(&self, name: &str) -> Result<(), RigFileError> {
        let bad = |key: String, why: &str| RigFileError::BadValue {
            what: format!("plan {name}: {key}"),
            why: why.into(),
        };
        if self.points.is_empty() {
            return Err(bad("points".into(), "give at least one [[points]] table"));
        }
        let repeats_why = format!("must be 1 to {MAX_REPEATS}");
        let seconds_why = format!("must be a positive number of seconds, at most {MAX_SECONDS}");
        if !(1..=MAX_REPEATS).contains(&self.repeats) {
            return Err(bad("repeats".into(), &repeats_why));
        }
        if !(self.rest_s.is_finite() && (0.0..=MAX_SECONDS).contains(&self.rest_s)) {
            return Err(bad(
                "rest_s".into(),
                &format!("must be 0 to {MAX_SECONDS} seconds"),
            ));
        }
        if !(self.window_s.is_finite() && self.window_s > 0.0 && self.window_s <= MAX_SECONDS) {
            return Err(bad("window_s".into(), &seconds_why));
        }
        if self.points.len() > MAX_POINTS {
            return Err(bad(
                "points".into(),
                &format!("{} tables: give at most {MAX_POINTS}", self.points.len()),
            ));
        }
        for (k, p) in self.points.iter().enumerate() {
            let key = |field: &str| format!("points[{}].{field}", k + 1);
            if !(p.load_nm.is_finite() && (0.0..=max_load_nm()).contains(&p.load_nm)) {
                return Err(bad(
                    key("load_nm"),
                    &format!(
                        "must be 0 to {} N m (twice the teeth's rated torque)",
                        max_load_nm()
                    ),
                ));
            }
            match self.mode {
                DriveMode::OpenLoop => match p.volts {
                    Some(v) if v.is_finite() && v > 0.0 && v <= MAX_VOLTS => {}
                    Some(_) => {
                        return Err(bad(
                            key("volts"),
                            &format!("must be a positive voltage, at most {MAX_VOLTS} V"),
                        ));
                    }
                    None => {
                        return Err(bad(
                            key("volts"),
                            "is missing: an open-loop plan gives each point's supply voltage",
                        ));
                    }
                },
                DriveMode::ClosedLoop => match p.hz {
                    Some(v) if v.is_finite() && v > 0.0 && v <= MAX_HZ => {}
                    Some(_) => {
                        return Err(bad(
                            key("hz"),
                            &format!("must be a positive frequency, at most {MAX_HZ} Hz"),
                        ));
                    }
                    None => {
                        return Err(bad(
                            key("hz"),
                            "is missing: a closed-loop plan gives each point's vibration frequency",
                        ));
                    }
                },
            }
            if p.repeats.is_some_and(|r| !(1..=MAX_REPEATS).contains(&r)) {
                return Err(bad(key("repeats"), &repeats_why));
            }
            if p.duration_s
                .is_some_and(|d| !(d.is_finite() && d > 0.0 && d <= MAX_SECONDS))
            {
                return Err(bad(key("duration_s"), &seconds_why));
            }
            if p.temp_c
                .is_some_and(|t| !(t.is_finite() && t.abs() <= 1000.0))
            {
                return Err(bad(
                    key("temp_c"),
                    "must be a temperature in deg C (-1000 to 1000)",
                ));
            }
        }
        let runs: u64 = self
            .points
            .iter()
            .map(|p| u64::from(p.repeats.unwrap_or(self.repeats)))
            .sum();
        if runs > MAX_RUNS {
            return Err(bad(
                "repeats".into(),
                &format!(
                    "the plan makes {runs} runs: give at most {MAX_RUNS} (fewer points or repeats)"
                ),
            ));
        }
        Ok(())
    }

    /// The runs in the order they are done.
    pub fn runs(&self) -> Vec<Run> {
        let mut runs = Vec::new();
        let max_repeats = self
            .points
            .iter()
            .map(|p| p.repeats.unwrap_or(self.repeats))
            .max()
            .unwrap_or(1);
        // Repeat-major, as a bench does a whole pass before the next.
        for r in 0..max_repeats {
            for p in &self.points {
                if r < p.repeats.unwrap_or(self.repeats) {
                    runs.push(Run {
                        index: 0,
                        load_nm: p.load_nm,
                        volts: (self.mode == DriveMode::OpenLoop)
                            .then_some(p.volts)
                            .flatten(),
                        hz: (self.mode == DriveMode::ClosedLoop)
                            .then_some(p.hz)
                            .flatten(),
                        repeat: r,
                        duration_s: p.duration_s,
                        temp_c: p.temp_c,
                    });
                }
            }
        }
        if self.order == Order::Random {
            let mut rng = model::plant::NoiseSource::new(self.seed ^ 0x5eed);
            for i in (1..runs.len()).rev() {
                let j = (rng.next_u64() % (i as u64 + 1)) as usize;
                runs.swap(i, j);
            }
        }
        for (k, r) in runs.iter_mut().enumerate() {
            r.index = k;
        }
        runs
    }

    /// The plan file's text (docs/plans.md), as the `toml` crate writes it; [`Plan::parse`]
    /// reads it back.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// The plan as one line of JSON, for the CSV's provenance (and `--resume`'s check that
    /// the plan is the same).
    pub fn one_line(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_plan_has_150_runs_in_a_seeded_random_order() {
        let plan = Plan::paper();
        let runs = plan.runs();
        assert_eq!(runs.len(), 150);
        assert_eq!(runs, plan.runs());
        assert!(
            runs.iter()
                .any(|r| r.load_nm == 0.368 && r.volts == Some(3.6))
        );
        assert!(
            runs.iter()
                .any(|r| r.load_nm == 3.68 && r.volts == Some(8.8))
        );
        let as_listed: Vec<_> = runs.iter().map(|r| (r.load_nm, r.volts)).collect();
        let mut sorted = as_listed.clone();
        sorted.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_ne!(as_listed, sorted, "the order is shuffled");
        assert_eq!(Plan::quick().runs().len(), 30);
    }

    #[test]
    fn the_shared_format_parses_with_defaults_and_overrides() {
        let text = r#"
name = "proposed by rig explain"
mode = "open-loop"
repeats = 1
order = "as-listed"
seed = 1
rest_s = 2.0
window_s = 0.5
reason = "separates A from B"

[[points]]
load_nm = 0.368
volts = 3.6
repeats = 5
duration_s = 3.0
temp_c = 40.0

[[points]]
load_nm = 1.0
volts = 6.2
"#;
        let plan = Plan::parse(text, "p.toml").unwrap();
        let runs = plan.runs();
        assert_eq!(runs.len(), 6);
        assert_eq!(runs[0].duration_s, Some(3.0));
        assert_eq!(runs[1].volts, Some(6.2));
        let minimal = Plan::parse("[[points]]\nload_nm = 1\nvolts = 3.6\n", "m").unwrap();
        assert_eq!(minimal.order, Order::Random);
        assert_eq!(minimal.window_s, 0.5);
    }

    /// What [`Plan::to_toml`] writes, [`Plan::parse`] reads back unchanged, for both drives.
    #[test]
    fn written_plans_read_back() {
        let mut plan = Plan::quick();
        plan.reason = "a \"quoted\" reason".into();
        plan.points[0].temp_c = Some(40.0);
        plan.points[1].duration_s = Some(3.0);
        assert_eq!(Plan::parse(&plan.to_toml(), "q").unwrap(), plan);
        plan.mode = DriveMode::ClosedLoop;
        for p in &mut plan.points {
            p.hz = p.volts.take().map(|v| v * 1.5);
        }
        assert_eq!(Plan::parse(&plan.to_toml(), "q").unwrap(), plan);
    }

    #[test]
    fn bad_plans_name_the_key() {
        for (text, want) in [
            ("name = \"x\"\n", "points"),
            ("[[points]]\nload_nm = 1\n", "points[1].volts"),
            ("[[points]]\nload_nm = -1\nvolts = 3\n", "points[1].load_nm"),
            (
                "mode = \"closed-loop\"\n[[points]]\nload_nm = 1\nvolts = 3\n",
                "points[1].hz",
            ),
            ("[[points]]\nload_nm = 1\nvolt = 3\n", "volt"),
            (
                "rest_s = -1\n[[points]]\nload_nm = 1\nvolts = 3\n",
                "rest_s",
            ),
        ] {
            let e = Plan::parse(text, "p.toml").unwrap_err().to_string();
            assert!(e.contains(want), "{text}: {e}");
        }
    }
}
