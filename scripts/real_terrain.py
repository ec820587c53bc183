#!/usr/bin/env python3
"""Real elevation data at robot scale (issue 19): P-F plans and co-simulated walks on crops of a real DEM.

The DEM is the one matplotlib's wheel ships (`jacksboro_fault_dem.npz`, 3 arc-second cells near
Jacksboro, Tennessee; origin and licence in docs/real-terrain.md), so nothing is downloaded. Steps:

1. geographic → local metres at the DEM's mean latitude (WGS84 radii of curvature), written as an
   ESRI ASCII grid with its own `dx`/`dy` (the cells are 74.6 m × 92.5 m; `pf-plan import`
   resamples to square cells itself);
2. square crops of `--source-columns` source columns, chosen by their slope statistics (closest to
   `--target-p95` / `--target-max`, not overlapping), each scaled uniformly (slopes kept) to
   `--cells` × `--cells` cells of `--cell-size` m by `pf-plan import`;
3. start and goal on the flattest footprint near two opposite corners (the controller's stand-up
   fails on ≥ 20° slopes, docs/slopes.md; a run that falls while standing up says nothing about
   the plan);
4. `pfnav-demo run --map` (P-F, inside `scripts/netns.sh`) per crop and planner slope limit;
5. OUT/table.md, OUT/results.json and one figure per crop (shaded relief, planned and walked paths).

    .venv/bin/python scripts/real_terrain.py                          # 3 crops × {no limit, 20°}
    .venv/bin/python scripts/real_terrain.py --exaggeration 1.5       # a separately labelled variant
    .venv/bin/python scripts/real_terrain.py --results-page real-terrain   # also docs/results/real-terrain.md
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import math
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[1]
DEM_SAMPLE = "jacksboro_fault_dem.npz"
# WGS84 ellipsoid: semi-major axis (m) and flattening.
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
# Start/goal search: cells this far (m) from both edges of a corner, footprint radius (m) over
# which the slope is averaged (about the robot's half length).
CORNER_BAND = (0.75, 2.25)
NODATA = -9999.0
FOOTPRINT_RADIUS = 0.3

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MetricDem:
    """The DEM in local metres: heights (row 0 = north), cell sizes and where it came from."""

    heights: FloatArray
    dx: float
    dy: float
    mean_latitude: float
    lon_range: tuple[float, float]
    lat_range: tuple[float, float]


@dataclass(frozen=True)
class Crop:
    """A square window of the metric DEM, source columns/rows [c0, c0+n) × [r0, r0+m) (row 0 = north)."""

    name: str
    c0: int
    r0: int
    columns: int
    rows: int
    source_p50: float
    source_p95: float
    source_max: float


@dataclass
class RunRow:
    crop: str
    limit: str
    map_p50: float
    map_p95: float
    map_max: float
    start_slope: float
    goal_slope: float
    planned: bool
    error: str = ""
    path_p50: float = math.nan
    path_p95: float = math.nan
    path_max: float = math.nan
    planner_cost: float = math.nan
    plan_length: float = math.nan
    goal_reached: bool = False
    fell: bool = False
    fall_time: float | None = None
    fall_reason: str = ""
    rms_error: float = math.nan
    final_distance: float = math.nan
    plan_end_distance: float = math.nan
    wall_seconds: float = math.nan
    extra: dict[str, Any] = field(default_factory=dict)


def load_metric_dem(exaggeration: float = 1.0) -> MetricDem:
    """matplotlib's sample DEM with cell sizes in metres (heights × `exaggeration`, 1 = as measured)."""
    from matplotlib import cbook

    with cbook.get_sample_data(DEM_SAMPLE) as dem:
        heights = np.asarray(dem["elevation"], dtype=np.float64) * exaggeration
        dlon, dlat = float(dem["dx"]), float(dem["dy"])
        # The file's "ymin" is the northern edge (row 0), its "ymax" the southern one.
        lons = (float(dem["xmin"]), float(dem["xmax"]))
        lats = (
            min(float(dem["ymin"]), float(dem["ymax"])),
            max(float(dem["ymin"]), float(dem["ymax"])),
        )
    lat = math.radians(0.5 * (lats[0] + lats[1]))
    e2 = WGS84_F * (2.0 - WGS84_F)
    w = 1.0 - e2 * math.sin(lat) ** 2
    meridional = WGS84_A * (1.0 - e2) / w**1.5
    prime_vertical = WGS84_A / math.sqrt(w)
    return MetricDem(
        heights=heights,
        dx=math.radians(dlon) * prime_vertical * math.cos(lat),
        dy=math.radians(dlat) * meridional,
        mean_latitude=math.degrees(lat),
        lon_range=lons,
        lat_range=lats,
    )


def write_esri_ascii(dem: MetricDem, path: Path, crop: Crop | None = None, rim: int = 0) -> Path:
    """The DEM (or a crop of it) as an ESRI ASCII grid in metres, lower-left corner at (0, 0).

    `rim` > 0 marks that many outer rings of source cells nodata, which `pf-plan import` turns into
    obstacles: a keep-out band along the map's edge, where the physics terrain ends.
    """
    heights = dem.heights if crop is None else dem.heights[crop.r0 : crop.r0 + crop.rows, crop.c0 : crop.c0 + crop.columns]
    if rim > 0:
        heights = heights.copy()
        heights[:rim, :] = heights[-rim:, :] = NODATA
        heights[:, :rim] = heights[:, -rim:] = NODATA
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as fh:
        fh.write(f"ncols {heights.shape[1]}\nnrows {heights.shape[0]}\nxllcorner 0\nyllcorner 0\n")
        fh.write(f"dx {dem.dx!r}\ndy {dem.dy!r}\nNODATA_value {NODATA:g}\n")
        np.savetxt(fh, heights, fmt="%.3f")
    return path


def cell_slopes_deg(heights: FloatArray, dx: float, dy: float) -> FloatArray:
    """Slope of each cell, degrees: central differences, one-sided at the edges (the planner's `slope_deg`)."""
    gy, gx = np.gradient(heights, dy, dx, edge_order=1)
    return np.degrees(np.arctan(np.hypot(gx, gy)))


def find_crops(
    dem: MetricDem,
    columns: int,
    count: int,
    target_p95: float,
    target_max: float,
    stride: int = 4,
) -> list[Crop]:
    """The `count` non-overlapping square windows whose slope p95 and max are closest to the targets."""
    rows = max(2, round(columns * dem.dx / dem.dy))
    slopes = cell_slopes_deg(dem.heights, dem.dx, dem.dy)
    ny, nx = slopes.shape
    if columns > nx or rows > ny:
        raise SystemExit(f"--source-columns {columns}: the DEM has only {nx} × {ny} cells")
    scored = []
    for r0 in range(0, ny - rows + 1, stride):
        for c0 in range(0, nx - columns + 1, stride):
            window = slopes[r0 : r0 + rows, c0 : c0 + columns]
            p50, p95, peak = np.percentile(window, [50, 95, 100])
            score = abs(p95 - target_p95) + 0.5 * abs(peak - target_max)
            scored.append((score, r0, c0, float(p50), float(p95), float(peak)))
    scored.sort()
    chosen: list[Crop] = []
    for _, r0, c0, p50, p95, peak in scored:
        if all(abs(r0 - c.r0) >= rows or abs(c0 - c.c0) >= columns for c in chosen):
            chosen.append(Crop(f"crop{len(chosen) + 1}", c0, r0, columns, rows, p50, p95, peak))
            if len(chosen) == count:
                break
    return chosen


def crop_window_metres(dem: MetricDem, crop: Crop) -> tuple[float, float, float, float]:
    """The crop in the grid's own coordinates (lower-left (0, 0), y north), inset by a quarter cell."""
    ny = dem.heights.shape[0]
    x0 = crop.c0 * dem.dx
    y0 = (ny - crop.r0 - crop.rows) * dem.dy
    x1 = x0 + crop.columns * dem.dx
    y1 = y0 + crop.rows * dem.dy
    return (
        x0 + 0.25 * dem.dx,
        y0 + 0.25 * dem.dy,
        x1 - 0.25 * dem.dx,
        y1 - 0.25 * dem.dy,
    )


def run_import(
    pf_plan: Path,
    asc: Path,
    out: Path,
    name: str,
    window: tuple[float, float, float, float] | None,
    scale: float,
    cell: float,
    start: tuple[float, float],
    goal: tuple[float, float],
) -> tuple[Path, str]:
    """`pf-plan import` of one crop; returns the sidecar and the printed summary."""
    yaw = math.atan2(goal[1] - start[1], goal[0] - start[0])
    command = [
        str(pf_plan), "import", str(asc), "--out", str(out), "--name", name,
        *([] if window is None else ["--crop", ",".join(f"{v:.3f}" for v in window)]),
        "--scale", repr(scale), "--cell-size", repr(cell),
        "--start", f"{start[0]:.3f},{start[1]:.3f}", "--goal", f"{goal[0]:.3f},{goal[1]:.3f}", f"--start-yaw={yaw:.4f}",
    ]  # fmt: skip
    proc = subprocess.run(
        command,
        capture_output=True,
        text=True,
        check=False,
        env={"RUST_BACKTRACE": "0", "PATH": "/usr/bin:/bin"},
    )
    if proc.returncode != 0:
        raise SystemExit(f"pf-plan import failed for {name}:\n{proc.stderr.strip()}")
    return out / f"{name}.json", proc.stdout.strip()


def summary_slopes(summary: str) -> tuple[float, float, float]:
    """p50, p95, max from the `slope:` line of `pf-plan import`'s summary (the planner's own figures)."""
    for line in summary.splitlines():
        if line.startswith("slope:"):
            parts = line.replace(",", " ").split()
            return float(parts[2]), float(parts[5]), float(parts[8])
    raise SystemExit(f"no slope line in the import summary:\n{summary}")


def flattest_near(slopes: FloatArray, resolution: float, corner: tuple[bool, bool]) -> tuple[tuple[float, float], float]:
    """The cell centre near a map corner (east?, north?) with the lowest slope averaged over the footprint."""
    ny, nx = slopes.shape
    k = max(1, round(FOOTPRINT_RADIUS / resolution))
    padded = np.pad(slopes, k, mode="edge")
    offsets = [(dy, dx) for dy in range(-k, k + 1) for dx in range(-k, k + 1) if dx * dx + dy * dy <= k * k]
    mean = sum(padded[k + dy : k + dy + ny, k + dx : k + dx + nx] for dy, dx in offsets) / len(offsets)
    centres_x = (np.arange(nx) + 0.5) * resolution
    centres_y = (np.arange(ny) + 0.5) * resolution
    lo, hi = CORNER_BAND
    from_x = (nx * resolution - centres_x) if corner[0] else centres_x
    from_y = (ny * resolution - centres_y) if corner[1] else centres_y
    mask = ((from_y >= lo) & (from_y <= hi))[:, None] & ((from_x >= lo) & (from_x <= hi))[None, :]
    candidates = np.where(mask, mean, np.inf)
    iy, ix = np.unravel_index(int(np.argmin(candidates)), candidates.shape)
    return (float(centres_x[ix]), float(centres_y[iy])), float(mean[iy, ix])


def path_slopes(slopes: FloatArray, resolution: float, x: FloatArray, y: FloatArray) -> tuple[float, float, float]:
    """p50, p95, max of the cell slope under each sample of a path."""
    ny, nx = slopes.shape
    ix = np.clip(np.floor(np.asarray(x) / resolution).astype(int), 0, nx - 1)
    iy = np.clip(np.floor(np.asarray(y) / resolution).astype(int), 0, ny - 1)
    p50, p95, peak = np.percentile(slopes[iy, ix], [50, 95, 100])
    return float(p50), float(p95), float(peak)


def run_demo(sidecar: Path, out: Path, max_slope: float | None, duration: float | None) -> tuple[int, str]:
    """`pfnav-demo run --map` (P-F) inside the private network namespace; returns exit code and stderr."""
    command = [
        "bash",
        str(REPO / "scripts" / "netns.sh"),
        str(Path(sys.executable).parent / "pfnav-demo"),
        "run",
        "--map",
        str(sidecar),
    ]
    command += ["--method", "pf", "--out", str(out), "--no-progress"]
    if max_slope is not None:
        command += ["--max-slope-deg", f"{max_slope:g}"]
    if duration is not None:
        command += ["--duration", f"{duration:g}"]
    proc = subprocess.run(command, capture_output=True, text=True, check=False, cwd=REPO)
    (out / "pfnav-demo.stderr.txt").parent.mkdir(parents=True, exist_ok=True)
    (out / "pfnav-demo.stderr.txt").write_text(proc.stderr)
    return proc.returncode, proc.stderr


def plot_crop(
    path: Path,
    crop: Crop,
    heights: FloatArray,
    resolution: float,
    runs: list[tuple[RunRow, dict[str, Any] | None]],
    start: tuple[float, float],
    goal: tuple[float, float],
    goal_radius: float,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LightSource

    ny, nx = heights.shape
    extent = (0.0, nx * resolution, 0.0, ny * resolution)
    shade = LightSource(azdeg=315, altdeg=45).shade(
        heights,
        cmap=plt.get_cmap("gist_earth"),
        blend_mode="soft",
        vert_exag=1.0,
        dx=resolution,
        dy=resolution,
    )
    fig, ax = plt.subplots(figsize=(9.6, 6.0))
    ax.imshow(shade, origin="lower", extent=extent)
    slopes = cell_slopes_deg(heights, resolution, resolution)
    contour = ax.contour(
        (np.arange(nx) + 0.5) * resolution,
        (np.arange(ny) + 0.5) * resolution,
        slopes,
        levels=[20.0],
        colors="white",
        linewidths=0.6,
        linestyles=":",
    )
    ax.clabel(contour, fmt="%g°", fontsize=6)
    colours = ["tab:red", "tab:blue", "tab:purple", "tab:orange"]
    for (row, log), colour in zip(runs, colours, strict=False):
        if log is None:
            ax.plot([], [], color=colour, label=f"{row.limit}: no plan")
            continue
        ax.plot(
            log["plan_x"],
            log["plan_y"],
            "--",
            color=colour,
            lw=1.4,
            label=f"{row.limit}: planned",
        )
        pos = log["base_pos"]
        outcome = "fell" if row.fell else ("goal" if row.goal_reached else f"ended {row.final_distance:.2f} m from the goal centre")
        ax.plot(
            pos[:, 0],
            pos[:, 1],
            "-",
            color=colour,
            lw=1.8,
            label=f"{row.limit}: walked ({outcome})",
        )
        if row.fell:
            ax.plot(pos[-1, 0], pos[-1, 1], "x", color=colour, ms=9, mew=2)
    ax.plot(*start, "o", color="white", mec="black", ms=7, label="start")
    ax.add_patch(plt.Circle(goal, goal_radius, fill=False, color="yellow", lw=1.5))
    ax.plot(*goal, "*", color="yellow", mec="black", ms=11, label="goal")
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(
        f"{crop.name}: DEM cols {crop.c0}–{crop.c0 + crop.columns}, rows {crop.r0}–{crop.r0 + crop.rows} (dotted: 20° slope)",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def fmt(value: float | None, digits: int = 1) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def write_table(path: Path, rows: list[RunRow], header: list[str]) -> None:
    lines = [*header, ""]
    lines.append(
        "| crop | planner slope limit | map slope p50 / p95 / max (°) | start / goal slope (°) | path slope p50 / p95 / max (°) | "
        "plan ∫p ds | plan length (m) | reached goal | fell | RMS tracking error (m) | final distance to goal / plan end's (m) |"
    )
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if not r.planned:
            lines.append(
                f"| {r.crop} | {r.limit} | {fmt(r.map_p50)} / {fmt(r.map_p95)} / {fmt(r.map_max)} | {fmt(r.start_slope)} / {fmt(r.goal_slope)} | "
                f"no plan: {r.error} | – | – | – | – | – | – |"
            )
            continue
        fell = f"yes, at {r.fall_time:.2f} s ({r.fall_reason})" if r.fell and r.fall_time is not None else ("yes" if r.fell else "no")
        lines.append(
            f"| {r.crop} | {r.limit} | {fmt(r.map_p50)} / {fmt(r.map_p95)} / {fmt(r.map_max)} | {fmt(r.start_slope)} / {fmt(r.goal_slope)} | "
            f"{fmt(r.path_p50)} / {fmt(r.path_p95)} / {fmt(r.path_max)} | {fmt(r.planner_cost, 2)} | {fmt(r.plan_length, 1)} | "
            f"{'yes' if r.goal_reached else 'no'} | {fell} | {fmt(r.rms_error, 3)} | {fmt(r.final_distance, 3)} / {fmt(r.plan_end_distance, 3)} |"
        )
    path.write_text("\n".join(lines) + "\n")


def parse_limits(text: str) -> list[float | None]:
    limits: list[float | None] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        if part == "none":
            limits.append(None)
            continue
        try:
            value = float(part)
        except ValueError as err:
            raise SystemExit(f"--limits: {part!r} is neither 'none' nor a number of degrees") from err
        if not 0.0 < value < 90.0:
            raise SystemExit(f"--limits: {value} is not in (0, 90) degrees")
        limits.append(value)
    if not limits:
        raise SystemExit("--limits: give at least one of 'none' or a number of degrees")
    return limits


def main(argv: list[str] | None = None) -> int:
    from tqdm import tqdm

    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n", 1)[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=REPO / "out" / "real_terrain",
        help="output folder (default out/real_terrain)",
    )
    parser.add_argument("--crops", type=int, default=3, help="number of crops (default 3)")
    parser.add_argument(
        "--source-columns",
        type=int,
        default=32,
        help="crop width in DEM columns (74.6 m each; default 32)",
    )
    parser.add_argument("--cells", type=int, default=64, help="map cells per side (default 64)")
    parser.add_argument(
        "--cell-size",
        type=float,
        default=0.125,
        help="map cell size at robot scale, m (default 0.125)",
    )
    parser.add_argument(
        "--target-p95",
        type=float,
        default=25.0,
        help="crop choice: slope p95 to aim at, degrees (default 25)",
    )
    parser.add_argument(
        "--target-max",
        type=float,
        default=35.0,
        help="crop choice: steepest slope to aim at, degrees (default 35)",
    )
    parser.add_argument(
        "--limits",
        default="none,20",
        help="planner slope limits to try, comma-separated degrees or 'none' (default none,20)",
    )
    parser.add_argument(
        "--edge-rim",
        type=int,
        default=1,
        help="also run each crop with this many source cells along its edge as nodata (obstacles), 0 = only the open map (default 1)",
    )
    parser.add_argument(
        "--exaggeration",
        type=float,
        default=1.0,
        help="vertical exaggeration (changes slopes; 1 = the DEM as measured)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=None,
        help="cap on simulated seconds per run (default: whole plan)",
    )
    parser.add_argument(
        "--figures-to",
        type=Path,
        default=None,
        help="also copy each crop's figure here (e.g. docs/img)",
    )
    parser.add_argument("--no-progress", action="store_true")
    parser.add_argument(
        "--results-page",
        default=None,
        metavar="NAME",
        help="also publish the table as docs/results/NAME.md, stamped with commit, machine and date",
    )
    args = parser.parse_args(argv)
    if not (math.isfinite(args.exaggeration) and args.exaggeration > 0.0):
        raise SystemExit(f"--exaggeration must be > 0, got {args.exaggeration}")
    if args.crops < 1 or args.cells < 16 or not args.cell_size > 0.0:
        raise SystemExit("--crops >= 1, --cells >= 16 and --cell-size > 0 are needed")
    limits = parse_limits(args.limits)
    sys.path.insert(0, str(REPO / "harness" / "src"))
    from pfnav_harness import paths, results_page

    if args.results_page is not None and not results_page.PAGE_NAME.match(args.results_page):
        raise SystemExit(f"--results-page: lower-case letters, digits and '-', got {args.results_page!r}")
    # Taken before the runs: the commit that ran and the load it ran under.
    stamp = results_page.collect_stamp() if args.results_page else None

    pf_plan = paths.pf_plan_path()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    variant = "" if args.exaggeration == 1.0 else f"_x{args.exaggeration:g}"
    dem = load_metric_dem(args.exaggeration)
    asc = write_esri_ascii(dem, out / f"jacksboro_fault_dem_m{variant}.asc")
    crops = find_crops(dem, args.source_columns, args.crops, args.target_p95, args.target_max)
    side = args.cells * args.cell_size
    started = time.perf_counter()
    rows: list[RunRow] = []
    crop_info = []
    bar = tqdm(
        total=len(crops) * len(limits) * (2 if args.edge_rim > 0 else 1),
        desc="real terrain runs",
        unit="run",
        disable=args.no_progress,
    )
    for crop in crops:
        crop = Crop(
            crop.name + variant,
            crop.c0,
            crop.r0,
            crop.columns,
            crop.rows,
            crop.source_p50,
            crop.source_p95,
            crop.source_max,
        )
        window = crop_window_metres(dem, crop)
        scale = side / (crop.columns * dem.dx)
        maps = out / "maps"
        # First import with placeholder corners, to place start and goal on the map it writes.
        sidecar, summary = run_import(
            pf_plan,
            asc,
            maps,
            crop.name,
            window,
            scale,
            args.cell_size,
            (side / 4, side / 4),
            (3 * side / 4, 3 * side / 4),
        )
        heights = np.load(maps / f"{crop.name}.heights.npy")
        slopes = cell_slopes_deg(heights, args.cell_size, args.cell_size)
        start, start_slope = flattest_near(slopes, args.cell_size, (False, False))
        goal, goal_slope = flattest_near(slopes, args.cell_size, (True, True))
        sidecar, summary = run_import(pf_plan, asc, maps, crop.name, window, scale, args.cell_size, start, goal)
        map_p50, map_p95, map_max = summary_slopes(summary)
        goal_radius = float(json.loads(sidecar.read_text())["goal"]["radius"])
        maps_by_edge = {"open": (sidecar, map_p50, map_p95, map_max)}
        if args.edge_rim > 0:
            # The same crop with a keep-out rim: its own file, imported whole (no --crop).
            rim_asc = write_esri_ascii(
                dem,
                out / "crops" / f"{crop.name}_rim{args.edge_rim}.asc",
                crop,
                args.edge_rim,
            )
            rim_sidecar, rim_summary = run_import(
                pf_plan,
                rim_asc,
                maps,
                f"{crop.name}_rim{args.edge_rim}",
                None,
                scale,
                args.cell_size,
                start,
                goal,
            )
            maps_by_edge[f"rim {args.edge_rim}"] = (
                rim_sidecar,
                *summary_slopes(rim_summary),
            )
        crop_info.append(
            {
                **asdict(crop),
                "scale": scale,
                "start": start,
                "goal": goal,
                "import_summary": summary,
            }
        )
        plotted: list[tuple[RunRow, dict[str, Any] | None]] = []
        for (edge, (sidecar, map_p50, map_p95, map_max)), limit in itertools.product(maps_by_edge.items(), limits):
            name = sidecar.stem
            label = ("none" if limit is None else f"{limit:g}°") + ("" if edge == "open" else f", edge keep-out ({edge} cell)")
            run_out = out / "runs" / f"{name}_{'nolimit' if limit is None else f'max{limit:g}'}"
            if run_out.exists():
                shutil.rmtree(run_out)
            row = RunRow(
                crop.name,
                label,
                map_p50,
                map_p95,
                map_max,
                start_slope,
                goal_slope,
                planned=False,
            )
            code, stderr = run_demo(sidecar, run_out, limit, args.duration)
            log_file = run_out / "logs" / f"{name}_pf.npz"
            if code != 0 or not log_file.is_file():
                errors = [line for line in stderr.splitlines() if line.startswith("pfnav-demo: error:")]
                row.error = (errors[-1].removeprefix("pfnav-demo: error: ") if errors else f"exit code {code}")[:160].replace("|", "/")
                rows.append(row)
                plotted.append((row, None))
                bar.update()
                continue
            metrics = json.loads((run_out / "metrics.json").read_text())["runs"][0]
            with np.load(log_file) as npz:
                log = {key: npz[key] for key in ("plan_x", "plan_y", "base_pos", "estimator")}
            row.planned = True
            row.path_p50, row.path_p95, row.path_max = path_slopes(slopes, args.cell_size, log["plan_x"], log["plan_y"])
            row.planner_cost = float(metrics["planner_cost"]) if metrics.get("planner_cost") is not None else math.nan
            row.plan_length = float(metrics["planned_length"])
            row.goal_reached = bool(metrics["goal_reached"])
            row.fell = bool(metrics["fell"])
            row.fall_time = metrics.get("fall_time")
            row.fall_reason = str(metrics.get("fall_reason", "")).replace("|", "/")
            row.rms_error = float(metrics["rms_error"])
            row.final_distance = float(metrics["final_distance_to_goal"])
            row.plan_end_distance = math.dist((float(log["plan_x"][-1]), float(log["plan_y"][-1])), goal)
            row.wall_seconds = float(metrics["wall_seconds"])
            row.extra = {
                "stop_reason": metrics.get("stop_reason"),
                "walk_start": metrics.get("walk_start"),
                "duration": metrics.get("duration"),
                "estimator": str(log["estimator"]),
            }
            rows.append(row)
            plotted.append((row, log))
            bar.update()
        figure = out / f"real_terrain_{crop.name}.png"
        plot_crop(figure, crop, heights, args.cell_size, plotted, start, goal, goal_radius)
        if args.figures_to is not None:
            args.figures_to.mkdir(parents=True, exist_ok=True)
            shutil.copy(figure, args.figures_to / figure.name)
    bar.close()
    total = time.perf_counter() - started
    fmu = paths.fmu_path()
    fmu_sha = hashlib.sha256(fmu.read_bytes()).hexdigest()[:12]
    estimators = sorted({str(r.extra.get("estimator")) for r in rows if r.extra}) or ["(no run)"]
    state_source = {"kalman": "on its own state estimate (IMU, encoders; no fixes)", "groundTruth": "on ground truth"}
    header = [
        f"# Real elevation data at robot scale{' (vertical exaggeration ×' + f'{args.exaggeration:g})' if variant else ''}",
        "",
        (
            f"Command: `{' '.join(['scripts/real_terrain.py', *(argv if argv is not None else sys.argv[1:])])}`; "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; total wall time {total:.0f} s."
        ),
        "",
        (
            f"DEM: matplotlib's `{DEM_SAMPLE}` ({dem.heights.shape[1]} × {dem.heights.shape[0]} cells of {dem.dx:.1f} m × {dem.dy:.1f} m at "
            f"latitude {dem.mean_latitude:.3f}°). Each crop: {args.source_columns} DEM columns, scaled uniformly to {args.cells} × {args.cells} "
            f"cells of {args.cell_size} m (heights scaled by the same factor, slopes kept). Slopes are the planner's (central differences per cell); "
            "map figures from `pf-plan import`, path figures over the cells under the planned path. P-F plans by `pf-planner-service` "
            f"(footprint radius as `pfnav-demo`'s default), the controller FMU `{fmu.name}` (sha256 {fmu_sha}) "
            f"{' / '.join(state_source.get(e, e) for e in estimators)}, DART physics. "
            "'reached goal' and 'fell' as `pfnav-demo` judges them (reached: the base came within the goal radius, "
            f"{goal_radius:g} m, of the goal centre). 'edge keep-out': the crop's outer ring of DEM cells written as nodata, "
            "which `pf-plan import` turns into obstacles (the physics terrain ends at the map's edge)."
        ),
    ]
    write_table(out / "table.md", rows, header)
    (out / "results.json").write_text(
        json.dumps(
            {
                "crops": crop_info,
                "runs": [asdict(r) for r in rows],
                "exaggeration": args.exaggeration,
            },
            indent=2,
            default=str,
        )
    )
    table = (out / "table.md").read_text()
    print(table)
    if args.results_page:
        title = "Real terrain: P-F plans walked on crops of a real elevation model"
        command = results_page.regenerate_command(
            ".venv/bin/python scripts/real_terrain.py", argv if argv is not None else sys.argv[1:]
        )
        page = results_page.write_results_page(args.results_page, title, results_page.without_pictures(table), command, stamp)
        print(f"results page: {page}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
