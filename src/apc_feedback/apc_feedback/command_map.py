"""Robot mode's command row: the model's torques in the driver's joint order, clipped to the
effort limits (the row a forward_command_controller takes on its ``~/commands``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from apc_feedback.arrays import any_true


class CommandMap:
    """Model-order torques -> one ``Float64MultiArray`` row in ``command_joints`` order, clipped.

    Parameters
    ----------
    model_joints : sequence of str
        The model's joint order (every array in apc).
    command_joints : sequence of str
        The command's order (the forward_command_controller's ``joints``): the same joints.
    effort_limit : (n,) array
        Per-joint bound in model order (the URDF's ``<limit effort>``).
    count : callable
        ``count("clipped.<joint>")`` for each joint clipped.
    """

    def __init__(
        self,
        model_joints: Sequence[str],
        command_joints: Sequence[str],
        effort_limit: np.ndarray,
        count: Callable[[str], object] = lambda name: None,
    ) -> None:
        model, command = list(model_joints), list(command_joints)
        if sorted(model) != sorted(command) or len(set(command)) != len(command):
            raise ValueError(
                f"command_joints must list the model's joints {model} once each, got {command}"
            )
        self.model_joints = tuple(model)
        self.joints = tuple(command)
        self.order = np.array([model.index(name) for name in command])
        self.limit = np.asarray(effort_limit, dtype=float)[self.order]
        self._clipped = tuple(f"clipped.{name}" for name in command)
        self._count = count

    def __call__(self, torque: np.ndarray) -> np.ndarray:
        """The command row (a new array), each joint clipped counted."""
        row = torque[self.order]
        over = np.abs(row) > self.limit
        if any_true(over):
            for i in np.flatnonzero(over):
                self._count(self._clipped[i])
            np.clip(row, -self.limit, self.limit, out=row)
        return row

    def to_model(self, row: np.ndarray) -> np.ndarray:
        """A command row back in model order."""
        torque = np.empty_like(row)
        torque[self.order] = row
        return torque
