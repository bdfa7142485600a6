"""The feedback laws by name: one list, one factory, used by the node and the offline runs.

Each law has a settings dataclass (or none), named as a family of node parameters
(``adaptive.rho``, ``gains.kp``), and a constructor. :func:`make_law` builds a law from its
name and its settings; :data:`LAWS` is what the node and the command lines offer.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from apc_core.robot import Robot
from apc_feedback.baselines import PD, PID, ComputedTorque, NoFeedback, PdGains, PidGains
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback, FeedbackError, FeedbackLaw


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
