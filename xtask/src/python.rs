//! `cargo xtask python`: the Python package `backdrive_rig` (crate `python/`) built as a
//! wheel by maturin, installed into a fresh virtual environment, tested with pytest (the
//! in-process and the served virtual rig), its types checked by mypy --strict, and the
//! example notebook executed
//! (`docs/examples/backdrive_rig.ipynb`). `cargo xtask test` runs it after the Rust tests.
//!
//! The Python tools are pinned ([`PINS`]) and come from PyPI once: `pip download` fills
//! `target/python-wheelhouse`, from which every later environment installs offline. The
//! wheel is built in the dev profile (the tests need no speed; a release build would add
//! minutes of fat LTO). Without PyPI the task fails saying so: the Python door is part of
//! what CI checks.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// The Python tools, pinned (what the wheel is built and tested with).
pub const PINS: [&str; 9] = [
    "maturin==1.16.0",
    "pytest==9.2.0",
    "numpy==2.4.6",
    "pandas==3.1.1",
    "matplotlib==3.11.2",
    "nbclient==0.11.0",
    "nbformat==5.11.1",
    "ipykernel==7.4.0",
    "mypy==2.4.1",
];

/// Marks a complete wheelhouse (the pins it holds).
const WHEELHOUSE_STAMP: &str = "pins.txt";

fn venv_python(venv: &Path) -> PathBuf {
    if cfg!(windows) {
        venv.join("Scripts").join("python.exe")
    } else {
        venv.join("bin").join("python")
    }
}

fn venv_bin(venv: &Path, tool: &str) -> PathBuf {
    if cfg!(windows) {
        venv.join("Scripts").join(format!("{tool}.exe"))
    } else {
        venv.join("bin").join(tool)
    }
}

fn host_python() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".into())
}

fn status(step: &str, mut cmd: Command) -> Result<(), String> {
    eprintln!("\n==> {step}");
    let s = cmd
        .status()
        .map_err(|e| format!("{step}: cannot start: {e}"))?;
    if s.success() {
        Ok(())
    } else {
        Err(format!("{step} failed ({s})"))
    }
}

/// A fresh virtual environment at `venv` (an old one is cleared).
fn fresh_venv(venv: &Path) -> Result<PathBuf, String> {
    let host = host_python();
    let mut c = Command::new(&host);
    c.args(["-m", "venv", "--clear"]).arg(venv);
    status(&format!("fresh virtual environment {}", venv.display()), c).map_err(|e| {
        format!("{e}; `{host} -m venv` needs CPython 3.9+ with venv (Debian/Ubuntu: python3-venv)")
    })?;
    Ok(venv_python(venv))
}

/// The pinned tools as wheels in `target/python-wheelhouse`, downloaded from PyPI when the
/// pins changed or the folder is incomplete.
pub fn wheelhouse(target_dir: &Path) -> Result<PathBuf, String> {
    let dir = target_dir.join("python-wheelhouse");
    let pins = PINS.join("\n");
    if std::fs::read_to_string(dir.join(WHEELHOUSE_STAMP)).is_ok_and(|s| s == pins) {
        return Ok(dir);
    }
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let download = || {
        Command::new(host_python())
            .args([
                "-m",
                "pip",
                "download",
                "--quiet",
                "--disable-pip-version-check",
                "--dest",
            ])
            .arg(&dir)
            .args(PINS)
            .status()
            .is_ok_and(|s| s.success())
    };
    eprintln!(
        "\n==> downloading the Python tools from PyPI ({})",
        PINS.join(", ")
    );
    if !download() && !download() {
        return Err(format!(
            "the Python tests need {} from PyPI and pip could not download them into {} (is PyPI reachable? `{} -m pip` installed?): fix the network and run `cargo xtask python` again",
            PINS.join(", "),
            dir.display(),
            host_python()
        ));
    }
    std::fs::write(dir.join(WHEELHOUSE_STAMP), pins)
        .map_err(|e| format!("cannot write {}: {e}", dir.display()))?;
    Ok(dir)
}

fn pip_install(python: &Path, wheelhouse: &Path, what: &[&str]) -> Result<(), String> {
    let mut c = Command::new(python);
    c.args([
        "-m",
        "pip",
        "install",
        "--quiet",
        "--disable-pip-version-check",
        "--no-index",
        "--find-links",
    ])
    .arg(wheelhouse)
    .args(what);
    status(&format!("pip install {}", what.join(" ")), c)
}

/// Builds the wheel (dev profile) into `target/python-wheels` with maturin from
/// `target/python-tools-venv`; returns its path, size and build time.
pub fn build_wheel(
    root: &Path,
    target_dir: &Path,
    wheelhouse: &Path,
) -> Result<(PathBuf, u64, f64), String> {
    let tools = target_dir.join("python-tools-venv");
    let maturin = venv_bin(&tools, "maturin");
    if !maturin.exists() {
        let python = fresh_venv(&tools)?;
        pip_install(&python, wheelhouse, &[PINS[0]])?;
    }
    let out = target_dir.join("python-wheels");
    let _ = std::fs::remove_dir_all(&out);
    let started = Instant::now();
    let mut c = Command::new(&maturin);
    c.args(["build", "--profile", "dev", "--manifest-path"])
        .arg(root.join("python").join("Cargo.toml"))
        .arg("--out")
        .arg(&out)
        .current_dir(root);
    status("backdrive_rig wheel (maturin, dev profile)", c)?;
    let seconds = started.elapsed().as_secs_f64();
    let wheel = std::fs::read_dir(&out)
        .map_err(|e| format!("cannot read {}: {e}", out.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .ok_or_else(|| format!("maturin wrote no wheel into {}", out.display()))?;
    let size = std::fs::metadata(&wheel).map(|m| m.len()).unwrap_or(0);
    Ok((wheel, size, seconds))
}

/// `cargo xtask python`: wheel, fresh environment, pytest, notebook. `rig` is the CLI the
/// served-rig tests start (`rig sim serve`).
pub fn run(root: &Path, target_dir: &Path, rig: &Path) -> Result<(), String> {
    let wheelhouse = wheelhouse(target_dir)?;
    let (wheel, size, seconds) = build_wheel(root, target_dir, &wheelhouse)?;
    println!(
        "backdrive_rig wheel: {} ({:.1} MB), built in {seconds:.0} s",
        wheel.display(),
        size as f64 / 1e6
    );
    let venv = target_dir.join("python-test-venv");
    let python = fresh_venv(&venv)?;
    let wheel_arg = wheel.display().to_string();
    let mut install: Vec<&str> = vec![&wheel_arg];
    install.extend(PINS[1..].iter().copied());
    pip_install(&python, &wheelhouse, &install)?;
    let mut c = Command::new(&python);
    c.args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("python").join("tests"))
        .env("BACKDRIVE_RIG_CLI", rig)
        // The tests import the installed wheel, never the source folder.
        .current_dir(target_dir);
    status(
        "pytest (backdrive_rig, in-process and served virtual rig)",
        c,
    )?;
    // The public API's types, strictly (python/pyproject.toml's [tool.mypy]), over the
    // package's source and the plain-script example: what a user's type checker sees.
    let mut c = Command::new(&python);
    c.args([
        "-m",
        "mypy",
        "--config-file",
        "pyproject.toml",
        "backdrive_rig",
    ])
    .arg(
        root.join("docs")
            .join("examples")
            .join("backdrive_rig_script.py"),
    )
    .current_dir(root.join("python"));
    status("mypy --strict (backdrive_rig and the script example)", c)?;
    let notebook = root
        .join("docs")
        .join("examples")
        .join("backdrive_rig.ipynb");
    let executed = target_dir.join("backdrive_rig.executed.ipynb");
    let mut c = Command::new(&python);
    c.args(["-c", EXECUTE_NOTEBOOK])
        .arg(&notebook)
        .arg(&executed)
        .current_dir(target_dir);
    status("example notebook (nbclient)", c)
}

/// Executes the notebook named by its first argument and writes it, with outputs, to the
/// second.
const EXECUTE_NOTEBOOK: &str = r#"
import sys, nbformat
from nbclient import NotebookClient
nb = nbformat.read(sys.argv[1], as_version=4)
NotebookClient(nb, timeout=900, kernel_name="python3").execute()
nbformat.write(nb, sys.argv[2])
print(f"executed {sys.argv[1]}: {len(nb.cells)} cells, written to {sys.argv[2]}")
"#;

#[cfg(test)]
mod tests {
    use super::PINS;

    #[test]
    fn every_tool_is_pinned_exactly_and_named_in_the_readme() {
        let readme = std::fs::read_to_string(crate::root().join("README.md")).unwrap();
        for pin in PINS {
            let (name, version) = pin.split_once("==").expect("an exact pin");
            assert!(!name.is_empty() && version.split('.').all(|p| p.parse::<u32>().is_ok()));
            assert!(
                readme.contains(&format!("{name} {version}")),
                "README's Python section does not list {pin}"
            );
        }
    }
}
