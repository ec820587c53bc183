#!/usr/bin/env bash
# Bundles target/fmu/QuadController.fmu from the FMU's shared library of the release build: the
# cdylib (crate fmu/binary) is linked by zig (fmu/binary/link-gcc.sh, through cargo-zigbuild's
# `zig cc`) against glibc 2.17 symbol versions, so it loads on any x86_64 glibc >= 2.17 (RHEL 7/8,
# Ubuntu 20.04, Debian 11, ...), and is stripped.
# With --all-platforms (or PFNAV_FMU_ALL_PLATFORMS=1) zig also links the Windows and macOS x86-64
# binaries (x86_64-pc-windows-gnu -> binaries/win64, x86_64-apple-darwin -> binaries/darwin64; no
# Windows or macOS SDK needed, rustup adds the two Rust targets); each is a full compile for its
# target, so they are not built by default.
# The tools come pinned from PyPI (harness/pyproject.toml, extra `build`) into .venv.
# Usage: scripts/build_fmu_portable.sh [--all-platforms] [--out PATH.fmu]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '\033[1;34m[fmu-portable]\033[0m %s\n' "$*"; }

GLIBC=2.17
CRATE=quad-controller-fmu-binary
TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
LIB="$TARGET_DIR/release/libquad_controller_fmu_binary.so"
# macOS: the oldest release Rust supports for x86_64-apple-darwin; without it zig stamps the
# newest macOS it knows as the minimum, and older macOS refuses to load the dylib.
export MACOSX_DEPLOYMENT_TARGET="${MACOSX_DEPLOYMENT_TARGET:-10.12}"
# FMI platform, Rust target, file cargo writes.
EXTRA_PLATFORMS=("win64 x86_64-pc-windows-gnu quad_controller_fmu_binary.dll"
                 "darwin64 x86_64-apple-darwin libquad_controller_fmu_binary.dylib")

all_platforms="${PFNAV_FMU_ALL_PLATFORMS:-0}"
bundle_args=()
for arg in "$@"; do
    case "$arg" in
        --all-platforms) all_platforms=1 ;;
        *) bundle_args+=("$arg") ;;
    esac
done

[[ -x .venv/bin/python ]] || { echo "no .venv: run scripts/setup.sh first" >&2; exit 1; }
# The pins live in harness/pyproject.toml; install them here too if setup.sh did not yet.
pins=()
for pkg in cargo-zigbuild ziglang; do
    pin="$(grep -oE "\"${pkg}==[^\"]+\"" harness/pyproject.toml | tr -d '"')"
    [[ -n "$pin" ]] || { echo "no pin for $pkg in harness/pyproject.toml" >&2; exit 1; }
    installed="$(.venv/bin/python -m pip show "$pkg" 2>/dev/null | sed -n 's/^Version: //p')"
    [[ "$pkg==$installed" == "$pin" ]] || pins+=("$pin")
done
if ((${#pins[@]})); then
    log "pip install ${pins[*]}"
    .venv/bin/pip install -q --disable-pip-version-check "${pins[@]}"
fi

# fmu/binary/link-gcc.sh (the workspace's linker, .cargo/config.toml) links the FMU's library with zig.
# The whole workspace is selected, as setup.sh selects it, so the dependencies keep the features of
# that one build and nothing is compiled twice (a no-op after setup.sh); of its targets only the
# libraries (the FMU's among them) and the bundler are built.
log "cargo build --release --workspace --lib --bin bundle-fmu (the FMU's library linked by zig for glibc $GLIBC)"
cargo build --quiet --release --workspace --lib --exclude lcm-codegen --bin bundle-fmu
[[ -f "$LIB" ]] || { echo "expected $LIB after the build" >&2; exit 1; }
binaries=(--lib "$LIB")

if [[ "$all_platforms" == 1 ]]; then
    for spec in "${EXTRA_PLATFORMS[@]}"; do
        read -r platform target file <<<"$spec"
        if ! rustup target list --installed | grep -qx "$target"; then
            log "rustup target add $target"
            rustup target add "$target"
        fi
        log "cargo zigbuild --release -p $CRATE --target $target (stripped)"
        # No macOS SDK here: zig links against its own libSystem stubs. rustc warns that invoking
        # `xcrun` failed; that warning is expected. The shipped binaries carry no debug info.
        CARGO_PROFILE_RELEASE_DEBUG=false CARGO_PROFILE_RELEASE_STRIP=true \
            cargo zigbuild --quiet --release -p "$CRATE" --target "$target"
        path="$TARGET_DIR/$target/release/$file"
        [[ -f "$path" ]] || { echo "expected $path after the build" >&2; exit 1; }
        binaries+=(--binary "$platform=$path")
    done
fi

log "bundling the FMU ($(( $(stat -c %s "$LIB") / 1024 )) KiB linux64 binary$( [[ "$all_platforms" == 1 ]] && echo ", win64, darwin64"))"
"$TARGET_DIR/release/bundle-fmu" "${binaries[@]}" ${bundle_args[@]+"${bundle_args[@]}"}
