//! Project automation. `cargo xtask test` runs every check CI runs:
//! installs the thumb target when missing, cross-builds the firmware and prints its flash
//! and RAM use, checks `model` and `protocol` for the target, then fmt, clippy (warnings
//! denied), docs (warnings denied), every host test, and a 10 s smoke run of each fuzz target
//! in `fuzz/` when a nightly toolchain and cargo-fuzz are installed. `cargo xtask
//! target-bench` counts the control core's cycles in an emulated Cortex-M4F (see
//! `target_bench`); `test` runs it with `--check` right after the firmware build (skipped
//! with a message only when its Python packages cannot be installed).

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

mod size;
mod target_bench;

/// The firmware's target.
const THUMB: &str = "thumbv7em-none-eabihf";
use size::{FLASH_BUDGET, FLASH_CEILING, RAM_BUDGET};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(),
        Some("firmware") => firmware().map(|_| ()),
        Some("setup") => setup(),
        Some("fuzz") => fuzz_smoke(),
        Some("target-bench") => target_bench(&args[1..]),
        _ => {
            eprintln!(
                "usage: cargo xtask <task>\n\n  test          every check CI runs (setup, firmware build + size, target bench --check, thumb checks, fmt, clippy, docs, tests, fuzz smoke)\n  firmware      cross-build the release firmware and print its flash/RAM use\n  setup         install the thumb target and the rustfmt/clippy components when missing\n  fuzz          the fuzz smoke run alone (10 s per target in fuzz/; needs nightly and cargo-fuzz)\n  target-bench  the control core's cycles in an emulated Cortex-M4F [--json] [--check: fail over budget]"
            );
            Err("no task given".into())
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

type Result<T = ()> = std::result::Result<T, String>;

/// The workspace root: the parent of this crate's folder, as `cargo run` reports it at run
/// time (a path baked in at compile time goes stale when the target folder is shared).
fn root() -> PathBuf {
    let manifest = std::env::var_os("CARGO_MANIFEST_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    manifest.parent().map(Path::to_path_buf).unwrap_or(manifest)
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

fn run(step: &str, mut cmd: Command) -> Result {
    eprintln!("\n==> {step}");
    let status = cmd
        .status()
        .map_err(|e| format!("{step}: cannot start: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{step} failed ({status})"))
    }
}

fn rustup_output(args: &[&str]) -> Result<String> {
    let out = Command::new("rustup")
        .args(args)
        .output()
        .map_err(|e| format!("rustup not found ({e}); install rustup first"))?;
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Installs the thumb target and rustfmt/clippy when missing (retrying once, as downloads can fail).
fn setup() -> Result {
    let installed = rustup_output(&["target", "list", "--installed"])?;
    if !installed.lines().any(|l| l.trim() == THUMB) {
        let add = || {
            Command::new("rustup")
                .args(["target", "add", THUMB])
                .status()
                .map(|s| s.success())
                .unwrap_or(false)
        };
        eprintln!("==> installing the {THUMB} target");
        if !add() && !add() {
            return Err(format!(
                "`rustup target add {THUMB}` failed twice; check the network and retry"
            ));
        }
    }
    let components = rustup_output(&["component", "list", "--installed"])?;
    for comp in ["rustfmt", "clippy"] {
        if !components.lines().any(|l| l.starts_with(comp)) {
            run(&format!("installing {comp}"), {
                let mut c = Command::new("rustup");
                c.args(["component", "add", comp]);
                c
            })?;
        }
    }
    Ok(())
}

/// Where the release firmware ELF is built.
fn firmware_elf() -> PathBuf {
    target_dir().join(THUMB).join("release").join("firmware")
}

/// The cargo target folder.
fn target_dir() -> PathBuf {
    std::env::var("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root().join("target"))
}

/// Builds `package`'s binary of the same name for the thumb target (release) and returns
/// the ELF's path.
fn thumb_release_build(package: &str) -> Result<PathBuf> {
    run(&format!("{package} release build ({THUMB})"), {
        let mut c = cargo();
        c.args([
            "build",
            "--package",
            package,
            "--release",
            "--target",
            THUMB,
        ]);
        c
    })?;
    Ok(target_dir().join(THUMB).join("release").join(package))
}

/// Builds the release firmware and prints (and checks) its flash and RAM use.
fn firmware() -> Result<size::Usage> {
    let elf = thumb_release_build("firmware")?;
    let usage = size::measure(&elf)?;
    println!(
        "firmware size: flash {} B ({:.1} KiB of {} KiB budget), static RAM {} B ({:.1} KiB of {} KiB budget)",
        usage.flash,
        usage.flash as f64 / 1024.0,
        FLASH_BUDGET / 1024,
        usage.ram,
        usage.ram as f64 / 1024.0,
        RAM_BUDGET / 1024
    );
    if usage.flash > FLASH_CEILING || usage.ram > RAM_BUDGET {
        return Err(format!(
            "firmware exceeds its flash ceiling ({FLASH_CEILING} B) or RAM budget"
        ));
    }
    if usage.flash > FLASH_BUDGET {
        println!(
            "firmware size: WARNING flash {} B is over the {} KiB budget (issue 11, open); CI fails above {} B",
            usage.flash,
            FLASH_BUDGET / 1024,
            FLASH_CEILING
        );
    }
    Ok(usage)
}

/// `cargo xtask target-bench [--json] [--check]`: builds the firmware (for its size) and
/// the bench image, runs the image in the emulator and prints the figures.
fn target_bench(args: &[String]) -> Result {
    let options = target_bench::Options::parse(args)?;
    setup()?;
    let firmware_elf = thumb_release_build("firmware")?;
    let python = target_bench::python_env(&target_dir())?;
    bench_run(options, &firmware_elf, &python)
}

/// The emulator run of `target_bench`, the firmware already built.
fn bench_run(options: target_bench::Options, firmware_elf: &Path, python: &Path) -> Result {
    let usage = size::measure(firmware_elf)?;
    let board = root().join("firmware").join("src").join("board.rs");
    let board = std::fs::read_to_string(&board)
        .map_err(|e| format!("cannot read {}: {e}", board.display()))?;
    let enable = target_bench::bridge_enable_bsrr(&board)?;
    let image = thumb_release_build("firmware-bench")?;
    let driver = root().join("xtask").join("target_bench").join("driver.py");
    let output = target_bench::run_driver(python, &driver, &image, Some((firmware_elf, enable)))?;
    let result = target_bench::result(&output, usage, &image)?;
    if options.json {
        println!("{result}");
    } else {
        print!("{}", target_bench::table(&result));
    }
    // Flash over its budget but within the ceiling is reported (`over_budget`), not failed
    // ([`size::FLASH_CEILING`]).
    let over: Vec<_> = target_bench::over_budget(&result)
        .into_iter()
        .filter(|&(key, v, _)| key != "flash_bytes" || v > FLASH_CEILING)
        .collect();
    if options.check && !over.is_empty() {
        let list: Vec<String> = over
            .iter()
            .map(|(k, v, limit)| format!("{k} {v} > {limit}"))
            .collect();
        return Err(format!("over budget: {}", list.join(", ")));
    }
    Ok(())
}

/// CI's target bench (`target-bench --check`) after the firmware build; skipped, saying
/// why, only when the emulator's Python packages cannot be installed (no python3, no venv
/// module, no network for pip).
fn bench_check() -> Result {
    let python = match target_bench::python_env(&target_dir()) {
        Ok(python) => python,
        Err(e) => {
            println!("target bench: SKIPPED, the emulator cannot be installed: {e}");
            return Ok(());
        }
    };
    eprintln!("\n==> target bench (--check)");
    let options = target_bench::Options {
        json: false,
        check: true,
    };
    bench_run(options, &firmware_elf(), &python)
}

fn test() -> Result {
    setup()?;
    run("rustfmt check", {
        let mut c = cargo();
        c.args(["fmt", "--all", "--", "--check"]);
        c
    })?;
    firmware()?;
    bench_check()?;
    run(
        "model, protocol and firmware-core build for the thumb target",
        {
            let mut c = cargo();
            c.args([
                "build",
                "--package",
                "model",
                "--package",
                "protocol",
                "--package",
                "firmware-core",
                "--target",
                THUMB,
            ]);
            c
        },
    )?;
    run("clippy, firmware on the thumb target", {
        let mut c = cargo();
        c.args([
            "clippy",
            "--package",
            "firmware",
            "--release",
            "--target",
            THUMB,
            "--",
            "-D",
            "warnings",
        ]);
        c
    })?;
    run("clippy, whole workspace on the host", {
        let mut c = cargo();
        c.args([
            "clippy",
            "--workspace",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ]);
        c
    })?;
    run("docs, warnings denied", {
        let mut c = cargo();
        c.args(["doc", "--workspace", "--no-deps"]);
        c.env("RUSTDOCFLAGS", "-D warnings");
        c
    })?;
    run("tests", {
        let mut c = cargo();
        c.args(["test", "--workspace"]);
        // The host's `rig flash` tests check the image built above.
        c.env("RIG_FIRMWARE_ELF", firmware_elf());
        c
    })?;
    fuzz_smoke()
}

/// The fuzz targets in `fuzz/`, one per decoder.
const FUZZ_TARGETS: [&str; 4] = ["frame", "flash_record", "rig_file", "measured_csv"];
/// How long the smoke run fuzzes each target, s.
const FUZZ_SECONDS: u32 = 10;

/// `cargo` through the rustup proxy (so `+nightly` works), without the variables the outer
/// stable cargo set for this process (`$CARGO` names the stable binary itself).
fn rustup_cargo() -> Command {
    let mut c = Command::new("cargo");
    c.current_dir(root());
    for var in [
        "CARGO",
        "RUSTUP_TOOLCHAIN",
        "RUSTC",
        "RUSTDOC",
        "CARGO_TARGET_DIR",
    ] {
        c.env_remove(var);
    }
    c
}

/// A short run of every fuzz target (`cargo +nightly fuzz`), when a nightly toolchain and
/// cargo-fuzz are installed; CI without them skips it.
fn fuzz_smoke() -> Result {
    // The fuzz crate is its own workspace: type-check its targets on the stable toolchain so an
    // API change in the crates they drive fails here, nightly or not.
    run("fuzz targets type-check (stable)", {
        let mut c = cargo();
        c.args(["check", "--manifest-path", "fuzz/Cargo.toml", "--bins"]);
        c.env("CARGO_TARGET_DIR", target_dir().join("fuzz-check"));
        c
    })?;
    let works = |args: &[&str]| {
        rustup_cargo()
            .args(args)
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
    };
    if !(works(&["+nightly", "--version"]) && works(&["+nightly", "fuzz", "--version"])) {
        println!("fuzz smoke: skipped (no nightly toolchain / cargo-fuzz)");
        return Ok(());
    }
    for target in FUZZ_TARGETS {
        // New inputs go to the (ignored) corpus folder; the checked-in seeds are read only.
        let corpus = root().join("fuzz").join("corpus").join(target);
        std::fs::create_dir_all(&corpus)
            .map_err(|e| format!("cannot create {}: {e}", corpus.display()))?;
        run(&format!("fuzz smoke: {target}, {FUZZ_SECONDS} s"), {
            let mut c = rustup_cargo();
            c.args(["+nightly", "fuzz", "run", "-O", target]);
            c.arg(&corpus);
            let seeds = root().join("fuzz").join("seeds").join(target);
            if seeds.is_dir() {
                c.arg(seeds);
            }
            c.args(["--", &format!("-max_total_time={FUZZ_SECONDS}")]);
            c
        })?;
    }
    Ok(())
}
