#!/usr/bin/env python3
"""What the robot knows, compared on the same runs: online navigation with the ideal disc sensor,
with a depth camera planning as if map and position were exact, with the camera planning on the
belief (the default: the estimator's σ and the map's height variances reach the planner), and
with the camera, belief planning and GNSS-class position fixes.

Every online scenario (the paper's three and `surprise`) × terrain-sensor seeds; each run is one
`pfnav-demo run --online` on the kalman estimator. Per run: goal reached and fall (judged on the
truth), walked ∫p ds over the full-knowledge optimum, whether the true final position error lies
inside the estimator's own 2σ, the share of the sensed map's cells whose height lies within 2σ of
the truth (after the estimate's offset), replan latency p99, refused updates.

Runs inside the private network namespace (the planner speaks LCM); two runs at a time by default,
each on its own channel prefix:
    bash scripts/netns.sh .venv/bin/python scripts/sensing_campaign.py --out out/sensing --results-page sensing
"""

from __future__ import annotations

import argparse
import platform
import queue
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import online_campaign

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ("mountain_pass", "pits", "c_shape", "surprise")
# GNSS-class fixes: 1 Hz, 0.5 m standard deviation per axis.
FIXES = ["--fix-rate", "1", "--fix-noise", "0.5"]


@dataclass(frozen=True)
class Setting:
    name: str
    args: tuple[str, ...]
    # Whether the terrain-sensor seed changes anything (the ideal disc has no noise).
    seeded: bool


SETTINGS = (
    Setting("ideal sensor", ("--terrain-sensor", "ideal"), False),
    Setting("camera, exact planning", ("--terrain-sensor", "depth_camera", "--no-belief-planning"), True),
    Setting("camera + belief", ("--terrain-sensor", "depth_camera"), True),
    Setting("camera + belief + fixes", ("--terrain-sensor", "depth_camera", *FIXES), True),
)


@dataclass(frozen=True)
class Job:
    setting: Setting
    scenario: str
    seed: int

    def folder(self, out: Path) -> Path:
        slug = self.setting.name.replace(" + ", "-").replace(", ", "-").replace(" ", "-")
        return out / f"{slug}_{self.scenario}_{self.seed}"


def run(job: Job, out: Path, prefix: str) -> dict[str, Any]:
    """One `pfnav-demo run --online`; its single run's metrics (or the failure)."""
    args = ["--online", "--scenario", job.scenario, "--terrain-sensor-seed", str(job.seed), "--channel-prefix", prefix, *job.setting.args]
    return online_campaign.run(job.folder(out), args)


def run_all(jobs: list[Job], out: Path, workers: int, report: Callable[[Job, dict[str, Any], int], None]) -> dict[Job, dict[str, Any]]:
    """Runs `jobs` on `workers` threads, each with its own LCM channel prefix."""
    todo: queue.Queue[Job] = queue.Queue()
    for job in jobs:
        todo.put(job)
    results: dict[Job, dict[str, Any]] = {}
    lock = threading.Lock()

    def worker(index: int) -> None:
        while True:
            try:
                job = todo.get_nowait()
            except queue.Empty:
                return
            metrics = run(job, out, f"PFNAV_SENSING{index}_")
            with lock:
                results[job] = metrics
                report(job, metrics, len(results))

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(workers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return results


def final_within_2sigma(m: dict[str, Any]) -> bool | None:
    e = m.get("estimation") or {}
    error, sigma = e.get("position_error_final"), e.get("position_sigma_final")
    if error is None or sigma is None:
        return None
    return bool(error <= 2.0 * sigma)


def span(values: list[float], digits: int = 2) -> str:
    if not values:
        return "–"
    lo, hi = min(values), max(values)
    return f"{lo:.{digits}f}" if abs(hi - lo) < 0.5 * 10**-digits else f"{lo:.{digits}f}–{hi:.{digits}f}"


def summary_rows(results: dict[Job, dict[str, Any]]) -> list[str]:
    rows = [
        "| setting | runs | goal | fell | ∫p ds / optimum: " + " / ".join(SCENARIOS) + " | final error within own 2σ | map cells within 2σ (pooled; per run) | replan p99 max [ms] | refused updates |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for setting in SETTINGS:
        runs = {job: m for job, m in results.items() if job.setting == setting}
        if not runs:
            continue
        ok = {job: m for job, m in runs.items() if "error" not in m}
        goal = sum(bool(m["goal_reached"]) for m in ok.values())
        fell = sum(bool(m["fell"]) for m in ok.values())
        ratios = " / ".join(span([m["online"]["cost_ratio"] for job, m in ok.items() if job.scenario == s]) for s in SCENARIOS)
        within = [final_within_2sigma(m) for m in ok.values()]
        judged = [w for w in within if w is not None]
        cells = [(m["online"]["map_cells"], m["online"]["map_within_2sigma"]) for m in ok.values() if m["online"].get("map_within_2sigma") is not None]
        if cells:
            total = sum(n for n, _ in cells)
            pooled = sum(n * f for n, f in cells) / total
            map_text = f"{pooled * 100:.0f} % of {total}; {span([f * 100 for _, f in cells], 0)} %"
        else:
            map_text = "– (exact)"
        p99 = [m["online"]["latency_p99"] for m in ok.values() if m["online"].get("latency_p99") is not None]
        refused = sum(len(m["online"]["rejected"]) for m in ok.values())
        errors = len(runs) - len(ok)
        p99_text = f"{max(p99) * 1e3:.0f}" if p99 else "–"
        rows.append(
            f"| {setting.name} | {len(runs)}{f' ({errors} failed to run)' if errors else ''} | {goal} | {fell} | {ratios} | "
            f"{sum(judged)} of {len(judged)} | {map_text} | {p99_text} | {refused} |"
        )
    return rows


def run_rows(results: dict[Job, dict[str, Any]]) -> list[str]:
    rows = [
        "| setting | scenario | seed | goal | fell | ∫p ds ratio | final error / own σ [m] | map cells within 2σ | replan p99 [ms] | refused | wall [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for job in sorted(results, key=lambda j: (SETTINGS.index(j.setting), SCENARIOS.index(j.scenario) if j.scenario in SCENARIOS else 99, j.seed)):
        m = results[job]
        seed = job.seed if job.setting.seeded else "–"
        if "error" in m:
            rows.append(f"| {job.setting.name} | {job.scenario} | {seed} | error: {m['error']} | | | | | | | {m['wall']:.0f} |")
            continue
        o, e = m["online"], m.get("estimation") or {}
        within = o.get("map_within_2sigma")
        p99 = o.get("latency_p99")
        rows.append(
            f"| {job.setting.name} | {job.scenario} | {seed} | {'yes' if m['goal_reached'] else 'no'} | {'yes' if m['fell'] else 'no'} | "
            f"{o['cost_ratio']:.2f} | {e.get('position_error_final', float('nan')):.2f} / {e.get('position_sigma_final', float('nan')):.2f} | "
            f"{'–' if within is None else f'{within * 100:.0f} %'} | {'–' if p99 is None else f'{p99 * 1e3:.0f}'} | {len(o['rejected'])} | {m['wall']:.0f} |"
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "sensing")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS), help="online scenarios (comma-separated)")
    parser.add_argument("--seeds", type=int, default=5, help="terrain-sensor seeds 0 … N−1 per scenario (default 5)")
    parser.add_argument("--settings", default=None, help="which settings, by number 1-4 (comma-separated; default all)")
    parser.add_argument("--workers", type=int, default=2, help="runs at a time (default 2)")
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also publish the tables as docs/results/NAME.md")
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "harness" / "src"))
    from pfnav_harness import results_page

    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    if args.seeds < 1 or args.workers < 1:
        parser.error("--seeds and --workers must be at least 1")
    chosen = SETTINGS if args.settings is None else tuple(SETTINGS[int(k) - 1] for k in args.settings.split(","))
    scenarios = [s for s in args.scenarios.split(",") if s]
    stamp = results_page.collect_stamp() if args.results_page else None
    jobs = [Job(setting, scenario, seed) for setting in chosen for scenario in scenarios for seed in (range(args.seeds) if setting.seeded else [0])]
    started = time.perf_counter()

    def report(job: Job, m: dict[str, Any], done: int) -> None:
        verdict = m["error"] if "error" in m else f"goal={'yes' if m['goal_reached'] else 'no'} fell={'yes' if m['fell'] else 'no'}"
        print(f"[{done}/{len(jobs)} {time.perf_counter() - started:5.0f} s] {job.setting.name} {job.scenario} seed {job.seed}: {verdict}", file=sys.stderr, flush=True)

    results = run_all(jobs, args.out, args.workers, report)
    lines = [
        (
            f"Machine: {platform.node()} ({platform.machine()}, {platform.processor() or 'cpu'}), {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
            f"{len(jobs)} runs, {args.workers} at a time, {time.perf_counter() - started:.0f} s"
        ),
        "",
        "## Summary",
        "",
        *summary_rows(results),
        "",
        "## Runs",
        "",
        *run_rows(results),
        "",
    ]
    text = "\n".join(lines)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.md").write_text(text + "\n")
    print(text)
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/python scripts/sensing_campaign.py", sys.argv[1:])
        title = "Navigating on what the robot knows: ideal sensor, depth camera, belief planning, fixes"
        print(f"results page: {results_page.write_results_page(args.results_page, title, text, command, stamp)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
