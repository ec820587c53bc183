"""The planner's trajectory as a reference signal indexed by time, with the terrain under it.

Heights and terrain planes are re-evaluated on the physics mesh (not taken from the plan's z) so
the controller sees exactly the ground the robot stands on. They are precomputed once per plan
sample: per-step work is one bisection and one interpolation of a small row.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from numpy.typing import NDArray

from .planner_client import Plan
from .scenario import Terrain

# Columns of a reference row.
X, Y, Z, YAW, VX, VY, YAW_RATE, T_HEIGHT, T_DZDX, T_DZDY = range(10)
N_COLUMNS = 10


def _moving_average(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Centred moving average with the end values repeated beyond both ends."""
    half = window // 2
    padded = np.concatenate([np.full(half, values[0]), values, np.full(window - 1 - half, values[-1])])
    return np.convolve(padded, np.ones(window) / window, mode="valid")


# Radius of the terrain plane fitted under the robot for its reference height and slopes, m.
TERRAIN_PLANE_RADIUS = 0.3


class ReferenceTrajectory:
    """Reference at plan time τ: linear interpolation between samples, held before 0 and after the end."""

    def __init__(self, plan: Plan, terrain: Terrain, plane_radius: float = TERRAIN_PLANE_RADIUS, heading_smoothing: float = 0.0) -> None:
        """`heading_smoothing` > 0: moving-average window (s) over the heading and velocity feed-forward.

        Grid-graph paths zig-zag between neighbour directions; their per-sample heading jumps
        (±45° at up to ~8 rad/s) are not something a legged robot should be asked to follow. The
        window smooths heading, velocity and yaw rate only; the reference positions (what the
        tracking error is measured against) stay exactly the plan's.
        """
        plan.validate()
        self.times = [float(t) for t in plan.t]
        n = len(self.times)
        rows = np.zeros((n, N_COLUMNS))
        rows[:, X] = plan.x
        rows[:, Y] = plan.y
        rows[:, Z] = terrain.height(plan.x, plan.y)
        rows[:, YAW] = np.unwrap(plan.yaw)
        rows[:, VX] = plan.vx
        rows[:, VY] = plan.vy
        rows[:, YAW_RATE] = plan.yaw_rate
        period = float(np.median(np.diff(plan.t)))
        window = round(heading_smoothing / period) if heading_smoothing > 0 else 1
        if window > 1 and n > 2:
            cos_yaw = _moving_average(np.cos(plan.yaw), window)
            sin_yaw = _moving_average(np.sin(plan.yaw), window)
            rows[:, YAW] = np.unwrap(np.arctan2(sin_yaw, cos_yaw))
            rows[:, YAW_RATE] = np.gradient(rows[:, YAW], plan.t)
            rows[:, VX] = _moving_average(plan.vx, window)
            rows[:, VY] = _moving_average(plan.vy, window)
        for i in range(n):
            plane = terrain.plane(float(plan.x[i]), float(plan.y[i]), radius=plane_radius)
            rows[i, T_HEIGHT] = plane.height
            rows[i, T_DZDX] = plane.dzdx
            rows[i, T_DZDY] = plane.dzdy
        self.rows = rows
        self._times = np.array(self.times)
        self.duration = self.times[-1] - self.times[0]
        self._t0 = self.times[0]
        # Outside the plan's time span the robot is asked to stand still at the end point.
        self._hold_first = rows[0].copy()
        self._hold_last = rows[-1].copy()
        for hold in (self._hold_first, self._hold_last):
            hold[VX] = hold[VY] = hold[YAW_RATE] = 0.0

    def sample(self, tau: float, out: NDArray[np.float64]) -> None:
        """Writes the reference row at plan time `tau` (seconds since the plan's first sample) into `out`."""
        t = self._t0 + tau
        times = self.times
        if t <= times[0]:
            out[:] = self._hold_first
        elif t >= times[-1]:
            out[:] = self._hold_last
        else:
            i = bisect.bisect_right(times, t) - 1
            a = (t - times[i]) / (times[i + 1] - times[i])
            r0 = self.rows[i]
            out[:] = r0 + a * (self.rows[i + 1] - r0)
        out[YAW] = math.remainder(out[YAW], 2.0 * math.pi)

    def sample_block(self, tau: NDArray[np.float64], out: NDArray[np.float64]) -> None:
        """`sample(tau[j], out[j])` for every j at once, with the same floating-point operations.

        Element-wise numpy arithmetic rounds exactly as the scalar code does, so each row is
        `sample`'s bit for bit (test_hs_reference).
        """
        times = self._times
        t = self._t0 + tau
        i = np.searchsorted(times, t, side="right") - 1
        np.clip(i, 0, len(times) - 2, out=i)
        t_i = times[i]
        a = (t - t_i) / (times[i + 1] - t_i)
        r0 = self.rows[i]
        np.add(r0, a[:, None] * (self.rows[i + 1] - r0), out=out)
        out[t <= times[0]] = self._hold_first
        out[t >= times[-1]] = self._hold_last
        tau_pi = 2.0 * math.pi
        out[:, YAW] = [math.remainder(yaw, tau_pi) for yaw in out[:, YAW].tolist()]
