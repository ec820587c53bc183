"""Fall rates with 95 % Wilson score intervals, overall and per factor level or bin.

Runs that ended in an error are not trials (they say nothing about falling) and are counted apart.
A factor with at most `MAX_LEVELS` distinct values is split by value; a continuous one (random
sampling over a range) into `BINS` equal-width bins over the values drawn.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

# z of a two-sided 95 % interval.
Z95 = 1.959963984540054
MAX_LEVELS = 8
BINS = 5
# Result columns that are factors (what a fall rate is broken down by), with their axis labels.
FACTOR_COLUMNS = {
    "push_magnitude": "push magnitude (N)",
    "push_direction_deg": "push direction (deg)",
    "push_heading_relative": "push direction relative to heading",
    "push_time": "push start, walk clock (s)",
    "push_duration": "push duration (s)",
    "payload_mass": "payload (fraction of trunk mass)",
    "payload_offset_x": "payload offset x (m)",
    "payload_offset_y": "payload offset y (m)",
    "payload_offset_z": "payload offset z (m)",
    "friction": "friction coefficient",
    "terrain_seed": "terrain seed",
    "comm_step": "FMU communication step (s)",
    "sensor_noise_seed": "sensor noise seed",
}


def wilson_interval(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion; (0, 1) without trials."""
    if trials < 0 or not 0 <= successes <= trials:
        raise ValueError(f"need 0 <= successes <= trials, got {successes} of {trials}")
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    z2 = z * z
    centre = (p + z2 / (2 * trials)) / (1 + z2 / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / (1 + z2 / trials)
    # Clamp the rounding noise at the ends (0/n and n/n give exactly 0 and 1).
    return max(0.0, centre - half) if successes else 0.0, min(1.0, centre + half) if successes < trials else 1.0


@dataclass(frozen=True)
class FallRate:
    label: str
    runs: int
    falls: int
    errors: int
    low: float
    high: float
    # Bin centre (or the level itself when numeric), for plotting; NaN for a non-numeric level.
    x: float = math.nan

    @property
    def rate(self) -> float:
        return self.falls / self.runs if self.runs else math.nan


def fall_rate(outcomes: np.ndarray, label: str = "all runs", x: float = math.nan) -> FallRate:
    outcomes = np.asarray(outcomes, dtype=object)
    errors = int(np.sum(outcomes == "error"))
    runs = len(outcomes) - errors
    falls = int(np.sum(outcomes == "fell"))
    low, high = wilson_interval(falls, runs)
    return FallRate(label, runs, falls, errors, low, high, x)


def _format(value: float) -> str:
    return f"{value:.4g}"


def factor_breakdown(table: pa.Table, column: str) -> list[FallRate]:
    """Fall rate per level (few distinct values) or per equal-width bin of `column`; empty when it does not vary."""
    values = np.asarray(table[column].to_pylist(), dtype=object)
    outcomes = row_outcomes(table)
    distinct = sorted(set(values.tolist()))
    if len(distinct) <= 1:
        return []
    if len(distinct) <= MAX_LEVELS or isinstance(distinct[0], bool):
        return [fall_rate(outcomes[values == level], f"{column} = {_format(level) if isinstance(level, float) else level}", float(level)) for level in distinct]
    numbers = values.astype(np.float64)
    edges = np.linspace(numbers.min(), numbers.max(), BINS + 1)
    index = np.clip(np.searchsorted(edges, numbers, side="right") - 1, 0, BINS - 1)
    rates = []
    for b in range(BINS):
        inside = index == b
        closing = "]" if b == BINS - 1 else ")"
        label = f"{column} in [{_format(edges[b])}, {_format(edges[b + 1])}{closing}"
        rates.append(fall_rate(outcomes[inside], label, 0.5 * (edges[b] + edges[b + 1])))
    return rates


def outcome_counts(table: pa.Table) -> dict[str, int]:
    from .runner import OUTCOMES

    outcomes = table["outcome"].to_pylist()
    return {name: outcomes.count(name) for name in OUTCOMES}


# Impulse bins (N·s), closed on the right so that "≤ 18 N·s" (90 N for 0.2 s, the bound) is a bin edge.
IMPULSE_EDGES = (0.0, 6.0, 12.0, 18.0, 24.0, 30.0)
# The same bins as velocity changes (impulse over mass, m/s) for our 12 kg robot: robots of other mass compare here.
VELOCITY_CHANGE_EDGES = (0.0, 0.5, 1.0, 1.5, 2.0, 2.5)
# The impulse below which no run may fall (docs/push-recovery.md).
NO_FALL_IMPULSE = 18.0


def row_outcomes(table: pa.Table) -> np.ndarray:
    """The rows' outcomes (OUTCOMES) as an object array, for masks."""
    return np.asarray(table["outcome"].to_pylist(), dtype=object)


def float_column(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as floats, NaN where a row has none (rows stored before it was recorded)."""
    return np.asarray([math.nan if v is None else v for v in table[name].to_pylist()], dtype=np.float64)


def push_impulses(table: pa.Table) -> np.ndarray:
    """Each run's push impulse, N·s: the force applied (`push_force`; the magnitude in rows stored
    before forces were recorded) times the duration."""
    magnitude = np.asarray(table["push_magnitude"].to_pylist(), dtype=np.float64)
    force = float_column(table, "push_force")
    force = np.where(np.isnan(force), magnitude, force)
    return force * np.asarray(table["push_duration"].to_pylist(), dtype=np.float64)


def velocity_changes(table: pa.Table) -> np.ndarray:
    """Each run's push impulse over the robot's mass, m/s (NaN where the mass was not recorded)."""
    return push_impulses(table) / float_column(table, "robot_mass")


def bin_bounds(edges: tuple[float, ...] | np.ndarray) -> list[tuple[float, float]]:
    """The (low, high] bins between consecutive `edges`, and an open last one above the last edge."""
    return [*itertools.pairwise(edges), (edges[-1], math.inf)]


def binned_fall_rates(values: np.ndarray, outcomes: np.ndarray, edges: tuple[float, ...] | np.ndarray, unit: str) -> list[FallRate]:
    """Fall rate per bin (low, high] of `values` (the first bin also takes `edges[0]`, the last one everything above)."""
    outcomes = np.asarray(outcomes, dtype=object)
    rates = []
    for i, (low, high) in enumerate(bin_bounds(edges)):
        inside = (values > low) & (values <= high) if i else (values >= low) & (values <= high)
        if math.isinf(high):
            if not inside.any():
                continue
            label, centre = f"> {_format(low)} {unit}", float(np.median(values[inside]))
        else:
            label, centre = f"{'[' if i == 0 else '('}{_format(low)}, {_format(high)}] {unit}", 0.5 * (low + high)
        rates.append(fall_rate(outcomes[inside], label, centre))
    return rates


def falls_up_to(table: pa.Table, impulse: float = NO_FALL_IMPULSE) -> FallRate:
    """The fall rate of the runs pushed with at most `impulse` N·s (no push included)."""
    return fall_rate(row_outcomes(table)[push_impulses(table) <= impulse + 1e-9], f"impulse ≤ {_format(impulse)} N·s")
