#!/usr/bin/env bash
# Builds the FMU binary for old Linux systems and bundles target/fmu/QuadController.fmu from it:
# the cdylib is linked by zig (cargo-zigbuild) against glibc 2.17 symbol versions, so it loads on
# any x86_64 glibc >= 2.17 (RHEL 7/8, Ubuntu 20.04, Debian 11, ...), and is built with the
# `fmu-release` profile (release code, no debug info, stripped).
# With --all-platforms (or PFNAV_FMU_ALL_PLATFORMS=1) zig also links the Windows and macOS x86-64
# binaries (x86_64-pc-windows-gnu -> binaries/win64, x86_64-apple-darwin -> binaries/darwin64; no
# Windows or macOS SDK needed, rustup adds the two Rust targets); they roughly double the first
# build, so they are not built by default.
# The tools come pinned from PyPI (scripts/requirements.txt) into .venv; run again, it only
# re-links what changed. Usage: scripts/build_fmu_portable.sh [--all-platforms] [--out PATH.fmu]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '\033[1;34m[fmu-portable]\033[0m %s\n' "$*"; }

GLIBC=2.17
TRIPLE=x86_64-unknown-linux-gnu
PROFILE=fmu-release
TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
# FMI platform, Rust target, file cargo writes.
# macOS: the oldest release Rust supports for x86_64-apple-darwin; without it zig stamps the
# newest macOS it knows as the minimum, and older macOS refuses to load the dylib.
export MACOSX_DEPLOYMENT_TARGET="${MACOSX_DEPLOYMENT_TARGET:-10.12}"
EXTRA_PLATFORMS=("win64 x86_64-pc-windows-gnu quad_controller_fmu.dll"
                 "darwin64 x86_64-apple-darwin libquad_controller_fmu.dylib")

all_platforms="${PFNAV_FMU_ALL_PLATFORMS:-0}"
bundle_args=()
for arg in "$@"; do
    case "$arg" in
        --all-platforms) all_platforms=1 ;;
        *) bundle_args+=("$arg") ;;
    esac
done

[[ -x .venv/bin/python ]] || { echo "no .venv: run scripts/setup.sh first" >&2; exit 1; }
# The pins live in scripts/requirements.txt; install them here too if that file was not applied yet.
pins=()
for pkg in cargo-zigbuild ziglang; do
    pin="$(grep -E "^${pkg}==" scripts/requirements.txt)"
    installed="$(.venv/bin/python -m pip show "$pkg" 2>/dev/null | sed -n 's/^Version: //p')"
    [[ "$pkg==$installed" == "$pin" ]] || pins+=("$pin")
done
if ((${#pins[@]})); then
    log "pip install ${pins[*]}"
    .venv/bin/pip install -q --disable-pip-version-check "${pins[@]}"
fi

# cargo-zigbuild runs zig as `python3 -m ziglang` when no `zig` is on PATH: the venv's python.
export PATH="$ROOT/.venv/bin:$PATH"
log "cargo zigbuild --profile $PROFILE -p quad-controller-fmu --lib --target $TRIPLE.$GLIBC"
cargo zigbuild --quiet --profile "$PROFILE" -p quad-controller-fmu --lib --target "$TRIPLE.$GLIBC"
lib="$TARGET_DIR/$TRIPLE/$PROFILE/libquad_controller_fmu.so"
[[ -f "$lib" ]] || { echo "expected $lib after the build" >&2; exit 1; }
binaries=(--lib "$lib")

if [[ "$all_platforms" == 1 ]]; then
    for spec in "${EXTRA_PLATFORMS[@]}"; do
        read -r platform target file <<<"$spec"
        if ! rustup target list --installed | grep -qx "$target"; then
            log "rustup target add $target"
            rustup target add "$target"
        fi
        log "cargo zigbuild --profile $PROFILE -p quad-controller-fmu --lib --target $target"
        # No macOS SDK here: zig links against its own libSystem stubs. rustc warns that invoking
        # `xcrun` failed; that warning is expected.
        cargo zigbuild --quiet --profile "$PROFILE" -p quad-controller-fmu --lib --target "$target"
        path="$TARGET_DIR/$target/$PROFILE/$file"
        [[ -f "$path" ]] || { echo "expected $path after the build" >&2; exit 1; }
        binaries+=(--binary "$platform=$path")
    done
fi

log "bundling the FMU ($(( $(stat -c %s "$lib") / 1024 )) KiB linux64 binary$( [[ "$all_platforms" == 1 ]] && echo ", win64, darwin64"))"
cargo run --release --quiet -p quad-controller-fmu --bin bundle-fmu -- "${binaries[@]}" ${bundle_args[@]+"${bundle_args[@]}"}
