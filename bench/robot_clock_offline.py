"""The wall-time robot grid's cells in simulated time: robot mode's loop closed offline.

:func:`apc_lab.robot_offline.run_robot_loop`, no ROS, deterministic: the 3-joint PUMA 560 and
the Franka Panda (``robot_compare``'s arms, 5 lb the controllers do not know, 10 % inertia
error), robot mode at T = 10 ms sampling on the states' arrival, case (c)'s move 1 s after
activation, as the wall-time bench sends it (:data:`~apc_lab.wall_clock.HOLD_BEFORE_S`: a law
that has learnt through a 0.2 s hold tracks the physical PUMA at 100 Hz where after 1 s it
is handed over). ``ideal``: apc's plant, positions only (the robot files' drivers); ``physical``:
the arm in MuJoCo with every effect of ``robot_sim``'s ``effects: puma560`` / ``panda``
(friction, rotor inertia on the PUMA, quantised encoders, the drive's differenced velocity
published, a drive that adds one cycle). Per driver rate (100 Hz-1 kHz), commands either all
on time (each reaches the drive before its next cycle) or 30 % of them one driver cycle late
(``Latency(late_ms=driver period, probability=0.3)``: the jitter of a loaded machine, which
wall time has and simulated time has not), and per law: the recommended preset alone,
supervised with the computed-torque fallback (the default) and with the PID fallback.

A physical arm's run is chaotic in its inputs: the payload's fifth digit can move the worst
error from 1 to 38 deg. So every cell is five runs that differ as real runs do, the payload
within ±1 % (:data:`PAYLOAD_FACTORS`) and, with late commands, the draws (seeds 0-4), and
reports the median and the worst run's max error over the joints, the worst final error
(deg, at the samples), the runs beyond :data:`apc_lab.wall_clock.LOST_DEG` ("lost", the
wall-time benchmark's rule), the runs with a hand-over and, in the JSON, ``chatter_nm``: how
far the command moves from one sample to the next in the hold after the move, the worst run's
worst joint's mean |u(k) - u(k-1)| (N m). About four minutes on one core.

    .venv/bin/python bench/robot_clock_offline.py [--arms ...] [--no-relinearize]
        [--ideal-velocity] [--no-armature] [--no-friction] [--no-feedforward-ahead]
        [--alpha-model A]
        [--set NAME=VALUE ...] [--json FILE]

``--no-relinearize``: the recommended preset with the paper's prior (Eq. 33 at the first set
point only, ``adaptive.relinearize: false``) instead of one that follows the set point.
``--ideal-velocity``: the ideal arm's driver publishes the arm's exact velocity as well (what
``robot_sim`` does by default), instead of positions only. The controllers of a physical arm
are told its rotor inertia and its friction (the controller nodes' ``armature``, ``friction``
and ``damping``), as the wall-time benchmark's are
(:func:`apc_lab.robot_compare.controller_arm_parameters`); ``--no-armature``,
``--no-friction``: not told.
``--alpha-model A``: the recommended preset with ``alpha_model`` A (``--set alpha_model=A``).
``--set NAME=VALUE`` (repeatable): the recommended preset with its setting NAME VALUE (a number,
an integer or a boolean as the preset's own value is; a later one wins), to measure a candidate
change of the preset on the whole grid; the JSON records them (``settings_overrides``).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from apc_feedback.payload_estimate import PayloadEstimateConfig
from apc_feedback.presets import recommended_settings
from apc_feedback.robot_loop import RobotLoop
from apc_feedback.supervisor import SupervisorConfig
from apc_lab.robot_compare import (
    ARM_EFFECTS,
    arm_scenario,
    controller_armature,
    controller_friction,
)
from apc_lab.robot_offline import Latency, run_robot_loop
from apc_lab.wall_clock import HOLD_BEFORE_S, LOST_DEG
from apc_plant_sim.effects import ArmEffects

ARMS = ("puma3", "panda")
EFFECTS = ("ideal", "physical")
RATES_HZ = (100, 250, 500, 1000)
#: The runs of a cell: the payload times these (run i also draws late commands with seed i).
PAYLOAD_FACTORS = (1.0, 0.99, 0.995, 1.005, 1.01)
#: Case (c)'s move (s), which starts :data:`~apc_lab.wall_clock.HOLD_BEFORE_S` after
#: activation, as the wall-time bench sends its goal; the run ends :data:`FINAL_HOLD_S` after it
#: (its last sample is the table's final error).
MOVE_S = 1.0
FINAL_HOLD_S = 1.3
#: The hold after the move from which the commands' chatter is measured (s after the move's
#: end): the worst joint's mean |u(k) - u(k-1)| (N m), docs/robot.md, "Commands that chatter".
CHATTER_AFTER_MOVE_S = 0.2
#: law label -> supervisor (None: the adaptive law alone).
LAWS: dict[str, SupervisorConfig | None] = {
    "adaptive alone": None,
    "supervised, computed-torque fallback": SupervisorConfig(),
    "supervised, PID fallback": SupervisorConfig(fallback="pid"),
}


def one_run(
    arm: str,
    effects: str | ArmEffects,
    rate_hz: float,
    late: bool,
    index: int,
    supervisor: SupervisorConfig | None,
    settings: dict | None = None,
    ideal_velocity: bool = False,
    setup: Callable[[RobotLoop], object] | None = None,
    armature: bool = True,
    feedforward_ahead: bool = True,
    friction: bool = True,
    latency: Latency | None = None,
    payload_factor: float | None = None,
    payload_estimate: bool = False,
) -> dict:
    """Run ``index`` of a cell: max error, error at the move's end and at the run's end per
    joint (deg), hand-overs, the commands' chatter in the hold (N m).

    ``effects``: one of :data:`EFFECTS`, or the arm's effects themselves (in MuJoCo, as
    ``physical``); ``setup``: as :func:`run_robot_loop`'s (to tell or change the law before
    activation); ``armature``, ``friction``: the controllers of a ``physical`` arm are told its
    rotor inertia (:func:`controller_armature`), its friction (:func:`controller_friction`;
    neither for effects given as themselves: what they cost unknown). ``latency``, in place
    of ``late``'s, and ``payload_factor``, in place of :data:`PAYLOAD_FACTORS`' ``index``-th:
    for runs outside the grid (``bench/activation_bursts.py``). ``payload_estimate``: robot
    mode estimates the payload in the hold (:func:`payload_estimate_config`).
    """
    scenario = arm_scenario(arm, "c")
    driver_ms = 1000.0 / rate_hz
    if latency is None and late:
        latency = Latency(late_ms=driver_ms, probability=0.3, seed=index)
    if payload_factor is None:
        payload_factor = PAYLOAD_FACTORS[index]
    if isinstance(effects, ArmEffects):
        arm_effects: ArmEffects | None = effects
    else:
        arm_effects = ARM_EFFECTS[arm]() if effects == "physical" else None
    run = run_robot_loop(
        HOLD_BEFORE_S + MOVE_S + FINAL_HOLD_S,
        goal_deg=scenario.q_goal_deg,
        hold_s=HOLD_BEFORE_S,
        driver_ms=driver_ms,
        phase_ms=0.37 * driver_ms,
        transport_ms=0.3 * min(1.0, driver_ms),
        payload_kg=scenario.payload_kg * payload_factor,
        latency=latency,
        supervisor=supervisor,
        effects=arm_effects,
        arm=scenario,
        settings=settings,
        velocity=True if ideal_velocity else None,
        setup=setup,
        feedforward_ahead=feedforward_ahead,
        armature=controller_armature(arm, effects)
        if armature and isinstance(effects, str)
        else None,
        friction=controller_friction(arm, effects)
        if friction and isinstance(effects, str)
        else None,
        payload_estimate=payload_estimate_config(arm) if payload_estimate else None,
    )
    errors = run.tracking_error_deg()
    return {
        "max_deg": errors.max(axis=0).round(3).tolist(),
        # The wall-time bench's "final" error; final_deg is the run's end, 1.3 s into the hold.
        "move_end_deg": run.tracking_error_at_move_end_deg().round(3).tolist(),
        "final_deg": errors[-1].round(3).tolist(),
        "handovers": run.counts.get("supervisor.handovers", 0),
        "chatter_nm": round(
            float(np.nanmax(run.command_chatter_nm(HOLD_BEFORE_S + MOVE_S + CHATTER_AFTER_MOVE_S))),
            2,
        ),
    }


def payload_estimate_config(arm: str) -> PayloadEstimateConfig:
    """Robot mode's payload estimate on ``arm``, told where its payload is fixed (the robot
    file's ``payload_estimate.*``)."""
    scenario = arm_scenario(arm, "c")
    return PayloadEstimateConfig(
        enable=True, frame=scenario.payload_frame or "", com_m=tuple(scenario.payload_com_m)
    )


def summarise(runs: list[dict]) -> dict:
    """A cell of :func:`one_run`'s runs: the worst and the median over the runs of the worst
    joint's max error, the worst error at the move's end (over the runs not lost) and at the
    run's end (deg), the runs lost (beyond ``LOST_DEG``), the runs, the runs with a hand-over.
    A run whose simulation blew up (an error not finite) counts as infinite, so as lost."""
    worst = [_finite(np.max(r["max_deg"])) for r in runs]
    kept = [(r, w) for r, w in zip(runs, worst, strict=True) if w <= LOST_DEG]
    return {
        "max_deg": max(worst),
        "median_max_deg": float(np.median(worst)),
        # Over the runs not lost, as the wall-time bench's final error: a lost run's goal may
        # have been aborted, its set point then the hold where the arm was.
        "move_end_deg": max(
            (_finite(np.max(r["move_end_deg"])) for r, _ in kept),
            default=float("inf"),
        ),
        "final_deg": max(_finite(np.max(r["final_deg"])) for r in runs),
        "lost": sum(w > LOST_DEG for w in worst),
        "runs": len(runs),
        "handover_runs": sum(r["handovers"] > 0 for r in runs),
        "chatter_nm": max(_finite(r["chatter_nm"]) for r in runs),
    }


def _finite(value: float) -> float:
    return float(value) if np.isfinite(value) else float("inf")


def measure(
    arms: tuple[str, ...] = ARMS,
    settings: dict | None = None,
    ideal_velocity: bool = False,
    armature: bool = True,
    feedforward_ahead: bool = True,
    friction: bool = True,
    payload_estimate: bool = False,
) -> list[dict]:
    """Every cell of ``arms``; ``settings``: the adaptive law's (default: the recommended
    preset); ``ideal_velocity``: the ideal arm's states carry its exact velocity;
    ``armature``, ``friction``: the controllers know a physical arm's rotor inertia, its
    friction; ``feedforward_ahead``, ``payload_estimate``: robot mode's."""
    cells = []
    for arm in arms:
        for effects in EFFECTS:
            for rate in RATES_HZ:
                for late in (False, True):
                    for law, supervisor in LAWS.items():
                        runs = [
                            one_run(
                                arm,
                                effects,
                                rate,
                                late,
                                i,
                                supervisor,
                                settings,
                                ideal_velocity,
                                armature=armature,
                                feedforward_ahead=feedforward_ahead,
                                friction=friction,
                                payload_estimate=payload_estimate,
                            )
                            for i in range(len(PAYLOAD_FACTORS))
                        ]
                        cell = {
                            "arm": arm,
                            "effects": effects,
                            "rate_hz": rate,
                            "commands": "30 % one cycle late" if late else "on time",
                            "law": law,
                            **summarise(runs),
                        }
                        cells.append(cell)
                        print(
                            f"{arm:6s} {effects:9s} {rate:5d} Hz {cell['commands']:20s} "
                            f"{law:37s} median {cell['median_max_deg']:8.2f} worst "
                            f"{cell['max_deg']:8.2f} / {cell['move_end_deg']:7.2f} / "
                            f"{cell['final_deg']:7.2f}  lost "
                            f"{cell['lost']}/{cell['runs']}  hand-overs in "
                            f"{cell['handover_runs']}  chatter {cell['chatter_nm']:.1f} N m",
                            flush=True,
                        )
    return cells


def _deg(value: float) -> str:
    return "lost" if value >= 1000.0 else f"{value:.2f}" if value < 100.0 else f"{value:.0f}"


def entry(cell: dict) -> str:
    """``median; worst max / final`` and what went wrong, e.g. ``1.01; 7.02 / 0.03 (1 h)``."""
    text = f"{_deg(cell['median_max_deg'])}; {_deg(cell['max_deg'])} / {_deg(cell['final_deg'])}"
    notes = []
    if cell["lost"]:
        notes.append(f"lost {cell['lost']}")
    if cell["handover_runs"]:
        notes.append(f"{cell['handover_runs']} h")
    return text + (f" ({', '.join(notes)})" if notes else "")


#: Column headings of the cells' keys (a driver's rate is shown in Hz).
HEADINGS = {"rate_hz": "driver"}


def markdown(
    cells: list[dict],
    rows: tuple[str, ...] = ("arm", "effects", "rate_hz", "commands"),
    column: str = "law",
    columns: tuple[str, ...] = tuple(LAWS),
) -> str:
    """One row per value of the ``rows`` keys (default: arm, effects, rate and timing of the
    commands); one column per value of ``column`` in ``columns`` (default: per law)."""
    lines = [
        "| " + " | ".join(HEADINGS.get(key, key) for key in rows) + " | " + " | ".join(columns)
        + " |",
        "|" + "---|" * (len(rows) + len(columns)),
    ]  # fmt: skip
    table: dict[tuple, dict[str, dict]] = {}
    for c in cells:
        table.setdefault(tuple(c[key] for key in rows), {})[c[column]] = c
    for values, entries in table.items():
        keyed = zip(rows, values, strict=True)
        heads = [f"{v} Hz" if key == "rate_hz" else str(v) for key, v in keyed]
        lines.append(
            "| " + " | ".join(heads) + " | " + " | ".join(entry(entries[c]) for c in columns)
            + " |"
        )  # fmt: skip
    return "\n".join(lines) + "\n"


def setting(text: str) -> tuple[str, bool | int | float]:
    """``NAME=VALUE`` of ``--set``: a setting of :func:`recommended_settings` and its value,
    parsed as the preset's own value is (a boolean, an integer or a number). An unknown name or
    a value that does not parse is an :class:`argparse.ArgumentTypeError` saying which."""
    name, sep, value = text.partition("=")
    name, value = name.strip(), value.strip()
    preset = recommended_settings()
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    if name not in preset:
        raise argparse.ArgumentTypeError(
            f"unknown setting {name!r}: one of {', '.join(sorted(preset))}"
        )
    default = preset[name]
    if isinstance(default, bool):
        words = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}
        if value.lower() not in words:
            raise argparse.ArgumentTypeError(f"setting {name!r}: not a boolean: {value!r}")
        return name, words[value.lower()]
    try:
        return name, int(value) if isinstance(default, int) else float(value)
    except ValueError:
        kind = "an integer" if isinstance(default, int) else "a number"
        raise argparse.ArgumentTypeError(f"setting {name!r}: not {kind}: {value!r}") from None


def parser() -> argparse.ArgumentParser:
    """The command line. ``--set``, ``--alpha-model`` and ``--no-relinearize`` all append to
    ``set``, the overrides of the preset's settings in the order given."""
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    cli.add_argument("--json", type=Path, help="write the cells here")
    cli.add_argument(
        "--no-relinearize",
        dest="set",
        action="append_const",
        const=("relinearize", False),
        help="the recommended preset with the paper's prior (Eq. 33 at the first set point)",
    )
    cli.add_argument(
        "--ideal-velocity",
        action="store_true",
        help="the ideal arm's states carry its exact velocity (a driver that publishes one)",
    )
    cli.add_argument(
        "--no-armature",
        action="store_true",
        help="the controllers' model of a physical arm lacks its rotor inertia",
    )
    cli.add_argument(
        "--no-friction",
        action="store_true",
        help="the controllers' model of a physical arm lacks its friction",
    )
    cli.add_argument(
        "--no-feedforward-ahead",
        action="store_true",
        help="robot mode's feedforward_ahead off: the nominal torque of the sample's own time",
    )
    cli.add_argument(
        "--payload-estimate",
        action="store_true",
        help="robot mode estimates the payload in the hold (payload_estimate.enable), as the "
        "robot files do; without it the grid measures the law alone",
    )
    cli.add_argument(
        "--alpha-model",
        dest="set",
        action="append",
        type=lambda value: setting(f"alpha_model={value}"),
        metavar="A",
        help="the preset's alpha_model instead (--set alpha_model=A)",
    )
    cli.add_argument(
        "--set",
        dest="set",
        action="append",
        type=setting,
        metavar="NAME=VALUE",
        help="the preset's setting NAME instead (repeatable; a later one wins)",
    )
    return cli


def overrides(args: argparse.Namespace) -> dict[str, bool | int | float]:
    """The preset's settings the command line changes, the last given of each name winning."""
    return dict(args.set or ())


def main() -> None:
    args = parser().parse_args()
    changed = overrides(args)
    settings = {**recommended_settings(), **changed} if changed else None
    cells = measure(
        tuple(args.arms),
        settings,
        args.ideal_velocity,
        not args.no_armature,
        not args.no_feedforward_ahead,
        not args.no_friction,
        args.payload_estimate,
    )
    print()
    print(markdown(cells), end="")
    if args.json:
        doc = {
            "simulated_time": True,
            "relinearize": (settings or recommended_settings())["relinearize"],
            "ideal_velocity": args.ideal_velocity,
            "armature": not args.no_armature,
            "friction": not args.no_friction,
            "feedforward_ahead": not args.no_feedforward_ahead,
            "payload_estimate": args.payload_estimate,
            "alpha_model": changed.get("alpha_model"),
            "settings_overrides": changed,
            "cells": cells,
        }
        args.json.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
