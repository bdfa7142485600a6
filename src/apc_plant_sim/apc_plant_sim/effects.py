"""What a physical arm adds to apc's plant, for offline measurement (no ROS).

:class:`PhysicalArm` wraps :class:`apc_plant_sim.plant.Plant` and offers the interface
:func:`apc_lab.offline.run_closed_loop` uses (``q``, ``qd``, ``k``, ``step``, ``limit``,
``set_robot``), so the same loop runs the ideal arm or one with any of these effects, each a
field of :class:`ArmEffects` and off by default:

- **viscous friction** ``b q'`` and **Coulomb friction** ``f± sign(q')`` at each joint, added to
  the plant's dynamics ``(D(q) + J_a) q'' + h + c = tau - friction(q')``;
- **rotor inertia** (armature) ``J_a = diag(J_m G²)``, the motors' inertia seen at the joints;
- **position quantisation**: the measured position is the encoder count times its resolution;
- **drive velocity**: the true velocity plus white Gaussian noise, or the backward difference of
  the quantised positions over one period (what a drive without a tachometer reports);
- **command delay** of whole periods: the command computed at sample ``k`` is applied over
  ``[(k+d)T, (k+d+1)T)``; the arm reports the torque it applied (a drive's measured effort).

Torque limits are the plant's own (the URDF's effort limits, on unless the plant's config turns
them off).

The PUMA 560 defaults (:func:`puma560_effects`) are the motor and gear data of Peter Corke's
Robotics Toolbox model ``Puma560`` (the consensus set of P. Corke and B. Armstrong-Helouvry, "A
search for consensus among model parameters reported for the PUMA 560 robot", ICRA 1994; the
friction is that identified by B. Armstrong, O. Khatib and J. Burdick, "The explicit dynamic
model and inertial parameters of the PUMA 560 arm", ICRA 1986), referred to the joint side as
the Toolbox does: armature ``J_m G²``, viscous ``B G²``, Coulomb ``T_c |G|``. The Franka Panda
defaults (:func:`panda_effects`) are an identified friction and an assumed encoder, no rotor
inertia (a link-side torque interface); each source is named at its constant.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from apc_core.params import settings_from
from apc_core.robot import Robot
from apc_plant_sim.plant import Plant, PlantConfig, PlantError, PlantStep

VelocitySource = Literal["exact", "noisy", "difference"]
_VELOCITY_SOURCES: tuple[str, ...] = ("exact", "noisy", "difference")

# PUMA 560 joints 1-3, motor side (Corke's Toolbox Puma560, see the module docstring).
PUMA560_MOTOR_INERTIA_KGM2 = (200e-6, 200e-6, 200e-6)  # J_m
PUMA560_GEAR_RATIO = (-62.6111, 107.815, -53.7063)  # G
PUMA560_MOTOR_VISCOUS_NM_S = (1.48e-3, 0.817e-3, 1.38e-3)  # B
PUMA560_MOTOR_COULOMB_POS_NM = (0.395, 0.126, 0.132)  # T_c for q' > 0
PUMA560_MOTOR_COULOMB_NEG_NM = (0.435, 0.071, 0.105)  # |T_c| for q' < 0
# Incremental encoders of 1000 counts per motor revolution (the Toolbox model carries no encoder
# data; an assumption of the order of the PUMA's motor encoders), so the joint resolution is
# 2 pi / (1000 |G|): 1.0e-4, 5.8e-5 and 1.2e-4 rad on joints 1-3.
PUMA560_ENCODER_COUNTS_PER_MOTOR_REV = 1000.0


# Franka Emika Panda, joints 1-7. Friction: the identification of C. Gaz, M. Cognetti, A. Oliva,
# P. Robuffo Giordano and A. De Luca, "Dynamic identification of the Franka Emika Panda robot with
# retrieval of feasible parameters using penalty-based optimization", IEEE RA-L 2019: per joint
# tau_f = phi1 / (1 + exp(-phi2 (q' + phi3))) - phi1 / (1 + exp(-phi2 phi3)), no viscous term; its
# levels for q' -> +inf and -inf are the Coulomb friction in each direction.
PANDA_FRICTION_PHI1_NM = (0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489)
PANDA_FRICTION_PHI2_S_RAD = (5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336)
PANDA_FRICTION_PHI3_RAD_S = (0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047, 0.0035526)
# No rotor inertia: the Panda's commanded torque is the link-side torque its joint torque sensors
# measure, the motor's inertia is inside the drive's own torque loop (and Gaz et al. identify the
# link inertias from those link-side torques, as apc's Panda URDF carries them).
# Franka publishes no encoder resolution: 2^16 counts per joint revolution (9.6e-5 rad, the order
# of the PUMA's joint-side resolution above) is an assumption.
PANDA_ENCODER_COUNTS_PER_JOINT_REV = 65536.0


class EffectsError(ValueError):
    """A bad effect parameter; the message names it."""


@dataclass(frozen=True)
class ArmEffects:
    """Effects of a physical arm, each off by default (all off: :class:`PhysicalArm` is the plant).

    Per-joint tuples are empty (off) or have one value per joint.

    Attributes
    ----------
    viscous_nm_s : per joint
        Viscous friction ``b`` (N m s/rad).
    coulomb_pos_nm, coulomb_neg_nm : per joint
        Coulomb friction magnitude (N m) when the joint turns in the positive and the negative
        direction.
    coulomb_smoothing_rad_s : float
        Velocity scale of the Coulomb term ``f tanh(q' / v_s)``: the sign function made
        continuous so that the plant's fixed-step RK4 stays stable (at h = 2.5 ms the slope
        ``f / v_s`` must stay below ~1000 times the joint inertia; 0.01 rad/s keeps it there for
        the PUMA's friction and inertia).
    armature_kgm2 : per joint
        Rotor inertia seen at the joint, ``J_m G²`` (kg m²).
    counts_per_rev : per joint
        Encoder counts per joint revolution; the measured position is ``round(q / r) r`` with
        ``r = 2 pi / counts``.
    velocity : {"exact", "noisy", "difference"}
        Measured velocity: the true one, the true one plus white noise of ``velocity_noise_rad_s``
        (standard deviation), or ``(q_m(k) - q_m(k-1)) / T`` of the measured positions.
    velocity_noise_rad_s : float
        Standard deviation of the velocity noise (``velocity="noisy"``).
    command_delay : int
        Whole periods between a command and the period it is applied over.
    seed : int
        Seed of the noise (runs are reproducible).
    """

    viscous_nm_s: tuple[float, ...] = ()
    coulomb_pos_nm: tuple[float, ...] = ()
    coulomb_neg_nm: tuple[float, ...] = ()
    coulomb_smoothing_rad_s: float = 0.01
    armature_kgm2: tuple[float, ...] = ()
    counts_per_rev: tuple[float, ...] = ()
    velocity: VelocitySource = "exact"
    velocity_noise_rad_s: float = 0.0
    command_delay: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("viscous_nm_s", "coulomb_pos_nm", "coulomb_neg_nm", "armature_kgm2"):
            values = tuple(float(v) for v in getattr(self, name))
            if not all(math.isfinite(v) and v >= 0.0 for v in values):
                raise EffectsError(f"{name} must be finite and >= 0, got {list(values)}")
            object.__setattr__(self, name, values)
        counts = tuple(float(v) for v in self.counts_per_rev)
        if not all(math.isfinite(v) and v > 0.0 for v in counts):
            raise EffectsError(f"counts_per_rev must be finite and > 0, got {list(counts)}")
        object.__setattr__(self, "counts_per_rev", counts)
        if not (math.isfinite(self.coulomb_smoothing_rad_s) and self.coulomb_smoothing_rad_s > 0):
            raise EffectsError(
                f"coulomb_smoothing_rad_s must be > 0, got {self.coulomb_smoothing_rad_s}"
            )
        if self.velocity not in _VELOCITY_SOURCES:
            raise EffectsError(
                f"velocity must be one of {', '.join(_VELOCITY_SOURCES)}, got {self.velocity!r}"
            )
        if not (math.isfinite(self.velocity_noise_rad_s) and self.velocity_noise_rad_s >= 0.0):
            raise EffectsError(
                f"velocity_noise_rad_s must be >= 0, got {self.velocity_noise_rad_s}"
            )
        if (
            isinstance(self.command_delay, bool)
            or not isinstance(self.command_delay, int)
            or self.command_delay < 0
        ):
            raise EffectsError(f"command_delay must be an integer >= 0, got {self.command_delay!r}")

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> ArmEffects:
        """Build from a plain mapping; an unknown key is rejected with its name."""
        return settings_from(ArmEffects, values, EffectsError, "arm effect")

    def per_joint(self, name: str, n: int) -> np.ndarray:
        """Field ``name`` as an (n,) array; zeros when it is off."""
        values = getattr(self, name)
        if not values:
            return np.zeros(n)
        if len(values) != n:
            raise EffectsError(f"{name} needs {n} values, got {len(values)}")
        return np.array(values, dtype=float)

    def mean_coulomb(self, n: int) -> np.ndarray:
        """The Coulomb level of each joint as one magnitude for both directions, the mean of
        the two (N m, (n,)): what a symmetric friction model (MuJoCo's ``frictionloss``, the
        controllers' ``friction``) takes of an arm whose two directions differ."""
        return 0.5 * (self.per_joint("coulomb_pos_nm", n) + self.per_joint("coulomb_neg_nm", n))


def puma560_effects(
    velocity: VelocitySource = "difference", command_delay: int = 1, seed: int = 0
) -> ArmEffects:
    """Every effect on for the three-joint PUMA 560, from its data (module docstring).

    The velocity noise of ``velocity="noisy"`` is one joint-side encoder count per period, the
    size of the step a backward difference of the quantised positions takes.
    """
    gear = np.abs(PUMA560_GEAR_RATIO)
    counts = PUMA560_ENCODER_COUNTS_PER_MOTOR_REV * gear
    return ArmEffects(
        viscous_nm_s=tuple(np.array(PUMA560_MOTOR_VISCOUS_NM_S) * gear**2),
        coulomb_pos_nm=tuple(np.array(PUMA560_MOTOR_COULOMB_POS_NM) * gear),
        coulomb_neg_nm=tuple(np.array(PUMA560_MOTOR_COULOMB_NEG_NM) * gear),
        armature_kgm2=tuple(np.array(PUMA560_MOTOR_INERTIA_KGM2) * gear**2),
        counts_per_rev=tuple(counts),
        velocity=velocity,
        velocity_noise_rad_s=float(2.0 * np.pi / counts.min() / 0.010),
        command_delay=command_delay,
        seed=seed,
    )


def panda_effects(
    velocity: VelocitySource = "difference", command_delay: int = 1, seed: int = 0
) -> ArmEffects:
    """Every effect of a physical arm for the Franka Emika Panda (7 joints), from the data above.

    Coulomb friction is Gaz et al.'s sigmoid at full speed, ``phi1 / (1 + exp(phi2 phi3))`` for
    ``q' > 0`` and ``phi1 / (1 + exp(-phi2 phi3))`` for ``q' < 0`` (they sum to ``phi1``); no
    viscous friction (their model has none) and no rotor inertia (see its comment). The velocity
    noise of ``velocity="noisy"`` is one encoder count per 10 ms.
    """
    phi1 = np.array(PANDA_FRICTION_PHI1_NM)
    shift = np.array(PANDA_FRICTION_PHI2_S_RAD) * np.array(PANDA_FRICTION_PHI3_RAD_S)
    counts = PANDA_ENCODER_COUNTS_PER_JOINT_REV
    return ArmEffects(
        coulomb_pos_nm=tuple(phi1 / (1.0 + np.exp(shift))),
        coulomb_neg_nm=tuple(phi1 / (1.0 + np.exp(-shift))),
        counts_per_rev=(counts,) * len(phi1),
        velocity=velocity,
        velocity_noise_rad_s=float(2.0 * np.pi / counts / 0.010),
        command_delay=command_delay,
        seed=seed,
    )


#: The single effects of :func:`puma560_effects`, one at a time (name -> fields kept on).
EFFECT_FIELDS: dict[str, tuple[str, ...]] = {
    "friction": ("viscous_nm_s", "coulomb_pos_nm", "coulomb_neg_nm"),
    "armature": ("armature_kgm2",),
    "quantisation": ("counts_per_rev",),
    "velocity_noise": ("velocity_noise_rad_s",),
    "velocity_difference": ("counts_per_rev",),
    "delay": ("command_delay",),
}


def single_effect(name: str, full: ArmEffects) -> ArmEffects:
    """Only effect ``name`` of ``full`` (``"all"``: ``full``; ``"ideal"``: none)."""
    if name == "all":
        return full
    if name == "ideal":
        return ArmEffects()
    if name not in EFFECT_FIELDS:
        raise EffectsError(f"effect must be ideal, all or one of {sorted(EFFECT_FIELDS)}")
    kept = {f: getattr(full, f) for f in EFFECT_FIELDS[name]}
    if name == "velocity_noise":
        kept["velocity"] = "noisy"
    elif name == "velocity_difference":
        kept["velocity"] = "difference"
    return replace(ArmEffects(seed=full.seed), **kept)


class DriveSensing:
    """What a drive reports of the arm: quantised positions and its velocity, once a period.

    The sensing fields of :class:`ArmEffects` (``counts_per_rev``, ``velocity``,
    ``velocity_noise_rad_s``, ``seed``); shared by :class:`PhysicalArm` and the simulated
    ros2_control robot's driver.
    """

    def __init__(self, effects: ArmEffects, n: int, period: float, q0: np.ndarray) -> None:
        counts = effects.per_joint("counts_per_rev", n)
        self._resolution = np.where(counts > 0.0, 2.0 * np.pi / np.where(counts > 0, counts, 1), 0)
        self._rng = np.random.default_rng(effects.seed)
        self._velocity = effects.velocity
        self._noise = effects.velocity_noise_rad_s
        self._period = period
        self._q_previous = self.quantise(q0)

    def quantise(self, q: np.ndarray) -> np.ndarray:
        """Positions as the encoder counts them (unchanged where counts_per_rev is off)."""
        r = self._resolution
        return np.where(r > 0.0, np.round(q / np.where(r > 0, r, 1.0)) * r, q)

    def read(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(measured position, reported velocity) of the true ``(q, q')``; call once a period."""
        q_measured = self.quantise(q)
        if self._velocity == "difference":
            qd_measured = (q_measured - self._q_previous) / self._period
        elif self._velocity == "noisy":
            qd_measured = qd + self._rng.normal(0.0, self._noise, len(qd))
        else:
            qd_measured = np.array(qd, dtype=float)
        self._q_previous = q_measured
        return q_measured, qd_measured


class _FrictionPlant(Plant):
    """apc's plant with armature and joint friction in its forward dynamics."""

    def __init__(self, robot: Robot, config: PlantConfig, effects: ArmEffects, q0, qd0) -> None:
        n = robot.n_joints
        self._armature = effects.per_joint("armature_kgm2", n)
        self._viscous = effects.per_joint("viscous_nm_s", n)
        self._coulomb_pos = effects.per_joint("coulomb_pos_nm", n)
        self._coulomb_neg = effects.per_joint("coulomb_neg_nm", n)
        self._smoothing = effects.coulomb_smoothing_rad_s
        self._friction = bool(
            self._viscous.any() or self._coulomb_pos.any() or self._coulomb_neg.any()
        )
        super().__init__(self._with_armature(robot), config, q0, qd0)

    def _with_armature(self, robot: Robot) -> Robot:
        if not self._armature.any():
            return robot
        model = robot.model.copy()
        model.armature = model.armature + self._armature
        return replace(robot, model=model)

    def set_robot(self, robot: Robot) -> None:
        super().set_robot(self._with_armature(robot))

    def friction(self, qd: np.ndarray) -> np.ndarray:
        """Friction torque opposing the motion (N m), ``b q' + f± tanh(q' / v_s)``."""
        coulomb = np.where(qd >= 0.0, self._coulomb_pos, self._coulomb_neg)
        return self._viscous * qd + coulomb * np.tanh(qd / self._smoothing)

    def acceleration(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        if self._friction:
            tau = tau - self.friction(qd)
        # Pinocchio's ABA and CRBA add model.armature to the joint-space inertia.
        return super().acceleration(q, qd, tau)


class PhysicalArm:
    """apc's plant with the effects of :class:`ArmEffects`, as :func:`run_closed_loop` uses it.

    ``q`` and ``qd`` are what the arm measures at the current sample, ``step`` applies a command
    after the command delay and reports the torque it applied.
    """

    def __init__(
        self,
        robot: Robot,
        config: PlantConfig,
        effects: ArmEffects,
        q0: np.ndarray,
        qd0: np.ndarray | None = None,
    ) -> None:
        self.effects = effects
        self._plant = _FrictionPlant(robot, config, effects, q0, qd0)
        n = self._plant.n_joints
        self._sensing = DriveSensing(effects, n, config.period, self._plant.q)
        self._pending: list[np.ndarray] = []
        self._measure()

    # The attributes run_closed_loop reads.
    @property
    def robot(self) -> Robot:
        return self._plant.robot

    @property
    def config(self) -> PlantConfig:
        return self._plant.config

    @property
    def n_joints(self) -> int:
        return self._plant.n_joints

    @property
    def k(self) -> int:
        return self._plant.k

    @property
    def true_q(self) -> np.ndarray:
        return self._plant.q

    @property
    def true_qd(self) -> np.ndarray:
        return self._plant.qd

    def set_robot(self, robot: Robot) -> None:
        self._plant.set_robot(robot)

    def limit(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._plant.limit(tau)

    def _measure(self) -> None:
        self.q, self.qd = self._sensing.read(self._plant.q, self._plant.qd)

    def step(self, tau: np.ndarray) -> PlantStep:
        """Take command ``tau``; apply the one ``command_delay`` periods old (at the start, the
        first command: the arm held it before the run) and measure the next sample."""
        tau = np.array(tau, dtype=float)
        if tau.shape != (self.n_joints,) or not np.isfinite(tau).all():
            raise PlantError(f"tau must be {self.n_joints} finite values, got {tau.tolist()}")
        delay = self.effects.command_delay
        if not self._pending:
            self._pending = [tau.copy() for _ in range(delay)]
        self._pending.append(tau.copy())
        applied = self._pending.pop(0)
        step = self._plant.step(applied)
        self._measure()
        return PlantStep(
            q=self.q.copy(), qd=self.qd.copy(), applied=step.applied, saturated=step.saturated
        )
