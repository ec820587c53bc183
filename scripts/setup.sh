#!/usr/bin/env bash
# Installs everything the demo and the tests need on a fresh Debian machine (run as root):
# Debian packages, the Python venv with pinned versions, generated LCM Python types, the
# release build of the workspace (the one build the demo, the Python tests and the Rust tests
# share) and the bundled FMU (its binary relinked portable to glibc >= 2.17).
# Safe to run again: it skips what is done.
#
# Usage: scripts/setup.sh [--tests]
#   (default)  what the demo runs: the harness, the planner's binaries, the FMU and its bundler;
#   --tests    also the test tools (pytest, ruff, the FMU checkers), the third-party robot data
#              and the workspace's test-only binaries (scripts/test.sh passes it).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
case "${1:-}" in
    "") for_tests=0 ;;
    --tests) for_tests=1 ;;
    *) echo "usage: $0 [--tests]" >&2; exit 2 ;;
esac
log() { printf '\033[1;34m[setup %4ds]\033[0m %s\n' "$SECONDS" "$*"; }

# gcc, patch, ca-certificates: the patched liblcm (scripts/build_liblcm.sh; its source comes from
# Debian's deb-src index through apt, into a private apt directory under build/).
# libfontconfig1-dev, libfreetype-dev, fonts-dejavu-core: pf-plan's plots. binutils: the linker
# and `ar` of the Rust builds. ffmpeg: the runs' videos (pfnav-demo --video). (The MPC
# benchmark's OSQP comparison, `cargo bench -p quad-controller --features osqp-comparison`, also
# needs cmake.) With --tests also chromium: the HTML report is checked in a headless browser.
APT_PACKAGES=(libglib2.0-dev iproute2 util-linux pkg-config gcc ca-certificates patch
              libfontconfig1-dev libfreetype-dev fonts-dejavu-core binutils ffmpeg)
if ((for_tests)); then
    APT_PACKAGES+=(chromium)
fi
missing=()
for pkg in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if ((${#missing[@]})); then
    log "apt-get install ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -q >/dev/null
    apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
fi

PYTHON="${PYTHON:-python3}"
if [[ ! -x .venv/bin/python ]]; then
    log "creating .venv with $($PYTHON --version)"
    "$PYTHON" -m venv .venv
fi
# LCM: Debian's and PyPI's liblcm let one UDP packet write out of bounds (docs/liblcm-fix.md).
# Every receiver here uses the patched build instead: the Rust transport links it, Python imports
# its module (the PyPI `lcm` package is not installed), lcm-logger/lcm-logplayer are its tools.
# It needs only the venv's interpreter, so it comes before the packages and the Rust build.
log "patched liblcm (build/lcm)"
bash scripts/build_liblcm.sh "$ROOT/.venv/bin/python"

# The Python packages download and unpack while cargo compiles (the two overlap on a fresh
# machine); only the FMU's link below needs them (zig comes from PyPI).
# The pins: harness/pyproject.toml (the harness and every tool), the robot data (--no-deps).
# The stamp holds their hash and which set is installed; the test set includes the demo's.
stamp=.venv/.pfnav-requirements
pins="$(cat harness/pyproject.toml scripts/requirements-robots.txt | sha256sum | cut -d' ' -f1)"
installed="$(cat "$stamp" 2>/dev/null || true)"
pip_pid=""
pip_log=build/setup-pip.log
if [[ "$installed" != "$pins tests" && ( $for_tests == 1 || "$installed" != "$pins demo" ) ]]; then
    log "installing pinned Python packages (in the background, log: $pip_log)"
    mkdir -p build
    (
        if ((for_tests)); then
            .venv/bin/pip install -q --disable-pip-version-check -e 'harness[dev,build]' &&
            .venv/bin/pip install -q --disable-pip-version-check --no-deps -r scripts/requirements-robots.txt &&
            echo "$pins tests" > "$stamp"
        else
            .venv/bin/pip install -q --disable-pip-version-check -e 'harness[build]' &&
            echo "$pins demo" > "$stamp"
        fi
    ) > "$pip_log" 2>&1 &
    pip_pid=$!
fi
wait_for_pip() {
    [[ -n "$pip_pid" ]] || return 0
    if ! wait "$pip_pid"; then
        cat "$pip_log" >&2
        echo "setup: installing the Python packages failed" >&2
        exit 1
    fi
    pip_pid=""
}
trap '[[ -n "$pip_pid" ]] && kill "$pip_pid" 2>/dev/null; true' EXIT

# One build for the demo, the Python tests and the Rust tests. Everything but the FMU's shared
# library first: that one is linked by zig for glibc 2.17 (fmu/binary/link-gcc.sh), which the
# Python packages bring. The demo needs only the binaries named below. Every command selects the
# whole workspace (then excludes packages or picks targets) so that every dependency keeps the
# features it has in the full build: the second command and the tests' build reuse this one.
if ((for_tests)); then
    first_targets=()
    second_targets=()
else
    first_targets=(--bin pf-plan --bin pf-planner-service --bin bundle-fmu --bin pf-robot)
    second_targets=(--lib --exclude lcm-codegen)
fi
log "cargo build --release --workspace (all but the FMU binary${first_targets[*]:+: ${first_targets[*]}})"
cargo build --release --workspace --exclude quad-controller-fmu-binary "${first_targets[@]}" --quiet
wait_for_pip
log "Python packages installed"

if .venv/bin/python -m pip show lcm >/dev/null 2>&1; then
    .venv/bin/python -m pip uninstall -y -q lcm
fi
site="$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
echo "$ROOT/build/lcm/python" > "$site/pfnav_lcm.pth"
ln -sf "$ROOT/build/lcm/bin/lcm-logger" .venv/bin/lcm-logger
ln -sf "$ROOT/build/lcm/bin/lcm-logplayer" .venv/bin/lcm-logplayer
# lcm-gen 1.5.3 (a code generator, no network code) from the PyPI wheel, for the Python types'
# metadata the tests use; nothing else of the wheel is installed.
if [[ ! -x build/lcm-gen/lcm-gen ]]; then
    log "lcm-gen 1.5.3 from the PyPI wheel"
    wheels="$(mktemp -d)"
    .venv/bin/python -m pip download -q --no-deps --only-binary :all: lcm==1.5.3 -d "$wheels"
    mkdir -p build/lcm-gen
    .venv/bin/python - "$wheels" <<'PY'
import glob, os, sys, zipfile
wheel = glob.glob(os.path.join(sys.argv[1], "lcm-1.5.3-*.whl"))[0]
with zipfile.ZipFile(wheel) as z, open("build/lcm-gen/lcm-gen", "wb") as out:
    out.write(z.read("bin/lcm-gen"))
os.chmod("build/lcm-gen/lcm-gen", 0o755)
PY
    rm -rf "$wheels"
fi
ln -sf "$ROOT/build/lcm-gen/lcm-gen" .venv/bin/lcm-gen

# Python LCM types are generated from lcm_types/*.lcm by lcm-gen, never hand-written.
if [[ -x lcm_types/gen_python.sh ]] || [[ -f lcm_types/gen_python.sh ]]; then
    log "generating Python LCM types into build/lcm_python"
    LCM_GEN="$ROOT/build/lcm-gen/lcm-gen" bash lcm_types/gen_python.sh
    echo "$ROOT/build/lcm_python" > "$site/pfnav_lcm_types.pth"
fi

log "cargo build --release --workspace${second_targets[*]:+ ${second_targets[*]}}"
cargo build --release --workspace "${second_targets[@]}" --quiet
log "bundling the FMU (scripts/build_fmu_portable.sh)"
bash scripts/build_fmu_portable.sh
log "done"
