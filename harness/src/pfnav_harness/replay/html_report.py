"""OUT/report.html: the Markdown report (tables, plots) as one page, with every run's video and recording.

The page is made from `report.md` itself (one source for the tables and notes) and refers only to
files inside OUT by relative paths: the PNGs beside it, `videos/NAME.mp4`, `recordings/NAME.rrd`.
It loads nothing from the network; the styles are inline.
"""

from __future__ import annotations

import html
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from markdown_it import MarkdownIt

from ..report import RunRecord
from .run_media import recording_path, video_path

STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1400px; padding: 0 1em; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; margin: 1em 0; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.5em; text-align: right; }
th { background: #f3f3f3; }
td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; }
code { background: #f3f3f3; padding: 0 0.2em; }
.runs { display: flex; flex-wrap: wrap; gap: 1em; }
.run { margin: 0; }
.run video { width: 560px; max-width: 100%; background: #000; }
.run figcaption { font-size: 0.9em; }
"""


@dataclass(frozen=True)
class RunFiles:
    """One run's name (its log's stem, SCENARIO_LABEL) and the files written for it, relative to OUT."""

    name: str
    video: str | None
    recording: str | None


def run_files(out: Path, scenario_runs: Mapping[str, Sequence[str]]) -> dict[str, list[RunFiles]]:
    """The videos and recordings that exist in OUT for each scenario's runs (run names as the logs have them)."""

    def relative(path: Path) -> str | None:
        return path.relative_to(out).as_posix() if path.is_file() else None

    return {
        scenario: [RunFiles(name, relative(video_path(out, name)), relative(recording_path(out, name))) for name in names]
        for scenario, names in scenario_runs.items()
    }


def runs_block(runs: Sequence[RunFiles]) -> str:
    """The HTML of a scenario's videos, each captioned with its run and how to open its recording."""
    figures = []
    for run in runs:
        if run.video is None and run.recording is None:
            continue
        parts = [f'<figure class="run" id="run-{html.escape(run.name)}">']
        if run.video is not None:
            parts.append(f'<video controls muted loop playsinline preload="metadata" src="{html.escape(run.video)}"></video>')
        caption = f"<b>{html.escape(run.name)}</b>"
        if run.recording is not None:
            path = html.escape(run.recording)
            caption += f' · Rerun recording <a href="{path}">{path}</a> (open with <code>rerun {path}</code>)'
        parts.append(f"<figcaption>{caption}</figcaption></figure>")
        figures.append("".join(parts))
    return f'<div class="runs">{"".join(figures)}</div>' if figures else ""


def with_runs(markdown: str, runs: Mapping[str, Sequence[RunFiles]]) -> str:
    """The report's Markdown with each scenario's videos right under its heading (`## SCENARIO`)."""
    lines = []
    for line in markdown.splitlines():
        lines.append(line)
        if line.startswith("## ") and line[3:].strip() in runs:
            block = runs_block(runs[line[3:].strip()])
            if block:
                lines.extend(["", block, ""])
    return "\n".join(lines) + "\n"


def run_names(runs: Mapping[str, Sequence[RunRecord]]) -> dict[str, list[str]]:
    """Each scenario's run names: the stems of their logs (OUT/logs/NAME.npz)."""
    return {scenario: [Path(record.log_file).stem for record in records if record.log_file] for scenario, records in runs.items()}


def write_html_report(out: Path, report_md: Path, scenario_runs: Mapping[str, Sequence[str]]) -> Path:
    """Writes OUT/report.html beside `report_md`; `scenario_runs`: each scenario's run names (log stems)."""
    markdown = report_md.read_text(encoding="utf-8")
    title = next((line[2:].strip() for line in markdown.splitlines() if line.startswith("# ")), "pfnav report")
    body = MarkdownIt("commonmark").enable("table").render(with_runs(markdown, run_files(out, scenario_runs)))
    page = out / "report.html"
    text = (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        # An empty icon: the browser asks for none (a missing favicon would be a console error).
        f'<title>{html.escape(title)}</title>\n<link rel="icon" href="data:,">\n'
        f"<style>{STYLE}</style>\n</head>\n<body>\n{body}</body>\n</html>\n"
    )
    # Written whole, then moved: a browser never sees half a page.
    partial = page.with_name(f".{page.name}.{os.getpid()}")
    partial.write_text(text, encoding="utf-8")
    partial.replace(page)
    return page
