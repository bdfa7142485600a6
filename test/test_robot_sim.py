"""``robot_sim`` over DDS: the executable behaves like a ros2_control robot.

One process per test (``python -m apc_plant_sim.robot_sim``), talked to from a test node in
this process: ``/joint_states`` as ``joint_state_broadcaster`` publishes it and efforts as an
effort ``forward_command_controller`` takes them.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import qos_profile_system_default
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from support.processes import node_process
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_core.robot import PAPER_GOAL_DEG, PAPER_START_DEG
from apc_lab.scenario import CONFIG_DIR

STATE_JOINTS = ["joint_2", "finger_joint", "joint_3", "joint_1"]
URDF_ORDER = ("joint_1", "joint_2", "joint_3")


class Peer:
    """A controller's side of the robot: reads /joint_states, publishes commands."""

    def __init__(self, graph, topic: str = "/effort_controller/commands") -> None:
        node = graph.add(Node("peer", context=graph.context))
        self.states: list[tuple[float, JointState]] = []
        self.clock: list[int] = []
        node.create_subscription(
            JointState,
            "/joint_states",
            lambda m: self.states.append((time.monotonic(), m)),
            wire.CONTROL_QOS,  # depth 10: a 500 Hz driver's burst of cycles is all kept
        )
        node.create_subscription(
            ClockMsg,
            "/clock",
            lambda m: self.clock.append(wire.stamp_to_ns(m.clock)),
            wire.CLOCK_QOS,
        )
        self.pub = node.create_publisher(Float64MultiArray, topic, qos_profile_system_default)
        self.diagnostics: list[dict[str, str]] = []
        node.create_subscription(
            DiagnosticArray,
            "/diagnostics",
            lambda m: self.diagnostics.extend(
                {kv.key: kv.value for kv in status.values}
                for status in m.status
                if status.hardware_id == "robot_sim"
            ),
            wire.DIAGNOSTICS_QOS,
        )

    def command(self, values) -> None:
        self.pub.publish(Float64MultiArray(data=[float(v) for v in values]))

    def by_name(self, msg: JointState, field: str) -> dict[str, float]:
        return dict(zip(msg.name, getattr(msg, field), strict=True))


def robot_sim(tmp_path: Path, *params: str):
    """``robot_sim`` with ``-p`` overrides, stopped when the test ends."""
    args = [sys.executable, "-m", "apc_plant_sim.robot_sim", "--ros-args"]
    for p in params:
        args += ["-p", p]
    return node_process(args, tmp_path / "robot_sim.err")


def test_wall_time_robot_rate_stamps_names_command_and_timeout(graph, tmp_path):
    """On wall time: names, brakes, stamps on the driver's cycle grid, a command applied, the
    command timeout, bad commands rejected. Nothing here depends on how punctually the machine
    runs (the rate a loaded machine keeps is measured in ``bench/robot_loop.py``)."""
    peer = Peer(graph)
    started_ns = time.time_ns()
    with robot_sim(
        tmp_path,
        "state_rate:=50.0",
        f"state_joints:={STATE_JOINTS}".replace("'", ""),
        "publish_velocity:=false",
        "command_timeout:=0.2",
        "q_initial_deg:=[0.0, -30.0, 45.0]",
    ) as proc:
        graph.spin_until(lambda: len(peer.states) >= 20 or proc.poll() is not None, 30, "states")
        assert proc.poll() is None, (tmp_path / "robot_sim.err").read_text()
        _, first = peer.states[-1]
        assert list(first.name) == STATE_JOINTS
        assert len(first.velocity) == 0 and len(first.effort) == len(STATE_JOINTS)
        position = peer.by_name(first, "position")
        # Brakes on until the first command: the arm stands at q_initial_deg.
        assert np.rad2deg(position["joint_2"]) == pytest.approx(-30.0)
        assert position["finger_joint"] == 0.0
        # Stamps: the node's clock (system time), on the cycle grid of 1/state_rate (a late
        # callback publishes its newest cycle's state: a gap is whole periods).
        stamps = np.array([wire.stamp_to_ns(m.header.stamp) for _, m in peer.states[-15:]])
        assert started_ns <= stamps[0] and stamps[-1] <= time.time_ns()
        gaps = np.diff(stamps)
        assert np.all(gaps > 0) and np.all(gaps % 20_000_000 == 0), gaps

        # A command in command_joints order (URDF order) is applied: it comes back as effort.
        command = [5.0, -40.0, 12.0]
        n_before = len(peer.states)
        t_cmd = time.monotonic()

        def applied() -> bool:
            if len(peer.states) <= n_before:
                return False
            effort = peer.by_name(peer.states[-1][1], "effort")
            return [effort[j] for j in URDF_ORDER] == command

        while not applied():
            peer.command(command)
            t_last = time.monotonic()
            graph.spin_for(0.01)
            assert time.monotonic() - t_cmd < 10.0, "command never applied"
        # The arm moves once released.
        graph.spin_until(
            lambda: peer.by_name(peer.states[-1][1], "position")["joint_2"] != position["joint_2"],
            10,
            "the arm released",
        )

        # No command for command_timeout: zero effort (the hardware's safety timeout), not before.
        graph.spin_until(
            lambda: all(v == 0.0 for v in peer.states[-1][1].effort), 10, "zero effort"
        )
        assert time.monotonic() - t_last >= 0.2
        # A bad command is rejected, never applied; /diagnostics counts them (once a second).
        # (One at a time: SystemDefaultsQoS keeps only the newest message with FastDDS, as
        # forward_command_controller needs, so a second sent before the first is taken would
        # replace it.)
        for n, bad in enumerate(([1.0, 2.0], [1.0, float("nan"), 3.0]), start=1):
            peer.command(bad)
            graph.spin_until(
                lambda n=n: peer.diagnostics and int(peer.diagnostics[-1].get("rejected", 0)) >= n,
                10,
                f"diagnostics with {n} rejected command(s)",
            )
        assert all(v == 0.0 for v in peer.states[-1][1].effort)
        counts = peer.diagnostics[-1]
        assert int(counts["rejected"]) == 2
        # (more than one timeout if the test's own command loop above stalled 0.2 s)
        assert int(counts["commands"]) >= 1 and int(counts["timeouts"]) >= 1
        assert int(counts["clipped"]) == 0


@pytest.mark.parametrize(
    "engine", [("engine:=pinocchio",), ("engine:=mujoco", "effects:=puma560")], ids=lambda e: e[0]
)
def test_sim_time_robot_steps_only_when_the_controller_answers(graph, tmp_path, engine):
    peer = Peer(graph, topic="/arm/commands")
    with robot_sim(
        tmp_path,
        *engine,
        "sim_time:=true",
        "state_rate:=100.0",
        "command_topic:=/arm/commands",
        "sim_wait_s:=30.0",
    ) as proc:
        graph.spin_until(lambda: peer.states or proc.poll() is not None, 30, "first state")
        assert proc.poll() is None, (tmp_path / "robot_sim.err").read_text()
        for _ in range(20):
            n = len(peer.states)
            peer.command([0.0, 10.0, 0.0])
            graph.spin_until(lambda n=n: len(peer.states) > n, 10, "next state")
        answered = len(peer.states)
        graph.spin_for(0.3)  # nothing answered: the robot waits (sim_wait_s is 30 s)
        assert len(peer.states) == answered
        stamps = [wire.stamp_to_ns(m.header.stamp) for _, m in peer.states]
        # Every period once, none skipped (before the first command time advanced one period
        # per 0.1 s with the brakes on; each of the 20 commands then advanced it one period).
        # (The states before this test's subscription matched are not seen.)
        assert stamps == [stamps[0] + k * 10_000_000 for k in range(len(stamps))]
        assert stamps[0] % 10_000_000 == 0 and len(stamps) >= 21
        assert peer.clock and max(peer.clock) == stamps[-1]


def _spin_until_quiet(graph, peer, quiet_s: float = 0.3) -> None:
    """Spin until no /clock message has come for ``quiet_s``: what the driver sent is in."""
    count = len(peer.clock)
    while True:
        graph.spin_for(quiet_s)
        if len(peer.clock) == count:
            return
        count = len(peer.clock)


@contextlib.contextmanager
def _on_the_tick_grid(graph, tmp_path, peer, *extra):
    """A 500 Hz driver in sim time answered every five cycles (controllers at 100 Hz), its first
    command taken and time at the controllers' tick grid (a multiple of five cycles), where it
    waits. sim_wait_s 30: the driver never steps on without a command while the test runs, so
    what is asserted does not depend on how fast this machine delivers the /clock messages."""
    args = ("sim_time:=true", "state_rate:=500.0", "sim_cycles_per_command:=5", "sim_wait_s:=30.0")
    with robot_sim(tmp_path, *args, *extra) as proc:
        graph.spin_until(lambda: peer.states or proc.poll() is not None, 30, "first state")
        assert proc.poll() is None, (tmp_path / "robot_sim.err").read_text()
        graph.spin_until(lambda: peer.clock, 10, "/clock")
        peer.command([0.0, 10.0, 0.0])
        graph.spin_until(lambda: max(peer.clock) % 10_000_000 == 0, 10, "the tick grid")
        _spin_until_quiet(graph, peer)
        yield proc


def test_sim_time_driver_faster_than_its_controllers_waits_every_n_cycles(graph, tmp_path):
    """500 Hz driver, controllers at 100 Hz: the first command moves time to the next multiple
    of five cycles (the controllers' tick grid), where it waits; every later one by five 2 ms
    cycles exactly."""
    peer = Peer(graph)
    with _on_the_tick_grid(graph, tmp_path, peer):
        for _ in range(10):
            before = max(peer.clock)
            peer.command([0.0, 10.0, 0.0])
            graph.spin_until(lambda b=before: max(peer.clock) >= b + 10_000_000, 10, "five cycles")
            _spin_until_quiet(graph, peer)
            assert max(peer.clock) - before == 10_000_000  # five cycles of 2 ms, then a wait
        stamps = [wire.stamp_to_ns(m.header.stamp) for _, m in peer.states]
        assert stamps == [stamps[0] + k * 2_000_000 for k in range(len(stamps))]


def test_sim_time_missed_states(graph, tmp_path):
    """``missed_states: 0.5``: about half the cycles between two commands publish no state
    (counted as ``unpublished_cycles``) while time goes on; the cycle the driver waits on
    (every fifth) always publishes, so each command is answered as before."""
    peer = Peer(graph)
    with _on_the_tick_grid(graph, tmp_path, peer, "missed_states:=0.5"):
        start = max(peer.clock)
        for i in range(1, 21):
            peer.command([0.0, 10.0, 0.0])
            graph.spin_until(lambda i=i: max(peer.clock) >= start + i * 10_000_000, 10, "cycles")
            _spin_until_quiet(graph, peer)
        stamps = {wire.stamp_to_ns(m.header.stamp) for _, m in peer.states}
        between = [start + 2_000_000 * j for j in range(100) if j % 5]
        assert all(start + 10_000_000 * i in stamps for i in range(21))  # the waited-on cycles
        assert sum(t not in stamps for t in between) >= 20  # about half of the 80
        graph.spin_until(
            lambda: peer.diagnostics and "unpublished_cycles" in peer.diagnostics[-1],
            10,
            "the count on /diagnostics",
        )
        assert 20 <= int(peer.diagnostics[-1]["unpublished_cycles"]) <= 80


@pytest.mark.parametrize(
    ("latency", "phase_ns", "periods"),
    [("0.0", 0, 1), ("0.025", 4_000_000, 4)],
    ids=["no latency", "25 ms latency, 4 ms phase"],
)
def test_sim_time_command_latency_and_phase(graph, tmp_path, latency, phase_ns, periods):
    """100 Hz driver in sim time: a step command answering the state at t is applied from the
    first cycle at or after t + command_latency and reported as the effort of the state one
    period after that: t + 10 ms without latency, t + 40 ms with 25 ms. Stamps and /clock are
    on the driver's cycles phase + i * 10 ms."""
    peer = Peer(graph)
    with robot_sim(
        tmp_path,
        "sim_time:=true",
        "state_rate:=100.0",
        "sim_wait_s:=30.0",
        f"command_latency:={latency}",
        f"phase:={phase_ns / 1e9}",
    ) as proc:
        graph.spin_until(lambda: peer.states or proc.poll() is not None, 30, "first state")
        assert proc.poll() is None, (tmp_path / "robot_sim.err").read_text()

        def stamps() -> set[int]:
            return {wire.stamp_to_ns(m.header.stamp) for _, m in peer.states}

        # Before the first command time moves with the brakes on. Once the driver has taken one
        # (its /diagnostics say so) it steps only when answered: its newest state is cycle
        # `cycles`, the one the next command answers.
        peer.command([0.0, 5.0, 0.0])
        graph.spin_until(
            lambda: peer.diagnostics and int(peer.diagnostics[-1].get("commands", 0)) >= 1,
            10,
            "the first command taken",
        )
        newest = phase_ns + int(peer.diagnostics[-1]["cycles"]) * 10_000_000
        graph.spin_until(lambda: newest in stamps(), 10, "the driver's newest state")

        def answer(values) -> int:
            """Answer the state the driver waits on, wait for the next; the answered stamp."""
            nonlocal newest
            answered = newest
            peer.command(values)
            newest += 10_000_000
            graph.spin_until(lambda: newest in stamps(), 10, "next state")
            return answered

        for _ in range(5):
            answer([0.0, 5.0, 0.0])
        t_step = answer([0.0, 10.0, 0.0])
        for _ in range(6):
            answer([0.0, 10.0, 0.0])
        effort = {
            wire.stamp_to_ns(m.header.stamp): peer.by_name(m, "effort")["joint_2"]
            for _, m in peer.states
        }
        first_step = min(stamp for stamp, value in effort.items() if value == 10.0)
        assert first_step - t_step == periods * 10_000_000
        # Until then the previous command, not the brakes' zero.
        assert effort[first_step - 10_000_000] == 5.0
        assert all(stamp % 10_000_000 == phase_ns for stamp in effort)
        assert peer.clock and all(c % 10_000_000 == phase_ns for c in peer.clock)


def test_bad_parameter_stops_with_one_line_naming_it(tmp_path):
    for params, name in (
        (["engine:=bullet"], "engine"),
        (["command_joints:=[joint_1, joint_2]"], "command_joints"),
        (["q_initial_deg:=[1.0]"], "q_initial_deg"),
        (["engine:=mujoco", "mujoco.integrator:=Verlet"], "mujoco.integrator"),
        (["engine:=mujoco", "damping:=[1.0]"], "damping"),
        (["engine:=mujoco", "frictionloss:=[1.0, -1.0, 0.0]"], "frictionloss"),
        (["engine:=pinocchio", "armature:=[0.1, 0.1, 0.1]"], "armature"),
        (["effects:=puma"], "effects"),
        (["velocity_source:=tacho"], "velocity_source"),
        (["encoder_counts_per_rev:=[0.0, 1.0, 1.0]"], "encoder_counts_per_rev"),
        (["state_rate:=100.0", "phase:=0.01"], "phase"),
        (["command_latency:=0.01", "command_latency_max:=0.005"], "command_latency_max"),
    ):
        args = [a for p in params for a in ("-p", p)]
        proc = subprocess.run(
            [sys.executable, "-m", "apc_plant_sim.robot_sim", "--ros-args", *args],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and f"parameter '{name}'" in lines[0], proc.stderr


def test_apcs_controllers_drive_the_mujoco_robot_in_sim_time(graph, tmp_path):
    """``robot_node`` with the shipped robot parameter file against robot_sim (MuJoCo,
    all effects off, 5 lb the controllers do not know) on its /clock: the arm holds its start
    within 0.5 deg, then makes the paper's move and ends within 0.01 deg of the goal
    (measured: 0.001 deg)."""
    peer = Peer(graph)
    goal_pub = graph.nodes[0].create_publisher(
        JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS
    )
    q0 = np.array(PAPER_START_DEG)
    goal = np.array(PAPER_GOAL_DEG)
    arm = [
        sys.executable,
        "-m",
        "apc_feedback.robot_node",
        "--ros-args",
        "--params-file",
        str(CONFIG_DIR / "puma560_3dof_robot.yaml"),
        "-p",
        "use_sim_time:=true",
    ]
    with (
        robot_sim(
            tmp_path,
            "engine:=mujoco",
            "sim_time:=true",
            "state_rate:=100.0",
            # a step waits up to 30 s of wall time for its command: a slow machine makes the
            # run slower, not different
            "sim_wait_s:=30.0",
            "payload.mass_kg:=2.268",
            f"q_initial_deg:={list(PAPER_START_DEG)}",
        ) as proc,
        node_process(arm, tmp_path / "arm.err") as controllers,
    ):

        def sim_time() -> float:
            return wire.stamp_to_ns(peer.states[-1][1].header.stamp) / 1e9 if peer.states else 0

        def running() -> None:
            for p, err in ((proc, "robot_sim.err"), (controllers, "arm.err")):
                assert p.poll() is None, (tmp_path / err).read_text()[-2000:]

        graph.spin_until(lambda: running() or sim_time() >= 1.0, 60, "1 s of holding")
        held = np.rad2deg(np.array(peer.states[-1][1].position))
        assert np.abs(held - q0).max() < 0.5
        graph.spin_until(lambda: goal_pub.get_subscription_count() > 0, 30, "robot_node")
        goal_pub.publish(
            JointTrajectory(
                joint_names=list(URDF_ORDER),
                points=[
                    JointTrajectoryPoint(
                        positions=list(np.deg2rad(goal)), time_from_start=Duration(sec=1)
                    )
                ],
            )
        )

        # Sim time runs as fast as the controllers answer, so it moves on while the goal is on
        # its way: the move is timed from when the arm leaves its hold, not from the publish.
        def moving() -> bool:
            position = np.rad2deg(np.array(peer.states[-1][1].position))
            return bool(np.abs(position - held).max() > 0.5)

        graph.spin_until(lambda: running() or moving(), 60, "the move to start")
        start = sim_time()
        graph.spin_until(lambda: running() or sim_time() >= start + 2.0, 120, "the move")
        final = np.rad2deg(np.array(peer.states[-1][1].position))
        assert np.abs(final - goal).max() < 0.01, final - goal
