"""The FMI user's example (examples/fmu_standalone/walk_dart.py) runs and walks (issue 21).

The script is run as a user would run it, shortened: 1.2 s of mode request Stand (stand-up takes
1 s), then 1 s of Locomotion at 0.2 m/s. Its per-millisecond CSV must show the FSM going StandUp →
Stand → Locomotion (codes from the FMU's FsmState enumeration) without Damping, the trunk held at
standing height while trotting, the scheduled stance alternating between the diagonal pairs, and
forward progress; the plot must be written.
"""

from __future__ import annotations

import csv
import itertools
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "examples" / "fmu_standalone" / "walk_dart.py"
STAND, WALK, VX = 1.2, 1.0, 0.2


@pytest.fixture(scope="module")
def run(fmu_file: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out = tmp_path_factory.mktemp("fmu_example")
    args = [
        sys.executable,
        str(SCRIPT),
        "--fmu",
        str(fmu_file),
        "--stand",
        str(STAND),
        "--walk",
        str(WALK),
        "--vx",
        str(VX),
        "--csv",
        str(out / "log.csv"),
        "--plot",
        str(out / "plot.png"),
    ]
    done = subprocess.run(args, capture_output=True, text=True, timeout=120, check=False, cwd=out)
    assert done.returncode == 0, done.stdout + done.stderr
    with (out / "log.csv").open() as f:
        rows = list(csv.DictReader(f))
    return {
        "stdout": done.stdout,
        "plot": out / "plot.png",
        "time": np.array([float(r["time"]) for r in rows]),
        "fsm": np.array([round(float(r["fsm_state"])) for r in rows]),
        "height": np.array([float(r["trunk_height"]) for r in rows]),
        "tau": np.array([float(r["torque_norm"]) for r in rows]),
        "x": np.array([float(r["x"]) for r in rows]),
        "stance": [r["stance"] for r in rows],
    }


@pytest.fixture(scope="module")
def fsm_codes(fmu_model_description: Any) -> dict[str, int]:
    types = {t.name: t for t in fmu_model_description.typeDefinitions}
    return {str(item.name): int(item.value) for item in types["FsmState"].items}


def test_example_stands_up_stands_and_trots(run: dict[str, Any], fsm_codes: dict[str, int]) -> None:
    time, fsm = run["time"], run["fsm"]
    assert len(time) == round((STAND + WALK) / 1e-3)
    assert fsm_codes["Damping"] not in fsm
    # StandUp → Stand during the stand request, Locomotion soon after the request changes.
    changes = [int(fsm[0]), *(int(b) for a, b in itertools.pairwise(fsm) if a != b)]
    assert changes == [fsm_codes["StandUp"], fsm_codes["Stand"], fsm_codes["Locomotion"]], changes
    assert time[fsm == fsm_codes["Stand"]].min() < STAND
    assert time[fsm == fsm_codes["Locomotion"]].min() < STAND + 0.05
    assert np.isfinite(run["tau"]).all()
    assert "Locomotion" in run["stdout"] and "trot steps" in run["stdout"]
    assert run["plot"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_example_trot_keeps_the_trunk_up_and_moves_forward(run: dict[str, Any], fsm_codes: dict[str, int]) -> None:
    walking = run["fsm"] == fsm_codes["Locomotion"]
    height = run["height"][walking]
    assert height.min() > 0.25, height.min()
    assert height.max() < 0.31, height.max()
    # Trot: the scheduled stance alternates between the diagonal pairs FR+RL and FL+RR.
    stance = [s for s, w in zip(run["stance"], walking, strict=True) if w]
    phases = [stance[0], *(b for a, b in itertools.pairwise(stance) if a != b)]
    assert set(phases) == {"1001", "0110"}, set(phases)
    assert len(phases) >= 5, phases
    # Forward progress at about the reference speed (0.2 m/s over 1 s).
    advance = float(run["x"][-1] - run["x"][walking][0])
    assert 0.5 * VX * WALK < advance < 1.5 * VX * WALK, advance
