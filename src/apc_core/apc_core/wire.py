"""The wire contract of apc: topic names, QoS, message <-> numpy conversion and validation.

Every node takes its topic names and QoS from here (no topic string literal in a ``node.py``),
and every message that crosses the wire goes through one of the converters below, so that a
malformed message is rejected at the border with a :class:`WireError` that names the field.

Topics (relative, so a namespace such as ``/puma`` moves a whole arm; clock and diagnostics global)
---------------------------------------------------------------------------------------------------
- ``JOINT_STATES``: ``sensor_msgs/JointState``, :data:`CONTROL_QOS`
- ``SETPOINT``: ``trajectory_msgs/JointTrajectory`` with one point, :data:`CONTROL_QOS`
- ``FEEDFORWARD_TORQUE``, ``FEEDBACK_TORQUE``: ``sensor_msgs/JointState`` (name + effort),
  :data:`CONTROL_QOS`
- ``ESTIMATE``: ``std_msgs/Float64MultiArray`` (:func:`estimate_to_msg`), :data:`CONTROL_QOS`
- ``TRAJECTORY_GOAL``: ``trajectory_msgs/JointTrajectory``, :data:`TRAJECTORY_GOAL_QOS`
- ``CLOCK`` (absolute): ``rosgraph_msgs/Clock``, :data:`CLOCK_QOS`
- ``DIAGNOSTICS`` (absolute): ``diagnostic_msgs/DiagnosticArray``, :data:`DIAGNOSTICS_QOS`

:data:`TOPICS` holds the same table as :class:`TopicSpec` rows for the recorder.

Conventions
-----------
- Time is integer nanoseconds everywhere. Sample ``k`` is stamped ``k * T`` computed in integers
  (:func:`sample_stamp_ns`), so stamps are exact for any run length (no float drift).
- Joint order comes from ``name`` (``joint_names``), never from the position in the array: every
  reader reorders to the order the caller asks for.
- Units: positions rad (or m), velocities rad/s, accelerations rad/s², torques N·m (or N).
- Nothing non-finite is published or accepted: the writers raise :class:`WireError` rather than
  publish garbage, the readers raise it rather than hand garbage to a controller.
"""

from __future__ import annotations

import array
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from builtin_interfaces.msg import Duration as DurationMsg
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

__all__ = [
    "CLOCK",
    "CLOCK_QOS",
    "CONTROL_QOS",
    "DEFAULT_MAX_ABS",
    "DIAGNOSTICS",
    "DIAGNOSTICS_QOS",
    "ESTIMATE",
    "ESTIMATE_COLS_LABEL",
    "ESTIMATE_ROWS_LABEL",
    "ESTIMATE_TRAILER",
    "FEEDBACK_TORQUE",
    "FEEDFORWARD_TORQUE",
    "JOINT_STATES",
    "MAX_LOOKAHEAD",
    "NS_PER_S",
    "SETPOINT",
    "TOPICS",
    "TRAJECTORY_GOAL",
    "TRAJECTORY_GOAL_QOS",
    "Estimate",
    "JointSample",
    "Setpoint",
    "TopicSpec",
    "Torque",
    "Waypoints",
    "WireError",
    "arrays_to_joint_state",
    "duration_to_ns",
    "estimate_to_msg",
    "joint_state_to_arrays",
    "msg_to_estimate",
    "msg_to_setpoint",
    "msg_to_torque",
    "msg_to_waypoints",
    "ns_to_duration",
    "ns_to_stamp",
    "sample_index",
    "sample_stamp_ns",
    "seconds_to_ns",
    "setpoint_to_msg",
    "stamp_to_ns",
    "theta_to_estimate_msg",
    "topic_spec",
    "torque_to_msg",
]

# ----------------------------------------------------------------------------------------------
# Topic names
# ----------------------------------------------------------------------------------------------
#: plant -> all: ``q``, ``q̇`` at sample k; ``effort`` = torque applied over the period ending at k.
JOINT_STATES = "joint_states"
#: feedforward -> feedback, recorder: the planned set point of sample k (one-point trajectory).
SETPOINT = "feedforward/setpoint"
#: feedforward -> plant: the nominal torque ``u_n(k)`` (JointState, name + effort only).
FEEDFORWARD_TORQUE = "feedforward/torque"
#: feedback -> plant: the perturbation torque ``δu(k)`` (JointState, name + effort only).
FEEDBACK_TORQUE = "feedback/torque"
#: feedback -> recorder: identification telemetry (see :func:`estimate_to_msg`).
ESTIMATE = "feedback/estimate"
#: user -> feedforward: a new goal (waypoints) to plan and run.
TRAJECTORY_GOAL = "feedforward/trajectory"
#: plant -> all: simulation time in lockstep mode (absolute: there is one clock per ROS graph).
CLOCK = "/clock"
#: every node -> monitors: loop timing, late/missing inputs, rejected messages, RLS health.
DIAGNOSTICS = "/diagnostics"

NS_PER_S = 1_000_000_000
#: Default bound on ``|value|`` for every numeric field read or written here. Nothing physical in
#: apc comes near it (rad, rad/s, rad/s², N·m of an arm); a value beyond it is a unit mix-up or
#: uninitialised memory, not a state.
DEFAULT_MAX_ABS = 1.0e6
#: Most samples a feedforward may publish ahead of the joint state it answers; the plant refuses
#: a nominal torque stamped further ahead than this (no plan runs that far ahead of the arm).
MAX_LOOKAHEAD = 8

# ----------------------------------------------------------------------------------------------
# QoS
# ----------------------------------------------------------------------------------------------
#: Control-loop topics (joint states, set point, both torques, estimate): RELIABLE, KEEP_LAST 10,
#: VOLATILE. Lockstep must not lose a sample (the plant waits for both torques of sample k, a
#: dropped one would stall it), so best effort is out. Depth 10 absorbs a short stall of a
#: subscriber without dropping (lockstep has at most one sample in flight; real time ~100 ms).
#: VOLATILE: an old control sample is meaningless to a late joiner.
CONTROL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ``/clock``: KEEP_LAST 1, BEST_EFFORT, VOLATILE -- what rclpy's ``TimeSource`` subscribes with
#: (and ``rclcpp::ClockQoS``). Only the newest time matters; lockstep does not depend on the clock
#: arriving (samples are matched by their stamps), a dropped clock message only delays ``now()``.
#: A RELIABLE publisher would also match this subscriber; BEST_EFFORT keeps the plant from ever
#: blocking on a slow clock subscriber.
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
#: Trajectory goals: RELIABLE, KEEP_LAST 10, VOLATILE. A goal must not be lost, but it must NOT be
#: TRANSIENT_LOCAL: a node that (re)starts late would receive the last goal again and replay an
#: old motion. A goal is an event, not a state.
TRAJECTORY_GOAL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ``/diagnostics``: the ROS default profile (RELIABLE, KEEP_LAST 10, VOLATILE), what
#: ``diagnostic_updater`` and ``diagnostic_aggregator`` use, so standard tools match.
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


@dataclass(frozen=True)
class TopicSpec:
    """One row of the wire table: what is published on ``name``, and with which QoS.

    Attributes
    ----------
    name : str
        Topic name (relative unless it starts with ``/``).
    msg_type : type
        The rclpy message class.
    qos : rclpy.qos.QoSProfile
        The profile publishers offer and subscribers request.
    """

    name: str
    msg_type: type
    qos: QoSProfile

    @property
    def type_name(self) -> str:
        """The ROS type name, e.g. ``"sensor_msgs/msg/JointState"``."""
        pkg = self.msg_type.__module__.split(".")[0]
        return f"{pkg}/msg/{self.msg_type.__name__}"


#: The whole wire, in the order of the design table; the recorder records all of it.
TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec(JOINT_STATES, JointState, CONTROL_QOS),
    TopicSpec(SETPOINT, JointTrajectory, CONTROL_QOS),
    TopicSpec(FEEDFORWARD_TORQUE, JointState, CONTROL_QOS),
    TopicSpec(FEEDBACK_TORQUE, JointState, CONTROL_QOS),
    TopicSpec(ESTIMATE, Float64MultiArray, CONTROL_QOS),
    TopicSpec(TRAJECTORY_GOAL, JointTrajectory, TRAJECTORY_GOAL_QOS),
    TopicSpec(CLOCK, Clock, CLOCK_QOS),
    TopicSpec(DIAGNOSTICS, DiagnosticArray, DIAGNOSTICS_QOS),
)


def topic_spec(name: str) -> TopicSpec:
    """Return the :data:`TOPICS` row of topic ``name``.

    Raises
    ------
    KeyError
        If ``name`` is not one of apc's topics.
    """
    for spec in TOPICS:
        if spec.name == name:
            return spec
    raise KeyError(f"{name!r} is not an apc topic; known: {[s.name for s in TOPICS]}")


# ----------------------------------------------------------------------------------------------
# Errors and time
# ----------------------------------------------------------------------------------------------
class WireError(ValueError):
    """A message (or an array about to be published) that breaks the wire contract.

    The text starts with the offending field (``"position: NaN at joint 'j2'"``), so a node can
    log it as is. Nodes catch it, count it, log it (throttled) and carry on.
    """


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


def _split_ns(ns: int, field: str) -> tuple[int, int]:
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
    sec, nanosec = _split_ns(ns, "stamp")
    if msg is None:
        return TimeMsg(sec=sec, nanosec=nanosec)
    msg.sec = sec
    msg.nanosec = nanosec
    return msg


def duration_to_ns(duration: Any, field: str = "time_from_start") -> int:
    """Convert a ``builtin_interfaces/Duration`` to integer ns (see :func:`stamp_to_ns`)."""
    return stamp_to_ns(duration, field)


def ns_to_duration(ns: int, msg: DurationMsg | None = None) -> DurationMsg:
    """Convert integer ns to a ``builtin_interfaces/Duration`` (see :func:`ns_to_stamp`)."""
    sec, nanosec = _split_ns(ns, "duration")
    if msg is None:
        return DurationMsg(sec=sec, nanosec=nanosec)
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


# ----------------------------------------------------------------------------------------------
# Validation helpers
# ----------------------------------------------------------------------------------------------
#: Permutations of name lists already checked, (got, names, allow_extra) -> perm: the same few
#: lists arrive every sample, and a dict lookup is a fraction of the check. Bounded.
_PERMS: dict[tuple[tuple[str, ...], tuple[str, ...], bool], list | None] = {}
_MAX_PERMS = 256


def _check_names(
    got: Sequence[str], names: Sequence[str], field: str, allow_extra: bool
) -> list | None:
    """Return ``perm`` with ``got[perm[i]] == names[i]`` (``None`` when it is the identity);
    raise WireError naming ``field``."""
    key = (tuple(got), tuple(names), allow_extra)
    try:
        return _PERMS[key]
    except KeyError:
        pass
    perm = _name_permutation(got, names, field, allow_extra)
    if len(_PERMS) >= _MAX_PERMS:
        _PERMS.clear()
    _PERMS[key] = None if perm == list(range(len(got))) else perm
    return _PERMS[key]


def _name_permutation(
    got: Sequence[str], names: Sequence[str], field: str, allow_extra: bool
) -> list:
    if len(got) == 0:
        raise WireError(f"{field}: empty (no joints in the message)")
    index: dict[str, int] = {}
    for i, name in enumerate(got):
        if name in index:
            raise WireError(f"{field}: duplicated joint {name!r}")
        index[name] = i
    missing = [n for n in names if n not in index]
    if missing:
        raise WireError(f"{field}: missing joint(s) {missing}; expected {list(names)}")
    if not allow_extra and len(index) != len(names):
        wanted = set(names)
        unknown = [n for n in got if n not in wanted]
        raise WireError(f"{field}: unknown joint(s) {unknown}; expected {list(names)}")
    return [index[n] for n in names]


_max_reduce = np.maximum.reduce
_min_reduce = np.minimum.reduce


def _check_finite(values: np.ndarray, field: str, labels: Sequence[str], max_abs: float) -> None:
    """Raise WireError if ``values`` holds NaN, Inf, or ``|v| > max_abs``; name the joint."""
    # Fast path (this runs ~25 times per sample): the sum of the entries is finite only if none
    # is NaN or Inf (x - x == 0 fails for both), then one bound on the largest |v|. For the short
    # vectors of a joint state plain Python is 3x quicker than numpy's reductions. Only a
    # failure (which includes a sum that merely overflows) gets the entry-by-entry check.
    if values.size <= 32:
        entries = values.ravel().tolist()
        total = sum(entries)
        if total - total == 0.0 and max(map(abs, entries), default=0.0) <= max_abs:
            return
    else:
        flat = values.ravel()
        low, high = _min_reduce(flat), _max_reduce(flat)
        if -max_abs <= low and high <= max_abs and high != math.inf and low != -math.inf:
            return
    finite = np.isfinite(values)
    if not finite.all():
        i = int(np.flatnonzero(~finite.ravel())[0])
        v = values.ravel()[i]
        kind = "NaN" if math.isnan(v) else "Inf"
        raise WireError(f"{field}: {kind} at {_label(labels, i)}")
    if values.size and float(np.max(np.abs(values))) > max_abs:
        i = int(np.argmax(np.abs(values).ravel()))
        raise WireError(
            f"{field}: |{values.ravel()[i]:.6g}| at {_label(labels, i)} exceeds max_abs {max_abs:g}"
        )


def _label(labels: Sequence[str], i: int) -> str:
    """``joint 'j2' (index 1)`` for a per-joint vector, ``index i`` otherwise."""
    if len(labels) > 0:
        return f"joint {labels[i % len(labels)]!r} (index {i})"
    return f"index {i}"


def _field_array(
    values: Any,
    perm: list | None,
    n: int,
    field: str,
    required: bool,
    names: Sequence[str],
    max_abs,
) -> np.ndarray | None:
    """Read a float64 sequence field of length n (or 0 if optional), reorder, validate."""
    length = len(values)
    if length == 0 and not required:
        return None
    if length != n:
        what = f"{n} (one per name)" if required else f"0 or {n} (one per name)"
        raise WireError(f"{field}: length {length}, expected {what}")
    if isinstance(values, array.array):
        raw = np.frombuffer(values, dtype=np.float64) if length else np.empty(0)
    else:
        raw = np.asarray(values, dtype=np.float64)
    # A copy either way: the result never aliases the message.
    out = raw.copy() if perm is None else raw[perm]
    _check_finite(out, field, names, max_abs)
    return out


def _as_vector(values: Any, n: int, field: str, names: Sequence[str], max_abs) -> np.ndarray:
    """Validate an array about to be published: shape (n,), finite, bounded."""
    try:
        arr = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise WireError(f"{field}: not a float array ({err})") from None
    if arr.shape != (n,):
        raise WireError(f"{field}: shape {arr.shape}, expected ({n},) (one per joint)")
    _check_finite(arr, field, names, max_abs)
    return arr


def _to_double_array(arr: np.ndarray | None) -> array.array:
    if arr is None:
        return array.array("d")
    return array.array("d", np.ascontiguousarray(arr, dtype=np.float64).tobytes())


def _set_names(current: Sequence[str], names: Sequence[str]) -> list[str] | None:
    """Return a new name list if ``current`` differs from ``names`` (avoids re-validation)."""
    wanted = list(names)
    return None if list(current) == wanted else wanted


# ----------------------------------------------------------------------------------------------
# Joint states and torques
# ----------------------------------------------------------------------------------------------
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


_JS_FIELDS = ("position", "velocity", "effort")


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
    if not required <= set(_JS_FIELDS):
        raise ValueError(f"require must be a subset of {_JS_FIELDS}, got {sorted(required)}")
    perm = _check_names(msg.name, names, "name", allow_extra)
    n = len(msg.name)
    stamp = stamp_to_ns(msg.header.stamp)
    position = _field_array(
        msg.position, perm, n, "position", "position" in required, names, max_abs
    )
    velocity = _field_array(
        msg.velocity, perm, n, "velocity", "velocity" in required, names, max_abs
    )
    effort = _field_array(msg.effort, perm, n, "effort", "effort" in required, names, max_abs)
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
        arrays[field] = None if values is None else _as_vector(values, n, field, names, max_abs)
    sec, nanosec = _split_ns(stamp_ns, "header.stamp")
    if msg is None:
        msg = JointState()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    new_names = _set_names(msg.name, names)
    if new_names is not None:
        msg.name = new_names
    msg.position = _to_double_array(arrays["position"])
    msg.velocity = _to_double_array(arrays["velocity"])
    msg.effort = _to_double_array(arrays["effort"])
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


# ----------------------------------------------------------------------------------------------
# Set point (one-point JointTrajectory)
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class Setpoint:
    """The planned set point of one sample, as carried by :data:`SETPOINT`.

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
        _as_vector(v, n, f"points[0].{f}", names, max_abs)
        for f, v in (("positions", q), ("velocities", qd), ("accelerations", qdd), ("effort", u_n))
    ]
    sec, nanosec = _split_ns(stamp_ns, "header.stamp")
    tfs_sec, tfs_nanosec = _split_ns(time_from_start_ns, "points[0].time_from_start")
    if msg is None:
        msg = JointTrajectory()
    msg.header.stamp.sec = sec
    msg.header.stamp.nanosec = nanosec
    new_names = _set_names(msg.joint_names, names)
    if new_names is not None:
        msg.joint_names = new_names
    if len(msg.points) != 1:
        msg.points = [JointTrajectoryPoint()]
    point = msg.points[0]
    point.positions = _to_double_array(vectors[0])
    point.velocities = _to_double_array(vectors[1])
    point.accelerations = _to_double_array(vectors[2])
    point.effort = _to_double_array(vectors[3])
    point.time_from_start.sec = tfs_sec
    point.time_from_start.nanosec = tfs_nanosec
    return msg


def msg_to_setpoint(
    msg: JointTrajectory, names: Sequence[str], *, max_abs: float = DEFAULT_MAX_ABS
) -> Setpoint:
    """Read a set point message (see :func:`setpoint_to_msg`), reordered to ``names``.

    Raises
    ------
    WireError
        Naming the field: ``joint_names`` empty/duplicated/missing/unknown; ``points`` not exactly
        one; any of ``positions, velocities, accelerations, effort`` not one per joint, NaN, Inf or
        beyond ``max_abs``; a malformed stamp or ``time_from_start``.
    """
    perm = _check_names(msg.joint_names, names, "joint_names", False)
    if len(msg.points) != 1:
        raise WireError(f"points: a set point has exactly one point, got {len(msg.points)}")
    point = msg.points[0]
    n = len(msg.joint_names)
    stamp = stamp_to_ns(msg.header.stamp)
    arrays = [
        _field_array(getattr(point, f), perm, n, f"points[0].{f}", True, names, max_abs)
        for f in ("positions", "velocities", "accelerations", "effort")
    ]
    tfs = duration_to_ns(point.time_from_start, "points[0].time_from_start")
    return Setpoint(stamp, *arrays, time_from_start_ns=tfs)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------------------------
# Trajectory goal (waypoints)
# ----------------------------------------------------------------------------------------------
class Waypoints(NamedTuple):
    """Waypoints of a goal, reordered to the caller's joint order.

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


def msg_to_waypoints(
    msg: JointTrajectory, names: Sequence[str], *, max_abs: float = DEFAULT_MAX_ABS
) -> Waypoints:
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
    Waypoints

    Raises
    ------
    WireError
        Naming the field: ``joint_names`` problems as in :func:`joint_state_to_arrays`; ``points``
        empty; ``points[i].<field>`` of the wrong length, NaN/Inf or beyond ``max_abs``;
        velocities or accelerations given for some points only; ``points[i].time_from_start``
        not > 0 or not strictly increasing.
    """
    perm = _check_names(msg.joint_names, names, "joint_names", False)
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
        pos = _field_array(point.positions, perm, n, f"points[{i}].positions", True, names, max_abs)
        positions[i] = pos
        for field in optional:
            values = _field_array(
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
    return Waypoints(times, positions, optional["velocities"], optional["accelerations"])


# ----------------------------------------------------------------------------------------------
# Identification estimate (Float64MultiArray)
# ----------------------------------------------------------------------------------------------
#: ``layout.dim[0].label`` of an estimate: rows of Θ = [F G w] (p = 2n).
ESTIMATE_ROWS_LABEL = "theta_rows"
#: ``layout.dim[1].label`` of an estimate: columns of Θ (p + m + 1 = 3n + 1).
ESTIMATE_COLS_LABEL = "theta_cols"
#: The scalars after Θ in ``data``, in order.
ESTIMATE_TRAILER = ("trace_p", "residual_norm", "stamp_ns")


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class Estimate:
    """Identification telemetry of one sample (the feedback's RLS state).

    Attributes
    ----------
    stamp_ns : int
        Sample time ``kT`` the estimate was computed at (after the update with sample k).
    F : (p, p) ndarray
        State matrix estimate F̂ of ``δx(k+1) = F δx(k) + G δu(k) + w``.
    G : (p, m) ndarray
        Input matrix estimate Ĝ.
    w : (p,) ndarray
        Offset estimate ŵ.
    trace_p : float
        trace(P) of the RLS covariance.
    residual_norm : float
        Norm of the one-step prediction residual.
    """

    stamp_ns: int
    F: np.ndarray
    G: np.ndarray
    w: np.ndarray
    trace_p: float
    residual_norm: float

    @property
    def theta(self) -> np.ndarray:
        """Θ = [F G w], shape (p, p + m + 1), so that ``δx(k+1) = Θ z(k)``."""
        return np.hstack([self.F, self.G, self.w[:, None]])


def estimate_to_msg(
    F: Any,
    G: Any,
    w: Any,
    trace_p: float,
    residual_norm: float,
    *,
    stamp_ns: int,
    msg: Float64MultiArray | None = None,
) -> Float64MultiArray:
    """Pack an RLS estimate into a ``std_msgs/Float64MultiArray``.

    Layout (``p`` = state size 2n, ``m`` = input size n, ``c = p + m + 1`` = 3n + 1):

    - ``layout.dim[0]``: label ``"theta_rows"``, size ``p``, stride ``p * c``;
      ``layout.dim[1]``: label ``"theta_cols"``, size ``c``, stride ``c``; ``data_offset = 0``.
      So the layout describes, in the standard MultiArray way, the matrix Θ = [F G w] stored
      row-major in ``data[0 : p*c]`` (any MultiArray viewer shows Θ correctly).
    - ``data[p*c : p*c + 3]`` = ``[trace_p, residual_norm, stamp_ns]``
      (:data:`ESTIMATE_TRAILER`): two health scalars, then the sample time.

    ``Float64MultiArray`` has no header, so the sample time travels in the data, as a float64
    holding integer nanoseconds: exact up to 2**53 ns (104 days of run time). Recordings also log
    it with log time = the sample time, but the message must say which sample it is on its own.

    Parameters
    ----------
    F : (p, p) array_like
    G : (p, m) array_like
    w : (p,) array_like
    trace_p, residual_norm : float
    stamp_ns : int
        Sample time ``kT`` (keyword-only so it cannot be forgotten or swapped).
    msg : std_msgs.msg.Float64MultiArray, optional
        A preallocated message to refill.

    Returns
    -------
    std_msgs.msg.Float64MultiArray

    Raises
    ------
    WireError
        On inconsistent shapes, non-finite values, or a stamp outside ``[0, 2**53]`` ns.
    """
    F = np.asarray(F, dtype=np.float64)
    G = np.asarray(G, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    if F.ndim != 2 or F.shape[0] != F.shape[1] or F.shape[0] == 0:
        raise WireError(f"F: shape {F.shape}, expected square (p, p) with p > 0")
    p = F.shape[0]
    if G.ndim != 2 or G.shape[0] != p or G.shape[1] == 0:
        raise WireError(f"G: shape {G.shape}, expected ({p}, m) with m > 0")
    if w.shape != (p,):
        raise WireError(f"w: shape {w.shape}, expected ({p},)")
    for field, values in (("F", F), ("G", G), ("w", w)):
        _check_finite(values, field, (), math.inf)
    return theta_to_estimate_msg(
        np.hstack([F, G, w[:, None]]), trace_p, residual_norm, stamp_ns=stamp_ns, msg=msg
    )


def theta_to_estimate_msg(
    theta_t: Any,
    trace_p: float,
    residual_norm: float,
    *,
    stamp_ns: int,
    msg: Float64MultiArray | None = None,
) -> Float64MultiArray:
    """:func:`estimate_to_msg` from ``Θᵀ = [F G w]`` in one (p, 3n+1) array, as the identifier
    holds it (``Rls.model_view()``): no copies of F, G, w on the way.

    Raises
    ------
    WireError
        On a shape that is not (p, p + m + 1) with m > 0, non-finite values, or a stamp outside
        ``[0, 2**53]`` ns.
    """
    theta = np.asarray(theta_t, dtype=np.float64)
    if theta.ndim != 2 or theta.shape[0] == 0 or theta.shape[1] < theta.shape[0] + 2:
        raise WireError(f"theta: shape {theta.shape}, expected (p, p + m + 1) with m > 0")
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)):
        raise WireError(f"stamp_ns: must be integer nanoseconds, got {type(stamp_ns).__name__}")
    if not 0 <= stamp_ns <= 2**53:
        raise WireError(f"stamp_ns: {stamp_ns} is outside [0, 2**53] (not exact as float64)")
    rows, cols = theta.shape
    data = np.empty(rows * cols + 3)
    data[: rows * cols] = theta.ravel()
    data[rows * cols :] = (trace_p, residual_norm, float(stamp_ns))
    _check_finite(data[: rows * cols], "theta", (), math.inf)
    _check_finite(data[rows * cols : rows * cols + 1], "trace_p", (), math.inf)
    _check_finite(data[rows * cols + 1 : rows * cols + 2], "residual_norm", (), math.inf)
    if msg is None:
        msg = Float64MultiArray()
    if len(msg.layout.dim) != 2:
        msg.layout.dim = [MultiArrayDimension(), MultiArrayDimension()]
    d0, d1 = msg.layout.dim
    d0.label, d0.size, d0.stride = ESTIMATE_ROWS_LABEL, rows, rows * cols
    d1.label, d1.size, d1.stride = ESTIMATE_COLS_LABEL, cols, cols
    msg.layout.data_offset = 0
    msg.data = _to_double_array(data)
    return msg


def msg_to_estimate(msg: Float64MultiArray) -> Estimate:
    """Unpack an estimate message (see :func:`estimate_to_msg` for the layout).

    Returns
    -------
    Estimate

    Raises
    ------
    WireError
        Naming the field: ``layout.dim`` not the two labelled dimensions, strides inconsistent,
        ``layout.data_offset`` not 0, ``data`` of the wrong length, NaN/Inf, or a stamp that is
        not a non-negative integer.
    """
    dims = msg.layout.dim
    if len(dims) != 2:
        raise WireError(f"layout.dim: expected 2 dimensions (theta rows, cols), got {len(dims)}")
    d0, d1 = dims
    if (d0.label, d1.label) != (ESTIMATE_ROWS_LABEL, ESTIMATE_COLS_LABEL):
        raise WireError(
            f"layout.dim: labels ({d0.label!r}, {d1.label!r}), expected "
            f"({ESTIMATE_ROWS_LABEL!r}, {ESTIMATE_COLS_LABEL!r})"
        )
    p, c = d0.size, d1.size
    if p == 0 or c < p + 2:
        raise WireError(f"layout.dim: sizes ({p}, {c}), expected (p, p + m + 1) with p, m > 0")
    if d1.stride != c or d0.stride != p * c:
        raise WireError(
            f"layout.dim: strides ({d0.stride}, {d1.stride}), expected ({p * c}, {c}) (row-major)"
        )
    if msg.layout.data_offset != 0:
        raise WireError(f"layout.data_offset: {msg.layout.data_offset}, expected 0")
    expected = p * c + len(ESTIMATE_TRAILER)
    if len(msg.data) != expected:
        raise WireError(f"data: length {len(msg.data)}, expected {expected} (p*c + 3)")
    data = np.array(msg.data, dtype=np.float64)
    _check_finite(data[: p * c], "data", (), math.inf)
    theta = data[: p * c].reshape(p, c)
    trace_p, residual_norm, stamp = (float(v) for v in data[p * c :])
    for name, v in (("trace_p", trace_p), ("residual_norm", residual_norm)):
        if not math.isfinite(v):
            raise WireError(f"data ({name}): {'NaN' if math.isnan(v) else 'Inf'}")
    if not (math.isfinite(stamp) and stamp >= 0 and stamp == math.floor(stamp)):
        raise WireError(f"data (stamp_ns): {stamp} is not a non-negative integer")
    return Estimate(
        stamp_ns=int(stamp),
        F=theta[:, :p].copy(),
        G=theta[:, p : c - 1].copy(),
        w=theta[:, c - 1].copy(),
        trace_p=float(trace_p),
        residual_norm=float(residual_norm),
    )
