"""The torque robot mode holds the arm with when it cannot close the loop (the watchdog).

Without fresh joint states no feedback can be computed, so the watchdog sends one command and
falls silent; the driver keeps applying it. The model's gravity alone does not hold a payload
the model does not know: on the physical Panda at 250 Hz (``robot_sim``'s ``effects: panda``,
5 lb at the hand) the wrist dropped under it within the 0.1-0.3 s of a stall and the law,
back with the states, met an arm already falling (lost in one wall-time run; in simulated
time 6.7-20.5 deg with a hand-over for stalls of 0.2-0.3 s in the hold after a move).
:class:`HoldTorque` adds what the controllers have been applying beyond the model's gravity,
averaged over :data:`HOLD_MEAN_S`: on a hold, the payload and the friction the law has learnt
to carry (0.44-0.47 deg through those stalls, no hand-over). It is no torque for a moving arm:
in a move the average holds inertial torque too, and a stall there is still not survived.
"""

from __future__ import annotations

import numpy as np

#: Time constant (s) of the average of the torque the controllers add beyond gravity.
HOLD_MEAN_S = 0.1


class HoldTorque:
    """An exponential average (time constant :data:`HOLD_MEAN_S`) of ``sent - gravity``, the
    torque the controllers apply beyond the model's gravity at the measured position; told
    each sample's command, never a clock.

    Parameters
    ----------
    period : float
        Sample period T (s).
    """

    def __init__(self, period: float) -> None:
        if not period > 0.0:
            raise ValueError(f"period must be > 0 s, got {period}")
        self._weight = min(1.0, period / HOLD_MEAN_S)
        self._extra: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the average (a new activation: what was learnt may not be on the arm)."""
        self._extra = None

    def sent(self, torque: np.ndarray, gravity: np.ndarray) -> None:
        """A sample's command ``torque`` and the model's ``gravity`` at its measured position
        (model order, N m)."""
        extra = np.asarray(torque, dtype=float) - np.asarray(gravity, dtype=float)
        if not np.all(np.isfinite(extra)):
            return  # a non-finite command is never sent; nothing to learn from it
        if self._extra is None:
            self._extra = extra
        else:
            self._extra = self._extra + self._weight * (extra - self._extra)

    def torque(self, gravity: np.ndarray) -> np.ndarray:
        """The hold: ``gravity`` plus the average added beyond it (gravity alone before any
        command)."""
        gravity = np.asarray(gravity, dtype=float)
        return gravity.copy() if self._extra is None else gravity + self._extra
