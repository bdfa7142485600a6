"""``trajectory_msgs/JointTrajectory`` on the wire: the one-point set point and the goal."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from apc_msgs_py.fields import (
    DEFAULT_MAX_ABS,
    WireError,
    as_vector,
    check_names,
    field_array,
    set_names,
    to_double_array,
)
from apc_msgs_py.stamps import NS_PER_S, duration_to_ns, split_ns, stamp_to_ns


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class SetpointStamped:
    """The planned set point of one sample as :data:`SETPOINT` carries it, stamped with its
    sample time (like ``PoseStamped`` to ``Pose``): the wire form of the feedforward's
    ``apc_feedforward.nominal.Setpoint``, which counts samples and seconds instead.

    Attributes
    ----------
    stamp_ns : int
        Sample time ``kT`` (``header.stamp``).
    q, qd, qdd : (n,) ndarray
        ``q_d`` (rad), ``q̇_d`` (rad/s), ``q̈_d`` (rad/s²).
    u_n : (n,) ndarray
        Nominal torque of the set point (N·m), carried in ``effort``.
    time_from_start_ns : int
        Time since the start of the motion (``points[0].time_from_start``).
    """

    stamp_ns: int
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    u_n: np.ndarray
    time_from_start_ns: int


def setpoint_to_msg(
    stamp_ns: int,
    names: Sequence[str],
    q: Any,
    qd: Any,
    qdd: Any,
    u_n: Any,
    time_from_start_ns: int,
    msg: JointTrajectory | None = None,
    *,
    max_abs: float = DEFAULT_MAX_ABS,
) -> JointTrajectory:
    """Build (or refill) the one-point ``JointTrajectory`` of a set point.

    Layout: ``header.stamp`` = sample time, ``joint_names`` = ``names``, one point with
    ``positions = q``, ``velocities = qd``, ``accelerations = qdd``, ``effort = u_n`` and
    ``time_from_start`` = time since the start of the motion.

    Raises
    ------
    WireError
        If an array has the wrong shape, NaN/Inf or exceeds ``max_abs``, or a time does not fit.
    """
    n = len(names)
    if n == 0:
        raise WireError("joint_names: empty (no joints)")
    vectors = [
        as_vector(v, n, f"points[0].{f}", names, max_abs)
        for f, v in (("positions", q), ("velocities", qd), ("accelerations", qdd), ("effort", u_n))
    ]
    sec, nanosec = split_ns(stamp_ns, "header.stamp")
    tfs_sec, tfs_nanosec = split_ns(time_from_start_ns, "points[0].time_from_start")
    if msg is None:
        msg = JointTrajectory()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    new_names = set_names(msg.joint_names, names)
    if new_names is not None:
        msg.joint_names = new_names
    if len(msg.points) != 1:
        msg.points = [JointTrajectoryPoint()]
    point = msg.points[0]
    point.positions = to_double_array(vectors[0])
    point.velocities = to_double_array(vectors[1])
    point.accelerations = to_double_array(vectors[2])
    point.effort = to_double_array(vectors[3])
    point.time_from_start.sec = tfs_sec
    point.time_from_start.nanosec = tfs_nanosec
    return msg


def msg_to_setpoint(
    msg: JointTrajectory, names: Sequence[str], *, max_abs: float = DEFAULT_MAX_ABS
) -> SetpointStamped:
    """Read a set point message (see :func:`setpoint_to_msg`), reordered to ``names``.

    Raises
    ------
    WireError
        Naming the field: ``joint_names`` empty/duplicated/missing/unknown; ``points`` not exactly
        one; any of ``positions, velocities, accelerations, effort`` not one per joint, NaN, Inf or
        beyond ``max_abs``; a malformed stamp or ``time_from_start``.
    """
    perm = check_names(msg.joint_names, names, "joint_names", False)
    if len(msg.points) != 1:
        raise WireError(f"points: a set point has exactly one point, got {len(msg.points)}")
    point = msg.points[0]
    n = len(msg.joint_names)
    stamp = stamp_to_ns(msg.header.stamp)
    arrays = [
        field_array(getattr(point, f), perm, n, f"points[0].{f}", True, names, max_abs)
        for f in ("positions", "velocities", "accelerations", "effort")
    ]
    tfs = duration_to_ns(point.time_from_start, "points[0].time_from_start")
    return SetpointStamped(stamp, *arrays, time_from_start_ns=tfs)  # type: ignore[arg-type]


class TrajectoryGoal(NamedTuple):
    """The waypoints of a trajectory goal (:data:`TRAJECTORY_GOAL`), reordered to the caller's
    joint order; the feedforward plans a trajectory through them.

    Unpacks as ``times_s, positions, velocities, accelerations``.

    Attributes
    ----------
    times_s : (m,) ndarray
        ``time_from_start`` of each point (s), strictly increasing, > 0.
    positions : (m, n) ndarray
        rad.
    velocities : (m, n) ndarray or None
        rad/s; ``None`` if no point carries velocities.
    accelerations : (m, n) ndarray or None
        rad/s²; ``None`` if no point carries accelerations.
    """

    times_s: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    accelerations: np.ndarray | None


def msg_to_trajectory_goal(
    msg: JointTrajectory, names: Sequence[str], *, max_abs: float = DEFAULT_MAX_ABS
) -> TrajectoryGoal:
    """Read a trajectory goal into waypoint arrays with columns ordered as ``names``.

    Parameters
    ----------
    msg : trajectory_msgs.msg.JointTrajectory
        ``m >= 1`` points. Each has ``positions`` (one per joint); ``velocities`` and
        ``accelerations`` are optional but, if given, must be given for every point. ``effort``
        is ignored. ``header.stamp`` is not interpreted here.
    names : sequence of str
        The caller's joint order.
    max_abs : float
        Largest accepted ``|value|``.

    Returns
    -------
    TrajectoryGoal

    Raises
    ------
    WireError
        Naming the field: ``joint_names`` problems as in :func:`joint_state_to_arrays`; ``points``
        empty; ``points[i].<field>`` of the wrong length, NaN/Inf or beyond ``max_abs``;
        velocities or accelerations given for some points only; ``points[i].time_from_start``
        not > 0 or not strictly increasing.
    """
    perm = check_names(msg.joint_names, names, "joint_names", False)
    m = len(msg.points)
    if m == 0:
        raise WireError("points: empty (a goal needs at least one waypoint)")
    n = len(msg.joint_names)
    times = np.empty(m)
    positions = np.empty((m, len(names)))
    optional: dict[str, np.ndarray | None] = {"velocities": None, "accelerations": None}
    present: dict[str, bool] = {}
    prev_ns = 0
    for i, point in enumerate(msg.points):
        tfs = duration_to_ns(point.time_from_start, f"points[{i}].time_from_start")
        if tfs <= prev_ns:
            what = "> 0" if i == 0 else f"after points[{i - 1}] ({prev_ns / NS_PER_S:.9g} s)"
            raise WireError(
                f"points[{i}].time_from_start: {tfs / NS_PER_S:.9g} s is not {what}"
                " (times must be strictly increasing and > 0)"
            )
        prev_ns = tfs
        times[i] = tfs / NS_PER_S
        pos = field_array(point.positions, perm, n, f"points[{i}].positions", True, names, max_abs)
        positions[i] = pos
        for field in optional:
            values = field_array(
                getattr(point, field), perm, n, f"points[{i}].{field}", False, names, max_abs
            )
            has = values is not None
            if present.setdefault(field, has) != has:
                raise WireError(
                    f"points[{i}].{field}: given for some points and not others"
                    f" (points[0] {'has' if present[field] else 'has none'})"
                )
            if has:
                if optional[field] is None:
                    optional[field] = np.empty((m, len(names)))
                optional[field][i] = values  # type: ignore[index]
    return TrajectoryGoal(times, positions, optional["velocities"], optional["accelerations"])
