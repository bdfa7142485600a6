"""The feedback laws by name: one list, one factory, used by the node and the offline runs.

Each law has a settings dataclass (or none), named as a family of node parameters
(``adaptive.rho``, ``gains.kp``), and a constructor. :func:`make_law` builds a law from its
name and its settings; :data:`LAWS` is what the node and the command lines offer.
:class:`LawParameters` is a law as the node's parameters see it: built from their values, its
run-time settings checked when set and taken at the next sample, every error naming the
parameter. Plain Python: the node maps its answers to ROS.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from apc_core.params import ConfigError, Param, params_from, subset
from apc_core.robot import Robot
from apc_feedback.baselines import PD, PID, ComputedTorque, NoFeedback, PdGains, PidGains
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback, FeedbackError
from apc_feedback.feedback_law import FeedbackLaw


@dataclass(frozen=True)
class LawKind:
    """How to build one feedback law.

    Attributes
    ----------
    settings : type or None
        The settings dataclass, built with its ``from_dict`` (unknown keys are refused); None:
        the law takes no settings.
    family : str
        Prefix of its settings as node parameters (``"adaptive."``); empty if none.
    build : callable
        ``build(robot, period, settings) -> FeedbackLaw``.
    """

    settings: type | None
    family: str
    build: Callable[[Robot, float, Any], FeedbackLaw]


LAWS: dict[str, LawKind] = {
    "adaptive": LawKind(
        AdaptiveConfig, "adaptive.", lambda robot, _, cfg: AdaptiveFeedback(robot.model, cfg)
    ),
    "computed_torque": LawKind(
        PdGains, "gains.", lambda robot, _, gains: ComputedTorque(robot.model, gains)
    ),
    "pd": LawKind(PdGains, "gains.", lambda robot, _, gains: PD(robot.n_joints, gains)),
    "pid": LawKind(
        PidGains,
        "pid.",
        lambda robot, period, gains: PID(robot.model, robot.effort_limit, period, gains),
    ),
    "none": LawKind(None, "", lambda robot, _, __: NoFeedback(robot.n_joints)),
}
#: The names of the laws, in the order they are offered.
CONTROLLER_KINDS: tuple[str, ...] = tuple(LAWS)


def make_law(
    kind: str, robot: Robot, period: float, settings: Mapping[str, Any] | None = None
) -> FeedbackLaw:
    """The feedback law ``kind`` on the controller's ``robot``, sampled every ``period`` s.

    ``settings`` are the fields of the law's settings dataclass (:class:`AdaptiveConfig` for
    ``adaptive``, whose ``period`` defaults to ``period``; :class:`PdGains` for
    ``computed_torque`` and ``pd``; :class:`PidGains` for ``pid``); missing ones take the
    dataclass's defaults.

    Raises
    ------
    FeedbackError
        An unknown ``kind`` (``field`` = ``"controller"``), settings for a law that takes none,
        or a bad setting (``field`` names it).
    """
    law = LAWS.get(kind)
    if law is None:
        raise FeedbackError(
            f"controller must be one of {', '.join(CONTROLLER_KINDS)}, got {kind!r}",
            field="controller",
        )
    settings = dict(settings or {})
    if law.settings is None:
        if settings:
            raise FeedbackError(f"controller {kind!r} takes no parameters, got {sorted(settings)}")
        return law.build(robot, period, None)
    if law.settings is AdaptiveConfig:
        settings.setdefault("period", period)
    return law.build(robot, period, law.settings.from_dict(settings))


#: The node's parameters of the laws: the choice, then each settings family once.
LAW_PARAMS: tuple[Param, ...] = (
    Param("controller", "adaptive", f"feedback law: one of {', '.join(CONTROLLER_KINDS)}"),
    *(
        row
        for family, cls in {k.family: k.settings for k in LAWS.values() if k.settings}.items()
        for row in params_from(cls, family)
    ),
)
_RUNTIME = {p.name for p in LAW_PARAMS if not p.read_only}


class LawParameters:
    """The law named by the ``controller`` parameter, built from the node's parameter values.

    Its run-time settings (``runtime=True`` fields, e.g. ``adaptive.r``, ``gains.kp``) are
    checked by the settings dataclass when set (:meth:`propose`, all or none) and taken by the
    law at the next sample (:meth:`take`), so a value is never half-applied mid-sample.

    Raises
    ------
    ConfigError
        From the constructor and :meth:`propose`, naming the parameter.
    """

    def __init__(self, values: Mapping[str, Any], robot: Robot) -> None:
        self.kind = values["controller"]
        self._names = set(values)
        law = LAWS.get(self.kind)
        self.family = law.family if law is not None else ""
        settings = subset(values, self.family) if self.family else None
        try:
            self.law = make_law(self.kind, robot, values["period"], settings)
        except FeedbackError as exc:
            raise self._naming(exc) from None
        self._pending: dict[str, Any] = {}

    def _naming(self, exc: FeedbackError) -> ConfigError:
        """The error as the node reports it: naming the setting's parameter, a node-wide one
        (``period``), or else the ``controller``."""
        name = next(
            (n for n in (f"{self.family}{exc.field}", exc.field) if n in self._names),
            "controller",
        )
        return ConfigError(f"parameter '{name}': {exc}")

    def _settings(self, updates: Mapping[str, Any]) -> Any:
        return dataclasses.replace(self.law.settings, **subset(updates, self.family))

    def propose(self, updates: Mapping[str, Any]) -> None:
        """Check new values of parameters by name (other parameters are not this class's to
        judge) and keep them for :meth:`take`; a refused set changes nothing."""
        pending = dict(self._pending)
        for name, value in updates.items():
            if name not in _RUNTIME:
                continue
            if not (self.family and name.startswith(self.family)):
                raise ConfigError(f"parameter '{name}': not used by controller '{self.kind}'")
            pending[name] = value
        try:
            self._settings(pending)
        except FeedbackError as exc:
            raise self._naming(exc) from None
        self._pending = pending

    def take(self) -> dict[str, Any]:
        """Give the law the values proposed since the last call; returns them by name."""
        pending, self._pending = self._pending, {}
        if pending:
            self.law.reconfigure(self._settings(pending))
        return pending
