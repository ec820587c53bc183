"""What `pfnav-demo run|demo --record --video` writes for each run, after the run.

Names follow the run's log: OUT/logs/NAME.npz gives OUT/recordings/NAME.rrd and
OUT/videos/NAME.mp4 (NAME = SCENARIO_LABEL), so the HTML report finds them from the log's name.

`MediaQueue` makes them from the saved logs in processes of their own as runs finish: they fill
the cores the runs leave idle (the last runs of a demo, the report's plots) instead of adding
their time to a run's.
"""

from __future__ import annotations

import multiprocessing
import sys
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from ..feedback_field import FeedbackField
from ..robot import RobotDescription
from ..scenario import Scenario
from .density import DensityOptions
from .run_log import RunLog, load_run_log

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

    def summary(self) -> str:
        parts = []
        if self.recording is not None:
            parts.append(f"recording {self.recording} ({self.recording.stat().st_size / 1e6:.1f} MB) in {self.recording_seconds:.1f} s")
        if self.video is not None:
            parts.append(f"video {self.video} in {self.video_seconds:.1f} s")
        return "; ".join(parts)


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
    density_options: DensityOptions | None = None,
) -> RunMedia:
    """The recording and/or the video of one finished run, from its log.

    An offline P-F run's recording (its `field` given) shows the plan's occupation density,
    planned again by pf-plan with `density_options` (None: leave it out)."""
    recording_file = video_file = None
    recording_seconds = video_seconds = 0.0
    if record:
        from .recording import write_recording

        started = time.perf_counter()
        density = None
        if field is not None and density_options is not None and "replan_t_apply" not in log:
            from .. import paths
            from .density import plan_density

            density = plan_density(paths.pf_plan_path(), scenario, field, density_options)
        recording_file = write_recording(log, scenario, robot, recording_path(out, run_name), run_name, field, density=density).path
        recording_seconds = time.perf_counter() - started
    if video:
        from .video import render_video

        started = time.perf_counter()
        video_file = render_video(log, scenario, robot, video_path(out, run_name), run_name, show_progress).path
        video_seconds = time.perf_counter() - started
    media = RunMedia(recording_file, recording_seconds, video_file, video_seconds)
    print(media.summary(), file=sys.stderr, flush=True)
    return media


def write_run_media_from_log(
    out: Path,
    log_file: Path,
    scenario: Scenario,
    robot: RobotDescription,
    field: FeedbackField | None,
    record: bool,
    video: bool,
    density_options: DensityOptions | None = None,
) -> RunMedia:
    """`write_run_media` for the run whose log is `log_file` (OUT/logs/NAME.npz)."""
    return write_run_media(out, log_file.stem, load_run_log(log_file), scenario, robot, field, record, video, density_options=density_options)


class MediaQueue:
    """Recordings and videos of finished runs, made in `workers` processes while other work goes on."""

    def __init__(self, out: Path, robot: RobotDescription, record: bool, video: bool, workers: int, density_options: DensityOptions | None = None) -> None:
        self.out, self.robot, self.record, self.video = out, robot, record, video
        self.density_options = density_options
        # spawn: a worker starts clean, without the parent's LCM or DART state.
        self.pool = ProcessPoolExecutor(max_workers=max(1, workers), mp_context=multiprocessing.get_context("spawn"))
        self.pending: list[Future[RunMedia]] = []

    def submit(self, log_file: Path, scenario: Scenario, field: FeedbackField | None) -> None:
        self.pending.append(
            self.pool.submit(write_run_media_from_log, self.out, log_file, scenario, self.robot, field, self.record, self.video, self.density_options)
        )

    def wait(self, show_progress: bool) -> list[RunMedia]:
        """Every submitted run's media (in submission order) once all are written; the first failure is raised."""
        from tqdm import tqdm

        try:
            return [future.result() for future in tqdm(self.pending, desc="recordings and videos", unit="run", disable=not show_progress)]
        finally:
            self.pool.shutdown(cancel_futures=True)
