"""ROS parameters declared once, with their meaning, and read once into plain values.

Each node lists its parameters as :class:`Param` rows (name, default, description with units,
range, read-only), the way ros2_controllers' JTC declares its parameter YAML. :func:`declare`
declares them all with ``ParameterDescriptor``\\ s and returns a plain ``dict``; the node's pure
``from_dict`` builds the frozen config and rejects a bad value with one line naming it.

A plain config dataclass (no rclpy: this module imports rclpy only where it declares) is the one
source of its settings: each field made with :func:`setting` carries its default, description
and range, :func:`check_settings` is its validation, and :func:`params_from` makes the node's
:class:`Param` rows from it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

_Config = TypeVar("_Config")

if TYPE_CHECKING:
    from rcl_interfaces.msg import ParameterDescriptor
    from rclpy.node import Node


class ConfigError(ValueError):
    """A parameter value that stops a node at start-up; the message names the parameter."""


class SettingError(ValueError):
    """A bad value of a config dataclass's setting; ``field`` names the setting (None when no
    single one is at fault), so that a node can name its parameter without parsing the text."""

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


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
        for a double); the node must then check the type itself (see :func:`check_settings`).
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
        from rcl_interfaces.msg import (
            FloatingPointRange,
            IntegerRange,
            ParameterDescriptor,
            ParameterType,
        )

        types = {
            bool: ParameterType.PARAMETER_BOOL,
            int: ParameterType.PARAMETER_INTEGER,
            float: ParameterType.PARAMETER_DOUBLE,
            str: ParameterType.PARAMETER_STRING,
        }
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
            desc.type = types[type(value)]
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
    from rclpy.parameter import Parameter

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


def subset(values: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """``{"adaptive.rho": 1}`` with prefix ``"adaptive."`` -> ``{"rho": 1}``."""
    return {k[len(prefix) :]: v for k, v in values.items() if k.startswith(prefix)}


def setting(
    default: Any,
    description: str,
    low: float | None = None,
    high: float | None = None,
    *,
    runtime: bool = False,
) -> Any:
    """A config dataclass field with what its node parameter needs, written once.

    ``low``/``high`` is the inclusive range :func:`check_settings` enforces (and the ROS
    descriptor shows); ``runtime`` makes the parameter settable while the node runs.
    """
    meta = {"description": description, "low": low, "high": high, "runtime": runtime}
    return dataclasses.field(default=default, metadata=meta)


def settings_from(
    cls: type[_Config], values: Mapping[str, Any], error: type[Exception], what: str
) -> _Config:
    """The config dataclass ``cls`` from a plain mapping (node parameter values, a scenario
    file): an unknown key raises ``error`` naming it (``unknown <what> 'key'``); a list becomes a
    tuple, since ROS array parameters arrive as lists and the frozen configs hold tuples."""
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise error(f"unknown {what} {unknown[0]!r}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})


def _settings(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if "description" in f.metadata]


def check_settings(config: Any, error: type[SettingError] = SettingError) -> None:
    """Validate every :func:`setting` field of the dataclass instance ``config`` (call it from
    ``__post_init__``): a number is a number (an integer for an integer setting; an integer is
    stored as a float for a float setting) within its range; ``error`` names the field."""
    for f in _settings(type(config)):
        value, low, high = getattr(config, f.name), f.metadata["low"], f.metadata["high"]
        if low is None or isinstance(f.default, bool | str):
            continue
        integer = isinstance(f.default, int)
        kinds = int if integer else int | float
        if isinstance(value, bool) or not isinstance(value, kinds):
            what = "an integer" if integer else "a number"
            raise error(
                f"{f.name} must be {what}, got {type(value).__name__} {value!r}", field=f.name
            )
        if not integer:
            value = float(value)
            object.__setattr__(config, f.name, value)
        if not (math.isfinite(value) and low <= value <= high):
            raise error(f"{f.name} = {value:g} is out of range [{low:g}, {high:g}]", field=f.name)


def params_from(cls: type, prefix: str) -> tuple[Param, ...]:
    """The node's :class:`Param` rows of the config dataclass ``cls``'s :func:`setting` fields,
    named ``<prefix><field>``; a runtime setting is dynamically typed (``ros2 param set`` may
    send an integer for a double) and checked by the dataclass when set."""
    return tuple(
        Param(
            f"{prefix}{f.name}",
            list(f.default) if isinstance(f.default, tuple) else f.default,
            f.metadata["description"],
            f.metadata["low"],
            f.metadata["high"],
            read_only=not f.metadata["runtime"],
            dynamic_typing=f.metadata["runtime"],
        )
        for f in _settings(cls)
    )
