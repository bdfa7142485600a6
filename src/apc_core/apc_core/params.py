"""ROS parameters declared once, with their meaning, and read once into plain values.

Each node lists its parameters as :class:`Param` rows (name, default, description with units,
range, read-only), the way ros2_controllers' JTC declares its parameter YAML. :func:`declare`
declares them all with ``ParameterDescriptor``\\ s and returns a plain ``dict``; the node's pure
``from_dict`` builds the frozen config and rejects a bad value with one line naming it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
)
from rclpy.node import Node
from rclpy.parameter import Parameter


class ConfigError(ValueError):
    """A parameter value that stops a node at start-up; the message names the parameter."""


_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


@dataclass(frozen=True)
class Param:
    """One declared parameter.

    Attributes
    ----------
    name : str
        Dotted name (``adaptive.rho``), nested in YAML parameter files.
    default : bool, int, float, str or list
        Its type is the parameter's type; a list of floats/str is a double/string array.
    description : str
        What it means, with units and what special values (0, empty) mean.
    low, high : float or None
        Inclusive range for numbers (``FloatingPointRange``/``IntegerRange``).
    read_only : bool
        Cannot change after start-up (timing, model, joint names).
    array_of : type
        Element type of an array parameter (needed when the default is empty).
    dynamic_typing : bool
        Let rclpy accept a value of another type (e.g. ``ros2 param set ... 200``, an integer,
        for a double); the node must then check the type itself (see :func:`check_number`).
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    read_only: bool = True
    array_of: type = float
    dynamic_typing: bool = False

    def descriptor(self) -> ParameterDescriptor:
        desc = ParameterDescriptor(
            name=self.name,
            description=self.description,
            read_only=self.read_only,
            dynamic_typing=self.dynamic_typing,
        )
        value = self.default
        if isinstance(value, list):
            elem = str if (value and isinstance(value[0], str)) else self.array_of
            desc.type = (
                ParameterType.PARAMETER_STRING_ARRAY
                if elem is str
                else ParameterType.PARAMETER_DOUBLE_ARRAY
            )
        else:
            desc.type = _TYPES[type(value)]
        if self.low is not None and self.high is not None:
            if isinstance(value, float):
                desc.floating_point_range = [
                    FloatingPointRange(from_value=float(self.low), to_value=float(self.high))
                ]
            elif isinstance(value, int) and not isinstance(value, bool):
                desc.integer_range = [
                    IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)
                ]
        return desc


def declare(node: Node, params: Iterable[Param]) -> dict[str, Any]:
    """Declare every parameter on ``node`` and return ``{name: value}``.

    An empty array default is declared by type only (rclpy would take ``[]`` for a byte
    array), and reads back as ``[]`` when no override is given. Values out of a declared range
    are refused by rclpy at declaration; that error is turned
    into a :class:`ConfigError` naming the parameter.
    """
    values: dict[str, Any] = {}
    for p in params:
        try:
            if isinstance(p.default, list) and not p.default:
                kind = (
                    Parameter.Type.STRING_ARRAY
                    if p.array_of is str
                    else Parameter.Type.DOUBLE_ARRAY
                )
                param = node.declare_parameter(p.name, kind, p.descriptor())
            else:
                param = node.declare_parameter(p.name, p.default, p.descriptor())
        except Exception as exc:  # rclpy raises several exception types here
            raise ConfigError(f"parameter '{p.name}': {exc}") from None
        value = param.value
        if isinstance(p.default, list):
            value = list(value) if value is not None else []
        values[p.name] = value
    return values


def check_number(param: Param, value: Any) -> float:
    """``value`` as a float within ``param``'s range, or :class:`ConfigError` naming it.

    Integers are accepted for a double (``ros2 param set`` sends ``200`` as an integer);
    booleans, strings, arrays and unset values are not.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(
            f"parameter '{param.name}': must be a number, got {type(value).__name__} {value!r}"
        )
    number = float(value)
    if not math.isfinite(number):
        raise ConfigError(f"parameter '{param.name}': must be finite, got {number}")
    if param.low is not None and param.high is not None and not param.low <= number <= param.high:
        raise ConfigError(
            f"parameter '{param.name}': {number:g} is outside [{param.low:g}, {param.high:g}]"
        )
    return number


def subset(values: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """``{"adaptive.rho": 1}`` with prefix ``"adaptive."`` -> ``{"rho": 1}``."""
    return {k[len(prefix) :]: v for k, v in values.items() if k.startswith(prefix)}
