"""Which controller FMU a robot runs on: the default FMU for ours, a cached `bundle-fmu` result for any other.

`bundle-fmu` is replaced by a small script with its command line (it records its calls and copies
the FMU it is given), so the choice, the cache and the error paths are tested without the Rust build.
"""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest

from pfnav_harness import paths
from pfnav_harness.errors import MissingArtifactError, SimulationError
from pfnav_harness.robot import PACKAGE_PATH_ENV, RobotDescription
from pfnav_harness.robot_fmu import fmu_for_robot, is_default_robot, robot_and_fmu

RECORDING_BUNDLER = textwrap.dedent(
    """\
    import json, os, shutil, sys
    args = sys.argv[1:]
    with open(os.environ["BUNDLER_LOG"], "a") as log:
        log.write(json.dumps({"args": args, "packages": os.environ.get("PFNAV_PACKAGE_PATH")}) + "\\n")
    if os.environ.get("BUNDLER_FAILS"):
        print("error: robot config: key `legs.FR.crouch`: not known", file=sys.stderr)
        sys.exit(2)
    shutil.copyfile(args[args.index("--binaries-from") + 1], args[args.index("--out") + 1])
    """
)


@pytest.fixture
def bundler(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A recording `bundle-fmu` and a default FMU file; returns the call log."""
    script = tmp_path / "bundle-fmu"
    script.write_text(f"#!{sys.executable}\n" + RECORDING_BUNDLER)
    script.chmod(0o755)
    default_fmu = tmp_path / "Default.fmu"
    default_fmu.write_bytes(b"the default FMU's bytes")
    log = tmp_path / "bundler.log"
    monkeypatch.setenv("PFNAV_BUNDLE_FMU", str(script))
    monkeypatch.setenv("PFNAV_FMU", str(default_fmu))
    monkeypatch.setenv("BUNDLER_LOG", str(log))
    return log


def other_robot(folder: Path, stand_height: str = "0.27") -> Path:
    """Our robot with another stand height: another robot for the FMU."""
    folder.mkdir(parents=True, exist_ok=True)
    ours = paths.default_robot_config_path()
    (folder / "quadruped.urdf").write_bytes((ours.parent / "quadruped.urdf").read_bytes())
    config = folder / "other.toml"
    config.write_text(ours.read_text().replace("stand_height = 0.28", f"stand_height = {stand_height}"))
    return config


def calls(log: Path) -> list[dict[str, object]]:
    return [json.loads(line) for line in log.read_text().splitlines()] if log.is_file() else []


def test_our_robot_runs_on_the_default_fmu_even_from_a_copy(bundler: Path, tmp_path: Path) -> None:
    ours = RobotDescription.load(paths.default_robot_config_path())
    assert is_default_robot(ours)
    assert fmu_for_robot(ours, tmp_path / "cache") == paths.fmu_path()
    copy = other_robot(tmp_path / "copy", stand_height="0.28")
    assert is_default_robot(RobotDescription.load(copy))
    assert calls(bundler) == []


def test_another_robot_gets_a_bundled_fmu_once(bundler: Path, tmp_path: Path) -> None:
    roots = [tmp_path / "packages"]
    robot = RobotDescription.load(other_robot(tmp_path / "robot"), roots)
    assert not is_default_robot(robot)
    cache = tmp_path / "cache"
    fmu = fmu_for_robot(robot, cache)
    assert fmu.parent == cache and fmu.name.startswith("fmu-") and fmu.suffix == ".fmu"
    assert fmu.read_bytes() == paths.fmu_path().read_bytes()
    (call,) = calls(bundler)
    args = call["args"]
    assert isinstance(args, list)
    assert args[args.index("--robot") + 1] == str(robot.config_path)
    assert args[args.index("--binaries-from") + 1] == str(paths.fmu_path())
    assert call["packages"] == str(roots[0].absolute())
    assert sorted(p.name for p in cache.iterdir()) == [fmu.name], "no partial file is left"
    # Cached: the same robot and default FMU are not bundled again.
    assert fmu_for_robot(robot, cache) == fmu
    assert len(calls(bundler)) == 1
    # Another robot, or a rebuilt default FMU, is another bundle.
    taller = RobotDescription.load(other_robot(tmp_path / "taller", stand_height="0.30"), roots)
    assert fmu_for_robot(taller, cache) != fmu
    paths.fmu_path().write_bytes(b"a rebuilt controller")
    assert fmu_for_robot(robot, cache) != fmu
    assert len(calls(bundler)) == 3


def test_bundling_errors_are_clear(bundler: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    robot = RobotDescription.load(other_robot(tmp_path / "robot"))
    monkeypatch.setenv("BUNDLER_FAILS", "1")
    with pytest.raises(SimulationError, match=r"bundle-fmu failed for the robot config .*other.toml \(exit 2\): error: robot config: key"):
        fmu_for_robot(robot, tmp_path / "cache")
    assert list((tmp_path / "cache").iterdir()) == []
    monkeypatch.setenv("PFNAV_BUNDLE_FMU", str(tmp_path / "no-such-bundle-fmu"))
    with pytest.raises(MissingArtifactError, match=r"other.toml is not ours, so its FMU has to be bundled: bundle-fmu binary .* not found"):
        fmu_for_robot(robot, tmp_path / "cache")


def test_the_robot_comes_from_the_environment_by_default(bundler: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    config = other_robot(tmp_path / "robot")
    monkeypatch.setenv("PFNAV_ROBOT", str(config))
    monkeypatch.delenv(PACKAGE_PATH_ENV, raising=False)
    robot, fmu = robot_and_fmu(None, tmp_path / "cache")
    assert robot.config_path == config and fmu.parent == tmp_path / "cache"
    monkeypatch.delenv("PFNAV_ROBOT")
    robot, fmu = robot_and_fmu(None, tmp_path / "cache")
    assert robot.config_path == paths.default_robot_config_path() and fmu == paths.fmu_path()
