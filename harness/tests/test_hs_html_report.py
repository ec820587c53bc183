"""OUT/report.html: made from report.md with every run's video, and checked in headless Chromium."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest
from headless_browser import HeadlessChromium, chromium_path
from replay_logs import synthetic_log

from pfnav_harness import paths
from pfnav_harness.replay.html_report import write_html_report
from pfnav_harness.replay.run_media import recording_path, video_path
from pfnav_harness.replay.video import HEIGHT, WIDTH, render_video
from pfnav_harness.robot import RobotDescription
from pfnav_harness.scenario import Scenario, load_scenario

SCENARIOS = ("ramp", "step")


def write_demo_output(out: Path, ramp_scenario: Scenario, scenario_writer: Callable[..., Path]) -> dict[str, list[str]]:
    """An output folder like the demo's for two scenarios: report.md with a table and a plot each, one video per run,
    and a recording for the first run only."""
    robot = RobotDescription.load(paths.default_robot_config_path())
    heights = np.where(np.arange(30) < 15, 0.0, 0.1)[None, :].repeat(20, axis=0)
    step = load_scenario(scenario_writer(out / "scenarios", "step", heights, 0.1, start=(0.5, 1.0), goal=(2.5, 1.0)))
    lines = ["# pfnav co-simulation report", "", "| scenario | method | goal reached |", "|---|---|---|"]
    lines += [f"| {name} | P-F | yes |" for name in SCENARIOS]
    for name, scenario in zip(SCENARIOS, (ramp_scenario, step), strict=True):
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot([0, 1], [0, 1])
        fig.savefig(out / f"{name}_paths.png")
        plt.close(fig)
        lines += ["", f"## {name}", "", f"![{name} paths]({name}_paths.png)", "", f"**P-F**: completed; log `logs/{name}_pf.npz`"]
        render_video(synthetic_log(scenario, robot), scenario, robot, video_path(out, f"{name}_pf"), f"{name}_pf")
    recording_path(out, "ramp_pf").parent.mkdir()
    recording_path(out, "ramp_pf").write_bytes(b"stand-in: the page only links it")
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return {name: [f"{name}_pf"] for name in SCENARIOS}


def test_page_holds_the_report_and_every_run(tmp_path: Path, ramp_scenario: Scenario, scenario_writer: Callable[..., Path]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    runs = write_demo_output(out, ramp_scenario, scenario_writer)
    page = write_html_report(out, out / "report.md", runs).read_text()
    assert "<table>" in page and '<img src="ramp_paths.png"' in page
    for name in SCENARIOS:
        # The video right under its scenario's heading.
        heading = page.index(f"<h2>{name}</h2>")
        assert page.index(f'src="videos/{name}_pf.mp4"') > heading
    assert page.count("<video") == len(SCENARIOS)
    assert "rerun recordings/ramp_pf.rrd" in page and "step_pf.rrd" not in page
    # Nothing from the network: every src and href stays inside the output folder.
    assert "http://" not in page and "https://" not in page


@pytest.mark.skipif(chromium_path() is None, reason="Chromium is not installed (Debian package `chromium`; `scripts/setup.sh --tests` installs it)")
def test_page_loads_in_headless_chromium_with_playable_videos(tmp_path: Path, ramp_scenario: Scenario, scenario_writer: Callable[..., Path]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    runs = write_demo_output(out, ramp_scenario, scenario_writer)
    page = write_html_report(out, out / "report.md", runs)
    binary = chromium_path()
    assert binary is not None
    with HeadlessChromium(binary) as browser:
        browser.open(page.as_uri())
        # Wait until every video has its metadata (or has failed): a browser that cannot play them says so here.
        videos = browser.evaluate(
            """Promise.all(Array.from(document.querySelectorAll('video')).map(v =>
                   v.readyState >= 1 || v.error ? v : new Promise(done => {
                       v.addEventListener('loadedmetadata', () => done(v)); v.addEventListener('error', () => done(v)); })))
               .then(vs => vs.map(v => ({src: v.getAttribute('src'), error: v.error && v.error.code,
                                         width: v.videoWidth, height: v.videoHeight, seconds: v.duration})))""",
        )
        images = browser.evaluate("Array.from(document.images).map(i => ({src: i.getAttribute('src'), loaded: i.complete && i.naturalWidth > 0}))")
        screenshot = browser.screenshot(tmp_path / "report.png")
        problems = browser.problems()
    assert problems.all() == []
    assert sorted(v["src"] for v in videos) == [f"videos/{name}_pf.mp4" for name in SCENARIOS]
    for video in videos:
        assert video["error"] is None, video
        assert (video["width"], video["height"]) == (WIDTH, HEIGHT)
        assert video["seconds"] > 1.5
    assert images and all(image["loaded"] for image in images), images
    # The screenshot stays in the test's folder as its artefact.
    assert screenshot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
