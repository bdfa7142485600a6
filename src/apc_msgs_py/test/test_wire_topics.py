"""The wire contract, names and time: topic names, the topic table, the QoS constants, and
stamps (exact integer nanoseconds, conversions, a malformed stamp rejected).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory
from wire_helpers import NAMES, _good_js

import apc_msgs_py as wire
from apc_msgs_py import WireError


# ----------------------------------------------------------------------------------------------
# Names and QoS
# ----------------------------------------------------------------------------------------------
def test_topic_names_are_relative_except_clock_and_diagnostics():
    relative = [
        wire.JOINT_STATES,
        wire.SETPOINT,
        wire.FEEDFORWARD_TORQUE,
        wire.FEEDBACK_TORQUE,
        wire.ESTIMATE,
        wire.TRAJECTORY_GOAL,
    ]
    assert relative == [
        "joint_states",
        "feedforward/setpoint",
        "feedforward/torque",
        "feedback/torque",
        "feedback/estimate",
        "feedforward/trajectory",
    ]
    assert not any(name.startswith("/") for name in relative)
    assert (wire.CLOCK, wire.DIAGNOSTICS) == ("/clock", "/diagnostics")


def test_topic_table_has_every_topic_with_its_type_and_qos():
    table = {spec.name: spec for spec in wire.TOPICS}
    assert len(table) == len(wire.TOPICS) == 10
    expected = {
        wire.JOINT_STATES: (JointState, wire.CONTROL_QOS),
        wire.SETPOINT: (JointTrajectory, wire.CONTROL_QOS),
        wire.FEEDFORWARD_TORQUE: (JointState, wire.CONTROL_QOS),
        wire.FEEDBACK_TORQUE: (JointState, wire.CONTROL_QOS),
        wire.ESTIMATE: (Float64MultiArray, wire.CONTROL_QOS),
        wire.TRAJECTORY_GOAL: (JointTrajectory, wire.TRAJECTORY_GOAL_QOS),
        wire.SAMPLE: (JointState, wire.CONTROL_QOS),
        wire.ROBOT_DESCRIPTION: (String, wire.ROBOT_DESCRIPTION_QOS),
        wire.CLOCK: (Clock, wire.CLOCK_QOS),
        wire.DIAGNOSTICS: (DiagnosticArray, wire.DIAGNOSTICS_QOS),
    }
    for name, (msg_type, qos) in expected.items():
        assert table[name].msg_type is msg_type
        assert table[name].qos is qos
        assert wire.topic_spec(name) is table[name]
    assert table[wire.JOINT_STATES].type_name == "sensor_msgs/msg/JointState"
    assert table[wire.CLOCK].type_name == "rosgraph_msgs/msg/Clock"
    with pytest.raises(KeyError):
        wire.topic_spec("nope")


@pytest.mark.parametrize(
    ("qos", "reliability", "durability", "history", "depth"),
    [
        (
            wire.CONTROL_QOS,
            ReliabilityPolicy.RELIABLE,
            DurabilityPolicy.VOLATILE,
            HistoryPolicy.KEEP_LAST,
            10,
        ),
        (
            wire.TRAJECTORY_GOAL_QOS,
            ReliabilityPolicy.RELIABLE,
            DurabilityPolicy.VOLATILE,  # not TRANSIENT_LOCAL: a late joiner must not replay a goal
            HistoryPolicy.KEEP_LAST,
            10,
        ),
        (
            wire.CLOCK_QOS,
            ReliabilityPolicy.BEST_EFFORT,
            DurabilityPolicy.VOLATILE,
            HistoryPolicy.KEEP_LAST,
            1,
        ),
        (
            wire.DIAGNOSTICS_QOS,
            ReliabilityPolicy.RELIABLE,
            DurabilityPolicy.VOLATILE,
            HistoryPolicy.KEEP_LAST,
            10,
        ),
    ],
)
def test_qos_constants(qos, reliability, durability, history, depth):
    assert qos.reliability == reliability
    assert qos.durability == durability
    assert qos.history == history
    assert qos.depth == depth


def test_control_writers_keep_a_deep_history_and_best_effort_stays_as_it_is():
    deep = wire.writer_qos(wire.CONTROL_QOS)
    assert deep.depth == wire.CONTROL_WRITER_DEPTH > wire.CONTROL_QOS.depth
    assert deep.reliability == ReliabilityPolicy.RELIABLE
    assert deep.durability == DurabilityPolicy.VOLATILE  # a late joiner gets nothing old
    assert deep.history == HistoryPolicy.KEEP_LAST
    assert wire.writer_qos(wire.CLOCK_QOS) is wire.CLOCK_QOS
    assert wire.writer_qos(deep).depth == wire.CONTROL_WRITER_DEPTH


def test_with_depth_copies_every_other_policy():
    from rclpy.duration import Duration

    qos = wire.with_depth(wire.CONTROL_QOS, 5)
    assert qos.depth == wire.CONTROL_QOS.depth  # never shallower
    original = wire.with_depth(wire.CONTROL_QOS, 10)
    original.deadline = Duration(seconds=2)
    deeper = wire.with_depth(original, 50)
    assert deeper.depth == 50 and deeper.deadline == Duration(seconds=2)
    assert original.depth == 10  # a copy


# ----------------------------------------------------------------------------------------------
# Time
# ----------------------------------------------------------------------------------------------
def test_sample_stamps_are_exact_integer_ns_for_an_hour_at_100_hz():
    period = wire.seconds_to_ns(0.01)
    assert period == 10_000_000
    stamp = Time()
    for k in range(360_001):
        ns = wire.sample_stamp_ns(k, period)
        assert ns == k * 10_000_000
        wire.ns_to_stamp(ns, stamp)
        assert (stamp.sec, stamp.nanosec) == (k // 100, (k % 100) * 10_000_000)
        assert wire.stamp_to_ns(stamp) == ns
    # Why integers: the float product drifts (truncation gets thousands of samples wrong).
    assert any(int(k * 0.01 * 1e9) != k * 10_000_000 for k in range(360_001))


def test_stamp_conversions():
    assert wire.stamp_to_ns(Time(sec=3, nanosec=5)) == 3_000_000_005
    assert wire.ns_to_stamp(-1) == Time(sec=-1, nanosec=999_999_999)
    assert wire.ns_to_stamp(np.int64(7)) == Time(sec=0, nanosec=7)
    duration = wire.ns_to_duration(2_500_000_000)
    assert (duration.sec, duration.nanosec) == (2, 500_000_000)
    assert wire.duration_to_ns(duration) == 2_500_000_000
    with pytest.raises(WireError, match=r"^stamp: time must be integer"):
        wire.ns_to_stamp(1.5)
    with pytest.raises(WireError, match="int32"):
        wire.ns_to_stamp(2**31 * 10**9)
    with pytest.raises(ValueError, match="k must be >= 0"):
        wire.sample_stamp_ns(-1, 10)
    with pytest.raises(ValueError, match="period_ns must be > 0"):
        wire.sample_stamp_ns(1, 0)
    with pytest.raises(ValueError, match="integer"):
        wire.sample_stamp_ns(1, 0.01)
    with pytest.raises(ValueError, match="finite"):
        wire.seconds_to_ns(math.nan)


def test_malformed_stamp_is_rejected():
    msg = _good_js()
    msg.header.stamp.nanosec = 1_000_000_000
    with pytest.raises(WireError, match=r"^header\.stamp\.nanosec"):
        wire.joint_state_to_arrays(msg, NAMES)
