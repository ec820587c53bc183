"""The Dask cluster a sweep runs on: a LocalCluster of one single-threaded process per core, or an existing one.

Processes, not threads: each run loads its own FMU instance, and FMUs in general are not safe to
share across threads of one process. `--scheduler ADDRESS` sends the same tasks to a running
dask-distributed scheduler (`dask scheduler` + `dask worker --nthreads 1 ...` on the machines);
its workers need the same paths to the FMU, the robot config and its URDF, and pf-plan (a shared file system).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager

from ..errors import HarnessError


class ClusterError(HarnessError):
    exit_code = 6


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:
        return max(1, os.cpu_count() or 1)


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[object]:
    """A `distributed.Client` on a new LocalCluster (`workers` processes, default one per core) or on `scheduler`."""
    from distributed import Client, LocalCluster

    if workers is not None and workers < 1:
        raise ClusterError(f"--workers must be >= 1, got {workers}")
    # Dask logs every worker start and stop at INFO; a sweep has its own progress bar.
    for name in ("distributed", "distributed.worker", "distributed.scheduler", "distributed.nanny", "distributed.core"):
        logging.getLogger(name).setLevel(logging.WARNING)
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as err:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: {err}") from err
        try:
            if not client.scheduler_info().get("workers"):
                client.wait_for_workers(1, timeout=60)
            yield client
        except TimeoutError as err:
            raise ClusterError(f"the Dask scheduler at {scheduler} has no workers (waited 60 s)") from err
        finally:
            client.close()
        return
    n = workers or default_workers()
    try:
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            # The scheduler serves HTTP whatever this says; a free port keeps two sweeps from colliding on 8787.
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.WARNING,
            # Each run uses a few hundred MB at most; Dask's default per-worker share of RAM is fine,
            # but pausing or restarting a worker mid-run would only lose work.
            memory_limit=0,
        )
    except OSError as err:
        raise ClusterError(f"cannot start a local Dask cluster of {n} workers: {err}") from err
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()
