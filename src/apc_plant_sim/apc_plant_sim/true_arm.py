"""The arm the plant node simulates, built from its parameters: plain, no rclpy.

The true arm is the URDF with a payload the controllers do not know; with ``payload.at_s > 0``
the arm starts without it and picks it up at that sample (mid-motion). Parameters are read
here, once, and a bad one stops the node with a :class:`~apc_core.params.ConfigError` naming it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from apc_core.params import ConfigError, Param, params_from
from apc_core.robot import Payload, Robot, RobotModelError, with_payload
from apc_plant_sim.plant import Plant, PlantConfig, PlantError

#: The plant node's parameters of the simulated arm (beside the robot's own).
TRUE_ARM_PARAMS: tuple[Param, ...] = (
    *params_from(PlantConfig, ""),
    Param("payload.mass_kg", 0.0, "payload on the simulated arm only (kg)", 0.0, 1e4),
    Param(
        "payload.frame",
        "",
        "frame carrying the payload; empty = the URDF's last link (fixed to the last joint)",
    ),
    Param("payload.com_m", [0.0, 0.0, 0.0], "payload centre of mass in payload.frame (m)"),
    Param(
        "payload.at_s",
        0.0,
        "time (s, sample time) the payload appears, picked up mid-motion; 0 = from the start",
        0.0,
        1e9,
    ),
    Param(
        "q_initial_deg",
        [],
        "initial joint positions (deg, URDF angles); empty = the middle of each joint's range",
    ),
)


def payload_from_params(robot: Robot, values: Mapping[str, Any]) -> tuple[Payload, Robot]:
    """The ``payload.*`` parameters as a :class:`Payload` and the arm carrying it.

    Raises
    ------
    ConfigError
        Naming the bad ``payload.*`` parameter.
    """
    mass, com = values["payload.mass_kg"], tuple(values["payload.com_m"])
    for name, value in (("payload.mass_kg", {"mass_kg": mass}), ("payload.com_m", {"com_m": com})):
        try:
            Payload(**value)
        except RobotModelError as exc:
            raise ConfigError(f"parameter '{name}': {exc}") from None
    payload = Payload(mass_kg=mass, com_m=com, frame=values["payload.frame"] or None)
    if payload.frame is not None and not robot.model.existFrame(payload.frame):
        raise ConfigError(f"parameter 'payload.frame': no frame '{payload.frame}' in the URDF")
    try:
        return payload, with_payload(robot, payload)
    except RobotModelError as exc:
        raise ConfigError(f"parameter 'payload.frame': {exc}") from None


class TrueArm:
    """The plant and the payload it picks up at sample ``pickup_k`` (0: carried from the start).

    Parameters
    ----------
    plant : Plant
        Integrates the arm; its model is swapped for ``loaded`` at ``pickup_k``.
    loaded : Robot
        The arm with its payload.
    pickup_k : int
    """

    def __init__(self, plant: Plant, loaded: Robot, pickup_k: int = 0) -> None:
        self.plant = plant
        self.loaded = loaded
        self.pickup_k = pickup_k

    @classmethod
    def from_params(cls, robot: Robot, values: Mapping[str, Any]) -> TrueArm:
        """Build from the node's parameter values (:data:`TRUE_ARM_PARAMS` and ``period``)."""
        payload, loaded = payload_from_params(robot, values)
        try:
            config = PlantConfig(
                period=values["period"],
                step=values["step"],
                enforce_torque_limits=values["enforce_torque_limits"],
                forward_dynamics=values["forward_dynamics"],
            )
        except PlantError as exc:
            raise ConfigError(f"parameter '{exc.field}': {exc}") from None
        n = robot.n_joints
        q0 = values["q_initial_deg"] or [0.0] * n
        if len(q0) != n:
            raise ConfigError(f"parameter 'q_initial_deg': needs {n} values, got {len(q0)}")
        at_s = values["payload.at_s"]
        pickup_k = round(at_s / config.period) if payload.mass_kg > 0.0 and at_s > 0.0 else 0
        plant = Plant(robot if pickup_k else loaded, config, np.deg2rad(q0))
        return cls(plant, loaded, pickup_k)

    def pick_up(self) -> bool:
        """Put the payload on if its sample has come (call before integrating the sample);
        True when that happens."""
        if not self.pickup_k or self.plant.k != self.pickup_k:
            return False
        self.plant.set_robot(self.loaded)
        return True
