"""``composed``: the nodes of one arm composed in one process (apc_lab.composed).

A lockstep run of the composed executable is the offline loop bit for bit (checked on every
joint state an observer in this process receives: position, velocity, and the applied torque
u_n + du of the period before), ``--controllers``
composes only feedforward and feedback and runs against a ``plant_node`` process, and
``--help`` lists each node's parameters.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from support.processes import node_process, write_params

import apc_msgs_py as wire
from apc_lab.experiment import RunSpec
from apc_lab.scenario import paper_scenario, paper_settings, run_offline

pytestmark = [pytest.mark.ros, pytest.mark.slow]

BIN = Path(sys.executable).parent
NAMES = ["joint_1", "joint_2", "joint_3"]


def _params_file(tmp_path: Path, spec: RunSpec, **plant: object) -> Path:
    params = spec.node_parameters()
    params["plant_node"].update(plant)
    return write_params(tmp_path / "params.yaml", params)


def _observe(graph, procs: list[subprocess.Popen], n_states: int) -> dict[int, JointState]:
    """Joint states by stamp until the plant's process (the last of ``procs``) exits and
    ``n_states`` are in (the last ones may still be on their way when it has)."""
    states: dict[int, JointState] = {}
    node = graph.add(rclpy.create_node("observer", context=graph.context))
    observer = node.create_subscription(
        JointState,
        wire.JOINT_STATES,
        lambda m: states.setdefault(wire.stamp_to_ns(m.header.stamp), m),
        # Deep: the run outpaces this test's executor, and keep-last 10 would drop samples.
        QoSProfile(depth=10_000, reliability=ReliabilityPolicy.RELIABLE),
    )
    # DDS matches a writer and a reader on each side on its own: the plant may count the
    # observer (its writer matched) while the observer has not matched the plant's writer yet
    # and drops the first samples (seen on a loaded machine). A second subscription, made only
    # once the observer has matched, is the plant's last awaited subscriber.
    graph.spin_until(lambda: observer.get_publisher_count() >= 1, 60.0, "the plant's joint states")
    node.create_subscription(JointState, wire.JOINT_STATES, lambda m: None, 10)
    deadline = time.monotonic() + 90
    while procs[-1].poll() is None:
        assert time.monotonic() < deadline, "the run did not end"
        graph.spin_for(0.05)
    graph.spin_until(lambda: len(states) >= n_states, 30.0, f"{n_states} joint states")
    return states


def _check_against_offline(states, scenario, settings) -> None:
    offline = run_offline(scenario, "adaptive", settings)
    # The plant starts once the observer has matched it (_observe): it sees every sample.
    assert sorted(states) == [k * 10_000_000 for k in range(len(offline.t))]
    for stamp, msg in states.items():
        k = stamp // 10_000_000
        sample = wire.joint_state_to_arrays(msg, NAMES)
        np.testing.assert_array_equal(sample.position, offline.q[k], err_msg=f"q[{k}]")
        np.testing.assert_array_equal(sample.velocity, offline.qd[k], err_msg=f"qd[{k}]")
        if k:  # u_n + du applied over the period before: the feedback's torques, bit for bit
            np.testing.assert_array_equal(sample.effort, offline.applied[k - 1], err_msg=f"{k}")


def test_composed_arm_lockstep_equals_offline(tmp_path, graph):
    scenario = paper_scenario("c", hold_s=0.2)
    settings = paper_settings(1.5e5)
    spec = RunSpec(scenario, "adaptive", settings, "lockstep")
    # ff, fb, the observer and its gate (_observe)
    params = _params_file(tmp_path, spec, wait_for_subscribers=4)
    argv = [str(BIN / "composed"), "--ros-args", "--params-file", str(params)]
    with node_process(argv, tmp_path / "arm.log", with_stdout=True) as arm:
        states = _observe(graph, [arm], scenario.n_samples + 1)
        assert arm.returncode == 0, (tmp_path / "arm.log").read_text()[-2000:]
        _check_against_offline(states, scenario, settings)


def test_controllers_only_run_against_a_plant_process(tmp_path, graph):
    scenario = paper_scenario("c", hold_s=0.0)
    settings = paper_settings(1.5e5)
    spec = RunSpec(scenario, "adaptive", settings, "lockstep")
    params = _params_file(tmp_path, spec, wait_for_subscribers=4)  # as in the lockstep test
    cmd = ["--ros-args", "--params-file", str(params)]
    with (
        node_process(
            [str(BIN / "composed"), "--controllers", *cmd],
            tmp_path / "controllers.log",
            with_stdout=True,
        ) as controllers,
        node_process(
            [str(BIN / "plant_node"), *cmd], tmp_path / "plant.log", with_stdout=True
        ) as plant,
    ):
        states = _observe(graph, [controllers, plant], scenario.n_samples + 1)
        assert plant.returncode == 0, (tmp_path / "plant.log").read_text()[-2000:]
        assert controllers.poll() is None  # the controllers run until stopped
        _check_against_offline(states, scenario, settings)
        log_text = (tmp_path / "controllers.log").read_text()
        assert "feedforward_node" in log_text and "feedback_node" in log_text
        assert "plant_node" not in log_text
    assert controllers.returncode == 0  # stopped by SIGINT (support.processes.node_process)


def test_help_lists_each_node_and_bad_arguments_exit_2() -> None:
    out = subprocess.run(
        [str(BIN / "composed"), "--help"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 0
    for section in ("--- plant_node ---", "--- feedforward_node ---", "--- feedback_node ---"):
        assert section in out.stdout
    assert "adaptive.q_position" in out.stdout and "lookahead" in out.stdout
    out = subprocess.run(
        [str(BIN / "composed"), "--controllers", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert "--- plant_node ---" not in out.stdout
    out = subprocess.run(
        [str(BIN / "composed"), "--fast"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode == 2 and "--fast" in out.stderr
