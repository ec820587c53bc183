#!/usr/bin/env python3
"""Cost of one elevation-map update (fuse a scan + grow the variances) on a 128² map, beside the
cost of simulating the scan itself (ray casting), for the depth camera and the lidar.

Usage: .venv/bin/python scripts/bench_mapping.py [--repeats 30] [--size 128] [--results-page mapping]
Prints min / median / max milliseconds over the repeats (with --results-page also
docs/results/NAME.md, stamped with commit, machine and date).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
from pfnav_harness import results_page
from pfnav_harness.elevation_map import ElevationMap, PoseBelief
from pfnav_harness.scenario import Terrain
from pfnav_harness.terrain_sensor import TerrainSensor, TerrainSensorConfig


def hills(size: int, resolution: float, seed: int) -> Terrain:
    rng = np.random.default_rng(seed)
    x = np.arange(size) * resolution
    gx, gy = np.meshgrid(x, x)
    heights = np.zeros((size, size))
    for _ in range(12):
        cx, cy = rng.uniform(0.0, size * resolution, 2)
        heights += rng.uniform(-0.6, 0.6) * np.exp(-((gx - cx) ** 2 + (gy - cy) ** 2) / (2.0 * rng.uniform(0.5, 2.0) ** 2))
    return Terrain((0.0, 0.0), resolution, heights)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--size", type=int, default=128, help="map cells per side")
    parser.add_argument("--resolution", type=float, default=0.125, help="m per cell")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--results-page", default=None, metavar="NAME", help="also publish the table as docs/results/NAME.md")
    args = parser.parse_args()
    if args.repeats < 1 or not 8 <= args.size <= 2048 or not 0.01 <= args.resolution <= 10.0:
        parser.error("--repeats >= 1, --size in [8, 2048], --resolution in [0.01, 10] m")
    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        parser.error(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    stamp = results_page.collect_stamp() if args.results_page else None
    terrain = hills(args.size, args.resolution, args.seed)
    centre = 0.5 * args.size * args.resolution
    rows = [
        f"Map {args.size}² cells of {args.resolution} m (hills, seed {args.seed}); the trunk circles 1 m around the centre; {args.repeats} scans per sensor.",
        "",
        "| sensor | rays | returns (median) | scan simulation, ms (min / median / max) | map update (fuse + grow), ms (min / median / max) |",
        "|---|---:|---:|---|---|",
    ]
    for name, config in (("depth_camera", TerrainSensorConfig(seed=args.seed)), ("lidar", TerrainSensorConfig.lidar(seed=args.seed))):
        sensor = TerrainSensor(terrain, config)
        emap = ElevationMap(terrain.origin, terrain.resolution, terrain.shape, config)
        scan_ms, map_ms, returns = [], [], []
        for k in range(args.repeats):
            yaw = 2.0 * math.pi * k / args.repeats
            x, y = centre + math.cos(yaw), centre + math.sin(yaw)
            position = np.array([x, y, float(terrain.height(x, y)) + 0.32])
            quaternion = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
            t0 = time.perf_counter()
            scan = sensor.scan(0.1 * k, position, quaternion)
            t1 = time.perf_counter()
            emap.fuse(scan, PoseBelief(position, quaternion))
            emap.grow(np.array([1e-5, 1e-5, 1e-5]))
            t2 = time.perf_counter()
            scan_ms.append(1e3 * (t1 - t0))
            map_ms.append(1e3 * (t2 - t1))
            returns.append(scan.returns)

        def stats(values: list[float]) -> str:
            return f"{min(values):.2f} / {float(np.median(values)):.2f} / {max(values):.2f}"

        rows.append(f"| {name} | {len(sensor.directions)} | {int(np.median(returns))} | {stats(scan_ms)} | {stats(map_ms)} |")
    print("\n".join(rows))
    if args.results_page:
        command = results_page.regenerate_command(".venv/bin/python scripts/bench_mapping.py", sys.argv[1:])
        path = results_page.write_results_page(args.results_page, "Elevation mapping: cost per update", "\n".join(rows), command, stamp)
        print(f"results page: {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
