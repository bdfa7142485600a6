"""Long runs offline: repeated moves and holds with payload changes, no ROS.

The closed loop of :func:`apc_lab.offline.run_closed_loop` (plant -> feedforward -> feedback,
one sample at a time, the same core modules the nodes run), driven by a :class:`Schedule`: 4-3-4
moves between a cycle of poses (``Feedforward.set_trajectory``), holds of 0.5 to 20 s in
between, and the payload on the simulated arm changed every few moves
(``Plant.set_robot(with_payload(...))``; the controllers are never told). Nothing is stored per
sample: running maxima and counts are kept per time segment (:class:`Segment`), so an hour costs
no memory. ``bench/long_run.py`` runs it for hours; the suite for minutes.

Configurations (:data:`CONFIGS`): ``guarded``, the default adaptive settings (the RLS wind-up
guard on, ``trace_max = 0``: trace(P) <= trace(P(0))), ``paper``, the printed settings (no
guard), ``guarded_qpos`` / ``paper_qpos`` the same with a position-weighted Q
(``q_position = 1e3``), and ``recommended``, the recommended preset.
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from apc_core.robot import (
    PAPER_GOAL_DEG,
    PAPER_START_DEG,
    Payload,
    load_robot,
    with_inertia_error,
    with_payload,
)
from apc_feedback.laws import make_law
from apc_feedforward.four_three_four import FourThreeFour
from apc_feedforward.nominal import Feedforward
from apc_lab.scenario import (
    PAPER_CASES,
    paper_scenario,
    paper_settings,
    recommended_settings,
)
from apc_plant_sim.plant import Plant, PlantConfig, PlantError

#: Poses visited in turn (URDF angles, deg): the paper's start and end, its stretched pose
#: (gravity loading of joint 2 peaks), and two more.
POSES_DEG: tuple[tuple[float, ...], ...] = (
    PAPER_START_DEG,
    PAPER_GOAL_DEG,
    (45.0, 0.0, -90.0),
    (-30.0, -20.0, -60.0),
    (60.0, 30.0, -120.0),
)
#: Holds after each move, in turn (s): short ones, and long ones where an unguarded RLS winds up.
HOLDS_S: tuple[float, ...] = (0.5, 2.0, 0.5, 5.0, 1.0, 20.0)
#: Payloads on the simulated arm, in turn (kg): none, the paper's 5 lb, half of it.
PAYLOADS_KG: tuple[float, ...] = (PAPER_CASES["a"], PAPER_CASES["c"], PAPER_CASES["b"])

CONFIGS: dict[str, dict[str, Any]] = {
    # AdaptiveConfig defaults: the paper's Q = 0.1 I, R, rho, alpha, and trace_max = 0 (guard on)
    "guarded": {},
    # as printed: trace_max < 0, no guard
    "paper": paper_settings(),
    # the same two with a position-weighted Q (bench/trace_guard.py), which holds a payload
    "guarded_qpos": {"q_position": 1e3},
    "paper_qpos": dict(paper_settings(), q_position=1e3),
    # the measured fix within the paper's structure (docs/paper.md, bench/preset_sweep.py)
    "recommended": recommended_settings(),
}


@dataclass
class Schedule:
    """What the arm does: moves between ``poses_deg`` with ``holds_s`` after each, and the
    payload changed (at the start of a move) every ``moves_per_payload`` moves."""

    poses_deg: Sequence[Sequence[float]] = POSES_DEG
    holds_s: Sequence[float] = HOLDS_S
    payloads_kg: Sequence[float] = PAYLOADS_KG
    moves_per_payload: int = 3
    segment_times: tuple[float, float, float] = (0.2, 0.6, 0.2)

    def events(self) -> Iterator[tuple[int, float | None, float]]:
        """``(target pose index, new payload or None, hold after the move)``, forever."""
        payloads = itertools.cycle(self.payloads_kg)
        holds = itertools.cycle(self.holds_s)
        next(payloads)  # the first payload is the one the arm starts with
        for i in itertools.count():
            target = (i + 1) % len(self.poses_deg)
            change = next(payloads) if i > 0 and i % self.moves_per_payload == 0 else None
            yield target, change, next(holds)


@dataclass
class Segment:
    """Running aggregates over one time segment."""

    t0_s: float
    n: int
    max_error_move: np.ndarray = field(init=False)
    max_error_hold: np.ndarray = field(init=False)
    max_trace_p: float = 0.0
    rejected: int = 0
    saturated: int = 0
    samples: int = 0
    moves: int = 0
    payload_changes: int = 0
    finite: bool = True

    def __post_init__(self) -> None:
        self.max_error_move = np.zeros(self.n)
        self.max_error_hold = np.zeros(self.n)

    def as_dict(self, period: float) -> dict[str, Any]:
        return {
            "t0_min": round(self.t0_s / 60.0, 3),
            "t1_min": round((self.t0_s + self.samples * period) / 60.0, 3),
            "max_error_deg_move": np.rad2deg(self.max_error_move).round(4).tolist(),
            "max_error_deg_hold": np.rad2deg(self.max_error_hold).round(4).tolist(),
            "max_trace_p": float(f"{self.max_trace_p:.4g}"),
            "rejected_updates": self.rejected,
            "saturated_samples": self.saturated,
            "moves": self.moves,
            "payload_changes": self.payload_changes,
            "finite": self.finite,
        }


def run_long(
    settings: Mapping[str, Any],
    seconds: float,
    *,
    schedule: Schedule | None = None,
    segment_s: float = 600.0,
    progress: bool = False,
) -> dict[str, Any]:
    """Run the schedule for ``seconds`` of simulated time with the adaptive law's ``settings``.

    Returns
    -------
    dict
        ``segments`` (see :meth:`Segment.as_dict`) and totals over the run: ``max_error_deg``
        (move / hold), ``max_trace_p``, ``trace_p0``, ``rejected_updates``,
        ``saturated_samples``, ``finite`` (state, torques, estimate and trace(P) finite at every
        sample), ``diverged_at_s`` (the plant refused a non-finite state), ``wall_s``.
    """
    schedule = schedule or Schedule()
    scenario = paper_scenario("a")
    period = scenario.period
    robot = load_robot(scenario.urdf, gravity=scenario.gravity)
    controller = with_inertia_error(robot, scenario.inertia_error)
    frame = scenario.payload_frame

    def carrying(mass: float):
        return with_payload(robot, Payload(mass_kg=mass, com_m=(0.0, 0.0, 0.0), frame=frame))

    poses = [np.deg2rad(p) for p in schedule.poses_deg]
    plant = Plant(
        carrying(schedule.payloads_kg[0]),
        PlantConfig(period=period, step=scenario.step),
        poses[0],
    )
    hold = FourThreeFour(poses[0], poses[0], segment_times=schedule.segment_times)
    feedforward = Feedforward(controller.model, hold, period, 0)
    feedback = make_law("adaptive", controller, period, dict(settings))
    feedback.reset()
    n = plant.n_joints
    total = round(seconds / period)
    per_segment = max(1, round(segment_s / period))
    segments: list[Segment] = []
    events = schedule.events()
    next_event_k = 0  # sample at which the next move starts
    move_end_k = -1
    current = 0
    applied_prev: np.ndarray | None = None
    diverged_at = None
    finite = True
    trace_p0 = math.nan
    t_wall = time.perf_counter()
    seg = Segment(0.0, n)
    for k in range(total + 1):
        if k % per_segment == 0 and 0 < k < total:  # (the final sample closes the last one)
            segments.append(seg)
            seg = Segment(k * period, n)
        if k == next_event_k:
            target, payload, hold_s = next(events)
            if payload is not None:
                plant.set_robot(carrying(payload))
                seg.payload_changes += 1
            move = FourThreeFour(
                poses[current], poses[target], segment_times=schedule.segment_times
            )
            feedforward.set_trajectory(move, k)
            move_end_k = feedforward.end_k()
            next_event_k = move_end_k + round(hold_s / period)
            current = target
            seg.moves += 1
        q, qd = plant.q, plant.qd
        sp = feedforward.sample(k)
        out = feedback.update(k, q, qd, sp.q, sp.qd, sp.qdd, sp.u_n, applied_prev)
        error = np.abs(q - sp.q)
        if k <= move_end_k:
            np.maximum(seg.max_error_move, error, out=seg.max_error_move)
        else:
            np.maximum(seg.max_error_hold, error, out=seg.max_error_hold)
        trace_p = out.trace_p
        if k == 0:
            trace_p0 = trace_p
        ok = bool(np.isfinite(trace_p) and np.all(np.isfinite(out.du)))
        ok = ok and bool(np.all(np.isfinite(feedback.rls.theta)))
        if not ok:
            seg.finite = finite = False
        if np.isfinite(trace_p):
            seg.max_trace_p = max(seg.max_trace_p, trace_p)
        seg.rejected += bool(out.rejected)
        seg.samples += 1
        if k == total:
            break
        try:
            step = plant.step(sp.u_n + out.du)
        except PlantError:
            diverged_at = k * period
            seg.finite = finite = False
            break
        applied_prev = step.applied
        seg.saturated += bool(step.saturated.any())
        if progress and k % 36_000 == 0:
            done = k / max(total, 1)
            print(f"\r{100 * done:5.1f} %", end="", file=sys.stderr, flush=True)
    segments.append(seg)
    if progress:
        print(file=sys.stderr)
    wall = time.perf_counter() - t_wall
    samples = sum(s.samples for s in segments)
    return {
        "settings": {k: v for k, v in dict(settings).items()},
        "simulated_s": round(samples * period, 2),
        "samples": samples,
        "wall_s": round(wall, 1),
        "samples_per_s": round(samples / wall),
        "moves": sum(s.moves for s in segments),
        "payload_changes": sum(s.payload_changes for s in segments),
        "finite": finite,
        "diverged_at_s": diverged_at,
        "trace_p0": trace_p0,
        "max_trace_p": float(f"{max(s.max_trace_p for s in segments):.4g}"),
        "rejected_updates": sum(s.rejected for s in segments),
        "saturated_samples": sum(s.saturated for s in segments),
        "max_error_deg": {
            "move": np.rad2deg(np.max([s.max_error_move for s in segments], axis=0))
            .round(4)
            .tolist(),
            "hold": np.rad2deg(np.max([s.max_error_hold for s in segments], axis=0))
            .round(4)
            .tolist(),
        },
        "segments": [s.as_dict(period) for s in segments],
    }
