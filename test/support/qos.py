"""QoS of the test's own readers and writers: the nodes' QoS with a deep history.

A test node is the reference for what the nodes published (or the source of what they
receive): it must not drop what it is slow to take. With the wire's KEEP_LAST 10 a reader on a
loaded machine lost five joint states once.
"""

from __future__ import annotations

from rclpy.qos import QoSProfile

import apc_msgs_py as wire


def deep(qos: QoSProfile, depth: int = 1000) -> QoSProfile:
    """``qos`` with a KEEP_LAST history at least ``depth`` deep (best effort stays best
    effort)."""
    return wire.with_depth(qos, depth)


#: The control topics' QoS (reliable, volatile), 1000 deep: what a test's capturing node and
#: its injector or stand-in use, deep enough that nothing is ever dropped.
DEEP_QOS = deep(wire.CONTROL_QOS)
