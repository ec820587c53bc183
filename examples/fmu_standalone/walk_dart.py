"""The controller FMU driving a simulated robot, with no harness: fmpy + dartpy + numpy (+ matplotlib).

The plant is the robot the FMU carries (its `resources/robot/`: the robot config, the URDF and its
meshes; `bundle-fmu --robot CONFIG` makes the FMU of another robot) on flat ground, simulated by
DART at 1 kHz: joints, feet, base link and the crouch it starts from are read from that config. Each
millisecond the script writes the measured state into the FMU's inputs, calls fmi2DoStep(1 ms),
and applies the FMU's joint torques to the DART body. The robot starts crouched on the ground;
the mode request is Stand for `--stand` seconds (the FSM goes Passive → StandUp → Stand), then
Locomotion with a forward reference velocity `--vx` for `--walk` seconds (trot).

    .venv/bin/python examples/fmu_standalone/walk_dart.py                      # 1.5 s stand + 3 s trot
    .venv/bin/python examples/fmu_standalone/walk_dart.py --vx 0 --plot out.png  # trot in place
    .venv/bin/python examples/fmu_standalone/walk_dart.py --fmu Go1.fmu             # another robot's FMU

Prints a table (time, FSM state, trunk height, torque norm, x, trot steps so far) and saves a plot of trunk height and
FSM state; `--csv` writes every millisecond. Exits with status 1 if the trunk falls (lower than
`--min-height`) or the controller drops to Damping.

DART notes (dartpy 6.20): ODE is the collision detector (FCL lets spheres sink into the ground);
DART orders the DOFs alphabetically by joint name, so joints are mapped by name; URDF joint limits
are enforced only after `setLimitEnforcement(True)`; the free joint's velocities are in the world
frame, as the FMU expects; the generalized forces are cleared by every `world.step()`, so the
torques are written before each step.
"""

from __future__ import annotations

import argparse
import csv
import sys
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import dartpy as dart
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from numpy.typing import NDArray

REPO = Path(__file__).resolve().parents[2]
LEGS = ("FR", "FL", "RR", "RL")  # the controller's leg order
DT = 0.001  # physics step = FMU communication step
FRICTION = 0.8
TROT_PAIRS = ("1001", "0110")  # stance legs FR FL RR RL of the two trot phases (diagonal pairs)


@dataclass(frozen=True)
class Robot:
    """What this script needs of the robot config in the FMU's resources (format: robot/README.md)."""

    urdf: Path
    base_link: str
    joints: tuple[str, ...]  # FMU joint i (1-based) = 3·leg + {abduction, hip, knee} + 1
    feet: tuple[str, ...]
    foot_radius: float
    crouch: NDArray[np.float64]  # the pose the stand-up starts from


def robot_of_fmu(unzipped: Path) -> Robot:
    folder = unzipped / "resources" / "robot"
    config = tomllib.loads((folder / "robot.toml").read_text())
    legs = [config["legs"][leg] for leg in LEGS]
    if any("crouch" not in leg for leg in legs):
        raise SystemExit(f"{folder / 'robot.toml'}: every leg needs a `crouch` (the pose the robot is set down in)")
    feet = tuple(leg["foot_link"] for leg in legs)
    radius = config.get("foot_radius")
    if radius is None:  # the foot link's sphere collision
        links = {link.get("name"): link for link in ET.parse(folder / "robot.urdf").getroot().findall("link")}
        spheres = links[feet[0]].findall("collision/geometry/sphere")
        radius = float(spheres[0].get("radius", "nan")) if spheres else float("nan")
    return Robot(
        urdf=folder / config["urdf"],
        base_link=config["base_link"],
        joints=tuple(joint for leg in legs for joint in leg["joints"]),
        feet=feet,
        foot_radius=float(radius),
        crouch=np.array([q for leg in legs for q in leg["crouch"]], dtype=np.float64),
    )


def build_world(spec: Robot) -> tuple[Any, Any, Any, NDArray[np.intp]]:
    """A DART world with a flat ground (top face z = 0) and the robot; returns world, robot, base, joint DOF indices."""
    world = dart.simulation.World()
    world.setTimeStep(DT)
    world.setGravity(np.array([0.0, 0.0, -9.81]))
    world.setCollisionDetector(dart.collision.OdeCollisionDetector())

    ground = dart.dynamics.Skeleton("ground")
    joint, body = ground.createWeldJointAndBodyNodePair()
    offset = dart.math.Isometry3()
    offset.set_translation(np.array([0.0, 0.0, -0.05]))
    joint.setTransformFromParentBodyNode(offset)
    box = body.createShapeNode(dart.dynamics.BoxShape(np.array([40.0, 40.0, 0.1])))
    box.createCollisionAspect()
    box.createDynamicsAspect().setFrictionCoeff(FRICTION)
    world.addSkeleton(ground)

    robot = dart.utils.DartLoader().parseSkeleton(dart.common.Uri(spec.urdf.resolve().as_uri()))
    if robot is None:
        raise SystemExit(f"DART could not load {spec.urdf}")
    for i in range(robot.getNumBodyNodes()):
        for node in robot.getBodyNode(i).getShapeNodes():
            if node.getCollisionAspect() is not None:
                aspect = node.getDynamicsAspect() or node.createDynamicsAspect()
                aspect.setFrictionCoeff(FRICTION)
    dofs = np.array([robot.getJoint(name).getIndexInSkeleton(0) for name in spec.joints], dtype=np.intp)
    for name in spec.joints:
        robot.getJoint(name).setLimitEnforcement(True)
    world.addSkeleton(robot)
    return world, robot, robot.getBodyNode(spec.base_link), dofs


def place_crouched(robot: Any, dofs: NDArray[np.intp], spec: Robot) -> None:
    """Level trunk, crouched joints, lowest foot 2 mm above the ground."""
    q = np.zeros(robot.getNumDofs())
    q[5] = 1.0
    q[dofs] = spec.crouch
    robot.setPositions(q)
    lowest = min(robot.getBodyNode(foot).getWorldTransform().translation()[2] for foot in spec.feet)
    q[5] -= lowest - spec.foot_radius - 0.002
    robot.setPositions(q)
    robot.setVelocities(np.zeros(robot.getNumDofs()))


def measured_state(robot: Any, base: Any, dofs: NDArray[np.intp]) -> list[float]:
    """The FMU's state inputs: base position, quaternion (w, x, y, z), linear and angular velocity (world), q, dq."""
    q, dq = robot.getPositions(), robot.getVelocities()
    quat = base.getWorldTransform().quaternion()
    sign = -1.0 if quat.w() < 0.0 else 1.0
    return [
        *q[3:6],
        sign * quat.w(),
        sign * quat.x(),
        sign * quat.y(),
        sign * quat.z(),
        *base.getLinearVelocity(),
        *base.getAngularVelocity(),
        *q[dofs],
        *dq[dofs],
    ]


def enumeration(md: Any, type_name: str) -> dict[str, int]:
    """Item name → code of an enumeration type of the modelDescription."""
    types = {t.name: t for t in md.typeDefinitions}
    return {str(item.name): int(item.value) for item in types[type_name].items}


def run(args: argparse.Namespace) -> int:
    md = read_model_description(str(args.fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fsm_codes, mode_codes = enumeration(md, "FsmState"), enumeration(md, "ModeRequest")
    fsm_names = {code: name for name, code in fsm_codes.items()}
    state_vrs = [
        vr[name]
        for name in (
            *(f"base.pos.{c}" for c in "xyz"),
            *(f"base.quat.{c}" for c in "wxyz"),
            *(f"base.vel.{c}" for c in "xyz"),
            *(f"base.omega.{c}" for c in "xyz"),
            *(f"joint.q[{i}]" for i in range(1, 13)),
            *(f"joint.dq[{i}]" for i in range(1, 13)),
        )
    ]
    ref_vrs = [vr["ref.x"], vr["ref.vx"]]  # the rest of the reference keeps its start value 0 (flat ground, yaw 0)
    torque_vrs = [vr[f"joint.tau[{i}]"] for i in range(1, 13)]
    stance_vrs = [vr[f"stance[{k}]"] for k in range(1, 5)]

    unzipped = Path(extract(str(args.fmu)))
    spec = robot_of_fmu(unzipped)
    world, robot, base, dofs = build_world(spec)
    place_crouched(robot, dofs, spec)
    effort = np.array([float(v.max) for v in md.modelVariables if v.name.startswith("joint.tau[")])

    slave = FMU2Slave(
        guid=md.guid,
        unzipDirectory=str(unzipped),
        modelIdentifier=md.coSimulation.modelIdentifier,
        instanceName="controller",
    )
    slave.instantiate(loggingOn=False)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal(state_vrs, measured_state(robot, base, dofs))
    slave.exitInitializationMode()

    steps = round((args.stand + args.walk) / DT)
    log = np.zeros((steps, 5))  # time, fsm state, trunk height, torque norm, x
    stance: list[str] = []  # scheduled stance legs FR FL RR RL as "1001" (FR and RL on the ground)
    forces = np.zeros(robot.getNumDofs())
    print(f"{'t [s]':>6}  {'fsm.state':<10} {'trunk z [m]':>11} {'|tau| [N.m]':>11} {'x [m]':>7}  {'steps':>5}")
    fell = ""
    touchdowns = 0  # trot steps: changes of the scheduled stance to a diagonal pair while walking
    x_walk = 0.0
    for k in range(steps):
        t = k * DT
        state = measured_state(robot, base, dofs)
        walking = t >= args.stand
        if walking:
            x_walk += args.vx * DT
        else:
            x_walk = state[0]
        slave.setReal(state_vrs + ref_vrs, [*state, x_walk, args.vx if walking else 0.0])
        slave.setInteger([vr["cmd.mode"]], [mode_codes["Locomotion" if walking else "Stand"]])
        slave.doStep(t, DT)
        tau = np.clip(slave.getReal(torque_vrs), -effort, effort)
        fsm = slave.getInteger([vr["fsm.state"]])[0]
        stance.append("".join("1" if c else "0" for c in slave.getBoolean(stance_vrs)))
        if walking and k > 0 and stance[-1] != stance[-2] and stance[-1] in TROT_PAIRS:
            touchdowns += 1
        forces[dofs] = tau
        robot.setForces(forces)
        world.step()
        height = float(robot.getPositions()[5])
        log[k] = ((k + 1) * DT, fsm, height, float(np.linalg.norm(tau)), float(robot.getPositions()[3]))
        if k % round(args.print_every / DT) == round(args.print_every / DT) - 1 or k == steps - 1:
            print(f"{t + DT:6.2f}  {fsm_names[fsm]:<10} {height:11.3f} {log[k, 3]:11.2f} {log[k, 4]:7.3f} {touchdowns:5d}")
        if t >= min(args.stand, 1.2) and height < args.min_height and not fell:
            fell = f"trunk at {height:.3f} m (< {args.min_height} m) at t={t + DT:.3f} s"
        if fsm == fsm_codes["Damping"] and not fell:
            fell = f"controller dropped to Damping at t={t + DT:.3f} s"
    slave.terminate()
    slave.freeInstance()

    reached = [name for name, code in fsm_codes.items() if (log[:, 1] == code).any()]
    walked = log[-1, 4] - log[int(args.stand / DT) - 1, 4]
    print(f"FSM states reached: {', '.join(reached)}; walked {walked:.2f} m in {args.walk:.1f} s; {touchdowns} trot steps")
    if args.csv:
        with args.csv.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["time", "fsm_state", "trunk_height", "torque_norm", "x", "stance"])
            writer.writerows([*row, legs] for row, legs in zip(log.tolist(), stance, strict=True))
    if args.plot:
        plot(log, fsm_codes, args.stand, args.plot)
        print(f"plot: {args.plot}")
    if fell:
        print(f"FELL: {fell}", file=sys.stderr)
        return 1
    return 0


def plot(log: NDArray[np.float64], fsm_codes: dict[str, int], stand: float, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    top.plot(log[:, 0], log[:, 2])
    top.set_ylabel("trunk height [m]")
    bottom.step(log[:, 0], log[:, 1], where="post")
    bottom.set_yticks(list(fsm_codes.values()), list(fsm_codes.keys()))
    bottom.set_ylabel("fsm.state")
    bottom.set_xlabel("time [s]")
    for axis in (top, bottom):
        axis.axvline(stand, color="grey", linestyle=":")
        axis.grid(alpha=0.3)
    top.set_title("QuadController.fmu on a DART body: stand, then trot")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", type=Path, default=REPO / "target" / "fmu" / "QuadController.fmu")
    parser.add_argument("--stand", type=float, default=1.5, help="seconds of mode request Stand (stand-up takes 1 s)")
    parser.add_argument("--walk", type=float, default=3.0, help="seconds of mode request Locomotion")
    parser.add_argument("--vx", type=float, default=0.2, help="forward reference velocity while walking [m/s]")
    parser.add_argument("--min-height", type=float, default=0.15, help="trunk height below which the run counts as a fall [m]")
    parser.add_argument("--print-every", type=float, default=0.25, help="table row interval [s]")
    parser.add_argument("--plot", type=Path, default=Path("fmu_standalone.png"), help="PNG of trunk height and FSM state ('' for none)")
    parser.add_argument("--csv", type=Path, default=None, help="write every millisecond (time, fsm_state, trunk_height, torque_norm, x, stance)")
    args = parser.parse_args()
    if str(args.plot) in ("", "."):
        args.plot = None
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
