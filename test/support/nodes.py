"""apc's nodes run inside a test: their parameters in, their diagnostics counters out."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from rclpy.parameter import Parameter


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
