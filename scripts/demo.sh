#!/usr/bin/env bash
# The main job, end to end on the paper's three scenarios (mountain_pass, pits, c_shape):
#  1. the planner alone: P-F (indicator and RBF bases), A* and Dijkstra on the same maps
#     -> out/planner/report.md with one PNG per scenario;
#  2. the co-simulation: pf-planner-service on LCM (private network namespace), P-F and A* plans,
#     the controller FMU (fmpy) walking a DART quadruped over the terrain
#     -> out/report.md with tables and plots.
# Extra arguments go to `pfnav-demo demo` (e.g. --scenario c_shape, --short, --duration 10,
# --lcm-log, --comm-step 0.002; see `.venv/bin/pfnav-demo demo --help`).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
start=$SECONDS
bash scripts/setup.sh
target/release/pf-plan demo --out out/planner
bash scripts/netns.sh .venv/bin/pfnav-demo demo --out out "$@"
echo "planner report: $ROOT/out/planner/report.md"
echo "co-simulation report: $ROOT/out/report.md"
echo "whole demo: $((SECONDS - start)) s"
