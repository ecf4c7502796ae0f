//! The firmware's build identity: the record the firmware carries in its image (see
//! `firmware/build.rs` and `RIG_FIRMWARE_ID` in `firmware/src/main.rs`), and the check after
//! flashing that the board runs what was flashed.

use std::fmt;

/// Symbol of the identity record in the firmware ELF.
pub const IDENTITY_SYMBOL: &str = "RIG_FIRMWARE_ID";

/// Start of the identity record.
pub const IDENTITY_PREFIX: &str = "rig firmware ";

/// Longest build string (the device reports it in a 20-byte field; `firmware/build.rs` clips).
pub const MAX_BUILD_LEN: usize = 20;

/// Separator between version and build in the record.
const BUILD_SEPARATOR: &str = " build ";

/// What a firmware image (or board) says it is.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct BuildIdentity {
    /// Firmware version, `major.minor.patch`.
    pub version: String,
    /// Git commit (short hash, `-dirty` when the tree had uncommitted changes) or `unknown`.
    pub build: String,
}

impl BuildIdentity {
    /// Reads a record `rig firmware <version> build <build>` (trailing NULs allowed).
    pub fn parse(record: &[u8]) -> Option<Self> {
        let text = std::str::from_utf8(record).ok()?;
        let text = text.trim_end_matches('\0');
        let rest = text.strip_prefix(IDENTITY_PREFIX)?;
        let (version, build) = rest.split_once(BUILD_SEPARATOR)?;
        let ok = |s: &str| !s.is_empty() && s.chars().all(|c| c.is_ascii_graphic());
        (ok(version) && ok(build) && build.len() <= MAX_BUILD_LEN).then(|| Self {
            version: version.to_owned(),
            build: build.to_owned(),
        })
    }

    /// Finds a record inside `bytes` (an image whose symbol table was stripped).
    pub fn find_in(bytes: &[u8]) -> Option<Self> {
        let prefix = IDENTITY_PREFIX.as_bytes();
        bytes
            .windows(prefix.len())
            .enumerate()
            .filter(|(_, w)| *w == prefix)
            .find_map(|(i, _)| {
                let tail = &bytes[i..];
                let len = tail
                    .iter()
                    .position(|&b| !(b.is_ascii_graphic() || b == b' '))
                    .unwrap_or(tail.len())
                    .min(96);
                Self::parse(&tail[..len])
            })
    }

    /// Whether the build was made from a tree with uncommitted changes.
    pub fn is_dirty(&self) -> bool {
        self.build.ends_with("-dirty")
    }

    /// Whether the build names a commit at all.
    pub fn is_known(&self) -> bool {
        self.build != "unknown"
    }
}

impl fmt::Display for BuildIdentity {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (build {})", self.version, self.build)
    }
}

/// What the running firmware said about itself over the serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reported<'a> {
    /// Its version, `major.minor.patch`.
    pub version: &'a str,
    /// Its build, when the firmware reports one (protocol with `firmware_build`).
    pub build: Option<&'a str>,
}

/// The outcome of a successful check.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Confirmation {
    /// Version and build agree (`false`: only the version could be compared).
    pub build_compared: bool,
    /// A caveat for the user, e.g. both builds were dirty.
    pub note: Option<String>,
}

/// Why the running firmware is not the flashed image.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the board runs firmware {reported} but the flashed image is {expected}: the new image is not running (reset the board; if it persists, flash again and watch `rig log`)"
)]
pub struct IdentityMismatch {
    /// What the image says.
    pub expected: String,
    /// What the board says.
    pub reported: String,
}

/// Compares what the board reports after flashing with the image's identity.
///
/// The version must match; the build must match when the board reports one and both
/// name a commit. Without a reported build only the version is compared, and the
/// confirmation says so.
pub fn confirm(
    image: &BuildIdentity,
    device: Reported<'_>,
) -> Result<Confirmation, IdentityMismatch> {
    let reported_text = match device.build {
        Some(b) => format!("{} (build {b})", device.version),
        None => device.version.to_owned(),
    };
    let mismatch = || IdentityMismatch {
        expected: image.to_string(),
        reported: reported_text.clone(),
    };
    if device.version.trim() != image.version {
        return Err(mismatch());
    }
    let Some(build) = device.build.map(str::trim) else {
        return Ok(Confirmation {
            build_compared: false,
            note: Some(format!(
                "the firmware does not report its build: only the version {} was compared",
                image.version
            )),
        });
    };
    if !image.is_known() || build == "unknown" {
        return Ok(Confirmation {
            build_compared: false,
            note: Some("built without git (build `unknown`): only the version was compared".into()),
        });
    }
    if build != image.build {
        return Err(mismatch());
    }
    let note = image.is_dirty().then(|| {
        format!(
            "build {} has uncommitted changes: two dirty builds of one commit carry the same name",
            image.build
        )
    });
    Ok(Confirmation {
        build_compared: true,
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(version: &str, build: &str) -> BuildIdentity {
        BuildIdentity {
            version: version.into(),
            build: build.into(),
        }
    }

    #[test]
    fn records_parse_and_bad_ones_do_not() {
        let r = BuildIdentity::parse(b"rig firmware 0.1.0 build 5b6e2ae664-dirty\0\0").unwrap();
        assert_eq!(r, id("0.1.0", "5b6e2ae664-dirty"));
        assert!(r.is_dirty() && r.is_known());
        assert!(!id("0.1.0", "unknown").is_known());
        assert_eq!(BuildIdentity::parse(b"rig firmware 0.1.0"), None);
        assert_eq!(BuildIdentity::parse(b"rig firmware  build x"), None);
        assert_eq!(BuildIdentity::parse(b"other 0.1.0 build x"), None);
        assert_eq!(BuildIdentity::parse(&[0xff, 0xfe]), None);
        // Longer than the device's field: not a record (e.g. neighbouring text in a scan).
        assert_eq!(
            BuildIdentity::parse(b"rig firmware 0.1.0 build fixturevibratingfault"),
            None
        );
    }

    #[test]
    fn a_record_is_found_among_other_bytes() {
        let mut image = vec![0u8, 1, 2, 0x72];
        image.extend_from_slice(b"rig firmware 1.2.3 build abc\0more");
        assert_eq!(BuildIdentity::find_in(&image), Some(id("1.2.3", "abc")));
        assert_eq!(BuildIdentity::find_in(b"rig firmware broken\0"), None);
    }

    #[test]
    fn same_version_and_build_confirm() {
        let image = id("0.1.0", "5b6e2ae664");
        let c = confirm(
            &image,
            Reported {
                version: "0.1.0",
                build: Some("5b6e2ae664"),
            },
        )
        .unwrap();
        assert!(c.build_compared);
        assert_eq!(c.note, None);
    }

    #[test]
    fn without_a_reported_build_only_the_version_counts() {
        let image = id("0.1.0", "5b6e2ae664");
        let c = confirm(
            &image,
            Reported {
                version: "0.1.0",
                build: None,
            },
        )
        .unwrap();
        assert!(!c.build_compared);
        assert!(c.note.unwrap().contains("only the version"));
        let e = confirm(
            &image,
            Reported {
                version: "0.0.9",
                build: None,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("0.0.9"), "{e}");
        assert!(e.to_string().contains("0.1.0 (build 5b6e2ae664)"), "{e}");
    }

    #[test]
    fn another_build_of_the_same_version_is_a_mismatch() {
        let image = id("0.1.0", "5b6e2ae664");
        let e = confirm(
            &image,
            Reported {
                version: "0.1.0",
                build: Some("1111111111"),
            },
        )
        .unwrap_err();
        assert_eq!(e.reported, "0.1.0 (build 1111111111)");
        assert!(e.to_string().contains("not running"));
    }

    #[test]
    fn dirty_and_unknown_builds_confirm_with_a_note() {
        let dirty = id("0.1.0", "5b6e2ae664-dirty");
        let c = confirm(
            &dirty,
            Reported {
                version: "0.1.0",
                build: Some("5b6e2ae664-dirty"),
            },
        )
        .unwrap();
        assert!(c.build_compared);
        assert!(c.note.unwrap().contains("uncommitted"));
        let unknown = id("0.1.0", "unknown");
        let c = confirm(
            &unknown,
            Reported {
                version: "0.1.0",
                build: Some("unknown"),
            },
        )
        .unwrap();
        assert!(!c.build_compared);
    }
}
