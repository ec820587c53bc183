"""What `pfnav-demo run|demo --record` writes for each run, after the run.

Names follow the run's log: OUT/logs/NAME.npz gives OUT/recordings/NAME.rrd (NAME =
SCENARIO_LABEL), so a report finds them from the log's name.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ..feedback_field import FeedbackField
from ..robot import RobotDescription
from ..scenario import Scenario
from .run_log import RunLog

RECORDINGS_DIR = "recordings"


def recording_path(out: Path, run_name: str) -> Path:
    return out / RECORDINGS_DIR / f"{run_name}.rrd"


@dataclass(frozen=True)
class RunMedia:
    """What was written for one run, and the wall seconds each took."""

    recording: Path | None = None
    recording_seconds: float = 0.0


def write_run_media(
    out: Path,
    run_name: str,
    log: RunLog,
    scenario: Scenario,
    robot: RobotDescription,
    field: FeedbackField | None,
    record: bool,
) -> RunMedia:
    """The recording of one finished run, from its log."""
    recording_file = None
    recording_seconds = 0.0
    if record:
        from .recording import write_recording

        started = time.perf_counter()
        recording_file = write_recording(log, scenario, robot, recording_path(out, run_name), run_name, field).path
        recording_seconds = time.perf_counter() - started
    return RunMedia(recording_file, recording_seconds)
