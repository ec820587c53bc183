"""The sweep's results on disk: a Parquet dataset appended to as runs finish, and resumable.

Layout of a store folder:
    spec.json          the spec the rows belong to (and its hash): a store refuses another spec
    rows/part-*.parquet one file per batch of finished runs (read together with pyarrow.dataset)
    plans/*.npz        the driver's plan per terrain seed, so a resumed sweep walks the same plans
A batch is written to a temporary name and renamed, so a crash never leaves half a file behind;
re-running skips the run ids already stored.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from ..errors import HarnessError
from ..planner_client import Plan
from .spec import SweepSpec

# One row per run: the columns, their types, in order.
ROW_SCHEMA = pa.schema(
    [
        ("run_id", pa.int64()),
        ("spec_hash", pa.string()),
        ("terrain_seed", pa.int64()),
        ("push_magnitude", pa.float64()),
        # The force applied, N: the magnitude times the spec's push scaling (null in older rows: the magnitude).
        ("push_force", pa.float64()),
        ("push_direction_deg", pa.float64()),
        ("push_heading_relative", pa.bool_()),
        ("push_time", pa.float64()),
        ("push_duration", pa.float64()),
        ("payload_mass", pa.float64()),
        ("payload_offset_x", pa.float64()),
        ("payload_offset_y", pa.float64()),
        ("payload_offset_z", pa.float64()),
        ("friction", pa.float64()),
        ("comm_step", pa.float64()),
        ("sensor_noise_seed", pa.int64()),
        # The physics engine (null in rows stored before it was recorded: those ran in DART).
        ("engine", pa.string()),
        # The robot's mass, kg (null in rows stored before it was recorded).
        ("robot_mass", pa.float64()),
        # Started from its group's saved post-stand-up state (payload and friction from there on).
        ("forked", pa.bool_()),
        ("outcome", pa.string()),
        ("fall_time", pa.float64()),
        ("rms_tracking_error", pa.float64()),
        ("max_tracking_error", pa.float64()),
        ("path_cost", pa.float64()),
        ("path_length", pa.float64()),
        ("simulated_time", pa.float64()),
        ("stop_reason", pa.string()),
        ("failure_reason", pa.string()),
        ("wall_time", pa.float64()),
        # CPU seconds of the worker process during the run: with wall_time, how much of a core the run had.
        ("cpu_time", pa.float64()),
    ]
)
ROW_COLUMNS = tuple(ROW_SCHEMA.names)
# Columns that depend on the machine and its load, not on the run.
NONDETERMINISTIC_COLUMNS = ("wall_time", "cpu_time")


def deterministic_rows(table: pa.Table) -> list[dict[str, Any]]:
    """The rows without the machine-dependent columns, NaN as None: equal for equal runs (NaN != NaN)."""
    rows = table.drop_columns(list(NONDETERMINISTIC_COLUMNS)).to_pylist()
    return [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()} for row in rows]


class StoreError(HarnessError):
    """The store folder belongs to another spec, or its files cannot be read."""

    exit_code = 2


class SweepStore:
    def __init__(self, folder: Path) -> None:
        self.folder = Path(folder)
        self.rows_dir = self.folder / "rows"
        self.plans_dir = self.folder / "plans"
        # The courses the runs walked, exported by `pfnav-sweep run` (one folder per terrain seed);
        # the report reads them back.
        self.scenarios_dir = self.folder / "scenarios"
        self.spec_file = self.folder / "spec.json"

    @classmethod
    def create(cls, folder: Path, spec: SweepSpec) -> SweepStore:
        """Opens (or starts) the store of `spec`; refuses a folder written by a different spec."""
        store = cls(folder)
        stored = store.stored_spec()
        if stored is not None and stored.get("hash") != spec.hash:
            unforked = dataclasses.replace(spec, fork=False)
            hint = (
                "its runs stood up by themselves: resume it with `fork = false` in the spec (or `pfnav-sweep run --no-fork`)"
                if spec.fork and stored.get("hash") == unforked.hash
                else "use another --out folder, or delete it to start over"
            )
            raise StoreError(f"{folder} holds the rows of another sweep spec (hash {stored.get('hash')}, this spec {spec.hash}): {hint}")
        store.rows_dir.mkdir(parents=True, exist_ok=True)
        store.plans_dir.mkdir(parents=True, exist_ok=True)
        if stored is None:
            _write_atomic(store.spec_file, json.dumps({"hash": spec.hash, "spec": spec.as_json()}, indent=2, sort_keys=True).encode())
        return store

    @classmethod
    def open_existing(cls, folder: Path) -> SweepStore:
        store = cls(folder)
        if store.stored_spec() is None:
            raise StoreError(f"{folder} is not a sweep store (no spec.json)")
        return store

    def stored_spec(self) -> dict[str, Any] | None:
        if not self.spec_file.is_file():
            return None
        try:
            data = json.loads(self.spec_file.read_text())
        except (OSError, ValueError) as err:
            raise StoreError(f"cannot read {self.spec_file}: {err}") from err
        if not isinstance(data, dict):
            raise StoreError(f"{self.spec_file} is not a sweep spec record")
        return data

    def append(self, rows: Iterable[dict[str, Any]]) -> int:
        """Writes one batch file; returns the number of rows written."""
        batch = list(rows)
        if not batch:
            return 0
        for row in batch:
            if tuple(row) != ROW_COLUMNS:
                missing = set(ROW_COLUMNS) - set(row)
                extra = set(row) - set(ROW_COLUMNS)
                raise StoreError(f"result row of run {row.get('run_id')} does not match the row schema (missing {sorted(missing)}, extra {sorted(extra)})")
        table = pa.Table.from_pylist(batch, schema=ROW_SCHEMA)
        first = min(int(r["run_id"]) for r in batch)
        name = f"part-{first:08d}-{len(batch):04d}-{os.getpid()}-{len(list(self.rows_dir.glob('part-*.parquet'))):06d}.parquet"
        path = self.rows_dir / name
        tmp = path.with_suffix(".parquet.tmp")
        pq.write_table(table, tmp)
        os.replace(tmp, path)
        return len(batch)

    def table(self) -> pa.Table:
        """Every stored row, sorted by run id (a run stored twice keeps its first row)."""
        files = sorted(self.rows_dir.glob("part-*.parquet")) if self.rows_dir.is_dir() else []
        if not files:
            return ROW_SCHEMA.empty_table()
        try:
            table = ds.dataset([str(f) for f in files], schema=ROW_SCHEMA, format="parquet").to_table()
        except (OSError, pa.ArrowInvalid) as err:
            raise StoreError(f"cannot read the rows in {self.rows_dir}: {err}") from err
        order = np.argsort(np.asarray(table["run_id"]), kind="stable")
        table = table.take(pa.array(order))
        ids = np.asarray(table["run_id"])
        keep = np.ones(len(ids), dtype=bool)
        keep[1:] = ids[1:] != ids[:-1]
        return table.filter(pa.array(keep))

    def done_ids(self) -> set[int]:
        return {int(v) for v in np.asarray(self.table()["run_id"])}

    def plan_file(self, scenario: str, terrain_seed: int, method: str) -> Path:
        return self.plans_dir / f"{scenario}_seed{terrain_seed}_{method}.npz"

    def load_plan(self, scenario: str, terrain_seed: int, method: str) -> Plan | None:
        path = self.plan_file(scenario, terrain_seed, method)
        if not path.is_file():
            return None
        try:
            with np.load(path, allow_pickle=False) as data:
                columns = {name: np.array(data[f"plan_{name}"]) for name in ("t", "x", "y", "z", "yaw", "vx", "vy", "yaw_rate")}
                metrics = json.loads(str(data["metrics"]))
        except (OSError, KeyError, ValueError) as err:
            raise StoreError(f"cannot read the stored plan {path}: {err} (delete it to plan again)") from err
        plan = Plan(method, metrics=metrics, **columns)
        plan.validate()
        return plan

    def save_plan(self, scenario: str, terrain_seed: int, plan: Plan) -> None:
        path = self.plan_file(scenario, terrain_seed, plan.method)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, **plan.to_npz_dict(), metrics=np.array(json.dumps(plan.metrics)))
        os.replace(tmp, path)


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)
