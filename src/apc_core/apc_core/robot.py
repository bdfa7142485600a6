"""Robot models: URDF -> ``pinocchio.Model``, and the two models a run needs.

One model is built once from the URDF; the plant's model (with a payload) and the controller's
model (with the paper's inertia error, no payload) are *new* models derived from it, never
in-place edits, the way Drake hands a controller its own plant. Each consumer calls
``model.createData()`` for its own scratch space.

Conventions
-----------
- Joint order and names come from the URDF (Pinocchio's depth-first order, which for a serial
  chain is base to tip).
- Only 1-dof joints (revolute, prismatic) may move, so ``nq == nv == n``; continuous joints
  (``nq = 2``) and floating bases are rejected. Joints named in ``lock_joints`` are frozen at a
  reference position (e.g. the Panda's fingers).
- Gravity is ``(0, 0, -g)`` in the base frame, ``g = 9.8062 m/s^2`` by default (the paper's).
"""

from __future__ import annotations

import glob
import math
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

PAPER_GRAVITY_M_S2 = 9.8062
#: The paper's maximum payload, 5 lb, in kg.
PAPER_MAX_PAYLOAD_KG = 5.0 * 0.45359237
#: The paper's sampling period T (s), the default of every node and run.
PAPER_PERIOD_S = 0.010
#: The start and end of the paper's move on the 3-joint PUMA 560, in the URDF's standard-DH
#: angles (deg): the paper's (0, 45, 45) and (90, -45, 135), its angles being (q1, -q2, -q3).
PAPER_START_DEG = (0.0, -45.0, -45.0)
PAPER_GOAL_DEG = (90.0, 45.0, -135.0)
_MOVABLE = {"revolute", "prismatic"}
_ALLOWED = _MOVABLE | {"fixed"}


class RobotModelError(ValueError):
    """A URDF or a model modification that apc cannot use; the message says which part."""


@dataclass(frozen=True)
class Payload:
    """A point-mass payload rigidly attached to a frame of the arm.

    Attributes
    ----------
    mass_kg : float
        Mass (kg), >= 0.
    com_m : (3,) tuple
        Centre of mass in ``frame`` (m).
    frame : str or None
        Name of a URDF link/frame; ``None`` means the body of the last moving joint.
    """

    mass_kg: float = 0.0
    com_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    frame: str | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0.0):
            raise RobotModelError(f"payload mass_kg must be finite and >= 0, got {self.mass_kg}")
        com = tuple(float(c) for c in self.com_m)
        if len(com) != 3 or not all(math.isfinite(c) for c in com):
            raise RobotModelError(f"payload com_m must be 3 finite numbers, got {self.com_m}")
        object.__setattr__(self, "com_m", com)


@dataclass(frozen=True)
class Robot:
    """A loaded arm: the Pinocchio model and what the rest of apc reads from it.

    Attributes
    ----------
    model : pinocchio.Model
        Treat as immutable; derive new models with :func:`with_payload` and
        :func:`with_inertia_error`.
    joint_names : tuple of str
        Moving joints, base to tip, in the order of every array in apc.
    effort_limit : (n,) ndarray
        |tau| bound per joint (N m or N) from the URDF ``<limit effort=...>``.
    source : str
        Where the URDF came from (a path, or ``"<string>"``).
    """

    model: pin.Model
    joint_names: tuple[str, ...]
    effort_limit: np.ndarray
    source: str = "<string>"
    position_limits: tuple[np.ndarray, np.ndarray] = field(
        default_factory=lambda: (np.zeros(0), np.zeros(0))
    )

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)


def _float_attr(elem: ET.Element, attr: str, where: str) -> float:
    text = elem.get(attr)
    if text is None:
        raise RobotModelError(f"{where}: missing attribute '{attr}'")
    try:
        value = float(text)
    except ValueError:
        raise RobotModelError(f"{where}: '{attr}' is not a number: {text!r}") from None
    if not math.isfinite(value):
        raise RobotModelError(f"{where}: '{attr}' is not finite: {text!r}")
    return value


def _vector_attr(elem: ET.Element | None, attr: str, where: str, default: str) -> np.ndarray:
    """A 3-vector attribute such as ``xyz="0 0 1"``; absent means ``default``."""
    text = default if elem is None else elem.get(attr, default)
    parts = text.split()
    try:
        values = np.array([float(v) for v in parts])
    except ValueError:
        raise RobotModelError(f"{where}: '{attr}' is not 3 numbers: {text!r}") from None
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        raise RobotModelError(f"{where}: '{attr}' must be 3 finite numbers, got {text!r}")
    return values


def _check_urdf_xml(text: str) -> None:
    """Reject what Pinocchio's URDF parser would silently accept or drop.

    urdfdom prints an error and *ignores* an unparsable ``<inertia>`` (Pinocchio then builds a
    massless link), so numbers are checked here first.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotModelError(f"URDF is not well-formed XML: {exc}") from None
    if root.tag != "robot":
        raise RobotModelError(f"URDF root element must be <robot>, got <{root.tag}>")
    for link in root.findall("link"):
        name = link.get("name", "?")
        inertial = link.find("inertial")
        if inertial is None:
            continue
        where = f"link '{name}' <inertial>"
        mass = inertial.find("mass")
        if mass is None:
            raise RobotModelError(f"{where}: missing <mass>")
        if _float_attr(mass, "value", where + " <mass>") < 0.0:
            raise RobotModelError(f"{where}: negative mass")
        origin = inertial.find("origin")
        _vector_attr(origin, "xyz", where + " <origin>", "0 0 0")
        _vector_attr(origin, "rpy", where + " <origin>", "0 0 0")
        inertia = inertial.find("inertia")
        if inertia is None:
            raise RobotModelError(f"{where}: missing <inertia>")
        ixx, ixy, ixz, iyy, iyz, izz = (
            _float_attr(inertia, attr, where + " <inertia>")
            for attr in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        )
        tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        scale = max(1.0, float(np.abs(tensor).max()))
        if np.linalg.eigvalsh(tensor).min() < -1e-9 * scale:
            raise RobotModelError(f"{where}: inertia tensor is not positive semidefinite")
    for joint in root.findall("joint"):
        name = joint.get("name", "?")
        jtype = joint.get("type")
        if jtype not in _ALLOWED:
            raise RobotModelError(
                f"joint '{name}' has type '{jtype}': apc supports revolute, prismatic and fixed "
                "joints (nq == nv); continuous and floating joints are not supported"
            )
        where = f"joint '{name}'"
        origin = joint.find("origin")
        _vector_attr(origin, "xyz", where + " <origin>", "0 0 0")
        _vector_attr(origin, "rpy", where + " <origin>", "0 0 0")
        if jtype in _MOVABLE:
            axis = _vector_attr(joint.find("axis"), "xyz", where + " <axis>", "1 0 0")
            if np.linalg.norm(axis) < 1e-9:
                raise RobotModelError(f"{where}: <axis> must not be zero")
            limit = joint.find("limit")
            if limit is None:
                raise RobotModelError(f"joint '{name}': missing <limit> (effort limit needed)")
            _float_attr(limit, "effort", f"joint '{name}' <limit>")


def read_urdf(urdf: str | Path) -> tuple[str, str]:
    """The XML of a URDF given as a file path or as the XML itself (a leading ``<``), and its
    source: the path, or ``"<string>"``."""
    if isinstance(urdf, Path) or not str(urdf).lstrip().startswith("<"):
        path = Path(urdf)
        if not path.is_file():
            raise RobotModelError(f"URDF file not found: {path}")
        return path.read_text(), str(path)
    return str(urdf), "<string>"


def load_robot(
    urdf: str | Path,
    *,
    gravity: float = PAPER_GRAVITY_M_S2,
    lock_joints: Sequence[str] = (),
    lock_positions: Mapping[str, float] | None = None,
    keep_joints: Sequence[str] | None = None,
) -> Robot:
    """Build a serial-arm model from a URDF file path or a URDF XML string.

    Parameters
    ----------
    urdf : str or Path
        A path to a ``.urdf`` file, or the XML text itself (detected by a leading ``<``).
    gravity : float
        Magnitude of gravity (m/s^2) along -z of the base frame.
    lock_joints : sequence of str
        Joints to freeze (e.g. grippers), at ``lock_positions[name]`` (default 0).
    keep_joints : sequence of str, optional
        Freeze every joint but these as well (a recording's joints: the arm it moved).

    Returns
    -------
    Robot

    Raises
    ------
    RobotModelError
        Missing file, malformed XML, unsupported joint type, non-numeric inertia, a branch in the
        kinematic tree after locking, or no moving joint.
    """
    text, source = read_urdf(urdf)
    _check_urdf_xml(text)
    if not (math.isfinite(gravity) and gravity >= 0.0):
        raise RobotModelError(f"gravity must be finite and >= 0, got {gravity}")
    try:
        model = pin.buildModelFromXML(text)
    except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
        raise RobotModelError(f"Pinocchio could not build the URDF: {exc}") from None

    if keep_joints is not None:
        unknown = [name for name in keep_joints if not model.existJointName(name)]
        if unknown:
            raise RobotModelError(f"keep_joints: no joint named {unknown} in the URDF")
        others = [name for name in list(model.names)[1:] if name not in keep_joints]
        lock_joints = (*lock_joints, *(name for name in others if name not in lock_joints))
    if lock_joints:
        lock_positions = dict(lock_positions or {})
        ids = []
        q_ref = pin.neutral(model)
        for name in lock_joints:
            if not model.existJointName(name):
                raise RobotModelError(f"lock_joints: no joint named '{name}' in the URDF")
            jid = model.getJointId(name)
            ids.append(jid)
            q_ref[model.joints[jid].idx_q] = float(lock_positions.get(name, 0.0))
        model = pin.buildReducedModel(model, ids, q_ref)

    if model.nq == 0:
        raise RobotModelError("the URDF has no moving joint")
    if model.nq != model.nv:
        raise RobotModelError(f"nq ({model.nq}) != nv ({model.nv}): only 1-dof joints supported")
    for jid in range(1, model.njoints):
        if model.parents[jid] != jid - 1:
            raise RobotModelError(
                f"joint '{model.names[jid]}' branches off joint '{model.names[model.parents[jid]]}'"
                ": apc needs a serial chain (lock the other branch with lock_joints)"
            )
    model.gravity.linear = np.array([0.0, 0.0, -gravity])
    # A URDF's <dynamics friction damping> is what a simulator applies (example-robot-data's
    # Panda: damping 0.003 for Gazebo); the controllers' friction is told (with_friction).
    model.friction = np.zeros(model.nv)
    model.damping = np.zeros(model.nv)
    names = tuple(model.names[j] for j in range(1, model.njoints))
    effort = np.array(model.effortLimit, dtype=float)
    if not np.all(effort > 0.0):
        bad = [n for n, e in zip(names, effort, strict=True) if not e > 0.0]
        raise RobotModelError(f"joints {bad} have no positive effort limit in the URDF")
    return Robot(
        model=model,
        joint_names=names,
        effort_limit=effort,
        source=source,
        position_limits=(
            np.array(model.lowerPositionLimit, dtype=float),
            np.array(model.upperPositionLimit, dtype=float),
        ),
    )


def _derived(robot: Robot, model: pin.Model) -> Robot:
    return Robot(
        model=model,
        joint_names=robot.joint_names,
        effort_limit=robot.effort_limit.copy(),
        source=robot.source,
        position_limits=robot.position_limits,
    )


def with_payload(robot: Robot, payload: Payload) -> Robot:
    """Return a new robot whose model carries ``payload`` (the plant's model).

    The payload is a point mass at ``payload.com_m`` in ``payload.frame``; its spatial inertia
    is added to the body of the joint that frame is attached to. ``robot`` is not changed.
    """
    model = pin.Model(robot.model)
    if payload.mass_kg == 0.0:
        return _derived(robot, model)
    if payload.frame is None:
        joint_id = model.njoints - 1
        placement = pin.SE3.Identity()
    else:
        if not model.existFrame(payload.frame):
            raise RobotModelError(f"payload frame '{payload.frame}' is not in the model")
        frame = model.frames[model.getFrameId(payload.frame)]
        joint_id = frame.parentJoint
        placement = frame.placement
        if joint_id == 0:
            raise RobotModelError(f"payload frame '{payload.frame}' does not move with any joint")
    point = pin.Inertia(payload.mass_kg, np.asarray(payload.com_m, dtype=float), np.zeros((3, 3)))
    model.inertias[joint_id] = model.inertias[joint_id] + placement.act(point)
    return _derived(robot, model)


def with_inertia_error(robot: Robot, relative_error: Sequence[float]) -> Robot:
    """Return a new robot whose link inertia tensors are scaled (the controller's model).

    Each moving body's rotational inertia about its centre of mass is multiplied by
    ``1 + relative_error[i]``; masses and centres of mass are unchanged. The body of joint i is
    the URDF link it moves plus whatever is fixed to it (for the 3-joint PUMA, link 3 carries
    the lumped wrist), which is what a controller's rigid-body model of "link i" is.

    Parameters
    ----------
    relative_error : (n,) sequence of float
        E.g. the paper's +-10 %: ``(+0.1, -0.1, +0.1)``. Each must be > -1.
    """
    err = np.asarray(relative_error, dtype=float)
    n = robot.n_joints
    if err.shape != (n,):
        raise RobotModelError(f"inertia error needs {n} values (one per joint), got {err.shape}")
    if not np.all(np.isfinite(err)) or np.any(err <= -1.0):
        raise RobotModelError(f"inertia error values must be finite and > -1, got {err.tolist()}")
    model = pin.Model(robot.model)
    for i in range(n):
        body = model.inertias[i + 1]
        model.inertias[i + 1] = pin.Inertia(
            body.mass, body.lever.copy(), body.inertia * (1.0 + err[i])
        )
    return _derived(robot, model)


def with_armature(robot: Robot, armature_kgm2: Sequence[float]) -> Robot:
    """Return a new robot whose joints carry a reflected rotor inertia (Pinocchio's
    ``model.armature``: ``G^2 J_m`` of each joint's drive, added to the mass matrix's diagonal,
    so to RNEA, CRBA, ABA and their derivatives). A URDF has no place for it; a geared arm's
    can exceed its links' inertia about the joint.

    Parameters
    ----------
    armature_kgm2 : (n,) sequence of float
        One per joint, each finite and >= 0.
    """
    model = pin.Model(robot.model)
    model.armature = _joint_values(robot, "armature", armature_kgm2)
    return _derived(robot, model)


def _joint_values(robot: Robot, name: str, values: Sequence[float]) -> np.ndarray:
    """``values`` as a new (n,) array, one finite value >= 0 per joint, else RobotModelError
    naming ``name``."""
    value = np.array(values, dtype=float)
    n = robot.n_joints
    if value.shape != (n,):
        raise RobotModelError(f"{name} needs {n} values (one per joint), got {value.shape}")
    if not np.all(np.isfinite(value)) or np.any(value < 0.0):
        raise RobotModelError(f"{name} values must be finite and >= 0, got {value.tolist()}")
    return value


def with_friction(
    robot: Robot, coulomb_nm: Sequence[float] | None, viscous_nm_s: Sequence[float] | None
) -> Robot:
    """Return a new robot whose joints carry a friction model (Pinocchio's ``model.friction``,
    Coulomb, N m, and ``model.damping``, viscous, N m s/rad; :func:`load_robot` leaves both at
    zero whatever the URDF's ``<dynamics>`` says); None keeps the robot's. RNEA leaves them
    out; the nominal torque adds them (:func:`apc_feedforward.nominal.nominal_torque`).

    Parameters
    ----------
    coulomb_nm, viscous_nm_s : (n,) sequence of float or None
        One per joint, each finite and >= 0.
    """
    model = pin.Model(robot.model)
    for name, values in (("friction", coulomb_nm), ("damping", viscous_nm_s)):
        if values is not None:  # Pinocchio's field of that name
            setattr(model, name, _joint_values(robot, name, values))
    return _derived(robot, model)


#: ``robot_description_path`` prefix of a URDF from the ``example-robot-data`` wheel.
EXAMPLE_ROBOT_DATA = "example-robot-data/"


def example_robot_urdf(relative: str) -> Path:
    """A URDF shipped by ``example-robot-data``, by its path under the package's ``robots/``
    (``panda_description/urdf/panda.urdf``): the PyPI wheel (installed under sys.prefix), else
    the ROS package (``ros-jazzy-example-robot-data``, found through the ament index)."""
    hits = glob.glob(f"{sys.prefix}/**/example-robot-data/robots/{relative}", recursive=True)
    if hits:
        return Path(hits[0])
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory("example-robot-data"))
    except Exception:  # no ament index, or no such package in it
        share = None
    if share is not None and (share / "robots" / relative).is_file():
        return share / "robots" / relative
    raise FileNotFoundError(f"example-robot-data does not ship {relative} here")


def alternating_error(n: int, magnitude: float = 0.1) -> np.ndarray:
    """The paper's "+-10 %" pattern extended to n joints: +m, -m, +m, ... ."""
    return np.array([magnitude if i % 2 == 0 else -magnitude for i in range(n)])
