"""What the test_bag_* modules share: apc's messages at the sizes that matter, their exact CDR,
a short run written to a bag, and field-by-field comparison across readers.

The writer takes raw CDR bytes, as a ``raw=True`` subscription delivers them (the bytes rosbag2
records); the tests that need no DDS make the same bytes with rosbags' serializer (:func:`_cdr`,
checked against raw subscription bytes in ``test_bag_cdr``). Not a test module: the test modules
import it by name (pytest puts this directory on ``sys.path``).
"""

from __future__ import annotations

import array

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import serialize_message
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Empty, Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire
from apc_recording import bag
from apc_recording.bag import BagWriter

T_NS = 10_000_000  # 10 ms
#: rosbags' ROS 2 Jazzy types: the serializer the tests make exact CDR bytes with.
JAZZY = get_typestore(Stores.ROS2_JAZZY)


def _cdr(msg) -> bytes:
    """The CDR bytes of ``msg`` that a ``raw=True`` subscription receives (same length).

    ``serialize_message`` sizes its buffer by an estimate that can be a few bytes long; rosbags
    reads the message from it and serializes it again at its exact size. Alignment gaps come out
    zeroed here (rclpy leaves them as they are), so only decoded values compare equal.
    """
    type_name = bag.message_type_name(msg)
    estimate = bytes(serialize_message(msg))
    msgdef = JAZZY.get_msgdef(type_name)
    decoded, _ = msgdef.deserialize_cdr_le(estimate[4:], 0, msgdef.cls, JAZZY)
    return bytes(JAZZY.serialize_cdr(decoded, type_name))


def _write(writer: BagWriter, topic: str, msg, log_time_ns: int) -> None:
    """Write ``msg`` on ``topic`` (added with no QoS the first time), as its exact CDR."""
    writer.add_topic(topic, type(msg))
    writer.write(topic, _cdr(msg), log_time_ns)


def _names(n: int) -> list[str]:
    return [f"joint_{i + 1}" for i in range(n)]


def _joint_state(n: int, k: int = 1, effort: bool = True) -> JointState:
    rng = np.random.default_rng(k)
    return wire.arrays_to_joint_state(
        k * T_NS,
        _names(n),
        rng.normal(size=n),
        rng.normal(size=n),
        rng.normal(size=n) if effort else None,
    )


def _goal(n: int) -> JointTrajectory:
    points = [
        JointTrajectoryPoint(
            positions=[0.1 * i] * n, time_from_start=wire.ns_to_duration(i * 10**9)
        )
        for i in (1, 2, 3)
    ]
    return JointTrajectory(joint_names=_names(n), points=points)


def _diagnostics(k: int = 1) -> DiagnosticArray:
    msg = DiagnosticArray()
    msg.header.stamp = wire.ns_to_stamp(k * T_NS)
    msg.status = [
        DiagnosticStatus(
            level=DiagnosticStatus.WARN,
            name="plant_node: loop",
            message="late torque",
            hardware_id="sim",
            values=[KeyValue(key="late", value=str(k)), KeyValue(key="missing", value="0")],
        )
    ]
    return msg


def _clock(k: int = 1) -> Clock:
    return Clock(clock=wire.ns_to_stamp(k * T_NS))


def _estimate(n: int, k: int = 1) -> Float64MultiArray:
    rng = np.random.default_rng(k)
    p = 2 * n
    return wire.estimate_to_msg(
        rng.normal(size=(p, p)),
        rng.normal(size=(p, n)),
        rng.normal(size=p),
        3.0,
        0.5,
        stamp_ns=k * T_NS,
    )


def _setpoint(n: int, k: int = 1) -> JointTrajectory:
    v = np.linspace(-1.0, 1.0, n) * k
    return wire.setpoint_to_msg(k * T_NS, _names(n), v, 2 * v, 3 * v, 4 * v, k * T_NS)


#: The messages apc sends, at the sizes that matter (n = 3, 6, 7 joints), plus edge cases of CDR
#: sizing. Value: (message, bytes serialize_message adds beyond the exact CDR).
SAMPLES = {
    **{f"joint_states n={n}": (_joint_state(n), 0) for n in (3, 6, 7)},
    "joint_states n=7 no effort": (_joint_state(7, effort=False), 4),
    **{
        f"torque n={n}": (wire.torque_to_msg(T_NS, _names(n), np.arange(n) + 0.5), 8)
        for n in (3, 6, 7)
    },
    **{f"setpoint n={n}": (_setpoint(n), 0) for n in (3, 6, 7)},
    "goal n=6 positions only": (_goal(6), 44),
    **{f"estimate n={n}": (_estimate(n), 0) for n in (3, 6, 7)},
    "clock": (_clock(), 0),
    "diagnostics": (_diagnostics(), 0),
    "diagnostics empty": (DiagnosticArray(), 0),
    "std_msgs Empty": (Empty(), 3),
    "std_msgs String odd": (String(data="abc"), 0),
}


def _plain(value):
    """Normalise rclpy / mcap_ros2 / rosbags field values for comparison."""
    if isinstance(value, bytes) and len(value) == 1:
        return value[0]  # rclpy's `byte` is bytes, the others give an int
    if isinstance(value, (array.array, np.ndarray, list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def assert_same(ros_msg, other, path="msg") -> None:
    """Every field of the rclpy message equals the same field of ``other`` (any reader's)."""
    for name in ros_msg.get_fields_and_field_types():
        a, b = getattr(ros_msg, name), getattr(other, name)
        here = f"{path}.{name}"
        if hasattr(a, "get_fields_and_field_types"):
            assert_same(a, b, here)
        elif isinstance(a, list) and a and hasattr(a[0], "get_fields_and_field_types"):
            assert len(a) == len(b), here
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                assert_same(x, y, f"{here}[{i}]")
        else:
            assert _plain(a) == _plain(b), here


N = 6


def _run_messages(samples: int = 5) -> list[tuple[str, object, int, int]]:
    """(topic, message, log_time_ns, publish_time_ns) of a short run on every apc topic."""
    out = []
    goal = _goal(N)
    out.append((wire.TRAJECTORY_GOAL, goal, 0, 0))
    for k in range(samples):
        t = k * T_NS
        out.append((wire.CLOCK, _clock(k), t, t))
        out.append((wire.JOINT_STATES, _joint_state(N, k), t, t + 1))
        out.append((wire.SETPOINT, _setpoint(N, k), t, t + 2))
        out.append(
            (wire.FEEDFORWARD_TORQUE, wire.torque_to_msg(t, _names(N), np.ones(N) * k), t, t)
        )
        out.append((wire.FEEDBACK_TORQUE, wire.torque_to_msg(t, _names(N), -np.ones(N) * k), t, t))
        out.append((wire.ESTIMATE, _estimate(N, k), t, t))
        out.append((wire.DIAGNOSTICS, _diagnostics(k), t, t))
    return out


def _write_run(target, **kwargs) -> list[tuple[str, object, int, int, bytes]]:
    """Write a short run; return (topic, message, log time, publish time, bytes written).

    The bytes are kept: alignment gaps inside a CDR message are not zeroed by rclpy, so two
    serialisations of one message may differ there (never in a decoded value).
    """
    messages = []
    with BagWriter(target, custom_data={"case": "c"}, **kwargs) as writer:
        for spec in wire.TOPICS:
            writer.add_topic(spec.name, spec.msg_type, spec.qos)
        for sequence, (topic, msg, log_time, publish_time) in enumerate(_run_messages()):
            data = _cdr(msg)
            writer.write(topic, data, log_time, publish_time, sequence)
            messages.append((topic, msg, log_time, publish_time, data))
    return messages
