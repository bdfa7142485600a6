"""Joint-space trajectory planning for the feedforward path of apc.

The feedforward component of the adaptive perturbation controller needs the desired joint
position, velocity and acceleration ``(q_d, q̇_d, q̈_d)`` at every sampling instant ``k*T``; the
nominal torques ``u_n`` are then computed from them by Newton-Euler.  This module plans those
set points.  It is numpy and scipy: no ROS types, no clock, no Pinocchio.  Time is always passed
in, as in ros2_controllers' ``Trajectory::sample``.

The planners are piecewise polynomials in time (``scipy.interpolate.PPoly``); the paper's 4-3-4
is :class:`apc_feedforward.four_three_four.FourThreeFour`, on the base classes here:

* :class:`Quintic` -- a quintic point-to-point move with given boundary velocities and
  accelerations.
* :class:`Waypoints` -- quintic segments through the points of a
  ``trajectory_msgs/JointTrajectory`` goal.
* :class:`Rejoin` -- a trajectory from one of its times on, approached from a state off it.

Units are SI throughout: s, rad, rad/s, rad/s².  Every sampler holds the start point before
``t = 0`` and the final point from ``t = duration`` on, with zero velocity and acceleration.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BPoly, PPoly

__all__ = [
    "PiecewisePolynomial",
    "Quintic",
    "Rejoin",
    "Trajectory",
    "TrajectoryError",
    "Waypoints",
]

FloatArray = NDArray[np.float64]


class TrajectoryError(ValueError):
    """A trajectory was given a bad argument; the message names the argument."""


# --------------------------------------------------------------------------------------------
# Argument checking
# --------------------------------------------------------------------------------------------


def _as_float_array(name: str, value: ArrayLike) -> FloatArray:
    try:
        arr = np.array(value, dtype=np.float64)  # copy: callers must not alias our state
    except (TypeError, ValueError) as exc:
        raise TrajectoryError(f"{name}: not convertible to a float array ({exc})") from None
    if not np.all(np.isfinite(arr)):
        raise TrajectoryError(f"{name}: must be finite, got {value!r}")
    return arr


def _as_vector(name: str, value: ArrayLike, n: int | None = None) -> FloatArray:
    """``value`` as a finite float vector of shape ``(n,)`` (any length if ``n`` is None)."""
    arr = _as_float_array(name, value)
    if arr.ndim != 1:
        raise TrajectoryError(f"{name}: must be a 1-D array, got shape {arr.shape}")
    if n is not None and arr.shape != (n,):
        raise TrajectoryError(f"{name}: must have shape ({n},), got {arr.shape}")
    if arr.size == 0:
        raise TrajectoryError(f"{name}: must not be empty")
    return arr


def _as_broadcast_vector(name: str, value: ArrayLike, n: int) -> FloatArray:
    """A scalar or an ``(n,)`` array, returned as a finite ``(n,)`` float vector."""
    arr = _as_float_array(name, value)
    if arr.ndim == 0:
        return np.full(n, float(arr))
    if arr.shape != (n,):
        raise TrajectoryError(f"{name}: must be a scalar or have shape ({n},), got {arr.shape}")
    return arr


def _as_matrix(name: str, value: ArrayLike, shape: tuple[int, int]) -> FloatArray:
    arr = _as_float_array(name, value)
    if arr.shape != shape:
        raise TrajectoryError(f"{name}: must have shape {shape}, got {arr.shape}")
    return arr


def _as_positive(name: str, value: float) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TrajectoryError(f"{name}: must be a number, got {value!r}") from None
    if not (math.isfinite(x) and x > 0.0):
        raise TrajectoryError(f"{name}: must be finite and > 0, got {value!r}")
    return x


def _readonly(arr: FloatArray) -> FloatArray:
    arr.setflags(write=False)
    return arr


# --------------------------------------------------------------------------------------------
# Base classes
# --------------------------------------------------------------------------------------------


class Trajectory:
    """Interface of a joint-space trajectory sampled at times it is told.

    Subclasses implement :meth:`sample_many`; :meth:`sample` and :meth:`sample_at_period` are
    built on it, so all three give bit-identical values at the same time.

    Attributes
    ----------
    n_joints : int
        Number of joints ``n``.
    duration : float
        Time at which the final point is reached, s.
    """

    n_joints: int
    duration: float

    def sample_many(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Sample at the times ``t``.

        Parameters
        ----------
        t : array_like, shape (m,)
            Times from the start of the trajectory, s.  Need not be sorted.

        Returns
        -------
        q, qd, qdd : ndarray, shape (m, n)
            Position (rad), velocity (rad/s) and acceleration (rad/s²).

        Raises
        ------
        TrajectoryError
            If ``t`` is not 1-D or not finite.
        """
        raise NotImplementedError

    def sample(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Sample at one time ``t`` (s).

        Edge cases, as JTC's ``Trajectory::sample`` documents them:

        * ``t < 0``: the start point with zero velocity and acceleration (hold the start);
        * ``t >= duration``: the final point with zero velocity and acceleration (hold the
          last set point);
        * ``t`` exactly on an interior knot: the segment that starts there (the trajectory is
          continuous there, so the other side agrees to rounding).

        Returns
        -------
        q, qd, qdd : ndarray, shape (n,)
            rad, rad/s, rad/s².

        Raises
        ------
        TrajectoryError
            If ``t`` is not a finite number.
        """
        try:
            t_arr = np.array([float(t)])
        except (TypeError, ValueError):
            raise TrajectoryError(f"t: must be a number, got {t!r}") from None
        q, qd, qdd = self.sample_many(t_arr)
        return q[0], qd[0], qdd[0]

    def sample_at_period(
        self, period: float, n_samples: int | None = None
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Sample at ``t_k = k * period`` for ``k = 0 .. n_samples - 1``.

        ``t_k`` is computed as the product ``k * period`` (not by accumulating ``period``), so
        it equals the time the controller is told at step ``k`` exactly.

        Parameters
        ----------
        period : float
            Sampling period T, s, > 0.
        n_samples : int, optional
            Number of samples ``m >= 1``.  Default ``floor(duration / period + 1e-9) + 1``,
            i.e. up to and including the end when ``duration`` is a multiple of ``period``
            (the 1e-9 absorbs rounding such as ``1.0 / 0.01 = 99.999...``).  Samples past the
            end hold the final point.

        Returns
        -------
        t : ndarray, shape (m,)
            Sample times, s.
        q, qd, qdd : ndarray, shape (m, n)
            rad, rad/s, rad/s².

        Raises
        ------
        TrajectoryError
            If ``period`` is not finite and positive or ``n_samples`` is not an int >= 1.
        """
        period = _as_positive("period", period)
        if n_samples is None:
            n_samples = math.floor(self.duration / period + 1e-9) + 1
        elif isinstance(n_samples, bool) or not isinstance(n_samples, int | np.integer):
            raise TrajectoryError(f"n_samples: must be an int, got {n_samples!r}")
        elif n_samples < 1:
            raise TrajectoryError(f"n_samples: must be >= 1, got {n_samples}")
        t = np.arange(int(n_samples), dtype=np.float64) * period
        q, qd, qdd = self.sample_many(t)
        return t, q, qd, qdd


class PiecewisePolynomial(Trajectory):
    """Per-joint piecewise polynomial in time, held at rest outside ``[0, duration)``.

    The position is a :class:`scipy.interpolate.PPoly` with the joints on its trailing axis;
    velocity and acceleration are its derivatives.  Segment ``i`` covers
    ``knot_times[i] <= t < knot_times[i + 1]``: a time exactly on an interior knot belongs to
    the segment starting there, as PPoly evaluates.  The planners below are subclasses.

    Parameters
    ----------
    poly : scipy.interpolate.PPoly
        Coefficients of shape ``(d + 1, s, n)``, breakpoints strictly increasing from 0, s.
        Units: rad / s**k for power k.
    q_start, q_end : array_like, shape (n,)
        Held before 0 and from ``duration`` on.  Planners pass their exact boundary positions,
        so the hold is exact.

    Raises
    ------
    TrajectoryError
        On a shape mismatch, non-finite values or breakpoints not starting at 0.
    """

    def __init__(self, poly: PPoly, q_start: ArrayLike, q_end: ArrayLike) -> None:
        knots = _as_vector("knot_times", poly.x)
        if knots[0] != 0.0:
            raise TrajectoryError(f"knot_times: must start at 0, got {knots[0]}")
        if poly.c.ndim != 3 or poly.c.shape[2] == 0:
            shape = poly.c.shape
            raise TrajectoryError(f"coefficients: must have shape (d + 1, s, n), got {shape}")
        if not np.all(np.isfinite(poly.c)):
            raise TrajectoryError("coefficients: must be finite")
        n = poly.c.shape[2]
        self.n_joints = int(n)
        self.duration = float(knots[-1])
        self._knots = _readonly(knots)
        self._q = poly
        self._qd = poly.derivative(1)
        self._qdd = poly.derivative(2)
        self._q_start = _readonly(_as_vector("q_start", q_start, n))
        self._q_end = _readonly(_as_vector("q_end", q_end, n))

    @property
    def knot_times(self) -> FloatArray:
        """Segment boundaries, shape (s + 1,), s; ``knot_times[0] = 0``, last = ``duration``."""
        return self._knots

    @property
    def poly(self) -> PPoly:
        """The position polynomial (not held at the ends), rad; do not modify it."""
        return self._q

    @property
    def n_segments(self) -> int:
        """Number of polynomial segments ``s``."""
        return self._knots.size - 1

    def sample_many(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Sample at the times ``t``; see :meth:`Trajectory.sample` for the edge cases.

        Parameters
        ----------
        t : array_like, shape (m,)
            Times, s.

        Returns
        -------
        q, qd, qdd : ndarray, shape (m, n)
            rad, rad/s, rad/s².

        Raises
        ------
        TrajectoryError
            If ``t`` is not 1-D or not finite.
        """
        t_arr = _as_float_array("t", t)
        if t_arr.ndim != 1:
            raise TrajectoryError(f"t: must be a 1-D array, got shape {t_arr.shape}")
        q = self._q(t_arr)
        qd = self._qd(t_arr)
        qdd = self._qdd(t_arr)
        before = t_arr < 0.0
        after = t_arr >= self.duration
        # Hold: outside [0, duration) the set point is the end point at rest, never an
        # extrapolated polynomial (which would run away quickly for degree 4-5).
        q[before] = self._q_start
        q[after] = self._q_end
        hold = before | after
        qd[hold] = 0.0
        qdd[hold] = 0.0
        return q, qd, qdd


def _hermite_quintics(knots: FloatArray, q: FloatArray, qd: FloatArray, qdd: FloatArray) -> PPoly:
    """Quintic segments meeting position, velocity and acceleration, shape (s + 1, n) each, at
    every knot: ``BPoly.from_derivatives`` (Bernstein basis) converted to power basis."""
    conditions = np.stack((q, qd, qdd), axis=1)  # (s + 1, 3, n): each knot's derivatives
    return PPoly.from_bernstein_basis(BPoly.from_derivatives(knots, conditions))


# --------------------------------------------------------------------------------------------
# Planners
# --------------------------------------------------------------------------------------------


class Quintic(PiecewisePolynomial):
    """Quintic point-to-point move, per joint, with given boundary velocity and acceleration.

    ``q(tau) = sum_{k=0}^{5} c_k tau**k`` meets ``q, q̇, q̈`` at ``tau = 0`` and
    ``tau = duration``.  Note that sampling holds the end points at rest outside
    ``[0, duration)``, so non-zero boundary velocity or acceleration shows as a step there.

    Parameters
    ----------
    q0, qf : array_like, shape (n,)
        Start and end positions, rad.
    duration : float
        Move time, s, > 0.
    qd0, qdf : float or array_like of shape (n,), default 0
        Start and end velocities, rad/s.
    qdd0, qddf : float or array_like of shape (n,), default 0
        Start and end accelerations, rad/s².

    Raises
    ------
    TrajectoryError
        On non-finite values, shape mismatch or ``duration <= 0``.
    """

    def __init__(
        self,
        q0: ArrayLike,
        qf: ArrayLike,
        duration: float,
        qd0: float | ArrayLike = 0.0,
        qdd0: float | ArrayLike = 0.0,
        qdf: float | ArrayLike = 0.0,
        qddf: float | ArrayLike = 0.0,
    ) -> None:
        q0_v = _as_vector("q0", q0)
        n = q0_v.size
        qf_v = _as_vector("qf", qf, n)
        T = _as_positive("duration", duration)
        velocities = (_as_broadcast_vector("qd0", qd0, n), _as_broadcast_vector("qdf", qdf, n))
        accelerations = (
            _as_broadcast_vector("qdd0", qdd0, n),
            _as_broadcast_vector("qddf", qddf, n),
        )
        knots = np.array([0.0, T])
        poly = _hermite_quintics(
            knots, np.stack((q0_v, qf_v)), np.stack(velocities), np.stack(accelerations)
        )
        super().__init__(poly, q_start=q0_v, q_end=qf_v)
        self.q0 = _readonly(q0_v)
        self.qf = _readonly(qf_v)


class Waypoints(PiecewisePolynomial):
    """Quintic segments through the points of a ``JointTrajectory`` goal.

    The robot starts at ``q_start`` at ``t = 0`` at rest (zero velocity and acceleration) and
    passes waypoint ``j`` at ``times[j]``.  Between consecutive points a quintic meets position,
    velocity and acceleration at both ends, so position and velocity are continuous
    everywhere, and acceleration too because both neighbouring segments use the same
    waypoint acceleration.

    Velocity heuristic (when ``velocities`` is None).  With segment slopes
    ``s_j = (p_j - p_{j-1}) / (t_j - t_{j-1})`` (``p_0 = q_start``, ``t_0 = 0``), the velocity at
    an interior waypoint, per joint, is

    * 0 if the two adjacent slopes differ in sign or either is 0 (the waypoint is a turning
      point or the start/end of a dwell, so stopping there avoids overshoot);
    * otherwise their mean ``(s_j + s_{j+1}) / 2``, limited in magnitude to
      ``2 * min(|s_j|, |s_{j+1}|)``.

    The last waypoint gets zero velocity.  The limit keeps every segment monotone: a quintic
    with zero end accelerations whose end velocities lie in ``[0, 2 s]`` (same sign as its slope
    ``s``) has no interior extremum, so joints never overshoot a waypoint (checked numerically
    on a grid; with equal end velocities it fails between 2 s and 2.25 s).

    Acceleration choice (when ``accelerations`` is None): zero at every waypoint, interior ones
    included.  That is C2 by construction and keeps the monotonicity above; it is not the
    smoothest possible choice (a spline would spread acceleration), but it is simple and local.

    Parameters
    ----------
    q_start : array_like, shape (n,)
        Position at ``t = 0``, rad (normally the measured state when the goal arrives).
    times : array_like, shape (m,)
        ``time_from_start`` of each waypoint, s; strictly increasing, first > 0.
    positions : array_like, shape (m, n)
        Waypoint positions, rad.
    velocities : array_like, shape (m, n), optional
        Waypoint velocities, rad/s.  Default: the heuristic above.
    accelerations : array_like, shape (m, n), optional
        Waypoint accelerations, rad/s².  Default: zero.
    allow_nonzero_end_velocity : bool, default False
        Like JTC's ``allow_nonzero_velocity_at_trajectory_end``: by default a given non-zero
        final velocity is rejected, because the trajectory holds the final point at rest
        afterwards and the velocity set point would step.

    Attributes
    ----------
    knot_positions, knot_velocities, knot_accelerations : ndarray, shape (m + 1, n)
        The boundary values actually used, row 0 being the start.  Read-only.

    Raises
    ------
    TrajectoryError
        If ``times`` is not strictly increasing with a positive first entry, shapes do not
        match ``(m, n)``, a value is not finite, or the final velocity is non-zero (unless
        allowed).
    """

    def __init__(
        self,
        q_start: ArrayLike,
        times: ArrayLike,
        positions: ArrayLike,
        velocities: ArrayLike | None = None,
        accelerations: ArrayLike | None = None,
        *,
        allow_nonzero_end_velocity: bool = False,
    ) -> None:
        q0 = _as_vector("q_start", q_start)
        n = q0.size
        t_wp = _as_vector("times", times)
        m = t_wp.size
        if t_wp[0] <= 0.0:
            raise TrajectoryError(f"times: first time_from_start must be > 0, got {t_wp[0]}")
        if np.any(np.diff(t_wp) <= 0.0):
            raise TrajectoryError(f"times: must be strictly increasing, got {t_wp}")
        p_wp = _as_matrix("positions", positions, (m, n))

        knots = np.concatenate(([0.0], t_wp))
        P = np.vstack((q0, p_wp))  # (m + 1, n)
        dt = np.diff(knots)

        if velocities is None:
            V = self._heuristic_velocities(P, dt)
        else:
            V = np.vstack((np.zeros(n), _as_matrix("velocities", velocities, (m, n))))
            if not allow_nonzero_end_velocity and np.any(V[-1] != 0.0):
                raise TrajectoryError(
                    f"velocities: final waypoint velocity must be 0, got {V[-1]} "
                    "(pass allow_nonzero_end_velocity=True to accept it)"
                )
        if accelerations is None:
            Acc = np.zeros((m + 1, n))
        else:
            Acc = np.vstack((np.zeros(n), _as_matrix("accelerations", accelerations, (m, n))))

        super().__init__(_hermite_quintics(knots, P, V, Acc), q_start=q0, q_end=P[-1])
        self.knot_positions = _readonly(P)
        self.knot_velocities = _readonly(V)
        self.knot_accelerations = _readonly(Acc)

    @staticmethod
    def _heuristic_velocities(P: FloatArray, dt: FloatArray) -> FloatArray:
        """Knot velocities (m + 1, n): 0 at both ends, limited mean of slopes inside."""
        slopes = np.diff(P, axis=0) / dt[:, None]  # (m, n)
        V = np.zeros_like(P)
        left, right = slopes[:-1], slopes[1:]
        same_sign = np.sign(left) * np.sign(right) > 0.0  # False on a sign change or a 0 slope
        limit = 2.0 * np.minimum(np.abs(left), np.abs(right))
        mean = 0.5 * (left + right)
        V[1:-1] = np.where(same_sign, np.sign(mean) * np.minimum(np.abs(mean), limit), 0.0)
        return V


class Rejoin(Trajectory):
    """``base`` from its time ``t0`` on, rejoined from a state off it: robot mode's hand-back.

    The set point starts at the measured state (``q0``, ``qd0``) and its offset from ``base``
    decays to zero over ``duration`` s as a quintic that ends at rest (zero offset, offset
    velocity and offset acceleration), so a law taking over mid-motion starts at zero error and
    the plan keeps its timing: ``q(tau) = base(t0 + tau) + e(tau)`` with ``e(0) = q0 -
    base(t0)``, ``e'(0) = qd0 - base'(t0)``, ``e''(0) = 0``. It lasts until ``base`` ends or
    the offset has gone, whichever is later; before ``tau = 0`` it holds its start at rest.

    Raises
    ------
    TrajectoryError
        On a shape mismatch, non-finite values, a ``t0`` that is not finite or ``duration <= 0``.
    """

    def __init__(
        self, base: Trajectory, t0: float, q0: ArrayLike, qd0: ArrayLike, duration: float
    ) -> None:
        n = base.n_joints
        q0_v, qd0_v = _as_vector("q0", q0, n), _as_vector("qd0", qd0, n)
        while isinstance(base, Rejoin) and t0 >= base._offset.duration:
            base, t0 = base._base, base._t0 + t0  # an earlier rejoin that has ended: its plan
        q_b, qd_b, _ = base.sample(t0)
        self._base = base
        self._t0 = float(t0)
        self._offset = Quintic(q0_v - q_b, np.zeros(n), duration, qd0=qd0_v - qd_b)
        self._q_start = _readonly(q0_v)
        self.n_joints = n
        self.duration = max(self._offset.duration, base.duration - self._t0)

    def sample_many(self, t: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Sample at the times ``t`` (s from the rejoin's start); see :meth:`Trajectory.sample`."""
        t_arr = _as_float_array("t", t)
        if t_arr.ndim != 1:
            raise TrajectoryError(f"t: must be a 1-D array, got shape {t_arr.shape}")
        q, qd, qdd = self._base.sample_many(self._t0 + t_arr)
        e, ed, edd = self._offset.sample_many(t_arr)
        q, qd, qdd = q + e, qd + ed, qdd + edd
        before = t_arr < 0.0
        q[before] = self._q_start
        qd[before] = 0.0
        qdd[before] = 0.0
        return q, qd, qdd
