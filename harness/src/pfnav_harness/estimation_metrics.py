"""How well the controller's state estimate follows the simulated truth, and the report's section on it.

Run logs of kalman-mode runs carry the FMU's estimate (`est_pos`, `est_vel`, `est_rpy`,
`est_status`, one row per physics step, held between communication points) next to the DART truth
(`base_pos`, `base_vel`, `base_quat`). Everything is measured while walking (t ≥ walk_start):

* velocity RMS: ‖est.vel − v‖ over the walk, 3-D and horizontal (m/s), and per world axis;
* position drift: the horizontal position error accrued during the walk (error at the end minus
  error at walk start, as vectors) over the horizontal length of the true path, in %; this is
  leg-odometry drift and does not depend on where the estimate stood when walking began;
* absolute horizontal position error (final, max, RMS) and height error RMS, m;
* yaw error: wrap(est yaw − true yaw), final and largest magnitude, rad;
* tracking RMS: true horizontal position against the plan's reference (what the robot did,
  judged by the truth, not by its own belief);
* status: the OR of every `est.status` bit seen while walking;
* the estimator's own horizontal uncertainty at the end, σ = √(var x + var y) from `est_pos_var`
  (logs that carry it), and whether the final horizontal error lies within 2σ.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from .metrics import roll_pitch_yaw, wrap_angle

FloatArray = NDArray[np.float64]
# Log keys a run with the estimator in the loop carries.
ESTIMATE_KEYS = ("est_pos", "est_vel", "est_rpy", "est_status")


class EstimationRun(Protocol):
    """What the section needs of a report record (`report.RunRecord`)."""

    log: dict[str, Any]
    estimation: EstimationMetrics | None

    @property
    def metrics(self) -> Any: ...


@dataclass
class EstimationMetrics:
    estimator: str
    # Last time measured: the end of the run, or the fall (what follows a fall says nothing).
    measured_until: float
    fix_rate: float
    fix_noise: float
    sensor_seed: int
    velocity_rms: float
    velocity_rms_horizontal: float
    velocity_rms_axes: tuple[float, float, float]
    drift_percent: float
    path_length: float
    position_error_final: float
    position_error_max: float
    position_rms: float
    height_error_rms: float
    yaw_error_final: float
    yaw_error_max: float
    tracking_rms: float
    status_bits: int
    fixes: int
    # √(var x + var y) of the estimate at the end, m (NaN: the log has no `est_pos_var`).
    position_sigma_final: float = math.nan

    @property
    def final_error_within_2sigma(self) -> bool | None:
        """Whether the final horizontal error lies inside the estimator's own 2σ (None: no σ logged)."""
        if not math.isfinite(self.position_sigma_final):
            return None
        return self.position_error_final <= 2.0 * self.position_sigma_final

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def has_estimate(log: dict[str, Any]) -> bool:
    return all(key in log for key in ESTIMATE_KEYS)


def _walking(log: dict[str, Any], until: float | None = None) -> NDArray[np.bool_]:
    t = np.asarray(log["t"])
    walking = t >= float(log.get("walk_start", 0.0))
    if until is not None:
        walking &= t <= until
    return walking if np.any(walking) else np.ones_like(t, dtype=bool)


def estimation_errors(log: dict[str, Any]) -> dict[str, FloatArray]:
    """Per-step errors (estimate − truth): `pos` (N, 3), `vel` (N, 3), `yaw` (N,)."""
    _, _, yaw = roll_pitch_yaw(np.asarray(log["base_quat"]))
    return {
        "pos": np.asarray(log["est_pos"]) - np.asarray(log["base_pos"]),
        "vel": np.asarray(log["est_vel"]) - np.asarray(log["base_vel"]),
        "yaw": wrap_angle(np.asarray(log["est_rpy"])[:, 2] - yaw),
    }


def _rms(values: FloatArray) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def compute_estimation_metrics(log: dict[str, Any], until: float | None = None) -> EstimationMetrics:
    """The metrics of one run log with an estimate (see `has_estimate`), over the walk up to `until`
    (the fall time of a run that fell; None: to the end)."""
    missing = [key for key in (*ESTIMATE_KEYS, "estimator") if key not in log]
    if missing:
        raise KeyError(f"the run log has no estimate ({', '.join(missing)} missing): was it run in kalman mode?")
    walking = _walking(log, until)
    errors = estimation_errors(log)
    pos_err = errors["pos"][walking]
    vel_err = errors["vel"][walking]
    yaw_err = errors["yaw"][walking]
    truth = np.asarray(log["base_pos"])[walking]
    path_length = float(np.sum(np.hypot(np.diff(truth[:, 0]), np.diff(truth[:, 1]))))
    accrued = pos_err[-1, :2] - pos_err[0, :2]
    drift = 100.0 * float(np.hypot(*accrued)) / path_length if path_length > 0.0 else float("nan")
    horizontal = np.hypot(pos_err[:, 0], pos_err[:, 1])
    ref = np.asarray(log["ref"])[walking]
    tracking = np.hypot(truth[:, 0] - ref[:, 0], truth[:, 1] - ref[:, 1])
    status = np.asarray(log["est_status"])[walking].astype(np.int64)
    fix_valid = np.asarray(log.get("fix_valid", np.zeros(0, dtype=bool)), dtype=bool)
    return EstimationMetrics(
        estimator=str(log["estimator"]),
        measured_until=float(np.asarray(log["t"])[walking][-1]),
        fix_rate=float(log.get("fix_rate", 0.0)),
        fix_noise=float(log.get("fix_noise", 0.0)),
        sensor_seed=int(log.get("sensor_seed", 0)),
        velocity_rms=_rms(np.linalg.norm(vel_err, axis=1)),
        velocity_rms_horizontal=_rms(np.hypot(vel_err[:, 0], vel_err[:, 1])),
        velocity_rms_axes=(_rms(vel_err[:, 0]), _rms(vel_err[:, 1]), _rms(vel_err[:, 2])),
        drift_percent=drift,
        path_length=path_length,
        position_error_final=float(horizontal[-1]),
        position_error_max=float(horizontal.max()),
        position_rms=_rms(horizontal),
        height_error_rms=_rms(pos_err[:, 2]),
        yaw_error_final=float(yaw_err[-1]),
        yaw_error_max=float(np.abs(yaw_err).max()),
        tracking_rms=_rms(tracking),
        status_bits=int(np.bitwise_or.reduce(status)) if status.size else 0,
        fixes=int(fix_valid.sum()),
        position_sigma_final=_final_sigma(log, walking),
    )


def _final_sigma(log: dict[str, Any], walking: NDArray[np.bool_]) -> float:
    if "est_pos_var" not in log:
        return math.nan
    variance = np.asarray(log["est_pos_var"])[walking]
    return float(math.sqrt(max(0.0, float(variance[-1, 0] + variance[-1, 1])))) if len(variance) else math.nan


def _sigma_cell(e: EstimationMetrics) -> str:
    within = e.final_error_within_2sigma
    if within is None:
        return "–"
    return f"{_fmt(e.position_sigma_final)} ({'within' if within else 'outside'} 2σ)"


def plot_estimation(log: dict[str, Any], title: str, path: Path) -> None:
    """Estimate against truth: xy path, velocity error and position error over time."""
    t = np.asarray(log["t"])
    walk_start = float(log.get("walk_start", 0.0))
    errors = estimation_errors(log)
    truth = np.asarray(log["base_pos"])
    est = np.asarray(log["est_pos"])
    fig = plt.figure(figsize=(12, 6.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.0, 1.3))
    ax_xy = fig.add_subplot(grid[:, 0])
    ax_xy.plot(truth[:, 0], truth[:, 1], "-", color="k", lw=2.0, label="truth (DART)")
    ax_xy.plot(est[:, 0], est[:, 1], "-", color="tab:red", lw=1.2, label="estimate")
    if "fix_valid" in log and "fix_pos" in log:
        fixes = np.asarray(log["fix_valid"], dtype=bool)
        if fixes.any():
            fix_pos = np.asarray(log["fix_pos"])[fixes]
            ax_xy.plot(fix_pos[:, 0], fix_pos[:, 1], ".", color="tab:blue", ms=3, label="position fixes")
    ax_xy.plot(*truth[0, :2], "o", color="white", mec="k", ms=8, label="start")
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.set_xlabel("x [m]")
    ax_xy.set_ylabel("y [m]")
    ax_xy.legend(fontsize=8, loc="best")
    ax_xy.set_title("trunk path")
    ax_vel = fig.add_subplot(grid[0, 1])
    for i, axis in enumerate("xyz"):
        ax_vel.plot(t, errors["vel"][:, i], lw=0.7, label=f"v{axis}")
    ax_vel.set_ylabel("velocity error [m/s]")
    ax_vel.legend(fontsize=8, ncol=3, loc="upper right")
    ax_pos = fig.add_subplot(grid[1, 1], sharex=ax_vel)
    ax_pos.plot(t, np.hypot(errors["pos"][:, 0], errors["pos"][:, 1]), color="tab:red", label="horizontal")
    ax_pos.plot(t, errors["pos"][:, 2], color="tab:green", lw=0.8, label="z")
    ax_yaw = ax_pos.twinx()
    ax_yaw.plot(t, np.degrees(errors["yaw"]), color="tab:purple", lw=0.8, ls="--", label="yaw [°]")
    ax_yaw.set_ylabel("yaw error [°]", color="tab:purple")
    ax_pos.set_ylabel("position error [m]")
    ax_pos.set_xlabel("t [s]")
    ax_pos.legend(fontsize=8, loc="upper left")
    for ax in (ax_vel, ax_pos):
        ax.axvline(walk_start, color="grey", ls=":", lw=1)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: estimate − truth (dotted line: walking starts)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _fmt(value: float, digits: int = 3) -> str:
    return f"{value:.{digits}f}" if math.isfinite(value) else "–"


def estimation_section(runs: dict[str, Sequence[EstimationRun]], out_dir: Path) -> list[str]:
    """The report's state-estimation table and plots (empty when no run had the estimator in the loop)."""
    estimated = [(name, rec) for name, records in runs.items() for rec in records if rec.estimation is not None]
    if not estimated:
        return []
    lines = [
        "## State estimation",
        "",
        "The controller ran on its own estimate (kalman mode) from a simulated ADIS16470 IMU, 14-bit joint encoders and, "
        "where stated, noisy position fixes; the truth is the DART trunk. Measured while walking. Drift: horizontal "
        "position error accrued during the walk over the length walked. Tracking: the true position against the plan.",
        "",
        "A run that fell is measured up to its fall (column 'until'). Own σ: the estimator's final horizontal "
        "standard deviation √(σx² + σy²); 'within 2σ' when the final error is at most twice that.",
        "",
        "| scenario | run | until [s] | fixes [Hz / m] | velocity RMS 3-D / horiz. [m/s] | RMS vx / vy / vz [m/s] | drift [% of m] | "
        "position err final / max / RMS [m] | own σ final [m] | height err RMS [m] | yaw err final / max [°] | "
        "tracking RMS [m] | status bits |",
        "|" + "---|" * 13,
    ]
    for name, rec in estimated:
        e = rec.estimation
        assert e is not None
        fixes = "none" if e.fix_rate <= 0.0 else f"{e.fix_rate:g} / {e.fix_noise:g}"
        vx, vy, vz = e.velocity_rms_axes
        lines.append(
            f"| {name} | {rec.metrics.method} | {e.measured_until:.1f}{' (fell)' if rec.metrics.fell else ''} | {fixes} | "
            f"{_fmt(e.velocity_rms)} / {_fmt(e.velocity_rms_horizontal)} | "
            f"{_fmt(vx)} / {_fmt(vy)} / {_fmt(vz)} | {_fmt(e.drift_percent, 2)} of {_fmt(e.path_length, 1)} | "
            f"{_fmt(e.position_error_final)} / {_fmt(e.position_error_max)} / {_fmt(e.position_rms)} | {_sigma_cell(e)} | "
            f"{_fmt(e.height_error_rms)} | "
            f"{_fmt(math.degrees(e.yaw_error_final), 2)} / {_fmt(math.degrees(e.yaw_error_max), 2)} | {_fmt(e.tracking_rms)} | "
            f"{e.status_bits:#x} |"
        )
    lines.append("")
    for name, rec in estimated:
        png = f"{name}_{rec.metrics.method}_estimation.png"
        plot_estimation(rec.log, f"{name} / {rec.metrics.method}", out_dir / png)
        lines.append(f"![{name} estimation]({png})")
        lines.append("")
    return lines
