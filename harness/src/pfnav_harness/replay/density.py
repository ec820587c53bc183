"""The P-F plan's occupation density for a recording, from the planner itself.

The planner service answers with the plan and the feedback law, not with the LP's density ρ. A
replay asks `pf-plan plan --density-out` for it, on the run's map with the run's traversability
model, planning grid and options, after the run. So that a drawing never shows the density of
another plan than the one walked, the field `pf-plan` computes alongside must match the run's
field (same grid, same cost-to-go); otherwise the density is left out and the reason noted.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import HarnessError, PlannerError
from ..feedback_field import FeedbackField
from ..scenario import Scenario, write_map
from ..tools import run_tool

# Cost-to-go of pf-plan's field and the run's agree to this relative tolerance (the service gets
# the map as float32 heights over LCM, pf-plan reads the float64 sidecar).
COST_TO_GO_RTOL = 1e-4


@dataclass(frozen=True)
class OccupationDensity:
    """ρ(x) of the P-F LP at the centre of every planning cell ([iy, ix]): the expected time the
    start's unit mass spends per square metre there (0 on the goal cells)."""

    origin: tuple[float, float]
    resolution: float
    density: NDArray[np.float64]

    @classmethod
    def from_npz(cls, path: Path) -> OccupationDensity:
        """Reads `pf-plan plan --density-out FILE.npz` (density, origin, resolution)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                origin = np.asarray(data["origin"], dtype=np.float64).ravel()
                density = np.asarray(data["density"], dtype=np.float64)
                resolution = float(np.asarray(data["resolution"]).ravel()[0])
        except (OSError, ValueError, KeyError) as err:
            raise PlannerError(f"cannot read the occupation density {path}: {err}") from err
        if origin.shape != (2,) or density.ndim != 2 or not (math.isfinite(resolution) and resolution > 0.0):
            raise PlannerError(f"{path}: not an occupation density (origin (2,), density (height, width), resolution > 0)")
        return cls((float(origin[0]), float(origin[1])), resolution, density)


@dataclass(frozen=True)
class DensityOptions:
    """The request options of the run's plans that change the P-F solution (None: the service's default)."""

    basis: str | None = None
    generators: str | None = None


@dataclass(frozen=True)
class DensityResult:
    """The density, or None and why not."""

    density: OccupationDensity | None
    reason: str = ""


def planning_grid_size(field: FeedbackField) -> int:
    """Cells along the longer side of the grid the field was planned on (`pf-plan --grid`)."""
    height, width = field.dir_x.shape
    return max(width, height)


def fields_agree(ours: FeedbackField, run: FeedbackField) -> bool:
    """Same grid and the same cost-to-go (reachable cells alike): the same plan."""
    if not ours.same_grid(run):
        return False
    reachable = run.cost_to_go >= 0.0
    if not np.array_equal(reachable, ours.cost_to_go >= 0.0):
        return False
    return bool(np.allclose(ours.cost_to_go[reachable], run.cost_to_go[reachable], rtol=COST_TO_GO_RTOL, atol=1e-9))


def plan_density(pf_plan: Path, scenario: Scenario, field: FeedbackField, options: DensityOptions = DensityOptions(), timeout: float = 120.0) -> DensityResult:
    """The occupation density of the P-F plan whose feedback law is `field`, planned again by
    `pf-plan` on `scenario` (its map, start, goal and traversability model)."""
    speed = float(np.max(field.speed)) if field.speed.size else 0.0
    with tempfile.TemporaryDirectory(prefix="pfnav-density-") as folder:
        work = Path(folder)
        map_json = write_map(scenario.terrain, work, "run_map", scenario.traversability, start=scenario.start, start_yaw=scenario.start_yaw, goal=scenario.goal)
        args = ["plan", "--map", str(map_json), "--method", "pf", "--grid", str(planning_grid_size(field)), "--out", str(work)]
        args += ["--field-out", str(work / "field.npz"), "--density-out", str(work / "density.npz")]
        if speed > 0.0:
            args += ["--speed", repr(speed)]
        if options.basis is not None:
            args += ["--basis", options.basis]
        if options.generators is not None:
            args += ["--generators", options.generators]
        try:
            run_tool(pf_plan, args, what="pf-plan could not plan the run's map again for its density", failure=PlannerError, timeout=timeout)
            ours = FeedbackField.from_npz(work / "field.npz")
            density = OccupationDensity.from_npz(work / "density.npz")
        except HarnessError as err:
            return DensityResult(None, f"pf-plan failed on the run's map: {err}")
    if not fields_agree(ours, field):
        return DensityResult(
            None,
            "pf-plan's plan on the run's map differs from the run's (its feedback field does not match): "
            "the run's planner options or cost model are not all known to the replay",
        )
    return DensityResult(density)
