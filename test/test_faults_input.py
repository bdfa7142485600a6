"""Bad input and faults, the input half: malformed messages, bad stamps, runtime parameters,
bad configuration, torque limits.

The strongest check is :func:`test_fuzz_garbage_on_every_topic_leaves_a_lockstep_run_bit_identical`:
a lockstep run of plant + feedforward + feedback in one process while a separate node throws
thousands of hypothesis-generated invalid messages (:mod:`support.fuzz`) at every subscribed
topic; every one is rejected and counted by the node it reaches, no callback raises, every
output is finite, and the run equals the offline loop (= the clean run) bit for bit. Injected
messages carry ``header.frame_id = "fuzz"`` so the capturing node (:mod:`support.capture`) can
tell them from the nodes' own output (the nodes never read ``frame_id``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pytest
import rclpy
from hypothesis import HealthCheck, Phase, given, settings
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from support.arm import NAMES, ROBOT, T_NS, N
from support.capture import Capture, assert_all_finite, compare_with_offline, has_whole_run
from support.fuzz import BATCH, Garbage, extreme_goal
from support.graph import Graph
from support.nodes import counter, errors, overrides, recorded_diagnostics
from support.parameter_rig import ParameterRig, assert_refused
from support.processes import NODE_MODULES
from support.qos import DEEP_QOS
from support.stand_ins import StandInPlant, stand_in_controllers, torque
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire
from apc_feedback.node import FeedbackNode
from apc_feedforward.node import FeedforwardNode
from apc_lab.experiment import RunSpec
from apc_lab.scenario import paper_scenario, paper_settings, run_offline
from apc_plant_sim.intake import Source
from apc_plant_sim.node import PlantNode

pytestmark = pytest.mark.ros


# ----------------------------------------------------------------------------------------------
# 1. The fuzz: garbage on every topic during a lockstep run
# ----------------------------------------------------------------------------------------------
def _start_lockstep(graph: Graph, spec: RunSpec) -> tuple[Any, Any, Any, Capture]:
    params = spec.node_parameters()
    ctx = graph.context
    ff = graph.add(
        FeedforwardNode(context=ctx, parameter_overrides=overrides(params["feedforward_node"]))
    )
    fb = graph.add(
        FeedbackNode(context=ctx, parameter_overrides=overrides(params["feedback_node"]))
    )
    capture = Capture(graph)
    topics = [wire.SETPOINT, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE]
    if spec.controller == "adaptive":
        topics.append(wire.ESTIMATE)
    graph.spin_until(lambda: capture.hears(*topics), what="discovery of the controllers")
    # wait_for_subscribers = 3: ff, fb and the capture listen to joint_states.
    plant = graph.add(PlantNode(context=ctx, parameter_overrides=overrides(params["plant_node"])))
    return ff, fb, plant, capture


def test_fuzz_garbage_on_every_topic_leaves_a_lockstep_run_bit_identical(graph):
    scenario = paper_scenario("c", hold_s=1.0)
    settings_ = paper_settings(1.5e5)
    ff, fb, plant, capture = _start_lockstep(
        graph, RunSpec(scenario, "adaptive", settings_, "lockstep", name="fuzz")
    )
    injector = graph.add(rclpy.create_node("injector", context=graph.context))
    pubs = {
        topic: injector.create_publisher(msg_type, topic, DEEP_QOS)
        for topic, msg_type in (
            (wire.JOINT_STATES, JointState),
            (wire.SETPOINT, JointTrajectory),
            (wire.FEEDFORWARD_TORQUE, JointState),
            (wire.FEEDBACK_TORQUE, JointState),
            (wire.TRAJECTORY_GOAL, JointTrajectory),
        )
    }
    wanted = {
        wire.JOINT_STATES: 3,  # ff, fb, capture
        wire.SETPOINT: 2,  # fb, capture
        wire.FEEDFORWARD_TORQUE: 2,  # plant, capture
        wire.FEEDBACK_TORQUE: 2,
        wire.TRAJECTORY_GOAL: 1,  # ff
    }
    graph.spin_until(
        lambda: all(pubs[t].get_subscription_count() >= c for t, c in wanted.items()),
        what="discovery of the injector",
    )
    # (node, counter key) -> expected value; every counter starts at 0 in a clean run.
    expected: dict[tuple[str, str], int] = {}
    nodes = {"ff": ff, "fb": fb, "plant": plant}
    receivers = {
        wire.JOINT_STATES: ("ff", "fb"),
        wire.SETPOINT: ("fb",),
        wire.FEEDFORWARD_TORQUE: ("plant",),
        wire.FEEDBACK_TORQUE: ("plant",),
        wire.TRAJECTORY_GOAL: ("ff",),
    }
    injected = {"n": 0}

    def got(who: str, key: str) -> int:
        return counter(nodes[who], key)

    @settings(
        max_examples=350,
        deadline=None,
        database=None,
        phases=(Phase.generate,),
        suppress_health_check=list(HealthCheck),
    )
    @given(batch=BATCH)
    def inject(batch: dict[str, list[Garbage]]) -> None:
        k = plant.k
        for topic, garbage in batch.items():
            for g in garbage:
                pubs[topic].publish(g.build(k))
                injected["n"] += 1
                kind = g.expected_counter(k)
                for who in receivers[topic]:
                    for key in (f"{kind}.{topic}", kind):
                        if key != "out_of_order":
                            expected[(who, key)] = expected.get((who, key), 0) + 1
        deadline = time.monotonic() + 10.0
        while any(got(w, key) < v for (w, key), v in expected.items()):
            assert time.monotonic() < deadline, {
                f"{w}:{key}": (got(w, key), v)
                for (w, key), v in expected.items()
                if got(w, key) != v
            }
            graph.executor.spin_once(timeout_sec=0.005)
        for (who, key), value in expected.items():
            if key.startswith("out_of_order"):
                assert got(who, key) >= value, (who, key)
            else:
                assert got(who, key) == value, (who, key, got(who, key), value, batch)
        for node in nodes.values():
            assert errors(node) == 0, node.diagnostics.counters

    inject()
    graph.spin_until(lambda: plant.done, timeout_s=60, what="the end of the run")
    assert plant.exit_code == 0, plant.diagnostics.message
    offline = run_offline(scenario, "adaptive", settings_)
    # the final sample's answers may still be on their way to the capture
    graph.spin_until(lambda: has_whole_run(capture, len(offline.t)), 30, "the last answers")
    assert injected["n"] >= 2000, injected
    assert_all_finite(capture)
    compare_with_offline(capture, offline)
    # The counters are on a real /diagnostics message (published once a second).
    graph.spin_until(
        lambda: all(
            int(capture.diagnostics.get(name, {}).get("rejected", 0)) > 0
            for name in ("feedforward_node", "feedback_node", "plant_node")
        ),
        timeout_s=5,
        what="rejected counters on /diagnostics",
    )
    for name, node in (("feedforward_node", ff), ("feedback_node", fb), ("plant_node", plant)):
        published = capture.diagnostics[name]
        assert 0 < int(published["rejected"]) <= counter(node, "rejected")
        assert any(key.startswith("rejected.") for key in published)


# ----------------------------------------------------------------------------------------------
# The controllers driven by a stand-in plant: stale/duplicate stamps, extreme goals
# ----------------------------------------------------------------------------------------------
def test_stale_duplicate_and_off_grid_joint_states(graph):
    """ff and fb: a re-sent sample is answered from the cache (identical output), an older one,
    a negative one and one off the grid are rejected and counted; nothing else is published."""
    params = RunSpec(paper_scenario("a"), "pd").node_parameters()
    ctx = graph.context
    ff = graph.add(
        FeedforwardNode(context=ctx, parameter_overrides=overrides(params["feedforward_node"]))
    )
    fb = graph.add(
        FeedbackNode(context=ctx, parameter_overrides=overrides(params["feedback_node"]))
    )
    plant = StandInPlant(graph)
    graph.spin_until(lambda: plant.js_pub.get_subscription_count() >= 2)
    graph.spin_until(lambda: plant.node.count_publishers(wire.FEEDBACK_TORQUE) >= 1)
    q0 = np.deg2rad(paper_scenario("a").q_start_deg)

    def answered(stamp: int, times: int = 1) -> bool:
        return all(
            plant.count(t, stamp) >= times
            for t in (wire.SETPOINT, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE)
        )

    for k in (0, 1):
        plant.joint_state(k * T_NS, q0, np.zeros(N))
        graph.spin_until(lambda k=k: answered(k * T_NS))
    # Sample 1 again, with other values: a resend; both answer from their cache.
    plant.joint_state(T_NS, q0 + 0.5, np.ones(N))
    graph.spin_until(lambda: answered(T_NS, 2))
    for topic in (wire.SETPOINT, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE):
        first, again = plant.got[topic][T_NS]
        assert first == again, topic
    # Older than the last sample, negative, off the grid: rejected by both.
    for stamp in (0, -T_NS, T_NS + T_NS // 2):
        plant.joint_state(stamp, q0, np.zeros(N))
    graph.spin_until(lambda: counter(ff, "rejected.joint_states") == 3)
    graph.spin_until(lambda: counter(fb, "rejected.joint_states") == 3)
    plant.joint_state(2 * T_NS, q0, np.zeros(N))
    graph.spin_until(lambda: answered(2 * T_NS))
    graph.spin_for(0.1)
    for node in (ff, fb):
        assert counter(node, "resent") == 1
        assert counter(node, "rejected") == 3
        assert errors(node) == 0
    assert sorted(plant.got[wire.FEEDBACK_TORQUE]) == [0, T_NS, 2 * T_NS]
    # The feedforward answers sample k with k + 1 as well (lookahead 1).
    assert sorted(plant.got[wire.SETPOINT]) == [0, T_NS, 2 * T_NS, 3 * T_NS]


def test_fuzz_extreme_goals_never_put_a_non_finite_value_on_the_wire(graph):
    """Valid-looking but absurd goals (hypothesis): each is rejected or run; every joint state
    is answered with finite set points and torques (ff), and fb either answers with a finite
    torque or refuses a torque beyond the wire's bound (counted) -- nothing raises."""
    params = RunSpec(paper_scenario("a"), "pd").node_parameters()
    ctx = graph.context
    ff = graph.add(
        FeedforwardNode(context=ctx, parameter_overrides=overrides(params["feedforward_node"]))
    )
    fb = graph.add(
        FeedbackNode(context=ctx, parameter_overrides=overrides(params["feedback_node"]))
    )
    plant = StandInPlant(graph)
    graph.spin_until(lambda: plant.goal_pub.get_subscription_count() >= 1)
    graph.spin_until(lambda: plant.js_pub.get_subscription_count() >= 2)
    graph.spin_until(lambda: plant.node.count_publishers(wire.FEEDBACK_TORQUE) >= 1)
    state = {"k": 0, "q": np.deg2rad(paper_scenario("a").q_start_deg), "qd": np.zeros(N)}

    def step() -> None:
        k = state["k"]
        stamp = k * T_NS
        refused = counter(fb, "rejected.feedback_law")
        plant.joint_state(stamp, state["q"], state["qd"])
        graph.spin_until(
            lambda: (
                plant.count(wire.FEEDFORWARD_TORQUE, stamp) == 1
                and (
                    plant.count(wire.FEEDBACK_TORQUE, stamp) == 1
                    or counter(fb, "rejected.feedback_law") > refused
                )
            ),
            timeout_s=5,
            what=f"answers to sample {k}",
        )
        sp = wire.msg_to_setpoint(plant.got[wire.SETPOINT][stamp][0], NAMES)  # finite, bounded
        wire.msg_to_torque(plant.got[wire.FEEDFORWARD_TORQUE][stamp][0], NAMES)
        if plant.count(wire.FEEDBACK_TORQUE, stamp):
            wire.msg_to_torque(plant.got[wire.FEEDBACK_TORQUE][stamp][0], NAMES)
        # The arm lags the set point a little, so the feedback has something to do.
        state["q"] = np.clip(sp.q + 0.01, -1e5, 1e5)
        state["qd"] = np.clip(0.5 * sp.qd, -1e5, 1e5)
        state["k"] = k + 1

    step()

    @settings(
        max_examples=40,
        deadline=None,
        database=None,
        phases=(Phase.generate,),
        suppress_health_check=list(HealthCheck),
    )
    @given(goal=extreme_goal())
    def run(goal: JointTrajectory) -> None:
        handled = counter(ff, "goals_accepted") + counter(ff, "rejected.feedforward/trajectory")
        plant.goal_pub.publish(goal)
        graph.spin_until(
            lambda: (
                counter(ff, "goals_accepted") + counter(ff, "rejected.feedforward/trajectory")
                > handled
            ),
            timeout_s=5,
            what="the goal to be handled",
        )
        # Run until the goal (if accepted) has started and ended.
        for _ in range(200):
            step()
            queued = counter(ff, "goals_accepted") - counter(ff, "goals_started")
            rejected_late = counter(ff, "rejected.feedforward/trajectory")
            assert ff.goals.feedforward is not None
            if state["k"] >= ff.goals.feedforward.end_k() and queued <= rejected_late:
                break
        for node in (ff, fb):
            assert errors(node) == 0, node.diagnostics.counters

    run()
    assert counter(ff, "goals_accepted") > 0
    assert counter(ff, "rejected.feedforward/trajectory") > 0
    assert counter(ff, "samples") == state["k"]


# ----------------------------------------------------------------------------------------------
# The plant: stamps of torques, duplicates, torque limits
# ----------------------------------------------------------------------------------------------
def test_plant_rejects_or_ignores_torques_with_wrong_stamps_and_clips_huge_ones(graph):
    """Lockstep plant, the test playing both controllers: a torque before sample 0 is sent, in
    the future (a nominal torque: beyond the feedforward's lookahead), off the grid or negative
    is rejected; an answer to an integrated sample is ignored (stale / out of order); a second
    torque for the current sample does not replace or add to the first; a nominal torque one
    sample ahead is kept for its sample; a huge valid torque is clipped to the URDF limits and
    counted."""
    from apc_lab.scenario import build
    from apc_plant_sim.plant import Plant

    scenario = paper_scenario("a")
    params = RunSpec(scenario, "none").node_parameters()["plant_node"]
    params.update(wait_for_subscribers=2, n_samples=0, resend_s=30.0, lockstep_timeout_s=30.0)
    ctx = graph.context
    ff_pub, fb_pub, states = stand_in_controllers(graph)
    plant = graph.add(PlantNode(context=ctx, parameter_overrides=overrides(params)))
    graph.spin_until(
        lambda: ff_pub.get_subscription_count() >= 1 and fb_pub.get_subscription_count() >= 1
    )

    ff_key, fb_key = f"rejected.{wire.FEEDFORWARD_TORQUE}", f"rejected.{wire.FEEDBACK_TORQUE}"
    # Before the plant sent sample 0 (it waits for a second listener): nobody computed this.
    torque(ff_pub, 0, np.zeros(N))
    graph.spin_until(lambda: counter(plant, ff_key) == 1)
    assert not plant.started
    graph.add(rclpy.create_node("listener", context=ctx)).create_subscription(
        JointState, wire.JOINT_STATES, lambda m: None, DEEP_QOS
    )
    graph.spin_until(lambda: 0 in states, what="sample 0")

    built = build(scenario)
    reference = Plant(built.plant_robot, built.plant_config, np.deg2rad(scenario.q_start_deg))
    a = np.array([5.0, 40.0, 10.0])
    # Sample 0: two different feedforward torques; the first stands, nothing is added.
    torque(ff_pub, 0, a)
    torque(ff_pub, 0, 3.0 * a)
    graph.spin_until(lambda: counter(plant, f"duplicate.{wire.FEEDFORWARD_TORQUE}") == 1)
    torque(fb_pub, 0, np.zeros(N))
    graph.spin_until(lambda: T_NS in states, what="sample 1")
    step = reference.step(a)
    got = wire.joint_state_to_arrays(
        states[T_NS], NAMES, require=("position", "velocity", "effort")
    )
    np.testing.assert_array_equal(got.position, step.q)
    np.testing.assert_array_equal(got.velocity, step.qd)
    np.testing.assert_array_equal(got.effort, a)

    # Sample 1: too far ahead, off grid, negative -> rejected; answers to sample 0 -> stale.
    for stamp in ((wire.MAX_LOOKAHEAD + 2) * T_NS, T_NS + 5, -T_NS):
        torque(ff_pub, stamp, a)
    torque(ff_pub, 0, a)
    torque(fb_pub, 2 * T_NS, np.zeros(N))  # a feedback torque is never ahead of the state
    torque(fb_pub, 0, np.zeros(N))
    graph.spin_until(lambda: counter(plant, f"stale.{wire.FEEDBACK_TORQUE}") == 1)
    graph.spin_until(lambda: counter(plant, ff_key) == 4)
    graph.spin_until(lambda: counter(plant, fb_key) == 1)
    graph.spin_until(lambda: counter(plant, f"stale.{wire.FEEDFORWARD_TORQUE}") == 1)
    torque(ff_pub, T_NS, a)
    torque(fb_pub, T_NS, np.zeros(N))
    graph.spin_until(lambda: 2 * T_NS in states, what="sample 2")
    reference.step(a)

    # Sample 2: an answer to sample 0 is out of order; the rejected future torque for sample 2
    # was not kept: with the nominal torque missing the plant does not step.
    torque(ff_pub, 0, a)
    torque(fb_pub, 2 * T_NS, np.zeros(N))
    graph.spin_until(lambda: counter(plant, f"out_of_order.{wire.FEEDFORWARD_TORQUE}") == 1)
    graph.spin_for(0.3)
    assert plant.k == 2
    # A huge but valid torque is clipped to the effort limits, and counted.
    huge = np.array([1e5, -1e5, 1e5])
    torque(ff_pub, 2 * T_NS, huge)
    torque(ff_pub, 3 * T_NS, a)  # one sample ahead, as the feedforward node sends it: kept
    graph.spin_until(lambda: 3 * T_NS in states, what="sample 3")
    limit = built.plant_robot.effort_limit
    applied = wire.joint_state_to_arrays(states[3 * T_NS], NAMES).effort
    np.testing.assert_array_equal(applied, np.sign(huge) * limit)
    step = reference.step(huge)
    np.testing.assert_array_equal(
        wire.joint_state_to_arrays(states[3 * T_NS], NAMES).position, step.q
    )
    assert counter(plant, "saturated_samples") == 1
    assert all(counter(plant, f"saturated.{name}") == 1 for name in NAMES)
    # Sample 3 needs only its feedback torque now: the nominal one came ahead.
    torque(fb_pub, 3 * T_NS, np.zeros(N))
    graph.spin_until(lambda: 4 * T_NS in states, what="sample 4")
    np.testing.assert_array_equal(
        wire.joint_state_to_arrays(states[4 * T_NS], NAMES).position, reference.step(a).q
    )
    assert counter(plant, fb_key) == 1
    assert counter(plant, "rejected") == 5
    assert errors(plant) == 0


#: Period of the real-time plant the test below steps by hand on its own /clock (0.1 s).
STEPPED_PERIOD_NS = 100_000_000


def test_realtime_plant_applies_a_nominal_torque_sent_ahead_at_its_own_sample(graph):
    """Real time on a ``/clock`` the test moves, the test playing both controllers: u_n(1),
    sent with u_n(0) (the feedforward's lookahead), waits for sample 1; sample 0 applies
    u_n(0). The clock moves a period once the plant holds the torques sent, so nothing here
    depends on how fast the machine delivers them."""
    params = RunSpec(paper_scenario("a"), "none", mode="realtime").node_parameters()["plant_node"]
    params.update(wait_for_subscribers=1, n_samples=0, period=0.1, step=0.025, watchdog_s=1.0)
    params.update(use_sim_time=True, publish_clock=False)
    ff_pub, fb_pub, states = stand_in_controllers(graph)
    clock_node = graph.add(rclpy.create_node("test_clock", context=graph.context))
    clock_pub = clock_node.create_publisher(ClockMsg, wire.CLOCK, wire.CLOCK_QOS)
    plant = graph.add(PlantNode(context=graph.context, parameter_overrides=overrides(params)))
    now_ns = 0

    def tick_until(done, what: str, advance: bool = True) -> None:
        """Move the clock a period (or keep saying the time), until ``done()``: /clock is best
        effort, a message may be dropped."""
        nonlocal now_ns
        deadline = time.monotonic() + 30
        while not done():
            assert time.monotonic() < deadline, what
            if advance:
                now_ns += STEPPED_PERIOD_NS
            clock_pub.publish(ClockMsg(clock=wire.ns_to_stamp(now_ns)))
            graph.spin_for(0.02)

    # The plant waits for its peers, then sends sample 0 at a tick.
    tick_until(lambda: 0 in states, "sample 0")

    def step_once_held(*held: tuple[Source, int], k: int) -> np.ndarray:
        """Tick once the plant holds ``held``; the torque joint state ``k`` reports applied."""
        nonlocal now_ns
        graph.spin_until(lambda: all(plant.intake.holds(*h) for h in held), what=f"{held}")
        now_ns += STEPPED_PERIOD_NS
        stamp = k * STEPPED_PERIOD_NS
        tick_until(lambda: stamp in states, f"sample {k}", advance=False)
        return wire.joint_state_to_arrays(states[stamp], NAMES, require=("effort",)).effort

    a, b = np.array([5.0, 40.0, 10.0]), np.array([-5.0, 30.0, 2.0])
    torque(ff_pub, 0, a)
    torque(ff_pub, STEPPED_PERIOD_NS, b)  # ahead
    torque(fb_pub, 0, np.zeros(N))
    held = ((Source.NOMINAL, 0), (Source.NOMINAL, STEPPED_PERIOD_NS), (Source.FEEDBACK, 0))
    np.testing.assert_array_equal(step_once_held(*held, k=1), a)
    torque(fb_pub, STEPPED_PERIOD_NS, np.ones(N))
    np.testing.assert_array_equal(
        step_once_held((Source.FEEDBACK, STEPPED_PERIOD_NS), k=2), b + 1.0
    )
    assert counter(plant, "rejected") == 0 and counter(plant, "watchdog_trips") == 0
    assert counter(plant, "late_samples") == 0
    assert errors(plant) == 0


def test_torque_limits_hold_in_a_recorded_run(tmp_path):
    """PD with absurd gains in a lockstep run: every applied torque in the recording is within
    the URDF's effort limits, and saturation is on the recorded /diagnostics."""
    from apc_lab.experiment import run_in_process
    from apc_recording.runs import load_run

    spec = RunSpec(
        paper_scenario("c", hold_s=0.2), "pd", {"kp": 1e6, "kv": 1e4}, "lockstep", name="sat"
    )
    outcome = run_in_process(spec, tmp_path, progress=False, timeout_s=60)
    assert outcome.ok, outcome.message
    run = load_run(outcome.path)
    limit = ROBOT.effort_limit
    effort = run.applied[1:]
    assert np.all(np.isfinite(effort))
    assert np.all(np.abs(effort) <= limit)
    saturated_rows = np.any(np.abs(effort) == limit, axis=1)
    assert saturated_rows.sum() > 10
    plant_status = recorded_diagnostics(outcome.path).get("plant_node")
    assert plant_status is not None, "the plant's final /diagnostics was not recorded"
    assert int(plant_status["saturated_samples"]) == saturated_rows.sum()
    assert any(int(plant_status.get(f"saturated.{name}", 0)) > 0 for name in NAMES)


# ----------------------------------------------------------------------------------------------
# 2. Runtime parameters of the feedback node, end to end through the parameter service (each
#    rule: test_feedback_node.py; the stamp rules: test_sampling.py)
# ----------------------------------------------------------------------------------------------


def test_pd_gains_change_at_run_time_and_bad_values_are_refused(graph):
    rig = ParameterRig(graph, "pd")
    q_d, qd_d = np.array([0.2, -0.3, 0.4]), np.array([0.1, 0.0, -0.1])
    q, qd = q_d - np.array([0.01, -0.02, 0.005]), qd_d.copy()
    du0 = rig.sample(q, qd, q_d, qd_d, np.zeros(N))
    np.testing.assert_array_equal(du0, 100.0 * (q_d - q) + 20.0 * (qd_d - qd))
    assert all(r.successful for r in rig.set(Parameter("gains.kp", value=200.0)))
    du1 = rig.sample(q, qd, q_d, qd_d, np.zeros(N))
    np.testing.assert_array_equal(du1, 2.0 * du0)  # the P term doubled (qd = qd_d)
    # An integer is fine for a double (what `ros2 param set ... gains.kv 40` sends).
    assert all(r.successful for r in rig.set(Parameter("gains.kv", value=40)))
    qd = qd_d + 0.05
    du2 = rig.sample(q, qd, q_d, qd_d, np.zeros(N))
    np.testing.assert_array_equal(du2, 200.0 * (q_d - q) + 40.0 * (qd_d - qd))
    # Refused, each with a reason naming the parameter; the law keeps its gains.
    assert_refused(rig.set(Parameter("gains.kp", value=-1.0)), "gains.kp", "out of range")
    assert_refused(rig.set(Parameter("gains.kp", value="fast")), "gains.kp", "must be a number")
    for name, value in (
        ("period", 0.02),
        ("controller", "adaptive"),
        ("adaptive.rho", 0.5),
        ("robot_description_path", "other.urdf"),
        ("inertia_error", [0.0, 0.0, 0.0]),
    ):
        assert_refused(rig.set(Parameter(name, value=value)), name, "read-only")
    np.testing.assert_array_equal(rig.sample(q, qd, q_d, qd_d, np.zeros(N)), du2)
    assert rig.fb.get_parameter("gains.kp").value == 200.0
    # Gains that make du exceed the wire's bound: the node publishes nothing and counts it.
    assert all(r.successful for r in rig.set(Parameter("gains.kp", value=1e9)))
    assert rig.sample(q, qd, q_d, qd_d, np.zeros(N)) is None
    assert counter(rig.fb, "rejected.feedback_law") == 1
    assert all(r.successful for r in rig.set(Parameter("gains.kp", value=200.0)))
    np.testing.assert_array_equal(rig.sample(q, qd, q_d, qd_d, np.zeros(N)), du2)
    assert counter(rig.fb, "parameter_updates") == 4
    assert errors(rig.fb) == 0


# ----------------------------------------------------------------------------------------------
# 3. Bad configuration: one line on stderr naming the parameter, exit code 2
# ----------------------------------------------------------------------------------------------
FF, FB, PLANT = "feedforward_node", "feedback_node", "plant_node"
BROKEN_URDF = '<robot name="x"><link name="a"/><joint name="j" type="revolute"><parent link="a"/>'
NO_JOINT_URDF = '<robot name="x"><link name="a"/></robot>'
BAD_CONFIGS = [
    # (id, node, arguments after --ros-args, parameter named, words of the reason)
    ("period_zero_ff", FF, ["-p", "period:=0.0"], "period", "out of range"),
    ("period_zero_plant", PLANT, ["-p", "period:=0.0"], "period", "out of range"),
    ("step_not_dividing", PLANT, ["-p", "step:=0.003"], "step", "divide"),
    ("r_zero", FB, ["-p", "adaptive.r:=0.0"], "adaptive.r", "out of range"),
    ("r_wrong_type", FB, ["-p", "adaptive.r:=small"], "adaptive.r", "must be a number"),
    ("rho_zero", FB, ["-p", "adaptive.rho:=0.0"], "adaptive.rho", "out of range"),
    ("controller", FB, ["-p", "controller:=lqr"], "controller", "must be one of"),
    ("forgetting", FB, ["-p", "adaptive.forgetting:=bogus"], "adaptive.forgetting", "bogus"),
    ("mode", PLANT, ["-p", "mode:=fast"], "mode", "must be one of"),
    (
        "sim_time_lockstep",
        PLANT,
        ["-p", "mode:=lockstep", "-p", "use_sim_time:=true"],
        "use_sim_time",
        "lockstep owns time",
    ),
    ("sim_time_own_clock", PLANT, ["-p", "use_sim_time:=true"], "publish_clock", "must be false"),
    (
        "urdf_missing",
        FB,
        ["-p", "robot_description_path:=/nonexistent/arm.urdf"],
        "robot_description_path",
        "arm.urdf",
    ),
    (
        "urdf_broken_file",
        PLANT,
        ["-p", "robot_description_path:={broken}"],
        "robot_description_path",
        "XML",
    ),
    ("urdf_broken_string", FF, ["-p", "robot_description:=<robot"], "robot_description", "XML"),
    (
        "urdf_no_joint",
        FF,
        ["-p", "robot_description_path:={no_joint}"],
        "robot_description_path",
        "joint",
    ),
    ("lock_joints", FF, ["-p", "lock_joints:=[nope]"], "lock_joints", "nope"),
    ("inertia_error_ff", FF, ["-p", "inertia_error:=[0.1]"], "inertia_error", "needs 3 values"),
    ("inertia_error_fb", FB, ["-p", "inertia_error:=[0.1, 0.1]"], "inertia_error", "needs 3"),
    ("armature_fb", FB, ["-p", "armature:=[0.1, -0.1, 0.1]"], "armature", ">= 0"),
    ("goal_length", FF, ["-p", "move.goal_deg:=[1.0]"], "move.goal_deg", "needs 3 values"),
    ("q_initial_length", PLANT, ["-p", "q_initial_deg:=[1.0]"], "q_initial_deg", "needs 3"),
    ("payload_frame", PLANT, ["-p", "payload.frame:=nope"], "payload.frame", "nope"),
    (
        "payload_frame_loaded",
        PLANT,
        ["-p", "payload.mass_kg:=2.0", "-p", "payload.frame:=nope"],
        "payload.frame",
        "nope",
    ),
    ("payload_com", PLANT, ["-p", "payload.com_m:=[0.0]"], "payload.com_m", "3"),
    ("payload_mass", PLANT, ["-p", "payload.mass_kg:=-1.0"], "payload.mass_kg", "out of range"),
]


@pytest.fixture(scope="module")
def bad_config_runs(tmp_path_factory):
    """Start every bad configuration at once (a few at a time); collect exit code and stderr."""
    from concurrent.futures import ThreadPoolExecutor

    base = tmp_path_factory.mktemp("urdf")
    files = {"broken": base / "broken.urdf", "no_joint": base / "no_joint.urdf"}
    files["broken"].write_text(BROKEN_URDF)
    files["no_joint"].write_text(NO_JOINT_URDF)

    def run(case: tuple) -> tuple[int, str]:
        _, node, args, _, _ = case
        args = [a.format(**{k: str(v) for k, v in files.items()}) for a in args]
        proc = subprocess.run(
            [sys.executable, "-m", NODE_MODULES[node], "--ros-args", *args],
            capture_output=True,
            text=True,
            timeout=60,
            env=os.environ.copy(),
        )
        return proc.returncode, proc.stderr

    with ThreadPoolExecutor(max_workers=8) as pool:
        return dict(zip((c[0] for c in BAD_CONFIGS), pool.map(run, BAD_CONFIGS), strict=True))


@pytest.mark.parametrize("case", BAD_CONFIGS, ids=[c[0] for c in BAD_CONFIGS])
def test_bad_configuration_stops_the_node_with_one_line(bad_config_runs, case):
    name, node, _, parameter, reason = case
    code, stderr = bad_config_runs[name]
    assert code == 2, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith(f"{node}: parameter '{parameter}': "), lines[0]
    assert reason in lines[0], lines[0]
