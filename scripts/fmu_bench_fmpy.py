"""Cost of one FMU step driven from Python through fmpy (FMU2Slave), for the README.

Measures, after the robot has stood up (1.5 s of 1 ms steps), the median wall time of
  * doStep(h = 1 ms) alone (one control tick), and
  * setReal(all 47 Real inputs) + doStep + getReal(12 torques), what a co-simulation master does.

Usage: .venv/bin/python scripts/fmu_bench_fmpy.py [FMU] [--steps N]
(PFNAV_FMU_DIRECT_REFERENCE overrides target/release/fmu-direct-reference.)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import time
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from pfnav_harness.fmu_runner import FmuContract

REPO = Path(__file__).resolve().parents[1]
DT = 0.001


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("fmu", nargs="?", default=str(REPO / "target" / "fmu" / "QuadController.fmu"))
    parser.add_argument("--steps", type=int, default=5000)
    args = parser.parse_args()

    md = read_model_description(args.fmu)
    refs = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=extract(args.fmu),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="bench",
    )
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    # Standing pose from the controller itself (the reference binary built by setup.sh --tests).
    reference = os.environ.get(
        "PFNAV_FMU_DIRECT_REFERENCE", str(REPO / "target" / "release" / "fmu-direct-reference")
    )
    done = subprocess.run([reference], input='{"segments": []}', capture_output=True, text=True, check=True)
    stand = json.loads(done.stdout)["stand_joint_positions"]
    real_inputs = [v for v in md.modelVariables if v.causality == "input" and v.type == "Real"]
    input_vrs = [v.valueReference for v in real_inputs]
    values = [float(v.start) for v in real_inputs]
    values[input_vrs.index(refs["base.pos.z"])] = FmuContract(md, args.fmu).stand_height
    for i, q in enumerate(stand):
        values[input_vrs.index(refs[f"joint.q[{i + 1}]"])] = q
    slave.setReal(input_vrs, values)
    torque_vrs = [refs[f"joint.tau[{i}]"] for i in range(1, 13)]

    t = 0.0
    for _ in range(1500):
        slave.doStep(t, DT)
        t += DT

    step_only = []
    for _ in range(args.steps):
        start = time.perf_counter()
        slave.doStep(t, DT)
        step_only.append(time.perf_counter() - start)
        t += DT
    full = []
    for _ in range(args.steps):
        start = time.perf_counter()
        slave.setReal(input_vrs, values)
        slave.doStep(t, DT)
        slave.getReal(torque_vrs)
        full.append(time.perf_counter() - start)
        t += DT
    (fsm,) = slave.getInteger([refs["fsm.state"]])
    slave.terminate()
    slave.freeInstance()
    print(f"fsm.state at the end: {fsm}")
    print(f"fmpy doStep (1 tick): median {statistics.median(step_only) * 1e6:.1f} us")
    print(
        "fmpy setReal(47) + doStep + getReal(12): "
        f"median {statistics.median(full) * 1e6:.1f} us over {args.steps} steps"
    )


if __name__ == "__main__":
    main()
