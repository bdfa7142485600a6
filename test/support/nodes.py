"""apc's nodes in a test: their parameters in, their diagnostics counters out (of a node run in
the test process, or as a run recorded them)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rclpy.parameter import Parameter

from apc_recording.bag import read_messages


def overrides(values: Mapping[str, Any]) -> list[Parameter]:
    """``parameter_overrides`` for a node made in the test process, from ``{name: value}``
    (one section of :meth:`RunSpec.node_parameters`)."""
    return [Parameter(k, value=v) for k, v in values.items()]


def counter(node: Any, key: str) -> int:
    """A node's diagnostics counter ``key`` (0 until first counted)."""
    return node.diagnostics.counters.get(key, 0)


def errors(node: Any) -> int:
    """Exceptions a node's callbacks caught (a bug, never bad input: that is 'rejected')."""
    return counter(node, "callback_errors")


def recorded_diagnostics(bag: Path) -> dict[str, dict[str, str]]:
    """Each node's last ``/diagnostics`` values in a recording, by node name (``plant_node``)."""
    last: dict[str, dict[str, str]] = {}
    for message in read_messages(bag, topics=["/diagnostics"]):
        for status in message.decode().status:
            last[status.name.rsplit("/", 1)[-1]] = {kv.key: kv.value for kv in status.values}
    return last
