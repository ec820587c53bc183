"""out/report.md and its PNGs: a table of scenarios × methods and the pictures of every run."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from numpy.typing import NDArray

from .estimation_metrics import EstimationMetrics, estimation_section
from .metrics import OnlineMetrics, RunMetrics
from .robot import JOINT_ROLES, LEG_LABELS
from .scenario import Scenario, Terrain

METHOD_COLOURS = {
    "pf": "tab:red",
    "astar": "tab:blue",
    "astar-admissible": "tab:cyan",
    "dijkstra": "tab:green",
    "pf-feedback": "tab:purple",
    "pf-online": "tab:orange",
}
METHOD_LABELS = {
    "pf": "P-F",
    "astar": "A*",
    "astar-admissible": "A* admissible",
    "dijkstra": "Dijkstra",
    "pf-feedback": "P-F feedback",
    "pf-online": "P-F online",
}


@dataclass
class RunRecord:
    """What the report needs from one run."""

    metrics: RunMetrics
    log: dict[str, NDArray[np.float64]]
    wall_seconds: float
    timing_per_sim_second: dict[str, float]
    stop_reason: str
    log_file: str | None = None
    online: OnlineMetrics | None = None
    # Estimate against truth, for runs with the estimator in the loop (kalman mode).
    estimation: EstimationMetrics | None = None


def _label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def _fmt(value: float | None, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "–"
    return f"{value:.{digits}f}"


def _terrain_axes(terrain: Terrain) -> tuple[Figure, Axes]:
    """A figure of the terrain's heights (colour bar) with its obstacle cells shaded."""
    (x0, y0), (x1, y1) = terrain.bounds()
    fig, ax = plt.subplots(figsize=(7.5, 6.5))
    im = ax.imshow(terrain.heights, origin="lower", extent=(x0, x1, y0, y1), cmap="terrain", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="terrain height [m]", shrink=0.8)
    if terrain.obstacles is not None and terrain.obstacles.any():
        mask = np.ma.masked_where(~terrain.obstacles, np.ones_like(terrain.heights))
        ax.imshow(mask, origin="lower", extent=(x0, x1, y0, y1), cmap="Greys", vmin=0, vmax=1.2, alpha=0.8, interpolation="nearest")
    return fig, ax


def plot_paths(scenario: Scenario, runs: Sequence[RunRecord], path: Path) -> None:
    """Terrain colour map with obstacles, start, goal, and each method's planned and executed path."""
    terrain = scenario.terrain
    fig, ax = _terrain_axes(terrain)
    (x0, y0), (x1, y1) = terrain.bounds()
    for run in runs:
        m = run.metrics
        colour = METHOD_COLOURS.get(m.method, "k")
        ax.plot(run.log["plan_x"], run.log["plan_y"], "--", color=colour, lw=1.5, label=f"{_label(m.method)} planned")
        pos = run.log["base_pos"]
        ax.plot(pos[:, 0], pos[:, 1], "-", color=colour, lw=2.0, alpha=0.85, label=f"{_label(m.method)} executed")
        if m.fell and m.fall_time is not None:
            k = int(np.searchsorted(run.log["t"], m.fall_time))
            k = min(k, len(pos) - 1)
            ax.plot(pos[k, 0], pos[k, 1], "x", color=colour, ms=12, mew=3)
    ax.plot(*scenario.start, "o", color="white", mec="k", ms=9, label="start")
    goal = plt.Circle(scenario.goal.center, scenario.goal.radius, fill=False, color="k", lw=2)
    ax.add_patch(goal)
    ax.plot(*scenario.goal.center, "*", color="gold", mec="k", ms=14, label="goal")
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{scenario.name}: planned (dashed) and executed (solid) paths")
    ax.legend(loc="best", fontsize=8, framealpha=0.85)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_tracking_error(scenario: Scenario, runs: Sequence[RunRecord], path: Path) -> None:
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for run in runs:
        m = run.metrics
        colour = METHOD_COLOURS.get(m.method, "k")
        t = run.log["t"]
        pos = run.log["base_pos"]
        ref = run.log["ref"]
        err = np.hypot(pos[:, 0] - ref[:, 0], pos[:, 1] - ref[:, 1])
        axes[0].plot(t, err, color=colour, label=f"{_label(m.method)} (RMS {m.rms_error:.3f} m)")
        height = pos[:, 2] - scenario.terrain.height(pos[:, 0], pos[:, 1])
        axes[1].plot(t, height, color=colour, label=_label(m.method))
        axes[0].axvline(m.walk_start, color="grey", ls=":", lw=1)
    axes[0].axhline(0.15, color="k", ls="--", lw=0.8, label="0.15 m")
    axes[0].set_ylabel("horizontal error [m]")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"{scenario.name}: tracking error (dotted line: walking starts)")
    axes[1].set_ylabel("base height above ground [m]")
    axes[1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_torques(run: RunRecord, path: Path) -> None:
    t = run.log["t"]
    tau = run.log["tau"]
    fig, axes = plt.subplots(4, 1, figsize=(8, 7.5), sharex=True)
    for leg in range(4):
        for j, role in enumerate(JOINT_ROLES):
            axes[leg].plot(t, tau[:, 3 * leg + j], lw=0.6, label=role)
        axes[leg].set_ylabel(f"{LEG_LABELS[leg]} [N·m]")
    axes[0].legend(fontsize=8, ncol=3, loc="upper right")
    axes[0].set_title(f"{run.metrics.scenario} / {_label(run.metrics.method)}: joint torques (∫τ²dt = {run.metrics.effort:.0f} N²m²s)")
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_contacts(run: RunRecord, path: Path, window: float = 3.0) -> None:
    """Actual (DART) and scheduled (controller) foot contacts over a window after walking starts."""
    t = run.log["t"]
    start = run.metrics.walk_start + 2.0
    if t[-1] < start + window:
        start = max(t[0], t[-1] - window)
    sel = (t >= start) & (t <= start + window)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    actual = run.log["contact_actual"][sel]
    sched = run.log["contact_scheduled"][sel]
    ts = t[sel]
    for leg in range(4):
        base = 3 - leg
        ax.fill_between(ts, base + 0.05, base + 0.05 + 0.4 * sched[:, leg], step="post", color="tab:orange", alpha=0.6, label="scheduled" if leg == 0 else None)
        ax.fill_between(
            ts, base + 0.5, base + 0.5 + 0.4 * actual[:, leg], step="post", color="tab:green", alpha=0.8, label="touching (DART)" if leg == 0 else None
        )
    ax.set_yticks([3.5, 2.5, 1.5, 0.5])
    ax.set_yticklabels(LEG_LABELS)
    ax.set_xlabel("t [s]")
    ax.set_title(f"{run.metrics.scenario} / {_label(run.metrics.method)}: foot contacts")
    ax.legend(fontsize=8, loc="upper right", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_report(
    out_dir: Path,
    scenarios: dict[str, Scenario],
    runs: dict[str, list[RunRecord]],
    header_lines: Sequence[str] = (),
    footer_lines: Sequence[str] = (),
) -> Path:
    """Writes the PNGs and `report.md` into `out_dir`; returns the report path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = ["# pfnav co-simulation report", ""]
    lines.extend(header_lines)
    lines.append("")
    lines.append(
        "| scenario | method | goal reached | fell | RMS err [m] | max err [m] | RMS heading err [°] | "
        "final dist [m] | time to goal [s] | ∫τ²dt [N²m²s] | ∫p ds executed | ∫p ds planned | planner ∫p ds | "
        "length exec/plan [m] | wall/sim |"
    )
    lines.append("|" + "---|" * 15)
    for name, records in runs.items():
        for rec in records:
            m = rec.metrics
            fell = f"yes (t={m.fall_time:.1f} s)" if m.fell and m.fall_time is not None else "no"
            wall_per_sim = rec.timing_per_sim_second.get("total", float("nan"))
            lines.append(
                f"| {name} | {_label(m.method)} | {'yes' if m.goal_reached else 'no'} | {fell} | {_fmt(m.rms_error)} | "
                f"{_fmt(m.max_error)} | {_fmt(m.rms_heading_error_deg, 1)} | {_fmt(m.final_distance_to_goal, 2)} | "
                f"{_fmt(m.time_to_goal, 1)} | {_fmt(m.effort, 0)} | {_fmt(m.executed_cost, 2)} | {_fmt(m.planned_cost, 2)} | "
                f"{_fmt(m.planner_cost, 2)} | {_fmt(m.executed_length, 1)}/{_fmt(m.planned_length, 1)} | {_fmt(wall_per_sim, 3)} |"
            )
    lines.append("")
    lines.append(
        "Errors are measured while walking (after the stand phase), horizontally between the base and the "
        "time-indexed reference. A fall is a base lower than the threshold above the ground or roll/pitch "
        "beyond the threshold relative to the local terrain slope. ∫p ds uses the scenario's traversability "
        "weights on the same map for executed and planned paths; 'planner ∫p ds' is the planner's own figure."
    )
    lines.append("")
    for name, records in runs.items():
        scenario = scenarios[name]
        lines.append(f"## {name}")
        lines.append("")
        paths_png = f"{name}_paths.png"
        error_png = f"{name}_tracking.png"
        plot_paths(scenario, records, out_dir / paths_png)
        plot_tracking_error(scenario, records, out_dir / error_png)
        lines.append(f"![{name} paths]({paths_png})")
        lines.append("")
        lines.append(f"![{name} tracking error]({error_png})")
        lines.append("")
        for rec in records:
            m = rec.metrics
            torque_png = f"{name}_{m.method}_torques.png"
            contact_png = f"{name}_{m.method}_contacts.png"
            plot_torques(rec, out_dir / torque_png)
            plot_contacts(rec, out_dir / contact_png)
            timing = rec.timing_per_sim_second
            lines.append(
                f"**{_label(m.method)}**: {rec.stop_reason}; simulated {m.duration:.1f} s in {rec.wall_seconds:.1f} s wall "
                f"(per simulated second: physics {_fmt(timing.get('physics'))} s, FMU {_fmt(timing.get('fmu'))} s, "
                f"Python {_fmt(timing.get('overhead'))} s)"
                + (f"; fall: {m.fall_reason}" if m.fell else "")
                + (f"; log `{rec.log_file}`" if rec.log_file else "")
            )
            lines.append("")
            lines.append(f"![{name} {m.method} torques]({torque_png}) ![{name} {m.method} contacts]({contact_png})")
            lines.append("")
    online_lines = online_section(scenarios, runs, out_dir)
    lines.extend(online_lines)
    lines.extend(estimation_section(runs, out_dir))
    lines.extend(footer_lines)
    report = out_dir / "report.md"
    report.write_text("\n".join(lines) + "\n")
    return report


def plot_replans(scenario: Scenario, run: RunRecord, path: Path) -> None:
    """The walked path over the terrain, each replan's path overlaid (early light, late dark), unseen cells hatched."""
    terrain = scenario.terrain
    log = run.log
    fig, ax = _terrain_axes(terrain)
    (x0, y0), (x1, y1) = terrain.bounds()
    if "known_final" in log:
        unseen = np.ma.masked_where(np.asarray(log["known_final"], dtype=bool), np.ones_like(terrain.heights))
        ax.imshow(unseen, origin="lower", extent=(x0, x1, y0, y1), cmap="Greys", vmin=0, vmax=3, alpha=0.35, interpolation="nearest")
    lengths = np.asarray(log.get("replan_path_lengths", np.zeros(0, dtype=np.int64)), dtype=np.int64)
    in_use = np.asarray(log.get("replan_in_use", np.zeros(len(lengths), dtype=bool)), dtype=bool)
    xs, ys = np.asarray(log.get("replan_path_x", np.zeros(0))), np.asarray(log.get("replan_path_y", np.zeros(0)))
    offsets = np.concatenate([[0], np.cumsum(lengths)])
    cmap = plt.get_cmap("Oranges")
    used = np.nonzero(in_use & (lengths > 1))[0]
    for rank, i in enumerate(used):
        shade = cmap(0.3 + 0.7 * rank / max(len(used) - 1, 1))
        ax.plot(xs[offsets[i] : offsets[i + 1]], ys[offsets[i] : offsets[i + 1]], "-", color=shade, lw=1.0, label="replanned paths" if rank == 0 else None)
    pos = log["base_pos"]
    ax.plot(pos[:, 0], pos[:, 1], "-", color="tab:red", lw=2.0, label="walked")
    if "push_force" in log:
        pushed = np.nonzero(np.any(log["push_force"] != 0.0, axis=1))[0]
        if len(pushed):
            ax.plot(pos[pushed, 0], pos[pushed, 1], "o", color="magenta", ms=3, label="pushed")
    ax.plot(*scenario.start, "k^", ms=9, label="start")
    ax.add_patch(plt.Circle(scenario.goal.center, scenario.goal.radius, fill=False, color="k", lw=1.5))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{scenario.name} / {_label(run.metrics.method)}: walked path and replans")
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _map_honesty(o: OnlineMetrics) -> str:
    """Share of a sensed map's cells within 2σ of the truth ('–' for the ideal sensor)."""
    if o.map_within_2sigma is None:
        return "–"
    return f"{o.map_within_2sigma * 100:.0f} % of {o.map_cells}"


def online_section(scenarios: dict[str, Scenario], runs: dict[str, list[RunRecord]], out_dir: Path) -> list[str]:
    """The report's online-navigation table and replan plots (empty when no run was online)."""
    online_runs = [(name, rec) for name, records in runs.items() for rec in records if rec.online is not None]
    if not online_runs:
        return []
    lines = [
        "## Online navigation",
        "",
        "The robot starts with the scenario's prior map (or nothing), a height sensor reveals the true terrain around it, "
        "the belief map goes to the planner service over LCM at every update and the service replans from the robot's "
        "current pose; the robot follows the newest feedback field. Latency: map published → reply sent by the service "
        "(wall clock); the simulation puts each answer in use after the stated budget of simulated time.",
        "",
        "| scenario | run | goal | fell | updates [Hz] | replans used | latency p50 / p99 / max [ms] | budget [ms] | ∫p ds walked | "
        "full-knowledge ∫p ds | ratio | max deviation [m] | pushes | known at end | map heights within 2σ | rejected updates |",
        "|" + "---|" * 16,
    ]
    for name, rec in online_runs:
        o = rec.online
        assert o is not None
        m = rec.metrics

        def ms(v: float | None) -> str:
            return "–" if v is None else f"{v * 1000:.0f}"

        lines.append(
            f"| {name} | {_label(m.method)} | {'yes' if m.goal_reached else 'no'} | {'yes' if m.fell else 'no'} | "
            f"{o.map_updates} ({o.update_rate:.1f}) | {o.replans_in_use} | {ms(o.latency_p50)} / {ms(o.latency_p99)} / {ms(o.latency_max)} | "
            f"{o.latency_budget * 1000:.0f} | {_fmt(o.executed_cost, 2)} | {_fmt(o.full_knowledge_cost, 2)} | {_fmt(o.cost_ratio, 2)} | "
            f"{_fmt(o.max_deviation, 2)} | {o.pushes} | {o.known_fraction * 100:.0f} % | {_map_honesty(o)} | {'; '.join(o.rejected) or '–'} |"
        )
    lines.append("")
    for name, rec in online_runs:
        png = f"{name}_{rec.metrics.method}_replans.png"
        plot_replans(scenarios[name], rec, out_dir / png)
        lines.append(f"![{name} replans]({png})")
        lines.append("")
    return lines
