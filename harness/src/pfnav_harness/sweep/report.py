"""The sweep report: fall rates with 95 % Wilson intervals (overall, per factor level) and plots, as markdown + PNG."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pyarrow as pa

from ..engine import DEFAULT_ENGINE
from .stats import FACTOR_COLUMNS, FallRate, factor_breakdown, fall_rate, outcome_counts
from .store import SweepStore

# Fall rate plots the issue asks for, when the factor varies.
PLOTTED_FACTORS = ("push_magnitude", "payload_mass", "friction")


def _percent(value: float) -> str:
    return "–" if math.isnan(value) else f"{100 * value:.1f} %"


def _rate_row(rate: FallRate) -> str:
    return f"| {rate.label} | {rate.runs} | {rate.falls} | {_percent(rate.rate)} | {_percent(rate.low)} – {_percent(rate.high)} | {rate.errors} |"


RATE_HEADER = "| level | trials | falls | fall rate | 95 % Wilson interval | errors |\n| --- | ---: | ---: | ---: | --- | ---: |"


def plot_fall_rate(rates: list[FallRate], column: str, path: Path) -> None:
    xs = np.array([r.x for r in rates])
    ys = np.array([r.rate for r in rates])
    lower = np.array([r.rate - r.low if r.runs else 0.0 for r in rates])
    upper = np.array([r.high - r.rate if r.runs else 0.0 for r in rates])
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.errorbar(xs, 100 * ys, yerr=100 * np.vstack([lower, upper]), fmt="o-", capsize=4)
    for x, y, r in zip(xs, ys, rates, strict=True):
        if r.runs:
            ax.annotate(f"n={r.runs}", (x, 100 * y), textcoords="offset points", xytext=(4, 6), fontsize=7)
    ax.set_xlabel(FACTOR_COLUMNS.get(column, column))
    ax.set_ylabel("fall rate (%), 95 % Wilson interval")
    ax.set_ylim(-5, 105)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_tracking_errors(table: pa.Table, path: Path) -> bool:
    """RMS tracking error histograms, one per outcome; False when no run has one."""
    errors = np.asarray(table["rms_tracking_error"].to_pylist(), dtype=np.float64)
    outcomes = np.asarray(table["outcome"].to_pylist(), dtype=object)
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


def write_report(store: SweepStore, out_dir: Path | None = None) -> Path:
    """Writes REPORT.md and its PNG plots into `out_dir` (default: the store folder); returns the markdown path."""
    out_dir = out_dir or store.folder
    out_dir.mkdir(parents=True, exist_ok=True)
    table = store.table()
    stored = store.stored_spec() or {}
    spec = stored.get("spec", {})
    counts = outcome_counts(table)
    overall = fall_rate(np.asarray(table["outcome"].to_pylist(), dtype=object))
    lines = [
        f"# Robustness sweep: {spec.get('scenario', '?')}",
        "",
        f"Spec hash `{stored.get('hash', '?')}`: {spec.get('runs', '?')} runs ({spec.get('sampling', '?')} sampling, seed {spec.get('seed', '?')}), "
        f"{spec.get('duration', '?')} simulated s each, method {spec.get('method', '?')}, estimator {spec.get('estimator') or '?'}, "
        f"physics engine {spec.get('engine', DEFAULT_ENGINE)}. Stored rows: {table.num_rows}.",
        "",
        _fork_note(table),
        "",
        "Outcomes: " + ", ".join(f"{name} {count}" for name, count in counts.items()) + ".",
        "A run is a trial unless it ended in an error; 'timeout' = neither fell nor reached the goal within the duration.",
        "",
        f"**Fall rate {_percent(overall.rate)}** ({overall.falls} of {overall.runs}), 95 % Wilson interval {_percent(overall.low)} – {_percent(overall.high)}.",
        "",
        "| factor | drawn from |",
        "| --- | --- |",
        *(f"| {name} | `{json.dumps(setting, separators=(', ', ': '))}` |" for name, setting in spec.get("factors", {}).items()),
        "",
        "## Fall rate per factor level",
        "",
    ]
    plots: list[str] = []
    for column in FACTOR_COLUMNS:
        rates = factor_breakdown(table, column)
        if not rates:
            continue
        lines += [f"### {FACTOR_COLUMNS[column]}", "", RATE_HEADER, *(_rate_row(r) for r in rates), ""]
        if column in PLOTTED_FACTORS:
            name = f"fall_rate_{column}.png"
            plot_fall_rate(rates, column, out_dir / name)
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
    wall = np.asarray(table["wall_time"].to_pylist(), dtype=np.float64)
    if len(wall):
        lines += [f"Wall time per run: median {np.median(wall):.1f} s, total {wall.sum() / 60:.1f} worker-minutes.", ""]
    path = out_dir / "REPORT.md"
    path.write_text("\n".join(lines))
    return path
