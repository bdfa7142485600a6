"""Physics engines behind the simulated ros2_control robot (:mod:`apc_plant_sim.robot_sim`).

An engine holds the arm's state and integrates it under a torque held for one driver period
(:class:`apc_plant_sim.robot_driver.Engine`). Two implementations, picked by name with
:func:`make_engine`:

- ``pinocchio``: apc's own plant (:class:`apc_plant_sim.plant.Plant`: Pinocchio's ABA, classical
  RK4) on the model with the payload — the same arm as ``plant_node``;
- ``mujoco``: MuJoCo's own dynamics and integrator on a model built from the URDF
  (:mod:`apc_plant_sim.mujoco_arm`), with the effects of a physical arm.

The payload is apc's: a point mass in a named frame, on from the start or picked up at a given
time (:meth:`load_payload`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from apc_core.params import ConfigError
from apc_core.robot import Payload, Robot, RobotModelError, with_payload
from apc_plant_sim.plant import Plant, PlantConfig

ENGINES = ("pinocchio", "mujoco")


def payload_from_values(robot: Robot, values: Mapping[str, Any]) -> Payload:
    """The ``payload.*`` parameters as a :class:`Payload`; a bad one names its parameter."""
    try:
        payload = Payload(
            mass_kg=values["payload.mass_kg"],
            com_m=tuple(values["payload.com_m"]),
            frame=values["payload.frame"] or None,
        )
    except RobotModelError as exc:
        field = "mass_kg" if "mass_kg" in str(exc) else "com_m"
        raise ConfigError(f"parameter 'payload.{field}': {exc}") from None
    if payload.frame is not None and not robot.model.existFrame(payload.frame):
        raise ConfigError(f"parameter 'payload.frame': no frame '{payload.frame}' in the URDF")
    return payload


class PinocchioEngine:
    """apc's plant model as a driver's engine: RK4 substeps of at most ``max_step`` seconds.

    Parameters
    ----------
    robot : Robot
        The arm without payload.
    payload : Payload
        Carried from the start (``loaded=True``) or from :meth:`load_payload`.
    period : float
        The driver period (s); every :meth:`advance` integrates exactly this long.
    max_step : float
        Longest RK4 step (s); the period is split into ``ceil(period / max_step)`` equal steps.
    q0 : (n,) array
        Initial position (rad).
    """

    def __init__(
        self,
        robot: Robot,
        payload: Payload,
        *,
        period: float,
        max_step: float,
        q0: np.ndarray,
        loaded: bool = True,
    ) -> None:
        try:
            self._loaded_robot = with_payload(robot, payload)
        except RobotModelError as exc:
            raise ConfigError(f"parameter 'payload.frame': {exc}") from None
        substeps = max(1, math.ceil(period / max_step - 1e-9))
        config = PlantConfig(period=period, step=period / substeps, enforce_torque_limits=False)
        self.joint_names = robot.joint_names
        self.effort_limit = robot.effort_limit.copy()
        self.loaded = loaded or payload.mass_kg == 0.0
        self.plant = Plant(self._loaded_robot if self.loaded else robot, config, q0)

    @property
    def q(self) -> np.ndarray:
        return self.plant.q

    @property
    def qd(self) -> np.ndarray:
        return self.plant.qd

    def advance(self, tau: np.ndarray, duration: float) -> None:
        if abs(duration - self.plant.config.period) > 1e-12:
            raise ValueError(
                f"the pinocchio engine integrates {self.plant.config.period} s, asked {duration}"
            )
        self.plant.step(tau)

    def hold(self) -> None:
        self.plant.qd = np.zeros(len(self.joint_names))

    def load_payload(self) -> None:
        """The payload is picked up: from now on the arm carries it (state kept)."""
        if not self.loaded:
            self.plant.set_robot(self._loaded_robot)
            self.loaded = True
