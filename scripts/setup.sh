#!/usr/bin/env bash
# Installs everything the demo and the tests need on a fresh Debian machine (run as root):
# Debian packages, the Python venv with pinned versions, generated LCM Python types,
# release builds of the workspace and the bundled FMU. Safe to run again: it skips what is done.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
log() { printf '\033[1;34m[setup]\033[0m %s\n' "$*"; }

# libclang-dev: bindgen in the fmi crate (the FMU importer used by the Rust FMU tests).
# cmake, make: OSQP's C sources (osqp-sys), the MPC benchmark's comparison solver and test cross-check.
APT_PACKAGES=(liblcm-dev liblcm-bin libglib2.0-dev iproute2 util-linux pkg-config
              libfontconfig1-dev libfreetype-dev fonts-dejavu-core binutils
              libclang-dev cmake make)
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
stamp=.venv/.pfnav-requirements
# Hash of everything pip installs from; a missing file hashes as empty instead of aborting.
want="$( { cat scripts/requirements.txt; cat harness/pyproject.toml 2>/dev/null || true; } | sha256sum | cut -d' ' -f1)"
if [[ "$(cat "$stamp" 2>/dev/null)" != "$want" ]]; then
    log "installing pinned Python packages"
    .venv/bin/pip install -q --disable-pip-version-check -r scripts/requirements.txt
    if [[ -f harness/pyproject.toml ]]; then
        .venv/bin/pip install -q --disable-pip-version-check -e harness
    fi
    echo "$want" > "$stamp"
fi

# Python LCM types are generated from lcm_types/*.lcm by lcm-gen, never hand-written.
if [[ -x lcm_types/gen_python.sh ]] || [[ -f lcm_types/gen_python.sh ]]; then
    log "generating Python LCM types into build/lcm_python"
    PATH="$ROOT/.venv/bin:$PATH" bash lcm_types/gen_python.sh
    site="$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"
    echo "$ROOT/build/lcm_python" > "$site/pfnav_lcm_types.pth"
fi

log "cargo build --release --workspace"
cargo build --release --workspace --quiet

if [[ -f fmu/Cargo.toml ]] && grep -q 'name = "bundle-fmu"' fmu/Cargo.toml; then
    log "bundling the FMU"
    cargo run --release --quiet -p quad-controller-fmu --bin bundle-fmu
fi
log "done"
