"""Sweep specs (TOML): the scenario, the factors and how runs sample them.

A spec names the scenario, the simulated duration of each run, a seed, the number of runs, the
physics engine (`engine`, default "dart"), the robot (`robot`: a robot config, relative to the repository root; default
`$PFNAV_ROBOT`, else ours), how pushes scale with the robot (`push_scaling`: "force", the magnitudes as given, or
"mass", magnitudes meant for our robot's mass and scaled by the robot's mass over it, so that every robot gets the
same velocity change) and the sampling ("random": every run draws each factor independently; "grid": every
combination once).
Each factor is a fixed value, a list (`{ values = [...] }`: random picks one, the grid takes each)
or a range (`{ range = [low, high] }`: random draws uniformly, the grid takes `steps` evenly spaced
points). Factors left out keep their default (`FACTORS`). Example: sweeps/tiny.toml.

Determinism: a run's factor values depend on (spec seed, run id, factor name) only, so a run is the
same whichever worker takes it, in whatever order, and adding a factor does not change the others.
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..engine import DEFAULT_ENGINE, DEFAULT_FRICTION, ENGINE_NAMES
from ..errors import HarnessError
from ..fmu_runner import DEFAULT_ESTIMATOR, ESTIMATOR_MODES
from ..pushes import HEADING_DIRECTIONS

SAMPLINGS = ("random", "grid")
PUSH_SCALINGS = ("force", "mass")
SPEC_KEYS = (
    "scenario",
    "duration",
    "seed",
    "runs",
    "sampling",
    "method",
    "stand_time",
    "estimator",
    "engine",
    "robot",
    "push_scaling",
    "fork",
    "factors",
)


class SpecError(HarnessError, ValueError):
    """A sweep spec that cannot be run (unknown factor, empty range, negative runs, ...)."""

    exit_code = 2


@dataclass(frozen=True)
class FactorInfo:
    """What a factor means, its unit, its default and the values it accepts."""

    description: str
    unit: str
    default: float | str
    low: float = -math.inf
    high: float = math.inf
    # Lower bound excluded (e.g. a duration must be > 0).
    low_open: bool = False
    integer: bool = False
    # Names accepted besides numbers (push directions relative to the robot's heading).
    names: tuple[str, ...] = ()


# The factors a sweep can vary, in the order runs draw them (the order never affects the draws).
FACTORS: dict[str, FactorInfo] = {
    "push_magnitude": FactorInfo("horizontal force on the trunk (0: no push)", "N", 0.0, low=0.0),
    "push_direction": FactorInfo(
        "push direction: degrees counter-clockwise from +x (world), or a side of the robot", "deg", "left", names=tuple(HEADING_DIRECTIONS)
    ),
    "push_time": FactorInfo("push start on the walk clock (after stand-up)", "s", 2.0, low=0.0),
    "push_duration": FactorInfo("push duration", "s", 0.2, low=0.0, low_open=True),
    "payload_mass": FactorInfo("mass added to the trunk, fraction of the trunk's mass (-0.2 = 20 % lighter)", "", 0.0, low=-1.0, low_open=True),
    "payload_offset_x": FactorInfo("payload offset from the trunk's centre of mass, forward", "m", 0.0),
    "payload_offset_y": FactorInfo("payload offset from the trunk's centre of mass, left", "m", 0.0),
    "payload_offset_z": FactorInfo("payload offset from the trunk's centre of mass, up", "m", 0.0),
    "friction": FactorInfo("ground and foot friction coefficient", "", DEFAULT_FRICTION, low=0.0, low_open=True),
    # Default: the scenario's own seed (resolved when the scenario is exported).
    "terrain_seed": FactorInfo("scenario generator seed (a new terrain, exported and planned once per seed)", "", -1, low=0, integer=True),
    "comm_step": FactorInfo("FMU communication step (a multiple of the 1 ms physics step)", "s", 0.001, low=0.0, low_open=True),
    # Only with `estimator = "kalman"`: on ground truth the controller never sees the sensors.
    "sensor_noise_seed": FactorInfo("seed of the body sensors' noise (IMU, encoders, fixes) the controller's estimator reads", "", 0, low=0, integer=True),
}
# Factors that only act in some configurations: refused where they would be silently ignored.
NEEDS_ESTIMATOR = ("sensor_noise_seed",)


@dataclass(frozen=True)
class Factor:
    """One factor of a spec: exactly one of `value`, `values` or `range` (with `steps` for the grid)."""

    name: str
    values: tuple[float | str, ...] = ()
    range: tuple[float, float] | None = None
    steps: int | None = None

    def grid_points(self) -> tuple[float | str, ...]:
        if self.range is None:
            return self.values
        if self.steps is None:
            raise SpecError(f"factor '{self.name}': grid sampling needs `steps` with a range (or a list of values)")
        low, high = self.range
        points = np.linspace(low, high, self.steps) if self.steps > 1 else np.array([low])
        info = FACTORS[self.name]
        return tuple(round(float(p)) if info.integer else float(p) for p in points)

    def draw(self, rng: np.random.Generator) -> float | str:
        info = FACTORS[self.name]
        if self.range is not None:
            low, high = self.range
            if info.integer:
                return int(rng.integers(int(low), int(high), endpoint=True))
            return float(rng.uniform(low, high))
        if len(self.values) == 1:
            return self.values[0]
        return self.values[int(rng.integers(len(self.values)))]

    def as_json(self) -> dict[str, Any]:
        if self.range is not None:
            return {"range": list(self.range), **({"steps": self.steps} if self.steps is not None else {})}
        return {"values": list(self.values)}


@dataclass(frozen=True)
class SweepSpec:
    scenario: str
    duration: float
    seed: int
    runs: int
    sampling: str = "random"
    method: str = "pf"
    stand_time: float = 1.5
    factors: dict[str, Factor] = field(default_factory=dict)
    source: Path | None = None
    # What the controller runs on: "groundTruth" (the simulator's state) or "kalman" (its estimator on the body sensors).
    estimator: str = DEFAULT_ESTIMATOR
    # Start runs from their group's saved post-stand-up state (docs/sweeps.md, "Forks"); off: every run stands up itself.
    fork: bool = True
    # The physics engine every run walks in (engine.ENGINE_NAMES).
    engine: str = DEFAULT_ENGINE
    # The robot config (as written, relative to the repository root); None: `$PFNAV_ROBOT`, else ours.
    robot: str | None = None
    # "force": push magnitudes as given; "mass": for our robot's mass, scaled by the robot's mass over it.
    push_scaling: str = "force"

    def as_json(self) -> dict[str, Any]:
        """The spec's content (what the hash covers): no file name, no comments, factors in canonical order."""
        return {
            "scenario": self.scenario,
            "duration": self.duration,
            "seed": self.seed,
            "runs": self.runs,
            "sampling": self.sampling,
            "method": self.method,
            "stand_time": self.stand_time,
            "estimator": self.estimator,
            "factors": {name: self.factors[name].as_json() for name in FACTORS if name in self.factors},
            # Forked runs carry their payload and friction from the fork on: other rows than unforked
            # ones. Only a forking spec says so, so an unforked spec keeps the hash it had before forks
            # existed and resumes the stores written then.
            **({"fork": True} if self.fork else {}),
            # Likewise the engine: a DART spec keeps the hash it had before the engine was a choice.
            **({"engine": self.engine} if self.engine != DEFAULT_ENGINE else {}),
            # And the robot and the push scaling: a spec without them keeps its hash.
            **({"robot": self.robot} if self.robot is not None else {}),
            **({"push_scaling": self.push_scaling} if self.push_scaling != "force" else {}),
        }

    @property
    def hash(self) -> str:
        text = json.dumps(self.as_json(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def run_factors(self, run_id: int) -> dict[str, float | str]:
        """The factor values of run `run_id` (0-based), defaults included, in `FACTORS` order."""
        if not 0 <= run_id < self.runs:
            raise SpecError(f"run id {run_id} is outside 0..{self.runs - 1}")
        if self.sampling == "grid":
            return self._grid_row(run_id)
        row: dict[str, float | str] = {}
        for index, (name, info) in enumerate(FACTORS.items()):
            factor = self.factors.get(name)
            if factor is None:
                row[name] = info.default
                continue
            # One generator per (seed, run, factor): draws do not depend on which other factors exist.
            rng = np.random.default_rng([self.seed, run_id, index])
            row[name] = factor.draw(rng)
        return row

    def _grid_row(self, run_id: int) -> dict[str, float | str]:
        varied = [name for name in FACTORS if name in self.factors]
        axes = [self.factors[name].grid_points() for name in varied]
        # Row-major over the factors in `FACTORS` order: the last factor changes fastest
        # (the order of itertools.product), indexed directly instead of enumerated.
        indices = np.unravel_index(run_id, [len(axis) for axis in axes]) if axes else ()
        chosen = {name: axis[int(i)] for name, axis, i in zip(varied, axes, indices, strict=True)}
        return {name: chosen.get(name, info.default) for name, info in FACTORS.items()}

    def grid_size(self) -> int:
        return math.prod(len(self.factors[name].grid_points()) for name in self.factors)

    def terrain_seeds(self) -> list[int | None]:
        """The distinct terrain seeds the runs use (None: the scenario's own), in first-use order."""
        seeds: dict[int | None, None] = {}
        for run_id in range(self.runs):
            seed = int(self.run_factors(run_id)["terrain_seed"])
            seeds[None if seed < 0 else seed] = None
        return list(seeds)


def _number(name: str, value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(float(value)):
        raise SpecError(f"factor '{name}': {what} must be a finite number, got {value!r}")
    return float(value)


def _check_bounds(name: str, value: float) -> None:
    info = FACTORS[name]
    too_low = value <= info.low if info.low_open else value < info.low
    if too_low or value > info.high:
        bound = f"> {info.low:g}" if info.low_open else f">= {info.low:g}"
        raise SpecError(f"factor '{name}' ({info.description}): values must be {bound}, got {value:g}")
    if info.integer and value != int(value):
        raise SpecError(f"factor '{name}': values must be integers, got {value:g}")


def _factor_value(name: str, value: Any) -> float | str:
    info = FACTORS[name]
    if isinstance(value, str):
        if value.lower() in info.names:
            return value.lower()
        accepted = f" or one of {', '.join(info.names)}" if info.names else ""
        raise SpecError(f"factor '{name}': unknown value {value!r} (a number{accepted})")
    number = _number(name, value, "each value")
    _check_bounds(name, number)
    return int(number) if info.integer else number


def parse_factor(name: str, raw: Any) -> Factor:
    if name not in FACTORS:
        known = ", ".join(FACTORS)
        raise SpecError(f"unknown factor '{name}' (known: {known})")
    if not isinstance(raw, dict):
        return Factor(name, values=(_factor_value(name, raw),))
    keys = set(raw)
    unknown = keys - {"values", "range", "steps"}
    if unknown:
        raise SpecError(f"factor '{name}': unknown key(s) {', '.join(sorted(unknown))} (use `values = [...]` or `range = [low, high]`, `steps` for the grid)")
    if ("values" in keys) == ("range" in keys):
        raise SpecError(f"factor '{name}': give exactly one of `values = [...]` or `range = [low, high]`")
    if "values" in keys:
        if "steps" in keys:
            raise SpecError(f"factor '{name}': `steps` only goes with a range")
        values = raw["values"]
        if not isinstance(values, list) or not values:
            raise SpecError(f"factor '{name}': `values` must be a non-empty list, got {values!r}")
        return Factor(name, values=tuple(_factor_value(name, v) for v in values))
    bounds = raw["range"]
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise SpecError(f"factor '{name}': `range` must be [low, high], got {bounds!r}")
    low, high = (_number(name, v, "range bounds") for v in bounds)
    if not low < high:
        raise SpecError(f"factor '{name}': empty range [{low:g}, {high:g}] (low must be < high; a fixed value is `{name} = {low:g}`)")
    _check_bounds(name, low)
    _check_bounds(name, high)
    steps = raw.get("steps")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
        raise SpecError(f"factor '{name}': `steps` must be an integer >= 1, got {steps!r}")
    return Factor(name, range=(low, high), steps=steps)


def parse_spec(data: dict[str, Any], source: Path | None = None) -> SweepSpec:
    where = f"{source}: " if source else ""
    unknown = set(data) - set(SPEC_KEYS)
    if unknown:
        raise SpecError(f"{where}unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(SPEC_KEYS)})")
    for key in ("scenario", "duration", "seed"):
        if key not in data:
            raise SpecError(f"{where}missing `{key}`")
    scenario = data["scenario"]
    if not isinstance(scenario, str) or not scenario:
        raise SpecError(f"{where}`scenario` must be a scenario name, got {scenario!r}")
    duration = data["duration"]
    if isinstance(duration, bool) or not isinstance(duration, int | float) or not (math.isfinite(duration) and duration > 0):
        raise SpecError(f"{where}`duration` (simulated seconds per run) must be > 0, got {duration!r}")
    seed = data["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SpecError(f"{where}`seed` must be an integer >= 0, got {seed!r}")
    sampling = data.get("sampling", "random")
    if sampling not in SAMPLINGS:
        raise SpecError(f"{where}`sampling` must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    method = data.get("method", "pf")
    if not isinstance(method, str) or not method:
        raise SpecError(f"{where}`method` must be a planner method name, got {method!r}")
    stand_time = data.get("stand_time", 1.5)
    if isinstance(stand_time, bool) or not isinstance(stand_time, int | float) or not (math.isfinite(stand_time) and stand_time >= 0):
        raise SpecError(f"{where}`stand_time` must be >= 0 s, got {stand_time!r}")
    estimator = data.get("estimator", DEFAULT_ESTIMATOR)
    if estimator not in ESTIMATOR_MODES:
        raise SpecError(f"{where}`estimator` must be one of {', '.join(ESTIMATOR_MODES)}, got {estimator!r}")
    engine = data.get("engine", DEFAULT_ENGINE)
    if engine not in ENGINE_NAMES:
        raise SpecError(f"{where}`engine` (physics engine) must be one of {', '.join(ENGINE_NAMES)}, got {engine!r}")
    robot = data.get("robot")
    if robot is not None and (not isinstance(robot, str) or not robot.endswith(".toml")):
        raise SpecError(f"{where}`robot` must be the path of a robot config (.toml, relative to the repository root), got {robot!r}")
    push_scaling = data.get("push_scaling", "force")
    if push_scaling not in PUSH_SCALINGS:
        raise SpecError(f"{where}`push_scaling` must be one of {', '.join(PUSH_SCALINGS)}, got {push_scaling!r}")
    fork = data.get("fork", True)
    if not isinstance(fork, bool):
        raise SpecError(f"{where}`fork` must be true or false, got {fork!r}")
    raw_factors = data.get("factors", {})
    if not isinstance(raw_factors, dict):
        raise SpecError(f"{where}`factors` must be a table")
    try:
        factors = {name: parse_factor(name, raw) for name, raw in raw_factors.items()}
    except SpecError as err:
        raise SpecError(f"{where}{err}") from None
    for name in NEEDS_ESTIMATOR:
        if name in factors and estimator != "kalman":
            raise SpecError(
                f"{where}factor '{name}' only acts with `estimator = \"kalman\"` (on ground truth the controller never reads the sensors); "
                "set it, or leave the factor out"
            )

    def spec_with(runs: int) -> SweepSpec:
        return SweepSpec(
            scenario, float(duration), seed, runs, sampling, method, float(stand_time), factors, source, estimator, fork, engine, robot, push_scaling
        )

    spec_without_runs = spec_with(1)
    runs = data.get("runs")
    if sampling == "grid":
        size = spec_without_runs.grid_size()
        if runs is not None and runs != size:
            raise SpecError(f"{where}grid sampling has {size} combinations; `runs` must be {size} or left out, got {runs!r}")
        runs = size
    if runs is None:
        raise SpecError(f"{where}missing `runs` (random sampling)")
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise SpecError(f"{where}`runs` must be an integer >= 1, got {runs!r}")
    return spec_with(runs)


def load_spec(path: Path, estimator: str | None = None, engine: str | None = None, robot: str | None = None, runs: int | None = None) -> SweepSpec:
    """The spec in the TOML file `path`; `estimator`, `engine`, `robot` and `runs` (if given) replace its
    own before the checks, so that one spec measures both estimators, both engines or several robots
    (the store hash differs). Random draws depend on (seed, run id, factor) only: the first N runs of
    a spec are the runs of the same spec with `runs = N`."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as err:
        raise SpecError(f"cannot read the sweep spec {path}: {err}") from err
    except tomllib.TOMLDecodeError as err:
        raise SpecError(f"{path}: not valid TOML: {err}") from err
    if estimator is not None:
        data["estimator"] = estimator
    if engine is not None:
        data["engine"] = engine
    if robot is not None:
        data["robot"] = robot
    if runs is not None:
        data["runs"] = runs
    return parse_spec(data, Path(path))
