"""``sensor_msgs/JointState`` on the wire: joint states and torque commands."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from sensor_msgs.msg import JointState

from apc_msgs_py.fields import (
    DEFAULT_MAX_ABS,
    WireError,
    as_vector,
    check_names,
    field_array,
    set_names,
    to_double_array,
)
from apc_msgs_py.stamps import split_ns, stamp_to_ns


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class JointSample:
    """One ``sensor_msgs/JointState``, reordered to the caller's joint order.

    Attributes
    ----------
    stamp_ns : int
        ``header.stamp`` in nanoseconds (the sample time ``kT``).
    position : (n,) ndarray or None
        rad (m); ``None`` only if not required and the message carried none.
    velocity : (n,) ndarray or None
        rad/s (m/s).
    effort : (n,) ndarray or None
        N·m (N).
    """

    stamp_ns: int
    position: np.ndarray | None
    velocity: np.ndarray | None
    effort: np.ndarray | None


#: The per-joint fields of a ``JointState``, the values :func:`joint_state_to_arrays` may require.
JOINT_STATE_FIELDS = ("position", "velocity", "effort")


def joint_state_to_arrays(
    msg: JointState,
    names: Sequence[str],
    *,
    require: Iterable[str] = ("position", "velocity"),
    max_abs: float = DEFAULT_MAX_ABS,
    allow_extra: bool = False,
) -> JointSample:
    """Read a ``JointState`` into arrays ordered as ``names``, validating every field.

    Parameters
    ----------
    msg : sensor_msgs.msg.JointState
    names : sequence of str
        The joint order the caller works in (the robot model's). The message may list its joints
        in any order: they are matched by name, never by position in the array.
    require : iterable of {"position", "velocity", "effort"}
        Fields that must have one entry per name. Other fields may be empty (-> ``None``) or have
        one entry per name.
    max_abs : float
        Largest accepted ``|value|`` of any entry (default :data:`DEFAULT_MAX_ABS`).
    allow_extra : bool
        Accept (and drop) joints not in ``names``, e.g. a gripper a real robot also reports.

    Returns
    -------
    JointSample
        Fresh arrays (never views of the message).

    Raises
    ------
    WireError
        Naming the field: ``name`` empty, duplicated, missing or unknown joints; a field whose
        length is not ``len(name)`` (or 0 when optional); NaN or Inf; ``|value| > max_abs``;
        ``header.stamp.nanosec`` not normalised.
    """
    required = set(require)
    if not required <= set(JOINT_STATE_FIELDS):
        raise ValueError(
            f"require must be a subset of {JOINT_STATE_FIELDS}, got {sorted(required)}"
        )
    perm = check_names(msg.name, names, "name", allow_extra)
    n = len(msg.name)
    stamp = stamp_to_ns(msg.header.stamp)
    position = field_array(
        msg.position, perm, n, "position", "position" in required, names, max_abs
    )
    velocity = field_array(
        msg.velocity, perm, n, "velocity", "velocity" in required, names, max_abs
    )
    effort = field_array(msg.effort, perm, n, "effort", "effort" in required, names, max_abs)
    return JointSample(stamp, position, velocity, effort)


def arrays_to_joint_state(
    stamp_ns: int,
    names: Sequence[str],
    position: Any = None,
    velocity: Any = None,
    effort: Any = None,
    msg: JointState | None = None,
    *,
    max_abs: float = DEFAULT_MAX_ABS,
) -> JointState:
    """Build (or refill) a ``JointState`` from arrays in the order ``names``.

    Parameters
    ----------
    stamp_ns : int
        Sample time ``kT`` in nanoseconds -> ``header.stamp``.
    names : sequence of str
        Joint names -> ``name``.
    position, velocity, effort : (n,) array_like or None
        ``None`` publishes an empty field.
    msg : sensor_msgs.msg.JointState, optional
        A preallocated message to refill (the name list is only reassigned if it changed).
    max_abs : float
        Largest accepted ``|value|``.

    Returns
    -------
    sensor_msgs.msg.JointState
        ``msg`` if given, else a new message. ``header.frame_id`` is left as is.

    Raises
    ------
    WireError
        If an array has the wrong shape, holds NaN/Inf or exceeds ``max_abs``: garbage is never
        published. The message is not modified in that case.
    """
    n = len(names)
    if n == 0:
        raise WireError("name: empty (no joints)")
    arrays = {}
    for field, values in (("position", position), ("velocity", velocity), ("effort", effort)):
        arrays[field] = None if values is None else as_vector(values, n, field, names, max_abs)
    sec, nanosec = split_ns(stamp_ns, "header.stamp")
    if msg is None:
        msg = JointState()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    new_names = set_names(msg.name, names)
    if new_names is not None:
        msg.name = new_names
    msg.position = to_double_array(arrays["position"])
    msg.velocity = to_double_array(arrays["velocity"])
    msg.effort = to_double_array(arrays["effort"])
    return msg


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class Torque:
    """A torque command read from the wire.

    Attributes
    ----------
    stamp_ns : int
        The sample time ``kT`` the torque belongs to.
    effort : (n,) ndarray
        N·m (N), in the caller's joint order.
    """

    stamp_ns: int
    effort: np.ndarray


def torque_to_msg(
    stamp_ns: int,
    names: Sequence[str],
    effort: Any,
    msg: JointState | None = None,
    *,
    max_abs: float = DEFAULT_MAX_ABS,
) -> JointState:
    """Build a torque message: a ``JointState`` with ``name`` and ``effort`` only.

    ``position`` and ``velocity`` are empty; ``header.stamp`` is the sample time ``kT`` the torque
    was computed for (the plant pairs torques with samples by this stamp).

    Raises
    ------
    WireError
        As :func:`arrays_to_joint_state`.
    """
    return arrays_to_joint_state(stamp_ns, names, effort=effort, msg=msg, max_abs=max_abs)


def msg_to_torque(
    msg: JointState, names: Sequence[str], *, max_abs: float = DEFAULT_MAX_ABS
) -> Torque:
    """Read a torque message (see :func:`torque_to_msg`), reordered to ``names``.

    Raises
    ------
    WireError
        As :func:`joint_state_to_arrays` with ``effort`` required; also if ``position`` or
        ``velocity`` is not empty (a joint state sent to a torque topic).
    """
    for field in ("position", "velocity"):
        if len(getattr(msg, field)) != 0:
            raise WireError(
                f"{field}: a torque message carries effort only, got {len(getattr(msg, field))} "
                f"{field} values (a joint state on a torque topic?)"
            )
    sample = joint_state_to_arrays(msg, names, require=("effort",), max_abs=max_abs)
    assert sample.effort is not None
    return Torque(sample.stamp_ns, sample.effort)
