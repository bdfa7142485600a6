"""The wire contract: topic names, QoS, stamps, and every message <-> numpy conversion.

Round trips check every field; every rejection raises WireError whose text names the field.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_msgs_py import WireError

NAMES = ["j1", "j2", "j3"]
PERM = [2, 0, 1]  # message order: j3, j1, j2


def _js(names, position, velocity, effort, sec=1, nanosec=20_000_000) -> JointState:
    msg = JointState(name=list(names), position=position, velocity=velocity, effort=effort)
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    return msg


def _good_js() -> JointState:
    return _js(NAMES, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [10.0, 20.0, 30.0])


def _wire_round_trip(msg):
    """Serialise and deserialise, as a subscriber sees the message."""
    return deserialize_message(serialize_message(msg), type(msg))


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


# ----------------------------------------------------------------------------------------------
# Joint states
# ----------------------------------------------------------------------------------------------
def test_joint_state_round_trip_every_field():
    q, qd, tau = np.array([0.1, -0.2, 0.3]), np.array([1.5, 2.5, -3.5]), np.array([7.0, 8.0, 9.0])
    msg = wire.arrays_to_joint_state(12_340_000_000, NAMES, q, qd, tau)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 340_000_000)
    assert list(msg.name) == NAMES
    assert list(msg.position) == q.tolist()
    assert list(msg.velocity) == qd.tolist()
    assert list(msg.effort) == tau.tolist()
    sample = wire.joint_state_to_arrays(
        _wire_round_trip(msg), NAMES, require=wire.JOINT_STATE_FIELDS
    )
    assert sample.stamp_ns == 12_340_000_000
    np.testing.assert_array_equal(sample.position, q)
    np.testing.assert_array_equal(sample.velocity, qd)
    np.testing.assert_array_equal(sample.effort, tau)


def test_joint_state_reorders_by_name():
    straight = wire.joint_state_to_arrays(_good_js(), NAMES, require=wire.JOINT_STATE_FIELDS)
    good = _good_js()
    permuted = _js(
        [NAMES[i] for i in PERM],
        [good.position[i] for i in PERM],
        [good.velocity[i] for i in PERM],
        [good.effort[i] for i in PERM],
    )
    sample = wire.joint_state_to_arrays(permuted, NAMES, require=wire.JOINT_STATE_FIELDS)
    assert sample.stamp_ns == straight.stamp_ns
    for field in wire.JOINT_STATE_FIELDS:
        np.testing.assert_array_equal(getattr(sample, field), getattr(straight, field))
    np.testing.assert_array_equal(sample.position, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(sample.velocity, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(sample.effort, [10.0, 20.0, 30.0])
    # The caller's order decides the output order.
    reversed_sample = wire.joint_state_to_arrays(permuted, NAMES[::-1])
    np.testing.assert_array_equal(reversed_sample.position, [0.3, 0.2, 0.1])


def test_joint_state_arrays_do_not_alias_the_message():
    msg = _good_js()
    sample = wire.joint_state_to_arrays(msg, NAMES)
    sample.position[0] = 99.0
    assert msg.position[0] == 0.1


def test_optional_effort_is_none_when_empty_and_checked_when_present():
    msg = _js(NAMES, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [])
    assert wire.joint_state_to_arrays(msg, NAMES).effort is None
    with pytest.raises(WireError, match=r"^effort: length 0, expected 3"):
        wire.joint_state_to_arrays(msg, NAMES, require=("position", "velocity", "effort"))
    bad = _js(NAMES, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0], [1.0])
    with pytest.raises(WireError, match=r"^effort: length 1, expected 0 or 3"):
        wire.joint_state_to_arrays(bad, NAMES)
    with pytest.raises(ValueError, match="require"):
        wire.joint_state_to_arrays(msg, NAMES, require=("torque",))


def test_extra_joints_only_when_allowed():
    msg = _js([*NAMES, "gripper"], [0.1, 0.2, 0.3, 9.0], [1.0, 2.0, 3.0, 9.0], [])
    with pytest.raises(WireError, match=r"^name: unknown joint\(s\) \['gripper'\]"):
        wire.joint_state_to_arrays(msg, NAMES)
    sample = wire.joint_state_to_arrays(msg, NAMES, allow_extra=True)
    np.testing.assert_array_equal(sample.position, [0.1, 0.2, 0.3])


def _mutate(field, value):
    def apply(msg):
        setattr(msg, field, value)
        return msg

    return apply


NAN, INF = float("nan"), float("inf")
JOINT_STATE_REJECTIONS = {
    "nan position": (_mutate("position", [0.1, NAN, 0.3]), r"^position: NaN at joint 'j2'"),
    "inf velocity": (_mutate("velocity", [1.0, 2.0, -INF]), r"^velocity: Inf at joint 'j3'"),
    "nan effort": (_mutate("effort", [NAN, 1.0, 1.0]), r"^effort: NaN at joint 'j1'"),
    "unknown name": (_mutate("name", ["j1", "j2", "x"]), r"^name: missing joint\(s\) \['j3'\]"),
    "unknown extra": (
        lambda m: _js(["j1", "j2", "j3", "x"], [0.0] * 4, [0.0] * 4, []),
        r"^name: unknown joint\(s\) \['x'\]",
    ),
    "missing name": (
        lambda m: _js(["j1", "j2"], [0.0] * 2, [0.0] * 2, []),
        r"^name: missing joint\(s\) \['j3'\]",
    ),
    "duplicated name": (
        _mutate("name", ["j1", "j2", "j1"]),
        r"^name: duplicated joint 'j1'",
    ),
    "short position": (_mutate("position", [0.1, 0.2]), r"^position: length 2, expected 3"),
    "long velocity": (_mutate("velocity", [0.0] * 4), r"^velocity: length 4, expected 3"),
    "missing velocity": (_mutate("velocity", []), r"^velocity: length 0, expected 3"),
    "empty": (lambda m: JointState(), r"^name: empty"),
    "huge": (_mutate("position", [0.1, 2e6, 0.3]), r"^position: \|2e\+06\| at joint 'j2'"),
}


@pytest.mark.parametrize("case", list(JOINT_STATE_REJECTIONS))
def test_joint_state_rejections_name_the_field(case):
    mutate, pattern = JOINT_STATE_REJECTIONS[case]
    msg = mutate(_good_js())
    with pytest.raises(WireError, match=pattern):
        wire.joint_state_to_arrays(msg, NAMES)


def test_max_abs_is_configurable():
    msg = _good_js()
    with pytest.raises(WireError, match=r"^effort: \|30\| at joint 'j3' .*exceeds max_abs 25"):
        wire.joint_state_to_arrays(msg, NAMES, max_abs=25.0)
    assert wire.joint_state_to_arrays(msg, NAMES, max_abs=30.0).effort is not None


def test_arrays_to_joint_state_reuses_msg_and_refuses_garbage():
    msg = JointState()
    out = wire.arrays_to_joint_state(10, NAMES, [1.0, 2.0, 3.0], msg=msg)
    assert out is msg
    assert list(msg.velocity) == [] and list(msg.effort) == []
    wire.arrays_to_joint_state(20, NAMES, [4.0, 5.0, 6.0], velocity=[0.0, 0.0, 0.0], msg=msg)
    assert msg.header.stamp.nanosec == 20 and list(msg.position) == [4.0, 5.0, 6.0]
    # A field-by-field copy: serialize_message's buffer can carry uninitialised padding bytes,
    # so two serialisations of one message need not be equal.
    before = copy.deepcopy(msg)
    for kwargs, pattern in [
        ({"position": [1.0, NAN, 3.0]}, r"^position: NaN at joint 'j2'"),
        ({"velocity": [1.0, 2.0]}, r"^velocity: shape \(2,\), expected \(3,\)"),
        ({"effort": [[1.0, 2.0, 3.0]]}, r"^effort: shape \(1, 3\)"),
        ({"effort": [1.0, INF, 3.0]}, r"^effort: Inf at joint 'j2'"),
        ({"position": [1.0, 2.0, 1e9]}, r"^position: \|1e\+09\|"),
        ({"position": ["a", "b", "c"]}, r"^position: not a float array"),
    ]:
        with pytest.raises(WireError, match=pattern):
            wire.arrays_to_joint_state(30, NAMES, msg=msg, **kwargs)
        assert msg == before  # a refused message is left untouched
    with pytest.raises(WireError, match=r"^name: empty"):
        wire.arrays_to_joint_state(0, [], [])
    with pytest.raises(WireError, match=r"^header\.stamp: time must be integer"):
        wire.arrays_to_joint_state(0.5, NAMES, [1.0, 2.0, 3.0])


# ----------------------------------------------------------------------------------------------
# Torques
# ----------------------------------------------------------------------------------------------
def test_torque_round_trip_and_reordering():
    msg = wire.torque_to_msg(30_000_000, NAMES, [1.0, -2.0, 3.5])
    assert list(msg.position) == [] and list(msg.velocity) == []
    assert list(msg.name) == NAMES and list(msg.effort) == [1.0, -2.0, 3.5]
    torque = wire.msg_to_torque(_wire_round_trip(msg), NAMES)
    assert torque.stamp_ns == 30_000_000
    np.testing.assert_array_equal(torque.effort, [1.0, -2.0, 3.5])
    permuted = wire.torque_to_msg(30_000_000, [NAMES[i] for i in PERM], [3.5, 1.0, -2.0])
    np.testing.assert_array_equal(wire.msg_to_torque(permuted, NAMES).effort, [1.0, -2.0, 3.5])


@pytest.mark.parametrize(
    ("msg", "pattern"),
    [
        (_js(NAMES, [0.0] * 3, [], [1.0] * 3), r"^position: a torque message carries effort only"),
        (_js(NAMES, [], [0.0] * 3, [1.0] * 3), r"^velocity: a torque message carries effort only"),
        (_js(NAMES, [], [], []), r"^effort: length 0, expected 3"),
        (_js(NAMES, [], [], [1.0, NAN, 1.0]), r"^effort: NaN at joint 'j2'"),
        (_js(["j1", "j2", "j2"], [], [], [1.0] * 3), r"^name: duplicated joint 'j2'"),
    ],
)
def test_torque_rejections(msg, pattern):
    with pytest.raises(WireError, match=pattern):
        wire.msg_to_torque(msg, NAMES)


# ----------------------------------------------------------------------------------------------
# Set point
# ----------------------------------------------------------------------------------------------
SP = {
    "q": np.array([0.1, 0.2, 0.3]),
    "qd": np.array([-1.0, 0.0, 1.0]),
    "qdd": np.array([5.0, 6.0, 7.0]),
    "u_n": np.array([11.0, -12.0, 13.0]),
}


def test_setpoint_round_trip_every_field():
    msg = wire.setpoint_to_msg(
        1_230_000_000, NAMES, SP["q"], SP["qd"], SP["qdd"], SP["u_n"], 230_000_000
    )
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (1, 230_000_000)
    assert list(msg.joint_names) == NAMES and len(msg.points) == 1
    point = msg.points[0]
    assert list(point.positions) == SP["q"].tolist()
    assert list(point.velocities) == SP["qd"].tolist()
    assert list(point.accelerations) == SP["qdd"].tolist()
    assert list(point.effort) == SP["u_n"].tolist()
    assert (point.time_from_start.sec, point.time_from_start.nanosec) == (0, 230_000_000)
    sp = wire.msg_to_setpoint(_wire_round_trip(msg), NAMES)
    assert sp.stamp_ns == 1_230_000_000
    assert sp.time_from_start_ns == 230_000_000
    for key in ("q", "qd", "qdd", "u_n"):
        np.testing.assert_array_equal(getattr(sp, key), SP[key])
    # refill in place
    again = wire.setpoint_to_msg(5, NAMES, *(v * 2 for v in SP.values()), 6, msg=msg)
    assert again is msg and list(msg.points[0].effort) == (2 * SP["u_n"]).tolist()


def test_setpoint_reorders_by_joint_names():
    names = [NAMES[i] for i in PERM]
    msg = wire.setpoint_to_msg(7, names, *(v[PERM] for v in SP.values()), 8)
    sp = wire.msg_to_setpoint(msg, NAMES)
    for key in ("q", "qd", "qdd", "u_n"):
        np.testing.assert_array_equal(getattr(sp, key), SP[key])


def _setpoint_msg() -> JointTrajectory:
    return wire.setpoint_to_msg(7, NAMES, SP["q"], SP["qd"], SP["qdd"], SP["u_n"], 8)


def _set_point_field(field, value):
    def apply(msg):
        setattr(msg.points[0], field, value)
        return msg

    return apply


SETPOINT_REJECTIONS = {
    "no point": (_mutate("points", []), r"^points: a set point has exactly one point, got 0"),
    "two points": (
        _mutate("points", [JointTrajectoryPoint(), JointTrajectoryPoint()]),
        r"^points: .* got 2",
    ),
    "nan acceleration": (
        _set_point_field("accelerations", [0.0, NAN, 0.0]),
        r"^points\[0\]\.accelerations: NaN at joint 'j2'",
    ),
    "short effort": (_set_point_field("effort", [1.0]), r"^points\[0\]\.effort: length 1"),
    "empty velocities": (_set_point_field("velocities", []), r"^points\[0\]\.velocities: length 0"),
    "inf position": (
        _set_point_field("positions", [INF, 0.0, 0.0]),
        r"^points\[0\]\.positions: Inf at joint 'j1'",
    ),
    "unknown joint": (
        _mutate("joint_names", ["j1", "j2", "zz"]),
        r"^joint_names: missing joint\(s\) \['j3'\]",
    ),
    "duplicated joint": (_mutate("joint_names", ["j1", "j1", "j3"]), r"^joint_names: duplicated"),
    "empty": (lambda m: JointTrajectory(), r"^joint_names: empty"),
    "huge effort": (_set_point_field("effort", [1e7, 0.0, 0.0]), r"^points\[0\]\.effort: \|1e\+07"),
}


@pytest.mark.parametrize("case", list(SETPOINT_REJECTIONS))
def test_setpoint_rejections_name_the_field(case):
    mutate, pattern = SETPOINT_REJECTIONS[case]
    with pytest.raises(WireError, match=pattern):
        wire.msg_to_setpoint(mutate(_setpoint_msg()), NAMES)


def test_setpoint_to_msg_refuses_garbage():
    with pytest.raises(WireError, match=r"^points\[0\]\.velocities: NaN"):
        wire.setpoint_to_msg(0, NAMES, SP["q"], [0.0, NAN, 0.0], SP["qdd"], SP["u_n"], 0)
    with pytest.raises(WireError, match=r"^points\[0\]\.effort: shape \(2,\)"):
        wire.setpoint_to_msg(0, NAMES, SP["q"], SP["qd"], SP["qdd"], [1.0, 2.0], 0)


# ----------------------------------------------------------------------------------------------
# Trajectory goal
# ----------------------------------------------------------------------------------------------
def _goal(names, times_s, positions, velocities=None, accelerations=None) -> JointTrajectory:
    msg = JointTrajectory(joint_names=list(names))
    for i, t in enumerate(times_s):
        point = JointTrajectoryPoint(positions=list(positions[i]))
        if velocities is not None:
            point.velocities = list(velocities[i])
        if accelerations is not None:
            point.accelerations = list(accelerations[i])
        point.time_from_start = wire.ns_to_duration(wire.seconds_to_ns(t))
        msg.points.append(point)
    return msg


POS = np.arange(9.0).reshape(3, 3) / 10.0
VEL = -np.arange(9.0).reshape(3, 3)
ACC = np.arange(9.0).reshape(3, 3) + 100.0


def test_waypoints_round_trip_every_field_and_reorder():
    times = [0.5, 1.25, 3.0]
    out = wire.msg_to_trajectory_goal(_wire_round_trip(_goal(NAMES, times, POS, VEL, ACC)), NAMES)
    times_s, positions, velocities, accelerations = out  # unpacks as a 4-tuple
    np.testing.assert_array_equal(times_s, times)
    np.testing.assert_array_equal(positions, POS)
    np.testing.assert_array_equal(velocities, VEL)
    np.testing.assert_array_equal(accelerations, ACC)
    permuted = _goal([NAMES[i] for i in PERM], times, POS[:, PERM], VEL[:, PERM], ACC[:, PERM])
    again = wire.msg_to_trajectory_goal(permuted, NAMES)
    for a, b in zip(again, out, strict=True):
        np.testing.assert_array_equal(a, b)


def test_waypoints_without_velocities_or_accelerations():
    out = wire.msg_to_trajectory_goal(_goal(NAMES, [1.0, 2.0, 3.0], POS), NAMES)
    assert out.velocities is None and out.accelerations is None
    np.testing.assert_array_equal(out.positions, POS)


def _goal_with(mutate):
    def build():
        msg = _goal(NAMES, [1.0, 2.0, 3.0], POS, VEL)
        mutate(msg)
        return msg

    return build


WAYPOINT_REJECTIONS = {
    "not increasing": (
        _goal_with(lambda m: setattr(m.points[2], "time_from_start", m.points[1].time_from_start)),
        r"^points\[2\]\.time_from_start: 2 s is not after points\[1\]",
    ),
    "zero first time": (
        _goal_with(lambda m: setattr(m.points[0], "time_from_start", wire.ns_to_duration(0))),
        r"^points\[0\]\.time_from_start: 0 s is not > 0",
    ),
    "mixed velocities": (
        _goal_with(lambda m: setattr(m.points[1], "velocities", [])),
        r"^points\[1\]\.velocities: given for some points and not others",
    ),
    "wrong length": (
        _goal_with(lambda m: setattr(m.points[2], "positions", [1.0, 2.0])),
        r"^points\[2\]\.positions: length 2, expected 3",
    ),
    "nan": (
        _goal_with(lambda m: setattr(m.points[1], "positions", [1.0, NAN, 2.0])),
        r"^points\[1\]\.positions: NaN at joint 'j2'",
    ),
    "inf velocity": (
        _goal_with(lambda m: setattr(m.points[0], "velocities", [INF, 0.0, 0.0])),
        r"^points\[0\]\.velocities: Inf at joint 'j1'",
    ),
    "no points": (_goal_with(lambda m: setattr(m, "points", [])), r"^points: empty"),
    "unknown joint": (
        _goal_with(lambda m: setattr(m, "joint_names", ["j1", "j2", "j9"])),
        r"^joint_names: missing joint\(s\) \['j3'\]",
    ),
    "huge": (
        _goal_with(lambda m: setattr(m.points[0], "positions", [0.0, 0.0, -5e6])),
        r"^points\[0\]\.positions: \|-5e\+06\| at joint 'j3'",
    ),
}


@pytest.mark.parametrize("case", list(WAYPOINT_REJECTIONS))
def test_waypoint_rejections_name_the_field(case):
    build, pattern = WAYPOINT_REJECTIONS[case]
    with pytest.raises(WireError, match=pattern):
        wire.msg_to_trajectory_goal(build(), NAMES)


# ----------------------------------------------------------------------------------------------
# Estimate
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [3, 6, 7])
def test_estimate_round_trip_every_field(n):
    p, m = 2 * n, n
    rng = np.random.default_rng(n)
    F, G, w = rng.normal(size=(p, p)), rng.normal(size=(p, m)), rng.normal(size=p)
    stamp = wire.sample_stamp_ns(360_000, 10_000_000)
    msg = wire.estimate_to_msg(F, G, w, 12.5, 0.25, stamp_ns=stamp)
    d0, d1 = msg.layout.dim
    assert (d0.label, d0.size, d0.stride) == ("theta_rows", p, p * (3 * n + 1))
    assert (d1.label, d1.size, d1.stride) == ("theta_cols", 3 * n + 1, 3 * n + 1)
    assert msg.layout.data_offset == 0
    assert len(msg.data) == p * (3 * n + 1) + 3
    theta = np.hstack([F, G, w[:, None]])
    np.testing.assert_array_equal(np.array(msg.data[: p * (3 * n + 1)]), theta.ravel())
    assert list(msg.data[-3:]) == [12.5, 0.25, float(stamp)]
    est = wire.msg_to_estimate(_wire_round_trip(msg))
    assert est.stamp_ns == stamp
    np.testing.assert_array_equal(est.F, F)
    np.testing.assert_array_equal(est.G, G)
    np.testing.assert_array_equal(est.w, w)
    np.testing.assert_array_equal(est.theta_t, theta)
    assert (est.trace_p, est.residual_norm) == (12.5, 0.25)
    refilled = wire.estimate_to_msg(F, G, w, 1.0, 2.0, stamp_ns=stamp + 1, msg=msg)
    assert refilled is msg and wire.msg_to_estimate(msg).stamp_ns == stamp + 1


def test_estimate_stamp_is_exact_up_to_2_pow_53():
    F, G, w = np.eye(2), np.ones((2, 1)), np.zeros(2)
    assert wire.msg_to_estimate(wire.estimate_to_msg(F, G, w, 0, 0, stamp_ns=2**53)).stamp_ns == (
        2**53
    )
    with pytest.raises(WireError, match=r"^stamp_ns: .*2\*\*53"):
        wire.estimate_to_msg(F, G, w, 0, 0, stamp_ns=2**53 + 1)
    with pytest.raises(TypeError):
        wire.estimate_to_msg(F, G, w, 0, 0)  # the sample time is required


def _estimate_msg() -> Float64MultiArray:
    return wire.estimate_to_msg(np.eye(4), np.ones((4, 2)), np.zeros(4), 1.0, 2.0, stamp_ns=10)


def _set_data(index, value):
    def apply(msg):
        data = list(msg.data)
        data[index] = value
        msg.data = data
        return msg

    return apply


ESTIMATE_REJECTIONS = {
    "labels": (
        lambda m: setattr(m.layout.dim[0], "label", "rows") or m,
        r"^layout\.dim: labels \('rows'",
    ),
    "one dim": (lambda m: setattr(m.layout, "dim", m.layout.dim[:1]) or m, r"^layout\.dim: expe"),
    "strides": (lambda m: setattr(m.layout.dim[1], "stride", 1) or m, r"^layout\.dim: strides"),
    "offset": (lambda m: setattr(m.layout, "data_offset", 1) or m, r"^layout\.data_offset: 1"),
    "short data": (
        lambda m: setattr(m, "data", list(m.data)[:-1]) or m,
        r"^data: length 30, expected 31",
    ),
    "nan theta": (_set_data(3, NAN), r"^data: NaN at index 3"),
    "inf trace": (_set_data(-3, INF), r"^data \(trace_p\): Inf"),
    "fractional stamp": (_set_data(-1, 1.5), r"^data \(stamp_ns\): 1\.5"),
    "empty": (lambda m: Float64MultiArray(), r"^layout\.dim: expected 2"),
    "bad sizes": (
        lambda m: Float64MultiArray(
            layout=_layout(4, 5),
            data=[0.0] * 23,
        ),
        r"^layout\.dim: sizes \(4, 5\)",
    ),
}


def _layout(rows, cols):
    from std_msgs.msg import MultiArrayLayout

    return MultiArrayLayout(
        dim=[
            MultiArrayDimension(label="theta_rows", size=rows, stride=rows * cols),
            MultiArrayDimension(label="theta_cols", size=cols, stride=cols),
        ]
    )


@pytest.mark.parametrize("case", list(ESTIMATE_REJECTIONS))
def test_estimate_rejections_name_the_field(case):
    mutate, pattern = ESTIMATE_REJECTIONS[case]
    with pytest.raises(WireError, match=pattern):
        wire.msg_to_estimate(mutate(_estimate_msg()))


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        ((np.ones((2, 3)), np.ones((2, 1)), np.zeros(2)), r"^F: shape \(2, 3\)"),
        ((np.eye(2), np.ones((3, 1)), np.zeros(2)), r"^G: shape \(3, 1\)"),
        ((np.eye(2), np.ones((2, 1)), np.zeros(3)), r"^w: shape \(3,\)"),
        ((np.eye(2) * NAN, np.ones((2, 1)), np.zeros(2)), r"^F: NaN"),
        ((np.eye(2), np.ones((2, 1)) * INF, np.zeros(2)), r"^G: Inf"),
    ],
)
def test_estimate_to_msg_refuses_garbage(args, pattern):
    with pytest.raises(WireError, match=pattern):
        wire.estimate_to_msg(*args, 1.0, 1.0, stamp_ns=0)
    with pytest.raises(WireError, match=r"^residual_norm: NaN"):
        wire.estimate_to_msg(np.eye(2), np.ones((2, 1)), np.zeros(2), 1.0, NAN, stamp_ns=0)
