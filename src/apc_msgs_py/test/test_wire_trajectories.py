"""The wire contract, JointTrajectory <-> numpy: the set point (one point) and the trajectory
goal (waypoints).

Round trips check every field and reordering by joint name; every rejection raises WireError
whose text names the field.
"""

from __future__ import annotations

import numpy as np
import pytest
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from wire_helpers import INF, NAMES, NAN, PERM, _mutate, _wire_round_trip

import apc_msgs_py as wire
from apc_msgs_py import WireError

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
