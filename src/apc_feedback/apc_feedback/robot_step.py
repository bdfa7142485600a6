"""What robot mode's loop answers each call with (:class:`apc_feedback.robot_loop.RobotLoop`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from apc_feedforward.nominal import Setpoint
from apc_msgs_py import JointSample


class Step(NamedTuple):
    """What the node publishes after one call of :class:`RobotLoop`, each None where there is
    none: the command row (``command_joints`` order); for observers, the sample taken (stamped
    ``kT``) and the plan's set point of that sample with the ``u_n`` sent; ``retime``: the
    sampling period (s) to build the loop again at, instead of starting (``period_from_driver``)."""

    command: np.ndarray | None = None
    sample: JointSample | None = None
    setpoint: Setpoint | None = None
    retime: float | None = None


NOTHING = Step()
