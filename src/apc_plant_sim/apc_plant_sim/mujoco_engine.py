"""The arm in MuJoCo: a model built through ``MjSpec`` from apc's robot model, and an engine.

Why from the Pinocchio model and not ``MjSpec.from_file(urdf)``: the Pinocchio model is what
every other part of apc runs (joints locked by ``lock_joints``, links joined by fixed joints
already merged into their moving body, the payload added as in apc's plant, gravity as
configured), so building MuJoCo bodies from it gives MuJoCo exactly the same kinematic tree and
inertias, and nothing else: MuJoCo's URDF import needs a ``<mujoco>`` extension element for its
compiler options, merges fixed links on its own terms and cannot take apc's payload or locked
joints. What is then integrated is MuJoCo's own: its recursive dynamics, its constraint solver
for friction loss, its integrator.

Physically impossible inertias
------------------------------
MuJoCo refuses a body whose principal moments of inertia (A, B, C) violate A + B >= C, which no
physical body does. The PUMA 560 parameter set (Armstrong, Khatib & Burdick 1986, as carried
by apc's URDF) has two such bodies:

- link 1: moments (0, 0, 0.35) kg m^2 about its centre of mass, 0.35 about the joint-1 axis.
  Link 1 hangs from the fixed base by joint 1 alone, so its angular velocity is always
  ``q1' a`` (``a`` the joint axis) and only ``a^T I a`` enters the kinetic energy; its
  moments about the two axes perpendicular to ``a`` never act. The correction raises those two
  to ``C / 2`` each (A + B = C): M(q) and the bias forces are unchanged exactly
  (``test_mujoco_engine.py``).
- link 3 of the 3-joint arm (link 3 with the wrist's 1.25 kg lumped at the wrist centre):
  moments (0.01269, 0.19630, 0.21635) kg m^2, A + B falls 0.00735 short of C. Link 3 turns
  about every axis as the arm moves, so no correction is invisible; the smallest one (in the
  Frobenius norm of the inertia tensor) moves the three moments by ``(+d, +d, -d)`` with
  ``d = (C - A - B) / 3`` = 0.00245 kg m^2 along the principal axes. What that changes in M(q)
  and in the bias forces is measured in ``test_mujoco_engine.py`` and stated in docs/robot.md.

:func:`physical_inertias` returns the corrected Pinocchio model and what it changed, so the
MuJoCo arm and a Pinocchio arm can be compared with the same inertias.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import pinocchio as pin

from apc_core.params import ConfigError
from apc_core.robot import Payload, Robot, RobotModelError
from apc_plant_sim.engines import EngineError, EngineSetup

# MuJoCo writes its warnings to MUJOCO_LOG.TXT in the working directory unless a handler takes
# them: they go to Python's logging instead.
mujoco.set_mju_user_warning(logging.getLogger("mujoco").warning)

#: MuJoCo's warnings that an integration went unstable (the state left mjMAXVAL or is NaN).
_UNSTABLE = tuple(
    int(w)
    for w in (
        mujoco.mjtWarning.mjWARN_BADQACC,
        mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL,
    )
)

#: MuJoCo integrators by the name the ``mujoco.integrator`` parameter takes.
INTEGRATORS = {
    "RK4": mujoco.mjtIntegrator.mjINT_RK4,
    "Euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
}

#: Relative margin by which a corrected body satisfies A + B >= C: MuJoCo diagonalises the
#: tensor again and checks the inequality on its own eigenvalues, which rounding can put a few
#: ulps on the wrong side of an exact equality.
MARGIN = 1e-9

#: Mass (kg) given to a moving body that has none (MuJoCo refuses a massless moving body): put
#: at the joint frame's origin, on the axis of the body's joint.
MIN_MASS_KG = 1e-6

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class InertiaCorrection:
    """What :func:`physical_inertias` changed on the body of one joint.

    Attributes
    ----------
    joint : str
        The joint whose moving body it is.
    before, after : (3,) ndarray
        Principal moments about the centre of mass (kg m^2), ascending.
    invisible : bool
        The change cannot act on the joint-space dynamics (a body hung from the fixed base by
        one revolute joint, changed only about axes perpendicular to it, and mass added on the
        joint axis).
    mass_added : float
        :data:`MIN_MASS_KG` if the body had no mass, else 0.
    """

    joint: str
    before: np.ndarray
    after: np.ndarray
    invisible: bool
    mass_added: float = 0.0


def _joint_axis(joint: pin.JointModel) -> tuple[str, np.ndarray]:
    """('hinge' | 'slide', axis in the joint frame) of a 1-dof Pinocchio joint."""
    name = joint.shortname()
    kind = "slide" if "Prismatic" in name or name.startswith("JointModelP") else "hinge"
    if name.endswith("Unaligned"):
        return kind, np.array(joint.extract().axis, dtype=float)
    letter = name[-1]
    if letter not in _AXES:
        raise RobotModelError(f"joint type {name} has no MuJoCo equivalent here")
    return kind, np.array(_AXES[letter])


def _project_moments(moments: np.ndarray) -> np.ndarray:
    """Nearest (Euclidean) principal moments with A + B >= C; ``moments`` ascending."""
    a, b, c = moments
    shortfall = c - a - b
    if shortfall <= 0.0:
        return moments.copy()
    d = (shortfall + MARGIN * c) / 3.0
    return np.array([a + d, b + d, c - d])


def physical_inertias(
    model: pin.Model, tolerance: float = 1e-12
) -> tuple[pin.Model, list[InertiaCorrection]]:
    """A copy of ``model`` whose bodies all satisfy A + B >= C, and what was changed.

    The body of a revolute joint whose parent is the fixed base, when the joint axis is one of
    its principal axes, is corrected about the two perpendicular axes only (invisible to the
    dynamics); any other body gets the smallest change of its inertia tensor (see module
    docstring). A massless moving body gets :data:`MIN_MASS_KG` at its joint's origin
    (invisible for a body hung from the base: on its axis). Other masses and centres of mass
    are never changed.
    """
    out = pin.Model(model)
    corrections: list[InertiaCorrection] = []
    for j in range(1, model.njoints):
        body = model.inertias[j]
        inertia = np.array(body.inertia)
        moments, axes = np.linalg.eigh(inertia)
        moments = np.maximum(moments, 0.0)  # eigh's rounding on a zero moment
        scale = max(float(moments[-1]), 1e-300)
        massless = body.mass <= 0.0
        if moments[0] + moments[1] >= moments[2] - tolerance * scale and not massless:
            continue
        kind, axis = _joint_axis(model.joints[j])
        along = np.abs(axes.T @ axis)
        root_hinge = model.parents[j] == 0 and kind == "hinge"
        mass, lever = body.mass, body.lever.copy()
        if massless:  # Pinocchio keeps no centre of mass for it: the joint origin, on the axis
            mass, lever = MIN_MASS_KG, np.zeros(3)
        if moments[0] + moments[1] >= moments[2] - tolerance * scale:
            new, invisible = moments.copy(), root_hinge
        elif root_hinge and np.isclose(along.max(), 1.0, atol=1e-9):
            k = int(np.argmax(along))
            new = moments.copy()
            others = [i for i in range(3) if i != k]
            shortfall = moments[k] * (1.0 + MARGIN) - moments[others].sum()
            # Raising the smaller two to a sum of C also keeps |A - B| <= C (both are >= 0).
            new[others] += max(shortfall, 0.0) / 2.0
            invisible = True
        else:
            new = _project_moments(moments)
            invisible = False
        corrected = axes @ np.diag(new) @ axes.T
        out.inertias[j] = pin.Inertia(mass, lever, 0.5 * (corrected + corrected.T))
        order = np.argsort(new)
        corrections.append(
            InertiaCorrection(
                model.names[j], moments, new[order], invisible, mass - float(body.mass)
            )
        )
    return out, corrections


@dataclass(frozen=True)
class JointEffects:
    """What a physical joint adds in MuJoCo, per joint (URDF joint order); zeros = ideal.

    Attributes
    ----------
    damping : (n,) tuple
        Viscous friction (N m s/rad), MuJoCo ``joint/damping``.
    frictionloss : (n,) tuple
        Coulomb friction (N m), MuJoCo ``joint/frictionloss`` (a constraint force, symmetric).
    armature : (n,) tuple
        Rotor inertia reflected through the gear, ``G^2 Jm`` (kg m^2), MuJoCo
        ``joint/armature``.
    """

    damping: tuple[float, ...]
    frictionloss: tuple[float, ...]
    armature: tuple[float, ...]

    @staticmethod
    def ideal(n: int) -> JointEffects:
        return JointEffects((0.0,) * n, (0.0,) * n, (0.0,) * n)

    def check(self, n: int) -> None:
        """Raise :class:`ConfigError` naming the first bad field."""
        for name in ("damping", "frictionloss", "armature"):
            values = getattr(self, name)
            if len(values) != n:
                raise ConfigError(f"parameter '{name}': needs {n} values, got {len(values)}")
            if not all(math.isfinite(v) and v >= 0.0 for v in values):
                raise ConfigError(f"parameter '{name}': every value must be >= 0, got {values}")


def build_spec(
    model: pin.Model, effects: JointEffects | None = None, names: Sequence[str] | None = None
) -> mujoco.MjSpec:
    """An ``MjSpec`` of ``model``: one body per joint, its inertia, no geometry or contact.

    Raises
    ------
    RobotModelError
        A joint MuJoCo has no equivalent for (apc's models have 1-dof joints only).
    """
    n = model.njoints - 1
    effects = effects or JointEffects.ideal(n)
    spec = mujoco.MjSpec()
    spec.modelname = model.name or "arm"
    spec.option.gravity = np.array(model.gravity.linear, dtype=float)
    # No geometry, so nothing to collide; contact off makes that explicit.
    spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    bodies = [spec.worldbody]
    for j in range(1, model.njoints):
        placement = model.jointPlacements[j]
        quat = pin.Quaternion(placement.rotation)
        body = bodies[model.parents[j]].add_body(
            name=f"body_{model.names[j]}",
            pos=np.array(placement.translation, dtype=float),
            quat=np.array([quat.w, quat.x, quat.y, quat.z]),
        )
        inertia = model.inertias[j]
        body.explicitinertial = True
        body.mass = float(inertia.mass)
        body.ipos = np.array(inertia.lever, dtype=float)
        tensor = np.array(inertia.inertia)
        body.fullinertia = np.array(
            [
                tensor[0, 0],
                tensor[1, 1],
                tensor[2, 2],
                tensor[0, 1],
                tensor[0, 2],
                tensor[1, 2],
            ]
        )
        kind, axis = _joint_axis(model.joints[j])
        i = j - 1
        body.add_joint(
            name=(names[i] if names is not None else model.names[j]),
            type=mujoco.mjtJoint.mjJNT_SLIDE if kind == "slide" else mujoco.mjtJoint.mjJNT_HINGE,
            axis=axis,
            damping=float(effects.damping[i]),
            frictionloss=float(effects.frictionloss[i]),
            armature=float(effects.armature[i]),
        )
        bodies.append(body)
    return spec


def compile_model(model: pin.Model, effects: JointEffects | None = None) -> mujoco.MjModel:
    """Compile :func:`build_spec`; MuJoCo's refusal becomes a :class:`RobotModelError`."""
    try:
        return build_spec(model, effects).compile()
    except ValueError as exc:
        raise RobotModelError(f"MuJoCo refuses the model: {exc}") from None


class MujocoEngine(EngineSetup):
    """The arm in MuJoCo as a driver's engine (:class:`apc_plant_sim.robot_driver.Engine`).

    Takes :class:`apc_plant_sim.engines.EngineSetup`'s arguments (the inertias of the arm, with
    and without payload, are made physical by :func:`physical_inertias`), and

    Parameters
    ----------
    effects : JointEffects
        Damping, friction loss, armature.
    integrator : str
        A key of :data:`INTEGRATORS`.
    """

    def __init__(
        self,
        robot: Robot,
        payload: Payload,
        *,
        effects: JointEffects | None = None,
        integrator: str = "RK4",
        **setup: Any,
    ) -> None:
        super().__init__(robot, payload, **setup)
        n = robot.n_joints
        effects = effects or JointEffects.ideal(n)
        effects.check(n)
        if integrator not in INTEGRATORS:
            raise ConfigError(
                f"parameter 'mujoco.integrator': must be one of {', '.join(INTEGRATORS)}, "
                f"got {integrator!r}"
            )
        self.corrections: list[InertiaCorrection] = []
        models = {}
        for key, arm in (("bare", robot), ("loaded", self.loaded_robot)):
            physical, corrections = physical_inertias(arm.model)
            if key == ("loaded" if self.loaded else "bare"):
                self.corrections = corrections
            mj_model = compile_model(physical, effects)
            mj_model.opt.timestep = self.period / self.substeps
            mj_model.opt.integrator = INTEGRATORS[integrator]
            mj_model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
            models[key] = mj_model
        self._models = models
        self.model = models["loaded" if self.loaded else "bare"]
        self.data = mujoco.MjData(self.model)
        self.data.qpos[:] = self.q0
        mujoco.mj_forward(self.model, self.data)

    @property
    def q(self) -> np.ndarray:
        return self.data.qpos.copy()

    @property
    def qd(self) -> np.ndarray:
        return self.data.qvel.copy()

    def advance(self, tau: np.ndarray, duration: float) -> None:
        """Integrate one period under ``tau``.

        Raises
        ------
        EngineError
            MuJoCo found the state unstable; the state before the period is kept (MuJoCo's own
            reset to the initial pose is off: an arm does not jump back to where it started).
        """
        self.check_duration(duration)
        data = self.data
        before = (data.time, data.qpos.copy(), data.qvel.copy())
        counts = [data.warning[w].number for w in _UNSTABLE]
        data.qfrc_applied[:] = tau
        for _ in range(self.substeps):
            mujoco.mj_step(self.model, data)
        if [data.warning[w].number for w in _UNSTABLE] != counts or not (
            np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all()
        ):
            data.time, data.qpos[:], data.qvel[:] = before
            mujoco.mj_forward(self.model, data)
            raise EngineError(f"MuJoCo: the simulation became unstable at t = {data.time:.4f} s")

    def hold(self) -> None:
        self.data.qvel[:] = 0.0

    def load_payload(self) -> None:
        """The payload is picked up: the loaded model from now on, state and time kept."""
        if self.loaded:
            return
        model = self._models["loaded"]
        data = mujoco.MjData(model)
        data.time = self.data.time
        data.qpos[:] = self.data.qpos
        data.qvel[:] = self.data.qvel
        mujoco.mj_forward(model, data)
        self.model, self.data, self.loaded = model, data, True
