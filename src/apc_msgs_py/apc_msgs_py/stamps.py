"""Time on the wire: integer nanoseconds, ROS stamps and durations, and the sample grid.

Time is integer nanoseconds everywhere. Sample ``k`` is stamped ``k * T`` computed in integers
(:func:`sample_stamp_ns`), so stamps are exact for any run length (no float drift).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration as DurationMsg
from builtin_interfaces.msg import Time as TimeMsg

from apc_msgs_py.fields import WireError

NS_PER_S = 1_000_000_000


def stamp_to_ns(stamp: Any, field: str = "header.stamp") -> int:
    """Convert a ``builtin_interfaces/Time`` (or ``Duration``) to integer nanoseconds.

    Parameters
    ----------
    stamp : builtin_interfaces.msg.Time or Duration
        Anything with integer ``sec`` and ``nanosec``.
    field : str
        Name used in the error message.

    Returns
    -------
    int
        ``sec * 10**9 + nanosec``, exact.

    Raises
    ------
    WireError
        If ``nanosec`` is outside ``[0, 10**9)`` (a malformed, non-normalised stamp).
    """
    nanosec = stamp.nanosec
    if not 0 <= nanosec < NS_PER_S:
        raise WireError(f"{field}.nanosec: {nanosec} is outside [0, 1e9)")
    return stamp.sec * NS_PER_S + nanosec


def split_ns(ns: int, field: str) -> tuple[int, int]:
    if isinstance(ns, bool) or not isinstance(ns, (int, np.integer)):
        raise WireError(f"{field}: time must be integer nanoseconds, got {type(ns).__name__}")
    sec, nanosec = divmod(int(ns), NS_PER_S)
    if not -(2**31) <= sec < 2**31:
        raise WireError(f"{field}: {ns} ns does not fit a ROS time (int32 seconds)")
    return sec, nanosec


def ns_to_stamp(ns: int, msg: TimeMsg | None = None) -> TimeMsg:
    """Convert integer nanoseconds to a ``builtin_interfaces/Time``.

    Parameters
    ----------
    ns : int
        Time in nanoseconds (may be negative; ``nanosec`` is then still in ``[0, 1e9)``, as
        ``rclpy.time.Time.to_msg`` does).
    msg : builtin_interfaces.msg.Time, optional
        A message to fill in place (no allocation).

    Returns
    -------
    builtin_interfaces.msg.Time

    Raises
    ------
    WireError
        If ``ns`` is not an integer or does not fit an int32 number of seconds.
    """
    return _filled(msg if msg is not None else TimeMsg(), *split_ns(ns, "stamp"))


def duration_to_ns(duration: Any, field: str = "time_from_start") -> int:
    """Convert a ``builtin_interfaces/Duration`` to integer ns (see :func:`stamp_to_ns`)."""
    return stamp_to_ns(duration, field)


def ns_to_duration(ns: int, msg: DurationMsg | None = None) -> DurationMsg:
    """Convert integer ns to a ``builtin_interfaces/Duration`` (see :func:`ns_to_stamp`)."""
    return _filled(msg if msg is not None else DurationMsg(), *split_ns(ns, "duration"))


def _filled(msg: Any, sec: int, nanosec: int) -> Any:
    """``msg`` (a ``Time`` or ``Duration``) with ``sec`` and ``nanosec`` set."""
    msg.sec = sec
    msg.nanosec = nanosec
    return msg


def seconds_to_ns(seconds: float) -> int:
    """Round a time in seconds to integer nanoseconds (``0.01`` -> ``10_000_000``).

    Use it once, on a configured period ``T``; then compute sample times in integers with
    :func:`sample_stamp_ns`, never ``k * T`` in floating point.

    Raises
    ------
    ValueError
        If ``seconds`` is not finite.
    """
    if not math.isfinite(seconds):
        raise ValueError(f"seconds must be finite, got {seconds}")
    return round(seconds * NS_PER_S)


def sample_stamp_ns(k: int, period_ns: int) -> int:
    """Time of sample ``k``: ``k * period_ns``, exact integer nanoseconds.

    Parameters
    ----------
    k : int
        Sample index, >= 0.
    period_ns : int
        Sampling period ``T`` in nanoseconds, > 0 (see :func:`seconds_to_ns`).

    Returns
    -------
    int
        ``k * period_ns``. With ``T = 10 ms`` this is exact for any ``k`` (Python integers do not
        overflow), unlike ``k * 0.01`` in floating point.

    Raises
    ------
    ValueError
        If ``k < 0``, ``period_ns <= 0`` or either is not an integer.
    """
    for name, value in (("k", k), ("period_ns", period_ns)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ValueError(f"{name} must be an integer, got {type(value).__name__}")
    if k < 0:
        raise ValueError(f"k must be >= 0, got {k}")
    if period_ns <= 0:
        raise ValueError(f"period_ns must be > 0, got {period_ns}")
    return int(k) * int(period_ns)


def sample_index(stamp_ns: int, period_ns: int) -> int:
    """The sample index ``k`` of a message stamped ``kT`` (the inverse of :func:`sample_stamp_ns`).

    Raises
    ------
    WireError
        If the stamp is negative or not a whole multiple of the period: no node ever sent
        such a sample (the plant stamps sample ``k`` exactly ``k * T``, ``k >= 0``).
    """
    if stamp_ns < 0:
        raise WireError(f"header.stamp: {stamp_ns} ns is negative (samples are kT, k >= 0)")
    if stamp_ns % period_ns:
        raise WireError(
            f"header.stamp: {stamp_ns} ns is not on the sample grid (a multiple of {period_ns} ns)"
        )
    return stamp_ns // period_ns
