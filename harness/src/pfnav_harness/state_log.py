"""Optional LCM log of the simulated robot state, replayable with `lcm-logplayer`.

The message type lives in `lcm/robot_state_t.lcm` (package `pfnav_sim`, harness-only: the wire
contract in lcm_types/ has no robot-state message). Its Python code is generated with lcm-gen at
first use into a cache folder, never written by hand and never committed.
"""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import HarnessError

CHANNEL = "PFNAV_SIM_ROBOT_STATE"
LCM_FILE = Path(__file__).resolve().parent / "lcm" / "robot_state_t.lcm"


def _lcm_gen() -> str:
    beside_python = Path(sys.executable).parent / "lcm-gen"
    if beside_python.is_file():
        return str(beside_python)
    found = shutil.which("lcm-gen")
    if found is None:
        raise HarnessError("lcm-gen not found (it ships with the `lcm` wheel in .venv/bin)")
    return found


def robot_state_type(cache_dir: Path) -> Any:
    """The generated `pfnav_sim.robot_state_t` class (generated into `cache_dir/lcm_python`)."""
    out = cache_dir / "lcm_python"
    if not (out / "pfnav_sim" / "robot_state_t.py").is_file():
        out.mkdir(parents=True, exist_ok=True)
        proc = subprocess.run([_lcm_gen(), "--python", "--ppath", str(out), str(LCM_FILE)], capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise HarnessError(f"lcm-gen failed on {LCM_FILE}: {proc.stderr.strip()}")
    if str(out) not in sys.path:
        sys.path.insert(0, str(out))
    return importlib.import_module("pfnav_sim").robot_state_t


def write_state_log(log: dict[str, NDArray[np.float64]], path: Path, cache_dir: Path, period: float = 0.01) -> int:
    """Writes every `period`-th logged step as robot_state_t events; returns the event count."""
    import lcm

    msg_type = robot_state_type(cache_dir)
    t = log["t"]
    if len(t) == 0:
        return 0
    dt = float(t[1] - t[0]) if len(t) > 1 else period
    every = max(1, round(period / dt))
    path.parent.mkdir(parents=True, exist_ok=True)
    events = lcm.EventLog(str(path), "w", overwrite=True)
    count = 0
    try:
        for k in range(0, len(t), every):
            msg = msg_type()
            msg.utime = round(float(t[k]) * 1e6)
            msg.position = log["base_pos"][k].tolist()
            msg.orientation = log["base_quat"][k].tolist()
            msg.linear_velocity = log["base_vel"][k].tolist()
            msg.angular_velocity = log["base_omega"][k].tolist()
            msg.joint_positions = log["q"][k].tolist()
            msg.joint_velocities = log["dq"][k].tolist()
            msg.joint_torques = log["tau"][k].tolist()
            msg.foot_contact = [bool(c) for c in log["contact_actual"][k]]
            msg.fsm_state = int(log["fsm"][k])
            msg.reference = log["ref"][k, 0:7].tolist()
            events.write_event(msg.utime, CHANNEL, msg.encode())
            count += 1
    finally:
        events.close()
    return count
