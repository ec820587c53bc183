#!/usr/bin/env bash
# The main job: plans the paper's three scenarios (mountain_pass, pits, c_shape) with P-F, A* and
# Dijkstra and writes out/report.md with one PNG per scenario.
# Extra arguments go to `pf-plan demo` (see `target/release/pf-plan demo --help`).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
bash scripts/setup.sh
bash scripts/netns.sh target/release/pf-plan demo --out out "$@"
echo "report: $ROOT/out/report.md"
