"""A stand-in for robot mode's plan in synthetic-time tests of :class:`RobotLoop`."""

from __future__ import annotations

import math

import numpy as np

from apc_feedforward.goals import Sampled
from apc_feedforward.nominal import Setpoint
from apc_msgs_py import TrajectoryGoal

HOLD_U_N = 0.5  # the scripted plan's nominal torque on a hold


class ScriptedPlan:
    """A stand-in for the feedforward's plan (``GoalQueue``): the set points a test scripts by
    sample, else a hold of the position measured at the first sample after a restart; a stop
    spans its duration at samples ``period`` s apart, as ``GoalQueue.stopping`` has it."""

    def __init__(self, period: float = 0.01) -> None:
        self.period = period
        self._stop_span: tuple[int, int] | None = None
        self.setpoints: dict[int, Setpoint] = {}
        self.queued: list[TrajectoryGoal] = []
        self.hold: np.ndarray | None = None
        self.restarts = 0
        self.stops: list[tuple[int, np.ndarray, np.ndarray, float]] = []
        self.fail = False

    def restart(self) -> int:
        self.restarts += 1
        self.setpoints.clear()
        self.hold = None
        self._stop_span = None
        dropped, self.queued = len(self.queued), []
        return dropped

    def stop(self, k, position, velocity, duration) -> None:
        """Recorded; the stand-in holds the stop's start (``GoalQueue.stop``'s first set point)
        in place of what was scripted."""
        self.stops.append((k, position.copy(), velocity.copy(), duration))
        self.setpoints.clear()
        self.hold = position.copy()
        self._stop_span = (k, k + math.ceil(duration / self.period - 1e-9))  # Feedforward.end_k

    def stopping(self, k) -> bool:
        return self._stop_span is not None and self._stop_span[0] <= k < self._stop_span[1]

    def add(self, goal: TrajectoryGoal) -> None:
        if goal.times_s[-1] <= 0.0:
            raise ValueError("points: a goal must take time")
        self.queued.append(goal)

    def sample(self, k, position, render) -> Sampled:
        if self.fail:
            return Sampled(failed=ValueError("the plan cannot be computed"))
        sp = self.setpoints.get(k)
        if sp is None:
            if self.hold is None:
                self.hold = position.copy()
            n = position.size
            sp = Setpoint(k, 0.0, self.hold, np.zeros(n), np.zeros(n), np.full(n, HOLD_U_N))
        return Sampled(setpoint=sp, rendered=render(sp))
