#!/usr/bin/env python3
"""Cost of one elevation-map update (fuse a scan + grow the variances) on a 128² map, beside the
cost of simulating the scan itself (ray casting), for the depth camera and the lidar.

Usage: .venv/bin/python scripts/bench_mapping.py [--repeats 30] [--size 128]
Prints min / median / max milliseconds over the repeats, with the machine and the date.
"""

from __future__ import annotations

import argparse
import datetime
import math
import platform
import time

import numpy as np
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
    args = parser.parse_args()
    terrain = hills(args.size, args.resolution, args.seed)
    centre = 0.5 * args.size * args.resolution
    print(f"{platform.node()} {platform.processor() or platform.machine()}, {datetime.date.today()}, map {args.size}² at {args.resolution} m")
    print(f"{'sensor':<14}{'rays':>6}{'returns':>9}  {'scan sim, ms (min/med/max)':>28}  {'map update, ms (min/med/max)':>30}")
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
            return f"{min(values):7.2f} {float(np.median(values)):7.2f} {max(values):7.2f}"

        print(f"{name:<14}{len(sensor.directions):>6}{int(np.median(returns)):>9}  {stats(scan_ms):>28}  {stats(map_ms):>30}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
