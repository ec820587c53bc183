"""Soak test of the FMU through fmpy: many doSteps and instantiate/free cycles in one process,
printing the resident set size (VmRSS) so that a leak shows up as growth.

Usage: .venv/bin/python scripts/fmu_soak.py [FMU] [--steps 1000000] [--cycles 500]
(PFNAV_FMU_DIRECT_REFERENCE overrides target/release/fmu-direct-reference, used for the standing pose.)
Each step sets the base height and vertical velocity (a small oscillation keeps the MPC busy),
runs doStep(h = 1 ms, one control tick) and reads the 12 torques.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from pfnav_harness.fmu_runner import FSM_TYPE, FmuContract, enumeration

REPO = Path(__file__).resolve().parents[1]
DT = 0.001


def rss_kib() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS in /proc/self/status")


def initialised(md: object, unzip_dir: str, name: str) -> FMU2Slave:
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fmu", nargs="?", default=str(REPO / "target" / "fmu" / "QuadController.fmu"))
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--cycles", type=int, default=500)
    args = parser.parse_args()
    md = read_model_description(args.fmu)
    refs = {v.name: v.valueReference for v in md.modelVariables}
    unzip_dir = extract(args.fmu)
    slave = initialised(md, unzip_dir, "soak")
    # Standing pose from the controller (reference binary built by setup.sh), so that the robot
    # stands up and every tick runs the MPC stance path.
    reference = os.environ.get("PFNAV_FMU_DIRECT_REFERENCE", str(REPO / "target" / "release" / "fmu-direct-reference"))
    done = subprocess.run([reference], input='{"segments": []}', capture_output=True, text=True, check=True)
    stand = json.loads(done.stdout)["stand_joint_positions"]
    slave.setReal([refs[f"joint.q[{i + 1}]"] for i in range(12)], stand)
    input_vrs = [refs["base.pos.z"], refs["base.vel.z"]]
    stand_height = FmuContract(md, args.fmu).stand_height
    torque_vrs = [refs[f"joint.tau[{i}]"] for i in range(1, 13)]
    report_every = max(args.steps // 10, 1)
    start = time.perf_counter()
    baseline = None
    print("step,rss_kib,elapsed_s", flush=True)
    for k in range(args.steps):
        phase = k * DT * 2.0
        slave.setReal(input_vrs, [stand_height + 0.005 * math.sin(phase), 0.01 * math.cos(phase)])
        slave.doStep(k * DT, DT)
        torques = slave.getReal(torque_vrs)
        if not all(math.isfinite(t) for t in torques):
            raise RuntimeError(f"non-finite torque at step {k}")
        if k == min(10_000, args.steps - 1):
            baseline = rss_kib()
        if (k + 1) % report_every == 0:
            print(f"{k + 1},{rss_kib()},{time.perf_counter() - start:.1f}", flush=True)
    (fsm,) = slave.getInteger([refs["fsm.state"]])
    print(f"fsm.state at the end: {enumeration(md, FSM_TYPE)(fsm).name}")
    after_steps = rss_kib()
    elapsed = time.perf_counter() - start
    slave.terminate()
    slave.fmi2FreeInstance(slave.component)
    before_cycles = rss_kib()
    for _ in range(args.cycles):
        extra = initialised(md, unzip_dir, "cycle")
        extra.doStep(0.0, 0.01)
        extra.terminate()
        extra.fmi2FreeInstance(extra.component)
    after_cycles = rss_kib()
    assert baseline is not None
    print(
        f"summary: {args.steps} doSteps in {elapsed:.1f} s ({elapsed / args.steps * 1e6:.1f} us/step); "
        f"RSS after 10k steps {baseline} KiB, after all steps {after_steps} KiB (growth {after_steps - baseline} KiB); "
        f"{args.cycles} instantiate/free cycles: RSS {before_cycles} -> {after_cycles} KiB"
    )


if __name__ == "__main__":
    main()
