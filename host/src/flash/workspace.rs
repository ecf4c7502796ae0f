//! Where the firmware ELF comes from when `--elf` is not given: the workspace around the
//! current directory, built by `cargo xtask firmware --no-check` (the image CI measures).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::RigError;

/// The firmware's target triple.
pub const THUMB: &str = "thumbv7em-none-eabihf";

/// The backdrive-rig workspace containing `start` (a folder with a `Cargo.toml` that has a
/// `[workspace]` table, a `memory.x` and `firmware/Cargo.toml`).
pub fn find_root(start: &Path) -> Option<PathBuf> {
    start.ancestors().find_map(|dir| {
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).ok()?;
        (manifest.contains("[workspace]")
            && dir.join("memory.x").is_file()
            && dir.join("firmware").join("Cargo.toml").is_file())
        .then(|| dir.to_path_buf())
    })
}

/// The workspace around the current directory, or an error that says what to do.
pub fn current_root() -> Result<PathBuf, RigError> {
    let cwd = std::env::current_dir()?;
    find_root(&cwd).ok_or_else(|| RigError::BadValue {
        what: "--elf".into(),
        why: format!(
            "not given, and {} is not inside the rig's source workspace (where rig would build the firmware): pass --elf PATH to the firmware ELF, or run rig from the workspace",
            cwd.display()
        ),
    })
}

/// The `cargo` to run: the one that runs us (`$CARGO`), else `cargo` on the PATH.
fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

/// cargo's target folder for the workspace at `root`: `cargo metadata` knows it (it honours
/// `CARGO_TARGET_DIR` and the configuration); without cargo, `$CARGO_TARGET_DIR` or `target`.
pub fn target_dir(root: &Path) -> PathBuf {
    let from_metadata = cargo()
        .args([
            "metadata",
            "--no-deps",
            "--format-version",
            "1",
            "--offline",
        ])
        .current_dir(root)
        .stderr(std::process::Stdio::null())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| serde_json::from_slice::<serde_json::Value>(&o.stdout).ok())
        .and_then(|v| v.get("target_directory")?.as_str().map(PathBuf::from));
    from_metadata.unwrap_or_else(|| match std::env::var_os("CARGO_TARGET_DIR") {
        Some(dir) if !dir.is_empty() => {
            let dir = PathBuf::from(dir);
            if dir.is_absolute() {
                dir
            } else {
                std::env::current_dir().unwrap_or_default().join(dir)
            }
        }
        _ => root.join("target"),
    })
}

/// Where the release firmware ELF of the workspace at `root` is (built or not).
pub fn release_elf(root: &Path) -> PathBuf {
    target_dir(root)
        .join(THUMB)
        .join("release")
        .join("firmware")
}

/// Builds the release firmware of the workspace at `root` (cargo's progress on stderr), the
/// image for a coasting bridge when `coast` (else the default, braking, the Pololu G2's),
/// and returns the ELF's path.
pub fn build_release(root: &Path, coast: bool) -> Result<PathBuf, RigError> {
    // Through xtask, which builds the release image exactly as CI measures it (its rustflags
    // trim registry paths from the panic locations: `thumb_rustflags` in xtask).
    let decay = if coast { "--coast" } else { "--brake" };
    eprintln!("building the firmware: cargo xtask firmware --no-check {decay}");
    let status = cargo()
        .args(["xtask", "firmware", "--no-check", decay])
        .current_dir(root)
        .stdout(std::process::Stdio::null())
        .status()
        .map_err(|e| RigError::BadValue {
            what: "firmware build".into(),
            why: format!("cannot run cargo ({e}): install Rust with rustup, or pass --elf PATH"),
        })?;
    if !status.success() {
        return Err(RigError::BadValue {
            what: "firmware build".into(),
            why: format!(
                "the firmware build (cargo xtask firmware --no-check {decay}) failed ({status}); see its messages above (a missing target: `rustup target add {THUMB}`)"
            ),
        });
    }
    let elf = release_elf(root);
    if !elf.is_file() {
        return Err(RigError::BadValue {
            what: "firmware build".into(),
            why: format!("cargo reported success but {} is missing", elf.display()),
        });
    }
    Ok(elf)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_workspace_is_found_from_inside_it() {
        let here = Path::new(env!("CARGO_MANIFEST_DIR"));
        let root = find_root(&here.join("src")).unwrap();
        assert!(root.join("memory.x").is_file());
        assert_eq!(find_root(Path::new("/")), None);
    }
}
