"""Messages made to break the nodes, as hypothesis strategies: the fuzz tests' input.

:data:`BATCH` draws, for every subscribed topic, messages that are invalid for every node that
subscribes to it (:class:`Garbage`: NaN/Inf, values beyond 1e6, missing, unknown or duplicated
joint names, wrong lengths, empty messages, negative, off-grid or stale stamps), each with the
counter it must bump; :func:`extreme_goal` draws goals that pass the wire's checks but may be
absurdly fast. Every injected message carries ``header.frame_id = FUZZ`` so that a capturing
node can tell it from the nodes' own output (the nodes never read ``frame_id``).

Stamps are drawn relative to the plant's current sample and resolved when the message is
built (:meth:`Garbage.build`), so that "stale" and "ahead" mean what they say at publish time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration, Time
from hypothesis import strategies as st
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

import apc_msgs_py as wire

from .arm import LOWER, NAMES, T_NS, UPPER, N

FUZZ = "fuzz"  # header.frame_id of every injected message
NAN, INF = float("nan"), float("inf")
#: The per-joint fields of a set point (one JointTrajectoryPoint).
SETPOINT_FIELDS = ("positions", "velocities", "accelerations", "effort")


# ----------------------------------------------------------------------------------------------
# Stamps: resolved when the message is published, relative to the plant's current sample k
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Stamp:
    """``kind``: rel (plausible: k + a), neg (< 0), offgrid (k + a, plus b ns), nanosec
    (nanosec >= 1e9), stale (k - a, a >= 2: older than any sample a node still waits for),
    far (k + 100000 + a: in the future, only for torques)."""

    kind: str
    a: int = 0
    b: int = 0

    def resolve(self, k: int) -> Time:
        if self.kind == "nanosec":
            return Time(sec=max(k + self.a, 0) * T_NS // wire.NS_PER_S, nanosec=self.b)
        ns = {
            "rel": max(k + self.a, 0) * T_NS,
            "neg": -self.a * T_NS - self.b,
            "offgrid": max(k + self.a, 0) * T_NS + self.b,
            "stale": (k - self.a) * T_NS,
            "far": (k + 100_000 + self.a) * T_NS,
        }[self.kind]
        sec, nanosec = divmod(ns, wire.NS_PER_S)
        return Time(sec=sec, nanosec=nanosec)


def stamps(*kinds: str) -> st.SearchStrategy[Stamp]:
    options = {
        "rel": st.builds(Stamp, st.just("rel"), st.integers(-3, 3)),
        "neg": st.one_of(
            st.builds(Stamp, st.just("neg"), st.integers(1, 10**6)),  # on the grid
            st.builds(Stamp, st.just("neg"), st.integers(0, 10**6), st.integers(1, T_NS - 1)),
        ),
        "offgrid": st.builds(
            Stamp, st.just("offgrid"), st.integers(-2, 3), st.integers(1, T_NS - 1)
        ),
        "nanosec": st.builds(
            Stamp, st.just("nanosec"), st.integers(-2, 3), st.integers(wire.NS_PER_S, 2**32 - 1)
        ),
        "stale": st.builds(Stamp, st.just("stale"), st.integers(2, 50)),
        "far": st.builds(Stamp, st.just("far"), st.integers(0, 10**5)),
    }
    return st.one_of(*(options[k] for k in kinds))


PLAUSIBLE = st.floats(-3.0, 3.0, allow_nan=False)
BAD = st.one_of(
    st.sampled_from([NAN, INF, -INF]),
    st.floats(1.0e6, 1e308, exclude_min=True),
    st.floats(-1e308, -1.0e6, exclude_max=True),
)
UNKNOWN_NAME = st.text(max_size=8).filter(lambda s: s not in NAMES)


def vec(draw: Any, n: int, values: Any = PLAUSIBLE) -> list[float]:
    return [draw(values) for _ in range(n)]


def spoil(draw: Any, values: list[float]) -> list[float]:
    """One entry replaced by NaN, Inf or a value beyond 1e6."""
    out = list(values)
    out[draw(st.integers(0, len(out) - 1))] = draw(BAD)
    return out


NAME_DEFECTS = ("no_names", "missing", "unknown", "extra", "duplicate")


def apply_name_defect(draw: Any, defect: str, names: list[str], columns: list[list]) -> list[str]:
    """Spoil the joint names; ``columns`` (per-joint arrays) are kept consistent in place."""
    i = draw(st.integers(0, N - 1))
    if defect == "no_names":
        return []
    if defect == "missing":
        for col in columns:
            if len(col) == N:
                del col[i]
        return names[:i] + names[i + 1 :]
    if defect == "unknown":
        return [*names[:i], draw(UNKNOWN_NAME), *names[i + 1 :]]
    if defect == "extra":
        for col in columns:
            if len(col) == N:
                col.append(draw(PLAUSIBLE))
        return [*names, draw(UNKNOWN_NAME)]
    j = draw(st.integers(0, N - 1).filter(lambda j: j != i))
    out = list(names)
    out[i] = out[j]
    return out


# ----------------------------------------------------------------------------------------------
# Garbage messages: each is invalid for every node that subscribes to its topic
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Garbage:
    """One injected message. ``expect``: the counter it must bump at the receiving node(s)."""

    topic: str
    defect: str
    stamp: Stamp
    names: tuple[str, ...] = ()
    fields: tuple[tuple[str, tuple[float, ...]], ...] = ()
    points: tuple[tuple[tuple[str, tuple[float, ...]], ...], ...] = ()
    times_ns: tuple[int, ...] = ()
    tfs_nanosec: int = 0
    expect: str = "rejected"

    def expected_counter(self, k: int) -> str:
        """``rejected`` or ``out_of_order`` (a stale torque), given the plant's sample k."""
        if self.expect == "out_of_order" and k - self.stamp.a < 0:
            return "rejected"  # older than sample 0: a negative stamp
        return self.expect

    def build(self, k: int) -> Any:
        if self.defect == "empty":
            msg = (
                JointState()
                if self.topic != wire.TRAJECTORY_GOAL and self.topic != wire.SETPOINT
                else JointTrajectory()
            )
            msg.header.frame_id = FUZZ
            return msg
        if self.topic in (wire.JOINT_STATES, wire.FEEDFORWARD_TORQUE, wire.FEEDBACK_TORQUE):
            msg = JointState(name=list(self.names), **{f: list(v) for f, v in self.fields})
        else:
            msg = JointTrajectory(joint_names=list(self.names))
            for i, point in enumerate(self.points):
                t = self.times_ns[i] if i < len(self.times_ns) else 0
                sec, nanosec = divmod(t, wire.NS_PER_S)
                p = JointTrajectoryPoint(
                    time_from_start=Duration(sec=sec, nanosec=nanosec),
                    **{f: list(v) for f, v in point},
                )
                if i == 0 and self.tfs_nanosec:
                    p.time_from_start.nanosec = self.tfs_nanosec
                msg.points.append(p)
        msg.header.stamp = self.stamp.resolve(k)
        msg.header.frame_id = FUZZ
        return msg


ANY_STAMP = ("rel", "neg", "offgrid", "nanosec", "stale")


@st.composite
def bad_joint_state(draw: Any) -> Garbage:
    """Invalid on ``joint_states`` for both controllers (ff needs position, fb also velocity)."""
    defect = draw(
        st.sampled_from(
            (
                "empty",
                *NAME_DEFECTS,
                "len_position",
                "len_velocity",
                "len_effort",
                "bad_position",
                "bad_velocity",
                "bad_effort",
                "stamp",
            )
        )
    )
    names = [NAMES[i] for i in draw(st.permutations(range(N)))]
    position, velocity = vec(draw, N), vec(draw, N)
    effort = vec(draw, N) if draw(st.booleans()) else []
    if defect in NAME_DEFECTS:
        names = apply_name_defect(draw, defect, names, [position, velocity, effort])
    elif defect == "len_position":
        position = vec(draw, draw(st.sampled_from((0, 1, 2, 4, 5))))
    elif defect == "len_velocity":
        velocity = vec(draw, draw(st.sampled_from((1, 2, 4))))
    elif defect == "len_effort":
        effort = vec(draw, draw(st.sampled_from((1, 2, 4))))
    elif defect == "bad_position":
        position = spoil(draw, position)
    elif defect == "bad_velocity":
        velocity = spoil(draw, velocity)
    elif defect == "bad_effort":
        effort = spoil(draw, vec(draw, N))
    stamp = draw(
        stamps(*(("neg", "offgrid", "nanosec", "stale") if defect == "stamp" else ANY_STAMP))
    )
    return Garbage(
        wire.JOINT_STATES,
        defect,
        stamp,
        tuple(names),
        (("position", tuple(position)), ("velocity", tuple(velocity)), ("effort", tuple(effort))),
    )


@st.composite
def bad_torque(draw: Any, topic: str) -> Garbage:
    """Invalid on a torque topic (the plant), or a stale stamp the plant must ignore."""
    defect = draw(
        st.sampled_from(
            (
                "empty",
                *NAME_DEFECTS,
                "len_effort",
                "bad_effort",
                "has_position",
                "has_velocity",
                "stamp",
                "stale",
            )
        )
    )
    names = [NAMES[i] for i in draw(st.permutations(range(N)))]
    effort = vec(draw, N, st.floats(-50.0, 50.0))
    position: list[float] = []
    velocity: list[float] = []
    if defect in NAME_DEFECTS:
        names = apply_name_defect(draw, defect, names, [effort])
    elif defect == "len_effort":
        effort = vec(draw, draw(st.sampled_from((0, 1, 2, 4))))
    elif defect == "bad_effort":
        effort = spoil(draw, effort)
    elif defect == "has_position":
        position = vec(draw, N)
    elif defect == "has_velocity":
        velocity = vec(draw, N)
    if defect == "stamp":
        stamp = draw(stamps("neg", "offgrid", "nanosec", "far"))
    elif defect == "stale":
        stamp = draw(stamps("stale"))
    else:
        stamp = draw(stamps(*ANY_STAMP))
    return Garbage(
        topic,
        defect,
        stamp,
        tuple(names),
        (("position", tuple(position)), ("velocity", tuple(velocity)), ("effort", tuple(effort))),
        expect="out_of_order" if defect == "stale" else "rejected",
    )


@st.composite
def bad_setpoint(draw: Any) -> Garbage:
    """Invalid on ``feedforward/setpoint`` (the feedback node)."""
    defect = draw(
        st.sampled_from(
            (
                "empty",
                *NAME_DEFECTS,
                "points0",
                "points2",
                *(f"len_{f}" for f in SETPOINT_FIELDS),
                *(f"bad_{f}" for f in SETPOINT_FIELDS),
                "tfs_nanosec",
                "stamp",
            )
        )
    )
    names = [NAMES[i] for i in draw(st.permutations(range(N)))]
    cols = {f: vec(draw, N) for f in SETPOINT_FIELDS}
    n_points = 1
    tfs_nanosec = 0
    if defect in NAME_DEFECTS:
        names = apply_name_defect(draw, defect, names, list(cols.values()))
    elif defect == "points0":
        n_points = 0
    elif defect == "points2":
        n_points = 2
    elif defect.startswith("len_"):
        cols[defect[4:]] = vec(draw, draw(st.sampled_from((0, 1, 2, 4))))
    elif defect.startswith("bad_"):
        cols[defect[4:]] = spoil(draw, cols[defect[4:]])
    elif defect == "tfs_nanosec":
        tfs_nanosec = draw(st.integers(wire.NS_PER_S, 2**32 - 1))
    stamp = draw(
        stamps(*(("neg", "offgrid", "nanosec", "stale") if defect == "stamp" else ANY_STAMP))
    )
    point = tuple((f, tuple(v)) for f, v in cols.items())
    return Garbage(
        wire.SETPOINT,
        defect,
        stamp,
        tuple(names),
        points=(point,) * n_points,
        times_ns=(draw(st.integers(0, 10**9)),) * n_points,
        tfs_nanosec=tfs_nanosec,
    )


@st.composite
def bad_goal(draw: Any) -> Garbage:
    """Invalid on ``feedforward/trajectory`` (the feedforward node)."""
    defect = draw(
        st.sampled_from(
            (
                "empty",
                *NAME_DEFECTS,
                "points0",
                "times_not_increasing",
                "first_time_not_positive",
                "tfs_nanosec",
                "len_positions",
                "len_velocities",
                "len_accelerations",
                "velocities_some",
                "bad_positions",
                "bad_velocities",
                "bad_accelerations",
                "out_of_limits",
                "final_velocity",
            )
        )
    )
    m = draw(st.integers(2 if defect in ("times_not_increasing", "velocities_some") else 1, 4))
    names = [NAMES[i] for i in draw(st.permutations(range(N)))]
    order = [NAMES.index(name) for name in names]
    times = list(np.cumsum([draw(st.integers(50, 500)) * 1_000_000 for _ in range(m)]))
    inside = st.floats(0.0, 1.0)
    points = []
    with_vel, with_acc = draw(st.booleans()), draw(st.booleans())
    for j in range(m):
        pos = [LOWER[i] + 0.1 + draw(inside) * (UPPER[i] - LOWER[i] - 0.2) for i in order]
        cols = {"positions": pos}
        if with_vel:
            cols["velocities"] = [0.0] * N if j == m - 1 else vec(draw, N, st.floats(-1, 1))
        if with_acc:
            cols["accelerations"] = vec(draw, N, st.floats(-1, 1))
        points.append(cols)
    tfs_nanosec = 0
    j = draw(st.integers(0, m - 1))
    if defect in NAME_DEFECTS:
        defect_cols = [col for p in points for col in p.values()]
        names = apply_name_defect(draw, defect, names, defect_cols)
    elif defect == "points0":
        points, times = [], []
    elif defect == "times_not_increasing":
        j = max(j, 1)
        times[j] = times[j - 1] - draw(st.integers(0, times[j - 1]))
    elif defect == "first_time_not_positive":
        times[0] = -draw(st.integers(0, 10**9))
    elif defect == "tfs_nanosec":
        tfs_nanosec = draw(st.integers(wire.NS_PER_S, 2**32 - 1))
    elif defect.startswith("len_"):
        points[j][defect[4:]] = vec(draw, draw(st.sampled_from((1, 2, 4))))
    elif defect == "velocities_some":
        for p in points:
            p["velocities"] = [0.0] * N
        del points[j]["velocities"]
    elif defect.startswith("bad_"):
        points[j][defect[4:]] = spoil(draw, points[j].get(defect[4:], vec(draw, N)))
    elif defect == "out_of_limits":
        i = draw(st.integers(0, N - 1))
        beyond = draw(st.floats(0.05, 1e5))
        limit = LOWER[order[i]] - beyond if draw(st.booleans()) else UPPER[order[i]] + beyond
        points[j]["positions"][i] = limit
    elif defect == "final_velocity":
        for p in points:
            p.setdefault("velocities", [0.0] * N)
        points[-1]["velocities"][draw(st.integers(0, N - 1))] = draw(st.floats(0.1, 2.0))
    return Garbage(
        wire.TRAJECTORY_GOAL,
        defect,
        Stamp("rel"),
        tuple(names),
        points=tuple(tuple((f, tuple(v)) for f, v in p.items()) for p in points),
        times_ns=tuple(int(t) for t in times),
        tfs_nanosec=tfs_nanosec,
    )


BATCH = st.fixed_dictionaries(
    {
        wire.JOINT_STATES: st.lists(bad_joint_state(), max_size=5),
        wire.SETPOINT: st.lists(bad_setpoint(), max_size=5),
        wire.FEEDFORWARD_TORQUE: st.lists(bad_torque(wire.FEEDFORWARD_TORQUE), max_size=5),
        wire.FEEDBACK_TORQUE: st.lists(bad_torque(wire.FEEDBACK_TORQUE), max_size=5),
        wire.TRAJECTORY_GOAL: st.lists(bad_goal(), max_size=3),
    }
)


# ----------------------------------------------------------------------------------------------
# Valid-looking goals: they pass the wire's checks, but may be absurdly fast
# ----------------------------------------------------------------------------------------------
def extreme_goal() -> st.SearchStrategy[JointTrajectory]:
    """Goals that pass the wire's checks but may be absurdly fast: waypoints inside the joint
    limits (or just outside), 1 ns to 50 ms apart, velocities/accelerations up to 1e5."""

    @st.composite
    def build(draw: Any) -> JointTrajectory:
        m = draw(st.integers(1, 3))
        t = 0
        msg = JointTrajectory(joint_names=list(NAMES))
        msg.header.frame_id = FUZZ
        big = st.one_of(st.floats(-1e5, 1e5), st.sampled_from([-1e5, -1e4, 1e3, 1e4, 1e5]))
        with_vel, with_acc = draw(st.booleans()), draw(st.booleans())
        for j in range(m):
            t += draw(
                st.one_of(
                    st.integers(1, 1000),  # ns apart: everything happens between two samples
                    st.integers(1, 5).map(lambda j: j * T_NS),  # on samples: their values show
                    st.integers(1, 50_000_000),
                )
            )
            pos = [draw(st.floats(float(LOWER[i]) - 0.2, float(UPPER[i]) + 0.2)) for i in range(N)]
            point = JointTrajectoryPoint(positions=pos, time_from_start=wire.ns_to_duration(t))
            if with_vel:
                point.velocities = [0.0] * N if j == m - 1 else [draw(big) for _ in range(N)]
            if with_acc:
                point.accelerations = [draw(big) for _ in range(N)]
            msg.points.append(point)
        return msg

    return build()
