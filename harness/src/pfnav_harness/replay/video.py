"""A run as a short MP4: an isometric view of the terrain (like the paper's Fig. 3) with the plan, the
walked trail and the robot drawn as its trunk and leg chains, rendered headless (matplotlib's Agg
canvas, frames piped to ffmpeg).

The terrain is drawn once; every frame restores that picture and draws only the robot, its trail
and the clock on it (blitting), so a run of 40 simulated seconds renders in a few seconds of CPU.
The run plays sped up so that the video lasts at most `MAX_SECONDS`.
"""

from __future__ import annotations

import math
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LightSource
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d.art3d import Line3D
from tqdm import tqdm

from ..errors import MissingArtifactError, SimulationError
from ..robot import RobotDescription
from ..scenario import Scenario
from .kinematics import LegKinematics
from .run_log import RunLog, frame_steps

FPS = 15
MAX_SECONDS = 10.0
# Size of the picture, pixels (even: H.264 in 4:2:0 needs even sides).
WIDTH, HEIGHT = 720, 540
# The terrain surface is drawn with at most this many cells along a side (a coarser mesh, same shape).
SURFACE_CELLS = 48
# The paper's isometric view: from above the start corner, looking across the map.
ELEVATION_DEG, AZIMUTH_DEG = 35.0, -60.0
# Lines on the ground float this far above the surface, m.
GROUND_LIFT = 0.05
TRUNK_COLOUR = "black"
LEG_COLOUR = "tab:blue"
TRAIL_COLOUR = "tab:red"
TOUCHING_COLOUR = "limegreen"
SWINGING_COLOUR = "white"
# The clock bar's ends, figure coordinates.
BAR_START, BAR_END = 0.06, 0.62
# The trunk drawn as the outline through the hip joints: FR, FL, RL, RR and back (legs in the controller's order FR, FL, RR, RL).
TRUNK_OUTLINE = (0, 1, 3, 2, 0)


@dataclass(frozen=True)
class VideoSummary:
    path: Path
    frames: int
    width: int
    height: int
    fps: int
    # Simulated seconds per second of video.
    speed: float


def ffmpeg_path() -> str:
    found = shutil.which("ffmpeg")
    if found is None:
        raise MissingArtifactError("ffmpeg is not installed (Debian package `ffmpeg`; scripts/setup.sh installs it)")
    return found


def playback_speed(duration: float) -> float:
    """Simulated seconds per video second: real time when the run fits into `MAX_SECONDS`, else faster."""
    return max(1.0, duration / MAX_SECONDS)


def render_video(log: RunLog, scenario: Scenario, robot: RobotDescription, path: Path, run_name: str, show_progress: bool = False) -> VideoSummary:
    """Renders the run to `path` (MP4, H.264) and summarises it."""
    ffmpeg = ffmpeg_path()
    t = np.asarray(log["t"], dtype=np.float64)
    duration = float(t[-1] - t[0])
    steps = frame_steps(t, FPS / playback_speed(duration))
    # The speed the chosen steps give (a whole number of log steps per frame).
    speed = float(t[steps[1]] - t[steps[0]]) * FPS if len(steps) > 1 else 1.0
    base = np.asarray(log["base_pos"], dtype=np.float64)
    chains = LegKinematics(robot).leg_chains(base[steps], np.asarray(log["base_quat"])[steps], np.asarray(log["q"])[steps])
    touching = np.asarray(log["contact_actual"], dtype=bool)[steps]
    terrain = scenario.terrain

    fig = plt.figure(figsize=(WIDTH / 100, HEIGHT / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    # Drawing order as given (terrain, then lines on it): mplot3d's depth sort would bury the lines in the surface.
    ax = fig.add_axes((0.0, 0.0, 1.0, 0.94), projection="3d", computed_zorder=False)
    ax.set_proj_type("ortho")
    ax.view_init(elev=ELEVATION_DEG, azim=AZIMUTH_DEG)
    stride = max(1, math.ceil(max(terrain.shape) / SURFACE_CELLS))
    vertices = terrain.vertices().reshape(*terrain.shape, 3)[::stride, ::stride]
    heights = vertices[..., 2]
    low, high = float(heights.min()), float(heights.max())
    colours = matplotlib.colormaps["terrain"]((heights - low) / (high - low) if high > low else np.zeros_like(heights))[..., :3]
    if terrain.obstacles is not None:
        colours[terrain.obstacles[::stride, ::stride]] = (0.25, 0.25, 0.25)
    # Hill shading in numpy (matplotlib's own per-polygon shading costs more than the rest of the background).
    shaded = LightSource(azdeg=315, altdeg=45).shade_rgb(colours, heights, vert_exag=1.0 / (stride * terrain.resolution), blend_mode="soft")
    ax.plot_surface(
        vertices[..., 0], vertices[..., 1], heights, facecolors=shaded, linewidth=0, antialiased=False, shade=False, rcount=200, ccount=200, zorder=1
    )
    plan_x, plan_y = np.asarray(log["plan_x"]), np.asarray(log["plan_y"])
    ax.plot(plan_x, plan_y, terrain.height(plan_x, plan_y) + GROUND_LIFT, "--", color="white", lw=1.5, zorder=2)
    angle = np.linspace(0.0, 2.0 * math.pi, 48)
    gx = scenario.goal.center[0] + scenario.goal.radius * np.cos(angle)
    gy = scenario.goal.center[1] + scenario.goal.radius * np.sin(angle)
    ax.plot(gx, gy, terrain.height(gx, gy) + GROUND_LIFT, color="gold", lw=2.0, zorder=2)
    (x0, y0), (x1, y1) = terrain.bounds()
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_zlim(low, high if high > low else low + 1.0)
    # zoom: the map fills the picture (an axis-free ortho view leaves wide margins otherwise).
    ax.set_box_aspect((x1 - x0, y1 - y0, max(0.15 * max(x1 - x0, y1 - y0), high - low)), zoom=1.15)
    ax.set_axis_off()
    fig.text(0.01, 0.975, f"{run_name}: planned (dashed), walked (red), feet green on the ground", fontsize=10, va="center")
    # The clock as a bar under the title, its ends labelled once (text drawn in every frame would cost more than the robot).
    fig.text(0.01, 0.94, f"{t[0]:.0f} s", fontsize=9, va="center")
    fig.text(0.99, 0.94, f"{t[-1]:.1f} s, played at {speed:.1f}× speed", fontsize=9, va="center", ha="right")
    fig.add_artist(Line2D([BAR_START, BAR_END], [0.94, 0.94], color="0.85", lw=4))
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)

    # The walked trail on the ground like the plan (at the trunk's height it would sit beside the plan in this view).
    trail_ground = np.stack([base[:, 0], base[:, 1], terrain.height(base[:, 0], base[:, 1]) + GROUND_LIFT], axis=1)
    # The moving parts: drawn over the background in every frame.
    # One artist per kind (legs apart by NaN breaks): each artist drawn costs more than its points.
    trail = Line3D([], [], [], color=TRAIL_COLOUR, lw=2.0)
    trunk = Line3D([], [], [], color=TRUNK_COLOUR, lw=3.0)
    legs = Line3D([], [], [], color=LEG_COLOUR, lw=2.0)
    feet_down = Line3D([], [], [], marker="o", ms=4, mec="black", mfc=TOUCHING_COLOUR, lw=0)
    feet_up = Line3D([], [], [], marker="o", ms=4, mec="black", mfc=SWINGING_COLOUR, lw=0)
    moving = (trail, trunk, legs, feet_down, feet_up)
    for artist in moving:
        ax.add_line(artist)
        artist.set_animated(True)
    clock = Line2D([BAR_START, BAR_START], [0.94, 0.94], color="tab:red", lw=4, animated=True)
    fig.add_artist(clock)
    # Legs as one polyline: each chain, then a NaN point that breaks the line.
    legs_points = np.concatenate([chains, np.full((*chains.shape[:2], 1, 3), np.nan)], axis=2).reshape(len(steps), -1, 3)

    path.parent.mkdir(parents=True, exist_ok=True)
    command = [ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgba", "-s", f"{WIDTH}x{HEIGHT}", "-r", str(FPS), "-i", "-"]
    # H.264 in 4:2:0 with the index up front: what browsers play; ultrafast keeps encoding cheap (the files stay small).
    command += ["-c:v", "libx264", "-preset", "ultrafast", "-crf", "28", "-pix_fmt", "yuv420p", "-movflags", "+faststart", str(path)]
    encoder = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
    assert encoder.stdin is not None
    try:
        for frame in tqdm(range(len(steps)), desc=f"video {run_name}", unit="frame", disable=not show_progress):
            k = steps[frame]
            canvas.restore_region(background)
            trail.set_data_3d(trail_ground[: k + 1 : 10, 0], trail_ground[: k + 1 : 10, 1], trail_ground[: k + 1 : 10, 2])
            outline = chains[frame, TRUNK_OUTLINE, 0]
            trunk.set_data_3d(outline[:, 0], outline[:, 1], outline[:, 2])
            legs.set_data_3d(legs_points[frame, :, 0], legs_points[frame, :, 1], legs_points[frame, :, 2])
            down, up = chains[frame, touching[frame], -1], chains[frame, ~touching[frame], -1]
            feet_down.set_data_3d(down[:, 0], down[:, 1], down[:, 2])
            feet_up.set_data_3d(up[:, 0], up[:, 1], up[:, 2])
            clock.set_xdata([BAR_START, BAR_START + (BAR_END - BAR_START) * (t[k] - t[0]) / max(duration, 1e-9)])
            for artist in moving:
                ax.draw_artist(artist)
            fig.draw_artist(clock)
            encoder.stdin.write(canvas.buffer_rgba())
        encoder.stdin.close()
        errors = encoder.stderr.read().decode(errors="replace") if encoder.stderr is not None else ""
        if encoder.wait() != 0:
            raise SimulationError(f"ffmpeg could not encode {path}: {errors.strip()}")
    finally:
        if encoder.poll() is None:
            encoder.kill()
            encoder.wait()
        plt.close(fig)
    return VideoSummary(path, len(steps), WIDTH, HEIGHT, FPS, speed)
