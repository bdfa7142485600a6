"""Named settings of the adaptive law, and the node parameters they are the defaults of.

``recommended`` is what the feedback node and every command start with: the paper's law with
the changes measured to work (:func:`recommended_settings`); ``paper`` is the law as printed
(:func:`paper_settings`), ``physical`` the recommended one for an arm behind a drive. The node's
``preset`` parameter picks one; an ``adaptive.*`` parameter given as well overrides its value.
Plain Python: no rclpy.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from typing import Any

from apc_core.params import ConfigError, Param
from apc_core.robot import PAPER_PERIOD_S
from apc_feedback.adaptive_config import HELD_SPLIT_PRIOR
from apc_feedback.laws import LAW_PARAMS, LAWS


def paper_settings(alpha: float = 1.5e5) -> dict[str, Any]:
    """The printed adaptive settings: Q = 0.1 I, R = 1e-6 I, rho = 0.95, P(0) = alpha I.

    As printed, the RLS has no wind-up guard (``trace_max < 0``); the corrected Eqs. 30, 33b
    and 35 are used (their modules, ``rls``, ``linearize`` and ``optimal``, say why).
    """
    return {
        "q_position": 0.1,
        "q_velocity": 0.1,
        "r": 1e-6,
        "rho": 0.95,
        "alpha": alpha,
        "trace_max": -1.0,
    }


def recommended_settings(alpha: float = 1.5e5) -> dict[str, Any]:
    """Within the paper's structure, what the measurements recommend (``bench/preset_sweep.py``):
    the paper's settings (R, P(0)) with these changes.

    Same RLS-identified perturbation model and optimal control of it, same feedforward, with
    changes chosen by measurement on the paper's three cases: a position-weighted Q (Eq. 34
    with Q = 0.1 I weighs next-step position ~ (T/2)^2 as much as velocity, so a payload's
    gravity builds up as position error), a 3-step receding horizon over the identified model,
    integral action on the position error, the RLS wind-up guard, and a projection that refuses
    RLS steps making a diagonal entry of Ĝ's velocity block (≈ T D⁻¹) non-positive (a payload
    picked up mid-motion otherwise flips Ĝ and the law saturates). ``alpha`` is ``P(0)`` of ŵ
    alone: F̂ and Ĝ start from Eq. 33 with ``P(0) = 1e-5`` (``alpha_model``), so a sample
    moves them as far as ``alpha_model |δu|²`` against 1 allows: a late command on a hold,
    which robot mode starts every activation with, must not move the model, and on a robot
    it must not fit what Eq. 16 does not describe (a jittering delay, quantised positions,
    friction) while the prior, which follows the set point and is told the delay and the
    velocity robot mode measures, is right; 1e-3 loses the physical PUMA at 250 Hz and costs
    the Panda there (docs/robot.md, "A slower model"). The input lags plan over the inputs on their
    way, and ``q_input_change`` weighs the planned input's change on the velocity it makes, so
    that the law does not keep its own inputs ringing at the Nyquist frequency, which sampled
    positions do not see (:mod:`apc_feedback.lagged_control`); ``input_ring_limit`` raises that
    weight wherever the plan would push each input on its way back harder than it came (the
    law's commands growing while the arm does not answer them: an arm held still by its
    friction, a 100 Hz driver), so that they do not. Why these values and not
    others, measured: docs/paper.md, "The model prior" and the preset sweep; docs/robot.md,
    "Commands ringing at the Nyquist frequency". ŵ forgets more slowly than the paper's
    (``rho`` 0.99, a memory of about 100 samples, 1 s at T = 10 ms, against 0.95's 20): with the
    integral action it would otherwise follow a joint's Coulomb friction as it flips with the
    velocity, and the two hold a light joint in a limit cycle (the Panda's wrist under its
    payload: ±0.35 deg at about 1 Hz, finals up to 0.45 deg; with 0.99, 0.02-0.19 deg;
    docs/robot.md, "Hunting in a hold").
    """
    return {
        **paper_settings(alpha),
        "rho": 0.99,  # ŵ's memory; 0.95 hunts on friction (docstring)
        "q_position": 2000.0,
        "q_velocity": 1.0,
        "trace_max": 0.0,
        "horizon": 3,
        "q_integral": 1e6,
        "integral_limit": 0.05,
        "project_g": True,
        "alpha_model": 1e-5,
        "input_lags": 2,
        "relinearize": True,
        "q_input_change": 0.003,
        "input_ring_limit": 1.0,
    }


def physical_settings(alpha: float = 1.5e5) -> dict[str, Any]:
    """The recommended preset told where a drive puts its inputs: applied one period late, and
    seen through a velocity differenced over one period (half a period more), so ``Ĝ(0)`` is
    split by 1.5 T and held there (``split_prior``: the delay is known, only the total input
    gain is learnt). The offline stand-in for what robot mode measures (it splits ``Ĝ(0)`` by
    the driver period it sees and learns the split). The split is held because, learnt from
    closed-loop data, the lags trade effect between them (``bench/effects_sweep.py``; the
    figures are in docs/paper.md, "What a physical arm adds").
    """
    return {
        **recommended_settings(alpha),
        "input_delay": 1.5 * PAPER_PERIOD_S,
        "split_prior": HELD_SPLIT_PRIOR,
    }


#: Each preset by name: ``preset(alpha)`` gives the adaptive settings it changes.
PRESETS: dict[str, Callable[..., dict[str, Any]]] = {
    "recommended": recommended_settings,
    "paper": paper_settings,
    "physical": physical_settings,
}
#: The preset of the feedback node and of the commands when none is named.
DEFAULT_PRESET = "recommended"

PRESET_PARAM = Param(
    "preset",
    DEFAULT_PRESET,
    f"defaults of the adaptive.* parameters: one of {', '.join(PRESETS)} (recommended: "
    "measured to work; paper: as printed); an adaptive.* value given as well overrides it",
)


def preset_rows(params: Iterable[Param], preset: str = DEFAULT_PRESET) -> tuple[Param, ...]:
    """``params`` without the ``preset`` row, each adaptive setting's default taken from
    ``preset``: what a node declares once it has read its preset. An unknown preset is a
    :class:`ConfigError` naming ``preset``."""
    make = PRESETS.get(preset)
    if make is None:
        raise ConfigError(
            f"parameter 'preset': must be one of {', '.join(PRESETS)}, got {preset!r}"
        )
    family = LAWS["adaptive"].family
    # What a preset leaves out is the law's own default (AdaptiveConfig's), not another
    # preset's: ``params`` may carry the default preset's values already.
    values = {row.name: row.default for row in LAW_PARAMS if row.name.startswith(family)}
    values.update({family + key: value for key, value in make().items()})
    return tuple(
        dataclasses.replace(row, default=type(row.default)(values[row.name]))
        if row.name in values
        else row
        for row in params
        if row.name != PRESET_PARAM.name
    )


def law_params(preset: str = DEFAULT_PRESET) -> tuple[Param, ...]:
    """The feedback laws' parameter rows (:data:`LAW_PARAMS`) with the adaptive law's defaults
    taken from ``preset``."""
    return preset_rows(LAW_PARAMS, preset)
