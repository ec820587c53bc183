"""A tiny sweep (sweeps/tiny.toml: 4 runs of 3.5 simulated s) on Dask: the same rows on 2 workers and on 1, resume, CLI.

The runs start from their group's fork (the spec's default), made once per sweep.

The plan comes from the planner service over LCM udpm:// (run inside scripts/netns.sh, as
scripts/test.sh does); it is made once for the module and shipped to the workers, which only
co-simulate with the real controller FMU.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from pfnav_harness import paths
from pfnav_harness.planner_client import DEFAULT_LCM_URL
from pfnav_harness.robot import RobotDescription
from pfnav_harness.sweep.cli import _lcm_planner, main
from pfnav_harness.sweep.cluster import dask_client
from pfnav_harness.sweep.driver import prepare_courses, run_sweep
from pfnav_harness.sweep.runner import Artifacts, Course
from pfnav_harness.sweep.spec import SweepSpec, load_spec
from pfnav_harness.sweep.store import SweepStore, deterministic_rows

# Our robot (robot/quadruped.toml), whatever $PFNAV_ROBOT says: these tests are calibrated on it.
ROBOT = RobotDescription.load(paths.default_robot_config_path())

TINY = paths.repo_root() / "sweeps" / "tiny.toml"


@pytest.fixture(scope="module")
def tiny_spec() -> SweepSpec:
    return load_spec(TINY)


@pytest.fixture(scope="module")
def artifacts() -> Artifacts:
    return Artifacts(paths.fmu_path(), ROBOT, paths.pf_plan_path())


@pytest.fixture(scope="module")
def planned(tiny_spec: SweepSpec, tmp_path_factory: pytest.TempPathFactory) -> tuple[SweepStore, dict[int, Course]]:
    """A store holding the tiny spec's plan (planned once over LCM), and the courses."""
    folder = tmp_path_factory.mktemp("planned")
    store = SweepStore.create(folder / "store", tiny_spec)
    courses = prepare_courses(tiny_spec, store, paths.pf_plan_path(), _lcm_planner(DEFAULT_LCM_URL, allow_host_network=False), folder / "scenarios")
    return store, courses


def fresh_store(planned: tuple[SweepStore, dict[int, Course]], spec: SweepSpec, folder: Path) -> SweepStore:
    """A new store of `spec` with the planned store's plans (no second planning)."""
    store = SweepStore.create(folder, spec)
    for plan_file in planned[0].plans_dir.glob("*.npz"):
        shutil.copy(plan_file, store.plans_dir / plan_file.name)
    return store


@pytest.fixture(scope="module")
def one_worker() -> Iterator[object]:
    with dask_client(workers=1) as client:
        yield client


@pytest.fixture(scope="module")
def one_worker_store(
    planned: tuple[SweepStore, dict[int, Course]], tiny_spec: SweepSpec, artifacts: Artifacts, one_worker: object, tmp_path_factory: pytest.TempPathFactory
) -> SweepStore:
    store = fresh_store(planned, tiny_spec, tmp_path_factory.mktemp("one") / "store")
    # One Parquet file per run, so the resume test can drop some.
    summary = run_sweep(tiny_spec, store, planned[1], artifacts, one_worker, show_progress=False, batch_rows=1)
    assert (summary.ran, summary.skipped) == (4, 0)
    return store


def test_two_workers_give_the_same_rows_as_one(
    planned: tuple[SweepStore, dict[int, Course]], tiny_spec: SweepSpec, artifacts: Artifacts, one_worker_store: SweepStore, tmp_path: Path
) -> None:
    store = fresh_store(planned, tiny_spec, tmp_path / "two")
    with dask_client(workers=2) as client:
        summary = run_sweep(tiny_spec, store, planned[1], artifacts, client, show_progress=False)
    assert (summary.ran, summary.errors) == (4, 0)
    two = store.table()
    one = one_worker_store.table()
    assert two["run_id"].to_pylist() == [0, 1, 2, 3]
    rows = two.to_pylist()
    assert all(r["outcome"] in ("goal", "fell", "timeout") and not r["failure_reason"] for r in rows), rows
    # The runs really ran: stood up, walked on, tracked the plan.
    assert all(r["simulated_time"] == pytest.approx(tiny_spec.duration, abs=0.002) or r["outcome"] == "fell" for r in rows)
    assert all(0.0 < r["rms_tracking_error"] < 0.5 and r["path_length"] > 0.0 and r["wall_time"] > 0.0 for r in rows)
    # Every run continued from the sweep's one post-stand-up fork (one terrain, one communication step).
    assert all(r["forked"] for r in rows)
    # Factor values from the spec, row for row.
    assert [r["push_magnitude"] for r in rows] == [tiny_spec.run_factors(i)["push_magnitude"] for i in range(4)]
    assert deterministic_rows(two) == deterministic_rows(one)


def test_resume_skips_finished_runs(
    planned: tuple[SweepStore, dict[int, Course]], tiny_spec: SweepSpec, artifacts: Artifacts, one_worker_store: SweepStore, one_worker: object
) -> None:
    before = deterministic_rows(one_worker_store.table())
    files = sorted(one_worker_store.rows_dir.glob("part-*.parquet"))
    assert len(files) == 4
    for lost in files[1::2]:
        lost.unlink()
    assert len(one_worker_store.done_ids()) == 2
    summary = run_sweep(tiny_spec, one_worker_store, planned[1], artifacts, one_worker, show_progress=False)
    assert (summary.skipped, summary.ran) == (2, 2)
    assert deterministic_rows(one_worker_store.table()) == before
    again = run_sweep(tiny_spec, one_worker_store, planned[1], artifacts, one_worker, show_progress=False)
    assert (again.skipped, again.ran) == (4, 0)


def test_cli_run_resumes_a_finished_store_and_reports(one_worker_store: SweepStore, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    copy = tmp_path / "store"
    shutil.copytree(one_worker_store.folder, copy)
    assert main(["run", str(TINY), "--out", str(copy), "--workers", "1", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "0 run(s) done (0 error(s)), 4 already stored" in out
    report = (copy / "REPORT.md").read_text()
    assert "Fall rate" in report and "push magnitude (N)" in report
    assert (copy / "fall_rate_push_magnitude.png").is_file()
    # Another spec on the same folder is refused, with the reason.
    other = tmp_path / "other.toml"
    other.write_text(TINY.read_text().replace("seed = 7", "seed = 8"))
    assert main(["run", str(other), "--out", str(copy), "--workers", "1"]) == 2
    assert "holds the rows of another sweep spec" in capsys.readouterr().err
