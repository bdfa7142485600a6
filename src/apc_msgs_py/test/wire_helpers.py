"""What the test_wire_* modules share: the joint names, a permutation of them, joint-state
messages, a serialise/deserialise round trip, a field mutator for rejection cases, NaN and Inf.

Not a test module: the test modules import it by name (pytest puts this directory on
``sys.path``).
"""

from __future__ import annotations

from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

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


def _mutate(field, value):
    def apply(msg):
        setattr(msg, field, value)
        return msg

    return apply


NAN, INF = float("nan"), float("inf")
