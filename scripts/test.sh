#!/usr/bin/env bash
# Runs every test of the project: formatting and lint gates, the Rust workspace tests and the
# Python tests. Installs what is missing first (scripts/setup.sh). Tests that use LCM's udpm://
# run inside private network namespaces (scripts/netns.sh), one for the Python tests and one for
# the Rust tests.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
start=$SECONDS
# Each line carries the seconds since the start, so a slow phase shows in the CI log.
log() { printf '\033[1;32m[test %4ds]\033[0m %s\n' "$((SECONDS - start))" "$*"; }

bash scripts/setup.sh --tests

log "cargo fmt --check"
cargo fmt --all -- --check
log "ruff"
.venv/bin/ruff check harness tests scripts examples

# The Python tests run on the release build setup.sh made while clippy and the Rust tests compile
# beside them at a lower priority: pytest is mostly one process, so the second core would
# otherwise idle. Nothing below rebuilds what the Python tests run (tests/test_build_reuse.py).
mkdir -p build/test-logs
pytest_log=build/test-logs/pytest.log
log "pytest (private network namespace) started beside the Rust checks, log: $pytest_log"
# setsid: pytest and everything it starts form one process group, stopped together on failure.
setsid bash scripts/netns.sh .venv/bin/python -m pytest -q tests harness/tests > "$pytest_log" 2>&1 &
pytest_pid=$!
stop_pytest() {
    if [[ -n "${pytest_pid:-}" ]]; then
        kill -- "-$pytest_pid" 2>/dev/null || true
        echo "--- pytest output so far ($pytest_log) ---"
        tail -n 60 "$pytest_log" || true
    fi
}
trap stop_pytest EXIT

# --release everywhere: clippy reuses the release build's proc macros and build scripts, and the
# tests link against the release build of the dependencies that setup.sh already compiled.
log "cargo clippy -D warnings"
nice -n 15 cargo clippy --release --workspace --all-targets --quiet -- -D warnings
log "building Rust tests"
nice -n 15 cargo test --release --workspace --no-run --quiet
log "cargo test (private network namespace)"
# pfnav-robot's tests time a 1 kHz loop against a body on its own clock: they run alone, after
# pytest, not starved beside it.
nice -n 15 bash scripts/netns.sh cargo test --release --workspace --exclude pfnav-robot --offline --quiet

log "waiting for pytest"
set +e
wait "$pytest_pid"
rc=$?
set -e
pytest_pid=""
cat "$pytest_log"
# Exit code 5 means "no tests collected": only acceptable while no Python tests exist yet.
if ((rc != 0 && rc != 5)); then
    log "pytest failed (exit $rc)"
    exit "$rc"
fi
log "cargo test -p pfnav-robot (real-time loop tests, alone on the machine)"
bash scripts/netns.sh cargo test --release -p pfnav-robot --offline --quiet
log "all tests passed in $((SECONDS - start)) s"
