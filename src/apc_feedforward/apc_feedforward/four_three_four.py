"""The 4-3-4 joint-interpolated trajectory (Paul; Fu, Gonzalez & Lee, *Robotics: Control,
Sensing, Vision and Intelligence*, ch. 4): the trajectory of the paper's "COMPUTER SIMULATION:
A THREE-JOINT PUMA ROBOT ARM" section, ``q = (0, 45, 45) deg`` to ``(90, -45, 135) deg`` in 1 s,
passing ``(45, 0, 90) deg`` at 0.5 s (which angles and times are used is decided by the
configuration layer, not here). numpy and scipy, on :mod:`apc_feedforward.trajectory`'s
piecewise polynomials."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import PPoly

from apc_feedforward.trajectory import (
    FloatArray,
    PiecewisePolynomial,
    TrajectoryError,
    _as_float_array,
    _as_positive,
    _as_vector,
    _readonly,
)

__all__ = ["LIFT_OFF", "SEGMENT_TIMES", "SET_DOWN", "FourThreeFour"]

#: The paper's 4-3-4 shape, the default of every 4-3-4 move: lift-off, travel and set-down
#: durations (s) of its 1 s move, and the lift-off and set-down points as fractions of the travel.
SEGMENT_TIMES = (0.2, 0.6, 0.2)
LIFT_OFF = 0.1
SET_DOWN = 0.9


def _basis_row(degree: int, u: float, derivative: int) -> FloatArray:
    """Row ``[d^j/du^j u**k for k = 0..degree]`` evaluated at ``u``."""
    row = np.zeros(degree + 1)
    for k in range(derivative, degree + 1):
        factor = math.prod(range(k - derivative + 1, k + 1))  # k! / (k - j)!
        row[k] = factor * u ** (k - derivative)
    return row


class FourThreeFour(PiecewisePolynomial):
    """4-3-4 joint-interpolated trajectory (the paper's planned trajectory).

    Per joint: a quartic from the initial point ``q0`` to the lift-off point, a cubic from
    lift-off to set-down, and a quartic from set-down to the final point ``qf``.  The 14
    coefficients per joint are fixed by 14 conditions (Fu, Gonzalez & Lee, ch. 4):

    * ``q(0) = q0``, ``q̇(0) = 0``, ``q̈(0) = 0``;
    * at lift-off ``t1``: both adjacent segments equal the lift-off position, and velocity and
      acceleration are continuous (4 conditions);
    * at set-down ``t1 + t2``: likewise (4 conditions);
    * ``q(t_f) = qf``, ``q̇(t_f) = 0``, ``q̈(t_f) = 0``.

    The 14x14 matrix depends only on the segment times, so one system with ``n`` right-hand
    sides is solved for all joints (``numpy.linalg.solve``; no inverse).  Each segment is
    solved in normalised time and its coefficients rescaled to seconds.

    With the default symmetric segment times and 10 % / 90 % lift-off / set-down, the
    trajectory is point-symmetric about its midpoint: ``q(t_f / 2) = (q0 + qf) / 2``.  For the
    paper's move, ``(0, 45, 45) -> (90, -45, 135) deg`` in 1 s, that is ``(45, 0, 90) deg`` at
    0.5 s, where the paper says links 2 and 3 are fully stretched.

    Parameters
    ----------
    q0, qf : array_like, shape (n,)
        Initial and final joint positions, rad.
    segment_times : sequence of 3 floats, default :data:`SEGMENT_TIMES`
        Durations ``(t1, t2, t3)`` of the lift-off, travel and set-down segments, s, each > 0.
    lift_off, set_down : float or (n,) array_like, default :data:`LIFT_OFF`, :data:`SET_DOWN`
        A float is a fraction of each joint's travel (position ``q0 + f * (qf - q0)``) and must
        lie in (0, 1); an array is the explicit joint positions, rad.  When both are fractions,
        ``lift_off < set_down`` is required.

    Attributes
    ----------
    q0, qf, lift_off_position, set_down_position : ndarray, shape (n,)
        Read-only, rad.

    Raises
    ------
    TrajectoryError
        If a segment time is not finite and positive, ``q0``/``qf`` are not finite or differ in
        shape, or ``lift_off``/``set_down`` are out of range or of the wrong shape.
    """

    def __init__(
        self,
        q0: ArrayLike,
        qf: ArrayLike,
        segment_times: Sequence[float] = SEGMENT_TIMES,
        lift_off: float | ArrayLike = LIFT_OFF,
        set_down: float | ArrayLike = SET_DOWN,
    ) -> None:
        q0_v = _as_vector("q0", q0)
        n = q0_v.size
        qf_v = _as_vector("qf", qf, n)
        times = _as_float_array("segment_times", segment_times)
        if times.shape != (3,):
            raise TrajectoryError(f"segment_times: must have 3 entries, got shape {times.shape}")
        for i, ti in enumerate(times):
            _as_positive(f"segment_times[{i}]", ti)
        q_lift = self._via_point("lift_off", lift_off, q0_v, qf_v)
        q_set = self._via_point("set_down", set_down, q0_v, qf_v)
        if _is_fraction(lift_off) and _is_fraction(set_down) and not lift_off < set_down:
            raise TrajectoryError(
                f"lift_off: fraction must be < set_down, got {lift_off} >= {set_down}"
            )

        t1, t2, t3 = (float(x) for x in times)
        coeffs = self._solve(t1, t2, t3, q0_v, q_lift, q_set, qf_v)
        knots = np.array([0.0, t1, t1 + t2, t1 + t2 + t3])
        # PPoly stores the highest power first: (3, 5, n) ascending -> (5, 3, n) descending.
        poly = PPoly(np.ascontiguousarray(coeffs[:, ::-1, :].transpose(1, 0, 2)), knots)
        super().__init__(poly, q_start=q0_v, q_end=qf_v)
        self.q0 = _readonly(q0_v)
        self.qf = _readonly(qf_v)
        self.lift_off_position = _readonly(q_lift)
        self.set_down_position = _readonly(q_set)

    @staticmethod
    def _via_point(
        name: str, value: float | ArrayLike, q0: FloatArray, qf: FloatArray
    ) -> FloatArray:
        if _is_fraction(value):
            f = float(value)  # type: ignore[arg-type]
            if not (math.isfinite(f) and 0.0 < f < 1.0):
                raise TrajectoryError(f"{name}: fraction of travel must be in (0, 1), got {f}")
            return q0 + f * (qf - q0)
        return _as_vector(name, value, q0.size)

    @staticmethod
    def _solve(
        t1: float,
        t2: float,
        t3: float,
        q0: FloatArray,
        q_lift: FloatArray,
        q_set: FloatArray,
        qf: FloatArray,
    ) -> FloatArray:
        """Coefficients, shape (3, 5, n), in local time (s); the cubic's 5th entry is 0."""
        # Unknowns x = [a0..a4 | b0..b3 | c0..c4] in normalised time u = tau / t_i of each
        # segment.  A time derivative of order j is (d^j/du^j) / t_i**j; the continuity rows
        # are multiplied through by t1**j (or t2**j) so the matrix depends only on time ratios.
        A = np.zeros((14, 14))
        B = np.zeros((14, q0.size))
        s1, s2, s3 = slice(0, 5), slice(5, 9), slice(9, 14)
        r12, r23 = t1 / t2, t2 / t3
        rows = [
            # start at rest
            ((s1, _basis_row(4, 0.0, 0)), None, q0),
            ((s1, _basis_row(4, 0.0, 1)), None, 0.0),
            ((s1, _basis_row(4, 0.0, 2)), None, 0.0),
            # lift-off knot
            ((s1, _basis_row(4, 1.0, 0)), None, q_lift),
            ((s2, _basis_row(3, 0.0, 0)), None, q_lift),
            ((s1, _basis_row(4, 1.0, 1)), (s2, -r12 * _basis_row(3, 0.0, 1)), 0.0),
            ((s1, _basis_row(4, 1.0, 2)), (s2, -(r12**2) * _basis_row(3, 0.0, 2)), 0.0),
            # set-down knot
            ((s2, _basis_row(3, 1.0, 0)), None, q_set),
            ((s3, _basis_row(4, 0.0, 0)), None, q_set),
            ((s2, _basis_row(3, 1.0, 1)), (s3, -r23 * _basis_row(4, 0.0, 1)), 0.0),
            ((s2, _basis_row(3, 1.0, 2)), (s3, -(r23**2) * _basis_row(4, 0.0, 2)), 0.0),
            # end at rest
            ((s3, _basis_row(4, 1.0, 0)), None, qf),
            ((s3, _basis_row(4, 1.0, 1)), None, 0.0),
            ((s3, _basis_row(4, 1.0, 2)), None, 0.0),
        ]
        for i, (first, second, rhs) in enumerate(rows):
            A[i, first[0]] = first[1]
            if second is not None:
                A[i, second[0]] = second[1]
            B[i] = rhs
        x = np.linalg.solve(A, B)  # (14, n)

        coeffs = np.zeros((3, 5, q0.size))
        for seg, (sl, ti) in enumerate(((s1, t1), (s2, t2), (s3, t3))):
            a = x[sl]
            coeffs[seg, : a.shape[0]] = a / (ti ** np.arange(a.shape[0]))[:, None]
        return coeffs


def _is_fraction(value: object) -> bool:
    """True for a plain real scalar (a fraction of travel), False for an array of positions."""
    return np.ndim(value) == 0 and not isinstance(value, bool | str)
