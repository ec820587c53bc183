"""The sweep report: fall rates with 95 % Wilson intervals (overall, per factor level) and plots, as markdown + PNG."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow as pa

from ..engine import DEFAULT_ENGINE
from .push_ground import DISTANCE_EDGES, GROUND_CHANGE, SEARCH_RANGE, SEARCH_STEP, distance_rates, ground_by_impulse_lines, push_ground_distances
from .stats import (
    FACTOR_COLUMNS,
    IMPULSE_EDGES,
    NO_FALL_IMPULSE,
    VELOCITY_CHANGE_EDGES,
    FallRate,
    binned_fall_rates,
    factor_breakdown,
    fall_rate,
    falls_up_to,
    float_column,
    outcome_counts,
    push_impulses,
    row_outcomes,
    velocity_changes,
)
from .store import SweepStore

# Fall rate plots the issue asks for, when the factor varies.
PLOTTED_FACTORS = ("push_magnitude", "payload_mass", "friction")


def _percent(value: float) -> str:
    return "–" if math.isnan(value) else f"{100 * value:.1f} %"


def _rate_row(rate: FallRate) -> str:
    return f"| {rate.label} | {rate.runs} | {rate.falls} | {_percent(rate.rate)} | {_percent(rate.low)} – {_percent(rate.high)} | {rate.errors} |"


RATE_HEADER = "| level | trials | falls | fall rate | 95 % Wilson interval | errors |\n| --- | ---: | ---: | ---: | --- | ---: |"


def draw_fall_rates(ax: plt.Axes, rates: list[FallRate], label: str | None = None) -> None:
    """Fall rate per level with its 95 % Wilson interval, each point annotated with its trials."""
    shown = [r for r in rates if r.runs]
    xs = np.array([r.x for r in shown])
    ys = np.array([r.rate for r in shown])
    lower = np.array([r.rate - r.low for r in shown])
    upper = np.array([r.high - r.rate for r in shown])
    ax.errorbar(xs, 100 * ys, yerr=100 * np.vstack([lower, upper]).reshape(2, -1), fmt="o-", capsize=4, label=label)
    for x, y, r in zip(xs, ys, shown, strict=True):
        ax.annotate(f"n={r.runs}", (x, 100 * y), textcoords="offset points", xytext=(4, 6), fontsize=7)
    ax.set_ylabel("fall rate (%), 95 % Wilson interval")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)


def plot_fall_rate(rates: list[FallRate], xlabel: str, path: Path) -> None:
    fig, ax = plt.subplots(figsize=(6, 4))
    draw_fall_rates(ax, rates)
    ax.set_xlabel(xlabel)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def impulse_rates(table: pa.Table) -> list[FallRate]:
    """Fall rate per push-impulse bin (`IMPULSE_EDGES`, N·s)."""
    return binned_fall_rates(push_impulses(table), row_outcomes(table), IMPULSE_EDGES, "N·s")


def velocity_change_rates(table: pa.Table) -> list[FallRate]:
    """Fall rate per bin of impulse over mass (m/s), empty when the rows have no robot mass."""
    changes = velocity_changes(table)
    if not np.isfinite(changes).any():
        return []
    return binned_fall_rates(changes, row_outcomes(table), VELOCITY_CHANGE_EDGES, "m/s")


def plot_tracking_errors(table: pa.Table, path: Path) -> bool:
    """RMS tracking error histograms, one per outcome; False when no run has one."""
    errors = np.asarray(table["rms_tracking_error"].to_pylist(), dtype=np.float64)
    outcomes = row_outcomes(table)
    finite = np.isfinite(errors)
    if not finite.any():
        return False
    fig, ax = plt.subplots(figsize=(6, 4))
    bins = np.linspace(errors[finite].min(), errors[finite].max() + 1e-9, 25)
    for outcome in ("goal", "timeout", "fell"):
        chosen = finite & (outcomes == outcome)
        if chosen.any():
            ax.hist(errors[chosen], bins=bins, alpha=0.6, label=f"{outcome} ({int(chosen.sum())})")
    ax.set_xlabel("RMS horizontal tracking error while walking (m)")
    ax.set_ylabel("runs")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def _fork_note(table: pa.Table) -> str:
    forked = sum(bool(f) and o != "error" for f, o in zip(table["forked"].to_pylist(), table["outcome"].to_pylist(), strict=True))
    if not any(table["forked"].to_pylist()):
        return "Every run stood up by itself (no forks)."
    return (
        f"{forked} of {table.num_rows} runs continued from their group's saved post-stand-up state (fork): "
        "the robot stood up unloaded at the prefix friction, its payload and friction act from the walk's start (docs/sweeps.md)."
    )


def _wall_time_line(table: pa.Table) -> str:
    wall = np.asarray(table["wall_time"].to_pylist(), dtype=np.float64)
    if not len(wall):
        return "No runs stored."
    return f"Wall time per run: median {np.median(wall):.1f} s, total {wall.sum() / 60:.1f} worker-minutes."


def _impulse_line(table: pa.Table) -> str:
    small = falls_up_to(table)
    return f"Runs pushed with at most {NO_FALL_IMPULSE:g} N·s (no push included): {small.falls} fell of {small.runs}."


def plot_ground_by_impulse(distances: np.ndarray, table: pa.Table, path: Path) -> None:
    """Fall rate against the push impulse, one line per class of ground along the push."""
    impulses, outcomes = push_impulses(table), row_outcomes(table)
    near = DISTANCE_EDGES[1]
    classes = {
        f"ground change within {near:g} m": distances <= near,
        f"within {near:g}–{SEARCH_RANGE:g} m": (distances > near) & (distances <= SEARCH_RANGE),
        f"none within {SEARCH_RANGE:g} m": distances > SEARCH_RANGE,
    }
    fig, ax = plt.subplots(figsize=(6, 4))
    for i, (label, chosen) in enumerate(classes.items()):
        if chosen.any():
            # Side by side within each impulse bin, so that the intervals and counts stay readable.
            rates = binned_fall_rates(impulses[chosen], outcomes[chosen], IMPULSE_EDGES, "N·s")
            draw_fall_rates(ax, [dataclasses.replace(r, x=r.x + 1.2 * (i - 1)) for r in rates], label)
    ax.set_xlabel("push impulse (N·s)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _push_ground_section(table: pa.Table, store: SweepStore, out_dir: Path) -> tuple[list[str], list[str]]:
    """Fall rates by the ground the push drives the robot towards, and its plot (nothing when the
    store keeps no courses)."""
    distances = push_ground_distances(table, store)
    if np.isnan(distances).all():
        return [], []
    rates = distance_rates(distances, table)
    plot_ground_by_impulse(distances, table, out_dir / "fall_rate_push_ground.png")
    lines = [
        "### ground along the push (m)",
        "",
        f"Distance along the push, from the plan's pose at its start, to the first ground more than {GROUND_CHANGE:g} m "
        f"higher or lower (a valley side, a wall, a pit; searched to {SEARCH_RANGE:g} m in {SEARCH_STEP:g} m steps, "
        f"'> {SEARCH_RANGE:g} m': none within it). Runs without a push are left out.",
        "",
        RATE_HEADER,
        *(_rate_row(r) for r in rates),
        "",
        "Falls/trials by that distance and the push's impulse:",
        "",
        *ground_by_impulse_lines(distances, table),
        "",
    ]
    return lines, ["![fall rate against the push impulse by the ground along the push](fall_rate_push_ground.png)"]


def write_report(store: SweepStore, out_dir: Path | None = None) -> Path:
    """Writes REPORT.md and its PNG plots into `out_dir` (default: the store folder); returns the markdown path."""
    out_dir = out_dir or store.folder
    out_dir.mkdir(parents=True, exist_ok=True)
    table = store.table()
    stored = store.stored_spec() or {}
    spec = stored.get("spec", {})
    counts = outcome_counts(table)
    overall = fall_rate(row_outcomes(table))
    lines = [
        f"# Robustness sweep: {spec.get('scenario', '?')}",
        "",
        f"Spec hash `{stored.get('hash', '?')}`: {spec.get('runs', '?')} runs ({spec.get('sampling', '?')} sampling, seed {spec.get('seed', '?')}), "
        f"{spec.get('duration', '?')} simulated s each, method {spec.get('method', '?')}, estimator {spec.get('estimator') or '?'}, "
        f"physics engine {spec.get('engine', DEFAULT_ENGINE)}, robot {spec.get('robot', 'ours (or $PFNAV_ROBOT)')}"
        f"{', push magnitudes scaled by its mass over ours' if spec.get('push_scaling') == 'mass' else ''}. Stored rows: {table.num_rows}.",
        "",
        _fork_note(table),
        "",
        "Outcomes: " + ", ".join(f"{name} {count}" for name, count in counts.items()) + ".",
        "A run is a trial unless it ended in an error; 'timeout' = neither fell nor reached the goal within the duration.",
        "",
        _wall_time_line(table),
        "",
        f"**Fall rate {_percent(overall.rate)}** ({overall.falls} of {overall.runs}), 95 % Wilson interval {_percent(overall.low)} – {_percent(overall.high)}.",
        "",
        _impulse_line(table),
        "",
        "| factor | drawn from |",
        "| --- | --- |",
        *(f"| {name} | `{json.dumps(setting, separators=(', ', ': '))}` |" for name, setting in spec.get("factors", {}).items()),
        "",
        "## Fall rate per factor level",
        "",
    ]
    plots: list[str] = []
    by_impulse = impulse_rates(table)
    if len(by_impulse) > 1:
        lines += ["### push impulse (force × duration, N·s)", "", RATE_HEADER, *(_rate_row(r) for r in by_impulse), ""]
        plot_fall_rate(by_impulse, "push impulse (N·s)", out_dir / "fall_rate_push_impulse.png")
        plots.append("![fall rate against the push impulse](fall_rate_push_impulse.png)")
    by_velocity = velocity_change_rates(table)
    if len(by_velocity) > 1:
        lines += ["### push impulse over the robot's mass (m/s)", "", RATE_HEADER, *(_rate_row(r) for r in by_velocity), ""]
    ground_lines, ground_plots = _push_ground_section(table, store, out_dir)
    lines += ground_lines
    plots += ground_plots
    for column in FACTOR_COLUMNS:
        rates = factor_breakdown(table, column)
        if not rates:
            continue
        lines += [f"### {FACTOR_COLUMNS[column]}", "", RATE_HEADER, *(_rate_row(r) for r in rates), ""]
        if column in PLOTTED_FACTORS:
            name = f"fall_rate_{column}.png"
            plot_fall_rate(rates, FACTOR_COLUMNS[column], out_dir / name)
            plots.append(f"![fall rate against {FACTOR_COLUMNS[column]}]({name})")
    if plot_tracking_errors(table, out_dir / "tracking_error.png"):
        plots.append("![RMS tracking error per outcome](tracking_error.png)")
    if plots:
        lines += ["## Plots", "", *(f"{p}\n" for p in plots)]
    failures = [(r, f) for r, f in zip(table["run_id"].to_pylist(), table["failure_reason"].to_pylist(), strict=True) if f]
    if failures:
        lines += ["## Errors", "", *(f"- run {r}: {f}" for r, f in failures[:20])]
        if len(failures) > 20:
            lines.append(f"- … and {len(failures) - 20} more")
        lines.append("")
    path = out_dir / "REPORT.md"
    path.write_text("\n".join(lines))
    return path


def store_label(store: SweepStore) -> str:
    """A store's robot, estimator and engine, for legends and table rows."""
    spec = (store.stored_spec() or {}).get("spec", {})
    robot = Path(spec["robot"]).stem if spec.get("robot") else "ours"
    estimator = spec.get("estimator") or "?"
    return f"{robot}, {estimator}, {spec.get('engine', DEFAULT_ENGINE)}"


def write_comparison(stores: list[SweepStore], out_dir: Path) -> Path:
    """COMPARE.md and compare_push.png in `out_dir`: the fall rate of each store overall, by push
    impulse (N·s) and by impulse over the robot's mass (m/s), so that robots of different mass compare."""
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = [
        "# Robustness sweeps compared: fall rate by push impulse",
        "",
        f"| sweep | store | spec hash | robot mass [kg] | trials | falls | fall rate | 95 % Wilson interval | falls at ≤ {NO_FALL_IMPULSE:g} N·s |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | --- | ---: |",
    ]
    fig, (by_impulse, by_velocity) = plt.subplots(1, 2, figsize=(11, 4))
    sections: list[str] = []
    for store in stores:
        table = store.table()
        label = store_label(store)
        overall = fall_rate(row_outcomes(table))
        small = falls_up_to(table)
        masses = {float(m) for m in float_column(table, "robot_mass") if math.isfinite(m)}
        mass = ", ".join(f"{m:.3f}" for m in sorted(masses)) or "–"
        lines.append(
            f"| {label} | `{store.folder.name}` | `{(store.stored_spec() or {}).get('hash', '?')}` | {mass} | {overall.runs} | {overall.falls} | "
            f"{_percent(overall.rate)} | {_percent(overall.low)} – {_percent(overall.high)} | {small.falls} of {small.runs} |"
        )
        impulses = impulse_rates(table)
        velocities = velocity_change_rates(table)
        sections += [f"## {label}", "", RATE_HEADER, *(_rate_row(r) for r in impulses), ""]
        if velocities:
            sections += [RATE_HEADER, *(_rate_row(r) for r in velocities), ""]
            draw_fall_rates(by_velocity, velocities, label)
        draw_fall_rates(by_impulse, impulses, label)
    by_impulse.set_xlabel("push impulse (N·s)")
    by_velocity.set_xlabel("push impulse over the robot's mass (m/s)")
    for ax in (by_impulse, by_velocity):
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_dir / "compare_push.png", dpi=110)
    plt.close(fig)
    lines += ["", *sections, "![fall rate by push impulse and by impulse over mass](compare_push.png)", ""]
    path = out_dir / "COMPARE.md"
    path.write_text("\n".join(lines))
    return path
