"""scripts/push_diagnosis.py: the figures of one pushed run, from a log built to known values."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
import push_diagnosis

DT = 0.001


def pushed_log(n: int = 3000, push_at: int = 1000) -> dict[str, np.ndarray]:
    t = np.arange(n) * DT
    push = np.zeros((n, 3))
    push[push_at : push_at + 200, 1] = 120.0
    velocity = np.zeros((n, 3))
    velocity[:, 0] = 0.4
    # The push adds 1.5 m/s sideways, ramping over its 0.2 s.
    velocity[push_at:, 1] = np.minimum(np.arange(n - push_at) * DT / 0.2, 1.0) * 1.5
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    roll = math.radians(50.0)
    quat[-1] = [math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0]
    tau = np.zeros((n, 12))
    # Joint 3 at its limit on the first 100 ticks after the push.
    tau[push_at : push_at + 100, 3] = -10.0
    scheduled = np.ones((n, 4), dtype=np.int8)
    actual = np.ones((n, 4), dtype=np.int8)
    # One of four feet off the ground in the second quarter of the window.
    actual[push_at + 500 : push_at + 1000, 0] = 0
    return {
        "t": t,
        "physics_dt": np.array(DT),
        "push_force": push,
        "base_vel": velocity,
        "base_quat": quat,
        "tau": tau,
        "contact_scheduled": scheduled,
        "contact_actual": actual,
        "est_vel": velocity + np.array([0.0, 0.2, 0.0]),
    }


def test_a_fall_is_taken_apart_from_the_push_to_the_fall() -> None:
    log = pushed_log()
    row = push_diagnosis.diagnose(log, 3000, np.full(12, 10.0), 0.28)
    assert row["fell"]
    assert row["fall_after"] == pytest.approx(2.0)
    assert row["dv"] == pytest.approx(1.5)
    assert row["capture_step"] == pytest.approx(1.5 * math.sqrt(0.28 / 9.81))
    # 100 of the 2000 window ticks have a joint at its limit; 500 of 8000 stance foot ticks lack contact.
    assert row["saturated"] == pytest.approx(100 / 2000)
    assert row["missed"] == pytest.approx(500 / 8000)
    assert row["tripped"] == 0.0
    assert row["estimate_error"] == pytest.approx(0.2)
    assert row["roll"] == pytest.approx(50.0)


def test_without_a_fall_the_window_is_two_seconds_and_a_run_without_a_push_is_refused() -> (
    None
):
    log = pushed_log()
    row = push_diagnosis.diagnose(log, None, np.full(12, 10.0), 0.28)
    assert not row["fell"] and math.isnan(row["fall_after"])
    assert row["saturated"] == pytest.approx(100 / 2000)
    log["push_force"][:] = 0.0
    with pytest.raises(ValueError, match="no push"):
        push_diagnosis.diagnose(log, None, np.full(12, 10.0), 0.28)


def test_a_run_that_falls_before_its_push_counts_as_a_fall_with_nothing_to_take_apart() -> (
    None
):
    log = pushed_log()
    log["push_force"][:] = 0.0
    row = push_diagnosis.diagnose(log, 500, np.full(12, 10.0), 0.28)
    assert row["fell"] and row["before_push"]
    assert math.isnan(row["dv"]) and math.isnan(row["fall_after"])
    # The same fields as a run taken apart, so every table and plot reads either kind.
    assert row.keys() == push_diagnosis.diagnose(pushed_log(), 3000, np.full(12, 10.0), 0.28).keys()
    row.update(variant="kalman", magnitude=90.0, direction="left", walk_time=4.0)
    text = push_diagnosis.tables([row], [push_diagnosis.Variant("kalman")], [90.0], ["left"])
    assert "yes, before the push" in text and "1/1" in text


def test_a_variant_names_fmu_parameters_and_labels_the_raibert_gain_as_before() -> None:
    variant = push_diagnosis.parse_variant("gait.period=0.2, gait.raibertGain=0.1")
    assert variant == push_diagnosis.Variant(
        "kalman", (("gait.period", 0.2), ("gait.raibertGain", 0.1))
    )
    assert variant.label == "kalman, gait.period 0.2, gait.raibertGain 0.1"
    gain = push_diagnosis.Variant(
        "kalman", ((push_diagnosis.RAIBERT_GAIN_PARAMETER, 0.15),)
    )
    assert gain.label == "kalman, Raibert gain 0.15 s"
    for bad in ("gait.period", "=0.2", "gait.period=fast"):
        with pytest.raises(ValueError):
            push_diagnosis.parse_variant(bad)
