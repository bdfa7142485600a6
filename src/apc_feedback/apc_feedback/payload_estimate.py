"""A payload's mass from the torques that hold the arm still (robot mode).

Held still, an arm's joint torques balance gravity: ``tau = g(q) + m a(q)``, where ``g`` is the
controller's model without the payload and ``a(q)`` the gravity torque of one kilogram at the
payload's point (its frame and centre of mass, which the user tells: where the tool is, not what
it weighs). Once a hold has lasted ``settle_s``, over a window of samples in which no joint
moved by more than ``still_rad``, the mass is the least-squares fit of the window's mean torque
less the model's gravity on ``a``: ``m = a.(tau - g) / a.a``. The torque is what the controllers
command; an arm whose drives hold part of the load by static friction shifts it (the physical
PUMA of robot_sim, its Coulomb friction told to the controllers: +7 % to +20 % over windows of
its first second; the physical Panda: within 1 %), and so does a model whose own gravity is
wrong.

Robot mode (:mod:`apc_feedback.robot_loop`) asks once per activation, in a hold with no goal
queued; with an estimate of at least ``min_kg`` and at most ``max_kg`` it carries on with the
payload in its model (the feedforward's plan and the watchdog's hold; the supervisor's fallback
keeps the model without it), and the adaptive law hands the load it held until then over to
the nominal torque without a bump (:class:`PayloadCarry`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin

from apc_core.params import SettingError, check_settings, setting, settings_from
from apc_core.robot import Payload, Robot, with_payload

Torque = Callable[[np.ndarray], np.ndarray]


class PayloadEstimateError(SettingError):
    """A bad ``payload_estimate.*`` setting; ``field`` names it."""


@dataclass(frozen=True)
class PayloadEstimateConfig:
    """How robot mode estimates its payload (``payload_estimate.*`` parameters)."""

    enable: bool = setting(
        False,
        "adaptive law: estimate the payload at the first still hold after each activation and "
        "carry it in the model (docs/robot.md, 'A payload estimated in the hold')",
    )
    frame: str = setting(
        "", "URDF frame the payload is fixed to (a tool flange); '' is the last joint's body"
    )
    com_m: tuple[float, ...] = setting(
        (0.0, 0.0, 0.0), "the payload's centre of mass in 'frame' (m; x, y, z)"
    )
    settle_s: float = setting(
        0.3,
        "how long a hold lasts before its window starts: the law's answer to the load settling (s)",
        0.0,
        10.0,
    )
    window_s: float = setting(
        0.2, "how long the arm must hold still for the estimate (s)", 0.0, 10.0
    )
    still_rad: float = setting(
        5e-3, "the most any joint may move within the window (rad)", 0.0, 1.0
    )
    min_kg: float = setting(
        0.1, "estimates below this leave the model without a payload (kg)", 0.0, 1e3
    )
    max_kg: float = setting(
        10.0,
        "estimates above this (the arm's rated payload, with a margin) are refused as a model "
        "that does not fit the arm (kg)",
        0.0,
        1e3,
    )

    def __post_init__(self) -> None:
        check_settings(self, PayloadEstimateError)
        com = tuple(float(c) for c in self.com_m)
        if len(com) != 3 or not all(np.isfinite(com)):
            raise PayloadEstimateError(
                f"com_m needs 3 finite numbers, got {list(self.com_m)}", field="com_m"
            )
        object.__setattr__(self, "com_m", com)
        for name in ("window_s", "still_rad"):
            if not getattr(self, name) > 0.0:
                raise PayloadEstimateError(f"{name} must be > 0", field=name)
        if self.min_kg >= self.max_kg:
            raise PayloadEstimateError(
                f"min_kg must be below max_kg ({self.max_kg:g}), got {self.min_kg:g}",
                field="min_kg",
            )

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> PayloadEstimateConfig:
        return settings_from(
            PayloadEstimateConfig, values, PayloadEstimateError, "payload_estimate parameter"
        )


class HoldPayloadEstimate:
    """The least-squares mass of the payload over a still window (see the module docstring).

    Parameters
    ----------
    config : PayloadEstimateConfig
    period : float
        The sampling period T (s): the window is ``ceil(window_s / T)`` samples.
    gravity : callable
        ``g(q)`` of the controller's model without the payload (model order).
    unit_gravity : callable
        ``a(q)``: the gravity torque of 1 kg at the payload's point (model order).
    """

    def __init__(
        self, config: PayloadEstimateConfig, period: float, gravity: Torque, unit_gravity: Torque
    ) -> None:
        if not (np.isfinite(period) and period > 0.0):
            raise ValueError(f"period must be finite and > 0 s, got {period}")
        self.config = config
        self.samples = max(2, int(np.ceil(config.window_s / period - 1e-9)))
        self.settle = int(np.ceil(config.settle_s / period - 1e-9))
        self._gravity, self._unit = gravity, unit_gravity
        self._window: list[tuple[np.ndarray, np.ndarray]] = []
        self._held = 0  # samples of the hold so far

    def reset(self) -> None:
        """Forget the hold (a move, a fault, another law in charge): the next one settles
        first."""
        self._window.clear()
        self._held = 0

    def add(self, position: np.ndarray, torque: np.ndarray) -> float | None:
        """One sample of a hold: the measured ``position`` and the torque commanded at it.
        Returns the mass (kg) once the last ``samples`` after the first ``settle`` were still,
        else None."""
        self._held += 1
        if self._held <= self.settle:
            return None
        window = self._window
        window.append((position.copy(), torque.copy()))  # the caller may reuse its arrays
        if len(window) > self.samples:
            window.pop(0)
        q = np.array([p for p, _ in window])
        if np.any(np.ptp(q, axis=0) > self.config.still_rad):
            # Moving: the window starts again at the newest sample.
            del window[:-1]
            return None
        if len(window) < self.samples:
            return None
        residual = np.mean([t - self._gravity(p) for p, t in window], axis=0)
        unit = np.mean([self._unit(p) for p, _ in window], axis=0)
        norm = float(unit @ unit)
        if not norm > 0.0:
            return None  # a pose where the payload's weight loads no joint
        return float(unit @ residual) / norm


class PayloadStep(NamedTuple):
    """What one sample of a hold comes to: the line to log (the estimate's verdict) and the
    mass the model carries from the next sample on (None: as it is)."""

    text: str | None = None
    carry_kg: float | None = None


NO_STEP = PayloadStep()


class PayloadCarry:
    """Robot mode's payload: estimated at the first still hold of an activation, and what the
    controllers' model carries (see the module docstring).

    The model takes an estimate on at once and the adaptive law measures its inputs from the
    new nominal torque, its offset ``ŵ`` taking what they held, so that it predicts and commands
    as before (``AdaptiveFeedback.move_nominal``): a bumpless hand-over of the load from the law
    to the nominal torque (docs/robot.md, "A payload estimated in the hold", has the ways
    tried).

    Parameters
    ----------
    estimate : HoldPayloadEstimate
    model_with : callable
        ``model_with(m)``: the controller's model with ``m`` kg at the payload's point, as
        ``(pinocchio model for the plan, its gravity g(q))``.
    """

    def __init__(
        self, estimate: HoldPayloadEstimate, model_with: Callable[[float], tuple[Any, Torque]]
    ) -> None:
        self.estimate = estimate
        self.model_with = model_with
        self.carried_kg = 0.0
        self.measured_kg: float | None = None
        self._done = False

    def start(self) -> None:
        """An activation: estimate again at its first still hold."""
        self._done = False
        self.estimate.reset()

    def observe(self, position: np.ndarray, torque: np.ndarray, holding: bool) -> PayloadStep:
        """One sample: its measured position, the torque commanded at it, and whether the
        adaptive law holds the arm still on the plan (the next sample too)."""
        if self._done:
            return NO_STEP  # once an activation: start() opens the next one
        if not holding:
            self.estimate.reset()
            return NO_STEP
        m = self.estimate.add(position, torque)
        if m is None:
            return NO_STEP
        self._done, self.measured_kg = True, m
        config = self.estimate.config
        held = f"the arm holds still with {m:.3g} kg beyond its model at the payload's point"
        if m > config.max_kg:
            return PayloadStep(
                f"{held}, more than payload_estimate.max_kg ({config.max_kg:g} kg): a model "
                "that does not fit the arm, or a wrong payload_estimate.frame; not carried"
            )
        target = m if m >= config.min_kg else 0.0
        if target == self.carried_kg:
            return PayloadStep(f"{held}; the model carries {target:.3g} kg already")
        before, self.carried_kg = self.carried_kg, target
        return PayloadStep(
            f"{held}; the model carries {target:.3g} kg from the next sample (was "
            f"{before:.3g} kg); the adaptive law hands the load it held over to the nominal torque",
            target,
        )


def payload_carry(
    robot: Robot, config: PayloadEstimateConfig, period: float
) -> PayloadCarry | None:
    """Robot mode's :class:`PayloadCarry` for the controller's ``robot`` (its model without a
    payload) sampled every ``period`` s; None unless ``config.enable``. Raises
    :class:`PayloadEstimateError` for a ``frame`` the model does not have."""
    if not config.enable:
        return None

    def model_with(mass: float) -> tuple[pin.Model, Torque]:
        try:
            payload = Payload(mass, config.com_m, config.frame or None)
            model = with_payload(robot, payload).model
        except ValueError as exc:  # RobotModelError
            raise PayloadEstimateError(str(exc), field="frame") from None
        data = model.createData()
        return model, lambda q: pin.computeGeneralizedGravity(model, data, q).copy()

    _, gravity = model_with(0.0)
    _, loaded = model_with(1.0)
    estimate = HoldPayloadEstimate(config, period, gravity, lambda q: loaded(q) - gravity(q))
    return PayloadCarry(estimate, model_with)
