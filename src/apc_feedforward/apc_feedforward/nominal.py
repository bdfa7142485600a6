"""Nominal torques by recursive Newton-Euler (Eqs. 2-8) along a planned trajectory.

The feedforward component of the paper: given the set point ``(q_d, qd_d, qdd_d)(kT)`` it
computes ``u_n(k) = RNEA(q_d, qd_d, qdd_d)`` on the *controller's* model (which has the
inertia error and knows no payload). Pinocchio's ``rnea`` is the Luh-Walker-Paul recursion of
Eqs. 2-8 in spatial-algebra form: a forward pass for link velocities and accelerations
(Eqs. 2-5) and a backward pass for forces, moments and joint torques (Eqs. 6-8).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from apc_feedforward.trajectory import Trajectory

#: Samples of the plan evaluated at once by :meth:`Feedforward.sample` (0.64 s at T = 10 ms).
BLOCK = 64


class FeedforwardError(ValueError):
    """Bad feedforward input; the message names the argument."""


@dataclass(frozen=True)
class Setpoint:
    """One sample of the plan and its nominal torque.

    Attributes
    ----------
    k : int
        Sample index; the sample time is ``k * period``.
    t : float
        Time since the start of the current motion (s).
    q, qd, qdd : (n,) ndarray
        Planned position (rad), velocity (rad/s), acceleration (rad/s^2).
    u_n : (n,) ndarray
        Nominal torque (N m), Eqs. 2-8.
    """

    k: int
    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    u_n: np.ndarray


#: Planned speed (rad/s) over which the Coulomb term of the controllers' friction model rises
#: to its value, ``f tanh(qd / FRICTION_SPEED)``: smooth through a plan's rest, where the sign
#: of the planned velocity says nothing of the friction a still joint meets.
FRICTION_SPEED = 0.01


class JointFriction(NamedTuple):
    """A model's joint friction, per joint, in the order :func:`apc_core.robot.with_friction`
    takes it."""

    coulomb: np.ndarray  # N m (Pinocchio's ``model.friction``)
    viscous: np.ndarray  # N m s/rad (Pinocchio's ``model.damping``)


def joint_friction(model: pin.Model) -> JointFriction | None:
    """The model's friction (Pinocchio's ``model.friction`` and ``model.damping``, as
    :func:`apc_core.robot.with_friction` sets them); None where both are zero."""
    coulomb = np.array(model.friction, dtype=float)
    viscous = np.array(model.damping, dtype=float)
    return JointFriction(coulomb, viscous) if coulomb.any() or viscous.any() else None


def friction_torque(friction: JointFriction, qd: np.ndarray) -> np.ndarray:
    """The joints' ``friction`` (:func:`joint_friction`) at velocity ``qd``: ``b qd + f tanh(qd
    / FRICTION_SPEED)`` (N m, (n,))."""
    return friction.viscous * qd + friction.coulomb * np.tanh(np.asarray(qd) / FRICTION_SPEED)


def nominal_torque(
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    qd: np.ndarray,
    qdd: np.ndarray,
    friction: JointFriction | None = None,
) -> np.ndarray:
    """``u_n = D(q) qdd + h(q, qd) + c(q)`` by recursive Newton-Euler (Eqs. 2-8), shape (n,),
    plus the joints' ``friction`` (:func:`joint_friction`) at the planned velocity:
    ``b qd + f tanh(qd / FRICTION_SPEED)``, which RNEA leaves out. On a physical arm whose
    commands act a sample or more late, friction is what feedback cannot correct in time
    (docs/robot.md, "What sets the physical PUMA's miss at 100 Hz")."""
    tau = pin.rnea(model, data, q, qd, qdd)
    if friction is not None:
        tau = tau + friction_torque(friction, qd)
    if not np.logical_and.reduce(np.isfinite(tau)):  # np.all's wrapper costs more (per sample)
        raise FeedforwardError("nominal torque is not finite (check the set point)")
    return np.array(tau, dtype=float)


class Feedforward:
    """Samples a trajectory at ``k * period`` and turns each set point into a nominal torque.

    The trajectory starts at sample ``start_k``; before it the first point is held, after it
    the last (the trajectory's own hold semantics). Time is passed in as a sample index, never
    read from a clock.

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model.
    trajectory : Trajectory
    period : float
        Sampling period T (s).
    start_k : int
        Sample index at which the trajectory's t = 0 falls.
    interval_middle : bool
        Each set point's nominal torque is the plan's at ``(k + 1/2) T``, the middle of the
        interval a command computed at sample ``k`` is held over: a second-order approximation
        of the interval's mean torque, which is what a held command should carry (robot mode,
        ``feedforward_ahead``); its ``q``, ``qd``, ``qdd`` stay at ``kT``, where the error is
        measured. Off: Eqs. 2-8 at ``kT``, as the paper's sampled law takes them.
    """

    def __init__(
        self,
        model: pin.Model,
        trajectory: Trajectory,
        period: float,
        start_k: int = 0,
        interval_middle: bool = False,
    ) -> None:
        if not period > 0.0:
            raise FeedforwardError(f"period must be > 0 s, got {period}")
        if trajectory.n_joints != model.nv:
            raise FeedforwardError(
                f"trajectory has {trajectory.n_joints} joints, model has {model.nv}"
            )
        self.model = model
        self._data = model.createData()
        self._friction = joint_friction(model)
        self.period = float(period)
        self.trajectory = trajectory
        self.start_k = int(start_k)
        self.interval_middle = bool(interval_middle)
        # (first k, q, qd, qdd at the samples, q, qd, qdd where the nominal torque is taken)
        self._block: tuple[int, *tuple[np.ndarray, ...]] | None = None

    def set_trajectory(self, trajectory: Trajectory, start_k: int) -> None:
        """Replace the plan; it starts at sample ``start_k``."""
        if trajectory.n_joints != self.model.nv:
            raise FeedforwardError(
                f"trajectory has {trajectory.n_joints} joints, model has {self.model.nv}"
            )
        self.trajectory = trajectory
        self.start_k = int(start_k)
        self._block = None

    def end_k(self) -> int:
        """First sample index at or after the end of the current motion."""
        steps = int(np.ceil(self.trajectory.duration / self.period - 1e-9))
        return self.start_k + steps

    def sample(self, k: int) -> Setpoint:
        """Set point and nominal torque at sample ``k`` (time ``k * period``; the torque half a
        period on with ``interval_middle``).

        The plan is evaluated :data:`BLOCK` samples at a time (one vectorised
        ``sample_many``) and read from that block while ``k`` is in it: the per-sample cost is
        then RNEA alone. The same products ``(k - start_k) * period``, and the polynomial
        evaluates each time on its own, as ``trajectory.sample(t)`` does: the same bits.
        """
        t = (k - self.start_k) * self.period
        block = self._block
        if block is None or not block[0] <= k < block[0] + BLOCK:
            times = (np.arange(k, k + BLOCK) - self.start_k) * self.period
            arrays = self.trajectory.sample_many(times)
            for a in arrays:  # the set points hand out rows: nobody may write through them
                a.flags.writeable = False
            if self.interval_middle:
                torque_at = self.trajectory.sample_many(times + 0.5 * self.period)
            else:
                torque_at = arrays
            block = (k, *arrays, *torque_at)
            self._block = block
        i = k - block[0]
        q, qd, qdd = block[1][i], block[2][i], block[3][i]
        u_n = nominal_torque(
            self.model, self._data, block[4][i], block[5][i], block[6][i], self._friction
        )
        return Setpoint(k=k, t=t, q=q, qd=qd, qdd=qdd, u_n=u_n)

    def acting_later(self, setpoint: Setpoint, samples: int) -> Setpoint:
        """``setpoint`` (this plan's, sample ``k``) with the nominal torque of sample ``k +
        samples``: what the arm should get from a command that acts over that sample's
        interval. Position, velocity and acceleration stay sample ``k``'s (the error is
        measured there)."""
        if samples < 0:
            raise ValueError(f"samples must be >= 0, got {samples}")
        if samples == 0:
            return setpoint
        return replace(setpoint, u_n=self.sample(setpoint.k + samples).u_n)
