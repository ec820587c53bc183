#!/usr/bin/env bash
# Runs every test of the project: formatting and lint gates, the Rust workspace tests and the
# Python tests. Installs what is missing first (scripts/setup.sh). Tests that use LCM's udpm://
# run inside a private network namespace (scripts/netns.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
start=$SECONDS
# Each line carries the seconds since the start, so a slow phase shows in the CI log.
log() { printf '\033[1;32m[test %4ds]\033[0m %s\n' "$((SECONDS - start))" "$*"; }

bash scripts/setup.sh

log "cargo fmt --check"
cargo fmt --all -- --check
# --release everywhere: clippy reuses the release build's proc macros and build scripts, and the
# tests link against the release build of the dependencies that setup.sh already compiled.
log "cargo clippy -D warnings"
cargo clippy --release --workspace --all-targets --quiet -- -D warnings
log "building tests"
cargo test --release --workspace --no-run --quiet

log "cargo test (private network namespace)"
bash scripts/netns.sh cargo test --release --workspace --offline --quiet

log "ruff"
.venv/bin/ruff check harness tests scripts examples

log "pytest (private network namespace)"
# Exit code 5 means "no tests collected": only acceptable while no Python tests exist yet.
set +e
bash scripts/netns.sh .venv/bin/python -m pytest -q tests harness/tests
rc=$?
set -e
if ((rc != 0 && rc != 5)); then exit "$rc"; fi
log "all tests passed in $((SECONDS - start)) s"
