"""The three nodes over DDS: goals, start-up errors, lockstep timeouts, real time, diagnostics."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from support.arm import T_NS
from support.nodes import overrides, recorded_diagnostics
from support.processes import NODE_MODULES, Children, write_params
from support.report import report
from support.sim_clock import ClockStepper
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_feedback.node import FeedbackNode
from apc_feedforward.node import FeedforwardNode
from apc_feedforward.trajectory import Waypoints
from apc_lab.experiment import RunSpec
from apc_lab.run_recorder import recorder_node
from apc_lab.scenario import paper_scenario, paper_settings, run_offline
from apc_plant_sim.node import PlantNode
from apc_recording.runs import load_run

pytestmark = pytest.mark.ros


def test_goal_is_executed_after_the_current_motion(graph):
    """A JointTrajectory goal (joints in another order) starts when the first move ends."""
    scenario = paper_scenario("a", hold_s=0.8)
    params = RunSpec(scenario, "computed_torque").node_parameters()
    ctx = graph.context
    ff = graph.add(
        FeedforwardNode(context=ctx, parameter_overrides=overrides(params["feedforward_node"]))
    )
    graph.add(FeedbackNode(context=ctx, parameter_overrides=overrides(params["feedback_node"])))
    helper = graph.add(rclpy.create_node("goal_sender", context=ctx))
    goal_pub = helper.create_publisher(
        JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS
    )
    setpoints = {}
    helper.create_subscription(
        JointTrajectory,
        wire.SETPOINT,
        lambda m: setpoints.__setitem__(
            wire.stamp_to_ns(m.header.stamp), wire.msg_to_setpoint(m, ff.joint_names)
        ),
        wire.CONTROL_QOS,
    )
    graph.spin_until(lambda: goal_pub.get_subscription_count() >= 1)
    order = [2, 0, 1]  # joint_3, joint_1, joint_2
    targets = np.deg2rad([[60.0, 20.0, -120.0], [30.0, 0.0, -90.0]])
    goal = JointTrajectory(joint_names=[ff.joint_names[i] for i in order])
    for t, q in zip((0.3, 0.6), targets, strict=True):
        goal.points.append(
            JointTrajectoryPoint(
                positions=[float(q[i]) for i in order],
                time_from_start=Duration(sec=0, nanosec=round(t * 1e9)),
            )
        )
    goal_pub.publish(goal)
    graph.spin_until(lambda: ff.diagnostics.counters.get("goals_accepted", 0) == 1)
    plant_params = dict(params["plant_node"], wait_for_subscribers=2)
    plant = graph.add(PlantNode(context=ctx, parameter_overrides=overrides(plant_params)))
    graph.spin_until(lambda: plant.done, timeout_s=60)
    assert plant.exit_code == 0
    # Set points 0 .. n_samples, and the lookahead beyond the last joint state.
    graph.spin_until(lambda: len(setpoints) == scenario.n_samples + 2)
    period_ns = 10_000_000
    q_end = np.deg2rad(scenario.q_goal_deg)
    plan = Waypoints(q_end, np.array([0.3, 0.6]), targets)
    for k in (100, 115, 130, 145, 160, 170, 180):
        expected = plan.sample((k - 100) * 0.01)
        np.testing.assert_allclose(setpoints[k * period_ns].q, expected[0], atol=1e-12)
        np.testing.assert_allclose(setpoints[k * period_ns].qd, expected[1], atol=1e-12)
    np.testing.assert_allclose(setpoints[130 * period_ns].q, targets[0], atol=1e-12)
    np.testing.assert_allclose(setpoints[180 * period_ns].q, targets[1], atol=1e-12)
    # Before the switch the paper's move ran untouched.
    np.testing.assert_allclose(setpoints[99 * period_ns].q, q_end, atol=np.deg2rad(0.01))


def test_bad_goal_is_rejected_and_counted(graph):
    params = RunSpec(paper_scenario("a"), "none").node_parameters()
    ff = graph.add(
        FeedforwardNode(
            context=graph.context, parameter_overrides=overrides(params["feedforward_node"])
        )
    )
    helper = graph.add(rclpy.create_node("goal_sender", context=graph.context))
    pub = helper.create_publisher(JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS)
    graph.spin_until(lambda: pub.get_subscription_count() >= 1)
    pub.publish(
        JointTrajectory(
            joint_names=["joint_1", "joint_2", "nope"],
            points=[
                JointTrajectoryPoint(positions=[0.0, 0.0, 0.0], time_from_start=Duration(sec=1))
            ],
        )
    )
    pub.publish(
        JointTrajectory(
            joint_names=list(ff.joint_names),
            points=[
                JointTrajectoryPoint(
                    positions=[0.0, float("nan"), 0.0], time_from_start=Duration(sec=1)
                )
            ],
        )
    )
    graph.spin_until(lambda: ff.diagnostics.counters.get("rejected", 0) == 2)
    assert ff.diagnostics.counters.get("goals_accepted", 0) == 0


def test_lockstep_missing_peer_ends_with_a_clear_error(graph):
    """No feedback node: the lockstep plant gives up after its timeout instead of hanging."""
    params = RunSpec(paper_scenario("a"), "none").node_parameters()
    graph.add(
        FeedforwardNode(
            context=graph.context, parameter_overrides=overrides(params["feedforward_node"])
        )
    )
    plant_params = dict(params["plant_node"], wait_for_subscribers=1, lockstep_timeout_s=1.0)
    t0 = time.monotonic()
    plant = graph.add(PlantNode(context=graph.context, parameter_overrides=overrides(plant_params)))
    graph.spin_until(lambda: plant.done, timeout_s=10)
    # Not before its timeout (a steady-clock feature: how long after it a loaded machine
    # gets there is not asserted; the rule itself: test_pacing.py in synthetic time).
    assert time.monotonic() - t0 >= 1.0
    assert plant.exit_code == 1
    assert "no publisher on feedback/torque" in plant.diagnostics.message
    # (its writer keeps a deep history: a reader matched late on its side gets every sample)
    assert plant.js_pub.qos_profile.depth == wire.CONTROL_WRITER_DEPTH


def test_lockstep_peer_dying_mid_run_ends_with_a_clear_error(graph):
    params = RunSpec(paper_scenario("a", hold_s=5.0), "none").node_parameters()
    ctx = graph.context
    graph.add(
        FeedforwardNode(context=ctx, parameter_overrides=overrides(params["feedforward_node"]))
    )
    fb = graph.add(
        FeedbackNode(context=ctx, parameter_overrides=overrides(params["feedback_node"]))
    )
    plant_params = dict(params["plant_node"], wait_for_subscribers=2, lockstep_timeout_s=1.0)
    plant = graph.add(PlantNode(context=ctx, parameter_overrides=overrides(plant_params)))
    graph.spin_until(lambda: plant.k >= 20)
    graph.executor.remove_node(fb)  # the feedback node stops answering
    graph.spin_until(lambda: plant.done, timeout_s=10)
    assert plant.exit_code == 1
    assert "no feedback/torque for sample" in plant.diagnostics.message
    assert plant.k < scenario_samples(params)


def scenario_samples(params):
    return params["plant_node"]["n_samples"]


@pytest.mark.parametrize(
    ("argv", "parameter"),
    [
        (["feedback_node", "-p", "adaptive.rho:=1.5"], "adaptive.rho"),
        (["feedback_node", "-p", "controller:=lqr"], "controller"),
        (["plant_node", "-p", "step:=0.003"], "step"),
        (["plant_node", "-p", "mode:=fast"], "mode"),
        (
            ["plant_node", "-p", "robot_description_path:=/nonexistent.urdf"],
            "robot_description_path",
        ),
        (["feedforward_node", "-p", "inertia_error:=[0.1]"], "inertia_error"),
        (["feedback_node", "-p", "adaptive.r:=0.0"], "adaptive.r"),
    ],
)
def test_bad_parameter_stops_the_node_with_one_line(argv, parameter):
    proc = subprocess.run(
        [sys.executable, "-m", NODE_MODULES[argv[0]], "--ros-args", *argv[1:]],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert f"'{parameter}'" in lines[0]


@pytest.mark.ros
@pytest.mark.slow
def test_realtime_three_processes_on_a_stepped_clock_track_as_lockstep(tmp_path, observer):
    """Real time at T = 10 ms, three processes, case (c), on a ``/clock`` the test moves one
    period at a time once both controllers have answered (:mod:`support.sim_clock`): the run
    is real time's rules (newest torques, the nominal torque sent ahead) with every torque on
    time, so it tracks as lockstep does, within 2x of its max error whatever the machine's load
    (a torque that reaches the plant after the observer is applied a period late; counted).

    Also checks that every node reports on /diagnostics (loop timing, compute time, counters).
    On wall time real time's lateness is measured, not asserted (``bench/ros_loop.py``).
    """
    scenario = paper_scenario("c", hold_s=0.5)
    settings = paper_settings(1.5e5)
    spec = RunSpec(scenario, "adaptive", settings, "realtime", name="realtime")
    params = spec.node_parameters()
    # ff, fb, the recorder and the observer listen to joint_states
    params["plant_node"].update(use_sim_time=True, publish_clock=False, wait_for_subscribers=4)
    bag = tmp_path / "realtime.mcap"
    recorder = observer.graph.add(recorder_node(bag, observer.context, spec.description()))
    kids = Children(tmp_path, write_params(tmp_path / "params.yaml", params))
    try:
        kids.start_controllers()
        observer.spin_until(observer.controllers_up, 30, "controllers' publishers")
        plant = kids.start("plant_node")
        clock = ClockStepper(observer, T_NS, 1, list(kids.procs.values()))
        k = clock.start()
        while k < scenario.n_samples - 1:
            k = clock.step()
        clock.tick()  # the last sample: the plant applies its torques and ends
        observer.spin_until(lambda: plant.poll() is not None, 30, "the plant's end")
        assert plant.returncode == 0, kids.stderr("plant_node")[-2000:]
        # Every sample 0..n_samples of the per-sample topics (the feedback answers the last
        # state too: it does not know it is the last).
        topics = ("/joint_states", "/feedforward/setpoint", "/feedback/torque")
        observer.spin_until(
            lambda: all(recorder.counts.get(t, 0) > scenario.n_samples for t in topics),
            30,
            f"the recorder's {topics}",
        )
    finally:
        kids.close()
    recorder.close()
    recorded = load_run(bag)
    lockstep = run_offline(scenario, "adaptive", settings)
    end = scenario.move_end_sample
    max_rt = np.nanmax(np.abs(recorded.error[: end + 1]), axis=0)
    max_ls = np.abs(lockstep.error[: end + 1]).max(axis=0)
    assert np.all(max_rt <= 2.0 * max_ls), (np.rad2deg(max_rt), np.rad2deg(max_ls))
    statuses = recorded_diagnostics(bag)
    assert {"plant_node", "feedforward_node", "feedback_node"} <= set(statuses)
    plant_status = statuses["plant_node"]
    assert "period_median_us" in plant_status and "integrate_median_us" in plant_status
    feedback = statuses["feedback_node"]
    assert "compute_median_us" in feedback and "trace_p" in feedback
    report(
        "real time on a stepped clock",
        max_error_deg=np.rad2deg(max_rt).round(4).tolist(),
        lockstep_deg=np.rad2deg(max_ls).round(4).tolist(),
        late_samples=int(plant_status.get("late_samples", 0)),
    )
