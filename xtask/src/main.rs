//! Project automation. `cargo xtask test` runs every check CI runs:
//! installs the thumb target when missing, cross-builds the firmware and prints its flash
//! and RAM use, checks `model` and `protocol` for the target, then fmt, clippy (warnings
//! denied), docs (warnings denied), every host test, and a 10 s smoke run of each fuzz target
//! in `fuzz/` when a nightly toolchain and cargo-fuzz are installed. `cargo xtask
//! target-bench` counts the control core's cycles in an emulated Cortex-M4F (see
//! `target_bench`); `test` runs it with `--check` right after the firmware build (skipped
//! with a message only when its Python packages cannot be installed). `cargo xtask python`
//! builds the `backdrive_rig` wheel, installs it in a fresh virtual environment and runs its
//! pytest suite and the example notebook (`python`); `test` runs it last.

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

mod python;
mod size;
mod target_bench;

/// The firmware's target.
const THUMB: &str = "thumbv7em-none-eabihf";
use size::{FLASH_BUDGET, RAM_BUDGET};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(),
        Some("firmware") => firmware_task(&args[1..]),
        Some("flash") => flash(),
        Some("setup") => setup().and_then(|()| setup_emulator()),
        Some("fuzz") => fuzz_smoke(),
        Some("target-bench") => target_bench(&args[1..]),
        Some("python") => python_task(true),
        _ => {
            eprintln!(
                "usage: cargo xtask <task>\n\n  test          every check CI runs (setup, firmware build + size, target bench --check, thumb checks, fmt, clippy, docs, tests, fuzz smoke)\n  firmware      cross-build the release firmware and print its flash/RAM use (fails over budget; --no-check: only prints; --coast: the image for a coasting bridge, default the G2's braking one; --both)\n  flash         build the release firmware and flash it with probe-rs, streaming its defmt log (`cargo fw-flash`)\n  setup         install the thumb target and the rustfmt/clippy components when missing\n  fuzz          the fuzz smoke run alone (10 s per target in fuzz/; needs nightly and cargo-fuzz)\n  target-bench  the control core's cycles in an emulated Cortex-M4F [--json] [--check: fail over budget]\n  python        the backdrive_rig wheel (maturin), installed in a fresh venv: pytest and the example notebook"
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

/// `cargo xtask setup`'s second half: the pinned Unicorn (and Capstone) in the project's venv
/// (`target/target-bench-venv`), for the target bench and the emulated board (`rig sim
/// serve --firmware`).
fn setup_emulator() -> Result {
    let python = target_bench::python_env(&target_dir())?;
    eprintln!("==> the emulator is installed ({})", python.display());
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

/// The cargo environment variable that adds to `.cargo/config.toml`'s rustflags for the
/// thumb target (cargo joins the two lists; the link arguments stay).
const THUMB_RUSTFLAGS_VAR: &str = "CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUSTFLAGS";

/// The rustflags every release image is built with, on top of `.cargo/config.toml`'s: each
/// crate-source folder of the cargo registry (`$CARGO_HOME/registry/src/<index>/`) is
/// remapped to nothing, so the panic locations in the image read
/// `embassy-stm32-0.6.0/src/...`. The image then does not depend on where the builder's
/// cargo home is: the same bytes, and the same size against the flash budget, on every
/// machine (a longer home path would add ~22 bytes per character), and 1.2 KB less flash.
/// A user's own value of the variable is kept, after ours.
fn thumb_rustflags() -> String {
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")));
    let mut flags: Vec<String> = home
        .and_then(|h| std::fs::read_dir(h.join("registry").join("src")).ok())
        .into_iter()
        .flatten()
        .filter_map(|entry| {
            let dir = entry.ok()?.path();
            let dir = dir.to_str()?;
            // cargo splits the variable at white space.
            (!dir.contains(char::is_whitespace)).then(|| format!("--remap-path-prefix={dir}/="))
        })
        .collect();
    flags.sort();
    if let Ok(user) = std::env::var(THUMB_RUSTFLAGS_VAR) {
        flags.push(user);
    }
    flags.join(" ")
}

/// Builds `package`'s binary of the same name for the thumb target (release, with
/// [`thumb_rustflags`]) and returns the ELF's path.
fn thumb_release_build(package: &str) -> Result<PathBuf> {
    thumb_release_build_with(package, &[])
}

/// [`thumb_release_build`] with cargo `features`.
fn thumb_release_build_with(package: &str, features: &[&str]) -> Result<PathBuf> {
    let what = if features.is_empty() {
        format!("{package} release build ({THUMB})")
    } else {
        format!(
            "{package} release build ({THUMB}, features {})",
            features.join(",")
        )
    };
    run(&what, {
        let mut c = cargo();
        c.args([
            "build",
            "--package",
            package,
            "--release",
            "--target",
            THUMB,
        ])
        .env(THUMB_RUSTFLAGS_VAR, thumb_rustflags());
        if !features.is_empty() {
            c.arg("--features").arg(features.join(","));
        }
        c
    })?;
    Ok(target_dir().join(THUMB).join("release").join(package))
}

/// The two firmware images: the default for the README's board (the Pololu G2, braking in
/// the PWM's off-time) and the one for a bridge that coasts (feature `bridge-coast-decay`).
/// Both are built, size-checked and boot-traced by `cargo xtask test`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Image {
    /// The default image: braking decay (`model::hardware::board::Decay::Brake`).
    Brake,
    /// `--features bridge-coast-decay`: coasting decay.
    Coast,
}

impl Image {
    /// Both, the default last (so `target/.../release/firmware` is the default image after
    /// a run that built both).
    pub const BOTH: [Image; 2] = [Image::Coast, Image::Brake];

    /// The decay's name, as `Info` and the log give it.
    pub fn name(self) -> &'static str {
        match self {
            Image::Brake => "brake",
            Image::Coast => "coast",
        }
    }

    fn features(self) -> &'static [&'static str] {
        match self {
            Image::Brake => &[],
            Image::Coast => &["bridge-coast-decay"],
        }
    }

    /// Where a copy of this image is kept (`firmware-brake`, `firmware-coast`) next to
    /// `firmware`, which is whichever was built last.
    pub fn kept_elf(self) -> PathBuf {
        target_dir()
            .join(THUMB)
            .join("release")
            .join(format!("firmware-{}", self.name()))
    }
}

/// Builds `image` and keeps a copy of its ELF ([`Image::kept_elf`]); returns the copy.
fn build_image(image: Image) -> Result<PathBuf> {
    let elf = thumb_release_build_with("firmware", image.features())?;
    let kept = image.kept_elf();
    std::fs::copy(&elf, &kept)
        .map_err(|e| format!("cannot copy {} to {}: {e}", elf.display(), kept.display()))?;
    Ok(kept)
}

/// `cargo xtask firmware [--no-check] [--coast | --both]`.
fn firmware_task(args: &[String]) -> Result {
    let mut check = true;
    let mut images = vec![Image::Brake];
    for a in args {
        match a.as_str() {
            "--no-check" => check = false,
            "--coast" => images = vec![Image::Coast],
            "--brake" => images = vec![Image::Brake],
            "--both" => images = Image::BOTH.to_vec(),
            other => {
                return Err(format!(
                    "firmware: unknown option `{other}` (options: --no-check, --coast, --brake, --both)"
                ));
            }
        }
    }
    for image in images {
        if check {
            firmware(image)?;
        } else {
            firmware_unchecked(image)?;
        }
    }
    Ok(())
}

/// Builds the release firmware and prints its flash and RAM use; fails when either is over
/// its budget ([`FLASH_BUDGET`], [`RAM_BUDGET`]).
fn firmware(image: Image) -> Result<size::Usage> {
    let usage = firmware_unchecked(image)?;
    if usage.flash > FLASH_BUDGET || usage.ram > RAM_BUDGET {
        return Err(format!(
            "the {} firmware is over its budget: flash {} B (budget {FLASH_BUDGET} B), static RAM {} B (budget {RAM_BUDGET} B); see \"Firmware flash\" in the README for where the bytes go",
            image.name(),
            usage.flash,
            usage.ram
        ));
    }
    Ok(usage)
}

/// Builds the release firmware and prints its flash and RAM use against the budgets,
/// without failing over them (what a flash of a grown development image wants).
fn firmware_unchecked(image: Image) -> Result<size::Usage> {
    let elf = build_image(image)?;
    let usage = size::measure(&elf)?;
    println!(
        "firmware ({} decay) size: flash {} B ({:.1} KiB of {} KiB budget), static RAM {} B ({:.1} KiB of {} KiB budget)",
        image.name(),
        usage.flash,
        usage.flash as f64 / 1024.0,
        FLASH_BUDGET / 1024,
        usage.ram,
        usage.ram as f64 / 1024.0,
        RAM_BUDGET / 1024
    );
    println!("firmware image: {}", elf.display());
    Ok(usage)
}

/// The probe-rs chip name of the board (the runner in `.cargo/config.toml` says the same).
const CHIP: &str = "STM32G474RETx";

/// `cargo xtask flash`: the release image as [`firmware_unchecked`] builds it, flashed and
/// run through a debug probe by `probe-rs run`, which then streams the defmt log.
fn flash() -> Result {
    let usage = firmware_unchecked(Image::Brake)?;
    if usage.flash > FLASH_BUDGET {
        println!("firmware size: over the {FLASH_BUDGET} B budget; flashing anyway");
    }
    let elf = firmware_elf();
    let status = Command::new("probe-rs")
        .args(["run", "--chip", CHIP])
        .arg(&elf)
        .status()
        .map_err(|e| {
            format!(
                "cannot run probe-rs ({e}): install it with `cargo install probe-rs-tools --locked`, or flash {} with `rig flash --elf`",
                elf.display()
            )
        })?;
    if status.success() {
        Ok(())
    } else {
        Err(format!(
            "probe-rs run failed ({status}); see its messages above"
        ))
    }
}

/// `cargo xtask target-bench [--json] [--check]`: builds the firmware (for its size) and
/// the bench image, runs the image in the emulator and prints the figures.
fn target_bench(args: &[String]) -> Result {
    let options = target_bench::Options::parse(args)?;
    setup()?;
    for image in Image::BOTH {
        build_image(image)?;
    }
    let python = target_bench::python_env(&target_dir())?;
    bench_run(options, &python)
}

/// The emulator run of `target_bench`, both firmware images already built
/// ([`Image::kept_elf`]): the control core's cycles and the default image's failure paths
/// and boot trace, then the other image's failure paths and boot trace (`images`).
fn bench_run(options: target_bench::Options, python: &Path) -> Result {
    let firmware_elf = Image::Brake.kept_elf();
    let usage = size::measure(&firmware_elf)?;
    let board = root().join("firmware").join("src").join("board.rs");
    let board = std::fs::read_to_string(&board)
        .map_err(|e| format!("cannot read {}: {e}", board.display()))?;
    let enable = target_bench::bridge_enable_bsrr(&board)?;
    let image = thumb_release_build("firmware-bench")?;
    let driver = root().join("xtask").join("target_bench").join("driver.py");
    let output = target_bench::run_driver(python, &driver, &image, Some((&firmware_elf, enable)))?;
    let mut result = target_bench::result(&output, usage, &image)?;
    let mut images = serde_json::Map::new();
    images.insert(
        Image::Brake.name().into(),
        target_bench::image_figures(&result),
    );
    let coast_elf = Image::Coast.kept_elf();
    let coast_usage = size::measure(&coast_elf)?;
    let boot = target_bench::run_boot_only(python, &driver, &coast_elf, enable)?;
    images.insert(
        Image::Coast.name().into(),
        target_bench::boot_only_figures(&boot, coast_usage, &result),
    );
    target_bench::add_images(&mut result, images)?;
    // The image itself over 10 s of a 10 Hz release on the emulated board (crate `emu`):
    // the lowest stack pointer of boot and run against the guard.
    let mut closed = serde_json::Map::new();
    for image in Image::BOTH {
        closed.insert(image.name().into(), closed_loop(&image.kept_elf())?);
    }
    result["closed_loop"] = serde_json::Value::Object(closed.clone());
    if options.json {
        println!("{result}");
    } else {
        print!("{}", target_bench::table(&result));
        for (name, run) in &closed {
            println!(
                "image {name}  closed loop {} s on the emulated board: lowest stack pointer {} B above the guard (>= {CLOSED_LOOP_MARGIN_MIN}), {} resets, {} faults, {} unmodelled accesses, release live: {}",
                run["seconds"],
                run["stack_margin_bytes"],
                run["resets"],
                run["faults"],
                run["unmodelled"],
                run["bridge_enabled"]
            );
        }
    }
    let bad: Vec<String> = closed
        .iter()
        .filter(|(_, r)| {
            r["stack_margin_bytes"]
                .as_i64()
                .is_none_or(|m| m < CLOSED_LOOP_MARGIN_MIN)
                || r["resets"] != 0
                || r["faults"] != 0
                || r["unmodelled"] != 0
                || r["bridge_enabled"] != true
        })
        .map(|(name, r)| format!("{name}: {r}"))
        .collect();
    if options.check && !bad.is_empty() {
        return Err(format!(
            "the closed-loop run on the emulated board fails: {}",
            bad.join("; ")
        ));
    }
    let over = target_bench::over_budget(&result);
    if options.check && !over.is_empty() {
        let list: Vec<String> = over
            .iter()
            .map(|(k, v, limit)| format!("{k} {v} > {limit}"))
            .collect();
        return Err(format!("over budget: {}", list.join(", ")));
    }
    let failed = target_bench::failed_boot_checks(&result);
    if options.check && !failed.is_empty() {
        return Err(format!(
            "the firmware's boot trace fails: {} (the register writes are in detail.boot of `cargo xtask target-bench --json`)",
            failed.join("; ")
        ));
    }
    Ok(())
}

/// The stack margin the closed-loop run must keep above the MPU guard, bytes.
const CLOSED_LOOP_MARGIN_MIN: i64 = 2048;

/// Runs `elf` on the emulated board through a 10 s release (`emu`'s `closed_loop`
/// example) and returns its JSON line.
fn closed_loop(elf: &Path) -> Result<serde_json::Value> {
    eprintln!(
        "\n==> 10 s of release on the emulated board: {}",
        elf.display()
    );
    let out = cargo()
        .args([
            "run",
            "-q",
            "--package",
            "emu",
            "--example",
            "closed_loop",
            "--",
        ])
        .arg(elf)
        .arg("10")
        .output()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "the closed-loop run of {} failed: {}",
            elf.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or("");
    serde_json::from_str(line).map_err(|e| format!("closed_loop printed no JSON ({e}): {text}"))
}

/// CI's target bench (`target-bench --check`) after the firmware build; skipped, saying
/// why, only when the emulator's Python packages cannot be installed (no python3, no venv
/// module, no network for pip). Returns whether the emulator (the venv's Unicorn, which the
/// emulated board of `rig sim serve --firmware` loads too) is installed.
fn bench_check() -> Result<bool> {
    let python = match target_bench::python_env(&target_dir()) {
        Ok(python) => python,
        Err(e) => {
            println!("target bench: SKIPPED, the emulator cannot be installed: {e}");
            println!("emulated-board tests: skipped for the same reason");
            return Ok(false);
        }
    };
    eprintln!("\n==> target bench (--check)");
    let options = target_bench::Options {
        json: false,
        check: true,
    };
    bench_run(options, &python)?;
    Ok(true)
}

fn test() -> Result {
    setup()?;
    run("rustfmt check", {
        let mut c = cargo();
        c.args(["fmt", "--all", "--", "--check"]);
        c
    })?;
    for image in Image::BOTH {
        firmware(image)?;
    }
    let emulator = bench_check()?;
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
        // The emulated board's tests run both images built above; with the emulator
        // installed, a missing piece is a failure, not a skip.
        if emulator {
            c.env("RIG_REQUIRE_EMULATOR", "1");
        }
        c
    })?;
    // `cargo test --workspace` built target/debug/rig for the CLI tests: reused.
    python_task(false)?;
    fuzz_smoke()
}

/// `cargo xtask python`: builds `rig` (the served-rig tests start `rig sim serve`) unless
/// `cargo test` just did, then the wheel, a fresh environment, pytest and the notebook
/// ([`python::run`]).
fn python_task(build_rig: bool) -> Result {
    if build_rig {
        run("rig (for the served virtual rig of the Python tests)", {
            let mut c = cargo();
            c.args(["build", "--package", "host", "--bin", "rig"]);
            c
        })?;
    }
    let rig = target_dir().join("debug").join("rig");
    python::run(&root(), &target_dir(), &rig)
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
