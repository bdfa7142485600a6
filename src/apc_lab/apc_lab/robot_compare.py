"""``robot_compare``: the comparison a ROS user would make, through the robot interface.

The simulated ros2_control robot (:mod:`apc_plant_sim.robot_sim`, engine MuJoCo) and apc's
robot-mode controller (the lifecycle commanding node ``robot_node``, autostarted, which samples
the feedforward's plan itself) run composed in one process with the recorder. The arm holds its
measured position for :data:`HOLD_BEFORE_S`; then the paper's move goes to robot_node as a goal
on ``feedforward/trajectory``, the way a user sends one: the 4-3-4's lift-off, set-down and
end as waypoints with their velocities and accelerations (the feedforward plans quintic segments
through them, and a quintic meeting a quartic's or a cubic's position, velocity and acceleration
at both ends is that polynomial: the plan is the 4-3-4 itself). The run ends
:data:`HOLD_AFTER_S` after the move.

Runs: the 3-joint PUMA 560 and the Franka Panda, cases (a)-(c) and the 5 lb payload picked up
:data:`PICKUP_AFTER_S` into the move, on the ideal arm and then with every effect of a physical
arm on (robot_sim's presets, :data:`PHYSICAL_PRESETS`: friction, rotor inertia where the arm
has it in its drive's torque path, encoder quantisation, the velocity differenced by the drive
from the quantised positions, a command delay of one driver period), for computed torque, the
JTC-style PID, and the adaptive law with the paper's settings and the recommended and physical
presets. Metrics per joint are read back from the recordings
(:func:`apc_recording.runs.load_robot_run`, :mod:`apc_lab.metrics`).

Time. ``sim``: robot_sim owns the clock and steps as fast as the controllers answer, every node
on ``use_sim_time``: reproducible, faster than real time. ``realtime``: the driver on its wall
timer, the controllers at 100 Hz on the wall clock, all in this one process.

    robot_compare [--quick] [--out runs/robot] [--arms puma3,panda] [--realtime]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from builtin_interfaces.msg import Duration
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_core.nodeutil import StopSignals, destroy_nodes, make_executor
from apc_core.params import ConfigError
from apc_core.robot import example_robot_urdf
from apc_feedback.payload_estimate import PayloadEstimateConfig
from apc_feedback.presets import DEFAULT_PRESET, PRESETS
from apc_lab.experiment import (
    Progress,
    law_parameters,
    overrides,
    wait_for,
)
from apc_lab.run_recorder import recorder_node, take_what_is_queued
from apc_lab.scenario import (
    CONFIG_DIR,
    PAPER_CASES,
    Scenario,
    paper_scenario,
    paper_settings,
    recommended_settings,
)
from apc_plant_sim.effects import panda_effects, puma560_effects, single_effect

#: The arm holds its measured position this long before the goal is sent (s, driver time).
HOLD_BEFORE_S = 0.3
#: Recorded after the end of the move (s).
HOLD_AFTER_S = 0.5
#: The pickup case: the payload is picked up this long after the goal is sent (s).
PICKUP_AFTER_S = 0.5
#: The driver's rate (ros2_control's ``update_rate``): a multiple of 1/T, as robot mode needs.
DRIVER_RATE_HZ = 500.0
#: sim time: wall seconds robot_sim waits for a command before it steps without one.
SIM_WAIT_S = 0.5
#: robot_sim's ``command_latency`` (s): a command reaches the driver this long after the state
#: it answers (a DDS hop and the law), so it is applied from the driver's next cycle, as on a
#: robot's clock; in sim time without it a command would act over its own state's cycle.
COMMAND_LATENCY_S = 0.0005

_ESTIMATE = PayloadEstimateConfig()
#: What the report says about these runs, before the tables.
SUMMARY = (
    "The simulated ros2_control robot (robot_sim: joint_state_broadcaster-style `/joint_states` "
    f"at {DRIVER_RATE_HZ:g} Hz, efforts as `Float64MultiArray` on `/effort_controller/commands`; "
    "MuJoCo's dynamics) and the robot-mode controller (lifecycle `robot_node` with the "
    "feedforward's plan inside, T = 10 ms), composed in one process on sim time. The arm holds "
    f"{HOLD_BEFORE_S:g} s, then the paper's move arrives as a goal on `feedforward/trajectory`; "
    "errors are the controllers' samples against their set points, from the move's start. "
    f"Every command reaches the driver {COMMAND_LATENCY_S * 1e3:g} ms after the state it "
    "answers, so it acts from the driver's next cycle, as on a robot's clock. "
    "`physical`: friction, rotor inertia, encoder quantisation, the velocity differenced by the "
    "drive from quantised positions over one driver period and a one-driver-period command "
    "delay, from each arm's data (apc_plant_sim/effects.py); the controllers are told the "
    "rotor inertia (`armature`), as a geared arm's user tells it. The pickup: 5 lb picked up "
    f"{PICKUP_AFTER_S:g} s into the move. Every law runs with the same robot-mode settings, "
    "without the robot files' payload estimate (`payload_estimate.enable`, which only the "
    "adaptive law can take and which needs a still hold of "
    f"{_ESTIMATE.settle_s + _ESTIMATE.window_s:g} s): the laws compared as they are. "
    "Cells: max / final error (deg)."
)
CASES = ("a", "b", "c", "pickup")
#: What the arm adds: nothing, or every effect of a physical arm (its data, :mod:`effects`).
EFFECTS = ("ideal", "physical")
#: Feedback laws by label: (controller, settings).
LAWS: dict[str, tuple[str, dict[str, Any] | None]] = {
    "computed torque": ("computed_torque", None),
    "PID": ("pid", None),
    "adaptive paper": ("adaptive", paper_settings()),
    "adaptive recommended": ("adaptive", recommended_settings()),
}
BASELINES = ("computed torque", "PID")
#: The robot-mode parameter file apc ships for each arm (in ``config/``).
ROBOT_FILES = {"puma3": "puma560_3dof_robot.yaml", "panda": "panda_robot.yaml"}
#: The law of the arm's robot file, run where it differs from the recommended preset.
ROBOT_FILE_LAW = "adaptive robot file"


def robot_file_law(arm: str) -> tuple[str, dict[str, Any]]:
    """``robot_node``'s law in the arm's shipped robot file: its controller and preset with the
    file's ``adaptive.*`` values."""
    params = yaml.safe_load((CONFIG_DIR / ROBOT_FILES[arm]).read_text())
    node = params["robot_node"]["ros__parameters"]
    settings = PRESETS[node.get("preset", DEFAULT_PRESET)]()
    family = "adaptive."
    settings.update({k[len(family) :]: v for k, v in node.items() if k.startswith(family)})
    return node.get("controller", "adaptive"), settings


def law_of(case: RobotCase) -> tuple[str, dict[str, Any] | None]:
    """(controller, settings) of a run's law."""
    return robot_file_law(case.arm) if case.law == ROBOT_FILE_LAW else LAWS[case.law]


@cache
def _panda_urdf() -> str:
    return str(example_robot_urdf("panda_description/urdf/panda.urdf"))


def arm_scenario(arm: str, case: str) -> Scenario:
    """The arm with case ``case``'s payload (the 5 lb of case (c) for the pickup)."""
    payload = PAPER_CASES["c" if case == "pickup" else case]
    if arm == "puma3":
        scenario = paper_scenario("c")
    elif arm == "panda":
        scenario = Scenario(
            urdf=_panda_urdf(),
            lock_joints=("panda_finger_joint1", "panda_finger_joint2"),
            payload_frame="panda_hand",
            inertia_error=(0.1, -0.1, 0.1, -0.1, 0.1, -0.1, 0.1),
            q_start_deg=(0.0, -20.0, 0.0, -120.0, 0.0, 100.0, 45.0),
            q_goal_deg=(60.0, 15.0, 20.0, -80.0, 30.0, 130.0, 0.0),
        )
    else:
        raise ValueError(f"arm must be puma3 or panda, got {arm!r}")
    at_s = HOLD_BEFORE_S + PICKUP_AFTER_S if case == "pickup" else 0.0
    return replace(scenario, payload_kg=payload, payload_at_s=at_s, hold_s=HOLD_AFTER_S)


#: robot_sim's ``effects`` preset of each arm: every effect of a physical arm from its data
#: (:func:`apc_plant_sim.effects.puma560_effects`, :func:`apc_plant_sim.effects.panda_effects`).
PHYSICAL_PRESETS = {"puma3": "puma560", "panda": "panda"}
#: The same data as :data:`PHYSICAL_PRESETS`, as :class:`ArmEffects` (one effect at a time).
ARM_EFFECTS = {"puma3": puma560_effects, "panda": panda_effects}
#: MuJoCo's own dynamics and integrator: an engine no one here wrote.
ENGINE = "mujoco"


def controller_armature(arm: str, effects: str) -> list[float] | None:
    """The rotor inertia the controllers are told (kg m^2 per joint, the controller nodes'
    ``armature``): the physical arm's, as a user configures a geared arm from its drives' data
    (motor inertia times gear ratio squared; a URDF cannot carry it); None for the ideal arm, an
    arm without it (the Panda's preset) and one effect alone (what each unknown effect costs).
    What the controllers still do not know: the payload, quantised encoders, the drive's
    differenced velocity and its delay."""
    if effects != "physical":
        return None
    data = ARM_EFFECTS[arm]()
    values = data.per_joint("armature_kgm2", len(data.counts_per_rev))
    return values.tolist() if values.any() else None


def controller_friction(arm: str, effects: str) -> tuple[list[float], list[float]] | None:
    """The friction the controllers are told, (Coulomb N m, viscous N m s/rad) per joint, the
    controller nodes' ``friction`` and ``damping``: the physical arm's, as a user configures it
    from a friction identification (a URDF's ``<dynamics>`` is not taken), Coulomb as one level
    for both directions, the mean of the two (what ``robot_sim``'s MuJoCo applies); None for the
    ideal arm and one effect alone (what each unknown effect costs)."""
    if effects != "physical":
        return None
    data = ARM_EFFECTS[arm]()
    n = len(data.counts_per_rev)
    coulomb, viscous = data.mean_coulomb(n), data.per_joint("viscous_nm_s", n)
    if not (coulomb.any() or viscous.any()):
        return None
    return coulomb.tolist(), viscous.tolist()


def controller_arm_parameters(arm: str, effects: str) -> dict[str, list[float]]:
    """The controller nodes' parameters that describe the arm as its user tells it (``armature``,
    ``friction``, ``damping``; :func:`controller_armature`, :func:`controller_friction`): every
    law's, so that the comparison stays fair; empty for the ideal arm and one effect alone."""
    values: dict[str, list[float]] = {}
    armature = controller_armature(arm, effects)
    if armature is not None:
        values["armature"] = armature
    friction = controller_friction(arm, effects)
    if friction is not None:
        values["friction"], values["damping"] = friction
    return values


@dataclass(frozen=True)
class RobotCase:
    """One run: arm, case, what the arm adds, feedback law, timing.

    ``effects``: ``ideal``, ``physical`` (every effect of the arm's preset), or one effect of
    the preset alone (a key of :data:`apc_plant_sim.effects.EFFECT_FIELDS`).
    """

    arm: str
    case: str
    effects: str
    law: str
    timing: str = "sim"

    @property
    def name(self) -> str:
        law = self.law.replace(" ", "_")
        return f"robot_{self.arm}_{self.case}_{self.effects}_{law}_{self.timing}"

    @property
    def scenario(self) -> Scenario:
        return arm_scenario(self.arm, self.case)


def plan(
    quick: bool = False, arms: Sequence[str] = ("puma3", "panda"), realtime: bool = False
) -> list[RobotCase]:
    """Every run (``quick``: case (c) only; the ``physical`` preset only where the arm is);
    ``realtime`` adds case (c) with every effect on, each law, on the wall clock."""
    cases = ("c",) if quick else CASES
    own_file = [arm for arm in arms if robot_file_law(arm) != LAWS["adaptive recommended"]]
    runs = [
        RobotCase(arm, case, effects, law)
        for arm in arms
        for effects in EFFECTS
        for case in cases
        for law in (*LAWS, ROBOT_FILE_LAW)
        if law != ROBOT_FILE_LAW or arm in own_file
    ]
    if realtime:
        runs += [
            RobotCase(arm, "c", "physical", law, "realtime")
            for arm in arms
            for law in (*LAWS, ROBOT_FILE_LAW)
            if law != ROBOT_FILE_LAW or arm in own_file
        ]
    return runs


def effect_parameters(arm: str, effects: str) -> dict[str, Any]:
    """robot_sim's physical-arm parameters: ``ideal``, the arm's preset (``physical``), or one
    effect of the preset alone. MuJoCo's ``frictionloss`` is one level for both directions (the
    mean of the two, as robot_sim makes it of a preset)."""
    if effects in ("ideal", "physical"):
        return {"effects": PHYSICAL_PRESETS[arm] if effects == "physical" else "ideal"}
    one = single_effect(effects, ARM_EFFECTS[arm]())
    n = len(ARM_EFFECTS[arm]().counts_per_rev)
    coulomb = one.mean_coulomb(n)
    values = {
        "effects": "ideal",
        "damping": one.per_joint("viscous_nm_s", n).tolist(),
        "frictionloss": coulomb.tolist(),
        "armature": one.per_joint("armature_kgm2", n).tolist(),
        "encoder_counts_per_rev": list(one.counts_per_rev),
        "velocity_source": one.velocity,
        "velocity_noise": float(one.velocity_noise_rad_s),
        "command_delay_cycles": int(one.command_delay),
    }
    # An empty list is the preset's value (here: none), and rclpy cannot type an empty array.
    return {k: v for k, v in values.items() if v != []}


def node_parameters(case: RobotCase) -> dict[str, dict[str, Any]]:
    """ROS parameters of each node, keyed by node name (a ROS parameter-file layout)."""
    sc = case.scenario
    shared: dict[str, Any] = {"robot_description_path": str(sc.urdf), "gravity": float(sc.gravity)}
    if sc.lock_joints:
        shared["lock_joints"] = list(sc.lock_joints)
    inertia_error = [float(v) for v in sc.inertia_error]
    controller, settings = law_of(case)
    period = float(sc.period)
    robot_node = {
        **shared,
        "period": period,
        "inertia_error": inertia_error,
        "autostart": True,
        **law_parameters(controller, settings),
    }
    robot_node.update(controller_arm_parameters(case.arm, case.effects))
    sim = case.timing == "sim"
    robot_sim = {
        **shared,
        "engine": ENGINE,
        **effect_parameters(case.arm, case.effects),
        "state_rate": DRIVER_RATE_HZ,
        "q_initial_deg": [float(v) for v in sc.q_start_deg],
        "payload.mass_kg": float(sc.payload_kg),
        "payload.frame": sc.payload_frame or "",
        "payload.com_m": [float(v) for v in sc.payload_com_m],
        "payload.at_s": float(sc.payload_at_s),
        "sim_time": sim,
        "sim_wait_s": SIM_WAIT_S,
        "command_latency": COMMAND_LATENCY_S,
        "sim_cycles_per_command": round(DRIVER_RATE_HZ * period),
    }
    return {"robot_node": robot_node, "robot_sim": robot_sim}


def goal_message(scenario: Scenario, joint_names: Sequence[str]) -> JointTrajectory:
    """The paper's 4-3-4 move as a trajectory goal (see the module docstring)."""
    move = scenario.move()
    msg = JointTrajectory()
    msg.joint_names = list(joint_names)
    for t in np.cumsum(scenario.segment_times):
        q, qd, qdd = move.sample(float(t))
        point = JointTrajectoryPoint()
        point.positions, point.velocities, point.accelerations = (
            [float(v) for v in a] for a in (q, qd, qdd)
        )
        ns = round(float(t) * wire.NS_PER_S)
        point.time_from_start = Duration(sec=ns // wire.NS_PER_S, nanosec=ns % wire.NS_PER_S)
        msg.points.append(point)
    return msg


def describe(case: RobotCase) -> dict[str, Any]:
    """What the recording stores about its run (``custom_data['apc.run']``)."""
    controller, settings = law_of(case)
    return {
        "name": case.name,
        "controller": controller,
        "settings": dict(settings or {}),
        "mode": f"robot_{case.timing}",
        "arm": case.arm,
        "case": case.case,
        "effects": case.effects,
        "law": case.law,
        "engine": ENGINE,
        "driver_rate_hz": DRIVER_RATE_HZ,
        "hold_before_s": HOLD_BEFORE_S,
        "scenario": {
            k: list(v) if isinstance(v, tuple) else v for k, v in asdict(case.scenario).items()
        },
    }


@dataclass
class RobotOutcome:
    path: Path
    ok: bool
    message: str
    wall_s: float


def _controllers_heard(recorder: Any, sender: Node, goal_pub: Any) -> bool:
    topics = (wire.SETPOINT, wire.SAMPLE)
    heard = all(recorder.count_publishers(recorder.resolve_topic_name(t)) >= 1 for t in topics)
    return heard and goal_pub.get_subscription_count() >= 1


def run_case(case: RobotCase, out_dir: Path, *, timeout_s: float = 120.0) -> RobotOutcome:
    """Run one case composed in this process (see the module docstring) and record it.

    SIGINT and SIGTERM end the run between two ``spin_once`` calls: the recording is finished,
    every node destroyed, and the outcome says ``interrupted``.
    """
    from apc_feedback.robot_node import RobotNode
    from apc_plant_sim.robot_sim import RobotSimNode

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{case.name}.mcap"
    params = node_parameters(case)
    scenario = case.scenario
    # A sample period past the hold after the move: the robot's state of the hold's last
    # sample is out (and so answered) before the robot stops.
    end_s = HOLD_BEFORE_S + scenario.duration + HOLD_AFTER_S + scenario.period
    with StopSignals() as stop:
        context = rclpy.Context()
        rclpy.init(context=context)
        nodes: list[Node] = []
        executor = None
        t0 = time.monotonic()
        try:
            sim = case.timing == "sim"
            clock = [Parameter("use_sim_time", value=sim)]
            recorder = recorder_node(path, context, describe(case), sim)
            nodes.append(recorder)
            # No /rosout: every case builds its nodes again, with the same names, in a fresh
            # context of this process; rcl keeps one rosout publisher per node name and process
            # and releases a lifecycle node's late, so the next case's robot_node logged into the
            # last one's dead publisher ("Failed to publish log message to rosout"). Nothing in
            # this private context reads /rosout; the log lines go to the run's log folder.
            controller = RobotNode(
                context=context,
                parameter_overrides=clock + overrides(params["robot_node"]),
                enable_rosout=False,
            )
            nodes.append(controller)
            sender = Node("goal_sender", context=context)
            nodes.append(sender)
            goal_pub = sender.create_publisher(
                JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS
            )
            executor = make_executor("events", context)
            for node in nodes:
                executor.add_node(node)
            wait_for(
                executor,
                lambda: stop.check() or _controllers_heard(recorder, sender, goal_pub),
                30.0,
                "the controllers",
            )
            # The robot comes last: its first joint state finds everything listening.
            robot = RobotSimNode(
                context=context,
                parameter_overrides=overrides(params["robot_sim"]),
                enable_rosout=False,
            )
            nodes.append(robot)
            executor.add_node(robot)
            goal = goal_message(scenario, controller.joint_names)
            sent = False
            while robot.driver_time < end_s:
                if time.monotonic() - t0 > timeout_s:
                    return RobotOutcome(path, False, f"timed out after {timeout_s} s", _since(t0))
                executor.spin_once(timeout_sec=0.05)
                stop.check()
                if not sent and robot.driver_time >= HOLD_BEFORE_S:
                    goal_pub.publish(goal)
                    sent = True
            counts = controller.diagnostics.counters
            faults = {k: counts.get(k, 0) for k in ("watchdog", "path_tolerance_aborts")}
            # The robot stops (no more states, so no more samples), and the recorder takes
            # what is still queued for it until it has taken nothing for a while: however far
            # a loaded machine left it behind, the recording ends where the run did. The
            # faults are read first: the controllers' watchdog fires once the states stop.
            executor.remove_node(robot)
            take_what_is_queued(executor, recorder)
            ok = not any(faults.values())
            return RobotOutcome(path, ok, "ok" if ok else f"faults {faults}", _since(t0))
        except (KeyboardInterrupt, ExternalShutdownException) as exc:
            return RobotOutcome(path, False, f"interrupted ({exc})".replace(" ()", ""), _since(t0))
        except (TimeoutError, ConfigError) as exc:
            return RobotOutcome(path, False, str(exc), _since(t0))
        finally:
            destroy_nodes(nodes, context, executor)


def _since(t0: float) -> float:
    return time.monotonic() - t0


def load(path: str | Path) -> Any:
    """A robot-mode recording from the start of the move to the end of the hold after it (the
    arm runs on while the recorder drains)."""
    from apc_recording.runs import load_robot_run

    run = load_robot_run(path)
    end = run.move_end_index + round(HOLD_AFTER_S / float(run.run["scenario"]["period"])) + 1
    rows = ("t", "q", "qd", "applied", "q_d", "qd_d", "qdd_d", "u_n", "du", "trace_p")
    return replace(run, residual_norm=run.residual_norm[:end],
                   **{name: getattr(run, name)[:end] for name in rows})  # fmt: skip


def hold_error_deg(path: str | Path) -> float:
    """Worst |q - q_d| (deg) of a robot-mode recording over the samples before the set point
    first moves: the sag of the hold before the goal."""
    from apc_recording.runs import load_robot_run

    return load_robot_run(path).run["hold_max_error_deg"]


def measure(path: str | Path) -> dict[str, Any]:
    """Per-joint metrics of a robot-mode recording (:mod:`apc_lab.metrics`)."""
    from apc_lab.analyze import robot_of
    from apc_lab.metrics import compute_metrics

    run = load(path)
    metrics = compute_metrics(
        run.joint_names, run.q, run.q_d, run.applied, run.move_end_index, robot=robot_of(run)
    )
    return {"samples": len(run.t), **metrics.as_dict()}


def execute(
    cases: Sequence[RobotCase], out: Path, progress: bool = True
) -> dict[str, dict[str, Any]]:
    """Run every case; {name: outcome and metrics}."""
    results: dict[str, dict[str, Any]] = {}
    bar = Progress(len(cases), "robot comparison", progress)
    for i, case in enumerate(cases):
        bar.update(i, case.name)
        outcome = run_case(case, out)
        entry: dict[str, Any] = {
            "ok": outcome.ok,
            "message": outcome.message,
            "path": str(outcome.path),
            "wall_s": round(outcome.wall_s, 2),
        }
        try:
            entry["metrics"] = measure(outcome.path)
        except (OSError, ValueError) as exc:
            entry.update(ok=False, message=f"{outcome.message}; unreadable: {exc}")
        if not entry["ok"]:
            print(f"\n{case.name}: FAILED ({entry['message']})", file=sys.stderr)
        results[case.name] = entry
    bar.update(len(cases))
    bar.close()
    return results


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="robot_compare", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="runs/robot", help="output directory")
    parser.add_argument("--quick", action="store_true", help="case (c) only")
    parser.add_argument("--arms", default="puma3,panda", help="puma3, panda or both")
    parser.add_argument("--realtime", action="store_true", help="also case (c) in real time")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    out = Path(args.out)
    t0 = time.monotonic()
    from apc_lab.robot_report import figures, report_section

    cases = plan(args.quick, [a for a in args.arms.split(",") if a], args.realtime)
    results = execute(cases, out, progress=not args.quiet)
    made = figures(cases, results, out)
    text = report_section(cases, results)
    figs = "\n".join(f"![{f.stem}]({f.name})" for f in made)
    (out / "report.md").write_text(f"# Through the robot interface\n\n{text}\n\n{figs}\n")
    print(text)
    print(f"\n{len(cases)} runs in {time.monotonic() - t0:.1f} s; report: {out / 'report.md'}")
    return 0 if all(r["ok"] for r in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
