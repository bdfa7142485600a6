"""The nodes' own output, captured in the test process by topic and stamp, and the checks run
on it: every number finite and within the wire's bound, every signal equal to the offline loop.

Messages a test injected (``header.frame_id`` :data:`~.fuzz.FUZZ`) are left out, so what is kept
is what the nodes published; the estimate carries its stamp in its data.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire

from .arm import NAMES, T_NS
from .fuzz import FUZZ, SETPOINT_FIELDS
from .graph import Graph
from .qos import DEEP_QOS

#: What the controllers publish, with its message type.
CONTROLLER_OUTPUT: tuple[tuple[str, type], ...] = (
    (wire.SETPOINT, JointTrajectory),
    (wire.FEEDFORWARD_TORQUE, JointState),
    (wire.FEEDBACK_TORQUE, JointState),
    (wire.ESTIMATE, Float64MultiArray),
)


class ByStamp:
    """Subscriptions of ``node`` to ``topics`` that keep every message the nodes published,
    by topic and stamp (``by_topic[topic][stamp_ns]``: the messages in order of arrival)."""

    def __init__(self, node: Any, topics: Iterable[tuple[str, type]]) -> None:
        self.by_topic: dict[str, dict[int, list[Any]]] = {}
        for topic, msg_type in topics:
            self.by_topic[topic] = {}
            node.create_subscription(msg_type, topic, lambda m, t=topic: self._take(t, m), DEEP_QOS)

    def _take(self, topic: str, msg: Any) -> None:
        if topic == wire.ESTIMATE:
            stamp = wire.msg_to_estimate(msg).stamp_ns
        elif msg.header.frame_id == FUZZ:
            return
        else:
            stamp = wire.stamp_to_ns(msg.header.stamp)
        self.by_topic[topic].setdefault(stamp, []).append(msg)

    def count(self, topic: str, stamp_ns: int) -> int:
        return len(self.by_topic[topic].get(stamp_ns, []))

    def first(self, topic: str) -> dict[int, Any]:
        """The first message per stamp; resends of a sample must be identical to it."""
        out = {}
        for stamp, msgs in self.by_topic[topic].items():
            for other in msgs[1:]:
                assert other == msgs[0], f"{topic} at {stamp} ns was published twice, differently"
            out[stamp] = msgs[0]
        return out


class Capture:
    """A node ``capture`` that keeps the nodes' own output on every control topic
    (``messages``) and each node's latest ``/diagnostics`` values (``diagnostics``, by node
    name)."""

    def __init__(self, graph: Graph) -> None:
        self.node = graph.add(rclpy.create_node("capture", context=graph.context))
        self._received = ByStamp(self.node, ((wire.JOINT_STATES, JointState), *CONTROLLER_OUTPUT))
        self.messages = self._received.by_topic
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.node.create_subscription(
            DiagnosticArray, wire.DIAGNOSTICS, self._diag, wire.DIAGNOSTICS_QOS
        )

    def _diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            self.diagnostics[status.name.rsplit("/", 1)[-1]] = {
                kv.key: kv.value for kv in status.values
            }

    def hears(self, *topics: str) -> bool:
        return all(self.node.count_publishers(self.node.resolve_topic_name(t)) >= 1 for t in topics)

    def first(self, topic: str) -> dict[int, Any]:
        """The first message per stamp; resends of a sample must be identical to it."""
        return self._received.first(topic)


def assert_all_finite(capture: Capture) -> None:
    """Every number every node put on the wire is finite (and within the wire's bound)."""
    for topic, by_stamp in capture.messages.items():
        for stamp, msgs in by_stamp.items():
            for msg in msgs:
                if topic == wire.ESTIMATE:
                    values = np.asarray(msg.data)
                elif topic == wire.SETPOINT:
                    values = np.concatenate(
                        [np.asarray(getattr(msg.points[0], f)) for f in SETPOINT_FIELDS]
                    )
                else:
                    values = np.concatenate(
                        [np.asarray(msg.position), np.asarray(msg.velocity), np.asarray(msg.effort)]
                    )
                assert np.all(np.isfinite(values)), f"non-finite value on {topic} at {stamp}"
                if topic != wire.ESTIMATE:  # trace(P) and the stamp may exceed 1e6
                    assert np.all(np.abs(values) <= wire.DEFAULT_MAX_ABS), (topic, stamp)


def has_whole_run(capture: Capture, n: int) -> bool:
    """Every sample of an ``n``-state lockstep run is in: its joint states, feedback torques and
    estimates, and the feedforward's outputs, one sample ahead (what
    :func:`compare_with_offline` compares)."""
    own = (wire.JOINT_STATES, wire.FEEDBACK_TORQUE, wire.ESTIMATE)
    ahead = (wire.SETPOINT, wire.FEEDFORWARD_TORQUE)
    return all(len(capture.first(t)) >= n for t in own) and all(
        len(capture.first(t)) >= n + 1 for t in ahead
    )


def compare_with_offline(capture: Capture, offline: Any) -> None:
    """Bit for bit: every captured signal equals the offline loop's (the clean run)."""
    n = len(offline.t)
    js = capture.first(wire.JOINT_STATES)
    sp = capture.first(wire.SETPOINT)
    ff = capture.first(wire.FEEDFORWARD_TORQUE)
    fb = capture.first(wire.FEEDBACK_TORQUE)
    est = capture.first(wire.ESTIMATE)
    stamps_ns = [k * T_NS for k in range(n)]
    assert sorted(js) == stamps_ns
    assert sorted(fb) == sorted(est) == stamps_ns
    # The feedforward runs one sample ahead (lookahead 1): its last set point answers no state.
    assert sorted(sp) == sorted(ff) == [*stamps_ns, n * T_NS]
    for k, stamp in enumerate(stamps_ns):
        s = wire.joint_state_to_arrays(js[stamp], NAMES)
        np.testing.assert_array_equal(s.position, offline.q[k])
        np.testing.assert_array_equal(s.velocity, offline.qd[k])
        if k == 0:
            assert s.effort is None
        else:
            np.testing.assert_array_equal(s.effort, offline.applied[k - 1])
        p = wire.msg_to_setpoint(sp[stamp], NAMES)
        for name, got in (("q_d", p.q), ("qd_d", p.qd), ("qdd_d", p.qdd), ("u_n", p.u_n)):
            np.testing.assert_array_equal(got, getattr(offline, name)[k], err_msg=f"{name}[{k}]")
        np.testing.assert_array_equal(wire.msg_to_torque(ff[stamp], NAMES).effort, offline.u_n[k])
        np.testing.assert_array_equal(wire.msg_to_torque(fb[stamp], NAMES).effort, offline.du[k])
        e = wire.msg_to_estimate(est[stamp])
        assert e.trace_p == offline.trace_p[k]
        np.testing.assert_array_equal(e.F, offline.F[k])
        np.testing.assert_array_equal(e.G, offline.G[k])
        np.testing.assert_array_equal(e.w, offline.w[k])
