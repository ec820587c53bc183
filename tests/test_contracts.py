"""Each contract between two parts of the stack is declared once (docs/contracts.md). These tests
fail when a copy of a declared value reappears in the code: every contract names its declaration
and the text a copy would have; the scanner itself is checked on planted copies, so no check can
pass vacuously."""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# Code and build files; prose (docs, READMEs, the changelog) may quote values.
CODE_SUFFIXES = (".rs", ".py", ".sh", ".toml", ".lcm", ".txt", ".cfg", ".ini")


@dataclass(frozen=True)
class Contract:
    name: str
    # The files allowed to hold the value: its declaration (and code generated from it at build time).
    declared_in: tuple[str, ...]
    # Regular expressions a copy would match.
    copies: tuple[str, ...]
    # A line a copy would be (checked to be found).
    example: str
    # File suffixes searched (default: every code file).
    suffixes: tuple[str, ...] = CODE_SUFFIXES
    # Files that must run without the harness and so keep their own copy; a test of its own checks
    # that copy against the declaration.
    standalone: tuple[str, ...] = ()

    def found_in(self, path: str, text: str) -> list[str]:
        """`path:line: text` of every copy in `text` (none in the declaration itself)."""
        if path in self.declared_in or path in self.standalone or path == "tests/test_contracts.py" or not path.endswith(self.suffixes):
            return []
        hits = []
        for number, line in enumerate(text.splitlines(), start=1):
            if any(re.search(pattern, line) for pattern in self.copies):
                hits.append(f"{path}:{number}: {line.strip()}")
        return hits


# The FMI user's example: fmpy and dartpy only, no harness.
STANDALONE_EXAMPLE = "examples/fmu_standalone/walk_dart.py"

CONTRACTS = [
    Contract(
        "LCM default URL and channel names",
        declared_in=("lcm_types/channels.toml",),
        copies=(
            r"239\.255\.76\.67",
            r'"PFNAV_"',
            r'"(MAP|PLAN_REQUEST|PLAN_REPLY|FEEDBACK_FIELD|SERVICE_STATUS|SIM_ROBOT_STATE|LOW_STATE|LOW_CMD|NAV_CMD|ROBOT_STATUS|ROBOT_ESTIMATE)"',
            r"\{prefix\}(MAP|PLAN_REQUEST|PLAN_REPLY|FEEDBACK_FIELD|SERVICE_STATUS)\b",
        ),
        example='self.lc.subscribe(self.prefix + "PLAN_REPLY", self._on_reply)',
    ),
    # pfnav-robot (Rust, lcm_types::channels) and pfnav-sim (Python, lcm_channels) read it.
    Contract(
        "the SCHED_FIFO priority of liblcm's receive thread",
        declared_in=("lcm_types/channels.toml",),
        copies=(r"RECEIVE_THREAD_PRIORITY\s*(:\s*\w+\s*)?=\s*\d",),
        example="RECEIVE_THREAD_PRIORITY = 1",
        suffixes=(".rs", ".py"),
    ),
    # The planner writes sidecars with `pf_planner::io::save_scenario` (one serde struct); Python
    # code, tests included, goes through `write_map`.
    Contract(
        "map sidecar writer (Python)",
        declared_in=("harness/src/pfnav_harness/scenario.py",),
        copies=(r"""["']start_yaw["']\s*:""",),
        example='meta = {"name": name, "start": [0.5, 0.5], "start_yaw": 0.0}',
        suffixes=(".py",),
    ),
    Contract(
        "the .npy writer of the planner",
        declared_in=("planner/core/src/io.rs",),
        copies=(r"\\x93NUMPY",),
        example='    bytes.extend_from_slice(b"\\x93NUMPY\\x01\\x00");',
        suffixes=(".rs",),
    ),
    # The harness sends 0 (terrain_map_t: "the planner's default"); only the service knows the value.
    Contract(
        "the traversability of unknown cells",
        declared_in=("planner/service/src/convert.rs",),
        copies=(r"DEFAULT_UNKNOWN_TRAVERSABILITY\s*(:\s*\w+\s*)?=", r"unknown[_-]traversability[^\n]*default\s*=\s*0?\.\d*[1-9]"),
        example='p.add_argument("--unknown-traversability", type=float, default=0.5)',
        suffixes=(".rs", ".py"),
    ),
    # Both are derived: the GUID from the variable table's interface (VariableTable::guid), the
    # saved-state layout id from the state types' source (fmu/build.rs). No hand-kept copy.
    Contract(
        "the FMU's GUID and saved-state layout",
        declared_in=("fmu/src/variables/mod.rs", "fmu/build.rs"),
        copies=(r"\{[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{4}-[0-9a-fA-F]{12}\}", r"FORMAT_VERSION\s*:\s*u\d+\s*="),
        example='pub const GUID: &str = "{320c93d8-147c-4514-a9e7-440d4235dda0}";',
        suffixes=(".rs", ".py"),
    ),
    # Rust code reads HEIGHT_MAP_SIZE / HEIGHT_MAP_CELLS; the FMU publishes one terrain.map.h[i]
    # per cell and the harness counts them (`fmu_runner.FmuContract.height_map_size`).
    Contract(
        "the controller's height-map size",
        declared_in=("controller/src/api.rs",),
        copies=(
            r"HEIGHT_MAP_(SIZE|CELLS)\s*(:\s*\w+\s*)?=\s*\d",
            r"terrain\.map\.h\[[^\]]*\][^\n]*\brange\(\s*(\d+\s*,\s*)?\d+\s*\)",
        ),
        example='terrain |= {f"terrain.map.h[{i + 1}]": rng.uniform(-0.03, 0.03) for i in range(121)}',
        suffixes=(".rs", ".py"),
    ),
    Contract(
        "the default ground friction",
        declared_in=("harness/src/pfnav_harness/engine.py",),
        copies=(r"(?i)friction[^\n]*(?<![\w.])0?\.80*(?![\d])",),
        example="    friction: float = 0.8",
        suffixes=(".py",),
        standalone=(STANDALONE_EXAMPLE,),
    ),
    # `metrics.FallThresholds` holds the thresholds and the look interval; the co-simulation
    # (`fallen`) and the metrics (`judge_fall`) apply them. A fall test with its own numbers
    # (a tilt or height limit, a `k % 10` look) is a second rule.
    Contract(
        "the fall rule",
        declared_in=("harness/src/pfnav_harness/metrics.py",),
        copies=(
            r"(min_base_height|max_roll|max_pitch|every_steps)\s*:\s*\w+\s*=\s*\d",
            r"\.(max_roll|max_pitch|min_base_height)\s*[-+*]",
            r"%\s*10\s*==\s*0[^\n]*fall",
        ),
        example="        return abs(roll) > self.config.fall.max_roll + 0.3",
        suffixes=(".py",),
    ),
    Contract(
        "the default estimator mode",
        declared_in=("harness/src/pfnav_harness/fmu_runner.py",),
        copies=(
            r"""estimator\w*\s*(:\s*str\s*)?=\s*["'](groundTruth|kalman)["']\s*$""",
            r"""estimator\w*\s*:\s*str\s*=\s*["']""",
            r"""\.get\(\s*["']estimator["']\s*,\s*["']""",
            r"""default\s*=\s*["'](groundTruth|kalman)["']""",
        ),
        example='    estimator: str = "groundTruth"',
        suffixes=(".py",),
    ),
    # Rust: the controller's default body height is `tuning::TUNED_STAND_HEIGHT`; our robot's own
    # (robot/quadruped.toml) is data, tied to it by controller/src/tuning.rs's tests. Python reads
    # the FMU's `stand.bodyHeight` start value (`FmuContract.stand_height`).
    Contract(
        "the stand height",
        declared_in=("controller/src/tuning.rs", "robot/quadruped.toml"),
        copies=(
            r"TUNED_STAND_HEIGHT\s*:\s*f64\s*=",
            r"body_height\s*:\s*(f64\s*=\s*)?0\.28\b",
            r"(stand_joint_positions|standing_state|nominal_foot_position|standing_pose_over_feet)\([^)]*\b0\.28\b",
            r"""["'](base\.pos\.z|ref\.bodyHeight|stand\.bodyHeight)["'][^\n]*(?<![\w.])0\.28\b""",
            r"height_above_terrain[^\n]*(?<![\w.])0\.28\b",
        ),
        example='    state = {"base.pos.z": 0.28, "ref.vx": 0.3, "ref.bodyHeight": 0.28}',
        suffixes=(".rs", ".py"),
    ),
]


def tracked_code_files() -> dict[str, str]:
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout.decode()
    files = {}
    for name in filter(None, listed.split("\0")):
        path = REPO / name
        if name.endswith(CODE_SUFFIXES) and path.is_file() and not name.startswith("third_party/"):
            files[name] = path.read_text(encoding="utf-8", errors="replace")
    return files


@pytest.fixture(scope="module")
def code() -> dict[str, str]:
    return tracked_code_files()


@pytest.mark.parametrize("contract", CONTRACTS, ids=lambda c: c.name)
def test_the_contract_is_declared_once(contract: Contract, code: dict[str, str]) -> None:
    for declaration in contract.declared_in:
        assert declaration in code, f"{contract.name}: the declaration {declaration} is not a tracked code file"
    copies = [hit for path, text in code.items() for hit in contract.found_in(path, text)]
    assert not copies, f"{contract.name} is declared in {', '.join(contract.declared_in)}; copies:\n" + "\n".join(copies)


@pytest.mark.parametrize("contract", CONTRACTS, ids=lambda c: c.name)
def test_a_planted_copy_is_found(contract: Contract) -> None:
    """A copy of each contract's value, in another file, is caught; in its declaration it is not."""
    elsewhere = "harness/src/pfnav_harness/elsewhere" + contract.suffixes[0]
    assert contract.found_in(elsewhere, "first line\n" + contract.example), contract.example
    assert not contract.found_in(contract.declared_in[0], contract.example)


def test_the_standalone_example_walks_on_the_default_friction(code: dict[str, str]) -> None:
    from pfnav_harness.world import DEFAULT_FRICTION

    found = re.findall(r"^FRICTION = (\S+)$", code[STANDALONE_EXAMPLE], flags=re.MULTILINE)
    assert found and float(found[0]) == DEFAULT_FRICTION, f"{STANDALONE_EXAMPLE}: FRICTION = {found}, the harness's DEFAULT_FRICTION = {DEFAULT_FRICTION}"


# Prose that quotes the height-map size (docs may quote values; these quotes are checked).
HEIGHT_MAP_PROSE = ("controller/README.md", "fmu/README.md", "docs/estimation.md")


def test_prose_quotes_the_declared_height_map_size() -> None:
    api = (REPO / "controller/src/api.rs").read_text()
    size = int(re.search(r"pub const HEIGHT_MAP_SIZE: usize = (\d+);", api).group(1))  # type: ignore[union-attr]
    quoted = 0
    for name in HEIGHT_MAP_PROSE:
        text = (REPO / name).read_text()
        for a, b in re.findall(r"(\d+) × (\d+)(?= (?:local|samples|elevation))", text):
            assert (int(a), int(b)) == (size, size), f"{name} says {a} × {b}; controller/src/api.rs declares HEIGHT_MAP_SIZE = {size}"
            quoted += 1
        for cells in re.findall(r"terrain\.map\.\{[^}]*h\[1\.\.(\d+)\]", text):
            assert int(cells) == size * size, f"{name} says h[1..{cells}]; HEIGHT_MAP_SIZE² = {size * size}"
            quoted += 1
    assert quoted >= 4, "the READMEs no longer quote the height-map size: update HEIGHT_MAP_PROSE"
