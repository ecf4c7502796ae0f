#!/bin/sh
# Checks that patches/embassy-stm32 is embassy-stm32 0.6.0 as published on crates.io with
# exactly the change in embassy-stm32-g4-clock-switch.diff, nothing else (see README.md).
#
#   patches/verify.sh             offline: every file against the published crate's SHA-256
#                                 list (embassy-stm32-0.6.0.sha256), the patched file after
#                                 undoing the diff
#   patches/verify.sh --crate F   also checks the list itself against the published .crate F
#                                 (its SHA-256 is the checksum crates.io and Cargo.lock give;
#                                 F defaults to the one in cargo's download cache, else it is
#                                 fetched from static.crates.io)
# Needs sha256sum, patch, tar, mktemp (and curl to fetch the crate).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
vendored="$here/embassy-stm32"
list="$here/embassy-stm32-0.6.0.sha256"
diff_file="$here/embassy-stm32-g4-clock-switch.diff"
crate_sha=486c0622deb5a519fc4d2cb8e3ef324f7568fcdfff201ff8fcab46557d663ceb
patched=src/rcc/g4.rs
fail() { echo "patches/verify.sh: $*" >&2; exit 1; }

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# 1. The vendored tree holds exactly the published files.
(cd "$vendored" && find . -type f | sed 's|^\./||' | LC_ALL=C sort) > "$work/have"
sed 's/^[0-9a-f]*  //' "$list" | LC_ALL=C sort > "$work/want"
if ! cmp -s "$work/have" "$work/want"; then
    diff "$work/want" "$work/have" >&2 || true
    fail "patches/embassy-stm32 has files the published crate does not, or lacks some (above: < published only, > vendored only)"
fi

# 2. Every file but the patched one is byte for byte the published one.
grep -v "  $patched\$" "$list" > "$work/unpatched.sha256"
(cd "$vendored" && sha256sum --quiet -c "$work/unpatched.sha256") \
    || fail "a vendored file differs from embassy-stm32 0.6.0 (above); only $patched may"

# 3. The patched file is the published one plus the diff: undo it and compare.
cp "$vendored/$patched" "$work/g4.rs"
patch --quiet -R "$work/g4.rs" "$diff_file" \
    || fail "embassy-stm32-g4-clock-switch.diff does not undo cleanly on the vendored $patched"
want=$(grep "  $patched\$" "$list" | cut -d' ' -f1)
have=$(sha256sum "$work/g4.rs" | cut -d' ' -f1)
[ "$want" = "$have" ] \
    || fail "the vendored $patched differs from the published one by more than the diff"

# 4. Optionally, the list against the published crate itself.
if [ "${1:-}" = "--crate" ]; then
    crate=${2:-}
    if [ -z "$crate" ]; then
        crate=$(ls "${CARGO_HOME:-$HOME/.cargo}"/registry/cache/*/embassy-stm32-0.6.0.crate 2>/dev/null | head -n 1 || true)
    fi
    if [ -z "$crate" ]; then
        crate="$work/embassy-stm32-0.6.0.crate"
        curl -sSfL -o "$crate" https://static.crates.io/crates/embassy-stm32/embassy-stm32-0.6.0.crate \
            || fail "cannot fetch embassy-stm32 0.6.0 from static.crates.io; pass --crate FILE"
    fi
    [ "$(sha256sum "$crate" | cut -d' ' -f1)" = "$crate_sha" ] \
        || fail "$crate is not the published embassy-stm32 0.6.0 (SHA-256 differs from $crate_sha)"
    mkdir "$work/crate"
    tar xzf "$crate" -C "$work/crate"
    (cd "$work/crate/embassy-stm32-0.6.0" && sha256sum --quiet -c "$list") \
        || fail "embassy-stm32-0.6.0.sha256 does not list the published crate's files"
    (cd "$work/crate/embassy-stm32-0.6.0" && find . -type f | sed 's|^\./||' | LC_ALL=C sort) > "$work/published"
    cmp -s "$work/published" "$work/want" \
        || fail "the published crate has other files than embassy-stm32-0.6.0.sha256 lists"
    echo "patches/verify.sh: the list matches the published embassy-stm32 0.6.0 ($crate_sha)"
fi
echo "patches/verify.sh: patches/embassy-stm32 is embassy-stm32 0.6.0 plus embassy-stm32-g4-clock-switch.diff only"
