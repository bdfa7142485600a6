"""An rclpy node in the test process that records what node processes publish, on its own
graph (context and executor): ``joint_states``, the nominal torque and ``/diagnostics``, or
every topic's serialized messages.

The system tests' reference for what happened and when: every message carries the monotonic
time it was received, and its reader queues are deep (:func:`.qos.deep`) so that it never drops
what it is slow to take.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

import apc_msgs_py as wire

from .arm import T_NS
from .graph import Graph
from .qos import deep


class Observer:
    """An rclpy node in the test process that records what the nodes publish.

    ``states``: ``(wall, stamp_ns, q, qd, effort)`` per ``joint_states``; ``ff``: ``{stamp:
    u_n}``; ``fb``: ``{stamp: du}``; ``diag``: ``(wall, level, message, values)`` of the
    plant's ``/diagnostics``;
    ``raw``: ``{(topic, key): [bytes, ...]}`` of every message when ``raw=True`` (the joint
    states and torques then also in ``states``, ``ff``, ``fb``).
    """

    def __init__(self, raw: bool = False, states: bool = True) -> None:
        self.graph = Graph()
        self.context = self.graph.context
        self.executor = self.graph.executor
        self.node = self.graph.add(rclpy.create_node("fault_observer", context=self.context))
        self.states: list[tuple[float, int, np.ndarray, np.ndarray, np.ndarray | None]] = []
        self.ff: dict[int, np.ndarray] = {}
        self.fb: dict[int, np.ndarray] = {}
        self.diag: list[tuple[float, int, str, dict[str, str]]] = []
        self.feedback_diag: dict[str, str] = {}  # the feedback node's latest values
        self.raw: dict[tuple[str, str], list[tuple[float, bytes]]] = {}
        # A deep reader queue: the observer is the reference, it must not drop what it is slow
        # to take (KEEP_LAST 10 dropped five joint states once on a loaded machine).
        qos = deep(wire.CONTROL_QOS)
        self._typed: dict[str, Any] = {}
        if raw:
            self._typed = {
                self.node.resolve_topic_name(topic): callback
                for topic, callback in (
                    (wire.JOINT_STATES, self._on_state),
                    (wire.FEEDFORWARD_TORQUE, self._on_ff),
                    (wire.FEEDBACK_TORQUE, self._on_fb),
                )
            }
            for spec in wire.TOPICS:
                topic = self.node.resolve_topic_name(spec.name)
                self.node.create_subscription(
                    spec.msg_type,
                    spec.name,
                    lambda data, topic=topic, cls=spec.msg_type: self._on_raw(topic, cls, data),
                    deep(spec.qos),
                    raw=True,
                )
        else:
            if states:  # (an extra joint_states subscriber counts for wait_for_subscribers)
                self.node.create_subscription(JointState, wire.JOINT_STATES, self._on_state, qos)
            self.node.create_subscription(JointState, wire.FEEDFORWARD_TORQUE, self._on_ff, qos)
            self.node.create_subscription(JointState, wire.FEEDBACK_TORQUE, self._on_fb, qos)
            self.node.create_subscription(
                DiagnosticArray, wire.DIAGNOSTICS, self._on_diag, deep(wire.DIAGNOSTICS_QOS)
            )

    def _on_state(self, msg: JointState) -> None:
        effort = np.array(msg.effort) if len(msg.effort) else None
        self.states.append(
            (
                time.monotonic(),
                wire.stamp_to_ns(msg.header.stamp),
                np.array(msg.position),
                np.array(msg.velocity),
                effort,
            )
        )

    def _on_ff(self, msg: JointState) -> None:
        self.ff[wire.stamp_to_ns(msg.header.stamp)] = np.array(msg.effort)

    def _on_fb(self, msg: JointState) -> None:
        self.fb[wire.stamp_to_ns(msg.header.stamp)] = np.array(msg.effort)

    def _on_diag(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith("plant_node"):
                values = {kv.key: kv.value for kv in status.values}
                self.diag.append((time.monotonic(), status.level, status.message, values))
            elif status.name.endswith("feedback_node"):
                self.feedback_diag = {kv.key: kv.value for kv in status.values}

    def _on_raw(self, topic: str, cls: type, data: bytes) -> None:
        key = ""
        if topic == "/diagnostics":  # three writers: order is only defined per writer
            key = deserialize_message(data, cls).status[0].name
        self.raw.setdefault((topic, key), []).append((time.monotonic(), bytes(data)))
        typed = self._typed.get(topic)  # the joint states and torques are also kept decoded
        if typed is not None:
            typed(deserialize_message(data, cls))

    # -- spinning -------------------------------------------------------------------------------
    def spin_for(self, seconds: float) -> None:
        self.graph.spin_for(seconds)

    def spin_until(self, condition, timeout_s: float, what: str, procs=()) -> float:
        """Spin until ``condition()``; return the time it took. Fails naming ``what``."""
        t0 = time.monotonic()
        while not condition():
            for proc in procs:
                assert proc.poll() is None, f"{what}: a node exited with {proc.returncode}"
            assert time.monotonic() - t0 < timeout_s, f"{what}: not within {timeout_s} s"
            self.executor.spin_once(timeout_sec=0.005)
        return time.monotonic() - t0

    def publishers(self, topic: str) -> int:
        return self.node.count_publishers(self.node.resolve_topic_name(topic))

    def subscribers(self, topic: str) -> int:
        return self.node.count_subscribers(self.node.resolve_topic_name(topic))

    def controllers_up(self) -> bool:
        """Both controllers publish their torques (they are running and discovered)."""
        return bool(
            self.publishers(wire.FEEDFORWARD_TORQUE) and self.publishers(wire.FEEDBACK_TORQUE)
        )

    # -- queries --------------------------------------------------------------------------------
    def k(self, period_ns: int = T_NS) -> int:
        """The newest joint state's sample index (-1 before the first)."""
        return self.states[-1][1] // period_ns if self.states else -1

    def diag_after(self, t: float, level: int | None = None) -> list:
        return [d for d in self.diag if d[0] > t and (level is None or d[1] == level)]

    def close(self) -> None:
        self.graph.close()
