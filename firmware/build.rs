//! Build script of the firmware: hands the board's `memory.x` to the linker and stamps the
//! build identity.
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`, so the workspace's `memory.x` (flash, RAM
//! and the calibration STORAGE region) is copied into `OUT_DIR` and that directory is put on
//! the link search path. Host builds (the stub binary, the core's tests) skip this.
//!
//! The build identity is the git commit of the work tree (short hash, `-dirty` when tracked
//! files had uncommitted changes), `unknown` without git or outside a repository, or the value
//! of `RIG_FIRMWARE_BUILD` when that is set (a release script building from a tarball). It
//! reaches the firmware as the compile-time variable `RIG_FIRMWARE_BUILD`; `src/main.rs` puts
//! it, with the version, in the ELF where `rig flash` reads it. It is recomputed when HEAD,
//! the index or the firmware's own inputs change, so `-dirty` describes the tree as it was
//! when the firmware's sources last changed.

use std::env;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Longest build string: the device reports it in a 20-byte field.
const MAX_BUILD_LEN: usize = 20;

fn main() {
    let manifest_dir =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest_dir.join("..");
    let memory_x = root.join("memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={}", memory_x.display());

    let build = build_identity(&root);
    println!("cargo:rustc-env=RIG_FIRMWARE_BUILD={build}");

    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }

    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(&memory_x, out_dir.join("memory.x"))
        .unwrap_or_else(|e| panic!("cannot copy {} into OUT_DIR: {e}", memory_x.display()));
    println!("cargo:rustc-link-search={}", out_dir.display());
}

/// The build string: `RIG_FIRMWARE_BUILD`, else `<short hash>[-dirty]`, else `unknown`.
fn build_identity(root: &Path) -> String {
    println!("cargo:rerun-if-env-changed=RIG_FIRMWARE_BUILD");
    if let Ok(given) = env::var("RIG_FIRMWARE_BUILD") {
        let given = given.trim();
        if !given.is_empty() {
            return clip(given);
        }
    }
    // The firmware's inputs: a change there re-runs this script, so `-dirty` follows them.
    for input in ["firmware", "protocol", "model", "Cargo.toml", "Cargo.lock"] {
        println!("cargo:rerun-if-changed={}", root.join(input).display());
    }
    let Some(hash) = git(root, &["rev-parse", "--short=10", "HEAD"]) else {
        return "unknown".into();
    };
    // HEAD, the branch it points at and the index: a commit, checkout or `git add` re-runs.
    for path in ["HEAD", "index", "packed-refs"] {
        watch_git_path(root, path);
    }
    if let Some(branch) = git(root, &["symbolic-ref", "-q", "HEAD"]) {
        watch_git_path(root, &branch);
    }
    let dirty = git(root, &["status", "--porcelain", "--untracked-files=no"])
        .is_some_and(|changes| !changes.is_empty());
    clip(&if dirty { format!("{hash}-dirty") } else { hash })
}

/// Keeps the build string within what the device can report.
fn clip(build: &str) -> String {
    build
        .chars()
        .filter(|c| c.is_ascii_graphic())
        .take(MAX_BUILD_LEN)
        .collect()
}

/// Re-runs this script when a file of the git directory changes (worktrees included).
fn watch_git_path(root: &Path, path: &str) {
    if let Some(p) = git(root, &["rev-parse", "--git-path", path]) {
        let p = PathBuf::from(p);
        let p = if p.is_absolute() { p } else { root.join(p) };
        if p.exists() {
            println!("cargo:rerun-if-changed={}", p.display());
        }
    }
}

/// Runs git in `root`; its trimmed output, or `None` when git is missing or fails.
fn git(root: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("-C")
        .arg(root)
        .args(args)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}
