"""`pfnav-demo replay LOG`: a Rerun recording (and optionally a video) of a run from its saved log."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import paths
from ..planner_client import BASES, GENERATORS
from ..robot import RobotDescription
from .run_media import recording_path


def add_replay_command(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    replay = sub.add_parser("replay", help="a Rerun recording (and optionally a video) of a run from its log OUT/logs/SCENARIO_LABEL.npz")
    replay.add_argument("log", type=Path, help="the run's log, as pfnav-demo writes it (OUT/logs/SCENARIO_LABEL.npz)")
    replay.add_argument("--out", type=Path, default=None, help="the recording to write (default: OUT/recordings/SCENARIO_LABEL.rrd beside the log's folder)")
    replay.add_argument(
        "--scenario-file",
        type=Path,
        default=None,
        help="the scenario's or map's JSON sidecar (default: OUT/scenarios/SCENARIO.json, which the demo writes)",
    )
    replay.add_argument(
        "--robot",
        type=Path,
        default=None,
        help="the robot config the run walked (default $PFNAV_ROBOT, else robot/quadruped.toml; the report names it)",
    )
    replay.add_argument(
        "--field",
        type=Path,
        default=None,
        help="the offline P-F plan's feedback field to draw over the terrain (`pf-plan plan --field-out FILE.npz`); "
        "pf-plan then plans the map again for the plan's occupation density",
    )
    replay.add_argument("--basis", choices=BASES, default=None, help="with --field: the P-F basis the run planned with (default: the service's, indicator)")
    replay.add_argument("--generators", choices=GENERATORS, default=None, help="with --field: the RBF generators the run planned with (default: transfer)")
    replay.add_argument("--video", type=Path, default=None, metavar="FILE.mp4", help="also render the run's video (isometric view, MP4) to this file")
    replay.add_argument("--pose-rate", type=float, default=50.0, help="poses per simulated second in the recording (default 50)")


def run_replay(args: argparse.Namespace) -> int:
    from ..feedback_field import FeedbackField
    from ..scenario import load_scenario
    from .density import DensityOptions, plan_density
    from .recording import write_recording
    from .run_log import load_run_log, scenario_of_log, with_logged_traversability

    log_path: Path = args.log
    log = load_run_log(log_path)
    scenario = load_scenario(args.scenario_file) if args.scenario_file is not None else scenario_of_log(log_path)
    scenario = with_logged_traversability(scenario, log)
    robot = RobotDescription.load(args.robot if args.robot is not None else paths.robot_config_path())
    field = FeedbackField.from_npz(args.field) if args.field is not None else None
    density = None
    if field is not None and "replan_t_apply" not in log:
        density = plan_density(paths.pf_plan_path(), scenario, field, DensityOptions(args.basis, args.generators))
    run_name = log_path.stem
    # The demo's layout: OUT/logs/NAME.npz → OUT/recordings/NAME.rrd.
    out = args.out if args.out is not None else recording_path(log_path.absolute().parent.parent, run_name)
    summary = write_recording(log, scenario, robot, out, run_name, field, pose_rate=args.pose_rate, density=density)
    print(
        f"recording: {summary.path} ({summary.bytes / 1e6:.1f} MB, {summary.t_last - summary.t_first:.1f} simulated s, "
        f"{summary.pose_frames} poses); open it with `rerun {summary.path}`",
        file=sys.stderr,
    )
    if args.video is not None:
        from .video import render_video

        video = render_video(log, scenario, robot, args.video, run_name)
        print(f"video: {video.path} ({video.frames} frames, {video.width}x{video.height}, {video.speed:.1f}× speed)", file=sys.stderr)
    return 0
