//! Units and sanity of `rig explain`'s input (issue 19, item 6 and the bounded reads): loads in
//! N mm and cam speeds in Hz are refused naming the column and the probable unit; repeated
//! rows and time stamps are reported; a file without line ends, a pipe and a huge header are
//! refused after a bounded read without echoing the file back; user effects have stated
//! limits.

use std::io::Write as _;

use explain::synth::{self, BenchSchedule, Conditions, SweepPlan};
use explain::{self, Dataset, ExplainError, MeasuredRow, Options, Verdict};
use model::effects::{CurrentModel, Effect};
use model::plant::NoiseSource;
use rigfile::RigFile;

fn sweep(seed: u64) -> Vec<MeasuredRow> {
    let model = RigFile::paper().current_model().unwrap();
    synth::generate(
        &model,
        &SweepPlan {
            noise_a: 0.01,
            ..SweepPlan::default()
        },
        seed,
    )
}

fn explain_rows(rows: Vec<MeasuredRow>) -> Result<explain::Explanation, ExplainError> {
    let data = Dataset::from_rows("units.csv", rows)?;
    let options = Options {
        replicates: 0,
        ..Options::default()
    };
    explain::explain(&data, &RigFile::paper(), &options).map(|o| o.explanation)
}

#[test]
fn loads_in_n_mm_are_refused_naming_the_column_and_the_unit() {
    let rows: Vec<MeasuredRow> = sweep(1)
        .into_iter()
        .map(|r| MeasuredRow {
            tau_rot: r.tau_rot * 1e3,
            ..r
        })
        .collect();
    let err = explain_rows(rows).unwrap_err().to_string();
    assert!(err.contains("tau_rot_nm") && err.contains("N mm"), "{err}");
    assert!(err.contains("divide the column by 1000"), "{err}");
}

#[test]
fn cam_speeds_in_hz_are_refused_naming_the_column_and_the_unit() {
    let rows: Vec<MeasuredRow> = sweep(2)
        .into_iter()
        .map(|r| MeasuredRow {
            omega_n: r.omega_n / std::f64::consts::TAU,
            ..r
        })
        .collect();
    let err = explain_rows(rows).unwrap_err().to_string();
    assert!(err.contains("omega_n_rad_s") && err.contains("Hz"), "{err}");
    assert!(err.contains("2 pi"), "{err}");
}

#[test]
fn data_in_si_units_passes_the_unit_screen() {
    for seed in 3..6 {
        let e = explain_rows(sweep(seed)).unwrap();
        assert_eq!(e.verdict, Verdict::NoMissingEffect, "{}", e.finding);
    }
}

#[test]
fn repeated_rows_and_time_stamps_are_reported() {
    let mut rows = sweep(7);
    let copies: Vec<MeasuredRow> = rows[10..14].to_vec();
    rows.extend(copies);
    let e = explain_rows(rows).unwrap();
    assert!(
        e.warnings
            .iter()
            .any(|w| w.starts_with("4 of 154 rows repeat an earlier row")),
        "{:?}",
        e.warnings
    );
    let mut rows = sweep(8);
    rows[20].t_s = rows[19].t_s;
    let e = explain_rows(rows).unwrap();
    assert!(
        e.warnings.iter().any(|w| w.contains("share their t_s")),
        "{:?}",
        e.warnings
    );
}

#[test]
fn a_file_without_line_ends_is_refused_after_a_bounded_read() {
    let dir = tempfile::tempdir().unwrap();
    // 8 MiB of zeros, as /dev/zero or a sparse file gives (the read stops at 64 KiB).
    let zeros = dir.path().join("zeros.csv");
    std::fs::File::create(&zeros)
        .unwrap()
        .set_len(8 << 20)
        .unwrap();
    let err = Dataset::read_csv(&zeros).unwrap_err().to_string();
    assert!(err.contains("longer than 64 KiB"), "{err}");
    assert!(err.len() < 400, "{err}");
    // A 2 MB header of unknown columns: refused without echoing it.
    let wide = dir.path().join("wide.csv");
    let mut f = std::fs::File::create(&wide).unwrap();
    let header: Vec<String> = (0..200_000).map(|k| format!("c{k}")).collect();
    writeln!(f, "{}", header.join(",")).unwrap();
    drop(f);
    let err = Dataset::read_csv(&wide).unwrap_err().to_string();
    assert!(
        err.len() < 400,
        "{} bytes: {}",
        err.len(),
        &err[..400.min(err.len())]
    );
    // A long header within the limit: the list of columns found is cut.
    let long = dir.path().join("long.csv");
    let mut f = std::fs::File::create(&long).unwrap();
    let header: Vec<String> = (0..3_000).map(|k| format!("c{k}")).collect();
    writeln!(f, "{}", header.join(",")).unwrap();
    writeln!(f, "{}", vec!["1"; 3_000].join(",")).unwrap();
    drop(f);
    let err = Dataset::read_csv(&long).unwrap_err().to_string();
    assert!(err.contains("omega_n_rad_s"), "{err}");
    assert!(
        err.contains("more bytes not shown") && err.len() < 800,
        "{err}"
    );
}

/// The issue's own cases: a 20 GiB file of zeros (`truncate -s 20G`), as a measured file and
/// as a rig file, is refused after a bounded read; a huge field is not echoed back whole.
#[test]
fn a_20_gib_file_and_a_huge_field_are_refused_without_echo() {
    let dir = tempfile::tempdir().unwrap();
    let huge = dir.path().join("x.csv");
    let file = std::fs::File::create(&huge).unwrap();
    if file.set_len(20 << 30).is_ok() {
        drop(file);
        let err = Dataset::read_csv(&huge).unwrap_err().to_string();
        assert!(err.contains("longer than 64 KiB"), "{err}");
        assert!(err.len() < 400, "{err}");
        let err = RigFile::load(&huge).unwrap_err().to_string();
        assert!(err.contains("more than the"), "{err}");
    }
    // A 60 KiB number in a row: the message shows its start only.
    let long = dir.path().join("long-field.csv");
    let mut text = String::from("omega_n_rad_s,tau_rot_nm,i_in_a\n");
    for k in 0..12 {
        text += &format!("31.4,{},2.5\n", 0.3 * (k + 1) as f64);
    }
    text += &format!("31.4,1.0,{}x\n", "7".repeat(60 << 10));
    std::fs::write(&long, text).unwrap();
    let err = Dataset::read_csv(&long).unwrap_err().to_string();
    assert!(err.contains("row 13") && err.contains("i_in_a"), "{err}");
    assert!(err.len() < 400, "{} bytes", err.len());
}

#[cfg(unix)]
#[test]
fn a_pipe_or_a_folder_is_refused_without_reading() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.csv");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .map(|s| s.success())
        .unwrap_or(false);
    if made {
        // Opening a FIFO without a writer would block: the refusal comes first.
        let err = Dataset::read_csv(&fifo).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        let err = RigFile::load(&fifo).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
    }
    let err = Dataset::read_csv(dir.path()).unwrap_err().to_string();
    assert!(err.contains("not a regular file"), "{err}");
}

#[test]
fn user_effects_have_stated_limits_on_size_and_count() {
    let long = "w * a".repeat(300);
    let text = format!(
        "[[user_effects]]\nname = \"big\"\nexpression = \"{long}\"\n[user_effects.params.a]\nunit = \"A\"\nbounds = [-1.0, 1.0]\nnull = 0.0\n"
    );
    let err = RigFile::parse(&text, "big.toml").unwrap_err().to_string();
    assert!(err.contains("at most 1024"), "{err}");
    let many: String = (0..20)
        .map(|k| {
            format!(
                "[[user_effects]]\nname = \"u{k}\"\nexpression = \"a * w\"\n[user_effects.params.a]\nunit = \"A\"\nbounds = [-1.0, 1.0]\nnull = 0.0\n"
            )
        })
        .collect();
    let err = RigFile::parse(&many, "many.toml").unwrap_err().to_string();
    assert!(err.contains("at most 16"), "{err}");
}

/// Rigs across the paper's Table 1 gear sets, strokes of 0.5-1.5 mm and carriers of
/// 2-6 kg.
fn screen_rigs() -> Vec<RigFile> {
    let cams = [(1.0, 3.82), (0.5, 2.0), (1.2, 4.2), (1.5, 6.0), (0.8, 3.0)];
    let mut rigs = Vec::new();
    for (g, z) in model::paper::TABLE1.iter().enumerate() {
        for (c, (e, m)) in cams.iter().enumerate() {
            if (g + c) % 2 == 0 {
                let text = format!(
                    "[gear]\nz = [{}, {}, {}, {}]\n[cam]\neccentricity_mm = {e}\ncarrier_mass_kg = {m}\n",
                    z[0], z[1], z[2], z[3]
                );
                rigs.push(RigFile::parse(&text, "screen.toml").unwrap());
            }
        }
    }
    rigs
}

/// Plans over the voltages the vibrator runs at (2.4-11 V) and light to full loads, with
/// and without the `v_in_v` column.
fn screen_plans() -> Vec<SweepPlan> {
    let plan = |voltages: &[f64], loads: &[f64], with_voltage: bool, noise_a: f64| SweepPlan {
        loads_nm: loads.to_vec(),
        voltages_v: voltages.to_vec(),
        repeats: 3,
        noise_a,
        with_voltage,
        ..SweepPlan::default()
    };
    let paper_loads: Vec<f64> = (1..=10).map(|k| 0.368 * k as f64).collect();
    let light: Vec<f64> = (1..=6).map(|k| 0.1 * k as f64).collect();
    vec![
        plan(&[3.6, 6.2, 8.8], &paper_loads, true, 0.003),
        plan(&[3.6, 6.2, 8.8], &paper_loads, false, 0.02),
        plan(&[2.4, 3.0, 3.6, 4.2], &light, true, 0.04),
        plan(&[2.4, 3.0, 3.6, 4.2], &paper_loads, false, 0.01),
        plan(&[7.0, 9.0, 11.0], &light, false, 0.003),
        plan(&[3.6, 4.9, 6.2, 7.5, 8.8], &light, true, 0.02),
    ]
}

/// What the rigs' data hide: nothing, each library effect, and currents in no library law
/// that bend the current's dependence on load (a saturating sensor, a quadratic sensor
/// nonlinearity, a resonance at the middle speed).
#[derive(Debug, Clone, Copy)]
enum Truth {
    None,
    Library(Effect),
    SaturatingSensor,
    SensorNonlinearity,
    Resonance,
}

fn screen_truths() -> Vec<Truth> {
    let mut t = vec![
        Truth::None,
        Truth::SaturatingSensor,
        Truth::SensorNonlinearity,
        Truth::Resonance,
    ];
    t.extend(Effect::ALL.map(Truth::Library));
    t
}

fn screen_rows(rig: &RigFile, truth: Truth, plan: &SweepPlan, seed: u64) -> Vec<MeasuredRow> {
    let mut model = rig.current_model().unwrap();
    let mut rng = NoiseSource::new(seed ^ 0x5c7e_e019);
    if let Truth::Library(e) = truth {
        model.effects = synth::plausible_effect(e, &model, plan, &mut rng);
    }
    let w_mid = synth::nominal_cam_speed(plan.voltages_v[plan.voltages_v.len() / 2]);
    let size = 0.1 + 0.2 * rng.uniform();
    let extra = move |m: &CurrentModel, c: &Conditions| -> f64 {
        let i = m.current(&c.op);
        match truth {
            Truth::SaturatingSensor => {
                let i_sat = 2.5 + 5.0 * size;
                i_sat * (i / i_sat).tanh() - i
            }
            Truth::SensorNonlinearity => size * (i - 2.8) * (i - 2.8),
            Truth::Resonance => {
                let x = (c.op.omega_n - w_mid) / (0.05 * w_mid);
                size * (-x * x).exp()
            }
            Truth::None | Truth::Library(_) => 0.0,
        }
    };
    synth::generate_session(&model, plan, &BenchSchedule::default(), seed, Some(&extra))
}

/// A unit slip: its name, how it changes a row, and the words its refusal must carry.
type WrongUnit<'a> = (&'a str, &'a dyn Fn(&mut MeasuredRow), &'a [&'a str]);

/// The unit screen as `rig explain` runs it: the range rules, then the fit and magnitude
/// screen.
fn screen(rig: &RigFile, rows: Vec<MeasuredRow>) -> Result<(), String> {
    let data = Dataset::from_rows("screen.csv", rows).unwrap();
    let start = rig.current_model().unwrap();
    let checked = explain::robust::range_check(&data).map_err(|e| e.to_string())?;
    explain::robust::unit_check(&data, &checked.excluded, &start).map_err(|e| e.to_string())
}

/// Issue 19 item 6 across rigs: data in the header's units passes the unit screen on every
/// rig, plan and truth, also with the bridge supply logged as `v_in_v` (a false refusal on
/// gears (49, 51, 48, 52) with a 1.2 mm stroke and a 4.2 kg carrier was once seen), and
/// loads in N mm, cam speeds in rpm and currents in mA are refused on every one, naming the
/// column and the probable unit; so are cam speeds in Hz wherever a `v_in_v` column gives
/// the motor's voltage (without it, the fit alone finds more than half of them).
#[test]
fn the_unit_screen_is_right_both_ways_on_every_rig() {
    let rigs = screen_rigs();
    let plans = screen_plans();
    let truths = screen_truths();
    let mut sets = 0;
    let mut failures = Vec::new();
    // Hz columns without a v_in_v column: (caught, sets).
    let mut hz_unvoiced = (0, 0);
    for (r, rig) in rigs.iter().enumerate() {
        for (p, plan) in plans.iter().enumerate() {
            // Every truth on every rig and plan would be 2,000 sets; a rotating share keeps
            // each rig, plan and truth in the run.
            for (t, &truth) in truths.iter().enumerate() {
                if (r + p + t) % 4 != 0 {
                    continue;
                }
                sets += 1;
                let seed = 19_000 + 100 * r as u64 + 10 * p as u64 + t as u64;
                let rows = screen_rows(rig, truth, plan, seed);
                let case = format!("rig {r} ({:?}), plan {p}, {truth:?}", rig.gear.z);
                if let Err(e) = screen(rig, rows.clone()) {
                    failures.push(format!("{case}: data in the header's units refused: {e}"));
                }
                // The bridge supply logged as v_in_v says nothing on the speed.
                let mut supply = rows.clone();
                for row in &mut supply {
                    row.v_in = row.v_in.map(|_| model::hardware::board::BRIDGE_SUPPLY_V);
                }
                if let Err(e) = screen(rig, supply) {
                    failures.push(format!("{case}: v_in_v = the supply: refused: {e}"));
                }
                let scaled = |f: &dyn Fn(&mut MeasuredRow)| {
                    let mut v = rows.clone();
                    v.iter_mut().for_each(f);
                    screen(rig, v)
                };
                let wrong: [WrongUnit; 4] = [
                    ("N mm", &|row| row.tau_rot *= 1e3, &["tau_rot_nm", "N mm"]),
                    (
                        "Hz",
                        &|row| row.omega_n /= std::f64::consts::TAU,
                        &["omega_n_rad_s", "Hz"],
                    ),
                    (
                        "rpm",
                        &|row| row.omega_n *= 60.0 / std::f64::consts::TAU,
                        &["omega_n_rad_s", "rpm"],
                    ),
                    (
                        "mA",
                        &|row| row.i_in = row.i_in.map(|i| i * 1e3),
                        &["i_in_a", "mA"],
                    ),
                ];
                for (unit, change, words) in wrong {
                    let voltage = plan.with_voltage;
                    match scaled(change) {
                        // Without a voltage a Hz column rests on the fit (counted below).
                        Ok(()) if unit == "Hz" && !voltage => hz_unvoiced.1 += 1,
                        Ok(()) => failures.push(format!("{case}: data in {unit} passed")),
                        Err(e) if !words.iter().all(|w| e.contains(w)) => {
                            failures.push(format!("{case}, {unit}: {e}"))
                        }
                        Err(_) if unit == "Hz" && !voltage => {
                            hz_unvoiced.0 += 1;
                            hz_unvoiced.1 += 1;
                        }
                        Err(_) => {}
                    }
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {sets} sets:\n{}",
        failures.len(),
        failures.join("\n")
    );
    assert!(sets >= 150, "{sets}");
    // Measured: 84 of 146; a floor against a screen that stops seeing them.
    assert!(
        2 * hz_unvoiced.0 > hz_unvoiced.1,
        "Hz without v_in_v caught in {} of {}",
        hz_unvoiced.0,
        hz_unvoiced.1
    );
}
