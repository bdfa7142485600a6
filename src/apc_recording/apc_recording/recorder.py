"""``recorder``: record apc's topics to a rosbag2-compatible MCAP file, the way rosbag2 does.

Subscriptions are created with ``raw=True``, so the exact CDR bytes that crossed the wire are
written: ``rclpy.serialization.serialize_message`` sizes its buffer by an estimate and can
append uninitialised padding (a 2-joint JointState: 100 bytes for 96 of CDR), which strict
readers such as rosbags reject. Each message's log time is the recorder's clock at reception
(sim time when ``use_sim_time`` is set, as in ``experiment``), like ``ros2 bag record``.
Chunks are flushed to the OS as they close, so a killed recorder loses at most the chunk it was
filling; SIGINT/SIGTERM close a complete file.

    recorder --ros-args -p output:=run.mcap [-p topics:="[joint_states, feedback/torque]"]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

from rclpy.event_handler import QoSSubscriptionMatchedInfo, SubscriptionEventCallbacks
from rclpy.node import Node

import apc_msgs_py as wire
from apc_core.nodeutil import run_node
from apc_core.params import ConfigError, Param, declare
from apc_recording.bag import BagWriter

PARAMS: tuple[Param, ...] = (
    Param("output", "", "MCAP file to write; empty = apc_<wall time>.mcap in the cwd"),
    Param(
        "topics",
        [],
        "topics to record (relative names resolve in the node's namespace); empty = all of apc's",
        array_of=str,
    ),
    Param("chunk_size", 1 << 20, "uncompressed bytes per MCAP chunk", 1024, 1 << 30),
    Param(
        "max_chunk_interval_s",
        1.0,
        "also close a chunk after this much log time (s), bounding what a kill can lose",
        0.001,
        3600.0,
    ),
    Param("compression", "zstd", "chunk compression: zstd, lz4 or none"),
)


#: Reader queue of each recording subscription. The publishers keep 10 samples; a Python
#: recorder that falls behind for longer than that (a loaded machine, a chunk being compressed)
#: would have the oldest dropped from a 10-deep reader queue without a trace (an observer with
#: depth 10 lost five joint states that way in test/test_faults_system.py). The channel metadata
#: still records the publishers' offered QoS.
RECORDER_QUEUE_DEPTH = 1000


class RecorderNode(Node):
    """Composable recorder (see module docstring). Call :meth:`close` to finish the file."""

    def __init__(
        self,
        node_name: str = "recorder",
        *,
        output: str | Path | None = None,
        custom_data: dict[str, str] | None = None,
        **kwargs: Any,
    ) -> None:
        super().__init__(node_name, **kwargs)
        values = declare(self, PARAMS)
        path = Path(output or values["output"] or f"apc_{time.strftime('%Y%m%d_%H%M%S')}.mcap")
        specs = wire.TOPICS
        if values["topics"]:
            wanted = set(values["topics"])
            unknown = wanted - {s.name for s in specs}
            if unknown:
                raise ConfigError(f"parameter 'topics': not apc topics: {sorted(unknown)}")
            specs = tuple(s for s in specs if s.name in wanted)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.writer = BagWriter(
                path,
                chunk_size=values["chunk_size"],
                compression=values["compression"],
                max_chunk_interval_ns=wire.seconds_to_ns(values["max_chunk_interval_s"]),
                custom_data=custom_data,
            )
        except Exception as exc:
            raise ConfigError(f"parameter 'output': {exc}") from None
        self.path = path
        self.counts: dict[str, int] = {}
        self._subs = []
        for spec in specs:
            topic = self.resolve_topic_name(spec.name)
            self.writer.add_topic(topic, spec.type_name, spec.qos)
            self.counts[topic] = 0
            self._subs.append(
                self.create_subscription(
                    spec.msg_type,
                    spec.name,
                    lambda data, topic=topic: self._on_message(topic, data),
                    wire.with_depth(spec.qos, RECORDER_QUEUE_DEPTH),
                    raw=True,
                    event_callbacks=SubscriptionEventCallbacks(
                        matched=lambda info, topic=topic: self._on_matched(topic, info)
                    ),
                )
            )
        self.get_logger().info(f"recording {len(specs)} topics to {path}")

    def _on_matched(self, topic: str, info: QoSSubscriptionMatchedInfo) -> None:
        # Says when a publisher is heard (or lost): a run started before the recorder hears
        # every publisher misses its first messages, across a slow network for seconds.
        self.get_logger().info(f"{topic}: {info.current_count} publisher(s)")

    def _on_message(self, topic: str, data: bytes) -> None:
        if self.writer.finished:
            return
        now = self.get_clock().now().nanoseconds
        self.writer.write(topic, data, log_time_ns=now, publish_time_ns=now)
        self.counts[topic] += 1

    def close(self) -> None:
        """Finish the MCAP file (idempotent)."""
        if not self.writer.finished:
            self.writer.finish()
            line = f"wrote {sum(self.counts.values())} messages to {self.path}"
            if self.context.ok():
                self.get_logger().info(line)
            else:
                # After a signal the context is shut down and a logger call would also print
                # "Failed to publish log message to rosout".
                print(f"[{self.get_name()}]: {line}", file=sys.stderr)


def main(args: list[str] | None = None) -> int:
    return run_node(RecorderNode, prog="recorder", summary=__doc__ or "", params=PARAMS, args=args)


if __name__ == "__main__":
    sys.exit(main())
