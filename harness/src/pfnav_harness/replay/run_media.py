"""What `pfnav-demo run|demo --record --video` writes for each run, after the run.

Names follow the run's log: OUT/logs/NAME.npz gives OUT/recordings/NAME.rrd and
OUT/videos/NAME.mp4 (NAME = SCENARIO_LABEL), so the HTML report finds them from the log's name.
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
VIDEOS_DIR = "videos"


def recording_path(out: Path, run_name: str) -> Path:
    return out / RECORDINGS_DIR / f"{run_name}.rrd"


def video_path(out: Path, run_name: str) -> Path:
    return out / VIDEOS_DIR / f"{run_name}.mp4"


@dataclass(frozen=True)
class RunMedia:
    """What was written for one run, and the wall seconds each took."""

    recording: Path | None = None
    recording_seconds: float = 0.0
    video: Path | None = None
    video_seconds: float = 0.0


def write_run_media(
    out: Path,
    run_name: str,
    log: RunLog,
    scenario: Scenario,
    robot: RobotDescription,
    field: FeedbackField | None,
    record: bool,
    video: bool,
    show_progress: bool = False,
) -> RunMedia:
    """The recording and/or the video of one finished run, from its log."""
    recording_file = video_file = None
    recording_seconds = video_seconds = 0.0
    if record:
        from .recording import write_recording

        started = time.perf_counter()
        recording_file = write_recording(log, scenario, robot, recording_path(out, run_name), run_name, field).path
        recording_seconds = time.perf_counter() - started
    if video:
        from .video import render_video

        started = time.perf_counter()
        video_file = render_video(log, scenario, robot, video_path(out, run_name), run_name, show_progress).path
        video_seconds = time.perf_counter() - started
    return RunMedia(recording_file, recording_seconds, video_file, video_seconds)
