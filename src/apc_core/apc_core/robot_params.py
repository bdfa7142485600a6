"""The arm a node is configured with: the robot parameters every node shares, the controllers'
model of the arm (its error, rotor inertia and friction), and the per-joint defaults derived
from the URDF. Plain Python: no rclpy."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from apc_core.config_files import resolve_config_path
from apc_core.defaults import derive
from apc_core.params import ConfigError, Param
from apc_core.robot import (
    PAPER_GRAVITY_M_S2,
    PAPER_PERIOD_S,
    Robot,
    RobotModelError,
    load_robot,
    read_urdf,
    with_armature,
    with_friction,
    with_inertia_error,
)

ROBOT_PARAMS: tuple[Param, ...] = (
    Param(
        "robot_description",
        "",
        "URDF XML of the arm; when empty, robot_description_path is loaded instead",
    ),
    Param(
        "robot_description_path",
        "puma560_3dof.urdf",
        "URDF file: absolute, relative to the working directory, a file name in apc's config "
        "directory (share/apc_core/config in a ROS install), or example-robot-data/<path> "
        "(e.g. example-robot-data/panda_description/urdf/panda.urdf)",
    ),
    Param("gravity", PAPER_GRAVITY_M_S2, "gravity along -z of the base frame (m/s^2)", 0.0, 100.0),
    Param(
        "lock_joints",
        [],
        "URDF joints frozen at 0 (e.g. a gripper), so the rest is a serial chain",
        array_of=str,
    ),
    Param(
        "period",
        PAPER_PERIOD_S,
        "sampling period T (s): torques are held for T, states are sampled every T",
        1e-4,
        1.0,
    ),
)


#: The controllers' arm: the robot, and the error of their model of it (in simulation).
CONTROLLER_ROBOT_PARAMS: tuple[Param, ...] = (
    *ROBOT_PARAMS,
    Param(
        "inertia_error",
        [],
        "relative error of the controller's link inertia tensors, one per joint (the paper's "
        "simulation study: [0.1, -0.1, 0.1]); empty = the URDF as is",
    ),
    Param(
        "armature",
        [],
        "the controllers' model: reflected rotor inertia G^2 J_m of each joint's drive "
        "(kg m^2, one per joint; a URDF has no place for it); empty = none",
    ),
    Param(
        "friction",
        [],
        "the controllers' model: Coulomb friction of each joint (N m, one per joint), added to "
        "the nominal torque at the planned velocity; empty = none (not the URDF's <dynamics>)",
    ),
    Param(
        "damping",
        [],
        "the controllers' model: viscous friction of each joint (N m s/rad, one per joint), "
        "added to the nominal torque; empty = none (not the URDF's <dynamics>)",
    ),
)


def robot_from_params(values: dict[str, Any]) -> Robot:
    """Load the arm named by :data:`ROBOT_PARAMS` values; errors name the parameter."""
    xml = values.get("robot_description", "")
    source_param = "robot_description" if xml else "robot_description_path"
    source = xml if xml else resolve_config_path(values["robot_description_path"])
    try:
        return load_robot(
            source,
            gravity=float(values["gravity"]),
            lock_joints=tuple(values.get("lock_joints", ())),
        )
    except RobotModelError as exc:
        param = "lock_joints" if str(exc).startswith("lock_joints") else source_param
        raise ConfigError(f"parameter '{param}': {exc}") from None


def urdf_xml(values: dict[str, Any]) -> str:
    """The URDF text :data:`ROBOT_PARAMS` values name (``robot_description``, else the file of
    ``robot_description_path``); call after :func:`robot_from_params` accepted them."""
    xml = values.get("robot_description", "")
    if not xml:
        xml, _ = read_urdf(resolve_config_path(values["robot_description_path"]))
    return xml


def controller_robot_from_params(values: dict[str, Any]) -> Robot:
    """The controllers' model of the arm named by :data:`CONTROLLER_ROBOT_PARAMS` values: the
    robot with ``inertia_error``, ``armature``, ``friction`` and ``damping``; errors name the
    parameter."""
    robot = robot_from_params(values)
    changes: tuple[tuple[str, Callable[[Robot, Any], Robot]], ...] = (
        ("inertia_error", with_inertia_error),
        ("armature", with_armature),
        ("friction", lambda arm, value: with_friction(arm, value, None)),
        ("damping", lambda arm, value: with_friction(arm, None, value)),
    )
    for name, change in changes:
        if values[name]:
            try:
                robot = change(robot, values[name])
            except RobotModelError as exc:
                raise ConfigError(f"parameter '{name}': {exc}") from None
    return robot


def fill_derived(values: dict[str, Any], robot: Robot, derived: Mapping[str, str]) -> list[str]:
    """Give each empty parameter in ``derived`` (parameter name -> :class:`ArmDefaults` field)
    the default derived from the arm's URDF (:mod:`apc_core.defaults`), in ``values``.

    Returns one line per default so chosen, saying what and how: the node logs them once its
    whole configuration is accepted, so a bad parameter still stops it with one line.
    """
    empty = [name for name in derived if not values[name]]
    if not empty:
        return []
    defaults = derive(robot, urdf_xml(values))
    for name in empty:
        value = getattr(defaults, derived[name])
        values[name] = list(value) if isinstance(value, tuple) else value
    return [defaults.describe(derived[name], name) for name in empty]
