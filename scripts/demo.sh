#!/usr/bin/env bash
# The main job, end to end on the paper's three scenarios (mountain_pass, pits, c_shape):
#  1. the planner alone: P-F (indicator and RBF bases), A* and Dijkstra on the same maps
#     -> out/planner/report.md with one PNG per scenario;
#  2. the co-simulation: pf-planner-service on LCM (private network namespace), P-F and A* plans,
#     the controller FMU (fmpy) walking a DART quadruped over the terrain
#     -> out/report.md with tables and plots;
#  3. online navigation: the three scenarios and `surprise`, the robot sensing the terrain as it
#     walks, map updates and replans over LCM at 2 Hz, the P-F feedback field followed from the
#     robot's own position -> out/online/report.md.
# Steps 2 and 3 also write a Rerun recording and a video of every run (OUT/recordings/*.rrd,
# OUT/videos/*.mp4; open a recording with `.venv/bin/rerun FILE.rrd`) and the report as one page
# with the videos, out/report.html and out/online/report.html.
# Extra arguments go to `pfnav-demo demo` (e.g. --scenario c_shape, --short, --duration 10,
# --lcm-log, --comm-step 0.002; see `.venv/bin/pfnav-demo demo --help`).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
start=$SECONDS
bash scripts/setup.sh
target/release/pf-plan demo --out out/planner
# Steps 2 and 3 run side by side, each in its own private network namespace (a --jobs among the
# extra arguments overrides the split below; the runs' results do not depend on it). The online
# step is the longer one (four runs of 40-70 simulated s against six shorter ones), so it gets
# every CPU and the co-simulation step half of them: on 2 cores the demo's runs took 161-184 s
# against 175-229 s at one process each (measured alternately, 2026-11-28); at 2 + 2 the
# extra process only slowed every run down. The online step keeps the terminal; the
# co-simulation step writes out/cosim.log, shown when it ends.
jobs=$(( ($(nproc) + 1) / 2 ))
mkdir -p out
bash scripts/netns.sh .venv/bin/pfnav-demo demo --out out --jobs "$jobs" --no-progress --record --video "$@" \
    > out/cosim.log 2>&1 &
cosim=$!
trap 'kill "$cosim" 2>/dev/null || true' EXIT
bash scripts/netns.sh .venv/bin/pfnav-demo demo --online --out out/online --jobs "$(nproc)" --record --video \
    --scenario mountain_pass --scenario pits --scenario c_shape --scenario surprise "$@"
cosim_status=0
wait "$cosim" || cosim_status=$?
trap - EXIT
cat out/cosim.log
if ((cosim_status != 0)); then
    echo "demo: the co-simulation step failed (exit $cosim_status), log above: out/cosim.log" >&2
    exit "$cosim_status"
fi
echo "planner report: $ROOT/out/planner/report.md"
echo "co-simulation report: $ROOT/out/report.md (with videos: $ROOT/out/report.html)"
echo "online navigation report: $ROOT/out/online/report.md (with videos: $ROOT/out/online/report.html)"
echo "recordings of every run: $ROOT/out/recordings/ and $ROOT/out/online/recordings/ (open one with .venv/bin/rerun FILE.rrd)"
echo "whole demo: $((SECONDS - start)) s"
