#!/usr/bin/env bash
# Builds the FMU binary for old Linux systems and bundles target/fmu/QuadController.fmu from it:
# the cdylib is linked by zig (cargo-zigbuild) against glibc 2.17 symbol versions, so it loads on
# any x86_64 glibc >= 2.17 (RHEL 7/8, Ubuntu 20.04, Debian 11, ...), and is built with the
# `fmu-release` profile (release code, no debug info, stripped).
# The tools come pinned from PyPI (scripts/requirements.txt) into .venv; run again, it only
# re-links what changed. Usage: scripts/build_fmu_portable.sh [--out PATH.fmu]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '\033[1;34m[fmu-portable]\033[0m %s\n' "$*"; }

GLIBC=2.17
TRIPLE=x86_64-unknown-linux-gnu
PROFILE=fmu-release

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
lib="${CARGO_TARGET_DIR:-$ROOT/target}/$TRIPLE/$PROFILE/libquad_controller_fmu.so"
[[ -f "$lib" ]] || { echo "expected $lib after the build" >&2; exit 1; }

log "bundling the FMU with $(basename "$lib") ($(( $(stat -c %s "$lib") / 1024 )) KiB)"
cargo run --release --quiet -p quad-controller-fmu --bin bundle-fmu -- --lib "$lib" "$@"
