"""A run's log as the co-simulation saves it (`cosim.save_log`), and the things a replay derives from it.

The log holds every physics step (1 kHz): far more than a picture needs. `frame_steps` picks the
steps a replay shows at a chosen rate.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import HarnessError, ScenarioError
from ..scenario import Scenario, load_scenario

RunLog = dict[str, NDArray[np.generic]]


class RunLogError(HarnessError):
    """The file is not a run log a replay can read (bad input, like an unknown scenario)."""

    exit_code = 2


# Keys every log has (cosim.CoSimulation._result); a replay refuses a file without them.
REQUIRED_KEYS = ("t", "base_pos", "base_quat", "q", "tau", "ref", "forces", "contact_actual", "fsm", "mpc_solve_time", "plan_x", "plan_y")


def load_run_log(path: Path) -> RunLog:
    """Every array of the npz log at `path`, checked for the keys a replay reads."""
    try:
        with np.load(path, allow_pickle=False) as data:
            log = {key: data[key] for key in data.files}
    except (OSError, ValueError) as err:
        raise RunLogError(f"cannot read the run log {path}: {err}") from err
    missing = [key for key in REQUIRED_KEYS if key not in log]
    if missing:
        raise RunLogError(f"{path} is not a pfnav-demo run log: no {', '.join(missing)}")
    if len(log["t"]) < 2:
        raise RunLogError(f"the run log {path} has fewer than two steps")
    return log


def frame_steps(t: NDArray[np.float64], rate: float) -> NDArray[np.int64]:
    """Indices of every n-th logged step from the first, n the smallest that gives at most `rate` steps per second; the last step is always one."""
    if not (math.isfinite(rate) and rate > 0.0):
        raise RunLogError(f"a replay rate must be positive, got {rate}")
    dt = float(t[1] - t[0])
    # The tolerance keeps an exact ratio (50 Hz from 1 kHz) at its integer despite rounding in t.
    every = max(1, math.ceil(1.0 / (rate * dt) - 1e-6))
    steps = np.arange(0, len(t), every, dtype=np.int64)
    if steps[-1] != len(t) - 1:
        steps = np.append(steps, len(t) - 1)
    return steps


def window_max(values: NDArray[np.float64], steps: NDArray[np.int64]) -> NDArray[np.float64]:
    """The largest value from each chosen step up to the next (a short spike must not vanish in a subsampled plot)."""
    return np.maximum.reduceat(values, steps) if len(steps) else np.zeros(0)


def run_name_of(log_path: Path) -> tuple[str, str]:
    """(scenario, run label) of a log the demo wrote as OUT/logs/SCENARIO_LABEL.npz (labels have no '_')."""
    scenario, sep, label = log_path.stem.rpartition("_")
    if not sep or not scenario:
        raise ScenarioError(f"{log_path.name}: not named SCENARIO_LABEL.npz like the demo's logs; give the scenario's JSON sidecar")
    return scenario, label


def scenario_of_log(log_path: Path) -> Scenario:
    """The scenario a demo log was walked on: OUT/scenarios/SCENARIO.json beside OUT/logs/."""
    name, _ = run_name_of(log_path)
    sidecar = log_path.absolute().parent.parent / "scenarios" / f"{name}.json"
    if not sidecar.is_file():
        raise ScenarioError(f"no {sidecar} for the log {log_path}: give the scenario's (or map's) JSON sidecar")
    return load_scenario(sidecar)


def horizontal_tracking_error(log: RunLog) -> NDArray[np.float64]:
    """Horizontal distance of the base from the reference at every step (the report's tracking error)."""
    pos, ref = log["base_pos"], log["ref"]
    return np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])


def estimated_quaternions(rpy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternions (w, x, y, z) of the estimator's roll, pitch, yaw (ZYX), one row per step."""
    half = 0.5 * np.asarray(rpy, dtype=np.float64)
    cr, sr = np.cos(half[:, 0]), np.sin(half[:, 0])
    cp, sp = np.cos(half[:, 1]), np.sin(half[:, 1])
    cy, sy = np.cos(half[:, 2]), np.sin(half[:, 2])
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )


def fsm_state_names(log: RunLog) -> dict[int, str]:
    """Code → name of the controller FSM's states, as the run's FMU declared them (logs from before
    the names were logged: only the damping state, else nothing)."""
    if "fsm_state_names" in log and "fsm_state_codes" in log:
        return {int(code): str(name) for code, name in zip(log["fsm_state_codes"], log["fsm_state_names"], strict=True)}
    if "fsm_damping" in log:
        return {int(log["fsm_damping"]): "Damping"}
    return {}


def fsm_transitions(fsm: NDArray[np.generic]) -> NDArray[np.int64]:
    """The steps at which the FSM state differs from the step before (the first step included)."""
    codes = np.asarray(fsm, dtype=np.int64)
    if len(codes) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.concatenate([[0], np.nonzero(np.diff(codes))[0] + 1]).astype(np.int64)


def with_logged_traversability(scenario: Scenario, log: RunLog) -> Scenario:
    """`scenario` with the cost model its run planned with, when the log records it (the demo's
    overrides are not in the scenario's sidecar)."""
    if "traversability" not in log:
        return scenario
    try:
        model = json.loads(str(log["traversability"]))
    except json.JSONDecodeError as err:
        raise RunLogError(f"the run log's traversability model is not JSON: {err}") from err
    if not isinstance(model, dict):
        raise RunLogError("the run log's traversability model is not a JSON object")
    return dataclasses.replace(scenario, traversability=model)

