"""Physics engines behind the simulated ros2_control robot (:mod:`apc_plant_sim.robot_sim`).

An engine holds the arm's state and integrates it under a torque held for one driver period
(:class:`apc_plant_sim.robot_driver.Engine`). Two implementations, picked by name with
:func:`make_engine`:

- ``pinocchio``: apc's own plant (:class:`apc_plant_sim.plant.Plant`: Pinocchio's ABA, classical
  RK4) on the model with the payload — the same arm as ``plant_node``;
- ``mujoco``: MuJoCo's own dynamics and integrator on a model built from the URDF
  (:mod:`apc_plant_sim.mujoco_engine`), with the effects of a physical arm.

The payload is apc's: a point mass in a named frame, on from the start or picked up at a given
time (:meth:`load_payload`). What a physical arm adds is :class:`ArmEffects`: friction and
armature go to the MuJoCo engine, the sensing effects to the driver.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from apc_core.params import ConfigError
from apc_core.robot import Payload, Robot, with_payload
from apc_plant_sim.effects import ArmEffects, panda_effects, puma560_effects
from apc_plant_sim.plant import Plant, PlantConfig, PlantError

ENGINES = ("pinocchio", "mujoco")


class EngineError(RuntimeError):
    """The physics could not integrate a period (the state would have become non-finite or
    unbounded); the engine keeps the state it had before."""


class EngineSetup:
    """What both engines take: the arm, its payload, the driver period and the step bound.

    Parameters
    ----------
    robot : Robot
        The arm without payload.
    payload : Payload
        Carried from the start (``loaded=True``) or from ``load_payload()``.
    period : float
        The driver period (s); every ``advance`` integrates exactly this long.
    max_step : float
        Longest integration step (s); the period is split into ``ceil(period / max_step)``
        equal steps.
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
        self.loaded_robot = with_payload(robot, payload)
        self.robot = robot
        self.period = period
        self.substeps = max(1, math.ceil(period / max_step - 1e-9))
        self.q0 = np.asarray(q0, dtype=float)
        self.loaded = loaded or payload.mass_kg == 0.0
        self.joint_names = robot.joint_names
        self.effort_limit = robot.effort_limit.copy()

    def check_duration(self, duration: float) -> None:
        if abs(duration - self.period) > 1e-12:
            raise ValueError(f"the engine integrates {self.period} s per call, asked {duration}")


class PinocchioEngine(EngineSetup):
    """apc's plant model as a driver's engine: RK4 substeps (see :class:`EngineSetup`)."""

    def __init__(self, robot: Robot, payload: Payload, **setup: Any) -> None:
        super().__init__(robot, payload, **setup)
        config = PlantConfig(
            period=self.period, step=self.period / self.substeps, enforce_torque_limits=False
        )
        self.plant = Plant(self.loaded_robot if self.loaded else robot, config, self.q0)

    @property
    def q(self) -> np.ndarray:
        return self.plant.q

    @property
    def qd(self) -> np.ndarray:
        return self.plant.qd

    def advance(self, tau: np.ndarray, duration: float) -> None:
        self.check_duration(duration)
        try:
            self.plant.step(tau)
        except PlantError as exc:  # the plant keeps its state
            raise EngineError(str(exc)) from None

    def hold(self) -> None:
        self.plant.qd = np.zeros(len(self.joint_names))

    def load_payload(self) -> None:
        """The payload is picked up: from now on the arm carries it (state kept)."""
        if not self.loaded:
            self.plant.set_robot(self.loaded_robot)
            self.loaded = True


#: ``effects`` presets: every effect of a physical arm from its data (name -> builder).
EFFECT_PRESETS = ("ideal", "puma560", "panda")

VELOCITY_SOURCES = ("exact", "noisy", "difference")


def effects_from_values(values: Mapping[str, Any], n: int) -> ArmEffects:
    """The physical-arm parameters as :class:`ArmEffects` (friction, armature and sensing).

    ``effects`` picks the preset (``ideal``: all off; ``puma560``: the three-joint PUMA 560's
    motor, gear and friction data, :func:`apc_plant_sim.effects.puma560_effects`; ``panda``:
    the Franka Panda's, :func:`apc_plant_sim.effects.panda_effects`); each
    per-joint parameter that is not empty, ``velocity_source`` when not empty and
    ``velocity_noise`` / ``command_delay_cycles`` when >= 0 replace the preset's value.
    MuJoCo's ``frictionloss`` is symmetric: a preset's Coulomb levels for the two directions
    become their mean.
    """
    preset = values["effects"]
    if preset == "ideal":
        base = ArmEffects()
    elif preset == "puma560":
        if n != 3:
            raise ConfigError(
                f"parameter 'effects': 'puma560' carries data for joints 1-3, the arm has {n}"
            )
        base = puma560_effects()
    elif preset == "panda":
        if n != 7:
            raise ConfigError(
                f"parameter 'effects': 'panda' carries data for the Panda's 7 joints, the arm "
                f"has {n}"
            )
        base = panda_effects()
    else:
        raise ConfigError(
            f"parameter 'effects': must be one of {', '.join(EFFECT_PRESETS)}, got {preset!r}"
        )
    has_coulomb = bool(base.coulomb_pos_nm or base.coulomb_neg_nm)
    coulomb = tuple(base.mean_coulomb(n).tolist()) if has_coulomb else ()
    chosen: dict[str, Any] = {}
    for param, field, preset_value in (
        ("damping", "viscous_nm_s", base.viscous_nm_s),
        ("frictionloss", "coulomb_pos_nm", coulomb),
        ("armature", "armature_kgm2", base.armature_kgm2),
        ("encoder_counts_per_rev", "counts_per_rev", base.counts_per_rev),
    ):
        value = tuple(values[param]) or preset_value
        if value and len(value) != n:
            raise ConfigError(f"parameter '{param}': needs {n} values, got {len(value)}")
        if not all(math.isfinite(v) and v >= 0.0 for v in value):
            raise ConfigError(f"parameter '{param}': every value must be >= 0, got {list(value)}")
        if param == "encoder_counts_per_rev" and not all(v > 0.0 for v in value):
            raise ConfigError(f"parameter '{param}': every value must be > 0, got {list(value)}")
        chosen[field] = value
    chosen["coulomb_neg_nm"] = chosen["coulomb_pos_nm"]
    velocity = values["velocity_source"] or base.velocity
    if velocity not in VELOCITY_SOURCES:
        raise ConfigError(
            f"parameter 'velocity_source': must be one of {', '.join(VELOCITY_SOURCES)}, "
            f"got {velocity!r}"
        )
    chosen["velocity"] = velocity
    noise = values["velocity_noise"]
    chosen["velocity_noise_rad_s"] = noise if noise >= 0.0 else base.velocity_noise_rad_s
    delay = values["command_delay_cycles"]
    chosen["command_delay"] = delay if delay >= 0 else base.command_delay
    chosen["seed"] = values["seed"]
    return replace(base, **chosen)


def make_engine(
    name: str,
    robot: Robot,
    payload: Payload,
    effects: ArmEffects,
    *,
    period: float,
    max_step: float,
    q0: np.ndarray,
    loaded: bool,
    integrator: str = "RK4",
) -> PinocchioEngine | Any:
    """The engine called ``name`` (:data:`ENGINES`); a bad choice names its parameter.

    ``pinocchio`` integrates the ideal arm: friction and armature are MuJoCo's (the engine that
    integrates them with its own constraint solver), so asking for them with ``pinocchio``
    stops with the parameter's name.
    """
    if name == "pinocchio":
        for param, field in (
            ("damping", "viscous_nm_s"),
            ("frictionloss", "coulomb_pos_nm"),
            ("armature", "armature_kgm2"),
        ):
            if any(getattr(effects, field)):
                raise ConfigError(
                    f"parameter '{param}': the pinocchio engine integrates the ideal arm; "
                    "use engine mujoco for friction and armature"
                )
        return PinocchioEngine(
            robot, payload, period=period, max_step=max_step, q0=q0, loaded=loaded
        )
    if name == "mujoco":
        from apc_plant_sim.mujoco_engine import JointEffects, MujocoEngine

        n = robot.n_joints
        joint_effects = JointEffects(
            damping=tuple(effects.per_joint("viscous_nm_s", n)),
            frictionloss=tuple(effects.per_joint("coulomb_pos_nm", n)),
            armature=tuple(effects.per_joint("armature_kgm2", n)),
        )
        return MujocoEngine(
            robot,
            payload,
            period=period,
            max_step=max_step,
            q0=q0,
            loaded=loaded,
            effects=joint_effects,
            integrator=integrator,
        )
    raise ConfigError(f"parameter 'engine': must be one of {', '.join(ENGINES)}, got {name!r}")
