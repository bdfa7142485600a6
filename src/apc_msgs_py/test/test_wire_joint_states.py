"""The wire contract, JointState <-> numpy: joint states and torques.

Round trips check every field and reordering by joint name; every rejection raises WireError
whose text names the field.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from sensor_msgs.msg import JointState
from wire_helpers import INF, NAMES, NAN, PERM, _good_js, _js, _mutate, _wire_round_trip

import apc_msgs_py as wire
from apc_msgs_py import WireError


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
