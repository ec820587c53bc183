#!/usr/bin/env python3
"""Online navigation and push campaigns: the measurements behind the README's online table.

1. online: every scenario (the paper's three and `surprise`) with sensing + replanning + the
   feedback field: goal, falls, replans, replan latency p50/p99, ∫p ds against the full-knowledge
   optimum;
2. pushes: sideways pushes (default 60 N for 0.2 s) at a seeded random walk time, SEEDS seeds ×
   the paper's scenarios, feedback mode on the full-knowledge plan, no replanning: goal, falls,
   and how far the push displaced the robot (largest distance to the unpushed run at equal
   times; the co-simulation is deterministic, so the difference is the push's doing).

Each run is one `pfnav-demo run` (its own report and metrics.json under OUT); the tables are printed
and written to OUT/summary.md, and with --results-page NAME to docs/results/NAME.md. Runs inside
the private network namespace (the planner speaks LCM):
    bash scripts/netns.sh .venv/bin/python scripts/online_campaign.py --out out/online-campaign --results-page online-campaign
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
# The pfnav-demo of the venv this script runs in.
DEMO = Path(sys.executable).parent / "pfnav-demo"
PAPER = ("mountain_pass", "pits", "c_shape")


def run(out: Path, args: list[str], engine: str) -> dict[str, Any]:
    """One `pfnav-demo run` in the physics engine `engine`; returns its single run's metrics (or the failure)."""
    command = [str(DEMO), "run", "--out", str(out), "--no-progress", "--engine", engine, *args]
    started = time.perf_counter()
    proc = subprocess.run(command, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [f"exit code {proc.returncode}"]
        return {"error": tail[0], "wall": wall}
    metrics = json.loads((out / "metrics.json").read_text())["runs"][0]
    metrics["wall"] = wall
    return metrics


def fmt(value: Any, digits: int = 2, scale: float = 1.0) -> str:
    if value is None:
        return "–"
    return f"{value * scale:.{digits}f}"


def online_rows(results: dict[str, dict[str, Any]]) -> list[str]:
    rows = [
        "| scenario | goal | fell | updates (Hz) | replans used | latency p50 / p99 / max [ms] | ∫p ds walked / full-knowledge | ratio | rejected | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, m in results.items():
        if "error" in m:
            rows.append(f"| {name} | error: {m['error']} | | | | | | | | {m['wall']:.0f} |")
            continue
        o = m["online"]
        rows.append(
            f"| {name} | {'yes' if m['goal_reached'] else 'no'} | {'yes' if m['fell'] else 'no'} | {o['map_updates']} ({o['update_rate']:.1f}) | "
            f"{o['replans_in_use']} | {fmt(o['latency_p50'], 0, 1e3)} / {fmt(o['latency_p99'], 0, 1e3)} / {fmt(o['latency_max'], 0, 1e3)} | "
            f"{o['executed_cost']:.2f} / {o['full_knowledge_cost']:.2f} | {o['cost_ratio']:.3f} | {len(o['rejected'])} | {m['wall']:.0f} |"
        )
    return rows


def displacement(pushed: Path, baseline: Path) -> float | None:
    """Largest horizontal distance between the pushed and the unpushed run at equal times."""
    try:
        a = np.load(next(pushed.glob("logs/*.npz")))
        b = np.load(next(baseline.glob("logs/*.npz")))
    except (StopIteration, OSError, ValueError):
        return None
    n = min(len(a["t"]), len(b["t"]))
    return float(np.max(np.hypot(*(a["base_pos"][:n, :2] - b["base_pos"][:n, :2]).T)))


def push_rows(results: dict[tuple[str, int], tuple[float | None, dict[str, Any]]]) -> list[str]:
    rows = [
        "| scenario | seed | push at [s] | goal | fell | displaced by the push [m] | max deviation from plan [m] | time to goal [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (name, seed), (at, m) in results.items():
        if "error" in m:
            rows.append(f"| {name} | {seed} | {fmt(at)} | error: {m['error']} | | | | |")
            continue
        rows.append(
            f"| {name} | {seed if seed else 'no push'} | {fmt(at)} | {'yes' if m['goal_reached'] else 'no'} | {'yes' if m['fell'] else 'no'} | "
            f"{fmt(m.get('displacement'))} | {m['max_path_deviation']:.2f} | {fmt(m['time_to_goal'], 1)} |"
        )
    return rows


def main() -> int:
    sys.path.insert(0, str(ROOT / "harness" / "src"))
    from pfnav_harness import results_page
    from pfnav_harness.engine import DEFAULT_ENGINE, ENGINE_NAMES

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "online")
    parser.add_argument("--scenarios", default=",".join((*PAPER, "surprise")), help="online runs (comma-separated)")
    parser.add_argument("--push-scenarios", default=",".join(PAPER), help="push runs (comma-separated; empty: none)")
    parser.add_argument("--seeds", type=int, default=5, help="push seeds per scenario (default 5)")
    parser.add_argument("--push", default="60@side", help="push force and direction MAG@DIR (default 60@side)")
    parser.add_argument("--push-duration", type=float, default=0.2)
    parser.add_argument("--push-window", default="2,12", help="walk-clock window of the push times, s (default 2,12)")
    parser.add_argument("--bad-map-updates", default="nan,shape,stale", help="broken updates sent in the first online run (empty: none)")
    parser.add_argument(
        "--engine", choices=ENGINE_NAMES, default=DEFAULT_ENGINE, help=f"physics engine of every run (pfnav-demo --engine; default {DEFAULT_ENGINE})"
    )
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also publish the tables as docs/results/NAME.md")
    args = parser.parse_args()
    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    # Taken before the runs: the commit that ran and the load it ran under.
    stamp = results_page.collect_stamp() if args.results_page else None

    scenarios = [s for s in args.scenarios.split(",") if s]
    push_scenarios = [s for s in args.push_scenarios.split(",") if s]
    first, last = (float(v) for v in args.push_window.split(","))
    lines = [
        (
            f"Machine: {platform.node()} ({platform.machine()}, {platform.processor() or 'cpu'}), {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
            f"physics engine {args.engine}"
        ),
        "",
    ]

    online: dict[str, dict[str, Any]] = {}
    for k, name in enumerate(scenarios):
        extra = ["--bad-map-updates", args.bad_map_updates] if k == 0 and args.bad_map_updates else []
        print(f"online {name} ...", file=sys.stderr, flush=True)
        online[name] = run(args.out / f"online_{name}", ["--scenario", name, "--online", *extra], args.engine)
    lines += ["## Online navigation (sensing + replanning + feedback field)", "", *online_rows(online), ""]
    for name, m in online.items():
        for reason in (m.get("online") or {}).get("rejected", []):
            lines.append(f"- {name}: {reason}")
    lines.append("")

    pushes: dict[tuple[str, int], tuple[float | None, dict[str, Any]]] = {}
    for name in push_scenarios:
        baseline = args.out / f"push_{name}_0"
        print(f"push {name}: unpushed baseline ...", file=sys.stderr, flush=True)
        pushes[(name, 0)] = (None, run(baseline, ["--scenario", name, "--follow", "feedback"], args.engine))
        for seed in range(1, args.seeds + 1):
            at = float(np.round(np.random.default_rng(seed).uniform(first, last), 3))
            print(f"push {name} seed {seed} at {at:.2f} s ...", file=sys.stderr, flush=True)
            spec = f"{args.push}:{at}+{args.push_duration}"
            folder = args.out / f"push_{name}_{seed}"
            metrics = run(folder, ["--scenario", name, "--follow", "feedback", "--push", spec], args.engine)
            metrics["displacement"] = displacement(folder, baseline)
            pushes[(name, seed)] = (at, metrics)
    if pushes:
        lines += [f"## Pushes ({args.push} N for {args.push_duration} s, feedback mode, no replanning)", "", *push_rows(pushes), ""]

    text = "\n".join(lines)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.md").write_text(text + "\n")
    print(text)
    if args.results_page:
        title = "Online navigation and push campaigns"
        command = results_page.regenerate_command(".venv/bin/python scripts/online_campaign.py", sys.argv[1:])
        print(f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
