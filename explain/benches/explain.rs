//! `rig explain` speed: the whole analysis (CSV parsing, outlier screening, base fit, every
//! candidate, the null simulation of the guard, held-out validation, the block bootstrap of
//! the selection, the gap tables) on the paper's 150-row sweep, 1e5 rows and 1e6 rows, and
//! the 150-row sweep against a rig file at its user-effect limits (16 `[[user_effects]]` of
//! nearly 1 KiB each, every one a candidate of every step and bootstrap replicate).
//! Targets: 1e5 rows in under 0.3 s, 1e6 rows in under 2 s (and 200 MB: measure with
//! `/usr/bin/time -v rig explain --measured BIG.csv --json --no-report`, BIG.csv from
//! `rig explain --synthetic speed-dependent-axial-friction --repeats 33334 --save-data BIG.csv`).
//!
//! ```sh
//! cargo bench -p explain --bench explain
//! ```

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use explain::synth::{self, SweepPlan};
use explain::{Dataset, Options, explain};
use rigfile::RigFile;

/// A synthetic sweep with a hidden speed-dependent axial friction, as CSV bytes.
fn sweep_csv(repeats: usize) -> Vec<u8> {
    let rig = RigFile::paper();
    let mut truth = rig.current_model().expect("the paper's rig is valid");
    truth.effects.axial_corner_speed = 20.0;
    let plan = SweepPlan {
        repeats,
        test_seconds: (0.5, 1.5),
        ..SweepPlan::default()
    };
    let rows = synth::generate(&truth, &plan, 7);
    let data = Dataset::from_rows("bench.csv", rows).expect("valid rows");
    let mut out = Vec::new();
    data.write_csv(&mut out).expect("in memory");
    out
}

/// A rig file at the user-effect limits: [`rigfile::MAX_USER_EFFECTS`] entries, each an
/// expression just under the 1 KiB limit (a sum of load, speed and sine terms).
fn user_effect_rig() -> RigFile {
    let mut text = String::new();
    for k in 0..rigfile::MAX_USER_EFFECTS {
        let mut e = format!("c{k} * (w / 60");
        let mut j = 0;
        while e.len() < 960 {
            e.push_str(&format!(
                " + {:.3} * tau * w / 600 - sin(w / {}) * 0.001",
                0.001 * (j + k) as f64,
                50 + j
            ));
            j += 1;
        }
        e.push(')');
        text.push_str(&format!(
            "[[user_effects]]\nname = \"u{k}\"\nexpression = \"{e}\"\nparams = {{ c{k} = {{ unit = \"A\", bounds = [-0.5, 0.5] }} }}\n\n"
        ));
    }
    RigFile::parse(&text, "user-effects.toml").expect("inside the user-effect limits")
}

fn bench(c: &mut Criterion) {
    let rig = RigFile::paper();
    let options = Options::default();
    let mut group = c.benchmark_group("explain");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(20));
    for (name, repeats) in [
        ("paper_sweep_150_rows", 5),
        ("rows_1e5", 3334),
        ("rows_1e6", 33334),
    ] {
        let csv = sweep_csv(repeats);
        group.bench_function(name, |b| {
            b.iter(|| {
                let data =
                    Dataset::parse_csv(black_box(csv.as_slice()), "bench.csv").expect("parses");
                let outcome = explain(&data, &rig, &options).expect("explains");
                black_box(outcome.explanation.verdict)
            })
        });
    }
    let csv = sweep_csv(5);
    let users = user_effect_rig();
    group.bench_function("paper_sweep_150_rows_16_user_effects_1k", |b| {
        b.iter(|| {
            let data = Dataset::parse_csv(black_box(csv.as_slice()), "bench.csv").expect("parses");
            let outcome = explain(&data, &users, &options).expect("explains");
            black_box(outcome.explanation.verdict)
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
