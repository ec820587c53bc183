"""Sweep statistics and storage: Wilson intervals, per-factor fall rates, the Parquet store and its refusals, the report."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest

from pfnav_harness.planner_client import Plan
from pfnav_harness.scenario import GoalRegion, Scenario, Terrain
from pfnav_harness.sweep.report import write_report
from pfnav_harness.sweep.runner import Course, RunTask, result_row
from pfnav_harness.sweep.spec import parse_spec
from pfnav_harness.sweep.stats import (
    IMPULSE_EDGES,
    binned_fall_rates,
    factor_breakdown,
    fall_rate,
    falls_up_to,
    push_impulses,
    velocity_changes,
    wilson_interval,
)
from pfnav_harness.sweep.store import ROW_COLUMNS, ROW_SCHEMA, StoreError, SweepStore


@pytest.mark.parametrize(
    ("falls", "trials", "low", "high"),
    [
        # Wilson score interval, z = 1.96: the textbook 0/10, 5/10, 10/10 and Newcombe (1998), Table I.
        (0, 10, 0.0, 0.2775),
        (5, 10, 0.2366, 0.7634),
        (10, 10, 0.7225, 1.0),
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ],
)
def test_wilson_interval_known_values(falls: int, trials: int, low: float, high: float) -> None:
    got = wilson_interval(falls, trials)
    assert got == pytest.approx((low, high), abs=1e-4)


def test_wilson_interval_edges() -> None:
    assert wilson_interval(0, 0) == (0.0, 1.0)
    with pytest.raises(ValueError, match="successes <= trials"):
        wilson_interval(11, 10)


def test_errors_are_not_trials() -> None:
    rate = fall_rate(np.array(["fell", "goal", "error", "timeout", "fell"], dtype=object))
    assert (rate.runs, rate.falls, rate.errors) == (4, 2, 1)
    assert rate.rate == 0.5
    # Wilson 95 % for 2 of 4: centre 0.5, half-width 1.96·√(1/16 + 1.96²/64) / (1 + 1.96²/4) = 0.350.
    assert (rate.low, rate.high) == pytest.approx((0.150, 0.850), abs=1e-3)


def _course() -> Course:
    terrain = Terrain((0.0, 0.0), 0.1, np.zeros((10, 10)))
    scenario = Scenario("flat", terrain, (0.2, 0.2), 0.0, GoalRegion((0.8, 0.8), 0.1))
    t = np.array([0.0, 1.0])
    plan = Plan("pf", t, t, t, 0 * t, 0 * t, 0 * t, 0 * t, 0 * t)
    return Course(5, scenario, plan)


def fake_rows(spec_hash: str, outcomes: list[str], **factor_values: list[Any]) -> list[dict[str, Any]]:
    """Result rows as the runner makes them (schema and factor columns), with chosen outcomes."""
    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": len(outcomes)})
    rows = []
    for run_id, outcome in enumerate(outcomes):
        factors = spec.run_factors(run_id) | {name: values[run_id] for name, values in factor_values.items()}
        task = RunTask(run_id, factors, 1.0, 0.5, spec_hash)
        rows.append(result_row(task, _course(), outcome=outcome, rms_tracking_error=0.01 * run_id, wall_time=1.0))
    return rows


def test_factor_breakdown_levels_and_bins() -> None:
    outcomes = ["fell", "goal", "fell", "goal", "fell", "fell"]
    table = pa.Table.from_pylist(fake_rows("h", outcomes, friction=[0.5, 0.5, 0.5, 1.0, 1.0, 1.0]))
    levels = factor_breakdown(table, "friction")
    assert [(r.label, r.runs, r.falls) for r in levels] == [("friction = 0.5", 3, 2), ("friction = 1", 3, 2)]
    assert factor_breakdown(table, "payload_mass") == []  # not varied
    magnitudes = list(np.linspace(0.0, 100.0, 20))
    many = pa.Table.from_pylist(fake_rows("h", ["fell" if m > 50 else "goal" for m in magnitudes], push_magnitude=magnitudes))
    bins = factor_breakdown(many, "push_magnitude")
    assert len(bins) == 5 and sum(b.runs for b in bins) == 20
    assert bins[0].falls == 0 and bins[-1].falls == bins[-1].runs == 4
    assert bins[0].x == pytest.approx(10.0)


def test_store_appends_resumes_and_refuses_another_spec(tmp_path: Path) -> None:
    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": 4})
    store = SweepStore.create(tmp_path / "store", spec)
    rows = fake_rows(spec.hash, ["goal", "fell", "timeout", "error"])
    assert tuple(rows[0]) == ROW_COLUMNS
    store.append(rows[2:])
    store.append(rows[:2])
    store.append(rows[1:2])  # a run stored twice keeps one row
    table = store.table()
    assert table["run_id"].to_pylist() == [0, 1, 2, 3]
    assert table["outcome"].to_pylist() == ["goal", "fell", "timeout", "error"]
    assert math.isnan(table["fall_time"][0].as_py())
    assert store.done_ids() == {0, 1, 2, 3}
    # Reopening with the same spec keeps the rows; another spec is refused.
    assert SweepStore.create(tmp_path / "store", spec).done_ids() == {0, 1, 2, 3}
    other = parse_spec({"scenario": "flat", "duration": 2.0, "seed": 1, "runs": 4})
    with pytest.raises(StoreError, match="another sweep spec"):
        SweepStore.create(tmp_path / "store", other)
    with pytest.raises(StoreError, match="does not match the row schema"):
        store.append([{**rows[0], "colour": "red"}])
    with pytest.raises(StoreError, match="not a sweep store"):
        SweepStore.open_existing(tmp_path / "nothing")
    # Plans round-trip through the store.
    plan = _course().plan
    store.save_plan("flat", 5, plan)
    loaded = store.load_plan("flat", 5, "pf")
    assert loaded is not None and np.array_equal(loaded.x, plan.x)
    assert store.load_plan("flat", 6, "pf") is None


def test_report_has_rates_and_plots(tmp_path: Path) -> None:
    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": 8})
    store = SweepStore.create(tmp_path / "store", spec)
    magnitudes = [10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0]
    store.append(fake_rows(spec.hash, ["goal", "goal", "timeout", "goal", "fell", "goal", "fell", "fell"], push_magnitude=magnitudes))
    path = write_report(store)
    text = path.read_text()
    assert "**Fall rate 37.5 %** (3 of 8), 95 % Wilson interval 13.7 % – 69.4 %" in text
    assert "| push_magnitude = 10 | 1 | 0 |" in text
    assert (store.folder / "fall_rate_push_magnitude.png").stat().st_size > 5000
    assert (store.folder / "tracking_error.png").is_file()


def test_report_publishes_a_results_page(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from pfnav_harness.sweep.cli import main

    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": 4})
    store = SweepStore.create(tmp_path / "store", spec)
    store.append(fake_rows(spec.hash, ["goal", "fell", "goal", "goal"]))
    monkeypatch.setenv("PFNAV_ROOT", str(tmp_path))
    # Inside scripts/netns.sh the page would name the wrapped command.
    monkeypatch.delenv("PFNAV_IN_NETNS", raising=False)
    assert main(["report", str(tmp_path / "store"), "--results-page", "sweep-flat"]) == 0
    page = (tmp_path / "docs" / "results" / "sweep-flat.md").read_text()
    assert page.startswith("# Robustness sweep: flat\n")
    assert "Generated by `.venv/bin/pfnav-sweep report store --results-page sweep-flat`" in page
    assert "**Fall rate 25.0 %** (1 of 4)" in page
    assert ".png)" not in page, "the plots stay in the store folder"


def test_impulse_bins_and_the_no_fall_bound(tmp_path: Path) -> None:
    """Impulses are force × duration in right-closed bins: 90 N for 0.2 s (18 N·s) counts as ≤ 18 N·s;
    rows stored before forces were recorded use the magnitude."""
    spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": 6})
    rows = fake_rows(spec.hash, ["goal", "fell", "goal", "fell", "fell", "goal"], push_magnitude=[0.0, 30.0, 90.0, 91.0, 150.0, 160.0], push_duration=[0.2] * 6)
    rows[1]["push_force"] = None
    for row in rows:
        row["robot_mass"] = 12.0
    table = pa.Table.from_pylist(rows, schema=ROW_SCHEMA)
    assert push_impulses(table) == pytest.approx([0.0, 6.0, 18.0, 18.2, 30.0, 32.0])
    assert velocity_changes(table) == pytest.approx(np.array([0.0, 6.0, 18.0, 18.2, 30.0, 32.0]) / 12.0)
    small = falls_up_to(table)
    assert (small.runs, small.falls) == (3, 1)
    bins = binned_fall_rates(push_impulses(table), np.array([r["outcome"] for r in rows], dtype=object), IMPULSE_EDGES, "N·s")
    assert [(b.label, b.runs, b.falls) for b in bins] == [
        ("[0, 6] N·s", 2, 1),
        ("(6, 12] N·s", 0, 0),
        ("(12, 18] N·s", 1, 0),
        ("(18, 24] N·s", 1, 1),
        ("(24, 30] N·s", 1, 1),
        ("> 30 N·s", 1, 0),
    ]


def test_comparison_of_stores_by_impulse(tmp_path: Path) -> None:
    """`pfnav-sweep compare` tables each store's fall rate overall, at ≤ 18 N·s and by impulse over mass, with one plot."""
    from pfnav_harness.sweep.cli import main

    folders = []
    for name, mass, outcomes in (("ours", 12.0, ["goal", "fell", "goal", "goal"]), ("go1", 13.1, ["fell", "fell", "goal", "goal"])):
        extra = {"robot": "robot/third_party/go1.toml", "push_scaling": "mass"} if name == "go1" else {}
        spec = parse_spec({"scenario": "flat", "duration": 1.0, "seed": 1, "runs": 4, **extra})
        store = SweepStore.create(tmp_path / name, spec)
        rows = fake_rows(spec.hash, outcomes, push_magnitude=[10.0, 60.0, 100.0, 140.0])
        for row in rows:
            row["robot_mass"] = mass
        store.append(rows)
        folders.append(str(store.folder))
    assert main(["compare", *folders, "--out", str(tmp_path / "cmp")]) == 0
    text = (tmp_path / "cmp" / "COMPARE.md").read_text()
    assert "| ours, kalman, dart | `ours` |" in text and "| 12.000 | 4 | 1 | 25.0 %" in text
    assert "| go1, kalman, dart | `go1` |" in text and "| 13.100 | 4 | 2 | 50.0 %" in text
    assert "## go1, kalman, dart" in text and "m/s" in text
    assert (tmp_path / "cmp" / "compare_push.png").stat().st_size > 5000
